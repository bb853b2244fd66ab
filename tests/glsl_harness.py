"""Run a small GLSL compute snippet over arrays and read the results back, to compare GLSL maths
with its NumPy twin. The snippet is a main file's text; it may #include "lib/....glsl".

    out = run_kernel(ctx, '''
        #include "lib/phase.glsl"
        layout(std430, binding = 0) readonly buffer In { float cos_theta[]; };
        layout(std430, binding = 1) writeonly buffer Out { float value[]; };
        uniform float g;
        void main() { uint i = gl_GlobalInvocationID.x; if (i < count) value[i] = phase_hg(cos_theta[i], g); }
    ''', inputs=[x.astype(np.float32)], out=(n,), uniforms={"g": 0.5})
"""
from __future__ import annotations

import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms

HEADER = "layout(local_size_x = 64) in;\nuniform uint count;\n"


def probe_textures(ctx, grid, texels: dict) -> list:
    """RGBA32F probe textures of `grid` (nx, ny, nz), texture number t holding texels[t] ((count,
    4), probe index = i + nx (j + ny k)), trilinear, each bound to its unit (probe_unit). Release
    them when done."""
    import moderngl
    from radiance_probes.rendering.probes.bake import probe_unit
    textures = []
    for t, values in texels.items():
        tex = ctx.texture3d(grid, 4, np.ascontiguousarray(values, np.float32).tobytes(), dtype="f4")
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.use(probe_unit(t))
        textures.append(tex)
    return textures


def probe_texel_centres(grid) -> np.ndarray:
    """The probes' positions (count, 3) in probe index order, over the box [-1, 1]^3."""
    ijk = np.stack(np.meshgrid(*(np.arange(n) for n in grid), indexing="ij"), -1).reshape(-1, 3)
    ijk = ijk[np.lexsort((ijk[:, 0], ijk[:, 1], ijk[:, 2]))]   # probe index = i + nx (j + ny k)
    return (ijk + 0.5) / np.asarray(grid) * 2.0 - 1.0

# lib/probes.glsl probe_fetch at points x (3 floats each): per point every coefficient's rgb
# (3 * SH_COUNT floats, coefficient-major) and then the sun's transmittance.
PROBE_FETCH_KERNEL = """
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
layout(std430, binding = 0) readonly buffer In { float x[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 coeffs[SH_COUNT];
    float sun;
    probe_fetch(vec3(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]), coeffs, sun);
    uint base = uint(3 * SH_COUNT + 1) * i;
    for (int k = 0; k < SH_COUNT; ++k)
        for (int c = 0; c < 3; ++c)
            o[base + uint(3 * k + c)] = coeffs[k][c];
    o[base + uint(3 * SH_COUNT)] = sun;
}
"""


def run_kernel(ctx, text: str, inputs: list[np.ndarray], out: tuple[int, ...],
               out_dtype=np.float32, uniforms: dict | None = None, count: int | None = None,
               defines: dict | None = None) -> np.ndarray:
    """Inputs bind to storage buffers 0..k-1, the output to binding k; one invocation per item."""
    program = compute_program(ctx, "<test kernel>", defines, text=HEADER + text)
    buffers = [ctx.buffer(np.ascontiguousarray(a).tobytes()) for a in inputs]
    for i, b in enumerate(buffers):
        b.bind_to_storage_buffer(i)
    out_bytes = int(np.prod(out)) * np.dtype(out_dtype).itemsize
    result = ctx.buffer(reserve=max(out_bytes, 4))
    result.bind_to_storage_buffer(len(buffers))
    n = count if count is not None else (len(inputs[0]) if inputs else out[0])
    set_uniforms(program, {"count": n, **(uniforms or {})})
    program.run((n + 63) // 64)
    data = np.frombuffer(result.read(), out_dtype)[: int(np.prod(out))].reshape(out).copy()
    for b in buffers:
        b.release()
    result.release()
    program.release()
    return data
