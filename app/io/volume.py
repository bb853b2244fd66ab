"""The Volume a renderer takes, its normalisation, and which paths name a volume. Reading files is
app/io/volume_files.py's (with volume_formats.py and dicom.py), the built-in volumes are
builtin_volumes.py's, and the one entry point, `load_volume`, is app/io/load.py's.

A :class:`Volume` holds the density normalised to [0, 1] as SPEC.md says (``data[z, y, x]``,
x fastest) and the world box it fills: centred at the origin, extent ``dims * spacing`` scaled so
that the longest side is 1."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from radiance_probes.io import dicom
from radiance_probes.io import volume_formats as formats
from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError, VolumeSpec


# What load_volume takes, by file name ending (a folder is a TIFF stack, DICOM images or a Zarr
# store; a file named DICOMDIR indexes a DICOM set).
VOLUME_SUFFIXES = ((".raw", ".nrrd", ".nhdr", ".npy") + formats.NIFTI_SUFFIXES
                   + formats.TIFF_SUFFIXES + formats.ZARR_SUFFIXES)


def is_volume_path(p: Path) -> bool:
    """A file load_volume reads by its name, a DICOMDIR, or a folder (a TIFF stack or DICOM)."""
    return (p.is_dir() or formats.has_suffix(p, VOLUME_SUFFIXES + dicom.DICOM_SUFFIXES)
            or dicom.is_dicomdir(p))


@dataclass(frozen=True, eq=False)
class Volume:
    # float32 normalised density in [0, 1]: [z, y, x], or [z, y, x, c] for several channels
    # (SPEC.md, Channels; each channel normalised by its own window, channel_ranges)
    data: np.ndarray
    spacing: tuple[float, float, float]  # voxel size along x, y, z (any unit)
    name: str
    value_range: tuple[float, float]     # raw values mapped to 0 and 1 (channel 0's)
    raw_dtype: str
    raw_min: float
    raw_max: float
    # What a person should know about how the file was read (the other series of a DICOM folder,
    # an oblique scan shown axis-aligned, files passed over); the CLI prints them, the viewer shows
    # them.
    notes: tuple[str, ...] = ()
    # The array axes' directions in the patient's LPS frame (columns x, y, z) as shown, where the
    # file says; None: it does not (app/io/orientation.py).
    direction: np.ndarray | None = None
    orientation: str = "data"            # how the axes were placed: "data" or "patient"
    oblique_degrees: float = 0.0         # "patient": the residual rotation not applied
    dicom_listing: dicom.DicomListing | None = None   # a DICOM folder's series
    dicom_series: dicom.DicomSeries | None = None     # ... and the one shown
    # Several channels: the raw values each channel maps to 0 and 1, and each one's raw min and
    # max; empty for a one-channel volume.
    channel_ranges: tuple[tuple[float, float], ...] = ()
    channel_raw: tuple[tuple[float, float], ...] = ()
    # A step of a time series: which, and of how many (1: no time axis).
    time: int = 0
    time_steps: int = 1
    # What is computed from the data once and kept with it (the majorant grid's density ranges,
    # keyed by their cells): a step shown again costs nothing.
    derived: dict = field(default_factory=dict, repr=False)
    # A volume read brick by brick (app/io/bricks.py): its BrickStore (data is then a LazyData), and
    # the sources of its coarser levels finest first (an OME-Zarr store's multiscales); None and
    # () for a volume in memory.
    bricks: object = field(default=None, repr=False)
    levels: tuple = field(default=(), repr=False)

    @property
    def dims(self) -> tuple[int, int, int]:
        """Voxel counts along x, y, z."""
        z, y, x = self.data.shape[:3]
        return (x, y, z)

    @property
    def channel_count(self) -> int:
        """1 for a one-channel volume ([z, y, x]), else the last axis of data."""
        return 1 if self.data.ndim == 3 else int(self.data.shape[3])

    def channel(self, c: int) -> np.ndarray:
        """Channel c's normalised density [z, y, x] (the data itself for one channel)."""
        if self.data.ndim == 3:
            if c != 0:
                raise IndexError(f"channel {c} of a one-channel volume")
            return self.data
        if hasattr(self.data, "channel"):   # read brick by brick (app/io/bricks.py LazyData)
            return self.data.channel(c)
        return self.data[..., c]

    @property
    def half_extent(self) -> np.ndarray:
        """Half the world box size along x, y, z; the longest side of the box is 1."""
        size = np.asarray(self.dims, np.float64) * np.asarray(self.spacing, np.float64)
        return (0.5 * size / size.max()).astype(np.float32)

    @property
    def exact_uint8(self) -> bool:
        """True when the data is 8-bit with the default range (in every channel), so a 16-bit
        normalised texture stores it exactly."""
        return self.raw_dtype == "uint8" and all(
            r == (0.0, 255.0) for r in (self.channel_ranges or (self.value_range,)))

    def raw_extents(self, read: bool = False) -> tuple[tuple[float, float], ...] | None:
        """Each channel's least and largest raw value ((raw_min, raw_max) for one channel). A
        store read brick by brick whose range pass was not needed has them once it is read
        (`read`: read it now, every brick once); None until then."""
        known = self.channel_raw or ((self.raw_min, self.raw_max),)
        if all(np.isfinite(v) for pair in known for v in pair):
            return known
        if self.bricks is None or not (read or self.bricks.ranges_read):
            return None
        return tuple((float(a), float(b)) for a, b in zip(*self.bricks.raw_extremes()))

    def histogram(self, bins: int = 128, channel: int = 0) -> np.ndarray:
        """Counts of the normalised values in `bins` bins over [0, 1]; kept in `derived` (a
        volume opening in the viewer has it made on the loading thread, 0.3 s for the foot)."""
        key = ("histogram", bins, channel, id(self.data))
        if key not in self.derived:
            self.derived[key] = self._histogram(bins, channel)
        return self.derived[key].copy()

    def _histogram(self, bins: int, channel: int) -> np.ndarray:
        data = self.channel(channel)
        if hasattr(data, "sample"):   # read brick by brick
            small = [src for src in self.levels if np.prod(src.shape[:3]) <= 1 << 24]
            if small:
                # the finest of the store's own coarser levels that is small: read whole (a
                # strided sample of level 0 would decode a row of chunks for every plane it
                # takes; at 2048^3, 8 times the volume). Its voxels are averages of level 0's:
                # the histogram's peaks are a little narrower than level 0's own.
                from radiance_probes.io.brick_sources import source_whole
                data = source_whole(small[0])
                if data.ndim == 4:
                    data = data[..., channel]
            else:                     # a strided sample of it
                data = data.sample()
        counts, _ = np.histogram(data, bins=bins, range=(0.0, 1.0))
        return counts


def normalise(raw: np.ndarray, value_range: tuple[float, float] | None, where: str,
              replace_nonfinite: float | None = None) -> tuple[np.ndarray, tuple[float, float]]:
    """Map raw values to [0, 1] as SPEC.md says; returns the float32 data and the range used."""
    if raw.dtype.kind not in "uif":
        raise VolumeError(f"{where}: unsupported data type {raw.dtype}")
    if raw.dtype.kind == "f":
        bad = ~np.isfinite(raw)
        if bad.any():
            if replace_nonfinite is None:
                raise VolumeError(f"{where}: {int(bad.sum())} voxels are NaN or Inf; give "
                                  f"{with_flag('volume.replace_nonfinite')} to replace them")
            raw = np.where(bad, raw.dtype.type(replace_nonfinite), raw)
    if value_range is None:
        if raw.dtype == np.uint8:
            value_range = (0.0, 255.0)
        elif raw.dtype == np.int8:
            value_range = (-128.0, 127.0)
        else:
            lo, hi = float(raw.min()), float(raw.max())
            if not hi > lo:
                raise VolumeError(f"{where}: every voxel is {lo}; give "
                                  f"{with_flag('volume.value_range')} to say what density "
                                  "that is")
            value_range = (lo, hi)
    lo, hi = (float(v) for v in value_range)
    if not (np.isfinite(lo) and np.isfinite(hi) and np.isfinite(hi - lo) and hi > lo):
        raise VolumeError(f"{where}: value range needs finite min < max, got {[lo, hi]}")
    if float32_exact(raw.dtype, lo, hi):
        data = np.empty(np.shape(raw), np.float32)   # the same values, in a quarter the time
        np.subtract(raw, np.float32(lo), out=data)
        data /= np.float32(hi - lo)
        return np.clip(data, 0.0, 1.0, out=data), (float(lo), float(hi))
    data = (raw.astype(np.float64) - lo) / (hi - lo)
    return np.clip(data, 0.0, 1.0).astype(np.float32), (float(lo), float(hi))


def float32_exact(dtype, lo: float, hi: float) -> bool:
    """Whether normalise's mapping (raw - lo) / (hi - lo) gives the same float32 densities
    computed in float32 as in float64: integers of at most 16 bits and a range of whole numbers
    within 2^23, so that raw - lo and hi - lo are exact in float32 (whole numbers below 2^24) and
    the one rounding left is the division's, correctly rounded either way (float64's quotient
    rounded again to float32 is float32's own: double rounding is innocuous for division where
    53 >= 2 x 24 + 1 bits, Figueroa 1995). tests/test_volume.py checks every 8- and 16-bit value."""
    dtype = np.dtype(dtype)
    return (dtype.kind in "ui" and dtype.itemsize <= 2
            and all(float(v).is_integer() and abs(v) <= 2 ** 23 for v in (lo, hi)))


def volume_from_canonical(raw: np.ndarray, spacing: tuple[float, float, float], name: str,
                          spec: VolumeSpec, channels: tuple | None, where: str,
                          fallback: tuple | None = None) -> Volume:
    """A Volume from raw values (c, z, y, x): one channel normalised by the volume's domain, or
    the channels to show each by its own (ChannelSpec.domain); `fallback`, per file channel, the
    domain where neither says (None: normalise's default, the data's own range)."""
    from radiance_probes.scene.channels import check_channel_count, default_channels
    count = raw.shape[0]
    if channels is None:
        channels = default_channels(count, where) if count > 1 else None
    if channels is None:
        data = raw[0]
        domain = spec.domain or (fallback[0] if fallback else None)
        norm, vr = normalise(data, domain, where, spec.replace_nonfinite)
        lo, hi = _finite_min_max(data)
        return Volume(norm, spacing, name, vr, data.dtype.name, lo, hi)
    check_channel_count(channels, count, where)
    norms, ranges, raws = [], [], []
    for i, ch in enumerate(channels):
        index = i if ch.index is None else ch.index
        data = raw[index]
        label = f"{where} (channel {index}{f' {ch.name}' if ch.name else ''})"
        domain = ch.domain(spec) or (fallback[index] if fallback else None)
        norm, vr = normalise(data, domain, label, spec.replace_nonfinite)
        norms.append(norm)
        ranges.append(vr)
        raws.append(_finite_min_max(data))
    if len(norms) == 1:
        return Volume(norms[0], spacing, name, ranges[0], raw.dtype.name, *raws[0])
    return Volume(np.stack(norms, axis=-1), spacing, name, ranges[0], raw.dtype.name,
                  raws[0][0], raws[0][1], channel_ranges=tuple(ranges), channel_raw=tuple(raws))


def _finite_min_max(raw: np.ndarray) -> tuple[float, float]:
    finite = raw[np.isfinite(raw)] if raw.dtype.kind == "f" else raw
    return (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
