"""The kept region of SPEC.md's "Crop and clip": a scene's crop box and clip plane resolved against
its volume into what every pass reads (glsl/lib/clip_region.glsl; the NumPy twin of that include
is `kept` and `sample_points` here, which app/twins/medium.py uses).

- The kept box: the crop box (world units, or voxel boundaries) intersected with the volume box.
  Outside it the medium is vacuum for every ray.
- The density inside it is read at the point clamped to the centres of the outermost voxels whose
  centres lie in the crop box (only along a side the crop cuts), as a volume is clamped to its edge
  voxels at its own faces. So a crop on voxel boundaries renders exactly as the cropped volume
  (``data[z0:z1, y0:y1, x0:x1]``) placed at the same spot; trilinear interpolation never reaches
  across the cut into voxels cut away.
- The clip plane (n, d) keeps dot(n, x) <= d; n is stored of unit length (d scaled with it, the
  same half-space). It only cuts: the density is read where the point is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radiance_probes.scene.types import Scene, SceneError

# A clamp bound on a side the crop does not cut (no clamp there): beyond any world coordinate.
UNBOUNDED = 1e30


@dataclass(frozen=True)
class ClipRegion:
    box_min: tuple[float, float, float]      # the kept box (crop box within the volume box)
    box_max: tuple[float, float, float]
    sample_min: tuple[float, float, float]   # density read at points clamped to these
    sample_max: tuple[float, float, float]
    plane: tuple[float, float, float, float]  # unit normal and distance; (0, 0, 0, 1) keeps all
    voxel_first: tuple[int, int, int]        # the kept voxels along x, y, z (first, count)
    voxel_count: tuple[int, int, int]
    dims: tuple[int, int, int]               # the volume's voxels along x, y, z

    @property
    def empty(self) -> bool:
        """Nothing of the volume is kept (the crop holds no voxel centre)."""
        return min(self.voxel_count) == 0

    @property
    def half_extent(self) -> np.ndarray:
        return 0.5 * (np.asarray(self.box_max, np.float64) - np.asarray(self.box_min, np.float64))

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (np.asarray(self.box_max, np.float64) + np.asarray(self.box_min, np.float64))

    def uniforms(self) -> dict:
        """What lib/clip_region.glsl reads."""
        return {"clip_region_on": 1, "kept_box_min": self.box_min, "kept_box_max": self.box_max,
                "kept_sample_min": self.sample_min, "kept_sample_max": self.sample_max,
                "clip_plane": self.plane}

    # ---- the NumPy twin of lib/clip_region.glsl ----------------------------------------------
    def kept(self, points) -> np.ndarray:
        """Whether each world point (..., 3) is kept (kept_at)."""
        p = np.asarray(points, np.float64)
        lo = np.asarray(self.box_min, np.float32).astype(np.float64)
        hi = np.asarray(self.box_max, np.float32).astype(np.float64)
        n = np.asarray(self.plane[:3], np.float32).astype(np.float64)
        d = float(np.float32(self.plane[3]))
        inside = np.all((p >= lo) & (p <= hi), axis=-1)
        return inside & (p @ n <= d)

    def sample_points(self, points) -> np.ndarray:
        """Where the density is read for each world point (kept_sample_point)."""
        lo = np.asarray(self.sample_min, np.float32).astype(np.float64)
        hi = np.asarray(self.sample_max, np.float32).astype(np.float64)
        return np.clip(np.asarray(points, np.float64), lo, hi)

    def cuts_box(self, lo, hi) -> np.ndarray:
        """Whether no point of the boxes [lo, hi] (..., 3) is kept (clip_region_cuts_box)."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        klo = np.asarray(self.box_min, np.float32).astype(np.float64)
        khi = np.asarray(self.box_max, np.float32).astype(np.float64)
        outside = np.any((hi < klo) | (lo > khi), axis=-1)
        n = np.asarray(self.plane[:3], np.float32).astype(np.float64)
        nearest = np.where(n >= 0.0, lo, hi)   # the box's corner with the least dot(n, x)
        return outside | (nearest @ n > float(np.float32(self.plane[3])))


OFF_UNIFORMS = {"clip_region_on": 0}


def region_uniforms(region: ClipRegion | None) -> dict:
    """The uniforms of lib/clip_region.glsl for a region or for none (everything kept)."""
    return OFF_UNIFORMS if region is None else region.uniforms()


def voxel_boundaries(n: int, half: float) -> np.ndarray:
    """World coordinates of the n + 1 voxel boundaries along an axis of n voxels."""
    return (np.arange(n + 1, dtype=np.float64) / n * 2.0 - 1.0) * half


def voxel_centres(n: int, half: float) -> np.ndarray:
    return ((np.arange(n, dtype=np.float64) + 0.5) / n * 2.0 - 1.0) * half


def clip_region(scene: Scene, dims, half_extent) -> ClipRegion | None:
    """The scene's kept region for a volume of `dims` (x, y, z) voxels filling the box of
    `half_extent`; None where neither a crop nor a clip plane is on. A voxel crop reaching beyond
    the volume raises SceneError naming the field."""
    crop = scene.crop if scene.crop is not None and scene.crop.enabled else None
    plane = (scene.clip_plane if scene.clip_plane is not None and scene.clip_plane.enabled
             else None)
    if crop is None and plane is None:
        return None
    he = np.asarray(half_extent, np.float64)
    dims = tuple(int(n) for n in dims)
    box_min, box_max = -he.copy(), he.copy()
    sample_min = np.full(3, -UNBOUNDED)
    sample_max = np.full(3, UNBOUNDED)
    first, count = [0, 0, 0], list(dims)
    if crop is not None:
        for a, axis in enumerate("xyz"):
            n = dims[a]
            faces = voxel_boundaries(n, he[a])
            centres = voxel_centres(n, he[a])
            if crop.units == "voxels":
                i0, i1 = int(crop.min[a]), int(crop.max[a])
                if i1 > n:
                    raise SceneError(f"crop.max[{a}]: {i1} is beyond the volume's {n} voxels "
                                     f"along {axis}")
                lo, hi = faces[i0], faces[i1]
                kept = np.arange(i0, i1)
            else:
                lo, hi = max(float(crop.min[a]), -he[a]), min(float(crop.max[a]), he[a])
                kept = np.flatnonzero((centres >= lo) & (centres <= hi))
            box_min[a], box_max[a] = lo, hi
            if kept.size == 0 or hi <= lo:
                first[a], count[a] = 0, 0
                continue
            first[a], count[a] = int(kept[0]), int(kept.size)
            if kept[0] > 0:
                sample_min[a] = centres[kept[0]]
            if kept[-1] < n - 1:
                sample_max[a] = centres[kept[-1]]
    if plane is not None:
        normal = np.asarray(plane.normal, np.float64)
        length = math.sqrt(float(normal @ normal))
        plane_values = (*(normal / length), plane.distance / length)
    else:
        plane_values = (0.0, 0.0, 0.0, 1.0)
    if min(count) == 0:   # nothing kept: an inverted box that no point is inside
        box_min, box_max = np.ones(3), -np.ones(3)
    return ClipRegion(box_min=tuple(map(float, box_min)), box_max=tuple(map(float, box_max)),
                      sample_min=tuple(map(float, sample_min)),
                      sample_max=tuple(map(float, sample_max)),
                      plane=tuple(float(v) for v in plane_values),
                      voxel_first=tuple(first), voxel_count=tuple(count), dims=dims)


def cropped_volume_offset(scene: Scene, dims, half_extent) -> np.ndarray:
    """Where the centre of the cropped volume's own box (SPEC.md: centred at the origin) lies in
    this scene's world: the translation from the cropped volume's world to the crop's, for crops
    that keep the longest side whole (the same scale; tests and docs/crop-and-movies.md)."""
    region = clip_region(scene, dims, half_extent)
    if region is None:
        return np.zeros(3)
    return region.centre
