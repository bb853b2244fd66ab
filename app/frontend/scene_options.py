"""The scene from the command line: the volume and scene-key options both front ends take, a scene
file or a volume path made a scene, every option applied to it (each key named by the flag that
sets it), the crop and clip plane checked against the volume."""
from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path

from radiance_probes.io.scene_file import (Scene, SceneError, TransferFunctionSpec, default_scene,
                                           load_scene, parse_scene, scene_to_dict, transfer_to_dict)
from radiance_probes.frontend.option_types import (OptionError, channel_arg, dims_arg, finite_float,
                                                   opacity_arg, series_arg, set_arg, spacing_arg,
                                                   surface_arg, time_arg, value_range_arg,
                                                   window_arg)


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
