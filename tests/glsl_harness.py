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

from app.gl.shaders import compute_program, set_uniforms

HEADER = "layout(local_size_x = 64) in;\nuniform uint count;\n"


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
