"""radiance-probes from Python: volume rendering with global illumination from radiance probes,
and the reference path tracer, on NumPy arrays, volume files, DICOM folders and scene files.

    import numpy as np
    import radiance_probes as rp

    image = rp.render(np.random.rand(64, 64, 64))          # linear RGB, (512, 512, 3)
    image.save("volume.png")

    with rp.Renderer("ct_folder/", window="soft_tissue", orientation="patient") as r:
        r.orbit(30, 15)
        first = r.render()                                 # bakes the probes once
        r.orbit(60, 15)
        second = r.render()                                # the same probes, a new camera

`render`, `Renderer` and `view` take any scene key (docs/scene-format.md) as a keyword. Each makes
and releases its own headless GL context. In Jupyter an Image shows inline and
`Renderer.widget()` orbits the camera with sliders (where ipywidgets is installed).
"""
from app.dicom import DicomSeries, list_series
from app.render.settings import RenderSettings
from app.scene import Scene, SceneError
from app.scene_types import VolumeError

from ._api import DEFAULT_SPP, METHODS, Renderer, render, view
from ._image import Image

__all__ = ["DEFAULT_SPP", "METHODS", "DicomSeries", "Image", "RenderSettings", "Renderer", "Scene",
           "SceneError", "VolumeError", "dicom_series", "render", "view"]


def dicom_series(path) -> list[DicomSeries]:
    """The series of a DICOM folder tree or DICOMDIR: number, uid, description, modality, size
    (columns x rows x slices) and, where one does not make a volume, why (`problem`)."""
    return list(list_series(path).series)
