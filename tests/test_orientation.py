"""`"orientation": "patient"` (app/io/orientation.py): NIfTI (sform/qform, RAS), DICOM (LPS) and NRRD
(space directions) volumes are permuted and flipped, never resampled, so that world +x is the
patient's left, +y superior and +z anterior. Known answer: the octant of a volume on the patient's
left, superior and anterior side lands in world's +x, +y, +z octant, whatever the acquisition
plane and storage order; "data" (the default) keeps the stored mapping; an oblique scan is shown
on its nearest axes with a note naming the angle; a file without orientation says so."""
from __future__ import annotations

import math

import nibabel as nib
import nrrd
import numpy as np
import pytest

from radiance_probes.io.orientation import PATIENT_WORLD, residual_degrees, to_patient
from radiance_probes.io.scene_file import VolumeSpec, parse_scene
from radiance_probes.io.load import load_volume
from test_volume_formats import ct_slice

DIMS = (6, 5, 4)   # x, y, z voxel counts: every axis a different length
LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0])
LEFT, SUPERIOR, ANTERIOR = PATIENT_WORLD.T   # in LPS


def rotation(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    t = math.radians(degrees)
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k


# Acquisitions as the axes' LPS directions (columns x, y, z): DICOM's axial, sagittal and coronal
# (z = row x column, as slices stack along the normal), and a left-handed one (NIfTI, NRRD only).
AXIAL = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], float).T
SAGITTAL = np.array([[0, 1, 0], [0, 0, -1], [-1, 0, 0]], float).T
CORONAL = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float).T
MIRRORED = np.array([[-1, 0, 0], [0, 1, 0], [0, 0, 1]], float).T   # radiological storage


def octant_volume(direction: np.ndarray) -> np.ndarray:
    """data[z, y, x]: 100 where the voxel lies on the patient's left, superior and anterior side of
    the centre, 1 elsewhere (positions from the axes' directions)."""
    nx, ny, nz = DIMS
    z, y, x = np.meshgrid(np.arange(nz) - (nz - 1) / 2, np.arange(ny) - (ny - 1) / 2,
                          np.arange(nx) - (nx - 1) / 2, indexing="ij")
    lps = np.einsum("ab,bzyx->azyx", direction, np.stack([x, y, z]))
    inside = ((np.einsum("a,azyx->zyx", LEFT, lps) > 0) & (np.einsum("a,azyx->zyx", SUPERIOR, lps) > 0)
              & (np.einsum("a,azyx->zyx", ANTERIOR, lps) > 0))
    return np.where(inside, 100, 1).astype(np.int16)


def assert_upright(v):
    """The marked octant is world's +x, +y, +z one (data[z, y, x] high in every index)."""
    marked = v.data > 0.5
    nz, ny, nx = v.data.shape
    z, y, x = np.nonzero(marked)
    assert marked.any()
    # the positive half of an axis of n voxels: its last n // 2 (the centre voxel of an odd one is
    # on neither side)
    assert (x >= nx - nx // 2).all() and (y >= ny - ny // 2).all() and (z >= nz - nz // 2).all()
    assert marked.sum() == (nx // 2) * (ny // 2) * (nz // 2)


def write_dicom(folder, direction):
    data = octant_volume(direction)
    iop = list(direction[:, 0]) + list(direction[:, 1])
    for k, plane in enumerate(data):
        ct_slice(folder / f"IM{(k * 7) % 11:03d}", plane, 0.0, "1.2.3.90", orientation=iop,
                 spacing=(1.0, 1.0), position=direction[:, 2] * 2.0 * k)
    return folder


def write_nifti(path, direction, qform_only=False):
    affine = np.eye(4)
    affine[:3, :3] = LPS_TO_RAS @ direction
    img = nib.Nifti1Image(np.ascontiguousarray(octant_volume(direction).transpose(2, 1, 0)), None)
    if qform_only:
        img.set_qform(affine, code=1)
        img.set_sform(None, code=0)
    else:
        img.set_sform(affine, code=2)
    nib.save(img, str(path))
    return path


def write_nrrd(path, direction, space="left-posterior-superior"):
    signs = np.eye(3) if space.startswith("left-posterior") else LPS_TO_RAS
    nrrd.write(str(path), octant_volume(direction),
               {"space": space, "space directions": (signs @ direction).T.tolist()},
               index_order="C")
    return path


def patient(path, **kw):
    return load_volume(VolumeSpec(path=str(path), builtin=None, orientation="patient", **kw))


@pytest.mark.parametrize("plane", ["axial", "sagittal", "coronal"])
def test_dicom_acquisitions_come_out_upright(tmp_path, plane):
    direction = {"axial": AXIAL, "sagittal": SAGITTAL, "coronal": CORONAL}[plane]
    v = patient(write_dicom(tmp_path / plane, direction))
    assert_upright(v)
    assert v.orientation == "patient" and v.oblique_degrees == 0.0 and not v.notes
    np.testing.assert_allclose(v.direction, PATIENT_WORLD, atol=1e-12)


@pytest.mark.parametrize("direction", [AXIAL, SAGITTAL, CORONAL, MIRRORED],
                         ids=["axial", "sagittal", "coronal", "mirrored"])
def test_nifti_and_nrrd_come_out_upright(tmp_path, direction):
    assert_upright(patient(write_nifti(tmp_path / "s.nii.gz", direction)))
    assert_upright(patient(write_nifti(tmp_path / "q.nii", direction, qform_only=True)))
    assert_upright(patient(write_nrrd(tmp_path / "lps.nrrd", direction)))
    assert_upright(patient(write_nrrd(tmp_path / "ras.nrrd", direction, "right-anterior-superior")))


def test_data_orientation_keeps_the_stored_mapping(tmp_path):
    """The default places data[z, y, x] on world z, y, x as stored, whatever the header says."""
    stored = octant_volume(SAGITTAL)
    for path in (write_nifti(tmp_path / "a.nii", SAGITTAL), write_nrrd(tmp_path / "a.nrrd", SAGITTAL),
                 write_dicom(tmp_path / "d", SAGITTAL)):
        v = load_volume(parse_scene({"volume": {"path": str(path)}}).volume)
        assert v.orientation == "data" and v.data.shape == stored.shape
        np.testing.assert_array_equal(v.data > 0.5, stored > 50)
    top = parse_scene({"volume": {"path": str(tmp_path / "a.nii")}, "orientation": "patient"})
    assert load_volume(top.volume).orientation == "patient"   # SPEC.md's top-level spelling


def test_spacing_follows_the_axes(tmp_path):
    """A scene's spacing is along the file's axes and moves with them."""
    v = patient(write_nrrd(tmp_path / "s.nrrd", SAGITTAL), spacing=(1.0, 2.0, 3.0))
    # sagittal: file x -> anterior-posterior (world z), y -> superior (world y), z -> left (world x)
    assert v.spacing == (3.0, 2.0, 1.0) and v.dims == (DIMS[2], DIMS[1], DIMS[0])


def test_an_oblique_scan_is_named_and_kept_as_metadata(tmp_path):
    tilted = rotation(SUPERIOR, 20.0) @ AXIAL        # axial, turned 20 degrees about the body axis
    v = patient(write_nifti(tmp_path / "o.nii", tilted))
    assert v.oblique_degrees == pytest.approx(20.0, abs=1e-6)
    assert len(v.notes) == 1 and "20.0 degrees" in v.notes[0] and "not resampled" in v.notes[0]
    assert residual_degrees(v.direction) == pytest.approx(20.0, abs=1e-6)
    assert v.data.shape == (DIMS[1], DIMS[2], DIMS[0])      # permuted as axial, not resampled


def test_a_file_without_orientation_says_so(tmp_path):
    np.save(tmp_path / "a.npy", octant_volume(AXIAL))
    v = patient(tmp_path / "a.npy")
    assert v.orientation == "data" and "says nothing of the patient's orientation" in v.notes[0]
    img = nib.Nifti1Image(octant_volume(AXIAL).transpose(2, 1, 0).copy(), None)
    img.set_sform(None, code=0)
    img.set_qform(None, code=0)
    nib.save(img, str(tmp_path / "n.nii"))
    assert patient(tmp_path / "n.nii").orientation == "data"


def test_to_patient_permutes_without_resampling():
    data = np.arange(4 * 5 * 6).reshape(4, 5, 6)
    placed = to_patient(data, (1.0, 2.0, 3.0), AXIAL)
    assert placed.axes == (0, 2, 1) and placed.flips == (False, False, True)
    assert sorted(placed.data.ravel()) == sorted(data.ravel())     # the same voxels, moved
    np.testing.assert_array_equal(placed.data, np.flip(data.transpose(1, 0, 2), axis=0))
    assert placed.spacing == (1.0, 3.0, 2.0)
