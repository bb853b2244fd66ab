"""DICOM as a scanner or a PACS writes it: a folder tree (searched recursively) or a DICOMDIR holds
one or more series; each is listed (number, description, modality, size, slice count) and checked
for whether its slices make one volume, the largest that does opens unless the scene names
another (``volume.series``: its SeriesInstanceUID or its number in the listing), and its slices
are read ordered by ImagePositionPatient along the slice normal (never by file name) with
RescaleSlope/RescaleIntercept applied. A multi-frame file is a series of slices too: an enhanced CT
or MR places each frame by its per-frame functional groups (PlanePositionSequence,
PlaneOrientationSequence, PixelMeasuresSequence, PixelValueTransformationSequence for the rescale,
each from the per-frame item or else the shared one), an RT dose grid by its GridFrameOffsetVector
(offsets along the normal from ImagePositionPatient), its values scaled by DoseGridScaling (Gy).

Headers are read first without pixel data (listing a tree costs a header per file; the pixel data's
length is checked against the file's, not read); only the chosen series' pixels are decoded. A
folder is read as an export leaves it: files that are not DICOM, unreadable, truncated, images
without pixel data or with headers that cannot be read are passed over, counted in one note that
names the first few (DicomListing.skip_note), and pydicom's warnings about what it read anyway
(a VR it guessed, a value it fixed) are counted there too, never printed; only a folder where no
series can be read is refused. Every refusal is one :class:`VolumeError` naming the folder or file
and the problem in plain words; numbers in messages are formatted, never library reprs.
"""
from __future__ import annotations

import os
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError
from radiance_probes.io.volume_formats import spacing_or_none

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


@contextmanager
def _library_warnings(seen: list):
    """pydicom's warnings while reading (a VR it had to guess, a value it fixed) go to `seen`,
    not to stderr: the listing counts the files they came from."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:   # others' warnings (a garbage collection's, say) go on as they came
        if f"{os.sep}pydicom{os.sep}" in str(w.filename) or str(w.filename) == __file__:
            # (pydicom's, attributed to its own line or, by its stacklevel, to the call here)
            seen.append(w)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)


def _names(paths, total: int) -> str:
    names = ", ".join(Path(f).name for f in list(paths)[:NAMED_SKIPPED])
    return names + (", ..." if total > NAMED_SKIPPED else "")


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
    # Multi-frame files: per entry of `files`, its frame (None: a single-frame file), and the
    # rescale (slope, intercept) each frame has (empty: each file's RescaleSlope/Intercept); the
    # pixel spacing (rows, columns) and slice thickness the functional groups give; what it is.
    frames: tuple[int | None, ...] = field(default=(), repr=False)
    rescale: tuple[tuple[float, float], ...] = field(default=(), repr=False)
    pixel_spacing: tuple[float, float] | None = field(default=None, repr=False)
    thickness: float | None = field(default=None, repr=False)
    kind: str = ""                   # "" (single-frame files), "enhanced multi-frame", "RT dose grid"

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
        if self.kind:
            text += f" ({self.kind})"
        if self.problem:
            text += f" (not a volume: {self.problem})" if reason else " (not a volume)"
        return text


@dataclass(frozen=True)
class DicomListing:
    where: Path                      # the folder or the DICOMDIR
    series: tuple[DicomSeries, ...]
    skipped: tuple[Path, ...] = ()   # files that are not DICOM
    other: int = 0                   # DICOM files without images (reports, presentation states)
    # DICOM files passed over: (file, why in a few words: unreadable, cut short, an image without
    # pixel data, a header value that cannot be read; the library's or our words on it, or "")
    broken: tuple[tuple[Path, str, str], ...] = ()
    irregular: tuple[Path, ...] = ()  # files pydicom read with a warning (read all the same)

    def broken_said(self) -> str:
        """For a refusal: the DICOM files passed over (a slice the series misses may be one)."""
        if not self.broken:
            return ""
        n = len(self.broken)
        return (f" ({n} DICOM file{'s' if n != 1 else ''} here passed over: "
                f"{_names([f for f, _, _ in self.broken], n)}; `radiance-probes series "
                f"{self.where}` says why)")

    def skip_note(self) -> str | None:
        """One line: the files passed over, counted by why, the first few named, and the files
        read with a warning of pydicom's; None where every file was read cleanly."""
        parts = []
        if self.skipped:
            parts.append(f"{len(self.skipped)} not DICOM ({_names(self.skipped, len(self.skipped))})")
        whys: dict[str, list] = {}
        for f, why, detail in self.broken:
            whys.setdefault(why, []).append((f, detail))
        for why, got in whys.items():
            first = got[0][1]
            parts.append(f"{len(got)} {why} ({_names([f for f, _ in got], len(got))}"
                         f"{f'; the first: {first}' if first else ''})")
        if not parts and not self.irregular:
            return None
        n = len(self.skipped) + len(self.broken)
        text = (f"{self.where.name}: passed over {n} file{'s' if n != 1 else ''}: "
                f"{'; '.join(parts)}" if n else f"{self.where.name}:")
        if self.irregular:
            k = len(self.irregular)
            text += (f"{'; ' if n else ' '}{k} file{'s' if k != 1 else ''} read despite header "
                     f"irregularities pydicom warned of ({_names(self.irregular, k)})")
        return text

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
                              f"{one.problem} ({replace(one, problem=None).label()})"
                              + self.broken_said())
        if not usable:
            raise VolumeError(f"{self.where}: none of its {len(self.series)} DICOM series makes "
                              f"one volume: {self.summary()}" + self.broken_said())
        return self.by_size()[0]

    def by_size(self) -> list[DicomSeries]:
        """The series that make one volume, the one largest() names first: series with patient
        geometry before single images without it (radiographs), then by voxels."""
        return sorted((s for s in self.series if s.problem is None), reverse=True,
                      key=lambda s: (s.orientation is not None, s.voxels, s.slices, -s.number))

    def summary(self) -> str:
        return "; ".join(s.label() for s in self.series)


def is_dicomdir(p: Path) -> bool:
    return p.is_file() and p.name.upper() == DICOMDIR_NAME


def is_dicom_file(p: Path) -> bool:
    """A file named .dcm, or one with DICOM's preamble ("DICM" at byte 128), as scanners export
    them without a suffix."""
    if not p.is_file():
        return False
    if p.suffix.lower() in DICOM_SUFFIXES:
        return True
    try:
        with open(p, "rb") as fh:
            fh.seek(128)
            return fh.read(4) == b"DICM"
    except OSError:
        return False


def frames_in(p: Path) -> int:
    """A DICOM file's NumberOfFrames (1 where it has none); 0 where it is not readable DICOM."""
    import pydicom
    try:
        with _library_warnings([]):
            ds = pydicom.dcmread(str(p), stop_before_pixels=True)
        return _frame_count(ds, p)
    except Exception:
        return 0


PIXEL_DATA_TAG = 0x7FE00010
UNDEFINED_LENGTH = 0xFFFFFFFF
DEFLATED = "1.2.840.10008.1.2.1.99"   # Deflated Explicit VR Little Endian
# The header values a listing reads of each file (beyond its geometry)
LISTED = ("SeriesNumber", "SeriesDescription", "Modality", "Rows", "Columns", "PixelSpacing",
          "SliceThickness", "SpacingBetweenSlices", "RescaleSlope", "RescaleIntercept")


def _read_header(f: Path):
    """A file's data set with its pixel data left unread (values over 1 KiB are deferred), and
    whether that pixel data ends past the file's end (a file cut short)."""
    import pydicom
    ds = pydicom.dcmread(str(f), defer_size=1024)
    raw = ds._dict.get(PIXEL_DATA_TAG)   # (pydicom's element before conversion: where it lies)
    tell, length = getattr(raw, "value_tell", None), getattr(raw, "length", None)
    meta = getattr(ds, "file_meta", None)
    deflated = str(meta.get("TransferSyntaxUID", "") if meta else "") == DEFLATED
    cut = (tell is not None and length not in (None, UNDEFINED_LENGTH) and not deflated
           and tell + length > f.stat().st_size)   # (a deflated file's offsets are inflated ones)
    return ds, cut


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
        stray: list = []   # (those of a file are counted with it; the DICOMDIR's here)
        with _library_warnings(stray):
            listing = _list_series(p)
        if stray and p not in listing.irregular:
            listing = replace(listing, irregular=(*listing.irregular, p))
        return listing
    except VolumeError:
        raise
    except Exception as exc:  # pydicom converts values lazily: a mangled one raises on first use
        raise VolumeError(f"{p}: cannot read the DICOM series ({_one_line(exc)})") from None


def _list_series(p: Path) -> DicomListing:
    from pydicom.errors import InvalidDicomError

    if not p.exists():
        raise VolumeError(f"{p}: not found")
    if not (p.is_dir() or p.is_file()):
        raise VolumeError(f"{p}: not a folder, a DICOMDIR or a DICOM file")
    files = (_dicomdir_files(p) if is_dicomdir(p) else _tree_files(p) if p.is_dir() else [p])
    if not files:
        raise VolumeError(f"{p}: the folder holds no files (expected DICOM images, or a folder of "
                          "TIFF slices)")
    groups: dict[str, list] = {}
    skipped, broken, irregular, other = [], [], [], 0
    for f in files:
        seen: list = []
        try:
            with _library_warnings(seen):
                ds, cut = _read_header(f)
        except InvalidDicomError:
            skipped.append(f)
            continue
        except Exception as exc:   # cut inside its header, or a header pydicom cannot parse
            broken.append((f, "unreadable", _one_line(exc)[:80]))
            continue
        if cut:
            broken.append((f, "cut short in the pixel data", ""))
            continue
        if not _is_image(ds):
            meta = getattr(ds, "file_meta", None)
            sop = ds.get("SOPClassUID") or (meta.get("MediaStorageSOPClassUID") if meta else None)
            if len(ds) == 0 or "Image Storage" in str(getattr(sop, "name", "") or ""):
                broken.append((f, "image files without pixel data", ""))
                continue
            other += 1   # a report or presentation state beside the images
            continue
        if "PixelData" not in ds and not any(k in ds for k in ("FloatPixelData",
                                                               "DoubleFloatPixelData")):
            broken.append((f, "image files without pixel data", ""))
            continue
        try:
            with _library_warnings(seen):   # (values are converted as they are first read)
                got = _slices_of(f, ds)
                uid = str(ds.get("SeriesInstanceUID", "") or "(no SeriesInstanceUID)")
                for keyword in LISTED:   # read here, so a value pydicom warns of is this file's
                    ds.get(keyword)
        except VolumeError as exc:   # a header value that cannot be read (NumberOfFrames: "x")
            broken.append((f, "with a header value that cannot be read", _header_problem(exc, f)))
            continue
        finally:
            if seen and (not irregular or irregular[-1] != f):
                irregular.append(f)
        groups.setdefault(uid, []).append((f, ds, got))
    if not groups:
        if broken:
            f, why, detail = broken[0]
            raise VolumeError(f"{p}: no DICOM series here can be read ({len(broken)} DICOM "
                              f"file{'s' if len(broken) != 1 else ''} passed over, the first "
                              f"{f.name}: {why}{f': {detail}' if detail else ''}"
                              + (f"; {len(skipped)} files not DICOM" if skipped else "") + ")")
        if other:
            raise VolumeError(f"{p}: holds no DICOM images ({other} DICOM files, none an image)")
        raise VolumeError(f"{p}: holds no DICOM files ({len(skipped)} files, none of them DICOM: "
                          f"{_names(skipped, len(skipped))})")

    def order(item):
        uid, members = item
        ds = members[0][1]
        number = str(ds.get("SeriesNumber", "") or "").strip()
        return (int(number) if number.lstrip("-").isdigit() else 1 << 30, number,
                str(ds.get("SeriesDescription", "") or ""), uid)

    seen: list = []
    with _library_warnings(seen):
        ordered = sorted(groups.items(), key=order)
    if seen:
        irregular.append(ordered[0][1][0][0])
    series = []
    for k, (uid, members) in enumerate(ordered):
        seen = []
        with _library_warnings(seen):
            series.append(_series_or_why(k + 1, uid, members))
        if seen and not any(f in irregular for f, _, _ in members):
            irregular.append(members[0][0])
    series = tuple(series)
    return DicomListing(p, series, tuple(skipped), other, tuple(broken), tuple(irregular))


def _series_or_why(number: int, uid: str, members: list) -> DicomSeries:
    """_series, or where a header value of its files cannot be read (pydicom converts values
    lazily: a mangled one raises at first use), the series listed with that as its problem."""
    try:
        return _series(number, uid, members)
    except Exception as exc:
        why = _one_line(exc) if isinstance(exc, VolumeError) else (
            f"a header value cannot be read ({_one_line(exc)[:80]})")
        return DicomSeries(number, uid, "", "", "", 0, 0,
                           tuple(f for f, _, _ in members), problem=why)


def _header_problem(exc: VolumeError, f: Path) -> str:
    """A header refusal's words without the file's path (the note names the file)."""
    text = str(exc)
    for prefix in (f"{f}, ", f"{f}: "):
        text = text.replace(prefix, "", 1) if text.startswith(str(f)) else text
    return text[:80]


@dataclass(frozen=True)
class _Slice:
    """One slice of a series: a single-frame file, or one frame of a multi-frame file."""
    file: Path
    frame: int | None                       # None: a single-frame file
    orientation: np.ndarray | None          # ImageOrientationPatient
    position: np.ndarray | None             # ImagePositionPatient
    rescale: tuple[float, float] | None = None   # multi-frame: (slope, intercept)
    pixel_spacing: np.ndarray | None = None      # multi-frame: from its functional groups
    thickness: float | None = None

    @property
    def name(self) -> str:
        return self.file.name if self.frame is None else f"{self.file.name} frame {self.frame + 1}"


def _frame_count(ds, f: Path) -> int:
    try:
        frames = int(ds.get("NumberOfFrames", 1) or 1)
    except (TypeError, ValueError):
        frames = 0
    if frames < 1:
        raise VolumeError(f"{f}: cannot read NumberOfFrames ({str(ds.get('NumberOfFrames'))!r})")
    return frames


def _slices_of(f: Path, ds) -> tuple[list[_Slice], str, str | None]:
    """A file's slices, what kind of file it is ("" single-frame, "enhanced multi-frame", "RT dose
    grid"), and why its frames cannot be placed (None: they can)."""
    frames = _frame_count(ds, f)
    if frames == 1 and "PerFrameFunctionalGroupsSequence" not in ds:
        return [_Slice(f, None, _floats(ds, "ImageOrientationPatient", 6, f),
                       _floats(ds, "ImagePositionPatient", 3, f))], "", None
    if "PerFrameFunctionalGroupsSequence" in ds:
        return _enhanced_slices(f, ds, frames)
    if "GridFrameOffsetVector" in ds:
        return _dose_slices(f, ds, frames)
    return [], "", (f"{f.name} is a multi-frame image of {frames} frames that places none of them "
                    "(no per-frame functional groups, no GridFrameOffsetVector: a cine loop or a "
                    "secondary capture?), so its frames do not make a volume")


def _enhanced_slices(f: Path, ds, frames: int) -> tuple[list[_Slice], str, str | None]:
    """An enhanced CT, MR or PET image: each frame placed by its functional groups, the per-frame
    item's macro first, else the shared one's."""
    kind = "enhanced multi-frame"
    per = list(ds.PerFrameFunctionalGroupsSequence)
    if len(per) != frames:
        return [], kind, (f"{f.name} has {len(per)} per-frame functional groups for its {frames} "
                          "frames")
    shared_seq = ds.get("SharedFunctionalGroupsSequence")
    shared = shared_seq[0] if shared_seq else None
    out = []
    for k, item in enumerate(per):
        where = f"{f}, frame {k + 1}"

        def macro(sequence: str, keyword: str, n: int):
            for group in (item, shared):
                inner = group.get(sequence) if group is not None else None
                if inner and keyword in inner[0]:
                    return _floats(inner[0], keyword, n, where)
            return _floats(ds, keyword, n, where) if keyword in ds else None

        slope = macro("PixelValueTransformationSequence", "RescaleSlope", 1)
        intercept = macro("PixelValueTransformationSequence", "RescaleIntercept", 1)
        gap = (macro("PixelMeasuresSequence", "SpacingBetweenSlices", 1)
               if macro("PixelMeasuresSequence", "SpacingBetweenSlices", 1) is not None
               else macro("PixelMeasuresSequence", "SliceThickness", 1))
        out.append(_Slice(f, k, macro("PlaneOrientationSequence", "ImageOrientationPatient", 6),
                          macro("PlanePositionSequence", "ImagePositionPatient", 3),
                          (1.0 if slope is None else float(slope[0]),
                           0.0 if intercept is None else float(intercept[0])),
                          macro("PixelMeasuresSequence", "PixelSpacing", 2),
                          None if gap is None else float(gap[0])))
    return out, kind, None


def _dose_slices(f: Path, ds, frames: int) -> tuple[list[_Slice], str, str | None]:
    """An RT dose grid: frame k at ImagePositionPatient + GridFrameOffsetVector[k] along the
    normal (offsets from 0: relative; else, for an axial grid, the frames' z), its values x
    DoseGridScaling."""
    kind = "RT dose grid"
    iop = _floats(ds, "ImageOrientationPatient", 6, f)
    origin = _floats(ds, "ImagePositionPatient", 3, f)
    if iop is None or origin is None:
        return [], kind, f"{f.name}: an RT dose grid without ImageOrientationPatient and ImagePositionPatient"
    offsets = _floats(ds, "GridFrameOffsetVector", frames, f)
    normal = np.cross(iop[:3], iop[3:])
    if offsets[0] != 0.0:   # absolute z positions, defined for an axial grid only
        if not np.allclose(np.abs(normal), (0.0, 0.0, 1.0), atol=ORIENTATION_TOLERANCE):
            return [], kind, (f"{f.name}: its GridFrameOffsetVector gives absolute positions "
                              f"(from {offsets[0]:.6g}), which a grid not axial (normal "
                              f"{_g(normal)}) cannot have")
        offsets = (offsets - origin[2]) * normal[2]
    scaling = _floats(ds, "DoseGridScaling", 1, f)
    rescale = (1.0 if scaling is None else float(scaling[0]), 0.0)
    return [_Slice(f, k, iop, origin + float(o) * normal, rescale) for k, o in
            enumerate(offsets)], kind, None


def _series(number: int, uid: str, members: list) -> DicomSeries:
    """A series' entry: its slices (single-frame files, or a multi-frame file's frames) ordered
    along the normal, and whether they make one volume."""
    ds0 = members[0][1]
    info = dict(number=number, uid=uid,
                series_number=str(ds0.get("SeriesNumber", "") or "").strip(),
                description=" ".join(str(ds0.get("SeriesDescription", "") or "").split()),
                modality=str(ds0.get("Modality", "") or ""),
                columns=int(ds0.get("Columns", 0) or 0), rows=int(ds0.get("Rows", 0) or 0))
    slices: list[_Slice] = []
    kinds = set()
    problem = None
    for f, ds, (got, kind, why) in members:
        slices += got
        kinds.add(kind)
        problem = problem or why
    kind = " and ".join(sorted(k for k in kinds if k))

    def entry(problem=None, ordered=None, positions=(), orientation=None):
        ordered = ordered if ordered is not None else (
            slices or [_Slice(f, None, None, None) for f, _, _ in members])
        multi = any(sl.frame is not None for sl in ordered)
        first = ordered[0]
        return DicomSeries(files=tuple(sl.file for sl in ordered), problem=problem,
                           positions=positions, orientation=orientation,
                           frames=tuple(sl.frame for sl in ordered) if multi else (),
                           rescale=(tuple(sl.rescale or (1.0, 0.0) for sl in ordered)
                                    if multi else ()),
                           pixel_spacing=(None if first.pixel_spacing is None else
                                          tuple(float(v) for v in first.pixel_spacing)),
                           thickness=first.thickness, kind=kind, **info)

    if problem:
        return entry(problem)
    sizes = {(int(ds.get("Columns", 0) or 0), int(ds.get("Rows", 0) or 0)) for _, ds, _ in members}
    if len(sizes) > 1:
        a, b = sorted(sizes)[:2]
        return entry(f"slices of different sizes ({a[0]} x {a[1]} and {b[0]} x {b[1]}, columns x "
                     "rows)")
    iops = [sl.orientation for sl in slices]
    if iops[0] is None:
        if len(slices) == 1:
            return entry(orientation=None)   # one image without geometry (a radiograph): as is
        return entry("no ImageOrientationPatient: the slices cannot be ordered")
    if any(o is None for o in iops):
        return entry("some slices have no ImageOrientationPatient")
    distinct: list[np.ndarray] = []
    for o in iops:
        if not any(np.allclose(o, d, atol=ORIENTATION_TOLERANCE) for d in distinct):
            distinct.append(o)
    if len(distinct) > 1:
        return entry(f"its {len(slices)} slices lie in {len(distinct)} different orientations "
                     "(a localiser or projections?)")
    iop = distinct[0]
    normal = np.cross(iop[:3], iop[3:])
    if not np.linalg.norm(normal) > 1e-6:
        return entry(f"ImageOrientationPatient {_g(iop)} has parallel row and column directions")
    normal /= np.linalg.norm(normal)
    spacings = {tuple(sl.pixel_spacing) for sl in slices if sl.pixel_spacing is not None}
    if len(spacings) > 1:
        a, b = sorted(spacings)[:2]
        return entry(f"frames of different pixel spacings ({_g(a)} and {_g(b)})")
    positions = []
    for sl in slices:
        pos = sl.position
        if pos is None:
            if len(slices) > 1:
                return entry(f"{sl.name} has no ImagePositionPatient: the slices cannot be "
                             "ordered")
            pos = np.zeros(3)
        positions.append(pos)
    order = sorted(range(len(slices)), key=lambda k: float(positions[k] @ normal))
    points = np.array([positions[k] for k in order])
    along = points @ normal
    ordered = [slices[k] for k in order]
    if len(slices) > 1:
        gaps = np.diff(along)
        k = int(np.argmin(gaps))
        if not gaps[k] > 1e-6:
            return entry(f"{ordered[k].name} and {ordered[k + 1].name} lie at the same position "
                         f"along the slice normal ({along[k]:.6g})" +
                         (" (several stacks or time points in one file?)"
                          if ordered[k].frame is not None else ""))
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
                          f"{chosen.problem}" + listing.broken_said())
    # Without a series named, a series whose pixels cannot be read (a compression no installed
    # decoder reads, a slice cut short) gives way to the next largest, said in a note.
    candidates = [chosen] if wanted is not None else listing.by_size()
    failed: list[str] = []
    seen: list = []
    for chosen in candidates:
        where = (str(p) if len(listing.series) == 1 else
                 f"{p}, series {chosen.label()}")
        try:
            with _library_warnings(seen):
                data, spacing = _read_pixels(chosen, need_spacing, where)
            break
        except VolumeError as exc:
            failed.append(str(exc))
        except Exception as exc:
            failed.append(f"{where}: cannot read the DICOM series ({_one_line(exc)})")
    else:
        more = len(failed) - 1
        raise VolumeError(failed[0] + (f" (and none of the {more} other series that make a "
                                       f"volume could be read either)" if more else "")) from None
    notes = []
    if failed:
        notes.append(f"{p.name}: {len(failed)} larger series could not be read, so this one "
                     f"opened; the first: {failed[0]}")
    if len(listing.series) > 1:
        others = "; ".join(s.label(reason=False) for s in listing.series if s is not chosen)
        how = "the largest that makes a volume" if wanted is None else "as the scene names"
        notes.append(f"{p.name} holds {len(listing.series)} DICOM series; opened {how}: "
                     f"{chosen.label()}. The others: {others}. Open another with --series N "
                     f"({with_flag('volume.series')}); `radiance-probes series {p}` lists them all")
    skip = listing.skip_note()
    if skip:
        notes.append(skip)
    if seen:
        notes.append(f"{p.name}: pydicom warned {len(seen)} time{'s' if len(seen) != 1 else ''} "
                     "while decoding the pixels (read all the same)")
    direction = None
    if chosen.orientation is not None:
        iop = np.array(chosen.orientation)
        direction = np.stack([iop[:3], iop[3:], np.cross(iop[:3], iop[3:])], axis=1)
    return DicomVolume(data, spacing, direction, chosen, listing, tuple(notes))


def _read_pixels(series: DicomSeries, need_spacing: bool, where: str
                 ) -> tuple[np.ndarray, tuple[float, float, float] | None]:
    import pydicom
    planes, slopes, intercepts, first = [], [], [], None
    frames = series.frames or (None,) * series.slices
    decoded: dict[Path, tuple] = {}   # a multi-frame file is decoded once for all its frames
    for k, (f, frame) in enumerate(zip(series.files, frames)):
        if f not in decoded:
            try:
                ds = pydicom.dcmread(str(f))
            except Exception as exc:
                raise VolumeError(f"{f}: cannot read DICOM ({_one_line(exc)})") from None
            if "PixelData" not in ds:
                raise VolumeError(f"{f}: an image without pixel data (a truncated file?)")
            try:
                decoded[f] = (ds, ds.pixel_array)
            except Exception as exc:
                raise VolumeError(f"{f}: cannot decode the pixel data ({_one_line(exc)})") from None
        ds, pixels = decoded[f]
        if frame is not None and pixels.ndim == 3 and _frame_count(ds, f) > 1:
            pixels = pixels[frame]
        if pixels.ndim != 2:
            raise VolumeError(f"{f}: pixel data of shape {list(pixels.shape)}; expected one "
                              "channel (rows x columns)")
        if pixels.shape != (series.rows, series.columns):
            raise VolumeError(f"{where}: slices of different sizes: {f.name} is {pixels.shape[1]} "
                              f"x {pixels.shape[0]}, the series {series.columns} x {series.rows} "
                              "(columns x rows)")
        if series.rescale:
            slope, intercept = series.rescale[k]
        else:
            slope, intercept = (_floats(ds, "RescaleSlope", 1, f),
                                _floats(ds, "RescaleIntercept", 1, f))
            slope = 1.0 if slope is None else float(slope[0])
            intercept = 0.0 if intercept is None else float(intercept[0])
        planes.append(pixels)
        slopes.append(slope)
        intercepts.append(intercept)
        first = first if first is not None else (f, ds)
    stack = np.stack(planes)
    slopes, intercepts = np.array(slopes), np.array(intercepts)
    if not (slopes == 1.0).all() or not (intercepts == 0.0).all():
        if not (slopes != 0).all():
            raise VolumeError(f"{where}: RescaleSlope 0 would make every voxel one value")
        stack = (stack.astype(np.float64) * slopes[:, None, None]
                 + intercepts[:, None, None]).astype(np.float32)

    first_f, ds = first
    ps = (np.array(series.pixel_spacing) if series.pixel_spacing is not None else
          _floats(ds, "PixelSpacing", 2, first_f))
    if series.slices > 1:
        dz = float(np.mean(np.diff(series.positions)))
    elif series.thickness is not None:
        dz = series.thickness
    else:
        thickness = (_floats(ds, "SpacingBetweenSlices", 1, first_f)
                     if "SpacingBetweenSlices" in ds else _floats(ds, "SliceThickness", 1, first_f))
        dz = None if thickness is None else float(thickness[0])
    values = None if ps is None or dz is None else (ps[1], ps[0], dz)  # x = column, y = row
    return stack, spacing_or_none(values, where, need_spacing)
