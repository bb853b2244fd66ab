"""Where a bricked volume's voxels come from: an array in memory (ArraySource) or a Zarr array
(ZarrSource, with the chunks its store holds listed once so that never-written chunks are not
read), read whole only where small, and the box-filtered next level of a pyramid."""
from __future__ import annotations

import math
import os
import re
import time
import weakref

import numpy as np

from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError


# stored_chunks' listings: {id(array): (a weak reference to the array, its grid or None)}
_STORED_CHUNKS: dict[int, tuple] = {}


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


def _edge_padded(block: np.ndarray, shape) -> np.ndarray:
    """A [z, y, x(, c)] block read at a volume's far faces, grown to `shape` (z, y, x) by
    repeating its last voxels (as clamped texture coordinates read beyond the faces)."""
    pad = [(0, n - m) for n, m in zip(shape, block.shape[:3])] + [(0, 0)] * (block.ndim - 3)
    return np.pad(block, pad, mode="edge") if any(p != (0, 0) for p in pad) else block


def source_whole(source) -> np.ndarray:
    """A source's whole volume as densities (one read: for a source known to be small)."""
    nz, ny, nx = source.shape[:3]
    return source.density(source.read(0, nz, 0, ny, 0, nx))


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
