"""An image's relative RMSE against a reference on the GPU (glsl/image_error.comp; NumPy twin
`metrics.rrmse`): the reference uploaded once, then one pass a measurement over the image's
texture and its per-tile sums read back (16 x 16 pixels a tile, 8 bytes each) and added in
float64. The bench's error curve measures the viewer's shown image this way: read back and
compared on the host, a 3840x2160 point took about 0.5 s with the GPU idle, and over a replay of
such points the H200 fell to its idle clock (345 of 1980 MHz), so the frames between them ran
five times slower than the viewer's (bench/h200-raymarch-4k)."""
from __future__ import annotations

import math

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms

GROUP_SIDE = 16
# texture units the pass reads from (bound before each dispatch)
IMAGE_UNIT, REFERENCE_UNIT = 20, 21


class ImageError:
    """`set_reference(ref)` once, then `rrmse(texture)` per measurement."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._pass = compute_program(ctx, "image_error.comp")
        self._reference: moderngl.Texture | None = None
        self._partials: moderngl.Buffer | None = None
        self._of = None   # the reference array the texture holds

    @property
    def size(self) -> tuple[int, int] | None:
        return None if self._reference is None else self._reference.size

    def set_reference(self, reference: np.ndarray) -> None:
        """The reference (H, W, 3) linear RGB, row 0 at the top, uploaded as RGB32F (once per
        array: the same array again uploads nothing)."""
        if reference is self._of:
            return
        ref = np.ascontiguousarray(reference, np.float32)
        if ref.ndim != 3 or ref.shape[2] != 3:
            raise ValueError(f"reference of shape {ref.shape}: expected (height, width, 3)")
        height, width = ref.shape[:2]
        if not np.isfinite(ref).all():   # (refused before as black: its float64 sum was NaN)
            raise ValueError("the reference image holds NaN or infinite values")
        if not np.any(ref):   # (no float64 copy: at 4K that took 150 ms of host time)
            raise ValueError("the reference image is black: relative RMSE is undefined")
        if self._reference is None or self._reference.size != (width, height):
            self.release()
            self._reference = self.ctx.texture((width, height), 3, dtype="f4")
            self._reference.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tiles = math.ceil(width / GROUP_SIDE) * math.ceil(height / GROUP_SIDE)
            self._partials = self.ctx.buffer(reserve=8 * tiles)
        self._reference.write(ref)
        self._of = reference

    def rrmse(self, texture: moderngl.Texture) -> float:
        """sqrt(sum (x - ref)^2) / sqrt(sum ref^2) over pixels and RGB of `texture` (any float
        texture of the reference's size; alpha ignored)."""
        if self._reference is None:
            raise RuntimeError("ImageError.rrmse: no reference set")
        if texture.size != self._reference.size:
            raise ValueError(f"image {texture.size[0]}x{texture.size[1]} differs from the "
                             f"reference's {self.size[0]}x{self.size[1]}")
        width, height = texture.size
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)   # image stores before it
        texture.use(IMAGE_UNIT)
        self._reference.use(REFERENCE_UNIT)
        self._partials.bind_to_storage_buffer(0)
        set_uniforms(self._pass, {"image": IMAGE_UNIT, "reference": REFERENCE_UNIT})
        self._pass.run(math.ceil(width / GROUP_SIDE), math.ceil(height / GROUP_SIDE))
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        sums = np.frombuffer(self._partials.read(), np.float32).reshape(-1, 2).astype(np.float64)
        diff, ref = sums.sum(axis=0)
        return float(math.sqrt(diff) / math.sqrt(ref))

    def release(self) -> None:
        for obj in (self._reference, self._partials):
            if obj is not None:
                obj.release()
        self._reference = self._partials = None
        self._of = None
