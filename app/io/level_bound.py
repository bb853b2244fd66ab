"""A lower bound on a level's bricks that are not constant, read from a small coarser level of the
same pyramid, so that a memory cap can pass over a level too large for it without its range pass
(app/rendering/levels/volume_placement.py; the range pass of level 0 of a 2048^3 store is seconds of reads).

Why it holds: a brick is constant (never uploaded, app/io/bricks.py constant_bricks) only if its
densities are all one value. A pyramid's coarser voxel lies between the least and largest of the
finer voxels it is made from (a mean, a strided sample, a rounded mean, a smoothing kernel with
non-negative weights), and the mapping from raw values to densities is monotonic
(app/io/volume.py normalise), so a coarser voxel made from one brick's voxels alone has that brick's
density where the brick is constant. The coarse voxels looked at are those whose footprint lies
inside the brick at least `margin` fine voxels from its faces (a quarter of a brick by default):
voxels made from finer voxels up to that far outside their own footprint (Gaussian pyramids reach
a few voxels) still come from the brick alone. Where they are not all equal (in any channel), the
brick is certainly not constant. Too few coarse voxels inside a brick (under 2 along an axis) say
nothing, so the bound only counts, never guesses.
"""
from __future__ import annotations

import numpy as np

# The coarse level used for the bound: at least this many of its voxels across a brick's inside
# (a brick of 64 voxels, a quarter margin each side: 32 fine voxels, 4 coarse ones at 8x), and at
# most BOUND_VOXELS voxels, read whole (a 256^3 level of a 2048^3 store: 32 MB of uint16, 0.1 s).
BOUND_ACROSS = 4
BOUND_VOXELS = 1 << 27


def default_margin(brick: int) -> int:
    return max(1, brick // 4)


def inside_ranges(n_fine: int, n_coarse: int, brick: int, margin: int) -> tuple[np.ndarray,
                                                                                  np.ndarray]:
    """Along one axis, for each brick b of the fine level: the coarse voxels [j0, j1) whose
    footprint [j n_fine / n_coarse, (j + 1) n_fine / n_coarse) lies within [b B + margin,
    min(b B + B, n_fine) - margin) (the world box's mapping between the levels). j1 <= j0: none."""
    count = -(-n_fine // brick)
    b = np.arange(count, dtype=np.int64)
    lo = b * brick + margin
    hi = np.minimum(b * brick + brick, n_fine) - margin
    # j n_fine / n_coarse >= lo  and  (j + 1) n_fine / n_coarse <= hi, in whole numbers
    j0 = -(-(lo * n_coarse) // n_fine)
    j1 = (hi * n_coarse) // n_fine
    return j0, np.maximum(j1, j0)


def _reduce_inside(values: np.ndarray, axis: int, j0: np.ndarray, j1: np.ndarray, op):
    """op (np.minimum or np.maximum) over [j0, j1) along `axis`, one row a brick (a row with
    j1 <= j0 holds a value of its own; the caller masks it): the insides are a few voxels long,
    so one gather a voxel of them (np.ufunc.reduceat took 0.4 s on a 256^3 level)."""
    n = values.shape[axis]
    last = np.clip(np.maximum(j1, j0 + 1) - 1, 0, n - 1)
    first = np.minimum(j0, last)
    out = values.take(first, axis=axis)
    for offset in range(1, int((last - first).max(initial=0)) + 1):
        out = op(out, values.take(np.minimum(first + offset, last), axis=axis))
    return out


def varying_bricks(coarse: np.ndarray, fine_dims, brick: int, margin: int | None = None,
                   ) -> np.ndarray:
    """[bz, by, bx] of the fine level of dims (x, y, z) in bricks of `brick`: True where the
    coarse level's densities coarse [z, y, x(, c)] (the same world box) certainly vary inside
    the brick, so the brick is not constant (the module's note says why)."""
    margin = default_margin(brick) if margin is None else int(margin)
    lo = hi = np.asarray(coarse, np.float32)
    inside = []
    for axis, (n_fine, n_coarse) in enumerate(zip(fine_dims[::-1], coarse.shape[:3])):
        j0, j1 = inside_ranges(int(n_fine), int(n_coarse), brick, margin)
        lo = _reduce_inside(lo, axis, j0, j1, np.minimum)
        hi = _reduce_inside(hi, axis, j0, j1, np.maximum)
        inside.append(j1 - j0 >= 2)
    varies = hi > lo
    if varies.ndim == 4:
        varies = varies.any(axis=-1)
    kz, ky, kx = inside
    return varies & kz[:, None, None] & ky[None, :, None] & kx[None, None, :]


def bound_level(fine_dims, levels, brick: int, margin: int | None = None):
    """Of `levels` (sources of coarser levels, finest first, shape [z, y, x(, c)]), the one that
    bounds the level of dims fine_dims best for its reading: the coarsest with at least
    BOUND_ACROSS voxels across a brick's inside along every axis and at most BOUND_VOXELS voxels;
    None where none has both."""
    margin = default_margin(brick) if margin is None else int(margin)
    across = brick - 2 * margin
    chosen = None
    for source in levels:
        shape = source.shape[:3]
        if any(across * int(n) // int(f) < BOUND_ACROSS
               for n, f in zip(shape, fine_dims[::-1])):
            break                     # coarser levels see even fewer
        if int(np.prod(shape, dtype=np.int64)) <= BOUND_VOXELS:
            chosen = source
    return chosen
