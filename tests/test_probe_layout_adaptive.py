"""The adaptive probe layout: per-axis probe planes (app/rendering/probes/planes.py) read through the
warp of glsl/lib/probe_warp.glsl, against its NumPy twin app/twins/probe_warp.py.

Tolerances
----------
* The warp table and the planes are float32; llvmpipe filters float textures with float weights,
  so probe_warp_uvw matches the twin's linear filter to 2e-6 and the planes exactly.
* probe_fetch against the twin (the table, then GL's trilinear filter): 2e-5 relative on values
  in [0, 1]; against exact trilinear interpolation between the probes at their real positions,
  the table's own error: at most about n / 16384 of a texel times the value's spread.
* The identity warp against the uniform grid's shaders: the same probes up to the float32
  rounding of the positions ((i + 0.5) / n computed on the host), so images within 1e-4.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.rendering.probes.planes import (MAX_SPACING, MIN_SPACING, adaptive_planes,
                                                     planes_from_density, probe_density)
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import SceneError, parse_scene
from radiance_probes.twins.probe_warp import (WARP_COLUMNS, probe_fractions, texture_trilinear,
                                              uniform_planes, warp_exact, warp_lookup, warp_table)
from radiance_probes.viewer.probe_view import probe_centres
from glsl_harness import PROBE_FETCH_KERNEL, run_kernel

HALF = (0.5, 0.5, 0.5)
WHITE = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}
CAMERA = {"eye": [0.0, 0.2, 1.3], "target": [0, 0, 0], "fov_y": 40.0, "width": 16, "height": 16}
UNIT = 14


def slab_field(n: int = 16, axis: int = 1, lo: int = 7, hi: int = 9, background: float = 0.1):
    """A field (z, y, x) that is `background` but 1 in the slab lo <= index < hi along `axis`."""
    f = np.full((n, n, n), background, np.float32)
    index = [slice(None)] * 3
    index[2 - axis] = slice(lo, hi)
    f[tuple(index)] = 1.0
    return f


def _slab_planes(grid=(5, 3, 7)):
    f = slab_field(16, axis=1)
    f[:, :, 2:5] += 0.5        # a step along x too
    f[11:, :, :] *= 0.3        # and along z
    planes = adaptive_planes(f, HALF, None, grid, 0.9)
    assert planes is not None and all(
        not np.allclose(p, uniform_planes(n)) for p, n in zip(planes, grid))
    return planes


# ---------------------------------------------------------------------------------------------
# (a) the GLSL against its twin

WARP_KERNEL = """
#include "lib/probe_warp.glsl"
layout(std430, binding = 0) readonly buffer In { float s[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 uvw = probe_warp_uvw(vec3(s[3u * i], s[3u * i + 1u], s[3u * i + 2u]));
    vec3 p = probe_warp_plane_fractions(uvec3(i % 256u));
    o[6u * i] = uvw.x; o[6u * i + 1u] = uvw.y; o[6u * i + 2u] = uvw.z;
    o[6u * i + 3u] = p.x; o[6u * i + 4u] = p.y; o[6u * i + 5u] = p.z;
}
"""


def _warp_texture(ctx, planes):
    import moderngl
    table = warp_table(planes)
    tex = ctx.texture((table.shape[1], table.shape[0]), 1, table.tobytes(), dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    tex.use(UNIT)
    return tex, table


def test_warp_and_planes_match_the_twin(ctx):
    planes = _slab_planes()
    tex, table = _warp_texture(ctx, planes)
    rng = np.random.default_rng(1)
    s = np.concatenate([rng.uniform(-0.1, 1.1, (4000, 3)),
                        np.stack([np.asarray(p)[np.arange(3000) % len(p)]
                                  for p in planes], -1)])   # exactly at the planes too
    n = len(s)
    out = run_kernel(ctx, WARP_KERNEL, [s.astype(np.float32).ravel()], (n, 6),
                     uniforms={"probe_warp": UNIT}, defines={"PROBE_WARP": 1}, count=n)
    tex.release()
    s32 = s.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(out[:, :3], warp_lookup(table, s32), atol=2e-6)
    # the table against the exact piecewise-linear warp: within n / columns of a texel
    exact = np.stack([warp_exact(planes[a], s32[:, a]) for a in range(3)], -1)
    assert np.abs(out[:, :3] - exact).max() < 2e-6 + 1.5 / WARP_COLUMNS
    # at a plane, its texel centre
    at = s32[4000:]
    for a, p in enumerate(planes):
        k = np.arange(3000) % len(p)
        np.testing.assert_allclose(out[4000:, a], (k + 0.5) / len(p), atol=2e-6 + 1.5 / WARP_COLUMNS)
        assert np.allclose(at[:, a], np.asarray(p, np.float32)[k])
        # the planes row (texelFetch) is exact, zero beyond the last plane
        i = np.arange(n) % 256
        expected = np.where(i < len(p), np.asarray(p + (0.0,) * 256, np.float32)[np.minimum(i, 255)], 0)
        np.testing.assert_array_equal(out[:, 3 + a], expected)


POSITION_KERNEL = """
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
layout(std430, binding = 0) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 p = probe_position(i);
    o[3u * i] = p.x; o[3u * i + 1u] = p.y; o[3u * i + 2u] = p.z;
}
"""


@pytest.mark.parametrize("warp", [0, 1])
def test_probe_position_matches_the_probe_view(ctx, warp):
    """probe_position (bake) and probe_centres (the viewer's spheres) put the probes at the same
    places, the adaptive planes where PROBE_WARP is 1."""
    grid = (5, 3, 7)
    planes = _slab_planes(grid) if warp else None
    box = ((-0.4, -0.3, -0.45), (0.35, 0.2, 0.5))
    tex = _warp_texture(ctx, planes)[0] if warp else None
    n = grid[0] * grid[1] * grid[2]
    low, high = np.asarray(box[0]), np.asarray(box[1])
    out = run_kernel(ctx, POSITION_KERNEL, [], (n, 3), count=n, defines={"PROBE_WARP": warp},
                     uniforms={"probe_warp": UNIT, "probe_grid": grid,
                               "probe_box_min": tuple(low), "probe_box_size": tuple(high - low)})
    if tex is not None:
        tex.release()
    np.testing.assert_allclose(out, probe_centres(grid, HALF, box, planes), atol=2e-6)
    if warp:   # not the uniform grid's
        assert np.abs(out - probe_centres(grid, HALF, box)).max() > 0.02


def test_probe_fetch_blends_the_probes_at_their_positions(ctx):
    """probe_fetch with an adaptive layout is GL's trilinear filter at the warped coordinates (the
    twin), which is trilinear interpolation between the 8 surrounding probes at their real
    positions (computed here on its own, by searching the planes), up to the table's error."""
    import moderngl
    grid = (5, 3, 7)
    planes = _slab_planes(grid)
    rng = np.random.default_rng(2)
    values = rng.random((grid[2], grid[1], grid[0], 4)).astype(np.float32)
    probe_tex = ctx.texture3d(grid, 4, values.tobytes(), dtype="f4")
    probe_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    probe_tex.repeat_x = probe_tex.repeat_y = probe_tex.repeat_z = False
    probe_tex.use(2)
    warp_tex, table = _warp_texture(ctx, planes)
    box = ((-0.4, -0.3, -0.45), (0.35, 0.2, 0.5))
    low, size = np.asarray(box[0]), np.asarray(box[1]) - np.asarray(box[0])
    s = rng.uniform(-0.1, 1.1, (5000, 3))
    x = (low + s * size).astype(np.float32)
    out = run_kernel(ctx, PROBE_FETCH_KERNEL, [x.ravel()], (len(x), 3 * 9 + 1),
                     defines={"PROBE_WARP": 1, "PROBE_GREY": 1, "PROBE_SH_ORDER": 0},
                     uniforms={"probe_warp": UNIT, "probe_textures": (2,), "probe_grid": grid,
                               "probe_box_min": tuple(low), "probe_box_size": tuple(size),
                               "probe_band_factors": (1.0, 1.0, 1.0),
                               "probe_radiance_scale": 2.0})
    probe_tex.release()
    warp_tex.release()
    s32 = (x.astype(np.float64) - low) / size
    uvw = warp_lookup(table, s32)
    # coefficients come back times probe_radiance_scale, the sun's transmittance as stored (last)
    for channel, column, scale in ((0, 0, 2.0), (3, -1, 1.0)):
        twin = scale * texture_trilinear(values[..., channel].astype(np.float64), uvw)
        np.testing.assert_allclose(out[:, column], twin, rtol=2e-5, atol=2e-6)
        # on its own: weights from the planes bracketing each point, clamped beyond the outer ones
        independent = np.zeros(len(x))
        idx, wts = [], []
        for a in range(3):
            p = np.asarray(planes[a])
            t = np.clip(s32[:, a], p[0], p[-1])
            i0 = np.clip(np.searchsorted(p, t, side="right") - 1, 0, len(p) - 2)
            idx.append(i0)
            wts.append((t - p[i0]) / (p[i0 + 1] - p[i0]))
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = ((wts[0] if dx else 1 - wts[0]) * (wts[1] if dy else 1 - wts[1])
                         * (wts[2] if dz else 1 - wts[2]))
                    independent += scale * w * values[idx[2] + dz, idx[1] + dy, idx[0] + dx,
                                                      channel]
        assert np.abs(out[:, column] - independent).max() < 3 * 1.5 * max(grid) / WARP_COLUMNS


# ---------------------------------------------------------------------------------------------
# (b) uniform layouts

SCENE = {"volume": {"builtin": "cloud", "size": [16, 12, 14]}, "camera": CAMERA,
         "density_scale": 30.0, "probes": {"grid": [4, 3, 5], "samples": 64}}


def _with_probes(scene: dict, **probes) -> dict:
    return {**scene, "probes": {**scene["probes"], **probes}}


def test_strength_zero_or_a_constant_indicator_gives_the_uniform_layout_exactly(ctx):
    """No warp at all (the uniform grid's shaders, bit for bit): strength 0, or an indicator
    without variation (a constant volume, a constant field)."""
    assert adaptive_planes(np.full((8, 8, 8), 0.3, np.float32), HALF, None, (4, 4, 4), 1.0) is None
    assert adaptive_planes(slab_field(), HALF, None, (4, 4, 4), 0.0) is None
    assert probe_density(np.ones(32), 0.7) is None and probe_density(np.zeros(32), 0.7) is None
    # a slab across y moves only the y planes: x and z stay exactly uniform
    planes = adaptive_planes(slab_field(), HALF, None, (4, 6, 5), 0.5)
    assert planes[0] == tuple(uniform_planes(4)) and planes[2] == tuple(uniform_planes(5))
    images = {}
    for name, scene in (("uniform", SCENE),
                        ("strength 0", _with_probes(SCENE, layout="adaptive", adaptive_strength=0)),
                        ("constant", _with_probes({**SCENE, "volume": {"builtin": "constant",
                                                                       "size": [8, 8, 8]}},
                                                  layout="adaptive", adaptive_strength=1.0)),
                        ("constant uniform", {**SCENE, "volume": {"builtin": "constant",
                                                                  "size": [8, 8, 8]}})):
        r = Renderer(ctx, parse_scene(scene))
        images[name] = r.render("raymarch", spp=1).image
        assert r.probe_grid.planes is None and "PROBE_WARP" not in r.probe_grid.defines()
        r.release()
    np.testing.assert_array_equal(images["strength 0"], images["uniform"])
    np.testing.assert_array_equal(images["constant"], images["constant uniform"])


@pytest.mark.parametrize("method", ["probes-only", "raymarch"])
def test_identity_warp_reproduces_the_uniform_image(ctx, method, monkeypatch):
    """The warp's code path with evenly spaced planes (forced) against the uniform grid's shaders:
    the same bake (walks from the same places) and the same image within float32 rounding."""
    out = {}
    for layout in ("uniform", "adaptive"):
        r = Renderer(ctx, parse_scene(_with_probes(SCENE, layout=layout)))
        monkeypatch.setattr(r, "adaptive_planes",
                            lambda grid, box: tuple(tuple(uniform_planes(n)) for n in grid))
        r.configure(raymarch_stage="compute")
        out[layout] = (r.render(method, spp=4).image, r.probe_grid.coefficients())
        assert (r.probe_grid.planes is not None) == (layout == "adaptive")
        assert r.probe_grid.defines().get("PROBE_WARP", 0) == (layout == "adaptive")
        r.release()
    (img_u, c_u), (img_a, c_a) = out["uniform"], out["adaptive"]
    assert img_u.max() > 0
    np.testing.assert_allclose(c_a, c_u, rtol=1e-4, atol=1e-5 * np.abs(c_u).max())
    np.testing.assert_allclose(img_a, img_u, rtol=1e-4, atol=1e-5 * img_u.max())


# ---------------------------------------------------------------------------------------------
# (c) where the planes go

@pytest.mark.parametrize("n", [3, 4, 8, 16, 64])
@pytest.mark.parametrize("strength", [0.25, 0.5, 1.0])
def test_a_slab_draws_planes_and_the_spacing_stays_within_bounds(n, strength):
    """More planes in the slab (spacing there below the uniform one, and the more so with a higher
    strength), every spacing within [MIN_SPACING, MAX_SPACING] times the uniform one, also for
    random fields; planes at equal quantiles of the density."""
    planes = adaptive_planes(slab_field(32, axis=2, lo=20, hi=23), HALF, None, (n, n, n), strength)
    z = np.asarray(planes[2])
    assert planes[0] == tuple(uniform_planes(n)) and planes[1] == tuple(uniform_planes(n))
    gaps = []
    for face in (20 / 32, 23 / 32):   # where sigma_t steps
        i = int(np.searchsorted(z, face))
        assert 0 < i < n, z                                   # planes on both sides of it
        gaps.append((z[i] - z[i - 1]) * n)                    # in uniform spacings
    # closer than the uniform spacing at both faces; with 3 or 4 planes at one of them at least
    # (measured at 4 planes, strength 1: 1.07 and 0.32, the other planes spread out)
    assert max(gaps) < 1.0 if n >= 8 else min(gaps) < 1.0, gaps
    rng = np.random.default_rng(n)
    for field in (slab_field(32, axis=2, lo=20, hi=23), rng.random((24, 20, 28)) ** 6,
                  np.pad(np.ones((2, 2, 2)), 11)):
        planes = adaptive_planes(field, HALF, None, (n, n, n), strength)
        for p in planes or ():
            p = np.asarray(p)
            spacing = np.diff(np.concatenate([[-p[0]], p, [2 - p[-1]]])) * n   # ends mirrored
            assert spacing.min() >= MIN_SPACING * (1 - 1e-9)
            assert spacing.max() <= MAX_SPACING * (1 + 1e-9)
            assert np.all(np.diff(p) > 0)


def test_stronger_mixing_concentrates_more():
    z = [np.asarray(adaptive_planes(slab_field(32, axis=2, lo=20, hi=23), HALF, None, (8, 8, 8),
                                    s)[2]) for s in (0.2, 0.5, 0.9)]
    inner = [np.diff(p)[(p[:-1] > 0.55) & (p[1:] < 0.8)] for p in z]
    assert inner[0].mean() > inner[1].mean() > inner[2].mean()


def test_planes_sit_at_the_density_quantiles():
    density = np.array([1.0, 1.0, 4.0, 4.0, 1.0, 1.0, 0.5, 0.5])
    p = planes_from_density(density, 6)
    cumulative = np.concatenate([[0], np.cumsum(density)]) / density.sum()
    np.testing.assert_allclose(np.interp(p, np.linspace(0, 1, 9), cumulative),
                               (np.arange(6) + 0.5) / 6, atol=1e-12)
    np.testing.assert_allclose(planes_from_density(np.ones(40), 5), uniform_planes(5), atol=1e-15)


def test_a_probe_box_restricts_the_indicator_to_it():
    """The indicator counts only what lies in the probe box (fit "visible"): a slab outside it
    changes nothing, and plane fractions are fractions of the box."""
    f = slab_field(32, axis=0, lo=2, hi=4)            # near the -x face
    box = ((-0.2, -0.5, -0.5), (0.5, 0.5, 0.5))       # which it lies outside of
    assert adaptive_planes(f, HALF, box, (4, 4, 4), 1.0) is None
    f[:, :, 20:22] = 1.0                              # a slab inside
    p = np.asarray(adaptive_planes(f, HALF, box, (6, 4, 4), 1.0)[0])
    slab = (np.array([20, 22]) / 32 - 0.5 - box[0][0]) / (box[1][0] - box[0][0])
    assert ((p > slab[0] - 0.1) & (p < slab[1] + 0.1)).sum() >= 3


# ---------------------------------------------------------------------------------------------
# (d) white furnace

@pytest.mark.parametrize("indicator", ["extinction", "sun"])
def test_furnace_stays_exact_with_an_adaptive_layout(ctx, indicator):
    """Albedo 1, a uniform environment, no sun: every probe holds environment x sqrt(4 pi) wherever
    the adaptive layout put it, and the raymarched image (probes read through the warp) is the
    environment."""
    env = [0.3, 0.6, 0.9]
    scene = {"volume": {"builtin": "cloud", "size": [12, 10, 8]}, "transfer_function": WHITE,
             "albedo": 1.0, "density_scale": 40.0, "environment": env, "max_bounces": 100000,
             "light": {"direction": [0.3, 1.0, 0.2], "irradiance": [0, 0, 0]}, "camera": CAMERA,
             "probes": {"grid": [3, 4, 2], "samples": 128, "layout": "adaptive",
                        "adaptive_strength": 1.0, "adaptive_indicator": indicator}}
    if indicator == "sun":   # a sun of no strength still casts its (unlit) transmittance
        scene["light"]["irradiance"] = [0, 0, 0]
    r = Renderer(ctx, parse_scene(scene))
    try:
        image = r.render("raymarch", spp=2).image
        assert r.probe_grid.planes is not None
        l00 = r.probe_grid.coefficients()[..., 0:3]
        np.testing.assert_allclose(l00, np.broadcast_to(np.asarray(env) * math.sqrt(4 * math.pi),
                                                        l00.shape), rtol=1e-5)
        np.testing.assert_allclose(image, np.broadcast_to(env, image.shape), rtol=1e-4)
        assert r.resources.read_stats()["truncated_paths"] == 0
    finally:
        r.release()


# ---------------------------------------------------------------------------------------------
# (e) a sharp feature: the error against a path-traced reference


def test_adaptive_layout_lowers_the_error_on_a_thin_dense_slab(ctx, tmp_path):
    """A thin dense slab in a thin medium, lit by the sun: the light steps at the slab. At 4 probes
    per axis the adaptive layout (extinction, strength 0.8) puts two y planes at the slab's faces
    and the probes image's relative RMSE against a converged path tracer falls from about 0.25 to
    0.07 (32 x 32, 16384 spp reference; lab/experiments/experiment_adaptive_layout.py has the sweep);
    here, smaller, it must at least fall by a third."""
    d = np.full((16, 16, 16), 0.1, np.float32)
    d[:, 7:9, :] = 1.0
    np.save(tmp_path / "slab.npy", d)
    scene = {"volume": {"path": str(tmp_path / "slab.npy")}, "density_scale": 40.0,
             "transfer_function": WHITE, "albedo": 0.9, "max_bounces": 16,
             "environment": [0.05, 0.05, 0.05],
             "light": {"direction": [0.3, 1.0, 0.2], "irradiance": [3, 3, 3]},
             "camera": {"eye": [1.3, 0.1, 0.9], "target": [0, 0, 0], "fov_y": 45.0,
                        "width": 16, "height": 16},
             "probes": {"grid": 4, "samples": 128, "fit": "box", "adaptive_strength": 0.8}}
    r = Renderer(ctx, parse_scene(scene))
    ref = r.render("pt", spp=2048, samples_per_pass=512).image
    errors = {}
    for layout in ("uniform", "adaptive"):
        r.set_scene(parse_scene(_with_probes(scene, layout=layout)))
        image = r.render("probes", spp=128, samples_per_pass=64).image
        errors[layout] = float(np.sqrt(np.mean((image - ref) ** 2) / np.mean(ref ** 2)))
    r.release()
    assert errors["adaptive"] < 0.67 * errors["uniform"], errors


# ---------------------------------------------------------------------------------------------
# the scene's options and the bake key

def test_scene_options_are_checked():
    s = parse_scene({"probes": {"layout": "adaptive", "adaptive_strength": 0.3,
                                "adaptive_indicator": "sun"}})
    assert (s.probes.layout, s.probes.adaptive_strength, s.probes.adaptive_indicator) == (
        "adaptive", 0.3, "sun")
    assert parse_scene({}).probes.layout == "uniform"
    assert parse_scene(s.to_dict()) == s
    for probes, message in (({"layout": "warped"}, "probes.layout: expected one of uniform, adaptive"),
                            ({"adaptive_strength": 1.5}, "probes.adaptive_strength: must be <= 1.0"),
                            ({"adaptive_strength": -0.1}, "probes.adaptive_strength: must be >= 0.0"),
                            ({"adaptive_strength": "high"}, "probes.adaptive_strength: expected a number"),
                            ({"adaptive_indicator": "gradient"},
                             "probes.adaptive_indicator: expected one of extinction, sun")):
        with pytest.raises(SceneError, match=message):
            parse_scene({"probes": probes})


def test_layout_changes_rebake(ctx):
    r = Renderer(ctx, parse_scene(SCENE))
    r.bake()
    assert r.probes_current() and r.probe_grid.planes is None
    for change in ({"layout": "adaptive"}, {"layout": "adaptive", "adaptive_strength": 0.9},
                   {"layout": "adaptive", "adaptive_strength": 0.9, "adaptive_indicator": "sun"}):
        before = r.probe_grid.planes
        r.set_scene(parse_scene(_with_probes(SCENE, **change)))
        assert not r.probes_current()
        r.bake()
        assert r.probe_grid.planes is not None and r.probe_grid.planes != before
    r.release()


def test_fragment_raymarch_reads_the_warp_too(ctx):
    images = {}
    for stage in ("compute", "fragment"):
        r = Renderer(ctx, parse_scene(_with_probes(SCENE, layout="adaptive",
                                                   adaptive_strength=1.0)))
        r.configure(raymarch_stage=stage)
        images[stage] = r.render("raymarch", spp=2).image
        assert r.probe_grid.planes is not None
        r.release()
    np.testing.assert_allclose(images["fragment"], images["compute"], rtol=1e-5, atol=1e-6)


def test_probe_fractions_follow_index_order():
    planes = ((0.1, 0.5), (0.2, 0.3, 0.9), (0.7,))
    f = probe_fractions((2, 3, 1), planes)
    assert f.shape == (6, 3)
    np.testing.assert_array_equal(f[1], [0.5, 0.2, 0.7])
    np.testing.assert_array_equal(f[2], [0.1, 0.3, 0.7])
