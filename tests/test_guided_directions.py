"""Guided directions (lib/guided_directions.glsl, twin app/twins/guided_directions.py): the GLSL
against its twin on probe textures fetched as the path tracer fetches them; sample_hg's inverse
(lib/phase.glsl hg_primary_sample) round-trips; the mixture's pdf integrates to 1 over the sphere
and the GLSL sampler's histogram matches it; SH order 0 probes are not baked while it is on.
Unbiased renders: tests/test_guided.py."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss

from radiance_probes.rendering.probe_layout import TEXTURES_FOR_ORDER, resolve_sh_order
from radiance_probes.rendering.probes import band_factors, probe_unit
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.twins import guided_directions as gd
from radiance_probes.twins.phase import hg_primary_sample, orthonormal_basis, sample_hg, sample_hg_cos_theta
from radiance_probes.twins.sh import SH_WINDOW_HANN, SH_WINDOW_NONE, sphere_quadrature
from glsl_harness import PROBE_FETCH_KERNEL, probe_textures, run_kernel

HEAD = """
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/phase.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
#include "lib/guided_directions.glsl"
uniform float g;
"""

# per item: x, w_in, three uniform numbers, another direction w (12 floats); out: the table's
# running sums, the point drawn, its q, its direction, u(w) and q(u(w)) by
# guided_direction_density_at (GUIDED_CELLS + 9 floats)
TABLE_KERNEL = HEAD + """
layout(std430, binding = 0) readonly buffer In { float v[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint b = 12u * i;
    vec3 x = vec3(v[b], v[b + 1u], v[b + 2u]), w_in = vec3(v[b + 3u], v[b + 4u], v[b + 5u]);
    vec3 w = vec3(v[b + 9u], v[b + 10u], v[b + 11u]);
    vec3 coeffs[SH_COUNT];
    float sun;
    probe_fetch(x, coeffs, sun);
    float cdf[GUIDED_CELLS];
    guided_direction_table(coeffs, w_in, g, cdf);
    vec2 u = guided_direction_primary(cdf, v[b + 6u], v[b + 7u], v[b + 8u]);
    vec3 drawn = sample_hg(w_in, g, u.x, u.y);
    uint o0 = uint(GUIDED_CELLS + 9) * i;
    for (int k = 0; k < GUIDED_CELLS; ++k)
        o[o0 + uint(k)] = cdf[k];
    uint r = o0 + uint(GUIDED_CELLS);
    o[r] = u.x; o[r + 1u] = u.y; o[r + 2u] = guided_direction_density(cdf, u);
    o[r + 3u] = drawn.x; o[r + 4u] = drawn.y; o[r + 5u] = drawn.z;
    vec2 back = hg_primary_sample(w_in, g, w);
    o[r + 6u] = back.x; o[r + 7u] = back.y;
    o[r + 8u] = guided_direction_density_at(coeffs, w_in, g, w);
}
"""

# per item: direction, u (5 floats); out: sample_hg's w and hg_primary_sample of it (5 floats)
ROUND_TRIP_KERNEL = """
#include "lib/phase.glsl"
uniform float g;
layout(std430, binding = 0) readonly buffer In { float v[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint b = 5u * i;
    vec3 d = vec3(v[b], v[b + 1u], v[b + 2u]);
    vec3 w = sample_hg(d, g, v[b + 3u], v[b + 4u]);
    vec2 u = hg_primary_sample(d, g, w);
    o[b] = w.x; o[b + 1u] = w.y; o[b + 2u] = w.z; o[b + 3u] = u.x; o[b + 4u] = u.y;
}
"""

# one event (x, w_in uniforms), many draws: per item three uniform numbers; out: the direction
SAMPLER_KERNEL = HEAD + """
uniform vec3 x;
uniform vec3 w_in;
layout(std430, binding = 0) readonly buffer In { float v[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 coeffs[SH_COUNT];
    float sun;
    probe_fetch(x, coeffs, sun);
    float cdf[GUIDED_CELLS];
    guided_direction_table(coeffs, w_in, g, cdf);
    vec2 u = guided_direction_primary(cdf, v[3u * i], v[3u * i + 1u], v[3u * i + 2u]);
    vec3 w = sample_hg(w_in, g, u.x, u.y);
    o[3u * i] = w.x; o[3u * i + 1u] = w.y; o[3u * i + 2u] = w.z;
}
"""

GRID = (3, 2, 4)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _probe_setup(ctx, order, seed, dc=1.0):
    """Random probe textures (texel values in [-1, 1], the DC raised by dc so the radiance is
    mostly positive, with some SH ringing below 0) and the uniforms that read them."""
    ids = TEXTURES_FOR_ORDER[order]
    rng = np.random.default_rng(seed)
    count = GRID[0] * GRID[1] * GRID[2]
    texels = {t: rng.uniform(-1.0, 1.0, (count, 4)).astype(np.float32) for t in ids}
    texels[ids[0]][:, :3] += dc   # coefficient 0's colour channels (lib/probe_packing.glsl)
    uniforms = {"probe_textures": tuple(probe_unit(t) for t in ids), "probe_grid": GRID,
                "probe_box_min": (-1.0, -1.0, -1.0), "probe_box_size": (2.0, 2.0, 2.0),
                "probe_radiance_scale": 1.5,
                "probe_window_factors": band_factors(1.0, "hann", order)}
    return probe_textures(ctx, GRID, texels), uniforms


def _fetch(ctx, x, order, uniforms):
    glsl_count = (max(order, 2) + 1) ** 2   # lib/sh.glsl's SH_COUNT: 9 below order 3
    fetched = run_kernel(ctx, PROBE_FETCH_KERNEL, [x.astype(np.float32).ravel()],
                         (len(x), 3 * glsl_count + 1), count=len(x),
                         defines={"PROBE_SH_ORDER": order, "PROBE_GREY": 0}, uniforms=uniforms)
    coeffs = fetched[:, :-1].reshape(len(x), glsl_count, 3).astype(np.float64)
    return coeffs[:, :(order + 1) ** 2]


@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("g", [0.0, 0.7, -0.4])
@pytest.mark.parametrize("probability", [0.5, 1.0])
def test_guided_directions_glsl_match_their_twin(ctx, order, g, probability):
    n = 96
    textures, uniforms = _probe_setup(ctx, order, seed=order + 10)
    rng = np.random.default_rng(order)
    x = rng.uniform(-0.9, 0.9, (n, 3))
    w_in = _unit(rng.normal(size=(n, 3)))
    xi = rng.uniform(0.0, 1.0, (n, 3))
    w = _unit(rng.normal(size=(n, 3)))
    uniforms = {**uniforms, "g": g, "guided_direction_probability": probability}
    defines = {"PROBE_SH_ORDER": order, "PROBE_GREY": 0}
    try:
        got = run_kernel(ctx, TABLE_KERNEL,
                         [np.concatenate([x, w_in, xi, w], 1).astype(np.float32).ravel()],
                         (n, gd.CELLS + 9), count=n, defines=defines, uniforms=uniforms)
        coeffs = _fetch(ctx, x, order, uniforms)
    finally:
        for tex in textures:
            tex.release()
    cells = gd.CELLS
    for i in range(n):
        cdf = gd.direction_table(coeffs[i], w_in[i], g, SH_WINDOW_HANN, order)
        np.testing.assert_allclose(got[i, :cells], cdf, rtol=1e-4, atol=1e-5 * cdf[-1])
        u = gd.sample_primary(cdf, probability, *xi[i])
        np.testing.assert_allclose(got[i, cells:cells + 2], u, atol=2e-6)
        np.testing.assert_allclose(got[i, cells + 2], gd.primary_density(cdf, u, probability),
                                   rtol=1e-4)
        np.testing.assert_allclose(got[i, cells + 3:cells + 6], sample_hg(w_in[i], g, *u),
                                   atol=2e-5)
        back = hg_primary_sample(w_in[i], g, w[i])
        np.testing.assert_allclose(got[i, cells + 6:cells + 8], back, atol=2e-5)
        np.testing.assert_allclose(got[i, cells + 8], gd.primary_density(cdf, back, probability),
                                   rtol=1e-4)
    # the table is not flat: the probes' radiance shapes it
    masses = np.diff(got[:, :cells], axis=1, prepend=0.0)
    assert np.all(masses > 0.0) and (masses.max(1) / masses.min(1)).max() > 3.0


@pytest.mark.parametrize("g", [0.0, 5e-4, 0.5, -0.7, 0.95])
def test_hg_primary_sample_inverts_sample_hg(ctx, g):
    """u -> sample_hg -> hg_primary_sample gives u back, in float64 (the twin) and in the GLSL."""
    n = 4096
    rng = np.random.default_rng(int(100 * abs(g)) + 1)
    d = _unit(rng.normal(size=(n, 3)))
    d[:4] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0]]   # the basis' special cases
    u = rng.uniform(0.01, 0.99, (n, 2))
    w = sample_hg(d, g, u[:, 0], u[:, 1])
    back = hg_primary_sample(d, g, w)
    np.testing.assert_allclose(back, u, atol=1e-9)
    got = run_kernel(ctx, ROUND_TRIP_KERNEL, [np.concatenate([d, u], 1).astype(np.float32).ravel()],
                     (n, 5), count=n, uniforms={"g": g})
    np.testing.assert_allclose(got[:, :3], w, atol=2e-5)
    du = np.abs(got[:, 3:] - u)
    du[:, 1] = np.minimum(du[:, 1], 1.0 - du[:, 1])   # the azimuth wraps
    # float32: cos theta's rounding is amplified by HG's steep CDF at g = 0.95 (390x at worst)
    assert du[:, 0].max() < (1e-4 if abs(g) > 0.9 else 1e-5) and du[:, 1].max() < 2e-4


def _cell_aligned_quadrature(w_in, g, nodes=48):
    """Directions and weights over the sphere whose nodes never sit on a cell's boundary: Gauss-
    Legendre in cos theta within each band of cells (cos theta about w_in; `nodes` each, for HG's
    steep rise at g = 0.95), each cell's azimuth in 4 midpoints (q is constant there, p_HG does
    not depend on the azimuth)."""
    t, wt = leggauss(nodes)
    edges = sample_hg_cos_theta(np.arange(gd.CELLS_COS + 1) / gd.CELLS_COS, g)
    edges = np.sort(np.concatenate([edges, [-1.0, 1.0]]))
    cos_t, w_cos = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi > lo:
            cos_t.append(lo + (hi - lo) * (t + 1.0) / 2.0)
            w_cos.append((hi - lo) / 2.0 * wt)
    cos_t, w_cos = np.concatenate(cos_t), np.concatenate(w_cos)
    m = gd.CELLS_PHI * 4
    phi = 2.0 * np.pi * (np.arange(m) + 0.5) / m
    b1, b2 = orthonormal_basis(np.asarray(w_in, np.float64))
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    w = (sin_t[:, None, None] * (np.cos(phi)[None, :, None] * b1 + np.sin(phi)[None, :, None] * b2)
         + cos_t[:, None, None] * w_in).reshape(-1, 3)
    weights = (w_cos[:, None] * np.full(m, 2.0 * np.pi / m)[None, :]).reshape(-1)
    return w, weights


@pytest.mark.parametrize("order", [1, 2, 4])
@pytest.mark.parametrize("g", [0.0, 0.5, -0.6, 0.95])
@pytest.mark.parametrize("probability", [0.0, 0.5, 1.0])
def test_guided_direction_pdf_integrates_to_one(order, g, probability):
    """Over the sphere, by quadrature aligned with the cells (to 1e-9), and by the generic sphere
    quadrature (world-aligned, crossing the cells' edges: to its accuracy) where HG is broad; also
    for zero coefficients (a uniform table)."""
    rng = np.random.default_rng(order + int(10 * abs(g)))
    for trial in range(3):
        coeffs = np.zeros(((order + 1) ** 2, 3)) if trial == 2 else rng.normal(size=((order + 1) ** 2, 3))
        w_in = _unit(rng.normal(size=3))
        w, weights = _cell_aligned_quadrature(w_in, g)
        pdf = gd.direction_pdf(coeffs, w_in, g, SH_WINDOW_NONE, order, probability, w)
        assert pdf.min() > 0.0
        np.testing.assert_allclose(weights @ pdf, 1.0, rtol=1e-9)
        if abs(g) <= 0.6:
            w, weights = sphere_quadrature(200)
            pdf = gd.direction_pdf(coeffs, w_in, g, SH_WINDOW_NONE, order, probability, w)
            np.testing.assert_allclose(weights @ pdf, 1.0, rtol=3e-3)


def test_guided_direction_sampler_histogram_matches_the_pdf(ctx):
    """131072 directions from the GLSL sampler at one event, binned over the sphere in 12 x 16
    world-aligned bins of equal area (crossing the cells' edges): the counts against the pdf's
    integral over each bin (the twin's pdf at the probes' coefficients there, 24 x 24 midpoints
    per bin), by chi-square; and the draws are guided (their spread differs from HG's)."""
    order, g, probability = 2, 0.5, 0.5
    n = 1 << 17
    textures, uniforms = _probe_setup(ctx, order, seed=5, dc=0.6)
    x = np.array([0.2, -0.3, 0.4])
    w_in = _unit(np.array([0.3, -0.5, 0.8]))
    rng = np.random.default_rng(9)
    xi = rng.uniform(0.0, 1.0, (n, 3))
    uniforms = {**uniforms, "g": g, "guided_direction_probability": probability,
                "x": tuple(x), "w_in": tuple(w_in)}
    try:
        w = run_kernel(ctx, SAMPLER_KERNEL, [xi.astype(np.float32).ravel()], (n, 3), count=n,
                       defines={"PROBE_SH_ORDER": order, "PROBE_GREY": 0}, uniforms=uniforms)
        coeffs = _fetch(ctx, x[None], order, uniforms)[0]
    finally:
        for tex in textures:
            tex.release()
    nz, nphi, sub = 12, 16, 24

    def bins(d):
        z = np.clip(((d[:, 2] + 1.0) / 2.0 * nz).astype(int), 0, nz - 1)
        phi = np.arctan2(d[:, 1], d[:, 0]) % (2.0 * np.pi)
        return z * nphi + np.clip((phi / (2.0 * np.pi) * nphi).astype(int), 0, nphi - 1)

    counts = np.bincount(bins(w.astype(np.float64)), minlength=nz * nphi)
    z = -1.0 + 2.0 * (np.arange(nz * sub) + 0.5) / (nz * sub)
    phi = 2.0 * np.pi * (np.arange(nphi * sub) + 0.5) / (nphi * sub)
    s = np.sqrt(1.0 - z * z)
    d = np.stack([s[:, None] * np.cos(phi), s[:, None] * np.sin(phi),
                  np.broadcast_to(z[:, None], (len(z), len(phi)))], -1).reshape(-1, 3)
    pdf = gd.direction_pdf(coeffs, w_in, g, SH_WINDOW_HANN, order, probability, d)
    area = 4.0 * np.pi / len(d)
    expected = n * np.bincount(bins(d), weights=pdf * area, minlength=nz * nphi)
    assert abs(expected.sum() / n - 1.0) < 2e-3
    chi2 = np.sum((counts - expected) ** 2 / expected)
    dof = nz * nphi - 1
    assert chi2 < dof + 5.0 * np.sqrt(2.0 * dof), chi2
    hg_pdf = gd.direction_pdf(coeffs, w_in, g, SH_WINDOW_HANN, order, 0.0, d)
    hg_expected = n * np.bincount(bins(d), weights=hg_pdf * area, minlength=nz * nphi)
    assert np.sum((counts - hg_expected) ** 2 / hg_expected) > 3.0 * chi2 + 100.0


def test_guided_directions_setting_and_the_order_it_bakes(ctx):
    """The setting is a probability; while it is on, `auto` bakes order 2 where g = 0 would give
    0 (order 0 holds no direction), and an explicit order is kept."""
    assert RenderSettings().guided_directions == 0.0    # off: bench/h100-guided-directions
    for bad in (-0.1, 1.5, True, "half", float("nan")):
        with pytest.raises(ValueError, match="guided directions"):
            RenderSettings(guided_directions=bad)
    assert resolve_sh_order("auto", 0.0, directions=True) == 2
    assert resolve_sh_order("auto", 0.0) == 0
    assert resolve_sh_order("auto", 0.8, 4096, directions=True) == resolve_sh_order("auto", 0.8, 4096)
    assert resolve_sh_order(0, 0.0, directions=True) == 0
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.scene import parse_scene
    r = Renderer(ctx, parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                                   "anisotropy": 0.0, "probes": {"grid": [2, 2, 2],
                                                                 "samples": 4}}),
                 settings=RenderSettings(guided_directions=0.5))
    try:
        assert r.probe_plan(region=False).sh_order == 2
        key = r.bake_key()
        r.settings = replace(r.settings, guided_directions=0.0)
        assert r.probe_plan(region=False).sh_order == 0 and r.bake_key() != key
    finally:
        r.release()
