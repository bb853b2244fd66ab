"""The probes as the Renderer bakes them: what a bake depends on, the grid's plan (layout,
visible region, adaptive planes), the bake whole or in budgeted slices, and what a render reads
of it (its defines and uniforms). A mixin of Renderer (app/rendering/renderer.py)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from radiance_probes.twins.light_grid import light_grid_lookup
from radiance_probes.rendering.cache_keys import (adaptive_planes_key, probe_bake_key,
                                                  visible_region_key)
from radiance_probes.rendering.probes.bake_level import SPACING_LEVEL, BakeMedium, spacing_level
from radiance_probes.rendering.probes.layout import (fitted_grid, resolve_channels,
                                                     resolve_precision, resolve_sh_order,
                                                     sun_lobe_g)
from radiance_probes.rendering.probes.planes import (MAX_FIELD_SIDE, MAX_SPACING, adaptive_planes,
                                                     extinction_field, sun_field)
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.rendering.budgets.dispatch_budget import dispatch_target_ms


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


# A budgeted bake's first slice, before any slice of this probe layout was timed: small enough
# for a frame on llvmpipe (64 walks a probe), and the next slices follow the measured time.
FIRST_SLICE_PROBES = 64


def _slice_estimate(estimate: float | None, seen: float) -> float:
    """The GPU ms per unit (probe walked, light-grid layer) that predicts the next slice: up at once
    to a dearer slice, down halfway to a cheaper one. Units cost more where the medium is denser
    and a slice is a run of neighbours, so the mean alone overshot an 8 ms budget by up to 50% on
    bonsai (H100); rising at once keeps the next slice of such a run inside it."""
    if estimate is None or seen >= estimate:
        return seen
    return 0.5 * (estimate + seen)


class ProbeStage:
    """The Renderer's probes: plan, bake, slices and what the passes read of them."""

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

    def bake_started_for_scene(self) -> bool:
        """Whether the probes in hand (finished or not) are the current scene's bake."""
        return self.probe_grid is not None and self._baked_key == self.bake_key()

    def forget_probes(self) -> None:
        """The next bake() bakes the same probes again (the bench times repeated bakes); the
        light grid stays."""
        self._baked_key = None

    def probe_uniforms(self) -> dict:
        self.probe_grid.bind()
        return self.probe_grid.uniforms(self.scene.anisotropy, self.scene.probes.sh_window,
                                        self.resources)

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
        if budget_ms is None:
            self.timer.start()
            grid.bake_pass(resources, light=light)
            self.timer.stop()
            ms = self.timer.elapsed_ms
        else:
            left = max(budget_ms - light_ms, 0.0)
            key = (grid.grid, grid.samples)
            per_probe = self._probe_ms.get(key)
            probes = (min(FIRST_SLICE_PROBES, grid.count) if per_probe is None
                      else max(1, int(left / max(per_probe, 1e-9))))
            # the viewer's frame: a slice sized by the estimate is read at the frame's end
            span = self._span_start(per_probe is not None)
            grid.deferred = self.deferred
            try:
                ran = grid.bake_probes(resources, probes, light=light)
            finally:
                grid.deferred = None

            def learn(ms, ran=ran, per_probe=per_probe):
                if ran:   # (the first slice of a bake also runs the sun's pass)
                    self._probe_ms[key] = _slice_estimate(per_probe, ms / ran)
            ms = self._span_stop(span, (per_probe or 0.0) * ran, learn)
        self.last_slice_ms = light_ms + ms
        return light_ms + ms

    def probes_shown(self) -> bool:
        """Whether the probe textures hold anything to render from: a finished bake, or one
        with at least one chunk walked (then the image shows the probes as they are)."""
        g = self.probe_grid
        return g is not None and (g.passes_done > 0 or g.next_probe > 0 or g.warm_walks > 0)
