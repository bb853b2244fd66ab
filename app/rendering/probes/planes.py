"""An adaptive probe layout: per axis, where the probe planes go (app/twins/probe_warp.py,
glsl/lib/probe_warp.glsl read them).

The light field changes fastest where the medium does, so each axis gets more planes where an
indicator field varies along that axis, and the same count in all:

1. an indicator field over the volume box (`indicator_field`): "extinction", sigma_t after the
   transfer function at the voxels; "sun", the sun's transmittance exp(-optical depth) at the
   light grid's texels (a small read of the grid once per layout);
2. per axis a, its variation along a: |F(i + 1) - F(i)| between neighbouring samples, summed over
   the other two axes within the probe box, binned over the box (BINS_PER_SPACING bins per
   uniform probe spacing) and smoothed over one uniform spacing (a plane serves its neighbourhood);
3. a probe density mixed with a uniform floor: (1 - strength) + strength * variation / its mean,
   then scaled and clamped so that its mean is 1 and it lies within [1 / MAX_SPACING,
   1 / MIN_SPACING]: no spacing wider than MAX_SPACING nor narrower than MIN_SPACING times the
   uniform one;
4. n planes at equal quantiles of the density's cumulative: plane i at quantile (i + 0.5) / n.

Strength 0, or an indicator without variation along an axis, gives that axis its uniform planes
exactly (None: the uniform layout, which the shaders take without the warp)."""
from __future__ import annotations

import math

import numpy as np

from radiance_probes.scene.transfer import lookup
from radiance_probes.twins.probe_warp import uniform_planes

MAX_SPACING = 3.0       # probe spacing at most this many times the uniform grid's
MIN_SPACING = 0.25      # and at least this fraction of it
BINS_PER_SPACING = 8    # bins of the density per uniform probe spacing
MAX_FIELD_SIDE = 256    # the indicator field is block-averaged down to this many samples per axis


def block_factors(shape: tuple[int, ...], max_side: int = MAX_FIELD_SIDE) -> tuple[int, ...]:
    """Voxels per block along each axis: the least that leave at most max_side blocks."""
    return tuple(max(1, math.ceil(n / max_side)) for n in shape)


def block_mean(field: np.ndarray, factors: tuple[int, int, int]) -> np.ndarray:
    """The field (z, y, x) averaged over blocks of `factors` voxels (edge-padded to whole blocks)."""
    f = np.asarray(field, np.float32)
    if tuple(factors) == (1, 1, 1):
        return f
    f = np.pad(f, [(0, -n % k) for n, k in zip(f.shape, factors)], mode="edge")
    (kz, ky, kx), (nz, ny, nx) = factors, (n // k for n, k in zip(f.shape, factors))
    return f.reshape(nz, kz, ny, ky, nx, kx).mean(axis=(1, 3, 5))


def extinction_field(data: np.ndarray, table: np.ndarray, density_scale: float) -> np.ndarray:
    """sigma_t after the transfer function at the voxels (z, y, x), block-averaged to at most
    MAX_FIELD_SIDE per axis; slab by slab, so a large volume is never copied whole."""
    factors = block_factors(data.shape[:3])
    step = factors[0] * max(1, 64 // factors[0])

    def sigma_t(slab: np.ndarray) -> np.ndarray:
        if not hasattr(table, "tables"):
            return density_scale * lookup(table[:, 3:4], slab)[..., 0]
        # several channels (data [z, y, x, c]): their sigma_t add up
        return density_scale * sum(lookup(t[:, 3:4], slab[..., c])[..., 0]
                                   for c, (t, on) in enumerate(zip(table.tables, table.on)) if on)

    slabs = [block_mean(sigma_t(data[z:z + step]), factors) for z in range(0, data.shape[0], step)]
    return np.concatenate(slabs)


def sun_field(optical_depth: np.ndarray) -> np.ndarray:
    """The sun's transmittance exp(-optical depth) at the light grid's texels (z, y, x),
    block-averaged to at most MAX_FIELD_SIDE per axis."""
    tau = np.asarray(optical_depth, np.float32)
    return block_mean(np.exp(-tau), block_factors(tau.shape))


def axis_variation(field: np.ndarray, half_extent, box, axis: int, bins: int) -> np.ndarray:
    """The field's variation along `axis` (0 = x) binned over the probe box: |F(i + 1) - F(i)|
    summed over the other axes' samples within the box, at the midpoint of each pair. `field`
    (z, y, x) is sampled at the cell centres of the volume box [-half_extent, half_extent]."""
    half = np.asarray(half_extent, np.float64)
    low, high = ((-half, half) if box is None
                 else (np.asarray(box[0], np.float64), np.asarray(box[1], np.float64)))
    size = np.maximum(high - low, 1e-12)

    def fractions(a: int, at: np.ndarray, n: int) -> np.ndarray:
        """World fractions of the box at sample coordinate `at` (in samples) along axis a."""
        return (at / n * 2 * half[a] - half[a] - low[a]) / size[a]

    g = np.moveaxis(np.asarray(field, np.float64), 2 - axis, 0)
    # the other two array axes keep their order: world axes in descending order (z, y, x)
    for position, other in enumerate(sorted((a for a in (0, 1, 2) if a != axis), reverse=True)):
        n = field.shape[2 - other]
        frac = fractions(other, np.arange(n) + 0.5, n)
        inside = (frac >= 0) & (frac <= 1)
        if not inside.any():   # a box thinner than a sample: the nearest one
            inside = np.abs(frac - 0.5) == np.abs(frac - 0.5).min()
        g = np.compress(inside, g, axis=1 + position)
    variation = np.abs(np.diff(g, axis=0)).sum(axis=(1, 2))
    n = g.shape[0]
    midpoints = fractions(axis, np.arange(1, n, dtype=np.float64), n)
    inside = (midpoints >= 0) & (midpoints <= 1)
    binned, _ = np.histogram(midpoints[inside], bins=bins, range=(0.0, 1.0),
                             weights=variation[inside])
    return binned


def smooth(values: np.ndarray, width: int) -> np.ndarray:
    """Moving average over `width` bins, normalised at the ends."""
    if width <= 1:
        return values.astype(np.float64)
    kernel = np.ones(width)
    total = np.convolve(values, kernel, mode="same")
    count = np.convolve(np.ones_like(values, dtype=np.float64), kernel, mode="same")
    return total / count


def probe_density(variation: np.ndarray, strength: float) -> np.ndarray | None:
    """Probe density per bin (mean 1, within [1 / MAX_SPACING, 1 / MIN_SPACING]) from a
    variation, mixed with the uniform density 1 by `strength` in [0, 1]; None where it is uniform
    (strength 0, or no variation or the same everywhere)."""
    v = np.asarray(variation, np.float64)
    top = v.max() if len(v) else 0.0
    if strength <= 0 or not np.isfinite(v).all() or top <= 0 or v.min() >= top:
        return None
    raw = (1.0 - strength) + strength * v / v.mean()
    # Bins without variation at strength 1 get a trace, so that a scale exists at which the
    # clamped density has mean 1 (else a few sharp bins could not hold the mass beyond the floor).
    raw = np.maximum(raw, 1e-9 * raw.max())
    lo, hi = 1.0 / MAX_SPACING, 1.0 / MIN_SPACING
    # mean(clip(c raw, lo, hi)) rises with c from lo to hi: bisect (geometrically) for 1
    c_lo, c_hi = lo / raw.max(), hi / raw.min()
    for _ in range(200):
        c = math.sqrt(c_lo * c_hi)
        if np.clip(c * raw, lo, hi).mean() < 1.0:
            c_lo = c
        else:
            c_hi = c
    return np.clip(c_hi * raw, lo, hi)


def planes_from_density(density: np.ndarray, n: int) -> np.ndarray:
    """n plane positions (world fractions of the box) at the quantiles (i + 0.5) / n of the
    piecewise-constant density over equal bins of [0, 1]."""
    cumulative = np.concatenate([[0.0], np.cumsum(density)])
    cumulative /= cumulative[-1]
    edges = np.linspace(0.0, 1.0, len(density) + 1)
    return np.interp(uniform_planes(n), cumulative, edges)


def adaptive_planes(field: np.ndarray, half_extent, box, grid: tuple[int, int, int],
                    strength: float) -> tuple | None:
    """Per axis the probe planes (world fractions of the box) from an indicator field (z, y, x)
    over the volume box; None when every axis comes out uniform."""
    planes, adaptive = [], False
    for axis, n in enumerate(grid):
        bins = BINS_PER_SPACING * n
        variation = smooth(axis_variation(field, half_extent, box, axis, bins), BINS_PER_SPACING)
        density = probe_density(variation, strength) if n > 1 else None
        if density is None:
            planes.append(uniform_planes(n))
        else:
            planes.append(planes_from_density(density, n))
            adaptive = True
    return tuple(tuple(float(v) for v in p) for p in planes) if adaptive else None
