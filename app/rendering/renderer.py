"""One front for every render method: the CLI, the viewer and the benchmark all call this."""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Callable

import moderngl
import numpy as np

from radiance_probes.methods import ACCUMULATED, METHODS as REGISTRY, method as registered
from radiance_probes.twins.camera import camera_frame
from radiance_probes.twins.light_grid import light_grid_lookup
from radiance_probes.gl.context import is_software
from radiance_probes.gl.shaders import set_uniforms
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.io.scene_file import Scene
from radiance_probes.io.volume import Volume
from radiance_probes.rendering.methods.accumulation import Accumulation, SumAccumulation
from radiance_probes.rendering.grids.area_light_grid import (AREA_GRID_METHODS, AreaLightGrid,
                                                             area_light_grid_max_side)
from radiance_probes.rendering.cache_keys import (adaptive_planes_key, area_light_grid_key, light_grid_key,
                         opacity_gradient_grid_key, probe_bake_key, visible_region_key)
from radiance_probes.rendering.probes.bake_level import SPACING_LEVEL, BakeMedium, spacing_level
from radiance_probes.rendering.limits import check_image_size
from radiance_probes.rendering.methods.pathtracer import PathTracer
from radiance_probes.rendering.grids.light_transmittance import (LightTransmittance,
                                                                 min_side_for_probes)
from radiance_probes.rendering.grids.opacity_gradient_grid import OpacityGradientGrid
from radiance_probes.rendering.probes.layout import (fitted_grid, resolve_channels, resolve_precision, resolve_sh_order,
                           sun_lobe_g)
from radiance_probes.rendering.probes.planes import (MAX_FIELD_SIDE, MAX_SPACING, adaptive_planes,
                                                     extinction_field, sun_field)
from radiance_probes.rendering.probes.visible_region import VisibleRegionPass
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.rendering.budgets.dispatch_budget import dispatch_target_ms
from radiance_probes.rendering.budgets.sample_bands import tile_grid
from radiance_probes.rendering.denoise.filter import (GUIDE_SETS, Denoised, choose_guides, radiance_as_albedo, sanitize,
                      shared_denoiser)
from radiance_probes.rendering.denoise.guides import GUIDE_FRAMES, DenoiseGuides
from radiance_probes.rendering.denoise.kept_means import KeptMeans, denoise_on_gl
from radiance_probes.rendering.methods.raymarch import Raymarcher, min_step_voxels
from radiance_probes.rendering.refine.refine import blend_images, render_refine
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.rendering.settings import (MAX_GATHER_EVENT, RAYMARCH_STAGES, RenderSettings,  # noqa: F401 (re-exported)
                       check_gather_event)

# The methods one accumulation holds (app/methods.py, the registry: every method's properties).
METHODS = ACCUMULATED
# The methods whose sample may be split into bands of work groups over several calls
# (add_groups): one pass whose every pixel is its own running mean (the raymarcher as a compute
# pass only; guided's two levels stay whole).
BANDED_METHODS = ("pt", "probes", "probes-only", "raymarch")
# The probes hold max_bounces - 1 events whatever the gather event, so a gather at event k lets a
# path scatter up to max_bounces + k - 1 times. Up to this max_bounces the CLI and the viewer say
# so: measured on llvmpipe (a cloud of albedo 0.95, 8^3 probes), gather 2 at max_bounces 2 came out
# 2% brighter than the path tracer, gather 3 at max_bounces 4 0.8%; at 16 the difference is below
# the probes' own error.
GATHER_BOUNCES_NOTE = 8
# Tracking steps one of `guided`'s level-0 rays may take (lib/guided_level0.glsl): far beyond any
# ray through a volume of the sizes offered (a GPU has no loop limit; llvmpipe ends an
# invocation's loops at 65535 iterations in all, so its tests keep rays short).
GUIDED_LEVEL0_BUDGET = 1 << 22


@dataclass(frozen=True)
class ProbePlan:
    """The probe grid a scene gets (Renderer.probe_plan): probes per axis, the world box they
    cover (low and high corners as plain floats; None: the whole volume box), the SH order kept
    (0, 1 or 2) and whether one grey channel is stored instead of three; `planes`, an adaptive
    layout's probe planes per axis (world fractions of the box; None: evenly spaced)."""
    grid: tuple[int, int, int]
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None
    sh_order: int
    grey: bool
    planes: tuple | None = None
    precision: str = "rgba32f"     # the textures' format (probe_layout.resolve_precision)

    def defines(self) -> dict:
        """The compile-time probe layout of the shaders that read such a grid (lib/probes.glsl)."""
        return {"PROBE_SH_ORDER": self.sh_order, "PROBE_GREY": int(self.grey),
                **({"PROBE_WARP": 1} if self.planes is not None else {})}


@dataclass
class RenderResult:
    image: np.ndarray          # linear RGB float32 (H, W, 3)
    method: str
    spp: int
    render_ms: float           # GPU time of the render passes (timestamp queries)
    bake_ms: float = 0.0       # GPU time of probe baking, where the method has one
    stats: dict = field(default_factory=dict)
    # With denoise: the raw image, what the denoiser did (Denoised: device, note, ms of its parts)
    # and the guides' GPU ms (their passes, counted apart from render_ms)
    raw_image: np.ndarray | None = None
    denoised: Denoised | None = None
    guides_ms: float = 0.0

    @property
    def ms_per_sample(self) -> float:
        return self.render_ms / max(self.spp, 1)


# A budgeted bake's first slice, before any slice of this probe layout was timed: small enough
# for a frame on llvmpipe (64 walks a probe), and the next slices follow the measured time.
FIRST_SLICE_PROBES = 64
# ... and of a sliced light-grid bake: this fraction of its slabs of sun rays (1/16).
FIRST_SLICE_LIGHT_FRACTION = 16


def _slice_estimate(estimate: float | None, seen: float) -> float:
    """The GPU ms per unit (probe walked, light-grid layer) that predicts the next slice: up at once
    to a dearer slice, down halfway to a cheaper one. Units cost more where the medium is denser
    and a slice is a run of neighbours, so the mean alone overshot an 8 ms budget by up to 50% on
    bonsai (H100); rising at once keeps the next slice of such a run inside it."""
    if estimate is None or seen >= estimate:
        return seen
    return 0.5 * (estimate + seen)


@dataclass
class _LightSlot:
    """A light grid and its bake's state: the image's (the raymarcher's sun, and the walks' at
    bake_level 0), or the bake's own at bake_level k > 0 (in the coarse medium)."""
    light: LightTransmittance | None = None
    key: tuple | None = None       # what the texture holds, once done
    pending: tuple | None = None   # the key of a sliced bake under way
    spent_ms: float = 0.0          # its GPU ms so far
    cost_ms: float = 0.0           # GPU ms the grid in hand took to bake

    def holds(self, key: tuple) -> bool:
        """Whether its texture holds the grid of `key`, done."""
        return self.light is not None and self.key == key


class Renderer:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None,
                 settings: RenderSettings | None = None, lab: LabOptions | None = None):
        """`settings`: how it renders and bakes (RenderSettings; None: the defaults), resolved
        for this device (RenderSettings.resolved). `lab`: the bench's and the experiments'
        comparison switches (LabOptions; None: the product's), never a user's."""
        self.ctx = ctx
        self._software = is_software(ctx)
        settings = (settings or RenderSettings()).resolved(self._software)  # checked first
        lab = lab or LabOptions()
        if not isinstance(lab, LabOptions):
            raise TypeError(f"lab: expected a LabOptions, got {type(lab).__name__}")
        self.resources = SceneResources(ctx, scene, volume,
                                        use_majorant_grid=settings.empty_space_skipping,
                                        volume_memory_bytes=settings.volume_memory_bytes,
                                        brick_size=settings.brick_size,
                                        mixed_levels=lab.mixed_levels)
        self.resources.environment_sampling = lab.environment_sampling
        self._settings = settings
        self._lab = lab
        self._passes: dict[tuple, PathTracer] = {}
        # Which path states a pass uses (pass_for): a PathTracer keeps one per pixel between
        # dispatches, so two accumulations of one method advanced in turn (the viewer's `refine`
        # halves) each need their own; 0 for everything else.
        self.pass_slot = 0
        self._acc: Accumulation | None = None
        self._acc0: Accumulation | None = None   # `guided`'s level 0
        self.timer = GpuTimer(ctx)
        self.probe_grid: ProbeGrid | None = None
        self._baked_key: tuple | None = None
        self._raymarchers: dict[str, Raymarcher] = {}
        self._image_light = _LightSlot()   # the light grid the image reads (the level shown)
        self._walk_light = _LightSlot()    # the bake's own at bake_level > 0 (the coarse level)
        # the raymarcher's opacity-gradient grid (hybrid scattering), made when first read
        self._gradient_grid: OpacityGradientGrid | None = None
        self.last_gradient_grid_ms = 0.0   # GPU ms of its last bake (0: it was current)
        # the area lights' optical-depth grid (raymarch, probes-only), made when first read
        self._area_grid: AreaLightGrid | None = None
        self._bake_medium: BakeMedium | None = None   # the coarse level, made when first needed
        self.baked_level = 0   # the bake level of the probes in hand (start_bake)
        self._probe_ms: dict[tuple, float] = {}   # measured GPU ms per probe walked, per layout
        self._sample_ms: dict[tuple, float] = {}  # GPU ms per sample of a path-state pass, per size
        self.last_slice_ms = 0.0
        self._layer_ms: dict[tuple, float] = {}     # GPU ms per light-grid slab of rays, per size
        self.method = "pt"
        self._region_key: tuple | None = None
        self._region = None
        self._region_pass = VisibleRegionPass(ctx)
        self._planes_key: tuple | None = None
        self._planes = None
        self.last_layout_ms = 0.0   # host time the last adaptive layout took (indicator, planes)
        self.seed = 0
        self.camera = None
        self.last_bake_ms = 0.0
        self.last_light_ms = 0.0
        self.lent_accumulation: Accumulation | None = None   # lend(): what begin made in the block
        self._guides: DenoiseGuides | None = None
        self._guide_acc: Accumulation | None = None   # the raymarched image a "probes" guide uses
        self._guides_key: tuple | None = None         # what the guides kept were made for
        self._guides_kept: tuple = (None, None)
        self._kept_means: KeptMeans | None = None     # denoise's tile means on the GPU

    @property
    def _light(self) -> LightTransmittance | None:
        """The light grid the image reads (the level shown)."""
        return self._image_light.light

    @property
    def light_cost_ms(self) -> float:
        """GPU ms the image's light grid in hand took to bake."""
        return self._image_light.cost_ms

    @property
    def settings(self) -> RenderSettings:
        """How this renderer renders and bakes (resolved for the device). Assign a new object
        (or call configure) to change it: what the change makes stale (probes, light grid,
        compiled passes) is redone when next needed."""
        return self._settings

    @settings.setter
    def settings(self, settings: RenderSettings) -> None:
        if not isinstance(settings, RenderSettings):
            raise TypeError(f"settings: expected a RenderSettings, got {type(settings).__name__}")
        self._settings = settings.resolved(self._software)
        self.resources.use_majorant_grid = self._settings.empty_space_skipping
        self.resources.set_bricking(self._settings.volume_memory_bytes, self._settings.brick_size)

    @property
    def lab(self) -> LabOptions:
        """The comparison switches this renderer runs with (lab_options.py; not for users).
        Assign a new LabOptions to change them: passes compile anew where they differ; a change
        of mixed_levels applies where the volume is next placed."""
        return self._lab

    @lab.setter
    def lab(self, lab: LabOptions) -> None:
        if not isinstance(lab, LabOptions):
            raise TypeError(f"lab: expected a LabOptions, got {type(lab).__name__}")
        self._lab = lab
        self.resources.mixed_levels = lab.mixed_levels
        self.resources.environment_sampling = lab.environment_sampling

    def configure(self, **changes) -> RenderSettings:
        """Replaces the named settings (RenderSettings' fields; checked); returns the new ones."""
        self.settings = replace(self._settings, **changes)
        return self._settings

    @property
    def raymarch_stage(self) -> str:
        return self._settings.raymarch_stage

    @property
    def raymarch_step_voxels(self) -> float:
        """The raymarch step in voxels of the smallest spacing."""
        return self._settings.raymarch_step

    @property
    def probe_gather_event(self) -> int:
        """The scattering event at which `probes` reads the probes (1: the first)."""
        return self._settings.gather_event

    def gather_bounces_past_limit(self) -> int | None:
        """With a later gather the probes (max_bounces - 1 events whatever the gather) let a
        `probes` path scatter up to max_bounces + k - 1 times: that count where it is worth saying
        (k > 1 reached, max_bounces at most GATHER_BOUNCES_NOTE), else None. A gather past
        max_bounces is never reached: the image is the path tracer's."""
        k, bounces = self._settings.gather_event, self.scene.max_bounces
        return bounces + k - 1 if 1 < k <= bounces <= GATHER_BOUNCES_NOTE else None

    @property
    def effective_raymarch_step_voxels(self) -> float:
        """The raymarch step the shader takes on the longest rays through this volume's box: the
        one asked for, or longer where it would need more than raymarch.MAX_MARCH_STEPS steps."""
        return max(self.raymarch_step_voxels, min_step_voxels(self.resources.volume))

    @property
    def scene(self) -> Scene:
        return self.resources.scene

    def set_scene(self, scene: Scene, volume: Volume | None = None, placed=None) -> set[str]:
        """`placed`: `volume` already placed (Resources.update)."""
        return self.resources.update(scene, volume, placed)

    def pass_for(self, method: str, probe_defines: dict | None = None) -> PathTracer:
        """The compiled pass of a method (compiled once per probe layout, on first use); the
        layout is the given probe grid's, else the one the current scene will bake."""
        defines = None
        lighting = REGISTRY[method].probe_lighting
        if lighting:   # a variant of glsl/pathtrace.comp that reads the probes at its gather event
            defines = {"PROBE_LIGHTING": lighting, **(probe_defines or self._probe_defines())}
        elif method == "guided":   # level 1: a path-traced sample minus level 0's prediction
            defines = {"GUIDED_RESIDUAL": 1,
                       "GUIDED_DIRECTION_CONTROL": int(self._settings.guided_direction_control),
                       **(probe_defines or self._probe_defines())}
        if self.resources.defines():
            defines = {**(defines or {}), **self.resources.defines()}
            if "HYBRID_SCATTERING" in defines:
                # With surfaces this pass keeps the crop and clip tests (their uniforms then say
                # "none": the same image). Compiled out, they made the path tracer's sample 16%
                # slower on the H200 (the foot at 1080p: 4.72 against 4.07 ms; 3.69 at k = 0),
                # while the raymarcher and k = 0 gain from it (bench/h200-hybrid-cost,
                # lab/experiments/hybrid_pt_bisect.py)
                defines.pop("NO_CLIP_REGION", None)
        if self._lab.sun_shadow_rays != 1:
            defines = {**(defines or {}), "SUN_SHADOW_RAYS": self._lab.sun_shadow_rays}
        defines = self._area_light_lab_defines(defines)
        if self._settings.shadow_tracking == "residual":
            defines = {**(defines or {}), "SHADOW_TRACKING_RESIDUAL": 1}
        key = (method, tuple(sorted((defines or {}).items())))
        if key not in self._passes:
            self._passes[key] = PathTracer(self.ctx, defines)
        if self.pass_slot:   # another accumulation's path states, the same program
            first = self._passes[key]
            key = (*key, self.pass_slot)
            if key not in self._passes:
                self._passes[key] = PathTracer(self.ctx, defines, share=first)
        return self._passes[key]

    def _probe_defines(self) -> dict:
        plan = self.probe_plan(region=False)
        return self._read_defines(plan.defines())

    def _read_defines(self, layout: dict) -> dict:
        """A probe layout's defines plus how the passes that read the probes interpolate them
        (the scene's probes.interpolation; lib/probe_visibility.glsl)."""
        if self.scene.probes.interpolation == "visibility":
            return {**layout, "PROBE_VISIBILITY": 1,
                    "PROBE_VISIBILITY_MAX_CELL": float(MAX_SPACING if layout.get("PROBE_WARP")
                                                       else 1.0)}
        return layout

    @property
    def pathtracer(self) -> PathTracer:
        return self.pass_for("pt")

    # ---- probes -------------------------------------------------------------------------------
    def bake_key(self) -> tuple:
        """What the probes in hand were baked for (a different key: a new bake): the volume's
        version, the crop, the resolved SH order and bake level, and the Scene's and the
        settings' fields the bake reads (cache_keys.probe_bake_key)."""
        return (*self.resources.bake_key()[:2], self._sh_order(), self.bake_level(),
                probe_bake_key(self.scene, self._settings))

    def bake_level(self) -> int:
        """The level the probes' bake walks, counted from the level shown (0: that level):
        RenderSettings.bake_level, or for -1 the one the probes' spacing allows
        (bake_level.spacing_level)."""
        level = self._settings.bake_level
        if level == SPACING_LEVEL:
            plan = self.probe_plan()
            level = spacing_level(self.resources.volume, plan.grid, plan.box)
        return level

    def bake_resources(self):
        """What the bake's passes read the medium through: the scene's resources at bake level
        0, else the coarse level's (bake_level.BakeMedium: its volume texture and majorant
        grid, the rest the scene's). Refused (VolumeError naming bake_level) where that level
        does not fit one texture."""
        level = self.bake_level()
        if level == 0:
            return self.resources
        if self._bake_medium is None:
            self._bake_medium = BakeMedium(self.ctx)
        return self._bake_medium.update(self.resources, level)

    def probes_current(self) -> bool:
        return (self.probe_grid is not None and self.probe_grid.done
                and self._baked_key == self.bake_key())

    def visible_region(self) -> tuple[np.ndarray, np.ndarray]:
        """World corners of what the transfer function makes visible (cached: one GPU pass over
        the volume, glsl/visible_region.comp, redone when the volume or the transfer function
        changes)."""
        key = (self.resources.volume_version, self.resources.clip,
               visible_region_key(self.scene))
        if self._region_key != key:
            self._region = self._region_pass.region(self.resources)
            self._region_key = key
        return self._region

    def probe_plan(self, region: bool = True) -> ProbePlan:
        """The probe grid the current scene gets: its counts, box, SH order, channels
        (probe_layout.py) and, for an adaptive layout, its planes (probe_planes.py);
        region=False skips the visible-region pass and the planes (evenly spaced)."""
        s = self.scene
        spec = s.probes
        grid, box = tuple(spec.grid), None
        clip = self.resources.clip
        # A time series' probes cover the whole box: its visible region moves from step to step,
        # and one grid for every step lets each step's bake start warm from the last one's.
        if spec.fit == "visible" and region and self.resources.volume.time_steps == 1:
            low, high = self.visible_region()
            grid = fitted_grid(spec.grid, low, high)
            box = (tuple(map(float, low)), tuple(map(float, high)))
        elif clip is not None and not clip.empty:   # "box": the kept box of a crop or clip plane
            box = (tuple(map(float, clip.box_min)), tuple(map(float, clip.box_max)))
        env = self.resources.environment
        # A map is grey when its three channels are equal everywhere; (1, 0, 0) stands for colour.
        environment = s.environment if env is None else ((1, 1, 1) if env.grey else (1, 0, 0))
        grid = tuple(int(v) for v in grid)
        planes = (self.adaptive_planes(grid, box)
                  if region and spec.layout == "adaptive" else None)
        return ProbePlan(grid=grid, box=box,
                         sh_order=self._sh_order(),
                         precision=resolve_precision(spec.precision,
                                                     self.scene.surface.gradient_factor > 0.0),
                         grey=resolve_channels(spec.channels, self.resources.medium_table,
                                               s.light.irradiance, environment) == 1,
                         planes=planes)

    def _sh_order(self) -> int:
        """The SH order the current scene's probes are baked with (probe_layout.resolve_sh_order;
        surfaces need directions (their irradiance is the clamped cosine's bands 0 to 2 of the
        probes' light): "auto" gives no order 0 while they are on)."""
        spec = self.scene.probes
        return resolve_sh_order(spec.sh_order, self.scene.anisotropy, spec.samples,
                                directions=self.scene.surface.gradient_factor > 0.0)

    def adaptive_planes(self, grid: tuple[int, int, int], box) -> tuple | None:
        """The adaptive layout's probe planes for this grid and box (cached; None: it came out
        uniform). The "sun" indicator bakes the light grid if stale and reads it back."""
        s = self.scene
        spec = s.probes
        sun = spec.adaptive_indicator == "sun"
        key = (self.resources.volume_version, self.resources.clip, grid, box,
               adaptive_planes_key(s, self._settings))
        if key != self._planes_key:
            start = time.perf_counter()
            if sun:
                self.bake_light()
                field = sun_field(self._light_box_optical_depth())
            else:
                field = extinction_field(self.resources.volume.data, self.resources.medium_table,
                                         s.density_scale)
            self._planes = adaptive_planes(field, self.resources.volume.half_extent, box, grid,
                                           spec.adaptive_strength)
            self._planes_key = key
            self.last_layout_ms = 1e3 * (time.perf_counter() - start)
        return self._planes

    def _light_box_optical_depth(self) -> np.ndarray:
        """The light grid's optical depth resampled (trilinear, as the shaders read it) at the
        texel centres of a box-aligned grid of its density, at most MAX_FIELD_SIDE per axis."""
        light = self._light
        scale = min(1.0, MAX_FIELD_SIDE / max(light.box_grid))
        dims = tuple(max(1, round(n * scale)) for n in light.box_grid)
        he = np.asarray(self.resources.volume.half_extent, np.float64)
        axes = [((2.0 * (np.arange(n) + 0.5)) / n - 1.0) * he[i] for i, n in enumerate(dims)]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return light_grid_lookup(light.read(), light.layout, np.stack([x, y, z], axis=-1))

    def start_bake(self, seed: int = 0, warm: bool = False) -> ProbeGrid:
        """(Re)starts the bake for the current scene; reuses the textures when the layout is
        unchanged, and then `warm` shows the new probes blended with the old ones until the
        bake ends (ProbeGrid.restart)."""
        spec = self.scene.probes
        plan = self.probe_plan()
        g = self.probe_grid
        env_map = self.resources.environment is not None
        st = self._settings
        lobe = sun_lobe_g(self.scene.anisotropy, plan.sh_order) if st.sun_lobe else 0.0
        medium = self.bake_resources().medium_defines()
        if g is None or (g.grid, g.samples, g.precision, g.sh_order, g.box, g.grey, g.sun,
                         g.adaptive, g.environment_map, g.planes, g.sun_lobe) != (
                plan.grid, spec.samples, plan.precision, plan.sh_order, plan.box, plan.grey,
                st.walk_sun, st.walk_adaptive, env_map, plan.planes, lobe) or (
                g.sun_correction != st.walk_sun_correction) or g.medium != medium or (
                g.shadow_tracking != st.shadow_tracking) or (
                g.area_lights != self.resources.area_lights_on):
            if g is not None:
                g.release()
            self.probe_grid = ProbeGrid(self.ctx, plan.grid, spec.samples, plan.precision,
                                        plan.sh_order, plan.box, plan.grey,
                                        sun=st.walk_sun, adaptive=st.walk_adaptive,
                                        sun_correction=st.walk_sun_correction,
                                        environment_map=env_map, planes=plan.planes,
                                        sun_lobe=lobe, medium=medium,
                                        shadow_tracking=st.shadow_tracking,
                                        area_lights=self.resources.area_lights_on)
        self.probe_grid.dispatch_target_ms = dispatch_target_ms(self)
        self.baked_level = self.bake_level()
        self.probe_grid.restart(seed, warm=warm)
        self._baked_key = self.bake_key()
        return self.probe_grid

    def bake_note(self) -> str | None:
        """What the probes in hand were baked on where it is not the level shown (bake_level >
        0), for `render`'s output and the API's notes; else None."""
        level, medium = self.baked_level, self._bake_medium
        if self.probe_grid is None or not level or medium is None or medium.volume is None:
            return None
        nx, ny, nz = medium.volume.dims
        return (f"probes baked on a level {level} coarser than the one shown ({nx} x {ny} x {nz}, "
                f"{medium.gpu_bytes / 2**20:.1f} MiB beside the volume): RenderSettings.bake_level, "
                f"a shortcut with a bias (docs/bricking.md)")

    def bake(self, seed: int = 0, progress: Callable | None = None, profile=None,
             counters=None) -> float:
        """Bakes the probes to completion if they are stale; returns the GPU time in ms.
        `profile` (a GpuProfile) and `counters` (ProbeGrid.walk_counters()) are the benchmark's
        bake profile; see ProbeGrid.bake_pass."""
        if self.probes_current():
            return 0.0
        grid = self.start_bake(seed)
        total = self._light_for_walks()
        light = self.walk_light() if grid.needs_light else None
        resources = self.bake_resources()
        if progress is None:
            # One timed span: the passes queue up on the GPU with no wait between them.
            self.timer.start()
            while not grid.done:
                grid.bake_pass(resources, profile=profile, counters=counters, light=light)
            self.timer.stop()
            total += self.timer.elapsed_ms
        while not grid.done:   # with progress: each pass waited for, so progress is shown live
            self.timer.start()
            grid.bake_pass(resources, profile=profile, counters=counters, light=light)
            self.timer.stop()
            total += self.timer.elapsed_ms
            progress(grid)
        self.last_bake_ms = total
        return total

    def _light_for_walks(self) -> float:
        """The light grid the walks read when walk_sun is "grid" (GPU ms if it was baked now; the
        bake's time includes it, and the raymarcher then finds it current)."""
        return self.bake_walk_light() if self.probe_grid.needs_light else 0.0

    def raymarcher(self, guided_level0: bool = False) -> Raymarcher:
        """The raymarcher for the probes in hand, or (guided_level0) `guided`'s level 0, an
        unbiased estimate of what they predict along camera rays (lib/guided_level0.glsl; compute
        only)."""
        # The layout of the textures it will read, and the scene's lights.
        defines = {**self._read_defines(self.probe_grid.defines()), **self.resources.defines()}
        stage = self.raymarch_stage
        if guided_level0:
            defines["GUIDED_LEVEL0"] = 1
            stage = "compute"
        defines = self._area_light_lab_defines(defines)
        # the opacity gradient read from its grid (hybrid scattering; not `guided`'s level 0,
        # whose paths keep the exact gradient), where the grid can be made
        grid = None if guided_level0 else self._gradient_grid_ready()
        if grid is not None:
            defines["OPACITY_GRADIENT_GRID"] = 1
        key = (stage, tuple(sorted(defines.items())))
        if key not in self._raymarchers:
            self._raymarchers[key] = Raymarcher(self.ctx, stage, defines)
        marcher = self._raymarchers[key]
        self._light.bind()
        if grid is not None:
            grid.bind()
            set_uniforms(marcher.program, grid.uniforms())
        return marcher

    # ---- the raymarcher's opacity-gradient grid (opacity_gradient_grid.py) ---------------------
    def _gradient_grid_key(self) -> tuple:
        """What the grid depends on: the level shown's version, the crop resolved against it, the
        medium's fields (not density_scale) and its defines (channels, crop on or off)."""
        res = self.resources
        return (res.volume_version, res.clip, opacity_gradient_grid_key(self.scene),
                tuple(sorted(res.medium_defines().items())))

    def _gradient_grid_for_scene(self) -> OpacityGradientGrid | None:
        """The grid object where the raymarcher reads one (surfaces on, k > 0, and the lab's
        switch on; grid_refusal then says whether the grid can be made), None where it computes
        the gradient. With k = 0 a grid kept from before gives its memory back."""
        if not self.scene.surface.gradient_factor > 0.0:
            if self._gradient_grid is not None:
                self._gradient_grid.drop()
            return None
        if not self._lab.opacity_gradient_grid:
            return None
        if self._gradient_grid is None:
            self._gradient_grid = OpacityGradientGrid(self.ctx)
        return self._gradient_grid

    def bake_gradient_grid(self) -> float:
        """Bakes the raymarcher's opacity-gradient grid if stale (where it reads one); GPU ms (0
        where it was current, not read, or refused: opacity_gradient_grid.grid_refusal)."""
        self.last_gradient_grid_ms = 0.0
        grid = self._gradient_grid_for_scene()
        if grid is None:
            return 0.0
        key = self._gradient_grid_key()
        if grid.key == key:
            return 0.0
        self.timer.start()
        baked = grid.update(self.resources, key)
        self.timer.stop()
        if baked:
            self.last_gradient_grid_ms = grid.cost_ms = self.timer.elapsed_ms
        return self.last_gradient_grid_ms

    def _gradient_grid_ready(self) -> OpacityGradientGrid | None:
        """The grid the raymarcher reads now, made if stale (untimed: the callers that time it
        bake it first, bake_gradient_grid); None where the raymarcher computes the gradient."""
        grid = self._gradient_grid_for_scene()
        if grid is None:
            return None
        grid.update(self.resources, self._gradient_grid_key())
        return grid if grid.usable else None

    @property
    def opacity_gradient_grid(self) -> OpacityGradientGrid | None:
        """The raymarcher's opacity-gradient grid, None before one was needed (its texture,
        memory, and `refusal` where it could not be made)."""
        return self._gradient_grid

    def _light_target(self) -> tuple[tuple, int]:
        """The light grid the current scene needs: its key and least texels along the longest
        axis (it follows the probe grid: light_transmittance.TEXELS_PER_PROBE)."""
        s, st = self.scene, self._settings
        min_side = (min_side_for_probes(s.probes.grid, st.light_min_side)
                    if st.light_follows_probes else st.light_min_side)
        key = (self.resources.volume_version, self.resources.clip, min_side,
               light_grid_key(s, st))
        return key, min_side

    def light_current(self) -> bool:
        return self._image_light.holds(self._light_target()[0])

    def light_baking(self) -> bool:
        """Whether a sliced light-grid bake for the current scene is under way (bake_light with
        a budget): its texture then holds new layers and the previous grid's, and readers use it
        as it is rather than finish it in one go."""
        pending = self._image_light.pending
        return pending is not None and pending == self._light_target()[0]

    def bake_light(self, budget_ms: float | None = None) -> float:
        """Bakes the sun's transmittance grid for the raymarcher and the walks if stale; GPU ms.
        `budget_ms` None: all of it (or the rest of a sliced bake); otherwise slabs of sun rays
        that the GPU time per layer measured by earlier slabs of this grid size predicts fits
        (1/16 of the grid before any was timed; at least one layer). An edit in the middle of a
        sliced bake restarts it."""
        key, min_side = self._light_target()
        return self._bake_light_slot(self._image_light, self.resources, key, min_side, budget_ms)

    def _walk_light_target(self) -> tuple[tuple, int]:
        """The key and least side of the light grid the walks read: the image's at bake level 0,
        else its own in the coarse medium (the same settings, over the coarse level's voxels)."""
        key, min_side = self._light_target()
        level = self.bake_level()
        return ((key, level) if level else key), min_side

    def bake_walk_light(self, budget_ms: float | None = None) -> float:
        """The light grid the walks read (walk_sun "grid"), baked if stale as bake_light does:
        at bake level 0 the image's own, else the bake's in the coarse medium; GPU ms."""
        if self.bake_level() == 0:
            return self.bake_light(budget_ms)
        key, min_side = self._walk_light_target()
        return self._bake_light_slot(self._walk_light, self.bake_resources(), key, min_side,
                                     budget_ms)

    def walk_light(self) -> LightTransmittance | None:
        """The light grid the walks read (bake_walk_light's)."""
        return self._light if self.bake_level() == 0 else self._walk_light.light

    def walk_light_current(self) -> bool:
        if self.bake_level() == 0:
            return self.light_current()
        return self._walk_light.holds(self._walk_light_target()[0])

    def _bake_light_slot(self, slot: _LightSlot, resources, key: tuple, min_side: int,
                         budget_ms: float | None) -> float:
        """bake_light for one light grid (`slot`) over `resources`' medium."""
        st = self._settings
        medium = resources.medium_defines()
        if (slot.light is None or slot.light.max_side != st.light_max_side
                or slot.light.precision != st.light_precision or slot.light.medium != medium):
            if slot.light is not None:
                slot.light.release()
            slot.light = LightTransmittance(self.ctx, st.light_max_side, st.light_precision,
                                            medium=medium)
            # a new object holds no grid: its key may be the old one's (surfaces switched on or
            # off change the medium's defines, not the grid's key), which held a texture
            slot.key = slot.pending = None
        slot.light.segment_target = st.light_segment_target
        if key == slot.key:
            return 0.0
        light = slot.light
        if slot.pending != key:
            light.begin(resources, self.scene.light.direction, min_side)
            slot.key = None
            slot.pending = key
            slot.spent_ms = 0.0
        layers = None
        if budget_ms is not None:
            per_layer = self._layer_ms.get(light.grid)
            layers = (max(1, light.layers // FIRST_SLICE_LIGHT_FRACTION) if per_layer is None
                      else max(1, int(budget_ms / max(per_layer, 1e-9))))
        self.timer.start()
        ran = light.bake_layers(resources, layers)
        self.timer.stop()
        ms = self.timer.elapsed_ms
        if ran and layers is not None:
            seen = ms / ran
            per_layer = self._layer_ms.get(light.grid)
            self._layer_ms[light.grid] = _slice_estimate(per_layer, seen)
        slot.spent_ms += ms
        if light.done:
            slot.key, slot.pending = key, None
            slot.cost_ms = slot.spent_ms
        return ms

    def light_grid_ms(self) -> float:
        """What the light grid the current scene uses cost to bake (GPU ms), baking it if stale:
        also when an earlier call baked the same grid (the benchmark charges it to every image)."""
        self.bake_light()
        return self.light_cost_ms

    # ---- the public frame API: accumulations a caller owns (the viewer, movies, the bench) -----
    @contextmanager
    def lend(self, acc: Accumulation | None, method: str | None = None, camera=None,
             seed: int | None = None, level0: Accumulation | None = None, slot: int = 0):
        """Within the block, begin() and add_samples() work on `acc` (None: begin makes one)
        instead of the Renderer's own accumulation: a caller's view, a movie's frame, one of
        refine's halves. `method`, `camera`, `seed` set what add_samples continues (a view
        begun earlier); `level0`: guided's level 0 to go with it; `slot`: the path states of a
        second accumulation of one method (refine's halves). Everything is given back after
        the block; `lend(...)` yields the Renderer, and `lent_accumulation` is what begin made."""
        kept = (self._acc, self._acc0, self.method, self.camera, self.seed, self.pass_slot)
        self._acc = acc
        if level0 is not None:
            self._acc0 = level0
        if method is not None:
            self.method = method
        if camera is not None:
            self.camera = camera
        if seed is not None:
            self.seed = seed
        self.pass_slot = slot
        try:
            yield self
        finally:
            self.lent_accumulation = self._acc
            self._acc, self._acc0, self.method, self.camera, self.seed, self.pass_slot = kept

    def bake_started_for_scene(self) -> bool:
        """Whether the probes in hand (finished or not) are the current scene's bake."""
        return self.probe_grid is not None and self._baked_key == self.bake_key()

    def forget_probes(self) -> None:
        """The next bake() bakes the same probes again (the bench times repeated bakes); the
        light grid stays."""
        self._baked_key = None

    def forget_light_grid(self) -> None:
        """The next bake_light() bakes the image's light grid again (its time is then real)."""
        self._image_light.key = self._image_light.pending = None

    @property
    def light_grid(self) -> LightTransmittance | None:
        """The light grid the image reads (its size and memory are in the records)."""
        return self._light

    def invalidate(self) -> None:
        """Forgets the baked probes, the light grid, the opacity-gradient grid and the
        denoiser's guides, so the next image pays for them again (the benchmark charges every
        record what its image cost)."""
        self._baked_key = None
        self._guides_key = None
        for slot in (self._image_light, self._walk_light):
            slot.key = slot.pending = None
        if self._gradient_grid is not None:
            self._gradient_grid.forget()
        if self._area_grid is not None:
            self._area_grid.forget()

    def probe_uniforms(self) -> dict:
        self.probe_grid.bind()
        return self.probe_grid.uniforms(self.scene.anisotropy, self.scene.probes.sh_window,
                                        self.resources)

    def accumulation(self, width: int, height: int) -> Accumulation:
        if self._acc is None or (self._acc.width, self._acc.height) != (width, height):
            if self._acc is not None:
                self._acc.release()
            self._acc = Accumulation(self.ctx, width, height)
        return self._acc

    # ---- streaming a mix of levels (LabOptions.mixed_levels under a cap) -----------------------
    def restream(self, camera=None, budget_s: float | None = None) -> bool:
        """Moves a mixed pool towards the bricks `camera` (None: the scene's) deserves
        (app/rendering/levels/level_stream.py); with `budget_s`, about that many seconds of writes, the
        rest left to the next calls (the viewer's frames). True when the medium changed: the
        majorant grid is then remade and the probes, light grid and visible region are stale
        (an edit of the medium). Nothing where the volume is not a streamed mix, or the camera
        deserves the mix held."""
        stream = self.resources.stream
        if stream is None:
            return False
        changed = stream.restream(self.scene.camera if camera is None else camera, budget_s)
        if changed:
            self.resources.medium_restreamed()
        return changed

    def streaming(self) -> bool:
        """Whether a restream is under way (its next call goes on with it)."""
        stream = self.resources.stream
        return stream is not None and stream.pending is not None

    # ---- progressive rendering (the viewer calls these once per frame) -------------------------
    def begin(self, method: str = "pt", width: int | None = None, height: int | None = None,
              seed: int = 0) -> Accumulation:
        """Starts a fresh accumulation for `method` with the scene's current camera."""
        if registered(method).composite:
            raise ValueError(f"{method} is made of {' and '.join(REGISTRY[method].parts)}'s "
                             f"images, which no one accumulation holds: render() it (or the "
                             f"viewer) (one accumulation: {', '.join(METHODS)})")
        self.camera = camera_frame(self.scene.camera, width, height)
        check_image_size(self.ctx, self.camera.width, self.camera.height)
        self.method = method
        self.seed = seed
        self.resources.reset_stats()
        acc = self.accumulation(self.camera.width, self.camera.height)
        acc.reset()
        if method == "guided":
            level0 = self._level0_accumulation(self.camera.width, self.camera.height)
            level0.reset()
            return SumAccumulation(acc, level0)
        return acc

    def _level0_accumulation(self, width: int, height: int) -> Accumulation:
        if self._acc0 is None or (self._acc0.width, self._acc0.height) != (width, height):
            if self._acc0 is not None:
                self._acc0.release()
            self._acc0 = Accumulation(self.ctx, width, height)
        return self._acc0

    def needs_probes(self, method: str | None = None) -> bool:
        return registered(method or self.method).needs_probes

    def bake_step(self, seed: int = 0, budget_ms: float | None = None) -> float:
        """One slice of a progressive bake if the probes are stale or unfinished (GPU ms; 0 when
        nothing was done); starts a new bake (warm when `bake_warm`) when the scene's bake inputs
        changed, so an edit in the middle of a bake is never lost. `budget_ms` None: the rest of
        the current pass. Otherwise as many probes' walks as the GPU time of earlier slices
        predicts fit in the budget (FIRST_SLICE_PROBES before any is timed; at least one probe's
        walks of one pass); the slice is timed as one span (one wait, for
        the timer), and its measured time per probe predicts the next slice."""
        if self.probes_current():
            return 0.0
        if self.probe_grid is None or self._baked_key != self.bake_key():
            self.start_bake(seed, warm=self._settings.bake_warm)
        grid = self.probe_grid
        if grid.needs_light:
            # the walks read the light grid: it comes first, in slices of the same budget
            light_ms = self.bake_walk_light(budget_ms)
            if not self.walk_light_current() or (budget_ms is not None and light_ms >= budget_ms):
                self.last_slice_ms = light_ms
                return light_ms
        else:
            light_ms = 0.0
        light = self.walk_light() if grid.needs_light else None
        resources = self.bake_resources()
        self.timer.start()
        if budget_ms is None:
            grid.bake_pass(resources, light=light)
            self.timer.stop()
            ms = self.timer.elapsed_ms
        else:
            left = max(budget_ms - light_ms, 0.0)
            key = (grid.grid, grid.samples)
            per_probe = self._probe_ms.get(key)
            probes = (min(FIRST_SLICE_PROBES, grid.count) if per_probe is None
                      else max(1, int(left / max(per_probe, 1e-9))))
            ran = grid.bake_probes(resources, probes, light=light)
            self.timer.stop()
            ms = self.timer.elapsed_ms
            if ran:
                seen = ms / ran
                # (the first slice of a bake also runs the sun's pass)
                self._probe_ms[key] = _slice_estimate(per_probe, seen)
        self.last_slice_ms = light_ms + ms
        return light_ms + ms

    def probes_shown(self) -> bool:
        """Whether the probe textures hold anything to render from: a finished bake, or one
        with at least one chunk walked (then the image shows the probes as they are)."""
        g = self.probe_grid
        return g is not None and (g.passes_done > 0 or g.next_probe > 0 or g.warm_walks > 0)

    def needs_light(self, method: str) -> bool:
        """Whether rendering `method` reads the light grid: the raymarcher and `guided` always,
        every path-traced method where the shadow rays are residual-tracked against it."""
        return (REGISTRY[method].needs_light_grid
                or self._settings.shadow_tracking == "residual")

    def add_samples(self, n: int = 1) -> float:
        """Adds n samples per pixel to the accumulation begun by begin(); returns GPU ms.
        Probe methods use the probes as they are now (bake them first for a final image)."""
        method, acc = self.method, self._acc
        extra, _ = self._sample_inputs(method)
        level0_ms = 0.0
        if method == "guided":
            # level 0's frames, guided_level0_ratio of them per sample of level 1 (at least one
            # whenever level 1 has more samples than level 0 has frames times the ratio)
            acc0 = self._acc0
            want = math.ceil((acc.samples + n) * self._settings.guided_level0_ratio)
            frames = max(0, want - acc0.samples)
            if frames:
                self.timer.start()
                self.raymarcher(guided_level0=True).run(
                    self.resources, self.camera, acc0, frames, self.seed ^ 0x5bd1e995,
                    self.raymarch_step_voxels * 2 * self.resources.march_step,
                    {**extra, **self._light.uniforms(),
                     "guided_level0_budget": GUIDED_LEVEL0_BUDGET})
                self.timer.stop()
                level0_ms = self.timer.elapsed_ms
            extra = {**extra, **self._light.uniforms()}
        if method == "raymarch":
            marcher = self.raymarcher()
            step = self.raymarch_step_voxels * 2 * self.resources.march_step
            uniforms = {**extra, **self._light.uniforms()}
            self.timer.start()
            if acc.groups_done:   # a frame part marched in bands (add_groups): the rest first
                marcher.run_groups(self.resources, self.camera, acc,
                                   (acc.groups_done, math.prod(tile_grid(acc.width, acc.height))),
                                 self.seed, step, uniforms)
                acc.samples, acc.groups_done, n = acc.samples + 1, 0, n - 1
            if n > 0:
                marcher.run(self.resources, self.camera, acc, n, self.seed, step, uniforms)
            self.timer.stop()
            return self.timer.elapsed_ms
        tracer, extra = self._traced_pass(method, extra)
        # Cut into dispatches of at most the device's target (dispatch_budget.py) by the GPU ms
        # per sample this pass took at this size last time: several samples a dispatch where they
        # fit, bands of rows where one sample of the whole image would not. Unknown yet: one
        # sample first on a GPU (one more wait for the timer).
        key = (id(tracer), acc.width, acc.height)
        target = dispatch_target_ms(self)
        total = 0.0
        while n > 0:
            per_sample = self._sample_ms.get(key)
            if per_sample is None or math.isinf(target):   # (a CPU rasteriser: no cutting)
                k, bands = (n if math.isinf(target) else 1), 1
            else:
                bands = max(1, math.ceil(per_sample / target))
                k = 1 if bands > 1 else max(1, min(n, int(target / max(per_sample, 1e-9))))
            self.timer.start()
            tracer.run(self.resources, self.camera, acc, acc.samples + k, self.seed, extra, bands)
            self.timer.stop()
            ms = self.timer.elapsed_ms
            self._sample_ms[key] = ms / k
            total += ms
            n -= k
        return total + level0_ms

    def _sample_inputs(self, method: str) -> tuple[dict | None, float]:
        """What a sample of `method` reads besides the scene: the probes' uniforms (methods
        that read probes), and the light grid baked first where it is stale (its ms)."""
        extra = None
        if self.needs_probes(method):
            if self.probe_grid is None:
                raise RuntimeError("probe methods need a bake first (bake() or bake_step())")
            extra = self.probe_uniforms()
            # probes-only traces no shadow rays, which the events before a later gather need
            extra["probe_gather_event"] = (self._settings.gather_event
                                           if "gather_event" in REGISTRY[method].options else 1)
        # a sliced light-grid bake under way (bake_step) is read as it is, not finished here
        light_ms = (self.bake_light() if self.needs_light(method)
                    and not self.light_baking() else 0.0)
        self.last_light_ms = light_ms
        if method == "raymarch":   # its opacity-gradient grid (last_gradient_grid_ms)
            self.bake_gradient_grid()
        if method in AREA_GRID_METHODS and self.resources.area_lights_on:
            self.bake_area_light_grid()   # their direct light (area_light_grid.py)
            self._area_grid.bind()
            extra = {**(extra or {}), **self._area_grid.uniforms()}
        return extra, light_ms

    def _area_light_lab_defines(self, defines: dict | None) -> dict | None:
        """AREA_LIGHT_NEAR_POINTS where the lab asks for another count and a light is on."""
        points = self._lab.area_light_near_points
        if points == LabOptions().area_light_near_points or not self.resources.area_lights_on:
            return defines
        return {**(defines or {}), "AREA_LIGHT_NEAR_POINTS": points}

    def bake_area_light_grid(self) -> float:
        """Bakes the area lights' optical-depth grid (the raymarcher's and probes-only's direct
        light from them) if stale; GPU ms (0 where it was current or no light is on)."""
        if not self.resources.area_lights_on:
            return 0.0
        if self._area_grid is None:
            self._area_grid = AreaLightGrid(self.ctx, area_light_grid_max_side(self._software))
        res = self.resources
        key = (res.volume_version, res.clip, area_light_grid_key(self.scene),
               tuple(sorted(res.medium_defines().items())))
        if key == self._area_grid.key:
            return 0.0
        self._area_grid.compile(res)   # (not in the bake's time)
        self.timer.start()
        baked = self._area_grid.update(res, key)
        self.timer.stop()
        if not baked:
            return 0.0
        self._area_grid.cost_ms = self.timer.elapsed_ms
        return self._area_grid.cost_ms

    @property
    def area_light_grid(self) -> AreaLightGrid | None:
        """The area lights' grid, None before one was needed (its size, memory, builds)."""
        return self._area_grid

    def _traced_pass(self, method: str, extra: dict | None) -> tuple[PathTracer, dict | None]:
        """The path-state pass of `method` (pt, the probe renderers, guided's level 1) and its
        uniforms."""
        defines = (self._read_defines(self.probe_grid.defines())
                   if REGISTRY[method].needs_probes else None)
        tracer = self.pass_for(method, defines)
        if self._settings.shadow_tracking == "residual":   # the shadow rays' control
            self._light.bind()
            extra = {**(extra or {}), **self._light.uniforms()}
        return tracer, extra

    def can_band(self, method: str) -> bool:
        """Whether add_groups can split a sample of `method` into bands."""
        return method in BANDED_METHODS and (method != "raymarch"
                                             or self.raymarch_stage == "compute")

    def add_groups(self, end: int) -> float:
        """Goes on with the sample in progress of the accumulation begun (sample acc.samples + 1;
        can_band methods only): its work groups (tiles of 8 x 8 pixels in raster order,
        sample_bands.tile_grid) from acc.groups_done to `end`. At the last group the sample is
        whole: acc.samples grows by one and groups_done is 0 again; until then the pixels done
        hold one sample more than the others, each pixel its own running mean. The pixels get
        exactly what whole samples give them: a pixel's random numbers follow its index and
        sample alone (app/rendering/budgets/sample_bands.py plans the bands). Returns the timer's ms of
        the groups (as in add_samples, a stale light grid's bake before them is in
        last_light_ms)."""
        method, acc = self.method, self._acc
        if not self.can_band(method):
            raise ValueError(f"{method}: a sample in bands of work groups is for "
                             f"{', '.join(BANDED_METHODS)} (the raymarcher as a compute pass)")
        total = math.prod(tile_grid(acc.width, acc.height))
        first, end = acc.groups_done, min(int(end), total)
        extra, _ = self._sample_inputs(method)
        if method == "raymarch":
            marcher = self.raymarcher()
            self.timer.start()
            marcher.run_groups(self.resources, self.camera, acc, (first, end), self.seed,
                               self.raymarch_step_voxels * 2 * self.resources.march_step,
                               {**extra, **self._light.uniforms()})
        else:
            tracer, extra = self._traced_pass(method, extra)
            self.timer.start()
            tracer.run_groups(self.resources, self.camera, acc, (first, end), acc.samples + 1,
                              self.seed, extra)
        self.timer.stop()
        if end >= total:
            acc.samples, acc.groups_done = acc.samples + 1, 0
        else:
            acc.groups_done = end
        return self.timer.elapsed_ms

    def image(self) -> np.ndarray:
        """The current accumulated linear RGB image (H, W, 3), row 0 at the top."""
        if self.method == "guided":
            return SumAccumulation(self._acc, self._acc0).read()
        return self._acc.read()

    @property
    def samples(self) -> int:
        return 0 if self._acc is None else self._acc.samples

    def render(self, method: str = "pt", spp: int = 64, seed: int = 0,
               width: int | None = None, height: int | None = None, samples_per_pass: int = 1,
               progress: Callable[[int, int], None] | None = None,
               bake_progress: Callable | None = None, denoise: bool = False,
               denoise_guides: str = "auto") -> RenderResult:
        """Renders the current scene from scratch with `spp` samples per pixel; with `denoise`,
        the image goes through the denoiser with `denoise_guides` (RenderResult.raw_image keeps
        the raw one; .denoised says what ran, or why not; "auto": denoise.choose_guides). A
        streamed mix
        of levels (LabOptions.mixed_levels under a cap) is first made the one this camera
        and image size deserve (restream, all of it)."""
        if self.resources.stream is not None:
            cam = self.scene.camera
            self.restream(replace(cam, width=width or cam.width, height=height or cam.height))
        if registered(method).composite:
            return self._render_composite(method, spp, seed, width, height, bake_progress,
                                          denoise, denoise_guides)
        acc = self.begin(method, width, height, seed)
        bake_ms = 0.0
        if self.needs_probes(method):
            bake_ms = self.bake(seed, progress=bake_progress)
        if self.needs_light(method):
            bake_ms += self.bake_light()
        if method == "raymarch":
            bake_ms += self.bake_gradient_grid()
        if method in AREA_GRID_METHODS:
            bake_ms += self.bake_area_light_grid()
        render_ms = 0.0
        chunk = max(samples_per_pass, 1)
        while acc.samples < spp:
            render_ms += self.add_samples(min(chunk, spp - acc.samples))
            if progress is not None:
                progress(acc.samples, spp)
        rgba = acc.read_rgba()
        stats = self.resources.read_stats()
        stats["min_samples"] = int(rgba[..., 3].min())
        image = rgba[..., :3].copy()
        if not denoise:
            return RenderResult(image, method, spp, render_ms, bake_ms, stats=stats)
        guides = choose_guides(denoise_guides, spp, self.needs_probes(method) and self.probes_shown())
        denoised, guides_ms = self.denoise(None, guides)
        return RenderResult(denoised.image, method, spp, render_ms, bake_ms, stats=stats,
                            raw_image=image, denoised=denoised, guides_ms=guides_ms)

    def _render_composite(self, method: str, spp: int, seed: int, width: int | None,
                          height: int | None, bake_progress: Callable | None, denoise: bool,
                          denoise_guides: str) -> RenderResult:
        """render() of a method made of others' images (the registry's `parts`): `refine`, as
        its view in the viewer ends (refine.render_refine). stats["shown"] names the part shown
        and stats["refine_estimate"] the estimated errors that chose it."""
        if method != "refine":
            raise NotImplementedError(f"render(): no still image of {method} yet")
        # the raymarcher's opacity-gradient grid too (surfaces on), so that the image's bake
        # time holds it (the raymarch inside render_refine then finds it current)
        bake_ms = (self.bake(seed, progress=bake_progress) + self.bake_light()
                   + self.bake_gradient_grid())
        self.resources.reset_stats()
        done = render_refine(self, spp, seed, width, height,
                             denoise_guides=denoise_guides if denoise else None)
        self.camera = camera_frame(self.scene.camera, width, height)   # the guides' camera
        stats = self.resources.read_stats()
        stats["shown"] = done.shown
        blend = done.blend
        stats["refine_estimate"] = {"guided": done.estimate.guided,
                                    "raymarch": done.estimate.raymarch,
                                    "samples": done.estimate.samples,
                                    "blend_weight": None if blend is None else blend.weight,
                                    "blend": None if blend is None else blend.blend,
                                    "guided_denoised": None if blend is None else blend.denoised}
        render_ms = done.raymarch_ms + done.guided_ms
        if not denoise:
            return RenderResult(done.image, method, spp, render_ms, bake_ms, stats=stats)
        if done.shown == "raymarch":   # nothing noisy shown: the filter has nothing to do
            return RenderResult(done.image, method, spp, render_ms, bake_ms, stats=stats)
        guides = choose_guides(denoise_guides, spp, self.probes_shown())
        denoised, guides_ms = self.denoise(done.image, guides, signed=REGISTRY[done.shown].signed)
        image, raw = denoised.image, done.image
        if blend is not None and blend.weight < 1.0 and denoised.denoised:
            image = blend_images(done.raymarch_image, denoised.image, blend.weight)
            raw = blend_images(done.raymarch_image, done.image, blend.weight)
        return RenderResult(image, method, spp, render_ms, bake_ms, stats=stats,
                            raw_image=raw, denoised=denoised, guides_ms=guides_ms)

    # ---- the denoiser's guides (denoise_guides.py) and the denoiser (denoise.py) ----------------
    def denoise_guides(self, guides: str = "albedo-normal", frames: int = GUIDE_FRAMES,
                       probe_frames: int = 16, camera=None
                       ) -> tuple[np.ndarray | None, np.ndarray | None, float]:
        """The noise-free guides of `camera` (a CameraFrame; None: the camera begun, else the
        scene's) as the denoiser
        takes them: (albedo, normal, GPU ms), each None where the set has none. "albedo" and
        "albedo-normal": where each ray first scatters in expectation (glsl/denoise_guide_images.comp,
        `frames` jittered rays a pixel); "probes": the raymarched image over the probes in hand
        (`probe_frames` frames; bake first), scaled into [0, 1], in the albedo's place. Kept
        while the camera, the medium and the probes stay: the same arrays again and 0 ms (the
        denoiser then keeps them on its device too)."""
        if guides not in GUIDE_SETS:
            raise ValueError(f"unknown denoise guides {guides!r} (known: {', '.join(GUIDE_SETS)})")
        if guides == "none":
            return None, None, 0.0
        camera = camera or self.camera or camera_frame(self.scene.camera)
        step = self.raymarch_step_voxels * 2 * self.resources.march_step
        key = (guides, tuple(camera.uniforms().items()), self.resources.bake_key(), step,
               frames, probe_frames,
               (self._baked_key, self.probe_grid.passes_done, self.probe_grid.next_probe)
               if guides == "probes" and self.probe_grid is not None else None)
        if self._guides_key == key:
            albedo, normal = self._guides_kept
            return albedo, normal, 0.0
        if guides == "probes":
            if not self.probes_shown():
                raise RuntimeError("the probes guide needs probes: bake first")
            acc = self._guide_acc
            if acc is None or (acc.width, acc.height) != (camera.width, camera.height):
                if acc is not None:
                    acc.release()
                acc = self._guide_acc = Accumulation(self.ctx, camera.width, camera.height)
            acc.reset()
            light_ms = self.bake_light() + self.bake_gradient_grid()
            extra = self.probe_uniforms()
            self.timer.start()
            self.raymarcher().run(self.resources, camera, acc, probe_frames, self.seed ^ 0x2545F491,
                                  step, {**extra, **self._light.uniforms()})
            self.timer.stop()
            albedo, normal, ms = radiance_as_albedo(acc.read()), None, light_ms + self.timer.elapsed_ms
        else:
            medium = self.resources.medium_defines()
            if self._guides is None or self._guides.defines != medium:
                if self._guides is not None:   # a crop, channels or surfaces changed the build
                    self._guides.release()
                self._guides = DenoiseGuides(self.ctx, medium)
            self.timer.start()
            self._guides.run(self.resources, camera, step, frames, self.seed)
            self.timer.stop()
            albedo, normal = self._guides.read()
            normal = normal if guides == "albedo-normal" else None
            ms = self.timer.elapsed_ms
        self._guides_key, self._guides_kept = key, (albedo, normal)
        return albedo, normal, ms

    def denoise(self, image: np.ndarray | None = None, guides: str = "albedo-normal",
                quality: str = "high", copy: bool = True,
                signed: bool | None = None) -> tuple[Denoised, float]:
        """The image of the camera begun (None: the accumulation in hand, read from GL straight
        into the denoiser's memory) through the denoiser with `guides`: (Denoised, the guides'
        GPU ms). Where the denoiser cannot run, Denoised holds the raw image and a note.
        `signed`: whether the image may dip below zero (None: the method begun's, app/methods.py).

        From the accumulation (every method but `guided`, whose image is the sum of two) the
        raw tile means are made and given back on the GPU (kept_means.denoise_on_gl: Denoised.ms
        has readback_ms, means_ms for the GL passes with a ctx.finish, upload_result_ms, and
        result_readback_ms, the corrected image read back for the host image returned, which a
        viewer does not pay); an image given here keeps the host path (keep_block_means)."""
        denoiser = shared_denoiser("auto", quality)
        if not denoiser.available:
            raw = self.image() if image is None else image
            return Denoised(sanitize(raw), None, denoiser.failure), 0.0
        albedo, normal, guides_ms = self.denoise_guides(guides)
        if image is None:
            acc = self._acc
            names = tuple(n for n, g in (("albedo", albedo), ("normal", normal)) if g is not None)
            staged = (denoiser.staging(acc.width, acc.height, names)
                      if self.method != "guided" else None)
            signed = REGISTRY[self.method].signed if signed is None else signed
            if staged is not None:
                if self._kept_means is None:
                    self._kept_means = KeptMeans(self.ctx)
                kept = self._kept_means
                return denoise_on_gl(kept, denoiser, acc.texture, staged, albedo, normal, signed,
                                     kept.result_texture(acc.width, acc.height),
                                     read_result=True), guides_ms
            image = self.image()
        signed = REGISTRY[self.method].signed if signed is None else signed
        return denoiser(image, albedo, normal, copy=copy, signed=signed), guides_ms

    def release(self) -> None:
        if self._guides is not None:
            self._guides.release()
        if self._kept_means is not None:
            self._kept_means.release()
        if self._guide_acc is not None:
            self._guide_acc.release()
        for p in (*self._passes.values(), *self._raymarchers.values()):
            p.release()
        for slot in (self._image_light, self._walk_light):
            if slot.light is not None:
                slot.light.release()
        if self._gradient_grid is not None:
            self._gradient_grid.release()
        if self._area_grid is not None:
            self._area_grid.release()
        if self._bake_medium is not None:
            self._bake_medium.release()
        if self.probe_grid is not None:
            self.probe_grid.release()
        for acc in (self._acc, self._acc0):
            if acc is not None:
                acc.release()
        self._region_pass.release()
        self.resources.release()
        self.timer.release()
