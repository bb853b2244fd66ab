"""The bake's ceiling: how fast this GPU marches through the scene's medium with trilinear
3D-texture fetches (glsl/ceiling_march.comp), measured by the benchmark itself on the device it
runs on. A walk's tracking step does at least this work (plus random numbers and a logarithm), so
tracking steps per second over this rate says how close the bake runs to the hardware."""
from __future__ import annotations

import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.gl.timer import GpuTimer


def measure_ceiling(renderer, rays: int = 1 << 21, steps: int = 256, repeats: int = 3,
                    chain: bool = False) -> dict:
    """The best of `repeats` timed marches of `rays` x `steps` trilinear steps through the scene's
    medium. chain=True: each step waits on the one before (DEPENDENT_CHAIN in the shader), so with
    as many rays as a small bake has walks the time is a walk of `steps` steps' latency floor."""
    ctx, resources = renderer.ctx, renderer.resources
    program = compute_program(ctx, "ceiling_march.comp", {"DEPENDENT_CHAIN": 1} if chain else None)
    sums = ctx.buffer(reserve=rays * 4)
    timer = GpuTimer(ctx)
    try:
        resources.bind()
        set_uniforms(program, resources.uniforms())
        set_uniforms(program, {"rays": rays, "steps": steps,
                               "step_length": 2.0 * resources.march_step})   # one voxel
        sums.bind_to_storage_buffer(0)
        program.run((rays + 63) // 64)           # warm-up
        best = float("inf")
        for _ in range(repeats):
            timer.start()
            program.run((rays + 63) // 64)
            timer.stop()
            best = min(best, timer.elapsed_ms)
        total = float(np.frombuffer(sums.read(), np.float32).astype(np.float64).sum())
    finally:
        timer.release()
        sums.release()
        program.release()
    return {"steps": rays * steps, "ms": best, "steps_per_s": rays * steps / (best / 1e3),
            "sigma_t_sum": total}


# The benchmark's check on the device's own speed: the same small march before every setting of a
# scene. The GPU may be shared or clocked down for part of a run (bench/h100's raymarch frames on
# bonsai and the anisotropic cloud drifted 1.5-3x slower over a few minutes and back, while the same
# settings timed alone did not); records whose check ran slower than the scene's fastest say so.
SPEED_CHECK_RAYS = 1 << 18
SPEED_CHECK_STEPS = 64
SPEED_CHECK_SLOWER = 1.2   # a check this much slower than the scene's fastest flags its records


def speed_check_ms(renderer, rays: int = SPEED_CHECK_RAYS) -> float:
    """GPU ms of a fixed trilinear march (`rays` x SPEED_CHECK_STEPS) through the scene's medium,
    the best of 3 after a warm-up. The checks of one run share `rays` (BenchConfig's
    speed_check_rays), so they compare; the small presets for llvmpipe use fewer, where the
    default march takes about 1.7 s a check."""
    return measure_ceiling(renderer, rays, SPEED_CHECK_STEPS)["ms"]
