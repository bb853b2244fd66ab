"""GpuTimer: timestamps that bracket the GPU work they should, and no change to the framebuffer
binding its caller had (on llvmpipe it flushes the rasteriser by binding a framebuffer of its own,
then puts back the one it found, viewport included)."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.memory import _gl_get_integer
from radiance_probes.gl.shaders import compute_program
from radiance_probes.gl.timer import GpuTimer

GL_DRAW_FRAMEBUFFER_BINDING = 0x8CA6
GL_READ_FRAMEBUFFER_BINDING = 0x8CAA


def test_the_timer_restores_the_framebuffer_it_found(ctx):
    colour = ctx.texture((8, 4), 4)
    fbo = ctx.framebuffer(color_attachments=[colour])
    timer = GpuTimer(ctx)
    try:
        fbo.use()
        ctx.viewport = (1, 1, 3, 2)
        fbo.clear(0.25, 0.5, 0.75, 1.0)
        timer.start()
        timer.stop()
        assert timer.elapsed_ms >= 0.0
        assert ctx.fbo is fbo and ctx.viewport == (1, 1, 3, 2)
        assert _gl_get_integer(GL_DRAW_FRAMEBUFFER_BINDING) == fbo.glo
        assert _gl_get_integer(GL_READ_FRAMEBUFFER_BINDING) == fbo.glo
        # The caller's next draw lands in its framebuffer, within its viewport.
        ctx.clear(1.0, 0.0, 0.0, 1.0, viewport=ctx.viewport)
        pixels = np.frombuffer(fbo.read(components=4), np.uint8).reshape(4, 8, 4)
        assert tuple(pixels[1, 1]) == (255, 0, 0, 255) and tuple(pixels[0, 0])[:3] == (64, 128, 191)
        # A framebuffer the caller released while bound is not put back: no framebuffer is.
        fbo.release()
        timer.start()
        timer.stop()
        assert ctx.fbo is None and _gl_get_integer(GL_DRAW_FRAMEBUFFER_BINDING) == 0
    finally:
        timer.release()
        colour.release()


def test_the_timer_brackets_compute_work_after_a_draw(ctx):
    """Work that runs after a pending raster scene is timed, not taken as zero or negative."""
    program = compute_program(ctx, "timed.comp", text="""
        layout(local_size_x = 64) in;
        layout(std430, binding = 0) buffer Out { float v[]; };
        void main() {
            float x = float(gl_GlobalInvocationID.x);
            for (int i = 0; i < 2000; ++i) x = sin(x) * 1.0001 + 0.5;
            v[gl_GlobalInvocationID.x] = x;
        }""")
    out = ctx.buffer(reserve=64 * 64 * 4)
    colour = ctx.texture((16, 16), 4)
    fbo = ctx.framebuffer(color_attachments=[colour])
    timer = GpuTimer(ctx)
    try:
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 1.0)
        out.bind_to_storage_buffer(0)
        timer.start()
        program.run(64)
        timer.stop()
        assert timer.elapsed_ms > 0.0
        assert ctx.fbo is fbo
    finally:
        for obj in (timer, out, fbo, colour, program):
            obj.release()

