"""The crop's known answer on a dataset (issue 32's target: a crop keeping half of bonsai renders
within noise of the half volume, with every method):

    python lab/experiments/crop_known_answer.py OUT.json [--scene assets/scenes/bonsai.json]
        [--size 512] [--spp 256] [--frames 64] [--probes 64,128]

For each method (pt, probes, probes-only, raymarch compute and fragment) it renders
- A: the whole volume with `--crop-voxels 128 0 0 256 256 256` (x from the middle),
- B and C: the half volume `data[:, :, 128:]` as its own scene (SPEC.md: centred at the origin,
  longest side 1; bonsai's y and z stay 256 voxels, so the scale is the same) with the camera
  moved by minus the kept box's centre, with two seeds,
and records rRMSE(A, B) beside rRMSE(B, C), their ratio (about 1 when the crop is the cropped
volume up to noise), and the times. tests/test_crop_clip.py checks the same on a small volume.
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

from radiance_probes.scene.clip_region import clip_region  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.rendering.settings import RenderSettings  # noqa: E402
from radiance_probes.io.scene_file import load_scene, parse_scene  # noqa: E402
from radiance_probes.io.load import load_scene_volume  # noqa: E402


def rms(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--scene", default="assets/scenes/bonsai.json")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=256, help="path tracer and probes samples")
    ap.add_argument("--frames", type=int, default=64, help="raymarched frames")
    ap.add_argument("--probes", default="64,128", help="probe grid, walks")
    ap.add_argument("--axis", type=int, default=0, help="the axis cut in half (0 x, 1 y, 2 z)")
    args = ap.parse_args()
    grid, walks = (int(v) for v in args.probes.split(","))
    scene = load_scene(args.scene)
    scene = scene.replace(camera=dataclasses.replace(scene.camera, width=args.size,
                                                     height=args.size),
                          probes=dataclasses.replace(scene.probes, grid=(grid,) * 3, samples=walks))
    volume = load_scene_volume(scene)
    dims = volume.dims
    lo, hi = [0, 0, 0], list(dims)
    lo[args.axis] = dims[args.axis] // 2
    if dims[args.axis] == max(dims) and list(dims).count(max(dims)) == 1:
        print("warning: halving the only longest side changes the cropped volume's scale: the "
              "comparison does not hold", file=sys.stderr)
    data = scene.to_dict()
    data["crop"] = {"min": lo, "max": hi, "units": "voxels"}
    crop_scene = parse_scene(data, base_dir=scene.base_dir)
    region = clip_region(crop_scene, dims, volume.half_extent)
    sl = tuple(slice(lo[a], hi[a]) for a in (2, 1, 0))
    half = dataclasses.replace(volume, data=np.ascontiguousarray(volume.data[sl]), name="half")
    offset = region.centre
    cam = scene.camera
    moved = scene.replace(camera=dataclasses.replace(
        cam, eye=tuple(np.asarray(cam.eye) - offset), target=tuple(np.asarray(cam.target) - offset)))
    ctx = create_headless_context()
    records = []
    for method, stage in (("pt", "compute"), ("probes", "compute"), ("probes-only", "compute"),
                          ("raymarch", "compute"), ("raymarch", "fragment")):
        spp = args.frames if method == "raymarch" else args.spp
        images, times = [], []
        for vol, sc, seed in ((volume, crop_scene, 1), (half, moved, 2), (half, moved, 3)):
            r = Renderer(ctx, sc, vol, RenderSettings(raymarch_stage=stage))
            start = time.perf_counter()
            res = r.render(method, spp=spp, seed=seed, samples_per_pass=16)
            times.append({"wall_s": time.perf_counter() - start, "render_ms": res.render_ms,
                          "bake_ms": res.bake_ms})
            images.append(res.image)
            r.release()
        a, b, c = images
        diff, noise = rms(a, b), rms(b, c)
        scale = float(np.sqrt(np.mean(np.asarray(b, np.float64) ** 2)))
        rec = {"method": method, "stage": stage, "spp": spp, "rrmse_crop_vs_half": diff / scale,
               "rrmse_half_vs_half": noise / scale, "ratio": diff / noise if noise > 0 else None,
               "times": times}
        records.append(rec)
        print(f"{method} ({stage}): crop vs half {diff / scale:.4f}, half vs half {noise / scale:.4f}, "
              f"ratio {rec['ratio']:.3f}", file=sys.stderr)
    out = {"device": describe(ctx), "scene": args.scene, "size": args.size, "crop": data["crop"],
           "offset": list(map(float, offset)), "probes": [grid, walks], "records": records}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
