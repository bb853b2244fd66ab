"""NumPy twin of glsl/majorant_grid.comp: macrocell majorants for empty-space skipping.

The box is cut into ``cells`` equal macrocells per axis (``macrocell_counts``). Each macrocell
stores a bound on sigma_t over every point inside it, which delta and ratio tracking
(glsl/lib/tracking.glsl) walk with a DDA instead of one global majorant.

Two stages:

- ``density_range_grid`` (once per volume, NumPy): the smallest and largest normalised density the
  trilinear filter can return anywhere in the cell. With SPEC.md's cell-centred sampling, a point
  at voxel coordinate ``s = u * n - 0.5`` reads voxels ``floor(s)`` and ``floor(s) + 1`` (clamped to
  the edge), so a cell spanning ``[s0, s1]`` reads voxels ``floor(s0)`` to ``floor(s1) + 1``; the
  span is widened by ``SUPPORT_SLACK`` voxels each way so that a point a rounding error outside the
  cell (the DDA and the sample position are computed separately) is still covered. Filtering is a
  convex combination of those voxels, so its result lies in ``[min, max]`` up to float rounding,
  which ``DENSITY_WIDEN`` covers.
- ``majorant_grid`` (whenever the transfer function or density_scale changes; on the GPU in
  app/rendering/grids/majorant_grid.py): ``density_scale * max A(d)`` over ``d`` in ``[min, max]``. ``A`` is
  piecewise linear, so its maximum over an interval is at the interval's ends or at a table node
  inside it. ``MAJORANT_SAFETY`` covers float32 rounding of the interpolation and the product.
"""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.channels import ChannelTables
from radiance_probes.scene.transfer import lookup

CELL_VOXELS = 8          # voxels per macrocell along an axis (before clamping the count)
MAX_CELLS = 64           # macrocells per axis at most
# Slack of the trilinear support in voxels: the DDA's cell and the sample point's position are
# rounded separately, so a collision may be evaluated a few ulps outside its cell; 1/32 voxel is
# orders of magnitude more than that and also covers a texture unit that snaps coordinates to
# 1/256 of a texel (llvmpipe's fixed-point weights).
SUPPORT_SLACK = 1.0 / 32.0
# Relative widening of each cell's density range: a texture unit's trilinear filter in float32 may
# land a few ulps (2^-23 relative each) outside the convex hull of the voxels it blends, and so may
# d * (N - 1) in the table lookup. 2^-20 is 8 ulps. A range of exactly [0, 0] stays [0, 0], so empty
# cells keep a majorant of exactly 0 and are skipped without a single random number.
DENSITY_WIDEN = 2.0 ** -20
# Factor on every majorant: the lookup's a + (b - a) f and density_scale * A round in float32 and
# can exceed the exact value by an ulp or two (2^-24 relative each); 2^-16 is a wide margin. Costs
# one null collision in 65536 on a homogeneous medium.
MAJORANT_SAFETY = 1.0 + 2.0 ** -16


def macrocell_counts(dims: tuple[int, int, int]) -> tuple[int, int, int]:
    """Macrocells along x, y, z for a volume of dims (x, y, z) voxels: ceil(n / 8) in [1, 64]."""
    return tuple(int(min(max(-(-int(n) // CELL_VOXELS), 1), MAX_CELLS)) for n in dims)


def voxel_ranges(n: int, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last voxel (inclusive, clamped to [0, n - 1]) that trilinear filtering can read at
    any point of each of `cells` equal macrocells along an axis of `n` voxels."""
    i = np.arange(cells, dtype=np.float64)
    s0 = i * n / cells - 0.5                  # voxel coordinate of the cell's lower face
    s1 = (i + 1.0) * n / cells - 0.5          # and of its upper face
    lo = np.floor(s0 - SUPPORT_SLACK).astype(np.int64)
    hi = np.floor(s1 + SUPPORT_SLACK).astype(np.int64) + 1
    return np.clip(lo, 0, n - 1), np.clip(hi, 0, n - 1)


def _reduce_axis(a: np.ndarray, axis: int, lo: np.ndarray, hi: np.ndarray, op) -> np.ndarray:
    moved = np.moveaxis(a, axis, 0)
    out = np.stack([op(moved[l:h + 1], axis=0) for l, h in zip(lo, hi)], axis=0)
    return np.moveaxis(out, 0, axis)


def channel_density_ranges(volume, cells: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """density_range_grid of each channel of a volume of several channels: [C, cz, cy, cx]."""
    ranges = [density_range_grid(volume.channel(c), cells) for c in range(volume.channel_count)]
    return np.stack([r[0] for r in ranges]), np.stack([r[1] for r in ranges])


def density_range_grid(data: np.ndarray, cells: tuple[int, int, int] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) normalised density per macrocell, float32 arrays [cz, cy, cx], widened by
    DENSITY_WIDEN. `data` is the volume's [z, y, x] array; min and max are separable, so the
    reduction runs one axis at a time."""
    data = np.asarray(data, np.float32)
    nz, ny, nx = data.shape
    if cells is None:
        cells = macrocell_counts((nx, ny, nz))
    lo_grid, hi_grid = data, data
    for axis, (n, c) in zip((2, 1, 0), zip((nx, ny, nz), cells)):
        lo, hi = voxel_ranges(n, c)
        lo_grid = _reduce_axis(lo_grid, axis, lo, hi, np.min)
        hi_grid = _reduce_axis(hi_grid, axis, lo, hi, np.max)
    return _widened(lo_grid, hi_grid)


def brick_density_range_grid(brick_min: np.ndarray, brick_max: np.ndarray, dims, brick: int,
                             cells: tuple[int, int, int] | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """density_range_grid of a volume read brick by brick (app/io/bricks.py), from each brick's
    own least and largest density ([bz, by, bx]) alone: a macrocell's range is the union of the
    bricks that hold the voxels its points read (voxel_ranges), so it contains the one of the
    whole array, widened alike. Of several channels ([bz, by, bx, c]) each channel's, [C, cz,
    cy, cx] as channel_density_ranges."""
    if cells is None:
        cells = macrocell_counts(dims)
    if np.ndim(brick_min) == 4:
        ranges = [brick_density_range_grid(brick_min[..., c], brick_max[..., c], dims, brick,
                                           cells) for c in range(np.shape(brick_min)[3])]
        return np.stack([r[0] for r in ranges]), np.stack([r[1] for r in ranges])
    lo_grid = np.asarray(brick_min, np.float32)
    hi_grid = np.asarray(brick_max, np.float32)
    for axis, (n, c) in zip((2, 1, 0), zip(dims, cells)):
        lo, hi = voxel_ranges(int(n), c)
        lo_grid = _reduce_axis(lo_grid, axis, lo // brick, hi // brick, np.min)
        hi_grid = _reduce_axis(hi_grid, axis, lo // brick, hi // brick, np.max)
    return _widened(lo_grid, hi_grid)


def _widened(lo_grid: np.ndarray, hi_grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranges widened by DENSITY_WIDEN, rounded outwards to float32."""
    lo_grid = lo_grid.astype(np.float64)
    hi_grid = hi_grid.astype(np.float64)
    lo_grid = np.where(lo_grid > 0, lo_grid * (1.0 - DENSITY_WIDEN), lo_grid * (1.0 + DENSITY_WIDEN))
    hi_grid = np.where(hi_grid > 0, hi_grid * (1.0 + DENSITY_WIDEN), hi_grid * (1.0 - DENSITY_WIDEN))
    # float32 rounding must not undo the widening: round outwards.
    lo32 = lo_grid.astype(np.float32)
    hi32 = hi_grid.astype(np.float32)
    lo32 = np.where(lo32 > lo_grid, np.nextafter(lo32, np.float32(-np.inf)), lo32).astype(np.float32)
    hi32 = np.where(hi32 < hi_grid, np.nextafter(hi32, np.float32(np.inf)), hi32).astype(np.float32)
    return lo32, hi32


def _range_max_table(values: np.ndarray) -> list[np.ndarray]:
    """Sparse table for range-maximum queries: level k holds max(values[i : i + 2^k])."""
    levels = [np.asarray(values, np.float64)]
    k = 1
    while 2 * k <= len(values):
        prev = levels[-1]
        levels.append(np.maximum(prev[:-k], prev[k:]))
        k *= 2
    return levels


def _range_max(levels: list[np.ndarray], i0: np.ndarray, i1: np.ndarray) -> np.ndarray:
    """max(values[i0 .. i1]) inclusive, -inf where i0 > i1."""
    length = np.maximum(i1 - i0 + 1, 1)
    k = np.floor(np.log2(length)).astype(np.int64)
    out = np.full(i0.shape, -np.inf)
    for level in range(len(levels)):
        sel = (k == level) & (i1 >= i0)
        if sel.any():
            a = levels[level][i0[sel]]
            b = levels[level][i1[sel] - (1 << level) + 1]
            out[sel] = np.maximum(a, b)
    return out


def max_alpha(table: np.ndarray, d_min: np.ndarray, d_max: np.ndarray) -> np.ndarray:
    """Largest opacity of the transfer function over densities [d_min, d_max] (elementwise)."""
    table = np.asarray(table)
    n = len(table)
    lo = np.clip(np.asarray(d_min, np.float64), 0.0, 1.0)
    hi = np.clip(np.asarray(d_max, np.float64), 0.0, 1.0)
    ends = np.maximum(lookup(table, lo)[..., 3], lookup(table, hi)[..., 3])
    i0 = np.ceil(lo * (n - 1)).astype(np.int64)
    i1 = np.minimum(np.floor(hi * (n - 1)).astype(np.int64), n - 1)
    inner = _range_max(_range_max_table(table[:, 3]), i0.ravel(), i1.ravel()).reshape(i0.shape)
    return np.maximum(ends, inner)


# How far beyond its faces (in cells) a cell counts for the crop and clip plane's test: a cell is
# cut away only when no point of it, widened by this, is kept.
CELL_SLACK = 1.0 / 256.0


def kept_density_ranges(d_min: np.ndarray, d_max: np.ndarray, clip, half_extent,
                        rounding: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(min, max, cut) per macrocell under a crop or clip plane (app.clip_region.ClipRegion), as
    glsl/majorant_grid.comp's kept_density_range: `cut` where no point of the cell is kept; else
    the union of the ranges of the cells that the cell's kept points read the density in (the
    cell clamped as kept_sample_point clamps points, up to a voxel inside the crop).
    `rounding` (in cells) widens (> 0) or narrows (< 0) that span of cells: where a crop face lies
    on a cell face, float32 on the GPU may take the neighbour in or leave it out; tests bound the
    GPU's grid between the two."""
    d_min, d_max = np.asarray(d_min), np.asarray(d_max)
    cz, cy, cx = d_min.shape
    cells = np.array([cx, cy, cz])
    he = np.asarray(half_extent, np.float32).astype(np.float64)
    size = 2.0 * he / cells
    k, j, i = np.meshgrid(np.arange(cz), np.arange(cy), np.arange(cx), indexing="ij")
    index = np.stack([i, j, k], axis=-1)
    lo = -he + index * size
    hi = lo + size
    slack = size * CELL_SLACK
    cut = clip.cuts_box(lo - slack, hi + slack)
    kmin = np.asarray(clip.box_min, np.float32).astype(np.float64)
    kmax = np.asarray(clip.box_max, np.float32).astype(np.float64)
    s_lo = clip.sample_points(np.maximum(lo, kmin))
    s_hi = clip.sample_points(np.minimum(hi, kmax))
    first = np.clip(np.floor((s_lo + he) / size - rounding).astype(np.int64), 0, cells - 1)
    last = np.clip(np.ceil((s_hi + he) / size + rounding).astype(np.int64) - 1, first, cells - 1)
    out_lo = np.full(d_min.shape, np.inf)
    out_hi = np.full(d_min.shape, -np.inf)
    span = int((last - first).max(initial=0)) + 1
    for dz in range(span):
        for dy in range(span):
            for dx in range(span):
                c = first + np.array([dx, dy, dz])
                use = np.all(c <= last, axis=-1)
                c = np.minimum(c, cells - 1)
                out_lo = np.where(use, np.minimum(out_lo, d_min[c[..., 2], c[..., 1], c[..., 0]]), out_lo)
                out_hi = np.where(use, np.maximum(out_hi, d_max[c[..., 2], c[..., 1], c[..., 0]]), out_hi)
    return out_lo, out_hi, cut


def majorant_grid(d_min: np.ndarray, d_max: np.ndarray, table,
                  density_scale: float, clip=None, half_extent=None,
                  rounding: float = 0.0) -> np.ndarray:
    """The majorant per macrocell, float32 [cz, cy, cx] (the twin of glsl/majorant_grid.comp);
    with a crop or clip plane (`clip`, in the box of `half_extent`), 0 in cells cut away
    (`rounding`: kept_density_ranges').
    Several channels (`table` an app.channels.ChannelTables, d_min and d_max [C, cz, cy, cx]):
    density_scale times the sum over the channels switched on of each one's largest opacity over
    its own range, which bounds their summed sigma_t."""
    if isinstance(table, ChannelTables):
        alpha = 0.0
        cut = None
        for c, (t, on) in enumerate(zip(table.tables, table.on)):
            lo, hi = d_min[c], d_max[c]
            if clip is not None:
                lo, hi, cut = kept_density_ranges(lo, hi, clip, half_extent, rounding)
            if on:
                alpha = alpha + max_alpha(t, lo, hi)
        m = float(density_scale) * np.broadcast_to(alpha, d_min.shape[1:]) * MAJORANT_SAFETY
        if cut is not None:
            m = np.where(cut, 0.0, m)
        return m.astype(np.float32)
    cut = None
    if clip is not None:
        d_min, d_max, cut = kept_density_ranges(d_min, d_max, clip, half_extent, rounding)
    m = float(density_scale) * max_alpha(table, d_min, d_max) * MAJORANT_SAFETY
    if cut is not None:
        m = np.where(cut, 0.0, m)
    return m.astype(np.float32)


def majorant_bound(d_min: np.ndarray, d_max: np.ndarray, table: np.ndarray,
                   density_scale: float) -> float:
    """One bound over every macrocell: the majorant of the whole volume's density range, an upper
    bound of the grid's maximum. It is 0 exactly when the whole volume is transparent, and then
    tracking returns at once instead of walking cells."""
    lo, hi = np.asarray(d_min), np.asarray(d_max)
    if lo.size == 0:
        return 0.0
    if isinstance(table, ChannelTables):   # [C, ...]: each channel's own range
        c = lo.shape[0]
        lo_c = lo.reshape(c, -1).min(axis=1).reshape(c, 1)
        hi_c = hi.reshape(c, -1).max(axis=1).reshape(c, 1)
        return float(majorant_grid(lo_c, hi_c, table, density_scale)[0])
    return float(majorant_grid(np.array([lo.min()]), np.array([hi.max()]), table, density_scale)[0])
