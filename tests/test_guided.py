"""`guided` (app/rendering/renderer.py; lib/guided_level0.glsl, lib/integrator.glsl GUIDED_RESIDUAL):
level 0, an unbiased estimate of what the probes and the light grid predict along camera rays,
plus level 1, a path-traced sample minus the single-collision estimate of the same prediction on
the same random numbers. Its mean is the path tracer's whatever the probes hold: checked here
against the path tracer over many seeds with the probes as baked, zero, ten times too bright and
baked for another sun; the white furnace; a level never reached changes nothing."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [16, 14, 12]}, "density_scale": 40.0,
         "albedo": 0.9, "anisotropy": 0.5, "max_bounces": 12,
         "light": {"direction": [0.4, 0.8, -0.45], "irradiance": [3, 3, 3]},
         "environment": [0.1, 0.12, 0.15],
         "camera": {"eye": [0.2, 0.3, 1.6], "width": 12, "height": 10},
         "probes": {"grid": [4, 4, 4], "samples": 64}}


def _means(r, method, seeds, spp=4):
    return np.array([r.render(method, spp=spp, seed=s, samples_per_pass=spp).image.mean(axis=(0, 1))
                     for s in seeds], np.float64)


def _guided_means_as_baked(r, seeds, spp=4):
    """`guided`'s image means with the probes as they are now (begin and add_samples: never
    re-baked, so probes changed by hand stay as they were made), every image finite."""
    baked_key = r._baked_key
    means = []
    for s in seeds:
        r.begin("guided", seed=s)
        r.add_samples(spp)
        assert r._baked_key == baked_key   # the probes were not re-baked
        image = r.image()
        assert np.all(np.isfinite(image))
        means.append(image.mean(axis=(0, 1)))
    return np.array(means, np.float64)


def _z(a, b):
    diff = a.mean(0) - b.mean(0)
    se = np.sqrt(a.var(0, ddof=1) / len(a) + b.var(0, ddof=1) / len(b))
    return diff / se


@pytest.mark.parametrize("probes", ["baked", "zero", "times ten", "another sun",
                                    "baked, first event only"])
def test_guided_mean_is_the_path_tracers_whatever_the_probes(ctx, probes):
    """With the direction control at every event (the default) and, "first event only", without
    it. (Guided directions and guided distances, measured and removed: docs/experiments.md.)"""
    scene = parse_scene(SCENE)
    r = Renderer(ctx, scene)
    if probes == "baked, first event only":
        r.settings = replace(r.settings, guided_direction_control=False)
    try:
        pt = _means(r, "pt", range(100, 124))
        if probes == "another sun":
            r.set_scene(scene.replace(light=replace(scene.light, direction=(-0.7, 0.2, 0.68))))
            r.bake(seed=3)
            grid = r.probe_grid
            r.set_scene(scene)
            r._baked_key = r.bake_key()   # keep the other sun's probes as if current
            assert r.probe_grid is grid
        else:
            r.bake(seed=3)
        if probes in ("zero", "times ten"):
            grid = r.probe_grid
            for tex in grid.textures:
                data = np.frombuffer(tex.read(), np.float32)
                tex.write((data * (0.0 if probes == "zero" else 10.0)).astype(np.float32).tobytes())
        guided = _guided_means_as_baked(r, range(200, 224))
    finally:
        r.release()
    z = _z(guided, pt)
    print(probes, guided.mean(0), pt.mean(0), z)
    assert np.all(np.abs(z) < 3.5), z


def test_guided_furnace_returns_the_environment(ctx):
    """Albedo 1, no sun, no bounce limit: every path returns the environment exactly. Level 1 is
    then the environment minus the probes' prediction at the first event (0 up to the probes'
    quadrature error in their higher bands) and level 0 estimates sum T sigma_t dt + T_exit = 1
    times the environment with the camera ray's ratio-tracked transmittance: unbiased, not exact
    per sample. The mean over 24 seeds of 4 samples is the environment within 3 standard errors
    per colour, and no pixel strays by as much as it (16 samples, 4 of level 0)."""
    scene = parse_scene({**SCENE, "albedo": 1.0, "max_bounces": 100000,
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "light": {"direction": [0, 1, 0], "irradiance": [0, 0, 0]},
                         "environment": [0.3, 0.3, 0.3]})
    r = Renderer(ctx, scene)
    try:
        means = _means(r, "guided", range(24))
        image = r.render("guided", spp=16, seed=1, samples_per_pass=16).image
    finally:
        r.release()
    se = means.std(0, ddof=1) / np.sqrt(len(means))
    assert np.all(np.abs(means.mean(0) - 0.3) < 3 * se + 1e-4), (means.mean(0), se)
    np.testing.assert_allclose(image, 0.3, rtol=1.0)


def test_guided_without_scattering_is_the_transmitted_environment(ctx):
    """max_bounces 0: nothing scatters; level 0 is the environment through an unbiased estimate of
    the camera ray's transmittance, level 1 adds nothing (it subtracts at the first event only what
    it would have added there, and no path scatters)."""
    scene = parse_scene({**SCENE, "max_bounces": 0})
    r = Renderer(ctx, scene)
    try:
        pt = _means(r, "pt", range(24), spp=8)
        guided = _means(r, "guided", range(24), spp=8)
        r.begin("guided", seed=3)
        r.add_samples(4)
        level1 = r._acc.read()
    finally:
        r.release()
    assert np.all(level1 == 0.0)
    assert np.all(np.abs(_z(guided, pt)) < 3.5)


def test_guided_under_an_environment_map_with_wrong_probes(ctx, tmp_path):
    """A map with a small bright patch (which the map's samples find) over a dim sky, no sun, and
    probes that claim the light comes from the opposite side (band 1 against the patch: their
    radiance towards it rings below 0): the direction control subtracts what they predict at
    every event, and `guided` keeps the path tracer's mean with the map's MIS."""
    from radiance_probes.rendering.probes.layout import colour_channel
    from radiance_probes.twins import environment_map as tw
    h, rotation = 16, 30.0
    sky = np.full((h, 2 * h, 3), 0.05, np.float32)
    sky[:h // 2] *= 3.0                                    # the upper half brighter
    sky[4:6, 10:12] = [8.0, 6.0, 4.0]                      # a small bright patch
    path = tmp_path / "sky.npy"
    np.save(path, sky)
    towards_patch = tw.rotate_y(tw.uv_to_direction(11.0 / (2 * h), 5.0 / h), rotation)
    scene = parse_scene({**SCENE, "light": {"direction": [0, 1, 0], "irradiance": [0, 0, 0]},
                         "environment": {"map": str(path), "rotation": rotation}})
    r = Renderer(ctx, scene)
    try:
        pt = _means(r, "pt", range(100, 148))
        r.bake(seed=3)
        grid = r.probe_grid
        assert grid.sh_order == 2 and not grid.grey
        scale = grid.radiance_scale
        away = -np.asarray(towards_patch, np.float64)
        coeffs = np.zeros(9)
        coeffs[0] = 0.3
        coeffs[1:4] = 0.6 * away[[1, 2, 0]]               # Y1-1 ~ y, Y10 ~ z, Y11 ~ x
        for number, tex in zip(grid.texture_ids, grid.textures):
            data = np.frombuffer(tex.read(), np.float32).reshape(-1, 4).copy()
            for k in range(9):
                for c in range(3):
                    f = colour_channel(k, c)
                    if f // 4 == number:
                        data[:, f % 4] = coeffs[k] / scale
            tex.write(data.tobytes())
        guided = _guided_means_as_baked(r, range(200, 248))
    finally:
        r.release()
    z = _z(guided, pt)
    print(guided.mean(0), pt.mean(0), z)
    assert guided.mean() > 0.01
    assert np.all(np.abs(z) < 3.5), z
