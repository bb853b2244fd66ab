"""A bricked volume on the GPU (glsl/lib/brick_pool.glsl; NumPy twin app/twins/brick_pool.py):
the atlas of slots, the page table and the constants, written a row of slots at a time (the host
never needs the whole volume), and in the checking build the slot -> brick map it checks
against."""
from __future__ import annotations

import time

import moderngl
import numpy as np

from radiance_probes.io.brick_layout import (APRON, CONSTANTS_WIDTH, FREE_SLOT, brick_counts,
                                             slot_bytes, slot_origin, slot_side, texel_bytes)
from radiance_probes.scene.types import VolumeError
from radiance_probes.twins.brick_pool import Packed

# Texture units (0: the volume, here the atlas; 1 to 15: the passes' own, app/rendering/*.py).
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
                 table: np.ndarray, constants: np.ndarray, exact_uint8: bool, name: str = "volume",
                 level_dims=(), level_table_z=()):
        """`level_dims`, `level_table_z`: mixed levels (lib/brick_pool.glsl BRICK_LEVELS), each
        level's dims (level 0 first) and the first z of its table in `table`; () for one level."""
        self.ctx = ctx
        self.dims = tuple(int(v) for v in dims)
        self.level_dims = tuple(tuple(int(v) for v in d) for d in level_dims)
        self.level_table_z = tuple(int(z) for z in level_table_z)
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
        want = counts[::-1]
        if self.levels > 1:
            want = (sum(brick_counts(d, self.brick)[2] for d in self.level_dims),) + want[1:]
        if table.shape != want:
            raise ValueError(f"page table of shape {table.shape} for {want} bricks")
        self.table = ctx.texture3d(want[::-1], 1, table.tobytes(), dtype="u4")
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
        self.table_writes = 0  # page-table texels written after the pool was made (streaming)
        # a streamed mix (app/rendering/levels/level_stream.py): the PoolPlan it was made from, and the
        # LevelStream that changes it (made by the Renderer's resources on first use)
        self.plan = None
        self.stream = None

    @classmethod
    def from_packed(cls, ctx: moderngl.Context, packed: Packed, exact_uint8: bool = False):
        """The pool of app/twins/brick_pool.py pack (tests; the renderer writes bricks from a
        store)."""
        channels = 1 if packed.atlas.ndim == 3 else packed.atlas.shape[3]
        pool = cls(ctx, packed.dims, packed.brick, channels, packed.grid, packed.table,
                   packed.constants, exact_uint8, level_dims=packed.level_dims,
                   level_table_z=packed.level_table_z)
        side = slot_side(packed.brick)
        for slot, brick in enumerate(packed.brick_of_slot):
            if brick != FREE_SLOT:
                o = slot_origin(slot, packed.grid) * side
                pool.write_slot(slot, int(brick), packed.atlas[o[2]:o[2] + side,
                                                               o[1]:o[1] + side, o[0]:o[0] + side])
        return pool

    @property
    def levels(self) -> int:
        return max(1, len(self.level_dims))

    @property
    def atlas_bytes(self) -> int:
        return int(np.prod(self.grid)) * slot_bytes(self.brick, self.channels, self.exact_uint8)

    @property
    def nbytes(self) -> int:
        """GPU bytes: the atlas, the page table and the constants."""
        return self.atlas_bytes + 4 * int(np.prod(self.table.size)) + 16 * self.constant_count

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

    def write_table(self, entries) -> None:
        """Writes page-table texels: entries [(z, y, x, value)] (the table's z, levels stacked),
        one texel a write (a stream changes a few hundred at most)."""
        for z, y, x, value in entries:
            self.table.write(np.array([value], np.uint32).tobytes(),
                             viewport=(int(x), int(y), int(z), 1, 1, 1))
            self.table_writes += 1

    def set_constants(self, constants: np.ndarray) -> None:
        """The constants' texture made again for new rows (a stream reading F's range pass)."""
        constants = np.asarray(constants, np.float32).reshape(-1, 4)
        rows = -(-len(constants) // CONSTANTS_WIDTH)
        width = min(len(constants), CONSTANTS_WIDTH)
        padded = np.zeros((rows * width, 4), np.float32)
        padded[:len(constants)] = constants
        texture = self.ctx.texture((width, rows), 4, padded.tobytes(), dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.constants.release()
        self.constants, self.constant_count = texture, len(constants)

    def free_slots(self, slots) -> None:
        """Marks slots as holding no brick (the checking build's slot map)."""
        self.brick_of_slot[np.asarray(slots, np.int64)] = FREE_SLOT
        if self.slots_buffer is not None:
            self.slots_buffer.write(self.brick_of_slot.tobytes())

    def defines(self) -> dict:
        """What the passes that read it are compiled with (lib/brick_pool.glsl)."""
        return {"VOLUME_BRICKED": 1, **({"BRICK_LEVELS": self.levels} if self.levels > 1 else {})}

    def uniforms(self) -> dict:
        mixed = {}
        if self.levels > 1:
            mixed = {"brick_level_dims": [tuple(d) for d in self.level_dims],
                     "brick_level_counts": [brick_counts(d, self.brick) for d in self.level_dims],
                     "brick_level_table_z": list(self.level_table_z)}
        return {"brick_atlas": ATLAS_UNIT, "brick_table": TABLE_UNIT,
                "brick_constants": CONSTANTS_UNIT, "brick_volume_dims": self.dims,
                "brick_counts": brick_counts(self.dims, self.brick), "brick_size": self.brick,
                "brick_slots": self.grid, "brick_constant_count": self.constant_count, **mixed}

    def use(self) -> None:
        """Binds the atlas, the table and the constants (and in the checking build the slot map)."""
        self.atlas.use(ATLAS_UNIT)
        self.table.use(TABLE_UNIT)
        self.constants.use(CONSTANTS_UNIT)
        from radiance_probes.gl.checks import checks_for
        if checks_for(self.ctx) is not None:
            if self.slots_buffer is None:
                self.slots_buffer = self.ctx.buffer(self.brick_of_slot.tobytes())
            self.slots_buffer.bind_to_storage_buffer(BRICK_SLOTS_BINDING)

    def release(self) -> None:
        if self.stream is not None:
            self.stream.cancel()         # its readers stopped
            self.stream = None
        for obj in (self.atlas, self.table, self.constants, self.slots_buffer):
            if obj is not None:
                obj.release()
        self.slots_buffer = None


def empty_pool(ctx: moderngl.Context, plan, exact_uint8: bool) -> "BrickPool":
    """The pool of an app.bricks.PoolPlan with its page table and constants and no brick written
    yet."""
    pool = BrickPool(ctx, plan.dims, plan.brick, plan.channels, plan.grid, plan.table,
                     plan.constants, exact_uint8, plan.name, level_dims=plan.level_dims,
                     level_table_z=plan.level_table_z)
    if getattr(plan, "mix", None) is not None:
        pool.plan = plan
    return pool


def upload_plan(ctx: moderngl.Context, plan, exact_uint8: bool) -> "BrickPool":
    """A BrickPool holding the resident bricks of an app.bricks.PoolPlan (each read once, its
    apron from its neighbours; constant bricks are not read), written a run of slots of a row at
    a time (PoolPlan.rows)."""
    start = time.perf_counter()
    pool = empty_pool(ctx, plan, exact_uint8)
    try:
        for first, bricks, block in plan.rows():
            pool.write_slots(first, bricks, block)
        pool.upload_seconds = time.perf_counter() - start
    except BaseException:
        pool.release()
        raise
    assert np.count_nonzero(pool.brick_of_slot != FREE_SLOT) == plan.resident
    return pool


def upload_store(ctx: moderngl.Context, store, exact_uint8: bool, max_side: int) -> "BrickPool":
    """A BrickPool holding every brick of an app.bricks.BrickStore that is not constant."""
    return upload_plan(ctx, store.pool_plan(max_side), exact_uint8)
