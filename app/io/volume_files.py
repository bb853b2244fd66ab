"""A volume file or folder read into its raw array: `.raw` (the Open SciVis naming or given
dimensions), NRRD, `.npy`, and through app/io/volume_formats.py and app/io/dicom.py NIfTI, TIFF,
Zarr and DICOM; a time series' steps; the notes a reading leaves (time step, page stacks)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radiance_probes.io import dicom
from radiance_probes.io import volume_formats as formats
from radiance_probes.io.orientation import NRRD_SPACES, unit_columns
from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError, VolumeSpec
from radiance_probes.io.volume_axes import resolve_axes, split_pages, to_canonical
from radiance_probes.io.volume import VOLUME_SUFFIXES, _finite_min_max


RAW_DTYPES = {
    "uint8": np.uint8, "int8": np.int8, "uint16": np.uint16, "int16": np.int16,
    "uint32": np.uint32, "int32": np.int32, "float32": np.float32, "float64": np.float64,
}


_RAW_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_([a-z]+\d+)\.raw$", re.IGNORECASE)


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
