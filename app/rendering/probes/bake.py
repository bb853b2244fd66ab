"""The radiance-probe grid: its RGBA 3D textures (seven up to SH order 2, 13 at order 3, 19 at 4;
lib/probe_packing.glsl) and the progressive bake that fills them.

A bake is a sequence of passes; each pass sends `directions` walks from every probe (a rotated
spherical Fibonacci set, lib/probes.glsl), projects them onto SH (order 2, or the grid's order
where that is higher) and folds them into each probe's running mean, then publishes the textures,
so a viewer can show probes that improve while it stays interactive. Probes are processed in chunks so the walks' buffers stay within a fixed
size whatever the grid size.

Nothing goes through the host while a pass runs on a GPU without a loop limit: one walk dispatch
and one projection dispatch per chunk (a few chunks a pass), no buffer cleared, uploaded or read
back. Where the driver limits loops (llvmpipe), walks are resumable paths (lib/integrator.glsl)
that keep their state in a buffer and the host re-dispatches a chunk until a 4-byte counter says
every walk has ended; the first dispatch of a chunk starts its walks afresh, so nothing is cleared.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import moderngl
import numpy as np

from radiance_probes.gl.context import UNBOUNDED_LOOP_BUDGET, loop_budget, loop_budget_unbounded
from radiance_probes.gl.memory import touch
from radiance_probes.gl.profiler import GpuProfile
from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.rendering.probes.layout import colour_textures, texture_ids
from radiance_probes.twins.probe_warp import WARP_ROWS, warp_table
from radiance_probes.rendering.resources import SceneResources

PROBE_UNIT = 2                # probe textures 0..6 bind to texture units 2..8
PROBE_UNIT_HIGH = 16          # and textures 7..18 (SH orders 3, 4) to units 16..27
PROBE_WARP_UNIT = 14          # an adaptive layout's warp and planes (lib/probe_warp.glsl)
PROBE_IMAGE_LIMIT = 8         # textures one dispatch publishes (lib/probe_publish.glsl)
DIRECTIONS_PER_PASS = 64     # = probe_project.comp's local size: one invocation per walk of a pass
WALKS_PER_CHUNK = 1 << 20     # resumable walks: 80 MiB of walk state and 16 MiB of results at most
WALKS_PER_CHUNK_UNBOUNDED = 1 << 22   # walks that end in one dispatch: 64 MiB of results at most
# A bake's first timed chunk: its walks' cost is not known yet. 2^18 walks (about one wave of an
# H100's threads) took 135 ms on the battery's backlit shells (bench/h100-bias: albedo 0.99, up to
# 256 events a walk); a sixteenth of that stays under the target there.
FIRST_CHUNK_WALKS = 1 << 14
PATH_STATE_BYTES = 80       # PathState of glsl/lib/integrator.glsl, std430
PATH_STATE_BYTES_ENVIRONMENT_MAP = 112   # the same with ENVIRONMENT_MAP
PATH_STATE_BYTES_SUN_CORRECTION = 32     # and the walks' sun correction (WALK_SUN_GRID)
PATH_STATE_BYTES_AREA_LIGHTS = 32        # and an area light's sample (AREA_LIGHTS)
WALK_SUN_MODES = ("ray", "grid")
WALK_PROFILE_SLOTS = 1024   # rows of 8 counters in glsl/lib/walk_profile.glsl
WALK_PROFILE_FIELDS = ("walks", "events", "flight_steps", "shadow_steps", "cell_steps",
                       "dispatch_walks")
WALK_PROFILE_MAXIMA = ("longest_walk_events", "longest_walk_steps")   # the rows' last two
WARM_WALKS = 64   # a warm restart's old probes count as this many walks until the last pass
SH_WINDOW_IDS = {"none": 0, "hann": 1, "lanczos": 2}


def radiance_scale(scene, environment=None) -> float:
    """What the probe textures' coefficients are stored relative to (lib/probes.glsl
    probe_radiance_scale): the scene's brightest light, the sun's irradiance or the environment's
    largest radiance (a map's brightest texel times its scale). A probe's radiance is that times
    a factor of the medium (below 1 for a thin medium, up to about 1 / (1 - albedo) for a thick
    one), so 16-bit texels (largest 65504, 11 significant bits down to 6e-5) hold it whatever the
    lights' units: unscaled, a sun and environment of 1e6 overflow them and ones of 1e-7 fall to
    their subnormals (tests/test_hard_cases.py). 1 when the scene has no light."""
    levels = [max(scene.light.irradiance)]
    for light in scene.area_lights:   # an area light: its radiance times its share of the sky
        if light.enabled:
            levels.append(float(max(light.colour)) * float(light.strength)
                          * _area_light_share(light))
    if environment is not None and scene.environment_map is not None:
        levels.append(float(np.max(environment.image)) * float(scene.environment_map.scale))
    else:
        levels.append(max(scene.environment))
    level = max(levels)
    return float(level) if math.isfinite(level) and level > 0.0 else 1.0


def _area_light_share(light) -> float:
    """The solid angle an area light fills seen from the box's centre, over pi: its irradiance
    there per unit of its radiance (radiance_scale's level for it)."""
    d = max(math.sqrt(sum(float(c) ** 2 for c in light.position)), 1e-6)
    if light.shape == "sphere":
        sin2 = min((float(light.size) / d) ** 2, 1.0)
        return sin2
    w, h = (float(v) for v in light.size)
    return min(w * h / (math.pi * d * d), 1.0)


def probe_unit(texture_number: int) -> int:
    """The texture unit probe texture `texture_number` binds to (PROBE_UNIT, PROBE_UNIT_HIGH)."""
    return PROBE_UNIT + texture_number if texture_number < 7 else PROBE_UNIT_HIGH + texture_number - 7


def accum_bytes(sh_order: int) -> int:
    """Bytes of one ProbeAccum (glsl/lib/probe_accum.glsl): the colour packing's channels and four
    floats (128 up to order 2)."""
    return 16 * colour_textures(sh_order) + 16


def band_factors(g: float, window: str, sh_order: int = 2) -> tuple[float, ...]:
    """Per-band multipliers g^l * window_l, l = 0 .. max(sh_order, 2) (NumPy twin of
    sh_band_factors in lib/sh.glsl, whose SH_ORDER is at least 2)."""
    from radiance_probes.twins.sh import sh_band_factors
    return tuple(float(v) for v in sh_band_factors(g, SH_WINDOW_IDS[window], max(sh_order, 2)))


@dataclass
class BakeProgress:
    passes_done: int
    passes_total: int
    samples_per_probe: int
    relative_change: float   # rms change of probe radiance in the last pass / rms radiance
    standard_error: float    # estimated relative standard error of the probe radiance mean


# How shadow rays towards the sun are tracked (lib/sun_shadow.glsl; RenderSettings.shadow_tracking).
SHADOW_TRACKINGS = ("ratio", "residual")


class ProbeGrid:
    def __init__(self, ctx: moderngl.Context, grid: tuple[int, int, int], samples: int,
                 precision: str = "rgba32f", sh_order: int = 2,
                 box: tuple | None = None, grey: bool = False, resumable: bool | None = None,
                 sun: str = "ray", adaptive: float = 0.0, environment_map: bool = False,
                 planes: tuple | None = None, sun_lobe: float = 0.0,
                 sun_correction: float = 0.0, medium: dict | None = None,
                 shadow_tracking: str = "ratio", area_lights: bool = False):
        """`box`: world (low, high) corners the probes cover (default: the volume box, given at
        bake time); `sh_order` 0 to 4 decides which textures exist (lib/probe_packing.glsl).
        `resumable`: walks that suspend and resume across dispatches (default: where the driver limits loops;
        False on such a driver only for walks short enough to fit its limit, as tests do).
        `sun`: at the walks' scattering events, "ray" traces a ratio-tracked shadow ray towards the
        sun (unbiased); "grid" reads the baked light grid (bake_pass(light=...)), a bias of its
        resolution. `adaptive` > 0: walks per probe follow the noise of each probe's neighbours
        (lib/probe_noise.glsl, unbiased): when the first pass ends, each probe gets the walks
        that give its neighbours' mean variance `adaptive` times the standard error the
        asked-for walks give a probe of average noise; 0 (default): every probe takes them all.
        `environment_map`: the walks' build for a scene whose environment is a map (they sample it
        at each scattering event; lib/integrator.glsl). `planes`: an adaptive layout's probe
        planes per axis, world fractions of the box (app/rendering/probes/planes.py); None: evenly
        spaced, and the shaders are built without the warp (PROBE_WARP 0). `sun_lobe` > 0: each
        probe also holds a lobe about the sun's direction of that Henyey-Greenstein g beside its
        bands (lib/sun_lobe.glsl; SH order 3 only); 0: none. `medium`: the scene's medium
        defines (SceneResources.medium_defines: its channels), which every pass is built with.
        `shadow_tracking`: how the walks' shadow rays towards the sun (sun "ray") and the grid
        sun's correction rays (sun "grid") are tracked: "ratio", or "residual" with the light
        grid as control (lib/sun_shadow.glsl; bake_pass(light=...) then needs the grid either
        way)."""
        if shadow_tracking not in SHADOW_TRACKINGS:
            raise ValueError(f"shadow tracking {shadow_tracking!r}: expected one of "
                             f"{', '.join(SHADOW_TRACKINGS)}")
        self.shadow_tracking = shadow_tracking
        self.environment_map = bool(environment_map)
        self.area_lights = bool(area_lights)   # the walks meet and sample area lights
        self.medium = dict(medium or {})
        if not (math.isfinite(sun_lobe) and 0.0 <= sun_lobe < 1.0):
            raise ValueError(f"sun lobe g {sun_lobe!r}: expected a number in [0, 1)")
        if sun_lobe > 0.0 and int(sh_order) != 3:
            raise ValueError("a sun lobe needs SH order 3 (the packing's spare channels)")
        self.sun_lobe = float(sun_lobe)
        if not (math.isfinite(adaptive) and adaptive >= 0.0):
            raise ValueError(f"adaptive walks factor {adaptive!r}: expected a finite number >= 0")
        self.adaptive = float(adaptive)
        if sun not in WALK_SUN_MODES:
            raise ValueError(f"walk sun mode {sun!r}: expected one of {', '.join(WALK_SUN_MODES)}")
        self.sun = sun
        # sun "grid": the least rate at which a shadow ray corrects the grid's sun (lib/integrator.glsl)
        self.sun_correction = float(sun_correction)
        self.ctx = ctx
        self.grid = tuple(int(v) for v in grid)
        self.samples = int(samples)
        self.precision = precision
        self.sh_order = int(sh_order)
        self.grey = bool(grey)
        self.radiance_scale = 1.0   # what the textures are stored relative to (radiance_scale)
        self.texture_ids = texture_ids(self.sh_order, self.grey)
        self.box = None if box is None else (tuple(map(float, box[0])), tuple(map(float, box[1])))
        self.count = self.grid[0] * self.grid[1] * self.grid[2]
        self.planes = None if planes is None else tuple(tuple(map(float, p)) for p in planes)
        self.warp_texture = None
        if self.planes is not None:
            if tuple(len(p) for p in self.planes) != self.grid:
                raise ValueError(f"probe planes per axis {tuple(len(p) for p in self.planes)} "
                                 f"do not match the grid {self.grid}")
            table = warp_table(self.planes)
            self.warp_texture = ctx.texture((table.shape[1], WARP_ROWS), 1, table.tobytes(),
                                            dtype="f4")
            self.warp_texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.warp_texture.repeat_x = self.warp_texture.repeat_y = False
        self.directions = min(self.samples, DIRECTIONS_PER_PASS)
        self.passes_total = math.ceil(self.samples / self.directions)
        dtype = "f4" if precision == "rgba32f" else "f2"
        self.textures = []
        for _ in self.texture_ids:
            tex = ctx.texture3d(self.grid, 4, dtype=dtype)
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = tex.repeat_z = False
            self.textures.append(tex)
        self.loop_budget, self.loop_reserve = loop_budget(ctx)
        self.resumable = (not loop_budget_unbounded(self.loop_budget) if resumable is None
                          else bool(resumable))
        if not self.resumable:
            self.loop_budget, self.loop_reserve = UNBOUNDED_LOOP_BUDGET, 0
        per_chunk = WALKS_PER_CHUNK if self.resumable else WALKS_PER_CHUNK_UNBOUNDED
        self.chunk_probes = max(1, min(self.count, per_chunk // self.directions))
        walks = self.chunk_probes * self.directions
        state_bytes = PATH_STATE_BYTES_ENVIRONMENT_MAP if self.environment_map else PATH_STATE_BYTES
        if sun == "grid":   # the sun correction's reservoir (lib/integrator.glsl)
            state_bytes += PATH_STATE_BYTES_SUN_CORRECTION
        if self.area_lights:   # the light sample (lib/integrator.glsl AREA_LIGHTS)
            state_bytes += PATH_STATE_BYTES_AREA_LIGHTS
        self.walk_states = ctx.buffer(reserve=walks * state_bytes) if self.resumable else None
        # sun "grid": two more entries a walk, its sun correction (glsl/probe_sun_correction.comp)
        self.walk_radiance = ctx.buffer(reserve=walks * 16 * (3 if sun == "grid" else 1))
        self.accum_floats = accum_bytes(self.sh_order) // 4
        self.accums = ctx.buffer(reserve=self.count * accum_bytes(self.sh_order))
        self.progress = ctx.buffer(reserve=4)
        self._progress_program = None   # glsl/probe_progress.comp, built on first use
        self._partial_sums = None
        # lib/probe_noise.glsl: the variance sum, the probe count, then each probe's passes
        self.noise = ctx.buffer(reserve=8 + 4 * self.count)
        # their memory now, in the frame the bake begins, not in its first walks' dispatch
        touch(ctx, self.walk_states, self.walk_radiance, self.accums, self.noise)
        defines = {"PROBE_IMAGE_FORMAT": precision, "PROBE_IMAGE_LIMIT": PROBE_IMAGE_LIMIT,
                   **self.defines()}
        tracking = {"SHADOW_TRACKING_RESIDUAL": 1} if shadow_tracking == "residual" else {}
        self._walk_defines = {"RESUMABLE_WALKS": int(self.resumable), **self.defines(),
                              **tracking}
        if sun == "grid":
            self._walk_defines["WALK_SUN_GRID"] = 1
            if self.sun_correction > 0.0:   # the correction's reservoir (lib/integrator.glsl)
                self._walk_defines["WALK_SUN_CORRECTION"] = 1
        if self.environment_map:
            self._walk_defines["ENVIRONMENT_MAP"] = 1
        if self.area_lights:
            self._walk_defines["AREA_LIGHTS"] = 1
        self.walk_program = compute_program(ctx, "probe_walks.comp", self._walk_defines)
        # sun "grid": each walk's correction of the grid's sun, traced after the walks
        self.correction_program = (compute_program(ctx, "probe_sun_correction.comp",
                                                   {**self.medium, **tracking} or None)
                                   if sun == "grid" else None)
        self._walk_profile_program = None   # the WALK_PROFILE build, compiled when first asked for
        self.project_program = compute_program(ctx, "probe_project.comp", defines)
        # slots past the first PROBE_IMAGE_LIMIT: published by their own dispatches
        self.publish_programs = [
            (first, compute_program(ctx, "probe_publish.comp",
                                    {**defines, "PROBE_PUBLISH_FIRST": first}))
            for first in range(PROBE_IMAGE_LIMIT, len(self.texture_ids), PROBE_IMAGE_LIMIT)]
        # the probes' own sun: from the light grid when the walks read it (probe_sun.comp)
        self.sun_program = compute_program(
            ctx, "probe_sun.comp",
            {**self.defines(), **({"PROBE_SUN_GRID": 1} if sun == "grid" else {})})
        self.noise_program = (compute_program(ctx, "probe_noise.comp", self.defines())
                              if self.adaptive else None)
        self.budget_program = (compute_program(ctx, "probe_walk_budget.comp", self.defines())
                               if self.adaptive else None)
        # Walk dispatches sized by time (_chunk): the target (None: fixed chunks) and the walks and
        # GPU ms of the last timed chunk, kept across restarts of this grid.
        self.dispatch_target_ms: float | None = None
        self._chunk_walks: int = FIRST_CHUNK_WALKS
        self._chunk_ms: float | None = None
        self._chunk_timer = GpuTimer(ctx)
        # the viewer's frame (gl/timer.DeferredSpans, set by ProbeStage.bake_step): a timed
        # chunk is read at the frame's end, the next frame's chunks sized by it
        self.deferred = None
        self.dispatches = 0
        self.passes_done = 0
        self.next_probe = 0        # the next probe to walk in the current pass
        self.seed = 0
        self.prior = None          # a warm restart's copy of the probes' running means
        self.warm_walks = 0.0

    @property
    def gpu_bytes(self) -> int:
        """GPU memory of the probe textures (what rendering reads)."""
        texel = 16 if self.precision == "rgba32f" else 8
        return len(self.textures) * self.count * texel

    @property
    def bake_bytes(self) -> int:
        """GPU memory the bake uses besides the textures (walk state, running means, a warm
        restart's copy of the old ones)."""
        states = self.walk_states.size if self.walk_states is not None else 0
        prior = self.prior.size if self.prior is not None else 0   # after a warm restart
        return states + prior + self.walk_radiance.size + self.accums.size

    @property
    def done(self) -> bool:
        return self.passes_done >= self.passes_total

    def restart(self, seed: int = 0, warm: bool = False) -> None:
        """Starts the bake over. `warm`: until the last pass, the textures show each probe's new
        running mean blended with what the probes held before (weighted as WARM_WALKS walks, so
        the old probes fade as walks come in); the running means and the final probes are the
        cold bake's, exactly. Cold: the texels of probes not yet walked keep their old values
        until the first pass reaches them."""
        had_walks = self.passes_done > 0 or self.next_probe > 0
        self.passes_done = 0
        self.next_probe = 0
        self.seed = seed
        if not (warm and not had_walks and self.warm_walks > 0):   # else: the prior still holds
            self.warm_walks = 0.0
        if warm and had_walks:
            if self.prior is None:
                self.prior = self.ctx.buffer(reserve=self.accums.size)
            self.ctx.copy_buffer(self.prior, self.accums)
            self.warm_walks = float(WARM_WALKS)

    def _pass_directions(self) -> int:
        remaining = self.samples - self.passes_done * self.directions
        return min(self.directions, remaining)

    def walk_counters(self) -> moderngl.Buffer:
        """A zeroed buffer for the profiling build's walk counters (bake_pass(counters=...)); zeroed
        from the host, once per profiled bake, never in a normal one."""
        return self.ctx.buffer(bytes(WALK_PROFILE_SLOTS * 8 * 4))

    @staticmethod
    def read_walk_counters(buffer: moderngl.Buffer) -> dict[str, int]:
        rows = np.frombuffer(buffer.read(), np.uint32).reshape(WALK_PROFILE_SLOTS, 8)
        sums = rows.astype(np.uint64).sum(0)
        counts = {name: int(v) for name, v in zip(WALK_PROFILE_FIELDS, sums)}
        counts.update({name: int(v) for name, v in zip(WALK_PROFILE_MAXIMA, rows[:, 6:].max(0))})
        return counts

    def _walk_program(self, counters: bool):
        if not counters:
            return self.walk_program
        if self._walk_profile_program is None:
            self._walk_profile_program = compute_program(
                self.ctx, "probe_walks.comp", {**self._walk_defines, "WALK_PROFILE": 1})
        return self._walk_profile_program

    @property
    def probes_left(self) -> int:
        """Probe walks (one probe's walks of one pass each) still to run before the bake is
        done: a budgeted bake's unit."""
        if self.done:
            return 0
        return (self.passes_total - self.passes_done) * self.count - self.next_probe

    @property
    def needs_light(self) -> bool:
        """Whether the walks or their correction read the light grid (bake_pass(light=...))."""
        return self.sun == "grid" or self.shadow_tracking == "residual"

    def bake_pass(self, resources: SceneResources, profile: GpuProfile | None = None,
                  counters: moderngl.Buffer | None = None, light=None) -> None:
        """Runs one pass over all probes (the rest of it, when bake_probes stopped within one).
        `profile` times its sections on the GPU ("sun", "walks", "project"); `counters` (from
        walk_counters()) runs the walks' profiling build, which adds what the walks did to it;
        `light` (a baked LightTransmittance) is what sun="grid" reads."""
        if not self.done:
            self.bake_probes(resources, self.count - self.next_probe, profile=profile,
                             counters=counters, light=light)

    def bake_probes(self, resources: SceneResources, max_probes: int,
                    profile: GpuProfile | None = None, counters: moderngl.Buffer | None = None,
                    light=None) -> int:
        """Walks and projects up to `max_probes` probes (dispatches of at most `chunk_probes`
        each, publishing their texels), continuing the current pass where the last call stopped
        and going on into the next ones: the budgeted bake's slice (Renderer.bake_step). Every
        walk's random numbers follow its probe, pass and slot, so any slicing gives the probes
        of whole passes. Returns the probes walked."""
        ran = 0
        while ran < max_probes and not self.done:
            k = min(max_probes - ran, self.count - self.next_probe)
            self._run_probes(resources, k, profile, counters, light)
            ran += k
        return ran

    def _run_probes(self, resources, k, profile, counters, light) -> None:
        if self.needs_light and light is None:
            raise ValueError("a bake with sun='grid' or residual shadow tracking needs the baked "
                             "light grid (light=...)")
        section = profile.section if profile is not None else _no_section
        directions = self._pass_directions()
        scene = resources.scene
        uniforms = resources.uniforms()
        uniforms["max_bounces"] = max(scene.max_bounces - 1, 0)  # the render's first event is one
        last_pass = self.passes_done + 1 >= self.passes_total
        uniforms.update({"probe_grid": self.grid, "directions": directions,
                         "pass_index": self.passes_done, "seed": self.seed & 0xFFFFFFFF,
                         "loop_budget": self.loop_budget, "loop_reserve": self.loop_reserve,
                         "march_step": resources.march_step,
                         "adaptive_walks": int(self.adaptive > 0),
                         "walk_sun_correction": self.sun_correction,
                         "warm_walks": 0.0 if last_pass else self.warm_walks})
        uniforms.update(self.box_uniforms(resources))
        if self.passes_done == 0 and self.next_probe == 0:   # a bake starts: the scene's lights
            self.radiance_scale = radiance_scale(scene, resources.environment)
        uniforms["probe_radiance_scale"] = self.radiance_scale
        uniforms["sun_lobe_g"] = self.sun_lobe
        uniforms["sun_lobe_phase_g"] = float(scene.anisotropy)   # what the lobe's fit weights by
        if self.warp_texture is not None:
            self.warp_texture.use(PROBE_WARP_UNIT)
            uniforms["probe_warp"] = PROBE_WARP_UNIT
        walk_program = self._walk_program(counters is not None)
        resources.bind()
        if self.needs_light:
            light.bind()
            uniforms.update(light.uniforms())
        set_uniforms(walk_program, uniforms)
        if self.correction_program is not None:
            set_uniforms(self.correction_program, uniforms)
        set_uniforms(self.project_program, uniforms)
        for _, program in self.publish_programs:
            set_uniforms(program, uniforms)
        if self.walk_states is not None:
            self.walk_states.bind_to_storage_buffer(1)
        self.progress.bind_to_storage_buffer(2)
        self.walk_radiance.bind_to_storage_buffer(3)
        self.accums.bind_to_storage_buffer(4)
        self.noise.bind_to_storage_buffer(6)
        (self.prior if self.prior is not None else self.accums).bind_to_storage_buffer(0)
        if counters is not None:
            counters.bind_to_storage_buffer(5)
        self._bind_images(0)
        if self.passes_done == 0 and self.next_probe == 0:
            self.noise.write(struct.pack("2f", -1.0, 0.0))   # no walk budgets until pass 0 ends
            with section("sun"):
                set_uniforms(self.sun_program, {**uniforms, "probe_count": self.count})
                self.sun_program.run((self.count + 63) // 64)
                self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
                self.dispatches += 1
        end = self.next_probe + k
        first = self.next_probe
        while first < end:
            n, timed = self._chunk(end - first, directions)
            set_uniforms(walk_program, {"first_probe": first, "chunk_probes": n})
            set_uniforms(self.project_program, {"first_probe": first})
            groups = (n * directions + 63) // 64
            with section("walks"):
                span = None
                if (timed and self.deferred is not None and self.deferred.tag is not None
                        and self._chunk_ms is not None):
                    span = self.deferred.start()
                elif timed:
                    self._chunk_timer.start()
                self._run_walks(walk_program, groups)
                if self.correction_program is not None and self.sun_correction > 0.0:
                    set_uniforms(self.correction_program, {"first_probe": first,
                                                           "walk_count": n * directions})
                    self.correction_program.run(groups)
                    self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
                    self.dispatches += 1
                if span is not None:
                    self.deferred.stop(span, 0.0, lambda ms, w=n * directions:
                                       self._learn_chunk(w, ms), tag="bake chunk")
                elif timed:
                    self._chunk_timer.stop()
                    self._learn_chunk(n * directions, self._chunk_timer.elapsed_ms)
            with section("project"):
                self.project_program.run(n)
                self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT
                                        | moderngl.TEXTURE_FETCH_BARRIER_BIT
                                        | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
                self.dispatches += 1
                for first_slot, program in self.publish_programs:
                    self._bind_images(first_slot)
                    set_uniforms(program, {"first_probe": first, "chunk_probes": n})
                    program.run((n + 63) // 64)
                    self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT
                                            | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
                    self.dispatches += 1
                if self.publish_programs:
                    self._bind_images(0)
            first += n
        self.next_probe = end
        if self.next_probe < self.count:
            return
        if self.passes_done == 0 and self.adaptive > 0:
            with section("project"):
                set_uniforms(self.noise_program, {"probe_count": self.count})
                self.noise_program.run(1)
                self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
                set_uniforms(self.budget_program, {
                    "probe_grid": self.grid, "adaptive_factor": self.adaptive,
                    "walks_asked": float(self.samples), "directions": self.directions,
                    "passes_total": self.passes_total})
                self.budget_program.run((self.count + 63) // 64)
                self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
                self.dispatches += 2
        self.next_probe = 0
        self.passes_done += 1

    def _learn_chunk(self, walks: int, ms: float) -> None:
        self._chunk_walks, self._chunk_ms = walks, ms

    def _chunk(self, left: int, directions: int) -> tuple[int, bool]:
        """Probes the next walk dispatch takes (of `left` still to walk in this call) and whether
        to time it. Where walks end in one dispatch and a dispatch target is set
        (dispatch_target_ms, by the Renderer), chunks follow the last timed chunk's GPU time
        towards the target: timed (one wait for the GPU) whenever the rest of the pass does not
        fit in one, or no chunk was timed yet (the first holds FIRST_CHUNK_WALKS); a pass that fits
        is not waited for. Else the fixed chunk_probes."""
        if self.resumable or self.dispatch_target_ms is None or math.isinf(self.dispatch_target_ms):
            return min(self.chunk_probes, left), False
        if self._chunk_ms is None:
            walks = FIRST_CHUNK_WALKS
        else:
            # A dispatch's time is not proportional to its walks: a small one waits for its
            # longest walk whatever its size (measured on the battery's shells, sizing each chunk
            # by the last one's time per walk kept chunks small and bakes 2.7x slower). So the
            # next chunk scales the last one by target / time, by at most 4x up and 2x down.
            scale = self.dispatch_target_ms / max(self._chunk_ms, 1e-6)
            walks = int(self._chunk_walks * min(max(scale, 0.5), 4.0))
        n = max(1, min(self.chunk_probes, left, walks // directions))
        return n, self._chunk_ms is None or n < left

    def _bind_images(self, first_slot: int) -> None:
        """Slots first_slot .. first_slot + 7 to image units 0 .. 7 (lib/probe_publish.glsl)."""
        for unit, tex in enumerate(self.textures[first_slot:first_slot + PROBE_IMAGE_LIMIT]):
            tex.bind_to_image(unit, read=False, write=True)

    def _run_walks(self, program, groups: int) -> None:
        """One dispatch where walks end in it; else dispatches until no walk has work left (the
        only host round trip of a bake: a driver with a loop limit needs it)."""
        if not self.resumable:
            program.run(groups)
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            self.dispatches += 1
            return
        first = 1
        while True:
            self.progress.write(bytes(4))
            set_uniforms(program, {"first_dispatch": first})
            program.run(groups)
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            self.dispatches += 1
            (pending,) = struct.unpack("I", self.progress.read())
            if pending == 0:
                return
            first = 0

    def walks_taken(self) -> np.ndarray:
        """Walks averaged into each probe, (nz, ny, nx) (a small read; for tests and the views)."""
        n = self.accum_floats
        data = np.frombuffer(self.accums.read(), np.float32).reshape(self.count, n)[:, n - 4]
        return data.reshape(self.grid[2], self.grid[1], self.grid[0]).copy()

    def progress_sums(self) -> tuple[float, float]:
        """Sums over probes of the last pass's squared change of L00 and of squared L00, reduced
        on the GPU (glsl/probe_progress.comp): a read of count / 256 pairs, not of every probe's
        accumulator (268 MB at 128^3 probes)."""
        groups = (self.count + 255) // 256
        if self._progress_program is None:
            self._progress_program = compute_program(self.ctx, "probe_progress.comp",
                                                     self.defines())
        if self._partial_sums is None or self._partial_sums.size != groups * 8:
            if self._partial_sums is not None:
                self._partial_sums.release()
            self._partial_sums = self.ctx.buffer(reserve=groups * 8)
        self.accums.bind_to_storage_buffer(4)
        self._partial_sums.bind_to_storage_buffer(0)
        set_uniforms(self._progress_program, {"probe_count": self.count})
        self._progress_program.run(groups)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        sums = np.frombuffer(self._partial_sums.read(), np.float32).reshape(groups, 2)
        return float(sums[:, 0].astype(np.float64).sum()), float(sums[:, 1].astype(np.float64).sum())

    def progress_report(self) -> BakeProgress:
        """The bake's progress from each probe's last change (call it when a pass ends)."""
        change, magnitude = self.progress_sums()
        rel = float(np.sqrt(change / magnitude)) if magnitude > 0 else 0.0
        # The mean of P pass estimates moves by (X_P - M_(P-1)) / P, whose mean square is
        # sigma^2 / (P (P - 1)); so the mean's standard error sigma / sqrt(P) is rms * sqrt(P - 1).
        p = self.passes_done
        se = rel * math.sqrt(p - 1) if p > 1 else float("nan")
        return BakeProgress(self.passes_done, self.passes_total, min(self.samples,
                            self.passes_done * self.directions), rel, se)

    def coefficients(self) -> np.ndarray:
        """The probes' running means as float32 (nz, ny, nx, C) in the colour packing
        (lib/probe_packing.glsl; C = 28 up to order 2, 52 at order 3, 76 at order 4)."""
        n = self.accum_floats
        data = np.frombuffer(self.accums.read(), np.float32).reshape(self.count, n)[:, :n - 4]
        return data.reshape(self.grid[2], self.grid[1], self.grid[0], n - 4).copy()

    def defines(self) -> dict:
        """Compile-time settings every shader reading these probes needs (lib/probes.glsl)."""
        return {"PROBE_SH_ORDER": self.sh_order, "PROBE_GREY": int(self.grey),
                **({"PROBE_SUN_LOBE": 1} if self.sun_lobe > 0 else {}),
                **self._warp_defines(), **self.medium}

    def _warp_defines(self) -> dict:
        """PROBE_WARP 1 for an adaptive layout; nothing for the uniform one (today's shaders)."""
        return {"PROBE_WARP": 1} if self.planes is not None else {}

    def box_uniforms(self, resources: SceneResources | None = None) -> dict:
        if self.box is None:
            half = np.asarray(resources.volume.half_extent, np.float64)
            low, high = -half, half
        else:
            low, high = np.asarray(self.box[0]), np.asarray(self.box[1])
        size = np.maximum(high - low, 1e-6)
        return {"probe_box_min": tuple(float(v) for v in low),
                "probe_box_size": tuple(float(v) for v in size)}

    def bind(self) -> None:
        for i, tex in zip(self.texture_ids, self.textures):
            tex.use(probe_unit(i))
        if self.warp_texture is not None:
            self.warp_texture.use(PROBE_WARP_UNIT)

    def uniforms(self, anisotropy: float, window: str,
                 resources: SceneResources | None = None) -> dict:
        u = {"probe_textures": tuple(probe_unit(i) for i in self.texture_ids)}
        u["probe_grid"] = self.grid
        if self.warp_texture is not None:
            u["probe_warp"] = PROBE_WARP_UNIT
        u.update(self.box_uniforms(resources))
        u["probe_band_factors"] = band_factors(anisotropy, window, self.sh_order)
        # the window alone (g = 1): `guided`'s direction control (lib/guided_direction_control.glsl)
        u["probe_window_factors"] = band_factors(1.0, window, self.sh_order)
        u["probe_radiance_scale"] = self.radiance_scale
        u["sun_lobe_g"] = self.sun_lobe
        u["sun_lobe_phase_g"] = float(anisotropy)
        return u

    def release(self) -> None:
        for _, program in self.publish_programs:
            program.release()
        for obj in (*self.textures, self.walk_states, self.walk_radiance, self.accums, self.progress,
                    self.noise, self.noise_program, self.budget_program, self.prior,
                    self.warp_texture,
                    self.walk_program, self._walk_profile_program, self.project_program,
                    self.correction_program,
                    self.sun_program, self._progress_program, self._partial_sums,
                    self._chunk_timer):
            if obj is not None:
                obj.release()


class _no_section:
    """Stands in for GpuProfile.section when a pass is not profiled."""

    def __init__(self, name: str):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
