"""DICOM as a scanner or PACS writes it (app/io/dicom.py): folder trees and DICOMDIRs list their
series, the largest that makes a volume opens with a note naming the others, a scene or --series
names another, and series that do not make a volume say why in plain words. Against small series
pydicom writes here, and against pydicom's own test folders where the installed pydicom ships them
(dicomdirtests: a tree of three folders, MR2 mixing three series, MR700 of differing
orientations)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pydicom
import pytest
from pydicom.fileset import FileSet

from radiance_probes.io.dicom import list_series
from radiance_probes.io.scene_file import VolumeSpec, parse_scene
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_volume
from test_volume_formats import ct_slice, write_dicom_series

PYDICOM_TESTS = Path(pydicom.__file__).parent / "data" / "test_files" / "dicomdirtests"
shipped = pytest.mark.skipif(not (PYDICOM_TESTS / "98892003").is_dir(),
                             reason="this pydicom does not ship its dicomdirtests folder (the "
                                    "synthetic tests above cover the same cases)")


def load(path, **kw):
    return load_volume(VolumeSpec(path=str(path), builtin=None, **kw))


def scanner_folder(root: Path) -> Path:
    """A study as a scanner exports it: an axial series of 4 slices in one subfolder, a scout of
    one slice in another, a 2-slice series of another size, a report and a text file."""
    axial = np.arange(4 * 4 * 5, dtype=np.int16).reshape(4, 4, 5)
    write_dicom_series(root / "S1" / "axial", axial, uid="1.2.3.10", description="Axial",
                       slope=1.0, intercept=-1024.0)
    ct_slice(root / "S1" / "scout" / "IM0001", axial[0], 300.0, "1.2.3.11", description="Scout")
    write_dicom_series(root / "S2", np.arange(72, dtype=np.int16).reshape(2, 6, 6), uid="1.2.3.12",
                       description="Small", seed=5)
    (root / "README.TXT").write_text("exported by a scanner")
    return root


def test_a_tree_lists_its_series_and_opens_the_largest(tmp_path):
    root = scanner_folder(tmp_path / "study")
    listing = list_series(root)
    assert [(s.description, s.slices, s.columns, s.rows) for s in listing.series] == [
        ("Axial", 4, 5, 4), ("Scout", 1, 5, 4), ("Small", 2, 6, 6)]
    assert [s.modality for s in listing.series] == ["CT"] * 3
    assert [f.name for f in listing.skipped] == ["README.TXT"]
    v = load(root)
    assert v.dims == (5, 4, 4) and v.dicom_series.uid == "1.2.3.10"
    assert (v.raw_min, v.raw_max) == (-1024.0, 79.0 - 1024.0)      # rescaled to HU
    note = " ".join(v.notes)
    assert "holds 3 DICOM series" in note and "Scout" in note and "Small" in note
    assert "--series" in note and "README.TXT" in note


def test_a_series_is_named_by_number_or_uid(tmp_path):
    root = scanner_folder(tmp_path / "study")
    assert load(root, series=3).dims == (6, 6, 2)
    assert load(root, series="1.2.3.11").dims == (5, 4, 1)
    scene = parse_scene({"volume": {"path": str(root), "series": "2"}})
    assert load_volume(scene.volume).dicom_series.description == "Scout"
    top = parse_scene({"volume": {"path": str(root)}, "series": 3})   # SPEC.md's spelling
    assert load_volume(top.volume).dims == (6, 6, 2)
    with pytest.raises(VolumeError) as err:
        load(root, series=9)
    text = str(err.value)
    assert "no series 9" in text and "Axial" in text and "Small" in text and "\n" not in text


def test_a_dicomdir_lists_what_it_indexes(tmp_path):
    src = scanner_folder(tmp_path / "src")
    fs = FileSet()
    for f in sorted(p for p in src.rglob("*") if p.is_file() and p.suffix != ".TXT"):
        ds = pydicom.dcmread(f)
        ds.PatientID, ds.PatientName, ds.StudyID, ds.AccessionNumber = "P1", "Anon", "1", ""
        ds.StudyDate, ds.StudyTime, ds.InstanceNumber = "20240101", "000000", 1
        ds.SeriesNumber = {"1.2.3.10": 1, "1.2.3.11": 2, "1.2.3.12": 3}[ds.SeriesInstanceUID]
        fs.add(ds)
    fs.write(tmp_path / "cd")
    dicomdir = tmp_path / "cd" / "DICOMDIR"
    assert [s.slices for s in list_series(dicomdir).series] == [4, 1, 2]
    assert load(dicomdir).dims == (5, 4, 4)
    assert load(tmp_path / "cd").dims == (5, 4, 4)     # its folder, searched, gives the same


def test_a_series_that_is_no_volume_is_listed_not_opened(tmp_path):
    """A tri-plane localiser beside a real series: listed with its reason, passed over by
    default, refused in plain words when named."""
    root = tmp_path / "mixed"
    write_dicom_series(root, np.arange(40, dtype=np.int16).reshape(2, 4, 5), uid="1.2.3.20",
                       description="Axial")
    for k, iop in enumerate(((1, 0, 0, 0, 1, 0), (0, 1, 0, 0, 0, -1), (1, 0, 0, 0, 0, -1))):
        ct_slice(root / f"LOC{k}", np.zeros((4, 5), np.int16), k, "1.2.3.21", orientation=iop,
                 description="Localiser")
    listing = list_series(root)
    loc = next(s for s in listing.series if s.uid == "1.2.3.21")
    assert loc.slices == 3 and "3 different orientations" in loc.problem
    assert load(root).dicom_series.uid == "1.2.3.20"       # 2 slices, but a volume
    with pytest.raises(VolumeError, match="does not make one volume") as err:
        load(root, series="1.2.3.21")
    assert "np." not in str(err.value)


def test_series_reads_only_the_chosen_pixels(tmp_path, monkeypatch):
    """Listing reads headers; only the chosen series' pixel data is decoded."""
    root = scanner_folder(tmp_path / "study")
    decoded = []
    real = pydicom.dataset.Dataset.pixel_array.fget
    monkeypatch.setattr(pydicom.dataset.Dataset, "pixel_array",
                        property(lambda ds: decoded.append(ds.SeriesInstanceUID) or real(ds)))
    load(root)
    assert set(decoded) == {"1.2.3.10"} and len(decoded) == 4


# ---- pydicom's own test folders -----------------------------------------------------------------

@shipped
def test_pydicom_tree_lists_its_series_and_opens_the_largest():
    tree = PYDICOM_TESTS / "98892003"
    listing = list_series(tree)
    assert len(listing.series) == 7 and {s.modality for s in listing.series} == {"MR"}
    assert sum(s.problem is None for s in listing.series) == 4   # four single slices
    v = load(tree)
    assert v.dicom_series.problem is None and v.dims[:2] == (16, 16)
    assert "holds 7 DICOM series" in v.notes[0] and "ANGIO" in v.notes[0]


@shipped
def test_pydicom_mixed_folder_lists_three_series_and_opens_one():
    listing = list_series(PYDICOM_TESTS / "98892003" / "MR2")
    assert [s.slices for s in listing.series] == [1, 3, 3]
    assert all("orientations" in s.problem for s in listing.series[1:])
    v = load(PYDICOM_TESTS / "98892003" / "MR2")
    assert v.dicom_series is listing.series[0] or v.dicom_series.uid == listing.series[0].uid


@shipped
def test_pydicom_differing_orientations_refused_plainly():
    with pytest.raises(VolumeError) as err:
        load(PYDICOM_TESTS / "98892003" / "MR700")
    text = str(err.value)
    assert "7 different orientations" in text and "ANGIO" in text
    assert "np." not in text and "float64" not in text and "\n" not in text


@shipped
def test_pydicom_dicomdir_opens_its_largest_volume():
    """The DICOMDIR indexes 13 series of three studies; the 5-slice CT is the largest volume (the
    4-slice one misses slices, and is listed as such)."""
    listing = list_series(PYDICOM_TESTS / "DICOMDIR")
    assert len(listing.series) == 13
    brain = next(s for s in listing.series if s.description == "Routine Brain")
    assert "uneven slice spacing" in brain.problem
    v = load(PYDICOM_TESTS / "DICOMDIR")
    assert v.dicom_series.description.startswith("SmartScore") and v.dims == (16, 16, 5)
    assert v.raw_min < -800   # Hounsfield units: RescaleIntercept -1024 applied


# ---- the command line ---------------------------------------------------------------------------

def test_the_series_command_lists_them_and_marks_the_default(tmp_path, capsys):
    from radiance_probes.cli.main import main
    root = scanner_folder(tmp_path / "study")
    assert main(["series", str(root)]) == 0
    out = capsys.readouterr().out
    assert "3 DICOM series" in out and '* 1: #' not in out   # SeriesNumber absent: no "#"
    lines = out.splitlines()
    assert lines[1].startswith("* 1: ") and "Axial" in lines[1] and "5 x 4 x 4" in lines[1]
    assert "SeriesInstanceUID 1.2.3.11" in out and "README.TXT" not in out


def test_render_takes_series_and_says_what_it_opened(tmp_path, capsys):
    from radiance_probes.cli.main import main
    root = scanner_folder(tmp_path / "study")
    assert main(["render", str(root), "--width", "8", "--height", "8", "--spp", "1",
                 "--out", str(tmp_path / "a.png")]) == 0
    err = capsys.readouterr().err
    assert "note: study holds 3 DICOM series" in err
    assert main(["render", str(root), "--series", "3", "--width", "8", "--height", "8",
                 "--spp", "1", "--out", str(tmp_path / "b.png")]) == 0
    assert "opened as the scene names" in capsys.readouterr().err
    for argv, needle in ((["render", str(root), "--series", "9"], "no series 9"),
                         (["render", "--series", "2"], "--series: volume.series: only for")):
        assert main(argv + ["--out", str(tmp_path / "c.png")]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0], lines


def test_window_and_orientation_options(tmp_path, capsys):
    """--data-window (a preset or LEVEL,WIDTH) and --orientation reach the scene as its keys would."""
    import argparse
    from radiance_probes.frontend.scene_options import apply_options, scene_from_arg
    from radiance_probes.frontend.option_types import window_arg
    scene = scene_from_arg(str(tmp_path))
    args = argparse.Namespace(data_window=window_arg("bone"), orientation="patient", series=2)
    out = apply_options(scene, args)
    assert out.volume.window == (400.0, 1800.0) and out.volume.orientation == "patient"
    assert out.volume.series == 2
    args = argparse.Namespace(data_window=window_arg("40,400"))
    assert apply_options(scene, args).volume.window == (40.0, 400.0)
    with pytest.raises(argparse.ArgumentTypeError, match="LEVEL,WIDTH"):
        window_arg("wide")


# ---- a folder as an export leaves it (issue 55) -------------------------------------------------

def export_folder(root: Path) -> Path:
    """80 files as a PACS export may leave them: a 58-slice series, a 10-slice one with a slice
    cut short in its header, 3 files cut in their pixel data, 3 images whose pixel data is gone,
    2 with a SeriesNumber pydicom warns of, and 4 that are not DICOM (a text file, an empty one,
    bytes named .dcm, an HTML index)."""
    write_dicom_series(root / "CT", np.arange(58 * 6 * 5, dtype=np.int16).reshape(58, 6, 5),
                       uid="1.2.3.58", description="Axial")
    second = write_dicom_series(root / "MR", np.ones((10, 4, 4), np.int16), uid="1.2.3.61",
                                description="Small", seed=2)
    cut = sorted(second.iterdir())[4]
    cut.write_bytes(cut.read_bytes()[:300])
    broken = root / "broken"
    for k in range(6):
        f = ct_slice(broken / f"B{k}", np.full((6, 5), k, np.int16), 100.0 + k, "1.2.3.62")
        if k < 3:
            f.write_bytes(f.read_bytes()[:-20])   # pixel data cut short
        else:
            ds = pydicom.dcmread(f)
            del ds.PixelData
            ds.save_as(f)
    for k in range(2):   # a value pydicom reads with a warning: SeriesNumber "1A"
        f = ct_slice(root / "odd" / f"O{k}", np.zeros((6, 5), np.int16), float(k), "1.2.3.63")
        ds = pydicom.dcmread(f)
        ds.add_new(0x00200011, "IS", None)
        ds[0x00200011]._value = "1A"
        ds.save_as(f)
    (root / "README.TXT").write_text("exported")
    (root / "empty.dcm").write_bytes(b"")
    (root / "junk.dcm").write_bytes(bytes(range(256)) * 4)
    (root / "INDEX.HTM").write_text("<html></html>")
    assert sum(1 for f in root.rglob("*") if f.is_file()) == 80
    return root


def test_an_export_with_broken_files_lists_what_it_can_and_says_what_it_passed_over(tmp_path, capsys):
    import warnings
    from radiance_probes.cli.main import main
    root = export_folder(tmp_path / "export")
    with warnings.catch_warnings(record=True) as caught:   # none of pydicom's gets out
        warnings.simplefilter("always")
        listing = list_series(root)
        assert main(["series", str(root)]) == 0
        v = load(root)
    assert not [w for w in caught if "pydicom" in w.filename]
    assert sorted(s.uid for s in listing.series) == ["1.2.3.58", "1.2.3.61", "1.2.3.63"]
    small = next(s for s in listing.series if s.uid == "1.2.3.61")
    assert small.slices == 9 and "uneven slice spacing" in small.problem   # the slice it lost
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if line]
    assert len(notes) == 1 and notes[0].startswith("note: export: passed over 11 files"), notes
    for words in ("4 not DICOM", "3 cut short in the pixel data",
                  "4 image files without pixel data",
                  "2 files read despite header irregularities pydicom warned of (O0, O1)"):
        assert words in notes[0], (words, notes[0])
    assert "Warning" not in captured.err and "Traceback" not in captured.err
    assert "3 DICOM series" in captured.out and "* " in captured.out
    assert v.dicom_series.uid == "1.2.3.58" and v.dims == (5, 6, 58)
    assert any("passed over 11 files" in n for n in v.notes)


def test_a_folder_where_no_series_can_be_read_is_refused_saying_why(tmp_path):
    root = tmp_path / "cut"
    for k in range(3):
        f = ct_slice(root / f"C{k}", np.zeros((6, 5), np.int16), float(k), "1.2.3.70")
        f.write_bytes(f.read_bytes()[:-20])
    (root / "notes.txt").write_text("hello")
    with pytest.raises(VolumeError) as err:
        list_series(root)
    text = str(err.value)
    assert "no DICOM series here can be read" in text and "cut short" in text and "C0" in text
    assert "1 files not DICOM" in text and "\n" not in text


def test_a_series_whose_pixels_cannot_be_decoded_gives_way_to_the_next(tmp_path, monkeypatch):
    """Without --series, the largest series that cannot be decoded (here: a decoder that fails
    for it) gives way to the next largest, with a note; named, it is refused."""
    root = scanner_folder(tmp_path / "study")
    real = pydicom.dataset.Dataset.pixel_array.fget

    def fail_axial(ds):
        if ds.SeriesInstanceUID == "1.2.3.10":
            raise RuntimeError("no decoder for this transfer syntax")
        return real(ds)
    monkeypatch.setattr(pydicom.dataset.Dataset, "pixel_array", property(fail_axial))
    v = load(root)
    assert v.dicom_series.uid == "1.2.3.12"
    assert any("1 larger series could not be read" in n and "no decoder" in n for n in v.notes)
    with pytest.raises(VolumeError, match="cannot decode the pixel data"):
        load(root, series="1.2.3.10")
