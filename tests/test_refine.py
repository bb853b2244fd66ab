"""The viewer's `refine` mode: the half-buffer error estimate (NumPy, on synthetic noise of known
variance; and the GPU reduction against it), and the session showing the raymarcher at once after
an edit and `guided` later (app/rendering/refine/refine.py, app/viewer/frame/session.py)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.rendering.metrics import rrmse
from radiance_probes.rendering.refine.refine import (BLEND_SNAP, BlendPass, HalfBuffers,
                                                     blend_from_sums, blend_images, error_from_sums,
                                                     half_buffer_error, half_buffer_sums,
                                                     judge_sums)
from radiance_probes.io.scene_file import parse_scene

SHAPE = (48, 64, 3)


def _truth(rng) -> np.ndarray:
    y, x = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    base = 0.2 + 0.8 * np.exp(-((x - 30) ** 2 + (y - 20) ** 2) / 300.0)
    return (base[..., None] * np.array([1.0, 0.7, 0.4]) * rng.uniform(0.8, 1.2, SHAPE))


def _halves(rng, truth, sigma, n_a, n_b):
    """Each half the mean of its own n independent samples truth + sigma * N(0, 1)."""
    a = truth + sigma * rng.standard_normal((n_a, *SHAPE)).mean(axis=0)
    b = truth + sigma * rng.standard_normal((n_b, *SHAPE)).mean(axis=0)
    return a, b


@pytest.mark.parametrize("n_a, n_b, scale", [(8, 8, 0.3), (5, 11, 0.3), (1, 1, 1.2), (2, 3, 2.0)])
def test_half_buffer_estimate_matches_the_true_error_of_their_mean(n_a, n_b, scale):
    """Synthetic noise of known per-pixel variance (it varies over the image): the estimate is the
    true relative RMSE of the halves' mean within 5%, from small errors to noise larger than the
    signal, with equal and unequal halves."""
    rng = np.random.default_rng(7 + n_a + n_b)
    truth = _truth(rng)
    sigma = scale * truth.mean() * rng.uniform(0.2, 1.8, SHAPE)   # heteroscedastic, known
    a, b = _halves(rng, truth, sigma, n_a, n_b)
    m = (n_a * a + n_b * b) / (n_a + n_b)
    expected = math.sqrt(np.mean(sigma ** 2) / (n_a + n_b)) / math.sqrt(np.mean(truth ** 2))
    measured = rrmse(m, truth)
    est = half_buffer_error(a, b, n_a, n_b).guided
    assert est == pytest.approx(expected, rel=0.05)
    assert est == pytest.approx(measured, rel=0.05)
    # without the denominator's correction the noisiest cases would miss by far more
    if scale >= 1.2:
        naive = math.sqrt(np.mean((a - b) ** 2) * n_a * n_b / (n_a + n_b) ** 2
                          / np.mean(m ** 2))
        assert abs(naive / measured - 1) > 0.1


def test_equal_halves_give_the_briefs_formula():
    rng = np.random.default_rng(3)
    truth = _truth(rng)
    a, b = _halves(rng, truth, 0.1, 4, 4)
    brief = math.sqrt(np.mean((a - b) ** 2)) / (2 * math.sqrt(np.mean(((a + b) / 2) ** 2)))
    # the same up to the denominator's noise correction (tiny at this noise)
    assert half_buffer_error(a, b, 4, 4).guided == pytest.approx(brief, rel=0.01)


def test_raymarch_error_estimated_against_the_halves_mean():
    """A biased image (5% too dark, a little noise of its own) judged against the unbiased halves:
    its estimated error is its true error, even when the halves are noisier than its bias."""
    rng = np.random.default_rng(11)
    truth = _truth(rng)
    biased = truth * 0.95 + 0.01 * rng.standard_normal(SHAPE)
    for scale in (0.05, 0.4):
        a, b = _halves(rng, truth, scale * truth.mean(), 4, 4)
        est = half_buffer_error(a, b, 4, 4, raymarched=biased)
        assert est.raymarch == pytest.approx(rrmse(biased, truth), rel=0.1)
    assert math.isnan(error_from_sums((1.0, 1.0, 0.0, 10), 0, 3).guided)   # a half empty


def test_gpu_reduction_and_combine_match_numpy(ctx):
    rng = np.random.default_rng(5)
    h, w = 37, 53     # not a multiple of the 16 x 16 workgroup
    buffers = HalfBuffers(ctx, w, h)
    try:
        parts = [rng.uniform(-0.2, 1.0, (h, w, 4)).astype(np.float32) for _ in range(5)]
        accs = [buffers.halves[0].residual, buffers.halves[0].level0, buffers.halves[1].residual,
                buffers.halves[1].level0]
        from radiance_probes.rendering.methods.accumulation import Accumulation
        ray = Accumulation(ctx, w, h)
        for acc, data in zip([*accs, ray], parts):
            acc.texture.write(data.tobytes())
        buffers.halves[0].residual.samples, buffers.halves[1].residual.samples = 3, 5
        buffers.combine(ray, reduce=True)
        a = parts[0][..., :3].astype(np.float64) + parts[1][..., :3]
        b = parts[2][..., :3].astype(np.float64) + parts[3][..., :3]
        want = half_buffer_sums(a, b, 3, 5, parts[4][..., :3])
        got = buffers.read_sums()
        np.testing.assert_allclose(got[:3], want[:3], rtol=1e-4)
        assert got[3] == want[3] == h * w * 3
        rgba = buffers.combined.read_rgba()
        np.testing.assert_allclose(rgba[..., :3], (3 * a + 5 * b) / 8, rtol=1e-5, atol=1e-6)
        assert (rgba[..., 3] == 8).all() and buffers.combined.samples == 8
        # the judgement's pass (STAGE 3) against its twin, and half A written alone
        denoised = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
        buffers.denoised_a.write(denoised.tobytes())
        got = buffers.judge(ray)
        want = judge_sums(denoised[..., :3], b, parts[4][..., :3])
        np.testing.assert_allclose(got[:3], want[:3], rtol=1e-4)
        assert got[3] == want[3]
        buffers.combine(ray, write_half_a=True)
        half_a = buffers.half_a.read_rgba()
        np.testing.assert_allclose(half_a[..., :3], a, rtol=1e-6, atol=1e-6)
        assert (half_a[..., 3] == 3).all() and buffers.half_a.samples == 3
        # the copy the viewer adopts as its filtered image: exact (RGBA32F)
        adopted = ctx.texture((w, h), 4, dtype="f4")
        buffers.copy_denoised_a(adopted)
        np.testing.assert_array_equal(np.frombuffer(adopted.read(), np.float32).reshape(h, w, 4),
                                      denoised)
        adopted.release()
        # the display's blend against its twin
        blended = ctx.texture((w, h), 4, dtype="f4")
        blender = BlendPass(ctx)
        blender.run(ray.texture, buffers.denoised_a, blended, 0.3)
        out = np.frombuffer(blended.read(), np.float32).reshape(h, w, 4)
        np.testing.assert_allclose(out[..., :3], blend_images(parts[4][..., :3],
                                                              denoised[..., :3], 0.3),
                                   rtol=1e-6, atol=1e-6)
        assert (out[..., 3] == denoised[..., 3]).all()
        blender.release()
        blended.release()
        ray.release()
    finally:
        buffers.release()


# ---- the session: the raymarcher at once, guided later ------------------------------------------

# 2^3 probes over a dense cloud: the raymarcher's interpolation is visibly biased, so `guided`
# (unbiased) overtakes it within a few dozen samples at this size.
SCENE = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
         "albedo": 0.9, "camera": {"width": 24, "height": 16},
         "probes": {"grid": [2, 2, 2], "samples": 64, "fit": "box"}}
MAX_SAMPLES = 512


def _frames_until_guided(s, limit=400) -> int:
    for frame in range(limit):
        s.step(MAX_SAMPLES, True)
        if s.refine_state()["shown"] == "guided":
            return frame + 1
    raise AssertionError(f"refine still shows the raymarcher after {limit} frames: "
                         f"{s.refine_state()}")


def test_guided_never_starts_in_a_frame_that_baked_and_its_level0_goes_in_bands(ctx):
    """A frame that ran a bake slice adds no guided sample (its first pays a whole level-0
    frame); the first guided frame comes after the bake's last; and guided's level 0 is
    advanced in bands over its samples (a frame in progress seen between whole ones)."""
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE))
    try:
        s.resize(24, 16)
        s.set_methods(["refine"])
        view = s.views["refine"]
        baked_frames, partial = 0, False
        for _ in range(200):
            before = view.guided_samples
            times = s.step(MAX_SAMPLES, True)
            if s._baked_this_frame:
                baked_frames += 1
                assert view.guided_samples == before, "guided sampled in a frame that baked"
            partial |= any(h.level0.groups_done > 0 for h in view.halves.halves)
            if view.guided_samples >= 16:
                break
        assert baked_frames >= 1 and view.guided_samples >= 16
        assert partial, "guided's level 0 was never in bands"
    finally:
        s.release()


def test_refine_shows_the_raymarcher_at_once_then_guided_after_every_edit(ctx):
    from radiance_probes.viewer.frame.views import RefineView
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE))
    try:
        s.resize(24, 16)
        s.set_methods(["refine"])
        view = s.views["refine"]
        assert isinstance(view, RefineView)
        s.step(MAX_SAMPLES, True)            # first frame: a bake slice and the raymarcher's image
        st = s.refine_state()
        assert st["shown"] == "raymarch" and st["raymarch_samples"] >= 1
        assert np.abs(s.image("refine")).max() > 0
        np.testing.assert_array_equal(s.image("refine"), view.ray.read())
        assert "raymarch" in s.label("refine")
        frames = _frames_until_guided(s)
        st = s.refine_state()
        est = st["estimated_rrmse"]
        assert est["guided"] < est["raymarch"] and min(st["half_samples"]) >= 4
        assert st["reads"] < frames      # the read-back is not every frame
        np.testing.assert_array_equal(s.image("refine"), view.halves.combined.read())
        assert "guided" in s.label("refine") and "est. error" in s.label("refine")
        # edits: a camera move, then a sun move (a re-bake): the raymarcher's image at once again
        scene = s.scene
        cam = scene.camera
        for edited in (scene.replace(camera=replace(cam, eye=(cam.eye[0] + 0.3, *cam.eye[1:]))),
                       scene.replace(light=replace(scene.light, direction=(0.6, 0.6, 0.52)))):
            s.set_scene(edited)
            s.step(MAX_SAMPLES, True)
            st = s.refine_state()
            assert st["shown"] == "raymarch" and st["raymarch_samples"] >= 1
            np.testing.assert_array_equal(s.image("refine"), view.ray.read())
            _frames_until_guided(s)
        # guided converges to the exact image: run to the cap, then its estimated error is its
        # error against a path-traced reference (corrected for the reference's own noise)
        while not s.finished(MAX_SAMPLES, True):
            s.step(MAX_SAMPLES, True)
        assert s.refine_state()["guided_samples"] == MAX_SAMPLES
        est = s.refine_state()["estimated_rrmse"]["guided"]
        r = s.renderer
        ref_a = r.render("pt", spp=4096, seed=901).image
        ref_b = r.render("pt", spp=4096, seed=902).image
        reference = 0.5 * (ref_a + ref_b)
        noise2 = rrmse(ref_a, ref_b) ** 2 / 4          # the reference's own error, squared
        measured = math.sqrt(max(rrmse(s.image("refine"), reference) ** 2 - noise2, 0.0))
        assert 0.6 * measured < est < 1.5 * measured, (est, measured)
    finally:
        s.release()


def test_interact_quick_preset_replays_refine(ctx, tmp_path):
    """`bench --preset interact-quick` replays refine (here alone, on one of its scenes): every
    event's first frame shows the raymarcher, later frames guided, its errors against the
    references recorded with the time to 2%, and the report says whether each event got within 2%
    within 1 s."""
    import json

    from radiance_probes.bench.config import PRESETS
    from radiance_probes.bench.report import write_report
    from radiance_probes.bench.runner import run_bench
    preset = PRESETS["interact-quick"]
    assert "refine" in preset.interact_methods
    # at 32x24, a quarter of the preset's pixels (64x48 took 62 s on llvmpipe, 25 s here)
    path = run_bench(preset.scaled(scenes=("anisotropic",), interact_methods=("refine",),
                                   interact_sizes=((32, 24),)), tmp_path)
    data = json.loads(path.read_text())
    recs = [r for r in data["records"] if r["method"] == "refine" and r["event"] != "flicker"]
    assert [(r["event"], r["variant"]) for r in recs] == [
        ("load", None), ("orbit", None),
        *[(e, v) for e in ("tf_drag", "sun_30deg", "density", "albedo") for v in ("warm", "cold")]]
    took_over = 0
    for r in recs:
        shown = [f[3] for f in r["frame_trace"]]
        assert set(shown) <= {"raymarch", "guided"}
        first = 0 if r["event"] != "orbit" else r["orbit_frames"] - 1
        assert shown[first] == "raymarch", (r["event"], shown)   # at once after the event
        after = shown[first:]
        k = after.index("guided") if "guided" in after else len(after)
        assert set(after[k:]) <= {"guided"}, (r["event"], shown)   # never back to the raymarcher
        took_over += k < len(after)
        if r["converged"]:
            assert shown[-1] == "guided"
        assert "ms_to_2pct" in r and "wall_ms_to_2pct" in r
        assert r["final_rrmse"] is not None and np.isfinite(r["final_rrmse"])
    # guided replaced the raymarcher within the preset's 60 frames after most events (on this
    # cloud the raymarcher over 8^3 probes is far off; guided at 32x24 gets below it after 8 of
    # the 10 events)
    assert took_over >= len(recs) // 2, took_over
    # the flicker on a still camera: refine's window of frames, and the raw path tracer's from
    # the same wall time, whose accumulating image changes every frame
    flick = [r for r in data["records"] if r["event"] == "flicker"]
    assert len(flick) == 1 and flick[0]["method"] == "refine"
    f, p = flick[0]["flicker"], flick[0]["flicker_pt"]
    assert f["frames"] == p["frames"] == preset.interact_flicker_frames
    if p["stopped"]:   # at 32x24 the path tracer may reach the viewer's 1024 spp first
        assert p["change_mean"] == 0.0
    else:
        assert p["from_wall_ms"] >= f["from_wall_ms"]
        assert p["frames_changed"] == p["frames"] and p["change_mean"] > 0.0
    assert 0.0 <= f["change_mean"] <= f["change_max"] and np.isfinite(f["error"])
    if p["change_mean"] > 0.0:
        assert flick[0]["flicker_ratio"] == pytest.approx(f["change_mean"] / p["change_mean"])
    text = write_report(path).read_text()
    assert "Within 2% within 1 s of every event" in text
    assert "| anisotropic | 32x24 | 8^3x128 | refine | 10 |" in text
    assert "### Flicker on a still camera" in text and "| anisotropic | refine |" in text


@pytest.mark.parametrize("n_a, n_b, scale, bias", [(8, 8, 0.5, 0.05), (4, 12, 1.0, 0.1),
                                                   (16, 16, 2.0, 0.25), (8, 8, 0.2, 0.3)])
def test_blend_from_sums_finds_the_best_weight_from_the_halves_alone(n_a, n_b, scale, bias):
    """refine.blend_from_sums: a known, biased filter (a 5x5 box blur) on half a and a biased
    clean image r (a smooth field of relative size `bias`), judged against half b alone: the
    weight is the one the truth would choose for D(a) within 0.05, and each estimated relative
    RMSE (D(a)'s, r's, the blend's) is the true one within 10% (where the noise of b leaves
    the raymarcher's bias measurable)."""
    rng = np.random.default_rng(11 + n_a)
    truth = _truth(rng)
    sigma = scale * truth.mean() * rng.uniform(0.5, 1.5, SHAPE)
    a, b = _halves(rng, truth, sigma, n_a, n_b)
    pad = np.pad(a, ((2, 2), (2, 2), (0, 0)), mode="edge")
    blurred = sum(pad[dy:dy + SHAPE[0], dx:dx + SHAPE[1]] for dy in range(5) for dx in range(5)) / 25
    y, x = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    ray = truth * (1.0 + bias * np.sin(x / 9.0 + y / 13.0)[..., None])
    apart = ray - blurred
    best = float(np.clip(np.sum((ray - truth) * apart) / np.sum(apart * apart), 0.0, 1.0))
    got = blend_from_sums(half_buffer_sums(a, b, n_a, n_b), judge_sums(blurred, b, ray), n_a, n_b)
    assert got.weight == pytest.approx(best, abs=0.05)
    assert got.denoised == pytest.approx(rrmse(blurred, truth), rel=0.1)
    assert got.raymarch == pytest.approx(rrmse(ray, truth), rel=0.1)
    # the blend's own estimate is of the weight chosen on the same halves, so it errs low where
    # b's noise dominates (15% at noise 2x the signal, 16 samples)
    assert got.blend == pytest.approx(rrmse(blend_images(ray, blurred, got.weight), truth),
                                      rel=0.1 if scale < 2.0 else 0.2)
    assert got.blend <= min(got.denoised, got.raymarch) * 1.001
    empty = blend_from_sums(half_buffer_sums(a, b, 0, n_b), judge_sums(blurred, b, ray), 0, n_b)
    assert empty.weight == 0.0 and math.isnan(empty.blend)


def test_blend_weight_snaps_to_either_image_near_the_ends():
    """A weight within BLEND_SNAP of 0 or 1 is 0 or 1: the raymarcher's image exact (r = t), or
    the filter's exact (D = t), each against a noisy half b."""
    rng = np.random.default_rng(2)
    truth = _truth(rng)
    a, b = _halves(rng, truth, 0.3 * truth.mean(), 8, 8)
    off = truth * 1.2
    assert blend_from_sums(half_buffer_sums(a, b, 8, 8), judge_sums(off, b, truth), 8, 8).weight == 0.0
    assert blend_from_sums(half_buffer_sums(a, b, 8, 8), judge_sums(truth, b, off), 8, 8).weight == 1.0
    assert 0.0 < BLEND_SNAP < 0.1


def test_refine_blends_by_its_judgement_where_the_denoise_switch_is_on(ctx, monkeypatch):
    """With the Denoise switch on, checks judge the blend (app/viewer/frame/refine_judgement.py: half A
    read back and filtered on the filter's thread, judged with the raymarcher's image against
    half B of its check, over frames) once per 4x growth of the samples, and guided takes over
    from the first weight above 0, blended with the raymarcher's image: the display is then
    (1 - w) r + w D(m), D(m) the switch's own filtered image. The raw estimate is held above the
    raymarcher's (it alone never switches), and the judgement's weight is set to 0, then 0.4,
    then 1 (guided alone, judging ends). With the switch off nothing is judged."""
    import time

    from radiance_probes.rendering.refine.refine import RefineBlend, RefineEstimate
    from radiance_probes.viewer.frame import refine_judgement
    from radiance_probes.viewer.frame import session as session_module
    from radiance_probes.viewer.frame.session import REFINE_MIN_HALF_SAMPLES, RenderSession
    monkeypatch.setattr(session_module.HalfBuffers, "estimate_from",
                        lambda self, sums, with_ray: RefineEstimate(1.0, 0.5, self.samples))
    weights, judged = [0.0], []
    real = refine_judgement.blend_from_sums

    def judge(sums, judge_sums, n_a, n_b):
        got = real(sums, judge_sums, n_a, n_b)   # the GL path and the filter ran
        assert 0.0 <= got.weight <= 1.0 and math.isfinite(got.denoised)
        assert min(n_a, n_b) >= REFINE_MIN_HALF_SAMPLES
        judged.append(got)
        return RefineBlend(weights[0], 0.01, got.denoised, got.raymarch)
    monkeypatch.setattr(refine_judgement, "blend_from_sums", judge)
    # judgements come once the samples grow 4x: a cap far above where the first lands, however
    # many samples a (wall-clock paced) frame takes, leaves room for the three asked here
    CAP = 1 << 14

    def step_until(done, limit_s=120.0):
        end = time.monotonic() + limit_s
        while not done():
            assert time.monotonic() < end, s.refine_state()
            s.step(CAP, True)
            time.sleep(0.002)   # the filter's thread runs between frames
    s = RenderSession(ctx, parse_scene(SCENE))
    try:
        s.resize(24, 16)
        s.set_methods(["refine"])
        s.denoise.set_enabled(False)
        for _ in range(12):
            s.step(CAP, True)
        assert not judged and s.views["refine"].shown == "raymarch"
        s.denoise.set_enabled(True)
        s.restart()
        view = s.views["refine"]
        step_until(lambda: judged)
        assert view.shown == "raymarch"          # a weight of 0: the raymarcher
        assert len(judged) == 1
        weights[0] = 0.4
        step_until(lambda: view.shown != "raymarch")
        assert view.shown == "guided" and view.weight == 0.4 and view.blending
        s.step(CAP, True)
        shown = s.shown_image("refine")
        filtered = s.denoise.images["refine"]
        d = np.frombuffer(filtered.texture.read(), np.float32).reshape(16, 24, 4)[..., :3]
        np.testing.assert_allclose(shown, blend_images(view.ray.read(), d, 0.4), rtol=1e-5,
                                   atol=1e-6)
        assert "blended" in s.label("refine")
        weights[0] = 1.0
        count = len(judged)
        step_until(lambda: not view.blending)
        assert view.shown == "guided" and view.weight == 1.0 and not view.blending
        assert len(judged) == count + 1          # judged no more once guided is alone
        for _ in range(20):
            s.step(CAP, True)
        assert len(judged) == count + 1
        step_until(lambda: s.denoise.idle())
        s.step(CAP, True)
        d = np.frombuffer(s.denoise.images["refine"].texture.read(),
                          np.float32).reshape(16, 24, 4)[..., :3]
        np.testing.assert_array_equal(s.shown_image("refine"), d)
    finally:
        s.release()


def test_still_refine_with_denoise_blends_as_the_viewer_does(ctx, monkeypatch):
    """render("refine", denoise=True) judges as the viewer's Denoise switch does (OIDN on the CPU,
    the GL path): its stats give the weight and estimates, guided is shown where the weight is
    above 0, and the image is (1 - w) r + w D(m) of the raymarcher's image and the halves' mean
    denoised; without denoise nothing is judged."""
    from radiance_probes.rendering.refine import refine as refine_module
    from radiance_probes.rendering.refine.refine import RefineEstimate
    from radiance_probes.rendering.renderer import Renderer
    monkeypatch.setattr(refine_module.HalfBuffers, "estimate_from",
                        lambda self, sums, with_raymarch: RefineEstimate(1.0, 0.5, self.samples))
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        raw = r.render("refine", spp=16, seed=1)
        assert raw.stats["shown"] == "raymarch"
        assert raw.stats["refine_estimate"]["blend_weight"] is None
        den = r.render("refine", spp=16, seed=1, denoise=True)
        est = den.stats["refine_estimate"]
        w = est["blend_weight"]
        assert 0.0 <= w <= 1.0 and math.isfinite(est["guided_denoised"])
        assert den.stats["shown"] == ("guided" if w > 0.0 else "raymarch")
        if 0.0 < w < 1.0:
            assert den.denoised is not None and den.denoised.denoised, den.denoised.note
            assert est["blend"] <= min(est["guided_denoised"], est["raymarch"] + 1e-9) * 1.001
        # the weight the judgement gives, whatever it is, makes the image
        monkeypatch.setattr(refine_module, "blend_from_sums",
                            lambda *a: refine_module.RefineBlend(0.25, 0.0, 0.0, 0.0))
        mixed = r.render("refine", spp=16, seed=1, denoise=True)
        assert mixed.stats["shown"] == "guided"
        ray = r.render("raymarch", spp=16, seed=1).image
        np.testing.assert_allclose(mixed.image, blend_images(ray, mixed.denoised.image, 0.25),
                                   rtol=1e-4, atol=1e-5)
    finally:
        r.release()
