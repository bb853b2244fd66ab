"""The scene's types (SPEC.md): frozen dataclasses, the error every bad scene value raises, the
limits values are checked against, and the scene written back as JSON data.

Loaders (app/io/volume.py) and transfer functions (app/scene/transfer.py) import these; app/io/scene_file.py parses
and validates JSON into them (and re-exports them), so neither side imports the other's parser.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any


class SceneError(ValueError):
    """A scene file or dictionary that does not follow SPEC.md; the message names the field."""


class VolumeError(ValueError):
    """A volume that cannot be used; the message names the file and the problem (raised by the
    loaders in app/io/volume.py and app/io/volume_formats.py, defined here so both can import it)."""


# CT windows in Hounsfield units, (level, width): the window maps level - width / 2 to density 0
# and level + width / 2 to 1 (radiology's usual lung, soft-tissue and bone windows; "air" spans
# air to lung parenchyma, for airways and gas).
WINDOW_PRESETS: dict[str, tuple[float, float]] = {
    "air": (-650.0, 700.0),
    "lung": (-600.0, 1500.0),
    "soft_tissue": (40.0, 400.0),
    "bone": (400.0, 1800.0),
}


def window_range(level: float, width: float) -> tuple[float, float]:
    """The data values a window (level, width) maps to densities 0 and 1."""
    return (float(level) - 0.5 * float(width), float(level) + 0.5 * float(width))


# Largest values we accept; beyond them a scene is almost surely a typo and would only hang.
MAX_BOUNCES_LIMIT = 1_000_000_000
MAX_IMAGE_SIDE = 16384
MAX_PROBE_AXIS = 256
MAX_PROBE_SAMPLES = 1 << 20
MAX_TRANSFER_ROWS = 4096  # the table is an N x 1 texture; GL guarantees widths up to 16384
SH_WINDOWS = ("none", "hann", "lanczos")
# "auto" (probe_layout.resolve_precision): rgba16f where surfaces read the probes' directions, else
# rgba32f
PROBE_PRECISIONS = ("auto", "rgba32f", "rgba16f")
PROBE_FITS = ("visible", "box")
PROBE_LAYOUTS = ("uniform", "adaptive")
# What drives an adaptive layout's probe density (app/rendering/probes/planes.py): "extinction", the
# variation of sigma_t along each axis; "sun", the variation of the sun's transmittance (light grid).
PROBE_INDICATORS = ("extinction", "sun")
# How a point blends the 8 probes around it (glsl/lib/probe_visibility.glsl): "trilinear", by
# distance alone; "visibility", each probe's weight also scaled by how much denser matter than the
# point's own lies on the straight way to it (no light or darkness through walls).
PROBE_INTERPOLATIONS = ("trilinear", "visibility")
# The SH orders probes can hold (glsl/lib/probe_packing.glsl; "auto" picks among them).
SH_ORDERS = (0, 1, 2, 3, 4)
# How a volume's array axes meet the world (app/io/orientation.py).
ORIENTATIONS = ("data", "patient")


@dataclass(frozen=True)
class VolumeSpec:
    path: str | None = None
    builtin: str | None = "cloud"
    size: tuple[int, int, int] = (64, 64, 64)
    # None: the file's own spacing (an NRRD header's), else 1, 1, 1. A value given here always wins,
    # even [1, 1, 1], which is why the default is None rather than (1, 1, 1).
    spacing: tuple[float, float, float] | None = None
    value_range: tuple[float, float] | None = None
    dims: tuple[int, int, int] | None = None  # for .raw files not in the Open SciVis naming
    dtype: str | None = None
    replace_nonfinite: float | None = None  # None: NaN/Inf in the data are an error
    # (slope, intercept): the file's stored values to data units (value * slope + intercept), as
    # DICOM's RescaleSlope/RescaleIntercept do, for data exported without them (an 8-bit CT
    # windowed from Hounsfield units); value_range, window and CT presets are then in data units.
    rescale: tuple[float, float] | None = None
    # (level, width) in data units (Hounsfield units for CT), or a WINDOW_PRESETS name in the JSON:
    # another way to give value_range (level -/+ width / 2), which it excludes.
    window: tuple[float, float] | None = None
    # A DICOM folder tree or DICOMDIR's series: its number in the listing (from 1) or its
    # SeriesInstanceUID; None: the largest series that makes one volume (app/io/dicom.py).
    series: int | str | None = None
    # "data": data[z, y, x] on world x, y, z as stored; "patient": axes permuted and flipped to
    # world +x = left, +y = superior, +z = anterior where the file says (app/io/orientation.py).
    orientation: str = "data"
    # Which array axis is which, e.g. "czyx" or "tzyx" (letters t, c, z, y, x, each once, z, y and
    # x always): needed for a .npy of more than 3 dimensions and for a file whose metadata leaves
    # axes unnamed; for a file whose metadata names its axes it must agree with them.
    axes: str | None = None

    @property
    def domain(self) -> tuple[float, float] | None:
        """The data values mapped to densities 0 and 1: value_range or the window; None for the
        default (the data's own range, or the type's for 8-bit data)."""
        if self.window is not None:
            return window_range(*self.window)
        return self.value_range


@dataclass(frozen=True)
class TransferFunctionSpec:
    colormap: str = "plasma"
    opacity: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.2, 0.0), (1.0, 1.0))
    rgba: tuple[tuple[float, float, float, float], ...] | None = None
    resolution: int = 256
    # Colour control points (density, r, g, b), linearly interpolated and constant beyond the
    # first and last: they replace the colormap's colours (JSON "colors"; excludes "colormap").
    colors: tuple[tuple[float, float, float, float], ...] | None = None
    # The clinical preset (app/scene/clinical_presets.py) the colours and opacity were expanded from
    # (JSON "preset": NAME, in place of colormap, colors, opacity and rgba): a label for the
    # viewer; the colours and opacity are what renders, and what a saved scene holds.
    preset: str | None = field(default=None, compare=False)


# The letters of volume.axes: time, channel and the three space axes.
AXIS_LETTERS = "tczyx"
# Channels (SPEC.md, Channels): at most this many are shown at once (one RGBA volume texture).
MAX_CHANNELS = 4
# The default colour of channel i where the scene gives it no transfer function: light tints, so
# that every channel also scatters some of the other colours (a pure primary would absorb them).
CHANNEL_COLOURS = ((0.25, 1.0, 0.25), (1.0, 0.25, 1.0), (0.25, 1.0, 1.0), (1.0, 1.0, 0.25))


def channel_transfer_function(i: int) -> "TransferFunctionSpec":
    """Channel i's default transfer function: its colour (CHANNEL_COLOURS) at every density, the
    default opacity ramp."""
    r, g, b = CHANNEL_COLOURS[i % len(CHANNEL_COLOURS)]
    return TransferFunctionSpec(colors=((0.0, r, g, b),))


@dataclass(frozen=True)
class ChannelSpec:
    """One channel of a multi-channel volume (SPEC.md, Channels): which channel of the file
    (`index`; None: its place in the scene's list), shown or not, its own transfer function and
    window (value_range or window, as volume's; None: volume's, else the channel's own range)."""
    transfer_function: "TransferFunctionSpec"
    name: str | None = None
    index: int | None = None
    enabled: bool = True
    value_range: tuple[float, float] | None = None
    window: tuple[float, float] | None = None

    def domain(self, volume: "VolumeSpec") -> tuple[float, float] | None:
        """The data values mapped to densities 0 and 1 in this channel."""
        if self.window is not None:
            return window_range(*self.window)
        if self.value_range is not None:
            return self.value_range
        return volume.domain


def _unit(v: tuple, name: str) -> tuple[float, float, float]:
    """``v`` scaled to unit length; idempotent, so a vector already of unit length is kept bit for bit
    (re-normalising one can change its last bits, which would break the JSON round trip)."""
    n = math.sqrt(sum(float(c) * float(c) for c in v))
    if not n >= 1e-9 or not math.isfinite(n):
        raise SceneError(f"{name}: must be a finite, non-zero vector, got {list(v)!r}")
    if abs(n - 1.0) <= 4e-16:
        return tuple(float(c) for c in v)
    return tuple(float(c) / n for c in v)


@dataclass(frozen=True)
class LightSpec:
    direction: tuple[float, float, float] = (0.5, 0.8, 0.3)  # normalised in __post_init__
    irradiance: tuple[float, float, float] = (3.0, 3.0, 3.0)

    def __post_init__(self) -> None:
        # A unit vector however the spec was made (parse_scene, LightSpec(), dataclasses.replace).
        object.__setattr__(self, "direction", _unit(self.direction, "light.direction"))


@dataclass(frozen=True)
class EnvironmentMapSpec:
    """An equirectangular environment map (SPEC.md): `path` relative to the scene file like volume
    paths, radiance multiplied by `scale`, the map turned by `rotation` degrees about +y (the
    radiance from direction d is the map's at R_y(-rotation) d)."""
    path: str
    scale: float = 1.0
    rotation: float = 0.0


@dataclass(frozen=True)
class CameraSpec:
    eye: tuple[float, float, float] = (0.0, 0.3, 2.2)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y: float = 35.0
    width: int = 512
    height: int = 512


@dataclass(frozen=True)
class ProbeSpec:
    grid: tuple[int, int, int] = (16, 16, 16)
    samples: int = 256
    sh_window: str = "none"
    # "auto": rgba16f with surfaces (k > 0), else rgba32f (probe_layout.resolve_precision)
    precision: str = "auto"
    # "auto": order 0 when g = 0 (the phase convolution zeroes bands 1 and 2: exact), else 2.
    sh_order: str | int = "auto"
    # "visible": the grid covers only where the transfer function makes the medium visible, and a
    # cubic grid N puts N probes along that region's longest side; "box": the whole volume box.
    fit: str = "visible"
    # "auto": one channel when the transfer function's colours and both lights are grey, else 3.
    channels: str | int = "auto"
    # "uniform": probe planes evenly spaced along each axis; "adaptive": per axis, more planes where
    # `adaptive_indicator` says the light changes fast (app/rendering/probes/planes.py), the same count.
    layout: str = "uniform"
    # 0: uniform; 1: the indicator alone decides (within the spacing bounds of probe_planes.py).
    adaptive_strength: float = 0.5
    adaptive_indicator: str = "extinction"
    interpolation: str = "trilinear"


# The surface's bounds (glsl/lib/hybrid_scattering.glsl): k beyond this makes every point with any
# gradient a surface (P = 1 - exp(-k |grad A|) rounds to 1 for |grad A| > 4e-3); GGX alpha below
# MIN_ROUGHNESS is a mirror the float pdf cannot hold.
MAX_GRADIENT_FACTOR = 1e4
MIN_ROUGHNESS = 0.02


@dataclass(frozen=True)
class SurfaceSpec:
    """Hybrid scattering (docs/scene-format.md, Surfaces): at each scattering event a surface BRDF
    scatters with probability 1 - exp(-gradient_factor |grad A|) (A = sigma_t / density_scale, in
    world units), the phase function otherwise. 0: the phase function alone (today's images, bit
    for bit). The BRDF: Lambertian diffuse (1 - max(specular)) / pi plus GGX of `roughness`
    (alpha) with the constant Fresnel colour `specular`."""
    gradient_factor: float = 0.0
    roughness: float = 0.5
    specular: tuple[float, float, float] = (0.04, 0.04, 0.04)


# Area lights (glsl/lib/area_lights.glsl): their shapes, and how many a scene may have on.
AREA_LIGHT_SHAPES = ("sphere", "rectangle")
MAX_AREA_LIGHTS = 8


@dataclass(frozen=True)
class AreaLightSpec:
    """An area light outside the volume box (docs/scene-format.md, Area lights): a sphere of radius
    `size` or a rectangle of `size` [width, height] centred at `position`, facing `normal` (a
    rectangle emits from its front face only; its edges lie along an orthonormal basis of the
    normal, app/scene/area_lights.py), of radiance colour x strength, uniform over its surface."""
    shape: str
    position: tuple[float, float, float]
    size: float | tuple[float, float]
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    strength: float = 1.0
    normal: tuple[float, float, float] = (0.0, -1.0, 0.0)
    enabled: bool = True


# Crop boxes are given in world units or in voxel indices (docs/crop-and-movies.md).
CROP_UNITS = ("world", "voxels")


@dataclass(frozen=True)
class CropSpec:
    """A crop box (SPEC.md, Crop and clip): the part of the volume box between its six planes is
    kept. units "world": `min` and `max` are world coordinates; "voxels": they are voxel
    boundaries, keeping voxels min <= i < max along each axis (NumPy's data[z0:z1, y0:y1, x0:x1]).
    Within the box the density is the cropped volume's (clamped to its outermost voxels, as a
    volume is at its own faces), so a crop on voxel boundaries renders as the cropped volume does."""
    min: tuple[float, float, float]
    max: tuple[float, float, float]
    units: str = "world"
    enabled: bool = True


@dataclass(frozen=True)
class ClipPlaneSpec:
    """A clip plane (SPEC.md): keeps the points x with dot(normal, x) <= distance (world units;
    a normal that is not of unit length scales the distance with it, the same kept half-space)."""
    normal: tuple[float, float, float]
    distance: float = 0.0
    enabled: bool = True


@dataclass(frozen=True)
class BookmarkSpec:
    """A camera saved under a name (the viewer's keys recall it; `animate --keyframes` flies
    through bookmarks). The image size stays the scene camera's."""
    name: str
    eye: tuple[float, float, float]
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y: float = 35.0

    def camera(self, base: "CameraSpec") -> "CameraSpec":
        """The bookmark as a camera of `base`'s image size."""
        return dataclasses.replace(base, eye=self.eye, target=self.target, up=self.up,
                                   fov_y=self.fov_y)


# The viewer's display modes (app/viewer/state.py DISPLAY_MODES; a test keeps them so). Its
# methods and a movie's are the registry's (app/methods.py).
VIEWER_DISPLAYS = ("image", "split", "error")
VIEWER_PROBE_VIEWS = ("off", "over", "alone")


@dataclass(frozen=True)
class ViewerSpec:
    """How the viewer showed the scene when it was saved (JSON "viewer"): it opens the same way."""
    method: str = "pt"
    display: str = "image"
    split_method: str = "probes"
    exposure: float = 1.0
    probe_view: str = "off"
    show_box: bool = False


@dataclass(frozen=True)
class Scene:
    volume: VolumeSpec = field(default_factory=VolumeSpec)
    transfer_function: TransferFunctionSpec = field(default_factory=TransferFunctionSpec)
    density_scale: float = 100.0
    albedo: float = 0.9
    anisotropy: float = 0.0
    light: LightSpec = field(default_factory=LightSpec)
    environment: tuple[float, float, float] = (0.1, 0.1, 0.1)
    # JSON "environment": {"map": ...}: the map replaces the constant `environment` (kept, unused).
    environment_map: EnvironmentMapSpec | None = None
    max_bounces: int = 64
    camera: CameraSpec = field(default_factory=CameraSpec)
    probes: ProbeSpec = field(default_factory=ProbeSpec)
    surface: SurfaceSpec = field(default_factory=SurfaceSpec)
    area_lights: tuple[AreaLightSpec, ...] = ()
    crop: CropSpec | None = None
    clip_plane: ClipPlaneSpec | None = None
    bookmarks: tuple[BookmarkSpec, ...] = ()
    viewer: ViewerSpec | None = None
    # Several channels (SPEC.md, Channels): empty for a one-channel volume, or a file's channels
    # each with the default colour of its place (app/scene/channels.py effective_channels).
    channels: tuple[ChannelSpec, ...] = ()
    # Time series (SPEC.md, Time series): the step shown of a volume with a time axis.
    time: int = 0
    # Folder that relative volume paths are also looked up in (the scene file's folder).
    base_dir: str | None = field(default=None, compare=False)

    def replace(self, **changes: Any) -> "Scene":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return scene_to_dict(self)


def scene_to_dict(scene: Scene) -> dict:
    """The scene as JSON-ready data; ``parse_scene(scene_to_dict(s)) == s``."""
    def conv(x):
        if isinstance(x, tuple):
            return [conv(v) for v in x]
        return x

    out: dict[str, Any] = {}
    for f in dataclasses.fields(scene):
        if f.name in ("base_dir", "environment_map"):
            continue
        if f.name == "transfer_function" and scene.channels:
            continue   # each channel has its own
        v = getattr(scene, f.name)
        if f.name in OPTIONAL_FIELDS:
            if v:   # written only where the scene has them, so older scenes stay as they were
                out[f.name] = ([_plain(b) for b in v] if f.name in ("bookmarks", "area_lights") else
                               [channel_to_dict(c) for c in v] if f.name == "channels" else
                               v if f.name == "time" else _plain(v))
            continue
        if f.name == "surface" and v == SurfaceSpec():
            continue   # k = 0: written only where the scene has surfaces
        if f.name == "environment" and scene.environment_map is not None:
            m = scene.environment_map
            out[f.name] = {"map": m.path, "scale": m.scale, "rotation": m.rotation}
            continue
        if dataclasses.is_dataclass(v):
            sub = {k.name: conv(getattr(v, k.name)) for k in dataclasses.fields(v)}
            if f.name == "volume":
                sub = {k: val for k, val in sub.items() if val is not None}
                if v.orientation == "data":
                    sub.pop("orientation")   # the default, left out as the other defaults are
                if v.window is not None:
                    sub["window"] = {"level": v.window[0], "width": v.window[1]}
                if v.path:
                    sub.pop("builtin", None)
                    sub.pop("size", None)
            if f.name == "transfer_function":
                sub = transfer_to_dict(v)
            out[f.name] = sub
        else:
            out[f.name] = conv(v)
    return out


# Scene fields written only where the scene has them (None or empty: left out).
OPTIONAL_FIELDS = ("crop", "clip_plane", "bookmarks", "viewer", "channels", "time", "area_lights")


def _plain(spec) -> dict:
    """A small spec dataclass as JSON data (tuples as lists)."""
    def conv(x):
        return [conv(v) for v in x] if isinstance(x, tuple) else x
    return {k.name: conv(getattr(spec, k.name)) for k in dataclasses.fields(spec)}


def channel_to_dict(channel: ChannelSpec) -> dict:
    """A channel as the JSON of the scene's channels list (unset fields left out)."""
    out: dict[str, Any] = {}
    if channel.name is not None:
        out["name"] = channel.name
    if channel.index is not None:
        out["index"] = channel.index
    out["enabled"] = channel.enabled
    if channel.value_range is not None:
        out["value_range"] = list(channel.value_range)
    if channel.window is not None:
        out["window"] = {"level": channel.window[0], "width": channel.window[1]}
    out["transfer_function"] = transfer_to_dict(channel.transfer_function)
    return out


def transfer_to_dict(tf: TransferFunctionSpec) -> dict:
    """The transfer function as the JSON the scene's transfer_function key (and a transfer-function
    file) holds: rgba rows, or colour points or a colormap with the opacity curve."""
    sub = _plain(tf)
    sub.pop("preset")   # the expanded colours and opacity are written
    if tf.rgba is not None:
        for key in ("colormap", "opacity", "colors"):
            sub.pop(key)
    else:
        sub.pop("rgba")
        sub.pop("colormap" if tf.colors is not None else "colors")
    return sub
