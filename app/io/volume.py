"""Volumes: file loaders (.raw, .nrrd, .npy here; NIfTI, TIFF and DICOM in app/io/volume_formats.py),
built-in procedural volumes, normalisation.

A :class:`Volume` holds the density normalised to [0, 1] as SPEC.md says (``data[z, y, x]``,
x fastest) and the world box it fills: centred at the origin, extent ``dims * spacing`` scaled so
that the longest side is 1.
"""
from __future__ import annotations

import math
import re
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from radiance_probes.io import dicom
from radiance_probes.io import volume_formats as formats
from radiance_probes.io.orientation import NRRD_SPACES, patient_axes, to_patient, unit_columns
from radiance_probes.scene.flags import flag_for, with_flag
from radiance_probes.scene.types import Scene, VolumeError, VolumeSpec
from radiance_probes.io.volume_axes import resolve_axes, split_pages, to_canonical

# What load_volume takes, by file name ending (a folder is a TIFF stack, DICOM images or a Zarr
# store; a file named DICOMDIR indexes a DICOM set).
VOLUME_SUFFIXES = ((".raw", ".nrrd", ".nhdr", ".npy") + formats.NIFTI_SUFFIXES
                   + formats.TIFF_SUFFIXES + formats.ZARR_SUFFIXES)


def is_volume_path(p: Path) -> bool:
    """A file load_volume reads by its name, a DICOMDIR, or a folder (a TIFF stack or DICOM)."""
    return (p.is_dir() or formats.has_suffix(p, VOLUME_SUFFIXES + dicom.DICOM_SUFFIXES)
            or dicom.is_dicomdir(p))


RAW_DTYPES = {
    "uint8": np.uint8, "int8": np.int8, "uint16": np.uint16, "int16": np.int16,
    "uint32": np.uint32, "int32": np.int32, "float32": np.float32, "float64": np.float64,
}
_RAW_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_([a-z]+\d+)\.raw$", re.IGNORECASE)


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


# --------------------------------------------------------------------------------------------
# Built-in procedural volumes: deterministic, smooth, any size.

def _grid(size: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-centred coordinates in [-1, 1] along each axis, broadcastable as [z, y, x]."""
    nx, ny, nz = size
    x = ((np.arange(nx) + 0.5) / nx * 2 - 1).astype(np.float32)
    y = ((np.arange(ny) + 0.5) / ny * 2 - 1).astype(np.float32)
    z = ((np.arange(nz) + 0.5) / nz * 2 - 1).astype(np.float32)
    return x[None, None, :], y[None, :, None], z[:, None, None]


def _smoothstep(e0: float, e1: float, v: np.ndarray) -> np.ndarray:
    t = np.clip((v - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def builtin_cloud(size: tuple[int, int, int]) -> np.ndarray:
    """A cumulus-like cloud: many Gaussian puffs over a flattened base, eroded by smooth noise."""
    x, y, z = _grid(size)
    rng = np.random.default_rng(7)
    shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
    puffs = np.zeros(shape, np.float32)
    for _ in range(36):
        c = rng.normal(0.0, [0.3, 0.15, 0.27])
        c[1] = abs(c[1]) - 0.15  # towers rise from a common base
        r = rng.uniform(0.16, 0.34)
        puffs = np.maximum(puffs, np.exp(-(((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
                                           / (r * r))).astype(np.float32))
    noise = np.zeros(shape, np.float32)
    for octave in range(4):
        f = 5.0 * 2.0 ** octave
        for _ in range(3):
            k = rng.normal(size=3)
            k *= f / np.linalg.norm(k)
            noise += (np.sin(k[0] * x + k[1] * y + k[2] * z + rng.uniform(0, 2 * np.pi))
                      / (3 * 1.8 ** octave)).astype(np.float32)
    d = _smoothstep(0.3, 0.95, puffs + 0.35 * noise)
    d *= _smoothstep(0.95, 0.75, np.maximum(np.maximum(abs(x), abs(y)), abs(z)))  # zero at the box
    d *= _smoothstep(-0.45, -0.3, y)  # flat cloud base
    return (d / max(float(d.max()), 1e-6)).astype(np.float32)


def builtin_hydrogen(size: tuple[int, int, int]) -> np.ndarray:
    """Probability density of a hydrogen-like 3d_z2 orbital, |psi|^2 with psi ~ r^2 e^(-r/3)(3cos^2-1)."""
    x, y, z = _grid(size)
    s = 14.0  # Bohr radii from the centre to a face
    X, Y, Z = x * s, y * s, z * s
    r = np.sqrt(X * X + Y * Y + Z * Z) + 1e-6
    cos_t = Y / r  # orbital axis along world +y
    psi = r * r * np.exp(-r / 3.0) * (3 * cos_t * cos_t - 1)
    p = (psi * psi).astype(np.float32)
    return np.sqrt(p / p.max()).astype(np.float32)  # sqrt keeps the outer lobes visible


def builtin_sphere(size: tuple[int, int, int]) -> np.ndarray:
    """A solid ball of radius 0.6 (of the half box) with a one-voxel soft edge."""
    x, y, z = _grid(size)
    r = np.sqrt(x * x + y * y + z * z)
    edge = 2.0 / max(size)
    return (1.0 - _smoothstep(0.6 - edge, 0.6 + edge, r)).astype(np.float32)


def builtin_constant(size: tuple[int, int, int]) -> np.ndarray:
    """Density 1 everywhere: a homogeneous medium filling the box."""
    return np.ones(size[::-1], np.float32)


def builtin_empty(size: tuple[int, int, int]) -> np.ndarray:
    """Density 0 everywhere: vacuum."""
    return np.zeros(size[::-1], np.float32)


def builtin_sheet(size: tuple[int, int, int]) -> np.ndarray:
    """A thin slab one voxel thick across the middle of the box (normal along y)."""
    d = np.zeros(size[::-1], np.float32)
    d[:, size[1] // 2, :] = 1.0
    return d


def _voxel_edge(size: tuple[int, int, int]) -> float:
    """Half a voxel of the largest axis in _grid's [-1, 1] units: soft edges one voxel wide."""
    return 1.0 / max(size)


def _smooth_noise(size: tuple[int, int, int], seed: int, frequency: float,
                  octaves: int = 3) -> np.ndarray:
    """Deterministic smooth noise in about [-1, 1]: sums of random plane waves (any size)."""
    x, y, z = _grid(size)
    rng = np.random.default_rng(seed)
    shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
    noise = np.zeros(shape, np.float32)
    total = 0.0
    for octave in range(octaves):
        f = frequency * 2.0 ** octave
        for _ in range(3):
            k = rng.normal(size=3)
            k *= f / np.linalg.norm(k)
            amp = 1.0 / 2.0 ** octave
            noise += amp * np.sin(k[0] * x + k[1] * y + k[2] * z
                                  + rng.uniform(0, 2 * np.pi)).astype(np.float32)
            total += amp
    return noise / (total / 2.0)


def builtin_shell(size: tuple[int, int, int]) -> np.ndarray:
    """A thin spherical shell: radius 0.6 of the half box, about two voxels thick (at least 1.5%
    of the box), density 1 in the shell and 0 inside and out."""
    x, y, z = _grid(size)
    r = np.sqrt(x * x + y * y + z * z)
    half = max(2.0 / max(size), 0.015)
    edge = _voxel_edge(size)
    inner = _smoothstep(0.6 - half - edge, 0.6 - half + edge, r)
    outer = 1.0 - _smoothstep(0.6 + half - edge, 0.6 + half + edge, r)
    return (inner * outer).astype(np.float32)


def builtin_pinholes(size: tuple[int, int, int]) -> np.ndarray:
    """A dense slab across the box (normal along y, 1/8 of the box thick, at least 2 voxels)
    pierced by a 4 x 4 grid of round holes along y, each about 1/24 of the box wide (at least
    one voxel), in a thin haze (0.02) that shows the beams the holes let through."""
    x, y, z = _grid(size)
    half_thick = max(0.125, 2.0 / size[1])
    edge = _voxel_edge(size)
    slab = (_smoothstep(-half_thick - edge, -half_thick + edge, y)
            * (1.0 - _smoothstep(half_thick - edge, half_thick + edge, y)))
    radius = max(1.0 / 12.0, 1.5 / max(size[0], size[2]))
    centres = (np.arange(4) + 0.5) / 4 * 1.6 - 0.8
    hole = np.zeros(np.broadcast_shapes(x.shape, z.shape), np.float32)
    for cx in centres:
        for cz in centres:
            d = np.sqrt((x - cx) ** 2 + (z - cz) ** 2)
            hole = np.maximum(hole, 1.0 - _smoothstep(radius - edge, radius + edge, d))
    return np.maximum(slab * (1.0 - hole), 0.02).astype(np.float32)


def builtin_speck(size: tuple[int, int, int]) -> np.ndarray:
    """A tiny dense ball (radius 3% of the half box, at least 1.5 voxels) off centre in thin
    haze: density 1 in the ball, 0.02 in the haze around it."""
    x, y, z = _grid(size)
    r = np.sqrt((x - 0.2) ** 2 + (y - 0.1) ** 2 + (z + 0.15) ** 2)
    radius = max(0.03, 3.0 / max(size))
    edge = _voxel_edge(size)
    ball = 1.0 - _smoothstep(radius - edge, radius + edge, r)
    return np.maximum(ball, 0.02).astype(np.float32)


def builtin_filaments(size: tuple[int, int, int]) -> np.ndarray:
    """Sixteen straight filaments one voxel thick along random axes through the box (each voxel
    within half a voxel of a line's axis has density 1): structure finer than any probe grid."""
    nx, ny, nz = size
    rng = np.random.default_rng(11)
    d = np.zeros((nz, ny, nx), np.float32)
    steps = 4 * max(size)
    for _ in range(16):
        start = rng.uniform(-0.8, 0.8, size=3)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        t = np.linspace(-1.6, 1.6, steps)[:, None]
        points = start + t * direction
        inside = np.all(np.abs(points) < 1.0, axis=1)
        index = np.floor((points[inside] + 1.0) / 2.0 * np.array([nx, ny, nz])).astype(int)
        index = np.clip(index, 0, np.array([nx, ny, nz]) - 1)
        d[index[:, 2], index[:, 1], index[:, 0]] = 1.0
    return d


def builtin_head(size: tuple[int, int, int]) -> np.ndarray:
    """A head-like volume: nested noisy ellipsoids, values as a CT or MRI might give them: a thin
    skin (0.3, about two voxels), fat beneath it (0.15), a skull (1.0), a noisy dense brain
    (0.55 to 0.75) and ventricles (0.1) inside it."""
    x, y, z = _grid(size)
    edge = _voxel_edge(size)
    wobble = 0.03 * _smooth_noise(size, 21, 4.0, octaves=2)

    def ellipsoid(a, b, c, cy=0.0):
        return np.sqrt((x / a) ** 2 + ((y - cy) / b) ** 2 + (z / c) ** 2) + wobble

    def inside(e, radius=1.0):
        return 1.0 - _smoothstep(radius - edge * 2, radius + edge * 2, e)

    skin_thick = max(0.02, 2.5 / max(size))
    head = ellipsoid(0.72, 0.88, 0.8)
    skull = ellipsoid(0.72 - 2 * skin_thick, 0.88 - 2 * skin_thick, 0.8 - 2 * skin_thick)
    brain = ellipsoid(0.58, 0.74, 0.66)
    ventricles = np.sqrt((np.abs(x) - 0.12) ** 2 / 0.06 ** 2 + (y - 0.05) ** 2 / 0.2 ** 2
                         + z ** 2 / 0.25 ** 2)
    texture = 0.65 + 0.1 * _smooth_noise(size, 23, 18.0)
    d = 0.3 * inside(head)                                          # skin ...
    d = np.where(inside(head, 1.0 - skin_thick / 0.8) > 0.5, 0.15, d)   # ... over fat
    d = np.maximum(d * (1.0 - inside(skull)), 0.0) + 1.0 * inside(skull)
    d = np.where(inside(brain) > 0.5, texture, d)
    d = np.where((inside(brain) > 0.5) & (ventricles < 1.0), 0.1, d)
    return np.clip(d, 0.0, 1.0).astype(np.float32)


BUILTIN_VOLUMES: dict[str, Callable[[tuple[int, int, int]], np.ndarray]] = {
    "cloud": builtin_cloud,
    "hydrogen": builtin_hydrogen,
    "sphere": builtin_sphere,
    "constant": builtin_constant,
    "empty": builtin_empty,
    "sheet": builtin_sheet,
    "shell": builtin_shell,
    "pinholes": builtin_pinholes,
    "speck": builtin_speck,
    "filaments": builtin_filaments,
    "head": builtin_head,
}


# --------------------------------------------------------------------------------------------
# Files

def _resolve(path: str, base_dir: str | None) -> Path:
    p = Path(path).expanduser()
    if p.exists() or p.is_absolute() or base_dir is None:
        return p
    alt = Path(base_dir) / p
    return alt if alt.exists() else p


def _one_line(exc: BaseException) -> str:
    """A library's error message on one line (some span several)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _read_raw(p: Path, dims: tuple[int, int, int] | None, dtype: str | None) -> np.ndarray:
    m = _RAW_NAME.search(p.name)
    if dims is None:
        if not m:
            raise VolumeError(f"{p}: cannot tell the dimensions from the name; expected "
                              "'name_XxYxZ_dtype.raw' or give "
                              f"{with_flag('volume.dims')} and {with_flag('volume.dtype')}")
        dims = (int(m.group(1)), int(m.group(2)), int(m.group(3)))
    if dtype is None:
        if not m:
            raise VolumeError(f"{p}: cannot tell the data type from the name; give "
                              f"{with_flag('volume.dtype')}")
        dtype = m.group(4).lower()
    if dtype not in RAW_DTYPES:
        raise VolumeError(f"{p}: unknown data type '{dtype}' (known: {', '.join(RAW_DTYPES)})")
    if min(dims) < 1:
        raise VolumeError(f"{p}: dimensions must be at least 1, got {dims}")
    np_dtype = np.dtype(RAW_DTYPES[dtype]).newbyteorder("<")
    expected = math.prod(dims) * np_dtype.itemsize   # Python integers: no 64-bit wrap-around
    actual = p.stat().st_size
    if actual != expected:
        raise VolumeError(f"{p}: file has {actual} bytes but {dims[0]}x{dims[1]}x{dims[2]} {dtype} "
                          f"needs {expected}")
    return np.fromfile(p, dtype=np_dtype).reshape(dims[2], dims[1], dims[0])


def _read_nrrd(p: Path) -> tuple[np.ndarray, tuple[float, float, float] | None, np.ndarray | None]:
    """The array (first, fastest axis = x), its spacing, and its axes' directions in LPS where the
    header gives an anatomical `space` and `space directions`."""
    import warnings

    import nrrd
    try:
        with warnings.catch_warnings():
            # NumPy warns (and pynrrd goes on with garbage) when a header's numbers do not fit.
            warnings.simplefilter("error", RuntimeWarning)
            data, header = nrrd.read(str(p), index_order="C")
    except Exception as exc:  # pynrrd raises several types for malformed files
        raise VolumeError(f"{p}: cannot read NRRD ({_one_line(exc)})") from None
    if data.ndim != 3:
        raise VolumeError(f"{p}: expected a 3D volume, the NRRD has {data.ndim} dimensions")
    spacing = None
    try:
        if "spacings" in header:
            spacing = tuple(float(s) for s in header["spacings"])
        elif "space directions" in header:
            dirs = np.asarray(header["space directions"], dtype=np.float64)
            spacing = tuple(float(np.linalg.norm(v)) for v in dirs)
    except (TypeError, ValueError) as exc:
        raise VolumeError(f"{p}: cannot read the NRRD's spacing ({_one_line(exc)})") from None
    if spacing is not None and len(spacing) != 3:
        raise VolumeError(f"{p}: the NRRD gives {len(spacing)} spacings for 3 axes")
    direction = None
    signs = NRRD_SPACES.get(str(header.get("space", "")).strip().lower())
    if signs is not None and "space directions" in header:
        try:
            dirs = np.asarray(header["space directions"], dtype=np.float64)
        except (TypeError, ValueError):
            dirs = None
        if dirs is not None and dirs.shape == (3, 3):   # rows: axes x, y, z
            direction = unit_columns(np.diag(signs) @ dirs.T)
    return data, spacing, direction


def _read_npy(p: Path) -> np.ndarray:
    try:
        data = np.load(p, allow_pickle=False)
    except Exception as exc:
        raise VolumeError(f"{p}: cannot read .npy ({_one_line(exc)})") from None
    if data.ndim < 3:
        raise VolumeError(f"{p}: expected a 3D array [z, y, x] (or 4D or 5D with channels and "
                          f"time steps: see {with_flag('volume.axes')}), got shape {list(data.shape)}")
    return data


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


def read_volume_array(spec: VolumeSpec, base_dir: str | None = None) -> "VolumeFile":
    """A volume file's raw values as (t, c, z, y, x) (app/io/volume_axes.py: axes from the file's
    metadata or volume.axes, refused where neither says), with what else the file says
    (VolumeFile)."""
    p = _resolve(spec.path, base_dir)
    need_spacing = spec.spacing is None
    file_spacing = direction = None
    notes: tuple[str, ...] = ()
    listing = series = None
    axes: str | None = "zyx"
    if spec.series is not None and not (p.is_dir() or dicom.is_dicomdir(p)):
        raise VolumeError(f"{p}: {with_flag('volume.series')} {spec.series} names a DICOM series, "
                          "but this is not a DICOM folder or DICOMDIR")
    if formats.is_zarr(p):
        raw, file_spacing, axes = formats.read_zarr(p, need_spacing)
    elif p.is_dir() and spec.series is None and formats.tiff_files(p):
        raw, axes = formats.read_tiff_folder(p)
    elif p.is_dir() or dicom.is_dicomdir(p):
        got = dicom.read_dicom(p, need_spacing, spec.series)
        raw, file_spacing, direction, notes = got.data, got.spacing, got.direction, got.notes
        listing, series = got.listing, got.series
    elif not p.is_file():
        raise VolumeError(f"{p}: volume file not found")
    elif formats.has_suffix(p, formats.NIFTI_SUFFIXES):
        raw, file_spacing, direction, axes = formats.read_nifti(p, need_spacing)
    elif formats.has_suffix(p, formats.TIFF_SUFFIXES):
        raw, axes = formats.read_tiff(p)
    elif dicom.is_dicom_file(p) and not formats.has_suffix(p, VOLUME_SUFFIXES):
        if dicom.frames_in(p) < 2:
            raise VolumeError(f"{p}: a single DICOM file of one slice; give the folder holding "
                              "its series")
        got = dicom.read_dicom(p, need_spacing, None)   # a multi-frame file: a volume of its own
        raw, file_spacing, direction, notes = got.data, got.spacing, got.direction, got.notes
        listing, series = got.listing, got.series
    else:
        suffix = p.suffix.lower()
        if suffix == ".raw":
            raw = _read_raw(p, spec.dims, spec.dtype)
        elif suffix in (".nrrd", ".nhdr"):
            raw, file_spacing, direction = _read_nrrd(p)
        elif suffix == ".npy":
            raw, axes = _read_npy(p), None
        else:
            raise VolumeError(f"{p}: unknown volume format '{suffix}' (known: "
                              f"{', '.join(VOLUME_SUFFIXES)}, a DICOMDIR, a Zarr store, or a "
                              "folder of TIFF or DICOM slices)")
    raw, axes, scene_axes = split_pages(raw, axes, spec.axes, str(p))
    notes += _page_stack_note(p, raw, axes, scene_axes)
    raw = to_canonical(raw, resolve_axes(axes, tuple(raw.shape), scene_axes, str(p)), str(p))
    if min(raw.shape) < 1:
        raise VolumeError(f"{p}: volume has zero size, shape {raw.shape[:1:-1]} (x, y, z)")
    return VolumeFile(raw, file_spacing if need_spacing else None, p.name, direction, notes,
                      listing, series)


def time_note(name: str, steps: int, time: int) -> tuple[str, ...]:
    """A volume with a time axis says so: how many steps, which is shown, how to show another."""
    if steps < 2:
        return ()
    return (f"{name} is a time series of {steps} steps; showing step {time} (--time N, or the "
            f"scene's time, picks another from 0 to {steps - 1}; the viewer's Time panel plays "
            "them)",)


def _page_stack_note(p: Path, raw: np.ndarray, axes: str | None, scene_axes: str | None
                     ) -> tuple[str, ...]:
    """A plain multi-page TIFF (its pages unnamed, read as z) whose page count a plausible channel
    count divides: a note that says so, and how to read the pages as channels instead."""
    if (scene_axes is not None or axes is None or raw.ndim != 3 or axes.count("?") != 1
            or not formats.has_suffix(p, formats.TIFF_SUFFIXES)):
        return ()
    pages = raw.shape[axes.index("?")]
    counts = [c for c in (3, 4) if pages % c == 0 and pages > c]
    if not counts:
        return ()
    ways = " or ".join(f"c{c}zyx ({c} channels of {pages // c} slices)" for c in counts)
    return (f"{p.name}: its {pages} pages carry no axes metadata and were read as {pages} z "
            f"slices; if they hold channels one after another, read them with --axes {ways} "
            f"(--set volume.axes=c{counts[0]}zyx; zc{counts[0]}yx where the channels alternate "
            "page by page)",)


@dataclass(frozen=True, eq=False)
class VolumeFile:
    """What read_volume_array found: the raw values (t, c, z, y, x), the file's spacing (None
    where it has none or the scene gives one), its name, the axes' directions in LPS where the
    file says, notes for a person, and a DICOM set's listing and the series read."""
    raw: np.ndarray
    spacing: tuple[float, float, float] | None
    name: str
    direction: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    listing: object = None
    series: object = None


def load_volume(spec: VolumeSpec, base_dir: str | None = None,
                channels: tuple | None = None, time: int = 0,
                brick: int | None = None) -> Volume:
    """Load the volume a scene names: a built-in or a file; errors name the file and the problem.
    `channels`: the channels to show (app/scene/channels.py effective_channels; None: a file of one
    channel, or its channels with their defaults). `time`: the step of a time series (SPEC.md,
    Time series: every step normalised alike, by the whole series' range where the scene gives
    none). A Zarr store larger than app/io/bricks.py LAZY_BYTES or LAZY_SIDE, or any with `brick`
    given, is read brick by brick (bricks of `brick` voxels, default 64) instead of whole."""
    spacing = spec.spacing if spec.spacing is not None else (1.0, 1.0, 1.0)
    if spec.path is None:
        name = spec.builtin or "cloud"
        if name not in BUILTIN_VOLUMES:
            raise VolumeError(f"unknown built-in volume '{name}' (known: {', '.join(BUILTIN_VOLUMES)})")
        if time != 0:
            raise VolumeError(f"built-in '{name}': time step {time} asked for, but the volume has "
                              "no time axis (one step); see the scene's time (--time STEP)")
        if spec.rescale is not None:
            raise VolumeError(f"built-in '{name}': {with_flag('volume.rescale')} applies to a "
                              "file's stored values")
        data = BUILTIN_VOLUMES[name](tuple(spec.size))
        domain = spec.domain
        if channels is not None:
            from radiance_probes.scene.channels import check_channel_count
            check_channel_count(channels, 1, f"built-in '{name}'")
            domain = channels[0].domain(spec)
        vr = domain or (0.0, 1.0)
        norm, vr = normalise(data, vr, f"built-in '{name}'")
        return Volume(norm, tuple(float(v) for v in spacing), f"builtin:{name}", vr, "float32",
                      float(data.min()), float(data.max()))
    p = _resolve(spec.path, base_dir)
    if formats.is_zarr(p) and (brick is not None or _large_zarr(p)) and spec.rescale is not None:
        raise VolumeError(f"{p}: {with_flag('volume.rescale')} is not applied to a Zarr store read "
                          "brick by brick; give its range in stored values "
                          f"({with_flag('volume.value_range')})")
    if formats.is_zarr(p) and (brick is not None or _large_zarr(p)):
        from radiance_probes.io.brick_layout import DEFAULT_BRICK_SIZE
        return lazy_zarr_volume(p, spec, time, channels, brick or DEFAULT_BRICK_SIZE)
    found = _read_series(spec, base_dir)
    raw, name, direction, notes = found.raw, found.name, found.direction, found.notes
    where = str(_resolve(spec.path, base_dir))
    if spec.rescale is not None:
        if found.series is not None:
            raise VolumeError(f"{where}: {with_flag('volume.rescale')} is for data exported without "
                              "its units; a DICOM series carries its own RescaleSlope and "
                              "RescaleIntercept, which are applied")
        slope, intercept = spec.rescale
        raw = raw.astype(np.float32) * np.float32(slope) + np.float32(intercept)
    if found.spacing is not None:
        spacing = found.spacing  # the header's spacing unless the scene gives one (even 1, 1, 1)
    if any(not (s > 0 and np.isfinite(s)) for s in spacing):
        raise VolumeError(f"{where}: spacing must be positive, got {spacing}")
    steps = raw.shape[0]
    if not 0 <= time < steps:
        raise VolumeError(f"{where}: time step {time} asked for, but the volume has "
                          + (f"{steps} time steps (0 to {steps - 1})" if steps > 1 else
                             "no time axis (one step)") + "; see the scene's time (--time STEP)")
    fallback = _series_domains(raw, spec) if steps > 1 else None
    notes += time_note(name, steps, time)
    step = raw[time]
    oblique = 0.0
    orientation = "data"
    if spec.orientation == "patient":
        if direction is None:
            notes += (f"{name} says nothing of the patient's orientation: shown as stored "
                      "(orientation \"data\")",)
        else:   # every channel placed alike (the same permutation and flips)
            placed = [to_patient(step[c], spacing, direction) for c in range(step.shape[0])]
            step = np.stack([p.data for p in placed])
            direction, orientation = placed[0].direction, "patient"
            # a scene's spacing is given along the file's axes, like the header's
            spacing = placed[0].spacing
            oblique = placed[0].oblique_degrees
            if oblique:
                notes += (f"{name} was scanned obliquely: its axes lie {oblique:.1f} degrees "
                          "from the patient's; shown on the nearest patient axes (permuted and "
                          f"flipped, not resampled: {patient_axes(direction)})",)
    volume = volume_from_canonical(step, tuple(float(s) for s in spacing), name, spec,
                                   channels, where, fallback)
    return dataclasses.replace(
        volume, notes=notes, direction=direction, orientation=orientation,
        oblique_degrees=oblique, dicom_listing=found.listing, dicom_series=found.series,
        **({"time": time, "time_steps": steps} if steps > 1 else {}))


# A Zarr volume larger than this (as float32) or longer than LAZY_SIDE along an axis is read
# brick by brick (app/io/volume.py load_volume) instead of whole.
LAZY_BYTES = 1 << 30
LAZY_SIDE = 2048


def lazy_zarr_volume(p, spec, time: int, channels, brick: int):
    """A Volume of a Zarr store read brick by brick (Volume.data a LazyData, Volume.bricks its
    BrickStore, Volume.levels the store's coarser levels, which read the same channels with the
    same value ranges): the time step `time`, the channels shown (as the whole loader chooses
    them: volume_from_canonical; several read as [z, y, x, c]); each channel normalised as the
    whole loader does (its value range, else the type's for 8-bit data, else its least and
    largest value, from the range pass)."""
    from radiance_probes.io.bricks import BrickStore, LazyData
    from radiance_probes.io.brick_sources import ZarrSource
    from radiance_probes.scene.channels import check_channel_count, default_channels
    from radiance_probes.scene.types import MAX_CHANNELS
    from radiance_probes.io.volume_formats import open_zarr
    where = str(p)
    array, file_spacing, axes, levels = open_zarr(p, spec.spacing is None)
    axes = resolve_axes(axes, tuple(array.shape), spec.axes, where)
    if any(a not in "tczyx" for a in axes) or not all(a in axes for a in "zyx"):
        raise VolumeError(f"{where}: axes {axes!r}; a bricked Zarr store needs z, y and x")
    size = dict(zip(axes, array.shape))
    steps = size.get("t", 1)
    if not 0 <= time < steps:
        raise VolumeError(f"{where}: time step {time} asked for, but the volume has "
                          + (f"{steps} time steps (0 to {steps - 1})" if steps > 1 else
                             "no time axis (one step)") + "; see the scene's time (--time STEP)")
    count = size.get("c", 1)
    if channels is None and count > 1:
        channels = default_channels(count, where)       # more than MAX_CHANNELS refused
    if channels is not None:
        if len(channels) > MAX_CHANNELS:
            raise VolumeError(f"{where}: {len(channels)} channels, at most {MAX_CHANNELS} are "
                              "shown at once (choose them with channels[i].index, "
                              f"{flag_for('channels')})")
        check_channel_count(channels, count, where)     # a channel the store lacks refused
        shown = [i if ch.index is None else ch.index for i, ch in enumerate(channels)]
        labels = [f"{where} (channel {index}{f' {ch.name}' if ch.name else ''})"
                  for index, ch in zip(shown, channels)]
        domains = [ch.domain(spec) for ch in channels]
    else:
        shown, labels, domains = [0], [where], [spec.domain]
    many = len(shown) > 1
    spacing = spec.spacing or file_spacing or (1.0, 1.0, 1.0)

    def source_of(a, ranges, step=time):
        return ZarrSource(a, axes, step, shown[0], ranges[0], where, spec.replace_nonfinite,
                          normalise, channels=shown if many else None, value_ranges=ranges)

    source = source_of(array, [None] * len(shown))
    store = BrickStore(source, brick, p.name)
    # The range pass (every brick read once) is needed here only where a channel's values map
    # by its own least and largest; else it waits for the placement, which may never need it
    # (a cap that a coarser level shows that level 0 exceeds: app/rendering/levels/volume_placement.py),
    # and the raw extremes are NaN until it is read (Volume.raw_extents).
    by_extremes = (any(d is None for d in domains)
                   and array.dtype not in (np.uint8, np.int8))
    if by_extremes:
        lows, highs = store.raw_extremes()
    else:
        lows = highs = np.full(len(shown), np.nan)
    series_lows, series_highs = lows, highs
    if steps > 1 and by_extremes:
        # SPEC.md, Time series: every step normalised alike, by the whole series' range where
        # the scene gives none: each other step's range pass (once per store)
        series_lows, series_highs = _series_extremes(
            p, steps, time, lows, highs, lambda step: source_of(array, [None] * len(shown), step),
            brick, (axes, tuple(shown), spec.replace_nonfinite))
    ranges, raws = [], []
    for c, (domain, label) in enumerate(zip(domains, labels)):
        # the channel's least and largest raw values (of the series, where it is one),
        # normalised as the whole loader normalises the channel: its domain, else the type's
        # (8-bit), else these (refused where equal); raw_min/max are the step's own
        extremes = (np.array([series_lows[c], series_highs[c]], array.dtype) if by_extremes
                    else np.zeros(2, array.dtype))     # (a domain: the values are not looked at)
        ranges.append(normalise(extremes, domain, label)[1])
        raws.append((float(lows[c]), float(highs[c])))
    source.value_range, source.value_ranges = ranges[0], ranges
    coarser = [source_of(a, ranges) for a in levels[1:]]
    notes = time_note(p.name, steps, time)
    if spec.orientation == "patient":
        notes += (f"{p.name} says nothing of the patient's orientation: shown as stored "
                  "(orientation \"data\")",)
    volume = Volume(LazyData(store), tuple(float(v) for v in spacing), p.name, ranges[0],
                    array.dtype.name, *raws[0], notes=notes, bricks=store,
                    levels=tuple(coarser),
                    **({"channel_ranges": tuple(ranges), "channel_raw": tuple(raws)}
                       if many else {}))
    return dataclasses.replace(volume, time=time, time_steps=steps) if steps > 1 else volume


# Each bricked time series' raw extremes over all its steps, per channel shown: {key: (lows, highs)}.
_SERIES_EXTREMES: dict = {}


def _series_extremes(p, steps: int, time: int, lows, highs, source_at, brick: int, reading):
    """Per channel shown, the least and largest raw values over every step of a bricked Zarr
    time series (`lows`, `highs`: step `time`'s, already read; source_at(step): a step's
    ZarrSource; `reading`: what else the values depend on): the other steps' range passes, once
    per store (kept while its files are unchanged)."""
    from radiance_probes.io.bricks import BrickStore
    try:
        stamp = p.stat().st_mtime_ns
    except OSError:
        stamp = None
    key = (str(p.resolve()), stamp, reading)
    if key not in _SERIES_EXTREMES or stamp is None:
        lo, hi = np.array(lows), np.array(highs)
        for step in range(steps):
            if step == time:
                continue
            step_lo, step_hi = BrickStore(source_at(step), brick, p.name).raw_extremes()
            lo, hi = np.minimum(lo, step_lo), np.maximum(hi, step_hi)
        _SERIES_EXTREMES.clear()          # one series at a time
        _SERIES_EXTREMES[key] = (lo, hi)
    return _SERIES_EXTREMES[key]


def _large_zarr(p: Path) -> bool:
    """A Zarr store too large to read whole (app/io/bricks.py LAZY_BYTES, LAZY_SIDE)."""
    array = formats.open_zarr(p)[0]
    spatial = sorted(array.shape)[-3:]
    return 4 * int(np.prod(array.shape, dtype=np.int64)) > LAZY_BYTES or max(spatial) > LAZY_SIDE


# The last time series read (app/io/volume.py _read_series): its key and (raw, spacing, name).
_SERIES_CACHE: list = []


def _read_series(spec: VolumeSpec, base_dir: str | None):
    """read_volume_array, kept in memory for a time series (one at a time), so that showing
    another step normalises that step and never reads the file again."""
    p = _resolve(spec.path, base_dir)
    try:
        stamp = p.stat().st_mtime_ns
    except OSError:
        stamp = None
    key = (str(p.resolve()) if stamp is not None else str(p), stamp, spec.axes, spec.dims,
           spec.dtype, spec.spacing, spec.series)
    if _SERIES_CACHE and _SERIES_CACHE[0][0] == key and stamp is not None:
        return _SERIES_CACHE[0][1]
    found = read_volume_array(spec, base_dir)
    _SERIES_CACHE.clear()
    if found.raw.shape[0] > 1:
        _SERIES_CACHE.append((key, found))
    return found


def _series_domains(raw: np.ndarray, spec: VolumeSpec) -> tuple:
    """Per channel, the values a time series' steps map to 0 and 1 where neither the scene nor
    the type says (normalise's own default): the least and largest over every step, so that one
    value is one density at every step (None where the type decides: 8-bit data)."""
    out = []
    for c in range(raw.shape[1]):
        data = raw[:, c]
        if data.dtype in (np.uint8, np.int8):
            out.append(None)
            continue
        lo, hi = _finite_min_max(data)
        out.append((lo, hi) if hi > lo else None)
    return tuple(out)


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


def volume_from_array(array, axes: str = "zyx", spacing=(1.0, 1.0, 1.0),
                      value_range: tuple[float, float] | None = None,
                      channels: tuple | None = None, time: int = 0,
                      name: str = "array") -> Volume:
    """A Volume from a NumPy array in memory (the Python API's way in): `axes` names its axes as
    volume.axes does ("zyx", "czyx", "tzyx", "tczyx", ...); `channels` and `time` as the scene's
    (app/scene/channels.py, SPEC.md); normalised as a file's would be. Errors are VolumeErrors naming
    the problem."""
    from radiance_probes.io.volume_axes import resolve_axes, to_canonical
    data = np.asarray(array)
    if not isinstance(axes, str):
        raise VolumeError(f"{name}: axes must be a string such as \"czyx\", got {axes!r}")
    raw = to_canonical(data, resolve_axes(None, tuple(data.shape), axes.lower(), name), name)
    if min(raw.shape) < 1:
        raise VolumeError(f"{name}: volume has zero size, shape {list(data.shape)}")
    spacing = tuple(float(v) for v in spacing)
    if len(spacing) != 3 or any(not (v > 0 and np.isfinite(v)) for v in spacing):
        raise VolumeError(f"{name}: spacing must be three positive numbers, got {list(spacing)}")
    steps = raw.shape[0]
    if not 0 <= time < steps:
        raise VolumeError(f"{name}: time step {time} asked for, but the array has "
                          + (f"{steps} time steps" if steps > 1 else "no time axis"))
    spec = VolumeSpec(path=name, builtin=None, value_range=value_range)
    volume = volume_from_canonical(raw[time], spacing, name, spec, channels, name,
                                   _series_domains(raw, spec) if steps > 1 else None)
    return dataclasses.replace(volume, time=time, time_steps=steps) if steps > 1 else volume


def _finite_min_max(raw: np.ndarray) -> tuple[float, float]:
    finite = raw[np.isfinite(raw)] if raw.dtype.kind == "f" else raw
    return (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)


def load_scene_volume(scene: Scene, brick: int | None = None) -> Volume:
    from radiance_probes.scene.channels import scene_channels
    from radiance_probes.scene.clinical_presets import check_hounsfield
    volume = load_volume(scene.volume, scene.base_dir, scene_channels(scene), scene.time, brick)
    if not scene.channels:
        # a CT window or clinical preset on data not in Hounsfield units: refused, naming both
        check_hounsfield(scene.volume, scene.transfer_function.preset, volume)
    return volume


# A preview of a Zarr store read brick by brick (app/rendering/levels/progressive_open.py): its finest level
# of at most this many voxels, read whole (256^3 of a 2048^3 store: a fraction of a second).
PREVIEW_VOXELS = 1 << 25


def reads_lazily(scene: Scene, brick: int | None = None) -> bool:
    """Whether the scene's volume is a Zarr store that load_volume reads brick by brick."""
    spec = scene.volume
    if spec.path is None:
        return False
    p = _resolve(spec.path, scene.base_dir)
    return formats.is_zarr(p) and (brick is not None or _large_zarr(p))


def zarr_preview(scene: Scene, max_voxels: int = PREVIEW_VOXELS,
                 memory_bytes: int | None = None) -> Volume | None:
    """A quick stand-in for a Zarr store read brick by brick, in the same world box: the finest
    of its own coarser levels (OME-Zarr multiscales) of at most `max_voxels` voxels (and within
    `memory_bytes` as float32, the volume's GPU memory cap), read whole,
    normalised by the scene's value range, else the type's for 8-bit data, else the level's own
    least and largest (which its note calls provisional: the store's are known only after its
    range pass); where the store has no such level, an empty box. None for a store of several
    channels, or a time step it lacks (the full open says what is wrong)."""
    from radiance_probes.io.brick_sources import ZarrSource
    from radiance_probes.scene.channels import scene_channels
    from radiance_probes.io.volume_formats import open_zarr
    spec = scene.volume
    p = _resolve(spec.path, scene.base_dir)
    where = str(p)
    array, file_spacing, axes, levels = open_zarr(p, spec.spacing is None)
    axes = resolve_axes(axes, tuple(array.shape), spec.axes, where)
    size = dict(zip(axes, array.shape))
    channels = scene_channels(scene)
    if size.get("c", 1) > 1 or (channels is not None and len(channels) > 1):
        return None
    if not 0 <= scene.time < size.get("t", 1):
        return None
    spacing = spec.spacing or file_spacing or (1.0, 1.0, 1.0)
    dims0 = [size[a] for a in "xyz"]
    if memory_bytes is not None:
        max_voxels = min(max_voxels, memory_bytes // 4)

    def in_box(data, note, value_range=(0.0, 1.0), lo=0.0, hi=0.0) -> Volume:
        dims = data.shape[:3][::-1]
        scaled = tuple(float(s) * n0 / n for s, n0, n in zip(spacing, dims0, dims))
        return Volume(data, scaled, p.name, value_range, array.dtype.name, lo, hi, notes=(note,))

    small = [a for a in levels[1:]
             if int(np.prod([dict(zip(axes, a.shape))[k] for k in "zyx"])) <= max_voxels]
    domain = spec.domain if channels is None else channels[0].domain(spec)
    raw = None
    if small:
        level = small[0]
        shape = [dict(zip(axes, level.shape))[k] for k in "zyx"]
        source = ZarrSource(level, axes, scene.time, 0, domain, where, spec.replace_nonfinite,
                            normalise)
        raw = source.read(0, shape[0], 0, shape[1], 0, shape[2])
        if domain is None and raw.dtype not in (np.uint8, np.int8) and not raw.max() > raw.min():
            raw = None
    if raw is None:
        return in_box(np.zeros((2, 2, 2), np.float32),
                      f"{p.name} is loading; it has no level small enough to preview")
    provisional = ""
    if domain is None and raw.dtype not in (np.uint8, np.int8):
        provisional = (" (densities provisional: this level's own least and largest values, until "
                       "the store's range pass)")
    data, value_range = normalise(raw, domain, where)
    nz = raw.shape[0]
    note = (f"preview: a {size['z'] / nz:.0f}x coarser level ({raw.shape[2]} x {raw.shape[1]} x "
            f"{nz}) while {p.name} loads{provisional}")
    return in_box(data, note, value_range, float(raw.min()), float(raw.max()))
