"""The slice view's maths (no GL, no ImGui): the data on three orthogonal planes beside the 3D
view, as Slicer, ParaView and napari show it. app/viewer/panels/slice_panel.py draws what this computes.

The world box is docs/scene-format.md's: centred at the origin, array axis x along world +x, y
along +y, z along +z, voxel i of n along an axis centred at ((i + 0.5) / n * 2 - 1) * half. The
slice across axis a at voxel index i is the plane world[a] = that centre, and it lies on the
screen as the 3D view shows it from a camera orbited from the default one (on +z looking along -z,
+y up; SCREEN_AXES):

  z slice: seen from +z, right +x, up +y (the default camera's own view)
  x slice: seen from +x, right -z, up +y (orbited a quarter turn to the right)
  y slice: seen from below, right +x, up +z (orbited under the volume)

With "orientation": "patient" (+x left, +y superior, +z anterior) that is the radiological
convention: the axial (y) slice seen from the feet, patient's left on the right, anterior up; the
sagittal (x) slice with the face to the left; the coronal (z) slice face on, left on the right.

Pixels are window coordinates (top-left origin); a slice's rectangle is (x, y, w, h) there.
Voxels are (i, j, k) along (x, y, z): the density of voxel (i, j, k) is data[k, j, i].
"""
from __future__ import annotations

import math

import numpy as np

AXES = "xyz"
# "off", all three beside the 3D view, or one of them (bigger).
SLICE_VIEWS = ("off", "three", "x", "y", "z")
# What a slice shows: the density as grey (the window: density 0 black, 1 white), or the
# renderer's transfer function (its colour where it is opaque, fading to black where it is clear).
SLICE_COLOURS = ("window", "transfer function")
# For the slice across each axis: (world axis, sign) along the image's right, and along its top.
SCREEN_AXES = {0: ((2, -1), (1, +1)), 1: ((0, +1), (2, +1)), 2: ((0, +1), (1, +1))}
# A value within this fraction of the value range of an integer reads as that integer: the
# float32 density keeps about 6e-8 of the range (16 times that, for the arithmetic around it).
FLOAT32_DENSITY_STEP = 1e-6
CUT_AWAY_SHADE = 0.3          # what is cut away (crop, clip plane) is drawn this bright
AXIS_COLOURS = {0: (0.95, 0.35, 0.35, 1.0), 1: (0.4, 0.9, 0.4, 1.0), 2: (0.45, 0.6, 1.0, 1.0)}
# The slice column: three slices stacked take at most this much of the view's width, one slice
# (bigger) at most this much.
THREE_WIDTH_FRACTION, ONE_WIDTH_FRACTION = 0.4, 0.5


# ---- slice index <-> world position ------------------------------------------------------------

def slice_coord(index: int, n: int, half: float) -> float:
    """The world coordinate of voxel `index`'s centre along an axis of n voxels (the slice's)."""
    return ((int(index) + 0.5) / n * 2.0 - 1.0) * float(half)


def slice_index(coord: float, n: int, half: float) -> int:
    """The voxel whose cell holds world coordinate `coord` along an axis of n voxels, clamped to
    the volume: the slice through that point."""
    i = math.floor((float(coord) + float(half)) / (2.0 * float(half)) * n)
    return int(min(max(i, 0), n - 1))


def slice_indices(point, dims, half_extent) -> tuple[int, int, int]:
    """The voxel (i, j, k) holding a world point (clamped into the volume): the three slices
    through it."""
    return tuple(slice_index(point[a], dims[a], half_extent[a]) for a in range(3))


def voxel_centre(voxel, dims, half_extent) -> np.ndarray:
    return np.array([slice_coord(voxel[a], dims[a], half_extent[a]) for a in range(3)])


# ---- the slice image ---------------------------------------------------------------------------

def image_shape(axis: int, dims) -> tuple[int, int]:
    """(rows, columns) of the slice across `axis`: voxels along its up and right axes."""
    (right, _), (up, _) = SCREEN_AXES[axis]
    return dims[up], dims[right]


def slice_image(data, axis: int, index: int) -> np.ndarray:
    """The densities of the slice across `axis` at voxel `index`, (rows, columns) as drawn: row 0
    at the top, column 0 at the left (SCREEN_AXES). `data`: one channel's [z, y, x]."""
    dims = (data.shape[2], data.shape[1], data.shape[0])
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    nu, nr = dims[up], dims[right]
    cols, rows = np.arange(nr), np.arange(nu)
    at = [None, None, None]
    at[axis] = int(index)
    at[right] = (cols if rsign > 0 else nr - 1 - cols)[None, :]
    at[up] = (nu - 1 - rows if usign > 0 else rows)[:, None]
    return np.asarray(data[at[2], at[1], at[0]])


def slice_world_points(axis: int, index: int, dims, half_extent) -> np.ndarray:
    """World centres (rows, columns, 3) of the slice image's texels."""
    rows, cols = image_shape(axis, dims)
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    he = np.asarray(half_extent, np.float64)
    fx = (np.arange(cols) + 0.5) / cols            # 0 at the left edge, 1 at the right
    fy = (np.arange(rows) + 0.5) / rows            # 0 at the top, 1 at the bottom
    out = np.empty((rows, cols, 3))
    out[..., axis] = slice_coord(index, dims[axis], he[axis])
    out[..., right] = (rsign * (2.0 * fx - 1.0) * he[right])[None, :]
    out[..., up] = (usign * (1.0 - 2.0 * fy) * he[up])[:, None]
    return out


# ---- mouse pixel <-> voxel <-> world -----------------------------------------------------------

def pixel_voxel(pixel, rect, axis: int, index: int, dims) -> tuple[int, int, int] | None:
    """The voxel (i, j, k) drawn under a window pixel of the slice across `axis` at voxel `index`
    drawn in `rect`; None outside the slice."""
    x0, y0, w, h = rect
    fx, fy = (pixel[0] - x0) / w, (pixel[1] - y0) / h
    if not (0.0 <= fx < 1.0 and 0.0 <= fy < 1.0):
        return None
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    nr, nu = dims[right], dims[up]
    c, r = min(int(fx * nr), nr - 1), min(int(fy * nu), nu - 1)
    voxel = [0, 0, 0]
    voxel[axis] = int(index)
    voxel[right] = c if rsign > 0 else nr - 1 - c
    voxel[up] = nu - 1 - r if usign > 0 else r
    return tuple(voxel)


def world_pixels(points, rect, axis: int, half_extent) -> np.ndarray:
    """Where world points (k, 3) land on the slice across `axis` drawn in `rect` (their component
    along `axis` is ignored: projected onto the slice), window pixels (k, 2)."""
    x0, y0, w, h = rect
    p = np.asarray(points, np.float64).reshape(-1, 3)
    he = np.asarray(half_extent, np.float64)
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    fx = (rsign * p[:, right] / he[right] + 1.0) / 2.0
    fy = (1.0 - usign * p[:, up] / he[up]) / 2.0
    return np.stack([x0 + fx * w, y0 + fy * h], axis=1)


def pixel_world(pixel, rect, axis: int, coord: float, half_extent) -> np.ndarray:
    """The world point under a window pixel of the slice across `axis` at world coordinate
    `coord` (the inverse of world_pixels)."""
    x0, y0, w, h = rect
    he = np.asarray(half_extent, np.float64)
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    fx, fy = (pixel[0] - x0) / w, (pixel[1] - y0) / h
    p = np.zeros(3)
    p[axis] = coord
    p[right] = rsign * (2.0 * fx - 1.0) * he[right]
    p[up] = usign * (1.0 - 2.0 * fy) * he[up]
    return p


# ---- the crop box and the clip plane on a slice ------------------------------------------------

def crop_rect(box_min, box_max, rect, axis: int, half_extent) -> tuple[float, float, float, float]:
    """The crop box [box_min, box_max] (world) on the slice across `axis` drawn in `rect`: its
    rectangle (left, top, right, bottom) in window pixels."""
    corners = world_pixels([box_min, box_max], rect, axis, half_extent)
    (left, top), (right, bottom) = corners.min(axis=0), corners.max(axis=0)
    return float(left), float(top), float(right), float(bottom)


def plane_segment(normal, distance: float, lo, hi, axis: int, coord: float) -> np.ndarray:
    """Where the plane dot(normal, x) = distance crosses the slice world[axis] = coord inside the
    box [lo, hi]: its two end points (2, 3) in world, or (0, 3) where it misses."""
    n = np.asarray(normal, np.float64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    (right, _), (up, _) = SCREEN_AXES[axis]
    if not lo[axis] <= coord <= hi[axis]:
        return np.zeros((0, 3))
    corners = []
    for u in (lo[right], hi[right]):
        for v in (lo[up], hi[up]):
            p = np.zeros(3)
            p[axis], p[right], p[up] = coord, u, v
            corners.append(p)
    c = [corners[0], corners[1], corners[3], corners[2]]    # around the rectangle
    points = []
    for p, q in zip(c, c[1:] + c[:1]):
        fp, fq = p @ n - distance, q @ n - distance
        if fp == 0.0:
            points.append(p)
        elif (fp < 0.0) != (fq < 0.0) and fq != 0.0:
            points.append(p + fp / (fp - fq) * (q - p))
    if len(points) < 2:
        return np.zeros((0, 3))
    points = np.unique(np.round(np.array(points), 12), axis=0)
    if len(points) < 2:
        return np.zeros((0, 3))
    # the two farthest apart (a plane through a corner may give three)
    d = np.linalg.norm(points[:, None] - points[None], axis=-1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return points[[i, j]]


# ---- colours -----------------------------------------------------------------------------------

def slice_rgba(densities: np.ndarray, mode: str, table=None, kept: np.ndarray | None = None
               ) -> np.ndarray:
    """The slice as drawn, uint8 (rows, columns, 4). `densities`: (rows, columns) of one channel,
    or (rows, columns, c) with `table` an app.channels.ChannelTables; "window": the density as
    grey (of the first channel given); "transfer function": each channel's table colour weighted
    by its opacity (app/scene/transfer.py lookup, the renderer's interpolation), channels added;
    `kept`: bool (rows, columns), what is cut away drawn at CUT_AWAY_SHADE."""
    from radiance_probes.scene.transfer import lookup
    d = np.asarray(densities, np.float64)
    if mode == "window":
        grey = np.clip(d if d.ndim == 2 else d[..., 0], 0.0, 1.0)
        rgb = np.repeat(grey[..., None], 3, axis=-1)
    elif mode == "transfer function":
        if hasattr(table, "tables"):
            rgb = np.zeros(d.shape[:2] + (3,))
            for c, (t, on) in enumerate(zip(table.tables, table.on)):
                if on:
                    rgba = lookup(np.asarray(t), d[..., c])
                    rgb += rgba[..., :3] * rgba[..., 3:]
        else:
            rgba = lookup(np.asarray(table), d)
            rgb = rgba[..., :3] * rgba[..., 3:]
    else:
        raise ValueError(f"unknown slice colours {mode!r} (known: {', '.join(SLICE_COLOURS)})")
    if kept is not None:
        rgb = rgb * np.where(kept, 1.0, CUT_AWAY_SHADE)[..., None]
    out = np.empty(rgb.shape[:2] + (4,), np.uint8)
    out[..., :3] = np.round(np.clip(rgb, 0.0, 1.0) * 255.0)
    out[..., 3] = 255
    return out


# ---- the value under the mouse, in data units --------------------------------------------------

def value_unit(volume, scene=None) -> str:
    """The data's unit where it is known: Hounsfield units for a DICOM CT (its rescale applied)
    or a scene windowed with a named CT window (app/scene/clinical_presets.py has checked the data),
    grays for an RT dose; "" otherwise."""
    from radiance_probes.scene.clinical_presets import is_ct, is_hounsfield_window
    if is_ct(volume) or (scene is not None and not scene.channels
                         and is_hounsfield_window(scene.volume.window)):
        return "HU"
    series = getattr(volume, "dicom_series", None)
    if series is not None and str(getattr(series, "modality", "")).upper() == "RTDOSE":
        return "Gy"
    return ""


def data_value(volume, voxel, channel: int = 0) -> tuple[float, int]:
    """The data value of a voxel (i, j, k) of one channel: the density mapped back through the
    value range (value_range, or channel_ranges) it was normalised by; integer data rounded to
    its integer, and so is float data within the float32 density's precision of one (a DICOM
    CT's rescaled HU are float32 integers). The volume keeps densities clamped to [0, 1], so a
    voxel beyond the range reads as its end: the second number says so (-1 below the range, +1
    above, 0 within). Returns (value, clamp)."""
    i, j, k = voxel
    d = float(volume.channel(channel)[k, j, i])
    ranges = volume.channel_ranges or (volume.value_range,)
    raws = volume.channel_raw or ((volume.raw_min, volume.raw_max),)
    lo, hi = ranges[channel]
    raw_lo, raw_hi = raws[channel]
    value = lo + d * (hi - lo)
    if (np.dtype(volume.raw_dtype).kind in "iu"
            or abs(value - round(value)) <= FLOAT32_DENSITY_STEP * (hi - lo)):
        value = float(round(value))
    clamp = -1 if d <= 0.0 and raw_lo < lo else (+1 if d >= 1.0 and raw_hi > hi else 0)
    return value, clamp


def value_text(value: float, clamp: int, unit: str = "") -> str:
    """A value as the slice view shows it: '812 HU', '<= -160 HU (below the window)'."""
    number = f"{value:.0f}" if float(value).is_integer() else f"{value:.4g}"
    text = f"{number} {unit}".strip()
    if clamp < 0:
        return f"<= {text} (below the window)"
    if clamp > 0:
        return f">= {text} (above the window)"
    return text


def describe_voxel(volume, voxel, scene=None) -> str:
    """'(i, j, k): value' for the voxel under the mouse, every channel's value for several."""
    unit = value_unit(volume, scene)
    where = f"({voxel[0]}, {voxel[1]}, {voxel[2]})"
    if volume.channel_count == 1:
        return f"{where}: {value_text(*data_value(volume, voxel), unit)}"
    values = [f"ch{c} {value_text(*data_value(volume, voxel, c), unit)}"
              for c in range(volume.channel_count)]
    return f"{where}: " + ", ".join(values)


# ---- names and the screen's axes ---------------------------------------------------------------

PLANE_OF_LPS = ("sagittal", "coronal", "axial")   # across L-R, across P-A, across S-I
LPS_LETTERS = (("R", "L"), ("A", "P"), ("I", "S"))  # the negative and positive end of L, P, S


def patient_axes(direction) -> tuple[int, int, int] | None:
    """For each world axis, the patient axis it mostly points along (0 L-R, 1 P-A, 2 S-I) and
    which way (sign), as ((lps, sign) x 3); None where the volume does not say or two axes share
    one patient axis. `direction`: Volume.direction (LPS, columns x, y, z)."""
    if direction is None:
        return None
    d = np.asarray(direction, np.float64)
    dominant = [int(np.argmax(np.abs(d[:, a]))) for a in range(3)]
    if len(set(dominant)) < 3:
        return None
    return tuple((dominant[a], 1 if d[dominant[a], a] > 0 else -1) for a in range(3))


def slice_name(axis: int, direction=None) -> str:
    """'z', or 'z (axial)' where the volume says where its axes point in the patient."""
    axes = patient_axes(direction)
    if axes is None:
        return AXES[axis]
    return f"{AXES[axis]} ({PLANE_OF_LPS[axes[axis][0]]})"


def edge_labels(axis: int, direction=None) -> dict[str, str]:
    """What the slice's edges face: {"right": "+x", "left": "-x", "top": ..., "bottom": ...}, in
    the patient's letters (L, R, A, P, S, I) where the volume says where its axes point."""
    (right, rsign), (up, usign) = SCREEN_AXES[axis]
    axes = patient_axes(direction)

    def end(a: int, sign: int) -> str:
        if axes is None:
            return f"{'+' if sign > 0 else '-'}{AXES[a]}"
        lps, s = axes[a]
        return LPS_LETTERS[lps][1 if sign * s > 0 else 0]

    return {"right": end(right, rsign), "left": end(right, -rsign),
            "top": end(up, usign), "bottom": end(up, -usign)}


# ---- where the slices go -----------------------------------------------------------------------

def shown_axes(mode: str) -> tuple[int, ...]:
    if mode == "off":
        return ()
    if mode == "three":
        return (2, 1, 0)      # z (the default camera's own view) on top, then y, then x
    return (AXES.index(mode),)


def column_width(mode: str, window_size, sidebar_width: float) -> float:
    """The width of the slice column at the window's right (window coordinates); 0 when off."""
    w, h = window_size
    view = max(w - sidebar_width, 1.0)
    if mode == "off":
        return 0.0
    if mode == "three":
        return float(max(min(h / 3.0, THREE_WIDTH_FRACTION * view), 1.0))
    return float(max(min(float(h), ONE_WIDTH_FRACTION * view), 1.0))


def slice_boxes(mode: str, column) -> list[tuple[int, tuple[float, float, float, float]]]:
    """(axis, box) of each slice shown, stacked in the column (x, y, w, h)."""
    axes = shown_axes(mode)
    if not axes:
        return []
    x, y, w, h = column
    step = h / len(axes)
    return [(a, (x, y + k * step, w, step)) for k, a in enumerate(axes)]


def fit_rect(area, extent) -> tuple[float, float, float, float]:
    """The largest rectangle of aspect extent (width, height) centred in `area` (x, y, w, h)."""
    x, y, w, h = area
    ew, eh = extent
    scale = min(w / ew, h / eh)
    fw, fh = ew * scale, eh * scale
    return (x + (w - fw) / 2.0, y + (h - fh) / 2.0, fw, fh)


def plane_extent(axis: int, half_extent) -> tuple[float, float]:
    """The slice's world width and height (along its right and up axes)."""
    (right, _), (up, _) = SCREEN_AXES[axis]
    return 2.0 * float(half_extent[right]), 2.0 * float(half_extent[up])


def slice_outline(axis: int, coord: float, half_extent) -> np.ndarray:
    """The slice plane's rectangle in the volume box, its 4 world corners in order (for drawing
    it in the 3D view)."""
    he = np.asarray(half_extent, np.float64)
    (right, _), (up, _) = SCREEN_AXES[axis]
    out = []
    for u, v in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        p = np.zeros(3)
        p[axis], p[right], p[up] = coord, u * he[right], v * he[up]
        out.append(p)
    return np.array(out)
