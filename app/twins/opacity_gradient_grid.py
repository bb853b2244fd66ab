"""NumPy twin of glsl/lib/opacity_gradient_grid.glsl (the raymarcher's one-fetch read of the
opacity-gradient grid) and of glsl/opacity_gradient_bake.comp (the grid's bake): grad A at every
voxel centre by hybrid_scattering.opacity_gradient, stored as half floats, read trilinearly."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.clip_region import ClipRegion
from radiance_probes.io.volume import Volume
from radiance_probes.twins.hybrid_scattering import opacity_gradient
from radiance_probes.twins.medium import classified_at, trilinear

HALF_MAX = 65504.0   # the largest half float: the bake clamps to it (opacity_gradient_bake.comp)


def voxel_centres(dims, half_extent) -> np.ndarray:
    """World positions (nz, ny, nx, 3) of the centres of a volume's voxels (x, y, z components),
    as the bake computes them: (2 (v + 0.5) / dims - 1) * half_extent."""
    he = np.asarray(half_extent, np.float64)
    axes = [(2.0 * (np.arange(n) + 0.5) / n - 1.0) * he[i] for i, n in enumerate(dims)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x, y, z], axis=-1)


def opacity_gradient_bake(volume: Volume, table, clip: ClipRegion | None = None) -> np.ndarray:
    """grad A (nz, ny, nx, 3) at every voxel centre: central differences of the classified
    opacity over one voxel per axis (the scene's surface_gradient_step), zero-opacity where the
    crop or clip plane cut the medium, clamped to the half float's range as stored."""
    step = 2.0 * np.asarray(volume.half_extent, np.float64) / np.asarray(volume.dims)
    grad = opacity_gradient(lambda p: classified_at(volume, table, p, clip)[..., 3],
                            voxel_centres(volume.dims, volume.half_extent), step)
    return np.clip(grad, -HALF_MAX, HALF_MAX)


def as_stored(grid: np.ndarray) -> np.ndarray:
    """The grid as the RGBA16F texture holds it (each component rounded to a half float)."""
    return np.asarray(grid).astype(np.float16).astype(np.float64)


def opacity_gradient_grid(grid: np.ndarray, half_extent, points) -> np.ndarray:
    """The grid (nz, ny, nx, 3) read at world points (..., 3) as the shader reads it: texture
    coordinates x / (2 half_extent) + 0.5, trilinear between texel centres, clamped to the edge."""
    he = np.asarray(half_extent, np.float64)
    dims = np.array(grid.shape[2::-1], np.float64)   # (nx, ny, nz)
    coord = (np.asarray(points, np.float64) / (2.0 * he) + 0.5) * dims - 0.5
    return np.stack([trilinear(grid[..., c], coord) for c in range(3)], axis=-1)
