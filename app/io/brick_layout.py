"""A bricked volume's layout: brick counts, atlas slots and their grid, the page table's codes
(constant, redirect, unmapped), which bricks a level's points reach, the levels' tables, constant
bricks and their values, and the bytes a slot takes. Pure arithmetic on arrays; no reading."""
from __future__ import annotations

import numpy as np


APRON = 1


CONSTANT = 0x80000000


REDIRECT = 0x40000000    # level 0's page table: | the coarser level that holds the brick's points


UNMAPPED = 0x3FFFFFFF    # a coarser level's brick no point reads (a slot past any atlas)


LEVEL_SHIFT = 28         # brick_of_slot: level << LEVEL_SHIFT | the brick's index in its level


DEFAULT_BRICK_SIZE = 64


FREE_SLOT = 0xFFFFFFFF   # brick_of_slot of a slot that holds no brick (the checking build)


CONSTANTS_WIDTH = 1024   # the constants' texture is this wide (k at (k % width, k // width))


def brick_counts(dims, brick: int) -> tuple[int, int, int]:
    """Bricks per axis (x, y, z) of a volume of dims (x, y, z) voxels."""
    return tuple(int(-(-int(n) // brick)) for n in dims)


def slot_side(brick: int) -> int:
    return brick + 2 * APRON


def slot_grid(slots: int, brick: int, max_side: int) -> tuple[int, int, int]:
    """Slots per axis (x, y, z) of an atlas holding at least `slots` slots (one at least), each
    axis within max_side texels, as near a cube as allows; ValueError where it cannot."""
    side = slot_side(brick)
    per_axis = max_side // side
    if per_axis < 1:
        raise ValueError(f"a brick of {brick} voxels ({side} texels with its apron) exceeds the "
                         f"3D texture side of {max_side}")
    n = max(int(slots), 1)
    sx = min(per_axis, int(np.ceil(n ** (1.0 / 3.0) - 1e-9)))
    sy = min(per_axis, int(np.ceil(np.sqrt(n / sx) - 1e-9)))
    sz = -(-n // (sx * sy))
    if sz > per_axis:
        raise ValueError(f"{n} bricks of {brick}^3 voxels need more slots than one 3D texture of "
                         f"{max_side}^3 texels holds ({per_axis ** 3})")
    return sx, sy, sz


def bricks_reached(dims0, dims, brick: int, lo0, hi0) -> tuple[np.ndarray, np.ndarray]:
    """The bricks (x, y, z; first and last, inclusive) of a level of `dims` voxels that points of
    level-0 bricks lo0 .. hi0 (inclusive, per axis) land in, where lib/brick_pool.glsl maps a
    point to uvw times a level's dims: a hair wider either side, for the float rounding."""
    d0 = np.asarray(dims0, np.float64)
    d = np.asarray(dims, np.float64)
    counts = np.asarray(brick_counts(dims, brick))
    lo = np.floor((np.asarray(lo0) * brick * d / d0 - 1e-3) / brick).astype(np.int64)
    hi = np.floor((np.minimum((np.asarray(hi0) + 1) * brick, d0) * d / d0 + 1e-3) / brick)
    return np.clip(lo, 0, counts - 1), np.clip(hi.astype(np.int64), 0, counts - 1)


def level_needs(level_of_brick: np.ndarray, level: int, dims0, dims, brick: int) -> np.ndarray:
    """[bz, by, bx] of a coarser level: True where a point of a level-0 brick that level holds
    (level_of_brick [bz0, by0, bx0] == level) lands."""
    counts = brick_counts(dims, brick)
    need = np.zeros(counts[::-1], bool)
    for z, y, x in np.argwhere(level_of_brick == level):
        lo, hi = bricks_reached(dims0, dims, brick, (x, y, z), (x, y, z))
        need[lo[2]:hi[2] + 1, lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] = True
    return need


def level_tables(levels, level_of_brick: np.ndarray, brick: int):
    """The page tables of a pool of mixed levels (lib/brick_pool.glsl BRICK_LEVELS), stacked
    along z, level 0's first; `levels` [(dims, each brick's least value [bz, by, bx(, c)], its
    constant mask)] finest first, `level_of_brick` [bz0, by0, bx0] the level each level-0 brick's
    points read. The bricks a level holds (level 0's that read it; a coarser level's that such
    points land in, level_needs) are constant (a row of the constants, each level's after the
    earlier levels') or resident (slots level by level, in layer order); a level-0 brick that
    reads level l holds REDIRECT | l, any other entry UNMAPPED. Returns (table, constants, each
    level's resident bricks (n, 3) z, y, x, each level's first z in the table)."""
    dims0 = levels[0][0]
    counts = [brick_counts(d, brick) for d, _, _ in levels]
    bx0, by0, _ = counts[0]
    table_z = [int(z) for z in np.cumsum([0] + [c[2] for c in counts[:-1]])]
    table = np.full((sum(c[2] for c in counts), by0, bx0), UNMAPPED, np.uint32)
    constants, residents, slots = [], [], 0
    for level, ((dims, lo, constant), c) in enumerate(zip(levels, counts)):
        need = (level_of_brick == 0) if level == 0 else level_needs(level_of_brick, level, dims0,
                                                                      dims, brick)
        part = table[table_z[level]:table_z[level] + c[2], :c[1], :c[0]]
        rows, which = constant_values(lo, constant & need)
        part[constant & need] = CONSTANT | (which[constant & need] + sum(map(len, constants)))
        constants.append(rows)
        resident = np.argwhere(need & ~constant)
        part[tuple(resident.T)] = np.arange(slots, slots + len(resident), dtype=np.uint32)
        slots += len(resident)
        residents.append(resident)
    moved = level_of_brick > 0
    table[:counts[0][2]][moved] = REDIRECT | level_of_brick[moved]
    return table, np.concatenate(constants), residents, table_z


def slot_origin(slot: int, grid) -> np.ndarray:
    """First texel (x, y, z) of a slot, counted as lib/brick_pool.glsl brick_slot_origin does
    (units of slots; times slot_side for texels)."""
    sx, sy, _ = grid
    return np.array([slot % sx, (slot // sx) % sy, slot // (sx * sy)], np.int64)


def around(a: np.ndarray, op) -> np.ndarray:
    """[bz, by, bx(, ...)]: op (np.minimum, np.maximum, np.logical_or, ...) over each brick and
    the 26 neighbours its apron reaches (clamped at the faces)."""
    p = np.pad(a, [(1, 1)] * 3 + [(0, 0)] * (a.ndim - 3), mode="edge")
    out = a.copy()
    nz, ny, nx = a.shape[:3]
    for dz, dy, dx in np.ndindex(3, 3, 3):
        out = op(out, p[dz:dz + nz, dy:dy + ny, dx:dx + nx])
    return out


def constant_bricks(brick_min: np.ndarray, brick_max: np.ndarray) -> np.ndarray:
    """[bz, by, bx] True where a brick and its apron certainly hold one value: the brick and
    every neighbour its apron reaches (26, clamped at the faces) each hold one value, the same.
    brick_min/max: each brick's own voxels' least and largest value, [bz, by, bx(, c)]."""
    lo = np.asarray(brick_min, np.float64)
    hi = np.asarray(brick_max, np.float64)
    if lo.ndim == 3:
        lo, hi = lo[..., None], hi[..., None]
    one = np.all(lo == hi, axis=-1)
    return around(one, np.logical_and) & np.all(around(lo, np.minimum) == around(lo, np.maximum),
                                                axis=-1)


def constant_values(brick_min: np.ndarray, constant: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The constants' table (K, 4) (row 0 vacuum, then each distinct value once) and each
    constant brick's row ([bz, by, bx], -1 elsewhere)."""
    lo = np.asarray(brick_min, np.float32)
    if lo.ndim == 3:
        lo = lo[..., None]
    rows = [np.zeros(4, np.float32)]
    index: dict[bytes, int] = {rows[0].tobytes(): 0}
    which = np.full(constant.shape, -1, np.int64)
    for z, y, x in zip(*np.nonzero(constant)):
        value = np.zeros(4, np.float32)
        value[:lo.shape[-1]] = lo[z, y, x]
        key = value.tobytes()
        if key not in index:
            index[key] = len(rows)
            rows.append(value)
        which[z, y, x] = index[key]
    return np.stack(rows), which


def texel_bytes(channels: int, exact_uint8: bool) -> int:
    """Bytes of one atlas texel: R16 (a component a channel) for exact 8-bit data, else R32F,
    as the one-texture volume (app/gl/textures.py volume_texture)."""
    return (2 if exact_uint8 else 4) * channels


def slot_bytes(brick: int, channels: int, exact_uint8: bool) -> int:
    return slot_side(brick) ** 3 * texel_bytes(channels, exact_uint8)
