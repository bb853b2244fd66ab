"""Light grid resolution beyond the volume's: raymarch rRMSE for bonsai/foot at 64^3 x 512 and
128^3 x 256 with MIN_SIDE 256 / 512 (and MAX_SIDE raised to 512). Usage: python scripts/experiment_light_grid_resolution.py OUT.json [NAME=REFDIR ...]
(the H100 run is bench/h100-light/results.json)."""
import json, sys
from dataclasses import replace
import numpy as np
from app.gl.context import create_headless_context
from app.render.renderer import Renderer
from app.bench.scenes import bench_scene
from app.bench.metrics import rrmse, corrected_rrmse
from app.volume import load_volume
import app.render.light_transmittance as lt

lt.TEXELS_PER_PROBE = 0   # the side is set through MIN_SIDE below, whatever the probe grid

ctx = create_headless_context()
# NAME=DIR pairs: DIR holds an earlier bench run's refs/NAME.npy and results.json
refs = dict(a.split("=", 1) for a in sys.argv[2:]) or {"bonsai": ".refs/before", "foot": ".refs/foot"}
out = []
for name, refdir in refs.items():
    scene = bench_scene(name, 512, 512)
    ref = np.load(f"{refdir}/refs/{name}.npy")
    noise = json.load(open(f"{refdir}/results.json"))["references"][name]["noise_rrmse"]
    vol = load_volume(scene.volume, scene.base_dir)
    for grid, walks in ((64, 512), (128, 256)):
        probes = replace(scene.probes, grid=(grid,) * 3, samples=walks)
        r = Renderer(ctx, scene.replace(probes=probes), vol)
        for min_side in (256, 384, 512):
            for sun in ("grid", "ray"):
                lt.MIN_SIDE = min_side
                r._light_key = None
                r._baked_key = None
                r.walk_sun = sun
                res = r.render("raymarch", spp=16, seed=3, samples_per_pass=16)
                e = rrmse(res.image, ref)
                rec = dict(scene=name, grid=grid, walks=walks, min_side=min_side, sun=sun,
                           light_grid=list(r._light.texture.size), rrmse=e,
                           corrected=corrected_rrmse(e, noise), bake_ms=res.bake_ms)
                print(json.dumps(rec), flush=True)
                out.append(rec)
        # light grid time alone at each size
        for min_side in (256, 384, 512):
            lt.MIN_SIDE = min_side
            times = []
            for _ in range(3):
                r._light_key = None
                times.append(r.bake_light())
            print(json.dumps(dict(scene=name, min_side=min_side, light_ms=sorted(times)[1])), flush=True)
        r.release()
json.dump(out, open(sys.argv[1], "w"), indent=1)
