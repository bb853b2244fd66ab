"""The GPU relative RMSE (app/rendering/image_error.py, glsl/image_error.comp) against its NumPy
twin `metrics.rrmse`, on llvmpipe: sizes that are not whole tiles, RGBA and RGB textures, the
alpha channel ignored, and the refusals."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.image_error import ImageError
from radiance_probes.rendering.metrics import rrmse


@pytest.fixture(scope="module")
def meter(ctx):
    m = ImageError(ctx)
    yield m
    m.release()


def _texture(ctx, image: np.ndarray):
    h, w, c = image.shape
    return ctx.texture((w, h), c, np.ascontiguousarray(image, np.float32).tobytes(), dtype="f4")


@pytest.mark.parametrize("size", [(75, 53), (64, 96), (1, 1)])
def test_matches_numpy(ctx, meter, size):
    w, h = size
    rng = np.random.default_rng(w * h)
    ref = rng.gamma(2.0, 0.3, (h, w, 3)).astype(np.float32)
    image = (ref * rng.normal(1.0, 0.2, ref.shape)).astype(np.float32)
    image[0, -1] = [5.0, 0.0, 1.0]   # a corner pixel off: a tile at the edge counts
    rgba = np.concatenate([image, rng.random((h, w, 1), np.float32) * 100], axis=2)
    meter.set_reference(ref)
    texture = _texture(ctx, rgba)
    got = meter.rrmse(texture)
    assert got == pytest.approx(rrmse(image, ref), rel=1e-5)
    texture.release()
    texture = _texture(ctx, image)   # RGB32F reads the same
    assert meter.rrmse(texture) == pytest.approx(rrmse(image, ref), rel=1e-5)
    texture.release()


def test_reference_changes_and_zero_error(ctx, meter):
    ref = np.full((20, 30, 3), 0.5, np.float32)
    texture = _texture(ctx, ref)
    meter.set_reference(ref)
    assert meter.rrmse(texture) == 0.0
    other = ref * 2.0   # a new reference of the same size is uploaded, not the old one read
    meter.set_reference(other)
    assert meter.rrmse(texture) == pytest.approx(0.5, rel=1e-6)
    texture.release()


def test_refusals(ctx, meter):
    with pytest.raises(ValueError, match="black"):
        meter.set_reference(np.zeros((4, 4, 3), np.float32))
    nan = np.ones((4, 4, 3), np.float32)
    nan[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        meter.set_reference(nan)
    with pytest.raises(ValueError, match="expected"):
        meter.set_reference(np.ones((4, 4), np.float32))
    meter.set_reference(np.ones((4, 4, 3), np.float32))
    texture = _texture(ctx, np.ones((5, 4, 3), np.float32))
    with pytest.raises(ValueError, match="differs"):
        meter.rrmse(texture)
    texture.release()


def test_the_replays_error_on_the_gpu_is_the_host_s(ctx, meter):
    """interact.shown_error with the GPU meter against the shown image read back, over a session's
    frames: refine while the raymarcher shows and once guided does, and the raymarcher alone."""
    from radiance_probes.bench.interact import shown_error
    from radiance_probes.io.scene_file import parse_scene
    from radiance_probes.viewer.frame.session import RenderSession
    # (test_refine's scene: guided takes over from the raymarcher within a few dozen frames)
    s = RenderSession(ctx, parse_scene({
        "volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
        "albedo": 0.9, "camera": {"width": 24, "height": 16},
        "probes": {"grid": [2, 2, 2], "samples": 64, "fit": "box"}}))
    try:
        s.resize(24, 16)
        s.set_methods(["refine", "raymarch"])
        reference = s.renderer.render("pt", spp=64, seed=5).image
        shown = set()
        for frame in range(200):
            s.step(512, True)
            if frame % 5:
                continue
            for method in ("refine", "raymarch"):
                host = shown_error(s, method, reference, 0.0)
                gpu = shown_error(s, method, reference, 0.0, meter)
                assert gpu == pytest.approx(host, rel=1e-4), (frame, method)
            shown.add(s.views["refine"].shown)
        assert shown == {"raymarch", "guided"}
    finally:
        s.release()
