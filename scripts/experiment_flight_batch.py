"""Tentative collisions tracked FLIGHT_BATCH at a time (lib/tracking.glsl) against one at a time:
the bake's walks and the path tracer's sample, GPU time, and whether the results are the same
(bench/h100-flight-batch). Usage: python scripts/experiment_flight_batch.py OUT.json SCENE[,SCENE...]
[BATCHES, default 1,2,4,8]"""
import sys, json, statistics
from dataclasses import replace
import numpy as np
sys.path.insert(0, ".")
import app.render.probes as probes_module
import app.render.pathtracer as pathtracer_module
from app.bench.scenes import bench_scene
from app.bench.records import progressive
from app.gl.context import create_headless_context, describe
from app.gl.profiler import GpuProfile
from app.render.renderer import Renderer
from app.volume import load_volume

ctx = create_headless_context(); dev = describe(ctx); print(dev, flush=True)
batches = [int(b) for b in (sys.argv[3] if len(sys.argv) > 3 else "1,2,4,8").split(",")]
SETTINGS = ((8, 16), (16, 16), (32, 64), (64, 64), (128, 64))
rows = []
med = statistics.median
for name in sys.argv[2].split(","):
    base = bench_scene(name, 512, 512)
    volume = load_volume(base.volume, base.base_dir)
    serial = {}
    for batch in batches:
        probes_module.WALK_FLIGHT_BATCH = batch
        pathtracer_module.PATH_FLIGHT_BATCH = batch
        r = Renderer(ctx, base, volume)
        for grid, walks in SETTINGS:
            s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks))
            r.set_scene(s); r.invalidate(); r.bake(seed=1)
            bakes, secs = [], []
            for rep in range(5):
                r.invalidate(); bakes.append(r.bake(seed=3))
            for rep in range(3):
                r.invalidate(); r.bake_light(); r._baked_key = None
                p = GpuProfile(); r.bake(seed=3, profile=p); secs.append(p.totals_ms()); p.release()
            coeffs = r.probe_grid.coefficients()
            key = (grid, walks)
            if batch == batches[0]:
                serial[key] = coeffs
            diff = float(np.abs(coeffs - serial[key]).max() / max(np.abs(serial[key]).max(), 1e-30))
            row = dict(scene=name, batch=batch, grid=grid, walks=walks, bake_ms=med(bakes),
                       sections={k: med([x[k] for x in secs if k in x]) for k in secs[0]},
                       max_rel_diff_vs_first=diff)
            print(json.dumps(row), flush=True); rows.append(row)
        r.set_scene(base)
        out = list(progressive(r, "pt", [16, 64], 17, 16))
        img = out[0][1]
        if batch == batches[0]:
            serial["pt"] = img
        diff = float(np.abs(img - serial["pt"]).max() / max(np.abs(serial["pt"]).max(), 1e-30))
        row = dict(scene=name, batch=batch, method="pt", ms_per_spp=out[1][2],
                   max_rel_diff_vs_first=diff)
        print(json.dumps(row), flush=True); rows.append(row)
        r.release()
json.dump(dict(device=dev, rows=rows), open(sys.argv[1], "w"), indent=1)
