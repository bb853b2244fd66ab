"""Visibility-weighted probe interpolation on synthetic scenes with known geometry, on llvmpipe: a
thin medium (sigma_t 2) with an opaque block (a third of the box along x, full height), a wall (two
voxels of 24, across x) or a dense cube in the middle (sigma_t 200), under a few suns, albedo 0.9 and
0.99, 4^3 and 8^3 probes over the box; rRMSE (%) of `raymarch` (ra) and `probes-only` (pr) with
trilinear (tri) and visibility-weighted (vis) interpolation against a 1024-spp path trace, 40 x 40.
    python lab/experiments/experiment_visibility_scenes.py    (bench/llvmpipe-visibility/scenes.txt, ~4 min)"""
import sys

import numpy as np

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import rrmse
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.io.volume import Volume

ctx = create_headless_context()
n = 24


def vol(kind):
    d = np.full((n, n, n), 0.01, np.float32)
    if kind == "block":
        d[:, :, :8] = 1.0
    if kind == "wall":
        d[:, :, 11:13] = 1.0
    if kind == "cube":
        d[6:18, 6:18, 6:18] = 1.0
    return Volume(d, (1.0, 1.0, 1.0), kind, (0.0, 1.0), "float32", 0.0, 1.0)


cases = [("block", [0, 1, 0]), ("block", [0.6, 0.7, 0.4]), ("wall", [0.9, 0.3, 0.3]),
         ("cube", [0.5, 0.8, 0.3]), ("cube", [-0.3, 0.5, 0.8])]
for kind, sun in cases:
    for albedo in (0.9, 0.99):
        base = {"volume": {"builtin": "constant", "size": [n, n, n]},
                "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                "density_scale": 200.0, "albedo": albedo, "environment": [0.05, 0.05, 0.05],
                "light": {"direction": sun, "irradiance": [3, 3, 3]},
                "camera": {"eye": [0.6, 0.7, 1.7], "target": [0, 0, 0], "fov_y": 38.0,
                           "width": 40, "height": 40}}
        v = vol(kind)
        r = Renderer(ctx, parse_scene(base), v)
        ref = r.render("pt", spp=1024, seed=1, samples_per_pass=128).image
        for grid in (4, 8):
            line = f"{kind:5s} sun {sun} a {albedo} grid {grid}:"
            for method, spp in (("raymarch", 2), ("probes-only", 128)):
                for name, interp in (("tri", "trilinear"), ("vis", "visibility")):
                    probes = {"grid": grid, "samples": 128, "fit": "box", "interpolation": interp}
                    r.set_scene(parse_scene({**base, "probes": probes}), v)
                    img = r.render(method, spp=spp, seed=2, samples_per_pass=spp).image
                    line += f" {method[:2]}-{name} {100*rrmse(img, ref):5.1f}"
            print(line, flush=True)
        r.release()
