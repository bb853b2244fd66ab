"""The scene of SPEC.md parsed once from JSON into the frozen dataclasses of app/scene/types.py
(re-exported here, so ``from radiance_probes.io.scene_file import Scene`` keeps working).

Every field has a default, so ``{}`` is the built-in default scene. Unknown fields and bad values
raise :class:`SceneError` naming the field by its JSON path (``camera.fov_y``).
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any, Mapping

from radiance_probes.methods import VIEWER_METHODS
from radiance_probes.scene.flags import flag_for, with_flag
from radiance_probes.scene.types import (AXIS_LETTERS, CROP_UNITS, MAX_CHANNELS, ChannelSpec,
                                         channel_transfer_function, MAX_BOUNCES_LIMIT,
                                         MAX_IMAGE_SIDE, MAX_PROBE_AXIS, MAX_PROBE_SAMPLES,
                                         MAX_TRANSFER_ROWS, ORIENTATIONS, PROBE_FITS,
                                         PROBE_INDICATORS, PROBE_INTERPOLATIONS, PROBE_LAYOUTS,
                                         PROBE_PRECISIONS, SH_ORDERS, SH_WINDOWS, VIEWER_DISPLAYS,
                                         VIEWER_PROBE_VIEWS, WINDOW_PRESETS, BookmarkSpec,
                                         CameraSpec, ClipPlaneSpec, CropSpec, EnvironmentMapSpec,
                                         LightSpec, ProbeSpec, Scene, SceneError, SurfaceSpec,
                                         TransferFunctionSpec, ViewerSpec, VolumeSpec,
                                         scene_to_dict, MAX_GRADIENT_FACTOR, MIN_ROUGHNESS,
                                         AREA_LIGHT_SHAPES, MAX_AREA_LIGHTS, AreaLightSpec,
                                         transfer_to_dict, window_range)
from radiance_probes.scene.clinical_presets import (CLINICAL_PRESETS, expand as expand_clinical,
                                                    preset as clinical_preset)
from radiance_probes.scene.transfer import COLORMAPS
from radiance_probes.io.builtin_volumes import BUILTIN_VOLUMES
from radiance_probes.io.volume_files import RAW_DTYPES

__all__ = ["MAX_BOUNCES_LIMIT", "MAX_IMAGE_SIDE", "MAX_PROBE_AXIS", "MAX_PROBE_SAMPLES",
           "MAX_TRANSFER_ROWS", "ORIENTATIONS", "PROBE_FITS", "PROBE_INDICATORS", "PROBE_INTERPOLATIONS",
           "PROBE_LAYOUTS", "PROBE_PRECISIONS",
           "SH_WINDOWS", "WINDOW_PRESETS",
           "BookmarkSpec", "CameraSpec", "ChannelSpec", "MAX_CHANNELS", "ClipPlaneSpec", "CropSpec", "EnvironmentMapSpec",
           "ViewerSpec", "load_transfer_function", "parse_transfer_function",
           "save_transfer_function", "transfer_to_dict",
           "AreaLightSpec", "LightSpec", "ProbeSpec", "Scene", "SceneError", "SurfaceSpec",
           "TransferFunctionSpec",
           "VolumeSpec",
           "default_scene", "load_scene", "parse_scene", "scene_to_dict"]

# --------------------------------------------------------------------------------------------
# Value checks. Each names the field by its dotted JSON path.

def _number(value: Any, name: str, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, hi_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except OverflowError:  # a JSON integer too large for a float
        raise SceneError(f"{name}: must be finite, got {value!r}") from None
    if not math.isfinite(v):
        raise SceneError(f"{name}: must be finite, got {value!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise SceneError(f"{name}: must be {'>' if lo_open else '>='} {lo}, got {value!r}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise SceneError(f"{name}: must be {'<' if hi_open else '<='} {hi}, got {value!r}")
    return v


def _integer(value: Any, name: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not (isinstance(value, int) or
                                       (isinstance(value, float) and value.is_integer())):
        raise SceneError(f"{name}: expected an integer, got {value!r}")
    v = int(value)
    if not lo <= v <= hi:
        raise SceneError(f"{name}: must be in [{lo}, {hi}], got {value!r}")
    return v


def _vector(value: Any, name: str, n: int, **limits: Any) -> tuple:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SceneError(f"{name}: expected a list of {n} numbers, got {value!r}")
    return tuple(_number(v, f"{name}[{i}]", **limits) for i, v in enumerate(value))


def _choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value.lower() not in choices:
        raise SceneError(f"{name}: expected one of {', '.join(choices)}, got {value!r}"
                         f"{did_you_mean(value, choices)}")
    return value.lower()


def did_you_mean(word: Any, choices) -> str:
    """' (did you mean X?)' where a choice is close to the word (difflib's ratio 0.6 and up,
    case aside), else ''."""
    import difflib
    if not isinstance(word, str):
        return ""
    lowered = {str(c).lower(): str(c) for c in choices}
    close = difflib.get_close_matches(word.lower(), list(lowered), n=1, cutoff=0.6)
    return f" (did you mean {lowered[close[0]]}?)" if close else ""


def _object(value: Any, name: str, allowed: set[str]) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise SceneError(f"{name or 'scene'}: expected a JSON object, got {type(value).__name__}")
    unknown = sorted(set(value) - allowed)
    if unknown:
        where = f"{name}." if name else ""
        raise SceneError(f"unknown field {where}{unknown[0]}"
                         f"{did_you_mean(unknown[0], allowed - {'$schema'})} "
                         f"(allowed: {', '.join(sorted(allowed))})")
    return value


def _fields(cls) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def _parse_volume(d: Any) -> VolumeSpec:
    d = _object(d, "volume", _fields(VolumeSpec))
    if "path" in d and "builtin" in d:
        raise SceneError(f"volume: give either {with_flag('volume.path')} or "
                         f"{with_flag('volume.builtin')}, not both")
    kw: dict[str, Any] = {}
    if "path" in d:
        if not isinstance(d["path"], str) or not d["path"]:
            raise SceneError(f"volume.path: expected a file path, got {d['path']!r}")
        kw["path"], kw["builtin"] = d["path"], None
    if "builtin" in d:
        kw["builtin"] = _choice(d["builtin"], "volume.builtin", tuple(BUILTIN_VOLUMES))
    if "size" in d:
        if kw.get("path"):
            raise SceneError("volume.size: only for built-in volumes (use "
                             f"{with_flag('volume.dims')} for files)")
        kw["size"] = tuple(_integer(v, f"volume.size[{i}]", 1, 2048)
                           for i, v in enumerate(_vector(d["size"], "volume.size", 3)))
    if "spacing" in d:
        kw["spacing"] = _vector(d["spacing"], "volume.spacing", 3, lo=0.0, lo_open=True)
    if d.get("value_range") is not None:
        kw["value_range"] = _parse_value_range(d["value_range"], "volume.value_range")
    if d.get("window") is not None:
        if "value_range" in kw:
            raise SceneError(f"volume.window: give either {with_flag('volume.window')} or "
                             f"{with_flag('volume.value_range')}, "
                             "not both")
        kw["window"] = _parse_window(d["window"])
    if d.get("dims") is not None:
        kw["dims"] = tuple(_integer(v, f"volume.dims[{i}]", 1, 1 << 20)
                           for i, v in enumerate(_vector(d["dims"], "volume.dims", 3)))
    if d.get("dtype") is not None:
        kw["dtype"] = _choice(d["dtype"], "volume.dtype", tuple(RAW_DTYPES))
    if d.get("replace_nonfinite") is not None:
        kw["replace_nonfinite"] = _number(d["replace_nonfinite"], "volume.replace_nonfinite")
    if d.get("rescale") is not None:
        slope, intercept = _vector(d["rescale"], "volume.rescale", 2)
        if slope == 0.0:
            raise SceneError("volume.rescale: the slope must not be 0 (stored values to data units "
                             "as value * slope + intercept)")
        kw["rescale"] = (slope, intercept)
    if d.get("series") is not None:
        if not kw.get("path"):
            raise SceneError("volume.series: only for a DICOM folder or DICOMDIR "
                             f"({with_flag('volume.path')})")
        kw["series"] = _series(d["series"])
    if "orientation" in d:
        kw["orientation"] = _choice(d["orientation"], "volume.orientation", ORIENTATIONS)
    if d.get("axes") is not None:
        if not kw.get("path"):
            raise SceneError("volume.axes: only for files (a built-in volume is one channel, z, y, x)")
        kw["axes"] = _parse_axes(d["axes"])
    return VolumeSpec(**kw)


def _series(value: Any) -> int | str:
    """A DICOM series: its number in the listing (from 1) or its SeriesInstanceUID."""
    if isinstance(value, bool) or not isinstance(value, (int, str)) or (
            isinstance(value, int) and value < 1) or (isinstance(value, str) and not value.strip()):
        raise SceneError(f"volume.series: expected a series number from 1 or a "
                         f"SeriesInstanceUID, got {value!r}")
    if isinstance(value, str) and value.strip().isdigit():
        return int(value)
    return value.strip() if isinstance(value, str) else value


def _parse_window(w: Any, name: str = "volume.window") -> tuple[float, float]:
    """A CT/MRI window: a preset name or {"level": L, "width": W} in data units."""
    if isinstance(w, str):
        return WINDOW_PRESETS[_choice(w, name, tuple(WINDOW_PRESETS))]
    w = _object(w, name, {"level", "width"})
    if set(w) != {"level", "width"}:
        raise SceneError(f"{name}: needs both level and width (or a preset: "
                         f"{', '.join(WINDOW_PRESETS)})")
    level = _number(w["level"], f"{name}.level")
    width = _number(w["width"], f"{name}.width", lo=0.0, lo_open=True)
    lo, hi = window_range(level, width)
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise SceneError(f"{name}: level {level:g} and width {width:g} give no finite range")
    return (level, width)


def _parse_value_range(value: Any, name: str) -> tuple[float, float]:
    lo, hi = _vector(value, name, 2)
    if not hi > lo:
        raise SceneError(f"{name}: needs min < max, got {[lo, hi]}")
    return (lo, hi)


def _parse_axes(value: Any) -> str:
    """volume.axes: the array's axes by letter, e.g. "czyx" (t, c, z, y, x; each once)."""
    if not isinstance(value, str) or not value:
        raise SceneError(f"volume.axes: expected a string of axis letters such as \"czyx\", "
                         f"got {value!r}")
    text = value.lower()
    if not re.fullmatch(r"([a-z?][0-9]*)+", text) or re.search(r"(^|[a-z])0", text):
        raise SceneError(f"volume.axes: expected axis letters, each with its count where a page "
                         f"axis is split (\"c3zyx\"), got {value!r}")
    axes = re.sub(r"[0-9]+", "", text)
    unknown = sorted(set(axes) - set(AXIS_LETTERS))
    if unknown:
        raise SceneError(f"volume.axes: unknown axis {unknown[0]!r} in {value!r} (letters: t time, "
                         "c channel, z, y, x)")
    twice = sorted(a for a in set(axes) if axes.count(a) > 1)
    if twice:
        raise SceneError(f"volume.axes: axis {twice[0]!r} appears twice in {value!r}")
    missing = [a for a in "zyx" if a not in axes]
    if missing:
        raise SceneError(f"volume.axes: {value!r} lacks {', '.join(missing)} (a volume always has "
                         "z, y and x)")
    return text


def _parse_channels(d: Any, has_transfer_function: bool,
                    base_dir: str | Path | None = None) -> tuple[ChannelSpec, ...]:
    """[{"name": ..., "index": i, "enabled": true, "transfer_function": {...}, "value_range":
    [lo, hi] | "window": {...}}, ...]: 1 to MAX_CHANNELS channels, at least one switched on."""
    if not isinstance(d, (list, tuple)):
        raise SceneError(f"channels: expected a list of channels, got {d!r}")
    if not d:
        raise SceneError("channels: no channels to show (the list is empty; leave the key out "
                         "for a one-channel volume)")
    if len(d) > MAX_CHANNELS:
        raise SceneError(f"channels: {len(d)} channels, at most {MAX_CHANNELS} are shown at once "
                         f"(choose them with channels[i].index, {flag_for('channels')})")
    if has_transfer_function:
        raise SceneError("transfer_function: a scene with channels gives each channel its own "
                         f"({with_flag('channels[i].transfer_function')}), not one for the "
                         "scene")
    out, seen = [], {}
    for i, c in enumerate(d):
        name = f"channels[{i}]"
        c = _object(c, name, _fields(ChannelSpec))
        kw: dict[str, Any] = {}
        if c.get("name") is not None:
            if not isinstance(c["name"], str):
                raise SceneError(f"{name}.name: expected a text, got {c['name']!r}")
            kw["name"] = c["name"]
        if c.get("index") is not None:
            kw["index"] = _integer(c["index"], f"{name}.index", 0, 1 << 16)
        index = kw.get("index", i)
        if index in seen:
            raise SceneError(f"{name}.index: the file's channel {index} is already "
                             f"channels[{seen[index]}]")
        seen[index] = i
        if "enabled" in c:
            kw["enabled"] = _boolean(c["enabled"], f"{name}.enabled")
        if c.get("value_range") is not None:
            kw["value_range"] = _parse_value_range(c["value_range"], f"{name}.value_range")
        if c.get("window") is not None:
            if "value_range" in kw:
                raise SceneError(f"{name}.window: give either {name}.window or "
                                 f"{name}.value_range, not both")
            kw["window"] = _parse_window(c["window"], f"{name}.window")
        tf = c.get("transfer_function")
        if tf is None:
            kw["transfer_function"] = channel_transfer_function(i)
        elif isinstance(tf, str):   # a transfer-function file, relative to the scene's folder
            kw["transfer_function"] = _transfer_file(tf, base_dir, f"{name}.transfer_function")
        else:
            kw["transfer_function"] = _parse_transfer(tf, f"{name}.transfer_function")
        out.append(ChannelSpec(**kw))
    if not any(c.enabled for c in out):
        raise SceneError("channels: no channels to show (every channel has enabled false; switch "
                         "one on)")
    return tuple(out)


def _parse_transfer(d: Any, name: str = "transfer_function",
                    preset_domain: tuple[float, float] | None = None) -> TransferFunctionSpec:
    """`preset_domain`: the data values the volume maps to densities 0 and 1, which a clinical
    preset's Hounsfield units are placed by (None: no preset may be given here)."""
    d = _object(d, name, _fields(TransferFunctionSpec))
    kw: dict[str, Any] = {}
    if "preset" in d:
        others = sorted(set(d) & {"colormap", "colors", "opacity", "rgba"})
        if others:
            raise SceneError(f"{name}.preset: a clinical preset gives the colours and opacity; "
                             f"give it or {name}.{others[0]}, not both")
        if preset_domain is None:
            raise SceneError(f"{name}.preset: clinical presets are for the scene's one "
                             "transfer_function of a one-channel volume (not a channel's, not a "
                             "transfer-function file)")
        label = _choice(d["preset"], f"{name}.preset", tuple(CLINICAL_PRESETS))
        colors, opacity = expand_clinical(label, preset_domain)
        kw.update(colors=colors, opacity=opacity, preset=label)
    if "rgba" in d and ("colormap" in d or "opacity" in d or "colors" in d):
        raise SceneError(f"{name}: give either rgba rows or colormap/colors and opacity, not both")
    if "colormap" in d and "colors" in d:
        raise SceneError(f"{name}: give either a colormap or colour points (colors), not both")
    if "colors" in d:
        pts = d["colors"]
        if not isinstance(pts, (list, tuple)) or not 1 <= len(pts) <= MAX_TRANSFER_ROWS:
            raise SceneError(f"{name}.colors: expected a list of 1 to {MAX_TRANSFER_ROWS} "
                             "[density, r, g, b] points")
        parsed = tuple(_vector(p, f"{name}.colors[{i}]", 4, lo=0.0, hi=1.0)
                       for i, p in enumerate(pts))
        xs = [p[0] for p in parsed]
        if any(b < a for a, b in zip(xs, xs[1:])):
            raise SceneError(f"{name}.colors: densities must not decrease")
        kw["colors"] = parsed
    if "colormap" in d:
        kw["colormap"] = _choice(d["colormap"], f"{name}.colormap", tuple(COLORMAPS))
    if "opacity" in d:
        pts = d["opacity"]
        if not isinstance(pts, (list, tuple)) or len(pts) < 1:
            raise SceneError(f"{name}.opacity: expected a list of [density, opacity] points")
        parsed = tuple(_vector(p, f"{name}.opacity[{i}]", 2, lo=0.0, hi=1.0)
                       for i, p in enumerate(pts))
        xs = [p[0] for p in parsed]
        if any(b < a for a, b in zip(xs, xs[1:])):
            raise SceneError(f"{name}.opacity: densities must not decrease")
        kw["opacity"] = parsed
    if "rgba" in d:
        rows = d["rgba"]
        if not isinstance(rows, (list, tuple)) or not 2 <= len(rows) <= MAX_TRANSFER_ROWS:
            raise SceneError(f"{name}.rgba: expected 2 to {MAX_TRANSFER_ROWS} rows of "
                             "[r, g, b, a]")
        kw["rgba"] = tuple(_vector(r, f"{name}.rgba[{i}]", 4, lo=0.0, hi=1.0)
                           for i, r in enumerate(rows))
    if "resolution" in d:
        kw["resolution"] = _integer(d["resolution"], f"{name}.resolution", 2,
                                    MAX_TRANSFER_ROWS)
    return TransferFunctionSpec(**kw)


def _boolean(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise SceneError(f"{name}: expected true or false, got {value!r}")
    return value


def _parse_crop(d: Any) -> CropSpec:
    """{"min": [x, y, z], "max": [x, y, z], "units": "world" | "voxels", "enabled": true}."""
    d = _object(d, "crop", _fields(CropSpec))
    for key in ("min", "max"):
        if key not in d:
            raise SceneError(f"crop.{key}: missing (a crop box needs both min and max corners)")
    units = _choice(d.get("units", "world"), "crop.units", CROP_UNITS)
    if units == "voxels":
        lo = tuple(_integer(v, f"crop.min[{i}]", 0, 1 << 20)
                   for i, v in enumerate(_vector(d["min"], "crop.min", 3)))
        hi = tuple(_integer(v, f"crop.max[{i}]", 0, 1 << 20)
                   for i, v in enumerate(_vector(d["max"], "crop.max", 3)))
    else:
        lo, hi = _vector(d["min"], "crop.min", 3), _vector(d["max"], "crop.max", 3)
    for i, axis in enumerate("xyz"):
        if not hi[i] > lo[i]:
            raise SceneError(f"crop.max[{i}]: must be > crop.min[{i}] (the box's {axis} extent; "
                             f"{flag_for('crop')}), "
                             f"got min {lo[i]:g}, max {hi[i]:g}")
    enabled = _boolean(d.get("enabled", True), "crop.enabled")
    return CropSpec(min=lo, max=hi, units=units, enabled=enabled)


def _parse_clip_plane(d: Any) -> ClipPlaneSpec:
    """{"normal": [nx, ny, nz], "distance": d, "enabled": true}: keeps dot(normal, x) <= d."""
    d = _object(d, "clip_plane", _fields(ClipPlaneSpec))
    if "normal" not in d:
        raise SceneError("clip_plane.normal: missing (the plane keeps the points x with "
                         "dot(normal, x) <= distance)")
    normal = _vector(d["normal"], "clip_plane.normal", 3)
    if math.sqrt(sum(c * c for c in normal)) < 1e-9:
        raise SceneError("clip_plane.normal: must not be the zero vector")
    distance = _number(d.get("distance", 0.0), "clip_plane.distance")
    enabled = _boolean(d.get("enabled", True), "clip_plane.enabled")
    return ClipPlaneSpec(normal=normal, distance=distance, enabled=enabled)


def _check_view(eye, target, up, name: str) -> None:
    """A view direction (target - eye) that exists and an up vector not parallel to it."""
    forward = [t - e for t, e in zip(target, eye)]
    if math.sqrt(sum(c * c for c in forward)) < 1e-9:
        raise SceneError(f"{name}.target: must differ from {name}.eye")
    cross = (forward[1] * up[2] - forward[2] * up[1], forward[2] * up[0] - forward[0] * up[2],
             forward[0] * up[1] - forward[1] * up[0])
    # |forward x up| = |forward| |up| sin(angle): reject sin(angle) < 1e-6 whatever the lengths.
    norm_f = math.sqrt(sum(c * c for c in forward))
    norm_u = math.sqrt(sum(c * c for c in up))
    if norm_u < 1e-12 or math.sqrt(sum(c * c for c in cross)) < 1e-6 * norm_f * norm_u:
        raise SceneError(f"{name}.up: must not be zero or parallel to the view direction")


def _parse_bookmarks(d: Any) -> tuple[BookmarkSpec, ...]:
    """[{"name": "front", "eye": [...], "target": [...], "up": [...], "fov_y": 35}, ...]."""
    if not isinstance(d, (list, tuple)):
        raise SceneError(f"bookmarks: expected a list of cameras with names, got {d!r}")
    out, seen = [], set()
    for i, b in enumerate(d):
        name = f"bookmarks[{i}]"
        b = _object(b, name, _fields(BookmarkSpec))
        label = b.get("name")
        if not isinstance(label, str) or not label.strip():
            raise SceneError(f"{name}.name: expected a non-empty name, got {label!r}")
        if label in seen:
            raise SceneError(f"{name}.name: {label!r} is used twice (names are unique)")
        seen.add(label)
        if "eye" not in b:
            raise SceneError(f"{name}.eye: missing")
        kw: dict[str, Any] = {"name": label}
        for key in ("eye", "target", "up"):
            if key in b:
                kw[key] = _vector(b[key], f"{name}.{key}", 3)
        if "fov_y" in b:
            kw["fov_y"] = _number(b["fov_y"], f"{name}.fov_y", 0.0, 179.0, lo_open=True)
        spec = BookmarkSpec(**kw)
        _check_view(spec.eye, spec.target, spec.up, name)
        out.append(spec)
    return tuple(out)


def _parse_viewer(d: Any) -> ViewerSpec:
    d = _object(d, "viewer", _fields(ViewerSpec))
    kw: dict[str, Any] = {}
    for key, choices in (("method", VIEWER_METHODS), ("split_method", VIEWER_METHODS),
                         ("display", VIEWER_DISPLAYS), ("probe_view", VIEWER_PROBE_VIEWS)):
        if key in d:
            kw[key] = _choice(d[key], f"viewer.{key}", choices)
    if "exposure" in d:
        kw["exposure"] = _number(d["exposure"], "viewer.exposure", 0.0, 1e6, lo_open=True)
    if "show_box" in d:
        kw["show_box"] = _boolean(d["show_box"], "viewer.show_box")
    return ViewerSpec(**kw)


def parse_transfer_function(data: Any, name: str = "transfer_function") -> TransferFunctionSpec:
    """A transfer function from JSON data (the scene's transfer_function key, or a file's)."""
    return _parse_transfer(data, name)


def load_transfer_function(path: str | Path) -> TransferFunctionSpec:
    """A transfer function kept on its own: a JSON file holding what a scene's transfer_function
    key holds. Errors name the file and the field."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise SceneError(f"transfer function file not found: {p}")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise SceneError(f"{p}: not a valid JSON transfer function ({exc})") from None
    except OSError as exc:
        raise SceneError(f"{p}: cannot read the transfer function ({exc})") from None
    try:
        return _parse_transfer(data, "transfer_function")
    except SceneError as exc:
        raise SceneError(f"{p}: {exc}") from None


def save_transfer_function(path: str | Path, spec: TransferFunctionSpec) -> Path:
    """Writes the transfer function as JSON (load_transfer_function reads it back equal)."""
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(transfer_to_dict(spec), indent=2) + "\n", encoding="utf-8")
    return p


def _parse_light(d: Any) -> LightSpec:
    d = _object(d, "light", _fields(LightSpec))
    kw: dict[str, Any] = {}
    if "direction" in d:
        v = _vector(d["direction"], "light.direction", 3)
        n = math.sqrt(sum(c * c for c in v))
        if n < 1e-9:
            raise SceneError("light.direction: must not be the zero vector")
        kw["direction"] = v  # LightSpec normalises it
    if "irradiance" in d:
        kw["irradiance"] = _vector(d["irradiance"], "light.irradiance", 3, lo=0.0)
    return LightSpec(**kw)


def _parse_environment(d: Any) -> dict[str, Any]:
    """[r, g, b] (a constant) or {"map": FILE, "scale": s, "rotation": degrees} (SPEC.md)."""
    if isinstance(d, str):
        raise SceneError(f"environment: expected [r, g, b] or {{\"map\": FILE, \"scale\": s, "
                         f"\"rotation\": degrees}}, got {d!r}")
    if not isinstance(d, Mapping):
        return {"environment": _vector(d, "environment", 3, lo=0.0)}
    d = _object(d, "environment", {"map", "scale", "rotation"})
    if not isinstance(d.get("map"), str) or not d["map"]:
        raise SceneError(f"environment.map: expected a file path, got {d.get('map')!r}")
    kw: dict[str, Any] = {"path": d["map"]}
    if "scale" in d:
        kw["scale"] = _number(d["scale"], "environment.scale", 0.0, 1e7)
    if "rotation" in d:
        kw["rotation"] = _number(d["rotation"], "environment.rotation", -360.0, 360.0)
    return {"environment_map": EnvironmentMapSpec(**kw)}


def _parse_camera(d: Any) -> CameraSpec:
    d = _object(d, "camera", _fields(CameraSpec))
    kw: dict[str, Any] = {}
    for key in ("eye", "target", "up"):
        if key in d:
            kw[key] = _vector(d[key], f"camera.{key}", 3)
    if "fov_y" in d:
        kw["fov_y"] = _number(d["fov_y"], "camera.fov_y", 0.0, 179.0, lo_open=True)
    for key in ("width", "height"):
        if key in d:
            kw[key] = _integer(d[key], f"camera.{key}", 1, MAX_IMAGE_SIDE)
    cam = CameraSpec(**kw)
    _check_view(cam.eye, cam.target, cam.up, "camera")
    return cam


def _parse_probes(d: Any) -> ProbeSpec:
    d = _object(d, "probes", _fields(ProbeSpec))
    kw: dict[str, Any] = {}
    if "grid" in d:
        g = d["grid"]
        if isinstance(g, (int, float)) and not isinstance(g, bool):
            g = [g, g, g]
        if not isinstance(g, (list, tuple)) or len(g) != 3:
            raise SceneError(f"probes.grid: expected an integer or a list of 3, got {g!r}")
        kw["grid"] = tuple(_integer(v, f"probes.grid[{i}]", 1, MAX_PROBE_AXIS) for i, v in enumerate(g))
    if "samples" in d:
        kw["samples"] = _integer(d["samples"], "probes.samples", 1, MAX_PROBE_SAMPLES)
    if "sh_window" in d:
        kw["sh_window"] = _choice(d["sh_window"], "probes.sh_window", SH_WINDOWS)
    if "precision" in d:
        kw["precision"] = _choice(d["precision"], "probes.precision", PROBE_PRECISIONS)
    if "sh_order" in d:
        order = d["sh_order"]
        if order != "auto" and (isinstance(order, bool) or order not in SH_ORDERS):
            raise SceneError(f"probes.sh_order: expected \"auto\" or 0 to 4, got {order!r}")
        kw["sh_order"] = order if order == "auto" else int(order)
    if "fit" in d:
        kw["fit"] = _choice(d["fit"], "probes.fit", PROBE_FITS)
    if "channels" in d:
        ch = d["channels"]
        if ch != "auto" and (isinstance(ch, bool) or ch not in (1, 3)):
            raise SceneError(f"probes.channels: expected \"auto\", 1 or 3, got {ch!r}")
        kw["channels"] = ch if ch == "auto" else int(ch)
    if "layout" in d:
        kw["layout"] = _choice(d["layout"], "probes.layout", PROBE_LAYOUTS)
    if "adaptive_strength" in d:
        kw["adaptive_strength"] = _number(d["adaptive_strength"], "probes.adaptive_strength", 0.0, 1.0)
    if "adaptive_indicator" in d:
        kw["adaptive_indicator"] = _choice(d["adaptive_indicator"], "probes.adaptive_indicator",
                                           PROBE_INDICATORS)
    if "interpolation" in d:
        kw["interpolation"] = _choice(d["interpolation"], "probes.interpolation",
                                      PROBE_INTERPOLATIONS)
    return ProbeSpec(**kw)


def _parse_surface(d: Any) -> SurfaceSpec:
    """{"gradient_factor": k, "roughness": alpha, "specular": [r, g, b]} (SurfaceSpec)."""
    d = _object(d, "surface", _fields(SurfaceSpec))
    kw: dict[str, Any] = {}
    if "gradient_factor" in d:
        kw["gradient_factor"] = _number(d["gradient_factor"], "surface.gradient_factor", 0.0,
                                        MAX_GRADIENT_FACTOR)
    if "roughness" in d:
        kw["roughness"] = _number(d["roughness"], "surface.roughness", MIN_ROUGHNESS, 1.0)
    if "specular" in d:
        kw["specular"] = _vector(d["specular"], "surface.specular", 3, lo=0.0, hi=1.0)
    return SurfaceSpec(**kw)


def _parse_area_lights(d: Any) -> tuple[AreaLightSpec, ...]:
    """[{"shape": "sphere" | "rectangle", "position": [x, y, z], "size": r | [w, h],
    "colour": [r, g, b], "strength": s, "normal": [nx, ny, nz], "enabled": true}, ...]. Whether a
    light stays outside the volume box is checked against the volume (app/scene/area_lights.py)."""
    if not isinstance(d, (list, tuple)):
        raise SceneError(f"area_lights: expected a list of lights, got {d!r}")
    if len(d) > MAX_AREA_LIGHTS:
        raise SceneError(f"area_lights: {len(d)} lights, at most {MAX_AREA_LIGHTS}")
    out = []
    for i, light in enumerate(d):
        name = f"area_lights[{i}]"
        light = _object(light, name, _fields(AreaLightSpec))
        for key in ("shape", "position", "size"):
            if key not in light:
                raise SceneError(f"{name}.{key}: missing (a light needs its shape, position and "
                                 "size)")
        kw: dict[str, Any] = {"shape": _choice(light["shape"], f"{name}.shape",
                                               AREA_LIGHT_SHAPES)}
        kw["position"] = _vector(light["position"], f"{name}.position", 3)
        if kw["shape"] == "sphere":
            kw["size"] = _number(light["size"], f"{name}.size", 0.0, 1e6, lo_open=True)
        else:
            kw["size"] = _vector(light["size"], f"{name}.size", 2, lo=0.0, hi=1e6, lo_open=True)
        if "colour" in light:
            kw["colour"] = _vector(light["colour"], f"{name}.colour", 3, lo=0.0, hi=1.0)
        if "strength" in light:
            kw["strength"] = _number(light["strength"], f"{name}.strength", 0.0, 1e9)
        if "normal" in light:
            normal = _vector(light["normal"], f"{name}.normal", 3)
            if math.sqrt(sum(c * c for c in normal)) < 1e-9:
                raise SceneError(f"{name}.normal: must not be the zero vector")
            kw["normal"] = normal
        if "enabled" in light:
            kw["enabled"] = _boolean(light["enabled"], f"{name}.enabled")
        out.append(AreaLightSpec(**kw))
    return tuple(out)


def preset_surface(name: str) -> SurfaceSpec:
    """The surface a clinical preset shades with."""
    p = clinical_preset(name)
    return SurfaceSpec(gradient_factor=p.gradient_factor, roughness=p.roughness,
                       specular=tuple(p.specular))


def _transfer_file(path: str, base_dir: str | Path | None, name: str) -> TransferFunctionSpec:
    p = Path(path).expanduser()
    if not p.is_absolute() and base_dir is not None:
        p = Path(base_dir) / p
    try:
        return load_transfer_function(p)
    except SceneError as exc:
        raise SceneError(f"{name}: {exc}") from None


# Volume keys a scene may also give at its top level, as SPEC.md writes them ("orientation":
# "patient"; "series" of a DICOM folder): the same as volume.orientation and volume.series.
TOP_LEVEL_VOLUME_KEYS = ("orientation", "series")


def parse_scene(data: Any, base_dir: str | Path | None = None) -> Scene:
    """Validate a JSON-like dictionary into a :class:`Scene`."""
    d = _object(data, "", (_fields(Scene) - {"base_dir", "environment_map"})
                | set(TOP_LEVEL_VOLUME_KEYS) | {"$schema"})
    if "$schema" in d and not isinstance(d["$schema"], str):   # for editors; nothing else reads it
        raise SceneError(f"$schema: expected the schema's address, got {d['$schema']!r}")
    kw: dict[str, Any] = {}
    lifted = {k: d[k] for k in TOP_LEVEL_VOLUME_KEYS if k in d}
    if lifted:
        volume = d.get("volume", {})
        if isinstance(volume, Mapping):
            both = sorted(set(lifted) & set(volume))
            if both:
                raise SceneError(f"{both[0]}: given both at the top level and as volume.{both[0]}; "
                                 "give it once")
            d = {**d, "volume": {**volume, **lifted}}
    if "volume" in d:
        kw["volume"] = _parse_volume(d["volume"])
    if "transfer_function" in d:
        tf = d["transfer_function"]
        if isinstance(tf, str):   # a transfer-function file, relative to the scene's folder
            kw["transfer_function"] = _transfer_file(tf, base_dir, "transfer_function")
        elif isinstance(tf, Mapping) and "preset" in tf and d.get("channels") is None:
            # A clinical preset is placed by the volume's window; with none given, the preset's
            # own window becomes the volume's.
            volume = kw.get("volume", VolumeSpec())
            if volume.domain is None:
                name = _choice(tf["preset"], "transfer_function.preset", tuple(CLINICAL_PRESETS))
                lo, hi = clinical_preset(name).window
                volume = dataclasses.replace(volume, window=(0.5 * (lo + hi), hi - lo))
                kw["volume"] = volume
            kw["transfer_function"] = _parse_transfer(tf, preset_domain=volume.domain)
        else:
            kw["transfer_function"] = _parse_transfer(tf)
    if "density_scale" in d:
        kw["density_scale"] = _number(d["density_scale"], "density_scale", 0.0, 1e7)
    if "albedo" in d:
        kw["albedo"] = _number(d["albedo"], "albedo", 0.0, 1.0)
    if "anisotropy" in d:
        kw["anisotropy"] = _number(d["anisotropy"], "anisotropy", -1.0, 1.0, lo_open=True, hi_open=True)
    kw["light"] = _parse_light(d.get("light", {}))
    if "environment" in d:
        kw.update(_parse_environment(d["environment"]))
    if "max_bounces" in d:
        kw["max_bounces"] = _integer(d["max_bounces"], "max_bounces", 0, MAX_BOUNCES_LIMIT)
    kw["camera"] = _parse_camera(d.get("camera", {}))
    if "probes" in d:
        kw["probes"] = _parse_probes(d["probes"])
    if d.get("area_lights") is not None:
        kw["area_lights"] = _parse_area_lights(d["area_lights"])
    if d.get("surface") is not None:
        kw["surface"] = _parse_surface(d["surface"])
    elif kw.get("transfer_function") is not None and kw["transfer_function"].preset is not None:
        kw["surface"] = preset_surface(kw["transfer_function"].preset)   # the preset's shading
    if d.get("crop") is not None:
        kw["crop"] = _parse_crop(d["crop"])
    if d.get("clip_plane") is not None:
        kw["clip_plane"] = _parse_clip_plane(d["clip_plane"])
    if d.get("bookmarks") is not None:
        kw["bookmarks"] = _parse_bookmarks(d["bookmarks"])
    if d.get("viewer") is not None:
        kw["viewer"] = _parse_viewer(d["viewer"])
    if d.get("time") is not None:
        kw["time"] = _integer(d["time"], "time", 0, 1 << 24)
    if d.get("channels") is not None:
        kw["channels"] = _parse_channels(d["channels"], "transfer_function" in d, base_dir)
    if base_dir is not None:
        kw["base_dir"] = str(base_dir)
    return Scene(**kw)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file."""
    p = Path(path)
    if not p.is_file():
        raise SceneError(f"scene file not found: {p}")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SceneError(f"{p}: not valid JSON ({exc})") from None
    except UnicodeDecodeError as exc:
        raise SceneError(f"{p}: not a UTF-8 text file ({exc})") from None
    except OSError as exc:
        raise SceneError(f"{p}: cannot read the scene file ({exc})") from None
    except RecursionError:
        raise SceneError(f"{p}: not valid JSON (nested too deeply)") from None
    try:
        return parse_scene(data, base_dir=p.resolve().parent)
    except SceneError as exc:
        raise SceneError(f"{p}: {exc}") from None


def default_scene() -> Scene:
    return parse_scene({})
