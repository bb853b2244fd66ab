"""Light grid resolution against the probe grid: raymarch rRMSE (16 frames, 512^2) and the light
grid's GPU time for bonsai/foot at 32^3, 64^3 and 128^3 probes x 64 walks with the light grid's box
side at 256 / 384 / 512 texels (the walks' sun from the grid), its texels 16- and 32-bit. Usage:
    python lab/experiments/experiment_light_grid_resolution.py OUT.json NAME=REFDIR [NAME=REFDIR ...]
where REFDIR holds an earlier bench run's refs/NAME.npy and results.json. The H100 runs are
bench/h100-light (per-texel march) and bench/h100-light-sheared (the sheared column march)."""
import json, statistics, sys
from dataclasses import replace
import numpy as np
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.rendering.metrics import rrmse, corrected_rrmse
from radiance_probes.io.load import load_volume

ctx = create_headless_context()
refs = dict(a.split("=", 1) for a in sys.argv[2:])
out = {"meta": {"device": describe(ctx), "command": " ".join(sys.argv)}, "records": []}
for name, refdir in refs.items():
    scene = bench_scene(name, 512, 512)
    ref = np.load(f"{refdir}/refs/{name}.npy")
    noise = json.load(open(f"{refdir}/results.json"))["references"][name]["noise_rrmse"]
    vol = load_volume(scene.volume, scene.base_dir)
    for grid in (32, 64, 128):
        probes = replace(scene.probes, grid=(grid,) * 3, samples=64)
        r = Renderer(ctx, scene.replace(probes=probes), vol)
        r.configure(light_follows_probes=False)
        for side, precision in ((s, p) for s in (256, 384, 512) for p in ("f2", "f4")):
            r.configure(light_min_side=side)
            r.configure(light_precision=precision)
            r._light_key = None
            r._baked_key = None
            res = r.render("raymarch", spp=16, seed=3, samples_per_pass=16)
            e = rrmse(res.image, ref)
            times = []
            for _ in range(3):
                r._light_key = None
                times.append(r.bake_light())
            rec = dict(scene=name, grid=grid, walks=64, min_side=side, precision=precision,
                       box_grid=list(r._light.box_grid), light_grid=list(r._light.grid),
                       rrmse=e, corrected=corrected_rrmse(e, noise), bake_ms=res.bake_ms,
                       light_ms=statistics.median(times))
            print(json.dumps(rec), flush=True)
            out["records"].append(rec)
        r.release()
json.dump(out, open(sys.argv[1], "w"), indent=1)
