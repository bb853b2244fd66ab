"""What both front ends (the CLI's ``render`` and the viewer, ``view``) share: the scene named on the
command line with its options applied, the option types that check each value as it is parsed,
the output checks made before a long render, and the render-to-files run itself.

The rule: every option and scene value is checked before any GPU work, and a bad one ends in one
line naming the option (or the scene field) and the problem. Values are checked where they are
parsed (argument types below; the scene's fields in app/io/scene_file.py); what depends on the device
(image sizes against its GL limits) right after the context exists and before the scene is
uploaded (app/rendering/limits.py); where the outputs go before the render starts. A render whose
output cannot be written at the end is not lost: it is written elsewhere and the error says where.
"""
from __future__ import annotations

import argparse
import json
import math
import re
from dataclasses import replace
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from radiance_probes.methods import METHODS
from radiance_probes.io.scene_file import (Scene, SceneError, TransferFunctionSpec, default_scene,
                                           load_scene, parse_scene, scene_to_dict, transfer_to_dict)

MAX_SPP = (1 << 31) - 1        # samples per pixel reach the shaders as a 32-bit uniform
MAX_WINDOW_SIDE = 16384
MAX_RENDER_SCALE = 4.0
DEFAULT_RAYMARCH_STEP = 0.5    # voxels; --raymarch-step's default (None: not given)


class OptionError(ValueError):
    """A command-line option that cannot work (a path that cannot be written, a bad combination);
    the message names the option."""


# ---- argument types: each checks its value as argparse parses it ------------------------------

def positive_int(text: str, limit: int = MAX_SPP) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 1 <= v <= limit:
        raise argparse.ArgumentTypeError(f"expected an integer from 1 to {limit}, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0 (exposures, steps, scales): nan, inf, 0 and negatives are refused."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def fraction(text: str) -> float:
    """A finite number in (0, 1] (a relative error target)."""
    v = positive_float(text)
    if v > 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1], got {text!r}")
    return v


def render_scale(text: str) -> float:
    """Render pixels per window pixel: finite, in (0, MAX_RENDER_SCALE]."""
    v = positive_float(text)
    if v > MAX_RENDER_SCALE:
        raise argparse.ArgumentTypeError(f"expected a number in (0, {MAX_RENDER_SCALE}], got {text!r}")
    return v


def grid_arg(text: str) -> list[int]:
    parts = text.split(",")
    if len(parts) not in (1, 3):
        raise argparse.ArgumentTypeError(f"expected N or NX,NY,NZ, got {text!r}")
    values = [positive_int(p) for p in parts]
    return values * 3 if len(values) == 1 else values


def window_size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        size = (0, 0)
    if not sep or min(size) < 64 or max(size) > MAX_WINDOW_SIDE:
        raise argparse.ArgumentTypeError(f"expected WxH from 64x64 to {MAX_WINDOW_SIDE}x"
                                         f"{MAX_WINDOW_SIDE}, got {text!r}")
    return size


class ArgumentParser(argparse.ArgumentParser):
    """argparse with its errors as one line (``radiance-probes render: error: ...``), exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


# ---- the scene ---------------------------------------------------------------------------------

def series_arg(text: str) -> int | str:
    """--series: a number in the folder's listing (from 1) or a SeriesInstanceUID."""
    text = text.strip()
    if text.isdigit():
        if int(text) < 1:
            raise argparse.ArgumentTypeError(f"expected a series number from 1 or a "
                                             f"SeriesInstanceUID, got {text!r}")
        return int(text)
    if not text:
        raise argparse.ArgumentTypeError("expected a series number or a SeriesInstanceUID")
    return text


def window_arg(text: str) -> str | dict:
    """--window: a preset name (soft_tissue, bone, lung, air) or LEVEL,WIDTH in data units."""
    from radiance_probes.scene.types import WINDOW_PRESETS
    if text.strip().lower() in WINDOW_PRESETS:
        return text.strip().lower()
    parts = text.split(",")
    try:
        level, width = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a preset ({', '.join(WINDOW_PRESETS)}) or "
                                         f"LEVEL,WIDTH, got {text!r}") from None
    return {"level": level, "width": width}


def add_volume_options(parser: argparse.ArgumentParser) -> None:
    """The options that say how a volume file is read (render and view)."""
    from radiance_probes.scene.types import ORIENTATIONS
    parser.add_argument("--series", type=series_arg, metavar="N|UID",
                        help="a DICOM folder or DICOMDIR's series: its number in the listing "
                             "(`radiance-probes series PATH`) or its SeriesInstanceUID (default: "
                             "the largest that makes a volume)")
    parser.add_argument("--data-window", dest="data_window", type=window_arg,
                        metavar="PRESET|LEVEL,WIDTH",
                        help="the values shown, as radiology gives them: soft_tissue, bone, lung, "
                             "air, or level and width in data units (Hounsfield units for CT)")
    parser.add_argument("--orientation", choices=ORIENTATIONS,
                        help="data: the array's axes as stored (default); patient: turned so that "
                             "+x is the patient's left, +y superior, +z anterior (NIfTI, DICOM, "
                             "NRRD)")


def scene_from_arg(arg: str | None) -> Scene:
    """The scene argument: a scene JSON file, a volume file (in the default scene), or none (the
    default scene)."""
    if arg is None:
        return default_scene()
    p = Path(arg)
    if p.suffix.lower() == ".json":
        return load_scene(p)
    return parse_scene({"volume": {"path": str(p)}})


# ---- scene keys on the command line: --set KEY=VALUE and the named flags ----------------------

def _numbers(text: str, n: int | None, what: str) -> list[float]:
    """`n` finite numbers separated by commas (any count where n is None)."""
    try:
        values = [float(t) for t in text.replace(" ", "").split(",")]
    except ValueError:
        values = []
    if not values or (n is not None and len(values) != n) or not all(map(math.isfinite, values)):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return values


def spacing_arg(text: str) -> list[float]:
    """--spacing: X,Y,Z voxel sizes > 0 (or one size for all three)."""
    values = _numbers(text, None, "X,Y,Z: three voxel sizes > 0 (or one for all three)")
    if len(values) == 1:
        values *= 3
    if len(values) != 3 or min(values) <= 0:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z: three voxel sizes > 0 (or one for all "
                                         f"three), got {text!r}")
    return values


def value_range_arg(text: str) -> list[float]:
    """--value-range: LO,HI data values, LO < HI."""
    lo, hi = _numbers(text, 2, "LO,HI: the data values shown as density 0 and 1")
    if not hi > lo:
        raise argparse.ArgumentTypeError(f"expected LO,HI with LO < HI, got {text!r}")
    return [lo, hi]


def dims_arg(text: str) -> list[int]:
    """--dims: X,Y,Z voxel counts of a .raw file."""
    values = _numbers(text, 3, "X,Y,Z: three voxel counts")
    if not all(v.is_integer() and v >= 1 for v in values):
        raise argparse.ArgumentTypeError(f"expected X,Y,Z: three whole voxel counts >= 1, got "
                                         f"{text!r}")
    return [int(v) for v in values]


def finite_float(text: str) -> float:
    return _numbers(text, 1, "a finite number")[0]


def time_arg(text: str) -> int:
    """--time: a time step from 0."""
    try:
        v = int(text)
    except ValueError:
        v = -1
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a time step 0, 1, 2, ..., got {text!r}")
    return v


def channel_arg(text: str) -> list[int]:
    """--channel: the file's channels to show, I or I,J,... from 0."""
    try:
        values = [int(t) for t in text.replace(" ", "").split(",")]
    except ValueError:
        values = []
    if not values or min(values) < 0 or len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"expected the file's channels to show, I or I,J,... "
                                         f"(from 0, each once), got {text!r}")
    return values


def opacity_arg(text: str) -> list[list[float]]:
    """--opacity: [density, opacity] points as D,A,D,A,... (or their JSON list), each in [0, 1],
    densities not decreasing."""
    expected = ("D,A,D,A,...: [density, opacity] points, each in [0, 1], densities not "
                "decreasing (e.g. 0,0,0.3,0,1,1)")
    try:
        data = json.loads(text)
        flat = [float(v) for point in data for v in point] if isinstance(data, list) else []
    except (ValueError, TypeError):
        flat = _numbers(text, None, expected)
    if not flat or len(flat) % 2 or not all(math.isfinite(v) and 0 <= v <= 1 for v in flat):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    points = [flat[i:i + 2] for i in range(0, len(flat), 2)]
    if any(b[0] < a[0] for a, b in zip(points, points[1:])):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return points


_SET_KEY = re.compile(r"[a-z_]+(\[\d+\])?(\.[a-z_]+(\[\d+\])?)*")


def set_value(text: str):
    """A --set value: JSON where it parses (1.5, [1, 1, 2], true, "text", {...}), else a comma
    list of numbers (1,1,2), else the text itself (czyx, grey)."""
    try:
        return json.loads(text)
    except ValueError:
        pass
    if "," in text:
        try:
            return [float(t) if not t.strip().lstrip("+-").isdigit() else int(t)
                    for t in text.split(",")]
        except ValueError:
            pass
    return text


def set_arg(text: str) -> tuple[str, object, str]:
    """--set KEY=VALUE: (the scene key, its value, the text given)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not _SET_KEY.fullmatch(key):
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE with a scene key of "
                                         f"docs/scene-format.md (e.g. --set volume.spacing=1,1,2), got "
                                         f"{text!r}")
    return key, set_value(value.strip()), text


def add_scene_key_options(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The flags that set scene keys (app/scene/flags.py names them in messages): --set for any
    key, and a flag of its own for the keys users set most."""
    from radiance_probes.scene.transfer import ALIASES, COLORMAPS
    from radiance_probes.io.volume_files import RAW_DTYPES
    parser.add_argument("--set", dest="set", action="append", type=set_arg, metavar="KEY=VALUE",
                        help="set any scene key (docs/scene-format.md), e.g. volume.spacing=1,1,2 "
                             "or transfer_function.colormap=grey; the value is read as JSON where "
                             "it parses, else as a comma list of numbers, else as text; repeatable, "
                             "applied after the other flags")
    parser.add_argument("--spacing", type=spacing_arg, metavar="X,Y,Z",
                        help="voxel size along x, y, z (volume.spacing; default: the file's, "
                             "else 1,1,1)")
    parser.add_argument("--value-range", type=value_range_arg, metavar="LO,HI",
                        help="the data values shown as density 0 and 1 (volume.value_range; "
                             "default: the data's range)")
    parser.add_argument("--dims", type=dims_arg, metavar="X,Y,Z",
                        help="a .raw file's voxels along x, y, z (volume.dims) where its name "
                             "does not say")
    parser.add_argument("--dtype", choices=tuple(RAW_DTYPES), metavar="TYPE",
                        help=f"a .raw file's sample type (volume.dtype): {', '.join(RAW_DTYPES)}")
    parser.add_argument("--axes", metavar="LETTERS",
                        help="which array axis is which, e.g. czyx (channels) or tzyx (time "
                             "steps); letters t, c, z, y, x (volume.axes)")
    parser.add_argument("--replace-nonfinite", type=finite_float, metavar="VALUE",
                        help="replace NaN and Inf voxels by this value (volume.replace_nonfinite; "
                             "default: refuse them)")
    parser.add_argument("--colormap", choices=COLORMAPS, metavar="NAME",
                        help="the transfer function's colours: "
                             f"{', '.join(c for c in COLORMAPS if c not in ALIASES)} "
                             "(transfer_function.colormap; also " +
                             ", ".join(f"{a} for {c}" for a, c in ALIASES.items()) + ")")
    parser.add_argument("--opacity", type=opacity_arg, metavar="D,A,D,A,...",
                        help="the transfer function's opacity as [density, opacity] points, "
                             "densities in [0, 1] over the value range (transfer_function.opacity; "
                             "default 0,0,0.2,0,1,1)")
    parser.add_argument("--time", type=time_arg, metavar="STEP",
                        help="the time step shown of a volume with a time axis, from 0 (time)")
    parser.add_argument("--channel", type=channel_arg, metavar="I[,J,...]",
                        help="the file's channels shown, from 0 (channels; default: all, at most "
                             "4)")
    return parser


# Each named flag: its argparse dest and the scene key it sets.
SCENE_KEY_FLAGS = {"spacing": "volume.spacing", "value_range": "volume.value_range",
                   "dims": "volume.dims", "dtype": "volume.dtype", "axes": "volume.axes",
                   "replace_nonfinite": "volume.replace_nonfinite",
                   "colormap": "transfer_function.colormap", "opacity": "transfer_function.opacity",
                   "time": "time", "channel": "channels"}
SCENE_KEY_DESTS = ("set", *SCENE_KEY_FLAGS)


def _set_key(data: dict, key: str, value, option: str) -> None:
    """Sets `key` (dotted, with [i] for list items) in the scene's JSON data; a key that excludes
    another in its object (volume.window and volume.value_range, a colormap and colour points)
    drops it; JSON null drops the key."""
    from radiance_probes.scene.flags import EXCLUDES
    parts = re.findall(r"([a-z_]+)(?:\[(\d+)\])?", key)
    node = data
    for depth, (name, index) in enumerate(parts):
        last = depth == len(parts) - 1
        if name == "transfer_function" and data.get("channels") and depth == 0:
            raise OptionError(f"{option}: the scene has channels, each with its own transfer "
                              "function: set one with --set channels[I].transfer_function."
                              f"{parts[-1][0] if len(parts) > 1 else 'colormap'}=...")
        if not isinstance(node, dict):
            raise OptionError(f"{option}: {key}: {'.'.join(p[0] for p in parts[:depth])} is not "
                              "an object of keys")
        if index:
            items = node.get(name)
            if not isinstance(items, list) or int(index) >= len(items):
                have = len(items) if isinstance(items, list) else 0
                raise OptionError(f"{option}: the scene's {name} list has {have} "
                                  f"entr{'y' if have == 1 else 'ies'}, so "
                                  f"{name}[{index}] is not one" +
                                  (" (--channel I,J,... makes the list)" if name == "channels"
                                   else ""))
            if last:
                items[int(index)] = value
            else:
                if not isinstance(items[int(index)], dict):
                    items[int(index)] = {}
                node = items[int(index)]
            continue
        if last:
            if value is None:
                node.pop(name, None)
            else:
                node[name] = value
            for other in EXCLUDES.get(parts[depth - 1][0] if depth else "", {}).get(name, ()):
                node.pop(other, None)
        else:
            if isinstance(node.get(name), str) and name == "transfer_function":
                node[name] = {}   # a transfer-function file's name: the flag replaces it
            node = node.setdefault(name, {})


def _channels_value(data: dict, indices: list[int]) -> list[dict]:
    """--channel I,J: the scene's own entries for those file channels where it has them."""
    have = {c.get("index", i): c for i, c in enumerate(data.get("channels") or [])
            if isinstance(c, dict)}
    return [{**have[i], "index": i} if i in have else {"index": i} for i in indices]


def scene_key_edits(data: dict, args: argparse.Namespace) -> dict[str, str]:
    """Applies the named flags and then every --set to the scene's JSON data; returns which option
    set each key (for messages)."""
    given = {dest: getattr(args, dest, None) for dest in SCENE_KEY_FLAGS}
    if given["value_range"] is not None and getattr(args, "data_window", None) is not None:
        raise OptionError("--value-range and --data-window: each gives the values shown; give "
                          "one of them")
    options: dict[str, str] = {}
    if given["channel"] is not None:     # first: --colormap and --opacity then go to its channel
        tf = None if data.get("channels") else data.pop("transfer_function", None)
        data["channels"] = _channels_value(data, given["channel"])
        if len(given["channel"]) == 1 and tf and tf != transfer_to_dict(TransferFunctionSpec()):
            data["channels"][0]["transfer_function"] = tf   # one channel: the scene's own, kept
        options["channels"] = "--channel"
    for dest, key in SCENE_KEY_FLAGS.items():
        value = given[dest]
        if value is None or dest == "channel":
            continue
        option = "--" + dest.replace("_", "-")
        if key.startswith("transfer_function.") and data.get("channels"):
            if len(data["channels"]) > 1:
                raise OptionError(f"{option}: the scene shows {len(data['channels'])} channels, "
                                  "each with its own transfer function: set one with --set "
                                  f"channels[I].{key}=...")
            key = f"channels[0].{key}"
        _set_key(data, key, value, option)
        options[key] = option
    for key, value, text in getattr(args, "set", None) or ():
        option = f"--set {text}"
        _set_key(data, key, value, option)
        options[key] = option
    return options
def surface_arg(text: str) -> dict:
    """--surface K[,ROUGHNESS[,SPECULAR]]: the scene's surface key (checked as the scene's is)."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 3 or len(values) != len(parts):
        raise argparse.ArgumentTypeError(f"expected K, K,ROUGHNESS or K,ROUGHNESS,SPECULAR (numbers), "
                                         f"got {text!r}")
    out: dict = {"gradient_factor": values[0]}
    if len(values) > 1:
        out["roughness"] = values[1]
    if len(values) > 2:
        out["specular"] = [values[2]] * 3
    return out


def add_scene_edit_options(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options `render`, `view` and `animate` share that edit the scene: the crop box, the
    clip plane and a transfer function kept in a file (docs/crop-and-movies.md), and the scene
    keys (--set and the named flags)."""
    add_scene_key_options(parser)
    parser.add_argument("--crop", nargs=6, type=float, metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
                        help="keep only the box between these world corners (the volume's longest "
                             "side is 1, centred at the origin)")
    parser.add_argument("--crop-voxels", nargs=6, type=int,
                        metavar=("I0", "J0", "K0", "I1", "J1", "K1"),
                        help="keep only voxels I0 <= i < I1, J0 <= j < J1, K0 <= k < K1 (x, y, z): "
                             "renders as the cropped volume data[K0:K1, J0:J1, I0:I1]")
    parser.add_argument("--clip-plane", nargs=4, type=float, metavar=("NX", "NY", "NZ", "D"),
                        help="keep only the points x with dot(n, x) <= D (world units)")
    parser.add_argument("--no-crop", action="store_true", help="switch off the scene's crop box")
    parser.add_argument("--no-clip-plane", action="store_true",
                        help="switch off the scene's clip plane")
    parser.add_argument("--transfer-function", metavar="JSON",
                        help="a transfer function saved on its own (the scene's transfer_function "
                             "key as a file) instead of the scene's")
    parser.add_argument("--surface", type=surface_arg, metavar="K[,ROUGHNESS[,SPECULAR]]",
                        help="surfaces inside the volume (the scene's surface key): at each "
                             "scattering event a BRDF scatters with probability 1 - exp(-K "
                             "|grad A|), A the transfer function's opacity; K = 0: the phase "
                             "function alone. ROUGHNESS: GGX alpha (0.02 to 1), SPECULAR: a grey "
                             "Fresnel F0 (0 to 1)")
    from radiance_probes.scene.clinical_presets import CLINICAL_PRESETS
    parser.add_argument("--clinical-preset", metavar="NAME", choices=tuple(CLINICAL_PRESETS),
                        help="a CT transfer function on Hounsfield units, coloured like an "
                             "anatomy atlas, with its surface shading: "
                             + "; ".join(f"{k}: {v.description}" for k, v in
                                         CLINICAL_PRESETS.items())
                             + ". Without --data-window it sets its own window. A CT opens with "
                               "ct_bone (or its --data-window's preset) unless the scene has a "
                               "transfer function")
    return parser


def add_colorbar_options(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """`render` and `animate`: a colour bar drawn into the PNG (or every frame)."""
    from radiance_probes.frontend.colorbar import POSITIONS
    parser.add_argument("--colorbar", nargs="?", const="right", choices=POSITIONS,
                        help="draw the transfer function's colour bar, labelled in data units, "
                             "at the right (default) or bottom edge of the image")
    parser.add_argument("--colorbar-title", default="value", metavar="TEXT",
                        help="the colour bar's title: the data's unit (default 'value')")
    return parser


def check_clip(scene: Scene, volume, args: argparse.Namespace | None = None) -> None:
    """The crop box and clip plane against the volume, before any GPU work: a voxel crop beyond
    it names the field (and the option that gave it), and one that keeps nothing is refused (an
    empty image is never meant)."""
    from radiance_probes.scene.clip_region import clip_region
    option = None
    if args is not None:
        option = ("--crop-voxels" if getattr(args, "crop_voxels", None) is not None else
                  "--crop" if getattr(args, "crop", None) is not None else None)
    try:
        region = clip_region(scene, volume.dims, volume.half_extent)
    except SceneError as exc:
        raise (OptionError(f"{option}: {exc}") if option else exc) from None
    if region is not None and region.empty:
        raise (OptionError if option else SceneError)(
            (f"{option}: " if option else "") + f"crop: keeps no voxel of the volume (min {list(scene.crop.min)}, max "
                         f"{list(scene.crop.max)} in {scene.crop.units} units; the volume box is "
                         f"{' x '.join(f'{2 * h:.4g}' for h in volume.half_extent)} world units "
                         f"centred at the origin, {' x '.join(map(str, volume.dims))} voxels)")


def _scene_edits(args: argparse.Namespace) -> dict:
    """Scene keys the crop, clip and transfer-function options set (JSON form)."""
    edits: dict = {}
    crop, voxels = getattr(args, "crop", None), getattr(args, "crop_voxels", None)
    if crop is not None and voxels is not None:
        raise OptionError("--crop and --crop-voxels: give one of them")
    if crop is not None:
        edits["crop"] = {"min": list(crop[:3]), "max": list(crop[3:]), "units": "world"}
    if voxels is not None:
        edits["crop"] = {"min": list(voxels[:3]), "max": list(voxels[3:]), "units": "voxels"}
    plane = getattr(args, "clip_plane", None)
    if plane is not None:
        edits["clip_plane"] = {"normal": list(plane[:3]), "distance": plane[3]}
    surface = getattr(args, "surface", None)
    if surface is not None:
        edits["surface"] = surface   # merged with the scene's own in apply_options
    return edits


# Scene fields the options set, for messages that name the option as well as the field.
_OPTION_FIELDS = {"crop.": "--crop", "clip_plane.": "--clip-plane",
                  "camera.width": "--width", "camera.height": "--height",
                  "probes.grid": "--probe-grid", "probes.samples": "--probe-samples",
                  "probes.sh_window": "--sh-window", "probes.precision": "--probe-precision",
                  "probes.layout": "--probe-layout", "probes.adaptive_strength": "--adaptive-strength",
                  "probes.adaptive_indicator": "--adaptive-indicator",
                  "probes.interpolation": "--probe-interpolation", "volume.series": "--series",
                  "volume.orientation": "--orientation", "volume.window": "--data-window",
                  "transfer_function.preset": "--clinical-preset", "surface.": "--surface"}


def apply_options(scene: Scene, args: argparse.Namespace) -> Scene:
    """The scene with the --probe-* and --width/--height options applied, validated as a scene
    file's values are (the same limits, the same messages, naming the option too)."""
    probes = {key: value for key, value in (
        ("grid", getattr(args, "probe_grid", None)), ("samples", getattr(args, "probe_samples", None)),
        ("sh_window", getattr(args, "sh_window", None)),
        ("precision", getattr(args, "probe_precision", None))) if value}
    probes.update({key: value for key, value in (
        ("layout", getattr(args, "probe_layout", None)),
        ("adaptive_strength", getattr(args, "adaptive_strength", None)),
        ("adaptive_indicator", getattr(args, "adaptive_indicator", None)),
        ("interpolation", getattr(args, "probe_interpolation", None))) if value is not None})
    camera = {key: value for key, value in (("width", getattr(args, "width", None)),
                                            ("height", getattr(args, "height", None))) if value}
    volume = {key: value for key, value in (("series", getattr(args, "series", None)),
                                            ("orientation", getattr(args, "orientation", None)),
                                            ("window", getattr(args, "data_window", None)))
              if value is not None}
    edits = _scene_edits(args)
    clinical = getattr(args, "clinical_preset", None)
    if clinical is not None:
        if getattr(args, "transfer_function", None):
            raise OptionError("--clinical-preset and --transfer-function: give one of them")
        if scene.channels:
            raise OptionError("--clinical-preset: the scene has channels, each with its own "
                              "transfer function; clinical presets are for one-channel CT")
    if getattr(args, "transfer_function", None):
        from radiance_probes.io.scene_file import load_transfer_function
        if scene.channels:
            raise OptionError("--transfer-function: the scene has channels, each with its own "
                              "transfer function (channels[i].transfer_function)")
        try:
            scene = scene.replace(transfer_function=load_transfer_function(args.transfer_function))
        except SceneError as exc:
            raise OptionError(f"--transfer-function: {exc}") from None
    if getattr(args, "no_crop", False) and scene.crop is not None:
        scene = scene.replace(crop=replace(scene.crop, enabled=False))
    if getattr(args, "no_clip_plane", False) and scene.clip_plane is not None:
        scene = scene.replace(clip_plane=replace(scene.clip_plane, enabled=False))
    keys_given = any(getattr(args, dest, None) is not None for dest in SCENE_KEY_DESTS)
    if (not probes and not camera and not volume and not edits and not keys_given
            and clinical is None):
        return scene
    data = scene_to_dict(scene)
    if clinical is not None:
        data["transfer_function"] = {"preset": clinical,
                                     "resolution": scene.transfer_function.resolution}
    data["probes"].update(probes)
    data["camera"].update(camera)
    if "window" in volume:
        data["volume"].pop("value_range", None)   # the window given replaces the scene's range
    data["volume"].update(volume)
    if "surface" in edits:   # the keys given replace the scene's (or the preset's), the rest kept
        base = data.get("surface")
        if base is None and clinical is not None:
            from radiance_probes.io.scene_file import preset_surface
            base = scene_to_dict(scene.replace(surface=preset_surface(clinical)))["surface"]
        edits = {**edits, "surface": {**(base or {}), **edits["surface"]}}
    data.update(edits)
    key_options = scene_key_edits(data, args)
    try:
        return parse_scene(data, base_dir=scene.base_dir)
    except SceneError as exc:
        text = str(exc)
        for key, option in reversed(key_options.items()):
            if any(text.startswith(start) for start in (key, f"unknown field {key}")):
                raise OptionError(f"{option}: {text}") from None
        for name, option in _OPTION_FIELDS.items():
            if text.startswith(name):
                if name == "crop." and data.get("crop", {}).get("units") == "voxels":
                    option = "--crop-voxels"
                raise OptionError(f"{option}: {text}") from None
        raise


# ---- outputs -----------------------------------------------------------------------------------

OUTPUT_SUFFIXES = {"--out": ".png", "--linear": ".npy", "--exr": ".exr", "--screenshot": ".png"}


def check_output(path: str, option: str) -> Path:
    """Raises OptionError unless `path` can be written: the right suffix, not a folder, its folder
    creatable and writable. Creates the missing folders (the write would) but leaves no file."""
    p = Path(path).expanduser()
    if p.is_dir():
        raise OptionError(f"{option} {path}: is a folder; give a file name")
    suffix = OUTPUT_SUFFIXES.get(option)
    if suffix and p.suffix.lower() != suffix:
        raise OptionError(f"{option} {path}: expected a {suffix} file name")
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OptionError(f"{option} {path}: {parent} is a file, not a folder")
            break
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        existed = p.exists()
        with open(p, "ab"):
            pass
        if not existed:
            p.unlink()
    except OSError as exc:
        raise OptionError(f"{option} {path}: cannot write there ({exc.strerror or exc})") from None
    return p


def check_outputs(args: argparse.Namespace) -> None:
    for option in OUTPUT_SUFFIXES:
        value = getattr(args, option[2:], None)
        if value:
            check_output(value, option)


def save_or_rescue(save, path: str, option: str, *payload) -> tuple[Path | None, str | None]:
    """Writes an output with `save(path, *payload)`. When that fails (the disk filled up, the
    folder went away during the render), writes it to the temporary folder instead. Returns
    (where it went, an error line or None)."""
    try:
        return save(path, *payload).resolve(), None
    except OSError as exc:
        reason = exc.strerror or str(exc)
    rescue = Path(tempfile.gettempdir()) / f"radiance-probes-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{Path(path).name}"
    try:
        where = save(rescue, *payload).resolve()
    except OSError as exc:
        return None, (f"{option} {path}: could not write it ({reason}), nor a copy at {rescue} "
                      f"({exc.strerror or exc}); the image is lost")
    return where, f"{option} {path}: could not write it ({reason}); it was written to {where} instead"


# ---- render to files (`render`, and `view` where no window can open) ---------------------------

def progress_printer(label: str):
    interactive = sys.stderr.isatty()
    last = [-1]

    def report(done: int, total: int) -> None:
        pct = int(100 * done / max(total, 1))
        if interactive:
            print(f"\r{label}: {done}/{total} ({pct}%)", end="" if done < total else "\n",
                  file=sys.stderr, flush=True)
        elif pct // 10 != last[0] // 10 or done == total:
            print(f"{label}: {done}/{total} ({pct}%)", file=sys.stderr, flush=True)
        last[0] = pct
    return report


def render_defaults() -> dict:
    """Every option `render` has, at its default: what the viewer's headless fallback starts from."""
    return dict(scene=None, method="pt", spp=64, samples_per_pass=1, out="render.png", linear=None,
                exr=None, probe_grid=None, probe_samples=None, sh_window=None, probe_precision=None,
                auto_probes=None, auto=None, denoise=False, denoise_guides="auto",
                raymarch_stage="compute", raymarch_step=None, seed=0, width=None,
                height=None, exposure=1.0, gl_backend=None, empty_space_skipping=True,
                gather_event=None, series=None, orientation=None, data_window=None, crop=None,
                crop_voxels=None, clip_plane=None, no_crop=False, no_clip_plane=False,
                transfer_function=None, clinical_preset=None, surface=None, colorbar=None,
                colorbar_title="value", volume_memory=None, **dict.fromkeys(SCENE_KEY_DESTS))


def render_to_files(args: argparse.Namespace) -> int:
    """Renders the scene the arguments name and writes the PNG (and the linear .npy/.exr); every
    check comes before the first GPU call. Returns the exit status."""
    from radiance_probes.gl.context import create_headless_context, describe
    from radiance_probes.frontend.imageio import save_exr, save_npy, save_png
    from radiance_probes.rendering.limits import check_image_size
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.rendering.methods.raymarch import check_step
    from radiance_probes.io.environment_map import load_scene_environment
    from radiance_probes.scene.framing import frame_default_camera
    from radiance_probes.io.load import load_scene_volume
    from radiance_probes.scene.clinical_presets import opening_scene

    auto = getattr(args, "auto", None)
    if auto is not None:
        if args.auto_probes is not None:
            raise OptionError("--auto and --auto-probes: --auto chooses the probes itself (or "
                              "the path tracer); give one of them")
        if getattr(args, "gather_event", None) is not None:
            raise OptionError("--gather-event: --auto renders the raymarcher or the path tracer, "
                              "neither reads it")
        if args.method != "pt" or args.spp != 64:
            print("note: --auto chooses the method and the samples: --method and --spp are not "
                  "used", file=sys.stderr)
    if args.auto_probes is not None and not METHODS[args.method].needs_probes:
        raise OptionError("--auto-probes chooses probe settings: use it with a probe method")
    gather_event = getattr(args, "gather_event", None)
    if gather_event is not None:
        from radiance_probes.rendering.settings import check_gather_event
        if "gather_event" not in METHODS[args.method].options:
            raise OptionError(f"--gather-event: the probes method's option (a final gather), "
                              f"not {args.method}'s")
        try:
            check_gather_event(gather_event)
        except ValueError as exc:
            raise OptionError(f"--gather-event: {exc}") from None
    scene = apply_options(scene_from_arg(args.scene), args)
    check_outputs(args)
    volume = load_scene_volume(scene)      # a file that does not load fails before the GPU starts
    scene = frame_default_camera(scene, volume.half_extent)   # a default view sees the whole box
    for note in volume.notes:
        print(f"note: {note}", file=sys.stderr)
    scene = opening_scene(scene, volume)   # a CT with no transfer function: its clinical preset
    if scene.transfer_function.preset is not None:
        print(f"note: transfer function: the clinical preset {scene.transfer_function.preset} "
              f"(--clinical-preset)", file=sys.stderr)
    if getattr(args, "colorbar", None) and volume.channel_count > 1:
        raise OptionError(f"--colorbar: a colour bar shows one transfer function; this volume has "
                          f"{volume.channel_count} channels, each with its own")
    load_scene_environment(scene)          # so does an environment map (kept in its cache)
    check_clip(scene, volume, args)        # and a crop that does not fit the volume
    from radiance_probes.scene.area_lights import check_area_lights
    check_area_lights(scene, volume.half_extent)   # and an area light in the volume box
    if "raymarch_step" in METHODS[args.method].options and args.raymarch_step is not None:
        try:
            check_step(args.raymarch_step, volume)   # a step asked for is taken, or refused
        except ValueError as exc:
            raise OptionError(f"--raymarch-step: {exc}") from None
    ctx = create_headless_context(args.gl_backend)
    check_image_size(ctx, scene.camera.width, scene.camera.height)
    from radiance_probes.rendering.settings import RenderSettings
    renderer = Renderer(ctx, scene, volume, RenderSettings(
        raymarch_stage=args.raymarch_stage,
        raymarch_step=args.raymarch_step or DEFAULT_RAYMARCH_STEP,
        empty_space_skipping=args.empty_space_skipping,
        gather_event=gather_event if gather_event is not None else 1,
        volume_memory_bytes=getattr(args, "volume_memory", None)))
    for note in renderer.resources.volume.notes:   # where bricking showed a coarser level
        if note not in volume.notes:
            print(f"note: {note}", file=sys.stderr)
    if args.auto_probes is not None:
        from radiance_probes.rendering.probes.auto import choose_probes
        choice = choose_probes(renderer, args.auto_probes, args.method,
                               progress=lambda m: print(f"auto: {m}", file=sys.stderr, flush=True))
        print(choice.report(trials=False))   # each trial was printed as it came
        scene = choice.scene
        renderer.set_scene(scene)
    bake_report = progress_printer("probe bake passes")

    def on_bake_pass(grid) -> None:
        bake_report(grid.passes_done, grid.passes_total)

    if auto is not None:
        from radiance_probes.rendering.refine.auto_progressive import auto_render
        from radiance_probes.rendering.still_images import RenderResult
        got = auto_render(renderer, auto, seed=args.seed,
                          progress=lambda m: print(f"auto: {m}", file=sys.stderr, flush=True),
                          denoise=getattr(args, "denoise", False))
        print(got.report(log=False))         # each trial was printed as it came
        scene, args.method = got.scene, got.method
        # the image's own render and bake: the rejected settings' are in the report's total
        result = RenderResult(got.image, got.method, got.image_spp, got.image_ms,
                              got.image_bake_ms)
    else:
        result = renderer.render(args.method, spp=args.spp, seed=args.seed,
                                 samples_per_pass=args.samples_per_pass,
                                 progress=progress_printer(
                                     f"{args.method} "
                                     f"{'frames' if not METHODS[args.method].noisy else 'samples'}"),
                                 bake_progress=on_bake_pass,
                                 denoise=getattr(args, "denoise", False),
                                 denoise_guides=getattr(args, "denoise_guides", "auto"))
    denoise = getattr(args, "denoise", False)
    if denoise and auto is not None and not got.denoised and METHODS[got.method].noisy:
        # auto returned the path tracer's raw image: denoise that one (a denoised one it chose,
        # or a raymarched image, which is clean, stays as it is)
        from radiance_probes.rendering.denoise.filter import choose_guides
        renderer.begin(args.method)
        guides = choose_guides(args.denoise_guides, result.spp,
                               renderer.needs_probes(args.method) and renderer.probes_shown())
        d, _ = renderer.denoise(result.image, guides)
        result.image, result.denoised = d.image, d
    if denoise:
        d = result.denoised
        if d is not None and d.denoised:
            print(f"denoised on OIDN's {d.device} device (guides: {args.denoise_guides}): "
                  f"filter {d.ms['filter_ms']:.1f} ms")
        elif d is not None:
            print(f"note: {d.note}", file=sys.stderr)
    errors = []
    if getattr(args, "colorbar", None):
        from radiance_probes.frontend.colorbar import scene_colorbar
        from radiance_probes.frontend.imageio import save_png8
        from radiance_probes.rendering.tonemap import to_uint8
        pixels = scene_colorbar(to_uint8(result.image, args.exposure), scene,
                                renderer.resources.volume, args.colorbar, args.colorbar_title)
        out, err = save_or_rescue(save_png8, args.out, "--out", pixels)
    else:
        out, err = save_or_rescue(save_png, args.out, "--out", result.image, args.exposure)
    errors.append(err)
    print(f"device: {describe(ctx)}")
    cam = scene.camera
    word = METHODS[result.method].sample_word if result.method in METHODS else "spp"
    print(f"method: {result.method}  image: {cam.width}x{cam.height}  {word}: {result.spp}")
    shown = result.stats.get("shown")   # a composite method's part shown (refine)
    if shown is not None:
        est = result.stats["refine_estimate"]
        w = est.get("blend_weight")
        what = (f"{shown}'s image" if w is None or w in (0.0, 1.0) else
                f"guided denoised blended with the raymarcher's image (weight {w:.2f}, estimated "
                f"rRMSE of the blend {est['blend']:.4f})")
        print(f"{result.method} shows {what} (estimated rRMSE: guided {est['guided']:.4f}, "
              f"raymarch {est['raymarch']:.4f})")
    if renderer.probe_grid is not None and METHODS[args.method].needs_probes:
        g = renderer.probe_grid
        rep = g.progress_report()
        print(f"probes: {g.grid[0]}x{g.grid[1]}x{g.grid[2]}, {g.samples} walks each, "
              f"{g.precision}, window {scene.probes.sh_window}; textures {g.gpu_bytes / 2**20:.1f} MiB; "
              f"bake GPU time: {result.bake_ms:.1f} ms; last pass changed the probes by "
              f"{100 * rep.relative_change:.2f}% (est. standard error "
              f"{'n/a, one pass' if rep.passes_done < 2 else f'{100 * rep.standard_error:.2f}%'})")
        if renderer.bake_note():
            print(f"note: {renderer.bake_note()}")
        if "gather_event" in METHODS[args.method].options and renderer.probe_gather_event > 1:
            k = renderer.probe_gather_event
            print(f"final gather: the probes read at scattering event {k}, the events before it "
                  f"path traced" + (f" (past max_bounces {scene.max_bounces}: no path reaches "
                                    f"it, the path tracer's image)" if k > scene.max_bounces
                                    else ""))
            most = renderer.gather_bounces_past_limit()
            if most is not None:
                print(f"note: the probes hold up to max_bounces - 1 = {scene.max_bounces - 1} "
                      f"scattering events whatever the gather event, so with {k} a path may "
                      f"scatter up to {most} times, not {scene.max_bounces} "
                      f"(a few percent brighter where max_bounces is this small; --gather-event 1 "
                      f"keeps the limit exactly)", file=sys.stderr)
        if scene.probes.layout == "adaptive":
            spacing = ("evenly spaced (no variation to follow)" if g.planes is None else
                       "spacing per axis from " + ", ".join(
                           f"{min(np.diff(p)) * len(p):.2f}-{max(np.diff(p)) * len(p):.2f}"
                           if len(p) > 1 else "1" for p in g.planes) + " x the uniform one")
            print(f"probe layout: adaptive ({scene.probes.adaptive_indicator}, strength "
                  f"{scene.probes.adaptive_strength:g}): {spacing}; "
                  f"{renderer.last_layout_ms:.0f} ms on the host")
    if "raymarch_step" in METHODS[args.method].options and (
            renderer.effective_raymarch_step_voxels > renderer.raymarch_step_voxels):
        print(f"note: raymarch step {renderer.effective_raymarch_step_voxels:.3g} voxels, not the "
              f"default {renderer.raymarch_step_voxels:g}: the shader takes at most 8192 steps "
              "across this volume's box")
    per = ("frame" if word == "frames" else "sample per pixel") + " of the whole image"
    print(f"render GPU time: {result.render_ms:.1f} ms  ({result.ms_per_sample:.3f} ms per {per})")
    if result.stats.get("truncated_paths") or result.stats.get("nonfinite_samples"):
        print(f"warning: {result.stats['truncated_paths']} paths ran out of their step budget and "
              f"{result.stats['nonfinite_samples']} samples were not finite; both were left out",
              file=sys.stderr)
    if args.linear:
        where, err = save_or_rescue(save_npy, args.linear, "--linear", result.image)
        errors.append(err)
        if where:
            print(f"linear image: {where}")
    if args.exr:
        where, err = save_or_rescue(save_exr, args.exr, "--exr", result.image)
        errors.append(err)
        if where:
            print(f"EXR image: {where}")
    if out:
        print(f"wrote {out}")
    errors = [e for e in errors if e]
    for e in errors:
        print(f"error: {e}", file=sys.stderr)
    return 1 if errors else 0


def memory_size(text: str) -> int:
    """Bytes from "4G", "512M", "65536" (K, M, G, T: powers of 1024)."""
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    scale = units.get(t[-1:], 1)
    number = t[:-1] if t[-1:] in units else t
    try:
        value = int(float(number) * scale)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a size in bytes such as 4G or 512M, got "
                                         f"{text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a size > 0, got {text!r}")
    return value
