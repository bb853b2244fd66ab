"""The denoising stage (app/rendering/denoise/filter.py) on OIDN's CPU device, and its guides
(glsl/denoise_guide_images.comp) against their NumPy twin (app/twins/denoise_guides.py)."""
from __future__ import annotations

import builtins
import sys
import time

import numpy as np
import pytest

from radiance_probes.rendering.denoise import filter as denoise_module
from radiance_probes.rendering.denoise.filter import Denoiser, sanitize
from radiance_probes.rendering.denoise.guides import DenoiseGuides
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins.camera import camera_frame
from radiance_probes.twins.denoise_guides import guide_frame
from radiance_probes.io.volume import Volume

pytest.importorskip("pyoidn", reason="the denoiser's library (pyoidn) is a dependency: install it")


def _clean_and_noisy(seed=0, size=96):
    """A smooth HDR image with a sharp edge, and a Monte Carlo-like noisy copy of it (each pixel's
    mean is the clean value: exponential weights of mean 1)."""
    y, x = np.mgrid[0:size, 0:size] / size
    clean = np.stack([0.2 + x, 0.3 + y, 0.5 + 2.0 * (x > 0.5)], axis=-1).astype(np.float32)
    rng = np.random.default_rng(seed)
    noisy = clean * rng.exponential(1.0, (size, size, 1)).astype(np.float32)
    return clean, noisy


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def cpu_denoiser():
    d = Denoiser("cpu")
    yield d
    d.close()


def test_the_filter_brings_a_noisy_image_closer_to_its_clean_answer(cpu_denoiser):
    clean, noisy = _clean_and_noisy()
    out = cpu_denoiser(noisy)
    assert out.denoised and out.device == "cpu" and out.note is None
    assert out.image.shape == noisy.shape and out.image.dtype == np.float32
    assert rmse(out.image, clean) < 0.25 * rmse(noisy, clean)
    # a noise-free albedo guide that knows the edge helps further, and the result keeps the mean
    albedo = np.clip(clean / clean.max(), 0, 1)
    guided = cpu_denoiser(noisy, albedo)
    assert rmse(guided.image, clean) < rmse(out.image, clean)
    assert abs(guided.image.mean() / clean.mean() - 1.0) < 0.03
    assert set(out.ms) == {"prepare_ms", "filter_ms", "check_ms", "means_ms"}


def test_a_warmed_filter_gives_the_same_image_and_takes_the_guides_given_after():
    """warm makes the filter and runs it once on black; the next call with guides of its own is
    the image a cold filter gives (the black guides were not kept in their place)."""
    clean, noisy = _clean_and_noisy(seed=3)
    albedo = np.clip(clean / clean.max(), 0, 1)
    normal = np.zeros_like(clean)
    normal[..., 2] = 1.0
    cold = Denoiser("cpu")
    warm = Denoiser("cpu")
    try:
        expected = cold(noisy, albedo, normal).image
        assert warm.warm(noisy.shape[1], noisy.shape[0], ("albedo", "normal")) > 0.0
        np.testing.assert_allclose(warm(noisy, albedo, normal).image, expected, rtol=1e-5,
                                   atol=1e-6)
    finally:
        cold.close()
        warm.close()


def test_no_nan_inf_or_negative_out_even_when_they_come_in(cpu_denoiser):
    clean, noisy = _clean_and_noisy(seed=1, size=48)
    bad = noisy.copy()
    bad[3, 4] = np.nan
    bad[10, 10] = np.inf
    bad[20, 30] = -np.inf
    bad[5, 40] = -7.0
    out = cpu_denoiser(bad, albedo=np.full_like(bad, np.nan), normal=np.full_like(bad, 5.0))
    assert out.denoised
    assert np.isfinite(out.image).all() and out.image.min() >= 0.0
    s = sanitize(bad)
    assert np.isfinite(s).all() and s.min() == 0.0 and s[10, 10].max() == 0.0


def test_shapes_are_checked_with_a_message(cpu_denoiser):
    clean, noisy = _clean_and_noisy(size=16)
    with pytest.raises(ValueError, match="albedo image is"):
        cpu_denoiser(noisy, albedo=np.zeros((8, 8, 3), np.float32))
    with pytest.raises(ValueError, match=r"\(height, width, 3\)"):
        cpu_denoiser(noisy[..., :2])
    with pytest.raises(ValueError, match="normal guide needs an albedo"):
        cpu_denoiser(noisy, normal=np.zeros_like(noisy))
    with pytest.raises(ValueError, match="quality"):
        Denoiser("cpu", quality="best")


def test_a_missing_library_gives_the_note_and_the_raw_image(monkeypatch):
    real_import = builtins.__import__

    def no_pyoidn(name, *args, **kwargs):
        if name == "pyoidn" or name.startswith("pyoidn."):
            raise ImportError("No module named 'pyoidn'")
        return real_import(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "pyoidn", raising=False)
    monkeypatch.setattr(builtins, "__import__", no_pyoidn)
    d = Denoiser("cpu")
    clean, noisy = _clean_and_noisy(size=16)
    noisy[0, 0] = np.nan
    out = d(noisy)
    assert not out.denoised and out.device is None
    assert "pip install pyoidn" in out.note and "as rendered" in out.note
    np.testing.assert_array_equal(out.image, sanitize(noisy))
    assert not d.available          # remembered: no second try every frame


def test_a_failing_filter_gives_the_note_and_the_raw_image(cpu_denoiser, monkeypatch):
    d = Denoiser("cpu")
    clean, noisy = _clean_and_noisy(size=16)
    assert d(noisy).denoised

    def broken(*args, **kwargs):
        raise RuntimeError("out of memory")

    monkeypatch.setattr(d, "_filter_for", broken)
    out = d(noisy[:8, :8].copy())
    assert not out.denoised and "out of memory" in out.note
    np.testing.assert_array_equal(out.image, noisy[:8, :8])
    d.close()


def test_shared_denoiser_is_one_per_setting():
    a = denoise_module.shared_denoiser("cpu", "fast")
    assert denoise_module.shared_denoiser("cpu", "fast") is a
    assert denoise_module.shared_denoiser("cpu", "high") is not a


# ---- the guides: GLSL against the NumPy twin --------------------------------------------------
CAMERA = {"eye": [0.35, 0.5, 1.6], "target": [0, 0, 0], "fov_y": 40.0, "width": 12, "height": 10}


def _ball_volume() -> Volume:
    """A ball of density with a soft rim inside a box, off-centre: normals point every way."""
    n = 20
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1) - 0.5
    r = np.sqrt((x - 0.08) ** 2 + y ** 2 + (z + 0.05) ** 2)
    data = np.clip((0.36 - r) / 0.08, 0.0, 1.0).astype(np.float32)
    return Volume(data, (1.0, 1.0, 1.0), "ball", (0.0, 1.0), "float32", 0.0, 1.0)


@pytest.mark.parametrize("tf", [{"colormap": "viridis"},
                                {"rgba": [[0.9, 0.2, 0.1, 0.0], [0.1, 0.8, 0.3, 1.0]]}])
def test_guides_match_their_numpy_twin(ctx, tf):
    volume = _ball_volume()
    scene = parse_scene({"volume": {"builtin": "empty", "size": [2, 2, 2]}, "transfer_function": tf,
                         "density_scale": 30.0, "albedo": 0.8, "camera": CAMERA})
    resources = SceneResources(ctx, scene, volume)
    guides = DenoiseGuides(ctx, resources.defines())
    try:
        camera = camera_frame(scene.camera)
        step = 2.0 * resources.march_step
        guides.run(resources, camera, step, frames=1, seed=7)
        albedo, normal = guides.read()
        want_albedo, want_normal = guide_frame(volume, resources.medium_table, 30.0, 0.8, camera,
                                               step, 2.0 * resources.march_step, frame=0, seed=7)
    finally:
        guides.release()
        resources.release()
    np.testing.assert_allclose(albedo, want_albedo, atol=2e-3)
    # GL filters with 8-bit fixed-point weights, and a normalised difference of two close fetches
    # amplifies that where the gradient is weak: a few pixels differ by up to 0.03, the mean not
    diff = np.abs(normal - want_normal)
    assert diff.mean() < 2e-3 and diff.max() < 0.06
    assert np.abs(want_normal).mean() > 0.05
    # the test means something: rays that miss are white, rays through the ball are not, and its
    # normals face the camera (towards +z of the eye, on the near side)
    assert (albedo.max(axis=-1) <= 1.0 + 1e-5).all()
    assert albedo[0, 0] == pytest.approx([1, 1, 1], abs=1e-5)
    centre = albedo[5, 6]
    assert centre.max() < 0.99
    assert normal[5, 6] @ np.array(CAMERA["eye"]) / np.linalg.norm(CAMERA["eye"]) > 0.3


# ---- in the renderer, the command line and the API ---------------------------------------------
def test_a_denoised_render_is_closer_to_the_converged_image(ctx):
    """Renderer.render(denoise=True) on a small cloud: the denoised 4-sample image is closer to a
    256-sample reference than the raw one, keeps its mean, and says what ran; every guide set
    runs (the probes' after a bake)."""
    from radiance_probes.rendering.metrics import rrmse
    from radiance_probes.rendering.renderer import Renderer
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [16, 16, 16]},
                         "density_scale": 40.0, "albedo": 0.9,
                         "camera": {"width": 40, "height": 32},
                         "probes": {"grid": [4, 4, 4], "samples": 16}})
    r = Renderer(ctx, scene)
    try:
        reference = r.render("pt", spp=256, seed=5).image
        result = r.render("pt", spp=4, seed=1, denoise=True)
        assert result.denoised.denoised and result.raw_image is not None
        assert rrmse(result.image, reference) < 0.8 * rrmse(result.raw_image, reference)
        assert abs(result.image.mean() / result.raw_image.mean() - 1) < 0.03
        r.bake()
        for guides in ("none", "albedo", "albedo-normal", "probes"):
            r.begin("pt")
            d, ms = r.denoise(result.raw_image, guides)
            assert d.denoised and np.isfinite(d.image).all() and ms >= 0.0
        # kept guides: the same camera and medium give the same arrays at no cost
        first = r.denoise_guides("albedo-normal")
        again = r.denoise_guides("albedo-normal")
        assert again[0] is first[0] and again[2] == 0.0
    finally:
        r.release()


def test_choose_guides_follows_the_records():
    from radiance_probes.rendering.denoise.filter import choose_guides
    assert choose_guides("auto", 4, has_probes=True) == "probes"
    assert choose_guides("auto", 1024, has_probes=True) == "none"
    assert choose_guides("auto", 4, has_probes=False) == "albedo-normal"
    assert choose_guides("auto", 64, has_probes=False) == "none"
    assert choose_guides("albedo", 4096, has_probes=False) == "albedo"
    with pytest.raises(ValueError, match="unknown denoise guides"):
        choose_guides("normals", 4, False)


def test_render_denoise_from_the_command_line_and_the_api(tmp_path, capsys):
    import radiance_probes as rp
    from radiance_probes.cli.main import main
    out = tmp_path / "d.png"
    assert main(["render", "--method", "pt", "--spp", "2", "--width", "24", "--height", "16",
                 "--denoise", "--out", str(out)]) == 0
    assert out.is_file() and "denoised on OIDN's cpu device" in capsys.readouterr().out
    image = rp.render(method="guided", spp=2, width=16, height=16, denoise=True,
                      probes={"grid": [4, 4, 4], "samples": 16})
    assert image.shape == (16, 16, 3) and not image.notes


def _step_until(s, done, max_samples, want_probes, limit_s=60.0):
    """Steps the session until done() (the filter's thread finishes between frames), within
    limit_s of wall time."""
    import time
    end = time.monotonic() + limit_s
    while not done():
        assert time.monotonic() < end, "the filtered image never came"
        s.step(max_samples, want_probes)
        time.sleep(0.002)


def test_the_viewers_denoise_switch(ctx, monkeypatch):
    """The session's Denoise: off by default on llvmpipe; switched on, the path tracer's view
    shows a filtered image, made again when its samples double (not every frame), dropped at a
    restart until the next; refine's guided image too. A failing filter switches it off with
    the note and the raw image shows."""
    from radiance_probes.viewer.frame import denoise_view
    from radiance_probes.viewer.frame.session import RenderSession
    monkeypatch.setattr(denoise_view, "INTERVAL_S", 1e9)   # the doubling rule alone
    s = RenderSession(ctx, parse_scene({
        "volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
        "albedo": 0.9, "camera": {"width": 24, "height": 16},
        "probes": {"grid": [2, 2, 2], "samples": 32, "fit": "box"}}))
    try:
        assert not s.denoise.enabled
        s.resize(24, 16)
        s.set_methods(["pt"])
        s.step(64, False)
        assert s.texture("pt") is s.views["pt"].acc.texture and s.denoise.runs == 0
        s.denoise.set_enabled(True)
        counts = []
        for _ in range(12):
            s.step(64, False)
            counts.append((s.views["pt"].acc.samples, s.denoise.runs))
        # the filter runs on its own thread (app/rendering/filter_worker.py): its image lands
        # on a later frame, which no frame waits for
        _step_until(s, lambda: s.denoise.runs > 0, 64, False)
        counts.append((s.views["pt"].acc.samples, s.denoise.runs))
        assert s.texture("pt") is not s.views["pt"].acc.texture
        filtered = s.denoise.images["pt"]
        # one filtered image per doubling of the samples, never more than one a frame
        samples = counts[-1][0]
        assert 1 <= counts[-1][1] <= 1 + samples.bit_length()
        assert counts[-1][1] < len(counts) or samples < 2
        assert filtered.samples <= samples < 2 * filtered.samples
        shown = np.frombuffer(s.texture("pt").read(), np.float32)
        assert np.isfinite(shown).all() and shown.max() > 0
        s.restart()
        view = s.views["pt"]   # raw until the next filter: paced by the wall clock (llvmpipe),
        # the last whole raw image until the new first sample is (RenderSession._begin)
        raw = view.held if view.shows_held else view.acc
        assert s.texture("pt") is raw.texture and raw.texture is not filtered.texture
        s.set_methods(["refine"])
        _step_until(s, lambda: s.refine_state()["shown"] == "guided" and s.denoise.texture(
            "refine", s.views["refine"], s.restarts) is not None, 256, True)
        assert s.texture("refine") is not s.views["refine"].acc.texture
        monkeypatch.setattr(denoise_view, "shared_denoiser",
                            lambda: type("Broken", (), {"staging": lambda *a: None,
                                                        "failure": "no library"})())
        s.set_methods(["pt"])
        s.step(256, False)
        assert not s.denoise.enabled and s.denoise.note == "no library"
        assert s.texture("pt") is s.views["pt"].acc.texture
    finally:
        s.release()


def test_keep_block_means_gives_back_the_raw_means():
    """keep_block_means: the whole image's mean exactly, each tile's to the interpolation's
    smoothing; a constant difference is added exactly; the tile means match a direct sum."""
    from radiance_probes.rendering.denoise.filter import _block_means, keep_block_means
    rng = np.random.default_rng(3)
    raw = rng.exponential(1.0, (70, 90, 3)).astype(np.float32)
    means = _block_means(raw, 32)
    assert means.shape == (3, 3, 3)
    np.testing.assert_allclose(means[2, 2], raw[64:, 64:].mean(axis=(0, 1)), rtol=1e-5)
    np.testing.assert_allclose(means[0, 1], raw[:32, 32:64].mean(axis=(0, 1)), rtol=1e-5)
    filtered = np.full_like(raw, 0.25)
    keep_block_means(means, filtered)
    assert filtered.mean() == pytest.approx(raw.mean(), rel=2e-3)
    flat = np.full_like(raw, 2.0)
    shifted = np.full_like(raw, 1.5)
    keep_block_means(_block_means(flat, 32), shifted)
    np.testing.assert_allclose(shifted, 2.0, rtol=1e-6)


def test_a_signed_image_keeps_its_negative_values_and_its_mean(cpu_denoiser):
    """guided's images are signed: filtered as such, negative regions stay negative and the mean
    stays the raw one's (clamping at 0 would raise it)."""
    y, x = np.mgrid[0:64, 0:64] / 64
    clean = np.stack([np.sin(6 * x) + 0.3 * y, 0.5 + 0 * x, 0.2 * np.cos(5 * y)], -1)
    clean = clean.astype(np.float32)
    rng = np.random.default_rng(4)
    noisy = clean + rng.normal(0.0, 0.3, clean.shape).astype(np.float32)
    signed = cpu_denoiser(noisy, signed=True).image
    clamped = cpu_denoiser(noisy, keep_means=False).image
    assert (signed[clean < -0.5] < 0).mean() > 0.9
    assert clamped.min() >= 0.0
    assert abs(signed.mean() - noisy.mean()) < 1e-3 * np.abs(noisy).mean() + 1e-4
    assert rmse(signed, clean) < 0.7 * rmse(noisy, clean)


def test_pyoidn_is_imported_without_torch(tmp_path, monkeypatch):
    """pyoidn's own `import torch` (tensor interop the project never uses, seconds of import on
    the filter's thread) fails while the project imports it; torch stays importable after."""
    (tmp_path / "pyoidn").mkdir()
    (tmp_path / "pyoidn" / "__init__.py").write_text(
        "try:\n    import torch\n    TORCH_AVAILABLE = True\nexcept ImportError:\n"
        "    TORCH_AVAILABLE = False\n")
    (tmp_path / "torch.py").write_text("IMPORTED = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("pyoidn", "torch"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    fake = denoise_module._import_pyoidn()
    assert fake.__file__.startswith(str(tmp_path))
    assert fake.TORCH_AVAILABLE is False
    assert "torch" not in sys.modules
    try:
        import torch   # noqa: F401 (the stand-in: still importable once pyoidn is in)
        assert sys.modules["torch"].IMPORTED
    finally:
        # the stand-ins out of sys.modules (monkeypatch puts back what was there before)
        sys.modules.pop("torch", None)
        sys.modules.pop("pyoidn", None)


@pytest.mark.parametrize("signed", [False, True])
def test_an_rgba_colour_filters_as_its_rgb_whatever_its_alpha(cpu_denoiser, signed):
    """An RGBA colour (the viewer's accumulations: alpha the sample count) is copied whole into
    the filter's buffer; its alpha, even NaN or infinite, changes nothing in the image, the
    means kept or the checks."""
    _, noisy = _clean_and_noisy(seed=3, size=40)
    if signed:
        noisy = noisy - 0.6 * noisy.mean()
    alpha = np.full(noisy.shape[:2] + (1,), 64.0, np.float32)
    alpha[3, 5], alpha[7, 1], alpha[0, 0] = np.nan, np.inf, 3e38
    rgba = np.ascontiguousarray(np.concatenate([noisy, alpha], axis=2))
    a = cpu_denoiser(noisy, signed=signed).image.copy()
    b = cpu_denoiser(rgba, signed=signed).image.copy()
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(b).all()


def test_a_signed_image_is_its_two_parts_filtered_apart(cpu_denoiser):
    """A signed image is filtered as its positive and its negative part, each by a filter of
    its own (the negative part written straight into its colour): the result is the two
    parts filtered alone, their difference; the caller's colour is left as it was."""
    _, noisy = _clean_and_noisy(seed=5, size=48)
    noisy = noisy - 0.7 * noisy.mean()
    given = noisy.copy()
    pos = cpu_denoiser(np.maximum(noisy, 0.0), keep_means=False).image.copy()
    neg = cpu_denoiser(np.maximum(-noisy, 0.0), keep_means=False).image.copy()
    d = cpu_denoiser(noisy, signed=True, keep_means=False)
    assert d.signed and d.denoised
    np.testing.assert_allclose(d.image, pos - neg, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(noisy, given)
    # an image with no negative pixel is one run, not signed
    assert not cpu_denoiser(np.abs(noisy), signed=True).signed


def test_a_guide_written_in_place_is_the_guide_given(cpu_denoiser):
    """guide_staging's memory, written and passed as the guide, filters as the same guide
    given as an array of its own; written anew, the new one is read, not the last."""
    clean, noisy = _clean_and_noisy(seed=6, size=40)
    albedo = np.clip(clean / clean.max(), 0.0, 1.0)
    h, w = noisy.shape[:2]
    a = cpu_denoiser(noisy, albedo).image.copy()
    view = cpu_denoiser.guide_staging(w, h, ("albedo",), "albedo")
    assert view.shape == (h, w, 3) and view.dtype == np.float32
    view[...] = albedo
    np.testing.assert_array_equal(cpu_denoiser(noisy, view).image, a)
    view[...] = 0.2 * albedo[::-1]
    b = cpu_denoiser(noisy, view).image.copy()
    c = cpu_denoiser(noisy, (0.2 * albedo[::-1]).copy()).image.copy()
    np.testing.assert_array_equal(b, c)
    assert np.abs(b - a).max() > 1e-3
    with pytest.raises(ValueError, match="normal"):
        cpu_denoiser.guide_staging(w, h, ("albedo",), "normal")


def test_tile_means_given_are_kept_as_its_own(cpu_denoiser):
    """raw_means (a GPU pass's, vec4 a tile) give the image _block_means would: the same
    result; a non-finite mean makes the colour usable and the means made again; a wrong shape
    is refused, naming it, and the denoiser stays usable."""
    from radiance_probes.rendering.denoise.filter import KEEP_MEANS_BLOCK, _block_means
    _, noisy = _clean_and_noisy(seed=7, size=70)
    means = _block_means(noisy, KEEP_MEANS_BLOCK)
    gpu_like = np.concatenate([means, np.zeros(means.shape[:2] + (1,))], axis=2)
    a = cpu_denoiser(noisy).image.copy()
    b = cpu_denoiser(noisy, raw_means=gpu_like.astype(np.float32)).image.copy()
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-6)
    broken = noisy.copy()
    broken[3, 4, 1] = np.nan
    bad = gpu_like.copy()
    bad[0, 0, 1] = np.nan
    c = cpu_denoiser(broken, raw_means=bad).image.copy()
    d = cpu_denoiser(broken).image.copy()
    np.testing.assert_array_equal(c, d)
    assert np.isfinite(c).all()
    with pytest.raises(ValueError, match="raw_means"):
        cpu_denoiser(noisy, raw_means=gpu_like[1:])
    assert cpu_denoiser.failure is None and cpu_denoiser(noisy).denoised


def test_radiance_as_albedo_into_a_buffer_of_its_own():
    """radiance_as_albedo's `out` holds what it returns without one, NaN, infinite and
    negative values as 0, from an RGBA image as from its RGB; a wrong `out` is refused."""
    from radiance_probes.rendering.denoise.filter import radiance_as_albedo
    rng = np.random.default_rng(8)
    image = rng.gamma(2.0, 0.5, (30, 20, 4)).astype(np.float32)
    image[1, 2, 0], image[3, 3, 2], image[5, 1, 1], image[0, 0, 3] = np.nan, np.inf, -2.0, np.nan
    want = radiance_as_albedo(image[..., :3].copy())
    out = np.full((30, 20, 3), 7.0, np.float32)
    got = radiance_as_albedo(image, out=out)
    assert got is out
    np.testing.assert_array_equal(out, want)
    assert out.min() >= 0.0 and out.max() <= 1.0 and out[1, 2, 0] == 0.0 and out[3, 3, 2] == 0.0
    # the scale is the quantile of the largest channel of the image made usable
    usable = sanitize(image[..., :3])
    scale = np.quantile(usable.max(axis=2), denoise_module.ALBEDO_SCALE_QUANTILE)
    np.testing.assert_allclose(want, np.clip(usable / scale, 0, 1), rtol=1e-6)
    with pytest.raises(ValueError, match="out"):
        radiance_as_albedo(image, out=np.zeros((30, 20, 4), np.float32))


def test_the_filter_thread_writes_the_probes_guide_in_place(cpu_denoiser):
    """A job with the probes guide made on the GPU (packed, flat): the thread copies it into the
    denoiser's memory; the image is the one the guide given as an array gives, the means to give
    back the colour's, and the output as the filter left it (no means kept on the thread)."""
    from radiance_probes.rendering.denoise.filter import KEEP_MEANS_BLOCK, _block_means
    from radiance_probes.rendering.denoise.filter_worker import FilterJob, FilterWorker
    from radiance_probes.twins.probe_albedo_guide import albedo_guide
    clean, noisy = _clean_and_noisy(seed=9, size=36)
    guide = albedo_guide(clean, denoise_module.ALBEDO_SCALE_QUANTILE)
    want = cpu_denoiser(noisy, guide.copy(), copy=True, keep_means=False).image
    worker = FilterWorker(cpu_denoiser)
    try:
        worker.submit("v", FilterJob(noisy, probe_albedo=guide.ravel().copy(), tag=1))
        result = None
        for _ in range(500):
            result = worker.take("v")
            if result is not None:
                break
            time.sleep(0.01)
        assert result is not None and result.rgb is not None
        np.testing.assert_array_equal(result.rgb, want)
        np.testing.assert_allclose(result.raw_means, _block_means(noisy, KEEP_MEANS_BLOCK),
                                   rtol=1e-6)
        assert not result.signed
    finally:
        worker.close()


@pytest.mark.parametrize("case", ["finite", "nan", "inf", "-inf", "negative", "float64"])
def test_radiance_as_albedo_is_the_sanitized_images_scaled(case):
    """Whichever way radiance_as_albedo goes (a finite float32 image divided as it is; else
    made usable first), the guide is the sanitized image over the quantile of its largest
    channel, clipped to [0, 1]: bit for bit what dividing the sanitized copy gives."""
    from radiance_probes.rendering.denoise.filter import radiance_as_albedo
    rng = np.random.default_rng(11)
    image = rng.gamma(2.0, 0.5, (25, 31, 3)).astype(np.float32)
    image[2, 3, 1] = {"finite": 1.0, "nan": np.nan, "inf": np.inf, "-inf": -np.inf,
                      "negative": -3.0, "float64": 2.0}[case]
    image[4, 4] = -1.0
    if case == "float64":
        image = image.astype(np.float64)
    usable = sanitize(image)
    peak = usable.max(axis=2)
    want = np.clip(usable / np.float32(np.quantile(peak, denoise_module.ALBEDO_SCALE_QUANTILE)),
                   0.0, 1.0)
    got = radiance_as_albedo(image)
    assert got.dtype == np.float32 and got.shape == image.shape
    np.testing.assert_array_equal(got, want.astype(np.float32))


@pytest.mark.parametrize("signed", [False, True])
def test_a_result_written_into_the_callers_array_is_the_copied_result(cpu_denoiser, signed):
    """Denoiser(out=): the result written into the caller's array (for a signed image the two
    parts' difference) is the image a copying call returns, bit for bit; an array of the wrong
    shape or type is refused by name."""
    clean, noisy = _clean_and_noisy(seed=21, size=40)
    colour = noisy - 0.3 * clean if signed else noisy
    want = cpu_denoiser(colour, signed=signed, copy=True, keep_means=False).image
    out = np.full(colour.shape[:2] + (3,), 9.0, np.float32)
    got = cpu_denoiser(colour, signed=signed, copy=False, keep_means=False, check_output=False,
                       out=out)
    assert got.image is out and got.signed == (signed and colour.min() < 0)
    np.testing.assert_array_equal(out, want)
    with pytest.raises(ValueError, match="out must be"):
        cpu_denoiser(colour, out=np.zeros(colour.shape[:2] + (4,), np.float32))


def test_a_signed_colour_told_it_has_no_negative_value_is_filtered_once(cpu_denoiser):
    """has_negative: the caller's word (the tile means' least values) replaces the host's look
    for a negative pixel: told True, a signed image is filtered as its two parts (the same image
    as when the denoiser looks); told False on a non-negative image, once (the same image too)."""
    clean, noisy = _clean_and_noisy(seed=23, size=40)
    signed = noisy - 0.3 * clean
    looked = cpu_denoiser(signed, signed=True, copy=True, keep_means=False)
    told = cpu_denoiser(signed, signed=True, copy=True, keep_means=False, has_negative=True)
    assert looked.signed and told.signed
    np.testing.assert_array_equal(told.image, looked.image)
    positive = cpu_denoiser(noisy, signed=True, copy=True, keep_means=False, has_negative=False)
    assert not positive.signed
    np.testing.assert_array_equal(positive.image,
                                  cpu_denoiser(noisy, copy=True, keep_means=False).image)

