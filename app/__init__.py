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
# The public names load on first use (PEP 562), so that importing a submodule (the command line,
# a test) does not load the whole facade first.
_PUBLIC = {
    "DicomSeries": "io.dicom", "RenderSettings": "rendering.settings", "Scene": "io.scene_file",
    "SceneError": "io.scene_file", "VolumeError": "scene.types", "DEFAULT_SPP": "api.render",
    "METHODS": "api.render", "Renderer": "api.render", "render": "api.render", "view": "api.render",
    "Image": "api.image",
}
__all__ = sorted([*_PUBLIC, "dicom_series"])


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'radiance_probes' has no attribute {name!r}")
    import importlib
    value = getattr(importlib.import_module(f"{__name__}.{_PUBLIC[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted([*globals(), *_PUBLIC])


def dicom_series(path) -> list:
    """The series of a DICOM folder tree or DICOMDIR: number, uid, description, modality, size
    (columns x rows x slices) and, where one does not make a volume, why (`problem`)."""
    from radiance_probes.io.dicom import list_series
    return list(list_series(path).series)
