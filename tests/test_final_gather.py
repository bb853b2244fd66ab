"""`probes` with a final gather (Renderer.probe_gather_event, lib/integrator.glsl): events before
the gather event are the path tracer's, so a gather the path never reaches renders the path
tracer's image bit for bit; the furnace stays exact at every gather event; the probes' error
reaches the image less the later the gather; probes-only is not affected."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.methods.pathtracer import PathTracer
from radiance_probes.rendering.renderer import MAX_GATHER_EVENT, Renderer
from radiance_probes.io.scene_file import parse_scene

WHITE = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}
CAMERA = {"eye": [0.0, 0.2, 1.3], "target": [0, 0, 0], "fov_y": 40.0, "width": 16, "height": 16}


def _renderer(ctx, **kw):
    base = {"volume": {"builtin": "cloud", "size": [16, 12, 14]}, "camera": CAMERA,
            "density_scale": 30.0, "albedo": 0.9, "anisotropy": 0.5,
            "light": {"direction": [0.3, 0.8, 0.4], "irradiance": [3, 3, 3]},
            "environment": [0.1, 0.12, 0.15], "probes": {"grid": [3, 3, 3], "samples": 32}}
    base.update(kw)
    return Renderer(ctx, parse_scene(base))


def _render(r, method, spp, event=1, seed=5):
    r.configure(gather_event=event)
    result = r.render(method, spp=spp, seed=seed, samples_per_pass=spp)
    assert result.stats["truncated_paths"] == 0 and result.stats["nonfinite_samples"] == 0
    return result.image


def test_a_gather_beyond_the_last_bounce_is_the_path_tracer_bit_for_bit(ctx):
    r = _renderer(ctx, max_bounces=3)
    pt = _render(r, "pt", 4)
    gathered = _render(r, "probes", 4, event=4)
    np.testing.assert_array_equal(gathered, pt)
    # ... and one the path reaches is not (the probes stand in from there)
    assert not np.array_equal(_render(r, "probes", 4, event=3), pt)
    r.release()


def test_a_gather_beyond_the_last_bounce_sees_an_environment_map_as_unsampled_pt(ctx, tmp_path):
    """With an environment map the probe builds take no map samples, so escapes before the gather
    count in full: the path tracer built without the map's samples, bit for bit."""
    h, w = 8, 16
    sky = np.zeros((h, w, 3), np.float32)
    sky[: h // 2] = [0.6, 0.7, 0.9]
    sky[h // 2:] = [0.2, 0.15, 0.1]
    path = tmp_path / "sky.npy"
    np.save(path, sky)
    r = _renderer(ctx, max_bounces=2, environment={"map": str(path)})
    defines = {**r.resources.defines(), "ENVIRONMENT_MAP_SAMPLING": 0}
    unsampled = PathTracer(ctx, defines)
    r._passes[("pt", tuple(sorted(r.resources.defines().items())))] = unsampled
    pt = _render(r, "pt", 4)
    np.testing.assert_array_equal(_render(r, "probes", 4, event=3), pt)
    r.release()


@pytest.mark.parametrize("event", [2, 3])
@pytest.mark.parametrize("g", [0.0, 0.8])
def test_furnace_stays_exact_at_every_gather_event(ctx, event, g):
    env = [0.3, 0.6, 0.9]
    r = _renderer(ctx, transfer_function=WHITE, albedo=1.0, anisotropy=g, density_scale=40.0,
                  environment=env, max_bounces=100000, light={"irradiance": [0, 0, 0]},
                  probes={"grid": [4, 4, 4], "samples": 64})
    image = _render(r, "probes", 8, event=event)
    np.testing.assert_allclose(image, np.broadcast_to(env, image.shape), rtol=1e-2)
    r.release()


def test_probes_error_falls_with_a_later_gather(ctx):
    """Coarse probes (2^3) in a forward-scattering cloud: the later the gather, the less of their
    error reaches the image (each measured at many samples against the path tracer)."""
    r = _renderer(ctx, probes={"grid": [2, 2, 2], "samples": 64}, anisotropy=0.8,
                  camera={**CAMERA, "width": 20, "height": 20}, max_bounces=64)
    reference = r.render("pt", spp=2048, seed=1, samples_per_pass=512).image

    def error(event):
        image = _render(r, "probes", 1024, event=event, seed=9)
        return float(np.sqrt(np.mean((image - reference) ** 2) / np.mean(reference ** 2)))

    errors = [error(k) for k in (1, 2, 3)]
    print("probes rRMSE at gather events 1, 2, 3:", errors)
    assert errors[2] < errors[1] < errors[0], errors
    r.release()


def test_probes_only_reads_its_probes_at_the_first_event_whatever_the_setting(ctx):
    r = _renderer(ctx)
    first = _render(r, "probes-only", 2, event=1)
    np.testing.assert_array_equal(_render(r, "probes-only", 2, event=3), first)
    r.release()


@pytest.mark.parametrize("bad", [0, MAX_GATHER_EVENT + 1, 1.5, True, "2"])
def test_a_gather_event_out_of_range_is_refused_by_name(ctx, bad):
    r = _renderer(ctx)
    with pytest.raises(ValueError, match="probe gather event"):
        r.configure(gather_event=bad)
    assert r.probe_gather_event == 1
    r.release()


@pytest.mark.parametrize("max_bounces, event, most", [(4, 1, None), (4, 2, 5), (4, 4, 7),
                                                      (4, 5, None), (64, 3, None)])
def test_scattering_past_max_bounces_is_counted_where_a_gather_is_reached(ctx, max_bounces,
                                                                          event, most):
    r = _renderer(ctx, max_bounces=max_bounces)
    r.configure(gather_event=event)
    assert r.gather_bounces_past_limit() == most
    r.release()
