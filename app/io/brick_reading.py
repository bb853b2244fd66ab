"""Reading a store's bricks in passes: a layer of bricks at a time on threads or processes (the
range pass's least and largest densities, the upload's cores as runs along x without aprons,
handed over in shared memory by _CoreReader), and how many threads, processes and bytes of shared
memory they may use."""
from __future__ import annotations


import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from multiprocessing import shared_memory

import numpy as np

from radiance_probes.io.brick_sources import _edge_padded


def _layer_ranges_of(source, z: int, brick: int, counts, dims, unwritten_row=None, fill=None,
                     band: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """([by, bx(, c)] least and largest raw values of layer z's bricks, [by, bx] True where the
    brick was read): the whole layer in one read, or, where some of its bricks are unwritten
    (unwritten_row [by, bx], those holding `fill` alone, unread), the written ones as runs along
    x of bands of `band` rows (_written_regions). A function of its arguments alone, so a process
    can run it."""
    bx, by, _ = counts
    regions = _written_regions(unwritten_row, band, by, bx)
    if regions == [(0, by, 0, bx)]:
        lo, hi = _brick_extremes(source, z, brick, dims, regions[0])
        return lo, hi, np.ones((by, bx), bool)
    lo = np.empty((by, bx) + fill.shape, fill.dtype)
    lo[...] = fill
    hi = lo.copy()
    read = np.zeros((by, bx), bool)
    for y0, y1, x0, x1 in regions:
        part_lo, part_hi = _brick_extremes(source, z, brick, dims, (y0, y1, x0, x1))
        if part_lo.dtype != fill.dtype:
            raise TypeError(f"layer {z} reads as {part_lo.dtype}, its fill value {fill.dtype}")
        lo[y0:y1, x0:x1], hi[y0:y1, x0:x1] = part_lo, part_hi
        read[y0:y1, x0:x1] = True
    return lo, hi, read


def _written_regions(unwritten_row, band: int, by: int, bx: int) -> list[tuple]:
    """The regions of a layer's bricks (y0, y1, x0, x1; ends exclusive) that hold every brick not
    in unwritten_row ([by, bx], None: none is): the whole layer where all are written, else per
    band of `band` rows (a band's last rows may lie past by), the runs along x of the bricks
    written in any of its rows (so a chunk the band's rows share is decoded once)."""
    if unwritten_row is None or not unwritten_row.any():
        return [(0, by, 0, bx)]
    regions = []
    for y0 in range(0, by, band):
        y1 = min(y0 + band, by)
        regions.extend((y0, y1, x0, x1) for x0, x1 in runs(~unwritten_row[y0:y1].all(axis=0)))
    return regions


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in a 1D mask, as (first, end) (end exclusive), in order."""
    xs = np.nonzero(mask)[0]
    if not len(xs):
        return []
    return [(int(run[0]), int(run[-1]) + 1)
            for run in np.split(xs, np.nonzero(np.diff(xs) != 1)[0] + 1)]


def _brick_extremes(source, z: int, brick: int, dims, region) -> tuple[np.ndarray, np.ndarray]:
    """[y1 - y0, x1 - x0(, c)] least and largest raw values of layer z's bricks in region (y0,
    y1, x0, x1) of bricks, read at once."""
    y0, y1, x0, x1 = region
    B = brick
    nx, ny, nz = dims
    block = source.read(z * B, min(z * B + B, nz), y0 * B, min(y1 * B, ny), x0 * B,
                        min(x1 * B, nx))
    # partial bricks at the far faces: the edge voxel repeated changes no least or largest
    d = block.shape[0]
    block = _edge_padded(block, (d, (y1 - y0) * B, (x1 - x0) * B))
    # along z first (whole planes, elementwise: a third of the time of reducing the three block
    # axes at once), then within each brick's B x B square
    shape = (y1 - y0, B, x1 - x0, B) + block.shape[3:]
    return (block.min(axis=0).reshape(shape).min(axis=(1, 3)),
            block.max(axis=0).reshape(shape).max(axis=(1, 3)))


def _read_cores_of(source, z: int, resident_row: np.ndarray, brick: int, dims,
                   densities: bool = False, into=None):
    """({(y, x): voxels [B, B, B(, c)]} of layer z's resident bricks (edge-padded to B at the far
    faces), read as runs along x; `densities`: mapped by the source; seconds reading, seconds
    mapping). `into` (a shared memory block's name, dtype, channels' shape): the cores are
    written there instead, one after another in np.argwhere order, and the dict is empty (a
    process's cores reach the caller so, not pickled). A function of its arguments alone, so a
    process can run it."""
    B = brick
    nx, ny, nz = dims
    cores, read_s, map_s = {}, 0.0, 0.0
    block = out = None
    if into is not None:
        block = shared_memory.SharedMemory(name=into[0])
    try:
        if block is not None:
            count = int(np.count_nonzero(resident_row))
            out = np.ndarray((count, B, B, B) + tuple(into[2]), np.dtype(into[1]),
                             buffer=block.buf)
        i = 0
        for y in range(resident_row.shape[0]):
            for x0, x1 in runs(resident_row[y]):
                start = time.perf_counter()
                raw = _edge_padded(source.read(z * B, min(z * B + B, nz), y * B,
                                               min(y * B + B, ny), x0 * B, min(x1 * B, nx)),
                                   (B, B, (x1 - x0) * B))
                read_s += time.perf_counter() - start
                if densities:
                    start = time.perf_counter()
                    raw = source.density(raw)
                    map_s += time.perf_counter() - start
                if out is not None and raw.dtype != out.dtype:
                    raise TypeError(f"layer {z}'s cores are {raw.dtype}, their shared block "
                                    f"{out.dtype}")
                for x in range(x0, x1):
                    core = raw[:, :, (x - x0) * B:(x - x0 + 1) * B]
                    if out is None:
                        cores[(y, x)] = core
                    else:
                        out[i] = core
                    i += 1
    finally:
        if block is not None:
            out = None                  # the block's buffer is no longer exported: it closes
            block.close()
    return cores, read_s, map_s


class _CoreReader:
    """The upload's reads of layers' resident cores (_read_cores_of), ahead of the layer
    assembled, in processes (a large Zarr store, BrickStore._in_processes) or on threads. A
    process writes a layer's cores into a shared memory block this reader creates for it (the
    parent owns every block: it unlinks a block's name as soon as the layer's read is done, and
    at close every block still named, after the readers have stopped, on errors and
    KeyboardInterrupt too), so the cores are never pickled through a pipe; a layer that would
    take the shared memory past its budget (_shared_budget) comes back pickled, as before."""

    def __init__(self, store: "BrickStore", is_resident: np.ndarray, densities: bool,
                 values: np.ndarray):
        self.store = store
        self.is_resident = is_resident
        self.densities = densities
        self.dtype = values.dtype
        self.extra = tuple(values.shape[3:])
        self.processes = store._in_processes()
        self.ahead = reader_processes() if self.processes else 2
        self.budget = _shared_budget() if self.processes else 0
        self.shared = 0                          # bytes of the blocks not yet released
        self.futures: dict[int, object] = {}
        self.blocks: dict[int, shared_memory.SharedMemory] = {}
        self.block_bytes: dict[int, int] = {}
        self.got: dict[int, dict] = {}
        self.submitted: set[int] = set()
        self.unlinked: set[int] = set()
        if self.processes:
            # the resource tracker started before the readers are forked, so that the blocks
            # they attach to are tracked by the parent's (which unlinks what is left at exit)
            from multiprocessing import resource_tracker
            resource_tracker.ensure_running()
            self.pool = ProcessPoolExecutor(reader_processes(), mp_context=_spawn())
            try:
                # forked now, before any block exists: a reader forked later would inherit the
                # blocks mapped here then, and keep their memory until the pool ends
                self.pool.submit(os.getpid).result()
            except BaseException:
                self.pool.shutdown(wait=True, cancel_futures=True)
                raise
        else:
            self.pool = ThreadPoolExecutor(reader_threads())

    def submit(self, n: int) -> None:
        """Reads layer n (once)."""
        if n in self.submitted:
            return
        B = self.store.brick
        count = int(np.count_nonzero(self.is_resident[n]))
        nbytes = count * B ** 3 * int(np.prod(self.extra, dtype=np.int64)) * self.dtype.itemsize
        into = None
        if self.processes and count and self.shared + nbytes <= self.budget:
            try:
                block = shared_memory.SharedMemory(create=True, size=nbytes)
            except OSError:      # no shared memory to be had (too many open, ...): pickled
                block = None
            if block is not None:
                self.blocks[n], self.block_bytes[n] = block, nbytes
                self.shared += nbytes
                into = (block.name, self.dtype.str, self.extra)
        self.submitted.add(n)
        self.futures[n] = self.pool.submit(_read_cores_of, self.store.source, n,
                                           self.is_resident[n], B, self.store.dims,
                                           self.densities, into)

    def cores(self, n: int) -> dict:
        """{(y, x): core} of layer n (waited for; each counted as a read of its brick once)."""
        if n not in self.got:
            self.submit(n)
            start = time.perf_counter()
            cores, read_s, map_s = self.futures.pop(n).result()
            store = self.store
            store._add_seconds("upload_read_wait", start)
            store.seconds["upload_read"] = store.seconds.get("upload_read", 0.0) + read_s
            store.seconds["upload_map"] = store.seconds.get("upload_map", 0.0) + map_s
            block = self.blocks.get(n)
            if block is not None:
                self._unlink(n)                 # its mapping here stays until released
                B = store.brick
                keys = [(int(y), int(x)) for y, x in np.argwhere(self.is_resident[n])]
                shared = np.ndarray((len(keys), B, B, B) + self.extra, self.dtype,
                                    buffer=block.buf)
                cores = {key: shared[i] for i, key in enumerate(keys)}
                del shared
                store.handed["shared"] += 1
            elif self.processes and cores:
                store.handed["pickled"] += 1
            self.got[n] = cores
            for y, x in cores:
                store.reads[n, y, x] += 1
        return self.got[n]

    def release_below(self, z: int) -> None:
        """Drops the cores of the layers below z, closing their blocks."""
        for n in [n for n in self.got if n < z]:
            del self.got[n]
            self._close(n)

    def _unlink(self, n: int) -> None:
        if n in self.blocks and n not in self.unlinked:
            self.unlinked.add(n)
            try:
                self.blocks[n].unlink()
            except FileNotFoundError:   # unlinked by another (the resource tracker at exit)
                pass

    def _close(self, n: int) -> None:
        if n not in self.blocks:
            return
        try:
            self._unlink(n)
        finally:
            block = self.blocks.pop(n)
            self.shared -= self.block_bytes.pop(n)
            try:
                block.close()
            except BufferError:   # a view of it still held (an error's traceback): freed with it
                pass

    def close(self) -> None:
        """Stops the readers (the layers not started are dropped) and unlinks and closes every
        block left."""
        self.got.clear()
        try:
            self.pool.shutdown(wait=True, cancel_futures=True)
        finally:
            for n in list(self.blocks):
                self._close(n)


# The shared memory the upload's reading processes may fill at once where there is no /dev/shm
# to ask (not Linux).
SHARED_BYTES = 4 << 30


def _shared_budget() -> int:
    """Bytes of shared memory blocks the upload's readers may hold at once: half of what
    /dev/shm has free (a container's is often small, and a process writing a block past what
    the file system holds is killed by SIGBUS), else SHARED_BYTES."""
    try:
        st = os.statvfs("/dev/shm")
    except (OSError, AttributeError):
        return SHARED_BYTES
    return st.f_bavail * st.f_frsize // 2


# Layers assembled at once (their bricks with aprons) while the caller takes an earlier one.
SLAB_THREADS = 3


# A store of at least this many voxels is read in processes (reader_processes): its range pass
# and its upload.
PROCESS_READ_VOXELS = 1 << 28


def reader_processes() -> int:
    """Processes reading a Zarr store's layers at once in the range pass."""
    return max(1, min(16, os.cpu_count() or 1))


def _spawn():
    # forked where the platform can (Zarr resets its event loop in a forked child): a spawned
    # process would import the caller's main module again, which a script without a
    # `if __name__ == "__main__"` guard would run again
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else "spawn")


def reader_threads() -> int:
    """Threads reading a store's layers at once (each holds a layer of bricks in memory)."""
    return max(1, min(8, os.cpu_count() or 1))
