"""How far can the smallest bakes fall? At the settings that decide the 5% targets (8^3 probes) a
bake has a few thousand walks, too few to fill the GPU, so it waits for its longest walk. This
measures, per scene and setting: the bake's sections (light grid, walks, projection) and the
raymarched frame (step 2, one frame) as GPU timestamps; the profiling build's longest walk (its
scattering events and tracking steps); and that walk's latency floor: as many invocations as the
bake has walks, each a chain of as many dependent trilinear sigma_t fetches as the longest walk
took tracking steps (glsl/ceiling_march.comp DEPENDENT_CHAIN), which no exact walk of that length
can beat. Run on the GPU:
    python lab/experiments/experiment_walk_floor.py OUT_DIR [--scenes thick,grey,hydrogen]
        [--settings 8x16,8x4,16x16]
(committed: bench/h100-walk-floor/walk_floor.json)."""
import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, ".")
from radiance_probes.bench.bake import _profile
from radiance_probes.rendering.budgets.ceiling import measure_ceiling
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="thick,grey,hydrogen")
parser.add_argument("--settings", default="8x16,8x4,16x16")
parser.add_argument("--repeats", type=int, default=5)
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
rows = []


def warm_up(renderer, seconds: float = 1.5) -> None:
    """Keeps the GPU busy for a while before a setting is timed: these bakes and frames last
    well under a millisecond, too short to raise an idle GPU's clock by themselves (a first run
    without this measured the later scenes' frames up to 3x slower than the benchmark's)."""
    start = time.time()
    while time.time() - start < seconds:
        measure_ceiling(renderer, rays=1 << 20, steps=256, repeats=1)


for name in args.scenes.split(","):
    base = bench_scene(name, 512, 512)
    if base is None:
        continue
    r = Renderer(ctx, base, load_volume(base.volume, base.base_dir))
    r.configure(raymarch_step=2.0)
    for setting in args.settings.split(","):
        grid, walks = (int(v) for v in setting.split("x"))
        r.set_scene(base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks)))
        warm_up(r)
        r.bake(seed=11)
        light_ms = r.light_grid_ms()
        profiles = [_profile(r, 11) for _ in range(args.repeats)]
        prof = {k: statistics.median(p[k] for p in profiles) for k in profiles[0]}
        frame_ms = statistics.median(r.render("raymarch", spp=1, seed=3).render_ms
                                     for _ in range(args.repeats))
        n, steps = int(prof["counted_walks"]), int(prof["longest_walk_steps"])
        floor = measure_ceiling(r, rays=n, steps=steps, repeats=args.repeats, chain=True)
        per_step = measure_ceiling(r, rays=n, steps=256, repeats=args.repeats, chain=True)
        row = dict(scene=name, grid=grid, walks=walks, device=device, light_ms=light_ms,
                   bake_walk_ms=prof["bake_walk_ms"], bake_project_ms=prof["bake_project_ms"],
                   bake_sun_ms=prof["bake_sun_ms"], bake_other_ms=prof["bake_other_ms"],
                   frame_ms=frame_ms, counted_walks=n, events_per_walk=prof["events_per_walk"],
                   steps_per_walk=prof["steps_per_walk"],
                   longest_walk_events=int(prof["longest_walk_events"]),
                   longest_walk_steps=steps, chain_floor_ms=floor["ms"],
                   chain_us_per_step=1e3 * per_step["ms"] / 256,
                   walk_us_per_longest_step=1e3 * prof["bake_walk_ms"] / max(steps, 1))
        row["floor_total_ms"] = (light_ms + row["chain_floor_ms"] + row["bake_project_ms"]
                                 + row["bake_sun_ms"] + frame_ms)
        rows.append(row)
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()
               if k != "device"}, flush=True)
    r.release()
(out / "walk_floor.json").write_text(json.dumps(rows, indent=1))
