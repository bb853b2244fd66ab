"""The denoiser's guides on the GPU (glsl/denoise_guide_images.comp; NumPy twin
app/twins/denoise_guides.py): the expected albedo and normal where each camera ray first scatters,
as two running-mean images over the same jittered rays the raymarcher takes."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.twins.camera import CameraFrame
from radiance_probes.rendering.methods.accumulation import Accumulation
from radiance_probes.rendering.methods.pathtracer import groups
from radiance_probes.rendering.resources import SceneResources

# Jittered rays a pixel's guides average: enough that an edge's anti-aliasing matches the colour's
# to the eye; the guides stay fixed while a progressive image accumulates (a camera or medium
# change makes new ones).
GUIDE_FRAMES = 4


class DenoiseGuides:
    def __init__(self, ctx: moderngl.Context, defines: dict | None = None):
        self.ctx = ctx
        self.defines = dict(defines or {})   # the medium's build (Renderer rebuilds on a change)
        self.program = compute_program(ctx, "denoise_guide_images.comp", defines)
        self.albedo: Accumulation | None = None
        self.normal: Accumulation | None = None

    def _images(self, width: int, height: int) -> None:
        if self.albedo is None or (self.albedo.width, self.albedo.height) != (width, height):
            self.release_images()
            self.albedo = Accumulation(self.ctx, width, height)
            self.normal = Accumulation(self.ctx, width, height)

    def run(self, resources: SceneResources, camera: CameraFrame, step: float,
            frames: int = GUIDE_FRAMES, seed: int = 0) -> None:
        """Marches `frames` jittered frames of both guides from scratch (step in world units; the
        gradient's step is a voxel, twice resources.march_step)."""
        self._images(camera.width, camera.height)
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, camera.uniforms())
        set_uniforms(self.program, {"raymarch_step": step, "seed": seed & 0xFFFFFFFF,
                                    "gradient_step": 2.0 * resources.march_step})
        self.albedo.bind_image(0)
        self.normal.bind_image(1)
        for frame in range(frames):
            set_uniforms(self.program, {"frame_index": frame})
            self.program.run(*groups(camera.width, camera.height))
            self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
        self.albedo.samples = self.normal.samples = frames

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(albedo, normal): float32 (H, W, 3) each, row 0 at the top."""
        return self.albedo.read(), self.normal.read()

    def release_images(self) -> None:
        for image in (self.albedo, self.normal):
            if image is not None:
                image.release()
        self.albedo = self.normal = None

    def release(self) -> None:
        self.release_images()
        self.program.release()
