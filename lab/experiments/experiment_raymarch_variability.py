"""Why does the raymarcher's GPU ms per sample at 1920x1080 vary between 1.4 and 2.8 ms in the
interact replay with 64^3 x 256 probes (steady 1.4 ms with 128^3 x 64)? Times the raymarcher alone
(8 samples, one per dispatch, three repeats) on bonsai over three sun directions and three camera
orbits for both probe settings, and prints the light grid each uses. Run on the GPU:
    python lab/experiments/experiment_raymarch_variability.py OUT.json
(committed: bench/h100-interact/raymarch_isolated.json)."""
import json
import sys
from dataclasses import replace
sys.path.insert(0, ".")
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.bench.interact import orbit, _rotate_y
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

ctx = create_headless_context()
print(describe(ctx))
base = bench_scene("bonsai", 1920, 1080)
vol = load_volume(base.volume, base.base_dir)
r = Renderer(ctx, base, vol)
rows = []
for grid, walks in ((64, 256), (128, 64)):
    for sun_deg in (0, 30, 60):
        for cam_deg in (0, 20, 40):
            s = orbit(base, cam_deg)
            light = replace(s.light, direction=_rotate_y(s.light.direction, sun_deg))
            s = s.replace(light=light, probes=replace(s.probes, grid=(grid,) * 3, samples=walks))
            r.set_scene(s)
            r.bake(seed=1)
            r.bake_light()
            per = []
            for rep in range(3):
                res = r.render("raymarch", spp=8, seed=rep, samples_per_pass=1)
                per.append(res.render_ms / 8)
            row = dict(grid=grid, walks=walks, sun=sun_deg, cam=cam_deg,
                       ms=[round(p, 3) for p in per], light=list(r._light.texture.size),
                       light_grid=list(r._light.grid) if hasattr(r._light, "grid") else None)
            rows.append(row)
            print(row, flush=True)
json.dump(rows, open(sys.argv[1], "w"), indent=1)
