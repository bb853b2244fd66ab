"""The denoiser's kept tile means on the GPU (app/rendering/denoise/kept_means.py: glsl/tile_means.comp,
glsl/keep_tile_means.comp) against their NumPy twin (app/rendering/denoise/filter.py _block_means,
keep_block_means) on llvmpipe; and the GL flow (Renderer.denoise, the viewer) against the host
path on OIDN's CPU device."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.denoise.filter import (KEEP_MEANS_BLOCK, _block_means, _make_usable,
                                                      keep_block_means)
from radiance_probes.rendering.denoise.kept_means import KeptMeans, tile_grid

SIZES = [(75, 53), (64, 96)]   # (width, height): neither a multiple of 32 nor of 8; both


@pytest.fixture(scope="module")
def kept(ctx):
    k = KeptMeans(ctx)
    yield k
    k.release()


def _texture(ctx, image: np.ndarray):
    """An RGBA32F (4 channels given) or RGB32F texture holding `image`, row 0 at texel row 0."""
    h, w, c = image.shape
    return ctx.texture((w, h), c, np.ascontiguousarray(image, np.float32).tobytes(), dtype="f4")


def _read_rgba(texture) -> np.ndarray:
    w, h = texture.size
    return np.frombuffer(texture.read(), np.float32).reshape(h, w, 4)


def _usable(image: np.ndarray, signed: bool) -> np.ndarray:
    """The twin of lib/usable_radiance.glsl: NaN and infinities 0, negatives 0 unless signed."""
    out = image.copy()
    if signed:
        np.nan_to_num(out, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    else:
        _make_usable(out)
    return out


def _twin(raw: np.ndarray, filtered: np.ndarray, signed: bool) -> np.ndarray:
    """What KeptMeans.restore makes, in NumPy: the output made usable, given back the raw tile
    means (keep_block_means), made usable again."""
    out = _usable(filtered, signed)
    keep_block_means(_block_means(raw, KEEP_MEANS_BLOCK), out, signed=signed)
    return _usable(out, signed)


def _restore(ctx, kept, raw_rgba: np.ndarray, filtered: np.ndarray, signed: bool) -> np.ndarray:
    h, w = raw_rgba.shape[:2]
    raw_tex = _texture(ctx, raw_rgba)
    try:
        kept.raw_means(raw_tex, raw_rgba.copy(), signed)
        out = kept.result_texture(w, h)
        kept.restore(kept.upload(filtered), out, signed)
        return _read_rgba(out).copy()
    finally:
        raw_tex.release()


def _raw_and_filtered(w: int, h: int, signed: bool, seed: int = 0):
    """A noisy raw RGBA image and a smooth 'filtered' one that is brighter than it on the left
    (tiles that gained energy) and darker on the right (tiles that lost), each channel its own
    way; signed: both dip below zero."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    clean = np.stack([0.4 + y, 0.8 + 0.3 * x, 0.6 + 0.2 * np.sin(7 * y)], -1)
    noise = rng.exponential(1.0, (h, w, 1))
    raw = clean * noise
    if signed:
        raw = raw - 0.8 + 0.5 * rng.normal(size=(h, w, 3))
        clean = clean - 0.8
    filtered = clean * (1.6 - 1.2 * x)[..., None]    # x 1.6 at the left, x 0.4 at the right
    rgba = np.concatenate([raw, np.ones((h, w, 1))], -1).astype(np.float32)
    return rgba, filtered.astype(np.float32)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_tile_means_match_their_numpy_twin(ctx, kept, size):
    w, h = size
    raw, _ = _raw_and_filtered(w, h, signed=True)
    raw[..., 3] = 1e6    # alpha (an accumulation's count) is not a channel of the mean
    tex = _texture(ctx, raw)
    try:
        means = kept.raw_means(tex, raw.copy(), signed=True)
    finally:
        tex.release()
    want = _block_means(raw[..., :3], KEEP_MEANS_BLOCK)
    assert means.shape == want.shape == (*tile_grid(w, h)[::-1], 3)
    np.testing.assert_allclose(means, want, rtol=2e-5, atol=2e-6)
    # the partial tiles at the right and bottom average the pixels they have
    np.testing.assert_allclose(means[-1, -1], raw[32 * (means.shape[0] - 1):,
                                                  32 * (means.shape[1] - 1):, :3].mean((0, 1)),
                               rtol=2e-5, atol=2e-6)
    # an RGB32F texture serves as well (the filter's output, uploaded)
    rgb = _texture(ctx, raw[..., :3])
    try:
        np.testing.assert_allclose(kept.raw_means(rgb, raw.copy(), signed=True), want, rtol=2e-5,
                                   atol=2e-6)
    finally:
        rgb.release()


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_the_viewers_tile_means_carry_each_tiles_least_value(ctx, kept, size):
    """dispatch_means_into (the viewer's filter jobs' raw means): each tile's mean and, fourth,
    its least component, which tells a signed colour's negative part; partial tiles too."""
    w, h = size
    raw, _ = _raw_and_filtered(w, h, signed=True)
    assert raw[..., :3].min() < 0
    tex = _texture(ctx, raw)
    tiles = tile_grid(w, h)
    out = ctx.buffer(reserve=16 * tiles[0] * tiles[1])
    try:
        kept.dispatch_means_into(tex, out)
        got = np.frombuffer(out.read(), np.float32).reshape(tiles[1], tiles[0], 4)
    finally:
        tex.release()
        out.release()
    np.testing.assert_allclose(got[..., :3], _block_means(raw[..., :3], KEEP_MEANS_BLOCK),
                               rtol=2e-5, atol=2e-6)
    starts = np.arange(0, w, KEEP_MEANS_BLOCK), np.arange(0, h, KEEP_MEANS_BLOCK)
    least = np.minimum.reduceat(np.minimum.reduceat(raw[..., :3].min(axis=2), starts[0], axis=1),
                                starts[1], axis=0)
    np.testing.assert_array_equal(got[..., 3], least)
    assert (least < 0).any()
    tex, small = _texture(ctx, raw), ctx.buffer(reserve=16)
    try:
        with pytest.raises(ValueError, match="bytes for"):
            kept.dispatch_means_into(tex, small)
    finally:
        tex.release()
        small.release()


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_restore_matches_keep_block_means(ctx, kept, size, signed):
    w, h = size
    raw, filtered = _raw_and_filtered(w, h, signed, seed=1)
    raw_means = _block_means(raw[..., :3], KEEP_MEANS_BLOCK)
    own = _block_means(filtered, KEEP_MEANS_BLOCK)
    # the case the test is for: tiles that gained and tiles that lost, in every channel
    for c in range(3):
        assert (raw_means[..., c] < own[..., c]).any() and (raw_means[..., c] > own[..., c]).any()
    if signed:
        assert (filtered < 0).mean() > 0.2
    got = _restore(ctx, kept, raw, filtered, signed)
    want = _twin(raw[..., :3], filtered, signed)
    scale = np.abs(filtered).mean()
    np.testing.assert_allclose(got[..., :3], want, rtol=2e-5, atol=2e-5 * scale)
    assert (got[..., 3] == 1.0).all()
    # the correction is not small next to that tolerance: the means came back
    assert np.abs(want - filtered).max() > 0.1 * scale
    assert abs(got[..., :3].mean() - raw[..., :3].mean()) < 0.02 * np.abs(raw[..., :3]).mean()
    if signed:
        assert (got[..., :3] < 0).mean() > 0.2   # a signed image keeps its negative values
    else:
        assert got.min() >= 0.0


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
def test_non_finite_and_negative_filter_output_comes_out_usable(ctx, kept, signed):
    """The restore pass is the check of the filter's output: NaN, infinities (and, unless
    signed, negative values) do not reach the image shown, and neither spreads through the tile
    means into its neighbours."""
    w, h = 75, 53
    raw, filtered = _raw_and_filtered(w, h, signed, seed=2)
    filtered[3, 4] = [np.nan, 1.0, 2.0]
    filtered[40, 70] = [np.inf, -np.inf, np.nan]
    filtered[10:14, 50:60] = -2.0
    got = _restore(ctx, kept, raw, filtered, signed)
    assert np.isfinite(got).all()
    if not signed:
        assert got.min() >= 0.0
    else:
        assert (got[10:14, 50:60] < 0).any()
    want = _twin(raw[..., :3], filtered, signed)
    assert np.isfinite(want).all()
    np.testing.assert_allclose(got[..., :3], want, rtol=2e-5, atol=2e-5 * np.abs(want).mean())


def test_the_raw_means_find_a_nan_and_the_host_sanitizes(ctx, kept):
    """A NaN or an infinity in the raw image makes its tile's mean non-finite: the host sanitizes
    the colour it staged (as Denoiser does) and writes its own means into the buffer restore
    reads, so the corrected image is finite and has the sanitized image's means."""
    w, h = 75, 53
    raw, filtered = _raw_and_filtered(w, h, signed=False, seed=3)
    raw[5, 6, 0] = np.nan
    raw[50, 70, 2] = np.inf
    raw[40, 10, 1] = -1.0        # negatives go to 0 with the others (_make_usable), as before
    staged = raw.copy()
    tex = _texture(ctx, raw)
    try:
        means = kept.raw_means(tex, staged, signed=False)
        out = kept.result_texture(w, h)
        kept.restore(kept.upload(filtered), out, False)
        got = _read_rgba(out)[..., :3].copy()
    finally:
        tex.release()
    assert staged[5, 6, 0] == 0.0 and staged[50, 70, 2] == 0.0 and staged[40, 10, 1] == 0.0
    assert np.isfinite(staged).all()
    clean = _usable(raw, signed=False)
    np.testing.assert_array_equal(staged[..., :3], clean[..., :3])
    np.testing.assert_allclose(means, _block_means(clean[..., :3], KEEP_MEANS_BLOCK), rtol=1e-6)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, _twin(clean[..., :3], filtered, False), rtol=2e-5,
                               atol=2e-5 * filtered.mean())
    # a finite image leaves the staged colour as it is (negatives included: OIDN clamps them)
    raw2 = raw.copy()
    raw2[5, 6, 0] = raw2[50, 70, 2] = 1.0
    staged2 = raw2.copy()
    tex = _texture(ctx, raw2)
    try:
        kept.raw_means(tex, staged2, signed=False)
    finally:
        tex.release()
    np.testing.assert_array_equal(staged2, raw2)


def test_restore_refuses_means_of_another_size(ctx, kept):
    raw, filtered = _raw_and_filtered(40, 40, signed=False)
    tex = _texture(ctx, raw)
    try:
        kept.raw_means(tex, raw.copy(), False)
    finally:
        tex.release()
    with pytest.raises(ValueError, match="raw means of"):
        kept.restore(kept.upload(np.zeros((41, 40, 3), np.float32)), kept.result_texture(40, 41),
                     False)


# ---- the GL flow with the filter (OIDN's CPU device) ---------------------------------------
def _tile_means(image):
    return _block_means(np.asarray(image, np.float32), KEEP_MEANS_BLOCK)


def test_renderer_denoise_restores_on_gl_as_the_host_path_does(ctx):
    """Renderer.denoise from the accumulation takes the GL flow: the same image as the host path
    (the filter's output given back the raw means by keep_block_means) to float tolerance; its
    tile means are the raw image's to the interpolation's smoothing, its mean to 0.5%; the
    parts it timed are there."""
    pytest.importorskip("pyoidn", reason="the denoiser's library (pyoidn) is a dependency")
    from radiance_probes.rendering.denoise.filter import shared_denoiser
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [16, 16, 16]},
                         "density_scale": 40.0, "albedo": 0.9,
                         "camera": {"width": 75, "height": 53}})
    r = Renderer(ctx, scene)
    try:
        result = r.render("pt", spp=2, seed=3, denoise=True, denoise_guides="none")
        d = result.denoised
        assert d.denoised and d.note is None and not d.signed
        assert {"readback_ms", "filter_ms", "means_ms", "upload_result_ms",
                "result_readback_ms"} <= set(d.ms)
        assert set(d.means_parts_ms) == {"raw_means_ms", "restore_ms"}
        assert d.ms["means_ms"] == pytest.approx(sum(d.means_parts_ms.values()))
        raw = result.raw_image
        host = shared_denoiser("auto", "high")(raw.copy(), copy=True).image
        assert result.image.shape == raw.shape and np.isfinite(result.image).all()
        assert result.image.min() >= 0.0
        np.testing.assert_allclose(result.image, host, rtol=1e-4, atol=1e-5 * raw.mean())
        assert abs(result.image.mean() / raw.mean() - 1.0) < 5e-3
        np.testing.assert_allclose(_tile_means(result.image), _tile_means(raw), rtol=0.1)
    finally:
        r.release()


def test_the_viewer_shows_the_gl_restored_image(ctx, monkeypatch):
    """The viewer's Denoise switch filters on its own thread (the host path: the means kept
    there, app/rendering/filter_worker.py) and uploads the result into the RGBA32F texture it
    shows: that image is what the host path makes of the same accumulation. STILL_MIX 1 (each
    landing shown as it came): the mix of a landing with the one shown is
    tests/test_frame_pipeline.py's."""
    import time
    pytest.importorskip("pyoidn", reason="the denoiser's library (pyoidn) is a dependency")
    from radiance_probes.viewer.frame import denoise_view
    monkeypatch.setattr(denoise_view, "STILL_MIX", 1.0)
    from radiance_probes.rendering.denoise.filter import choose_guides, shared_denoiser
    from radiance_probes.io.scene_file import parse_scene
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene({
        "volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
        "albedo": 0.9, "camera": {"width": 40, "height": 35}}))
    try:
        s.resize(40, 35)
        s.set_methods(["pt"])
        s.denoise.set_enabled(True)
        view = s.views["pt"]
        end = time.monotonic() + 60   # the filter's image of the newest samples, over frames
        while time.monotonic() < end:
            s.step(64, False)
            got = s.denoise.images.get("pt")
            if got is not None and got.samples == view.acc.samples and s.denoise.idle():
                break
            time.sleep(0.002)
        got = s.denoise.images["pt"]
        assert s.texture("pt") is got.texture and got.texture.components == 4
        assert view.acc.samples == got.samples   # (the filter runs after a frame's samples)
        raw = view.acc.read()
        shown = s.shown_image("pt")
        guides = choose_guides("auto", got.samples, False)
        albedo, normal, _ = s.renderer.denoise_guides(guides, camera=view.camera)
        host = shared_denoiser()(raw.copy(), albedo, normal, copy=True).image
        assert shown.shape == raw.shape and np.isfinite(shown).all() and shown.min() >= 0.0
        np.testing.assert_allclose(shown, host, rtol=1e-4, atol=1e-5 * raw.mean())
        assert abs(shown.mean() / raw.mean() - 1.0) < 5e-3
    finally:
        s.release()


def test_the_denoiser_leaves_its_means_and_check_to_a_gl_caller():
    """keep_means and check_output off (the GL flow): the image handed out is the filter's output
    buffer itself (the next call writes the same memory), the same values as with the host's
    check, no host means; Denoised.signed says when the output was filtered as two parts."""
    pytest.importorskip("pyoidn", reason="the denoiser's library (pyoidn) is a dependency")
    from radiance_probes.rendering.denoise.filter import Denoiser
    d = Denoiser("cpu")
    try:
        rng = np.random.default_rng(5)
        first = rng.exponential(1.0, (40, 48, 3)).astype(np.float32)
        second = rng.exponential(1.0, (40, 48, 3)).astype(np.float32)
        checked = d(first, keep_means=False).image
        a = d(first, copy=False, keep_means=False, check_output=False, color_finite=True)
        np.testing.assert_array_equal(a.image, checked)
        assert a.ms["means_ms"] == 0.0 and not a.signed
        kept_a = a.image.copy()
        b = d(second, copy=False, keep_means=False, check_output=False, color_finite=True)
        assert np.shares_memory(a.image, b.image) and not np.array_equal(a.image, kept_a)
        signed = d(first - 1.5, signed=True, keep_means=False, check_output=False)
        assert signed.signed and signed.image.min() < 0.0
        assert not d(first, signed=True).signed    # nothing below zero: one run, unsigned
    finally:
        d.close()
