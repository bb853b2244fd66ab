"""The bake's ceiling: how fast this GPU marches through the scene's medium with trilinear
3D-texture fetches (glsl/ceiling_march.comp), measured by the benchmark itself on the device it
runs on. A walk's tracking step does at least this work (plus random numbers and a logarithm), so
tracking steps per second over this rate says how close the bake runs to the hardware."""
from __future__ import annotations

from ..gl.shaders import compute_program, set_uniforms
from ..gl.timer import GpuTimer


def measure_ceiling(renderer, rays: int = 1 << 21, steps: int = 256, repeats: int = 3) -> dict:
    ctx, resources = renderer.ctx, renderer.resources
    program = compute_program(ctx, "ceiling_march.comp")
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
    finally:
        timer.release()
        sums.release()
        program.release()
    return {"steps": rays * steps, "ms": best, "steps_per_s": rays * steps / (best / 1e3)}
