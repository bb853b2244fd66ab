"""refine's probes guide made on the GPU (glsl/probe_albedo_guide.comp; NumPy twin
app/twins/probe_albedo_guide.py): the raymarched image over the probes scaled into an albedo guide
in three passes over the texture (a histogram of its pixels' largest channel, the quantile's scale
from it, the guide written packed into a storage buffer), read back beside the colour. On the
H200 the host's radiance_as_albedo (its largest-channel array, quantile and division) took 65-157
ms of a refine filter job beside the frames (bench/h200-interact-refine-56/host-passes); the
filter's thread now copies the packed guide into the filter's memory and does nothing else to it.

The scale's quantile is read from 32 bins an octave with the bin's count spread evenly: within
one bin's width (at most 3.1%) of np.quantile's, and the guide of a pixel at most that much
brighter or darker than radiance_as_albedo's (tests/test_probe_guide_gl.py)."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.rendering.denoise.filter import ALBEDO_SCALE_QUANTILE
from radiance_probes.twins.probe_albedo_guide import HISTOGRAM_BINS

PROBE_GUIDE_UNIT = 23   # the raymarched image's texture unit during the passes (no other binds it)


def guide_bytes(width: int, height: int) -> int:
    """The packed guide's size: 3 float32 a pixel."""
    return 12 * width * height


class ProbeAlbedoGuide:
    """The three passes, the histogram's buffer (zero between images: pass 1 clears it) and the
    packed guides' buffers, one a key (a view, a judgement), each exactly guide_bytes long."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        defines = {"ALBEDO_GUIDE_QUANTILE": f"{ALBEDO_SCALE_QUANTILE!r}"}
        self._passes = [compute_program(ctx, "probe_albedo_guide.comp",
                                        {**defines, "GUIDE_PASS": i}) for i in range(3)]
        self.histogram = ctx.buffer(bytes(16 + 4 * HISTOGRAM_BINS))
        self._guides: dict = {}

    def dispatch(self, key, texture: moderngl.Texture) -> moderngl.Buffer:
        """The guide of `texture` (rgb: radiance; RGBA32F or RGB32F) dispatched into the buffer
        kept under `key`, returned for a read-back (fence.start_read: its fence covers these
        passes). Its host copy is (height, width, 3) float32 in [0, 1], row y texel row y."""
        width, height = texture.size
        nbytes = guide_bytes(width, height)
        out = self._guides.get(key)
        if out is None or out.size != nbytes:
            if out is not None:
                out.release()
            out = self._guides[key] = self.ctx.buffer(reserve=nbytes)
        histogram, scale, guide = self._passes
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        texture.use(PROBE_GUIDE_UNIT)
        self.histogram.bind_to_storage_buffer(0)
        set_uniforms(histogram, {"probe_image": PROBE_GUIDE_UNIT})
        histogram.run(-(-width // 64), -(-height // 64))
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        set_uniforms(scale, {"pixel_count": width * height})
        scale.run(1)
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        out.bind_to_storage_buffer(1)
        set_uniforms(guide, {"probe_image": PROBE_GUIDE_UNIT})
        guide.run(-(-width // 16), -(-height // 16))
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT
                                | moderngl.BUFFER_UPDATE_BARRIER_BIT)
        return out

    def scale(self) -> float:
        """The last dispatch's scale (a read: tests)."""
        return float(np.frombuffer(self.histogram.read(size=4), np.float32)[0])

    def release_guides(self) -> None:
        for buf in self._guides.values():
            buf.release()
        self._guides.clear()

    def release(self) -> None:
        self.release_guides()
        self.histogram.release()
        for program in self._passes:
            program.release()
