"""What the viewer's UI edits: the scene (frozen, replaced on every edit) and how it is shown.
Pure Python, no GL: the panels, the keyboard and scripts all change the scene through these."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from radiance_probes.methods import METHODS as REGISTRY, REFERENCE, VIEWER_METHODS as METHODS
from radiance_probes.io.scene_file import (BookmarkSpec, CameraSpec, ClipPlaneSpec, CropSpec, Scene,
                                           ViewerSpec)
from radiance_probes.viewer.history import SceneHistory

DISPLAY_MODES = ("image", "split", "error")   # one method; two side by side; error heat map
PROBE_VIEWS = ("off", "over", "alone")        # probe spheres: none, over the volume, alone
PROBE_AXIS_STEPS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)
MAX_MESSAGES = 8
MAX_SAMPLES = 1024   # samples per pixel an accumulation stops at (the viewer's default)


@dataclass
class ViewerState:
    scene: Scene
    home_camera: CameraSpec                # what "reset camera" returns to
    method: str = "pt"
    split_method: str = "probes"           # the right half of the split view
    display: str = "image"
    split_position: float = 0.5            # divider, as a fraction of the view's width
    probe_view: str = "off"
    probe_slab_axis: str = "all"           # the probe view's slab: all, or one plane across x/y/z
    probe_slab: float = 0.5                # where that plane is, 0 to 1 across the probe box
    show_box: bool = False
    # The slice view (app/viewer/slice_view.py): off, three slices or one beside the 3D view,
    # coloured by the window or the transfer function, through this world point.
    slice_view: str = "off"
    slice_colours: str = "window"
    slice_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    exposure: float = 1.0
    max_samples: int = MAX_SAMPLES         # accumulation stops here (per pixel)
    render_scale: float = 1.0              # render pixels per window pixel
    heat_max: float = 1.0                  # per-pixel relative error at the top of the heat map
    show_ui: bool = True
    show_help: bool = False
    scene_path: str | None = None          # the scene file it came from (saving writes elsewhere)
    show_handles: bool = True              # the crop box's and clip plane's handles over the view
    errors: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)
    history: SceneHistory | None = None    # undo and redo (ctrl+z, ctrl+y)
    # Several channels: the one whose transfer function and window the editor changes now (its
    # panel sets it while it draws); None: the scene's own transfer function.
    channel: int | None = None
    # A time series: playing (a step every 1 / play_rate seconds, looping) or paused.
    playing: bool = False
    play_rate: float = 10.0                # steps a second

    def __post_init__(self):
        if self.history is None:
            self.history = SceneHistory(self.scene)

    @classmethod
    def for_scene(cls, scene: Scene, **kw) -> "ViewerState":
        state = cls(scene=scene, home_camera=scene.camera, **kw)
        state.apply_viewer_spec(scene.viewer)
        return state

    # ---- the viewer's state kept in the scene file ("viewer") -----------------------------------
    def apply_viewer_spec(self, spec: ViewerSpec | None) -> None:
        """Shows the scene as the viewer that saved it did: method, view, exposure, probe view."""
        if spec is None:
            return
        self.set_method(spec.method)
        self.split_method = spec.split_method
        self.set_display(spec.display)
        self.exposure = spec.exposure
        self.probe_view = spec.probe_view
        self.show_box = spec.show_box

    def viewer_spec(self) -> ViewerSpec:
        return ViewerSpec(method=self.method, display=self.display, split_method=self.split_method,
                          exposure=float(self.exposure), probe_view=self.probe_view,
                          show_box=bool(self.show_box))

    # ---- undo and redo -------------------------------------------------------------------------
    def undo(self) -> None:
        scene = self.history.undo(self.scene)
        if scene is None:
            self.note("nothing to undo")
        else:
            self.scene = scene

    def redo(self) -> None:
        scene = self.history.redo(self.scene)
        if scene is None:
            self.note("nothing to redo")
        else:
            self.scene = scene

    # ---- bookmarks -----------------------------------------------------------------------------
    def save_bookmark(self, slot: int | None = None, name: str | None = None) -> BookmarkSpec:
        """The current camera as bookmark number `slot` (1-based; it replaces the one there, keeping
        its name) or as a new last one."""
        cam = self.scene.camera
        marks = list(self.scene.bookmarks)
        index = len(marks) if slot is None or slot > len(marks) else slot - 1
        if name is None:
            name = marks[index].name if index < len(marks) else _free_bookmark_name(marks)
        mark = BookmarkSpec(name=name, eye=cam.eye, target=cam.target, up=cam.up, fov_y=cam.fov_y)
        if index < len(marks):
            marks[index] = mark
        else:
            marks.append(mark)
        self.scene = self.scene.replace(bookmarks=tuple(marks))
        self.note(f"bookmark {index + 1} '{name}' saved")
        return mark

    def go_to_bookmark(self, slot: int) -> None:
        """The camera of bookmark number `slot` (1-based)."""
        marks = self.scene.bookmarks
        if not 1 <= slot <= len(marks):
            self.note(f"no bookmark {slot} (the scene has {len(marks)}; ctrl+{slot} saves one)")
            return
        self.set_camera(marks[slot - 1].camera(self.scene.camera))
        self.note(f"bookmark {slot} '{marks[slot - 1].name}'")

    def delete_bookmark(self, slot: int) -> None:
        marks = list(self.scene.bookmarks)
        if 1 <= slot <= len(marks):
            del marks[slot - 1]
            self.scene = self.scene.replace(bookmarks=tuple(marks))

    # ---- crop box and clip plane ---------------------------------------------------------------
    def set_crop(self, lo, hi, units: str | None = None, enabled: bool = True) -> None:
        crop = self.scene.crop
        units = units or (crop.units if crop is not None else "voxels")
        if units == "voxels":
            lo, hi = tuple(int(round(v)) for v in lo), tuple(int(round(v)) for v in hi)
        else:
            lo, hi = tuple(float(v) for v in lo), tuple(float(v) for v in hi)
        if any(b <= a for a, b in zip(lo, hi)):
            return   # an empty box is never meant: the edit is not taken
        self.scene = self.scene.replace(crop=CropSpec(min=lo, max=hi, units=units,
                                                      enabled=enabled))

    def set_clip_plane(self, normal=None, distance: float | None = None,
                       enabled: bool | None = None) -> None:
        plane = self.scene.clip_plane or ClipPlaneSpec(normal=(1.0, 0.0, 0.0), distance=0.0,
                                                       enabled=False)
        changes = {k: v for k, v in (("normal", None if normal is None else tuple(map(float, normal))),
                                     ("distance", None if distance is None else float(distance)),
                                     ("enabled", enabled)) if v is not None}
        self.scene = self.scene.replace(clip_plane=replace(plane, **changes))

    def toggle_clipping(self, dims=None) -> None:
        """The crop box and the clip plane on or off together (key x); with neither in the scene,
        a crop box around the whole volume, its handles shown, to drag."""
        crop, plane = self.scene.crop, self.scene.clip_plane
        if crop is None and plane is None:
            if dims is None:
                return
            self.set_crop((0, 0, 0), tuple(dims), "voxels")
            self.show_handles = True
            return
        on = not any(x is not None and x.enabled for x in (crop, plane))
        if crop is not None:
            self.scene = self.scene.replace(crop=replace(crop, enabled=on))
        if plane is not None:
            self.scene = self.scene.replace(clip_plane=replace(plane, enabled=on))
        self.note(f"crop and clip {'on' if on else 'off'}")

    # ---- what is rendered ----------------------------------------------------------------------
    def shown_methods(self) -> list[str]:
        """Methods whose accumulations the display needs, the main one first."""
        if self.probe_view == "alone":
            return []
        methods = [self.method]
        if self.display == "split" and self.split_method != self.method:
            methods.append(self.split_method)
        if self.display == "error" and self.method != REFERENCE:
            methods.append(REFERENCE)
        return methods

    def wants_probes(self) -> bool:
        return self.probe_view != "off" or any(REGISTRY[m].needs_probes
                                               for m in self.shown_methods())

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
            self.split_method = REFERENCE if self.method != REFERENCE else "probes"

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
        from radiance_probes.scene.types import EnvironmentMapSpec
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

    @property
    def transfer_function(self):
        """The transfer function the editor shows: the edited channel's, or the scene's."""
        if self.scene.channels:
            return self.scene.channels[self.edited_channel].transfer_function
        return self.scene.transfer_function

    @property
    def edited_channel(self) -> int:
        """The channel the editor changes (0 where none was chosen, or it no longer exists)."""
        n = len(self.scene.channels)
        return self.channel if self.channel is not None and 0 <= self.channel < n else 0

    def set_edited_transfer(self, tf) -> None:
        """Replaces the transfer function the editor shows (the edited channel's, or the scene's)."""
        if self.scene.channels:
            self.set_channel(self.edited_channel, transfer_function=tf)
        else:
            self.scene = self.scene.replace(transfer_function=tf)

    def set_time(self, step: int, steps: int) -> None:
        """Shows step `step` of a series of `steps` (wrapping around at either end)."""
        if steps > 1:
            self.scene = self.scene.replace(time=int(step) % int(steps))

    def step_time(self, delta: int, steps: int) -> None:
        self.set_time(self.scene.time + delta, steps)

    def set_channel(self, index: int, **changes) -> None:
        """Edits channel `index` (enabled, transfer_function, window, value_range, name); the last
        channel shown is not switched off (nothing would be left to show: a note says so)."""
        channels = list(self.scene.channels)
        if not 0 <= index < len(channels):
            raise IndexError(f"channel {index}: the scene has {len(channels)} channels")
        new = replace(channels[index], **changes)
        channels[index] = new
        if not any(c.enabled for c in channels):
            self.note("the last channel shown stays on: with every channel off there is nothing "
                      "to show")
            return
        self.scene = self.scene.replace(channels=tuple(channels))

    def show_channels(self, count: int) -> None:
        """A volume of several channels opened without a channels list: its channels written into
        the scene with their defaults (each in its own colour), so the panels can edit them."""
        if count > 1 and not self.scene.channels:
            from radiance_probes.scene.channels import default_channels
            self.scene = self.scene.replace(channels=default_channels(count, "volume"))
            self.history.reset(self.scene)

    def set_transfer(self, **changes) -> None:
        """Edits the transfer function (the edited channel's, or the scene's). An explicit RGBA
        table keeps its colours when its opacity curve is edited (its alpha column is rewritten),
        and keeps its opacity curve when a colormap replaces its colours."""
        from radiance_probes.scene.transfer import opacity_points, rgba_with_opacity
        tf = self.transfer_function
        if tf.rgba is not None:
            if "colormap" in changes or "colors" in changes:
                changes.setdefault("opacity", opacity_points(tf)[0])
                tf = replace(tf, rgba=None)
            elif "opacity" in changes:
                changes["rgba"] = rgba_with_opacity(tf, changes.pop("opacity"))
        if "colormap" in changes:      # a colormap replaces colour points
            changes.setdefault("colors", None)
        changes.setdefault("preset", None)   # an edited preset is a preset no longer
        self.set_edited_transfer(replace(tf, **changes))

    def set_clinical_preset(self, name: str, domain: tuple[float, float]) -> None:
        """The scene's transfer function becomes the clinical preset `name` (app/scene/clinical_presets.py),
        placed by `domain`, the data values the volume maps to densities 0 and 1."""
        from radiance_probes.scene.clinical_presets import with_preset
        if self.scene.channels:
            raise ValueError("clinical presets are for one-channel CT volumes")
        self.scene = with_preset(self.scene, name, domain)

    def cycle_colormap(self, step: int = 1) -> None:
        from radiance_probes.scene.transfer import COLORMAPS, ALIASES
        names = [c for c in COLORMAPS if c not in ALIASES]
        current = ALIASES.get(self.transfer_function.colormap, self.transfer_function.colormap)
        index = names.index(current) if current in names else -1
        self.set_transfer(colormap=names[(index + step) % len(names)])

    def edit(self, **changes) -> None:
        """Top-level scene fields: density_scale, albedo, anisotropy, environment, ..."""
        self.scene = self.scene.replace(**changes)

    def load_scene(self, scene: Scene, path: str | None = None) -> None:
        self.scene, self.home_camera = scene, scene.camera
        self.history.reset(scene)   # another scene: the steps were the last one's
        self.apply_viewer_spec(scene.viewer)
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


def _free_bookmark_name(marks) -> str:
    taken = {m.name for m in marks}
    return next(f"view {i}" for i in range(1, len(marks) + 2) if f"view {i}" not in taken)


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
