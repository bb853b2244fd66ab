"""Where the probes go and what they store, chosen from the scene so cost follows it:

- the grid covers only the region the transfer function makes visible (where sigma_t can be > 0,
  trilinear interpolation and clamp-to-edge included), and a cubic grid request N becomes N probes
  along that region's longest side with the other axes in proportion (equal probe spacing);
- the SH order: with g = 0 the phase convolution multiplies bands l >= 1 by g^l = 0, so order 0
  (one coefficient) gives exactly the same images as any higher order at a fraction of the memory
  and texture fetches; "auto" picks 0 for g = 0, else the highest order (at most AUTO_MAX_ORDER)
  whose band still carries |g|^l >= AUTO_BAND_WEIGHT of the phase function, and at least 2; bands
  above 2 only with at least AUTO_WALKS_PER_HIGH_BAND walks per probe;
- the colour channels: when the transfer function's colours and both lights are grey, r = g = b in
  every probe, and one channel is stored ("auto" channels), in 1 to 7 textures instead of 2 to 19.

The packing itself (which texture and channel holds what) is lib/probe_packing.glsl's; the
functions here are its NumPy twin.
"""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.types import SH_ORDERS
from radiance_probes.twins.sh import sh_count
from radiance_probes.twins.visible_region import (visible_region)  # noqa: F401  (the NumPy twin; the renderer's is on the GPU)

SUN_CHANNEL = 27            # the colour packing's channel of the sun's transmittance
# "auto" keeps band l while |g|^l >= this: the phase convolution scales band l by g^l, so a band
# below it adds at most this fraction of its radiance's band to any pixel (|g| >= 0.59: order 3;
# 0.5: order 2).
AUTO_BAND_WEIGHT = 0.2
# ... and no more than order 3: on the bench's g = 0.8 cloud (bench/h100, "SH orders at the same
# probe setting") order 4 lowered no error below order 3's, was worse with few walks (its two
# more bands carry more of the walks' noise) and cost 1.5x order 3's raymarched frame.
AUTO_MAX_ORDER = 3
# ... and bands above 2 only for probes of at least this many walks: each added band holds more of
# the walks' noise, and on that cloud order 3 lowered the error from 128 walks per probe on
# (64^3 x 512: 4.57 -> 3.67%; 128^3 x 256: 4.07 -> 3.49%) but raised it with 16 or 64
# (64^3 x 64: 5.99 -> 6.28%; 128^3 x 64: 4.76 -> 5.08%).
AUTO_WALKS_PER_HIGH_BAND = 128
# Probes of order 3 also hold a lobe about the sun's direction (lib/sun_lobe.glsl) of
# Henyey-Greenstein g h = g^SUN_LOBE_POWER, where h >= SUN_LOBE_MIN_G (g > 0: forward scattering).
# Measured on the H100 (bench/h100-sun-lobe; raymarched, corrected rRMSE): on the bench's g = 0.8
# backlit cloud, powers 1, 2, 3, 4, 6 and 10 at 128^3 x 256 gave 3.43, 3.07, 2.76, 2.76, 2.97 and
# 3.17% against 3.49% without; at power 3 on variants of it (g = 0.9 and 0.7, side-, front- and
# top-lit, albedo 0.8) every probe setting of 64^3 or more gained (front-lit 128^3 x 256: 5.04 ->
# 3.32%, g = 0.9: 11.4 -> 9.6%), g = 0.6 (h = 0.22) changed nothing, and 32^3 x 256 lost up to 1.4
# points backlit (the lobe's amplitude changes faster near the rim than 32^3 probes resolve) and
# gained up to 1.5 points front- or side-lit. The lobe costs no memory (the last texture's spare
# channels), about 2% of the bake and 3% of a raymarched frame. Those powers were measured with the
# amplitude fitted to the radiance; fitted for the phase function (lib/sun_lobe.glsl, today's),
# power 3 stays: backlit 2.73% (2 gives 2.94, 4 2.78), front-lit 2.84% (2.59, 3.03), g = 0.9
# 8.34% (9.10, 7.45) at 128^3 x 256 (bench/h100-sun-lobe/fit_phase_weighted.json).
SUN_LOBE_POWER = 3.0
SUN_LOBE_MIN_G = 0.2


def sun_lobe_g(anisotropy: float, sh_order: int) -> float:
    """The probes' sun lobe g for a layout (0: none): order 3 (where the last texture has spare
    channels) and a forward-scattering g whose lobe would not be too broad to matter."""
    if sh_order != 3 or anisotropy <= 0.0:
        return 0.0
    h = float(anisotropy) ** SUN_LOBE_POWER
    return h if h >= SUN_LOBE_MIN_G else 0.0


def colour_channel(k: int, colour: int) -> int:
    """The colour packing's channel of SH coefficient k, colour 0..2 (probe_colour_channel)."""
    return 3 * k + colour if k < 9 else 28 + 3 * (k - 9) + colour


def colour_textures(order: int) -> int:
    """Textures of the colour packing (and the bake's running means): 7 up to order 2, 13, 19."""
    if order <= 2:
        return 7
    return (colour_channel(sh_count(order) - 1, 2) + 1 + 3) // 4


def texture_ids(order: int, grey: bool) -> tuple[int, ...]:
    """The texture numbers a probe grid of this order has, in slot order (probe_texture_number):
    texture 6 (colour) or 0 (grey) always, for the sun's transmittance in its alpha channel."""
    if order not in SH_ORDERS:
        raise ValueError(f"SH order {order!r}: expected one of {', '.join(map(str, SH_ORDERS))}")
    if grey:
        return tuple(range((sh_count(order) + 1 + 3) // 4))
    return {0: (0, 6), 1: (0, 1, 2, 6)}.get(order, tuple(range(colour_textures(order))))


TEXTURES_FOR_ORDER = {order: texture_ids(order, False) for order in SH_ORDERS}
GREY_TEXTURES_FOR_ORDER = {order: texture_ids(order, True) for order in SH_ORDERS}


def unpack_coefficients(channels: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Colour-packed channels (..., 4 * colour_textures) -> SH coefficients (..., K, 3) of bands
    0 .. order and the sun's transmittance (...)."""
    channels = np.asarray(channels)
    k = np.arange(sh_count(order))
    index = np.array([[colour_channel(int(i), c) for c in range(3)] for i in k])
    return channels[..., index], channels[..., SUN_CHANNEL]


def scene_is_grey(table: np.ndarray, irradiance, environment) -> bool:
    """True when every transfer-function colour and both lights have r = g = b exactly, so that
    every path's radiance has equal channels."""
    grey = lambda v: np.all(np.asarray(v)[..., 0:1] == np.asarray(v)[..., :3])  # noqa: E731
    if hasattr(table, "tables"):   # several channels: a mix of grey colours is grey
        colours = all(grey(np.asarray(t)[:, :3]) for t, on in zip(table.tables, table.on) if on)
    else:
        colours = grey(np.asarray(table)[:, :3])
    return bool(colours and grey(irradiance) and grey(environment))


def resolve_channels(channels: str | int, table: np.ndarray, irradiance, environment) -> int:
    if channels == "auto":
        return 1 if scene_is_grey(table, irradiance, environment) else 3
    return int(channels)


# "auto"'s order where the probes must hold directions (surfaces) and g = 0 would give 0.
AUTO_DIRECTIONAL_ORDER = 2


def resolve_precision(precision: str, directions: bool = False) -> str:
    """The probe textures' format: `precision` itself, or for "auto" rgba16f where the probes
    must hold directions for surfaces (glsl/lib/hybrid_scattering.glsl), else rgba32f (today's
    images, bit for bit). Why: with surfaces and g = 0 the raymarcher reads seven probe textures
    a sample instead of two, and at 1080p on the H200 16-bit texels took the foot's frame from
    10.1 to 3.9 ms and bonsai's from 3.8 to 1.9 ms, their error against the path tracer the same
    to the fourth digit (2.627 -> 2.628%, 7.051 -> 7.053%; bench/h200-hybrid-cost)."""
    if precision == "auto":
        return "rgba16f" if directions else "rgba32f"
    return precision


def resolve_sh_order(order: str | int, anisotropy: float, walks: int | None = None,
                     directions: bool = False) -> int:
    """The SH order probes are baked with: `order` itself, or for "auto" the scene's choice for
    probes of `walks` walks each (None: as many as the higher bands want). `directions`: the
    probes must hold directions (surfaces reading their irradiance,
    glsl/lib/hybrid_scattering.glsl): "auto" then never
    gives order 0, which holds none (AUTO_DIRECTIONAL_ORDER instead where g = 0)."""
    if order == "auto":
        g = abs(float(anisotropy))
        if g == 0.0:
            return AUTO_DIRECTIONAL_ORDER if directions else 0
        if walks is not None and walks < AUTO_WALKS_PER_HIGH_BAND:
            return 2
        kept = max(l for l in SH_ORDERS if l <= AUTO_MAX_ORDER and g ** l >= AUTO_BAND_WEIGHT)
        return max(2, kept)
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
