"""NumPy twin of glsl/lib/medium.glsl: density sampling, sigma_t, albedo, the volume box."""
from __future__ import annotations

import numpy as np

from ..transfer import lookup
from ..volume import Volume


def density_at(volume: Volume, points: np.ndarray) -> np.ndarray:
    """Trilinear, cell-centred, clamped-to-edge density at world points (..., 3), as GL does."""
    he = volume.half_extent.astype(np.float64)
    uvw = np.asarray(points, np.float64) / (2.0 * he) + 0.5
    return trilinear(volume.data, uvw * np.array(volume.dims, np.float64) - 0.5)


def trilinear(data: np.ndarray, coord: np.ndarray) -> np.ndarray:
    """GL's linear filtering of a 3D texture `data` (z, y, x) at texel coordinates (..., 3) (x, y,
    z; texel centres at integers), clamped to the edge."""
    base = np.floor(coord)
    f = coord - base
    out = np.zeros(coord.shape[:-1], np.float64)
    nz, ny, nx = data.shape
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                ix = np.clip(base[..., 0].astype(np.int64) + dx, 0, nx - 1)
                iy = np.clip(base[..., 1].astype(np.int64) + dy, 0, ny - 1)
                iz = np.clip(base[..., 2].astype(np.int64) + dz, 0, nz - 1)
                w = ((f[..., 0] if dx else 1 - f[..., 0]) * (f[..., 1] if dy else 1 - f[..., 1])
                     * (f[..., 2] if dz else 1 - f[..., 2]))
                out += w * data[iz, iy, ix]
    return out


def sigma_t_at(volume: Volume, table: np.ndarray, density_scale: float, points: np.ndarray) -> np.ndarray:
    return density_scale * lookup(table, density_at(volume, points))[..., 3]


def albedo_at(volume: Volume, table: np.ndarray, albedo: float, points: np.ndarray) -> np.ndarray:
    return albedo * lookup(table, density_at(volume, points))[..., :3]


def box_intersect(half_extent: np.ndarray, origin: np.ndarray, direction: np.ndarray):
    """(t_near, t_far, hit) for rays against the box, t_near clamped at 0, as in GLSL."""
    d = np.where(direction == 0.0, 1e-30, direction)
    inv = 1.0 / d
    ta = (-half_extent - origin) * inv
    tb = (half_extent - origin) * inv
    t_near = np.maximum(np.max(np.minimum(ta, tb), axis=-1), 0.0)
    t_far = np.min(np.maximum(ta, tb), axis=-1)
    return t_near, t_far, t_far > t_near


def majorant(table: np.ndarray, density_scale: float) -> float:
    """A bound on sigma_t over the whole box: the largest opacity in the table (it is linear between entries)."""
    return float(density_scale * table[:, 3].max())
