"""Medical and microscopy volume files read with the libraries made for them: NIfTI (nibabel) and
TIFF stacks (tifffile), each mapped to ``data[z, y, x]`` as docs/scene-format.md says (DICOM series:
app/io/dicom.py). Orientation matrices are returned as metadata; app/io/volume.py applies them where
the scene asks for ``"orientation": "patient"`` (app/io/orientation.py).

Every problem, whatever the library raises, ends in one :class:`VolumeError` naming the file (or
folder) and the problem. ``app/io/volume.py`` normalises the array like any other format's.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from radiance_probes.io.orientation import RAS_TO_LPS, unit_columns
from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError
from radiance_probes.io.volume_axes import tiff_axes

NIFTI_SUFFIXES = (".nii", ".nii.gz")
ZARR_SUFFIXES = (".zarr",)
# Files that make a folder a Zarr store (version 2: .zarray or .zgroup; version 3: zarr.json).
ZARR_MARKERS = (".zarray", ".zgroup", "zarr.json")
TIFF_SUFFIXES = (".tif", ".tiff")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def has_suffix(p: Path, suffixes: tuple[str, ...]) -> bool:
    name = p.name.lower()
    return any(name.endswith(s) for s in suffixes)


def spacing_or_none(values, where: str, need: bool) -> tuple[float, float, float] | None:
    """The header's three voxel sizes, or None (with the scene giving its own); a header without
    usable sizes is an error only when the scene gives none."""
    try:
        spacing = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        spacing = ()
    if len(spacing) == 3 and all(np.isfinite(s) and s > 0 for s in spacing):
        return spacing
    if need:
        shown = "absent" if not spacing else "[" + ", ".join(f"{s:g}" for s in spacing) + "]"
        raise VolumeError(f"{where}: missing spacing: the header's voxel sizes are {shown}; give "
                          f"{with_flag('volume.spacing')}")
    return None


# ---- NIfTI ---------------------------------------------------------------------------------------

def read_nifti(p: Path, need_spacing: bool
               ) -> tuple[np.ndarray, tuple[float, float, float] | None, np.ndarray | None, str]:
    """The stored array ``[i, j, k]`` becomes ``data[k, j, i]`` (a 4D ``[i, j, k, t]``, a time
    series, ``data[t, k, j, i]``); spacing from the voxel sizes (pixdim); scl_slope/scl_inter
    applied (nibabel's array proxy applies them, keeping the stored integer type where they are
    the identity). Also the axes' directions in LPS from the sform, else the qform (RAS in the
    file), or None where neither is set (codes 0). Returns the array, the spacing, the directions
    and the array's axes ("zyx" or "tzyx")."""
    import nibabel as nib
    try:
        img = nib.load(str(p))
        if not isinstance(img, (nib.Nifti1Image, nib.Nifti2Image)):
            raise VolumeError(f"{p}: not a NIfTI image ({type(img).__name__})")
        shape = tuple(int(s) for s in img.shape)
        # The header as stored: nibabel's load "fixes" zero voxel sizes to 1, which would hide
        # a header without spacing.
        with nib.openers.ImageOpener(str(p)) as fobj:
            zooms = type(img.header).from_fileobj(fobj, check=False).get_zooms()
        if len(shape) == 4 and shape[3] == 1:
            shape = shape[:3]
        if len(shape) not in (3, 4):
            raise VolumeError(f"{p}: expected a 3D volume or a 4D time series [i, j, k, t], the "
                              f"NIfTI has shape {list(img.shape)}")
        data = np.asanyarray(img.dataobj).reshape(shape)
        direction = _nifti_direction(img)
    except VolumeError:
        raise
    except Exception as exc:  # nibabel raises many types for truncated or corrupt files
        raise VolumeError(f"{p}: cannot read NIfTI ({_one_line(exc)})") from None
    if data.dtype.names is not None:
        raise VolumeError(f"{p}: NIfTI with {data.dtype.names} channels; expected one scalar")
    spacing = spacing_or_none(zooms[:3], str(p), need_spacing)
    if data.ndim == 4:
        return np.ascontiguousarray(data.transpose(3, 2, 1, 0)), spacing, direction, "tzyx"
    return np.ascontiguousarray(data.transpose(2, 1, 0)), spacing, direction, "zyx"


def _nifti_direction(img) -> np.ndarray | None:
    """The directions of i, j, k (= x, y, z) in LPS, from the sform (else the qform) where its code
    says it is set."""
    for get in (img.header.get_sform, img.header.get_qform):
        affine, code = get(coded=True)
        if affine is not None and int(code) > 0:
            return unit_columns(RAS_TO_LPS @ np.asarray(affine, np.float64)[:3, :3])
    return None


# ---- TIFF ----------------------------------------------------------------------------------------

class _LogCollector(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def _tiff_series(p: Path) -> tuple[np.ndarray, str]:
    """The file's image as tifffile reads its first series, with that series' axes in our
    letters (app/io/volume_axes.py tiff_axes); a file of several series of single pages (a stack
    written page by page) as those pages, unnamed ("?yx")."""
    import tifffile
    errors = _LogCollector()
    log = logging.getLogger("tifffile")
    log.addHandler(errors)
    try:
        with tifffile.TiffFile(str(p)) as tif:
            series = list(tif.series)
            if len(series) == 1:
                data, axes, shape = series[0].asarray(), series[0].axes, series[0].shape
            elif series and all(len(s.shape) == 2 for s in series):
                pages = [s.asarray() for s in series]
                data, axes, shape = None, "IYX", None
            elif series:
                shapes = ", ".join(f"{s.axes} {list(s.shape)}" for s in series[:4])
                raise VolumeError(f"{p}: the TIFF holds {len(series)} images ({shapes}); "
                                  "expected one volume")
    except VolumeError:
        raise
    except Exception as exc:
        raise VolumeError(f"{p}: cannot read TIFF ({_one_line(exc)})") from None
    finally:
        log.removeHandler(errors)
    if errors.messages:  # tifffile logs (and skips) what it cannot read, e.g. a truncated file
        raise VolumeError(f"{p}: cannot read TIFF ({' '.join(errors.messages[0].split())})")
    if not series:
        raise VolumeError(f"{p}: the TIFF has no pages")
    if data is None:
        data = _stack(pages, [f"page {i}" for i in range(len(pages))], str(p))
        shape = data.shape
    return data, tiff_axes(axes, tuple(shape), str(p))


def _stack(pages: list[np.ndarray], names: list[str], where: str) -> np.ndarray:
    first = pages[0]
    for page, name in zip(pages, names):
        if page.shape != first.shape:
            raise VolumeError(f"{where}: pages of different shapes: {names[0]} is "
                              f"{first.shape[1]} x {first.shape[0]} but {name} is "
                              f"{page.shape[1]} x {page.shape[0]} (columns x rows)")
        if page.dtype != first.dtype:
            raise VolumeError(f"{where}: pages of different types: {names[0]} is {first.dtype} "
                              f"but {name} is {page.dtype}")
    return np.stack(pages)


def read_tiff(p: Path) -> tuple[np.ndarray, str]:
    """One TIFF file (a multi-page stack: page = z, page row = y, column = x; or an image whose
    metadata, ImageJ's or OME's or tifffile's own, names its axes: [c, z, y, x], [t, z, c, y, x],
    ...): the array and its axes ("?" where the file leaves one unnamed)."""
    return _tiff_series(p)


def tiff_files(folder: Path) -> list[Path]:
    return sorted((f for f in folder.iterdir() if f.is_file() and not f.name.startswith(".")
                   and has_suffix(f, TIFF_SUFFIXES)), key=lambda f: f.name)


def read_tiff_folder(folder: Path) -> tuple[np.ndarray, str]:
    """A folder of TIFFs sorted by file name (plain string order: zero-pad numbers): single pages
    are the z slices of one volume; volumes (multi-page files, or files whose metadata names their
    axes) are the steps of a time series, which must all have the same axes and shape."""
    files = tiff_files(folder)
    if not files:
        raise VolumeError(f"{folder}: no .tif/.tiff files in the folder")
    images = [(f, *_tiff_series(f)) for f in files]
    flat = [f.name for f, data, _ in images if data.ndim == 2]
    if len(flat) == len(images):
        return _stack([data for _, data, _ in images], [f.name for f in files], str(folder)), "zyx"
    if flat:
        volume = next(f.name for f, data, _ in images if data.ndim > 2)
        raise VolumeError(f"{folder}: mixes single pages ({flat[0]}) and volumes ({volume}): a "
                          "folder is one volume's z slices or one volume per time step")
    f0, first, axes0 = images[0]
    for f, data, axes in images[1:]:
        if axes != axes0 or data.shape != first.shape:
            raise VolumeError(f"{folder}: time steps that do not match: {f0.name} is "
                              f"{_shape_text(axes0, first.shape)} but {f.name} is "
                              f"{_shape_text(axes, data.shape)}")
        if data.dtype != first.dtype:
            raise VolumeError(f"{folder}: time steps of different types: {f0.name} is "
                              f"{first.dtype} but {f.name} is {data.dtype}")
    if "t" in axes0:
        raise VolumeError(f"{folder}: {f0.name} is itself a time series (axes {axes0}); a folder "
                          "of time steps takes one volume per file")
    return np.stack([data for _, data, _ in images]), "t" + axes0


def _shape_text(axes: str, shape) -> str:
    return "[" + ", ".join(f"{a} {n}" for a, n in zip(axes, shape)) + "]"


# ---- Zarr and OME-Zarr ---------------------------------------------------------------------------

def is_zarr(p: Path) -> bool:
    """A Zarr store: a folder named *.zarr, or one holding a Zarr array's or group's metadata."""
    return p.is_dir() and (has_suffix(p, ZARR_SUFFIXES)
                           or any((p / m).is_file() for m in ZARR_MARKERS))


# Axis names as Zarr files give them (OME-Zarr's axes, version 3's dimension_names, xarray's
# _ARRAY_DIMENSIONS) in our letters; other names are unnamed ("?").
ZARR_AXIS_NAMES = {"t": "t", "time": "t", "c": "c", "channel": "c", "ch": "c", "z": "z",
                   "y": "y", "x": "x"}
ZARR_AXIS_TYPES = {"time": "t", "channel": "c"}


def _zarr_axes(names) -> str | None:
    if not names or any(n is None for n in names):
        return None
    return "".join(ZARR_AXIS_NAMES.get(str(n).lower(), "?") for n in names)


def open_zarr(p: Path, need_spacing: bool = True):
    """A Zarr array, or an OME-Zarr image, opened without reading it: (array, spacing, axes,
    levels), levels the multiscales' arrays finest first (the array alone for a plain array);
    see read_zarr."""
    try:
        import zarr
    except ImportError:
        raise VolumeError(f"{p}: reading Zarr needs the zarr package (pip install zarr)") from None
    try:
        node = zarr.open(str(p), mode="r")
        spacing = None
        if isinstance(node, zarr.Group):
            attrs = node.attrs.asdict()
            multiscales = attrs.get("multiscales") or attrs.get("ome", {}).get("multiscales")
            if not multiscales:
                arrays = sorted(name for name, _ in node.arrays())
                raise VolumeError(f"{p}: a Zarr group without OME-Zarr multiscales metadata; give "
                                  f"the path of one of its arrays ({', '.join(arrays) or 'none'})")
            image = multiscales[0]
            level = image["datasets"][0]
            axes_meta = image.get("axes")
            names = None
            if axes_meta:
                names = [a.get("name") if isinstance(a, dict) else a for a in axes_meta]
                types = [a.get("type") if isinstance(a, dict) else None for a in axes_meta]
                names = [ZARR_AXIS_TYPES.get(t, n) for n, t in zip(names, types)]
            array = node[level["path"]]
            levels = [node[d["path"]] for d in image["datasets"]]
            for transform in level.get("coordinateTransformations", []):
                if transform.get("type") == "scale" and names:
                    scale = dict(zip(_zarr_axes(names) or "", transform["scale"]))
                    values = [scale.get(a) for a in "xyz"]
                    spacing = spacing_or_none(values, str(p), False)
        else:
            array = node
            levels = [array]
            names = getattr(array.metadata, "dimension_names", None) or \
                array.attrs.asdict().get("_ARRAY_DIMENSIONS")
    except VolumeError:
        raise
    except Exception as exc:   # zarr and its codecs raise many types for broken stores
        raise VolumeError(f"{p}: cannot read Zarr ({_one_line(exc)})") from None
    return array, spacing, _zarr_axes(names), levels


def read_zarr(p: Path, need_spacing: bool
              ) -> tuple[np.ndarray, tuple[float, float, float] | None, str | None]:
    """A Zarr array, or an OME-Zarr image (a group whose multiscales metadata, version 0.4 or
    0.5, names its axes and the scale of its finest level, which is read). Returns the array, the
    spacing (OME's scale along x, y, z; None where the store has none) and the axes as the store
    names them (None where it names none: volume.axes must)."""
    array, spacing, axes, _ = open_zarr(p, need_spacing)
    try:
        data = np.asarray(array[...])
    except Exception as exc:   # zarr and its codecs raise many types for broken stores
        raise VolumeError(f"{p}: cannot read Zarr ({_one_line(exc)})") from None
    return data, spacing, axes   # (no spacing: the scene's, or 1, 1, 1)
