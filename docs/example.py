"""An example of the Python API (radiance_probes): a NumPy volume rendered with the probes and
with the path tracer, a turntable whose probes are baked once, and a CT-like series read from a
DICOM folder. The tests run it on llvmpipe (tests/test_docs.py); on a GPU raise SIZE.

    .venv/bin/python docs/example.py [OUT_FOLDER]      # writes PNGs there (default: example_out)
"""
import sys
import time
from pathlib import Path

import numpy as np

import radiance_probes as rp

SIZE = 96                                   # image side in pixels
out = Path(sys.argv[1] if len(sys.argv) > 1 else "example_out")
out.mkdir(parents=True, exist_ok=True)

# A volume: a soft, lumpy ball in a noisy background, 40 slices of 48 x 56 voxels, the slices
# twice as far apart as the pixels.
z, y, x = np.meshgrid(np.linspace(-1, 1, 40), np.linspace(-1, 1, 48), np.linspace(-1, 1, 56),
                      indexing="ij")
rng = np.random.default_rng(0)
ball = np.exp(-4 * (x * x + y * y + z * z)) * (1 + 0.3 * np.sin(9 * x) * np.cos(7 * y))
volume = (1000 * ball + rng.normal(0, 20, ball.shape)).astype(np.int16)

# 1. One image: the defaults window the values and frame the box.
image = rp.render(volume, spacing=(1, 1, 2), width=SIZE, height=SIZE, colormap="inferno")
image.save(out / "ball.png")
print(f"{image!r}; {image.notes[0]}")

# 2. A renderer that keeps its probes: a turntable of six frames, one bake.
start = time.perf_counter()
with rp.Renderer(volume, spacing=(1, 1, 2), width=SIZE, height=SIZE, colormap="inferno",
                 anisotropy=0.5, light={"direction": [0.2, 1.0, -0.4]}) as r:
    for k, azimuth in enumerate(range(0, 360, 60)):
        r.orbit(azimuth, 25)
        r.render(spp=2).save(out / f"turn_{k}.png")
    print(f"turntable: 6 frames, {r.bakes} bake, {time.perf_counter() - start:.1f} s on {r.device}")
    # the same view with the reference path tracer, and the probes' error against it
    reference = r.render("pt", spp=16)
    probes = r.render("raymarch", spp=4)
    error = np.sqrt(np.mean((probes.linear - reference.linear) ** 2) / np.mean(reference.linear ** 2))
    print(f"raymarched probes against a 16-spp path trace: {100 * error:.1f}% (the path "
          "tracer's own noise included)")

# 3. DICOM: a series written with pydicom, read back as a scanner folder.
try:
    import pydicom
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid
except ImportError:
    sys.exit(0)
folder, series = out / "ct", generate_uid()
for k, plane in enumerate(volume):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID = CTImageStorage, generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(str(folder / f"IM{k:03d}"), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.SeriesInstanceUID, ds.SeriesDescription = "CT", series, "example"
    ds.ImagePositionPatient, ds.ImageOrientationPatient = [0.0, 0.0, 2.0 * k], [1, 0, 0, 0, 1, 0]
    ds.PixelSpacing, ds.RescaleSlope, ds.RescaleIntercept = [1.0, 1.0], 1, -1024
    ds.Rows, ds.Columns = plane.shape
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit, ds.PixelRepresentation = 15, 1
    ds.PixelData = np.ascontiguousarray(plane + 1024).astype(np.int16).tobytes()
    folder.mkdir(parents=True, exist_ok=True)
    ds.save_as(str(folder / f"IM{k:03d}"), enforce_file_format=True)
for s in rp.dicom_series(folder):
    print(f"series {s.number}: {s.description} {s.modality} {s.columns} x {s.rows} x {s.slices}")
rp.render(folder, width=SIZE, height=SIZE, window=(400, 1200), orientation="patient",
          colormap="grey").save(out / "ct.png")
print(f"wrote {len(list(out.glob('*.png')))} images to {out}")
