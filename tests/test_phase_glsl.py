import numpy as np
import pytest

from radiance_probes.twins.phase import phase_hg, sample_hg_cos_theta
from glsl_harness import run_kernel


@pytest.mark.parametrize("g", [-0.9, 0.0, 0.3, 0.99])
def test_phase_glsl_matches_numpy(ctx, g):
    x = np.linspace(-1, 1, 1001).astype(np.float32)
    got = run_kernel(ctx, """
        #include "lib/phase.glsl"
        layout(std430, binding = 0) readonly buffer In { float cos_theta[]; };
        layout(std430, binding = 1) writeonly buffer Out { float value[]; };
        uniform float g;
        void main() { uint i = gl_GlobalInvocationID.x; if (i < count) value[i] = phase_hg(cos_theta[i], g); }
    """, [x], (len(x),), uniforms={"g": g})
    np.testing.assert_allclose(got, phase_hg(x, g), rtol=2e-5)
