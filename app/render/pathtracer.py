"""The reference volumetric path tracer pass (glsl/pathtrace.comp)."""
from __future__ import annotations

import moderngl

from ..camera import CameraFrame
from ..gl.shaders import compute_program, set_uniforms
from .accumulation import Accumulation
from .resources import SceneResources

LOCAL_SIZE = 8


def groups(width: int, height: int) -> tuple[int, int]:
    return (width + LOCAL_SIZE - 1) // LOCAL_SIZE, (height + LOCAL_SIZE - 1) // LOCAL_SIZE


class PathTracer:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = compute_program(ctx, "pathtrace.comp")

    def run(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation,
            samples: int, seed: int = 0, samples_per_pass: int = 1) -> None:
        """Adds `samples` samples per pixel to `acc`, `samples_per_pass` per dispatch."""
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, camera.uniforms())
        acc.bind_image(0)
        gx, gy = groups(acc.width, acc.height)
        done = 0
        while done < samples:
            n = min(samples_per_pass, samples - done)
            set_uniforms(self.program, {"seed": seed & 0xFFFFFFFF, "first_sample": acc.samples,
                                        "samples_per_pass": n})
            self.program.run(gx, gy)
            self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
            acc.samples += n
            done += n
