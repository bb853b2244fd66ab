"""Bricked volumes on the host: a BrickStore reads a volume's bricks (from an array in memory or a
Zarr array, never the whole array at once), keeps each brick's least and largest density (read
once), and writes the bricks that are not constant into a brick pool (app/gl/brick_pool.py); and
the levels a memory cap chooses between (a 2x box-filtered pyramid, or an OME-Zarr store's own).

Reading: rows of bricks along x ("pencils") at a time, so a Zarr store's chunks are decoded once a
pass. The range pass reads every brick once; the upload pass reads only the bricks that are not
constant, with their aprons (the one voxel of each neighbour they need); a constant brick (the
brick and its apron one value) is never read again nor uploaded. `reads` counts, per brick, how
many times its voxels were read.
"""
from __future__ import annotations

import numpy as np

from .scene_types import VolumeError
from .twins.brick_pool import (APRON, CONSTANT, FREE_SLOT, brick_counts, constant_bricks,
                               constant_values, slot_grid, slot_side)


class ArraySource:
    """A [z, y, x(, c)] array in memory (float32 densities in [0, 1])."""

    def __init__(self, data: np.ndarray):
        self.data = data
        self.shape = data.shape

    def density(self, block: np.ndarray) -> np.ndarray:
        return block

    def read(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        return np.asarray(self.data[z0:z1, y0:y1, x0:x1], np.float32)


class ZarrSource:
    """One time step of one channel of a Zarr array, read region by region and normalised by
    `value_range` (app/volume.py normalise: the same mapping as a whole volume's)."""

    def __init__(self, array, axes: str, time: int, channel: int, value_range, where: str,
                 replace_nonfinite=None):
        self.array = array
        self.axes = axes
        self.time, self.channel = time, channel
        self.value_range = value_range
        self.where = where
        self.replace_nonfinite = replace_nonfinite
        size = dict(zip(axes, array.shape))
        self.shape = (size["z"], size["y"], size["x"])

    def raw(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        pick = {"t": self.time, "c": self.channel, "z": slice(z0, z1), "y": slice(y0, y1),
                "x": slice(x0, x1)}
        index = tuple(pick.get(a, 0) for a in self.axes)
        block = np.asarray(self.array[index])
        kept = [a for a in self.axes if a in "zyx"]
        return np.transpose(block, [kept.index(a) for a in "zyx"])

    def read(self, z0, z1, y0, y1, x0, x1) -> np.ndarray:
        """Raw values, finite (non-finite ones replaced as the scene says, else refused)."""
        raw = self.raw(z0, z1, y0, y1, x0, x1)
        if raw.dtype.kind == "f":
            bad = ~np.isfinite(raw)
            if bad.any():
                if self.replace_nonfinite is None:
                    raise VolumeError(f"{self.where}: voxels in z {z0} to {z1 - 1} are NaN or "
                                      "Inf; give volume.replace_nonfinite to replace them")
                raw = np.where(bad, raw.dtype.type(self.replace_nonfinite), raw)
        return raw

    def density(self, raw: np.ndarray) -> np.ndarray:
        """Raw values as densities (app/volume.py normalise with the volume's value range)."""
        from .volume import normalise
        return normalise(raw, self.value_range, self.where)[0]


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

    def _pencil(self, bz: int, by: int, x0: int, x1: int, apron: int) -> np.ndarray:
        """The raw voxels of bricks x0 .. x1 - 1 of row (by, bz), with `apron` voxels around,
        clamped to the volume (the edge voxel repeated)."""
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

    def ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Each brick's least and largest density [bz, by, bx(, c)]: the raw ones as densities
        (the mapping is monotonic, so the least raw value's density is the least density)."""
        lo, hi = self.raw_ranges()
        return self.source.density(lo), self.source.density(hi)

    def raw_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Each brick's least and largest raw value [bz, by, bx(, c)] (one read of every brick,
        the first time)."""
        if self._ranges is None:
            bx, by, bz = self.counts
            shape = (bz, by, bx) + ((self.channels,) if self.channels > 1 else ())
            lo = hi = None
            B = self.brick
            for z in range(bz):
                for y in range(by):
                    row = self._pencil(z, y, 0, bx, 0)
                    if lo is None:
                        lo, hi = np.empty(shape, row.dtype), np.empty(shape, row.dtype)
                    for x in range(bx):
                        part = row[:, :, x * B:(x + 1) * B]
                        lo[z, y, x] = part.min(axis=(0, 1, 2))
                        hi[z, y, x] = part.max(axis=(0, 1, 2))
            self._ranges = (lo, hi)
        return self._ranges

    def constant(self) -> np.ndarray:
        """[bz, by, bx] True where the brick and its apron hold one value (never uploaded)."""
        return constant_bricks(*self.ranges())

    def resident_count(self) -> int:
        return int(np.count_nonzero(~self.constant()))

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

    def upload(self, ctx, exact_uint8: bool, max_side: int):
        """A BrickPool holding every brick that is not constant (read once more, with aprons,
        a run of neighbours at a time; constant bricks are not read)."""
        from .gl.brick_pool import BrickPool
        table, constants, grid, resident = self.layout(max_side)
        pool = BrickPool(ctx, self.dims, self.brick, self.channels, grid, table, constants,
                         exact_uint8, self.name)
        try:
            B, side = self.brick, slot_side(self.brick)
            bx, by, _ = self.counts
            rows: dict[tuple[int, int], list[int]] = {}
            for z, y, x in resident:
                rows.setdefault((int(z), int(y)), []).append(int(x))
            for (z, y), xs in rows.items():
                runs = np.split(np.asarray(xs), np.nonzero(np.diff(xs) != 1)[0] + 1)
                for run in runs:
                    x0, x1 = int(run[0]), int(run[-1]) + 1
                    pencil = self._pencil(z, y, x0, x1, APRON)
                    for x in range(x0, x1):
                        o = (x - x0) * B
                        block = self.source.density(pencil[:, :, o:o + side])
                        pool.write_slot(int(table[z, y, x]), x + bx * (y + by * z), block)
        except BaseException:
            pool.release()
            raise
        assert np.count_nonzero(pool.brick_of_slot != FREE_SLOT) == len(resident)
        return pool


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
    from .gl.brick_pool import slot_bytes
    need = slot_bytes(brick, channels, exact_uint8)
    if cap < need:
        raise VolumeError(f"{name}: volume_memory_bytes {cap} is below one brick: a brick of "
                          f"{brick}^3 voxels with its apron takes {need} bytes "
                          f"({need / 2**20:.2f} MiB); give a larger cap or a smaller brick")


# A bricked volume's densities are materialised whole (np.asarray) only up to this many bytes.
HOST_WHOLE_BYTES = 1 << 30


class LazyData:
    """The densities [z, y, x] of a volume read brick by brick (Volume.data of a store too large
    to read whole): its shape, and the whole array only where it is small enough."""
    ndim = 3
    dtype = np.dtype(np.float32)

    def __init__(self, store: BrickStore):
        self.store = store
        self.shape = store.source.shape[:3]
        self.size = int(np.prod(self.shape, dtype=np.int64))
        self.nbytes = 4 * self.size

    def read(self) -> np.ndarray:
        nz, ny, nx = self.shape
        return self.store.source.density(self.store.source.read(0, nz, 0, ny, 0, nx))

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
        nz = self.shape[0]
        parts = [src.density(src.read(z, z + 1, 0, self.shape[1], 0, self.shape[2]))[:, ::k, ::k]
                 for z in range(0, nz, k)]
        return np.concatenate(parts, axis=0)


# A Zarr volume larger than this (as float32) or longer than LAZY_SIDE along an axis is read
# brick by brick (app/volume.py load_volume) instead of whole.
LAZY_BYTES = 1 << 30
LAZY_SIDE = 2048


def lazy_zarr_volume(p, spec, time: int, channels, brick: int):
    """A Volume of a Zarr store read brick by brick (Volume.data a LazyData, Volume.bricks its
    BrickStore, Volume.levels the store's coarser levels): one channel (several are refused), the
    time step `time`; normalised as the whole loader does (the value range, else the type's for
    8-bit data, else the data's least and largest, from the range pass)."""
    import dataclasses
    from .volume import Volume, _resolve
    from .volume_axes import resolve_axes
    from .volume_formats import open_zarr
    where = str(p)
    array, file_spacing, axes, levels = open_zarr(p, spec.spacing is None)
    axes = resolve_axes(axes, tuple(array.shape), spec.axes, where)
    size = dict(zip(axes, array.shape))
    if size.get("c", 1) > 1 or channels is not None and len(channels) > 1:
        raise VolumeError(f"{where}: a Zarr store of {size.get('c', 1)} channels too large to "
                          "read whole; bricking reads one channel: give volume.axes without c, or "
                          "a store of one channel")
    if any(a not in "tczyx" for a in axes) or not all(a in axes for a in "zyx"):
        raise VolumeError(f"{where}: axes {axes!r}; a bricked Zarr store needs z, y and x")
    steps = size.get("t", 1)
    if not 0 <= time < steps:
        raise VolumeError(f"{where}: time step {time} asked for, but the volume has "
                          + (f"{steps} time steps (0 to {steps - 1})" if steps > 1 else
                             "no time axis (one step)") + "; see the scene's time")
    spacing = spec.spacing or file_spacing or (1.0, 1.0, 1.0)
    domain = spec.domain if channels is None else channels[0].domain(spec)
    source = ZarrSource(array, axes, time, 0, domain, where, spec.replace_nonfinite)
    store = BrickStore(source, brick, p.name)
    raw_lo, raw_hi = store.raw_ranges()
    lo, hi = float(raw_lo.min()), float(raw_hi.max())
    if domain is None:
        if array.dtype == np.uint8:
            domain = (0.0, 255.0)
        elif array.dtype == np.int8:
            domain = (-128.0, 127.0)
        elif not hi > lo:
            raise VolumeError(f"{where}: every voxel is {lo}; give volume.value_range to say "
                              "what density that is")
        else:
            domain = (lo, hi)
    source.value_range = tuple(float(v) for v in domain)
    coarser = [ZarrSource(a, axes, time, 0, source.value_range, where, spec.replace_nonfinite)
               for a in levels[1:]]
    notes = ()
    if spec.orientation == "patient":
        notes += (f"{p.name} says nothing of the patient's orientation: shown as stored "
                  "(orientation \"data\")",)
    volume = Volume(LazyData(store), tuple(float(v) for v in spacing), p.name,
                    source.value_range, array.dtype.name, lo, hi, notes=notes,
                    bricks=store, levels=tuple(coarser))
    return dataclasses.replace(volume, time=time, time_steps=steps) if steps > 1 else volume
