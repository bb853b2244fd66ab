"""refine's probes guide on the GPU (app/rendering/denoise/probe_guide.py, glsl/probe_albedo_guide.comp)
against its NumPy twin (app/twins/probe_albedo_guide.py) on llvmpipe, and the twin against the
host's radiance_as_albedo (np.quantile's scale): within one histogram bin's width."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.denoise.filter import ALBEDO_SCALE_QUANTILE, radiance_as_albedo
from radiance_probes.rendering.denoise.probe_guide import ProbeAlbedoGuide
from radiance_probes.twins import probe_albedo_guide as twin

BIN_WIDTH = 1.0 / 32.0   # a bin's width relative to its lower edge, at most (32 bins an octave)
Q = ALBEDO_SCALE_QUANTILE


@pytest.fixture(scope="module")
def guide(ctx):
    g = ProbeAlbedoGuide(ctx)
    yield g
    g.release()


def _images():
    rng = np.random.default_rng(5)
    out = {}
    out["lognormal"] = np.exp(rng.normal(-1.0, 2.0, (53, 75, 4))).astype(np.float32)
    bad = out["lognormal"].copy()
    bad[3, 4, 0], bad[10, 2, 1], bad[7, 7, 2], bad[1, 1, :3] = np.nan, np.inf, -5.0, -np.inf
    out["non-finite"] = bad
    sparse = np.zeros((40, 64, 4), np.float32)
    sparse[:5, :, :3] = rng.uniform(0.0, 3.0, (5, 64, 3))
    out["mostly black"] = sparse       # the quantile among the lit pixels' few
    out["black"] = np.zeros((17, 9, 4), np.float32)
    out["one value"] = np.full((16, 16, 4), 0.37, np.float32)
    out["large"] = (rng.uniform(0, 1, (130, 200, 4)) ** 8 * 1e4).astype(np.float32)
    return out


def _gl_guide(ctx, guide, image):
    h, w = image.shape[:2]
    texture = ctx.texture((w, h), 4, np.ascontiguousarray(image).tobytes(), dtype="f4")
    try:
        buf = guide.dispatch("test", texture)
        got = np.frombuffer(buf.read(), np.float32).reshape(h, w, 3).copy()
        return got, guide.scale()
    finally:
        texture.release()


@pytest.mark.parametrize("name", list(_images()))
def test_the_gpu_guide_is_its_twins(ctx, guide, name):
    """Histogram, scale and guide as the twin makes them (the histogram's integers exactly; the
    scale to float32 rounding; the guide to GLSL's division), and the histogram cleared after
    (a second image is not counted on top of the first)."""
    image = _images()[name]
    for _ in range(2):   # the second run finds the histogram the first left: zero
        got, scale = _gl_guide(ctx, guide, image)
        want_scale = twin.guide_scale(image, Q)
        assert scale == pytest.approx(want_scale, rel=1e-6, abs=0.0)
        np.testing.assert_allclose(got, twin.albedo_guide(image, Q), rtol=2e-6, atol=1e-7)
    assert (got >= 0).all() and (got <= 1).all() and np.isfinite(got).all()
    assert np.frombuffer(guide.histogram.read(), np.uint32)[4:].sum() == 0


def test_the_gpu_histogram_counts_every_pixel_in_its_bin(ctx, guide):
    """Pass 0's counts (read before pass 1 clears them) against np.bincount of the bits."""
    image = _images()["non-finite"]
    h, w = image.shape[:2]
    texture = ctx.texture((w, h), 4, image.tobytes(), dtype="f4")
    try:
        guide.histogram.write(bytes(guide.histogram.size))
        texture.use(23)
        guide.histogram.bind_to_storage_buffer(0)
        guide._passes[0]["probe_image"] = 23
        guide._passes[0].run(-(-w // 64), -(-h // 64))
        got = np.frombuffer(guide.histogram.read(), np.uint32)[4:]
        np.testing.assert_array_equal(got, twin.peak_histogram(image))
        assert got.sum() == w * h
    finally:
        guide.histogram.write(bytes(guide.histogram.size))
        texture.release()


@pytest.mark.parametrize("name", list(_images()))
def test_the_twins_scale_is_within_a_bin_of_np_quantile(name):
    """The histogram's scale against the host's (np.quantile of the usable largest channel):
    within one bin's width; the guides then differ by at most that ratio, where unclipped."""
    image = _images()[name]
    usable = twin.largest_channel(image)
    host = float(np.quantile(usable, Q))
    got = twin.guide_scale(image, Q)
    if host == 0.0:
        assert got == 0.0
        assert (twin.albedo_guide(image, Q) == 0).all()
        return
    assert abs(got / host - 1.0) <= BIN_WIDTH
    host_guide = radiance_as_albedo(image.copy())
    ours = twin.albedo_guide(image, Q)
    np.testing.assert_allclose(ours, host_guide, rtol=BIN_WIDTH, atol=BIN_WIDTH)
