"""`auto` without a search (app/rendering/refine/auto_progressive.py): the error estimates against the
path tracer's two halves, checked on images whose error is known; the choice on a small scene,
checked against a converged reference."""
import math

import numpy as np
import pytest

from radiance_probes.rendering.metrics import rrmse
from radiance_probes.rendering.refine.auto_progressive import (RAYMARCH_FRAMES, Halves, auto_render,
                                                               denoised_aim, estimate_denoised,
                                                               estimate_image, estimate_pt,
                                                               should_judge_denoised)
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [20, 20, 20]}, "density_scale": 40.0,
         "camera": {"eye": [0, 0.3, 2.2], "width": 32, "height": 32}}


def _exact(shape=(96, 128, 3), seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    base = 0.2 + 0.8 * np.exp(-((x - 60) ** 2 + (y - 40) ** 2) / 900.0)
    return (base[..., None] * rng.uniform(0.5, 1.0, size=(1, 1, 3))).astype(np.float64)


@pytest.mark.parametrize("noise,bias", [(0.5, 0.02), (0.2, 0.05), (1.0, 0.01), (0.3, 0.0)])
def test_estimates_find_the_known_errors(noise, bias):
    """Halves of known per-sample noise around an exact image t, and an image r = t (1 + bias
    pattern) + its own noise: the path tracer's estimated error is the halves' mean's true one,
    and r's is its true error against t, each within a few of its standard errors; where r's
    error is far below the path tracer's noise it is still resolved."""
    t = _exact()
    rng = np.random.default_rng(7)
    halves = Halves(t.shape)
    spp = 4
    for half in (0, 1):
        sample_noise = rng.normal(size=t.shape) * noise * t / math.sqrt(spp)
        halves.add(half, t + sample_noise, spp)
    est, se, _ = estimate_pt(halves)
    true = rrmse(halves.mean(), t)
    assert abs(est - true) <= 4 * se + 1e-3, (est, true, se)
    pattern = np.sin(np.arange(t.shape[1]) / 7.0)[None, :, None]
    r = t * (1 + bias * pattern) + rng.normal(size=t.shape) * 0.002 * t
    est_r, se_r = estimate_image(r, halves)
    true_r = rrmse(r, t)
    assert abs(est_r - true_r) <= 4 * se_r + 2e-3, (est_r, true_r, se_r)
    assert se_r < 0.5 * noise / math.sqrt(2 * spp)   # far finer than the halves' own noise


@pytest.mark.parametrize("noise,blur", [(0.5, 3), (1.0, 5), (0.2, 3)])
def test_the_denoised_estimate_finds_a_filtered_halfs_known_error(noise, blur):
    """A stand-in denoiser (a box blur, biased at the image's slopes) on half a: its estimated
    error from half b is its true error against the exact image, within a few standard errors,
    though the blur's error is far below the halves' own noise."""
    def uniform_filter(image, size):
        k = size // 2
        padded = np.pad(image, ((k, k), (k, k), (0, 0)), mode="edge")
        h, w = image.shape[:2]
        return sum(padded[dy:dy + h, dx:dx + w] for dy in range(size)
                   for dx in range(size)) / size ** 2
    t = _exact()
    rng = np.random.default_rng(11)
    halves = Halves(t.shape)
    spp = 4
    for half in (0, 1):
        halves.add(half, t + rng.normal(size=t.shape) * noise * t / math.sqrt(spp), spp)
    filtered = uniform_filter(halves.means()[0], blur)
    est, se = estimate_denoised(filtered, halves)
    true = rrmse(filtered, t)
    assert abs(est - true) <= 4 * se + 2e-3, (est, true, se)
    assert true < 0.8 * estimate_pt(halves)[0]   # the case is one the denoiser wins


def test_the_denoised_candidate_is_judged_where_it_may_pass():
    """First round: judged. Then only where the last ratio of D(a)'s error to the raw error, times
    the raw error now, is within the target, or the samples grew 4x."""
    assert should_judge_denoised([], 2, 0.3, 0.05)
    last = [(4, 0.06, 0.2)]                      # the filter took the error to 0.3x the raw one
    assert not should_judge_denoised(last, 8, 0.18, 0.05)    # 0.3 x 0.18 = 0.054 > 0.05
    assert should_judge_denoised(last, 8, 0.16, 0.05)        # 0.048: may pass
    assert should_judge_denoised(last, 16, 0.5, 0.05)        # 4x the samples: judged anyway


def test_the_denoised_aim_follows_its_fall_and_stays_in_range():
    """Two judgements whose error fell as samples^-0.3 (within the clamp): the aim is where that
    fall meets the target; a steeper or flatter fall is clamped; one judgement gives no aim."""
    upper, target = 0.06, 0.05
    judged = [(8, 0.08, 0.3), (16, 0.08 * 2 ** -0.3, 0.2)]
    aim = denoised_aim(judged, upper, target)
    assert aim == pytest.approx(16 * (upper / target) ** (1 / 0.3) * 1.05)
    flat = [(8, 0.08, 0.3), (16, 0.0799, 0.2)]                  # alpha ~0: clamped at 0.15
    assert denoised_aim(flat, upper, target) == pytest.approx(16 * 1.2 ** (1 / 0.15) * 1.05)
    assert denoised_aim(judged[:1], upper, target) == math.inf
    assert denoised_aim(judged, 0.04, target) == pytest.approx(16 * 1.05)   # already within


def test_auto_with_the_denoiser_returns_a_denoised_path_tracer_within_the_target(ctx):
    """With denoise, the path tracer denoised is a candidate (OIDN on the CPU here): where no
    probe setting reaches the target it wins with fewer samples than the raw path tracer needs, and its
    image is within the target of a converged reference."""
    from radiance_probes.rendering.denoise.filter import shared_denoiser
    if not shared_denoiser("auto").available:
        pytest.fail(f"the denoiser should load in the test environment: "
                    f"{shared_denoiser('auto').failure}")
    # OIDN needs an image of some size to find structure in (at 32^2 it loses to the raw image)
    r = Renderer(ctx, parse_scene({**SCENE, "camera": {**SCENE["camera"], "width": 96,
                                                       "height": 96}}))
    try:
        reference = r.render("pt", spp=1024, seed=99, samples_per_pass=256).image
        # a ladder whose one setting does not reach 5% (as in the fallback test below)
        raw = auto_render(r, 0.05, ladder=((2, 16),), max_pt_spp=8192)
        got = auto_render(r, 0.05, ladder=((2, 16),), max_pt_spp=8192, denoise=True)
        assert raw.method == "pt" and not raw.denoised
        assert got.met and got.denoised and got.method == "pt", got.report()
        assert got.pt_spp < raw.pt_spp, (got.pt_spp, raw.pt_spp)
        assert rrmse(got.image, reference) <= 0.05 + 0.015, got.report()   # the reference's noise
        assert "denoised" in got.report() and any(t.get("method") == "pt+denoise"
                                                  for t in got.trials)
        assert got.gpu_ms > got.pt_ms   # the guides and filters are charged
        judged = [t for t in got.trials if t.get("method") == "pt+denoise"]
        assert all(t["filter_ms"] > 0 for t in judged)
        assert got.gpu_ms - got.pt_ms >= sum(t["filter_ms"] for t in judged)
        assert got.denoise_setup_ms > 0 and "set-up" in got.report()
    finally:
        r.release()


def test_auto_returns_an_image_within_the_target(ctx):
    """On a small cloud, loose target: the image returned (raymarched or path traced) is within
    the target of a converged reference, and the report and the cost say what was spent."""
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        reference = r.render("pt", spp=2048, seed=99, samples_per_pass=256).image
        before = r.scene
        got = auto_render(r, 0.15, ladder=((2, 16), (4, 16), (6, 64)), max_pt_spp=4096)
        assert got.met and got.estimate + 2 * got.standard_error <= 0.15
        true = rrmse(got.image, reference)
        assert true <= 0.15 + 0.03, (true, got.report())     # the reference's own noise
        assert got.gpu_ms >= got.pt_ms > 0 and got.pt_spp >= 2
        if got.method == "raymarch":
            assert r.scene is got.scene and got.scene.probes.grid[0] in (2, 4, 6)
            # the image's own time: its render (and its bake), not the rejected settings'
            assert got.image_spp == RAYMARCH_FRAMES and got.image_ms > 0
            chosen = got.trials[-1]["ms"]
            assert got.image_ms + got.image_bake_ms == pytest.approx(chosen)
        else:
            assert r.scene == before
            assert (got.image_spp, got.image_ms) == (got.pt_spp, got.pt_ms)
        assert np.isfinite(got.image).all() and got.image.min() >= 0
        assert "auto:" in got.report()
        # the trials' lines once each: in the log (what progress printed), out of report(log=False)
        assert got.report().splitlines()[1:] == ["  " + line for line in got.log]
        assert got.report(log=False) == got.report().splitlines()[0]
    finally:
        r.release()


def test_auto_falls_back_to_the_path_tracer_where_no_probes_reach_the_target(ctx):
    """A target no probe setting of the ladder reaches: the path tracer's image, with the trials
    capped by their share of its time."""
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        got = auto_render(r, 0.04, ladder=((2, 16),), max_pt_spp=8192)
        assert got.method == "pt" and got.met
        assert all(t["grid"] == 2 for t in got.trials)
        # ms per sample is the path tracer's own: the rejected setting's bake is left out
        assert (got.image_spp, got.image_ms) == (got.pt_spp, got.pt_ms)
        assert got.gpu_ms > got.image_ms
    finally:
        r.release()


def test_auto_rejects_a_meaningless_target(ctx):
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        with pytest.raises(ValueError, match="target"):
            auto_render(r, 1.5)
    finally:
        r.release()


def test_the_path_tracers_rounds_stop_near_the_samples_the_target_needs():
    """An error falling exactly as 1 / sqrt(samples): the rounds never more than double, always
    add samples, and stop within PT_MARGIN and a round's rounding of the samples the target
    needs (doubling every round overshot by up to 2x)."""
    from radiance_probes.rendering.refine.auto_progressive import PT_MARGIN, Z, next_pt_spp
    for target, c in ((0.02, 0.47), (0.01, 0.31), (0.05, 0.9), (0.013, 0.2)):
        need = (c / target) ** 2            # error c / sqrt(spp); se 1% of the estimate
        spp = 2
        while True:
            est = c / math.sqrt(spp)
            if est + Z * 0.01 * est <= target:
                break
            nxt = next_pt_spp(spp, est, 0.01 * est, target)
            assert spp + 2 <= nxt <= 2 * spp and nxt % 2 == 0
            spp = nxt
        assert need <= spp * (1 + Z * 0.01) ** 2
        assert spp <= max(need * (1 + Z * 0.01) ** 2 * PT_MARGIN + 2, 4), (target, spp, need)
    assert next_pt_spp(8, math.inf, math.inf, 0.01) == 16


def test_the_command_line_prints_each_trial_once(tmp_path, capsys):
    """render --auto: each trial's line once (as it comes), then the outcome; the time per sample
    printed is the image's own."""
    import json

    from radiance_probes.cli.main import main
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(SCENE))
    assert main(["render", str(scene), "--auto", "0.1", "--out", str(tmp_path / "a.png")]) == 0
    out, err = capsys.readouterr()
    lines = [line.removeprefix("auto:").strip() for line in (out + err).splitlines()
             if "rRMSE" in line]
    assert sum("probes" in line for line in lines) >= 1, out + err   # a trial was made
    assert len(lines) == len(set(lines)), out + err
    # the image's own time: per sample, or per frame where the raymarcher's image was chosen
    assert ("ms per frame" if "raymarched over" in out else "ms per sample") in out, out
