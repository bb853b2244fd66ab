"""Multi-frame DICOM (app/io/dicom.py): an RT dose grid (pydicom's own rtdose.dcm: 15 frames placed by
GridFrameOffsetVector, values x DoseGridScaling) and an enhanced CT or MR (frames placed by their
per-frame functional groups, rescaled by PixelValueTransformationSequence) each open as a volume
with the geometry a series of single slices of the same data has; a multi-frame file that places
no frame is refused in plain words."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pydicom
import pytest
from pydicom.data import get_testdata_file
from pydicom.dataset import Dataset, FileDataset, FileMetaDataset
from pydicom.sequence import Sequence
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

from radiance_probes.cli.main import main
from radiance_probes.io.dicom import list_series
from radiance_probes.io.scene_file import VolumeSpec
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_volume
from test_volume_formats import ct_slice

ENHANCED_CT = "1.2.840.10008.5.1.4.1.1.2.1"
ENHANCED_MR = "1.2.840.10008.5.1.4.1.1.4.1"


def load(path, **kw):
    return load_volume(VolumeSpec(path=str(path), builtin=None, **kw))


@pytest.fixture
def rtdose(tmp_path) -> Path:
    """pydicom's rtdose.dcm (it ships with pydicom) in a folder of its own."""
    folder = tmp_path / "dose"
    folder.mkdir()
    return Path(shutil.copy(get_testdata_file("rtdose.dcm"), folder / "rtdose.dcm"))


def test_rtdose_opens_as_a_15_slice_volume_with_its_grid_spacing(rtdose):
    ds = pydicom.dcmread(rtdose)
    for where in (rtdose.parent, rtdose):          # its folder, or the file itself
        v = load(where)
        assert v.dims == (10, 10, 15)
        assert v.spacing == (10.0, 10.0, 5.0)     # PixelSpacing; GridFrameOffsetVector steps of 5
        # DoseGridScaling applied: values in Gy, frame k is the file's frame k (offsets rise)
        scaled = ds.pixel_array.astype(np.float64) * float(ds.DoseGridScaling)
        assert v.raw_max == pytest.approx(scaled.max(), rel=1e-6)
        assert v.raw_min == pytest.approx(scaled.min(), rel=1e-6)
        lo, hi = v.value_range
        np.testing.assert_allclose(v.data, (scaled - lo) / (hi - lo), atol=1e-5)
        series = v.dicom_series
        np.testing.assert_allclose(series.positions, -761.87 + 5.0 * np.arange(15))
        assert series.kind == "RT dose grid"


def test_rtdose_with_absolute_offsets_places_the_frames_the_same(rtdose, tmp_path):
    """GridFrameOffsetVector may hold the frames' z (first not 0): the same grid."""
    ds = pydicom.dcmread(rtdose)
    ds.GridFrameOffsetVector = [float(ds.ImagePositionPatient[2]) + 5.0 * k for k in range(15)]
    (tmp_path / "abs").mkdir()
    ds.save_as(tmp_path / "abs" / "dose.dcm")
    v, ref = load(tmp_path / "abs"), load(rtdose)
    assert v.dims == ref.dims and v.spacing == ref.spacing
    np.testing.assert_array_equal(v.data, ref.data)
    np.testing.assert_allclose(v.dicom_series.positions, ref.dicom_series.positions)


def test_the_series_command_lists_a_multiframe_series(rtdose, capsys):
    assert main(["series", str(rtdose.parent)]) == 0
    out = capsys.readouterr().out
    assert "RTDOSE, 10 x 10 x 15 (RT dose grid)" in out and "* 1:" in out


def _frame_group(position, slope=None, intercept=None, orientation=None) -> Dataset:
    item = Dataset()
    pos = Dataset()
    pos.ImagePositionPatient = [float(v) for v in position]
    item.PlanePositionSequence = Sequence([pos])
    if orientation is not None:
        o = Dataset()
        o.ImageOrientationPatient = list(orientation)
        item.PlaneOrientationSequence = Sequence([o])
    if slope is not None:
        t = Dataset()
        t.RescaleSlope, t.RescaleIntercept, t.RescaleType = slope, intercept, "HU"
        item.PixelValueTransformationSequence = Sequence([t])
    return item


def write_enhanced(path: Path, frames: np.ndarray, positions, orientation, spacing_xy,
                   sop_class=ENHANCED_CT, slope=1.0, intercept=0.0, per_frame_orientation=False,
                   order=None) -> Path:
    """An enhanced multi-frame image as a modern scanner writes one file: the orientation and
    pixel measures shared (or the orientation per frame), each frame's position and rescale in its
    per-frame functional group; the frames stored in `order` (default: as given)."""
    order = list(range(len(frames))) if order is None else list(order)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID, ds.SOPInstanceUID = sop_class, meta.MediaStorageSOPInstanceUID
    ds.Modality = "CT" if sop_class == ENHANCED_CT else "MR"
    ds.SeriesInstanceUID, ds.StudyInstanceUID = generate_uid(), "1.2.3"
    ds.SeriesDescription = "enhanced"
    ds.NumberOfFrames = len(frames)
    ds.Rows, ds.Columns = frames.shape[1:]
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit, ds.PixelRepresentation = 15, 1
    shared = Dataset()
    measures = Dataset()
    measures.PixelSpacing = [spacing_xy[1], spacing_xy[0]]   # rows (y), then columns (x)
    measures.SliceThickness = 1.0
    shared.PixelMeasuresSequence = Sequence([measures])
    if not per_frame_orientation:
        o = Dataset()
        o.ImageOrientationPatient = list(orientation)
        shared.PlaneOrientationSequence = Sequence([o])
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    rescale = sop_class == ENHANCED_CT
    ds.PerFrameFunctionalGroupsSequence = Sequence([
        _frame_group(positions[k], slope if rescale else None, intercept if rescale else None,
                     orientation if per_frame_orientation else None) for k in order])
    ds.PixelData = np.ascontiguousarray(frames[order].astype(np.int16)).tobytes()
    ds.save_as(str(path), enforce_file_format=True)
    return path


# an oblique stack: rows along (cos, sin, 0), columns along z; slices step along the normal
ANGLE = np.radians(30.0)
ORIENTATION = (np.cos(ANGLE), np.sin(ANGLE), 0.0, 0.0, 0.0, -1.0)
NORMAL = np.cross(ORIENTATION[:3], ORIENTATION[3:])
ORIGIN = np.array([-12.0, 30.0, 80.0])
GAP = 1.25


def oblique_data() -> tuple[np.ndarray, list[np.ndarray]]:
    data = np.random.default_rng(3).integers(-500, 1500, (6, 5, 7)).astype(np.int16)
    return data, [ORIGIN + k * GAP * NORMAL for k in range(len(data))]


def write_classic(folder: Path, data: np.ndarray, positions, slope: float, intercept: float
                  ) -> Path:
    """The same slices as a classic series of single-frame files at the same positions."""
    uid = generate_uid()
    for k, (plane, position) in enumerate(zip(data, positions)):
        ct_slice(folder / f"IM{(7 * k) % 11:04d}", plane, 0.0, uid, slope, intercept,
                 spacing=(0.7, 0.9), orientation=ORIENTATION, position=position)
    return folder


@pytest.mark.parametrize("sop_class", [ENHANCED_CT, ENHANCED_MR])
def test_an_enhanced_image_opens_with_its_frames_geometry(sop_class, tmp_path):
    """Frames stored out of position order, an oblique orientation, a shared pixel spacing and a
    per-frame rescale (CT): slice k is the frame k-th along the normal, the spacing is the pixel
    measures' and the positions' step, every voxel centre of the box lies where the frames'
    positions put it, and the volume is the one the same slices give as a classic series."""
    data, positions = oblique_data()
    slope, intercept = (2.0, -1024.0) if sop_class == ENHANCED_CT else (1.0, 0.0)
    path = write_enhanced(tmp_path / "enh" / "IM1", data, positions, ORIENTATION, (0.7, 0.9),
                          sop_class, slope, intercept, order=[3, 0, 5, 1, 4, 2])
    classic = write_classic(tmp_path / "classic", data, positions, slope, intercept)
    v = load(path)
    assert v.dims == (7, 5, 6) and v.dicom_series.kind == "enhanced multi-frame"
    assert v.spacing == pytest.approx((0.7, 0.9, GAP))
    values = data.astype(np.float64) * slope + intercept
    assert (v.raw_min, v.raw_max) == pytest.approx((values.min(), values.max()))
    lo, hi = v.value_range
    np.testing.assert_allclose(v.data, (values - lo) / (hi - lo), atol=1e-6)
    # the world box against the positions: voxel (i, j, k) at p0 + D (i sx, j sy, k sz) in LPS
    d = v.direction
    np.testing.assert_allclose(d[:, 0], ORIENTATION[:3], atol=1e-9)
    np.testing.assert_allclose(d[:, 1], ORIENTATION[3:], atol=1e-9)
    for k, position in enumerate(positions):
        np.testing.assert_allclose(positions[0] + d @ (np.array([0, 0, k]) * v.spacing),
                                   position, atol=1e-9)
    corner = positions[0] + d @ ((np.array(v.dims) - 1) * v.spacing)
    np.testing.assert_allclose(corner, positions[-1] + d[:, 0] * 6 * 0.7 + d[:, 1] * 4 * 0.9,
                               atol=1e-9)
    extent = np.array(v.dims) * np.array(v.spacing)
    np.testing.assert_allclose(np.array(v.half_extent) / max(v.half_extent), extent / extent.max())
    for orientation in ("data", "patient"):
        a, b = load(path, orientation=orientation), load(classic, orientation=orientation)
        assert a.dims == b.dims and a.spacing == pytest.approx(b.spacing)
        np.testing.assert_allclose(a.half_extent, b.half_extent)
        np.testing.assert_allclose(a.direction, b.direction)
        np.testing.assert_array_equal(a.data, b.data)


def test_enhanced_frames_with_per_frame_orientation_and_the_file_alone(tmp_path, capsys):
    """The orientation in each frame's group instead of the shared one; the file given alone (as
    scanners export it, without a suffix) opens as its folder does, and `series` lists it."""
    data, positions = oblique_data()
    path = write_enhanced(tmp_path / "enh" / "IM1", data, positions, ORIENTATION, (0.7, 0.9),
                          per_frame_orientation=True)
    a, b = load(path), load(path.parent)
    assert a.dims == b.dims == (7, 5, 6)
    np.testing.assert_array_equal(a.data, b.data)
    assert main(["series", str(path)]) == 0
    assert "CT, 7 x 5 x 6 (enhanced multi-frame)" in capsys.readouterr().out


def test_multiframe_refusals_say_why(tmp_path):
    """Frames at one position (two stacks, or time points, in one file) and a multi-frame image
    that places no frame (a cine loop) are listed with the reason, and refused plainly; a single
    one-slice file still asks for its folder."""
    data, positions = oblique_data()
    twice = write_enhanced(tmp_path / "twice" / "IM1", np.concatenate([data, data]),
                           positions + positions, ORIENTATION, (0.7, 0.9))
    with pytest.raises(VolumeError, match=r"IM1 frame \d+ and IM1 frame \d+ lie at the same "
                                          r"position .*several stacks or time points"):
        load(twice.parent)
    cine = pydicom.dcmread(twice)
    del cine.PerFrameFunctionalGroupsSequence, cine.SharedFunctionalGroupsSequence
    (tmp_path / "cine").mkdir()
    cine.save_as(tmp_path / "cine" / "loop.dcm")
    listing = list_series(tmp_path / "cine")
    assert "places none of them" in listing.series[0].problem
    with pytest.raises(VolumeError, match="cine loop"):
        load(tmp_path / "cine" / "loop.dcm")
    one = ct_slice(tmp_path / "one" / "slice.dcm", data[0], 0.0, generate_uid())
    with pytest.raises(VolumeError, match="a single DICOM file of one slice; give the folder"):
        load(one)
