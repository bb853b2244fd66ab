"""NumPy twin of glsl/lib/camera.glsl: the pinhole camera of SPEC.md as the shaders see it (the
renderers pass its frame as uniforms; the tests generate the same rays)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pyrr import vector, vector3

from radiance_probes.scene.types import CameraSpec


@dataclass(frozen=True)
class CameraFrame:
    eye: np.ndarray
    forward: np.ndarray  # unit view direction
    right: np.ndarray    # scaled by tan(fov_y / 2) * aspect
    up: np.ndarray       # scaled by tan(fov_y / 2)
    width: int
    height: int

    def uniforms(self) -> dict:
        return {"camera_eye": tuple(self.eye), "camera_forward": tuple(self.forward),
                "camera_right": tuple(self.right), "camera_up": tuple(self.up),
                "image_size": (self.width, self.height)}

    def ray_directions(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """NumPy twin of camera_ray_direction: unit directions through image points in pixels."""
        ndc_x = 2.0 * px / self.width - 1.0
        ndc_y = 1.0 - 2.0 * py / self.height
        d = (self.forward[None, :] + ndc_x[..., None] * self.right + ndc_y[..., None] * self.up)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)   # (pyrr normalises 1D and 2D only)


def camera_frame(spec: CameraSpec, width: int | None = None, height: int | None = None) -> CameraFrame:
    w = width or spec.width
    h = height or spec.height
    eye = np.asarray(spec.eye, np.float64)
    forward = vector.normalise(np.asarray(spec.target, np.float64) - eye)
    right = vector.normalise(vector3.cross(forward, np.asarray(spec.up, np.float64)))
    up = vector3.cross(right, forward)
    tan_half = math.tan(math.radians(spec.fov_y) / 2)
    return CameraFrame(eye.astype(np.float32), forward.astype(np.float32),
                       (right * tan_half * w / h).astype(np.float32),
                       (up * tan_half).astype(np.float32), w, h)
