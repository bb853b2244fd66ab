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

from ..twins.visible_region import visible_region  # noqa: F401  (the NumPy twin; the renderer's is on the GPU)

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
