"""Orbit, pan and zoom of the scene camera (a CameraSpec), and the matrices that draw geometry
with the very camera the renderers trace rays from (app/twins/camera.py). The vector and matrix
maths is pyrr's (rotations about an axis, look-at and perspective matrices); pyrr writes matrices
for row vectors (``v @ M``), so they are transposed here into the column-vector form GL and the
rest of the code use."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pyrr import matrix44, quaternion, vector, vector3

from radiance_probes.twins.camera import CameraFrame
from radiance_probes.io.scene_file import CameraSpec

ORBIT_DEGREES_PER_PIXEL = 0.4
ZOOM_PER_WHEEL_STEP = 0.9          # distance factor of one wheel notch towards the target
MIN_DISTANCE, MAX_DISTANCE = 0.05, 100.0
POLE_MARGIN_DEGREES = 1.0          # orbiting stops this far from looking straight along `up`


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """v turned about the unit axis by angle (radians, right-handed)."""
    return quaternion.apply_to_vector(quaternion.create_from_axis_rotation(axis, angle), v)


def _basis(cam: CameraSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    eye, target = np.asarray(cam.eye, np.float64), np.asarray(cam.target, np.float64)
    forward = vector.normalise(target - eye)
    right = vector.normalise(vector3.cross(forward, np.asarray(cam.up, np.float64)))
    up = vector3.cross(right, forward)
    return eye, target, forward, right, up


def _spec(cam: CameraSpec, eye: np.ndarray, target: np.ndarray) -> CameraSpec:
    return replace(cam, eye=tuple(float(v) for v in eye), target=tuple(float(v) for v in target))


def orbit(cam: CameraSpec, dx_pixels: float, dy_pixels: float) -> CameraSpec:
    """Turns the eye about the target as if the cursor dragged the scene: right turns it right
    (the eye yaws left about `up`), down tilts its top towards the viewer (the eye rises); the
    distance to the target is kept and the view never flips over the pole."""
    eye, target, forward, right, _ = _basis(cam)
    world_up = vector.normalise(np.asarray(cam.up, np.float64))
    offset = eye - target
    yaw = -math.radians(dx_pixels * ORBIT_DEGREES_PER_PIXEL)     # the eye moves left
    tilt = math.radians(dy_pixels * ORBIT_DEGREES_PER_PIXEL)     # the eye moves up
    # Angle between the view direction and `up` (tilting up increases it); keep it within
    # (margin, 180 - margin).
    polar = math.acos(float(np.clip(np.dot(forward, world_up), -1.0, 1.0)))
    margin = math.radians(POLE_MARGIN_DEGREES)
    tilt = float(np.clip(tilt, min(margin - polar, 0.0), max(math.pi - margin - polar, 0.0)))
    offset = _rotate(offset, right, -tilt)
    offset = _rotate(offset, world_up, yaw)
    return _spec(cam, target + offset, target)


def pan(cam: CameraSpec, dx_pixels: float, dy_pixels: float, viewport_height: float) -> CameraSpec:
    """Moves eye and target together so that the point at the target follows the cursor."""
    eye, target, _, right, up = _basis(cam)
    distance = float(np.linalg.norm(target - eye))
    world_per_pixel = 2.0 * distance * math.tan(math.radians(cam.fov_y) / 2) / max(viewport_height, 1)
    shift = (-dx_pixels * right + dy_pixels * up) * world_per_pixel
    return _spec(cam, eye + shift, target + shift)


def recentre(cam: CameraSpec, point) -> CameraSpec:
    """Moves eye and target together so that the orbit's centre (the target) is `point`, keeping
    the view direction and distance (a click in the slice view)."""
    eye, target = np.asarray(cam.eye, np.float64), np.asarray(cam.target, np.float64)
    shift = np.asarray(point, np.float64) - target
    return _spec(cam, eye + shift, target + shift)


def zoom(cam: CameraSpec, wheel_steps: float) -> CameraSpec:
    """Moves the eye towards the target (positive steps) or away, keeping the view direction."""
    eye, target, forward, _, _ = _basis(cam)
    distance = float(np.linalg.norm(target - eye)) * ZOOM_PER_WHEEL_STEP ** wheel_steps
    distance = float(np.clip(distance, MIN_DISTANCE, MAX_DISTANCE))
    return _spec(cam, target - forward * distance, target)


# ---- matrices ---------------------------------------------------------------------------------

def view_projection(frame: CameraFrame, near: float = 0.01, far: float = 100.0) -> np.ndarray:
    """The 4x4 matrix (row-major NumPy; transpose for GL) mapping world points to clip space so
    that a point on the ray through image point (px, py) lands at that point of the viewport, row
    0 at the top: the rasterised twin of camera_ray_direction. The frame's `right` and `up` are
    scaled by tan(fov_y / 2) (times the aspect), which gives the perspective's field of view."""
    eye = frame.eye.astype(np.float64)
    forward = frame.forward.astype(np.float64)
    tan_half = float(np.linalg.norm(frame.up))
    aspect = float(np.linalg.norm(frame.right)) / tan_half
    view = matrix44.create_look_at(eye, eye + forward, frame.up.astype(np.float64), dtype=np.float64)
    proj = matrix44.create_perspective_projection(math.degrees(2.0 * math.atan(tan_half)), aspect,
                                                  near, far, dtype=np.float64)
    return matrix44.multiply(view, proj).T   # pyrr: v @ view @ proj; here M @ v


def project(matrix: np.ndarray, points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Image positions in pixels ((0, 0) top-left) of world points (..., 3); NaN behind the eye."""
    p = np.concatenate([np.asarray(points, np.float64),
                        np.ones(np.shape(points)[:-1] + (1,))], axis=-1)
    clip = p @ matrix.T
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = clip[..., :2] / clip[..., 3:4]
    ndc[clip[..., 3] <= 0] = np.nan
    return np.stack([(ndc[..., 0] + 1) * 0.5 * width, (1 - ndc[..., 1]) * 0.5 * height], axis=-1)


def gl_matrix(matrix: np.ndarray) -> bytes:
    """Bytes of a row-major NumPy matrix as GLSL's column-major mat4 expects them."""
    return np.ascontiguousarray(matrix.T, np.float32).tobytes()
