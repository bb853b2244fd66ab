"""Where the probes go and what they store, chosen from the scene so cost follows it:

- the grid covers only the region the transfer function makes visible (where sigma_t can be > 0,
  trilinear interpolation and clamp-to-edge included), and a cubic grid request N becomes N probes
  along that region's longest side with the other axes in proportion (equal probe spacing);
- the SH order: with g = 0 the phase convolution multiplies bands 1 and 2 by g^l = 0, so order 0
  (one coefficient) gives exactly the same images as order 2 at a fraction of the memory and
  texture fetches; "auto" picks 0 for g = 0 and 2 otherwise;
- the colour channels: when the transfer function's colours and both lights are grey, r = g = b in
  every probe, and one channel is stored ("auto" channels), in 1 to 3 textures instead of 2 to 7.
"""
from __future__ import annotations

import numpy as np

# Probe textures (of the seven in lib/probes.glsl's packing) that each SH order needs: texture 6
# always, for the sun's transmittance in its alpha channel.
TEXTURES_FOR_ORDER = {0: (0, 6), 1: (0, 1, 2, 6), 2: (0, 1, 2, 3, 4, 5, 6)}


GREY_TEXTURES_FOR_ORDER = {0: (0,), 1: (0, 1), 2: (0, 1, 2)}


def texture_ids(order: int, grey: bool) -> tuple[int, ...]:
    return (GREY_TEXTURES_FOR_ORDER if grey else TEXTURES_FOR_ORDER)[order]


def scene_is_grey(table: np.ndarray, irradiance, environment) -> bool:
    """True when every transfer-function colour and both lights have r = g = b exactly, so that
    every path's radiance has equal channels."""
    rgb = np.asarray(table)[:, :3]
    grey = lambda v: np.all(np.asarray(v)[..., 0:1] == np.asarray(v)[..., :3])  # noqa: E731
    return bool(grey(rgb) and grey(irradiance) and grey(environment))


def resolve_channels(channels: str | int, table: np.ndarray, irradiance, environment) -> int:
    if channels == "auto":
        return 1 if scene_is_grey(table, irradiance, environment) else 3
    return int(channels)


def resolve_sh_order(order: str | int, anisotropy: float) -> int:
    if order == "auto":
        return 0 if anisotropy == 0.0 else 2
    return int(order)


def _positive_interval_test(table_alpha: np.ndarray):
    """f(lo, hi) -> bool array: does the piecewise-linear opacity exceed 0 anywhere in [lo, hi]?"""
    alpha = np.asarray(table_alpha, np.float64)
    n = len(alpha)
    positive = alpha > 0
    before = np.concatenate([[0], np.cumsum(positive)])  # positive nodes with index < k

    def test(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        a_lo = np.interp(lo, np.linspace(0, 1, n), alpha)
        a_hi = np.interp(hi, np.linspace(0, 1, n), alpha)
        first = np.clip(np.ceil(lo * (n - 1)), 0, n).astype(np.int64)
        last = np.clip(np.floor(hi * (n - 1)), -1, n - 1).astype(np.int64)
        inside = before[last + 1] - before[np.minimum(first, last + 1)] > 0
        return (a_lo > 0) | (a_hi > 0) | inside
    return test


def visible_region(data: np.ndarray, half_extent, table_alpha: np.ndarray,
                   density_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """World-space (low, high) corners of the smallest box outside which sigma_t is 0 everywhere.
    The whole volume box when nothing is visible (then no light scatters anywhere)."""
    half = np.asarray(half_extent, np.float64)
    if density_scale <= 0:
        return -half, half
    # Pad with the edge voxels: between the box face and the outermost voxel centre the density is
    # clamped to that voxel's, so the padded neighbour pair covers that slab.
    d = np.pad(np.asarray(data, np.float32), 1, mode="edge")
    lo = hi = None
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                s = d[dz:d.shape[0] - 1 + dz, dy:d.shape[1] - 1 + dy, dx:d.shape[2] - 1 + dx]
                lo = s if lo is None else np.minimum(lo, s)
                hi = s if hi is None else np.maximum(hi, s)
    visible = _positive_interval_test(table_alpha)(lo, hi)   # cells [z, y, x], (n + 1) per axis
    if not visible.any():
        return -half, half
    low, high = np.empty(3), np.empty(3)
    for axis, reduce_axes in ((0, (0, 1)), (1, (0, 2)), (2, (1, 2))):  # x, y, z
        used = np.flatnonzero(visible.any(axis=reduce_axes))
        n = d.shape[2 - axis] - 2          # voxels along this axis
        # padded index k sits at the box face (k = 0, n + 1) or at voxel centre k - 1
        pos = np.concatenate([[-half[axis]],
                              ((np.arange(n) + 0.5) / n * 2.0 - 1.0) * half[axis], [half[axis]]])
        low[axis], high[axis] = pos[used[0]], pos[used[-1] + 1]
    return low, high


def fitted_grid(grid: tuple[int, int, int], low: np.ndarray, high: np.ndarray) -> tuple[int, int, int]:
    """A cubic request N becomes N probes along the region's longest side and proportionally fewer
    (at least 1) along the others; an explicit non-cubic grid is kept as given."""
    if not (grid[0] == grid[1] == grid[2]):
        return tuple(grid)
    extent = np.maximum(np.asarray(high) - np.asarray(low), 0.0)
    longest = extent.max()
    if longest <= 0:
        return tuple(grid)
    return tuple(int(max(1, round(grid[0] * e / longest))) for e in extent)
