"""The benchmark's scenes: the paper's four datasets with its colormaps and views, plus two built-in
scenes that stress what the datasets do not (thick high-albedo media, strong anisotropy)."""
from __future__ import annotations

from ..paths import ASSETS_DIR
from ..scene import Scene, load_scene, parse_scene

DATASET_SCENES = ("fuel", "hydrogen", "foot", "bonsai")

# Optically thick, albedo 0.99: multiple scattering carries most of the light.
THICK = {"volume": {"builtin": "cloud", "size": [96, 96, 96]}, "density_scale": 400.0,
         "albedo": 0.99, "transfer_function": {"colormap": "grey"},
         "light": {"direction": [0.3, 0.9, 0.3], "irradiance": [3.0, 3.0, 3.0]},
         "environment": [0.1, 0.12, 0.16], "max_bounces": 256}
# Strongly forward-scattering (g = 0.8), lit from behind: the phase function shapes the image.
ANISOTROPIC = {"volume": {"builtin": "cloud", "size": [96, 96, 96]}, "density_scale": 120.0,
               "albedo": 0.95, "anisotropy": 0.8,
               "light": {"direction": [-0.3, 0.35, -0.89], "irradiance": [4.0, 4.0, 4.0]},
               "environment": [0.08, 0.08, 0.1]}
# The thick cloud with a grey environment: everything grey, so probes need one channel.
GREY = {**THICK, "environment": [0.12, 0.12, 0.12]}
# An 8^3 cloud: the interact mode's end-to-end test (not in the sweeps).
TINY = {"volume": {"builtin": "cloud", "size": [8, 8, 8]}, "density_scale": 30.0, "albedo": 0.8,
        "max_bounces": 8}
BUILTIN_SCENES = {"thick": THICK, "anisotropic": ANISOTROPIC, "grey": GREY, "tiny": TINY}
ALL_SCENES = (*DATASET_SCENES, "thick", "anisotropic", "grey")


def bench_scene(name: str, width: int, height: int) -> Scene | None:
    """The named scene at the given image size; None when its dataset is absent."""
    if name in BUILTIN_SCENES:
        scene = parse_scene(BUILTIN_SCENES[name])
    elif name in DATASET_SCENES:
        from ..volume import _resolve
        scene = load_scene(ASSETS_DIR / "scenes" / f"{name}.json")
        if not _resolve(scene.volume.path, scene.base_dir).exists():   # a file or a TIFF/DICOM folder
            return None
    else:
        raise ValueError(f"unknown benchmark scene '{name}' (known: {', '.join(ALL_SCENES)})")
    from dataclasses import replace
    return scene.replace(camera=replace(scene.camera, width=width, height=height))
