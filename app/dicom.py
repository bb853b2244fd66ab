"""DICOM as a scanner or a PACS writes it: a folder tree (searched recursively) or a DICOMDIR holds
one or more series; each is listed (number, description, modality, size, slice count) and checked
for whether its slices make one volume, the largest that does opens unless the scene names
another (``volume.series``: its SeriesInstanceUID or its number in the listing), and its slices
are read ordered by ImagePositionPatient along the slice normal (never by file name) with
RescaleSlope/RescaleIntercept applied.

Headers are read first without pixel data (listing a tree costs a header per file); only the chosen
series' pixels are decoded. Every problem ends in one :class:`VolumeError` naming the folder or file
and the problem in plain words; numbers in messages are formatted, never library reprs.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .scene_flags import with_flag
from .scene_types import VolumeError
from .volume_formats import spacing_or_none

DICOM_SUFFIXES = (".dcm",)
DICOMDIR_NAME = "DICOMDIR"
# Neighbouring slice gaps may differ by this fraction of the mean gap (rounding in the headers'
# decimal strings); beyond it the series is unevenly spaced and would render distorted.
SLICE_GAP_TOLERANCE = 1e-3
# Slices whose ImageOrientationPatient differ by more than this (direction cosines) do not stack.
ORIENTATION_TOLERANCE = 1e-4
# Slice positions may stray from the line along the normal by this fraction of the gap (a gantry
# tilt shears the volume; it would need resampling).
SHEAR_TOLERANCE = 1e-2
# Non-DICOM files named in a note, at most.
NAMED_SKIPPED = 3


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _g(values) -> str:
    """Numbers as plain text: 0.959171, -0.0001 (never np.float64(...))."""
    return " ".join(f"{float(v):.6g}" for v in values)


def _floats(ds, keyword: str, n: int, where) -> np.ndarray | None:
    value = ds.get(keyword)
    if value is None or value == "":
        return None
    try:
        out = np.array([float(v) for v in (value if n > 1 else [value])], np.float64)
    except (TypeError, ValueError):
        raise VolumeError(f"{where}: cannot read {keyword} ({str(value)!r})") from None
    if len(out) != n or not np.isfinite(out).all():
        raise VolumeError(f"{where}: {keyword} should be {n} finite numbers, got {str(value)!r}")
    return out


@dataclass(frozen=True)
class DicomSeries:
    """One series of a listing: what a person picks from, and whether it is one volume."""
    number: int                      # its place in the listing, from 1
    uid: str                         # SeriesInstanceUID
    series_number: str               # the header's SeriesNumber ("" when absent)
    description: str
    modality: str
    columns: int
    rows: int
    files: tuple[Path, ...]
    problem: str | None = None       # why its slices do not make one volume (None: they do)
    # per file in `files`' order: the position along the slice normal, and the geometry
    positions: tuple[float, ...] = field(default=(), repr=False)
    orientation: tuple[float, ...] | None = field(default=None, repr=False)  # the shared IOP

    @property
    def slices(self) -> int:
        return len(self.files)

    @property
    def voxels(self) -> int:
        return self.columns * self.rows * self.slices

    def label(self, reason: bool = True) -> str:
        """'2: #3 "AXIAL 1mm" CT, 512 x 512 x 120' and, where it is not one volume, why (or only
        that, with reason=False)."""
        text = f"{self.number}: "
        if self.series_number:
            text += f"#{self.series_number} "
        text += f'"{self.description}" ' if self.description else ""
        text += f"{self.modality or '?'}, {self.columns} x {self.rows} x {self.slices}"
        if self.problem:
            text += f" (not a volume: {self.problem})" if reason else " (not a volume)"
        return text


@dataclass(frozen=True)
class DicomListing:
    where: Path                      # the folder or the DICOMDIR
    series: tuple[DicomSeries, ...]
    skipped: tuple[Path, ...] = ()   # files that are not DICOM
    other: int = 0                   # DICOM files without images (reports, presentation states)

    def find(self, wanted: str | int) -> DicomSeries:
        """The series a scene names: its number in the listing or its SeriesInstanceUID."""
        for s in self.series:
            if (isinstance(wanted, int) and s.number == wanted) or (
                    isinstance(wanted, str) and s.uid == wanted.strip()):
                return s
        if isinstance(wanted, str) and wanted.strip().isdigit():
            return self.find(int(wanted))
        raise VolumeError(f"{self.where}: no series {wanted} here; the series are: "
                          f"{self.summary()} (name one by its number or SeriesInstanceUID)")

    def largest(self) -> DicomSeries:
        """The series with the most voxels that makes one volume (ties: the first listed)."""
        usable = [s for s in self.series if s.problem is None]
        if not usable and len(self.series) == 1:
            one = self.series[0]
            raise VolumeError(f"{self.where}: its DICOM series does not make one volume: "
                              f"{one.problem} ({replace(one, problem=None).label()})")
        if not usable:
            raise VolumeError(f"{self.where}: none of its {len(self.series)} DICOM series makes "
                              f"one volume: {self.summary()}")
        # series with patient geometry before single images without it (radiographs)
        return max(usable, key=lambda s: (s.orientation is not None, s.voxels, s.slices,
                                          -s.number))

    def summary(self) -> str:
        return "; ".join(s.label() for s in self.series)


def is_dicomdir(p: Path) -> bool:
    return p.is_file() and p.name.upper() == DICOMDIR_NAME


def _tree_files(folder: Path) -> list[Path]:
    """Every file under the folder (hidden ones and DICOMDIR indexes left out), in a fixed order."""
    out = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        out += [Path(root) / f for f in sorted(files)
                if not f.startswith(".") and f.upper() != DICOMDIR_NAME]
    return out


def _dicomdir_files(p: Path) -> list[Path]:
    import pydicom
    from pydicom.fileset import FileSet
    try:
        files = [Path(instance.path) for instance in FileSet(pydicom.dcmread(str(p)))]
    except Exception as exc:
        raise VolumeError(f"{p}: cannot read the DICOMDIR ({_one_line(exc)})") from None
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise VolumeError(f"{p}: the DICOMDIR names {len(missing)} files that are not there "
                          f"(first: {missing[0]})")
    return files


def _is_image(ds) -> bool:
    return any(k in ds for k in ("Rows", "Columns", "ImagePositionPatient", "PixelData"))


def list_series(path: str | Path) -> DicomListing:
    """The DICOM series under a folder (searched recursively) or named by a DICOMDIR."""
    p = Path(path)
    try:
        return _list_series(p)
    except VolumeError:
        raise
    except Exception as exc:  # pydicom converts values lazily: a mangled one raises on first use
        raise VolumeError(f"{p}: cannot read the DICOM series ({_one_line(exc)})") from None


def _list_series(p: Path) -> DicomListing:
    import pydicom
    from pydicom.errors import InvalidDicomError

    if not p.exists():
        raise VolumeError(f"{p}: not found")
    if not (p.is_dir() or is_dicomdir(p)):
        raise VolumeError(f"{p}: not a folder or a DICOMDIR file")
    files = _dicomdir_files(p) if is_dicomdir(p) else _tree_files(p)
    if not files:
        raise VolumeError(f"{p}: the folder holds no files (expected DICOM images, or a folder of "
                          "TIFF slices)")
    groups: dict[str, list] = {}
    skipped, other = [], 0
    for f in files:
        try:
            ds = pydicom.dcmread(str(f), stop_before_pixels=True)
        except InvalidDicomError:
            skipped.append(f)
            continue
        except Exception as exc:
            raise VolumeError(f"{f}: cannot read DICOM ({_one_line(exc)})") from None
        if not _is_image(ds):
            meta = getattr(ds, "file_meta", None)
            sop = ds.get("SOPClassUID") or (meta.get("MediaStorageSOPClassUID") if meta else None)
            if len(ds) == 0 or "Image Storage" in str(getattr(sop, "name", "") or ""):
                raise VolumeError(f"{f}: an image without pixel data (a truncated file?)")
            other += 1   # a report or presentation state beside the images
            continue
        uid = str(ds.get("SeriesInstanceUID", "") or "(no SeriesInstanceUID)")
        groups.setdefault(uid, []).append((f, ds))
    if not groups:
        if other:
            raise VolumeError(f"{p}: holds no DICOM images ({other} DICOM files, none an image)")
        names = ", ".join(f.name for f in skipped[:NAMED_SKIPPED])
        raise VolumeError(f"{p}: holds no DICOM files ({len(skipped)} files, none of them DICOM: "
                          f"{names}{', ...' if len(skipped) > NAMED_SKIPPED else ''})")

    def order(item):
        uid, members = item
        ds = members[0][1]
        number = str(ds.get("SeriesNumber", "") or "").strip()
        return (int(number) if number.lstrip("-").isdigit() else 1 << 30, number,
                str(ds.get("SeriesDescription", "") or ""), uid)

    series = tuple(_series(k + 1, uid, members)
                   for k, (uid, members) in enumerate(sorted(groups.items(), key=order)))
    return DicomListing(p, series, tuple(skipped), other)


def _series(number: int, uid: str, members: list) -> DicomSeries:
    """A series' entry: its slices ordered along the normal, and whether they make one volume."""
    ds0 = members[0][1]
    info = dict(number=number, uid=uid,
                series_number=str(ds0.get("SeriesNumber", "") or "").strip(),
                description=" ".join(str(ds0.get("SeriesDescription", "") or "").split()),
                modality=str(ds0.get("Modality", "") or ""),
                columns=int(ds0.get("Columns", 0) or 0), rows=int(ds0.get("Rows", 0) or 0))
    files = tuple(f for f, _ in members)

    def entry(problem=None, ordered=files, positions=(), orientation=None):
        return DicomSeries(files=ordered, problem=problem, positions=positions,
                           orientation=orientation, **info)

    for f, ds in members:
        if int(ds.get("NumberOfFrames", 1) or 1) != 1:
            return entry(f"{f.name} is a multi-frame image; expected a series of single slices")
    sizes = {(int(ds.get("Columns", 0) or 0), int(ds.get("Rows", 0) or 0)) for _, ds in members}
    if len(sizes) > 1:
        a, b = sorted(sizes)[:2]
        return entry(f"slices of different sizes ({a[0]} x {a[1]} and {b[0]} x {b[1]}, columns x "
                     "rows)")
    iops = [_floats(ds, "ImageOrientationPatient", 6, f) for f, ds in members]
    if iops[0] is None:
        if len(members) == 1:
            return entry(orientation=None)   # one image without geometry (a radiograph): as is
        return entry("no ImageOrientationPatient: the slices cannot be ordered")
    if any(o is None for o in iops):
        return entry("some slices have no ImageOrientationPatient")
    distinct: list[np.ndarray] = []
    for o in iops:
        if not any(np.allclose(o, d, atol=ORIENTATION_TOLERANCE) for d in distinct):
            distinct.append(o)
    if len(distinct) > 1:
        return entry(f"its {len(members)} slices lie in {len(distinct)} different orientations "
                     "(a localiser or projections?)")
    iop = distinct[0]
    normal = np.cross(iop[:3], iop[3:])
    if not np.linalg.norm(normal) > 1e-6:
        return entry(f"ImageOrientationPatient {_g(iop)} has parallel row and column directions")
    normal /= np.linalg.norm(normal)
    positions = []
    for f, ds in members:
        pos = _floats(ds, "ImagePositionPatient", 3, f)
        if pos is None:
            if len(members) > 1:
                return entry(f"{f.name} has no ImagePositionPatient: the slices cannot be ordered")
            pos = np.zeros(3)
        positions.append(pos)
    order = sorted(range(len(members)), key=lambda k: float(positions[k] @ normal))
    points = np.array([positions[k] for k in order])
    along = points @ normal
    ordered = tuple(files[k] for k in order)
    if len(members) > 1:
        gaps = np.diff(along)
        k = int(np.argmin(gaps))
        if not gaps[k] > 1e-6:
            return entry(f"{ordered[k].name} and {ordered[k + 1].name} lie at the same position "
                         f"along the slice normal ({along[k]:.6g})")
        if gaps.max() - gaps.min() > SLICE_GAP_TOLERANCE * gaps.mean():
            return entry(f"uneven slice spacing along the normal (gaps from {gaps.min():.6g} to "
                         f"{gaps.max():.6g}): a slice missing?")
        steps = np.diff(points, axis=0)
        off_line = np.linalg.norm(steps - np.outer(gaps, normal), axis=1)
        if off_line.max() > SHEAR_TOLERANCE * gaps.mean():
            return entry("the slice positions step sideways, not along the slice normal (a "
                         "gantry tilt?): the volume would need resampling")
    return entry(None, ordered, tuple(float(a) for a in along), tuple(float(v) for v in iop))


@dataclass(frozen=True)
class DicomVolume:
    data: np.ndarray                                  # [z, y, x], rescaled
    spacing: tuple[float, float, float] | None
    direction: np.ndarray | None                      # LPS columns of axes x, y, z
    series: DicomSeries
    listing: DicomListing
    notes: tuple[str, ...]


def read_dicom(path: str | Path, need_spacing: bool, wanted: str | int | None = None
               ) -> DicomVolume:
    """The series a scene names (or the largest that makes a volume) of a folder tree or a
    DICOMDIR: pixel row = y, column = x, slices along the normal = z; spacing from PixelSpacing
    and the slice positions; RescaleSlope/Intercept applied (CT in Hounsfield units)."""
    p = Path(path)
    listing = list_series(p)
    chosen = listing.largest() if wanted is None else listing.find(wanted)
    if chosen.problem:
        raise VolumeError(f"{p}: series {chosen.number} does not make one volume: "
                          f"{chosen.problem}")
    where = (str(p) if len(listing.series) == 1 else
             f"{p}, series {chosen.label()}")
    try:
        data, spacing = _read_pixels(chosen, need_spacing, where)
    except VolumeError:
        raise
    except Exception as exc:
        raise VolumeError(f"{where}: cannot read the DICOM series ({_one_line(exc)})") from None
    notes = []
    if len(listing.series) > 1:
        others = "; ".join(s.label(reason=False) for s in listing.series if s is not chosen)
        how = "the largest that makes a volume" if wanted is None else "as the scene names"
        notes.append(f"{p.name} holds {len(listing.series)} DICOM series; opened {how}: "
                     f"{chosen.label()}. The others: {others}. Open another with --series N "
                     f"({with_flag('volume.series')}); `radiance-probes series {p}` lists them all")
    if listing.skipped:
        names = ", ".join(f.name for f in listing.skipped[:NAMED_SKIPPED])
        n = len(listing.skipped)
        notes.append(f"{p.name}: passed over {n} file{'s' if n != 1 else ''} that "
                     f"{'are' if n != 1 else 'is'} not DICOM "
                     f"({names}{', ...' if len(listing.skipped) > NAMED_SKIPPED else ''})")
    direction = None
    if chosen.orientation is not None:
        iop = np.array(chosen.orientation)
        direction = np.stack([iop[:3], iop[3:], np.cross(iop[:3], iop[3:])], axis=1)
    return DicomVolume(data, spacing, direction, chosen, listing, tuple(notes))


def _read_pixels(series: DicomSeries, need_spacing: bool, where: str
                 ) -> tuple[np.ndarray, tuple[float, float, float] | None]:
    import pydicom
    planes, slopes, intercepts, first = [], [], [], None
    for f in series.files:
        try:
            ds = pydicom.dcmread(str(f))
        except Exception as exc:
            raise VolumeError(f"{f}: cannot read DICOM ({_one_line(exc)})") from None
        if "PixelData" not in ds:
            raise VolumeError(f"{f}: an image without pixel data (a truncated file?)")
        try:
            pixels = ds.pixel_array
        except Exception as exc:
            raise VolumeError(f"{f}: cannot decode the pixel data ({_one_line(exc)})") from None
        if pixels.ndim != 2:
            raise VolumeError(f"{f}: pixel data of shape {list(pixels.shape)}; expected one "
                              "channel (rows x columns)")
        if pixels.shape != (series.rows, series.columns):
            raise VolumeError(f"{where}: slices of different sizes: {f.name} is {pixels.shape[1]} "
                              f"x {pixels.shape[0]}, the series {series.columns} x {series.rows} "
                              "(columns x rows)")
        slope = _floats(ds, "RescaleSlope", 1, f)
        intercept = _floats(ds, "RescaleIntercept", 1, f)
        planes.append(pixels)
        slopes.append(1.0 if slope is None else float(slope[0]))
        intercepts.append(0.0 if intercept is None else float(intercept[0]))
        first = first if first is not None else (f, ds)
    stack = np.stack(planes)
    slopes, intercepts = np.array(slopes), np.array(intercepts)
    if not (slopes == 1.0).all() or not (intercepts == 0.0).all():
        if not (slopes != 0).all():
            raise VolumeError(f"{where}: RescaleSlope 0 would make every voxel one value")
        stack = (stack.astype(np.float64) * slopes[:, None, None]
                 + intercepts[:, None, None]).astype(np.float32)

    first_f, ds = first
    ps = _floats(ds, "PixelSpacing", 2, first_f)
    if series.slices > 1:
        dz = float(np.mean(np.diff(series.positions)))
    else:
        thickness = (_floats(ds, "SpacingBetweenSlices", 1, first_f)
                     if "SpacingBetweenSlices" in ds else _floats(ds, "SliceThickness", 1, first_f))
        dz = None if thickness is None else float(thickness[0])
    values = None if ps is None or dz is None else (ps[1], ps[0], dz)  # x = column, y = row
    return stack, spacing_or_none(values, where, need_spacing)
