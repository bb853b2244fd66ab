"""How a Renderer renders and bakes, beside the scene: one frozen object (RenderSettings).

The scene says what is rendered (SPEC.md); these settings say how: which shortcuts the bake and
the renderers take, and the raymarcher's step and stage. A Renderer holds one RenderSettings
(Renderer.settings); a variant is `renderer.configure(walk_adaptive=0.0)` or
`renderer.settings = replace(settings, ...)`, and records, the viewer and the benchmark carry
`settings.as_dict()` so each image names exactly what made it.

Fields that depend on the device (a CPU rasteriser or a GPU) may be left None, meaning "this
device's default"; `resolved(software)` fills them in, and Renderer.settings always holds the
resolved object.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

from radiance_probes.rendering.grids.light_transmittance import (MAX_SIDE as LIGHT_MAX_SIDE,
                                                                 MIN_SIDE as LIGHT_MIN_SIDE,
                                                                 PRECISION as LIGHT_PRECISION,
                                                                 PRECISIONS as LIGHT_PRECISIONS,
                                                                 SEGMENT_TARGET_INVOCATIONS,
                                                                 SOFTWARE_MIN_SIDE)

from radiance_probes.rendering.probes.bake_level import check_bake_level
from radiance_probes.rendering.probes.bake import SHADOW_TRACKINGS, WALK_SUN_MODES

RAYMARCH_STAGES = ("compute", "fragment")
# The latest event `probes` may gather at: beyond a few events the path tracer's own sampling
# is most of the cost, and the probes stand in for little.
MAX_GATHER_EVENT = 8


def check_gather_event(event) -> int:
    """The gather event `probes` may take (an integer from 1 to MAX_GATHER_EVENT), or ValueError."""
    if isinstance(event, bool) or not isinstance(event, int) or not 1 <= event <= MAX_GATHER_EVENT:
        raise ValueError(f"probe gather event: expected an integer from 1 to {MAX_GATHER_EVENT}, "
                         f"got {event!r}")
    return event


def _check_positive_int(name: str, value, allow_zero: bool = False) -> None:
    low = 0 if allow_zero else 1
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")


@dataclass(frozen=True)
class RenderSettings:
    """Every switch of the bake and the renderers (defaults: the measured defaults; each
    shortcut's bias is in docs/bias.md and the bench's bias table)."""
    # The sun at the bake's walk events: "grid" (the baked light grid, lib/light_grid.glsl) or
    # "ray" (a ratio-tracked shadow ray, unbiased).
    walk_sun: str = "grid"
    # ... corrected without bias (walk_sun "grid"): each event's rate of correction is this at
    # least (more where the grid's optical depth changes fast, up to half); a walk keeps one of
    # its events, weighted by rate and sun, and with probability the sum of its rates (at most 1)
    # a ratio-tracked shadow ray from there corrects the grid's transmittance after the walks
    # (lib/integrator.glsl, glsl/probe_sun_correction.comp); 0: the grid alone, whose
    # interpolation made probes up to 7.5% dark on the stress battery.
    walk_sun_correction: float = 0.05
    # Walks per probe from the noise of its neighbours (lib/probe_noise.glsl, unbiased; 0: every
    # probe takes all its walks): a probe stops once the walks its neighbours' first pass asks
    # for are done.
    walk_adaptive: float = 1.0
    # Probes of SH order 3 also hold a lobe about the sun's direction where the scene scatters
    # forward (probe_layout.sun_lobe_g; lib/sun_lobe.glsl); False: never (comparisons).
    sun_lobe: bool = True
    # `probes` reads the probes at this scattering event (1: the paper's renderer; k > 1 traces
    # events 1 .. k-1 as the path tracer does first: a final gather). Read-side only.
    gather_event: int = 1
    # A bake restarted by an edit starts from the previous probes (ProbeGrid.restart(warm)).
    bake_warm: bool = True
    # The light grid: texels per axis at most, at least along the longest axis (None: the
    # device's), whether it follows the probe grid (None: the device's), its texel precision,
    # and how its columns are cut into segments (None: the device's; 0: never).
    light_max_side: int = LIGHT_MAX_SIDE
    light_min_side: int | None = None
    light_follows_probes: bool | None = None
    light_precision: str = LIGHT_PRECISION
    light_segment_target: int | None = None
    # The raymarcher: a compute pass (default) or the design card's fragment pass; its step in
    # voxels of the smallest spacing.
    raymarch_stage: str = "compute"
    raymarch_step: float = 0.5
    # Tracking over the macrocell majorant grid (True) or one global majorant (the same unbiased
    # estimator, for comparisons).
    empty_space_skipping: bool = True
    # `guided`: frames of level 0 (an unbiased estimate of what the probes predict along camera
    # rays) per path-traced sample of level 1 (the sample minus that prediction).
    # Level 0's residual-tracked march is far less noisy than level 1 (llvmpipe, the foot at 32^2:
    # 7.8e-4 against 7.0e-3 relative variance a sample), so it needs fewer samples.
    guided_level0_ratio: float = 0.25
    # `guided`: at every scattering event, the probes' radiance in the direction drawn minus its
    # mean over the phase function as a control variate (mean 0 at any probes;
    # lib/guided_direction_control.glsl). False: level 1 subtracts at the first event only.
    guided_direction_control: bool = True
    # Bricked volumes (app/rendering/levels/volume_placement.py): the volume's GPU memory at most, in bytes
    # (None: what the device has left); where one 3D texture exceeds it, the finest level whose
    # bricks fit is shown, with a note. `brick_size`: bricks of that many voxels per axis always
    # (None: bricks of 64 only where one texture does not fit; tests force small ones).
    volume_memory_bytes: int | None = None
    brick_size: int | None = None
    # How every shadow ray towards the sun is tracked, in the renderers and the bake: "ratio"
    # (ratio tracking against the macrocell majorants) or "residual" (residual ratio tracking with
    # the light grid's optical depth as the control: the same collisions, factors near 1 where the
    # grid follows the medium; unbiased for any grid; needs the light grid baked;
    # lib/sun_shadow.glsl).
    shadow_tracking: str = "ratio"
    # The probes' bake (its walks, their sun and its light grid, the probes' own sun) walks the
    # volume this many levels coarser than the level shown (app/rendering/probes/bake_level.py: coarser()'s
    # level in one texture with its own majorant grid); what the image reads directly (camera
    # rays, the raymarcher's sun, the path tracer) stays on the level shown. 0: the level shown
    # (the default); -1: the coarsest level whose voxel is at most half the probe spacing along
    # every axis. A shortcut with a bias (docs/bricking.md, measured against the path tracer).
    bake_level: int = 0

    def __post_init__(self):
        if self.walk_sun not in WALK_SUN_MODES:
            raise ValueError(f"walk sun mode {self.walk_sun!r}: expected one of "
                             f"{', '.join(WALK_SUN_MODES)}")
        a = self.walk_adaptive
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not (
                math.isfinite(a) and a >= 0.0):
            raise ValueError(f"adaptive walks factor {a!r}: expected a finite number >= 0")
        r = self.guided_level0_ratio
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (
                math.isfinite(r) and 0.0 < r <= 64.0):
            raise ValueError(f"guided level-0 ratio {r!r}: expected a number in (0, 64]")
        q = self.walk_sun_correction
        if isinstance(q, bool) or not isinstance(q, (int, float)) or not 0.0 <= q <= 1.0:
            raise ValueError(f"walk sun correction {q!r}: expected a rate in [0, 1]")
        check_gather_event(self.gather_event)
        check_bake_level(self.bake_level)
        if self.volume_memory_bytes is not None:
            _check_positive_int("volume memory bytes", self.volume_memory_bytes)
        if self.brick_size is not None:
            _check_positive_int("brick size", self.brick_size)
            if self.brick_size < 2:
                raise ValueError(f"brick size: expected at least 2 voxels, got {self.brick_size}")
        if self.shadow_tracking not in SHADOW_TRACKINGS:
            raise ValueError(f"shadow tracking {self.shadow_tracking!r}: expected one of "
                             f"{', '.join(SHADOW_TRACKINGS)}")
        _check_positive_int("light grid max side", self.light_max_side)
        if self.light_min_side is not None:
            _check_positive_int("light grid min side", self.light_min_side)
        if self.light_segment_target is not None:
            _check_positive_int("light grid segment target", self.light_segment_target,
                                allow_zero=True)
        if self.light_precision not in LIGHT_PRECISIONS:
            raise ValueError(f"light grid precision {self.light_precision!r}: expected one of "
                             f"{', '.join(LIGHT_PRECISIONS)}")
        if self.raymarch_stage not in RAYMARCH_STAGES:
            raise ValueError(f"raymarch stage: expected one of {', '.join(RAYMARCH_STAGES)}, "
                             f"got {self.raymarch_stage!r}")
        step = self.raymarch_step
        if isinstance(step, bool) or not isinstance(step, (int, float)) or not (
                math.isfinite(step) and step > 0):
            raise ValueError(f"raymarch step: expected a finite number of voxels > 0, got {step!r}")
        for name in ("sun_lobe", "bake_warm", "empty_space_skipping",
                     "guided_direction_control"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected true or false, got {getattr(self, name)!r}")

    def resolved(self, software: bool) -> "RenderSettings":
        """These settings with the device's defaults where a field is None: on a CPU rasteriser
        (llvmpipe) the light grid starts at SOFTWARE_MIN_SIDE texels, does not follow the probe
        grid and marches whole columns; on a GPU at LIGHT_MIN_SIDE, following the probes, in
        segments (light_transmittance.py)."""
        return replace(
            self,
            light_min_side=(self.light_min_side if self.light_min_side is not None
                            else SOFTWARE_MIN_SIDE if software else LIGHT_MIN_SIDE),
            light_follows_probes=(self.light_follows_probes
                                  if self.light_follows_probes is not None else not software),
            light_segment_target=(self.light_segment_target
                                  if self.light_segment_target is not None
                                  else 0 if software else SEGMENT_TARGET_INVOCATIONS),
            raymarch_step=float(self.raymarch_step))

    def as_dict(self) -> dict:
        """Plain values for records (JSON)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> "RenderSettings":
        """The inverse of as_dict; unknown names are an error that names them."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown render setting(s): {', '.join(unknown)} "
                             f"(known: {', '.join(sorted(known))})")
        return cls(**values)

    def differences(self, other: "RenderSettings") -> dict:
        """The fields where `other` differs from these, as {name: other's value}."""
        return {f.name: getattr(other, f.name) for f in fields(self)
                if getattr(self, f.name) != getattr(other, f.name)}
