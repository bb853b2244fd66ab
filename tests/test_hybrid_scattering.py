"""Hybrid scattering (glsl/lib/hybrid_scattering.glsl, the scene's `surface`): the BRDF, its
sampler and pdf against the NumPy twin (app/twins/hybrid_scattering.py); the pdf integrates to 1
and a sampled histogram follows it; the gradient against the twin medium's; k = 0 compiles and
renders today's images bit for bit; a white furnace with a non-absorbing BRDF stays exact; single
scattering with surfaces matches an independent quadrature; bad keys name the field."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import SceneError, parse_scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.twins import hybrid_scattering as hs
from radiance_probes.twins.directions import fibonacci_directions as spherical_fibonacci
from radiance_probes.twins.medium import classified_at
from radiance_probes.io.load import load_scene_volume
from glsl_harness import run_kernel

BRDF_KERNEL = """
#include "lib/medium.glsl"
#include "lib/phase.glsl"
#include "lib/hybrid_scattering.glsl"
layout(std430, binding = 0) readonly buffer In { float a[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
uniform float test_alpha;
uniform vec3 test_f0;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint b = 12u * i;
    vec3 n = vec3(a[b], a[b + 1u], a[b + 2u]);
    vec3 v = vec3(a[b + 3u], a[b + 4u], a[b + 5u]);
    vec3 l = vec3(a[b + 6u], a[b + 7u], a[b + 8u]);
    vec3 k = surface_kernel(n, v, l, test_alpha, test_f0);
    float pdf = surface_pdf(n, v, l, test_alpha, test_f0);
    vec3 weight;
    float sample_pdf;
    vec3 s = surface_sample(n, v, test_alpha, test_f0, a[b + 9u], a[b + 10u], a[b + 11u],
                            weight, sample_pdf);
    uint c = 11u * i;
    o[c] = k.r; o[c + 1u] = k.g; o[c + 2u] = k.b; o[c + 3u] = pdf;
    o[c + 4u] = s.x; o[c + 5u] = s.y; o[c + 6u] = s.z;
    o[c + 7u] = weight.r; o[c + 8u] = weight.g; o[c + 9u] = weight.b; o[c + 10u] = sample_pdf;
}
"""


def _unit(r, n):
    v = r.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _cases(n=512, seed=3):
    r = np.random.default_rng(seed)
    normal = _unit(r, n)
    v = _unit(r, n)
    v = np.where((np.sum(v * normal, 1) < 0)[:, None], -v, v)   # v on n's side, as the shader's
    l = _unit(r, n)
    u = r.uniform(0, 1, (n, 3))
    f32 = lambda x: x.astype(np.float32).astype(np.float64)   # noqa: E731 (what the GPU gets)
    return f32(normal), f32(v), f32(l), f32(u)


@pytest.mark.parametrize("alpha,f0", [(0.3, (0.2, 0.1, 0.05)), (0.8, (0.04, 0.04, 0.04)),
                                      (0.5, (0.0, 0.0, 0.0))])
def test_the_brdf_its_sampler_and_pdf_match_the_twin(ctx, alpha, f0):
    n, v, l, u = _cases()
    data = np.concatenate([n, v, l, u], axis=1).astype(np.float32).ravel()
    out = run_kernel(ctx, BRDF_KERNEL, [data], (len(n), 11), count=len(n),
                     uniforms={"test_alpha": alpha, "test_f0": f0}).astype(np.float64)
    kernel = hs.surface_kernel(n, v, l, alpha, f0)
    pdf = hs.surface_pdf(n, v, l, alpha, f0)
    np.testing.assert_allclose(out[:, :3], kernel, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(out[:, 3], pdf, rtol=2e-4, atol=2e-5)
    s, weight, spdf = hs.surface_sample(n, v, alpha, f0, u[:, 0], u[:, 1], u[:, 2])
    np.testing.assert_allclose(out[:, 4:7], s, atol=2e-4)
    np.testing.assert_allclose(out[:, 10], spdf, rtol=2e-3, atol=2e-4)
    ok = spdf > 1e-2   # a weight's relative error grows as its pdf falls
    np.testing.assert_allclose(out[ok, 7:10], weight[ok], rtol=3e-3, atol=1e-4)
    assert (kernel > 0).any() and (kernel == 0).any()   # both sides of the surface were met
    if max(f0) == 0:   # diffuse alone: the weight is exactly 1 where the sample is above
        assert np.all(out[:, 7:10][spdf > 0] == 1.0)


@pytest.mark.parametrize("alpha", [0.25, 0.6, 1.0])
@pytest.mark.parametrize("f0", [(0.0, 0.0, 0.0), (0.3, 0.2, 0.1)])
@pytest.mark.parametrize("view_deg", [0.0, 50.0, 85.0])
def test_the_pdf_integrates_to_one_and_the_brdf_absorbs_only_its_specular_loss(alpha, f0,
                                                                                view_deg):
    l = spherical_fibonacci(400_000)
    n = np.array([0.0, 0.0, 1.0])
    t = np.radians(view_deg)
    v = np.array([np.sin(t), 0.0, np.cos(t)])
    area = 4 * np.pi / len(l)
    pdf = hs.surface_pdf(n, v, l, alpha, f0)
    assert abs(pdf.sum() * area - 1.0) < 3e-3
    albedo = hs.surface_kernel(n, v, l, alpha, f0).sum(axis=0) * area
    s = max(f0)
    assert np.all(albedo <= 1.0 + 3e-3)
    assert np.all(albedo >= 1.0 - s - 3e-3)      # the diffuse part alone keeps 1 - s
    if s == 0:
        np.testing.assert_allclose(albedo, 1.0, atol=3e-3)   # non-absorbing


@pytest.mark.parametrize("alpha,f0,view_deg", [(0.3, (0.5, 0.5, 0.5), 40.0),
                                               (0.7, (0.1, 0.1, 0.1), 75.0)])
def test_a_sampled_histogram_matches_the_pdf(alpha, f0, view_deg):
    r = np.random.default_rng(11)
    m = 200_000
    n = np.array([0.0, 0.0, 1.0])
    t = np.radians(view_deg)
    v = np.array([np.sin(t), 0.0, np.cos(t)])
    l, weight, pdf = hs.surface_sample(np.broadcast_to(n, (m, 3)), np.broadcast_to(v, (m, 3)),
                                       alpha, f0, r.uniform(size=m), r.uniform(size=m),
                                       r.uniform(size=m))
    # the pdf it returns is the pdf of the direction it drew
    np.testing.assert_allclose(pdf, hs.surface_pdf(n, v, l, alpha, f0), rtol=1e-9)
    # bins over (cos theta, phi) on the whole sphere; expected counts from the pdf by quadrature
    bins_c, bins_p = 12, 8

    def bin_of(d):
        c = np.clip(((d[:, 2] + 1) / 2 * bins_c).astype(int), 0, bins_c - 1)
        p = ((np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi) % 1.0) * bins_p).astype(int) % bins_p
        return c * bins_p + p

    counts = np.bincount(bin_of(l), minlength=bins_c * bins_p)
    q = spherical_fibonacci(1_000_000)
    expected = np.bincount(bin_of(q), weights=hs.surface_pdf(n, v, q, alpha, f0),
                           minlength=bins_c * bins_p) * (4 * np.pi / len(q)) * m
    big = expected > 50
    chi2 = np.sum((counts[big] - expected[big]) ** 2 / expected[big])
    assert chi2 < 3 * big.sum(), (chi2, big.sum())
    assert counts[~big].sum() < 0.01 * m + 3 * np.sqrt(expected[~big].sum() + 1)
    # the weights average the BRDF's albedo (an unbiased estimate of its integral)
    area = 4 * np.pi / len(q)
    want = hs.surface_kernel(n, v, q, alpha, f0).sum(axis=0) * area
    np.testing.assert_allclose(weight.mean(axis=0), want, rtol=0.02)


GRADIENT_KERNEL = """
#include "lib/medium.glsl"
#include "lib/phase.glsl"
#include "lib/hybrid_scattering.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 g = opacity_gradient(vec3(p[3u * i], p[3u * i + 1u], p[3u * i + 2u]));
    o[4u * i] = g.x; o[4u * i + 1u] = g.y; o[4u * i + 2u] = g.z;
    o[4u * i + 3u] = surface_probability(g, surface_gradient_factor);
}
"""


def _scene(**kw):
    base = {"volume": {"builtin": "sphere", "size": [16, 14, 12]},
            "transfer_function": {"colormap": "grey", "opacity": [[0, 0], [1, 1]]},
            "light": {"irradiance": [0, 0, 0]}, "environment": [0, 0, 0]}
    base.update(kw)
    return parse_scene(base)


def test_the_gradient_and_the_surface_chance_match_the_twin(ctx):
    scene = _scene(surface={"gradient_factor": 0.05})
    r = Renderer(ctx, scene)
    try:
        res = r.resources
        assert res.defines().get("HYBRID_SCATTERING") == 1
        volume = res.volume
        pts = np.random.default_rng(2).uniform(-0.45, 0.45, (600, 3)) * volume.half_extent / 0.5
        pts = pts.astype(np.float32).astype(np.float64)
        res.bind()
        out = run_kernel(ctx, GRADIENT_KERNEL, [pts.astype(np.float32).ravel()], (len(pts), 4),
                         count=len(pts), uniforms=res.uniforms(),
                         defines=res.defines()).astype(np.float64)
        table = transfer_table(scene.transfer_function)
        step = 2.0 * volume.half_extent / np.array(volume.dims)
        want = hs.opacity_gradient(lambda x: classified_at(volume, table, x)[..., 3], pts, step)
    finally:
        r.release()
    np.testing.assert_allclose(out[:, :3], want, atol=1e-3 * np.abs(want).max())
    np.testing.assert_allclose(out[:, 3], hs.surface_probability(want, 0.05), atol=1e-3)
    assert np.abs(want).max() > 1.0 and (out[:, 3] > 0.3).any() and (out[:, 3] < 0.01).any()


def _render(ctx, scene, method="pt", spp=4, seed=0):
    r = Renderer(ctx, scene)
    try:
        result = r.render(method, spp=spp, seed=seed, samples_per_pass=spp)
        hybrid = r.resources.defines().get("HYBRID_SCATTERING")
    finally:
        r.release()
    return result.image, hybrid


LIT = {"light": {"direction": [0.4, 0.8, 0.45], "irradiance": [3, 3, 3]},
       "environment": [0.2, 0.3, 0.4], "density_scale": 30.0,
       "camera": {"eye": [0.3, 0.2, 1.6], "width": 10, "height": 8},
       "probes": {"grid": 4, "samples": 8}}


@pytest.mark.parametrize("method", ["pt", "probes", "raymarch"])
def test_k_zero_is_todays_image_bit_for_bit(ctx, method):
    """k = 0 compiles without HYBRID_SCATTERING whatever the other surface keys: the same program,
    the same image bits as a scene without surfaces; k > 0 changes the image."""
    plain, hybrid_plain = _render(ctx, _scene(**LIT), method)
    zero, hybrid_zero = _render(ctx, _scene(**LIT, surface={"gradient_factor": 0.0,
                                                            "roughness": 0.1,
                                                            "specular": [0.9, 0.5, 0.1]}), method)
    assert hybrid_plain is None and hybrid_zero is None
    assert plain.tobytes() == zero.tobytes()
    lit, hybrid_lit = _render(ctx, _scene(**LIT, surface={"gradient_factor": 0.5}), method)
    assert hybrid_lit == 1 and np.abs(lit - plain).max() > 1e-3


@pytest.mark.parametrize("method", ["raymarch", "probes"])
def test_an_isotropic_phase_function_reads_band_zero_alone_for_the_same_image(ctx, method,
                                                                             monkeypatch):
    """With surfaces and g = 0 the passes that read the probes are built with PHASE_ISOTROPIC
    (lib/probes.glsl: the phase function's light from the probes' band 0 alone, as g^l = 0 above
    it): the image of the full sum to float rounding. g != 0 and k = 0 keep the full sum."""
    from radiance_probes.rendering.resources import SceneResources

    def render(scene):
        r = Renderer(ctx, scene)
        try:
            image = r.render(method, spp=4, seed=3, samples_per_pass=4).image
            return image, r.resources.defines().get("PHASE_ISOTROPIC")
        finally:
            r.release()
    scene = _scene(**{**LIT, "anisotropy": 0.0}, surface={"gradient_factor": 0.5})
    image, isotropic = render(scene)
    real = SceneResources.defines
    monkeypatch.setattr(SceneResources, "defines", lambda self: {
        k: v for k, v in real(self).items() if k != "PHASE_ISOTROPIC"})
    full, dropped = render(scene)
    monkeypatch.setattr(SceneResources, "defines", real)
    assert isotropic == 1 and dropped is None
    assert np.abs(full).max() > 0
    np.testing.assert_allclose(image, full, rtol=1e-5, atol=1e-6 * np.abs(full).max())
    assert render(_scene(**{**LIT, "anisotropy": 0.3}, surface={"gradient_factor": 0.5}))[1] is None
    assert render(_scene(**{**LIT, "anisotropy": 0.0}))[1] is None


def test_with_surfaces_the_path_tracer_keeps_the_clip_tests_for_the_same_image(ctx, monkeypatch):
    """With surfaces and no crop, glsl/pathtrace.comp is built with the crop and clip tests (their
    uniforms saying none; compiled out they made the hybrid sample 16% slower on an H200), and its
    image is bit for bit the one the pass with the tests compiled out makes; without surfaces the
    tests stay compiled out."""
    from radiance_probes.rendering import renderer as renderer_module
    scene = _scene(**LIT, surface={"gradient_factor": 0.5})
    built = []
    real = renderer_module.PathTracer

    def tracer(ctx_, defines=None, **kw):
        built.append(dict(defines or {}))
        return real(ctx_, defines, **kw)
    monkeypatch.setattr(renderer_module, "PathTracer", tracer)
    kept, _ = _render(ctx, scene)
    assert built and all("NO_CLIP_REGION" not in d and d.get("HYBRID_SCATTERING") for d in built)

    def folded(ctx_, defines=None, **kw):
        return real(ctx_, {**(defines or {}), "NO_CLIP_REGION": 1}, **kw)
    monkeypatch.setattr(renderer_module, "PathTracer", folded)
    out, _ = _render(ctx, scene)
    assert kept.tobytes() == out.tobytes()
    built.clear()
    monkeypatch.setattr(renderer_module, "PathTracer", tracer)
    _render(ctx, _scene(**LIT))
    assert built and all(d.get("NO_CLIP_REGION") == 1 for d in built)


def test_surfaces_switched_on_in_a_renderer_bake_its_light_grid_again(ctx):
    """k from 0 to > 0 in one Renderer (the viewer's slider) changes the medium's defines, so the
    light grid's pass is compiled anew; its grid (same key: k is not in it) is baked again, not
    read from the new pass's empty texture."""
    scene = _scene(**LIT)
    r = Renderer(ctx, scene)
    try:
        r.render("raymarch", spp=1)
        r.set_scene(scene.replace(surface=type(scene.surface)(gradient_factor=0.5)))
        image = r.render("raymarch", spp=1).image
        r.set_scene(scene)
        again = r.render("raymarch", spp=1).image
    finally:
        r.release()
    assert np.isfinite(image).all() and np.abs(image - again).max() > 1e-3


def test_white_furnace_with_a_non_absorbing_brdf(ctx):
    """Albedo 1 in a uniform environment with surfaces everywhere the opacity changes, the BRDF
    diffuse alone (F0 = 0): every path still escapes with throughput 1, each pixel the
    environment to float rounding, as without surfaces."""
    env = [0.25, 0.5, 1.0]
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "albedo": 1.0, "density_scale": 100.0, "environment": env,
                         "light": {"irradiance": [0, 0, 0]}, "max_bounces": 1_000_000_000,
                         "surface": {"gradient_factor": 5.0, "specular": [0, 0, 0]},
                         "camera": {"eye": [0.0, 0.1, 1.2], "fov_y": 20.0, "width": 10,
                                    "height": 10}})
    img, hybrid = _render(ctx, scene, spp=4)
    assert hybrid == 1
    np.testing.assert_allclose(img, np.broadcast_to(env, img.shape), rtol=2e-6)


def test_the_probes_walks_in_a_furnace_with_surfaces(ctx):
    """The probes' walks run the same integrator: in the furnace with a non-absorbing BRDF every
    walk brings back the environment exactly, so every probe's L00 is env sqrt(4 pi) to float
    rounding; and the raymarcher and `probes` reading them through the surfaces' SH irradiance
    show the environment within a few percent (the clamped cosine of a constant is exact, the
    order-2 SH of the probes' constant radiance too)."""
    env = np.array([0.25, 0.5, 1.0])
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "albedo": 1.0, "density_scale": 10.0, "environment": list(env),
                         "light": {"irradiance": [0, 0, 0]}, "max_bounces": 1_000_000,
                         "surface": {"gradient_factor": 5.0, "specular": [0, 0, 0]},
                         "probes": {"grid": [2, 2, 2], "samples": 8},
                         "camera": {"eye": [0.0, 0.1, 1.2], "fov_y": 20.0, "width": 8,
                                    "height": 8}})
    r = Renderer(ctx, scene)
    try:
        r.configure(walk_adaptive=0.0)
        r.bake()
        assert r.resources.defines().get("HYBRID_SCATTERING") == 1
        assert r.probe_grid.sh_order == 2          # surfaces keep the probes' directions
        l00 = r.probe_grid.coefficients()[..., 0:3] / np.sqrt(4 * np.pi)
        np.testing.assert_allclose(l00, np.broadcast_to(env, l00.shape), rtol=2e-5)
        for method in ("raymarch", "probes"):
            image = r.render(method, spp=2).image
            np.testing.assert_allclose(image.mean(axis=(0, 1)), env, rtol=0.03)
    finally:
        r.release()


def _hybrid_single_scatter(scene, volume, sub=3, steps=160, shadow_steps=48):
    """Per-pixel single-scattered sun (RGB) by nested quadrature, each point's kernel the mean
    of the phase function and the surface BRDF's K by their chances (1 - P, P): the answer the
    path tracer's random choice must average to. Independent of the GLSL."""
    from transport_reference import optical_depth, pixel_rays
    from radiance_probes.twins.medium import albedo_at, box_intersect, sigma_t_at
    from radiance_probes.twins.phase import phase_hg
    cam, dirs = pixel_rays(scene, sub)
    table = transfer_table(scene.transfer_function)
    he = volume.half_extent.astype(np.float64)
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(he, eye, dirs)
    t1 = np.where(hit, t1, t0)
    sun = np.asarray(scene.light.direction, np.float64)
    E = np.asarray(scene.light.irradiance, np.float64)
    s = scene.surface
    step = 2.0 * he / np.array(volume.dims)
    dt = (t1 - t0) / steps
    out = np.zeros(dirs.shape[:-1] + (3,))
    tau_cam = np.zeros(dirs.shape[:-1])
    for k in range(steps):
        t = t0 + (t1 - t0) * (k + 0.5) / steps
        x = eye + t[..., None] * dirs
        sig = sigma_t_at(volume, table, scene.density_scale, x)
        tau_mid = tau_cam + 0.5 * sig * dt
        _, s1, _ = box_intersect(he, x, np.broadcast_to(sun, x.shape))
        tau_sun = optical_depth(volume, table, scene.density_scale, x,
                                np.broadcast_to(sun, x.shape), np.zeros_like(s1), s1, shadow_steps)
        grad = hs.opacity_gradient(lambda p: classified_at(volume, table, p)[..., 3], x, step)
        chance = hs.surface_probability(grad, s.gradient_factor)[..., None]
        with np.errstate(invalid="ignore", divide="ignore"):
            normal = hs.surface_normal(grad, -dirs)
        surface = np.nan_to_num(hs.surface_kernel(normal, -dirs, np.broadcast_to(sun, x.shape),
                                                  s.roughness, s.specular))
        kernel = (1 - chance) * phase_hg(dirs @ sun, scene.anisotropy)[..., None] + chance * surface
        w = (np.exp(-tau_mid - tau_sun) * sig * dt)[..., None]
        out += w * kernel * albedo_at(volume, table, scene.albedo, x) * E
        tau_cam += sig * dt
    return out.mean(axis=-2)


def test_single_scattering_with_surfaces_matches_quadrature(ctx):
    """A soft ball lit by the sun, one scattering event, surfaces where its edge is (P from 0 inside
    to ~1 at the edge, a specular lobe): the path tracer's image is the quadrature's plus noise."""
    scene = _scene(volume={"builtin": "sphere", "size": [16, 16, 16]}, density_scale=6.0,
                   albedo=0.9, anisotropy=0.3, max_bounces=1,
                   light={"direction": [0.5, 0.7, 0.5], "irradiance": [2.0, 1.5, 1.0]},
                   surface={"gradient_factor": 0.3, "roughness": 0.4, "specular": [0.3, 0.3, 0.3]},
                   camera={"eye": [0.3, 0.1, 1.0], "fov_y": 40.0, "width": 10, "height": 8})
    volume = load_scene_volume(scene)
    ref = _hybrid_single_scatter(scene, volume)
    a, _ = _render(ctx, scene, spp=512, seed=1)
    b, _ = _render(ctx, scene, spp=512, seed=2)
    noise_var = np.mean((a - b) ** 2) / 2
    err_var = np.mean(((a + b) / 2 - ref) ** 2)
    assert err_var < 1.5 * noise_var / 2 + (5e-3 * ref.mean()) ** 2, (err_var, noise_var)
    np.testing.assert_allclose(((a + b) / 2).mean(axis=(0, 1)), ref.mean(axis=(0, 1)), rtol=0.03)
    # the surfaces matter here: the phase function alone gives another image
    plain = _hybrid_single_scatter(scene.replace(surface=type(scene.surface)()), volume)
    assert abs(plain.mean() - ref.mean()) > 0.1 * ref.mean()


ROULETTE_KERNEL = """
#include "lib/medium.glsl"
#include "lib/phase.glsl"
#include "lib/hybrid_scattering.glsl"
layout(std430, binding = 0) readonly buffer In { float a[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    o[i] = hybrid_march_roulette(a[2u * i], a[2u * i + 1u]);
}
"""


def test_the_raymarchers_roulette_matches_the_twin_and_keeps_the_mean(ctx):
    """hybrid_march_roulette against its twin, and the twin's mean transmittance over u is the
    transmittance."""
    r = np.random.default_rng(5)
    n = 4096
    threshold = hs.HYBRID_MARCH_ROULETTE_TRANSMITTANCE
    transmittance = (threshold * 10.0 ** r.uniform(-4, 0, n)).astype(np.float32)
    u = r.uniform(0, 1, n).astype(np.float32)
    out = run_kernel(ctx, ROULETTE_KERNEL, [np.stack([transmittance, u], 1).ravel()], (n,),
                     count=n)
    twin = hs.hybrid_march_roulette(transmittance, u)
    margin = np.abs(u - transmittance / threshold) > 1e-6   # not on the rounding's edge
    np.testing.assert_array_equal(out[margin], twin[margin])
    assert (twin > 0).any() and (twin == 0).any()
    m = 200_000
    for t in (0.3 * threshold, 0.077 * threshold, 0.99 * threshold):
        mean = hs.hybrid_march_roulette(np.float32(t), r.uniform(0, 1, m)).mean()
        assert abs(mean / t - 1) < 4 * np.sqrt((threshold / t - 1) / m), (t, mean)


def _raymarch_frames_mean(ctx, scene, frames, seed, monkeypatch, roulette=True):
    """The raymarcher's mean of `frames` frames; roulette False: built with
    HYBRID_MARCH_NO_ROULETTE (the march stops at transmittance 1e-6, as without surfaces)."""
    from radiance_probes.rendering import renderer as renderer_module
    real = renderer_module.Raymarcher
    if not roulette:
        monkeypatch.setattr(renderer_module, "Raymarcher", lambda ctx_, stage, defines=None: real(
            ctx_, stage, {**(defines or {}), "HYBRID_MARCH_NO_ROULETTE": 1}))
    try:
        image, hybrid = _render(ctx, scene, "raymarch", spp=frames, seed=seed)
    finally:
        monkeypatch.setattr(renderer_module, "Raymarcher", real)
    assert hybrid == 1
    return image.astype(np.float64)


def test_the_hybrid_raymarchers_roulette_averages_to_the_full_march(ctx, monkeypatch):
    """With surfaces the raymarcher ends rays below transmittance 2e-2 by a roulette. A cloud dark
    in front of a bright environment, where many camera rays fall below 1e-3 inside it and the
    light from beyond is much of what reaches the camera: with the same seeds (the same rays and
    jitter) the mean over frames is the march that goes on to 1e-6, within the roulette's noise,
    overall and pixel by pixel (a roulette that kept the transmittance instead of carrying 2e-2
    fails by tens of standard errors). The full march's stop at 1e-6 leaves out at most 1e-6 of
    the environment, which the roulette's rays still bring: allowed for."""
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [16, 16, 16]},
                         "transfer_function": {"rgba": [[1.0, 0.9, 0.8, 0.0],
                                                        [0.9, 0.8, 1.0, 1.0]]},
                         "light": {"direction": [0.4, 0.8, 0.45], "irradiance": [3, 3, 3]},
                         "surface": {"gradient_factor": 0.3, "roughness": 0.3,
                                     "specular": [0.3, 0.3, 0.3]},
                         "probes": {"grid": 4, "samples": 8},
                         "camera": {"eye": [0.1, 0.3, 1.5], "fov_y": 22.0, "width": 16,
                                    "height": 12},
                         "density_scale": 35.0, "albedo": 0.02, "anisotropy": 0.5,
                         "environment": [4.0, 6.0, 8.0]})
    seeds, frames = 8, 64
    diff = np.array([_raymarch_frames_mean(ctx, scene, frames, seed, monkeypatch)
                     - _raymarch_frames_mean(ctx, scene, frames, seed, monkeypatch,
                                             roulette=False) for seed in range(1, seeds + 1)])
    truncated = 1e-6 * max(scene.environment)
    seed_means = diff.mean(axis=(1, 2, 3))
    se = seed_means.std(ddof=1) / np.sqrt(seeds)
    assert se > 0   # the roulette is drawn
    assert abs(seed_means.mean()) < 5 * se + truncated, (seed_means.mean(), se)
    mean, var = diff.mean(0), diff.var(0, ddof=1)
    drawn = var > 0
    assert np.all(np.abs(mean[~drawn]) <= truncated)
    # each pixel's mean beyond what the stop at 1e-6 may leave out, against its spread over the
    # seeds: t^2 of 7 degrees of freedom (F(1, 7)) at most, whose median is 0.51 (the median, not
    # the mean: a pixel's roulette noise is a few rare survivals, skewed, and its t^2 has a long
    # tail; the roulette's noise is small, so the stop's share, up to 1e-3 of a dark pixel, would
    # otherwise stand out)
    excess = np.maximum(np.abs(mean[drawn]) - truncated, 0.0)
    t2 = excess ** 2 / (var[drawn] / seeds)
    assert drawn.sum() > 100 and np.median(t2) < 1.0, np.median(t2)
    # the roulette is met: camera rays of optical depth above ln(1000) through the cloud
    from transport_reference import optical_depth, pixel_rays
    from radiance_probes.twins.medium import box_intersect
    volume = load_scene_volume(scene)
    cam, dirs = pixel_rays(scene, 1)
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(volume.half_extent.astype(np.float64), eye, dirs)
    tau = optical_depth(volume, transfer_table(scene.transfer_function), scene.density_scale,
                        eye, dirs, t0, np.where(hit, t1, t0), 256)
    assert np.mean(tau > np.log(1e3)) > 0.2, np.mean(tau > np.log(1e3))


@pytest.mark.parametrize("surface, needle", [
    ({"gradient_factor": -1}, "surface.gradient_factor: must be >= 0.0"),
    ({"gradient_factor": 1e9}, "surface.gradient_factor: must be <= 10000"),
    ({"roughness": 0.0}, "surface.roughness: must be >= 0.02"),
    ({"specular": [0.1, 2, 0]}, "surface.specular[1]: must be <= 1.0"),
    ({"specular": 0.5}, "surface.specular: expected a list of 3 numbers"),
    ({"k": 1}, "unknown field surface.k"),
])
def test_bad_surface_keys_name_the_field(surface, needle):
    with pytest.raises(SceneError) as err:
        parse_scene({"surface": surface})
    assert needle in str(err.value)


def test_a_clinical_preset_brings_its_surface_unless_the_scene_gives_one():
    s = parse_scene({"volume": {"path": "ct.nii"}, "transfer_function": {"preset": "ct_bone"}})
    assert s.surface.gradient_factor > 0
    own = parse_scene({"volume": {"path": "ct.nii"}, "transfer_function": {"preset": "ct_bone"},
                       "surface": {"gradient_factor": 0}})
    assert own.surface.gradient_factor == 0


def test_the_twin_of_the_probes_surface_radiance_is_the_cosine_integral():
    """surface_probe_radiance's diffuse part is (1 - s) / pi times the irradiance: for order-2 SH
    radiance the clamped-cosine integral over n's hemisphere, by quadrature."""
    from radiance_probes.twins.sh import sh_evaluate, sh_project_function
    coeffs = sh_project_function(lambda w: np.stack([1 + w[..., 0], 1 + 0.5 * w[..., 2],
                                                     np.ones(w.shape[:-1])], -1), order=2)
    n = np.array([0.6, 0.0, 0.8])
    v = np.array([0.0, 0.0, 1.0])
    q = spherical_fibonacci(200_000)
    cos = np.maximum(q @ n, 0)
    irradiance = (sh_evaluate(coeffs, q) * cos[:, None]).sum(0) * 4 * np.pi / len(q)
    got = hs.surface_probe_radiance(coeffs, n, v, (0.0, 0.0, 0.0))
    np.testing.assert_allclose(got, irradiance / np.pi, rtol=2e-3)


def test_furnace_under_a_constant_map_with_surfaces(ctx, tmp_path):
    """Albedo 1, a diffuse BRDF at every edge of the cloud, a constant environment map: each path
    mixes the map's samples (weighted against the BRDF's pdf at surface events) and its escapes,
    so the image is the environment within its noise only if the MIS weights of both sides use
    the same pdfs."""
    env = np.array([0.25, 0.5, 1.0])
    path = tmp_path / "constant.npy"
    np.save(path, np.broadcast_to(env, (16, 32, 3)).astype(np.float32))
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                         "transfer_function": {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]},
                         "albedo": 1.0, "density_scale": 30.0, "environment": {"map": str(path)},
                         "light": {"irradiance": [0, 0, 0]}, "max_bounces": 1_000_000,
                         "surface": {"gradient_factor": 5.0, "specular": [0, 0, 0]},
                         "camera": {"eye": [0.0, 0.1, 1.2], "fov_y": 20.0, "width": 10,
                                    "height": 10}})
    img, hybrid = _render(ctx, scene, spp=64)
    assert hybrid == 1
    se = img.std(axis=(0, 1)) / np.sqrt(img.shape[0] * img.shape[1])
    assert (np.abs(img.mean(axis=(0, 1)) - env) < 4 * se + 1e-6).all(), (img.mean(axis=(0, 1)), se)
    assert (np.abs(img.mean(axis=(0, 1)) / env - 1) < 0.03).all()


def test_the_surface_option_merges_into_the_scene():
    import argparse
    from radiance_probes.frontend.option_types import OptionError, surface_arg
    from radiance_probes.frontend.scene_options import apply_options, scene_from_arg
    scene = scene_from_arg(None)
    out = apply_options(scene, argparse.Namespace(surface=surface_arg("2,0.3,0.1")))
    assert (out.surface.gradient_factor, out.surface.roughness, out.surface.specular) == (
        2.0, 0.3, (0.1, 0.1, 0.1))
    with pytest.raises(OptionError, match="--surface: surface.gradient_factor: must be >= 0.0"):
        apply_options(scene, argparse.Namespace(surface=surface_arg("-1")))
    with pytest.raises(argparse.ArgumentTypeError, match="K,ROUGHNESS"):
        surface_arg("shiny")
