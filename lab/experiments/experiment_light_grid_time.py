"""The light grid's bake time per side: the sheared column march (light_transmittance.comp) for
the scene's sun and for a sun 45 degrees off two axes (the widest sheared grid), next to the
per-texel march it replaced (bench/h100-light-time, where that run measured the same box grid),
for 16- and 32-bit texels.
Usage:
    python lab/experiments/experiment_light_grid_time.py OUT.json [scene ...]"""
import dataclasses, json, statistics, sys
from pathlib import Path
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.io.load import load_volume

BEFORE = Path(__file__).resolve().parents[2] / "bench/h100-light-time/results.json"
before = {}
if BEFORE.is_file():
    for rec in json.load(open(BEFORE))["records"]:
        before.setdefault((rec["scene"], tuple(rec["light_grid"])), rec["ms_skipping"])

ctx = create_headless_context()
names = sys.argv[2:] or ["bonsai", "foot", "fuel", "hydrogen"]
out = {"meta": {"device": describe(ctx), "command": " ".join(sys.argv)}, "records": []}
for name in names:
    scene = bench_scene(name, 64, 64)
    if scene is None:
        continue
    r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
    r.configure(light_follows_probes=False)
    for sun in ("scene", "oblique"):
        if sun == "oblique":
            r.set_scene(scene.replace(light=dataclasses.replace(scene.light, direction=(0.5, 0.70710678, 0.5))))
        for side, precision in ((s, p) for s in (128, 256, 384, 512) for p in ("f2", "f4")):
            r.configure(light_min_side=side)
            r.configure(light_precision=precision)
            ms = []
            for _ in range(4):
                r._light_key = None
                ms.append(r.bake_light())
            light = r._light
            rec = {"scene": name, "sun": sun, "precision": precision,
                   "sun_direction": list(r.scene.light.direction),
                   "box_grid": list(light.box_grid), "light_grid": list(light.grid),
                   "ms": statistics.median(ms[1:]),
                   "ms_per_texel_march": before.get((name, tuple(light.box_grid))) if sun == "scene" else None}
            print(json.dumps(rec), flush=True)
            out["records"].append(rec)
    r.release()
json.dump(out, open(sys.argv[1], "w"), indent=1)
