"""Viewer screenshots of the volume formats people bring (issue 13):
  screenshots/viewer_dicom_ct.png  the chest CT of ../shared/datasets (8-bit NRRD) written as a DICOM
                                   series by pydicom, slices under shuffled names, RescaleSlope 8 and
                                   RescaleIntercept -1024 so that it arrives in Hounsfield-like units,
                                   opened as a folder with the soft-tissue window;
  screenshots/viewer_nifti_mri.png nibabel's own example anatomical MRI (anatomical.nii, 33x41x25 at
                                   2 mm, shipped with nibabel), windowed to its brightest tissue.
Run: .venv/bin/python scripts/format_screenshots.py   (llvmpipe: about a minute each)"""
from __future__ import annotations

import json
import random
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CHEST = ROOT.parent / "shared" / "datasets" / "lidc2_chest_ct_256x256x133.nrrd"


def write_ct_series(folder: Path) -> None:
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
        ds.SeriesDescription = "LIDC chest CT (8-bit dataset, rescaled)"
        ds.ImagePositionPatient = [0.0, 0.0, float(k * spacing[2])]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [float(spacing[1]), float(spacing[0])]
        ds.SliceThickness = float(spacing[2])
        ds.RescaleSlope, ds.RescaleIntercept = 8.0, -1024.0
        sl = np.ascontiguousarray(stored[:, :, k].T)   # rows = y, columns = x
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


def main() -> int:
    import nibabel
    out = ROOT / "screenshots"
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        if CHEST.is_file():
            write_ct_series(tmp / "ct_series")
            shoot({"volume": {"path": str(tmp / "ct_series"), "window": "soft_tissue"},
                   "transfer_function": {"colormap": "coolwarm"}, "density_scale": 40.0,
                   "camera": {"width": 256, "height": 256}},
                  out / "viewer_dicom_ct.png", tmp, "ct")
        else:
            print(f"{CHEST} is absent: no DICOM screenshot", file=sys.stderr)
        mri = Path(nibabel.__file__).parent / "tests" / "data" / "anatomical.nii"
        # its brightest tissue (a window over the top 20% of its voxels): the rest is made clear
        shoot({"volume": {"path": str(mri), "window": {"level": 12000, "width": 4000}},
               "transfer_function": {"colormap": "viridis"}, "density_scale": 20.0,
               "camera": {"width": 256, "height": 256}},
              out / "viewer_nifti_mri.png", tmp, "mri")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
