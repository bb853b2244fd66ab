"""NIfTI, TIFF and DICOM loaders against files the libraries themselves write, the CT/MRI window,
and every format's bad input ending in one VolumeError naming the file and the problem."""
from __future__ import annotations

import random
from pathlib import Path

import nibabel as nib
import numpy as np
import pydicom
import pytest
import tifffile
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from radiance_probes.io.scene_file import SceneError, VolumeSpec, parse_scene
from radiance_probes.scene.types import WINDOW_PRESETS
from radiance_probes.scene.transfer import lookup, transfer_table
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_volume

# x = 5, y = 4, z = 3: every axis a different length, so a swapped axis cannot pass
ARRAY = (np.arange(3 * 4 * 5, dtype=np.int16).reshape(3, 4, 5) * 37 - 900)
SPACING = (0.7, 0.8, 2.5)


def write_tiff(path, data_zyx):
    """One page per z (three planes would otherwise be stored as one RGB page)."""
    tifffile.imwrite(path, data_zyx, photometric="minisblack")


def load(path, **kw):
    return load_volume(VolumeSpec(path=str(path), builtin=None, **kw))


def write_nifti(path: Path, data_zyx: np.ndarray, spacing=SPACING, slope=None, inter=None):
    img = nib.Nifti1Image(np.ascontiguousarray(data_zyx.transpose(2, 1, 0)), np.eye(4))
    img.header.set_zooms(spacing)
    if slope is not None:
        img.header.set_slope_inter(slope, inter)
    nib.save(img, str(path))
    return path


def ct_slice(path: Path, pixels: np.ndarray, z: float, series_uid: str, slope=1.0, intercept=0.0,
             spacing=SPACING[:2], orientation=(1, 0, 0, 0, 1, 0), description="CT", position=None):
    """A minimal valid CT image slice, as a scanner would write it (its folder made if missing)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.Modality = "CT"
    ds.SeriesInstanceUID = series_uid
    ds.SeriesDescription = description
    ds.StudyInstanceUID = "1.2.3"
    ds.ImagePositionPatient = ([-10.0, 20.0, float(z)] if position is None
                               else [float(v) for v in position])
    ds.ImageOrientationPatient = list(orientation)
    ds.PixelSpacing = [spacing[1], spacing[0]]   # row spacing (y), then column spacing (x)
    ds.SliceThickness = 2.5
    ds.RescaleSlope = slope
    ds.RescaleIntercept = intercept
    ds.Rows, ds.Columns = pixels.shape
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit = 15
    ds.PixelRepresentation = 1 if pixels.dtype == np.int16 else 0
    ds.PixelData = np.ascontiguousarray(pixels).tobytes()
    ds.save_as(str(path), enforce_file_format=True)
    return path


def write_dicom_series(folder: Path, data_zyx: np.ndarray, z0=-40.0, dz=SPACING[2], seed=0,
                       slope=1.0, intercept=0.0, uid=None, **kw) -> Path:
    """Slices under shuffled file names, so name order is not position order."""
    folder.mkdir(parents=True, exist_ok=True)
    uid = uid or generate_uid()
    names = [f"IM{n:04d}" for n in random.Random(seed).sample(range(1000), len(data_zyx))]
    for k, (name, sl) in enumerate(zip(names, data_zyx)):
        ct_slice(folder / name, sl, z0 + k * dz, uid, slope, intercept, **kw)
    assert sorted(names) != names, "the file names should not already be in slice order"
    return folder


# ---- the same array through every format ---------------------------------------------------------

def test_every_format_gives_the_same_volume(tmp_path):
    ref = load(np.save(tmp_path / "a.npy", ARRAY) or tmp_path / "a.npy", spacing=SPACING)
    nii = load(write_nifti(tmp_path / "a.nii", ARRAY))
    niigz = load(write_nifti(tmp_path / "a.nii.gz", ARRAY))
    write_tiff(tmp_path / "a.tif", ARRAY)
    tif = load(tmp_path / "a.tif", spacing=SPACING)
    (tmp_path / "pages").mkdir()
    for k, page in enumerate(ARRAY):
        tifffile.imwrite(tmp_path / "pages" / f"slice_{k:03d}.tiff", page)
    folder = load(tmp_path / "pages", spacing=SPACING)
    dcm = load(write_dicom_series(tmp_path / "dcm", ARRAY))
    for v in (nii, niigz, tif, folder, dcm):
        assert v.data.shape == (3, 4, 5) and v.dims == (5, 4, 3)
        np.testing.assert_array_equal(v.data, ref.data)
        np.testing.assert_allclose(v.spacing, SPACING, rtol=1e-6)
        assert (v.raw_min, v.raw_max) == (float(ARRAY.min()), float(ARRAY.max()))
    assert nii.raw_dtype == tif.raw_dtype == dcm.raw_dtype == "int16"   # precision kept


def test_uint8_keeps_the_full_type_range(tmp_path):
    a = (np.arange(60, dtype=np.uint8).reshape(3, 4, 5) + 10)
    v = load(write_nifti(tmp_path / "b.nii.gz", a))
    assert v.value_range == (0.0, 255.0) and v.exact_uint8
    np.testing.assert_array_equal(v.data, (a / 255.0).astype(np.float32))


def test_float_and_16_bit_keep_precision(tmp_path):
    a = np.linspace(0, 1, 60, dtype=np.float32).reshape(3, 4, 5) + np.float32(1e-6)
    v = load(write_nifti(tmp_path / "f.nii", a))
    assert v.raw_dtype == "float32" and len(np.unique(v.data)) == 60
    u = (np.arange(60, dtype=np.uint16).reshape(3, 4, 5) + 60000)   # neighbours 1 / 65535 apart
    write_tiff(tmp_path / "u.tif", u)
    v = load(tmp_path / "u.tif")
    assert v.raw_dtype == "uint16" and len(np.unique(v.data)) == 60


def test_nifti_scaling_applied(tmp_path):
    v = load(write_nifti(tmp_path / "s.nii", ARRAY, slope=2.0, inter=-1024.0))
    assert v.raw_min == 2.0 * ARRAY.min() - 1024 and v.raw_max == 2.0 * ARRAY.max() - 1024


# ---- DICOM ----------------------------------------------------------------------------------------

def test_dicom_orders_by_position_not_name_and_applies_rescale(tmp_path):
    stored = (np.arange(4 * 3 * 2, dtype=np.uint16).reshape(4, 3, 2) * 10)
    folder = write_dicom_series(tmp_path / "s", stored, slope=2.0, intercept=-1024.0, seed=3)
    v = load(folder, value_range=(-1024.0, 0.0))
    hu = stored.astype(np.float64) * 2.0 - 1024.0
    np.testing.assert_allclose(v.data, ((hu + 1024.0) / 1024.0).astype(np.float32), atol=1e-7)
    assert (v.raw_min, v.raw_max) == (-1024.0, float(hu.max()))
    np.testing.assert_allclose(v.spacing, SPACING)


def test_dicom_orders_along_the_normal_when_positions_descend(tmp_path):
    stored = (np.arange(4 * 3 * 2, dtype=np.int16).reshape(4, 3, 2))
    folder = write_dicom_series(tmp_path / "d", stored[::-1], z0=10.0, dz=-2.0)
    v = load(folder)
    np.testing.assert_array_equal(v.data[0], load(write_dicom_series(
        tmp_path / "u", stored, z0=4.0, dz=2.0)).data[0])
    assert v.spacing[2] == pytest.approx(2.0)


@pytest.mark.filterwarnings("ignore::UserWarning")   # pydicom warns on the mangled value it reads
@pytest.mark.parametrize("case, message", [
    ("no images", "holds no DICOM images"),
    ("sizes", "slices of different sizes"),
    ("only text", "holds no DICOM files"),
    ("same position", "same position"),
    ("gap", "uneven slice spacing"),
    ("no spacing", "missing spacing"),
    ("empty", "holds no files"),
    ("orientations", "3 different orientations"),
    ("gantry tilt", "step sideways"),
])
def test_dicom_bad_series(tmp_path, case, message):
    folder = tmp_path / "bad"
    data = np.zeros((3, 4, 5), np.int16)
    data[:, 1, 1] = 100
    if case == "empty":
        folder.mkdir()
    elif case == "only text":
        folder.mkdir()
        (folder / "notes.txt").write_text("hello")
    elif case == "orientations":   # a tri-plane localiser: one series, three planes
        for k, iop in enumerate(((1, 0, 0, 0, 1, 0), (0, 1, 0, 0, 0, -1), (1, 0, 0, 0, 0, -1))):
            ct_slice(folder / f"L{k}", data[0], k, "1.2.3.7",
                     orientation=(0.959171, 0.282842, 0.0, 0.0, 0.0, -1.0) if k == 2 else iop)
    elif case == "gantry tilt":    # positions step along y as well as z
        write_dicom_series(folder, data)
        for f in folder.iterdir():
            ds = pydicom.dcmread(f)
            ds.ImagePositionPatient = [-10.0, float(ds.ImagePositionPatient[2]) * 0.3,
                                       float(ds.ImagePositionPatient[2])]
            ds.save_as(f)
    elif case == "no images":
        folder.mkdir()
        for k in range(2):   # structured reports: DICOM files, but no images
            meta = FileMetaDataset()
            meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.88.11"   # Basic Text SR
            meta.MediaStorageSOPInstanceUID = generate_uid()
            meta.TransferSyntaxUID = ExplicitVRLittleEndian
            ds = FileDataset(str(folder / f"SR{k}"), {}, file_meta=meta, preamble=b"\0" * 128)
            ds.SOPClassUID = meta.MediaStorageSOPClassUID
            ds.SeriesInstanceUID, ds.Modality = "1.2.3.9", "SR"
            ds.save_as(str(folder / f"SR{k}"), enforce_file_format=True)
    elif case == "sizes":
        write_dicom_series(folder, data)
        ct_slice(folder / "zz", np.zeros((4, 6), np.int16), -40 + 3 * 2.5,
                 pydicom.dcmread(next(folder.iterdir())).SeriesInstanceUID)
    elif case == "same position":
        write_dicom_series(folder, data, dz=0.0)
    elif case == "gap":
        write_dicom_series(folder, np.zeros((4, 4, 5), np.int16))
        sorted(folder.iterdir(), key=lambda f: float(pydicom.dcmread(f).ImagePositionPatient[2]))[2].unlink()
    elif case == "no spacing":
        write_dicom_series(folder, data)
        for f in folder.iterdir():
            ds = pydicom.dcmread(f)
            del ds.PixelSpacing
            ds.save_as(f)
    with pytest.raises(VolumeError) as err:
        load(folder)
    text = str(err.value)
    assert message in text and str(folder) in text and "\n" not in text, text
    assert "np." not in text and "float64" not in text, text   # plain numbers, no library reprs
    if case == "no spacing":   # the scene's own spacing makes the same series loadable
        assert load(folder, spacing=(1, 1, 1)).spacing == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("case, why", [
    ("truncated", "image files without pixel data"),
    ("truncated pixels", "cut short in the pixel data"),
    ("frames", "with a header value that cannot be read"),
])
def test_dicom_broken_slice_is_passed_over_with_a_note(tmp_path, case, why):
    """A file cut short or with a header value that is no number: passed over (issue 55: a
    folder is read as an export leaves it), named in one note with why; the rest opens."""
    folder = tmp_path / "bad"
    data = np.zeros((4, 4, 5), np.int16)
    data[:, 1, 1] = 100
    write_dicom_series(folder, data)
    by_z = sorted(folder.iterdir(), key=lambda f: float(pydicom.dcmread(f).ImagePositionPatient[2]))
    middle, f = by_z[1], by_z[-1]   # the last slice: the three before it still make a volume
    middle.write_bytes(middle.read_bytes()[:300])
    with pytest.raises(VolumeError) as err:   # a slice missing: refused, the passed-over named
        load(folder)
    assert "uneven slice spacing" in str(err.value) and f"passed over: {middle.name}" in str(err.value)
    middle.unlink()
    if case == "truncated":
        f.write_bytes(f.read_bytes()[:300])
    elif case == "truncated pixels":
        f.write_bytes(f.read_bytes()[:-7])
    else:   # a value pydicom reads but that is no number
        ds = pydicom.dcmread(f)
        ds.add_new(0x00280008, "IS", None)
        ds[0x00280008]._value = "x"
        ds.save_as(f)
    v = load(folder)
    assert v.dims[2] == 2
    notes = [n for n in v.notes if "passed over" in n]
    assert len(notes) == 1 and f"1 {why} ({f.name}" in notes[0] and "\n" not in notes[0], v.notes
    if case == "frames":
        assert "cannot read NumberOfFrames ('x')" in notes[0]


# ---- TIFF and NIfTI bad input --------------------------------------------------------------------

def test_tiff_pages_of_different_shapes(tmp_path):
    p = tmp_path / "mixed.tif"
    with tifffile.TiffWriter(p) as w:
        w.write(np.zeros((4, 5), np.uint8))
        w.write(np.zeros((4, 6), np.uint8))
    with pytest.raises(VolumeError, match="pages of different shapes") as err:
        load(p)
    assert str(p) in str(err.value)
    (tmp_path / "f").mkdir()
    tifffile.imwrite(tmp_path / "f" / "a.tif", np.zeros((4, 5), np.uint8))
    tifffile.imwrite(tmp_path / "f" / "b.tif", np.zeros((5, 5), np.uint8))
    with pytest.raises(VolumeError, match="b.tif is 5 x 5"):
        load(tmp_path / "f")


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz", ".tif"])
def test_truncated_and_corrupt_files(tmp_path, suffix):
    p = tmp_path / f"v{suffix}"
    if suffix == ".tif":
        write_tiff(p, ARRAY)
    else:
        write_nifti(p, ARRAY)
    whole = p.read_bytes()
    for cut in (whole[: len(whole) // 2], whole[:40], b"garbage" * 10):
        p.write_bytes(cut)
        with pytest.raises(VolumeError) as err:
            load(p)
        assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_nonfinite_float_data_and_missing_spacing(tmp_path):
    a = ARRAY.astype(np.float32)
    a[1, 2, 3] = np.nan
    with pytest.raises(VolumeError, match="NaN or Inf"):
        load(write_nifti(tmp_path / "nan.nii", a))
    a[1, 2, 3] = np.inf
    write_tiff(tmp_path / "inf.tif", a)
    with pytest.raises(VolumeError, match="NaN or Inf"):
        load(tmp_path / "inf.tif")
    assert load(tmp_path / "inf.tif", replace_nonfinite=0.0).raw_max == float(ARRAY.max())
    p = write_nifti(tmp_path / "nospacing.nii", ARRAY, spacing=(1.0, 0.0, 1.0))
    with pytest.raises(VolumeError, match="missing spacing"):
        load(p)


# ---- the window ----------------------------------------------------------------------------------

def test_window_maps_level_and_width(tmp_path):
    hu = np.array([-1000, -160, 40, 240, 1000, 2000], np.int16).reshape(1, 1, 6)
    np.save(tmp_path / "hu.npy", hu)
    v = load(tmp_path / "hu.npy", window=(40.0, 400.0))
    assert v.value_range == (-160.0, 240.0)
    np.testing.assert_allclose(v.data.ravel(), [0, 0, 0.5, 1, 1, 1])


def test_ct_preset_opacity_at_known_hounsfield_units(tmp_path):
    scene = parse_scene({"volume": {"path": str(tmp_path / "hu.npy"), "window": "bone"},
                         "transfer_function": {"opacity": [[0, 0], [0.5, 0], [1, 1]]}})
    level, width = WINDOW_PRESETS["bone"]
    assert scene.volume.window == (level, width) == (400.0, 1800.0)
    hu = np.array([-1000, 0, 200, 850, 1300, 3000], np.int16).reshape(1, 1, 6)   # air .. dense bone
    np.save(tmp_path / "hu.npy", hu)
    v = load_volume(scene.volume)
    alpha = lookup(transfer_table(scene.transfer_function), v.data)[..., 3].ravel()
    # the window spans -500 .. 1300 HU: soft tissue and below transparent, bone opaque by 1300
    np.testing.assert_allclose(alpha, [0, 0, 0, 0.5, 1, 1], atol=1e-6)


def test_window_in_the_scene_json():
    s = parse_scene({"volume": {"path": "ct", "window": {"level": -600, "width": 1500}}})
    assert s.volume.domain == (-1350.0, 150.0)
    assert parse_scene(s.to_dict()) == s
    assert s.to_dict()["volume"]["window"] == {"level": -600.0, "width": 1500.0}
    for bad, field in ([{"window": "liver"}, "volume.window"],
                       [{"window": {"level": 0}}, "volume.window"],
                       [{"window": {"level": 0, "width": 0}}, "volume.window.width"],
                       [{"window": "lung", "value_range": [0, 1]}, "volume.window"]):
        with pytest.raises(SceneError, match=field.replace(".", r"\.")):
            parse_scene({"volume": {"path": "ct", **bad}})


def test_histogram_axis_in_data_units():
    from radiance_probes.viewer.panels.tf_editor import data_ticks, window_choice
    ticks, labels = data_ticks((-160.0, 240.0))   # the soft-tissue window in HU
    assert labels == ["-100", "0", "100", "200"]
    np.testing.assert_allclose(ticks, [60 / 400, 160 / 400, 260 / 400, 360 / 400])
    ticks, labels = data_ticks((0.0, 255.0))
    assert labels == ["0", "100", "200"] and ticks[-1] == pytest.approx(200 / 255)
    assert window_choice((400.0, 1800.0)) == "bone" and window_choice((1.0, 2.0)) == "custom"
    assert window_choice(None) == "value range"
