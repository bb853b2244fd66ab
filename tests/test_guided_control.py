"""`guided`'s control variate on the direction (lib/guided_direction_control.glsl, twin
app.twins.guided_direction_control.py): the GLSL against its twin, with the coefficients fetched from probe
textures as the path tracer fetches them; its mean over the phase function is 0 for any
coefficients (what keeps `guided` unbiased at any probes); and, in a render, `guided` with and
without it has the path tracer's mean."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.probes.bake import band_factors, probe_unit, SH_WINDOW_IDS
from radiance_probes.rendering.probes.layout import TEXTURES_FOR_ORDER
from radiance_probes.twins.guided_direction_control import direction_control
from radiance_probes.twins.phase import phase_hg
from radiance_probes.twins.sh import (SH_WINDOW_HANN, SH_WINDOW_LANCZOS, SH_WINDOW_NONE,
                                      sphere_quadrature)
from glsl_harness import PROBE_FETCH_KERNEL, probe_texel_centres, probe_textures, run_kernel

CONTROL_KERNEL = """
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
#include "lib/guided_direction_control.glsl"
layout(std430, binding = 0) readonly buffer In { float v[]; };   // x, w_in, w, weight per item
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint b = 10u * i;
    vec3 coeffs[SH_COUNT];
    float sun;
    probe_fetch(vec3(v[b], v[b + 1u], v[b + 2u]), coeffs, sun);
    vec3 c = guided_direction_control(coeffs, vec3(v[b + 3u], v[b + 4u], v[b + 5u]),
                                      vec3(v[b + 6u], v[b + 7u], v[b + 8u]), v[b + 9u]);
    o[3u * i] = c.r; o[3u * i + 1u] = c.g; o[3u * i + 2u] = c.b;
}
"""


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("order", [2, 3])
@pytest.mark.parametrize("window", ["none", "hann"])
def test_direction_control_glsl_matches_its_twin(ctx, order, window):
    grid = (3, 2, 4)
    count = grid[0] * grid[1] * grid[2]
    ids = TEXTURES_FOR_ORDER[order]
    rng = np.random.default_rng(order)
    texels = {t: rng.uniform(-1.0, 1.0, (count, 4)).astype(np.float32) for t in ids}
    textures = probe_textures(ctx, grid, texels)
    n = 64
    x = rng.uniform(-0.9, 0.9, (n, 3))
    w_in = _unit(rng.normal(size=(n, 3)))
    w = _unit(rng.normal(size=(n, 3)))
    weight = np.where(np.arange(n) % 2 == 0, 1.0, rng.uniform(0.5, 2.0, n))   # HG's, guided's
    g = 0.6
    uniforms = {"probe_textures": tuple(probe_unit(t) for t in ids), "probe_grid": grid,
                "probe_box_min": (-1.0, -1.0, -1.0), "probe_box_size": (2.0, 2.0, 2.0),
                "probe_radiance_scale": 2.0,
                "probe_band_factors": band_factors(g, window, order),
                "probe_window_factors": band_factors(1.0, window, order)}
    defines = {"PROBE_SH_ORDER": order, "PROBE_GREY": 0}
    sh_count = (order + 1) ** 2
    try:
        got = run_kernel(ctx, CONTROL_KERNEL,
                         [np.concatenate([x, w_in, w, weight[:, None]], 1).astype(np.float32)
                          .ravel()], (n, 3),
                         count=n, defines=defines, uniforms=uniforms)
        fetched = run_kernel(ctx, PROBE_FETCH_KERNEL, [x.astype(np.float32).ravel()],
                             (n, 3 * sh_count + 1), count=n, defines=defines, uniforms=uniforms)
    finally:
        for tex in textures:
            tex.release()
    coeffs = fetched[:, :-1].reshape(n, sh_count, 3)
    expected = np.stack([direction_control(coeffs[i], w_in[i], w[i], g, SH_WINDOW_IDS[window],
                                           order, weight[i]) for i in range(n)])
    assert np.abs(expected).max() > 0.1       # the control is not trivially zero here
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max())


@pytest.mark.parametrize("order", [2, 3, 4])
@pytest.mark.parametrize("window", [SH_WINDOW_NONE, SH_WINDOW_HANN, SH_WINDOW_LANCZOS])
@pytest.mark.parametrize("g", [-0.6, 0.0, 0.5, 0.95])
def test_direction_control_has_mean_zero_over_the_phase_function(order, window, g):
    """integral HG(w_in . w) control(w) dw = 0, by quadrature, for random coefficients (any probes)
    and random arrival directions; the control itself is far from 0 (it is not trivially so)."""
    rng = np.random.default_rng(int(10 * (g + 1)) + order)
    coeffs = rng.normal(size=((order + 1) ** 2, 3))
    w, weights = sphere_quadrature(192 if abs(g) > 0.9 else 96)
    for w_in in _unit(rng.normal(size=(6, 3))):
        control = direction_control(coeffs, w_in, w, g, window, order)
        mean = (phase_hg(w @ w_in, g) * weights) @ control
        assert np.abs(control).max() > 0.1
        np.testing.assert_allclose(mean, 0.0, atol=1e-6 * np.abs(control).max() + 1e-9)


def test_the_variance_script_runs_and_the_control_acts(tmp_path):
    """lab/experiments/guided_variance.py --quick (the anisotropic cloud, g = 0.8, whose probes hold
    directions): every estimator's variance is finite and positive, the direction control
    changes `guided`'s estimate (it acts), and the report names every estimator."""
    import json
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, str(root / "lab" / "experiments" / "guided_variance.py"), str(tmp_path),
                    "--quick"], check=True, capture_output=True, cwd=root)
    data = json.loads((tmp_path / "results.json").read_text())
    (scene,) = data["results"]
    est = scene["estimators"]
    assert set(est) == {"pt", "pt, 1 bounce", "pt, 2 bounces", "guided, first event", "guided",
                        "guided, level-0 ratio 1"}
    for name, rec in est.items():
        assert rec["finite"] and 0.0 < rec["relative_variance"] < np.inf, name
        assert rec["ms_per_sample"] > 0.0, name
    assert est["guided"]["relative_variance"] != est["guided, first event"]["relative_variance"]
    assert 0.0 < est["pt, 1 bounce"]["share_of_pt_variance"] < 2.0
    report = (tmp_path / "report.md").read_text()
    assert all(f"| {name} |" in report for name in est)
