"""Issue 29, step 1: how much of the path tracer's per-pixel variance is the sun's shadow rays' own
noise, and (step 6) what residual ratio tracking of the shadow ray with the light grid as its
control takes away.

    python lab/experiments/experiment_shadow_variance.py OUT_DIR [--side 32] [--width 48]
        [--height 48] [--spp 16] [--images 8] [--scenes fuel,hydrogen,...] [--rays 1,16]
        [--tracking ratio,residual] [--bounces 1,own]

Per scene, per max_bounces (1: the first event alone, the camera ray's free flight against the sun's
shadow ray there; `own`: the scene's), per shadow-ray estimator (RenderSettings.shadow_tracking,
where this checkout has it) and per count N of independent shadow rays a scattering event averages
(LabOptions.sun_shadow_rays, app/rendering/lab_options.py; 1 is the renderers', 16 nearly a noiseless shadow ray): the path
tracer renders K images of SPP samples a pixel with independent seeds. From them a sample's relative
variance
    v = SPP * sum over pixels of var_k(image_k) / sum over pixels of mean_k(image_k)^2
(the image's squared rRMSE at one sample; with K = 2 exactly lab/experiments/guided_variance.py's
SPP * sum((a - b)^2) / 2 / sum(((a + b) / 2)^2); more images, more degrees of freedom a pixel) and the GPU ms a sample costs (timer queries; on llvmpipe
only indicative). Averaging N rays divides the shadow rays' own noise (their variance given the
path) by N and leaves the rest, so v_N = A + B / N, and the shadow rays' share of a one-ray sample's
variance is B / v_1 = (v_1 - v_N) N / ((N - 1) v_1) (the share column; from two noisy v's, a guide
with its own error). Each row's image mean is compared with the first row's of its scene and
bounces (z: the difference over its standard error from the two images' pixel noise): averaging
rays, or another unbiased estimator of the ray, may not move the mean (|z| beyond 3 would say it
did; with three colours and several rows a scene, a z of 2-3 now and then is chance).

--side S: every volume at S voxels along its longest axis at most (data sets block-averaged, the
built-in volumes generated at that size; the light grid follows); 0: each scene's own volume.
Scenes: the bench's (app/bench/scenes.py ALL_SCENES, data sets from ../shared/datasets where
present) and `cloud`, the built-in default scene (parse_scene({})).

Writes OUT_DIR/results.json (every row) and OUT_DIR/log.txt; the record's README says what ran.
Full size on a GPU (the bench's scenes at 512^2 with their own volumes):
    python lab/experiments/experiment_shadow_variance.py bench/h100-shadow-variance \\
        --side 0 --width 512 --height 512 --spp 64 --images 4
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.bench.scenes import ALL_SCENES, bench_scene  # noqa: E402
from radiance_probes.rendering.lab_options import LabOptions  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.rendering.settings import RenderSettings  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.io.load import load_volume  # noqa: E402

SCENES = (*ALL_SCENES, "cloud")
HAS_TRACKING = "shadow_tracking" in {f.name for f in dataclasses.fields(RenderSettings)}


def relative_variance(images: list, spp: int) -> float:
    """One sample's relative variance from K independent images of spp samples each: spp times the
    pixels' variance across the images (K - 1 degrees of freedom a pixel), summed, over the sum
    of the mean image's squares (two images: lab/experiments/guided_variance.py's estimate)."""
    stack = np.stack([np.asarray(i, np.float64)[..., :3] for i in images])
    mean = stack.mean(axis=0)
    return float(spp * np.sum(stack.var(axis=0, ddof=1)) / max(np.sum(mean ** 2), 1e-300))


def block_average(data: np.ndarray, side: int) -> np.ndarray:
    """data [z, y, x] averaged over blocks of f^3 voxels, f the least integer that brings the
    longest axis to `side` or fewer voxels (edges padded by repeating the last voxels)."""
    f = -(-max(data.shape[:3]) // side)
    if f <= 1:
        return data
    pad = [(0, (-n) % f) for n in data.shape[:3]]
    data = np.pad(data, pad, mode="edge")
    z, y, x = (n // f for n in data.shape[:3])
    return data.reshape(z, f, y, f, x, f).mean(axis=(1, 3, 5)).astype(np.float32)


def scene_and_volume(name: str, side: int, width: int, height: int):
    """(scene, volume or None) at the given size; None, None where the data set is absent."""
    if name == "cloud":
        scene = parse_scene({})
        scene = scene.replace(camera=dataclasses.replace(scene.camera, width=width,
                                                         height=height))
    else:
        scene = bench_scene(name, width, height)
        if scene is None:
            return None, None
    if side <= 0:
        return scene, None
    spec = scene.volume
    if spec.path is None:   # a built-in: generated at the size
        size = tuple(max(2, round(v * side / max(spec.size))) for v in spec.size)
        size = tuple(min(v, s) for v, s in zip(size, spec.size))
        return scene.replace(volume=dataclasses.replace(spec, size=size)), None
    volume = load_volume(spec, scene.base_dir)
    data = block_average(volume.data, side)
    factor = np.array(volume.data.shape[:3][::-1], float) / np.array(data.shape[:3][::-1], float)
    small = dataclasses.replace(volume, data=data,
                                spacing=tuple(float(s * f) for s, f in
                                              zip(volume.spacing, factor)))
    return scene, small


def render_images(renderer: Renderer, count: int, spp: int, per_pass: int, seed: int):
    """count path-traced images of spp samples (seeds seed, seed + 1, ...) and GPU ms a sample
    (after an untimed render: a pass's first render holds one-off work)."""
    renderer.render("pt", spp=min(per_pass, spp), seed=seed + 7919, samples_per_pass=per_pass)
    images, ms, stats = [], [], []
    for s in range(seed, seed + count):
        result = renderer.render("pt", spp=spp, seed=s, samples_per_pass=per_pass)
        images.append(result.image)
        ms.append(result.render_ms / spp)
        stats.append(result.stats)
    return images, float(np.mean(ms)), stats


def mean_and_error(images: list) -> tuple[np.ndarray, np.ndarray]:
    """The image's mean RGB over all images, and that mean's variance (from the pixels' variance
    across the images, pixels independent)."""
    stack = np.stack([np.asarray(i, np.float64)[..., :3].reshape(-1, 3) for i in images])
    count, pixels = stack.shape[:2]
    mean = stack.mean(axis=(0, 1))
    var = stack.var(axis=0, ddof=1).sum(axis=0) / count / pixels ** 2
    return mean, var


def measure_scene(ctx, name: str, args, log) -> dict | None:
    scene, volume = scene_and_volume(name, args.side, args.width, args.height)
    if scene is None:
        log(f"{name}: data set absent, skipped")
        return None
    renderer = Renderer(ctx, scene, volume)
    dims = tuple(int(v) for v in renderer.resources.volume.dims)
    out = {"scene": name, "volume_dims": dims, "width": args.width, "height": args.height,
           "spp": args.spp, "images": args.images, "own_max_bounces": scene.max_bounces, "rows": []}
    try:
        for bounces_name in args.bounces.split(","):
            bounces = scene.max_bounces if bounces_name == "own" else int(bounces_name)
            if bounces_name != "own" and bounces >= scene.max_bounces:
                continue
            renderer.set_scene(scene.replace(max_bounces=bounces))
            first = None
            for tracking in args.tracking.split(","):
                if tracking != "ratio" and not HAS_TRACKING:
                    log(f"{name}: shadow tracking {tracking!r} is not in this checkout, skipped")
                    continue
                for rays in (int(n) for n in args.rays.split(",")):
                    renderer.lab = LabOptions(sun_shadow_rays=rays)
                    if HAS_TRACKING:
                        renderer.configure(shadow_tracking=tracking)
                    t0 = time.perf_counter()
                    images, ms, stats = render_images(renderer, args.images, args.spp,
                                                      args.per_pass, args.seed)
                    v = relative_variance(images, args.spp)
                    mean, mean_var = mean_and_error(images)
                    row = {"max_bounces": bounces, "tracking": tracking, "shadow_rays": rays,
                           "relative_variance": v, "ms_per_sample": ms,
                           "mean_rgb": mean.tolist(),
                           "finite": bool(all(np.all(np.isfinite(i)) for i in images)),
                           "negative_pixels": int(sum(np.sum(i < 0.0) for i in images)),
                           "truncated_paths": int(sum(s.get("truncated_paths", 0)
                                                      for s in stats)),
                           "wall_s": None}
                    if first is None:
                        first = (row, mean, mean_var)
                    else:
                        f_row, f_mean, f_var = first
                        row["mean_z_vs_first"] = float(np.max(np.abs(mean - f_mean)
                                                              / np.sqrt(f_var + mean_var + 1e-300)))
                        row["mean_ratio_vs_first"] = float(mean.sum() / max(f_mean.sum(), 1e-300))
                    base = next((r for r in out["rows"] if r["max_bounces"] == bounces
                                 and r["tracking"] == tracking and r["shadow_rays"] == 1), None)
                    if base is not None and rays > 1:
                        v1 = base["relative_variance"]
                        row["shadow_share_of_one_ray"] = (v1 - v) * rays / ((rays - 1) * v1)
                    ratio_one = next((r for r in out["rows"] if r["max_bounces"] == bounces
                                      and r["tracking"] == "ratio" and r["shadow_rays"] == rays),
                                     None)
                    if ratio_one is not None and tracking != "ratio":
                        row["v_over_ratio"] = v / ratio_one["relative_variance"]
                        row["vt_over_ratio"] = (v * ms / (ratio_one["relative_variance"]
                                                          * ratio_one["ms_per_sample"]))
                    row["wall_s"] = time.perf_counter() - t0
                    out["rows"].append(row)
                    log(f"{name} {dims} bounces {bounces} {tracking} x{rays}: v {v:.4g}, "
                        f"{ms:.4g} ms a sample, share {row.get('shadow_share_of_one_ray', '-')}, "
                        f"z {row.get('mean_z_vs_first', '-')} ({row['wall_s']:.1f} s)")
    finally:
        renderer.release()
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--scenes", default=",".join(SCENES))
    p.add_argument("--side", type=int, default=32,
                   help="voxels along the longest axis at most (0: each scene's own)")
    p.add_argument("--width", type=int, default=48)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--spp", type=int, default=16, help="samples a pixel of each image")
    p.add_argument("--images", type=int, default=8, help="independent images a row")
    p.add_argument("--per-pass", type=int, default=16, help="samples a render pass adds")
    p.add_argument("--rays", default="1,16", help="shadow rays an event averages, first 1")
    p.add_argument("--tracking", default="ratio,residual" if HAS_TRACKING else "ratio")
    p.add_argument("--bounces", default="1,own")
    p.add_argument("--seed", type=int, default=1000)
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    from radiance_probes.gl.context import create_headless_context, describe
    ctx = create_headless_context()
    device = describe(ctx)
    log_file = (args.out / "log.txt").open("a")

    def log(msg):
        print(msg, flush=True)
        log_file.write(msg + "\n")
        log_file.flush()

    log(f"{device}: {' '.join(sys.argv)}")
    results = []
    path = args.out / "results.json"
    for name in args.scenes.split(","):
        r = measure_scene(ctx, name, args, log)
        if r is not None:
            results.append(r)
        path.write_text(json.dumps({"device": device, "command": " ".join(sys.argv),
                                    "args": {k: str(v) for k, v in vars(args).items()},
                                    "results": results}, indent=1))
    log(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
