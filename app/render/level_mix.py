"""Mixed levels under a memory cap, by screen footprint (lib/brick_pool.glsl BRICK_LEVELS): where
a whole level (C) is the finest that fits the cap, the memory it leaves holds bricks of the level
one finer (F) where the camera sees them largest, the rest staying C.

Each brick of F (the pool's level 0) reads F or C:
- F where F's brick is constant (it costs no slot and is exact);
- F, in order of footprint, where a voxel of C would cover more than MIX_FOOTPRINT_PX pixels of
  the camera's image at the brick's nearest point, and a slot is left under the cap;
- C elsewhere (bricks outside the view frustum always).

The footprint of a voxel of world size s at distance d is s / (2 d tan(fov_y / 2) / height)
pixels. The choice depends on the camera given when the volume is placed (a later camera keeps
it: the medium stays one for every method and sample, and the viewer does not re-place it).
Every method reads the same mixed medium: the path tracer stays the reference of what is shown.
Off by default (RenderSettings.mixed_levels): the benchmark has not shown it paying.
"""
from __future__ import annotations

import math

import numpy as np

from ..bricks import (PoolPlan, around, brick_counts, bricks_reached, constant_values,
                      level_needs, level_tables, slot_bytes, slot_grid)
from ..twins.camera import camera_frame
from ..twins.majorant_grid import brick_density_range_grid

# A brick of F is worth its slot where a voxel of C would cover more than this many pixels (a
# voxel of F more than one): C is then visibly coarser than the image. Where no brick is, one
# whole level is shown: on the H100 (bench/h100-bricks-open) mixing at an overview, where a voxel
# of F covers 0.3 to 0.5 pixels, took the 2048^3 volume's rRMSE against level 0 from 0.82% to
# 0.79% and its 1080p frame from 7.1 to 16.1 ms (the raymarcher steps at F's voxels everywhere).
MIX_FOOTPRINT_PX = 2.0


def footprints(dims, brick: int, half_extent, camera) -> np.ndarray:
    """[bz, by, bx]: pixels a voxel of a level of `dims` covers at each brick's point nearest the
    camera (inf with the eye inside it; -1 for a brick wholly outside the view frustum)."""
    frame = camera_frame(camera)
    dims = np.asarray(dims, np.float64)
    h = np.asarray(half_extent, np.float64)
    bx, by, bz = brick_counts(tuple(int(v) for v in dims), brick)
    edges = [np.minimum(np.arange(n + 1) * brick, d) / d * 2.0 * hh - hh
             for n, d, hh in zip((bx, by, bz), dims, h)]
    lo = np.stack(np.meshgrid(edges[0][:-1], edges[1][:-1], edges[2][:-1], indexing="ij"), -1)
    hi = np.stack(np.meshgrid(edges[0][1:], edges[1][1:], edges[2][1:], indexing="ij"), -1)
    lo, hi = lo.transpose(2, 1, 0, 3), hi.transpose(2, 1, 0, 3)    # [bz, by, bx, 3]
    eye = np.asarray(frame.eye, np.float64)
    distance = np.linalg.norm(np.clip(eye, lo, hi) - eye, axis=-1)
    voxel = float(np.max(2.0 * h / dims))
    tan_half = math.tan(math.radians(camera.fov_y) / 2.0)
    with np.errstate(divide="ignore"):
        px = np.where(distance > 0, voxel * camera.height / (2.0 * distance * tan_half), np.inf)
    # the frustum: a brick is out when all 8 corners are beyond one of its 4 side planes or
    # behind the eye
    fwd = np.asarray(frame.forward, np.float64)
    right = np.asarray(frame.right, np.float64)
    up = np.asarray(frame.up, np.float64)
    out = np.zeros(px.shape, bool)
    corners = [np.where(np.asarray(c, bool), hi, lo) - eye for c in np.ndindex(2, 2, 2)]
    z = np.stack([c @ fwd for c in corners])
    for axis, scale in ((right, np.dot(right, right)), (up, np.dot(up, up))):
        s = np.stack([c @ axis for c in corners]) / scale      # image coordinate times depth
        out |= np.all(s > z, axis=0) | np.all(s < -z, axis=0)
    out |= np.all(z <= 0, axis=0)
    return np.where(out, -1.0, px)


def mixed_plan(fine, coarse, cap: int, camera, half_extent, max_side: int,
               exact_uint8: bool, name: str = "volume") -> tuple[PoolPlan | None, str]:
    """The pool of `fine` (F, a BrickStore) and `coarse` (C, the finest whole level that fits
    `cap`) mixed by footprint, and what it holds in words; (None, why) where no brick of F is
    worth a slot."""
    B = fine.brick
    channels = fine.channels
    per_slot = slot_bytes(B, channels, exact_uint8)
    fdims, cdims = fine.dims, coarse.dims
    counts_f, counts_c = fine.counts, coarse.counts
    px_c = footprints(fdims, B, half_extent, camera) * (np.max(np.asarray(fdims) /
                                                               np.asarray(cdims)))
    seen = px_c > MIX_FOOTPRINT_PX
    # which of F's bricks are constant needs F's range pass (seconds at 2048^3): only where the
    # camera sees some brick large enough to be worth a slot
    const_f = fine.constant() if seen.any() else None
    candidates = np.argwhere(~const_f & seen) if const_f is not None else np.empty((0, 3))
    if not len(candidates):
        return None, (f"no brick of the finer level is seen with a voxel of the shown level "
                      f"over {MIX_FOOTPRINT_PX} px")
    const_c = coarse.constant()
    level_of = np.where(const_f, 0, 1).astype(np.int64)        # F's constant bricks read F
    order = np.argsort(-px_c[tuple(candidates.T)], kind="stable")
    table_texels = (counts_f[0] * counts_f[1] * (counts_f[2] + counts_c[2]))

    def fixed_bytes(n_constants: int) -> int:
        return 4 * table_texels + 16 * n_constants

    lo_f, _ = fine.ranges()
    lo_c, _ = coarse.ranges()
    n_constants = (len(constant_values(lo_f, const_f)[0]) + len(constant_values(lo_c, const_c)[0]))
    # C's bricks as if no brick of F were taken (taking some only frees C's): an upper bound
    resident_c = int((level_needs(level_of, 1, fdims, cdims, B) & ~const_c).sum())

    def fits(slots: int) -> bool:
        try:
            grid = slot_grid(slots, B, max_side)
        except ValueError:
            return False
        return int(np.prod(grid)) * per_slot + fixed_bytes(n_constants) <= cap

    taken = 0
    for k in order:
        if not fits(resident_c + taken + 1):
            break
        z, y, x = candidates[k]
        level_of[z, y, x] = 0
        taken += 1
    if not taken:
        return None, "the cap leaves no slot for a brick of the finer level"
    plan = _plan(fine, coarse, level_of, const_f, const_c, max_side, name)
    total = int(np.prod(plan.grid)) * per_slot + fixed_bytes(len(plan.constants))
    if total > cap:          # (the slot grid rounds up; never seen, but never over the cap)
        return None, "the mixed pool's atlas would exceed the cap"
    plan.level_of_brick = level_of
    worth = len(candidates)
    why = (f"{taken} of the {int((~const_f).sum())} bricks of level {fdims[0]} x {fdims[1]} x "
           f"{fdims[2]} that are not constant read it (of {worth} seen with a voxel of the "
           f"coarser level over {MIX_FOOTPRINT_PX} px, nearest the camera first), the rest the "
           "coarser level")
    return plan, why


def _plan(fine, coarse, level_of, const_f, const_c, max_side: int, name: str) -> PoolPlan:
    table, constants, (resident_f, resident_c), table_z = level_tables(
        [(fine.dims, fine.ranges()[0], const_f), (coarse.dims, coarse.ranges()[0], const_c)],
        level_of, fine.brick)
    grid = slot_grid(len(resident_f) + len(resident_c), fine.brick, max_side)
    return PoolPlan(fine.dims, fine.brick, fine.channels, table, constants, grid,
                    [(fine, resident_f, 0), (coarse, resident_c, 1)], name,
                    level_dims=(fine.dims, coarse.dims), level_table_z=tuple(table_z))


def mixed_density_ranges(fine, coarse, level_of: np.ndarray, cells) -> tuple:
    """The majorant grid's density ranges (app/twins/majorant_grid.py density_range_grid) of a
    mixed pool: per brick of F, the range of what its points read, with the apron (F's brick and
    its 26 neighbours in F; in C, the bricks its points land in and their neighbours), then
    unioned over the bricks each macrocell's points read, as for one level."""
    lo_f, hi_f = (np.asarray(a, np.float32) for a in fine.ranges())
    lo_c, hi_c = (np.asarray(a, np.float32) for a in coarse.ranges())
    lo_f, hi_f = around(lo_f, np.minimum), around(hi_f, np.maximum)
    lo_c, hi_c = around(lo_c, np.minimum), around(hi_c, np.maximum)
    eff_lo, eff_hi = lo_f.copy(), hi_f.copy()
    for z, y, x in np.argwhere(level_of == 1):
        a, b = bricks_reached(fine.dims, coarse.dims, fine.brick, (x, y, z), (x, y, z))
        sl = (slice(a[2], b[2] + 1), slice(a[1], b[1] + 1), slice(a[0], b[0] + 1))
        eff_lo[z, y, x] = lo_c[sl].min(axis=(0, 1, 2))
        eff_hi[z, y, x] = hi_c[sl].max(axis=(0, 1, 2))
    return brick_density_range_grid(eff_lo, eff_hi, fine.dims, fine.brick, cells)
