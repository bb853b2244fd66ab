"""Area lights (the scene's area_lights; glsl/lib/area_lights.glsl, AREA_LIGHTS): the sampler and
its pdf against the NumPy twin (app/twins/area_lights.py); the pdf integrates to 1 over the
directions that meet a light; a small sphere light far away lights the volume as the sun of the
same irradiance does (pt, probes); no light on compiles every pass as before; bad
lights (a negative size, a light in the volume) are refused naming the field. (The raymarcher and
probes-only take the lights' scattered light from the probes and their direct single scattering
from an optical-depth grid per light: tests/test_area_light_grid.py.)"""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.scene.area_lights import check_area_lights, light_geometry
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import SceneError, parse_scene
from radiance_probes.twins import area_lights as twin
from radiance_probes.twins.directions import fibonacci_directions
from glsl_harness import run_kernel

LIGHTS = [{"shape": "sphere", "position": [0.2, 1.4, 0.3], "size": 0.3, "colour": [1, 0.8, 0.6],
           "strength": 5.0},
          {"shape": "rectangle", "position": [1.1, 0.1, -0.2], "size": [0.6, 0.4],
           "normal": [-1, 0.2, 0.1], "strength": 3.0}]

SAMPLE_KERNEL = """
#include "lib/phase.glsl"
#include "lib/area_lights.glsl"
layout(std430, binding = 0) readonly buffer In { float a[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint b = 6u * i;
    vec3 x = vec3(a[b], a[b + 1u], a[b + 2u]);
    vec3 radiance;
    float pdf;
    vec3 w = area_light_sample(x, a[b + 3u], a[b + 4u], a[b + 5u], radiance, pdf);
    float t;
    int hit = area_light_first_hit(x, w, t);
    float again = hit >= 0 ? area_light_pdf(hit, x, w, t) : 0.0;
    uint c = 8u * i;
    o[c] = w.x; o[c + 1u] = w.y; o[c + 2u] = w.z;
    o[c + 3u] = radiance.r; o[c + 4u] = radiance.g; o[c + 5u] = radiance.b;
    o[c + 6u] = pdf; o[c + 7u] = again;
}
"""


def _lights(scene):
    return [light_geometry(light) for light in scene.area_lights if light.enabled]


def test_the_sampler_matches_the_twin_and_its_pdf_is_the_one_a_hit_reads(ctx):
    scene = parse_scene({"area_lights": LIGHTS})
    lights = _lights(scene)
    r = np.random.default_rng(5)
    n = 400
    x = r.uniform(-0.5, 0.5, (n, 3))
    x[-40:] = [1.6, 0.0, -0.2]          # behind the rectangle: its back face sends nothing
    u = r.uniform(0, 1, (n, 3))
    data = np.concatenate([x, u], axis=1).astype(np.float32)
    from radiance_probes.scene.area_lights import area_light_uniforms
    out = run_kernel(ctx, SAMPLE_KERNEL, [data.ravel()], (n, 8), count=n,
                     uniforms=area_light_uniforms(scene)).astype(np.float64)
    data = data.astype(np.float64)
    checked = 0
    for k in range(n):
        w, radiance, pdf = twin.sample(lights, data[k, :3], *data[k, 3:])
        np.testing.assert_allclose(out[k, :3], w, atol=2e-4)
        if pdf > 0 and out[k, 6] > 0:
            np.testing.assert_allclose(out[k, 3:6], radiance, rtol=1e-5)
            np.testing.assert_allclose(out[k, 6], pdf, rtol=2e-3)
            checked += 1
        # the pdf a sample reports is the one a path that drew the same direction reads at its hit
        if out[k, 6] > 0:
            assert out[k, 7] == pytest.approx(out[k, 6], rel=1e-5)
    assert checked > 0.8 * n
    behind = out[-40:]
    rect = data[-40:, 3] >= 0.5   # those that chose the rectangle: its back, no radiance
    assert rect.any() and np.all(behind[rect, 3:6] == 0) and np.all(behind[~rect, 3:6] > 0)


@pytest.mark.parametrize("x", [[0.0, 0.0, 0.0], [0.45, -0.3, 0.2], [-0.4, 0.45, -0.45]])
def test_the_light_pdf_integrates_to_one_over_the_directions_that_meet_a_light(x):
    lights = _lights(parse_scene({"area_lights": LIGHTS}))
    dirs = fibonacci_directions(40_000)
    pdf = np.array([twin.direction_pdf(lights, x, w) for w in dirs])
    assert abs(pdf.sum() * 4 * np.pi / len(dirs) - 1.0) < 0.03
    # and sampled directions land where the pdf says (a coarse histogram over the two lights)
    r = np.random.default_rng(1)
    hits = [twin.first_hit(lights, x, twin.sample(lights, x, *r.uniform(size=3))[0])[0]
            for _ in range(2000)]
    share = np.mean(np.array(hits) == 0)
    assert abs(share - 0.5) < 0.04     # each light chosen half the time, every sample meets it


SUN_DIRECTION = np.array([0.3, 0.8, 0.52])
SUN_DIRECTION = SUN_DIRECTION / np.linalg.norm(SUN_DIRECTION)


def _lit(kind, **kw):
    """The soft ball lit by the sun, or by a sphere light of radius 0.5 at distance 60 along the
    sun's direction whose irradiance on a plane facing it is the sun's: E = L pi sin^2 theta."""
    E = 2.0
    base = {"volume": {"builtin": "sphere", "size": [12, 12, 12]},
            "transfer_function": {"colormap": "grey", "opacity": [[0, 0], [1, 1]]},
            "density_scale": 4.0, "albedo": 0.9, "environment": [0, 0, 0], "max_bounces": 4,
            "camera": {"eye": [0.2, 0.1, 1.4], "fov_y": 30.0, "width": 8, "height": 8},
            "probes": {"grid": 4, "samples": 64}}
    if kind == "sun":
        base["light"] = {"direction": list(SUN_DIRECTION), "irradiance": [E] * 3}
    else:
        R, r = 60.0, 0.5
        L = E / (np.pi * r * r / (R * R))
        base["light"] = {"irradiance": [0, 0, 0]}
        base["area_lights"] = [{"shape": "sphere", "position": list(R * SUN_DIRECTION),
                                "size": r, "strength": L}]
    base.update(kw)
    return parse_scene(base)


def _image(ctx, scene, method, spp, seed=1):
    r = Renderer(ctx, scene)
    try:
        image = r.render(method, spp=spp, seed=seed, samples_per_pass=min(spp, 256)).image
        on = r.resources.defines().get("AREA_LIGHTS")
    finally:
        r.release()
    return image, on


def test_a_small_far_sphere_light_is_the_sun_in_the_path_tracer(ctx):
    sun, on_sun = _image(ctx, _lit("sun"), "pt", 512)
    light, on_light = _image(ctx, _lit("light"), "pt", 512, seed=2)
    assert on_sun is None and on_light == 1
    se = np.sqrt(sun.var() / sun.size + light.var() / light.size)
    assert abs(light.mean() - sun.mean()) < 4 * se + 0.01 * sun.mean(), (light.mean(), sun.mean())
    assert np.sqrt(np.mean((light - sun) ** 2)) < 0.1 * np.sqrt(np.mean(sun ** 2))


def test_a_small_far_sphere_light_is_the_sun_in_probes(ctx):
    """The probes' walks sample the light at their events as the path tracer does and, as for the
    sun, leave out the light they meet before scattering; `probes` adds that direct part by a light
    sample at its gather event, as it adds the sun by a shadow ray: the light's image is the sun's
    within the probes' own noise."""
    sun, _ = _image(ctx, _lit("sun"), "probes", 16)
    light, _ = _image(ctx, _lit("light"), "probes", 16)
    assert abs(light.mean() / sun.mean() - 1) < 0.1, (light.mean(), sun.mean())


def test_no_light_on_compiles_the_passes_as_before(ctx):
    """All lights switched off: no AREA_LIGHTS, the same image bits as a scene without lights."""
    plain, _ = _image(ctx, _lit("sun"), "pt", 4)
    off, on = _image(ctx, _lit("sun", area_lights=[{**LIGHTS[0], "enabled": False}]), "pt", 4)
    assert on is None and plain.tobytes() == off.tobytes()


@pytest.mark.parametrize("lights, needle", [
    ([{**LIGHTS[0], "size": -1}], "area_lights[0].size: must be > 0.0"),
    ([{**LIGHTS[1], "size": [0.5, 0]}], "area_lights[0].size[1]: must be > 0"),
    ([{**LIGHTS[0], "shape": "disk"}], "area_lights[0].shape: expected one of sphere, rectangle"),
    ([{**LIGHTS[0], "strength": -2}], "area_lights[0].strength: must be >= 0.0"),
    ([{"shape": "sphere", "size": 1}], "area_lights[0].position: missing"),
    ([{**LIGHTS[1], "normal": [0, 0, 0]}], "area_lights[0].normal: must not be the zero vector"),
    ([LIGHTS[0]] * 9, "area_lights: 9 lights, at most 8"),
])
def test_bad_lights_name_the_field(lights, needle):
    with pytest.raises(SceneError) as err:
        parse_scene({"area_lights": lights})
    assert needle in str(err.value)


def test_a_light_in_the_volume_is_refused(ctx):
    half = np.array([0.5, 0.5, 0.4])
    inside = [{"shape": "sphere", "position": [0.0, 0.8, 0.0], "size": 0.35},
              {"shape": "rectangle", "position": [0.6, 0.0, 0.0], "size": [0.5, 0.3],
               "normal": [1, 1, 0]}]
    for i, light in enumerate(inside):
        scene = parse_scene({"area_lights": [LIGHTS[0], light]})
        with pytest.raises(SceneError, match=r"area_lights\[1\]: the .* reaches into the volume "
                                             r"box \(1 x 1 x 0.8"):
            check_area_lights(scene, half)
    check_area_lights(parse_scene({"area_lights": LIGHTS}), half)   # these stay outside
    # the renderer refuses it before rendering
    with pytest.raises(SceneError, match="reaches into the volume box"):
        Renderer(ctx, parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                                   "area_lights": [inside[0]]}))


def _light_single_scatter(scene, volume, sub=2, steps=40, directions=20000, shadow_steps=24):
    """Single scattering of the scene's one sphere light by quadrature: along each camera ray, at
    each point the light's radiance over the directions of its cone (a Fibonacci set), times the
    transmittance to the box's boundary and the phase function. Independent of the GLSL."""
    from transport_reference import optical_depth, pixel_rays
    from radiance_probes.scene.transfer import transfer_table
    from radiance_probes.twins.medium import albedo_at, box_intersect, sigma_t_at
    from radiance_probes.twins.phase import phase_hg
    cam, rays = pixel_rays(scene, sub)
    table = transfer_table(scene.transfer_function)
    he = volume.half_extent.astype(np.float64)
    eye = np.broadcast_to(cam.eye.astype(np.float64), rays.shape)
    t0, t1, hit = box_intersect(he, eye, rays)
    t1 = np.where(hit, t1, t0)
    light = _lights(scene)[0]
    radiance = np.asarray(light[4])
    dirs = fibonacci_directions(directions)
    out = np.zeros(rays.shape[:-1] + (3,))
    tau_cam = np.zeros(rays.shape[:-1])
    dt = (t1 - t0) / steps
    for k in range(steps):
        x = eye + (t0 + (t1 - t0) * (k + 0.5) / steps)[..., None] * rays
        sig = sigma_t_at(volume, table, scene.density_scale, x)
        tau_mid = tau_cam + 0.5 * sig * dt
        flat, flat_rays, flat_sig = x.reshape(-1, 3), rays.reshape(-1, 3), sig.reshape(-1)
        seen_light = np.zeros(len(flat))
        for j, p in enumerate(flat):
            if flat_sig[j] <= 0:
                continue
            _, axis, cos_max = twin.cone(light, p)
            ws = dirs[dirs @ axis >= cos_max]
            _, s1, _ = box_intersect(he, np.broadcast_to(p, ws.shape), ws)
            tau = optical_depth(volume, table, scene.density_scale, np.broadcast_to(p, ws.shape),
                                ws, np.zeros(len(ws)), s1, shadow_steps)
            ph = phase_hg(ws @ flat_rays[j], scene.anisotropy)
            seen_light[j] = (np.exp(-tau) * ph).sum() * 4 * np.pi / len(dirs)
        w = (np.exp(-tau_mid) * sig * dt * seen_light.reshape(sig.shape))[..., None]
        out += w * albedo_at(volume, table, scene.albedo, x) * radiance
        tau_cam += sig * dt
    return out.mean(axis=-2)


def test_single_scattering_of_a_near_light_matches_quadrature(ctx):
    """A large light close to the volume, one scattering event: light samples and phase-sampled
    paths that meet the light both count, each weighted by MIS; their sum must be the quadrature's
    answer (a wrong weight on either side shows as bias)."""
    scene = parse_scene({"volume": {"builtin": "constant", "size": [8, 8, 8]},
                         "transfer_function": {"rgba": [[1, 1, 1, 1], [1, 1, 1, 1]]},
                         "density_scale": 2.0, "albedo": 0.9, "anisotropy": 0.3, "max_bounces": 1,
                         "light": {"irradiance": [0, 0, 0]}, "environment": [0, 0, 0],
                         "area_lights": [{"shape": "sphere", "position": [0.1, 0.95, 0.2],
                                          "size": 0.35, "strength": 2.0}],
                         # inside the box, looking through the medium: no silhouettes to resolve
                         "camera": {"eye": [0.0, -0.3, 0.4], "target": [0.1, 0.2, -0.4],
                                    "fov_y": 50.0, "width": 5, "height": 5}})
    from radiance_probes.io.load import load_scene_volume
    ref = _light_single_scatter(scene, load_scene_volume(scene), steps=32, directions=10000,
                                shadow_steps=2)
    a, _ = _image(ctx, scene, "pt", 1024, seed=1)
    b, _ = _image(ctx, scene, "pt", 1024, seed=2)
    noise_var = np.mean((a - b) ** 2) / 2
    err_var = np.mean(((a + b) / 2 - ref) ** 2)
    assert err_var < 1.5 * noise_var / 2 + (1e-2 * ref.mean()) ** 2, (err_var, noise_var)
    np.testing.assert_allclose(((a + b) / 2).mean(), ref.mean(), rtol=0.03)
