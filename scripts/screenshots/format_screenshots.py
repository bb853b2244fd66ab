"""Viewer screenshots of the volume formats people bring (issues 13 and 31):
  screenshots/viewer_dicom_ct.png  the chest CT of ../shared/datasets (8-bit NRRD) written as a DICOM
                                   series by pydicom, slices under shuffled names, RescaleSlope 8 and
                                   RescaleIntercept -1024 so that it arrives in Hounsfield-like units,
                                   opened as a folder with the soft-tissue window;
  screenshots/viewer_nifti_mri.png nibabel's own example anatomical MRI (anatomical.nii, 33x41x25 at
                                   2 mm, shipped with nibabel), windowed to its brightest tissue;
  screenshots/viewer_dicom_study.png the same chest CT in a study folder as a scanner exports it
                                   (the CT series, a one-slice scout and a three-plane localiser in
                                   subfolders, a README.TXT), opened as the README says:
                                   `view FOLDER --data-window soft_tissue --orientation patient`
                                   (raymarched), the Data panel open on the series list;
  screenshots/viewer_slices.png    the same chest CT series (its rows flipped to run posterior, as
                                   its anatomy says) with the slice view (issue 44): axial, coronal
                                   and sagittal slices beside the 3D view in a wide window (-1000 to
                                   800 HU: the 8-bit data's tissue is no real HU), a crop box (the
                                   chest's front cut away) and a clip plane drawn on them, a click
                                   in the axial slice having moved the slices and the orbit's
                                   centre, the mouse over the coronal slice reading its value in HU.
Run: .venv/bin/python scripts/screenshots/format_screenshots.py [NAME ...]   (llvmpipe: about a minute each;
NAME, e.g. viewer_slices, makes only those)"""
from __future__ import annotations

import json
import random
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CHEST = ROOT.parent / "shared" / "datasets" / "lidc2_chest_ct_256x256x133.nrrd"


def write_slice(path: Path, pixels: np.ndarray, series: str, description: str, position, orientation,
                spacing, number: int) -> None:
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    path.parent.mkdir(parents=True, exist_ok=True)
    ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.SeriesInstanceUID, ds.StudyInstanceUID = "CT", series, "1.2.3"
    ds.SeriesDescription, ds.SeriesNumber = description, number
    ds.ImagePositionPatient = [float(v) for v in position]
    ds.ImageOrientationPatient = list(orientation)
    ds.PixelSpacing = [float(spacing[1]), float(spacing[0])]
    ds.SliceThickness = 2.5
    ds.RescaleSlope, ds.RescaleIntercept = 8.0, -1024.0
    ds.Rows, ds.Columns = pixels.shape
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit, ds.PixelRepresentation = 15, 0
    ds.PixelData = np.ascontiguousarray(pixels, np.uint16).tobytes()
    ds.save_as(str(path), enforce_file_format=True)


def write_study(root: Path) -> None:
    """The chest CT as series 2 of a study, with a scout (series 1, one coronal slice: the CT's
    mean over y) and a three-plane localiser (series 3) in their own subfolders, and a text file."""
    from pydicom.uid import generate_uid
    import nrrd
    write_ct_series(root / "SE000002")
    data, header = nrrd.read(str(CHEST))            # stored x, y, z; LPS, axial
    spacing = np.abs(np.diag(header["space directions"]))
    scout = data.astype(np.float32).mean(axis=1)     # x, z: coronal, rows along -z
    write_slice(root / "SE000001" / "IM00001", scout[:, ::-1].T, generate_uid(), "Scout", (0, 0, 0),
                (1, 0, 0, 0, 0, -1), (spacing[0], spacing[2]), 1)
    localiser = generate_uid()
    for k, iop in enumerate(((1, 0, 0, 0, 1, 0), (0, 1, 0, 0, 0, -1), (1, 0, 0, 0, 0, -1))):
        write_slice(root / "SE000003" / f"IM{k:05d}", data[:64, :64, 60].T, localiser,
                    "3-plane localiser", (0, 0, 10 * k), iop, spacing, 3)
    (root / "README.TXT").write_text("exported by a scanner\n")


def write_ct_series(folder: Path, rows_anterior: bool = False) -> None:
    """The chest CT as a DICOM series. Its NRRD header says LPS, but its rows run anterior (the
    table and the spine lie at low y): `rows_anterior` flips them so that the series' axial
    orientation holds (anterior up in an axial slice); without it the series is written as the
    header says, as the screenshots made before the slice view were."""
    import nrrd
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid
    data, header = nrrd.read(str(CHEST))            # stored x, y, z
    spacing = np.abs(np.diag(header["space directions"]))
    stored = data.astype(np.uint16)   # HU = 8 * value - 1024 (the slope and intercept below)
    series = generate_uid()
    names = random.Random(1).sample(range(10000), data.shape[2])
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(data.shape[2]):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        path = folder / f"IM{names[k]:05d}"
        ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
        ds.Modality, ds.SeriesInstanceUID, ds.StudyInstanceUID = "CT", series, "1.2.3"
        ds.SeriesDescription, ds.SeriesNumber = "LIDC chest CT (8-bit dataset, rescaled)", 2
        ds.ImagePositionPatient = [0.0, 0.0, float(k * spacing[2])]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [float(spacing[1]), float(spacing[0])]
        ds.SliceThickness = float(spacing[2])
        ds.RescaleSlope, ds.RescaleIntercept = 8.0, -1024.0
        sl = np.ascontiguousarray(stored[:, ::-1 if rows_anterior else 1, k].T)   # rows y, columns x
        ds.Rows, ds.Columns = sl.shape
        ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
        ds.BitsAllocated = ds.BitsStored = 16
        ds.HighBit, ds.PixelRepresentation = 15, 0
        ds.PixelData = sl.tobytes()
        ds.save_as(str(path), enforce_file_format=True)


def shoot(scene: dict, out: Path, tmp: Path, name: str) -> None:
    (tmp / f"{name}.json").write_text(json.dumps(scene))
    cmd = [str(ROOT / ".venv/bin/radiance-probes"), "view", str(tmp / f"{name}.json"),
           "--screenshot", str(out), "--frames", "48", "--window", "1280x800"]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def shoot_slices(series: Path, out: Path, tmp: Path) -> None:
    """viewer_slices.png: the CT series in patient orientation with its three slices, a crop box
    and a clip plane; a click in the axial slice, then the mouse resting on the coronal one."""
    script = tmp / "slices.json"
    script.write_text(json.dumps([
        {"click": "Slices"}, {"frames": 2},
        {"click": {"slice": "y", "at": [0.58, 0.45]}}, {"until": "done"},
        {"move": {"slice": "z", "at": [0.56, 0.55]}}, {"frames": 2},
        {"screenshot": str(out / "viewer_slices.png")}, {"close": True}]))
    cmd = [str(ROOT / ".venv/bin/radiance-probes"), "view", str(series), "--data-window=-100,1800",
           "--orientation", "patient", "--method", "raymarch", "--slices",
           "--crop-voxels", "20", "0", "0", "236", "133", "200", "--clip-plane", "-1", "0", "0.6",
           "0.25", "--spp", "4", "--script", str(script), "--window", "1280x800"]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def main(names: list[str]) -> int:
    import nibabel
    out = ROOT / "screenshots"
    wanted = lambda name: not names or name in names   # noqa: E731
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        if CHEST.is_file() and wanted("viewer_slices"):
            write_ct_series(tmp / "ct_upright", rows_anterior=True)
            shoot_slices(tmp / "ct_upright", out, tmp)
        if CHEST.is_file() and wanted("viewer_dicom_ct"):
            write_ct_series(tmp / "ct_series")
            shoot({"volume": {"path": str(tmp / "ct_series"), "window": "soft_tissue"},
                   "transfer_function": {"colormap": "coolwarm"}, "density_scale": 40.0,
                   "camera": {"width": 256, "height": 256}},
                  out / "viewer_dicom_ct.png", tmp, "ct")
        if CHEST.is_file() and wanted("viewer_dicom_study"):
            write_study(tmp / "study")
            script = tmp / "data_panel.json"
            script.write_text(json.dumps([{"click": "Data"}, {"frames": 12},
                                          {"screenshot": str(out / "viewer_dicom_study.png")},
                                          {"close": True}]))
            cmd = [str(ROOT / ".venv/bin/radiance-probes"), "view", str(tmp / "study"),
                   "--data-window", "soft_tissue", "--orientation", "patient", "--method",
                   "raymarch", "--script", str(script), "--window", "1280x800"]
            print(" ".join(cmd), flush=True)
            subprocess.run(cmd, check=True)
        if not CHEST.is_file():
            print(f"{CHEST} is absent: no DICOM screenshots", file=sys.stderr)
        if not wanted("viewer_nifti_mri"):
            return 0
        mri = Path(nibabel.__file__).parent / "tests" / "data" / "anatomical.nii"
        # its brightest tissue (a window over the top 20% of its voxels): the rest is made clear
        shoot({"volume": {"path": str(mri), "window": {"level": 12000, "width": 4000}},
               "transfer_function": {"colormap": "viridis"}, "density_scale": 20.0,
               "camera": {"width": 256, "height": 256}},
              out / "viewer_nifti_mri.png", tmp, "mri")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
