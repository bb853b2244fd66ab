"""The probes' lobe about the sun's direction (glsl/lib/sun_lobe.glsl): its NumPy twin against the
series it is derived from, and the GLSL against the twin.

Tolerances: the twin against Gauss-Legendre quadrature of its Legendre series, 1e-9 (float64);
the GLSL (float32) against the twin, 2e-5 relative to the lobe's peak."""
from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.twins import sun_lobe
from glsl_harness import probe_texel_centres, probe_textures, run_kernel

MU, W = np.polynomial.legendre.leggauss(200)


def legendre_coefficients(values, lmax):
    """f_l = 2 pi int f P_l dmu, so f = sum (2l+1)/(4 pi) f_l P_l (the phase-function convention)."""
    return np.array([2 * np.pi * np.sum(W * values * np.polynomial.legendre.Legendre.basis(l)(MU))
                     for l in range(lmax + 1)])


@pytest.mark.parametrize("h,n", [(0.8, 3), (0.6, 3), (0.9, 2), (0.8, 4)])
def test_twin_is_the_hg_series_above_band_n(h, n):
    r = legendre_coefficients(sun_lobe.residual(MU, h, n), 40)
    want = np.array([0.0 if l <= n else h ** l for l in range(41)])
    np.testing.assert_allclose(r, want, atol=1e-9)
    # <r, r> over the sphere, and the lobe's own projection is amplitude 1
    np.testing.assert_allclose(2 * np.pi * np.sum(W * sun_lobe.residual(MU, h, n) ** 2),
                               sun_lobe.norm(h, n), rtol=1e-9)
    b = sun_lobe.hg(MU, h)
    for g in (1.0, 0.8, 0.6):
        np.testing.assert_allclose(2 * np.pi * np.sum(W * b * sun_lobe.basis(MU, h, n, g)), 1.0,
                                   rtol=1e-9)
    # the phase function HG_g convolved with r: coefficients (g h)^l above band n (Funk-Hecke)
    g = 0.7
    c = legendre_coefficients(sun_lobe.convolved(MU, g, h, n), 40)
    np.testing.assert_allclose(c, [0.0 if l <= n else (g * h) ** l for l in range(41)], atol=1e-9)


KERNEL = """
#include "lib/sun_lobe.glsl"
layout(std430, binding = 0) readonly buffer In { float mu[]; };
layout(std430, binding = 1) writeonly buffer Out { vec2 o[]; };
uniform float phase_g;
uniform int order;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i < count)
        o[i] = vec2(sun_lobe_basis(mu[i], phase_g, sun_lobe_g, order),
                    sun_lobe_convolved(mu[i], phase_g, order));
}
"""


@pytest.mark.parametrize("h,g,n", [(0.8, 0.8, 3), (0.6, 0.9, 3), (0.8, 0.8, 4)])
def test_glsl_against_twin(ctx, h, g, n):
    mu = np.linspace(-1.0, 1.0, 1001)
    got = run_kernel(ctx, KERNEL, [mu.astype(np.float32)], (len(mu), 2),
                     uniforms={"sun_lobe_g": h, "phase_g": g, "order": n})
    basis = sun_lobe.basis(mu, h, n, g)
    conv = sun_lobe.convolved(mu, g, h, n)
    np.testing.assert_allclose(got[:, 0], basis, atol=2e-5 * np.abs(basis).max())
    np.testing.assert_allclose(got[:, 1], conv, atol=2e-5 * np.abs(conv).max())


# ---------------------------------------------------------------------------------------------
# The bake's projection (glsl/probe_project.comp) and the renderers


def _lobe_scene(tmp_path, g, h, amplitude, base, sun):
    """An empty volume under an environment map L(omega) = base + amplitude HG_h(omega . sun):
    every walk escapes at once, so a probe sees exactly the map."""
    from radiance_probes.twins import environment_map as tw
    rows = 96
    v = (np.arange(rows) + 0.5) / rows
    u = (np.arange(2 * rows) + 0.5) / (2 * rows)
    V, U = np.meshgrid(v, u, indexing="ij")
    d = tw.uv_to_direction(U, V)
    s = np.asarray(sun, float) / np.linalg.norm(sun)
    lum = base + amplitude * sun_lobe.hg(d @ s, h)
    path = tmp_path / "lobe.npy"
    np.save(path, np.repeat(lum[..., None], 3, axis=-1).astype(np.float32))
    from radiance_probes.io.scene_file import parse_scene
    return parse_scene({"volume": {"builtin": "empty", "size": [4, 4, 4]}, "anisotropy": g,
                        "environment": {"map": str(path)},
                        "light": {"direction": list(sun), "irradiance": [0, 0, 0]},
                        "probes": {"grid": [2, 2, 2], "samples": 4096, "sh_order": 3},
                        "camera": {"eye": [0, 0, 2], "target": [0, 0, 0], "width": 8, "height": 8}})


def test_bake_projects_the_lobe_and_leaves_the_bands_alone(ctx, tmp_path):
    """Probes that see base + A HG_h(omega . s) hold amplitude A in the lobe's channels (r is
    orthogonal to the bands and to the constant), and the same SH bands as without the lobe."""
    from radiance_probes.rendering.probes.layout import sun_lobe_g
    from radiance_probes.rendering.renderer import Renderer
    g, amplitude = 0.8, 0.7
    h = sun_lobe_g(g, 3)
    assert h == pytest.approx(g ** 3)
    scene = _lobe_scene(tmp_path, g, h, amplitude, 0.4, (-0.3, 0.35, -0.89))
    r = Renderer(ctx, scene)
    r.configure(walk_adaptive=0.0)   # every probe takes all its walks
    try:
        r.bake(seed=5)
        with_lobe = r.probe_grid.coefficients()
        assert r.probe_grid.sun_lobe == pytest.approx(h)
        r.configure(sun_lobe=False)
        r.bake(seed=5)
        without = r.probe_grid.coefficients()
        assert r.probe_grid.sun_lobe == 0.0
    finally:
        r.release()
    # The walks' rotated 64-point Fibonacci sets integrate the lobe's high bands with a spread of
    # 0.22 a pass (NumPy, 2000 sets): 0.028 over 64 passes, 0.01 over the 8 probes' mean.
    lobe = with_lobe[..., 49:52]
    assert abs(lobe.mean() - amplitude) < 0.04
    np.testing.assert_allclose(lobe, amplitude, atol=0.12)
    np.testing.assert_array_equal(with_lobe[..., :49], without[..., :49])
    np.testing.assert_array_equal(without[..., 49:52], 0.0)


@pytest.mark.parametrize("method", ["raymarch", "probes"])
def test_furnace_with_the_lobe_returns_the_environment(ctx, method):
    """A white furnace (albedo 1, every direction the same radiance): the lobe's projection is
    0 up to the quadrature of the walks' directions, and the image is the environment."""
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    env = [0.3, 0.6, 0.9]
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [16, 12, 14]}, "anisotropy": 0.8,
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "albedo": 1.0, "density_scale": 40.0, "environment": env,
                         "max_bounces": 100000, "light": {"irradiance": [0, 0, 0]},
                         "probes": {"grid": [4, 4, 4], "samples": 128, "sh_order": 3},
                         "camera": {"eye": [0.0, 0.2, 1.3], "target": [0, 0, 0], "fov_y": 40.0,
                                    "width": 16, "height": 16}})
    r = Renderer(ctx, scene)
    try:
        result = r.render(method, spp=4)
        assert r.probe_grid.sun_lobe > 0
        np.testing.assert_allclose(result.image, np.broadcast_to(env, result.image.shape),
                                   rtol=1e-2)
    finally:
        r.release()


def test_sun_lobe_g_rule():
    from radiance_probes.rendering.probes.layout import sun_lobe_g
    assert sun_lobe_g(0.8, 3) == pytest.approx(0.512)
    assert sun_lobe_g(0.8, 2) == 0.0 and sun_lobe_g(0.8, 4) == 0.0
    assert sun_lobe_g(-0.8, 3) == 0.0 and sun_lobe_g(0.5, 3) == 0.0


INSCATTER_KERNEL = """
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/lights.glsl"
#include "lib/directions.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
layout(std430, binding = 0) readonly buffer In { float q[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 x = vec3(q[6u * i], q[6u * i + 1u], q[6u * i + 2u]);
    vec3 d = vec3(q[6u * i + 3u], q[6u * i + 4u], q[6u * i + 5u]);
    float sun;
    vec3 v = probe_inscattered(x, d, sun);
    o[3u * i] = v.r; o[3u * i + 1u] = v.g; o[3u * i + 2u] = v.b;
}
"""


def test_probe_inscattered_adds_the_convolved_lobe(ctx):
    """lib/probes.glsl probe_inscattered with PROBE_SUN_LOBE at the probes' texel centres, against
    NumPy: the convolved bands of the unpacked coefficients plus the lobe's amplitude (channels
    49 .. 51) times the convolved residual at d . s, clamped at 0."""
    from radiance_probes.rendering.probes.layout import TEXTURES_FOR_ORDER, colour_channel
    from radiance_probes.rendering.probes.bake import probe_unit
    from radiance_probes.twins.sh import sh_band_factors, sh_basis
    grid, order, g, h, scale = (3, 2, 2), 3, 0.8, 0.512, 2.0
    count = grid[0] * grid[1] * grid[2]
    ids = TEXTURES_FOR_ORDER[order]
    rng = np.random.default_rng(3)
    texels = {t: rng.uniform(-0.05, 0.05, (count, 4)).astype(np.float32) for t in ids}
    texels[0][:, :3] = rng.uniform(0.5, 1.0, (count, 3))   # L00 keeps most results positive
    texels[12][:, 1:] = rng.uniform(2.0, 5.0, (count, 3))  # the lobe
    textures = probe_textures(ctx, grid, texels)
    x = probe_texel_centres(grid)
    sun = np.array([-0.3, 0.35, -0.89]) / np.linalg.norm([-0.3, 0.35, -0.89])
    d = rng.normal(size=(count, 3))
    d[:4] = sun                               # the lobe's peak
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    try:
        out = run_kernel(ctx, INSCATTER_KERNEL, [np.concatenate([x, d], 1).astype(np.float32).ravel()],
                         (count, 3), count=count,
                         defines={"PROBE_SH_ORDER": order, "PROBE_GREY": 0, "PROBE_SUN_LOBE": 1},
                         uniforms={"probe_textures": tuple(probe_unit(t) for t in ids),
                                   "probe_grid": grid, "probe_box_min": (-1.0, -1.0, -1.0),
                                   "probe_box_size": (2.0, 2.0, 2.0), "probe_radiance_scale": scale,
                                   "probe_band_factors": tuple(sh_band_factors(g, 0, order)),
                                   "sun_direction": tuple(sun), "sun_lobe_g": h,
                                   "sun_lobe_phase_g": g})
    finally:
        for tex in textures:
            tex.release()
    channel = {4 * t + c: texels[t][:, c].astype(np.float64) for t in ids for c in range(4)}
    coeffs = np.stack([np.stack([channel[colour_channel(k, c)] for c in range(3)], -1)
                       for k in range(16)], 1) * scale                      # (count, 16, 3)
    factors = np.repeat(sh_band_factors(g, 0, order), [1, 3, 5, 7])
    bands = np.einsum("nk,nkc->nc", sh_basis(d, order) * factors, coeffs)
    lobe = np.stack([channel[colour_channel(16, c)] for c in range(3)], -1) * scale
    expected = np.maximum(bands + lobe * sun_lobe.convolved(d @ sun, g, h, order)[:, None], 0.0)
    np.testing.assert_allclose(out, expected, rtol=1e-4, atol=1e-5)
    assert (lobe[:4] * sun_lobe.convolved(1.0, g, h, order)).min() > 0.05   # the lobe shows


def test_every_program_that_reads_lobe_probes_compiles(ctx):
    """The passes and the viewer's probe spheres build with PROBE_SUN_LOBE (the spheres' program
    once lacked the sun's direction the lobe needs)."""
    from radiance_probes.gl.shaders import compute_program, render_program
    defines = {"PROBE_SH_ORDER": 3, "PROBE_SUN_LOBE": 1}
    for grey in (0, 1):
        d = {**defines, "PROBE_GREY": grey}
        render_program(ctx, "probe_sphere_instanced.vert", "probe_sphere.frag", d).release()
        compute_program(ctx, "raymarch.comp", d).release()
        render_program(ctx, "fullscreen.vert", "raymarch.frag", d).release()
        compute_program(ctx, "pathtrace.comp", {**d, "PROBE_LIGHTING": 1}).release()
        compute_program(ctx, "pathtrace.comp", {**d, "PROBE_LIGHTING": 2}).release()


# ---------------------------------------------------------------------------------------------
# The lobe's shape chosen per scene (lab/sun_lobe_fit.py, lab/sun_lobe_fit.comp: an experiment's,
# outside the package since it left the product)


def _lab_fit():
    import sys
    from pathlib import Path
    root = str(Path(__file__).resolve().parents[1])
    if root not in sys.path:
        sys.path.insert(0, root)
    import lab.sun_lobe_fit
    return lab.sun_lobe_fit

DIRECTIONS_KERNEL = """
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
layout(std430, binding = 0) writeonly buffer Out { vec4 o[]; };
uniform uint directions;
uniform uint walk_seed;
uniform uint walk_pass;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i < count)
        o[i] = vec4(probe_walk_direction(i / directions, walk_pass, i % directions, directions,
                                         walk_seed), 0.0);
}
"""


def test_lobe_amplitudes_glsl_against_twin(ctx):
    import moderngl
    from radiance_probes.gl.shaders import compute_program, set_uniforms
    probes, directions, seed, pass_index, g = 37, 64, 12345, 1, 0.8
    hs = (0.64, 0.512, 0.4096)
    dirs = run_kernel(ctx, DIRECTIONS_KERNEL, [], (probes * directions, 4),
                      uniforms={"directions": directions, "walk_seed": seed,
                                "walk_pass": pass_index},
                      count=probes * directions, defines={"PROBE_SH_ORDER": 3, "PROBE_GREY": 0})
    sun = np.array([-0.3, 0.35, -0.89])
    sun /= np.linalg.norm(sun)
    mu = (dirs[:, :3].astype(np.float64) @ sun).reshape(probes, directions)
    rng = np.random.default_rng(7)
    radiance = (0.3 + rng.uniform(size=(probes, directions, 3))
                + 2.0 * sun_lobe.hg(mu, 0.6)[..., None]).astype(np.float32)
    valid = rng.uniform(size=(probes, directions)) > 0.05
    walks = np.concatenate([radiance, np.where(valid, 1.0, 2.0)[..., None]], axis=-1)
    fit = _lab_fit()
    program = compute_program(ctx, "sun_lobe_fit.comp", {"PROBE_SH_ORDER": 3, "PROBE_GREY": 0,
                                                         "PROBE_SUN_LOBE": 1,
                                                         "SUN_LOBE_CANDIDATES": len(hs)},
                              text=fit.SHADER.read_text())
    first = 5   # outputs before this one's
    walk_buffer = ctx.buffer(walks.astype(np.float32).tobytes())
    out = ctx.buffer(reserve=16 * (first + probes * len(hs)))
    try:
        set_uniforms(program, {"probe_count": probes, "directions": directions, "seed": seed,
                               "pass_index": pass_index, "first_output": first,
                               "candidate_h": hs, "sun_lobe_g": hs[0], "sun_lobe_phase_g": g,
                               "sun_direction": tuple(sun)})
        walk_buffer.bind_to_storage_buffer(3)
        out.bind_to_storage_buffer(0)
        program.run((probes + 63) // 64)
        ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        got = np.frombuffer(out.read(), np.float32).reshape(-1, 4)[first:].reshape(probes, len(hs), 4)
    finally:
        walk_buffer.release()
        out.release()
        program.release()
    want, count = fit.lobe_amplitudes(mu, radiance, valid, hs, g, 3)
    assert np.abs(want).max() > 0
    np.testing.assert_allclose(got[..., :3], want, rtol=1e-4, atol=1e-4 * np.abs(want).max())
    np.testing.assert_array_equal(got[..., 3], np.repeat(count[:, None], len(hs), axis=1))


def test_fit_gains_twin_on_synthetic_amplitudes():
    """Two independent noisy estimates of known amplitudes: the gain estimate is unbiased for the
    error each lobe takes out less the noise of a bake of main_walks walks."""
    rng = np.random.default_rng(3)
    hs, g, n = (0.64, 0.512), 0.8, 3
    true = np.stack([np.full((4000, 3), 0.5), np.full((4000, 3), 0.8)], axis=1)
    sigma = np.array([0.6, 0.3])[None, :, None]   # one pass's noise per candidate
    a = true + sigma * rng.standard_normal(true.shape)
    b = true + sigma * rng.standard_normal(true.shape)
    gains = _lab_fit().fit_gains(a, b, hs, g, n, pilot_walks=64, main_walks=256)
    norms = np.array([sun_lobe.norm(g * h, n) for h in hs])
    want = norms * 4000 * 3 * (np.array([0.25, 0.64]) - np.array([0.36, 0.09]) * 64 / 256)
    np.testing.assert_allclose(gains, want, rtol=0.05)


@pytest.mark.parametrize("power", [2, 4])
def test_fit_chooses_the_lobe_the_probes_see(ctx, tmp_path, power, monkeypatch):
    """Probes under an environment map base + A HG_h(omega . s): the pilot picks h among g^2, g^3
    and g^4 (the error the lobe removes is largest for the lobe that is there), and a bake with
    its power (as lab/experiments/experiment_sun_lobe.py sets it) holds it."""
    from radiance_probes.rendering.probes import layout as probe_layout
    from radiance_probes.rendering.renderer import Renderer
    g = 0.8
    scene = _lobe_scene(tmp_path, g, g ** power, 0.7, 0.4, (-0.3, 0.35, -0.89))
    scene = scene.replace(probes=replace(scene.probes, grid=(8, 8, 8), samples=256))
    r = Renderer(ctx, scene)
    fitter = _lab_fit().SunLobeFitter(ctx)
    try:
        fit = fitter.fit_for(r, seed=3)
        assert fit.candidates == pytest.approx((g ** 2, g ** 3, g ** 4))
        assert fit.h == pytest.approx(g ** power), fit
        assert fit.power == pytest.approx(power)
        monkeypatch.setattr(probe_layout, "SUN_LOBE_POWER", fit.power)
        r.bake(seed=3)
        assert r.probe_grid.sun_lobe == pytest.approx(g ** power)
    finally:
        fitter.release()
        r.release()
