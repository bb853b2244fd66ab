"""The stress battery (app/bench/scenes.py BATTERY: procedural scenes built to break shortcuts) at
small size on llvmpipe, with the checking build of the shaders (glsl/lib/checks.glsl): every
method and the bake run over every scene with no bounds or loop-cap hit, no truncated or
non-finite path, and finite, non-negative images. The bench runs the same scenes at full size on
the GPU for the bias table (`bench --preset bias`)."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.bench.scenes import BATTERY_SCENES, battery_scene
from radiance_probes.gl.checks import check_sites
from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.gl.dispatch_log import DispatchLog
from radiance_probes.rendering.budgets.dispatch_budget import DISPATCH_BOUND_MS, device_slowdown
from radiance_probes.rendering.renderer import METHODS, Renderer


def test_every_site_of_the_checking_build_is_named():
    sites, count = check_sites()
    assert len(sites) >= 10 and max(sites) < count
    assert len(set(sites.values())) == len(sites)


def test_the_checking_build_counts_a_hit(checked_ctx):
    """A check that must fire: 64 invocations index a 3-element range with their own index; the
    61 out of range are counted at the site named, and nothing else is."""
    ctx, checks = checked_ctx
    program = compute_program(ctx, "check_demo.comp", text="""
layout(local_size_x = 64) in;
#include "lib/checks.glsl"
uniform int size;
void main()
{
    CHECK_INDEX(int(gl_GlobalInvocationID.x), size, CHECK_SITE_PROBE_INDEX);
    CHECK_LOOP_COUNTER(iterations);
    for (int i = 0; i < 10; ++i) {
        CHECK_LOOP(iterations, 4, CHECK_SITE_MARCH_LOOP);
    }
}
""")
    checks.reset()
    set_uniforms(program, {"size": 3})
    program.run(1)
    assert checks.hits() == {"probe_index": 61, "march_loop": 64}
    program.release()
    checks.reset()
    assert checks.hits() == {}


@pytest.mark.parametrize("name", BATTERY_SCENES)
def test_battery_scene_renders_clean_with_every_method(checked_ctx, name):
    ctx, checks = checked_ctx
    scene = battery_scene(name, side=12, width=12, height=10, grid=3, samples=64)
    scene = scene.replace(max_bounces=min(scene.max_bounces, 16))
    r = Renderer(ctx, scene)
    checks.reset()
    log = DispatchLog().__enter__()
    try:
        for method in METHODS:
            result = r.render(method, spp=2, seed=1)
            image = result.image
            assert np.all(np.isfinite(image)), method
            if method == "guided":
                # a control variate: a pixel's estimate may dip below 0 at a few samples (level
                # 1 subtracts the probes' prediction); its mean over the image may not
                assert image.mean() >= 0.0, method
            else:
                assert image.min() >= 0.0, method
            assert result.stats["truncated_paths"] == 0, method
            assert result.stats["nonfinite_samples"] == 0, method
            hits = checks.hits()
            assert hits == {}, f"{name} {method}: {hits}"
        # the adaptive bake's budgets and the probes' own sun by marching (walk_sun "ray")
        r.configure(walk_sun="ray")
        r.invalidate()
        r.render("probes-only", spp=1, seed=2)
        assert checks.hits() == {}, f"{name} ray-sun bake: {checks.hits()}"
        # no dispatch beyond the bound, scaled by this device's speed against the H100's (on
        # llvmpipe a dispatch's host time includes compiling its shader on first use)
        longest, program = log.take()
        assert longest < DISPATCH_BOUND_MS * device_slowdown(r), (program, longest)
    finally:
        log.__exit__(None, None, None)
        r.release()


def test_the_checking_build_renders_the_normal_builds_image(ctx, checked_ctx):
    """Without a hit the checks change nothing: the same image, bit for bit, from the session's
    normal context and the checked one."""
    checked, checks = checked_ctx
    scene = battery_scene("head", side=12, width=12, height=10, grid=3, samples=64)
    images = []
    for context in (ctx, checked):
        context.__enter__()
        r = Renderer(context, scene)
        try:
            images.append(r.render("probes", spp=2, seed=4).image)
        finally:
            r.release()
    assert checks.hits() == {}
    np.testing.assert_array_equal(images[0], images[1])
