"""The controls that more than one front end offers, each once: its label, range and scale, so the
viewer's panels (app/viewer/panels.py, tf_editor.py) and the napari plugin (app/napari_plugin/)
show the same names over the same ranges. Imports nothing of the package but the scene's types.
"""
from __future__ import annotations

from dataclasses import dataclass

from radiance_probes.scene.types import MAX_GRADIENT_FACTOR, MIN_ROUGHNESS


@dataclass(frozen=True)
class Control:
    label: str              # what the panel calls it
    lo: float
    hi: float
    log: bool = False       # a logarithmic slider
    integer: bool = False
    unit: str = ""          # shown after the value ("deg")


MAX_SAMPLES = Control("Max samples", 1, 65536, log=True, integer=True)
RENDER_SCALE = Control("Render scale", 0.125, 1.0)
EXPOSURE = Control("Exposure", 0.05, 20.0, log=True)
PROBES_PER_AXIS = Control("Probes per axis", 1, 64, integer=True)
WALKS_PER_PROBE = Control("Walks per probe", 1, 16384, log=True, integer=True)
SUN_AZIMUTH = Control("Sun azimuth", -180.0, 180.0, unit="deg")
SUN_ELEVATION = Control("Sun elevation", -89.0, 89.0, unit="deg")
SUN_STRENGTH = Control("Sun strength", 0.0, 100.0, log=True)
ENVIRONMENT_STRENGTH = Control("Environment strength", 0.0, 10.0, log=True)
SURFACE_K = Control("Surface k", 0.0, min(100.0, MAX_GRADIENT_FACTOR), log=True)
ROUGHNESS = Control("Roughness", MIN_ROUGHNESS, 1.0)
DENOISE = "Denoise"          # a checkbox
METHOD = "Method"            # a choice of methods.VIEWER_METHODS
CT_PRESET = "CT preset"      # a choice of "(none)" and clinical_presets.CLINICAL_PRESETS

CONTROLS = (MAX_SAMPLES, RENDER_SCALE, EXPOSURE, PROBES_PER_AXIS, WALKS_PER_PROBE, SUN_AZIMUTH,
            SUN_ELEVATION, SUN_STRENGTH, ENVIRONMENT_STRENGTH, SURFACE_K, ROUGHNESS)
