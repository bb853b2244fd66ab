"""napari's image layers as this project's scene: the data, its placement (camera_map.Placement),
and each layer's look (contrast limits, colormap, gamma, opacity, visibility) as a transfer
function and window; several visible layers as channels (docs/channels-and-time.md). A layer that
cannot be rendered gives a LayerProblem, one sentence naming the layer and what to do.

The look: napari shows a value v as colormap(((v - lo) / (hi - lo)) ** gamma) with the layer's
opacity. Here the window [lo, hi] (contrast_limits) maps v to the density d in [0, 1], and the
transfer function is TRANSFER_ROWS rows at evenly spaced d: colour colormap(d ** gamma), opacity
layer.opacity * d ** gamma (the extinction per unit length is density_scale times that opacity).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radiance_probes.napari_plugin.camera_map import Placement, napari_camera, right_handed

TRANSFER_ROWS = 64            # rows of each layer's transfer function
MAX_CHANNELS = 4              # SPEC.md: a volume has up to 4 channels
MAX_VOXELS = 512 ** 3         # a larger layer is refused (say so) rather than copied whole


class LayerProblem(ValueError):
    """A layer (or the viewer's state) that the plugin cannot render, in one sentence."""


@dataclass(frozen=True)
class LayerScene:
    """What the renderer is given: the array ([z, y, x], or [c, z, y, x] for channels), the
    render()/Renderer keyword options, the placement and the layers' names."""
    data: np.ndarray
    options: dict
    placement: Placement
    names: tuple[str, ...]
    notes: tuple[str, ...] = ()


def transfer_rows(colormap, gamma: float, opacity: float) -> list[list[float]]:
    """The transfer function's rgba rows for one layer's look (module docstring). `colormap`:
    napari's Colormap (its map() takes values in [0, 1] and gives RGBA)."""
    d = np.linspace(0.0, 1.0, TRANSFER_ROWS)
    g = d ** float(gamma)
    rgba = np.asarray(colormap.map(g), np.float64)[:, :4]
    rows = np.clip(np.column_stack([rgba[:, :3], float(opacity) * g]), 0.0, 1.0)
    return [[float(v) for v in row] for row in rows]


def _kind(layer) -> str:
    return type(layer).__name__


def _check_layer(layer, viewer) -> None:
    name = layer.name
    kind = _kind(layer)
    if kind == "Labels":
        raise LayerProblem(f"layer {name!r} is a Labels layer: the plugin renders image layers "
                           "of numbers (convert the labels to an image layer to see them lit)")
    if kind != "Image":
        raise LayerProblem(f"layer {name!r} is a {kind} layer: the plugin renders image layers")
    if getattr(layer, "rgb", False):
        raise LayerProblem(f"layer {name!r} is RGB: the plugin renders one value per voxel; "
                           "split the colours into channels (one layer each)")
    if layer.ndim < 3:
        raise LayerProblem(f"layer {name!r} is {layer.ndim}D: the plugin renders 3D volumes "
                           "(z, y, x)")
    if getattr(layer, "multiscale", False):
        raise LayerProblem(f"layer {name!r} is multiscale: give the plugin one level as its own "
                           "layer")
    if layer.ndim > 3:
        # the leading axes are on napari's sliders; the plugin renders the last three, sliced
        # where the sliders are
        displayed = tuple(viewer.dims.displayed)
        last = tuple(range(viewer.dims.ndim - 3, viewer.dims.ndim))
        if displayed != last:
            raise LayerProblem(
                f"layer {name!r} is {layer.ndim}D and napari shows its axes {displayed}, so no "
                f"slider picks the time step: the plugin renders the last three axes (z, y, x) "
                "with the others on sliders (reset napari's axis order: dims.order)")
    scale = np.asarray(layer.scale, np.float64)[-3:]
    if not np.all(scale > 0):
        raise LayerProblem(f"layer {name!r} has a scale of {tuple(scale)}: the plugin needs "
                           "positive voxel sizes (a mirrored layer is not supported)")
    affine = np.asarray(layer.affine.affine_matrix, np.float64)
    rotate = np.asarray(layer.rotate, np.float64)
    shear = np.asarray(layer.shear, np.float64)
    if not (np.allclose(affine, np.eye(len(affine))) and np.allclose(rotate, np.eye(len(rotate)))
            and np.allclose(shear, 0.0)):
        raise LayerProblem(f"layer {name!r} has a rotation, shear or affine transform: the "
                           "plugin places volumes by scale and translate only")


def _layer_array(layer, viewer) -> np.ndarray:
    data = layer.data
    if layer.ndim > 3:   # sliced where napari's sliders are
        lead = layer.ndim - 3
        world_axes = range(viewer.dims.ndim - layer.ndim, viewer.dims.ndim - 3)
        index = tuple(int(np.clip(round((viewer.dims.point[a] - layer.translate[i])
                                        / layer.scale[i]), 0, layer.data.shape[i] - 1))
                      for i, a in zip(range(lead), world_axes))
        data = data[index]
    size = int(np.prod(data.shape))
    if size > MAX_VOXELS:
        raise LayerProblem(f"layer {layer.name!r} has {size} voxels, more than the plugin's "
                           f"{MAX_VOXELS}: give it a downsampled copy as a layer")
    array = np.asarray(data)
    if array.dtype.kind not in "uifb":
        raise LayerProblem(f"layer {layer.name!r} holds {array.dtype} values: expected numbers")
    return array


def render_layers(viewer, selected=None) -> list:
    """The layers to render: the visible image layers, in napari's order (the selection alone
    where layers are selected and any of them is not visible-image-3D, so that its problem is
    named)."""
    layers = list(selected) if selected else [l for l in viewer.layers if l.visible]
    if not layers:
        raise LayerProblem("no visible layer: add an image layer (File > Open, or "
                           "File > Open Sample > Global illumination) and make it visible")
    return layers


def layer_scene(viewer, layers=None) -> LayerScene:
    """The scene for napari's visible image layers (or `layers`): one layer, or up to
    MAX_CHANNELS of the same shape, scale and translate as channels. Raises LayerProblem."""
    if viewer.dims.ndisplay != 3:
        raise LayerProblem("napari shows 2D: switch to the 3D view (the cube button at the "
                           "bottom left, or viewer.dims.ndisplay = 3)")
    layers = render_layers(viewer) if layers is None else list(layers)
    if not layers:
        raise LayerProblem("no visible layer: add an image layer and make it visible")
    for layer in layers:
        _check_layer(layer, viewer)
    if len(layers) > MAX_CHANNELS:
        raise LayerProblem(f"{len(layers)} visible image layers: the plugin renders up to "
                           f"{MAX_CHANNELS} as channels; hide the others")
    arrays = [_layer_array(l, viewer) for l in layers]
    first = layers[0]
    for layer, array in zip(layers[1:], arrays[1:]):
        if array.shape != arrays[0].shape:
            raise LayerProblem(f"layers {first.name!r} and {layer.name!r} differ in shape "
                               f"({arrays[0].shape} and {array.shape}): channels share one grid; "
                               "hide one of them")
        if not (np.allclose(layer.scale[-3:], first.scale[-3:])
                and np.allclose(layer.translate[-3:], first.translate[-3:])):
            raise LayerProblem(f"layers {first.name!r} and {layer.name!r} differ in scale or "
                               "translate: channels share one grid; hide one of them")
    placement = Placement(tuple(int(n) for n in arrays[0].shape),
                          tuple(float(s) for s in first.scale[-3:]),
                          tuple(float(t) for t in first.translate[-3:]),
                          right_handed(napari_camera(viewer).orientation))
    looks = []
    for layer in layers:
        lo, hi = (float(v) for v in layer.contrast_limits)
        if not hi > lo:
            raise LayerProblem(f"layer {layer.name!r} has contrast limits {lo:g}..{hi:g}: "
                               "widen them (the window must not be empty)")
        looks.append(({"rgba": transfer_rows(layer.colormap, layer.gamma, layer.opacity)},
                      [lo, hi]))
    spacing = list(placement.spacing_xyz)
    if len(layers) == 1:
        tf, window = looks[0]
        data = placement.volume_data(arrays[0])
        options = {"spacing": spacing, "value_range": window, "transfer_function": tf}
    else:
        data = np.stack([placement.volume_data(a).astype(np.float32) for a in arrays])
        options = {"spacing": spacing, "axes": "czyx",
                   "channels": [{"name": l.name, "index": i, "transfer_function": tf,
                                 "value_range": window}
                                for i, (l, (tf, window)) in enumerate(zip(layers, looks))]}
    return LayerScene(np.ascontiguousarray(data), options, placement,
                      tuple(l.name for l in layers))
