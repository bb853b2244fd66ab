"""napari's 3D view as this project's camera, and back: where napari's world (its displayed axes
in z, y, x order, the layer's `scale` and `translate` applied) lands in ours (the volume's box
centred at the origin, its longest side 1, axes x, y, z; SPEC.md "Camera and image").

napari's 3D camera is vispy's: `center` (z, y, x) is the point looked at; `zoom` is canvas pixels
per world unit at that point; `perspective` is the vertical field of view in degrees (0:
orthographic); `view_direction` and `up_direction` (z, y, x) come from its `angles` and
`orientation`. vispy puts the eye at the distance where the canvas's height spans
height / zoom world units at the centre.

Our world from napari's: `ours = M (p - c) / L` with `c` the centre of the layer's box in napari's
world, `L` the box's longest side in world units, and `M` the reversal z, y, x -> x, y, z,
followed, where napari's orientation is right-handed (its default), by z -> -z (the volume's
slices then stored in reverse): two reflections make a rotation, so napari's screen right,
up and view direction are a proper camera frame here (right = forward x up), with no mirrored
image. With a left-handed napari orientation the reversal alone is already proper.

Orthographic: our camera is a pinhole, so napari's orthographic view is drawn with a narrow field
of view, ORTHO_FOV_DEG, from far enough back that the centre's plane spans the same height: a
point at depth d in front of or behind the centre moves by d / distance of its offset: under
0.06% of the box's size for this field of view (under one pixel where the box spans 1500 pixels).
The raymarched image of a box at 0.05 degrees equals the one at 0.25 to 0.1% (float32 still
resolves the positions from that far).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ORTHO_FOV_DEG = 0.05   # our field of view for napari's orthographic camera (module docstring)


@dataclass(frozen=True)
class Placement:
    """How one layer's voxels sit in napari's world and in ours."""
    shape_zyx: tuple[int, int, int]
    scale_zyx: tuple[float, float, float]
    translate_zyx: tuple[float, float, float]
    flip_z: bool            # right-handed napari orientation: our z is napari's -z

    @property
    def spacing_xyz(self) -> tuple[float, float, float]:
        return tuple(float(s) for s in self.scale_zyx[::-1])

    @property
    def centre_zyx(self) -> np.ndarray:
        """The centre of the box of voxel centres (= of the voxels' box) in napari's world."""
        n, s, t = (np.asarray(v, np.float64) for v in (self.shape_zyx, self.scale_zyx,
                                                       self.translate_zyx))
        return t + s * (n - 1) / 2.0

    @property
    def longest_side(self) -> float:
        """L: the box's longest side in napari's world units (ours is 1)."""
        return float(np.max(np.asarray(self.shape_zyx, np.float64) * np.abs(self.scale_zyx)))

    def vector_to_ours(self, v_zyx) -> np.ndarray:
        v = np.asarray(v_zyx, np.float64)[..., ::-1].copy()
        if self.flip_z:
            v[..., 2] = -v[..., 2]
        return v

    def vector_to_napari(self, v_xyz) -> np.ndarray:
        v = np.asarray(v_xyz, np.float64).copy()
        if self.flip_z:
            v[..., 2] = -v[..., 2]
        return v[..., ::-1]

    def point_to_ours(self, p_zyx) -> np.ndarray:
        return self.vector_to_ours((np.asarray(p_zyx, np.float64) - self.centre_zyx)
                                   / self.longest_side)

    def point_to_napari(self, p_xyz) -> np.ndarray:
        return self.vector_to_napari(p_xyz) * self.longest_side + self.centre_zyx

    def voxel_to_ours(self, index_zyx) -> np.ndarray:
        """Our world position of voxel (k, j, i)'s centre as our renderer places it: the box
        -h..h holds N voxels, centre i at -h + (i + 0.5) 2h / N along each axis (texel centres).
        Independent of napari's world: tests compare it with point_to_ours(napari's position)."""
        n = np.asarray(self.shape_zyx, np.float64)[::-1]
        size = n * np.abs(np.asarray(self.scale_zyx, np.float64)[::-1])
        half = 0.5 * size / size.max()
        idx = np.asarray(index_zyx, np.float64)[..., ::-1].copy()
        if self.flip_z:   # the slices are stored in reverse (volume_data)
            idx[..., 2] = n[2] - 1 - idx[..., 2]
        if np.any(np.asarray(self.scale_zyx) < 0):
            raise ValueError("negative scale")
        return -half + (idx + 0.5) * 2 * half / n

    def volume_data(self, data_zyx: np.ndarray) -> np.ndarray:
        """The array as our renderer is given it (slices reversed where flip_z)."""
        return data_zyx[::-1] if self.flip_z else data_zyx


def right_handed(orientation) -> bool:
    """napari's orientation (depth, vertical, horizontal) is right-handed: its default ('towards',
    'down', 'right') and any one with an even number of changes from it."""
    default = ("towards", "down", "right")
    changes = sum(str(getattr(o, "value", o)) != d for o, d in zip(orientation, default))
    return changes % 2 == 0


def napari_to_camera(center_zyx, view_direction_zyx, up_direction_zyx, zoom: float,
                     perspective: float, width: int, height: int, placement: Placement,
                     scale: float = 1.0) -> dict:
    """Our scene's camera (eye, target, up, fov_y, width, height) for napari's 3D camera seen on
    a canvas of width x height pixels (napari's zoom counts those), its image `scale` times the
    canvas's size (the same view, fewer pixels)."""
    if not (zoom > 0 and math.isfinite(zoom)):
        raise ValueError(f"napari's zoom must be a finite number > 0, got {zoom!r}")
    forward = placement.vector_to_ours(view_direction_zyx)
    forward /= np.linalg.norm(forward)
    up = placement.vector_to_ours(up_direction_zyx)
    up = up - forward * float(up @ forward)
    up /= np.linalg.norm(up)
    target = placement.point_to_ours(center_zyx)
    # vispy: scale_factor = min(w, h) / zoom spans the smaller side; the height spans
    # scale_factor * max(1, h / w) world units at the centre
    view_height = min(width, height) / zoom * max(1.0, height / width) / placement.longest_side
    fov = float(perspective) if perspective > 0 else ORTHO_FOV_DEG
    distance = view_height / (2.0 * math.tan(math.radians(fov) / 2.0))
    eye = target - distance * forward
    return {"eye": [float(v) for v in eye], "target": [float(v) for v in target],
            "up": [float(v) for v in up], "fov_y": fov,
            "width": max(1, int(round(width * scale))), "height": max(1, int(round(height * scale)))}


def napari_camera(viewer):
    """The viewer's camera model: `viewer.scene.camera` from napari 0.9 (`viewer.camera` before,
    deprecated since)."""
    scene = getattr(viewer, "scene", None)
    camera = getattr(scene, "camera", None)
    return camera if camera is not None else viewer.camera


def camera_from_viewer(viewer, width: int, height: int, placement: Placement,
                       scale: float = 1.0) -> dict:
    """napari_to_camera for the viewer's camera model as it stands, on a width x height canvas."""
    cam = napari_camera(viewer)
    return napari_to_camera(cam.center, cam.view_direction, cam.up_direction, cam.zoom,
                            cam.perspective, width, height, placement, scale)


def camera_to_napari(camera: dict, placement: Placement, perspective: float | None = None
                     ) -> dict:
    """The way back: napari's center, zoom and view/up directions (z, y, x) that show what our
    `camera` shows on its width x height canvas (`perspective` None: our fov_y, or 0 where it is
    ORTHO_FOV_DEG). napari's own set_view_direction turns the directions into angles."""
    eye, target, up = (np.asarray(camera[k], np.float64) for k in ("eye", "target", "up"))
    forward = (target - eye) / np.linalg.norm(target - eye)
    distance = float(np.linalg.norm(target - eye))
    view_height = 2.0 * distance * math.tan(math.radians(camera["fov_y"]) / 2.0)
    w, h = int(camera["width"]), int(camera["height"])
    zoom = min(w, h) * max(1.0, h / w) / (view_height * placement.longest_side)
    if perspective is None:
        perspective = 0.0 if abs(camera["fov_y"] - ORTHO_FOV_DEG) < 1e-9 else camera["fov_y"]
    return {"center": tuple(float(v) for v in placement.point_to_napari(target)), "zoom": zoom,
            "perspective": float(perspective),
            "view_direction": tuple(float(v) for v in placement.vector_to_napari(forward)),
            "up_direction": tuple(float(v) for v in placement.vector_to_napari(up))}
