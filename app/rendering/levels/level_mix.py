"""Mixed levels under a memory cap, by screen footprint (lib/brick_pool.glsl BRICK_LEVELS): where
a whole level (C) is the finest that fits the cap, the memory it leaves holds bricks of the level
one finer (F) where the camera sees them largest, the rest staying C.

Each brick of F (the pool's level 0) reads F or C:
- F where F's brick is constant (it costs no slot and is exact);
- F, in order of footprint, where a voxel of C would cover more than MIX_FOOTPRINT_PX pixels of
  the camera's image at the brick's nearest point, and a slot is left under the cap;
- C elsewhere (bricks outside the view frustum always).

The footprint of a voxel of world size s at distance d is s / (2 d tan(fov_y / 2) / height)
pixels. The placement chooses for the camera it is given; C is resident whole and the atlas has
every slot the cap allows, so F's bricks are streamed as the camera moves
(app/rendering/levels/level_stream.py: the same choice, choose_fine, made again for the new camera).
Every method reads the same mixed medium: the path tracer stays the reference of what is shown.
Off but for the bench's comparisons (LabOptions.mixed_levels, app/rendering/lab_options.py): the
benchmark has not shown it paying.
"""
from __future__ import annotations

import math

import numpy as np

from dataclasses import dataclass

from radiance_probes.io.brick_layout import (CONSTANT, REDIRECT, UNMAPPED, around, brick_counts,
                                             bricks_reached, constant_values, slot_bytes, slot_side)
from radiance_probes.io.bricks import PoolPlan
from radiance_probes.twins.camera import camera_frame
from radiance_probes.twins.majorant_grid import brick_density_range_grid

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


@dataclass
class Mix:
    """What a streamed mix chooses from (app/rendering/levels/level_stream.py): the finer level F and the
    coarser C (BrickStores), the volume's box, the slots of the pool's atlas (`capacity`, all the
    cap allows) and how many of them C's bricks take (C is resident whole: slots 0 .. c_slots - 1)."""
    fine: object
    coarse: object
    half_extent: tuple
    capacity: int
    c_slots: int
    const_f: np.ndarray | None = None    # F's constant bricks when planned (None: unread)

    @property
    def f_slots(self) -> int:
        """The slots left for F's bricks."""
        return self.capacity - self.c_slots


def choose_fine(mix: Mix, camera) -> tuple[np.ndarray, np.ndarray | None, int, np.ndarray]:
    """The mix a camera deserves: (level_of [bz, by, bx] of F: 0 for F, 1 for C; F's constant
    bricks (None while F's range pass is unread: they then read C); how many bricks are worth a
    slot; the chosen F bricks that take a slot (n, 3) z, y, x, the most deserving first). F's
    bricks that are not constant and where a voxel of C covers more than MIX_FOOTPRINT_PX pixels
    take F's slots, largest footprint first, as many as `mix.f_slots`; bricks outside the view
    frustum never. F's range pass is read the first time some brick is seen that large."""
    fine, coarse = mix.fine, mix.coarse
    ratio = float(np.max(np.asarray(fine.dims) / np.asarray(coarse.dims)))
    px_c = footprints(fine.dims, fine.brick, mix.half_extent, camera) * ratio
    seen = px_c > MIX_FOOTPRINT_PX
    # which of F's bricks are constant needs F's range pass (seconds at 2048^3): only where the
    # camera sees some brick large enough to be worth a slot (or it was read before)
    const_f = fine.constant() if (seen.any() or fine.ranges_read) else None
    level_of = np.ones(tuple(fine.counts[::-1]), np.int64)
    if const_f is None:
        return level_of, None, 0, np.empty((0, 3), np.int64)
    level_of[const_f] = 0                        # F's constant bricks read F (exact, no slot)
    candidates = np.argwhere(~const_f & seen)
    order = np.argsort(-px_c[tuple(candidates.T)], kind="stable")
    chosen = candidates[order[:max(mix.f_slots, 0)]]
    level_of[tuple(chosen.T)] = 0
    return level_of, const_f, len(candidates), chosen


def stream_layout(mix: Mix, level_of: np.ndarray, const_f: np.ndarray | None, chosen):
    """The page table and constants of a streamed mix (lib/brick_pool.glsl BRICK_LEVELS): C whole
    (its table at F's, above it along z: each brick a slot 0 .. c_slots - 1 in layer order, or a
    constant), and F's entries: a constant (where F's range pass is read), a slot (the `chosen`
    bricks, c_slots on, in the order given) or REDIRECT | 1 (read C). The constants: C's rows,
    then F's. Returns (table, constants, C's resident bricks (n, 3) z, y, x)."""
    fine, coarse = mix.fine, mix.coarse
    cf, cc = fine.counts, coarse.counts
    table = np.full((cf[2] + cc[2], cf[1], cf[0]), UNMAPPED, np.uint32)
    const_c = coarse.constant()
    rows_c, which_c = constant_values(coarse.ranges()[0], const_c)
    part = table[cf[2]:, :cc[1], :cc[0]]
    part[const_c] = CONSTANT | which_c[const_c]
    resident_c = np.argwhere(~const_c)
    part[tuple(resident_c.T)] = np.arange(len(resident_c), dtype=np.uint32)
    top = table[:cf[2]]
    top[...] = REDIRECT | 1
    constants = rows_c
    if const_f is not None:
        rows_f, which_f = constant_values(fine.ranges()[0], const_f)
        top[const_f] = CONSTANT | (which_f[const_f] + len(rows_c))
        constants = np.concatenate([rows_c, rows_f])
    chosen = np.asarray(chosen, np.int64).reshape(-1, 3)
    top[tuple(chosen.T)] = np.arange(len(resident_c), len(resident_c) + len(chosen),
                                     dtype=np.uint32)
    assert np.array_equal(top != (REDIRECT | 1), level_of == 0)
    return table, constants, resident_c


def slots_within(most: int, brick: int, max_side: int) -> tuple[int, int, int]:
    """The slot grid (x, y, z) with the most slots up to `most` (the nearest a cube of those),
    each axis within max_side texels: a mix's atlas takes every slot the cap allows
    (slot_grid, which rounds a count up to a near cube, would leave up to a third unused)."""
    per_axis = max_side // slot_side(brick)
    if per_axis < 1 or most < 1:
        raise ValueError("no slot")
    n = np.arange(1, min(per_axis, most) + 1)
    sx, sy = np.meshgrid(n, n, indexing="ij")
    sz = np.minimum(per_axis, most // (sx * sy))
    total = sx * sy * sz
    spread = np.maximum(np.maximum(sx, sy), sz) - np.minimum(np.minimum(sx, sy), sz)
    best = np.lexsort((spread.ravel(), -total.ravel()))[0]
    return int(sx.ravel()[best]), int(sy.ravel()[best]), int(sz.ravel()[best])


def mixed_plan(fine, coarse, cap: int, camera, half_extent, max_side: int,
               exact_uint8: bool, name: str = "volume") -> tuple[PoolPlan | None, str]:
    """The pool of `fine` (F, a BrickStore) and `coarse` (C, the finest whole level that fits
    `cap`) mixed by footprint, and what it holds in words; (None, why) where the cap leaves no
    slot for a brick of F. The atlas has every slot the cap allows (C's bricks whole, the rest
    for F's, streamed as the camera moves: app/rendering/levels/level_stream.py); the constants' bytes are
    reserved for C's and a row for each brick of F, so the capacity does not depend on whether
    F's range pass has been read."""
    B = fine.brick
    per_slot = slot_bytes(B, fine.channels, exact_uint8)
    fdims, cdims = fine.dims, coarse.dims
    counts_f, counts_c = fine.counts, coarse.counts
    const_c = coarse.constant()
    c_slots = int(np.count_nonzero(~const_c))
    table_texels = counts_f[0] * counts_f[1] * (counts_f[2] + counts_c[2])
    n_constants = (len(constant_values(coarse.ranges()[0], const_c)[0])
                   + 1 + int(np.prod(counts_f)))
    fixed = 4 * table_texels + 16 * n_constants

    try:
        grid = slots_within(max((cap - fixed) // per_slot, 0), B, max_side)
    except ValueError:
        grid = (0, 0, 0)
    if int(np.prod(grid)) <= c_slots:
        return None, "the cap leaves no slot for a brick of the finer level"
    mix = Mix(fine, coarse, tuple(float(v) for v in half_extent), int(np.prod(grid)), c_slots)
    level_of, const_f, worth, chosen = choose_fine(mix, camera)
    mix.const_f = const_f
    # F's slots in layer order (PoolPlan.rows writes a level's bricks in consecutive slots)
    layer = chosen[np.lexsort(chosen.T[::-1])]
    table, constants, resident_c = stream_layout(mix, level_of, const_f, layer)
    plan = PoolPlan(fdims, B, fine.channels, table, constants, grid,
                    [(coarse, resident_c, 1), (fine, layer, 0)],
                    name, level_dims=(fdims, cdims), level_table_z=(0, counts_f[2]))
    plan.level_of_brick = level_of
    plan.mix = mix
    total = int(np.prod(plan.grid)) * per_slot + 4 * table.size + 16 * len(plan.constants)
    if total > cap:          # (never: the constants are reserved for)
        return None, "the mixed pool's atlas would exceed the cap"
    taken = len(chosen)
    if const_f is None:
        why = (f"no brick of level {fdims[0]} x {fdims[1]} x {fdims[2]} is seen with a voxel of "
               f"the coarser level over {MIX_FOOTPRINT_PX} px: the coarser level everywhere")
    else:
        why = (f"{taken} of the {int((~const_f).sum())} bricks of level {fdims[0]} x {fdims[1]} "
               f"x {fdims[2]} that are not constant read it (of {worth} seen with a voxel of the "
               f"coarser level over {MIX_FOOTPRINT_PX} px, nearest the camera first), the rest "
               "the coarser level")
    why += (f"; {mix.f_slots} slots for its bricks, streamed as the camera moves (the choice "
            "above is for the camera the volume was placed with)")
    return plan, why


def coarse_ranges_read(fine, coarse) -> tuple[np.ndarray, np.ndarray]:
    """[bz, by, bx(, c)] of F: the least and largest density the points of each brick of F read
    where it reads C: over the bricks of C its points land in (bricks_reached) and their
    neighbours (the apron). Per axis, then the box's least and largest axis by axis (the same
    values as brick by brick, in array operations)."""
    lo, hi = (np.asarray(v, np.float32) for v in coarse.ranges())
    lo, hi = around(lo, np.minimum), around(hi, np.maximum)
    for axis in (2, 1, 0):                    # x, y, z of the table's [z, y, x]
        a = 2 - axis                          # that axis's index in (x, y, z)
        n = fine.counts[a]
        at = np.zeros((n, 3), np.int64)
        at[:, a] = np.arange(n)
        first, last = (r[:, a] for r in bricks_reached(fine.dims, coarse.dims, fine.brick,
                                                        at, at))
        span = int((last - first).max()) + 1
        lo = np.minimum.reduce([np.take(lo, np.minimum(first + k, last), axis=axis)
                                for k in range(span)])
        hi = np.maximum.reduce([np.take(hi, np.minimum(first + k, last), axis=axis)
                                for k in range(span)])
    return lo, hi


def mixed_density_ranges(fine, coarse, level_of: np.ndarray, cells) -> tuple:
    """The majorant grid's density ranges (app/twins/majorant_grid.py density_range_grid) of a
    mixed pool: per brick of F, the range of what its points read, with the apron (F's brick and
    its 26 neighbours in F; in C, the bricks its points land in and their neighbours), then
    unioned over the bricks each macrocell's points read, as for one level. F's range pass is
    read only where some brick reads F."""
    eff_lo, eff_hi = coarse_ranges_read(fine, coarse)
    f = level_of == 0
    if f.any():
        lo_f, hi_f = (np.asarray(v, np.float32) for v in fine.ranges())
        eff_lo[f] = around(lo_f, np.minimum)[f]
        eff_hi[f] = around(hi_f, np.maximum)[f]
    return brick_density_range_grid(eff_lo, eff_hi, fine.dims, fine.brick, cells)
