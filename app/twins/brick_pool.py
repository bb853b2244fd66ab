"""NumPy twin of glsl/lib/brick_pool.glsl: a volume cut into bricks of B voxels per axis, each
non-constant brick in a slot of an atlas with a one-voxel apron ((B + 2)^3 texels a slot), a page
table (a uint32 a brick: its slot, or CONSTANT | k for a brick whose voxels and apron all hold
constant k) and the table of constants (k = 0 is vacuum).

The layout (brick counts, slots, which bricks are constant) is app/io/bricks.py's, shared with the
store. `pack` builds the three from a whole array (what app/gl/brick_pool.py uploads brick by brick from
an app.bricks.BrickStore); `bricked_sample` and `bricked_voxel` read them as the shader does, and
equal app/twins/medium.py trilinear of the whole array (the seams included) within float rounding.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radiance_probes.io.brick_layout import (APRON, CONSTANT, CONSTANTS_WIDTH, DEFAULT_BRICK_SIZE,
                                             FREE_SLOT, LEVEL_SHIFT, REDIRECT, brick_counts,
                                             constant_bricks, constant_values, level_tables,
                                             slot_grid, slot_origin, slot_side)
from radiance_probes.twins.medium import trilinear

def brick_block(data: np.ndarray, b, brick: int) -> np.ndarray:
    """Brick b's (x, y, z) voxels with the apron: data [z, y, x(, c)] at indices b B - 1 ..
    b B + B along each axis, clamped to the volume (the edge voxel repeated)."""
    idx = [np.clip(np.arange(int(b[a]) * brick - APRON, int(b[a]) * brick + brick + APRON),
                   0, data.shape[2 - a] - 1) for a in range(3)]
    return data[np.ix_(idx[2], idx[1], idx[0])]


@dataclass
class Packed:
    """What the shader reads: the atlas [Z, Y, X(, C)], the page table [bz, by, bx] (uint32), the
    constants (K, 4) float32, and the layout."""
    atlas: np.ndarray
    table: np.ndarray
    constants: np.ndarray
    grid: tuple[int, int, int]       # slots per axis
    brick: int
    dims: tuple[int, int, int]       # the volume's voxels (x, y, z)
    brick_of_slot: np.ndarray        # the linear brick index a slot holds (FREE_SLOT: none)
    # Mixed levels: each level's dims (x, y, z; level 0 first) and the first z of its table
    # in `table` (level 0's at 0); () for one level.
    level_dims: tuple = ()
    level_table_z: tuple = ()

    @property
    def levels(self) -> int:
        return max(1, len(self.level_dims))

    @property
    def channels(self) -> int:
        return 1 if self.atlas.ndim == 3 else self.atlas.shape[3]

    def slot_texels(self, slot: np.ndarray) -> np.ndarray:
        """The first texel (x, y, z) of slots (...), as brick_slot_origin counts them."""
        sx, sy, _ = self.grid
        return np.stack([slot % sx, (slot // sx) % sy, slot // (sx * sy)], -1) * \
            slot_side(self.brick)

    def dims_of(self, level: int) -> tuple[int, int, int]:
        return self.dims if level == 0 else tuple(self.level_dims[level])

    def counts_of(self, level: int) -> tuple[int, int, int]:
        return brick_counts(self.dims_of(level), self.brick)

    def entry(self, b: np.ndarray, level) -> np.ndarray:
        """The page table's entries of bricks b (..., 3) (x, y, z) of `level` (an int or an array)."""
        z0 = (np.asarray(self.level_table_z, np.int64)[level] if self.level_table_z else 0)
        return self.table[b[..., 2] + z0, b[..., 1], b[..., 0]].astype(np.int64)


def brick_ranges(data: np.ndarray, brick: int) -> tuple[np.ndarray, np.ndarray]:
    """Each brick's own voxels' least and largest value: [bz, by, bx(, c)]."""
    nz, ny, nx = data.shape[:3]
    bx, by, bz = brick_counts((nx, ny, nz), brick)
    pad = [(0, bz * brick - nz), (0, by * brick - ny), (0, bx * brick - nx)] + \
        [(0, 0)] * (data.ndim - 3)
    full = np.pad(data, pad, mode="edge")
    shaped = full.reshape((bz, brick, by, brick, bx, brick) + data.shape[3:])
    return shaped.min(axis=(1, 3, 5)), shaped.max(axis=(1, 3, 5))


def pack(data: np.ndarray, brick: int, max_side: int = 2048) -> Packed:
    """The bricked form of data [z, y, x(, c)] (float32 densities): slots in page-table order."""
    data = np.asarray(data, np.float32)
    nz, ny, nx = data.shape[:3]
    dims = (nx, ny, nz)
    counts = brick_counts(dims, brick)
    lo, hi = brick_ranges(data, brick)
    constant = constant_bricks(lo, hi)
    constants, which = constant_values(lo, constant)
    resident = np.argwhere(~constant)            # (z, y, x), in linear brick order
    grid = slot_grid(len(resident), brick, max_side)
    side = slot_side(brick)
    atlas = np.zeros((grid[2] * side, grid[1] * side, grid[0] * side) + data.shape[3:], np.float32)
    table = np.where(constant, CONSTANT | np.maximum(which, 0), 0).astype(np.uint32)
    brick_of_slot = np.full(grid[0] * grid[1] * grid[2], FREE_SLOT, np.uint32)
    for slot, (z, y, x) in enumerate(resident):
        o = slot_origin(slot, grid) * side
        atlas[o[2]:o[2] + side, o[1]:o[1] + side, o[0]:o[0] + side] = \
            brick_block(data, (x, y, z), brick)
        table[z, y, x] = slot
        brick_of_slot[slot] = x + counts[0] * (y + counts[1] * z)
    return Packed(atlas, table, constants, grid, brick, dims, brick_of_slot)


def pack_levels(levels: list[np.ndarray], level_of_brick: np.ndarray, brick: int,
                max_side: int = 2048) -> Packed:
    """The mixed-level form: `levels` a pyramid's arrays [z, y, x(, c)] (level 0 the finest) in
    one world box, `level_of_brick` [bz0, by0, bx0] the level whose voxels each level-0 brick's
    points read. Level 0's bricks that read level 0, and every brick of a coarser level such a
    point lands in (app/io/bricks.py level_needs), are resident or constant; slots level by level."""
    levels = [np.asarray(a, np.float32) for a in levels]
    dims = [tuple(a.shape[:3][::-1]) for a in levels]
    described = []
    for data, d in zip(levels, dims):
        lo, hi = brick_ranges(data, brick)
        described.append((d, lo, constant_bricks(lo, hi)))
    table, constants, residents, table_z = level_tables(described, level_of_brick, brick)
    blocks, owners = [], []
    for level, (data, resident) in enumerate(zip(levels, residents)):
        c = brick_counts(dims[level], brick)
        for z, y, x in resident:
            blocks.append(brick_block(data, (x, y, z), brick))
            owners.append((level << LEVEL_SHIFT) | int(x + c[0] * (y + c[1] * z)))
    grid = slot_grid(len(blocks), brick, max_side)
    side = slot_side(brick)
    atlas = np.zeros((grid[2] * side, grid[1] * side, grid[0] * side) + levels[0].shape[3:],
                     np.float32)
    brick_of_slot = np.full(grid[0] * grid[1] * grid[2], FREE_SLOT, np.uint32)
    for slot, (block, owner) in enumerate(zip(blocks, owners)):
        o = slot_origin(slot, grid) * side
        atlas[o[2]:o[2] + side, o[1]:o[1] + side, o[0]:o[0] + side] = block
        brick_of_slot[slot] = owner
    return Packed(atlas, table, constants, grid, brick, dims[0], brick_of_slot,
                  tuple(dims), tuple(table_z))


def _redirect(packed: Packed, uvw: np.ndarray):
    """(level, t, b, entry) of each point: level 0's brick, or the level its entry sends it to."""
    dims = np.asarray(packed.dims, np.float64)
    t = np.clip(uvw * dims, 0.0, dims)
    b = np.clip(np.floor(t / packed.brick).astype(np.int64), 0,
                np.asarray(packed.counts_of(0)) - 1)
    entry = packed.entry(b, 0)
    level = np.zeros(entry.shape, np.int64)
    if packed.levels > 1:
        moved = (entry & (CONSTANT | REDIRECT)) == REDIRECT
        level[moved] = np.clip(entry[moved] & ~REDIRECT, 1, packed.levels - 1)
        for lv in range(1, packed.levels):
            at = level == lv
            if at.any():
                d = np.asarray(packed.dims_of(lv), np.float64)
                t[at] = np.clip(uvw[at] * d, 0.0, d)
                b[at] = np.clip(np.floor(t[at] / packed.brick).astype(np.int64), 0,
                                np.asarray(packed.counts_of(lv)) - 1)
                entry[at] = packed.entry(b[at], lv)
    return level, t, b, entry


def bricked_sample(packed: Packed, uvw: np.ndarray) -> np.ndarray:
    """lib/brick_pool.glsl bricked_sample at texture coordinates uvw (..., 3): (..., C)."""
    uvw = np.asarray(uvw, np.float64)
    _, t, b, entry = _redirect(packed, uvw)
    constant = (entry & CONSTANT) != 0
    channels = packed.channels
    out = np.empty(uvw.shape[:-1] + (channels,), np.float64)
    out[constant] = packed.constants[entry[constant] & ~CONSTANT][:, :channels]
    slot = np.where(constant, 0, entry)
    origin = packed.slot_texels(slot)
    coord = origin + APRON + (t - 0.5 - b * packed.brick)   # texel centres at integers
    resident = ~constant
    for c in range(channels):
        atlas = packed.atlas if packed.atlas.ndim == 3 else packed.atlas[..., c]
        out[resident, c] = trilinear(atlas, coord[resident])
    return out


def bricked_voxel(packed: Packed, v: np.ndarray) -> np.ndarray:
    """lib/brick_pool.glsl bricked_voxel at voxels v (..., 3) (x, y, z) inside the volume."""
    v = np.asarray(v, np.int64)
    b = np.clip(v // packed.brick, 0, np.asarray(brick_counts(packed.dims, packed.brick)) - 1)
    entry = packed.entry(b, 0)
    constant = (entry & CONSTANT) != 0
    slot = np.where(constant, 0, entry)
    origin = packed.slot_texels(slot)
    t = origin + APRON + v - b * packed.brick
    got = packed.atlas[t[..., 2], t[..., 1], t[..., 0]]
    channels = packed.channels
    got = got.reshape(v.shape[:-1] + (channels,)).astype(np.float64)
    got[constant] = packed.constants[entry[constant] & ~CONSTANT][:, :channels]
    return got


def bricked_voxel_range(packed: Packed, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """lib/brick_pool.glsl bricked_voxel_range at voxels v (..., 3): (least, largest), (..., C);
    (one level: the voxel's value twice)."""
    v = np.asarray(v, np.int64)
    channels = packed.channels
    b = np.clip(v // packed.brick, 0, np.asarray(packed.counts_of(0)) - 1)
    entry = packed.entry(b, 0)
    lo = np.empty(v.shape[:-1] + (channels,), np.float64)
    hi = np.empty_like(lo)
    moved = (entry & (CONSTANT | REDIRECT)) == REDIRECT
    here = ~moved
    if here.any():
        lo[here] = hi[here] = bricked_voxel(packed, v[here])
    # a level-0 voxel on its brick's faces: with its neighbours from the apron, since a cell
    # across the face is level 0's filtering of them on this side, whatever level the
    # neighbouring brick reads
    local = v - b * packed.brick
    face = here & ((entry & CONSTANT) == 0) & np.any((local == 0) | (local == packed.brick - 1), -1)
    if packed.levels > 1 and face.any():
        slot = entry[face]
        origin = packed.slot_texels(slot) + APRON + local[face]
        f_lo, f_hi = lo[face], hi[face]
        for off in np.ndindex(3, 3, 3):
            i = origin + np.asarray(off) - 1
            val = packed.atlas[i[:, 2], i[:, 1], i[:, 0]].reshape(len(i), channels)
            f_lo, f_hi = np.minimum(f_lo, val), np.maximum(f_hi, val)
        lo[face], hi[face] = f_lo, f_hi
    for lv in range(1, packed.levels):
        at = moved & (np.clip(entry & ~REDIRECT, 1, packed.levels - 1) == lv)
        if not at.any():
            continue
        d = np.asarray(packed.dims_of(lv), np.float64)
        t = (v[at] + 0.5) * d / np.asarray(packed.dims, np.float64)
        lb = np.clip(np.floor(t / packed.brick).astype(np.int64), 0,
                     np.asarray(packed.counts_of(lv)) - 1)
        e = packed.entry(lb, lv)
        const = (e & CONSTANT) != 0
        vals = np.empty((8,) + lo[at].shape, np.float64)
        slot = np.where(const, 0, e)
        origin = packed.slot_texels(slot) + APRON - lb * packed.brick
        first = np.floor(t - 0.5).astype(np.int64)
        for k, off in enumerate(np.ndindex(2, 2, 2)):
            w = np.clip(first + np.asarray(off[::-1]), lb * packed.brick - 1,
                        lb * packed.brick + packed.brick)
            i = origin + w
            vals[k] = packed.atlas[i[:, 2], i[:, 1], i[:, 0]].reshape(len(i), channels)
        vals[:, const] = packed.constants[e[const] & ~CONSTANT][:, :channels]
        lo[at], hi[at] = vals.min(0), vals.max(0)
    return lo, hi


def mixed_reference(levels: list[np.ndarray], level_of_brick: np.ndarray, brick: int,
                    uvw: np.ndarray) -> np.ndarray:
    """What a mixed pool means: at each point, the trilinear filtering (app/twins/medium.py) of
    the whole array of the level its level-0 brick reads, at uvw times that level's dims."""
    uvw = np.asarray(uvw, np.float64)
    dims0 = np.asarray(levels[0].shape[:3][::-1], np.float64)
    t0 = np.clip(uvw * dims0, 0.0, dims0)
    counts0 = np.asarray(brick_counts(dims0.astype(int), brick))
    b0 = np.clip(np.floor(t0 / brick).astype(np.int64), 0, counts0 - 1)
    which = level_of_brick[b0[:, 2], b0[:, 1], b0[:, 0]]
    channels = 1 if levels[0].ndim == 3 else levels[0].shape[3]
    out = np.empty((len(uvw), channels), np.float64)
    for lv, data in enumerate(levels):
        at = which == lv
        if not at.any():
            continue
        d = np.asarray(data.shape[:3][::-1], np.float64)
        coord = np.clip(uvw[at] * d, 0.0, d) - 0.5
        for c in range(channels):
            out[at, c] = trilinear(data if data.ndim == 3 else data[..., c], coord)
    return out
