"""What the viewer's UI edits: the scene (frozen, replaced on every edit) and how it is shown.
Pure Python, no GL: the panels, the keyboard and scripts all change the scene through these."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from ..render.renderer import METHODS
from ..scene import CameraSpec, Scene

DISPLAY_MODES = ("image", "split", "error")   # one method; two side by side; error heat map
PROBE_VIEWS = ("off", "over", "alone")        # probe spheres: none, over the volume, alone
PROBE_AXIS_STEPS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)
MAX_MESSAGES = 8


@dataclass
class ViewerState:
    scene: Scene
    home_camera: CameraSpec                # what "reset camera" returns to
    method: str = "pt"
    split_method: str = "probes"           # the right half of the split view
    display: str = "image"
    split_position: float = 0.5            # divider, as a fraction of the view's width
    probe_view: str = "off"
    show_box: bool = False
    exposure: float = 1.0
    max_samples: int = 1024                # accumulation stops here (per pixel)
    render_scale: float = 1.0              # render pixels per window pixel
    heat_max: float = 1.0                  # per-pixel relative error at the top of the heat map
    show_ui: bool = True
    show_help: bool = False
    scene_path: str | None = None          # the scene file it came from (saving writes elsewhere)
    errors: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)

    @classmethod
    def for_scene(cls, scene: Scene, **kw) -> "ViewerState":
        return cls(scene=scene, home_camera=scene.camera, **kw)

    # ---- what is rendered ----------------------------------------------------------------------
    def shown_methods(self) -> list[str]:
        """Methods whose accumulations the display needs, the main one first."""
        if self.probe_view == "alone":
            return []
        methods = [self.method]
        if self.display == "split" and self.split_method != self.method:
            methods.append(self.split_method)
        if self.display == "error" and self.method != "pt":
            methods.append("pt")
        return methods

    def wants_probes(self) -> bool:
        return self.probe_view != "off" or any(m != "pt" for m in self.shown_methods())

    # ---- edits (each replaces the frozen scene) -------------------------------------------------
    def set_method(self, method: str) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}")
        self.method = method

    def cycle(self, name: str, choices: tuple[str, ...], step: int = 1) -> None:
        setattr(self, name, choices[(choices.index(getattr(self, name)) + step) % len(choices)])

    def set_display(self, mode: str) -> None:
        if mode not in DISPLAY_MODES:
            raise ValueError(f"unknown display mode {mode!r}")
        self.display = mode
        if mode == "split" and self.split_method == self.method:
            self.split_method = "pt" if self.method != "pt" else "probes"

    def toggle_display(self, mode: str) -> None:
        self.set_display("image" if self.display == mode else mode)

    def set_camera(self, camera: CameraSpec) -> None:
        self.scene = self.scene.replace(camera=camera)

    def reset_camera(self) -> None:
        self.set_camera(self.home_camera)

    def set_light_angles(self, azimuth_deg: float, elevation_deg: float) -> None:
        light = replace(self.scene.light, direction=direction_from_angles(azimuth_deg, elevation_deg))
        self.scene = self.scene.replace(light=light)

    def set_environment_map(self, path: str | None = None, **changes) -> None:
        """A map file (a new map starts at scale 1, rotation 0), its scale or rotation (degrees
        about +y, wrapped into [-180, 180]); path="" goes back to the constant environment."""
        from ..scene_types import EnvironmentMapSpec
        current = self.scene.environment_map
        if path == "":
            self.scene = self.scene.replace(environment_map=None)
            return
        spec = EnvironmentMapSpec(path) if path is not None else current
        if spec is None:
            return
        if "rotation" in changes and not -180.0 <= changes["rotation"] <= 180.0:
            changes["rotation"] = (float(changes["rotation"]) + 180.0) % 360.0 - 180.0
        self.scene = self.scene.replace(environment_map=replace(spec, **changes))

    def turn_light(self, d_azimuth_deg: float, d_elevation_deg: float) -> None:
        az, el = angles_from_direction(self.scene.light.direction)
        self.set_light_angles(az + d_azimuth_deg, max(-89.0, min(89.0, el + d_elevation_deg)))

    def set_probe_grid(self, grid: tuple[int, int, int]) -> None:
        grid = tuple(max(1, min(256, int(v))) for v in grid)
        self.scene = self.scene.replace(probes=replace(self.scene.probes, grid=grid))

    def step_probe_grid(self, step: int) -> None:
        """Every axis to the next coarser (step < 0) or finer density of PROBE_AXIS_STEPS."""
        self.set_probe_grid(tuple(_next_step(v, step) for v in self.scene.probes.grid))

    def set_volume(self, **changes) -> None:
        """How the volume file is read: its DICOM `series`, its `orientation` (a reload)."""
        self.scene = self.scene.replace(volume=replace(self.scene.volume, **changes))

    def set_probes(self, **changes) -> None:
        self.scene = self.scene.replace(probes=replace(self.scene.probes, **changes))

    def set_transfer(self, **changes) -> None:
        """Edits the transfer function. An explicit RGBA table keeps its colours when its opacity
        curve is edited (its alpha column is rewritten), and keeps its opacity curve when a
        colormap replaces its colours."""
        from ..transfer import opacity_points, rgba_with_opacity
        tf = self.scene.transfer_function
        if tf.rgba is not None:
            if "colormap" in changes:
                changes.setdefault("opacity", opacity_points(tf)[0])
                tf = replace(tf, rgba=None)
            elif "opacity" in changes:
                changes["rgba"] = rgba_with_opacity(tf, changes.pop("opacity"))
        self.scene = self.scene.replace(transfer_function=replace(tf, **changes))

    def cycle_colormap(self, step: int = 1) -> None:
        from ..transfer import COLORMAPS, ALIASES
        names = [c for c in COLORMAPS if c not in ALIASES]
        current = ALIASES.get(self.scene.transfer_function.colormap,
                              self.scene.transfer_function.colormap)
        index = names.index(current) if current in names else -1
        self.set_transfer(colormap=names[(index + step) % len(names)])

    def edit(self, **changes) -> None:
        """Top-level scene fields: density_scale, albedo, anisotropy, environment, ..."""
        self.scene = self.scene.replace(**changes)

    def load_scene(self, scene: Scene, path: str | None = None) -> None:
        self.scene, self.home_camera = scene, scene.camera
        if path is not None and path.lower().endswith(".json"):
            self.scene_path = path

    # ---- messages ------------------------------------------------------------------------------
    def error(self, text: str) -> None:
        if text not in self.errors:
            self.errors.append(text)
            del self.errors[:-MAX_MESSAGES]

    def note(self, text: str) -> None:
        self.messages.append(text)
        del self.messages[:-MAX_MESSAGES]


def _next_step(value: int, step: int) -> int:
    if step > 0:
        return next((s for s in PROBE_AXIS_STEPS if s > value), PROBE_AXIS_STEPS[-1])
    return next((s for s in reversed(PROBE_AXIS_STEPS) if s < value), PROBE_AXIS_STEPS[0])


def direction_from_angles(azimuth_deg: float, elevation_deg: float) -> tuple[float, float, float]:
    """Unit vector towards the light: elevation above the x-z plane, azimuth from +z towards +x."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return (math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az))


def angles_from_direction(direction) -> tuple[float, float]:
    x, y, z = direction
    n = math.sqrt(x * x + y * y + z * z)
    return (math.degrees(math.atan2(x, z)), math.degrees(math.asin(max(-1.0, min(1.0, y / n)))))


def colour_and_strength(rgb) -> tuple[tuple[float, float, float], float]:
    """An RGB quantity as a colour whose largest channel is 1 and a strength (that channel)."""
    strength = max(float(c) for c in rgb)
    if strength <= 0.0:
        return (1.0, 1.0, 1.0), 0.0
    return tuple(float(c) / strength for c in rgb), strength


def scaled(colour, strength: float) -> tuple[float, float, float]:
    return tuple(float(c) * float(strength) for c in colour)


# ---- opacity curve control points ----------------------------------------------------------------

def move_point(points, index: int, x: float, y: float) -> tuple[tuple[float, float], ...]:
    """Moves one control point; it stays between its neighbours and inside [0, 1]^2."""
    pts = [tuple(p) for p in points]
    lo = pts[index - 1][0] if index > 0 else 0.0
    hi = pts[index + 1][0] if index + 1 < len(pts) else 1.0
    pts[index] = (min(max(float(x), lo), hi), min(max(float(y), 0.0), 1.0))
    return tuple(pts)


def add_point(points, x: float, y: float) -> tuple[tuple[float, float], ...]:
    x, y = min(max(float(x), 0.0), 1.0), min(max(float(y), 0.0), 1.0)
    return tuple(sorted([*map(tuple, points), (x, y)], key=lambda p: p[0]))


def remove_point(points, index: int) -> tuple[tuple[float, float], ...]:
    """Removes one control point; a curve keeps at least two."""
    pts = list(map(tuple, points))
    if len(pts) > 2:
        del pts[index]
    return tuple(pts)
