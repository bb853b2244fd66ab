"""Environment maps (SPEC.md's equirectangular map; README "Environment maps"): the lookup against
SPEC.md's formula, lib/environment_map.glsl against its NumPy twin on the GPU context, the sampling
pdf and its samples, the transport's known answers with a map, and bad map files.

Tolerances
----------
* GLSL (u, v) against the twin's: 2e-6 (float32 atan/acos on unit vectors, against float64).
* GLSL radiance against the twin's bilinear at the GLSL's own (u, v): rtol 1e-5 (texelFetch and
  mix in float32, exact weights); against the full twin, the (u, v) error times the map's largest
  step between neighbouring pixels, times W or H.
* sampling: GLSL and twin draw the same pixel from the same numbers except where a number lies
  within float32 rounding of a CDF entry (allowed: 1 in 1000); their directions agree to 1e-5.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.io.environment_map import load_environment_map, read_environment_map
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.resources import (ENVIRONMENT_CDF_UNIT, ENVIRONMENT_MAP_UNIT,
                                                 environment_textures)
from radiance_probes.io.scene_file import EnvironmentMapSpec, SceneError, parse_scene
from radiance_probes.twins import environment_map as tw
from glsl_harness import run_kernel

# ---------------------------------------------------------------------------------------------
# The convention (pure NumPy)


def test_spec_convention_axes():
    """SPEC.md: u = frac(atan2(d.x, -d.z) / 2 pi), v = acos(d.y) / pi; row 0 is +y."""
    d = np.array([[0, 1, 0], [0, -1, 0], [0, 0, -1], [1, 0, 0], [0, 0, 1], [-1, 0, 0]], float)
    u, v = tw.direction_to_uv(d)
    np.testing.assert_allclose(v, [0, 1, 0.5, 0.5, 0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(u[2:], [0.0, 0.25, 0.5, 0.75], atol=1e-12)
    rng = np.random.default_rng(1)
    x = rng.normal(size=(1000, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    np.testing.assert_allclose(tw.uv_to_direction(*tw.direction_to_uv(x)), x, atol=1e-12)


def test_bilinear_pixel_centres_wrap_and_clamp():
    img = np.arange(4 * 8 * 3, dtype=np.float32).reshape(4, 8, 3)
    h, w = 4, 8
    i, j = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    np.testing.assert_allclose(tw.bilinear(img, (j + 0.5) / w, (i + 0.5) / h), img)
    # u = 0 lies halfway between the last and the first column (wrapping); v = 0 is row 0 (clamped).
    np.testing.assert_allclose(tw.bilinear(img, np.array(0.0), np.array(0.5 / h)),
                               (img[0, 0] + img[0, w - 1]) / 2)
    np.testing.assert_allclose(tw.bilinear(img, np.array(0.5 / w), np.array(0.0)), img[0, 0])
    np.testing.assert_allclose(tw.bilinear(img, np.array(0.5 / w), np.array(1.0)), img[h - 1, 0])


def test_rotation_turns_the_map_about_up():
    """A map turned by 90 degrees shows at +x what it showed at -z (R_y(90) takes -z to -x... so
    world d reads the map at R_y(-90) d)."""
    img = np.zeros((8, 16, 3), np.float32)
    img[3:5, 0] = img[3:5, 15] = 1.0           # bright around u = 0, the map's -z
    rng = np.random.default_rng(2)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for deg in (90.0, -37.0):
        np.testing.assert_allclose(tw.radiance(img, d, rotation=deg),
                                   tw.radiance(img, tw.rotate_y(d, -deg)), atol=1e-12)
    # R_y(90) takes the map's -z (u = 0) to world -x.
    np.testing.assert_allclose(tw.rotate_y(np.array([0.0, 0.0, -1.0]), 90.0), [-1, 0, 0], atol=1e-12)
    assert tw.radiance(img, np.array([-1.0, 0, 0]), rotation=90.0)[0] > 0.4
    assert tw.radiance(img, np.array([0.0, 0, -1.0]), rotation=90.0)[0] == 0.0


def test_distribution_pdf_integrates_to_one_and_covers_the_radiance():
    rng = np.random.default_rng(3)
    img = np.zeros((16, 32, 3), np.float32)
    img[5, 7] = [50, 20, 10]
    img[12, 30] = [0, 0, 3]
    dist = tw.build_distribution(img)
    assert dist.pdf_uv.mean() == pytest.approx(1.0, rel=1e-12)
    # Solid-angle pdf over a fine midpoint grid in (theta, phi): integrates to 1.
    n = 1024
    theta = (np.arange(n) + 0.5) / n * np.pi
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = tw.uv_to_direction(P / (2 * np.pi), T / np.pi)
    pdf = tw.pdf(dist, d)
    integral = (pdf * np.sin(T)).sum() * (np.pi / n) * (np.pi / n)
    assert integral == pytest.approx(1.0, abs=2e-3)
    # Wherever the bilinear radiance is > 0, the pdf is > 0 (no bias).
    le = tw.radiance(img, d)
    assert (pdf[le.max(axis=-1) > 0] > 0).all()
    # A black map falls back to each pixel's solid angle (uniform over the sphere, per pixel).
    flat = tw.build_distribution(np.zeros((4, 8, 3)))
    band = np.cos(np.pi * np.arange(4) / 4) - np.cos(np.pi * np.arange(1, 5) / 4)
    np.testing.assert_allclose(flat.pdf_uv, np.broadcast_to((band / band.mean())[:, None], (4, 8)))


# ---------------------------------------------------------------------------------------------
# GLSL against the twin on the tests' GL context

KERNEL = """
#include "lib/environment_map.glsl"
layout(std430, binding = 0) readonly buffer In { vec4 inputs[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 d = inputs[i].xyz;
    vec3 m = environment_to_map(d);
    vec2 uv = environment_uv(m);
    vec3 le = environment_radiance(d);
    float pdf_d = environment_pdf(d);
    float pdf_s;
    vec3 s = environment_sample(inputs[i].w, fract(inputs[i].w * 7919.0 + 0.5 * d.x + 0.3), pdf_s);
    uint b = i * 12u;
    o[b] = uv.x; o[b + 1u] = uv.y;
    o[b + 2u] = le.r; o[b + 3u] = le.g; o[b + 4u] = le.b;
    o[b + 5u] = pdf_d;
    o[b + 6u] = s.x; o[b + 7u] = s.y; o[b + 8u] = s.z;
    o[b + 9u] = pdf_s;
    o[b + 10u] = environment_pdf(s);
    o[b + 11u] = fract(inputs[i].w * 7919.0 + 0.5 * d.x + 0.3);
}
"""


def _glsl(ctx, img, dirs, u1, rotation=0.0, scale=1.0):
    dist = tw.build_distribution(img)
    tex, cdf = environment_textures(ctx, img, dist)
    tex.use(ENVIRONMENT_MAP_UNIT)
    cdf.use(ENVIRONMENT_CDF_UNIT)
    a = math.radians(rotation)
    inputs = np.concatenate([dirs, u1[:, None]], axis=1).astype(np.float32)
    out = run_kernel(ctx, KERNEL, [inputs], (len(dirs), 12), uniforms={
        "environment_map": ENVIRONMENT_MAP_UNIT, "environment_cdf": ENVIRONMENT_CDF_UNIT,
        "environment_size": (img.shape[1], img.shape[0]), "environment_scale": scale,
        "environment_rotation": (math.cos(a), math.sin(a))})
    tex.release()
    cdf.release()
    return out.astype(np.float64), dist


def _random_map(rng, h=16):
    img = rng.uniform(0.0, 1.0, size=(h, 2 * h, 3)).astype(np.float32)
    img[h // 3, h // 2] = [40.0, 30.0, 20.0]   # a bright pixel
    img[:, 5] = 0.0                             # and a black column
    return img


@pytest.mark.parametrize("rotation", [0.0, 123.0])
def test_glsl_lookup_matches_twin(ctx, rotation):
    rng = np.random.default_rng(4)
    img = _random_map(rng)
    n = 4096
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:4] = [[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, 1]]
    d = d.astype(np.float32).astype(np.float64)
    out, _ = _glsl(ctx, img, d, rng.uniform(size=n), rotation=rotation, scale=2.5)
    m = tw.rotate_y(d, -rotation)
    u, v = tw.direction_to_uv(m)
    du = np.abs(out[:, 0] - u)
    du = np.minimum(du, 1 - du)[2:]      # the seam: 0 and 1 are the same u; u is moot at the poles
    assert du.max() < 2e-6 and np.abs(out[:, 1] - v).max() < 2e-6
    # Exactly the bilinear twin at the GLSL's own (u, v) ...
    np.testing.assert_allclose(out[:, 2:5], 2.5 * tw.bilinear(img, out[:, 0], out[:, 1]),
                               rtol=1e-5, atol=1e-5)
    # ... and the full twin within the (u, v) error times the map's steepest step (not at the
    # poles, where u is undefined and the top and bottom rows differ along u).
    step = 2.5 * max(np.abs(np.diff(img, axis=0)).max(), np.abs(np.diff(img, axis=1)).max())
    bound = step * 2e-6 * 2 * img.shape[0] * 2 + 1e-5
    assert np.abs(out[2:, 2:5] - tw.radiance(img, d[2:], 2.5, rotation)).max() < bound


def test_glsl_pdf_integrates_to_one_and_matches_twin(ctx):
    rng = np.random.default_rng(5)
    img = _random_map(rng)
    n_t = 256
    theta = (np.arange(n_t) + 0.5) / n_t * np.pi
    phi = (np.arange(2 * n_t) + 0.5) / (2 * n_t) * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = tw.rotate_y(tw.uv_to_direction(P / (2 * np.pi), T / np.pi), 40.0).reshape(-1, 3)
    d = d.astype(np.float32).astype(np.float64)   # what the GLSL reads
    out, dist = _glsl(ctx, img, d, rng.uniform(size=len(d)), rotation=40.0)
    pdf = out[:, 5].reshape(T.shape)
    integral = (pdf * np.sin(T)).sum() * (np.pi / n_t) ** 2
    assert integral == pytest.approx(1.0, abs=2e-3)
    # float32 rotation and sin(theta) near the poles: 1e-4 (the first and last rows), 2e-5 elsewhere.
    twin = tw.pdf(dist, d, 40.0)
    polar = np.abs(d[:, 1]) > 0.99
    np.testing.assert_allclose(out[~polar, 5], twin[~polar], rtol=2e-5)
    np.testing.assert_allclose(out[polar, 5], twin[polar], rtol=1e-4)


def test_glsl_samples_follow_the_pdf(ctx):
    """The GLSL sampler against the twin's (same numbers, same pixels), its pdf against the pdf
    of the direction it returns, and a chi-square test of where 2^17 samples land against the
    distribution's pixel probabilities."""
    rng = np.random.default_rng(6)
    img = _random_map(rng, h=8)
    img[2, 3] = [400.0, 400.0, 400.0]   # a hot spot the sampler must find
    n = 1 << 17
    u1 = rng.uniform(size=n)
    d_dummy = rng.normal(size=(n, 3))
    d_dummy /= np.linalg.norm(d_dummy, axis=1, keepdims=True)
    out, dist = _glsl(ctx, img, d_dummy, u1, rotation=-75.0)
    s, pdf_s, pdf_of_s = out[:, 6:9], out[:, 9], out[:, 10]
    u2 = out[:, 11]
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, atol=1e-5)
    # The returned pdf is the pdf of the returned direction (what MIS needs), except where float32
    # rounding puts the direction on the neighbouring pixel's side of a pixel edge.
    same = np.abs(pdf_s / pdf_of_s - 1) < 1e-4
    assert same.mean() > 0.999, same.mean()
    ts, tp = tw.sample(dist, u1.astype(np.float32).astype(np.float64), u2, rotation=-75.0)
    close = np.linalg.norm(ts - s, axis=1) < 1e-5
    assert close.mean() > 0.999
    np.testing.assert_allclose(pdf_s[close], tp[close], rtol=5e-4)
    # Histogram over the map's pixels against the distribution's probabilities.
    h, w = img.shape[:2]
    u, v = tw.direction_to_uv(tw.rotate_y(s, 75.0))
    j = np.minimum((u * w).astype(int), w - 1)
    i = np.minimum((v * h).astype(int), h - 1)
    counts = np.bincount(i * w + j, minlength=h * w).astype(float)
    expected = (dist.pdf_uv / dist.pdf_uv.sum()).ravel() * n
    keep = expected > 5
    chi2 = (((counts - expected) ** 2) / expected)[keep].sum()
    dof = keep.sum() - 1
    assert chi2 < dof + 5 * math.sqrt(2 * dof), (chi2, dof)
    assert counts[~keep].sum() <= expected[~keep].sum() + 5 * math.sqrt(expected[~keep].sum() + 1)


# ---------------------------------------------------------------------------------------------
# Transport with a map

WHITE_SOLID = {"rgba": [[1, 1, 1, 1.0], [1, 1, 1, 1.0]]}
CLOSE_CAMERA = {"eye": [0.0, 0.1, 1.2], "target": [0, 0, 0], "fov_y": 20.0}
ENV = np.array([0.25, 0.5, 1.0])


@pytest.fixture(scope="module")
def constant_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("env") / "constant.npy"
    np.save(p, np.broadcast_to(ENV, (16, 32, 3)).astype(np.float32))
    return str(p)


def _furnace(env, g=0.5, **kw):
    return parse_scene({"volume": {"builtin": "constant", "size": [8, 8, 8]},
                        "transfer_function": WHITE_SOLID, "albedo": 1.0, "density_scale": 20.0,
                        "anisotropy": g, "light": {"irradiance": [0, 0, 0]}, "environment": env,
                        "max_bounces": 1_000_000, "probes": {"grid": [3, 3, 3], "samples": 256},
                        "camera": {**CLOSE_CAMERA, "width": 12, "height": 12}, **kw})


def test_white_furnace_with_a_constant_map(ctx, constant_map):
    """Albedo 1 under a constant map: the path tracer returns the environment within its noise
    (each path's estimate now mixes the map's samples and escapes, so it is no longer exact), and
    every probe's L00 is env * sqrt(4 pi) within the walks' noise."""
    r = Renderer(ctx, _furnace({"map": constant_map}))
    try:
        spp = 64
        img = r.render("pt", spp=spp).image
        assert r.resources.read_stats()["truncated_paths"] == 0
        # Per-pixel noise from the image itself; the image mean within 4 standard errors.
        se = img.std(axis=(0, 1)) / math.sqrt(img.shape[0] * img.shape[1])
        assert (np.abs(img.mean(axis=(0, 1)) - ENV) < 4 * se + 1e-6).all(), (img.mean(axis=(0, 1)), se)
        assert (np.abs(img.mean(axis=(0, 1)) / ENV - 1) < 0.03).all()
        r.configure(walk_sun="ray", walk_adaptive=0.0)
        r.bake()
        l00 = r.probe_grid.coefficients()[..., 0:3] / math.sqrt(4 * math.pi)
        rel = l00 / ENV
        assert abs(rel.mean() - 1) < 4 * rel.std() / math.sqrt(rel.size / 3) + 1e-6, rel.mean()
        assert abs(rel.mean() - 1) < 0.02 and np.abs(rel - 1).max() < 0.2
        # The probes' renderers show the map too (within the probes' noise).
        for method in ("probes", "raymarch"):
            image = r.render(method, spp=4).image
            np.testing.assert_allclose(image.mean(axis=(0, 1)), ENV, rtol=0.03)
    finally:
        r.release()


def test_constant_map_renders_the_constant_environment(ctx, constant_map):
    """A cloud (albedo 0.9, sun on) under a constant map and under the same constant colour:
    the same image within the two renders' noise."""
    kw = {"volume": {"builtin": "cloud", "size": [20, 16, 16]}, "density_scale": 30.0,
          "albedo": 0.9, "light": {"direction": [0.5, 0.8, 0.3], "irradiance": [2, 2, 2]},
          "camera": {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "width": 16, "height": 16}}
    images = {}
    for name, env in (("constant", ENV.tolist()), ("map", {"map": constant_map})):
        r = Renderer(ctx, parse_scene({**kw, "environment": env}))
        halves = [r.render("pt", spp=128, seed=s).image for s in (1, 2)]
        r.release()
        images[name] = halves
    noise = {k: np.abs(a - b) / 2 for k, (a, b) in images.items()}    # ~ |mean - truth| scale
    mean = {k: (a + b) / 2 for k, (a, b) in images.items()}
    diff = mean["map"] - mean["constant"]
    sigma = np.sqrt(np.mean(noise["map"] ** 2) + np.mean(noise["constant"] ** 2))
    rrmse = math.sqrt(np.mean(diff ** 2)) / math.sqrt(np.mean(mean["constant"] ** 2))
    assert math.sqrt(np.mean(diff ** 2)) < 3 * sigma + 1e-6, (rrmse, sigma)
    assert abs(mean["map"].mean() / mean["constant"].mean() - 1) < 0.02


def _patch_map(h, row, col, size):
    img = np.zeros((h, 2 * h, 3), np.float32)
    img[row:row + size, col:col + size] = 1.0
    return img


def _patch_irradiance(img, towards):
    """Irradiance the map (scale 1) gives a plane facing `towards`: a fine quadrature of the
    bilinear twin."""
    n = 1024
    theta = (np.arange(n) + 0.5) / n * np.pi
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = tw.uv_to_direction(P / (2 * np.pi), T / np.pi)
    le = tw.bilinear(img, P / (2 * np.pi), T / np.pi)[..., 0]
    cos = np.maximum(d @ towards, 0.0)
    return float((le * cos * np.sin(T)).sum() * (np.pi / n) ** 2)


@pytest.fixture(scope="module")
def patch_scenes(tmp_path_factory):
    """A cloud lit by a small bright patch (3 x 3 pixels of a 64 x 128 map, about 4 degrees,
    turned by 60 degrees about +y) and the same cloud lit by a sun from the patch's direction
    with the patch's irradiance."""
    h, row, col, size = 64, 18, 40, 3
    img = _patch_map(h, row, col, size)
    centre_uv = ((col + size / 2) / (2 * h), (row + size / 2) / h)
    rotation = -60.0
    towards = tw.rotate_y(tw.uv_to_direction(*centre_uv), rotation)
    e_patch = _patch_irradiance(img, tw.uv_to_direction(*centre_uv))
    irradiance = 3.0
    p = tmp_path_factory.mktemp("env") / "patch.npy"
    np.save(p, img)
    kw = {"volume": {"builtin": "cloud", "size": [20, 16, 16]}, "density_scale": 20.0,
          "albedo": 0.9, "anisotropy": 0.3,
          "camera": {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "fov_y": 30.0,
                     "width": 20, "height": 20}}
    sun = parse_scene({**kw, "environment": [0, 0, 0],
                       "light": {"direction": towards.tolist(), "irradiance": [irradiance] * 3}})
    patch = parse_scene({**kw, "light": {"irradiance": [0, 0, 0]},
                         "environment": {"map": str(p), "scale": irradiance / e_patch,
                                         "rotation": rotation}})
    return sun, patch


def test_small_bright_patch_renders_like_a_sun(ctx, patch_scenes):
    """The patch's irradiance equals the sun's: the images agree within 5% relative RMSE (the
    patch is ~4 degrees wide, so its shadows are a little softer than the sun's), and the
    importance-sampled render has far less noise than phase sampling alone (at half the samples,
    more than 5x less noise: 25x more samples would not close the gap)."""
    sun, patch = patch_scenes
    r = Renderer(ctx, sun)
    ref = r.render("pt", spp=512, seed=1, samples_per_pass=512).image
    ref2 = r.render("pt", spp=512, seed=2, samples_per_pass=512).image
    r.release()
    r = Renderer(ctx, patch)
    a = r.render("pt", spp=256, seed=1, samples_per_pass=256).image
    b = r.render("pt", spp=256, seed=2, samples_per_pass=256).image
    from radiance_probes.rendering.lab_options import LabOptions
    r.lab = LabOptions(environment_sampling=False)
    c = r.render("pt", spp=128, seed=1, samples_per_pass=128).image
    d = r.render("pt", spp=128, seed=2, samples_per_pass=128).image
    r.release()
    img, ref = (a + b) / 2, (ref + ref2) / 2
    rms = math.sqrt(np.mean(ref ** 2))
    rrmse = math.sqrt(np.mean((img - ref) ** 2)) / rms
    # Relative standard errors of the 512-spp map mean and the 1024-spp sun mean, from their
    # halves' differences (phase sampling alone: its 256-spp mean).
    noise_is = math.sqrt(np.mean((a - b) ** 2)) / 2 / rms
    noise_ref = math.sqrt(np.mean((ref - ref2) ** 2)) / rms     # (ref - ref2) / 2 is about the mean's
    noise_phase = math.sqrt(np.mean((c - d) ** 2)) / 2 / rms
    error = math.sqrt(max(rrmse ** 2 - noise_is ** 2 - (noise_ref / 2) ** 2, 0.0))
    print(f"patch vs sun: rRMSE {rrmse:.4f}, less the noise {error:.4f}; relative noise: "
          f"importance {noise_is:.4f} (512 spp), phase only {noise_phase:.4f} (256 spp), "
          f"sun {noise_ref / 2:.4f} (1024 spp)")
    assert ref.max() > 0.1
    assert noise_is < 0.08            # the comparison below can see a 5% error
    assert error < 0.05
    assert abs(img.mean() / ref.mean() - 1) < 0.03
    assert noise_phase > 5 * noise_is


def test_background_is_the_map(ctx, tmp_path):
    """An empty volume: every method shows the map itself, read at the camera rays' directions."""
    from radiance_probes.twins.camera import camera_frame
    h = 32
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = (np.arange(2 * h) + 0.5) / (2 * h) * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    img = np.stack([1 + np.cos(T), 1 + 0.5 * np.sin(P), 1 + 0.3 * np.sin(T) * np.cos(P)], -1)
    p = tmp_path / "smooth.npy"
    np.save(p, img.astype(np.float32))
    scene = parse_scene({"volume": {"builtin": "empty", "size": [4, 4, 4]},
                         "environment": {"map": str(p), "scale": 0.5, "rotation": 30},
                         "light": {"irradiance": [0, 0, 0]}, "probes": {"grid": [2, 2, 2], "samples": 16},
                         "camera": {"eye": [0.3, 0.5, 2.0], "target": [0, 0, 0], "fov_y": 60.0,
                                    "width": 16, "height": 12}})
    frame = camera_frame(scene.camera)
    sub = (np.arange(8) + 0.5) / 8      # the pixel's mean over its area: 8 x 8 points
    rows = (np.arange(12)[:, None] + sub[None, :]).reshape(-1)
    cols = (np.arange(16)[:, None] + sub[None, :]).reshape(-1)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    dirs = frame.ray_directions(cc, rr).astype(np.float64)
    r = Renderer(ctx, scene)
    try:
        for method in ("pt", "probes", "raymarch"):
            image = r.render(method, spp=256, samples_per_pass=256).image
            expect = tw.radiance(img, dirs, 0.5, 30.0).reshape(12, 8, 16, 8, 3).mean(axis=(1, 3))
            np.testing.assert_allclose(image, expect, rtol=0.01, err_msg=method)
    finally:
        r.release()


def test_scene_round_trip_and_bad_fields():
    s = parse_scene({"environment": {"map": "sky.exr", "scale": 2, "rotation": -30}})
    assert s.environment_map == EnvironmentMapSpec("sky.exr", 2.0, -30.0)
    assert parse_scene(s.to_dict()) == s
    assert parse_scene({}).environment_map is None
    for bad, field in (({"scale": 1}, "environment.map"), ({"map": ""}, "environment.map"),
                       ({"map": "a.exr", "scale": -1}, "environment.scale"),
                       ({"map": "a.exr", "rotation": 400}, "environment.rotation"),
                       ({"map": "a.exr", "tint": 1}, "environment.tint"), ("sky.exr", "environment")):
        with pytest.raises(SceneError, match=field.replace(".", r"\.")):
            parse_scene({"environment": bad})


# ---------------------------------------------------------------------------------------------
# Bad map files: one SceneError naming the file and the problem, before any GPU work


def _exr(path, img):
    import OpenEXR
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": np.ascontiguousarray(img, np.float32)}).write(str(path))


def _hdr(path, img):
    import cv2
    assert cv2.imwrite(str(path), np.ascontiguousarray(np.asarray(img, np.float32)[..., ::-1]))


def test_hdr_map_reads(tmp_path):
    """Radiance RGBE keeps 8 bits of mantissa per pixel's largest channel: each pixel within
    1/128 of its largest value, and in RGB (not OpenCV's BGR) order."""
    img = np.random.default_rng(8).uniform(0.1, 5.0, size=(8, 16, 3)).astype(np.float32)
    img[2, 3] = [100.0, 0.5, 0.25]
    _hdr(tmp_path / "sky.hdr", img)
    back = read_environment_map(tmp_path / "sky.hdr")
    assert back.shape == img.shape and back.dtype == np.float32
    assert (np.abs(back - img) <= img.max(axis=-1, keepdims=True) / 128).all()
    assert back[2, 3, 0] > 90 and back[2, 3, 2] < 1


def test_exr_map_reads(tmp_path):
    img = np.random.default_rng(7).uniform(size=(8, 16, 3)).astype(np.float32)
    _exr(tmp_path / "sky.exr", img)
    np.testing.assert_array_equal(read_environment_map(tmp_path / "sky.exr"), img)
    # Relative to the scene file's folder, like volume paths.
    env = load_environment_map(EnvironmentMapSpec("sky.exr"), str(tmp_path))
    np.testing.assert_array_equal(env.image, img)


def _bad_maps(tmp_path):
    good = np.ones((8, 16, 3), np.float32)
    cases = {}
    p = tmp_path / "square.exr"
    _exr(p, np.ones((8, 8, 3)))
    cases["square.exr"] = (p, "2:1")
    for name, value, problem in (("negative.exr", -1.0, "negative"), ("nan.exr", np.nan, "non-finite"),
                                 ("inf.npy", np.inf, "non-finite")):
        img = good.copy()
        img[3, 4, 1] = value
        p = tmp_path / name
        _exr(p, img) if name.endswith(".exr") else np.save(p, img)
        cases[name] = (p, problem)
    _exr(tmp_path / "whole.exr", good)
    whole = (tmp_path / "whole.exr").read_bytes()
    (tmp_path / "truncated.exr").write_bytes(whole[: len(whole) // 2])
    cases["truncated.exr"] = (tmp_path / "truncated.exr", "cannot read")
    (tmp_path / "garbage.exr").write_bytes(b"not an exr file at all")
    cases["garbage.exr"] = (tmp_path / "garbage.exr", "cannot read")
    np.save(tmp_path / "whole.npy", good)
    data = (tmp_path / "whole.npy").read_bytes()
    (tmp_path / "truncated.npy").write_bytes(data[:-40])
    cases["truncated.npy"] = (tmp_path / "truncated.npy", "cannot read")
    cases["missing.exr"] = (tmp_path / "missing.exr", "not found")
    (tmp_path / "sky.hdr").write_bytes(b"#?RADIANCE\n")
    cases["sky.hdr"] = (tmp_path / "sky.hdr", "cannot read")
    _hdr(tmp_path / "whole.hdr", good)
    whole = (tmp_path / "whole.hdr").read_bytes()
    (tmp_path / "truncated.hdr").write_bytes(whole[:-10])
    cases["truncated.hdr"] = (tmp_path / "truncated.hdr", "cannot read")
    (tmp_path / "sky.png").write_bytes(b"\x89PNG")
    cases["sky.png"] = (tmp_path / "sky.png", "unknown environment map format")
    np.save(tmp_path / "grey3d.npy", np.ones((8, 16, 2), np.float32))
    cases["grey3d.npy"] = (tmp_path / "grey3d.npy", "shape")
    return cases


def test_bad_maps_name_the_file_and_the_problem(tmp_path):
    for name, (path, problem) in _bad_maps(tmp_path).items():
        with pytest.raises(SceneError) as info:
            load_environment_map(EnvironmentMapSpec(str(path)))
        message = str(info.value)
        assert name in message and problem in message, message
        assert "\n" not in message


@pytest.mark.parametrize("method", ["pt", "raymarch"])
def test_cli_bad_map_is_one_line_before_the_gpu(tmp_path, capsys, monkeypatch, method):
    """The render command with a bad map: a non-zero exit, one line naming the file and the
    problem, and no GL context made (creating one fails the test)."""
    import json
    import radiance_probes.gl.context
    from radiance_probes.cli.main import main

    def refuse(*_a, **_k):
        raise AssertionError("a GL context was created before the map was checked")
    monkeypatch.setattr(radiance_probes.gl.context, "create_headless_context", refuse)
    for name, (path, problem) in _bad_maps(tmp_path).items():
        scene = tmp_path / f"scene_{name}.json"
        scene.write_text(json.dumps({"environment": {"map": path.name}}))
        rc = main(["render", str(scene), "--out", str(tmp_path / "x.png"), "--method", method])
        _, err = capsys.readouterr()
        lines = [line for line in err.splitlines() if line.strip()]
        assert rc == 2 and len(lines) == 1, (name, rc, lines)
        assert name in lines[0] and problem in lines[0] and "Traceback" not in err, lines[0]
