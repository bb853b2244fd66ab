"""Medical and microscopy volume files read with the libraries made for them: NIfTI (nibabel) and
TIFF stacks (tifffile), each mapped to ``data[z, y, x]`` as docs/scene-format.md says (DICOM series:
app/dicom.py). Orientation matrices are returned as metadata; app/volume.py applies them where
the scene asks for ``"orientation": "patient"`` (app/orientation.py).

Every problem, whatever the library raises, ends in one :class:`VolumeError` naming the file (or
folder) and the problem. ``app/volume.py`` normalises the array like any other format's.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .orientation import RAS_TO_LPS, unit_columns
from .scene_types import VolumeError

NIFTI_SUFFIXES = (".nii", ".nii.gz")
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
                          "volume.spacing")
    return None


# ---- NIfTI ---------------------------------------------------------------------------------------

def read_nifti(p: Path, need_spacing: bool
               ) -> tuple[np.ndarray, tuple[float, float, float] | None, np.ndarray | None]:
    """The stored array ``[i, j, k]`` becomes ``data[k, j, i]``; spacing from the voxel sizes
    (pixdim); scl_slope/scl_inter applied (nibabel's array proxy applies them, keeping the stored
    integer type where they are the identity). Also the axes' directions in LPS from the sform,
    else the qform (RAS in the file), or None where neither is set (codes 0)."""
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
        if len(shape) != 3:
            raise VolumeError(f"{p}: expected a 3D volume, the NIfTI has shape {list(img.shape)}")
        data = np.asanyarray(img.dataobj).reshape(shape)
        direction = _nifti_direction(img)
    except VolumeError:
        raise
    except Exception as exc:  # nibabel raises many types for truncated or corrupt files
        raise VolumeError(f"{p}: cannot read NIfTI ({_one_line(exc)})") from None
    if data.dtype.names is not None:
        raise VolumeError(f"{p}: NIfTI with {data.dtype.names} channels; expected one scalar")
    spacing = spacing_or_none(zooms[:3], str(p), need_spacing)
    return np.ascontiguousarray(data.transpose(2, 1, 0)), spacing, direction


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


def _tiff_pages(p: Path) -> list[np.ndarray]:
    import tifffile
    errors = _LogCollector()
    log = logging.getLogger("tifffile")
    log.addHandler(errors)
    try:
        with tifffile.TiffFile(str(p)) as tif:
            pages = [page.asarray() for page in tif.pages]
    except Exception as exc:
        raise VolumeError(f"{p}: cannot read TIFF ({_one_line(exc)})") from None
    finally:
        log.removeHandler(errors)
    if errors.messages:  # tifffile logs (and skips) what it cannot read, e.g. a truncated file
        raise VolumeError(f"{p}: cannot read TIFF ({' '.join(errors.messages[0].split())})")
    if not pages:
        raise VolumeError(f"{p}: the TIFF has no pages")
    for i, page in enumerate(pages):
        if page.ndim != 2:
            raise VolumeError(f"{p}: page {i} has shape {list(page.shape)}; expected one channel "
                              "(rows x columns)")
    return pages


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


def read_tiff(p: Path) -> np.ndarray:
    """One multi-page file (page = z, page row = y, column = x)."""
    pages = _tiff_pages(p)
    return _stack(pages, [f"page {i}" for i in range(len(pages))], str(p))


def tiff_files(folder: Path) -> list[Path]:
    return sorted((f for f in folder.iterdir() if f.is_file() and not f.name.startswith(".")
                   and has_suffix(f, TIFF_SUFFIXES)), key=lambda f: f.name)


def read_tiff_folder(folder: Path) -> np.ndarray:
    """A folder of single-page TIFFs, sorted by file name (plain string order: zero-pad numbers)."""
    files = tiff_files(folder)
    if not files:
        raise VolumeError(f"{folder}: no .tif/.tiff files in the folder")
    pages = []
    for f in files:
        got = _tiff_pages(f)
        if len(got) != 1:
            raise VolumeError(f"{f}: {len(got)} pages; a folder stack takes single-page TIFFs")
        pages.append(got[0])
    return _stack(pages, [f.name for f in files], str(folder))
