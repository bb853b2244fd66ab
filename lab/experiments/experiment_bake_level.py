"""What does the probes' bake save by walking a coarser level than the image
(RenderSettings.bake_level), and what does it cost in error against the path tracer?

    python lab/experiments/experiment_bake_level.py OUT_DIR [--quick] [--scenes a,b,...]
        [--levels 0,1,2,-1] [--size 512] [--side N] [--grid 32] [--walks 256] [--frames 16]
        [--ref-spp 4096] [--seeds 2] [--max-bounces N]

Per scene: a path-traced reference (`pt`, which always walks the level shown) of two independent
halves, whose difference gives its noise (app/rendering/metrics.py reference_noise); then per bake
level, for each seed, the probes baked from cold and the raymarcher's image (--frames frames):
  - bake_ms: the probes' bake (after an untimed one at the same level) (its walks' light grid included: the image's at level 0, its own in
    the coarse medium above), GPU time;
  - prep_ms: everything the raymarched image needed before its frames (the bake and, above level
    0, the image's own light grid too);
  - rrmse, and rrmse_corrected (the reference's noise taken out, metrics.corrected_rrmse), of the
    raymarched image against the reference; image_mean_vs_reference.
Level -1 is recorded with the level the probes' spacing gave (resolved_level).

Full size (a GPU): 512^2 images of the bench's scenes (app/bench/scenes.py): the data sets where
../shared/datasets has them, the thick and anisotropic clouds, and the battery's backlit shells of
albedo 0.99 (g = 0.6 and 0.9, about two voxels thick) and its dense speck, probes 32^3 x 256.
--quick (llvmpipe, about half a minute): the built-in scenes at 16 voxels, 16^2 images, probes 4^3 x
32, 256 reference samples, 2 frames, max_bounces at most 16, one seed; --side/--size/... override
either (bench/llvmpipe-bake-level's run: --quick --side 32 --size 48 --grid 8 --ref-spp 1024
--seeds 2 --frames 8).
Writes OUT_DIR/bake_level.json (meta: device from the GL renderer string, arguments; records) and
prints a table.
"""
from __future__ import annotations

import argparse
import copy
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse  # noqa: E402
from radiance_probes.bench.scenes import BUILTIN_SCENES, DATASET_SCENES, bench_scene  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.rendering.settings import RenderSettings  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402

BUILT_IN = ("thick", "anisotropic", "shell-g06", "shell-g09", "speck")

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("out")
parser.add_argument("--quick", action="store_true", help="llvmpipe: small scenes, seconds")
parser.add_argument("--scenes", default=None, help="default: data sets found, then "
                    + ",".join(BUILT_IN) + " (--quick: the built-in ones)")
parser.add_argument("--levels", default="0,1,2,-1")
parser.add_argument("--size", type=int, default=None, help="image side (512; quick 16)")
parser.add_argument("--side", type=int, default=None,
                    help="built-in volumes' longest side in voxels (the bench's; quick 16)")
parser.add_argument("--grid", type=int, default=None, help="probes per axis (32; quick 4)")
parser.add_argument("--walks", type=int, default=None, help="walks per probe (256; quick 32)")
parser.add_argument("--frames", type=int, default=None, help="raymarched frames (16; quick 2)")
parser.add_argument("--ref-spp", type=int, default=None, help="reference spp (4096; quick 256)")
parser.add_argument("--seeds", type=int, default=None, help="bakes per level (2; quick 1)")
parser.add_argument("--max-bounces", type=int, default=None,
                    help="at most this many (the scene's; quick 16)")
args = parser.parse_args()
q = args.quick


def pick(value, full, quick):
    return value if value is not None else (quick if q else full)


size = pick(args.size, 512, 16)
side = pick(args.side, None, 16)
grid = pick(args.grid, 32, 4)
walks = pick(args.walks, 256, 32)
frames = pick(args.frames, 16, 2)
ref_spp = pick(args.ref_spp, 4096, 256)
seeds = list(range(11, 11 + pick(args.seeds, 2, 1)))
max_bounces = pick(args.max_bounces, None, 16)
levels = [int(v) for v in args.levels.split(",")]
names = (args.scenes.split(",") if args.scenes else
         list(BUILT_IN) if q else [*DATASET_SCENES, *BUILT_IN])
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)


def scene_of(name: str):
    """The bench's scene at this run's sizes (None: a data set that is absent)."""
    if name in BUILTIN_SCENES and side is not None:
        spec = copy.deepcopy(BUILTIN_SCENES[name])
        full = spec["volume"]["size"]
        spec["volume"]["size"] = [max(2, round(v * side / max(full))) for v in full]
        scene = parse_scene(spec)
        scene = scene.replace(camera=replace(scene.camera, width=size, height=size))
    else:
        scene = bench_scene(name, size, size)
    if scene is None:
        return None
    if max_bounces is not None:
        scene = scene.replace(max_bounces=min(scene.max_bounces, max_bounces))
    return scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks))


ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
meta = {"device": device, "command": " ".join(sys.argv), "quick": q, "size": size, "side": side,
        "grid": grid, "walks": walks, "frames": frames, "ref_spp": ref_spp, "seeds": seeds,
        "max_bounces_cap": max_bounces, "levels": levels, "started": time.strftime("%F %T")}
records = []


def flush():
    (out / "bake_level.json").write_text(json.dumps({"meta": meta, "records": records}, indent=1))


for name in names:
    scene = scene_of(name)
    if scene is None:
        print(f"{name}: data set absent, skipped", flush=True)
        continue
    r = Renderer(ctx, scene)
    start = time.time()
    half = max(1, ref_spp // 2)
    a = r.render("pt", spp=half, seed=1001, samples_per_pass=half).image
    b = r.render("pt", spp=half, seed=2002, samples_per_pass=half).image
    reference = 0.5 * (a + b)
    noise = reference_noise(a, b)
    ref_s = time.time() - start
    ref_mean = float(reference.mean(dtype="float64"))
    print(f"{name}: {r.resources.volume.dims} voxels, reference {ref_spp} spp in {ref_s:.1f} s, "
          f"noise {100 * noise:.2f}%", flush=True)
    for level in levels:
        r.settings = RenderSettings(bake_level=level)
        r.invalidate()
        r.render("raymarch", spp=1, seed=1)   # untimed: compiles this level's passes (llvmpipe
        rows = []                             # compiles at the first dispatch, inside the timer)
        for seed in seeds:
            r.invalidate()
            result = r.render("raymarch", spp=frames, seed=seed, samples_per_pass=frames)
            e = rrmse(result.image, reference)
            rows.append({"seed": seed, "bake_ms": r.last_bake_ms, "prep_ms": result.bake_ms,
                         "rrmse": e, "rrmse_corrected": corrected_rrmse(e, noise),
                         "mean_vs_reference": float(result.image.mean(dtype="float64"))
                         / ref_mean - 1.0})
        medium = r._bake_medium if r.bake_level() else None
        rec = {"scene": name, "device": device, "level": level, "resolved_level": r.bake_level(),
               "volume_dims": list(r.resources.volume.dims),
               "bake_dims": list(medium.volume.dims if medium else r.resources.volume.dims),
               "walk_light_grid": list(r.walk_light().grid) if r.walk_light() else None,
               "reference_spp": ref_spp, "reference_noise": noise,
               "bake_ms": statistics.median(x["bake_ms"] for x in rows),
               "prep_ms": statistics.median(x["prep_ms"] for x in rows),
               "rrmse": statistics.mean(x["rrmse"] for x in rows),
               "rrmse_corrected": statistics.mean(x["rrmse_corrected"] for x in rows),
               "mean_vs_reference": statistics.mean(x["mean_vs_reference"] for x in rows),
               "per_seed": rows}
        records.append(rec)
        flush()
        print(f"  level {level:>2} ({rec['resolved_level']}, bake {rec['bake_dims']}): bake "
              f"{rec['bake_ms']:.1f} ms, prep {rec['prep_ms']:.1f} ms, rRMSE "
              f"{100 * rec['rrmse']:.2f}% (corrected {100 * rec['rrmse_corrected']:.2f}%), mean "
              f"{100 * rec['mean_vs_reference']:+.2f}%", flush=True)
    r.release()

meta["finished"] = time.strftime("%F %T")
flush()
print(f"\n| scene | bake level | walks | bake ms | prep ms | rRMSE vs pt | corrected | mean | "
      f"reference noise |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for rec in records:
    d = rec["bake_dims"]
    lvl = (f"{rec['level']} (-> {rec['resolved_level']})" if rec["level"] < 0
           else str(rec["level"]))
    print(f"| {rec['scene']} | {lvl} | {d[0]}x{d[1]}x{d[2]} | {rec['bake_ms']:.1f} | "
          f"{rec['prep_ms']:.1f} | {100 * rec['rrmse']:.2f}% | "
          f"{100 * rec['rrmse_corrected']:.2f}% | {100 * rec['mean_vs_reference']:+.2f}% | "
          f"{100 * rec['reference_noise']:.2f}% |")
