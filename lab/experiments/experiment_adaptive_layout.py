"""Adaptive probe layout against the uniform one at the same probe count, on llvmpipe: a thin
dense slab (sigma_t 40 in 2 of 16 voxels along y, 4 elsewhere) lit by the sun, 32 x 32 pixels,
a 2 x 8192 spp path-traced reference; relative RMSE of `probes` (256 frames) and `raymarch`
(4 frames) per grid, layout, indicator and strength. Usage (from the repository root):
    PYTHONPATH=. python lab/experiments/experiment_adaptive_layout.py [OUT.json]
The README's table (Radiance probes, adaptive probe density) is this script's output."""
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

ctx = create_headless_context()
folder = Path(tempfile.mkdtemp())
d = np.full((16, 16, 16), 0.1, np.float32)
d[:, 7:9, :] = 1.0          # the slab across y (z, y, x)
np.save(folder / "slab.npy", d)
base = {"volume": {"path": str(folder / "slab.npy")}, "density_scale": 40.0,
        "transfer_function": {"rgba": [[1, 1, 1, 0], [1, 1, 1, 1]]}, "albedo": 0.9,
        "max_bounces": 16, "environment": [0.05, 0.05, 0.05],
        "light": {"direction": [0.3, 1.0, 0.2], "irradiance": [3, 3, 3]},
        "camera": {"eye": [1.3, 0.1, 0.9], "target": [0, 0, 0], "fov_y": 45.0,
                   "width": 32, "height": 32},
        "probes": {"grid": 4, "samples": 256, "fit": "box"}}
r = Renderer(ctx, parse_scene(base))
halves = [r.render("pt", spp=8192, samples_per_pass=512, seed=s).image for s in (0, 1)]
ref = 0.5 * (halves[0] + halves[1])
noise = float(np.sqrt(np.mean((halves[0] - halves[1]) ** 2) / np.mean(ref ** 2)) / 2)
print(f"reference noise (relative RMSE) {noise:.4f}")


def rrmse(x):
    return float(np.sqrt(np.mean((x - ref) ** 2) / np.mean(ref ** 2)))


rows = []
for grid in (4, 6, 8):
    for layout, indicator, strength in (("uniform", None, None), ("adaptive", "extinction", 0.5),
                                        ("adaptive", "extinction", 0.8), ("adaptive", "sun", 0.5),
                                        ("adaptive", "sun", 0.8)):
        probes = {**base["probes"], "grid": grid, "layout": layout}
        if indicator:
            probes.update(adaptive_indicator=indicator, adaptive_strength=strength)
        r.set_scene(parse_scene({**base, "probes": probes}))
        start = time.time()
        row = {"grid": grid, "layout": layout, "indicator": indicator, "strength": strength,
               "probes": rrmse(r.render("probes", spp=256, samples_per_pass=64).image),
               "raymarch": rrmse(r.render("raymarch", spp=4).image)}
        planes = r.probe_grid.planes
        row["y_planes"] = None if planes is None else [round(v, 3) for v in planes[1]]
        rows.append(row)
        print(grid, layout, indicator or "", strength or "", f"probes {row['probes']:.4f}",
              f"raymarch {row['raymarch']:.4f}", row["y_planes"], f"{time.time() - start:.1f} s")
if len(sys.argv) > 1:
    Path(sys.argv[1]).write_text(json.dumps({"reference_noise": noise, "rows": rows}, indent=1))
