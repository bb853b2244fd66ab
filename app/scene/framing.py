"""The default camera framed to the volume: a scene that leaves the camera at its default
(CameraSpec's eye, target, up and field of view) sees the whole box, whatever its proportions,
at the camera's field of view and the image's aspect, from any direction at that distance: the
eye moves back along its default direction until the box's bounding sphere fits the image, with
a margin, so an orbit about the target (Renderer.orbit, the viewer's drag), which keeps the
distance, never cuts the box (issue 55: a box framed for the default direction alone touched the
image's edges at azimuths 120 and 240). A sphere that fits already keeps the default eye."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from radiance_probes.scene.types import CameraSpec, Scene

# The box's bounding sphere stays this fraction of the half field of view (its tangent) inside the
# image's nearer edges.
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


def sphere_distance(radius: float, fov_y: float, aspect: float, margin: float = MARGIN) -> float:
    """The least distance from a sphere's centre at which it fits a view whose centre it is on:
    its silhouette's half angle, asin(radius / distance), within the narrower half field of view
    (the vertical one, or the horizontal one the aspect gives), that less `margin` of its
    tangent."""
    tan_half = math.tan(math.radians(fov_y) / 2) * min(1.0, aspect) * (1.0 - margin)
    return float(radius) * math.hypot(1.0, tan_half) / tan_half


def framed_camera(camera: CameraSpec, half_extent, aspect: float | None = None) -> CameraSpec:
    """The camera with its eye moved back along its direction until the box's bounding sphere
    (about the box's centre, the origin, which the default view's target is) fits the image with
    MARGIN, so the box fits from every direction at that distance (never closer than it is); the
    image's aspect from the camera's size unless given (the viewer's view)."""
    aspect = aspect if aspect is not None else camera.width / camera.height
    eye, target = np.asarray(camera.eye, np.float64), np.asarray(camera.target, np.float64)
    distance = float(np.linalg.norm(eye - target))
    radius = float(np.linalg.norm(np.asarray(half_extent, np.float64)))
    need = sphere_distance(radius, camera.fov_y, aspect)
    if need <= distance:
        return camera       # the sphere in the image already
    new_eye = target + (eye - target) * (need / distance)
    return dataclasses.replace(camera, eye=tuple(float(v) for v in new_eye))


def frame_default_camera(scene: Scene, half_extent, aspect: float | None = None) -> Scene:
    """The scene with its camera framed to the box where the scene left the view at its default;
    a camera the scene gives is its own, left as it is."""
    if not is_default_view(scene.camera):
        return scene
    camera = framed_camera(scene.camera, half_extent, aspect)
    return scene if camera is scene.camera else scene.replace(camera=camera)
