"""The raymarcher (glsl/lib/raymarch.glsl) as a compute pass or as the design card's fragment
pass; both are built from the same source and write the same accumulation image."""
from __future__ import annotations

import moderngl

from ..twins.camera import CameraFrame
from ..gl.shaders import compute_program, render_program, set_uniforms
from .accumulation import Accumulation
from .pathtracer import groups
from .resources import SceneResources

STAGES = ("compute", "fragment")
MAX_MARCH_STEPS = 8192   # glsl/lib/raymarch.glsl clamps a ray's step count to this


def voxel_size(volume) -> float:
    """The smallest voxel side in world units (the box's longest side is 1)."""
    he = volume.half_extent
    return float(min(2.0 * he[i] / volume.dims[i] for i in range(3)))


def min_step_voxels(volume) -> float:
    """The smallest raymarch step (in voxels of the smallest side) the shader honours: a ray
    across the box's diagonal may take at most MAX_MARCH_STEPS steps, beyond which the shader
    would silently lengthen them."""
    diagonal = 2.0 * float((volume.half_extent.astype("float64") ** 2).sum() ** 0.5)
    return diagonal / MAX_MARCH_STEPS / voxel_size(volume)


def check_step(step_voxels: float, volume) -> None:
    """Raises ValueError for a step the shader would lengthen on this volume's longest rays."""
    low = min_step_voxels(volume)
    if step_voxels < low:
        raise ValueError(f"raymarch step {step_voxels:g} voxels: too fine for this volume (a ray "
                         f"across its box may take at most {MAX_MARCH_STEPS} steps); use at "
                         f"least {low:.3g}")


class Raymarcher:
    def __init__(self, ctx: moderngl.Context, stage: str = "compute", defines: dict | None = None):
        if stage not in STAGES:
            raise ValueError(f"raymarch stage must be one of {STAGES}, got {stage!r}")
        self.ctx = ctx
        self.stage = stage
        if stage == "compute":
            self.program = compute_program(ctx, "raymarch.comp", defines)
        else:
            self.program = render_program(ctx, "fullscreen.vert", "raymarch.frag", defines)
            self.vao = ctx.vertex_array(self.program, [])
        self._fbo = None

    def _framebuffer(self, width: int, height: int):
        if self._fbo is None or self._fbo.size != (width, height):
            if self._fbo is not None:
                self._fbo.release()
            self._fbo = self.ctx.framebuffer(
                color_attachments=[self.ctx.renderbuffer((width, height), 1)])
        return self._fbo

    def run(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation, frames: int,
            seed: int, step: float, uniforms: dict) -> None:
        """Adds `frames` jittered frames to acc's running mean."""
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, camera.uniforms())
        set_uniforms(self.program, uniforms)
        set_uniforms(self.program, {"raymarch_step": step,
                                    "seed": seed & 0xFFFFFFFF})
        acc.bind_image(0)
        for _ in range(frames):
            set_uniforms(self.program, {"frame_index": acc.samples})
            if self.stage == "compute":
                self.program.run(*groups(acc.width, acc.height))
            else:
                fbo = self._framebuffer(acc.width, acc.height)
                fbo.use()
                self.vao.render(moderngl.TRIANGLES, vertices=3)
            self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
            acc.samples += 1

    def release(self) -> None:
        self.program.release()
        if self.stage == "fragment":
            self.vao.release()
        if self._fbo is not None:
            self._fbo.release()
