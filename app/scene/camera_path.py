"""Camera paths for movies (`radiance-probes animate`, the viewer's recorder): a turntable about
the camera's up axis through its target, or a smooth flight through bookmarks.

Keyframes are interpolated as an orbit, not as straight lines between eyes: each camera is its
target, its distance to the target (on a log scale) and the unit direction from the target to
the eye; each of these follows a Catmull-Rom spline through the keyframes (C1: no kinks at a
keyframe), the direction normalised again, the up vector likewise and then made perpendicular to
the view. A flight between two cameras on a circle about one target stays on that circle (straight
lines between the eyes would cut inside it, towards the volume). The flight eases in and out (the
spline parameter follows a cosine ramp over the whole movie), so it starts and stops at rest.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from radiance_probes.scene.types import CameraSpec


def turntable(camera: CameraSpec, degrees: float, frames: int) -> list[CameraSpec]:
    """`frames` cameras turning by `degrees` in all about the up axis through the target, frame i
    at degrees * i / frames (right-handed about up; 360 degrees loops without a repeated frame)."""
    if frames < 1:
        raise ValueError(f"frames: expected at least 1, got {frames}")
    eye = np.asarray(camera.eye, np.float64)
    target = np.asarray(camera.target, np.float64)
    axis = np.asarray(camera.up, np.float64)
    axis /= np.linalg.norm(axis)
    offset = eye - target
    out = []
    for i in range(frames):
        a = math.radians(degrees * i / frames)
        # Rodrigues' rotation of the offset about the axis
        rotated = (offset * math.cos(a) + np.cross(axis, offset) * math.sin(a)
                   + axis * (axis @ offset) * (1.0 - math.cos(a)))
        out.append(replace(camera, eye=tuple(float(v) for v in target + rotated)))
    return out


def _catmull_rom(points: np.ndarray, s: float) -> np.ndarray:
    """The uniform Catmull-Rom spline through `points` (K, D) at parameter s in [0, K - 1], the
    end points repeated beyond the ends."""
    k = len(points)
    if k == 1:
        return points[0].copy()
    i = min(int(math.floor(s)), k - 2)
    t = s - i
    p0, p1, p2, p3 = (points[min(max(j, 0), k - 1)] for j in (i - 1, i, i + 1, i + 2))
    t2, t3 = t * t, t * t * t
    return 0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2
                  + (-p0 + 3 * p1 - 3 * p2 + p3) * t3)


def keyframes(cameras: list[CameraSpec], frames: int, base: CameraSpec | None = None
              ) -> list[CameraSpec]:
    """`frames` cameras flying smoothly through `cameras` in order, the first frame at the first
    keyframe and the last at the last (image size from `base`, else the first camera)."""
    if not cameras:
        raise ValueError("keyframes: no cameras to fly through (the scene has no bookmarks)")
    if frames < 1:
        raise ValueError(f"frames: expected at least 1, got {frames}")
    base = base or cameras[0]
    targets = np.array([c.target for c in cameras], np.float64)
    offsets = np.array([c.eye for c in cameras], np.float64) - targets
    distances = np.linalg.norm(offsets, axis=1)
    directions = offsets / distances[:, None]
    ups = np.array([c.up for c in cameras], np.float64)
    ups /= np.linalg.norm(ups, axis=1, keepdims=True)
    fovs = np.array([[c.fov_y] for c in cameras], np.float64)
    log_d = np.log(distances)[:, None]
    out = []
    for i in range(frames):
        u = i / (frames - 1) if frames > 1 else 0.0
        s = 0.5 * (1.0 - math.cos(math.pi * u)) * (len(cameras) - 1)   # eased in and out
        target = _catmull_rom(targets, s)
        direction = _catmull_rom(directions, s)
        length = np.linalg.norm(direction)
        # (only keyframes looking from opposite sides of the target cancel out)
        direction = direction / length if length > 1e-9 else directions[int(round(s))]
        eye = target + math.exp(float(_catmull_rom(log_d, s)[0])) * direction
        up = _catmull_rom(ups, s)
        forward = -direction
        up = up - forward * (up @ forward)          # perpendicular to the view
        norm = np.linalg.norm(up)
        up = up / norm if norm > 1e-9 else ups[min(int(round(s)), len(ups) - 1)]
        fov = float(np.clip(_catmull_rom(fovs, s)[0], 1.0, 179.0))
        out.append(replace(base, eye=tuple(map(float, eye)), target=tuple(map(float, target)),
                           up=tuple(map(float, up)), fov_y=fov))
    return out
