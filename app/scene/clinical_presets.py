"""Clinical transfer-function presets for CT in Hounsfield units (HU): bone, skin, muscle, vessels
with contrast, lung, coloured like an anatomy atlas; and the check that a window or preset meant
for Hounsfield units meets data that is in them.

A preset is a piecewise-linear curve over HU: control points (hu, r, g, b, opacity), constant
beyond the first and last, plus the surface its tissue shows (the scene's `surface`: gradient
factor k, roughness, specular colour; docs/scene-format.md) and the HU window it is drawn for.
`expand` maps it onto the normalised densities of a volume's window (the data values mapped to
densities 0 and 1): the control points inside the window keep their HU place, and the curve's
values at the window's ends are added there, so the table is the preset's curve exactly, cut to
the window.

Which data is in Hounsfield units (`hounsfield_problem`): a DICOM series of modality CT is (its
RescaleSlope/Intercept applied by app/io/dicom.py); 8-bit data is not (HU span -1024 to 3071, 8 bits
hold 256 values); data with no value below 0 is not (every CT in HU holds air at about -1000, and
unsigned stored values with no rescale applied start at 0). Anything else is taken as HU.
"""
from __future__ import annotations

from dataclasses import dataclass

from radiance_probes.scene.types import WINDOW_PRESETS, SceneError, VolumeError


@dataclass(frozen=True)
class ClinicalPreset:
    description: str
    window: tuple[float, float]     # the HU range it is drawn for (its default value range)
    points: tuple[tuple[float, float, float, float, float], ...]   # (hu, r, g, b, opacity)
    gradient_factor: float          # the surface's k (scene surface.gradient_factor)
    roughness: float                # GGX alpha of its specular lobe
    specular: tuple[float, float, float]


BONE = (0.93, 0.87, 0.74)
SKIN = (0.94, 0.72, 0.60)
MUSCLE = (0.72, 0.24, 0.20)
FAT = (0.93, 0.82, 0.45)
BLOOD = (0.80, 0.08, 0.08)
LUNG = (0.93, 0.62, 0.62)

# Hounsfield units of the tissues (approximate, adult CT): air -1000, lung -900 to -500, fat -100
# to -50, water 0, soft tissue and muscle 20 to 60, blood 40 (with iodine contrast 150 to 500),
# cancellous bone 300 to 800, cortical bone 1000 and more.
CLINICAL_PRESETS: dict[str, ClinicalPreset] = {
    "ct_bone": ClinicalPreset(
        "bone alone, ivory: soft tissue transparent, bone from 150 HU opaque at 400",
        (-200.0, 1800.0),
        ((150.0, *BONE, 0.0), (400.0, *BONE, 0.8), (1000.0, 1.0, 0.97, 0.90, 1.0)),
        gradient_factor=0.05, roughness=0.45, specular=(0.08, 0.08, 0.08)),
    "ct_skin": ClinicalPreset(
        "the body's outer surface in skin tone: air transparent, the skin's edge from -500 HU",
        (-1000.0, 1000.0),
        ((-500.0, *SKIN, 0.0), (-200.0, *SKIN, 0.9), (200.0, *SKIN, 1.0),
         (400.0, *BONE, 1.0)),
        gradient_factor=0.05, roughness=0.55, specular=(0.04, 0.04, 0.04)),
    "ct_muscle": ClinicalPreset(
        "fat faint yellow, muscle and organs red, bone ivory",
        (-200.0, 1200.0),
        ((-150.0, *FAT, 0.0), (-60.0, *FAT, 0.05), (0.0, *MUSCLE, 0.1), (40.0, *MUSCLE, 0.5),
         (120.0, *MUSCLE, 0.5), (250.0, *BONE, 0.9), (800.0, *BONE, 1.0)),
        gradient_factor=0.02, roughness=0.5, specular=(0.05, 0.05, 0.05)),
    "ct_vessels": ClinicalPreset(
        "vessels with iodine contrast red (150 to 450 HU), bone ivory, soft tissue transparent",
        (-100.0, 1500.0),
        ((120.0, *BLOOD, 0.0), (200.0, *BLOOD, 0.8), (400.0, *BLOOD, 0.9),
         (550.0, *BONE, 0.9), (1000.0, *BONE, 1.0)),
        gradient_factor=0.05, roughness=0.3, specular=(0.1, 0.1, 0.1)),
    "ct_lung": ClinicalPreset(
        "lung parenchyma faint pink, airway and vessel walls and soft tissue stronger; air clear",
        (-1000.0, 400.0),
        ((-950.0, *LUNG, 0.0), (-850.0, *LUNG, 0.02), (-500.0, *LUNG, 0.1),
         (-200.0, 0.85, 0.45, 0.42, 0.4), (100.0, *MUSCLE, 0.6), (300.0, *BONE, 1.0)),
        gradient_factor=0.02, roughness=0.6, specular=(0.03, 0.03, 0.03)),
}

# The preset a named CT window opens with (a scene that names the window and no transfer function;
# opening_preset).
WINDOW_CLINICAL = {"bone": "ct_bone", "soft_tissue": "ct_muscle", "lung": "ct_lung",
                   "air": "ct_lung"}
# The preset a CT (DICOM modality CT) opens with where the scene gives no window.
CT_DEFAULT_PRESET = "ct_bone"


def preset(name: str) -> ClinicalPreset:
    try:
        return CLINICAL_PRESETS[name]
    except KeyError:
        raise SceneError(f"unknown clinical preset {name!r} (known: "
                         f"{', '.join(CLINICAL_PRESETS)})") from None


def expand(name: str, domain: tuple[float, float]
           ) -> tuple[tuple[tuple[float, float, float, float], ...],
                      tuple[tuple[float, float], ...]]:
    """The preset as colour points (density, r, g, b) and opacity points (density, opacity) over
    normalised density, for a volume whose `domain` (lo, hi) of data values maps to 0 and 1."""
    import numpy as np
    p = preset(name)
    lo, hi = (float(v) for v in domain)
    if not hi > lo:
        raise SceneError(f"clinical preset {name}: the window needs min < max, got {[lo, hi]}")
    pts = np.asarray(p.points, np.float64)
    hus = pts[:, 0]
    inside = [float(h) for h in hus if lo < h < hi]
    where = [lo, *inside, hi]
    values = np.stack([np.interp(where, hus, pts[:, c]) for c in range(1, 5)], axis=1)
    dens = [(h - lo) / (hi - lo) for h in where]
    dens[0], dens[-1] = 0.0, 1.0
    clip = lambda v: float(min(max(v, 0.0), 1.0))   # noqa: E731
    colors = tuple((clip(d), *(clip(v) for v in row[:3])) for d, row in zip(dens, values))
    opacity = tuple((clip(d), clip(row[3])) for d, row in zip(dens, values))
    return colors, opacity


def is_hounsfield_window(window: tuple[float, float] | None) -> str | None:
    """The name of a named CT window (WINDOW_PRESETS) that `window` (level, width) is, else None."""
    if window is None:
        return None
    for name, w in WINDOW_PRESETS.items():
        if tuple(float(v) for v in window) == w:
            return name
    return None


def is_ct(volume) -> bool:
    """Whether the volume is a DICOM series of modality CT."""
    series = getattr(volume, "dicom_series", None)
    return series is not None and str(getattr(series, "modality", "")).upper() == "CT"


def hounsfield_problem(volume) -> str | None:
    """Why the volume's values are not Hounsfield units, or None where they may be (module
    docstring). `volume`: app.volume.Volume (its raw type and raw extremes)."""
    if is_ct(volume):
        return None
    dtype = str(volume.raw_dtype)
    if dtype in ("uint8", "int8"):
        return (f"its data is 8-bit ({dtype}, at most 256 values), which cannot hold Hounsfield "
                "units (-1024 to 3071)")
    if not volume.raw_min < 0.0:
        return (f"its values run from {volume.raw_min:g} to {volume.raw_max:g}, none below 0: a CT "
                "in Hounsfield units holds air near -1000 (a scanner's stored values with no "
                "RescaleSlope/RescaleIntercept applied, or data of another kind)")
    return None


def check_hounsfield(volume_spec, transfer_preset: str | None, volume) -> None:
    """Raises VolumeError naming the window or preset when a window or clinical preset meant for
    Hounsfield units meets data that is not in them (it would render an opaque or empty box)."""
    window = is_hounsfield_window(volume_spec.window)
    if window is None and transfer_preset is None:
        return
    problem = hounsfield_problem(volume)
    if problem is None:
        return
    what = (f"the CT window {window!r}" if window is not None else
            f"the clinical preset {transfer_preset!r}")
    if window is not None and transfer_preset is not None:
        what = f"the CT window {window!r} and the clinical preset {transfer_preset!r}"
    raise VolumeError(f"{volume.name}: {what} is meant for Hounsfield units, but {problem}. Give "
                      "the window in the data's own units (--data-window LEVEL,WIDTH, "
                      "volume.window {level, width} or volume.value_range) and a transfer "
                      "function that is not a clinical preset; or, for a CT exported without "
                      "its units (8-bit, windowed), the export's mapping to Hounsfield units "
                      "(--set volume.rescale=SLOPE,INTERCEPT)")


def opening_preset(scene, volume) -> str | None:
    """The clinical preset a scene opens with where it gives no transfer function of its own
    (the default's) and its volume is a CT: a DICOM series of modality CT, or a scene whose window
    is a named CT window (Hounsfield units; check_hounsfield has refused data not in them). The
    named window's preset (WINDOW_CLINICAL), else CT_DEFAULT_PRESET; None: not a CT."""
    from radiance_probes.scene.types import TransferFunctionSpec
    if scene.channels or scene.transfer_function != TransferFunctionSpec():
        return None
    window = is_hounsfield_window(scene.volume.window)
    if window is None and not is_ct(volume):
        return None
    return WINDOW_CLINICAL.get(window or "", CT_DEFAULT_PRESET)


def with_preset(scene, name: str, domain: tuple[float, float]):
    """The scene with the clinical preset `name` as its transfer function, placed by `domain`
    (the data values its volume maps to densities 0 and 1), and its surface shading."""
    import dataclasses
    from radiance_probes.scene.types import SurfaceSpec, TransferFunctionSpec
    colors, opacity = expand(name, domain)
    tf = TransferFunctionSpec(colors=colors, opacity=opacity, preset=name,
                              resolution=scene.transfer_function.resolution)
    p = preset(name)
    surface = SurfaceSpec(gradient_factor=p.gradient_factor, roughness=p.roughness,
                          specular=tuple(p.specular))
    return dataclasses.replace(scene, transfer_function=tf, surface=surface)


def opening_scene(scene, volume):
    """The scene a front end opens `volume` with: a CT (opening_preset) with its clinical preset
    placed by the volume's own value range, else `scene` unchanged."""
    name = opening_preset(scene, volume)
    if name is None:
        return scene
    return with_preset(scene, name, volume.value_range)
