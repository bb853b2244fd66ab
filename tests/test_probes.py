"""Radiance probes: bake and render checks with known answers, convergence towards the path
tracer, and hard cases (no NaN, no negative radiance, no hang)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

WHITE = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}
WHITE_SOLID = {"rgba": [[1, 1, 1, 1.0], [1, 1, 1, 1.0]]}
CAMERA = {"eye": [0.0, 0.2, 1.3], "target": [0, 0, 0], "fov_y": 40.0, "width": 16, "height": 16}


def _renderer(ctx, **kw):
    base = {"volume": {"builtin": "cloud", "size": [16, 12, 14]}, "camera": CAMERA,
            "probes": {"grid": [4, 4, 4], "samples": 64}}
    base.update(kw)
    return Renderer(ctx, parse_scene(base))


def _check_clean(result):
    assert result.stats["truncated_paths"] == 0
    assert result.stats["nonfinite_samples"] == 0
    assert np.isfinite(result.image).all()
    assert (result.image >= 0).all()


def test_empty_volume_probes_hold_the_environment_projection(ctx):
    env = np.array([0.2, 0.5, 0.9])
    r = _renderer(ctx, volume={"builtin": "empty", "size": [8, 8, 8]}, environment=env.tolist(),
                  probes={"grid": [3, 2, 5], "samples": 128})
    r.bake()
    c = r.probe_grid.coefficients()  # (nz, ny, nx, 28)
    l00 = c[..., 0:3]
    np.testing.assert_allclose(l00, np.broadcast_to(env * math.sqrt(4 * math.pi), l00.shape), rtol=1e-5)
    # Higher bands vanish up to the quadrature error of a 64-point rotated Fibonacci set.
    assert np.abs(c[..., 3:27]).max() < 2e-2 * env.max() * math.sqrt(4 * math.pi)
    np.testing.assert_array_equal(c[..., 27], 1.0)  # vacuum: the sun is unshadowed
    r.release()


@pytest.mark.parametrize("method", ["probes", "probes-only"])
@pytest.mark.parametrize("g", [-0.5, 0.0, 0.8])
def test_furnace_probe_methods_return_the_environment(ctx, method, g):
    env = [0.3, 0.6, 0.9]
    r = _renderer(ctx, transfer_function=WHITE, albedo=1.0, anisotropy=g, density_scale=40.0,
                  environment=env, max_bounces=100000, light={"irradiance": [0, 0, 0]})
    result = r.render(method, spp=8)
    _check_clean(result)
    np.testing.assert_allclose(result.image, np.broadcast_to(env, result.image.shape), rtol=1e-2)
    r.release()


def _rrmse(x, ref):
    return float(np.sqrt(np.mean((x - ref) ** 2)) / np.sqrt(np.mean(ref ** 2)))


def test_probe_image_converges_towards_path_tracer(ctx):
    """Smooth, moderately thin scene: error against a path-traced reference falls as the probe
    grid and the walks per probe grow."""
    kw = dict(volume={"builtin": "cloud", "size": [20, 16, 20]}, density_scale=12.0, albedo=0.95,
              environment=[0.1, 0.1, 0.1], light={"direction": [0.4, 0.8, 0.45], "irradiance": [3, 3, 3]},
              camera={**CAMERA, "width": 24, "height": 24})
    r = _renderer(ctx, **kw)
    ref = r.render("pt", spp=2048, samples_per_pass=512).image
    errors = []
    for grid, samples in ((1, 16), (3, 64), (8, 256)):
        rr = _renderer(ctx, **kw, probes={"grid": [grid] * 3, "samples": samples})
        res = rr.render("probes", spp=512, samples_per_pass=512)
        _check_clean(res)
        errors.append(_rrmse(res.image, ref))
        rr.release()
    r.release()
    print("probe rRMSE vs path tracer at grids 1, 3, 8:", errors)
    assert errors[2] < errors[0], errors
    assert errors[2] < 0.1, errors


HARD_CASES = {
    "one probe along an axis": dict(probes={"grid": [1, 3, 2], "samples": 32}),
    "probes finer than the volume": dict(volume={"builtin": "cloud", "size": [4, 4, 4]},
                                         probes={"grid": [9, 9, 9], "samples": 16}),
    "opaque block": dict(volume={"builtin": "sphere", "size": [12, 12, 12]},
                         transfer_function=WHITE, density_scale=5000.0),
    "albedo 1, sigma_t 1000": dict(transfer_function=WHITE_SOLID, albedo=1.0, density_scale=1000.0,
                                   volume={"builtin": "constant", "size": [4, 4, 4]}),
    "g = +0.95": dict(anisotropy=0.95),
    "g = -0.95": dict(anisotropy=-0.95),
    "thin sheet": dict(volume={"builtin": "sheet", "size": [16, 16, 16]},
                       transfer_function=WHITE_SOLID, density_scale=300.0),
}


@pytest.mark.parametrize("case", list(HARD_CASES))
@pytest.mark.parametrize("method", ["probes", "probes-only"])
def test_hard_cases_stay_finite_and_nonnegative(ctx, case, method):
    r = _renderer(ctx, **HARD_CASES[case])
    result = r.render(method, spp=4)
    _check_clean(result)
    assert np.isfinite(r.probe_grid.coefficients()).all()
    if method == "probes":  # the sun's shadow ray lights every case; probes-only may see black
        assert result.image.max() > 0  # where all probes sit deep inside an opaque medium
    r.release()


def test_sh_window_options_and_clamp_keep_radiance_nonnegative(ctx):
    """A strongly directional field (forward scattering of the sun through a thin medium) rings in
    order-2 SH; every window with the clamp gives non-negative images."""
    for window in ("none", "hann", "lanczos"):
        r = _renderer(ctx, anisotropy=0.9, density_scale=8.0,
                      probes={"grid": [3, 3, 3], "samples": 64, "sh_window": window})
        result = r.render("probes-only", spp=4)
        _check_clean(result)
        r.release()


def test_rgba16f_probes_match_rgba32f(ctx):
    images = {}
    for precision in ("rgba32f", "rgba16f"):
        r = _renderer(ctx, probes={"grid": [4, 4, 4], "samples": 64, "precision": precision})
        images[precision] = r.render("probes-only", spp=16).image
        r.release()
    assert _rrmse(images["rgba16f"], images["rgba32f"]) < 2e-3


def test_camera_moves_never_rebake(ctx):
    r = _renderer(ctx)
    first = r.render("probes", spp=1)
    assert first.bake_ms > 0
    moved = r.scene.replace(camera=r.scene.camera.__class__(**{**r.scene.camera.__dict__, "eye": (0.5, 0.2, 1.2)}))
    r.set_scene(moved)
    second = r.render("probes", spp=1)
    assert second.bake_ms == 0
    r.set_scene(moved.replace(albedo=0.5))
    assert r.render("probes", spp=1).bake_ms > 0
    r.release()


@pytest.mark.parametrize("g", [-0.5, 0.0, 0.8])
def test_furnace_raymarch_returns_the_environment(ctx, g):
    env = [0.3, 0.6, 0.9]
    r = _renderer(ctx, transfer_function=WHITE, albedo=1.0, anisotropy=g, density_scale=40.0,
                  environment=env, max_bounces=100000, light={"irradiance": [0, 0, 0]})
    result = r.render("raymarch", spp=2)
    np.testing.assert_allclose(result.image, np.broadcast_to(env, result.image.shape), rtol=1e-2)
    r.release()


def test_raymarch_fragment_equals_compute(ctx):
    images = {}
    for stage in ("compute", "fragment"):
        r = _renderer(ctx, probes={"grid": [4, 4, 4], "samples": 32})
        r.configure(raymarch_stage=stage)
        images[stage] = r.render("raymarch", spp=2).image
        r.release()
    assert images["compute"].max() > 0
    np.testing.assert_allclose(images["fragment"], images["compute"], rtol=1e-5, atol=1e-6)


def test_transfer_table_from_buffer_changes_no_image(ctx, monkeypatch):
    """Compute passes read the transfer table from a storage buffer on a GPU and with texelFetch on
    llvmpipe (app/gl/shaders.py transfer_from_buffer): the same values, so the same images."""
    import radiance_probes.gl.shaders as shaders
    images = {}
    for from_buffer in (False, True):
        monkeypatch.setattr(shaders, "transfer_from_buffer", lambda ctx, v=from_buffer: v)
        r = _renderer(ctx, probes={"grid": [4, 4, 4], "samples": 32})
        r.bake(seed=1)
        images[from_buffer] = [r.render(m, spp=2, seed=1).image for m in ("pt", "raymarch", "probes")]
        r.release()
    for texture_image, buffer_image in zip(images[False], images[True]):
        assert texture_image.max() > 0
        np.testing.assert_array_equal(buffer_image, texture_image)


def _raymarch_frames(r, frames, seed=3):
    acc = r.begin("raymarch", seed=seed)
    r.add_samples(frames)
    return acc.read_rgba()


def test_raymarch_skipping_empty_space_changes_nothing(ctx):
    """The raymarcher jumps over macrocells the majorant grid bounds by 0 (the corners around this
    ball, whose edge is one voxel wide): the same samples contribute, so the image is the one
    marched through every step."""
    r = _renderer(ctx, volume={"builtin": "sphere", "size": [32, 24, 28]}, density_scale=60.0,
                  camera={**CAMERA, "width": 48, "height": 40})
    r.bake()
    assert (r.resources.majorant_grid.read() == 0).mean() > 0.2
    skipping = _raymarch_frames(r, 3)
    r.resources.use_majorant_grid = False     # the same probes, every step marched
    marching = _raymarch_frames(r, 3)
    assert skipping[..., :3].max() > 0
    np.testing.assert_array_equal(skipping, marching)
    r.release()


def test_the_raymarch_work_group_shape_changes_nothing(ctx, monkeypatch):
    """Without surfaces the compute pass runs 8 x 4 groups (one warp; measured faster on an H200),
    with them or for `guided`'s level 0 8 x 8: each pixel's arithmetic is the same, so a frame is
    the 8 x 8 one bit for bit, at a size neither shape divides (the edge groups half empty)."""
    from radiance_probes.rendering.methods import raymarch
    assert raymarch.group_shape({}) == (8, 4)
    assert raymarch.group_shape({"HYBRID_SCATTERING": 1}) == (8, 8)
    assert raymarch.group_shape({"GUIDED_LEVEL0": 1}) == (8, 8)
    assert raymarch.group_shape({"RAYMARCH_GROUP_X": 4, "RAYMARCH_GROUP_Y": 2}) == (4, 2)
    with pytest.raises(ValueError, match="must divide 8"):
        raymarch.group_shape({"RAYMARCH_GROUP_X": 16, "RAYMARCH_GROUP_Y": 8})
    r = _renderer(ctx, camera={**CAMERA, "width": 37, "height": 29})
    r.bake()
    monkeypatch.setattr(raymarch, "LAYER_PIXELS", 1)   # one dispatch a frame, the groups' grid
    plain = _raymarch_frames(r, 2)
    assert r.raymarcher().group == (8, 4)
    monkeypatch.setattr(raymarch, "GROUP_PLAIN", (8, 8))
    r._raymarchers.clear()
    assert r.raymarcher().group == (8, 8)
    wide = _raymarch_frames(r, 2)
    assert plain[..., :3].max() > 0
    np.testing.assert_array_equal(plain, wide)
    r.release()


def test_raymarch_frames_in_one_dispatch_equal_one_per_dispatch(ctx, monkeypatch):
    """Small images march several frames per dispatch into layers, folded in frame order: the
    same running mean as one dispatch per frame."""
    from radiance_probes.rendering.methods import raymarch
    r = _renderer(ctx, camera={**CAMERA, "width": 24, "height": 20})
    r.bake()
    assert raymarch.frame_layers(24, 20, 5) == 5
    layered = _raymarch_frames(r, 5)
    monkeypatch.setattr(raymarch, "LAYER_PIXELS", 1)
    assert raymarch.frame_layers(24, 20, 5) == 1
    one_by_one = _raymarch_frames(r, 5)
    assert layered[..., :3].max() > 0 and (layered[..., 3] == 5).all()
    np.testing.assert_allclose(layered, one_by_one, rtol=1e-6, atol=1e-7)
    # and in chunks that do not divide the frames (3 + 2), continuing the same mean
    monkeypatch.setattr(raymarch, "LAYER_PIXELS", 24 * 20 * 3)
    np.testing.assert_allclose(_raymarch_frames(r, 5), one_by_one, rtol=1e-6, atol=1e-7)
    r.release()


@pytest.mark.parametrize("case", list(HARD_CASES))
def test_hard_cases_raymarch_finite(ctx, case):
    r = _renderer(ctx, **HARD_CASES[case])
    image = r.render("raymarch", spp=1).image
    assert np.isfinite(image).all() and (image >= 0).all()
    r.release()
