"""The light grid's layout: a grid sheared along the sun's direction (glsl/lib/light_grid.glsl), so
that each column of texels along one axis lies on one sun ray and the bake
(glsl/light_transmittance.comp) fills a column with one march instead of one march per texel."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The sheared axes widen with the shear (up to 1 + h_a / h_b times the box's texels), and axis a
# takes 1 / |sun_a| times the box's texels, so that the texels along a sun ray are as far apart as
# the box grid's (a grid whose cells are longer along the ray interpolated the sun's transmittance
# at points in the foot's matter 4% worse: 11.3% against 10.9% relative RMS, 256 texels). Capped:
# each axis at most SHEARED_MAX_FACTOR x the largest side asked for, and the whole grid at most
# MAX_TEXELS (1 GiB at 16 bits a texel), beyond which the sheared axes are coarsened.
SHEARED_MAX_FACTOR = 2
MAX_TEXELS = 1 << 29


@dataclass(frozen=True)
class LightGridLayout:
    axis: int                           # a: the sun direction's largest component (0 x, 1 y, 2 z)
    shear: tuple[float, float, float]   # sun_direction / sun_direction[a], component a zero
    half_extent: tuple[float, float, float]   # half the sheared coordinates' range per axis
    size: tuple[int, int, int]          # texels per axis (x, y, z)
    # The box the grid covers: the volume box, or the kept box of a crop or clip plane
    # (app/scene/clip_region.py), centred at `centre`; sheared coordinates are relative to the centre.
    box_half_extent: tuple[float, float, float] = (0.5, 0.5, 0.5)
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def ray_axes(self) -> tuple[int, int]:
        """The two axes b < c other than a, which number the sun rays (one per texel column)."""
        b, c = (j for j in range(3) if j != self.axis)
        return b, c

    @property
    def layer_axis(self) -> int:
        """The axis a sliced bake steps along in slabs of rays: c of ray_axes."""
        return self.ray_axes[1]

    def uniforms(self) -> dict:
        mask = tuple(1.0 if i == self.axis else 0.0 for i in range(3))
        return {"light_grid_axis": self.axis, "light_grid_axis_mask": mask,
                "light_grid_shear": self.shear, "light_grid_half_extent": self.half_extent,
                "light_grid_centre": self.centre, "light_box_half_extent": self.box_half_extent}


def light_grid_layout(box_grid: tuple[int, int, int], box_half_extent, sun_direction,
                      max_side: int, centre=(0.0, 0.0, 0.0)) -> LightGridLayout:
    """The sheared layout holding `box_grid` texels' density (texels per axis over the box, of
    light_grid_size) for this sun: along the axis a of the sun's largest component, the box's
    extent in box_grid[a] / |sun_a| texels (the box grid's spacing along the ray); along each
    other axis b, the range of x_b - shear_b x_a over the box, [-(h_b + |shear_b| h_a),
    h_b + |shear_b| h_a], at the box grid's texel spacing (capped)."""
    d = np.asarray(sun_direction, np.float64)
    d = d / np.linalg.norm(d)
    h = np.asarray(box_half_extent, np.float64)
    a = int(np.argmax(np.abs(d)))
    shear = d / d[a]
    shear[a] = 0.0
    half = h + np.abs(shear) * h[a]
    half[a] = h[a]
    n = np.asarray(box_grid, np.float64)
    size = np.ceil(n * half / h - 1e-6)
    size[a] = np.ceil(n[a] / abs(d[a]) - 1e-6)
    size = np.minimum(size, np.maximum(n, SHEARED_MAX_FACTOR * max_side))
    total = float(np.prod(size))
    if total > MAX_TEXELS:   # coarsen the two sheared axes alike
        scale = np.sqrt(MAX_TEXELS / total)
        for j in range(3):
            if j != a:
                size[j] = np.floor(size[j] * scale)
    size = np.maximum(size, 1).astype(int)
    return LightGridLayout(a, tuple(float(v) for v in shear), tuple(float(v) for v in half),
                           tuple(int(v) for v in size), tuple(float(v) for v in h),
                           tuple(float(v) for v in centre))
