"""NumPy twin of glsl/lib/brick_pool.glsl: a volume cut into bricks of B voxels per axis, each
non-constant brick in a slot of an atlas with a one-voxel apron ((B + 2)^3 texels a slot), a page
table (a uint32 a brick: its slot, or CONSTANT | k for a brick whose voxels and apron all hold
constant k) and the table of constants (k = 0 is vacuum).

The layout (brick counts, slots, which bricks are constant) is app/bricks.py's, shared with the
store. `pack` builds the three from a whole array (what app/gl/brick_pool.py uploads brick by brick from
an app.bricks.BrickStore); `bricked_sample` and `bricked_voxel` read them as the shader does, and
equal app/twins/medium.py trilinear of the whole array (the seams included) within float rounding.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bricks import (APRON, CONSTANT, CONSTANTS_WIDTH, DEFAULT_BRICK_SIZE,  # noqa: F401
                      FREE_SLOT, brick_counts, constant_bricks, constant_values, slot_grid,
                      slot_origin, slot_side)
from .medium import trilinear

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


def bricked_sample(packed: Packed, uvw: np.ndarray) -> np.ndarray:
    """lib/brick_pool.glsl bricked_sample at texture coordinates uvw (..., 3): (..., C)."""
    uvw = np.asarray(uvw, np.float64)
    dims = np.asarray(packed.dims, np.float64)
    t = np.clip(uvw * dims, 0.0, dims)
    b = np.clip(np.floor(t / packed.brick).astype(np.int64), 0, np.asarray(
        brick_counts(packed.dims, packed.brick)) - 1)
    entry = packed.table[b[..., 2], b[..., 1], b[..., 0]].astype(np.int64)
    constant = (entry & CONSTANT) != 0
    channels = 1 if packed.atlas.ndim == 3 else packed.atlas.shape[3]
    out = np.empty(uvw.shape[:-1] + (channels,), np.float64)
    out[constant] = packed.constants[entry[constant] & ~CONSTANT][:, :channels]
    slot = np.where(constant, 0, entry)
    origin = np.stack([slot % packed.grid[0], (slot // packed.grid[0]) % packed.grid[1],
                       slot // (packed.grid[0] * packed.grid[1])], -1) * slot_side(packed.brick)
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
    entry = packed.table[b[..., 2], b[..., 1], b[..., 0]].astype(np.int64)
    constant = (entry & CONSTANT) != 0
    slot = np.where(constant, 0, entry)
    origin = np.stack([slot % packed.grid[0], (slot // packed.grid[0]) % packed.grid[1],
                       slot // (packed.grid[0] * packed.grid[1])], -1) * slot_side(packed.brick)
    t = origin + APRON + v - b * packed.brick
    got = packed.atlas[t[..., 2], t[..., 1], t[..., 0]]
    channels = 1 if packed.atlas.ndim == 3 else packed.atlas.shape[3]
    got = got.reshape(v.shape[:-1] + (channels,)).astype(np.float64)
    got[constant] = packed.constants[entry[constant] & ~CONSTANT][:, :channels]
    return got
