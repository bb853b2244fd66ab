"""One front for every render method: the CLI, the viewer and the benchmark all call this."""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import replace

import moderngl
import numpy as np

from radiance_probes.methods import ACCUMULATED, METHODS as REGISTRY, method as registered
from radiance_probes.twins.camera import camera_frame
from radiance_probes.gl.context import is_software
from radiance_probes.gl.shaders import set_uniforms
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.io.scene_file import Scene
from radiance_probes.io.volume import Volume
from radiance_probes.rendering.methods.accumulation import Accumulation, SumAccumulation
from radiance_probes.rendering.methods.guided_level0 import level0_groups_due
from radiance_probes.rendering.grids.area_light_grid import AREA_GRID_METHODS, AreaLightGrid
from radiance_probes.rendering.probes.bake_level import BakeMedium
from radiance_probes.rendering.limits import check_image_size
from radiance_probes.rendering.methods.pathtracer import PathTracer
from radiance_probes.rendering.grids.opacity_gradient_grid import OpacityGradientGrid
from radiance_probes.rendering.probes.visible_region import VisibleRegionPass
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.rendering.budgets.dispatch_budget import dispatch_target_ms
from radiance_probes.rendering.budgets.sample_bands import tile_grid
from radiance_probes.rendering.denoise.guides import DenoiseGuides
from radiance_probes.rendering.denoise.kept_means import KeptMeans
from radiance_probes.rendering.methods.raymarch import Raymarcher, min_step_voxels
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.rendering.probes.stage import ProbeStage
from radiance_probes.rendering.grids.stage import GridStage, _LightSlot
from radiance_probes.rendering.still_images import StillImages
from radiance_probes.rendering.settings import (MAX_GATHER_EVENT, RAYMARCH_STAGES, RenderSettings,
                                                check_gather_event)  # noqa: F401 (re-exported)

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


class Renderer(ProbeStage, GridStage, StillImages):
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
        # the viewer's frame: spans read at its end (gl/timer.DeferredSpans; RenderSession.step),
        # each timed block returning its estimate meanwhile; None: every block read as it ends
        self.deferred = None
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


    def prepare(self, method: str, width: int, height: int, slots: tuple[int, ...] = (0,)) -> None:
        """Compiles the programs a sample of `method` at width x height will run and gives its
        path states (one set per slot: refine's halves) their memory, so that its first sample
        pays for neither. The viewer calls it in the frame its bake begins, where the probes'
        layout is first known (issue 56: on the H200 `guided`'s first frame in a load spent 40 ms
        on compiles from the driver's shader cache and 17 ms in its first dispatch, and 6 s on
        compiles with the cache empty, lab/experiments/frame_host_profile.py). Nothing where a
        method that reads probes has no probe grid yet."""
        if self.needs_probes(method) and self.probe_grid is None:
            return
        if method == "raymarch":
            self.raymarcher()
            return
        if method == "guided":
            self.raymarcher(guided_level0=True)
        defines = (self._read_defines(self.probe_grid.defines())
                   if REGISTRY[method].needs_probes else None)
        kept = self.pass_slot
        try:
            for slot in slots:
                self.pass_slot = slot
                self.pass_for(method, defines).allocate(width, height)
        finally:
            self.pass_slot = kept

    @property
    def pathtracer(self) -> PathTracer:
        return self.pass_for("pt")


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


    def needs_light(self, method: str) -> bool:
        """Whether rendering `method` reads the light grid: the raymarcher and `guided` always,
        every path-traced method where the shadow rays are residual-tracked against it."""
        return (REGISTRY[method].needs_light_grid
                or self._settings.shadow_tracking == "residual")

    def add_samples(self, n: int = 1, level0_bands: bool = False) -> float:
        """Adds n samples per pixel to the accumulation begun by begin(); returns GPU ms.
        Probe methods use the probes as they are now (bake them first for a final image).
        `level0_bands` (guided): level 0's next frame in bands spread over level 1's samples
        (app/rendering/methods/guided_level0.py: the viewer's frames), not whole when due."""
        method, acc = self.method, self._acc
        extra, _ = self._sample_inputs(method)
        level0_ms = 0.0
        if method == "guided":
            level0_ms = self._advance_level0(acc.samples + n, extra, level0_bands)
            extra = {**extra, **self._light.uniforms()}
        if method == "raymarch":
            marcher = self.raymarcher()
            step = self.raymarch_step_voxels * 2 * self.resources.march_step
            uniforms = {**extra, **self._light.uniforms()}
            # (ms per sample learned from calls of whole samples alone, which only are deferred)
            key, count, whole = ("raymarch", acc.width, acc.height), n, not acc.groups_done
            per_sample = self._sample_ms.get(key)
            span = self._span_start(per_sample is not None and whole)
            if acc.groups_done:   # a frame part marched in bands (add_groups): the rest first
                marcher.run_groups(self.resources, self.camera, acc,
                                   (acc.groups_done, math.prod(tile_grid(acc.width, acc.height))),
                                 self.seed, step, uniforms)
                acc.samples, acc.groups_done, n = acc.samples + 1, 0, n - 1
            if n > 0:
                marcher.run(self.resources, self.camera, acc, n, self.seed, step, uniforms)

            def learn(ms):
                if whole and count > 0:
                    self._sample_ms[key] = ms / count
            return self._span_stop(span, (per_sample or 0.0) * count, learn)
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
            span = self._span_start(per_sample is not None)
            tracer.run(self.resources, self.camera, acc, acc.samples + k, self.seed, extra, bands)
            total += self._span_stop(span, (per_sample or 0.0) * k,
                                     lambda ms, k=k: self._sample_ms.__setitem__(key, ms / k))
            n -= k
        return total + level0_ms

    def _span_start(self, estimable: bool):
        """Begins a timed block: a deferred span where the viewer's frame defers its timers
        (self.deferred) and the block's time can be estimated, else the renderer's own timer."""
        if self.deferred is not None and self.deferred.tag is not None and estimable:
            return self.deferred.start()
        self.timer.start()
        return None

    def _span_stop(self, span, estimate_ms: float, on_done=None) -> float:
        """Ends the block begun by _span_start: its estimate (a deferred span, read at the
        frame's end, when on_done learns its time), or its time read now (one wait)."""
        if span is not None:
            return self.deferred.stop(span, estimate_ms, on_done)
        self.timer.stop()
        ms = self.timer.elapsed_ms
        if on_done is not None:
            on_done(ms)
        return ms

    def _advance_level0(self, samples: int, extra: dict, bands: bool) -> float:
        """guided's level 0 brought to what level 1 at `samples` samples needs
        (guided_level0.level0_groups_due): whole frames in one run, a frame in progress in work
        groups. Returns the timer's ms."""
        acc0 = self._acc0
        total = math.prod(tile_grid(acc0.width, acc0.height))
        due = level0_groups_due(samples, self._settings.guided_level0_ratio, total, bands)
        have = acc0.samples * total + acc0.groups_done
        if due <= have:
            return 0.0
        marcher = self.raymarcher(guided_level0=True)
        step = self.raymarch_step_voxels * 2 * self.resources.march_step
        uniforms = {**extra, **self._light.uniforms(),
                    "guided_level0_budget": GUIDED_LEVEL0_BUDGET}
        seed = self.seed ^ 0x5bd1e995
        key = ("level0", acc0.width, acc0.height)
        per_group = self._sample_ms.get(key)
        groups = due - have
        span = self._span_start(per_group is not None)
        while have < due:
            first = acc0.groups_done
            if first == 0 and due - have >= total:   # whole frames
                frames = (due - have) // total
                marcher.run(self.resources, self.camera, acc0, frames, seed, step, uniforms)
                have += frames * total
                continue
            end = min(total, first + (due - have))
            marcher.run_groups(self.resources, self.camera, acc0, (first, end), seed, step,
                               uniforms)
            have += end - first
            acc0.groups_marched(end, total)
        return self._span_stop(span, (per_group or 0.0) * groups,
                               lambda ms: self._sample_ms.__setitem__(key, ms / groups))

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
        acc.groups_marched(end, total)
        return self.timer.elapsed_ms

    def image(self) -> np.ndarray:
        """The current accumulated linear RGB image (H, W, 3), row 0 at the top."""
        if self.method == "guided":
            return SumAccumulation(self._acc, self._acc0).read()
        return self._acc.read()

    @property
    def samples(self) -> int:
        return 0 if self._acc is None else self._acc.samples


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
