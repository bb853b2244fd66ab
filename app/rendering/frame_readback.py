"""An accumulation as the 8-bit sRGB picture a movie frame or a PNG holds, tone mapped on the GPU
(glsl/tonemap_frame.comp) and read back at 4 bytes a pixel (app/movie/frames.py)."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.rendering.methods.accumulation import Accumulation


class FrameReadback:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = compute_program(ctx, "tonemap_frame.comp")
        self.texture: moderngl.Texture | None = None

    def read(self, acc: Accumulation, exposure: float = 1.0) -> np.ndarray:
        """(height, width, 3) uint8, row 0 at the top: to_uint8(acc.read(), exposure) to within
        one step of rounding."""
        size = (acc.width, acc.height)
        if self.texture is None or self.texture.size != size:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture(size, 4, dtype="f1")
        self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
        acc.texture.bind_to_image(0, read=True, write=False)
        self.texture.bind_to_image(1, read=False, write=True)
        set_uniforms(self.program, {"exposure": float(exposure)})
        self.program.run((acc.width + 15) // 16, (acc.height + 15) // 16)
        self.ctx.memory_barrier(moderngl.TEXTURE_UPDATE_BARRIER_BIT)
        raw = np.frombuffer(self.texture.read(), np.uint8).reshape(acc.height, acc.width, 4)
        return raw[..., :3].copy()

    def release(self) -> None:
        self.program.release()
        if self.texture is not None:
            self.texture.release()
