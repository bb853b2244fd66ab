"""Numerical hard cases for every render method (pt, probes, probes-only, raymarch).

Every render here must come out finite, non-negative, with no truncated path and no non-finite
sample in RenderResult.stats, every pixel holding all its samples, and within a wall-time bound
(tiny images, few samples, probe grids of at most 4 per axis); where the answer is known, it is
checked:

* empty volume (null collisions only, the sun on): the environment, bit for bit;
* fully opaque box (sigma_t 1e4 and 1e7), albedo 0: exactly 0 where the box covers a pixel,
  exactly the environment where it misses, in between elsewhere; camera inside it: all black;
  lit with albedo 0.9: the environment where it misses, every covered pixel lit (pt);
* albedo 0 (pure absorber) on a single voxel, non-cubic and anisotropic-spacing volumes, a plate
  one voxel thick, an extreme spacing ratio (1000:1), a camera inside the medium, and the cloud:
  Beer-Lambert (z-scores for the stochastic methods, quadrature noise for the raymarcher);
* albedo 1 (white furnace), sun off, on the same volumes, g = +-0.99, sigma_t 1e4 (a sheet, so
  paths stay short), camera inside a uniform medium and probe grids of 1 along axes: the
  environment;
* the sun along the camera's up vector, along the view direction, against it, and along a world
  axis: single scattering against quadrature (pt and probes without bias; probes-only and
  raymarch within their approximation), and with g = +-0.99 at full multiple scattering: clean;
* 1e5 accumulated samples of a constant stay exactly that constant (the real path tracer and probe
  passes; the raymarcher at a count of 1e5; glsl/lib/integrator.glsl's path_finish at magnitudes
  1e-30 to 3e38 over 1e5 frames) and the running mean of noisy input drifts no more than float32
  rounding allows;
* uint16 and float32 volumes with huge (1e30, the float32 limits, a 1e30 value range) or tiny
  (1e-30, subnormal) values, read from .npy files: the normalised data are exact; renders are clean,
  a volume scaled by 2^100 renders bit for bit as the unscaled one, and densities of 1e-26 (a 1e30
  value range) render the environment;
* 16-bit probe textures under a sun and environment of 1e6 (coefficients past half floats' 65504)
  and of 1e-7 (coefficients in their subnormals) raymarch as 32-bit ones do, to half-float rounding;
* regressions: a new volume is never taken for one already baked (probes and light grid were keyed
  by id(volume), which CPython reuses); paths cut by a tiny loop budget, inside flights and shadow
  rays, resume to the same image (shadow rays cut short used to drop the path: at sigma_t 1e4 on
  llvmpipe, 55 of 1024 paths).

Already covered elsewhere and not repeated here: white furnace of the path tracer for sigma_t 1 to
1000 and g in {-0.9, 0, 0.9}, the pt absorber on the cloud, single scattering at g = 0.5
(test_transport.py); empty-volume probe coefficients, probe furnaces at g in {-0.5, 0, 0.8},
finite/non-negative probe and raymarch images for a grid of [1, 3, 2], probes finer than the
volume, an opaque sphere, albedo 1 at sigma_t 1000, g = +-0.95 and a thin sheet (test_probes.py);
bad scene and volume input (test_scene.py, test_volume.py).
"""
from __future__ import annotations

import math
import time

import moderngl
import numpy as np
import pytest
from dataclasses import replace

from radiance_probes.twins import rng as nrng
from radiance_probes.twins.camera import camera_frame
from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.twins.medium import box_intersect
from radiance_probes.rendering.probes.layout import resolve_sh_order
from radiance_probes.twins.phase import phase_hg
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.still_images import RenderResult
from radiance_probes.io.scene_file import Scene, parse_scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.io.volume import Volume
from radiance_probes.io.builtin_volumes import builtin_cloud
from radiance_probes.io.load import load_scene_volume
from glsl_harness import HEADER
from transport_reference import optical_depth, pixel_rays

METHODS = ("pt", "probes", "probes-only", "raymarch")
WHITE = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}          # opacity follows density
WHITE_SOLID = {"rgba": [[1, 1, 1, 1.0], [1, 1, 1, 1.0]]}    # opacity 1 at every density
ENV = (0.1, 0.35, 0.7)   # not dyadic: exact comparisons see any rounding
SUN = {"direction": [0.3, 0.8, 0.5], "irradiance": [2.0, 2.5, 3.0]}
SUN_OFF = {"irradiance": [0, 0, 0]}
CAMERA = {"eye": [0.35, 0.3, 1.5], "target": [0, 0, 0], "fov_y": 38.0, "width": 16, "height": 16}
FAR = {"eye": [0.8, 0.6, 2.6], "target": [0, 0, 0], "fov_y": 40.0, "width": 16, "height": 16}
INSIDE = {"eye": [0.1, 0.05, 0.15], "target": [0.25, 0.1, -1.0], "fov_y": 60.0,
          "width": 16, "height": 16}
PROBES = {"grid": [3, 3, 3], "samples": 32}
UNBOUNDED = 1_000_000_000
RENDER_SECONDS = 20.0    # hang guard per render (each takes well under a second here)
SPP = {"pt": 4, "probes": 4, "probes-only": 4, "raymarch": 2}


def _scene(**kw) -> Scene:
    base = {"volume": {"builtin": "constant", "size": [6, 6, 6]}, "transfer_function": WHITE_SOLID,
            "density_scale": 5.0, "albedo": 0.0, "light": SUN, "environment": list(ENV),
            "camera": CAMERA, "probes": PROBES}
    base.update(kw)
    return parse_scene(base)


@pytest.fixture(scope="module")
def renderers(ctx):
    """One Renderer for the whole module (its shaders compile once, which on llvmpipe costs more
    than these renders), switched between scenes with set_scene. Volumes are cached per scene
    volume spec, so the methods of one case share the volume and the probes bake once."""
    r = Renderer(ctx, _scene(), load_scene_volume(_scene()))
    volumes: dict = {}

    def use(scene: Scene, volume: Volume | None = None) -> Renderer:
        if volume is None:
            key = (scene.volume, scene.base_dir)
            if key not in volumes:
                volumes[key] = load_scene_volume(scene)
            volume = volumes[key]
        r.set_scene(scene, volume)
        return r

    yield use
    r.release()


def _render(r: Renderer, method: str, spp: int | None = None, seed: int = 0,
            samples_per_pass: int | None = None) -> RenderResult:
    """Renders and checks what every hard case must satisfy."""
    spp = spp or SPP[method]
    start = time.perf_counter()
    result = r.render(method, spp=spp, seed=seed, samples_per_pass=samples_per_pass or spp)
    seconds = time.perf_counter() - start
    assert seconds < RENDER_SECONDS, f"{method} took {seconds:.1f} s"
    cam = r.scene.camera
    assert result.image.shape == (cam.height, cam.width, 3) and result.image.dtype == np.float32
    assert result.stats["truncated_paths"] == 0, result.stats
    assert result.stats["nonfinite_samples"] == 0, result.stats
    assert result.stats["min_samples"] == spp, result.stats  # no pixel lost a sample
    assert np.isfinite(result.image).all()
    assert (result.image >= 0).all(), result.image.min()
    if method != "pt":
        assert np.isfinite(r.probe_grid.coefficients()).all()
    return result


def _env_image(scene: Scene) -> np.ndarray:
    cam = scene.camera
    return np.broadcast_to(np.asarray(scene.environment, np.float32), (cam.height, cam.width, 3))


# ---------------------------------------------------------------------------------------------
# Empty volume

@pytest.mark.parametrize("method", METHODS)
def test_empty_volume_renders_the_environment_exactly(renderers, method):
    """Density 0 under a transfer function whose opacity reaches 1, so the majorant is 50 and every
    ray takes null collisions; the sun is on but nothing scatters it. Bit for bit the environment."""
    scene = _scene(volume={"builtin": "empty", "size": [6, 5, 7]}, transfer_function=WHITE,
                   density_scale=50.0, albedo=0.9, anisotropy=0.5)
    result = _render(renderers(scene), method)
    np.testing.assert_array_equal(result.image, _env_image(scene))


# ---------------------------------------------------------------------------------------------
# Fully opaque box

def _coverage(scene: Scene, volume: Volume, n: int = 7):
    """Pixels surely inside the box's silhouette with an optical depth that leaves nothing in float32
    (every point of the pixel's square, edges included, sampled n x n, hits the box with a chord of
    at least 0.05, and so do the 8 neighbours'), and pixels surely outside (no sample of the pixel or
    its neighbours hits)."""
    cam = camera_frame(scene.camera)
    offs = np.linspace(0.0, 1.0, n)
    ox, oy = np.meshgrid(offs, offs)
    cols = np.arange(cam.width)[None, :, None] + ox.ravel()[None, None, :]
    rows = np.arange(cam.height)[:, None, None] + oy.ravel()[None, None, :]
    cols, rows = np.broadcast_arrays(cols, rows)
    dirs = cam.ray_directions(cols.astype(np.float64), rows.astype(np.float64))
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(volume.half_extent.astype(np.float64), eye, dirs)
    deep = (hit & (t1 - t0 > 0.05)).all(axis=-1)
    miss = ~hit.any(axis=-1)

    def all_neighbours(mask):
        p = np.pad(mask, 1, mode="edge")
        h, w = mask.shape
        return np.logical_and.reduce([p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                                      for dy in (-1, 0, 1) for dx in (-1, 0, 1)])

    return all_neighbours(deep), all_neighbours(miss)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("sigma_t", [1e4, 1e7])
def test_opaque_absorbing_box_is_black_where_it_covers(renderers, method, sigma_t):
    scene = _scene(density_scale=sigma_t, volume={"builtin": "constant", "size": [8, 8, 8]},
                   camera=FAR)
    r = renderers(scene)
    image = _render(r, method).image
    covered, outside = _coverage(scene, r.resources.volume)
    assert covered.sum() >= 20 and outside.sum() >= 20, (covered.sum(), outside.sum())
    assert (image[covered] == 0).all()
    np.testing.assert_array_equal(image[outside], _env_image(scene)[outside])
    assert (image <= _env_image(scene)).all()  # an absorber only takes light away


@pytest.mark.parametrize("method", METHODS)
def test_camera_inside_opaque_absorber_sees_black(renderers, method):
    scene = _scene(density_scale=1e4, camera=INSIDE)
    image = _render(renderers(scene), method).image
    assert (image == 0).all()


@pytest.mark.parametrize("method", METHODS)
def test_opaque_lit_box_stays_finite_and_lit(renderers, method):
    """sigma_t 1e4, albedo 0.9, the sun and the environment: walks of 64 events within a
    ten-thousandth of the surface; only the bounds are known. pt and probes light the surface (the
    latter by its shadow ray); probes-only and raymarch take the sun's transmittance from grids
    whose points lie inside the box, where it is 0, so they may render it black (README, known
    limit)."""
    scene = _scene(density_scale=1e4, albedo=0.9, volume={"builtin": "constant", "size": [8, 8, 8]},
                   camera=FAR)
    r = renderers(scene)
    image = _render(r, method).image
    covered, outside = _coverage(scene, r.resources.volume)
    np.testing.assert_array_equal(image[outside], _env_image(scene)[outside])
    if method == "pt":
        assert image[covered].min() > 0  # the environment lights every face by multiple scattering
    if method == "probes":
        assert image[covered].max() > 0  # the faces the sun reaches (its probes, inside, are dark)


# ---------------------------------------------------------------------------------------------
# Albedo 0: Beer-Lambert

ABSORBERS = {
    "cloud": dict(volume={"builtin": "cloud", "size": [16, 12, 14]}, transfer_function=WHITE,
                  density_scale=8.0),
    "single voxel": dict(volume={"builtin": "constant", "size": [1, 1, 1]}, density_scale=3.0,
                         camera=FAR),
    "non-cubic 20x6x11": dict(volume={"builtin": "cloud", "size": [20, 6, 11]},
                              transfer_function=WHITE, density_scale=12.0),
    "anisotropic spacing": dict(volume={"builtin": "cloud", "size": [12, 10, 8],
                                        "spacing": [1.0, 2.5, 0.4]},
                                transfer_function=WHITE, density_scale=12.0),
    "plate one voxel thick": dict(volume={"builtin": "constant", "size": [12, 1, 7]},
                                  density_scale=15.0),
    "spacing ratio 1000": dict(volume={"builtin": "constant", "size": [6, 6, 6],
                                       "spacing": [1.0, 1e-3, 1.0]}, density_scale=1e3),
    "camera inside": dict(density_scale=1.5, camera=INSIDE),
}
_REFERENCES: dict = {}


def _subray_transmittance(scene: Scene, volume: Volume, sub: int) -> np.ndarray:
    """exp(-optical depth) through the box at sub x sub stratified points of every pixel, (H, W, S):
    exact for a homogeneous box (every voxel 1 under an opaque transfer function), else by midpoint
    quadrature (transport_reference.optical_depth)."""
    cam, dirs = pixel_rays(scene, sub)
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(volume.half_extent.astype(np.float64), eye, dirs)
    t1 = np.where(hit, t1, t0)
    table = transfer_table(scene.transfer_function)
    if (volume.data == 1).all() and (table[:, 3] == 1).all():
        return np.exp(-scene.density_scale * (t1 - t0))
    return np.exp(-optical_depth(volume, table, scene.density_scale, eye, dirs, t0, t1, 128))


def _absorber_reference(case: str, scene: Scene, volume: Volume):
    """(pixel mean of T, spread of T over the pixel, error of that mean), once per case. The error
    is the change from a grid of half the resolution; for a homogeneous box, plus 1 / n where its
    silhouette crosses the pixel or a neighbour (a jump in T that a grid of n x n points resolves
    only to a row of them); for a varying density, plus 2e-3 of quadrature error (the cloud's
    density is 0 at the box faces: it has no such jump)."""
    if case not in _REFERENCES:
        homogeneous = bool((volume.data == 1).all())
        n = 64 if homogeneous else 6  # closed form is cheap; quadrature is not
        fine = _subray_transmittance(scene, volume, n)
        coarse = _subray_transmittance(scene, volume, n // 2).mean(axis=-1)
        edge = (fine == 1.0).any(axis=-1) & (fine < 1.0).any(axis=-1)
        edge = np.pad(edge, 1, mode="edge")
        h, w = fine.shape[:2]
        edge = np.logical_or.reduce([edge[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                                     for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
        err = np.abs(fine.mean(axis=-1) - coarse) + (edge / n if homogeneous else 2e-3)
        _REFERENCES[case] = (fine.mean(axis=-1), fine.std(axis=-1), err + 1e-6)
    return _REFERENCES[case]


def _absorber_params():
    for case in ABSORBERS:
        for method in METHODS:
            if case == "cloud" and method == "pt":
                continue  # test_transport.py::test_absorber_matches_beer_lambert
            yield pytest.param(case, method, id=f"{case}-{method}")


@pytest.mark.parametrize("case, method", list(_absorber_params()))
def test_absorber_matches_beer_lambert(renderers, case, method):
    """Albedo 0 with the sun on: the image is the environment times the transmittance. The path
    tracer and the probe renderers (the same camera path, ended at the first event) give Bernoulli
    samples; the raymarcher integrates exp(-sigma_t dt) step by step, at a random point of the pixel
    each frame."""
    scene = _scene(**ABSORBERS[case])
    r = renderers(scene)
    ref_t, spread, ref_err = _absorber_reference(case, scene, r.resources.volume)
    assert ref_t.min() < 0.6, "the view should show real absorption"
    if scene.camera.eye != tuple(INSIDE["eye"]):
        assert ref_t.max() == 1.0, "and pixels that miss the volume"
    env = np.asarray(scene.environment)
    if method == "raymarch":
        spp = 64
        img = _render(r, method, spp=spp).image
        # The pixel's area is sampled at 64 random points: noise spread / 8. The march adds the
        # error of its piecewise-constant quadrature (half-voxel steps) where density varies.
        march = 0.0 if (r.resources.volume.data == 1).all() else 2e-3
        tol = 5.0 * spread / math.sqrt(spp) + ref_err + march + 1e-6
        signed = img / env - ref_t[..., None]
        err = np.abs(signed).max(axis=-1)
        worst = np.unravel_index(np.argmax(err - tol), err.shape)
        assert (err <= tol).all(), (worst, err[worst], tol[worst])
        assert abs(signed.mean()) < 2e-3  # no bias over the image (measured at most 7e-4)
    else:
        spp = 256
        img = _render(r, method, spp=spp, samples_per_pass=128).image
        sigma = np.sqrt(ref_t * (1 - ref_t) / spp + ref_err ** 2)[..., None] * env + 1e-7
        z = (img - ref_t[..., None] * env) / sigma
        assert np.abs(z).max() < 5.5, np.abs(z).max()
        assert abs(z[..., 0].mean()) < 5.0 / math.sqrt(z[..., 0].size)  # no bias
        # Albedo 0: every sample is 0 or the environment, so the channels keep its ratios.
        np.testing.assert_allclose(img[..., 1] / env[1], img[..., 0] / env[0], rtol=1e-5, atol=1e-7)
    assert (img <= env * (1 + 1e-6)).all()  # an absorber only takes light away


# ---------------------------------------------------------------------------------------------
# Albedo 1: white furnace

CLOUD = {"builtin": "cloud", "size": [16, 12, 14]}
FURNACES = {
    "single voxel": dict(volume={"builtin": "constant", "size": [1, 1, 1]}, density_scale=10.0,
                         anisotropy=0.3),
    "non-cubic 20x6x11": dict(volume={"builtin": "cloud", "size": [20, 6, 11]},
                              transfer_function=WHITE, density_scale=40.0, anisotropy=0.5),
    "anisotropic spacing": dict(volume={"builtin": "cloud", "size": [12, 10, 8],
                                        "spacing": [1.0, 2.5, 0.4]},
                                transfer_function=WHITE, density_scale=40.0, anisotropy=-0.3),
    "spacing ratio 1000": dict(volume={"builtin": "constant", "size": [6, 6, 6],
                                       "spacing": [1.0, 1e-3, 1.0]}, density_scale=3e3),
    "g = +0.99": dict(volume=CLOUD, transfer_function=WHITE, density_scale=30.0, anisotropy=0.99),
    "g = -0.99": dict(volume=CLOUD, transfer_function=WHITE, density_scale=30.0, anisotropy=-0.99),
    "sigma_t 1e4 sheet": dict(volume={"builtin": "sheet", "size": [8, 16, 8]},
                              transfer_function=WHITE, density_scale=1e4,
                              probes={"grid": [2, 2, 2], "samples": 16}),
    "camera inside uniform medium": dict(density_scale=20.0, anisotropy=0.5, camera=INSIDE),
    "probe grid 1x1x1": dict(volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                             anisotropy=0.5, probes={"grid": [1, 1, 1], "samples": 32}),
    "probe grid 1x4x2": dict(volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                             anisotropy=0.5, probes={"grid": [1, 4, 2], "samples": 32}),
    "probe grid 4x1x3": dict(volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                             anisotropy=-0.5, probes={"grid": [4, 1, 3], "samples": 32}),
}


def _furnace_params():
    for case in FURNACES:
        for method in METHODS:
            if case.startswith("probe grid") and method == "pt":
                continue  # the path tracer has no probes
            yield pytest.param(case, method, id=f"{case}-{method}")


@pytest.mark.parametrize("case, method", list(_furnace_params()))
def test_furnace_returns_the_environment(renderers, case, method):
    """Albedo 1, the sun off, no bounce limit: every path escapes carrying throughput 1. The path
    tracer returns the environment to float rounding (2e-6); the probe methods up to the
    quadrature error of the probes' higher SH bands (band 0 holds the environment exactly; bands 1
    and 2, which the phase function scales by g and g^2, hold the error of 32 rotated Fibonacci
    directions per probe, measured at most 0.02 |g|; with so few walks "auto" keeps order 2; orders
    3 and 4, asked for at g = +-0.99, measured 0.023 |g| and 0.044 |g|, hence the bound by order)."""
    scene = _scene(albedo=1.0, light=SUN_OFF, max_bounces=UNBOUNDED, **FURNACES[case])
    img = _render(renderers(scene), method).image
    rel = np.abs(img / np.asarray(ENV, np.float32) - 1).max()
    order = resolve_sh_order(scene.probes.sh_order, scene.anisotropy, scene.probes.samples)
    bound = 2e-6 if method == "pt" else 1e-5 + (3e-2 if order <= 3 else 5e-2) * abs(scene.anisotropy)
    assert rel < bound, rel


# ---------------------------------------------------------------------------------------------
# The sun along the camera's axes: single scattering against quadrature

SUNS = ("camera up", "view direction", "against view", "world +y")
SUN_CAMERA = {"eye": [0.0, 0.45, 1.4], "target": [0, 0, 0], "fov_y": 40.0, "width": 12, "height": 12}


def _sun_direction(sun: str) -> list[float]:
    frame = camera_frame(parse_scene({"camera": SUN_CAMERA}).camera)
    up = frame.up.astype(np.float64) / np.linalg.norm(frame.up)  # the camera's own up vector
    forward = frame.forward.astype(np.float64)
    return {"camera up": up, "view direction": forward, "against view": -forward,
            "world +y": np.array([0.0, 1.0, 0.0])}[sun].tolist()


def _sun_scene(sun: str, **kw) -> Scene:
    base = dict(volume={"builtin": "constant", "size": [8, 8, 8]}, density_scale=1.5, albedo=0.8,
                anisotropy=0.5, max_bounces=1, environment=[0, 0, 0], camera=SUN_CAMERA,
                light={"direction": _sun_direction(sun), "irradiance": [2.0, 1.5, 1.0]})
    base.update(kw)
    return _scene(**base)


def _single_scatter_homogeneous(scene: Scene, volume: Volume, sub: int = 12,
                                steps: int = 192) -> np.ndarray:
    """Single-scattered sun in a homogeneous box (sigma_t = density_scale, albedo = albedo), with
    the camera's and the sun's transmittance in closed form and midpoint quadrature along the ray."""
    cam, dirs = pixel_rays(scene, sub)
    he = volume.half_extent.astype(np.float64)
    sun = np.asarray(scene.light.direction, np.float64)
    sigma, E = scene.density_scale, np.asarray(scene.light.irradiance, np.float64)
    u = (np.arange(steps) + 0.5) / steps
    out = np.zeros(dirs.shape[:2] + (3,))
    for row in range(dirs.shape[0]):
        d = dirs[row]                                        # (W, S, 3)
        eye = np.broadcast_to(cam.eye.astype(np.float64), d.shape)
        t0, t1, hit = box_intersect(he, eye, d)
        length = np.where(hit, t1 - t0, 0.0)                 # (W, S)
        x = eye[..., None, :] + (t0[..., None] + length[..., None] * u)[..., None] * d[..., None, :]
        _, s1, _ = box_intersect(he, x, np.broadcast_to(sun, x.shape))
        integrand = sigma * np.exp(-sigma * length[..., None] * u - sigma * s1)
        line = integrand.mean(axis=-1) * length * phase_hg(d @ sun, scene.anisotropy)
        out[row] = scene.albedo * line.mean(axis=-1)[..., None] * E
    return out


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("sun", SUNS)
def test_sun_along_camera_axes_single_scattering(renderers, sun, method):
    """max_bounces 1, no environment: the image is single-scattered sun, with the phase function's
    peak (g = 0.5) at the image centre when the sun is along the view direction. pt and probes (the
    sun by a shadow ray) are unbiased estimates of it; probes-only takes the sun's transmittance
    from the 3^3 probes and raymarch from the baked light grid, both interpolated (and clamped to
    the outermost grid points near the box faces), so they get a bound."""
    scene = _sun_scene(sun)
    r = renderers(scene)
    if sun not in _REFERENCES:
        _REFERENCES[sun] = _single_scatter_homogeneous(scene, r.resources.volume)
    ref = _REFERENCES[sun]
    if method in ("pt", "probes"):
        a = _render(r, method, spp=512, seed=1, samples_per_pass=256).image
        b = _render(r, method, spp=512, seed=2, samples_per_pass=256).image
        noise_var = np.mean((a - b) ** 2) / 2
        err_var = np.mean(((a + b) / 2 - ref) ** 2)
        assert err_var < 1.5 * noise_var / 2 + (2e-3 * ref.mean()) ** 2, (err_var, noise_var / 2)
        np.testing.assert_allclose(((a + b) / 2).mean(axis=(0, 1)), ref.mean(axis=(0, 1)), rtol=0.02)
    else:
        img = _render(r, method, spp=64 if method == "raymarch" else 256, samples_per_pass=128).image
        rrmse = np.sqrt(np.mean((img - ref) ** 2) / np.mean(ref ** 2))
        bound = 0.08 if method == "raymarch" else 0.2
        np.testing.assert_allclose(img.mean(axis=(0, 1)), ref.mean(axis=(0, 1)), rtol=bound / 2)
        assert rrmse < bound, rrmse


LIT = {
    "g = +0.99, sun along view": dict(sun="view direction", anisotropy=0.99),
    "g = -0.99, sun against view": dict(sun="against view", anisotropy=-0.99),
    "g = +0.99, sun along camera up": dict(sun="camera up", anisotropy=0.99),
    "g = -0.99, sun along world +y": dict(sun="world +y", anisotropy=-0.99),
}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("case", list(LIT))
def test_sharp_phase_with_the_sun_on_camera_axes(renderers, case, method):
    """g = +-0.99 at full multiple scattering in a cloud, the sun on the camera's axes (the phase
    peak, 1584 / (4 pi) times the isotropic value, lies in the image for the view-direction cases):
    finite, non-negative, lit."""
    kw = dict(LIT[case])
    scene = _sun_scene(kw.pop("sun"), volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                       albedo=0.95, max_bounces=64, environment=list(ENV), **kw)
    image = _render(renderers(scene), method).image
    assert image.max() > 0


LIT_CASES = {
    "cloud sigma_t 1e4": dict(volume=CLOUD, transfer_function=WHITE, density_scale=1e4),
    "single voxel": dict(volume={"builtin": "constant", "size": [1, 1, 1]}, density_scale=4.0),
    "camera inside cloud": dict(volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                                camera={**INSIDE, "eye": [0.0, 0.0, 0.05]}),
    "spacing ratio 1000": dict(volume={"builtin": "constant", "size": [6, 6, 6],
                                       "spacing": [1.0, 1e-3, 1.0]}, density_scale=3e3),
    "probe grid 1x1x1": dict(volume=CLOUD, transfer_function=WHITE, density_scale=20.0,
                             probes={"grid": [1, 1, 1], "samples": 32}),
}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("case", list(LIT_CASES))
def test_lit_hard_cases_stay_clean(renderers, case, method):
    """The sun and the environment on, albedo 0.9, 64 bounces. The cloud at sigma_t 1e4 has a
    majorant of 1e4 over thin regions: its shadow rays take thousands of null collisions, more than
    one llvmpipe dispatch allows, and must resume in the next one rather than drop the path."""
    scene = _scene(albedo=0.9, anisotropy=0.6, max_bounces=64, **LIT_CASES[case])
    image = _render(renderers(scene), method).image
    assert image.max() > 0


# ---------------------------------------------------------------------------------------------
# 1e5 accumulated samples

FRAMES = 100_000
EXACT_ENV = (0.1, 1.0 / 3.0, 0.7)  # none of them a float32 exactly


@pytest.mark.parametrize("method", ["pt", "probes", "probes-only"])
def test_running_mean_of_a_constant_stays_exact_over_1e5_samples(renderers, method):
    """Every pass keeps rgb = running mean, a = count, updated by path_finish in
    glsl/lib/integrator.glsl as mean += (x - mean) / count. For a constant x the first sample sets
    the mean to x exactly and every later one adds (x - x) / n = 0, so after 1e5 samples per pixel
    the image is x to the last bit and the count is exact (float32 counts exactly to 2^24). An
    empty volume under density 0 (majorant 0: no tracking at all) makes every sample the
    environment, so 1e5 samples of 8 x 8 pixels take a fraction of a second."""
    scene = _scene(volume={"builtin": "empty", "size": [2, 2, 2]}, density_scale=0.0,
                   environment=list(EXACT_ENV), camera={**CAMERA, "width": 8, "height": 8},
                   probes={"grid": [1, 1, 1], "samples": 1})
    r = renderers(scene)
    result = _render(r, method, spp=FRAMES, samples_per_pass=FRAMES)
    np.testing.assert_array_equal(result.image, _env_image(scene))
    assert (r.accumulation(8, 8).read_rgba()[..., 3] == FRAMES).all()


def test_raymarch_running_mean_at_1e5_frames(renderers):
    """The raymarcher's own update (glsl/lib/raymarch.glsl, one dispatch per frame, so 1e5 real
    frames would take seconds): its accumulation is preloaded with the constant at a count of
    1e5 - 16 and 16 real frames are added; the mean stays bit for bit and the count reaches 1e5."""
    scene = _scene(volume={"builtin": "empty", "size": [2, 2, 2]}, density_scale=0.0,
                   environment=list(EXACT_ENV), camera={**CAMERA, "width": 8, "height": 8},
                   probes={"grid": [1, 1, 1], "samples": 1})
    r = renderers(scene)
    acc = r.begin("raymarch")
    r.bake()
    start = np.empty((8, 8, 4), np.float32)
    start[..., :3] = np.asarray(EXACT_ENV, np.float32)
    start[..., 3] = FRAMES - 16
    acc.texture.write(start.tobytes())
    acc.samples = FRAMES - 16
    r.add_samples(16)
    rgba = acc.read_rgba()
    np.testing.assert_array_equal(rgba[..., :3], _env_image(scene))
    assert (rgba[..., 3] == FRAMES).all()


RUNNING_MEAN_KERNEL = """
#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/tracking.glsl"
#include "lib/integrator.glsl"
layout(std430, binding = 0) readonly buffer Scale { float scale[]; };
layout(std430, binding = 1) buffer Means { vec4 mean_and_count[]; };
uniform uint first_frame;
uniform int frames;
uniform int noisy;   // 0: x = scale; 1: x = scale * u, u uniform from the frame's random stream
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count)
        return;
    vec4 m = mean_and_count[i];
    PathState p;
    path_begin(p, vec3(0.0), vec3(0.0, 0.0, 1.0), 0u);
    for (int k = 0; k < frames; ++k) {
        float x = scale[i];
        if (noisy != 0) {
            uint rng = rng_seed(i, first_frame + uint(k), 0u);
            x *= rng_next(rng);
        }
        p.radiance = vec3(x);
        path_finish(m, p, PATH_DONE);
    }
    mean_and_count[i] = m;
}
"""


def _running_mean_glsl(ctx, scales: np.ndarray, noisy: bool) -> np.ndarray:
    """path_finish applied FRAMES times per item; dispatches of 4000 frames stay within llvmpipe's
    loop limit (65535 iterations per SIMD batch of 8)."""
    program = compute_program(ctx, "<running mean kernel>", text=HEADER + RUNNING_MEAN_KERNEL)
    scale_buf = ctx.buffer(np.ascontiguousarray(scales, np.float32).tobytes())
    means = ctx.buffer(reserve=16 * len(scales))
    means.clear()
    stats = ctx.buffer(reserve=16)
    stats.clear()
    scale_buf.bind_to_storage_buffer(0)
    means.bind_to_storage_buffer(1)
    stats.bind_to_storage_buffer(7)
    chunk = 4000
    try:
        for first in range(0, FRAMES, chunk):
            set_uniforms(program, {"count": len(scales), "first_frame": first,
                                   "frames": min(chunk, FRAMES - first), "noisy": int(noisy)})
            program.run((len(scales) + 63) // 64)
            ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        assert np.frombuffer(stats.read(), np.uint32)[:2].tolist() == [0, 0]
        return np.frombuffer(means.read(), np.float32).reshape(len(scales), 4).copy()
    finally:
        for obj in (scale_buf, means, stats, program):
            obj.release()


# Magnitudes from the tiny to near the float32 limit (subnormals excluded: GPUs may flush them).
MAGNITUDES = np.array([1e-30, 3e-20, 0.1, 1.0 / 3.0, 1.0, 7.0, 1e10, 1e30, 3e38], np.float32)


def test_running_mean_of_constants_over_1e5_frames_glsl(ctx):
    out = _running_mean_glsl(ctx, MAGNITUDES, noisy=False)
    np.testing.assert_array_equal(out[:, :3], np.repeat(MAGNITUDES[:, None], 3, axis=1))
    np.testing.assert_array_equal(out[:, 3], FRAMES)


def test_running_mean_of_noise_over_1e5_frames_drifts_only_by_rounding(ctx):
    """x_k = s * u_k with u_k from the GLSL random stream (its NumPy twin gives the same float32
    values): after 1e5 frames the running mean is within 1e-4 of the exact mean of those values.
    Rounding errors of step k shrink by k / n by the end, so they add up like a random walk of
    about eps * sqrt(n / 3) = 1e-5 (measured in float32 NumPy: 4e-6); 1e-4 is ten times that."""
    out = _running_mean_glsl(ctx, MAGNITUDES, noisy=True)
    for i, s in enumerate(MAGNITUDES):
        state = nrng.rng_seed(np.uint32(i), np.arange(FRAMES, dtype=np.uint32), np.uint32(0))
        _, u = nrng.rng_next(state)
        exact = (np.float32(s) * u).astype(np.float64).mean()
        np.testing.assert_allclose(out[i, :3], exact, rtol=1e-4, err_msg=f"scale {s}")
    np.testing.assert_array_equal(out[:, 3], FRAMES)


# ---------------------------------------------------------------------------------------------
# uint16 and float32 volumes with huge or tiny values

F32_MAX = float(np.finfo(np.float32).max)


def _pattern() -> np.ndarray:
    p = builtin_cloud((9, 7, 6)).astype(np.float64)
    assert p.min() == 0.0 and p.max() == 1.0
    return p


def _range_case(name: str):
    """(raw array as stored, value_range for the scene or None, normalised data expected)."""
    p = _pattern()
    if name == "float32 ~1e30":
        raw = (p * 2.0 ** 100).astype(np.float32)    # exact: a power of two
        return raw, None, p
    if name == "float32 ~1e-30":
        raw = (p * 2.0 ** -100).astype(np.float32)
        return raw, None, raw.astype(np.float64) / float(raw.max())
    if name == "float32 +-3.4e38 (max - min overflows float32)":
        raw = (-F32_MAX + p * 2 * F32_MAX).astype(np.float32)
        raw.flat[np.argmin(p)], raw.flat[np.argmax(p)] = -F32_MAX, F32_MAX
        return raw, None, (raw.astype(np.float64) + F32_MAX) / (2 * F32_MAX)
    if name == "float32 subnormal":
        k = np.round(p * 1000)
        raw = (k * 2.0 ** -149).astype(np.float32)      # 1e-45 to 1.4e-42: all subnormal
        return raw, None, k / 1000
    if name == "float32 value_range [0, 2^101]":
        raw = (p * 2.0 ** 100).astype(np.float32)
        return raw, [0.0, 2.0 ** 101], p / 2
    if name == "uint16 full range":
        raw = np.round(p * 65535).astype(np.uint16)
        return raw, None, raw / 65535.0
    if name == "uint16 value_range [-1e30, 1e30]":
        raw = np.round(p * 65535).astype(np.uint16)
        return raw, [-1e30, 1e30], (raw.astype(np.float64) + 1e30) / 2e30
    if name == "uint16 value_range [0, 1e30]":
        raw = np.round(p * 65535).astype(np.uint16)
        return raw, [0.0, 1e30], raw / 1e30
    raise KeyError(name)


RANGE_CASES = ("float32 ~1e30", "float32 ~1e-30", "float32 +-3.4e38 (max - min overflows float32)",
               "float32 subnormal", "float32 value_range [0, 2^101]", "uint16 full range",
               "uint16 value_range [-1e30, 1e30]", "uint16 value_range [0, 1e30]")


@pytest.fixture(scope="module")
def range_volumes(tmp_path_factory):
    """Each case written as a .npy file and read through the scene's loader, once."""
    folder = tmp_path_factory.mktemp("ranges")
    out = {}
    for i, name in enumerate(RANGE_CASES):
        raw, value_range, expected = _range_case(name)
        path = folder / f"case{i}.npy"
        np.save(path, raw)
        spec = {"path": str(path)}
        if value_range is not None:
            spec["value_range"] = value_range
        scene = _scene(volume=spec, transfer_function=WHITE, density_scale=30.0, albedo=0.8,
                       anisotropy=0.3, camera={**CAMERA, "width": 12, "height": 12})
        out[name] = (scene, load_scene_volume(scene), expected)
    return out


@pytest.mark.parametrize("name", RANGE_CASES)
def test_extreme_value_ranges_normalise_exactly(range_volumes, name):
    scene, volume, expected = range_volumes[name]
    assert volume.data.dtype == np.float32 and np.isfinite(volume.data).all()
    assert volume.data.min() >= 0 and volume.data.max() <= 1
    np.testing.assert_array_equal(volume.data, expected.astype(np.float32))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", RANGE_CASES)
def test_extreme_value_ranges_render(renderers, range_volumes, name, method):
    """Clean renders with the sun on; where the normalised data is the pattern itself the image
    equals the pattern's own bit for bit (the raw scale never reaches the GPU); where a 1e30 range
    leaves densities of 1e-26 the image is the environment."""
    scene, volume, _ = range_volumes[name]
    image = _render(renderers(scene, volume), method).image
    if name == "float32 ~1e30":
        pattern = Volume(_pattern().astype(np.float32), (1.0, 1.0, 1.0), "pattern", (0.0, 1.0),
                         "float32", 0.0, 1.0)
        np.testing.assert_array_equal(image, _render(renderers(scene, pattern), method).image)
    if name == "uint16 value_range [0, 1e30]":
        np.testing.assert_allclose(image, _env_image(scene), rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# Regressions found by these cases

def test_new_volume_never_reuses_stale_probes_or_light(renderers, monkeypatch):
    """Baked probes and the raymarcher's light grid were keyed by id(volume); a freed volume's id
    is often reused by a later one (CPython), which then passed for already baked (4 times in 100
    tries, measured). As a viewer might: bake for volume A, switch to B without baking (A is freed),
    switch to C; C must never pass for baked."""
    from radiance_probes.rendering.grids.light_transmittance import LightTransmittance
    bakes = []
    real_begin = LightTransmittance.begin     # every light-grid bake, whole or sliced, begins
    monkeypatch.setattr(LightTransmittance, "begin",
                        lambda self, resources, *rest: (bakes.append(1),
                                                        real_begin(self, resources, *rest)))
    scene = _scene(camera={**CAMERA, "width": 4, "height": 4},
                   probes={"grid": [1, 1, 1], "samples": 1})
    r = renderers(scene)

    def volume(v):
        return Volume(np.full((2, 2, 2), v, np.float32), (1.0, 1.0, 1.0), "v", (0.0, 1.0),
                      "float32", 0.0, 1.0)

    for i in range(300):
        r.set_scene(scene, volume(1.0))
        r.bake()
        r.bake_light()
        r.set_scene(scene, volume(0.0))  # the baked volume is freed here
        r.set_scene(scene, volume(0.5))
        assert not r.probes_current(), f"stale probes taken as current (try {i})"
        before = len(bakes)
        r.bake_light()
        assert len(bakes) == before + 1, f"stale light grid taken as current (try {i})"


@pytest.mark.parametrize("method", ["pt", "probes"])
def test_paths_cut_by_a_tiny_loop_budget_give_the_same_image(renderers, method):
    """Flights and shadow rays resume across dispatches exactly (free flight and ratio tracking are
    memoryless and the random state is saved): with a budget of 48 loop iterations per dispatch
    (llvmpipe allows ~8000) nearly every path is cut, often inside a shadow ray, yet nothing is
    dropped and the image matches the uncut one to float rounding of the resumed positions."""
    scene = _scene(volume=CLOUD, transfer_function=WHITE, density_scale=300.0, albedo=0.9,
                   anisotropy=0.5, max_bounces=16, camera={**CAMERA, "width": 8, "height": 8})
    r = renderers(scene)
    tracer = r.pass_for(method)
    saved = tracer.loop_budget, tracer.loop_reserve
    first = tracer.dispatches
    whole = _render(r, method, spp=2).image
    uncut = tracer.dispatches - first
    tracer.loop_budget, tracer.loop_reserve = 48, 24
    try:
        first = tracer.dispatches
        cut = _render(r, method, spp=2).image
        assert tracer.dispatches - first > 10 * uncut  # it really was cut into many dispatches
    finally:
        tracer.loop_budget, tracer.loop_reserve = saved
    assert whole.max() > 0
    np.testing.assert_allclose(cut, whole, rtol=1e-4, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# 16-bit probes at any light level

@pytest.mark.parametrize("level", [1e6, 1e-7])
def test_16bit_probes_hold_any_light_level(renderers, level):
    """The probe textures store SH coefficients relative to the scene's brightest light
    (probes.radiance_scale), so 16-bit texels give the 32-bit image whatever the lights' units:
    at 1e6 the coefficients pass 65504 (a half float's largest), at 1e-7 they fall below 6.1e-5
    (its smallest normal number), and unscaled either would break the image."""
    sun = {"direction": [0.3, 0.8, 0.5], "irradiance": [2.0 * level, 2.5 * level, 3.0 * level]}
    scene = _scene(volume={"builtin": "cloud", "size": [8, 8, 8]}, transfer_function=WHITE,
                   density_scale=20.0, albedo=0.9, light=sun, environment=[e * level for e in ENV],
                   probes={**PROBES, "precision": "rgba16f"})
    r = renderers(scene)
    half = _render(r, "raymarch").image
    stored = np.abs(r.probe_grid.coefficients()[..., :27]).max()
    assert stored > 65504 if level > 1 else stored < 6.1e-5   # the case is as hard as it says
    full = _render(renderers(scene.replace(probes=replace(scene.probes, precision="rgba32f"))),
                   "raymarch").image
    assert full.max() > 0
    assert np.abs(half - full).max() <= 2e-3 * full.max()
