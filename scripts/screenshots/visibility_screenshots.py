"""The leak that visibility-weighted probe interpolation removes, in pictures: a thin medium split
by an opaque wall (two voxels of 24, between two probe planes of a 4^3 grid), the sun low from +x;
the path tracer, then `probes-only` (the sun's transmittance read from the probes) and the
raymarcher with trilinear and with visibility-weighted interpolation, each with its rRMSE.
Runs on llvmpipe in about a minute:
    python scripts/screenshots/visibility_screenshots.py screenshots    (writes visibility_leak.png)"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, ".")
sys.path.insert(0, str(Path(__file__).parent))
from panel_sheet import ldr, panel_sheet
from radiance_probes.rendering.metrics import rrmse
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.io.volume import Volume

SIZE, PANEL = 128, 256
out = Path(sys.argv[1] if len(sys.argv) > 1 else "screenshots")
out.mkdir(parents=True, exist_ok=True)
n = 24
density = np.full((n, n, n), 0.01, np.float32)
density[:, :, 11:13] = 1.0           # the wall, x in [-1/24, 1/24]; probe planes at x = -1/8, 1/8
volume = Volume(density, (1.0, 1.0, 1.0), "wall", (0.0, 1.0), "float32", 0.0, 1.0)
scene = {"volume": {"builtin": "constant", "size": [n, n, n]},
         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}, "density_scale": 200.0,
         "albedo": 0.9, "environment": [0.05, 0.05, 0.05],
         "light": {"direction": [0.9, 0.3, 0.3], "irradiance": [3, 3, 3]},
         "camera": {"eye": [0.0, 0.8, 1.8], "target": [0, 0, 0], "fov_y": 38.0,
                    "width": SIZE, "height": SIZE}}
ctx = create_headless_context()
r = Renderer(ctx, parse_scene(scene), volume)
reference = r.render("pt", spp=1024, seed=1, samples_per_pass=64).image
panels = [(ldr(reference, PANEL), "path tracer", "1024 spp")]
for method, spp in (("probes-only", 256), ("raymarch", 4)):
    for interpolation in ("trilinear", "visibility"):
        r.set_scene(parse_scene({**scene, "probes": {"grid": 4, "samples": 256, "fit": "box",
                                                     "interpolation": interpolation}}), volume)
        image = r.render(method, spp=spp, seed=2, samples_per_pass=spp).image
        panels.append((ldr(image, PANEL), f"{method}, {interpolation}",
                       f"rRMSE {100 * rrmse(image, reference):.1f}%"))
r.release()
sheet = panel_sheet(panels, PANEL, 5, "thin medium split by an opaque wall, sun from +x, 4^3 probes: "
                    "python scripts/screenshots/visibility_screenshots.py screenshots")
sheet.save(out / "visibility_leak.png")
print("wrote", out / "visibility_leak.png")
