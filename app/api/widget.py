"""A small orbit widget for Jupyter: the rendered image with azimuth, elevation and distance
sliders (ipywidgets, an optional dependency: imported only when asked for)."""
from __future__ import annotations

import math

import numpy as np


def _ipywidgets():
    try:
        import ipywidgets
    except ImportError:
        raise ImportError("the orbit widget needs ipywidgets: pip install ipywidgets (the images "
                          "themselves show inline without it)") from None
    return ipywidgets


def camera_angles(camera) -> tuple[float, float, float]:
    """Azimuth (degrees from +z towards +x), elevation and distance of the eye about the target."""
    offset = np.asarray(camera.eye, np.float64) - np.asarray(camera.target, np.float64)
    distance = float(np.linalg.norm(offset))
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, offset[1] / distance))))
    azimuth = math.degrees(math.atan2(offset[0], offset[2]))
    return azimuth, elevation, distance


def orbit_widget(renderer, method: str = "raymarch", spp: int | None = None,
                 exposure: float = 1.0):
    widgets = _ipywidgets()
    azimuth, elevation, distance = camera_angles(renderer.scene.camera)
    picture = widgets.Image(value=renderer.render(method, spp, exposure=exposure).png_bytes(),
                            format="png")
    sliders = [widgets.FloatSlider(value=round(azimuth), min=-180, max=180, step=1,
                                   description="azimuth", continuous_update=False),
               widgets.FloatSlider(value=round(elevation), min=-89, max=89, step=1,
                                   description="elevation", continuous_update=False),
               widgets.FloatSlider(value=round(distance, 2), min=0.3, max=10.0, step=0.05,
                                   description="distance", continuous_update=False)]

    def redraw(_change=None) -> None:
        renderer.orbit(*(s.value for s in sliders))
        picture.value = renderer.render(method, spp, exposure=exposure).png_bytes()

    for s in sliders:
        s.observe(redraw, names="value")
    box = widgets.VBox([picture, widgets.HBox(sliders)])
    box.redraw = redraw
    return box
