"""The crop box's and the clip plane's handles over the view: one on each face of the kept box
(drag it to move that face along its axis) and one on the clip plane (drag it along the normal).
Geometry only (no GL, no ImGui): where the handles are in the world, the plane's outline inside
the box, and what a drag of some pixels does to the scene."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radiance_probes.scene.clip_region import clip_region
from radiance_probes.io.scene_file import Scene

GRAB_PIXELS = 9.0


@dataclass(frozen=True)
class Handle:
    kind: str            # "crop" (a face of the box) or "plane"
    axis: int = 0        # crop: the face's axis (0 x, 1 y, 2 z)
    side: int = 0        # crop: 0 the low face, 1 the high one
    position: tuple = (0.0, 0.0, 0.0)   # where it is drawn (world)
    direction: tuple = (1.0, 0.0, 0.0)  # the way a drag moves it (unit, world)

    @property
    def name(self) -> str:
        return "plane" if self.kind == "plane" else f"crop {'xyz'[self.axis]} {('min', 'max')[self.side]}"


def kept_box(scene: Scene, volume) -> tuple[np.ndarray, np.ndarray]:
    """The box the handles sit on: the crop's (within the volume box) while it is on, else the
    volume box."""
    he = np.asarray(volume.half_extent, np.float64)
    crop = scene.crop
    if crop is None or not crop.enabled:
        return -he, he
    region = clip_region(scene.replace(clip_plane=None), volume.dims, he)
    if region is None or region.empty:
        return -he, he
    return np.asarray(region.box_min), np.asarray(region.box_max)


def plane_polygon(normal, distance: float, lo, hi) -> np.ndarray:
    """The plane dot(normal, x) = distance inside the box [lo, hi]: its outline's corners in order
    around the normal, (k, 3); empty when the plane misses the box."""
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    d = float(distance) / np.linalg.norm(np.asarray(normal, np.float64))
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.array([[(lo, hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)])
    points = []
    for i in range(8):
        for a in range(3):
            j = i | (1 << a)
            if j == i:
                continue
            p, q = corners[i], corners[j]
            fp, fq = p @ n - d, q @ n - d
            if (fp < 0) != (fq < 0) or fp == 0:
                t = fp / (fp - fq) if fp != fq else 0.0
                points.append(p + t * (q - p))
    if len(points) < 3:
        return np.zeros((0, 3))
    pts = np.unique(np.round(np.array(points), 12), axis=0)
    centre = pts.mean(axis=0)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    order = np.argsort(np.arctan2((pts - centre) @ v, (pts - centre) @ u))
    return pts[order]


def handles(scene: Scene, volume) -> list[Handle]:
    """The handles of what is on: six for the crop box, one for the clip plane (the centre of its
    outline inside the kept box)."""
    out = []
    lo, hi = kept_box(scene, volume)
    if scene.crop is not None and scene.crop.enabled:
        centre = 0.5 * (lo + hi)
        for axis in range(3):
            for side, value in enumerate((lo[axis], hi[axis])):
                p = centre.copy()
                p[axis] = value
                direction = np.zeros(3)
                direction[axis] = 1.0
                out.append(Handle("crop", axis, side, tuple(p), tuple(direction)))
    plane = scene.clip_plane
    if plane is not None and plane.enabled:
        outline = plane_polygon(plane.normal, plane.distance, lo, hi)
        if len(outline):
            n = np.asarray(plane.normal, np.float64)
            out.append(Handle("plane", position=tuple(outline.mean(axis=0)),
                              direction=tuple(n / np.linalg.norm(n))))
    return out


def dragged(scene: Scene, volume, handle: Handle, start, world_distance: float) -> Scene:
    """The scene with the handle moved `world_distance` along its direction from `start` (the
    crop's min/max corners, or the plane's distance, when the drag began). Voxel crops move by
    whole voxels; a face stops one voxel (or one voxel's width) short of the opposite face."""
    from dataclasses import replace
    if handle.kind == "plane":
        plane = scene.clip_plane
        length = float(np.linalg.norm(plane.normal))
        return scene.replace(clip_plane=replace(plane, distance=float(start + world_distance * length)))
    crop = scene.crop
    lo, hi = [list(v) for v in start]
    he = np.asarray(volume.half_extent, np.float64)
    a, n = handle.axis, volume.dims[handle.axis]
    if crop.units == "voxels":
        step = 2.0 * he[a] / n
        value = int(round((lo, hi)[handle.side][a] + world_distance / step))
        if handle.side == 0:
            lo[a] = min(max(value, 0), hi[a] - 1)
        else:
            hi[a] = max(min(value, n), lo[a] + 1)
        return scene.replace(crop=replace(crop, min=tuple(int(v) for v in lo),
                                          max=tuple(int(v) for v in hi)))
    width = 2.0 * he[a] / n
    value = float((lo, hi)[handle.side][a] + world_distance)
    if handle.side == 0:
        lo[a] = min(max(value, -he[a]), hi[a] - width)
    else:
        hi[a] = max(min(value, he[a]), lo[a] + width)
    return scene.replace(crop=replace(crop, min=tuple(map(float, lo)), max=tuple(map(float, hi))))


def drag_start(scene: Scene, handle: Handle):
    """What `dragged` moves from: the crop's corners, or the plane's distance."""
    if handle.kind == "plane":
        return float(scene.clip_plane.distance)
    return (tuple(scene.crop.min), tuple(scene.crop.max))

