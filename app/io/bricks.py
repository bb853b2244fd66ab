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
pickled. `reads` counts, per brick, how many times its voxels were read.
"""
from __future__ import annotations

import math
import multiprocessing
import os
import re
import time
import weakref
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from multiprocessing import shared_memory

import numpy as np

from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError

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



class ArraySource:
    """A [z, y, x(, c)] array in memory (float32 densities in [0, 1])."""

    def __init__(self, data: np.ndarray):
        self.data = data
        self.shape = data.shape

    def density(self, block: np.ndarray) -> np.ndarray:
        return block

    def read(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        return np.asarray(self.data[z0:z1, y0:y1, x0:x1], np.float32)


# A Zarr array's chunks are listed (stored_chunks) only where its grid of chunks (or shards) has at
# most this many (a boolean each; a file each to list).
MAX_LISTED_CHUNKS = 1 << 24

# stored_chunks' listings: {id(array): (a weak reference to the array, its grid or None)}
_STORED_CHUNKS: dict[int, tuple] = {}


def stored_chunks(array) -> np.ndarray | None:
    """[the array's grid of stored chunks, an index an axis] True where the array's store holds
    the chunk's key: its store listed once per array object (the series' steps and channels of
    one array share it). A sharded array's grid is of its shards (a shard stored: each of its
    chunks maybe written). None where the listing cannot be trusted to hold every chunk Zarr
    would read (a store other than a local directory, a zip file or memory: remote ones; a
    linked directory inside the array; a chunk key encoding whose keys are not read back;
    more than MAX_LISTED_CHUNKS; any error): every chunk then counts as written. The arrays
    listed are opened read-only (app/io/volume_formats.py open_zarr): an array object written to
    after its listing would need a new one."""
    key = id(array)
    held = _STORED_CHUNKS.get(key)
    if held is not None and held[0]() is array:
        return held[1]
    try:
        grid = _listed_chunk_grid(array)
    except Exception:     # whatever the store or its codecs raise: listed as unknown, read all
        grid = None
    try:
        _STORED_CHUNKS[key] = (weakref.ref(array, lambda _: _STORED_CHUNKS.pop(key, None)), grid)
    except TypeError:     # an array that cannot be weakly referenced: not kept
        pass
    return grid


def _listed_chunk_grid(array) -> np.ndarray | None:
    stored = array.shards or array.chunks            # a key per shard where sharded
    shape = tuple(-(-int(n) // int(c)) for n, c in zip(array.shape, stored))
    if math.prod(shape) > MAX_LISTED_CHUNKS:
        return None
    keys = _array_keys(array)
    if keys is None:
        return None
    # A key Zarr reads is its encoding of a chunk's coordinates (array.metadata.encode_chunk_key:
    # "c/1/2/3", "c.1.2.3", "1.2.3", "1/2/3"): read back here as the key's whole numbers in
    # order, kept where encoding them gives the key again (zarr.json, .zarray, "01" are not
    # chunks Zarr reads). An encoding those numbers do not read back (checked on a few
    # coordinates) is not listed.
    encode = array.metadata.encode_chunk_key
    last = tuple(n - 1 for n in shape)
    for probe in ((0,) * len(shape), last, tuple(min(n, 10 + i) for i, n in enumerate(last))):
        if _key_numbers(encode(probe)) != probe:
            return None
    grid = np.zeros(shape, bool)
    for k in keys:
        coords = _key_numbers(k)
        if (len(coords) == len(shape) and all(c < n for c, n in zip(coords, shape))
                and encode(coords) == k):
            grid[coords] = True
    return grid


def _key_numbers(key: str) -> tuple[int, ...]:
    return tuple(int(n) for n in re.findall(r"[0-9]+", key))


def _array_keys(array) -> list[str] | None:
    """The keys of the array's store under the array (relative to it), or None where the store
    is not one whose listing is complete: a local directory (walked here, since the store's own
    listing does not descend into linked directories, which Zarr reads through), a zip file or
    memory."""
    from zarr.core.sync import collect_aiterator
    from zarr.storage import LocalStore, MemoryStore, ZipStore
    store, path = array.store_path.store, array.store_path.path
    if isinstance(store, LocalStore):
        top = os.path.join(str(store.root), path)
        keys = []

        def refuse(error):
            raise error
        for folder, folders, files in os.walk(top, onerror=refuse):
            if any(os.path.islink(os.path.join(folder, f)) for f in folders):
                return None
            where = os.path.relpath(folder, top).replace(os.sep, "/")
            keys.extend(f if where == "." else f"{where}/{f}" for f in files)
        return keys
    if isinstance(store, (MemoryStore, ZipStore)):
        prefix = f"{path}/" if path else ""
        return [k[len(prefix):] for k in collect_aiterator(store.list_prefix(prefix))
                if k.startswith(prefix)]
    return None


def bricks_overlapping(chunk_grid: np.ndarray, chunks, brick: int, shape) -> np.ndarray:
    """[bz, by, bx] True where a brick of `brick` voxels overlaps a True cell of chunk_grid
    ([z, y, x] a cell a chunk of `chunks` (z, y, x) voxels) of a volume of `shape` (z, y, x)."""
    out = np.asarray(chunk_grid, bool)
    for axis, (n, c) in enumerate(zip(shape, chunks)):
        first = np.arange(0, n, brick)
        last = np.minimum(first + brick, n) - 1
        # the True cells among chunks first // c .. last // c of each brick, from running counts
        counts = np.cumsum(out, axis=axis, dtype=np.int32)
        counts = np.concatenate([np.zeros_like(np.take(counts, [0], axis)), counts], axis)
        out = (np.take(counts, last // c + 1, axis) - np.take(counts, first // c, axis)) > 0
    return out


class ZarrSource:
    """One time step of a Zarr array, read region by region: one channel (`channel`; [z, y, x]),
    or several (`channels`, the file's channel indices in the order shown; [z, y, x, c]),
    normalised by `value_range` (of several channels each by its own of `value_ranges`;
    app/io/volume.py normalise: the same mapping as a whole volume's). It pickles (the array by its
    store's path), so a process can read it."""
    process_safe = True

    def __init__(self, array, axes: str, time: int, channel: int, value_range, where: str,
                 replace_nonfinite=None, normalise=None, channels=None, value_ranges=None):
        self.array = array
        self.axes = axes
        self.time, self.channel = time, channel
        self.value_range = value_range
        self.where = where
        self.replace_nonfinite = replace_nonfinite
        self.normalise = normalise   # app/io/volume.py normalise (given: this module is below it)
        self.channels = None if channels is None else tuple(int(c) for c in channels)
        self.value_ranges = value_ranges
        size = dict(zip(axes, array.shape))
        self.shape = ((size["z"], size["y"], size["x"])
                      + (() if self.channels is None else (len(self.channels),)))

    def raw(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        many, ordered = self.channels is not None, True
        pick = {"t": self.time, "c": self.channel, "z": slice(z0, z1), "y": slice(y0, y1),
                "x": slice(x0, x1)}
        if many:
            first, n = self.channels[0], len(self.channels)
            # channels in order, one after another: a plain slice; else orthogonal indexing
            # (only their chunks decoded)
            ordered = self.channels == tuple(range(first, first + n))
            pick["c"] = slice(first, first + n) if ordered else list(self.channels)
        index = tuple(pick.get(a, 0) for a in self.axes)
        block = np.asarray(self.array[index] if ordered else self.array.oindex[index])
        kept = [a for a in self.axes if a in ("zyxc" if many else "zyx")]
        return np.transpose(block, [kept.index(a) for a in ("zyxc" if many else "zyx")])

    def read(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        """Raw values, finite (non-finite ones replaced as the scene says, else refused)."""
        return self._finite(self.raw(z0, z1, y0, y1, x0, x1), z0, z1)

    def _finite(self, raw: np.ndarray, z0: int, z1: int) -> np.ndarray:
        if raw.dtype.kind == "f":
            bad = ~np.isfinite(raw)
            if bad.any():
                if self.replace_nonfinite is None:
                    raise VolumeError(f"{self.where}: voxels in z {z0} to {z1 - 1} are NaN or "
                                      f"Inf; give {with_flag('volume.replace_nonfinite')} to replace them")
                raw = np.where(bad, raw.dtype.type(self.replace_nonfinite), raw)
        return raw

    @property
    def chunks(self) -> tuple[int, int, int]:
        """The array's chunks' voxels along z, y, x (of a sharded array, its inner chunks: what
        a read decodes)."""
        size = dict(zip(self.axes, self.array.chunks))
        return size["z"], size["y"], size["x"]

    def unwritten_bricks(self, brick: int):
        """(mask, fill): mask [bz, by, bx] True where every chunk (or shard) the brick overlaps
        along z, y and x, of this time step and these channels, was never written to the store
        (Zarr leaves out a chunk equal to the fill value), so that every voxel of it reads as
        `fill`, the raw value read gives an unwritten voxel ([c] of several channels; the type
        read gives). None where that is not known (stored_chunks cannot list the store, a
        format 2 array without a fill value, a fill value a read would refuse as non-finite):
        every brick is then read."""
        grid = stored_chunks(self.array)
        value = self.array.fill_value
        if grid is None or value is None:
            return None
        fill = np.full(() if self.channels is None else (len(self.channels),), value,
                       self.array.dtype)
        try:
            fill = self._finite(fill, 0, self.shape[0])
        except VolumeError:             # a read refuses it, saying where: read those bricks
            return None
        stored = dict(zip(self.axes, self.array.shards or self.array.chunks))
        pick = []
        for a, n in zip(self.axes, grid.shape):
            if a == "t":
                pick.append([self.time // stored["t"]])
            elif a == "c":
                shown = [self.channel] if self.channels is None else self.channels
                pick.append(sorted({c // stored["c"] for c in shown}))
            else:
                pick.append(np.arange(n))
        picked = grid[np.ix_(*pick)]
        others = tuple(i for i, a in enumerate(self.axes) if a not in "zyx")
        written = picked.any(axis=others) if others else picked
        kept = [a for a in self.axes if a in "zyx"]
        written = np.transpose(written, [kept.index(a) for a in "zyx"])
        mask = ~bricks_overlapping(written, [stored[a] for a in "zyx"], brick, self.shape[:3])
        return mask, fill

    def density(self, raw: np.ndarray) -> np.ndarray:
        """Raw values as densities (app/io/volume.py normalise with the volume's value range; of
        several channels, the last axis, each channel with its own)."""
        if self.channels is None:
            return self.normalise(raw, self.value_range, self.where)[0]
        out = np.empty(raw.shape, np.float32)
        for c, value_range in enumerate(self.value_ranges):
            out[..., c] = self.normalise(raw[..., c], value_range, self.where)[0]
        return out


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
        # where the reads' time went (scripts/brick_bench.py records it): the range pass's
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
                with ProcessPoolExecutor(reader_processes(), mp_context=_spawn()) as pool:
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
        return (getattr(self.source, "process_safe", False) and reader_processes() > 1
                and nz * ny * nx * self.channels >= PROCESS_READ_VOXELS)

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


def _edge_padded(block: np.ndarray, shape) -> np.ndarray:
    """A [z, y, x(, c)] block read at a volume's far faces, grown to `shape` (z, y, x) by
    repeating its last voxels (as clamped texture coordinates read beyond the faces)."""
    pad = [(0, n - m) for n, m in zip(shape, block.shape[:3])] + [(0, 0)] * (block.ndim - 3)
    return np.pad(block, pad, mode="edge") if any(p != (0, 0) for p in pad) else block


def source_whole(source) -> np.ndarray:
    """A source's whole volume as densities (one read: for a source known to be small)."""
    nz, ny, nx = source.shape[:3]
    return source.density(source.read(0, nz, 0, ny, 0, nx))


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


def box_filtered(data: np.ndarray) -> np.ndarray:
    """The next level of a pyramid: 2 x 2 x 2 voxels averaged ([z, y, x(, c)]; an odd axis has
    its last voxel repeated first)."""
    pad = [(0, n % 2) for n in data.shape[:3]] + [(0, 0)] * (data.ndim - 3)
    d = np.pad(np.asarray(data, np.float32), pad, mode="edge")
    nz, ny, nx = d.shape[:3]
    d = d.reshape((nz // 2, 2, ny // 2, 2, nx // 2, 2) + d.shape[3:])
    return d.mean(axis=(1, 3, 5), dtype=np.float64).astype(np.float32)


def source_box_filtered(source, brick: int) -> np.ndarray:
    """box_filtered of a source too large to read whole, read slab by slab along z (an even
    number of slices each): the next level, in memory."""
    nz = source.shape[0]
    step = 2 * max(1, brick // 2)
    parts = []
    for z0 in range(0, nz, step):
        raw = source.read(z0, min(z0 + step, nz), 0, source.shape[1], 0, source.shape[2])
        parts.append(box_filtered(source.density(raw)))
    return np.concatenate(parts, axis=0)


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
