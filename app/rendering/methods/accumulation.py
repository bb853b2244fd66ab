"""The running-mean image every progressive method writes: RGBA32F, rgb the mean, a the count of
samples averaged into that pixel."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.rendering.image_ops import clear_image, copy_image


class Accumulation:
    def __init__(self, ctx: moderngl.Context, width: int, height: int):
        self.ctx = ctx
        self.width, self.height = width, height
        self.texture = ctx.texture((width, height), 4, dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        # cleared (and copied, snapshot) on the GPU (rendering/image_ops.py): writing zeros from
        # the host was a 33 MB upload per restart at 1080p, and the viewer restarts after every
        # bake slice
        self.samples = 0  # samples per pixel asked for so far (whole samples: every row's)
        # work groups (tiles of 8 x 8 pixels, raster order) [0, groups_done) of sample
        # samples + 1 are done (Renderer.add_groups: a sample split into bands over frames); 0
        # when no sample is part done
        self.groups_done = 0

    def reset(self) -> None:
        clear_image(self.texture)
        self.samples = 0
        self.groups_done = 0

    def groups_marched(self, end: int, total: int) -> None:
        """The sample in progress has its work groups [0, end) done (of `total`): at `total` it
        is whole (samples grows by one, groups_done is 0 again), else groups_done is `end`."""
        if end >= total:
            self.samples, self.groups_done = self.samples + 1, 0
        else:
            self.groups_done = end

    def bind_image(self, unit: int = 0, read: bool = True) -> None:
        self.texture.bind_to_image(unit, read=read, write=True)

    def snapshot(self) -> "Accumulation":
        """A copy of the running mean as it is now, made on the GPU (no host transfer): the
        benchmark keeps one per snapshot of a timed run and reads them after the run, so the GPU
        is not left idle mid-run while the host reads an image back and measures it."""
        copy = Accumulation(self.ctx, self.width, self.height)
        copy_image(self.texture, copy.texture)
        copy.samples, copy.groups_done = self.samples, self.groups_done
        return copy

    def read_rgba(self) -> np.ndarray:
        """(height, width, 4) float32, row 0 at the top (the shaders store pixel (c, r) at texel (c, r))."""
        raw = np.frombuffer(self.texture.read(), np.float32)
        return raw.reshape(self.height, self.width, 4).copy()

    def read(self) -> np.ndarray:
        """The linear RGB image of SPEC.md: float32 (height, width, 3), row 0 at the top."""
        return self.read_rgba()[..., :3].copy()

    def release(self) -> None:
        self.texture.release()


class SumAccumulation:
    """Two running means read as their sum: `guided`'s level 0 (frames of an unbiased estimate of
    what the probes predict) and level 1 (path-traced samples minus that prediction's
    single-collision estimate), each averaged over its own count. Counts (alpha, `samples`) are
    level 1's."""

    def __init__(self, residual: Accumulation, level0: Accumulation):
        self.residual, self.level0 = residual, level0

    @property
    def width(self) -> int:
        return self.residual.width

    @property
    def height(self) -> int:
        return self.residual.height

    @property
    def samples(self) -> int:
        return self.residual.samples

    def snapshot(self) -> "SumAccumulation":
        return SumAccumulation(self.residual.snapshot(), self.level0.snapshot())

    def read_rgba(self) -> np.ndarray:
        rgba = self.residual.read_rgba()
        rgba[..., :3] += self.level0.read_rgba()[..., :3]
        return rgba

    def read(self) -> np.ndarray:
        return self.read_rgba()[..., :3].copy()

    def release(self) -> None:
        self.residual.release()
        self.level0.release()
