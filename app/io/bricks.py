"""Bricked volumes on the host: a BrickStore reads a volume's bricks (from an array in memory or a
Zarr array, never the whole array at once), keeps each brick's least and largest density (read
once), and writes the bricks that are not constant into a brick pool (app/gl/brick_pool.py); and
the levels a memory cap chooses between (a 2x box-filtered pyramid, or an OME-Zarr store's own).

Reading: the range pass reads a layer of bricks (B voxels along z, the whole y and x) at a time,
several layers at once on threads (Zarr's decoders and NumPy's reductions run outside the GIL), so
each of a store's chunks is decoded once a pass. A Zarr store's bricks whose chunks were never
written (Zarr leaves out a chunk equal to the fill value; its store listed once, stored_chunks)
are not read: each holds the fill value alone; a layer holding some is read as runs along x of its
written bricks. The upload pass reads only the bricks that are not constant and hold more than
one value, each once, as runs along x without aprons (chunk-aligned: a pencil with its apron would
decode the 3 x 3 rows of chunks around it, 9 times the data); each brick's apron is assembled from
its neighbours' voxels: those read, or a brick of one value's value (a constant brick, the brick
and its apron one value, is never read again nor uploaded). The upload's readers map the bricks to
densities themselves, and readers in processes hand them over in shared memory (_CoreReader), not
pickled. `reads` counts, per brick, how many times its voxels were read."""
from __future__ import annotations

import math
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from radiance_probes.scene.types import VolumeError
from radiance_probes.io.brick_layout import (CONSTANT, LEVEL_SHIFT, around, brick_counts,
                                             constant_bricks, constant_values, slot_bytes,
                                             slot_grid, slot_side)
from radiance_probes.io import brick_reading as reading
from radiance_probes.io.brick_reading import (SLAB_THREADS, _CoreReader, _layer_ranges_of, _spawn,
                                              reader_threads)
from radiance_probes.io.brick_sources import source_whole


class BrickStore:
    """A volume's bricks of `brick` voxels per axis, from a source with read(z0, z1, y0, y1, x0,
    x1) -> [z, y, x(, c)] densities."""

    def __init__(self, source, brick: int, name: str = "volume"):
        self.source = source
        self.brick = int(brick)
        self.name = name
        nz, ny, nx = source.shape[:3]
        self.dims = (int(nx), int(ny), int(nz))
        self.channels = 1 if len(source.shape) == 3 else int(source.shape[3])
        self.counts = brick_counts(self.dims, self.brick)
        bx, by, bz = self.counts
        self.reads = np.zeros((bz, by, bx), np.int64)
        self._ranges = None
        # where the reads' time went (lab/experiments/brick_bench.py records it): the range pass's
        # wall seconds; the upload's reading and mapping (summed over the readers) and the
        # waits of the caller's thread for the readers and the assembling threads
        self.seconds: dict[str, float] = {}
        # layers of bricks the upload's reading processes handed over: in shared memory, pickled
        self.handed = {"shared": 0, "pickled": 0}

    def pencil(self, bz: int, by: int, x0: int, x1: int, apron: int) -> np.ndarray:
        """The raw voxels of bricks x0 .. x1 - 1 of row (by, bz), with `apron` voxels around,
        clamped to the volume (the edge voxel repeated): the plain read that resident_layers'
        assembled bricks equal (tests/test_bricks.py compares them); the upload does not use it,
        since a read with aprons decodes the rows of chunks around it too."""
        nx, ny, nz = self.dims
        B = self.brick
        lo = [bz * B - apron, by * B - apron, x0 * B - apron]
        hi = [bz * B + B + apron, by * B + B + apron, x1 * B + apron]
        n = (nz, ny, nx)
        cl = [min(max(l, 0), m - 1) for l, m in zip(lo, n)]
        ch = [max(min(h, m), c + 1) for h, m, c in zip(hi, n, cl)]
        block = self.source.read(cl[0], ch[0], cl[1], ch[1], cl[2], ch[2])
        pad = [(c - l, h - d) for l, c, h, d in zip(lo, cl, hi, ch)] + [(0, 0)] * (block.ndim - 3)
        if any(p != (0, 0) for p in pad):
            block = np.pad(block, pad, mode="edge")
        self.reads[bz, by, x0:x1] += 1
        return block

    def raw_extremes(self) -> tuple[np.ndarray, np.ndarray]:
        """Each channel's least and largest raw value over the volume ([c] each), from the range
        pass (read now where it was not yet)."""
        lo, hi = self.raw_ranges()
        return (lo.reshape(-1, self.channels).min(axis=0),
                hi.reshape(-1, self.channels).max(axis=0))

    @property
    def ranges_read(self) -> bool:
        """Whether the range pass has been read (raw_ranges reads it the first time)."""
        return self._ranges is not None

    def ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Each brick's least and largest density [bz, by, bx(, c)]: the raw ones as densities
        (the mapping is monotonic, so the least raw value's density is the least density)."""
        lo, hi = self.raw_ranges()
        return self.source.density(lo), self.source.density(hi)

    def raw_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Each brick's least and largest raw value [bz, by, bx(, c)] (one read of every brick,
        the first time: a layer of bricks a read, layers on threads; a Zarr store's bricks whose
        chunks were never written are not read: each holds the fill value alone)."""
        if self._ranges is None:
            start = time.perf_counter()
            bx, by, bz = self.counts
            found = getattr(self.source, "unwritten_bricks", None)
            unwritten, fill = (found(self.brick) if found else None) or (None, None)
            self._add_seconds("chunk_listing", start)
            rows = [None if unwritten is None else unwritten[z] for z in range(bz)]
            band = self._band_rows()
            if self._in_processes():
                # a Zarr store's reads decode on one event loop, under the GIL (0.5 GB/s at best
                # on the H100's host whatever the threads): separate processes read the layers
                with ProcessPoolExecutor(reading.reader_processes(), mp_context=_spawn()) as pool:
                    layers = list(pool.map(_layer_ranges_of, [self.source] * bz, range(bz),
                                           [self.brick] * bz, [self.counts] * bz,
                                           [self.dims] * bz, rows, [fill] * bz, [band] * bz))
            else:
                with ThreadPoolExecutor(reader_threads()) as pool:
                    layers = list(pool.map(
                        lambda z: _layer_ranges_of(self.source, z, self.brick, self.counts,
                                                   self.dims, rows[z], fill, band), range(bz)))
            self.reads += np.stack([layer[2] for layer in layers])
            lo = np.stack([layer[0] for layer in layers])
            hi = np.stack([layer[1] for layer in layers])
            self._ranges = (lo, hi)
            self._add_seconds("range_pass", start)
        return self._ranges

    def _band_rows(self) -> int:
        """Rows of bricks (along y) whose voxels begin and end on the source's chunks' rows
        (the fewest): a layer's written bricks are read a band of rows at a time, so that no
        chunk is decoded twice in a layer (1 where the source says nothing of chunks)."""
        chunks = getattr(self.source, "chunks", None)
        if chunks is None:
            return 1
        return min(math.lcm(self.brick, int(chunks[1])) // self.brick, self.counts[1])

    def _in_processes(self) -> bool:
        """Whether the range pass reads in processes: a source that can be sent to one (a Zarr
        array, not an array in memory) and large enough to repay starting them (about 1 s)."""
        nz, ny, nx = self.source.shape[:3]
        return (getattr(self.source, "process_safe", False) and reading.reader_processes() > 1
                and nz * ny * nx * self.channels >= reading.PROCESS_READ_VOXELS)

    def resident_layers(self, resident: np.ndarray, densities: bool = False):
        """For each layer z holding bricks that are not constant, in order: (z, (y, x), the
        voxels of each such brick with its apron [B + 2, B + 2, B + 2(, c)]); `densities`: as
        densities (the source's mapping, applied where the bricks are read). write_resident's
        bricks, each in an array of its own (the upload writes them into its rows of slots)."""
        side = slot_side(self.brick)
        values = (self.ranges() if densities else self.raw_ranges())[0]
        blocks: dict = {}

        def dest(z: int, y: int, x: int) -> np.ndarray:
            blocks[(z, y, x)] = block = np.empty((side,) * 3 + values.shape[3:], values.dtype)
            return block

        for z, bricks in self.write_resident(resident, dest, densities):
            for y, x in bricks:
                yield z, (y, x), blocks.pop((z, y, x))

    def write_resident(self, resident: np.ndarray, dest, densities: bool = False):
        """Writes each brick of `resident` ((z, y, x) rows) with its apron into dest(z, y, x) (an
        array [B + 2, B + 2, B + 2(, c)] it returns; called on the assembling threads) and yields
        (z, the layer's bricks [(y, x)] in np.argwhere order) for each layer z holding some, in
        order, once its bricks and every earlier layer's are written. `densities`: mapped by the
        source (app/io/volume.py normalise) where they are read. Every brick that is not constant is
        read once (runs along x, no apron, layers ahead in processes or on threads; from
        processes through shared memory, _CoreReader), but for one of a single value (its
        least, from the range pass); an apron voxel is its neighbour's: read, or a brick of one
        value's value, or at the volume's faces the edge voxel repeated (as clamped texture
        coordinates read it)."""
        bx, by, bz = self.counts
        values = (self.ranges() if densities else self.raw_ranges())[0]
        is_resident = np.zeros((bz, by, bx), bool)
        if len(resident):
            is_resident[tuple(np.asarray(resident).T)] = True
        layers_wanted = [int(z) for z in np.nonzero(is_resident.any(axis=(1, 2)))[0]]
        need = sorted({n for z in layers_wanted for n in (z - 1, z, z + 1) if 0 <= n < bz})
        # the cores read: the resident bricks' and their neighbours' that hold more than one
        # value (with mixed levels a neighbour may vary and yet not be resident at this level;
        # with one level every brick not resident is constant, and none is added). A brick of
        # one value (resident where a neighbour varies: a Zarr store's unwritten brick next to
        # a written one, say) is not read: its voxels are that value, as its apron is for its
        # neighbours
        lo, hi = self.raw_ranges()
        uniform = np.all((lo == hi).reshape(lo.shape[:3] + (-1,)), axis=-1)
        read = around(is_resident, np.logical_or) & ~uniform
        reader = _CoreReader(self, read, densities, values)
        try:
            with ThreadPoolExecutor(SLAB_THREADS) as assemble:
                pending = []                        # (z, its bricks, its assembly's future)
                for z in layers_wanted:
                    for n in need:       # the layers it reads, then layers read ahead
                        if n <= z + reader.ahead:
                            reader.submit(n)
                    near = {n: reader.cores(n) for n in (z - 1, z, z + 1) if 0 <= n < bz}
                    bricks = [(int(y), int(x)) for y, x in np.argwhere(is_resident[z])]
                    pending.append((z, bricks, assemble.submit(
                        self._assemble, z, bricks, near, values, dest)))
                    del near
                    while len(pending) > SLAB_THREADS or (pending and z == layers_wanted[-1]):
                        done_z, bricks, future = pending.pop(0)
                        start = time.perf_counter()
                        future.result()
                        self._add_seconds("upload_assembly_wait", start)
                        reader.release_below(done_z)   # no later layer reads them
                        yield done_z, bricks
        finally:
            reader.close()

    def _assemble(self, z: int, bricks, near: dict, values: np.ndarray, dest) -> None:
        for y, x in bricks:
            self._with_apron(z, y, x, near, values, dest(z, y, x))

    def _with_apron(self, z: int, y: int, x: int, near: dict, values: np.ndarray,
                    out: np.ndarray) -> None:
        """Brick (z, y, x) with its apron into out [B + 2, B + 2, B + 2(, c)], from the cores of
        layers z - 1 .. z + 1 (near {n: {(y, x): core}}) and the other bricks' one value
        (values [bz, by, bx(, c)]; the brick's own too, where it holds one): per axis, the
        neighbour below's last voxel (at the volume's first face the brick's own first one), the
        brick's, the neighbour above's first (at the last face the brick's own last)."""
        B = self.brick
        bx, by, bz = self.counts

        def parts(b: int, count: int):
            below = (slice(0, 1), -1, slice(B - 1, B)) if b > 0 else (slice(0, 1), 0, slice(0, 1))
            above = ((slice(B + 1, B + 2), 1, slice(0, 1)) if b + 1 < count
                     else (slice(B + 1, B + 2), 0, slice(B - 1, B)))
            return below, (slice(1, B + 1), 0, slice(0, B)), above

        across = [(oy, ox, y + dy, x + dx, (sy, sx)) for oy, dy, sy in parts(y, by)
                  for ox, dx, sx in parts(x, bx)]
        for oz, dz, sz in parts(z, bz):
            n = z + dz
            cores = near.get(n) or {}
            for oy, ox, ny, nx, (sy, sx) in across:
                core = cores.get((ny, nx))
                out[oz, oy, ox] = values[n, ny, nx] if core is None else core[sz, sy, sx]

    def _add_seconds(self, what: str, start: float) -> None:
        self.seconds[what] = self.seconds.get(what, 0.0) + time.perf_counter() - start

    def constant(self) -> np.ndarray:
        """[bz, by, bx] True where the brick and its apron hold one value (never uploaded)."""
        return constant_bricks(*self.ranges())

    def resident_count(self) -> int:
        return int(np.count_nonzero(~self.constant()))

    def pool_plan(self, max_side: int) -> "PoolPlan":
        """The pool of this store's bricks that are not constant (one level)."""
        table, constants, grid, resident = self.layout(max_side)
        return PoolPlan(self.dims, self.brick, self.channels, table, constants, grid,
                        [(self, resident, 0)], self.name)

    def layout(self, max_side: int):
        """(page table, constants, slot grid, resident bricks (z, y, x) in slot order)."""
        lo, _ = self.ranges()
        constant = self.constant()
        constants, which = constant_values(lo, constant)
        resident = np.argwhere(~constant)
        grid = slot_grid(len(resident), self.brick, max_side)
        table = np.where(constant, CONSTANT | np.maximum(which, 0), 0).astype(np.uint32)
        for slot, (z, y, x) in enumerate(resident):
            table[z, y, x] = slot
        return table, constants, grid, resident


@dataclass
class PoolPlan:
    """What a brick pool holds (app/gl/brick_pool.py), decided on the host: its page table
    ([z, y, x]: level 0's, then with mixed levels each coarser level's stacked along z), the
    constants, the slot grid, and per level the store and its resident bricks (z, y, x) whose
    slots, consecutive in layer order, the table holds. `rows()` reads and assembles them."""
    dims: tuple
    brick: int
    channels: int
    table: np.ndarray
    constants: np.ndarray
    grid: tuple
    parts: list                      # (BrickStore, resident (n, 3) z, y, x, level)
    name: str = "volume"
    level_dims: tuple = ()           # mixed levels: each level's dims, level 0 first
    level_table_z: tuple = ()        # ... and the first z of its table
    level_of_brick: np.ndarray | None = None   # ... and the level each level-0 brick reads
    mix: object = None               # ... streamed: app/rendering/levels/level_mix.py Mix

    @property
    def resident(self) -> int:
        return sum(len(r) for _, r, _ in self.parts)

    def level_table(self, level: int, store) -> np.ndarray:
        """A level's page table, a view of `table`."""
        z0 = self.level_table_z[level] if self.level_table_z else 0
        bx, by, bz = store.counts
        return self.table[z0:z0 + bz, :by, :bx]

    def rows(self):
        """(first slot, the bricks' ids (level << LEVEL_SHIFT | index in the level), block
        [B + 2, B + 2, k (B + 2)(, c)] of k bricks side by side) for each run of consecutive slots
        within a row of the slot grid, as soon as its bricks are read and assembled: host work
        only (a thread may do it; BrickStore.write_resident), written with one Texture3D.write
        each (BrickPool.write_slots)."""
        for store, resident, level in self.parts:
            if len(resident):
                rows = _SlotRows(self, store, self.level_table(level, store), resident, level)
                layers = store.write_resident(resident, rows.dest, densities=True)
                try:
                    for z, _ in layers:
                        yield from rows.ready(z)
                finally:
                    layers.close()   # its readers stopped and their shared memory unlinked now
                assert not rows.staged


class _SlotRows:
    """A level's resident bricks, gathered on the host into runs of consecutive slots within a
    row of the slot grid (they take consecutive slots in layer order): the assembling threads
    write each brick in its place in its run's array, and a run is handed on once the layer of
    its last brick is done: a Texture3D.write a run instead of a brick, and no copy of a brick on
    its way."""

    def __init__(self, plan: PoolPlan, store, table: np.ndarray, resident: np.ndarray,
                 level: int):
        import threading
        self.table = table
        self.side = slot_side(plan.brick)
        self.per_row = plan.grid[0]
        self.extra = (plan.channels,) if plan.channels > 1 else ()
        bx, by, _ = store.counts
        resident = np.asarray(resident, np.int64).reshape(-1, 3)
        slots = table[resident[:, 0], resident[:, 1], resident[:, 2]].astype(np.int64)
        if np.any(np.diff(slots) != 1):
            raise ValueError("a level's resident bricks must take consecutive slots")
        self.first_slot = int(slots[0])
        self.ids = (level << LEVEL_SHIFT) | (resident[:, 2] + bx * (resident[:, 1]
                                                                    + by * resident[:, 0]))
        rows = slots // self.per_row
        self.runs = []                 # (first slot, count, last layer), in order
        for row in np.unique(rows):
            at = np.nonzero(rows == row)[0]
            self.runs.append((int(slots[at[0]]), len(at), int(resident[at[-1], 0])))
        self.next_run = 0
        self.staged: dict[int, np.ndarray] = {}
        self.lock = threading.Lock()

    def dest(self, z: int, y: int, x: int) -> np.ndarray:
        """Where brick (z, y, x) goes: its place in its run's array (made on first use)."""
        slot = int(self.table[z, y, x])
        row = slot // self.per_row
        first = max(row * self.per_row, self.first_slot)
        with self.lock:
            staged = self.staged.get(row)
            if staged is None:
                k = next(n for f, n, _ in self.runs if f == first)
                staged = np.empty((self.side, self.side, k * self.side) + self.extra, np.float32)
                self.staged[row] = staged
        i = slot - first
        return staged[:, :, i * self.side:(i + 1) * self.side]

    def ready(self, z: int):
        """The runs whose bricks all lie in layers up to z (all written), in order."""
        while self.next_run < len(self.runs) and self.runs[self.next_run][2] <= z:
            first, k, _ = self.runs[self.next_run]
            with self.lock:
                staged = self.staged.pop(first // self.per_row)
            i = first - self.first_slot
            yield first, self.ids[i:i + k], staged
            self.next_run += 1


def refuse_cap_below_brick(cap: int, brick: int, channels: int, exact_uint8: bool,
                           name: str) -> None:
    need = slot_bytes(brick, channels, exact_uint8)
    if cap < need:
        raise VolumeError(f"{name}: volume_memory_bytes {cap} is below one brick: a brick of "
                          f"{brick}^3 voxels with its apron takes {need} bytes "
                          f"({need / 2**20:.2f} MiB); give a larger cap or a smaller brick")


# A bricked volume's densities are materialised whole (np.asarray) only up to this many bytes.
HOST_WHOLE_BYTES = 1 << 30


class LazyData:
    """The densities [z, y, x(, c)] of a volume read brick by brick (Volume.data of a store too
    large to read whole): its shape, and the whole array only where it is small enough;
    channel(c) is one channel's [z, y, x]."""
    dtype = np.dtype(np.float32)

    def __init__(self, store: BrickStore, channel: int | None = None):
        self.store = store
        self.channel_index = channel
        shape = tuple(store.source.shape)
        self.shape = shape[:3] if channel is not None else shape
        self.ndim = len(self.shape)
        self.size = int(np.prod(self.shape, dtype=np.int64))
        self.nbytes = 4 * self.size

    def channel(self, c: int) -> "LazyData":
        return LazyData(self.store, c)

    def _picked(self, data: np.ndarray) -> np.ndarray:
        return data if self.channel_index is None else data[..., self.channel_index]

    def read(self) -> np.ndarray:
        return self._picked(source_whole(self.store.source))

    def __array__(self, dtype=None, copy=None):
        if self.nbytes > HOST_WHOLE_BYTES:
            raise VolumeError(f"{self.store.name}: the {self.shape[2]} x {self.shape[1]} x "
                              f"{self.shape[0]} volume is read brick by brick "
                              f"({self.nbytes / 2**30:.1f} GiB as float32); this use needs it "
                              "whole in host memory")
        data = self.read()
        return data if dtype is None else data.astype(dtype)

    def sample(self, max_voxels: int = 1 << 24) -> np.ndarray:
        """Every k-th voxel along each axis (at most about max_voxels): for histograms."""
        k = max(1, int(np.ceil((self.size / max_voxels) ** (1.0 / 3.0))))
        src = self.store.source
        nz, ny, nx = self.shape[:3]
        parts = [self._picked(src.density(src.read(z, z + 1, 0, ny, 0, nx)))[:, ::k, ::k]
                 for z in range(0, nz, k)]
        return np.concatenate(parts, axis=0)
