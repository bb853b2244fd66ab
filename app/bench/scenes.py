"""The benchmark's scenes: the paper's four datasets with its colormaps and views, plus two built-in
scenes that stress what the datasets do not (thick high-albedo media, strong anisotropy)."""
from __future__ import annotations

from radiance_probes.paths import ASSETS_DIR
from radiance_probes.io.scene_file import Scene, load_scene, parse_scene

DATASET_SCENES = ("fuel", "hydrogen", "foot", "bonsai")
# Dataset scenes a preset names itself, not in the default sweeps: the chest CT with `ct_bone`
# (surfaces) under a sphere light and a dim sun (assets/scenes/chest.json; the interact replays).
LIT_DATASET_SCENES = ("chest",)

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
# The stress battery: procedural scenes built to break shortcuts (issue 30), at full size for the
# bench's bias table (`bench --preset bias`) and scaled down by the tests (battery_scene). Each
# says what it breaks.
_WHITE_RAMP = {"rgba": [[1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 1.0, 1.0]]}   # A(d) = d, white
_BACKLIT = [0.0, 0.3, -0.954]   # the sun behind the volume, seen from the default camera (+z)
BATTERY = {
    # A thin dense shell lit from behind, albedo 0.99: what reaches the camera side has scattered
    # through the rim many times; walks' radiance is heavy-tailed (rare walks find the rim).
    "shell-g06": {"volume": {"builtin": "shell", "size": [128, 128, 128]},
                  "transfer_function": _WHITE_RAMP, "density_scale": 400.0, "albedo": 0.99,
                  "anisotropy": 0.6, "light": {"direction": _BACKLIT, "irradiance": [4, 4, 4]},
                  "environment": [0.02, 0.02, 0.025], "max_bounces": 256},
    "shell-g09": {"volume": {"builtin": "shell", "size": [128, 128, 128]},
                  "transfer_function": _WHITE_RAMP, "density_scale": 400.0, "albedo": 0.99,
                  "anisotropy": 0.9, "light": {"direction": _BACKLIT, "irradiance": [4, 4, 4]},
                  "environment": [0.02, 0.02, 0.025], "max_bounces": 256},
    # An opaque slab with pinholes over haze: beams narrower than a probe spacing or a coarse
    # light-grid texel.
    "pinholes": {"volume": {"builtin": "pinholes", "size": [128, 128, 128]},
                 "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 0.004],
                                                [1, 1, 1, 1.0]]},
                 "density_scale": 300.0, "albedo": 0.9, "anisotropy": 0.3,
                 "light": {"direction": [0.15, 0.97, 0.2], "irradiance": [6, 6, 6]},
                 "environment": [0.01, 0.01, 0.012],
                 "camera": {"eye": [0.0, -0.55, 2.1], "target": [0, -0.15, 0]}},
    # A tiny dense object in thin haze: a shadow and a bright spot far smaller than a probe cell.
    "speck": {"volume": {"builtin": "speck", "size": [128, 128, 128]},
              "transfer_function": {"opacity": [[0.0, 0.0], [0.02, 0.0005], [0.5, 0.5],
                                                [1.0, 1.0]], "colormap": "grey"},
              "density_scale": 2000.0, "albedo": 0.9, "anisotropy": 0.0,
              "light": {"direction": [0.7, 0.5, 0.5], "irradiance": [5, 5, 5]},
              "environment": [0.05, 0.05, 0.06]},
    # One-voxel filaments: detail below every grid's resolution.
    "filaments": {"volume": {"builtin": "filaments", "size": [128, 128, 128]},
                  "transfer_function": _WHITE_RAMP, "density_scale": 300.0, "albedo": 0.95,
                  "anisotropy": 0.3, "light": {"direction": [0.4, 0.8, 0.45],
                                               "irradiance": [4, 4, 4]},
                  "environment": [0.1, 0.1, 0.12]},
    # An HDR sun against a dim sky: 16-bit probes and light grids, relative storage.
    "hdr-sun": {"volume": {"builtin": "cloud", "size": [96, 96, 96]}, "density_scale": 120.0,
                "albedo": 0.9, "anisotropy": 0.5,
                "light": {"direction": [0.3, 0.6, 0.74], "irradiance": [2000, 1900, 1700]},
                "environment": [0.002, 0.002, 0.003]},
    # Nothing at all, and all of it opaque.
    "empty": {"volume": {"builtin": "empty", "size": [32, 32, 32]}, "albedo": 0.9,
              "environment": [0.3, 0.35, 0.4]},
    "opaque": {"volume": {"builtin": "constant", "size": [32, 32, 32]},
               "density_scale": 10000.0, "albedo": 0.8,
               "light": {"direction": [0.3, 0.8, 0.52], "irradiance": [3, 3, 3]},
               "environment": [0.1, 0.1, 0.1]},
    # Head-like: nested noisy ellipsoids, a thin bright skin over a dense interior, backlit with
    # albedo 0.99 and g = 0.6 (as the held-out MRI head).
    "head": {"volume": {"builtin": "head", "size": [128, 128, 128]},
             "transfer_function": {"opacity": [[0.0, 0.0], [0.08, 0.0], [0.3, 0.6], [0.45, 0.15],
                                               [0.6, 0.7], [1.0, 1.0]], "colormap": "grey"},
             "density_scale": 150.0, "albedo": 0.99, "anisotropy": 0.6,
             "light": {"direction": [0.25, 0.35, -0.9], "irradiance": [4, 4, 4]},
             "environment": [0.03, 0.03, 0.035], "max_bounces": 256},
}
BUILTIN_SCENES = {"thick": THICK, "anisotropic": ANISOTROPIC, "grey": GREY, "tiny": TINY,
                  **BATTERY}
ALL_SCENES = (*DATASET_SCENES, "thick", "anisotropic", "grey")
BATTERY_SCENES = tuple(BATTERY)


def battery_scene(name: str, side: int, width: int, height: int, grid: int | None = None,
                  samples: int | None = None) -> Scene:
    """A battery scene scaled down for the tests: the volume at `side` voxels along its longest
    axis (the same procedural volume, coarser), the image and, where given, the probes."""
    import copy
    from dataclasses import replace
    spec = copy.deepcopy(BATTERY[name])
    size = spec["volume"]["size"]
    spec["volume"]["size"] = [max(2, round(v * side / max(size))) for v in size]
    scene = parse_scene(spec)
    probes = scene.probes
    if grid is not None:
        probes = replace(probes, grid=(grid, grid, grid))
    if samples is not None:
        probes = replace(probes, samples=samples)
    return scene.replace(camera=replace(scene.camera, width=width, height=height), probes=probes)


def bench_scene(name: str, width: int, height: int) -> Scene | None:
    """The named scene at the given image size; None when its dataset is absent."""
    if name in BUILTIN_SCENES:
        scene = parse_scene(BUILTIN_SCENES[name])
    elif name in DATASET_SCENES or name in LIT_DATASET_SCENES:
        from radiance_probes.io.volume_files import _resolve
        scene = load_scene(ASSETS_DIR / "scenes" / f"{name}.json")
        if not _resolve(scene.volume.path, scene.base_dir).exists():   # a file or a TIFF/DICOM folder
            return None
    else:
        raise ValueError(f"unknown benchmark scene '{name}' (known: "
                         f"{', '.join((*ALL_SCENES, *LIT_DATASET_SCENES, *BATTERY_SCENES))})")
    from dataclasses import replace
    return scene.replace(camera=replace(scene.camera, width=width, height=height))
