"""Writes assets/scenes/sky.exr: a small procedural sky for the environment-map scene (SPEC.md's
equirectangular convention, app/twins/environment_map.py): a blue gradient above the horizon, a
dim ground below it and a small bright sun (a disc of 2.5 degrees radius at 35 degrees
elevation, towards +z and a little +x, so the default camera sees the cloud front-lit).

    python scripts/screenshots/make_sky.py [OUT.exr] [HEIGHT]      # default assets/scenes/sky.exr, 128
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from radiance_probes.frontend.imageio import save_exr  # noqa: E402
from radiance_probes.twins.environment_map import uv_to_direction  # noqa: E402

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "assets/scenes/sky.exr"
h = int(sys.argv[2]) if len(sys.argv) > 2 else 128
w = 2 * h
v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
d = uv_to_direction(u, v)
up = d[..., 1]
horizon = np.array([0.55, 0.6, 0.7])
zenith = np.array([0.12, 0.25, 0.6])
ground = np.array([0.08, 0.07, 0.06])
t = np.clip(up, 0.0, 1.0)[..., None] ** 0.5
sky = np.where(up[..., None] > 0, horizon * (1 - t) + zenith * t, ground * (0.5 + 0.5 * np.exp(up[..., None] * 8)))
el, az = np.radians(35.0), np.radians(20.0)
sun = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
cos_angle = d @ sun
radius = np.radians(2.5)
disc = cos_angle > np.cos(radius)
# Radiance of the disc: an irradiance of about 3 on a plane facing it (pi r^2 L = 3).
sky[disc] = np.array([1.0, 0.95, 0.85]) * 3.0 / (np.pi * radius ** 2)
glow = np.exp((cos_angle - 1.0) * 60.0)[..., None] * np.array([0.6, 0.5, 0.35])
save_exr(out, (sky + glow).astype(np.float16).astype(np.float32))
print(f"wrote {out} ({w} x {h}, sun towards {np.round(sun, 3).tolist()})")
