"""The default camera framed to the volume's box: a scene that leaves the camera at its default
(CameraSpec's eye, target, up and field of view) sees the whole box, whatever its proportions,
at the camera's field of view and the image's aspect. The eye moves back along its default
direction only as far as the box needs, with a margin (a box that fits already keeps the default
eye: the images of such scenes stay as they were)."""
from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from radiance_probes.scene.types import CameraSpec, Scene

# The box's corners stay this fraction of the half field of view inside the image's edges.
MARGIN = 0.03


def is_default_view(camera: CameraSpec) -> bool:
    """The camera's view (not its image size) is CameraSpec's default, or the default moved back
    along its direction (as framed here): the scene gave none."""
    default = CameraSpec()
    if (camera.target, camera.up, camera.fov_y) != (default.target, default.up, default.fov_y):
        return False
    eye, home = np.asarray(camera.eye, np.float64), np.asarray(default.eye, np.float64)
    scale = float(eye @ home) / float(home @ home)
    return scale >= 1.0 - 1e-9 and bool(np.allclose(eye, scale * home, rtol=0, atol=1e-9))


def framing_distance(half_extent, eye, target, up, fov_y: float, aspect: float,
                     margin: float = MARGIN) -> float:
    """The least distance from the target, along the eye's direction, at which every corner of the
    box (centred at the origin, `half_extent` along x, y, z) lies inside the view: within the
    vertical field of view and the horizontal one the aspect (width / height) gives."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    back = (eye - target) / np.linalg.norm(eye - target)
    forward = -back
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    tan_y = math.tan(math.radians(fov_y) / 2) * (1.0 - margin)
    tan_x = tan_y * aspect
    h = np.asarray(half_extent, np.float64)
    need = 0.0
    for signs in itertools.product((-1.0, 1.0), repeat=3):
        corner = np.array(signs) * h - target
        # at distance d the corner lies d + corner.forward in front of the eye
        depth = float(corner @ forward)
        need = max(need, abs(float(corner @ true_up)) / tan_y - depth,
                   abs(float(corner @ right)) / tan_x - depth)
    return need


def framed_camera(camera: CameraSpec, half_extent, aspect: float | None = None) -> CameraSpec:
    """The camera with its eye moved back along its direction until the box fits (never closer
    than it is); the image's aspect from the camera's size unless given (the viewer's view)."""
    aspect = aspect if aspect is not None else camera.width / camera.height
    eye, target = np.asarray(camera.eye, np.float64), np.asarray(camera.target, np.float64)
    distance = float(np.linalg.norm(eye - target))
    if framing_distance(half_extent, eye, target, camera.up, camera.fov_y, aspect, 0.0) <= distance:
        return camera       # every corner in the image already
    need = framing_distance(half_extent, eye, target, camera.up, camera.fov_y, aspect)
    new_eye = target + (eye - target) * (need / distance)
    return dataclasses.replace(camera, eye=tuple(float(v) for v in new_eye))


def frame_default_camera(scene: Scene, half_extent, aspect: float | None = None) -> Scene:
    """The scene with its camera framed to the box where the scene left the view at its default;
    a camera the scene gives is its own, left as it is."""
    if not is_default_view(scene.camera):
        return scene
    camera = framed_camera(scene.camera, half_extent, aspect)
    return scene if camera is scene.camera else scene.replace(camera=camera)
