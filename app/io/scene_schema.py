"""The scene file's JSON Schema, generated from the scene's types (app/scene/types.py): its keys
and nesting from the dataclasses' fields, defaults from their defaults, and each key's meaning and
range from KEYS below (a test fails when a field has no entry, or an entry no field). Editors
validate and complete scene files with it (docs/scene.schema.json, a `"$schema"` key or the
editor's settings); docs/scene-format.md's key table is generated from it too.

    radiance-probes schema [--out docs/scene.schema.json]    # the schema
    radiance-probes schema --table                           # the key table, markdown
    radiance-probes schema --update-docs                     # both, into docs/ of this checkout

The loader (app/io/scene_file.py) stays the authority: it also checks what a schema cannot say (a
value_range's min below its max, a camera's up not along its view), and names the field in its
message. A test checks both agree at every range's bounds.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from radiance_probes.methods import VIEWER_METHODS
from radiance_probes.scene.types import (AXIS_LETTERS, CHANNEL_COLOURS, CROP_UNITS, MAX_CHANNELS,
                                         MAX_BOUNCES_LIMIT, MAX_IMAGE_SIDE, MAX_PROBE_AXIS,
                                         MAX_PROBE_SAMPLES, MAX_TRANSFER_ROWS, ORIENTATIONS,
                                         PROBE_FITS, PROBE_INDICATORS, PROBE_INTERPOLATIONS,
                                         PROBE_LAYOUTS, PROBE_PRECISIONS, SH_ORDERS, SH_WINDOWS,
                                         VIEWER_DISPLAYS, VIEWER_PROBE_VIEWS, WINDOW_PRESETS,
                                         BookmarkSpec, CameraSpec, ChannelSpec, ClipPlaneSpec,
                                         CropSpec, LightSpec, ProbeSpec, Scene, SurfaceSpec,
                                         MAX_GRADIENT_FACTOR, MIN_ROUGHNESS, AREA_LIGHT_SHAPES,
                                         MAX_AREA_LIGHTS, AreaLightSpec, TransferFunctionSpec,
                                         ViewerSpec, VolumeSpec)

SCHEMA_ID = "https://radiance-probes.invalid/scene.schema.json"
# Scene fields that are not JSON keys: where relative paths are looked up, and the environment map
# (written as "environment": {"map": ...}).
NOT_KEYS = {"base_dir", "environment_map"}
NESTED = {"volume": VolumeSpec, "transfer_function": TransferFunctionSpec, "light": LightSpec,
          "camera": CameraSpec, "probes": ProbeSpec, "surface": SurfaceSpec, "crop": CropSpec,
          "clip_plane": ClipPlaneSpec, "viewer": ViewerSpec}
# Scene fields that are lists of objects (each item's keys are named "bookmarks[].name", ...).
LISTS = {"bookmarks": BookmarkSpec, "channels": ChannelSpec, "area_lights": AreaLightSpec}
# What a nested object's key takes besides the object: a transfer-function file's name in place of
# the transfer function; null for the optional ones (as if absent).
ALSO = {"transfer_function": ("string",), "crop": ("null",), "clip_plane": ("null",),
        "viewer": ("null",), "bookmarks": ("null",), "channels": ("null",),
        "area_lights": ("null",)}
# Keys an object must hold (the loader names the one missing), and a voxel crop's integer corners.
REQUIRED = {"crop": ["min", "max"], "clip_plane": ["normal"], "bookmarks[]": ["name", "eye"],
            "area_lights[]": ["shape", "position", "size"]}


@dataclass(frozen=True)
class Key:
    meaning: str
    schema: dict
    default: str | None = None     # the default as words, where the type's default is None
    values: str | None = None      # the range as words, where the schema's is not plain


def number(lo=None, hi=None, lo_open=False, hi_open=False, integer=False) -> dict:
    out: dict[str, Any] = {"type": "integer" if integer else "number"}
    if lo is not None:
        out["exclusiveMinimum" if lo_open else "minimum"] = lo
    if hi is not None:
        out["exclusiveMaximum" if hi_open else "maximum"] = hi
    return out


def vector(n: int, item: dict | None = None) -> dict:
    return {"type": "array", "items": item or {"type": "number"}, "minItems": n, "maxItems": n}


def choice(values) -> dict:
    return {"type": "string", "enum": list(values)}


BOOLEAN = {"type": "boolean"}
# crop with "units": "voxels": its corners are voxel boundaries, integers from 0.
VOXEL_CROP = {"if": {"required": ["units"], "properties": {"units": {"const": "voxels"}}},
              "then": {"properties": {"min": vector(3, number(0, 1 << 20, integer=True)),
                                      "max": vector(3, number(0, 1 << 20, integer=True))}}}


def _colormaps() -> tuple[str, ...]:
    from radiance_probes.scene.transfer import COLORMAPS
    return tuple(COLORMAPS)


def _clinical() -> dict:
    from radiance_probes.scene.clinical_presets import CLINICAL_PRESETS
    return CLINICAL_PRESETS


def _builtins() -> tuple[str, ...]:
    from radiance_probes.io.builtin_volumes import BUILTIN_VOLUMES
    return tuple(BUILTIN_VOLUMES)


def _dtypes() -> tuple[str, ...]:
    from radiance_probes.io.volume_files import RAW_DTYPES
    return tuple(RAW_DTYPES)


def keys() -> dict[str, Key]:
    """Every scene key by its dotted path: meaning and JSON Schema of its value."""
    unit = number(0.0, 1.0)
    return {
        "volume": Key("The scalar field: a built-in procedural volume or a file.", {}),
        "volume.path": Key(
            "A volume file or folder, relative to the scene file's folder (or absolute): .raw, "
            ".nrrd/.nhdr, .npy, .nii/.nii.gz, .tif/.tiff, a folder of TIFF slices or steps, a Zarr "
            "or OME-Zarr store, a folder of DICOM files (searched recursively), a DICOMDIR, or "
            "a multi-frame DICOM file (enhanced CT or MR, RT dose). "
            "Excludes volume.builtin.",
            {"type": "string", "minLength": 1}, default="none (the built-in volume)",
            values="a path"),
        "volume.builtin": Key("A built-in procedural volume (used when there is no path).",
                              choice(_builtins())),
        "volume.size": Key("The built-in volume's voxels along x, y, z (not for files).",
                           vector(3, number(1, 2048, integer=True))),
        "volume.spacing": Key(
            "Voxel size along x, y, z (any unit; only the ratios matter). Given here it wins over "
            "the file's, even [1, 1, 1].", vector(3, number(0.0, lo_open=True)),
            default="the file's (NRRD, NIfTI, DICOM), else [1, 1, 1]"),
        "volume.value_range": Key(
            "The data values mapped to density 0 and 1 (min < max). Excludes volume.window.",
            vector(2), default="0..255 for 8-bit data, else the data's own min and max"),
        "volume.window": Key(
            "The same range as radiology gives it, in data units (Hounsfield units for CT): level "
            "- width/2 maps to 0, level + width/2 to 1; or a preset: "
            + ", ".join(f"{name} ({level:g}, {width:g})" for name, (level, width)
                        in WINDOW_PRESETS.items()) + ". Excludes volume.value_range.",
            {"oneOf": [choice(WINDOW_PRESETS),
                       {"type": "object", "additionalProperties": False,
                        "required": ["level", "width"],
                        "properties": {"level": {"type": "number"},
                                       "width": number(0.0, lo_open=True)}}]},
            default="none", values="a preset name or {\"level\": L, \"width\": W > 0}"),
        "volume.dims": Key("Voxels along x, y, z of a .raw file not named name_XxYxZ_dtype.raw.",
                           vector(3, number(1, 1 << 20, integer=True)), default="from the name"),
        "volume.dtype": Key("The sample type of such a .raw file.", choice(_dtypes()),
                            default="from the name"),
        "volume.rescale": Key(
            "[slope, intercept]: the file's stored values to data units (value * slope + "
            "intercept), as DICOM's RescaleSlope and RescaleIntercept, for data exported without "
            "them (an 8-bit CT windowed from Hounsfield units). volume.value_range, volume.window "
            "and the CT presets are then in data units. Not for DICOM (it carries its own).",
            vector(2), default="none: the stored values are the data"),
        "volume.replace_nonfinite": Key(
            "The value NaN and Inf voxels get; without it they are an error.", {"type": "number"},
            default="none (an error)"),
        "volume.series": Key(
            "A DICOM folder tree's or DICOMDIR's series: its number in the listing (radiance-probes "
            "series PATH) or its SeriesInstanceUID.",
            {"oneOf": [number(1, integer=True), {"type": "string", "minLength": 1}]},
            default="the largest series that makes a volume",
            values="a number from 1 or a SeriesInstanceUID"),
        "volume.axes": Key(
            "Which array axis is which, one letter each: t (time), c (channel), z, y, x; z, y and "
            "x always. Needed for a .npy of more than 3 dimensions and a file whose metadata "
            "leaves axes unnamed; where the file names its axes (ImageJ, OME, Zarr) it must agree. "
            "A count after letters splits a TIFF's unnamed page axis: \"c3zyx\" reads 96 pages as "
            "3 channels of 32 slices.",
            {"type": "string", "pattern": f"^([{AXIS_LETTERS}]([1-9][0-9]*)?){{3,5}}$"},
            default="the file's own (3D .npy: zyx)", values="e.g. \"czyx\", \"tzyx\""),
        "volume.orientation": Key(
            "data: the array's axes on world x, y, z as stored; patient: permuted and flipped so "
            "that +x is the patient's left, +y superior, +z anterior (NIfTI, DICOM, NRRD files "
            "that say so).", choice(ORIENTATIONS)),
        "orientation": Key("volume.orientation, given at the scene's top level.",
                           choice(ORIENTATIONS), default="data"),
        "series": Key("volume.series, given at the scene's top level.",
                      {"oneOf": [number(1, integer=True), {"type": "string", "minLength": 1}]},
                      default="the largest series", values="a number from 1 or a SeriesInstanceUID"),
        "transfer_function": Key(
            "Density to colour and opacity; or the name of a transfer-function file that holds "
            "this object (relative to the scene file's folder; radiance-probes render "
            "--transfer-function FILE and the viewer's Save TF).", {}),
        "transfer_function.colormap": Key("The colour along density 0 to 1. Excludes "
                                          "transfer_function.colors.", choice(_colormaps())),
        "transfer_function.colors": Key(
            "Colour control points [density, r, g, b], densities not decreasing; linear between "
            "them, constant beyond. Replace the colormap (excludes transfer_function.colormap).",
            {"type": "array", "minItems": 1, "maxItems": MAX_TRANSFER_ROWS,
             "items": vector(4, unit)}, default="none (the colormap)"),
        "transfer_function.opacity": Key(
            "Opacity control points [density, opacity], densities not decreasing; linear between "
            "them, constant beyond.",
            {"type": "array", "minItems": 1, "items": vector(2, unit)}),
        "transfer_function.rgba": Key(
            f"Explicit rows [r, g, b, a] at densities evenly spaced from 0 to 1 (2 to "
            f"{MAX_TRANSFER_ROWS} rows). Excludes colormap, colors and opacity.",
            {"type": "array", "minItems": 2, "maxItems": MAX_TRANSFER_ROWS,
             "items": vector(4, unit)}, default="none (colormap and opacity)"),
        "transfer_function.preset": Key(
            "A clinical CT preset on Hounsfield units (app/scene/clinical_presets.py): "
            + "; ".join(f"{k}: {v.description}" for k, v in _clinical().items())
            + ". It gives the colours and opacity, placed by the volume's window (with none given "
            "it sets its own, volume.window), and the surface's shading where the scene gives no "
            "surface. Data not in Hounsfield units (8-bit, or no value below 0) is refused. A "
            "saved scene holds the colours and opacity it made. Excludes colormap, colors, "
            "opacity and rgba.", choice(_clinical()), default="none"),
        "transfer_function.resolution": Key("Rows of the table the colormap and opacity make.",
                                            number(2, MAX_TRANSFER_ROWS, integer=True)),
        "density_scale": Key("Extinction sigma_t per unit of world length at opacity 1 (the "
                             "box's longest side is 1).", number(0.0, 1e7)),
        "albedo": Key("Single-scattering albedo, times the colormap's colour.", unit),
        "anisotropy": Key("Henyey-Greenstein g: > 0 forward, 0 isotropic, < 0 backward.",
                          number(-1.0, 1.0, lo_open=True, hi_open=True)),
        "surface": Key(
            "Hybrid scattering: surfaces inside the volume (glsl/lib/hybrid_scattering.glsl). At "
            "each scattering event a surface BRDF scatters with probability 1 - exp(-k length(grad A)), "
            "A = sigma_t / density_scale (the transfer function's opacity) and its gradient in "
            "world units, the phase function otherwise. A clinical preset sets it where the "
            "scene does not.", {}),
        "surface.gradient_factor": Key(
            "k: 0 scatters by the phase function alone (the images without surfaces, bit for "
            "bit); larger makes weaker edges surfaces (a jump of A from 0 to 1 over one voxel "
            "of a 256-voxel side is a gradient of length ~128).", number(0.0, MAX_GRADIENT_FACTOR)),
        "surface.roughness": Key("GGX alpha of the specular lobe (0.02: nearly a mirror, 1: "
                                 "rough).", number(MIN_ROUGHNESS, 1.0)),
        "surface.specular": Key(
            "The specular lobe's Fresnel colour F0 (constant); the diffuse lobe is the "
            "transfer function's colour times albedo times 1 - max(F0). [0, 0, 0]: diffuse "
            "alone, which absorbs nothing.", vector(3, unit)),
        "area_lights": Key(
            f"Area lights, at most {MAX_AREA_LIGHTS}, each wholly outside the volume box (checked "
            "against the volume: a light that reaches into it is refused). The path tracer samples "
            "them at every scattering event (next-event estimation, MIS against the phase "
            "function's or the BRDF's sampling) and sees them where a ray meets one; the probes' "
            "walks too; the raymarcher and probes-only take their direct light from an "
            "optical-depth grid per light and the rest from the probes.", {},
            default="none", values="a list of lights"),
        "area_lights[].shape": Key("sphere, or rectangle (one-sided: it emits towards its "
                                   "normal).", choice(AREA_LIGHT_SHAPES), default="required"),
        "area_lights[].position": Key("The light's centre (world units).", vector(3),
                                      default="required"),
        "area_lights[].size": Key(
            "A sphere's radius, or a rectangle's [width, height] (world units, > 0); the "
            "rectangle's edges lie along the orthonormal basis of its normal.",
            {"oneOf": [number(0.0, 1e6, lo_open=True),
                       vector(2, number(0.0, 1e6, lo_open=True))]},
            default="required", values="r > 0, or [w, h] > 0"),
        "area_lights[].colour": Key("Its colour; the radiance is colour x strength.",
                                    vector(3, unit)),
        "area_lights[].strength": Key("Radiance scale (the radiance is colour x strength, "
                                      "uniform over the light's surface).", number(0.0, 1e9)),
        "area_lights[].normal": Key("A rectangle's facing direction (not zero; normalised).",
                                    vector(3)),
        "area_lights[].enabled": Key("false: the light is off (as if absent).", BOOLEAN),
        "light": Key("The sun: a directional light.", {}),
        "light.direction": Key("Towards the light, from the scene (normalised; not zero).",
                               vector(3)),
        "light.irradiance": Key("RGB irradiance on a plane facing the light.",
                                vector(3, number(0.0))),
        "environment": Key(
            "Radiance arriving from every direction: a constant [r, g, b], or an equirectangular "
            "map {\"map\": FILE (.exr, .hdr, .npy; relative to the scene file), \"scale\": s "
            "(0 to 1e7, default 1), \"rotation\": degrees about +y (-360 to 360, default 0)}.",
            {"oneOf": [vector(3, number(0.0)),
                       {"type": "object", "additionalProperties": False, "required": ["map"],
                        "properties": {"map": {"type": "string", "minLength": 1},
                                       "scale": number(0.0, 1e7),
                                       "rotation": number(-360.0, 360.0)}}]},
            values="[r, g, b] >= 0, or {\"map\", \"scale\", \"rotation\"}"),
        "max_bounces": Key("Scattering events per path at most.",
                           number(0, MAX_BOUNCES_LIMIT, integer=True)),
        "camera": Key("A pinhole camera.", {}),
        "camera.eye": Key("Where the camera is (world units; the volume's box is centred at the "
                          "origin, its longest side 1). Where the scene leaves the view at its "
                          "default and the box's bounding sphere does not fit the image (a tall "
                          "image, a long box), the eye moves back along its direction until it "
                          "does, so the whole box stays in view from any direction at that "
                          "distance (an orbit).", vector(3)),
        "camera.target": Key("The point it looks at (not the eye).", vector(3)),
        "camera.up": Key("Up on the image (not along the view).", vector(3)),
        "camera.fov_y": Key("Vertical field of view, degrees.", number(0.0, 179.0, lo_open=True)),
        "camera.width": Key("Image width, pixels.", number(1, MAX_IMAGE_SIDE, integer=True)),
        "camera.height": Key("Image height, pixels.", number(1, MAX_IMAGE_SIDE, integer=True)),
        "probes": Key("The radiance probes' grid and bake.", {}),
        "probes.grid": Key(
            "Probes per axis: N (along the visible region's longest side, the others in "
            "proportion) or [nx, ny, nz].",
            {"oneOf": [number(1, MAX_PROBE_AXIS, integer=True),
                       vector(3, number(1, MAX_PROBE_AXIS, integer=True))]},
            values=f"1 to {MAX_PROBE_AXIS}, or 3 of them"),
        "probes.samples": Key("Walks per probe.", number(1, MAX_PROBE_SAMPLES, integer=True)),
        "probes.sh_window": Key("Window against SH ringing.", choice(SH_WINDOWS)),
        "probes.precision": Key("Probe texture format (rgba16f: half the memory); auto: rgba16f "
                                "with surfaces (surface.gradient_factor > 0), else rgba32f.",
                                choice(PROBE_PRECISIONS)),
        "probes.sh_order": Key(
            "Spherical-harmonics order; auto: 0 for g = 0, 3 for |g|^3 >= 0.2 with 128 walks or "
            "more, else 2.",
            {"oneOf": [{"const": "auto"}, {"type": "integer", "enum": list(SH_ORDERS)}]},
            values="\"auto\" or 0 to 4"),
        "probes.fit": Key("visible: the grid covers where the transfer function makes the medium "
                          "visible; box: the whole volume box.", choice(PROBE_FITS)),
        "probes.channels": Key("auto: one channel where the transfer function and lights are "
                               "grey, else 3.",
                               {"oneOf": [{"const": "auto"}, {"type": "integer", "enum": [1, 3]}]},
                               values="\"auto\", 1 or 3"),
        "probes.layout": Key("uniform planes, or adaptive: denser where the indicator varies.",
                             choice(PROBE_LAYOUTS)),
        "probes.adaptive_strength": Key("adaptive: 0 uniform .. 1 the indicator alone.", unit),
        "probes.adaptive_indicator": Key("adaptive: what drives the density.",
                                         choice(PROBE_INDICATORS)),
        "probes.interpolation": Key("How a point blends its 8 probes: trilinear, or weighted by "
                                    "visibility (against leaks through dense matter).",
                                    choice(PROBE_INTERPOLATIONS)),
        "crop": Key("A crop box: only the part of the volume between its corners is kept, for "
                    "every ray and every method (docs/crop-and-movies.md). Absent or null: none.",
                    {}),
        "crop.min": Key("The box's low corner along x, y, z: world coordinates, or with units "
                        "voxels the first voxel kept along each axis (integers from 0).",
                        vector(3), default="required"),
        "crop.max": Key("The box's high corner, above min on every axis: world coordinates, or "
                        "with units voxels one past the last voxel kept (at most the volume's "
                        "voxels along that axis).", vector(3), default="required"),
        "crop.units": Key("world: the corners in world units (the volume box centred at the "
                          "origin, its longest side 1); voxels: voxel boundaries along the "
                          "volume's x, y, z (as placed, after orientation), keeping min <= i < "
                          "max, which renders as data[z0:z1, y0:y1, x0:x1].",
                          choice(CROP_UNITS)),
        "crop.enabled": Key("false: the box stays in the file but cuts nothing.", BOOLEAN),
        "clip_plane": Key("A clip plane: keeps the points x with dot(normal, x) <= distance "
                          "(world units), with the crop box their intersection. Absent or null: "
                          "none.", {}),
        "clip_plane.normal": Key("The normal, pointing to the side cut away (not zero; a normal "
                                 "not of unit length scales the distance with it).", vector(3),
                                 default="required"),
        "clip_plane.distance": Key("The plane's offset along the normal, world units.",
                                   {"type": "number"}),
        "clip_plane.enabled": Key("false: the plane stays in the file but cuts nothing.",
                                  BOOLEAN),
        "bookmarks": Key("Cameras saved under names: the viewer recalls them (ctrl+1..9 save, "
                         "shift+1..9 recall) and radiance-probes animate --keyframes flies through "
                         "them. The image size stays the camera's.", {}),
        "bookmarks[].name": Key("The bookmark's name, unique in the scene.",
                                {"type": "string", "minLength": 1}, default="required",
                                values="text"),
        "bookmarks[].eye": Key("Where the camera is (world units).", vector(3),
                               default="required"),
        "bookmarks[].target": Key("The point it looks at (not the eye).", vector(3)),
        "bookmarks[].up": Key("Up on the image (not along the view).", vector(3)),
        "bookmarks[].fov_y": Key("Vertical field of view, degrees.",
                                 number(0.0, 179.0, lo_open=True)),
        "channels": Key(
            f"A volume's channels shown (SPEC.md, Channels): 1 to {MAX_CHANNELS}, at least one "
            "switched on; they add their extinctions and mix their colours by extinction. Absent: "
            "one channel, or a file's 2 to 4 channels each in the colour of its place. Excludes "
            "the scene's transfer_function.", {"minItems": 1, "maxItems": MAX_CHANNELS},
            default="none"),
        "channels[].name": Key("A name for the viewer's panel.", {"type": "string"},
                               default="none", values="text"),
        "channels[].index": Key("The file's channel shown here (from 0), each once.",
                                number(0, 1 << 16, integer=True), default="its place in the list"),
        "channels[].enabled": Key("false: the channel adds nothing (kept for the viewer's "
                                  "switch).", BOOLEAN),
        "channels[].value_range": Key(
            "The channel's data values mapped to density 0 and 1 (min < max). Excludes "
            "channels[].window.", vector(2),
            default="volume's, else the channel's own min and max (0..255 for 8-bit data)"),
        "channels[].window": Key(
            "As volume.window, for this channel. Excludes channels[].value_range.",
            {"oneOf": [choice(WINDOW_PRESETS),
                       {"type": "object", "additionalProperties": False,
                        "required": ["level", "width"],
                        "properties": {"level": {"type": "number"},
                                       "width": number(0.0, lo_open=True)}}]},
            default="volume's", values="a preset name or {\"level\": L, \"width\": W > 0}"),
        "channels[].transfer_function": Key(
            "The channel's transfer function, as the scene's transfer_function (an object or a "
            "file name).", {"$ref": "#/properties/transfer_function"},
            default="one colour by its place ("
            + ", ".join("(" + ", ".join(f"{v:g}" for v in c) + ")" for c in CHANNEL_COLOURS)
            + ") and the default opacity", values="as transfer_function"),
        "time": Key("A time series' step shown (SPEC.md, Time series), from 0.",
                    number(0, 1 << 24, integer=True)),
        "viewer": Key("How the viewer showed the scene when it was saved (Ctrl+S); it opens the "
                      "same way. Other commands ignore it. Absent or null: the viewer's "
                      "defaults.", {}),
        "viewer.method": Key("The method shown.", choice(VIEWER_METHODS)),
        "viewer.display": Key("image, split (against split_method) or error (a heat map "
                              "against the path tracer).", choice(VIEWER_DISPLAYS)),
        "viewer.split_method": Key("The method on the split view's other side.",
                                   choice(VIEWER_METHODS)),
        "viewer.exposure": Key("The display's exposure.", number(0.0, 1e6, lo_open=True)),
        "viewer.probe_view": Key("The probe spheres: off, over the volume, or alone.",
                                 choice(VIEWER_PROBE_VIEWS)),
        "viewer.show_box": Key("The volume's box drawn.", BOOLEAN),
    }


def _json(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_json(v) for v in value]
    return value


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return _json(f.default)
    return dataclasses.MISSING


def scene_schema() -> dict:
    """The JSON Schema (draft 2020-12) of a scene file."""
    table = keys()
    used: set[str] = set()

    def entry(path: str, f: dataclasses.Field | None) -> dict:
        if path not in table:
            raise KeyError(f"scene field {path} has no entry in app/io/scene_schema.py's keys(): "
                           "say what it means and its range there")
        used.add(path)
        key = table[path]
        out = {"description": key.meaning, **key.schema}
        default = _default(f) if f is not None else dataclasses.MISSING
        if default is not dataclasses.MISSING and default is not None:
            out["default"] = default
        return out

    def also(name: str, sub: dict) -> dict:
        """The key's schema taking what ALSO says besides its own type."""
        if name in ALSO:
            sub["type"] = [sub["type"], *ALSO[name]]
            if "string" in ALSO[name]:
                sub["minLength"] = 1
        return sub

    def obj(prefix: str, cls) -> dict:
        props = {}
        for f in dataclasses.fields(cls):
            if f.name in NOT_KEYS:
                continue
            path = f"{prefix}{f.name}"
            if f.name in NESTED and cls is Scene:
                props[f.name] = also(f.name, {**entry(path, None),
                                              **obj(f"{path}.", NESTED[f.name])})
            elif f.name in LISTS and cls is Scene:
                props[f.name] = also(f.name, {**entry(path, None), "type": "array",
                                              "items": obj(f"{path}[].", LISTS[f.name])})
            else:
                props[f.name] = entry(path, f)
        out = {"type": "object", "additionalProperties": False, "properties": props}
        name = prefix.rstrip(".")
        if name in REQUIRED:
            out["required"] = REQUIRED[name]
        if cls is CropSpec:
            out.update(VOXEL_CROP)
        return out

    schema = {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
              "title": "radiance-probes scene",
              "description": "A scene file of radiance-probes (docs/scene-format.md). Every key "
                             "has a default, so {} is a scene.",
              **obj("", Scene)}
    from radiance_probes.io.scene_file import TOP_LEVEL_VOLUME_KEYS
    for name in TOP_LEVEL_VOLUME_KEYS:
        schema["properties"][name] = entry(name, None)
    schema["properties"]["$schema"] = {"type": "string",
                                       "description": "The schema an editor validates with."}
    stale = set(table) - used
    if stale:
        raise KeyError(f"app/io/scene_schema.py's keys() names {sorted(stale)}, which no scene field "
                       "has")
    return schema


def schema_text() -> str:
    """The schema as the committed docs/scene.schema.json holds it."""
    return json.dumps(scene_schema(), indent=2) + "\n"


def _num(v) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def _range(schema: dict) -> str:
    if schema.get("type") == "boolean":
        return "true, false"
    if schema.get("type") == "string" and "enum" not in schema:
        return "text"
    if "enum" in schema:
        return ", ".join(str(v) for v in schema["enum"])
    if schema.get("type") == "array":
        n = schema.get("minItems")
        inner = _range(schema.get("items", {}))
        count = f"{n}" if n == schema.get("maxItems") else f"{n} or more"
        return f"{count} of {inner}" if inner else f"{count} numbers"
    lo = schema.get("minimum", schema.get("exclusiveMinimum"))
    hi = schema.get("maximum", schema.get("exclusiveMaximum"))
    kind = "integer" if schema.get("type") == "integer" else "number"
    if lo is None and hi is None:
        return "" if kind == "number" else "integers"
    left = "(" if "exclusiveMinimum" in schema else "["
    right = ")" if "exclusiveMaximum" in schema else "]"
    if hi is None:
        return f"{'>' if left == '(' else '>='} {_num(lo)}" + (" (integer)" if kind == "integer"
                                                              else "")
    text = f"{left}{'-inf' if lo is None else _num(lo)}, {_num(hi)}{right}"
    return text + (" (integer)" if kind == "integer" else "")


def key_table() -> str:
    """docs/scene-format.md's table: every key with its default, range and meaning."""
    schema = scene_schema()
    table = keys()
    rows = ["| key | default | range | meaning |", "| --- | --- | --- | --- |"]

    def walk(prefix: str, props: dict) -> None:
        for name, sub in props.items():
            if name == "$schema":
                continue
            path = f"{prefix}{name}"
            key = table[path]
            if "properties" in sub and not key.schema:
                kinds = {"string": "a file name", "null": "null"}
                kind = " or ".join(["object", *(kinds[t] for t in ALSO.get(path, ()))])
                rows.append(f"| `{path}` | | {kind} | {key.meaning} |")
                walk(f"{path}.", sub["properties"])
                continue
            if "properties" in sub.get("items", {}):
                count = (f"list of {sub['minItems']} to {sub['maxItems']} objects"
                         if "maxItems" in sub else "list of objects")
                kind = " or ".join([count, *ALSO.get(path, ())])
                rows.append(f"| `{path}` | [] | {kind} | {key.meaning} |")
                walk(f"{path}[].", sub["items"]["properties"])
                continue
            default = key.default if key.default is not None else (
                json.dumps(sub["default"]) if "default" in sub else "none")
            values = key.values if key.values is not None else _range(sub) or "any number"
            cells = [f"`{path}`", default, values, key.meaning]
            rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")

    walk("", schema["properties"])
    return "\n".join(rows) + "\n"


TABLE_START = "<!-- key table: generated by `radiance-probes schema --table`; do not edit -->"
TABLE_END = "<!-- end of the key table -->"


def update_docs(docs) -> list:
    """Rewrites docs/scene.schema.json and the key table of docs/scene-format.md in the folder
    `docs` (a checkout's); returns the files written."""
    from pathlib import Path
    docs = Path(docs)
    page = docs / "scene-format.md"
    text = page.read_text()
    if TABLE_START not in text or TABLE_END not in text:
        raise ValueError(f"{page}: no key table markers ({TABLE_START} ... {TABLE_END})")
    head, rest = text.split(TABLE_START, 1)
    _, tail = rest.split(TABLE_END, 1)
    page.write_text(f"{head}{TABLE_START}\n{key_table()}{TABLE_END}{tail}")
    (docs / "scene.schema.json").write_text(schema_text())
    return [docs / "scene.schema.json", page]
