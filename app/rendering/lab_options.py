"""Switches kept for the bench's comparisons and lab/experiments alone: one frozen record
(LabOptions), NOT for users. Each one measured no gain as a product setting and left
RenderSettings (docs/experiments.md says what each found, with its record under bench/); the
defaults are the product's images, bit for bit. A Renderer holds one (`Renderer(..., lab=...)`,
`Renderer.lab`); the front ends (command line, viewer, Python API) never set it.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class LabOptions:
    # Independent ratio-tracked shadow rays towards the sun a scattering event averages, in the
    # render passes (lib/integrator.glsl SUN_SHADOW_RAYS): 1, the product; more measures how much
    # of a path's variance the shadow ray's own noise holds (the mean is the same;
    # lab/experiments/experiment_shadow_variance.py).
    sun_shadow_rays: int = 1
    # Under a memory cap, the memory the shown level leaves holds the next finer level's bricks
    # where the scene's camera sees them largest (app/rendering/levels/level_mix.py), streamed as the
    # camera moves (app/rendering/levels/level_stream.py). On the H100 (bench/h100-bricks-open) it took a
    # zoomed view of the 2048^3 volume from 2.97% to 2.92% rRMSE against level 0, for frames 2.3x
    # as long and 7 s more to open (lab/experiments/brick_bench.py compares it).
    mixed_levels: bool = False
    # False: paths find an environment map by phase sampling alone (lib/integrator.glsl
    # ENVIRONMENT_MAP_SAMPLING 0), for measuring what the map's importance sampling gains
    # (lab/experiments/envmap_sampling.py: about 1900x the efficiency on the sky scene).
    environment_sampling: bool = True
    # False: the raymarcher's hybrid branch computes the exact opacity gradient (six medium
    # lookups) at every sample instead of reading the baked grid (app/rendering/
    # opacity_gradient_grid.py), for measuring the grid's bias and what it saves
    # (lab/experiments/experiment_hybrid_scattering.py, hybrid_raymarch_variants.py).
    opacity_gradient_grid: bool = True
    # The midpoints the raymarcher and probes-only march over an area light's first two grid
    # texels before reading its optical-depth grid (lib/area_light_grid.glsl
    # AREA_LIGHT_NEAR_POINTS): 4, the product; 0 reads the grid alone, for timing the march
    # against its bias (lab/experiments/experiment_area_light_raymarch.py --near-points).
    area_light_near_points: int = 4

    def __post_init__(self):
        rays = self.sun_shadow_rays
        if isinstance(rays, bool) or not isinstance(rays, int) or rays < 1:
            raise ValueError(f"sun shadow rays: expected an integer >= 1, got {rays!r}")
        points = self.area_light_near_points
        if isinstance(points, bool) or not isinstance(points, int) or not 0 <= points <= 16:
            raise ValueError(f"area light near points: expected an integer in 0..16, got "
                             f"{points!r}")
        for name in ("mixed_levels", "environment_sampling", "opacity_gradient_grid"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected true or false, got {getattr(self, name)!r}")

    def as_dict(self) -> dict:
        return asdict(self)
