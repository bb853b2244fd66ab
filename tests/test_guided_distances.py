"""Guided distances (lib/guided_distances.glsl, twin app/twins/guided_distances.py): the
real-or-null probability in GLSL against its twin; the twin's flights keep delta tracking's mean for predictions
that are plainly wrong, with each decision's weight at most 1 / (1 - P); in `guided`, a flight it
never guides changes nothing and one it guides changes the samples. The mean with wrong probes:
tests/test_guided.py."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.scene import parse_scene
from radiance_probes.twins import guided_distances as gdist
from glsl_harness import run_kernel
from test_guided import SCENE

KERNEL = """
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/directions.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
#include "lib/light_grid.glsl"
#include "lib/guided_distances.glsl"
layout(std430, binding = 0) readonly buffer In { float v[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    o[i] = guided_collision_probability(v[4u * i], v[4u * i + 1u], v[4u * i + 2u], v[4u * i + 3u]);
}
"""


def _cases(n: int, rng: np.random.Generator) -> np.ndarray:
    a = rng.uniform(0.0, 1.0, n)
    source = rng.exponential(1.0, n) * (rng.random(n) < 0.8)   # some 0
    beyond = rng.exponential(1.0, n) * (rng.random(n) < 0.8)
    share = rng.choice([0.0, 0.25, 0.5, 0.9, 0.999], n)
    cases = np.stack([a, source, beyond, share], 1)
    cases[:8] = [[0.3, 0, 0, 0.5], [0.3, 1, 0, 0.5], [0.3, 0, 1, 0.5], [0.3, 1e-30, 1e-30, 0.9],
                 [1e-6, 1e6, 1e-6, 0.5], [0.999999, 1e-6, 1e6, 0.5], [0.5, 2, 2, 0.999],
                 [0.7, 1, 3, 0.0]]
    return cases


def test_collision_probability_glsl_matches_its_twin(ctx):
    cases = _cases(512, np.random.default_rng(3))
    got = run_kernel(ctx, KERNEL, [cases.astype(np.float32).ravel()], (len(cases),),
                     count=len(cases), defines={"PROBE_SH_ORDER": 2, "PROBE_GREY": 0})
    c32 = cases.astype(np.float32).astype(np.float64)
    want = gdist.collision_probability(*c32.T)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-7)


def test_the_twins_flight_bound_is_the_glsls():
    from radiance_probes.gl.shaders import GLSL_DIR
    text = (GLSL_DIR / "lib" / "guided_distances.glsl").read_text()
    assert f"const float GUIDED_FLIGHT_WEIGHT_BOUND = {gdist.FLIGHT_WEIGHT_BOUND};" in text


def test_probability_lies_inside_and_weights_are_bounded():
    """0 < p < 1 wherever 0 < a < 1 and P < 1; each outcome's probability times its weight is the
    analog one's; no weight exceeds 1 / (1 - P); P = 0 is delta tracking (p = a, weights 1); a
    prediction of nothing on both sides leaves p = a."""
    cases = _cases(4096, np.random.default_rng(4))
    a, source, beyond, share = cases.T
    a = np.clip(a, 1e-6, 1.0 - 1e-6)
    p = gdist.collision_probability(a, source, beyond, share)
    assert np.all((p > 0.0) & (p < 1.0))
    w_real, w_null = gdist.decision_weights(a, p)
    np.testing.assert_allclose(p * w_real, a, rtol=1e-12)
    np.testing.assert_allclose((1.0 - p) * w_null, 1.0 - a, rtol=1e-9)
    bound = 1.0 / (1.0 - share)
    assert np.all(w_real <= bound * (1 + 1e-9)) and np.all(w_null <= bound * (1 + 1e-9))
    np.testing.assert_allclose(gdist.collision_probability(a, source, beyond, 0.0), a)
    np.testing.assert_allclose(gdist.collision_probability(a, 0.0, 0.0, 0.7), a)
    # the zero-variance side follows the predictions: more of the source, more real collisions
    assert gdist.collision_probability(0.5, 10.0, 1.0, 1.0) > 0.9
    assert gdist.collision_probability(0.5, 1.0, 10.0, 1.0) < 0.1


@pytest.mark.parametrize("share", [0.5, 0.9])
@pytest.mark.parametrize("prediction", ["good", "reversed", "zero source"])
def test_twin_flights_keep_delta_trackings_mean(share, prediction):
    """A 1D medium sigma_t(x) = 2 + 1.5 sin 6x on [0, 1] under a majorant of 3.6: the estimate
    f(x) at a real collision, g on escape, has mean  integral T sigma_t f dx + T(1) g  whatever
    the predictions S and B say (here: good ones, ones that point the wrong way, S = 0)."""
    sigma_t = lambda x: 2.0 + 1.5 * np.sin(6.0 * x)          # noqa: E731
    f = lambda x: 1.0 + np.cos(3.0 * x)                      # noqa: E731
    escape = 0.7
    xs = np.linspace(0.0, 1.0, 200001)
    s = sigma_t(xs)
    tau = np.concatenate([[0.0], np.cumsum((s[1:] + s[:-1]) / 2.0 * np.diff(xs))])
    exact = np.trapezoid(np.exp(-tau) * s * f(xs), xs) + np.exp(-tau[-1]) * escape
    source, beyond = {
        "good": (f, lambda x: np.full_like(x, 1.0)),
        "reversed": (lambda x: 3.0 - f(x), lambda x: 5.0 * x),
        "zero source": (lambda x: np.zeros_like(x), lambda x: 0.1 + x)}[prediction]
    weight, collided, x = gdist.track_1d(sigma_t, 3.6, 1.0, source, beyond, share,
                                         np.random.default_rng(7), 200000)
    estimate = weight * np.where(collided, f(np.minimum(x, 1.0)), escape)
    se = estimate.std() / np.sqrt(estimate.size)
    assert abs(estimate.mean() - exact) < 4.0 * se, (estimate.mean(), exact, se)


def test_guided_distances_setting_is_a_probability_below_1():
    for bad in (1.0, -0.1, float("nan"), True, "0.5"):
        with pytest.raises(ValueError, match="guided distances"):
            RenderSettings(guided_distances=bad)
    assert RenderSettings().guided_distances == 0.0


def _guided_image(r, seed, spp=4):
    r.begin("guided", seed=seed)
    r.add_samples(spp)
    return r.image()


@pytest.mark.parametrize("max_bounces, changes", [(1, False), (12, True)])
def test_a_flight_never_guided_changes_nothing(ctx, max_bounces, changes):
    """Flights are guided after a path's first event, up to the last event it may scatter at:
    with max_bounces 1 no flight is, and `guided`'s image is bit for bit the one without guided
    distances (the decisions draw the same numbers); with 12 the samples differ."""
    scene = parse_scene({**SCENE, "max_bounces": max_bounces})
    r = Renderer(ctx, scene)
    try:
        r.bake(seed=3)
        plain = _guided_image(r, 5)
        r.settings = replace(r.settings, guided_distances=0.9)
        guided = _guided_image(r, 5)
    finally:
        r.release()
    assert np.all(np.isfinite(guided))
    assert (not np.array_equal(plain, guided)) == changes
