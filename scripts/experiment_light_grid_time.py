"""The light grid's bake time with and without jumping over empty macrocells, per side, and the
largest difference between the two grids (they must agree). Usage:
    python scripts/experiment_light_grid_time.py OUT.json [scene ...]"""
import json, statistics, sys
import numpy as np
from app.gl.context import create_headless_context, describe
from app.render.renderer import Renderer
from app.bench.scenes import bench_scene
from app.volume import load_volume

ctx = create_headless_context()
names = sys.argv[2:] or ["bonsai", "foot", "fuel", "hydrogen"]
out = {"meta": {"device": describe(ctx), "command": " ".join(sys.argv)}, "records": []}
for name in names:
    scene = bench_scene(name, 64, 64)
    if scene is None:
        continue
    r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
    r.light_follows_probes = False
    for side in (128, 256, 384, 512):
        r.light_min_side = side
        grids, times = {}, {}
        for skipping in (True, False):
            r.set_empty_space_skipping(skipping)
            ms = []
            for _ in range(4):
                r._light_key = None
                ms.append(r.bake_light())
            times[skipping] = statistics.median(ms[1:])
            tex = r._light.texture
            grids[skipping] = np.frombuffer(tex.read(), np.float32)
        rec = {"scene": name, "light_grid": list(r._light.texture.size),
               "ms_skipping": times[True], "ms_plain": times[False],
               "max_abs_diff": float(np.abs(grids[True] - grids[False]).max()),
               "max_tau": float(grids[False].max())}
        print(json.dumps(rec), flush=True)
        out["records"].append(rec)
    r.release()
json.dump(out, open(sys.argv[1], "w"), indent=1)
