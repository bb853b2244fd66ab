"""What a restart's clear of an accumulation costs, and a framebuffer copy (issue 56: in the 4K
raymarch replay on the H200 every frame that restarts its accumulation takes 4-6 ms of wall time
beyond its timed GPU work, against 0.7 ms for a frame that does not).

    python3 lab/experiments/clear_cost.py OUT.json [REPEATS]

Per image size (1920x1080, 3840x2160; RGBA32F, as Accumulation), each way of zeroing or copying
the image REPEATS times: the wall ms from the call to glFinish (after a finish), and the GPU ms
between timestamps around it. Ways: `framebuffer_clear` (moderngl Framebuffer.clear, what
Accumulation.reset does), `clear_tex_image` (glClearTexImage), `compute_clear` (a compute pass
of imageStore(0)), `copy_framebuffer` (moderngl copy_framebuffer, what snapshot and refine use),
`copy_image` (glCopyImageSubData), `compute_copy` (a compute pass of imageLoad / imageStore). The
compute passes are inline below: an experiment, not the package's."""
from __future__ import annotations

import ctypes
import json
import sys
import time

import moderngl
import numpy as np

from radiance_probes.gl.context import create_headless_context
from radiance_probes.gl.timer import GpuTimer, _lib

CLEAR = """#version 430
layout(local_size_x = 16, local_size_y = 16) in;
layout(rgba32f, binding = 0) writeonly uniform image2D target;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (all(lessThan(p, imageSize(target)))) imageStore(target, p, vec4(0.0));
}
"""
COPY = """#version 430
layout(local_size_x = 16, local_size_y = 16) in;
layout(rgba32f, binding = 0) readonly uniform image2D source;
layout(rgba32f, binding = 1) writeonly uniform image2D target;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (all(lessThan(p, imageSize(target)))) imageStore(target, p, imageLoad(source, p));
}
"""
GL_TEXTURE_2D, GL_RGBA, GL_FLOAT = 0x0DE1, 0x1908, 0x1406


def main(out: str, repeats: int = 30) -> None:
    ctx = create_headless_context()
    gl = _lib()
    gl.glClearTexImage.argtypes = [ctypes.c_uint, ctypes.c_int, ctypes.c_uint, ctypes.c_uint,
                                   ctypes.c_void_p]
    gl.glCopyImageSubData.argtypes = [ctypes.c_uint, ctypes.c_uint, ctypes.c_int] + [ctypes.c_int] * 3 \
        + [ctypes.c_uint, ctypes.c_uint, ctypes.c_int] + [ctypes.c_int] * 3 + [ctypes.c_int] * 3
    clear, copy = ctx.compute_shader(CLEAR), ctx.compute_shader(COPY)
    timer = GpuTimer(ctx)
    rows = []
    for width, height in ((1920, 1080), (3840, 2160)):
        a = ctx.texture((width, height), 4, dtype="f4")
        b = ctx.texture((width, height), 4, dtype="f4")
        fa = ctx.framebuffer(color_attachments=[a])
        fb = ctx.framebuffer(color_attachments=[b])
        groups = ((width + 15) // 16, (height + 15) // 16)

        def compute_clear():
            a.bind_to_image(0, read=False, write=True)
            clear.run(*groups)
            ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

        def compute_copy():
            b.bind_to_image(0, read=True, write=False)
            a.bind_to_image(1, read=False, write=True)
            copy.run(*groups)
            ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

        ways = {
            "framebuffer_clear": lambda: fa.clear(0.0, 0.0, 0.0, 0.0),
            "clear_tex_image": lambda: gl.glClearTexImage(a.glo, 0, GL_RGBA, GL_FLOAT, None),
            "compute_clear": compute_clear,
            "copy_framebuffer": lambda: ctx.copy_framebuffer(fa, fb),
            "copy_image": lambda: gl.glCopyImageSubData(b.glo, GL_TEXTURE_2D, 0, 0, 0, 0,
                                                        a.glo, GL_TEXTURE_2D, 0, 0, 0, 0,
                                                        width, height, 1),
            "compute_copy": compute_copy,
        }
        b.write(np.ones((height, width, 4), np.float32))
        for name, way in ways.items():
            walls, gpus = [], []
            for _ in range(repeats):
                ctx.finish()
                t = time.perf_counter()
                timer.start()
                way()
                timer.stop()
                ctx.finish()
                walls.append(1e3 * (time.perf_counter() - t))
                gpus.append(timer.elapsed_ms)
            zero = name.endswith("clear")
            got = np.frombuffer(a.read(), np.float32)
            right = bool(np.all(got == (0.0 if zero else 1.0)))
            if not zero:
                fa.clear(0.0, 0.0, 0.0, 0.0)
            row = {"width": width, "height": height, "way": name, "right": right,
                   "wall_ms_median": float(np.median(walls[1:])), "wall_ms_max": float(max(walls)),
                   "gpu_ms_median": float(np.median(gpus[1:])), "first_wall_ms": walls[0]}
            print(json.dumps(row), flush=True)
            rows.append(row)
        for x in (fa, fb, a, b):
            x.release()
    with open(out, "w") as f:
        json.dump({"device": ctx.info["GL_RENDERER"], "repeats": repeats, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1], *map(int, sys.argv[2:3]))
