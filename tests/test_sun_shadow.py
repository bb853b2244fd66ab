"""The sun's shadow ray (lib/sun_shadow.glsl, twin app/twins/sun_shadow.py): ratio tracking, or
residual ratio tracking with the light grid's optical depth as the control
(RenderSettings.shadow_tracking). The twin's mean is exp(-integral) on a known medium for right and
wrong controls; the GLSL's estimates agree with the twin's in mean and variance on a cloud, and a
shadow ray cut into chunks (resumed) gives the same estimates as one uncut; the path tracer's mean
with residual shadow rays is the ratio-tracking path tracer's with the light grid as baked, ten
times too deep and zero (as tests/test_guided.py does for wrong probes); the bake's walks take it
too."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins.light_grid import light_grid_optical_depth
from radiance_probes.twins.medium import box_intersect, sigma_t_at
from radiance_probes.twins.sun_shadow import sun_transmittance
from glsl_harness import run_kernel
from test_guided import SCENE as GUIDED_SCENE, _z

# ---------------------------------------------------------------------------------------------
# the twin on a known medium

L = 1.5


def _sigma(t):
    return 3.0 + 2.0 * np.sin(5.0 * t)


def _depth(t):
    """The exact optical depth from t to L."""
    t = np.asarray(t, np.float64)
    return 3.0 * (L - t) + 0.4 * (np.cos(5.0 * t) - np.cos(5.0 * L))


EDGES = np.array([0.0, 0.5, 1.0, L])
MAJORANTS = np.array([5.0, 5.0, 5.0])
EXACT = float(np.exp(-_depth(0.0)))


@pytest.mark.parametrize("control", ["exact", "times ten", "zero", "reversed", "none"])
def test_twin_mean_is_the_transmittance_whatever_the_control(control):
    depth = {"exact": _depth, "times ten": lambda t: 10.0 * _depth(t),
             "zero": lambda t: 0.0 * np.asarray(t), "reversed": lambda t: _depth(L - np.asarray(t)),
             "none": None}[control]
    n = 200_000
    est = sun_transmittance(_sigma, EDGES, MAJORANTS, depth, 0.05, n, np.random.default_rng(7))
    assert np.all(np.isfinite(est)) and np.all(est >= 0.0)
    se = est.std(ddof=1) / np.sqrt(n)
    assert abs(est.mean() - EXACT) < 4.0 * se + 1e-12, (est.mean(), EXACT, se)


def test_twin_exact_control_takes_the_noise_away():
    n = 50_000
    rng = np.random.default_rng(3)
    ratio = sun_transmittance(_sigma, EDGES, MAJORANTS, None, 0.05, n, rng)
    residual = sun_transmittance(_sigma, EDGES, MAJORANTS, _depth, 0.05, n, rng)
    assert residual.var() < 0.05 * ratio.var()
    # a constant medium with its exact control: every estimate is exp(-tau), no noise at all
    const = sun_transmittance(lambda t: np.full(np.shape(t), 4.0), EDGES, MAJORANTS,
                              lambda t: 4.0 * (L - np.asarray(t)), 0.1, 1000, rng)
    np.testing.assert_allclose(const, np.exp(-4.0 * L), rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# the GLSL against the twin

KERNEL = """
#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/tracking.glsl"
#include "lib/sun_shadow.glsl"
layout(std430, binding = 0) readonly buffer Points { vec4 points[]; };
layout(std430, binding = 1) writeonly buffer Out { vec2 o[]; };
uniform uint samples;
uniform int chunk;
uniform uint seed;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint point = i / samples;
    vec3 p = points[point].xyz;
    uint rng = rng_seed(point, i % samples, seed);
    uint rng2 = rng;
    int steps = 60000;
    float whole = sun_transmittance(p, rng, steps);
    // the same ray cut every `chunk` steps and resumed
    float t = -1.0, transmittance = 1.0;
    for (int k = 0; k < 20000; ++k) {
        int s = chunk;
        if (sun_transmittance_continue(p, t, transmittance, rng2, s))
            break;
    }
    o[i] = vec2(whole, transmittance);
}
"""

CLOUD = {"volume": {"builtin": "cloud", "size": [16, 14, 12]}, "density_scale": 12.0,
         "albedo": 0.9, "light": {"direction": [0.4, 0.8, -0.45], "irradiance": [3, 3, 3]},
         "camera": {"width": 8, "height": 8}}


@pytest.mark.parametrize("empty_space_skipping", [False, True])
def test_glsl_residual_shadow_ray_agrees_with_its_twin(ctx, empty_space_skipping):
    scene = parse_scene(CLOUD)
    r = Renderer(ctx, scene, settings=RenderSettings(shadow_tracking="residual",
                                                     light_precision="f4",
                                                     empty_space_skipping=empty_space_skipping))
    try:
        r.bake_light()
        res = r.resources
        points = np.array([[0.0, -0.3, 0.1], [-0.2, -0.1, 0.3], [0.25, 0.0, -0.2]])
        samples = 4000
        uniforms = {**res.uniforms(), **r._light.uniforms(), "samples": samples, "chunk": 3,
                    "seed": 5}
        res.bind()
        r._light.bind()
        out = run_kernel(ctx, KERNEL, [np.c_[points, np.zeros(3)].astype(np.float32).ravel()],
                         (len(points) * samples, 2), uniforms=uniforms,
                         count=len(points) * samples,
                         defines={"SHADOW_TRACKING_RESIDUAL": 1, **res.defines()})
        glsl = out.reshape(len(points), samples, 2)
        assert np.all(np.isfinite(glsl)) and np.all(glsl >= 0.0)
        # resumed in chunks of 3 steps: the very same estimates
        np.testing.assert_allclose(glsl[..., 1], glsl[..., 0], rtol=1e-5, atol=1e-7)
        light = r._light
        grid = light.read()
        lu = light.uniforms()
        d = np.asarray(scene.light.direction, np.float64)
        d = d / np.linalg.norm(d)
        rng = np.random.default_rng(11)
        for p, est in zip(points, glsl[..., 0]):
            t0, t1, _ = box_intersect(res.volume.half_extent, p[None], d[None])
            t0, t1 = float(t0[0]), float(t1[0])

            def sigma(t, p=p):
                return sigma_t_at(res.volume, res.table, scene.density_scale,
                                  p + np.asarray(t)[..., None] * d)

            def depth(t, p=p):
                return light_grid_optical_depth(grid, light.layout, res.volume, res.table,
                                                scene.density_scale, d,
                                                p + np.asarray(t)[..., None] * d,
                                                lu["light_grid_texel"],
                                                lu["light_grid_march_step"])
            # the global majorant (the macrocells' own majorants change the variance, not the
            # mean: the grid build is compared on the mean only)
            twin = sun_transmittance(sigma, [t0, t1], [res.majorant], depth,
                                     lu["shadow_control_step"], 20_000, rng)
            ts = np.linspace(t0, t1, 4001)
            exact = np.exp(-np.sum(sigma(0.5 * (ts[1:] + ts[:-1]))) * (ts[1] - ts[0]))
            se_glsl = est.std(ddof=1) / np.sqrt(samples)
            se_twin = twin.std(ddof=1) / np.sqrt(len(twin))
            print(p, est.mean(), twin.mean(), exact, est.var(), twin.var())
            assert abs(est.mean() - exact) < 4.0 * se_glsl + 1e-4 * exact
            assert abs(twin.mean() - exact) < 4.0 * se_twin + 1e-4 * exact
            if not empty_space_skipping:
                assert 0.8 < (est.var() + 1e-12) / (twin.var() + 1e-12) < 1.25
    finally:
        r.release()


# ---------------------------------------------------------------------------------------------
# the path tracer and the bake

# test_guided's small cloud, with fewer walks a probe
SCENE = {**GUIDED_SCENE, "probes": {"grid": [4, 4, 4], "samples": 32}}


def _means(r, seeds, spp=4):
    out = []
    for s in seeds:
        result = r.render("pt", spp=spp, seed=s, samples_per_pass=spp)
        assert np.all(np.isfinite(result.image)) and np.all(result.image >= 0.0)
        assert result.stats["truncated_paths"] == 0 and result.stats["nonfinite_samples"] == 0
        out.append(result.image.mean(axis=(0, 1)))
    return np.array(out, np.float64)


@pytest.mark.parametrize("grid_scale", [1.0, 10.0, 0.0])
def test_residual_path_tracer_mean_is_the_ratio_path_tracers(ctx, grid_scale):
    scene = parse_scene(SCENE)
    r = Renderer(ctx, scene)
    try:
        ratio = _means(r, range(100, 124))
        r.configure(shadow_tracking="residual")
        r.bake_light()
        if grid_scale != 1.0:   # a wrong control: the grid's depths scaled, kept as if current
            tex = r._light.texture
            data = np.frombuffer(tex.read(), np.float16).astype(np.float32)
            tex.write((data * grid_scale).astype(np.float16).tobytes())
        residual = _means(r, range(200, 224))
        assert r.light_current()
    finally:
        r.release()
    z = _z(residual, ratio)
    print(grid_scale, residual.mean(0), ratio.mean(0), z)
    assert np.all(np.abs(z) < 3.5), z


@pytest.mark.parametrize("walk_sun", ["ray", "grid"])
def test_bake_takes_residual_shadow_rays(ctx, walk_sun):
    """The walks' shadow rays (walk_sun "ray") or the grid sun's correction rays ("grid") residual
    tracked: the bake runs and its probes hold what ratio tracking's hold, up to their noise."""
    scene = parse_scene(SCENE)
    means = {}
    for tracking in ("ratio", "residual"):
        r = Renderer(ctx, scene, settings=RenderSettings(walk_sun=walk_sun,
                                                         shadow_tracking=tracking,
                                                         walk_adaptive=0.0))
        try:
            r.bake(seed=3)
            assert r.probes_current()
            assert r.light_current() or (tracking, walk_sun) == ("ratio", "ray")
            image = r.render("probes-only", spp=2, seed=1, samples_per_pass=2).image
            assert np.all(np.isfinite(image)) and np.all(image >= 0.0)
            means[tracking] = image.mean()
        finally:
            r.release()
    assert abs(means["residual"] / means["ratio"] - 1.0) < 0.05, means


def test_shadow_tracking_setting_is_checked():
    with pytest.raises(ValueError, match="shadow tracking"):
        RenderSettings(shadow_tracking="delta")
    from radiance_probes.rendering.lab_options import LabOptions
    with pytest.raises(ValueError, match="sun shadow rays"):
        LabOptions(sun_shadow_rays=0)
    with pytest.raises(TypeError):
        RenderSettings(sun_shadow_rays=2)   # a lab option, not a product setting
    assert replace(RenderSettings(), shadow_tracking="residual").shadow_tracking == "residual"
