"""render(), Renderer, view(): the project's renderers from Python, on NumPy arrays or files, with
a GL context the API makes (headless: EGL, else OSMesa, else GLX) and releases itself.

Defaults are chosen to show something for any data: the values windowed to their 0.5th to 99.5th
percentiles (``window="auto"``), the default transfer function (opacity rising from density 0.2),
and the default camera, which frames the volume's box (its longest side is 1, centred at the
origin). Everything else is the scene format's (docs/scene-format.md): any scene key can be given
as a keyword, and a few common nested ones directly (see SHORTCUTS).
"""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from radiance_probes.methods import METHODS as REGISTRY, NAMES
from radiance_probes.io.scene_file import (Scene, SceneError, did_you_mean, load_scene, parse_scene,
                                           scene_to_dict)
from radiance_probes.scene.types import CameraSpec, VolumeError, VolumeSpec
from radiance_probes.scene.flags import COLOUR_SOURCES
from radiance_probes.scene.clinical_presets import opening_scene
from radiance_probes.io.volume import Volume, normalise
from radiance_probes.io.load import load_scene_volume

from radiance_probes.api.image import Image

# Keywords that stand for a nested scene key: render(data, colormap="viridis", width=256).
SHORTCUTS = {
    **{k: "volume" for k in ("spacing", "value_range", "window", "series", "orientation",
                             "builtin", "size", "dims", "dtype", "replace_nonfinite", "axes")},
    **{k: "transfer_function" for k in ("colormap", "colors", "opacity", "rgba", "resolution")},
    **{k: "camera" for k in ("width", "height", "fov_y", "eye", "target", "up")},
}
# A transfer function's colours come from one of COLOUR_SOURCES: giving one replaces the others the
# base scene had (update(colormap="viridis") after colour points, update(rgba=...) after a colormap).
SCENE_KEYS = tuple(f.name for f in dataclasses.fields(Scene)
                   if f.name not in ("base_dir", "environment_map"))
# Every method (app/methods.py, the registry) and the samples per pixel a render takes unless
# told: the raymarcher's frames differ only by their jittered start; the others are Monte Carlo.
METHODS = NAMES
DEFAULT_SPP = {name: m.default_spp for name, m in REGISTRY.items()}
# window="auto": the values between these percentiles map to densities 0 and 1.
AUTO_WINDOW_PERCENTILES = (0.5, 99.5)
AUTO_WINDOW_SAMPLES = 1 << 21     # voxels the percentiles are taken over, at most (a regular subsample)


def _merge(base: dict, options: dict) -> dict:
    """Scene data with keyword options applied: shortcuts go into their object, nested dicts are
    merged key by key, anything else replaces."""
    out = json.loads(json.dumps(base))
    for key, value in options.items():
        if isinstance(value, tuple):
            value = list(value)
        if key in SHORTCUTS:
            sub = out.setdefault(SHORTCUTS[key], {})
            if not isinstance(sub, dict):   # a transfer-function file's name in a scene dict
                raise SceneError(f"{key}: the scene's {SHORTCUTS[key]} is {sub!r}, not an object "
                                 f"to change; give {SHORTCUTS[key]}= whole, or the scene as a "
                                 "file or Scene (which read the file)")
            if SHORTCUTS[key] == "transfer_function":
                for other in COLOUR_SOURCES.get(key, ()):
                    sub.pop(other, None)
            sub[key] = value
        elif key in SCENE_KEYS:
            if isinstance(value, dict) and isinstance(out.get(key), dict) and key != "environment":
                kept = out[key]
                if key == "transfer_function":
                    kept = {k: v for k, v in kept.items()
                            if not any(k in COLOUR_SOURCES.get(g, ()) for g in value)}
                out[key] = {**kept, **value}
            else:
                out[key] = value
        else:
            raise SceneError(f"unknown option {key!r}"
                             f"{did_you_mean(key, [*SCENE_KEYS, *SHORTCUTS])}: give a scene key "
                             f"({', '.join(SCENE_KEYS)}) or one of {', '.join(sorted(SHORTCUTS))}")
    return out


def _window_value(window: Any) -> Any:
    """window=(level, width) as the scene's {"level", "width"}; a preset name or a dict as is."""
    if isinstance(window, (tuple, list)) and len(window) == 2:
        return {"level": window[0], "width": window[1]}
    return window


def as_array(data: Any) -> np.ndarray:
    """A NumPy array of numbers, 3D [z, y, x] (or 4D, 5D with channels or time steps, named by
    axes=), or a plain error saying what is wrong."""
    array = np.asarray(data)
    if array.dtype == bool:
        array = array.astype(np.uint8)
    if array.dtype.kind == "c":
        raise VolumeError(f"array of complex values ({array.dtype}): give their magnitude "
                          "(np.abs) or one part")
    if array.dtype.kind not in "uif":
        raise VolumeError(f"array of {array.dtype} values: expected numbers")
    if array.dtype == np.float16:
        array = array.astype(np.float32)
    if array.ndim not in (3, 4, 5):
        raise VolumeError(f"expected a 3D array [z, y, x], got shape {tuple(array.shape)} (4D "
                          "and 5D arrays hold channels or time steps, named by axes=)")
    if min(array.shape) < 1:
        raise VolumeError(f"the array is empty (shape {tuple(array.shape)})")
    return array


def volume_from_array(array: np.ndarray, spec: VolumeSpec, name: str = "array") -> Volume:
    """The array as the loader would give it from a file (normalised by the scene's range)."""
    spacing = spec.spacing if spec.spacing is not None else (1.0, 1.0, 1.0)
    norm, vr = normalise(array, spec.domain, name, spec.replace_nonfinite)
    finite = array[np.isfinite(array)] if array.dtype.kind == "f" else array
    return Volume(norm, tuple(float(s) for s in spacing), name, vr, array.dtype.name,
                  float(finite.min()) if finite.size else 0.0,
                  float(finite.max()) if finite.size else 0.0)


def auto_window(volume: Volume) -> Volume:
    """The volume with its values windowed to their 0.5th to 99.5th percentiles (kept as it is
    where those are equal: a mask, a constant), with a note saying so."""
    data = volume.data
    step = max(1, math.ceil((data.size / AUTO_WINDOW_SAMPLES) ** (1 / 3)))
    lo, hi = np.percentile(data[::step, ::step, ::step], AUTO_WINDOW_PERCENTILES)
    if not hi - lo > 1e-6 or (lo <= 0.0 and hi >= 1.0):
        return volume
    a, b = volume.value_range
    raw_lo, raw_hi = a + float(lo) * (b - a), a + float(hi) * (b - a)
    data = np.clip((data - np.float32(lo)) / np.float32(hi - lo), 0.0, 1.0).astype(np.float32)
    note = (f"values windowed to their {AUTO_WINDOW_PERCENTILES[0]:g}th to "
            f"{AUTO_WINDOW_PERCENTILES[1]:g}th percentiles, {raw_lo:.6g} to {raw_hi:.6g} (give "
            "value_range or window to choose)")
    return dataclasses.replace(volume, data=data, value_range=(raw_lo, raw_hi),
                               notes=volume.notes + (note,))


def build_scene(data: Any = None, scene: Any = None, options: dict | None = None
                ) -> tuple[Scene, Volume]:
    """The scene and volume that `data` (an array, a volume file or folder, a scene file, or None
    for the scene's own volume), a base `scene` (a Scene, a dict or a JSON file) and keyword
    options make."""
    options = dict(options or {})
    window = options.pop("window", "auto")
    base_dir = None
    if isinstance(scene, Scene):
        base, base_dir = scene_to_dict(scene), scene.base_dir
    elif isinstance(scene, (str, Path)):
        loaded = load_scene(scene)
        base, base_dir = scene_to_dict(loaded), loaded.base_dir
    elif isinstance(scene, dict):
        base = scene
    elif scene is None:
        base = {}
    else:
        raise SceneError(f"scene: expected a Scene, a dict or a scene file, got "
                         f"{type(scene).__name__}")
    array = None
    from_file = False
    if isinstance(data, (str, Path)) and Path(data).suffix.lower() == ".json":
        if scene is not None:
            raise SceneError("give a scene file either as data or as scene=, not both")
        loaded = load_scene(data)
        base, base_dir = scene_to_dict(loaded), loaded.base_dir
    elif isinstance(data, (str, Path)):
        base = {**base, "volume": {"path": str(Path(data).expanduser().resolve())}}
        from_file = True
    elif data is not None and not isinstance(data, Volume):
        array = as_array(data)
    if window not in ("auto", None):
        options["window"] = _window_value(window)
    merged = _merge(base, options)
    given = array is not None or isinstance(data, Volume)
    axes = None
    if given:   # the scene's volume keys say how to read the array (spacing, range, window, axes)
        merged["volume"] = {k: v for k, v in merged.get("volume", {}).items()
                            if k not in ("path", "builtin", "size")}
        axes = merged["volume"].pop("axes", None)
    parsed = parse_scene(merged, base_dir=base_dir)
    if given:
        parsed = parsed.replace(volume=dataclasses.replace(parsed.volume, builtin=None))
        if isinstance(data, Volume):
            volume = data
        elif axes is None and array.ndim == 3 and not parsed.channels and not parsed.time:
            volume = volume_from_array(array, parsed.volume)
        else:   # channels or time steps (app/io/volume.py volume_from_array reads them as a file)
            from radiance_probes.io.load import volume_from_array as from_axes
            if axes is None and array.ndim != 3:
                raise VolumeError(f"a {array.ndim}D array (shape {tuple(array.shape)}): say which "
                                  "axis is which with axes=, e.g. \"czyx\" or \"tzyx\"")
            spec = parsed.volume
            volume = from_axes(array, axes or "zyx", spec.spacing or (1.0, 1.0, 1.0), spec.domain,
                               parsed.channels or None, parsed.time)
    else:
        volume = load_scene_volume(parsed)
        parsed = opening_scene(parsed, volume)   # a CT with no transfer function: its preset
    if volume.channel_count > 1 or volume.time_steps > 1:
        window = None   # each channel, and a series as a whole, by its own range (or the scene's)
    if window == "auto" and parsed.volume.domain is None and (array is not None or from_file):
        volume = auto_window(volume)
        parsed = parsed.replace(volume=dataclasses.replace(parsed.volume,
                                                           value_range=volume.value_range))
    check_clip(parsed, volume)
    from radiance_probes.scene.framing import frame_default_camera
    return frame_default_camera(parsed, volume.half_extent), volume   # the whole box in view


def check_clip(scene: Scene, volume: Volume) -> None:
    """A crop beyond the volume, or one that keeps nothing, is refused before any GPU work (as the
    command line does): an empty image is never meant."""
    from radiance_probes.frontend.scene_options import check_clip as check
    check(scene, volume)


def _camera(scene: Scene, camera: Any) -> Scene:
    if camera is None:
        return scene
    if isinstance(camera, CameraSpec):
        return scene.replace(camera=camera)
    if not isinstance(camera, dict):
        raise SceneError(f"camera: expected a dict of camera keys or a CameraSpec, got "
                         f"{type(camera).__name__}")
    # the volume's spec kept as it is: an array's scene names no file, and parsing its dict again
    # would name the built-in cloud (whose one channel then fails an array's channels)
    parsed = parse_scene(_merge(scene_to_dict(scene), {"camera": camera}), base_dir=scene.base_dir)
    return parsed.replace(volume=scene.volume)


class Renderer:
    """A renderer that keeps its GL context, volume and probes across many frames: camera moves
    never re-bake the probes; light, transfer-function, volume or probe changes do (on the next
    render that needs them). Use it as a context manager, or call close().

        with radiance_probes.Renderer(volume, spacing=(1, 1, 2)) as r:
            for angle in range(0, 360, 30):
                r.orbit(angle, 20)
                frames.append(r.render())
    """

    def __init__(self, data: Any = None, *, scene: Any = None, settings=None,
                 gl_backend: str | None = None, **scene_options):
        from radiance_probes.gl.context import create_headless_context
        from radiance_probes.rendering.renderer import Renderer as AppRenderer
        self._data = data
        self._base = scene
        self._options = dict(scene_options)
        self.scene, self.volume = build_scene(data, scene, scene_options)
        self.bakes = 0                 # probe bakes run so far (camera moves never add one)
        self._ctx = create_headless_context(gl_backend)
        try:
            with self._ctx:
                self._renderer = AppRenderer(self._ctx, self.scene, self.volume, settings)
        except BaseException:
            self._ctx.release()
            raise

    # ---- the scene ------------------------------------------------------------------------------
    @property
    def notes(self) -> tuple[str, ...]:
        """How the data was read: DICOM series, orientation, the window chosen; and for a bricked
        volume under a memory cap, the level shown; probes baked on a coarser level
        (RenderSettings.bake_level)."""
        note = self._renderer.bake_note()
        return self._renderer.resources.volume.notes + ((note,) if note else ())

    @property
    def device(self) -> str:
        from radiance_probes.gl.context import describe
        return describe(self._ctx)

    @property
    def settings(self):
        """How it renders and bakes (app.rendering.settings.RenderSettings, resolved for the
        device); change it with configure()."""
        return self._renderer.settings

    def configure(self, **changes) -> None:
        """Changes RenderSettings fields (gather_event=2, walk_sun="ray", ...)."""
        with self._ctx:
            self._renderer.configure(**changes)

    def update(self, **scene_options) -> None:
        """Changes the scene (any scene key or shortcut, as the constructor takes them)."""
        if not scene_options:
            return
        if any(SHORTCUTS.get(k) == "volume" or k == "volume" for k in scene_options):
            # the volume is read again with the new options; the camera stays where it was
            self._options.update(scene_options)
            scene, volume = build_scene(self._data, self._base, self._options)
            if not any(SHORTCUTS.get(k) == "camera" or k == "camera" for k in scene_options):
                scene = scene.replace(camera=self.scene.camera)
        else:
            scene = parse_scene(_merge(scene_to_dict(self.scene), scene_options),
                                base_dir=self.scene.base_dir)
            check_clip(scene, self.volume)
            volume = None
            self._options.update(scene_options)
        with self._ctx:
            self._renderer.set_scene(scene, volume)
        self.scene = scene
        if volume is not None:
            self.volume = volume

    def orbit(self, azimuth: float, elevation: float, distance: float | None = None) -> CameraSpec:
        """Puts the camera on a sphere about its target: azimuth in degrees from +z towards +x,
        elevation above the x-z plane (within +-89), +y up; the distance kept unless given."""
        cam = self.scene.camera
        target = np.asarray(cam.target, np.float64)
        if distance is None:
            distance = float(np.linalg.norm(np.asarray(cam.eye) - target))
        if not (math.isfinite(distance) and distance > 0):
            raise SceneError(f"orbit: distance must be a finite number > 0, got {distance!r}")
        az, el = math.radians(azimuth), math.radians(max(-89.0, min(89.0, elevation)))
        offset = distance * np.array([math.cos(el) * math.sin(az), math.sin(el),
                                      math.cos(el) * math.cos(az)])
        camera = dataclasses.replace(cam, eye=tuple(float(v) for v in target + offset),
                                     up=(0.0, 1.0, 0.0))
        self.scene = self.scene.replace(camera=camera)
        return camera

    # ---- images -------------------------------------------------------------------------------
    def render(self, method: str = "raymarch", spp: int | None = None, camera: Any = None,
               seed: int = 0, exposure: float = 1.0, denoise: bool = False,
               denoise_guides: str = "auto", **scene_options) -> Image:
        """One image of the current scene (with `camera` and any scene options changed first):
        `method` one of METHODS (radiance_probes.methods: raymarch, interactive, over the probes,
        the default; pt, the reference path tracer; probes, probes-only, guided, refine);
        `spp` samples (raymarched frames) per pixel (None: DEFAULT_SPP's). `denoise`: through the denoiser (Open Image
        Denoise), guided by `denoise_guides` (auto, none, albedo, albedo-normal, probes); where it
        cannot run, the raw image and a note (Image.notes)."""
        if method not in METHODS:
            raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
        spp = DEFAULT_SPP[method] if spp is None else spp
        if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
            raise ValueError(f"spp: expected an integer >= 1, got {spp!r}")
        self.update(**scene_options)
        self.scene = _camera(self.scene, camera)
        with self._ctx:
            r = self._renderer
            if self.scene is not r.scene:
                r.set_scene(self.scene)
            if r.needs_probes(method) and not r.probes_current():
                self.bakes += 1
            result = r.render(method, spp=spp, seed=seed, denoise=denoise,
                              denoise_guides=denoise_guides)
        notes = self.notes
        if result.denoised is not None and not result.denoised.denoised:
            notes = (*notes, result.denoised.note)
        return Image(result.image, method, spp, self.scene, result.render_ms, result.bake_ms,
                     exposure, notes)

    def widget(self, method: str = "raymarch", spp: int | None = None, exposure: float = 1.0):
        """In Jupyter: the image with sliders that orbit the camera (needs ipywidgets)."""
        from radiance_probes.api.widget import orbit_widget
        return orbit_widget(self, method, spp, exposure)

    # ---- its GL context ------------------------------------------------------------------------
    def close(self) -> None:
        """Releases the renderer's GPU objects and its GL context (idempotent)."""
        if self._ctx is None:
            return
        with self._ctx:
            self._renderer.release()
        self._ctx.release()
        self._ctx = None

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render(data: Any = None, method: str = "raymarch", spp: int | None = None, *,
           scene: Any = None, camera: Any = None, seed: int = 0, exposure: float = 1.0,
           denoise: bool = False, denoise_guides: str = "auto", settings=None,
           gl_backend: str | None = None, **scene_options) -> Image:
    """Renders `data` once and releases the GL context. `data`: a NumPy array [z, y, x] of any
    numeric dtype (give spacing=(x, y, z) where voxels are not cubes), a volume file, a folder
    (TIFF slices or DICOM, searched recursively), a scene JSON file, or None (the built-in
    cloud). Keywords are scene keys or their shortcuts (colormap=, opacity=, width=, window=,
    series=, orientation=, density_scale=, ...); `settings` a RenderSettings (how it bakes and
    renders). `denoise`: through the denoiser (Renderer.render)."""
    with Renderer(data, scene=scene, settings=settings, gl_backend=gl_backend,
                  **scene_options) as r:
        return r.render(method, spp, camera=camera, seed=seed, exposure=exposure, denoise=denoise,
                        denoise_guides=denoise_guides)


def view(data: Any = None, method: str = "raymarch", *, scene: Any = None, block: bool = True,
         screenshot: str | Path | None = None, frames: int | None = None, **scene_options):
    """Opens the viewer (`radiance-probes view`) on `data` as render() takes it, in a process of
    its own; with no display it renders headless to view.png and says so. `block=False` returns
    the process instead of waiting for the window to close."""
    built, volume = build_scene(data, scene, scene_options)
    folder = Path(tempfile.mkdtemp(prefix="radiance-probes-view-"))
    scene_data = scene_to_dict(built)
    if isinstance(data, (str, Path)) and built.volume.path is not None and built.base_dir:
        candidate = Path(built.base_dir) / built.volume.path
        if candidate.exists():
            scene_data["volume"]["path"] = str(candidate.resolve())
    if built.volume.path is None and built.volume.builtin is None:   # an array
        np.save(folder / "volume.npy", np.ascontiguousarray(volume.data))
        scene_data["volume"] = {"path": str(folder / "volume.npy"), "spacing": list(volume.spacing),
                                "value_range": [0.0, 1.0]}   # the array as the renderer holds it
    env = scene_data.get("environment")
    if isinstance(env, dict) and built.base_dir and not Path(env["map"]).is_absolute():
        env["map"] = str((Path(built.base_dir) / env["map"]).resolve())
    (folder / "scene.json").write_text(json.dumps(scene_data, indent=2))
    argv = [sys.executable, "-m", "radiance_probes", "view", str(folder / "scene.json"), "--method", method]
    if screenshot is not None:
        argv += ["--screenshot", str(screenshot)]
    if frames is not None:
        argv += ["--frames", str(int(frames))]
    if not block:
        return subprocess.Popen(argv)
    return subprocess.run(argv, check=False).returncode
