"""NumPy twin of glsl/lib/medium.glsl: density sampling, sigma_t, albedo, the volume box, and the
crop and clip plane of lib/clip_region.glsl (`clip`: an app.clip_region.ClipRegion, None: all kept).

`table` is a one-channel volume's RGBA table, or for a volume of several channels an
app.channels.ChannelTables: the medium is then the channels' mixture (mixed_transfer_at)."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.channels import ChannelTables
from radiance_probes.scene.clip_region import ClipRegion
from radiance_probes.scene.transfer import lookup
from radiance_probes.io.volume import Volume


def density_at(volume: Volume, points: np.ndarray, clip: ClipRegion | None = None) -> np.ndarray:
    """Trilinear, cell-centred, clamped-to-edge density at world points (..., 3), as GL does;
    with a crop, read at the point clamped inside the kept voxels' centres (kept_sample_point).
    Several channels: (..., C), one density a channel (densities_at)."""
    he = volume.half_extent.astype(np.float64)
    points = np.asarray(points, np.float64) if clip is None else clip.sample_points(points)
    uvw = points / (2.0 * he) + 0.5
    coord = uvw * np.array(volume.dims, np.float64) - 0.5
    if volume.data.ndim == 3:
        return trilinear(volume.data, coord)
    return np.stack([trilinear(volume.channel(c), coord) for c in range(volume.channel_count)],
                    axis=-1)


def mixed_transfer_at(tables: ChannelTables, densities: np.ndarray) -> np.ndarray:
    """The channels' mixture at densities (..., C): RGBA with alpha the sum of the channels'
    opacities (those switched on) and colour their opacity-weighted mean, 0 where no channel has
    opacity (lib/medium.glsl mixed_transfer_at)."""
    a = np.zeros(densities.shape[:-1], np.float64)
    weighted = np.zeros(densities.shape[:-1] + (3,), np.float64)
    for c, (table, on) in enumerate(zip(tables.tables, tables.on)):
        tf = lookup(table, densities[..., c])
        a_c = tf[..., 3] if on else np.zeros_like(a)
        a = a + a_c
        weighted = weighted + a_c[..., None] * tf[..., :3]
    with np.errstate(invalid="ignore", divide="ignore"):
        rgb = np.where(a[..., None] > 0, weighted / np.where(a > 0, a, 1.0)[..., None], 0.0)
    return np.concatenate([rgb, a[..., None]], axis=-1)


def transfer_at(table, densities: np.ndarray) -> np.ndarray:
    """The medium's RGBA at densities: the one table's lookup, or the channels' mixture."""
    if isinstance(table, ChannelTables):
        return mixed_transfer_at(table, densities)
    return lookup(table, densities)


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


def classified_at(volume: Volume, table: np.ndarray, points: np.ndarray,
                  clip: ClipRegion | None = None) -> np.ndarray:
    """The transfer function's RGBA at world points (..., 4), zero where the crop or clip plane
    cut the medium away."""
    rgba = transfer_at(table, density_at(volume, points, clip))
    if clip is not None:
        rgba = np.where(clip.kept(points)[..., None], rgba, 0.0)
    return rgba


def sigma_t_at(volume: Volume, table: np.ndarray, density_scale: float, points: np.ndarray,
               clip: ClipRegion | None = None) -> np.ndarray:
    return density_scale * classified_at(volume, table, points, clip)[..., 3]


def albedo_at(volume: Volume, table: np.ndarray, albedo: float, points: np.ndarray,
              clip: ClipRegion | None = None) -> np.ndarray:
    return albedo * transfer_at(table, density_at(volume, points, clip))[..., :3]


def box_intersect(half_extent: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                  clip: ClipRegion | None = None):
    """(t_near, t_far, hit) for rays against the box (the kept box with a crop or clip plane),
    t_near clamped at 0, as in GLSL."""
    d = np.where(direction == 0.0, 1e-30, direction)
    inv = 1.0 / d
    lo, hi = -np.asarray(half_extent, np.float64), np.asarray(half_extent, np.float64)
    if clip is not None:
        lo, hi = np.asarray(clip.box_min, np.float64), np.asarray(clip.box_max, np.float64)
    ta = (lo - origin) * inv
    tb = (hi - origin) * inv
    t_near = np.maximum(np.max(np.minimum(ta, tb), axis=-1), 0.0)
    t_far = np.min(np.maximum(ta, tb), axis=-1)
    return t_near, t_far, t_far > t_near


def majorant(table, density_scale: float) -> float:
    """A bound on sigma_t over the whole box: the largest opacity in the table (it is linear
    between entries); of several channels, the sum of those switched on."""
    if isinstance(table, ChannelTables):
        return float(density_scale * sum(float(t[:, 3].max()) for t, on in
                                         zip(table.tables, table.on) if on))
    return float(density_scale * table[:, 3].max())
