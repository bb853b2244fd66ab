"""NumPy twin of glsl/lib/shadow_march.glsl: the sun's optical depth marched from each point (the
probes' own sun; the light grid's twin is light_grid.py)."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.medium import box_intersect, sigma_t_at
from radiance_probes.io.volume import Volume


def sun_optical_depth_march(volume: Volume, table: np.ndarray, density_scale: float,
                            sun_direction, points: np.ndarray, march_step: float) -> np.ndarray:
    """Midpoint quadrature of sigma_t from each point (..., 3) to the box boundary towards the sun,
    at most 4096 steps; like the GLSL it stops adding once past 104. The direction is normalised
    here, as the scene's is before it reaches the shader."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    d = np.asarray(sun_direction, np.float64)
    d = d / np.linalg.norm(d)
    he = volume.half_extent.astype(np.float64)
    t0, t1, hit = box_intersect(he, pts, np.broadcast_to(d, pts.shape))
    tau = np.zeros(len(pts))
    for i in np.flatnonzero(hit):
        n = int(np.clip(np.ceil((t1[i] - t0[i]) / march_step), 1, 4096))
        dt = (t1[i] - t0[i]) / n
        ts = t0[i] + (np.arange(n) + 0.5) * dt
        sig = sigma_t_at(volume, table, density_scale, pts[i] + ts[:, None] * d) * dt
        before = np.concatenate([[0.0], np.cumsum(sig)[:-1]])
        tau[i] = sig[before < 104.0].sum()
    return tau.reshape(np.shape(points)[:-1])
