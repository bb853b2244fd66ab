"""The shape of the probes' lobe about the sun's direction, chosen per scene from a pilot bake
(lab/sun_lobe_fit.comp; the lobe itself: glsl/lib/sun_lobe.glsl). An experiment's, outside the
package (lab/experiments/experiment_sun_lobe.py): it was RenderSettings.sun_lobe_fit, built and
measured, never the default, and left the product (docs/experiments.md). To bake with the lobe it
chooses, set radiance_probes.rendering.probes.layout.SUN_LOBE_POWER to the fit's `power` (the
experiment does).

The lobe is HG_h about the sun's direction with h = g^p. The best p depends on the scene:
measured on the H100 it is 2 for a front-lit g = 0.8 cloud, 3 to 4 backlit, and 4 at g = 0.9
(bench/h100-sun-lobe). So before a bake that holds the lobe, a pilot grid of probes (PILOT_GRID
per axis over the same box, shadow rays to the sun) walks two passes of PILOT_WALKS walks; for
each candidate p, the two passes' independent amplitudes estimate what the lobe would take out of
the error the renderers see, less the noise its amplitude would add with the bake's own walk count
(fit_gains below);
the candidate with the largest sum over probes wins. Its cost (the pilot's walks and the fit, GPU
time) is part of the bake's time; its read-back (two passes' amplitudes, 96 bytes a pilot probe)
is one wait per bake start.

Built and measured, not the default (bench/h100-sun-lobe/auto_fit_*.json,
H100, five variants of the bench's cloud at 32^3 to 192^3 probes): at g = 0.9 it chose p = 4 and
gained 0.8 to 0.9 points (128^3 x 256: 8.34 -> 7.45%); on the bench's cloud it kept p = 3 (64^3 x
128: 4); elsewhere it lost up to 0.14 points, and front-lit it kept p = 3 where p = 2 measured
better (2.84 against 2.59%). The pilot took 2.5 to 7 ms of GPU time a bake."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import moderngl
import numpy as np

from radiance_probes.gl.context import is_software
from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.rendering.probes import layout as probe_layout
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.twins.sun_lobe import basis, norm

SHADER = Path(__file__).resolve().with_name("sun_lobe_fit.comp")

SUN_LOBE_FIT_POWERS = (2.0, 3.0, 4.0)   # candidate h = g^p
PILOT_WALKS = 64   # per pass; the pilot walks two passes
PILOT_GRID = {"gpu": 16, "software": 8}   # probes per axis (at most the bake's own)
PILOT_SEED = 0x51D1   # mixed with the bake's seed: a bake's choice follows its seed


@dataclass
class SunLobeFit:
    h: float                      # the chosen lobe g
    power: float                  # ... as the phase function's g to this power
    candidates: tuple             # the h tried
    gains: tuple                  # each one's summed gain (larger: better)
    gpu_ms: float                 # the pilot's and the fit's GPU time


def candidate_hs(anisotropy: float) -> tuple[float, ...]:
    """The lobe shapes tried for phase-function g: g^p for SUN_LOBE_FIT_POWERS, those at least
    SUN_LOBE_MIN_G (a broader lobe changed nothing where measured)."""
    return tuple(h for h in (float(anisotropy) ** p for p in SUN_LOBE_FIT_POWERS)
                 if h >= probe_layout.SUN_LOBE_MIN_G)


class SunLobeFitter:
    """Bakes the pilot and chooses the lobe (fit); keeps the pilot's probe grid and the fit's
    program between bakes while the pilot's layout stays (its shaders compile once)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._pilot = None
        self._pilot_key = None
        self._program = None
        self._program_key = None
        self.timer = GpuTimer(ctx)

    def _pilot_for(self, grid, box, grey, environment_map, h, medium=None):
        side = PILOT_GRID["software" if is_software(self.ctx) else "gpu"]
        pilot_grid = tuple(min(int(n), side) for n in grid)
        key = (pilot_grid, box, bool(grey), bool(environment_map), tuple(sorted((medium or {}).items())))
        if self._pilot_key != key:
            if self._pilot is not None:
                self._pilot.release()
            self._pilot = ProbeGrid(self.ctx, pilot_grid, 2 * PILOT_WALKS, "rgba32f", 3, box, grey,
                                    sun="ray", environment_map=environment_map, sun_lobe=h,
                                    medium=medium)
            self._pilot_key = key
        self._pilot.sun_lobe = h   # a uniform of its shaders (built with PROBE_SUN_LOBE 1)
        return self._pilot

    def fit(self, resources, box, grid: tuple[int, int, int], main_walks: int, grey: bool,
            environment_map: bool, seed: int) -> SunLobeFit:
        """The chosen lobe g for order-3 probes of `grid` with `main_walks` walks over `box`."""
        scene = resources.scene
        hs = candidate_hs(scene.anisotropy)
        if not hs:
            raise ValueError(f"no sun-lobe candidate for anisotropy {scene.anisotropy}")
        pilot = self._pilot_for(grid, box, grey, environment_map, hs[0],
                                resources.medium_defines())
        key = (tuple(sorted(pilot.defines().items())), len(hs))
        if self._program_key != key:
            if self._program is not None:
                self._program.release()
            self._program = compute_program(self.ctx, "sun_lobe_fit.comp",
                                            {**pilot.defines(), "SUN_LOBE_CANDIDATES": len(hs)},
                                            text=SHADER.read_text())
            self._program_key = key
        outputs = pilot.count * len(hs)
        amplitudes = self.ctx.buffer(reserve=16 * 2 * outputs)
        try:
            pilot.restart((int(seed) * 0x9E3779B1 + PILOT_SEED) & 0xFFFFFFFF)
            set_uniforms(self._program, {
                **resources.uniforms(), **pilot.box_uniforms(resources), "probe_grid": pilot.grid,
                "probe_count": pilot.count, "directions": PILOT_WALKS,
                "seed": pilot.seed & 0xFFFFFFFF, "candidate_h": hs,
                "sun_lobe_phase_g": float(scene.anisotropy)})
            self.timer.start()
            for pass_index in (0, 1):   # two independent passes of PILOT_WALKS walks
                pilot.bake_pass(resources)   # its walks stay in walk_radiance
                resources.bind()
                set_uniforms(self._program, {"pass_index": pass_index,
                                             "first_output": pass_index * outputs})
                pilot.walk_radiance.bind_to_storage_buffer(3)
                amplitudes.bind_to_storage_buffer(0)
                self._program.run((pilot.count + 63) // 64)
                self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            self.timer.stop()
            self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
            values = np.frombuffer(amplitudes.read(), np.float32).reshape(2, pilot.count, len(hs), 4)
        finally:
            amplitudes.release()
        gains = fit_gains(values[0, ..., :3], values[1, ..., :3], hs, float(scene.anisotropy), 3,
                          PILOT_WALKS, max(int(main_walks), 1))
        if np.all(np.isfinite(gains)):
            best = int(np.argmax(gains))
        else:   # a non-finite walk (counted in tracking_stats): the fixed power's shape
            best = int(np.argmin([abs(h - scene.anisotropy ** probe_layout.SUN_LOBE_POWER)
                                  for h in hs]))
        power = math.log(hs[best]) / math.log(float(scene.anisotropy))
        return SunLobeFit(hs[best], power, hs, tuple(float(v) for v in gains),
                          self.timer.elapsed_ms)

    def fit_for(self, renderer, seed: int = 0) -> SunLobeFit:
        """The fit for the probes `renderer` (a radiance_probes Renderer) would bake now."""
        plan = renderer.probe_plan()
        return self.fit(renderer.bake_resources(), plan.box, plan.grid,
                        renderer.scene.probes.samples, plan.grey,
                        renderer.resources.environment is not None, seed)

    def release(self) -> None:
        if self._pilot is not None:
            self._pilot.release()
        if self._program is not None:
            self._program.release()
        self.timer.release()
        self._pilot = self._program = None
        self._pilot_key = self._program_key = None


# ---- NumPy twin of lab/sun_lobe_fit.comp, and the choice ------------------------------------

def lobe_amplitudes(mu, radiance, valid, hs, g, n):
    """lab/sun_lobe_fit.comp: each probe's lobe amplitude for each candidate h, as the bake
    estimates it from one pass's walks. mu (P, D): each walk's direction . sun; radiance (P, D, 3);
    valid (P, D). Returns amplitudes (P, len(hs), 3) and walks used (P,)."""
    mu = np.asarray(mu, np.float64)
    radiance = np.where(np.asarray(valid, bool)[..., None], np.asarray(radiance, np.float64), 0.0)
    count = np.sum(valid, axis=1).astype(np.float64)
    out = np.zeros((mu.shape[0], len(hs), 3))
    for k, h in enumerate(hs):
        s = np.sum(radiance * basis(mu, h, n, g)[..., None], axis=1)
        out[:, k] = np.where(count[:, None] > 0, 4.0 * np.pi * s / np.maximum(count, 1)[:, None], 0.0)
    return out, count


def fit_gains(a, b, hs, g, n, pilot_walks, main_walks):
    """What each candidate lobe takes out of the error the renderers see, summed over probes and
    colours, less the noise its amplitude adds in a bake of `main_walks` walks per probe: a and b
    (P, K, 3) are two independent passes' amplitudes of `pilot_walks` walks each. The error
    removed is A^2 <r_gh, r_gh> (A the true amplitude; lib/sun_lobe.glsl), estimated without bias
    by a b <r_gh, r_gh>; the bake's amplitude has the variance of one pass's times pilot_walks /
    main_walks, one pass's estimated as (a - b)^2 / 2."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    norms = np.array([norm(g * h, n) for h in hs])
    explained = np.sum(a * b, axis=(0, 2))
    noise = 0.5 * np.sum((a - b) ** 2, axis=(0, 2)) * pilot_walks / main_walks
    return norms * (explained - noise)
