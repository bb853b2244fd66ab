"""What the viewer starts with per device class ("gpu", "software": llvmpipe) where the user said
nothing: the render scale and the probe setting, from measurements."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from radiance_probes.io.scene_file import Scene

# Render pixels per window pixel: llvmpipe renders half the window's pixels per side.
RENDER_SCALE = {"gpu": 1.0, "software": 0.5}

# The probe grid and walks per probe when neither the scene nor the command line names them. On a
# GPU, 128^3 x 64: in the replayed viewer session on the H100 at 1920x1080
# (bench/h100-interact/report.md, bonsai, the raymarcher) every edit reached 5% within 150 ms of
# GPU time and 3% within 215 ms, where 64^3 x 256 ended above 3% after the density edit (3.8%)
# and the load (4.0%); the bake of 128^3 x 64 takes about 140 ms of 8 ms slices. On llvmpipe no
# setting was measured in a window, so the scene's default (16^3 x 256) stays.
PROBES = {"gpu": (128, 64), "software": None}


def probes_named(scene_arg: str | None, probe_grid, probe_samples,
                 bundled: Path | None = None) -> bool:
    """Whether the user chose the probe setting: a --probe-grid or --probe-samples option, or a
    scene file (the given one, or the scene bundled with a volume file) with probes.grid or
    probes.samples in it."""
    if probe_grid is not None or probe_samples is not None:
        return True
    path = Path(scene_arg) if scene_arg and scene_arg.lower().endswith(".json") else bundled
    if path is None:
        return False
    try:
        probes = json.loads(Path(path).read_text(encoding="utf-8")).get("probes", {})
    except (OSError, ValueError, AttributeError):
        return True   # unreadable here: leave the scene as it loaded
    return isinstance(probes, dict) and ("grid" in probes or "samples" in probes)


def with_device_probes(scene: Scene, device: str, named: bool) -> tuple[Scene, str | None]:
    """The scene with the device class's probe setting where the user named none, and the line
    that says so (None: unchanged)."""
    setting = PROBES[device]
    if named or setting is None:
        return scene, None
    grid, walks = setting
    if scene.probes.grid == (grid,) * 3 and scene.probes.samples == walks:
        return scene, None
    scene = scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks))
    return scene, (f"probes {grid}^3 x {walks}, the default on a GPU (measured in "
                   "bench/h100-interact); --probe-grid and --probe-samples, or probes in the "
                   "scene file, choose others")
