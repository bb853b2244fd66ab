"""A bricked volume on the GPU (glsl/lib/brick_pool.glsl; NumPy twin app/twins/brick_pool.py):
the atlas of slots, the page table and the constants, written a row of slots at a time (the host
never needs the whole volume), and in the checking build the slot -> brick map it checks
against."""
from __future__ import annotations

import threading
import time

import moderngl
import numpy as np

from ..bricks import (APRON, CONSTANTS_WIDTH, FREE_SLOT, brick_counts, slot_bytes,  # noqa: F401
                      slot_origin, slot_side, texel_bytes)
from ..scene_types import VolumeError
from ..twins.brick_pool import Packed

# Texture units (0: the volume, here the atlas; 1 to 15: the passes' own, app/render/*.py).
ATLAS_UNIT = 0
TABLE_UNIT = 16
CONSTANTS_UNIT = 17
BRICK_SLOTS_BINDING = 10    # lib/brick_pool.glsl, the checking build only


def atlas_payload(block: np.ndarray, exact_uint8: bool) -> bytes:
    """A block of normalised densities as the atlas stores them (volume_texture's encoding)."""
    return atlas_texels(block, exact_uint8).tobytes()


def atlas_texels(block: np.ndarray, exact_uint8: bool) -> np.ndarray:
    """atlas_payload as a C-contiguous array (what the writes hand to Texture3D.write, which
    reads its buffer: no copy to bytes; float32 densities pass as they are)."""
    if exact_uint8:
        return (np.round(block * 255.0).astype(np.uint16) * 257).astype(np.uint16)
    return np.ascontiguousarray(block, np.float32)


class BrickPool:
    """The atlas (grid slots of (B + 2)^3 texels), the page table and the constants."""

    def __init__(self, ctx: moderngl.Context, dims, brick: int, channels: int, grid,
                 table: np.ndarray, constants: np.ndarray, exact_uint8: bool, name: str = "volume"):
        self.ctx = ctx
        self.dims = tuple(int(v) for v in dims)
        self.brick = int(brick)
        self.channels = int(channels)
        self.grid = tuple(int(v) for v in grid)
        self.exact_uint8 = bool(exact_uint8)
        side = slot_side(self.brick)
        size = tuple(g * side for g in self.grid)
        ctx.error
        try:
            self.atlas = ctx.texture3d(size, self.channels, dtype="nu2" if exact_uint8 else "f4",
                                       alignment=1)
        except moderngl.Error as exc:
            raise VolumeError(f"{name}: cannot create the {size} brick atlas ({exc})") from None
        err = ctx.error
        if err != "GL_NO_ERROR":
            self.atlas.release()
            raise VolumeError(f"{name}: the {size} brick atlas "
                              f"({self.atlas_bytes / 2**20:.0f} MiB): OpenGL error {err}")
        self.atlas.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.atlas.repeat_x = self.atlas.repeat_y = self.atlas.repeat_z = False
        table = np.ascontiguousarray(table, np.uint32)
        counts = brick_counts(self.dims, self.brick)
        if table.shape != counts[::-1]:
            raise ValueError(f"page table of shape {table.shape} for {counts[::-1]} bricks")
        self.table = ctx.texture3d(counts, 1, table.tobytes(), dtype="u4")
        self.table.filter = (moderngl.NEAREST, moderngl.NEAREST)
        constants = np.asarray(constants, np.float32).reshape(-1, 4)
        self.constant_count = len(constants)
        rows = -(-len(constants) // CONSTANTS_WIDTH)
        width = min(len(constants), CONSTANTS_WIDTH)
        padded = np.zeros((rows * width, 4), np.float32)
        padded[:len(constants)] = constants
        self.constants = ctx.texture((width, rows), 4, padded.tobytes(), dtype="f4")
        self.constants.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.brick_of_slot = np.full(int(np.prod(self.grid)), FREE_SLOT, np.uint32)
        self.slots_buffer = None
        self.uploads = 0      # bricks written (tests count them)
        self.writes = 0       # Texture3D.write calls of the atlas (a row of slots each, at most)
        self.write_seconds = 0.0  # in them
        self.upload_seconds = None   # upload_store's, all of it

    @classmethod
    def from_packed(cls, ctx: moderngl.Context, packed: Packed, exact_uint8: bool = False):
        """The pool of app/twins/brick_pool.py pack (tests; the renderer writes bricks from a
        store)."""
        channels = 1 if packed.atlas.ndim == 3 else packed.atlas.shape[3]
        pool = cls(ctx, packed.dims, packed.brick, channels, packed.grid, packed.table,
                   packed.constants, exact_uint8)
        side = slot_side(packed.brick)
        for slot, brick in enumerate(packed.brick_of_slot):
            if brick != FREE_SLOT:
                o = slot_origin(slot, packed.grid) * side
                pool.write_slot(slot, int(brick), packed.atlas[o[2]:o[2] + side,
                                                               o[1]:o[1] + side, o[0]:o[0] + side])
        return pool

    @property
    def atlas_bytes(self) -> int:
        return int(np.prod(self.grid)) * slot_bytes(self.brick, self.channels, self.exact_uint8)

    @property
    def nbytes(self) -> int:
        """GPU bytes: the atlas, the page table and the constants."""
        return self.atlas_bytes + 4 * int(np.prod(brick_counts(self.dims, self.brick))) + \
            16 * self.constant_count

    def write_slot(self, slot: int, brick: int, block: np.ndarray) -> None:
        """Writes brick `brick` (linear index) with its apron ((B + 2)^3 [z, y, x(, c)]) to slot."""
        self.write_slots(slot, [brick], block)

    def write_slots(self, first: int, bricks, block: np.ndarray) -> None:
        """Writes bricks (linear indices) with their aprons to the slots first, first + 1, ... of
        one row of slots (along x): block [B + 2, B + 2, k (B + 2)(, c)], the k bricks side by
        side along x; one Texture3D.write."""
        side = slot_side(self.brick)
        k = len(bricks)
        o = slot_origin(first, self.grid)
        if block.shape[:3] != (side, side, k * side) or k < 1 or o[0] + k > self.grid[0]:
            raise ValueError(f"block of shape {block.shape} for {k} bricks from slot {first} "
                             f"(rows of {self.grid[0]} slots of {side}^3 texels)")
        o = o * side
        start = time.perf_counter()
        self.atlas.write(atlas_texels(block, self.exact_uint8),
                         viewport=(int(o[0]), int(o[1]), int(o[2]), k * side, side, side),
                         alignment=1)
        self.write_seconds += time.perf_counter() - start
        self.writes += 1
        self.brick_of_slot[first:first + k] = bricks
        self.uploads += k
        if self.slots_buffer is not None:
            self.slots_buffer.write(self.brick_of_slot.tobytes())

    def uniforms(self) -> dict:
        return {"brick_atlas": ATLAS_UNIT, "brick_table": TABLE_UNIT,
                "brick_constants": CONSTANTS_UNIT, "brick_volume_dims": self.dims,
                "brick_counts": brick_counts(self.dims, self.brick), "brick_size": self.brick,
                "brick_slots": self.grid, "brick_constant_count": self.constant_count}

    def use(self) -> None:
        """Binds the atlas, the table and the constants (and in the checking build the slot map)."""
        self.atlas.use(ATLAS_UNIT)
        self.table.use(TABLE_UNIT)
        self.constants.use(CONSTANTS_UNIT)
        from .checks import checks_for
        if checks_for(self.ctx) is not None:
            if self.slots_buffer is None:
                self.slots_buffer = self.ctx.buffer(self.brick_of_slot.tobytes())
            self.slots_buffer.bind_to_storage_buffer(BRICK_SLOTS_BINDING)

    def release(self) -> None:
        for obj in (self.atlas, self.table, self.constants, self.slots_buffer):
            if obj is not None:
                obj.release()
        self.slots_buffer = None


def upload_store(ctx: moderngl.Context, store, exact_uint8: bool, max_side: int) -> "BrickPool":
    """A BrickPool holding every brick of an app.bricks.BrickStore that is not constant (each read
    once more, its apron from its neighbours: BrickStore.write_resident; constant bricks are not
    read), written a row of slots at a time (_SlotRows)."""
    start = time.perf_counter()
    table, constants, grid, resident = store.layout(max_side)
    pool = BrickPool(ctx, store.dims, store.brick, store.channels, grid, table, constants,
                     exact_uint8, store.name)
    try:
        rows = _SlotRows(pool, store, table, resident)
        layers = store.write_resident(resident, rows.dest, densities=True)
        try:
            for z, _ in layers:
                rows.write_through(z)
        finally:
            layers.close()      # its readers stopped and their shared memory unlinked now
        assert not rows.staged
        pool.upload_seconds = time.perf_counter() - start
    except BaseException:
        pool.release()
        raise
    assert np.count_nonzero(pool.brick_of_slot != FREE_SLOT) == len(resident)
    return pool


class _SlotRows:
    """The atlas's rows of slots, gathered on the host: the resident bricks take consecutive
    slots in layer order (BrickStore.layout), a row of the slot grid (grid x slots along x) at a
    time, so a row's bricks are assembled side by side into one array ([B + 2, B + 2,
    grid x (B + 2)(, c)], the assembling threads writing each brick in its place) and the row is
    written with one Texture3D.write once the layer of its last brick is done: grid x times fewer
    writes than a brick a write, each of rows grid x times longer, and no copy of a brick on its
    way (the assembly writes the texels the texture reads)."""

    def __init__(self, pool: BrickPool, store, table: np.ndarray, resident: np.ndarray):
        self.pool = pool
        self.table = table
        self.side = slot_side(pool.brick)
        self.per_row = pool.grid[0]
        self.extra = (pool.channels,) if pool.channels > 1 else ()
        bx, by, _ = store.counts
        resident = np.asarray(resident, np.int64).reshape(-1, 3)
        self.count = len(resident)
        self.linear = resident[:, 2] + bx * (resident[:, 1] + by * resident[:, 0])
        rows = -(-self.count // self.per_row)
        last = np.minimum((np.arange(rows) + 1) * self.per_row, self.count) - 1
        self.last_layer = resident[last, 0] if rows else np.zeros(0, np.int64)
        self.next_row = 0
        self.staged: dict[int, np.ndarray] = {}
        self.lock = threading.Lock()

    def dest(self, z: int, y: int, x: int) -> np.ndarray:
        """Where brick (z, y, x) goes: its place in its row's array (made on first use)."""
        row, i = divmod(int(self.table[z, y, x]), self.per_row)
        with self.lock:
            staged = self.staged.get(row)
            if staged is None:
                k = min(self.per_row, self.count - row * self.per_row)
                staged = np.empty((self.side, self.side, k * self.side) + self.extra, np.float32)
                self.staged[row] = staged
        return staged[:, :, i * self.side:(i + 1) * self.side]

    def write_through(self, z: int) -> None:
        """Writes, in order, every row whose bricks all lie in layers up to z (all written)."""
        while self.next_row < len(self.last_layer) and self.last_layer[self.next_row] <= z:
            row = self.next_row
            first = row * self.per_row
            with self.lock:
                staged = self.staged.pop(row)
            k = staged.shape[2] // self.side
            self.pool.write_slots(first, self.linear[first:first + k], staged)
            self.next_row += 1
