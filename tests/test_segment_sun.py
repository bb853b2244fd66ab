"""The raymarcher's sun over a segment (glsl/lib/segment_sun.glsl) against its NumPy twin and the
integral it stands for, and the raymarcher on a fully opaque box against single scattering's
closed form."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.twins.segment_sun import segment_sun_weight
from glsl_harness import run_kernel

KERNEL = """
#include "lib/segment_sun.glsl"
layout(std430, binding = 0) readonly buffer In { vec4 args[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec4 a = args[i];
    o[i] = segment_sun_weight(a.x, a.y, a.z, a.w);
}
"""


def _cases():
    rng = np.random.default_rng(4)
    n = 4096
    sigma_t = 10 ** rng.uniform(-3, 5, n)
    dt = 10 ** rng.uniform(-4, -1, n)
    tau_start = rng.uniform(0, 20, n)
    tau_end = np.clip(tau_start + rng.normal(0, 3, n), 0, 104)
    tau_end[::5] = tau_start[::5] + rng.normal(0, 1e-4, len(tau_end[::5]))   # x near 0
    tau_end[1::7] = np.maximum(tau_start[1::7] - sigma_t[1::7] * dt[1::7], 0)   # x near 0 too
    return np.stack([sigma_t, dt, tau_start, tau_end], axis=1)


def test_glsl_matches_the_twin(ctx):
    args = _cases()
    got = run_kernel(ctx, KERNEL, [args.astype(np.float32)], (len(args),))
    want = segment_sun_weight(*args.astype(np.float32).astype(np.float64).T)
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-7)


def test_twin_is_the_integral():
    """Against a fine midpoint quadrature of sigma_t exp(-sigma_t s) exp(-tau(s)) over [0, dt] (where
    the quadrature resolves the integrand: sigma_t dt and the sun's change below 100)."""
    cases = _cases()
    cases = cases[(cases[:, 0] * cases[:, 1] < 100) & (np.abs(cases[:, 3] - cases[:, 2]) < 100)]
    assert len(cases) > 1000
    for sigma_t, dt, tau_start, tau_end in cases[:400]:
        s = (np.arange(20000) + 0.5) / 20000 * dt
        tau = tau_start + (tau_end - tau_start) * s / dt
        quad = np.sum(sigma_t * np.exp(-sigma_t * s - tau)) * dt / 20000
        assert segment_sun_weight(sigma_t, dt, tau_start, tau_end) == pytest.approx(
            quad, rel=2e-3, abs=1e-12)


def test_constant_sun_is_the_segment_opacity():
    sigma_t, dt, tau = 37.0, 0.01, 1.3
    assert segment_sun_weight(sigma_t, dt, tau, tau) == pytest.approx(
        (1 - np.exp(-sigma_t * dt)) * np.exp(-tau), rel=1e-9)


@pytest.mark.parametrize("density_scale", [100.0, 1e4])
def test_raymarched_opaque_box_has_single_scatterings_closed_form(ctx, density_scale):
    """A homogeneous box, single scattering only (max_bounces 1: the probes hold nothing), seen
    face on: near the middle of the face, a semi-infinite medium's albedo E p mu_s / (mu_s + 1),
    whatever sigma_t. Taking the sun's transmittance at one point of each segment, the raymarcher
    gave 85% too little at sigma_t = 1e4 (its lit skin is far thinner than a step)."""
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    sun = np.array([0.3, 0.8, 0.52])
    sun /= np.linalg.norm(sun)
    scene = parse_scene({"volume": {"builtin": "constant", "size": [8, 8, 8]},
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "density_scale": density_scale, "albedo": 0.8, "max_bounces": 1,
                         "light": {"direction": sun.tolist(), "irradiance": [3, 3, 3]},
                         "environment": [0, 0, 0], "probes": {"grid": [2, 2, 2], "samples": 16},
                         "camera": {"eye": [0, 0, 2.2], "target": [0, 0, 0], "fov_y": 10.0,
                                    "width": 8, "height": 8}})
    expected = 0.8 * 3.0 / (4 * np.pi) * sun[2] / (sun[2] + 1.0)
    r = Renderer(ctx, scene)
    try:
        image = r.render("raymarch", spp=4, seed=3).image
    finally:
        r.release()
    # the light grid's trilinear optical depth near the face: 2% (its texels are the volume's here)
    assert float(image[2:6, 2:6].mean()) == pytest.approx(expected, rel=0.02)
