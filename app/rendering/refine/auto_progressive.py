"""`auto` without a separate search: the cheapest image whose estimated error is within a target,
a raymarched one over probes where some probe setting reaches it, else the path tracer's own.

The path tracer's image accumulates at full resolution as two independent halves (a round
doubles its samples, or adds fewer where its error's fall predicts the target sooner:
next_pt_spp). It is the reference everything is judged against, and also the fallback:
- its own relative RMSE is estimated from the halves (app/rendering/refine/refine.py: N^2 = w mean((a -
  b)^2) estimates the mean's noise, T^2 = mean(m^2) - N^2 the image's power);
- a raymarched image r (independent of the halves) has E[mean((r - m)^2)] = its squared error +
  N^2, so mean((r - m)^2 - w (a - b)^2) / T^2 estimates its squared relative error. Averaged over
  every pixel, that estimate is precise long before the path tracer itself is within the target
  (the per-pixel noise averages away): on a 512^2 image a few to a few tens of samples decide a
  probe setting at 1%.

Every estimate carries its standard error over pixels (a pixel's three channels summed, so that
they count once); a decision waits until the interval (EST +- Z standard errors) is on one side of
the target. Probe settings are tried from the cheapest (LADDER, by bake cost), and only while what
has been spent on them, with the next one's expected cost (the last one's scaled by probes x
walks, by at most GROWTH), is within EXPLORE_SHARE of the path tracer's time so far plus its estimated time still to
go: where no setting reaches the target (a floor of the probes above it) the trials cost at most
that share over the path tracer's own time (a quarter: half found probe images on two cheap scenes
that a quarter misses, 17 ms, and cost bonsai 0.25 to 0.8 s more where none is found;
bench/h100-auto-progressive v5). A setting whose estimate is a standard error above the target
gives way to the next; one not yet told apart from it is kept while the path tracer's samples
narrow the interval. Everything counts: bakes, light grids, raymarched frames and path
traced samples (GPU time), and the host's wall time is reported beside it.

With `denoise` the path tracer denoised is a candidate too (issue 42). Half a's image through the
denoiser, D(a), is independent of half b, so E[mean((D(a) - b)^2)] = its squared error + Var(b),
and Var(b) is the share n_a / (n_a + n_b) of E[(a - b)^2]: mean((D(a) - b)^2 - n_a / (n_a + n_b)
(a - b)^2) / T^2 estimates D(a)'s squared relative error (estimate_denoised). Once that is within
the target the image returned is both halves' mean denoised, which has twice D(a)'s samples; the
estimate reported is D(a)'s, an upper bound in expectation. The guides (albedo and normal, made
once: their GPU ms) and every filter run (its own wall ms: the colour's copy into the filter's
memory, the filter, the output's read and the tile means kept) are charged to the search. The
filter's set-up (its weights' load and the device's first run) happens once a process, before the
first judgement, and is reported beside the total, not in it, as the shaders' compiles are not.

A judgement costs a filter run, so D(a) is judged at the first round and then only where it may
pass: where the last judgement's ratio of D(a)'s error to the raw image's, times the raw image's
error now, is within the target (the ratio grows with the samples: the prediction errs low, so a
round that may pass is not skipped), or the samples have grown JUDGE_GROWTH times since. After two
judgements the rounds aim at the samples where D(a)'s error, falling as samples^-alpha (alpha from
those two, clamped to DENOISED_FALL), meets the target, where that is sooner than the raw path
tracer's aim: the filter's error falls slower than the raw one's, so the raw aim overshoots.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from radiance_probes.io.scene_file import Scene
from radiance_probes.rendering.probes.auto import PROBES_PER_VOXEL_LIMIT
from radiance_probes.methods import METHODS
from radiance_probes.rendering.refine.refine import weight

# (probes per axis, walks per probe), in order of bake cost (probes x walks, then probes)
LADDER = ((8, 16), (16, 16), (32, 16), (32, 64), (64, 64), (128, 64), (128, 256), (192, 64),
          (256, 64))
RAYMARCH_FRAMES = 8        # a candidate's raymarched frames (its sub-pixel jitter averaged)
EXPLORE_SHARE = 0.25       # probe trials' time at most this share of the path tracer's expected
GROWTH = 3.0               # a trial expected to cost at most this many times the one before
Z = 2.0                    # standard errors a decision stands clear of the target by
MAX_PT_SPP = 1 << 16
PT_MARGIN = 1.05           # the path tracer's next round aims this many times the samples predicted
JUDGE_GROWTH = 4           # the denoised candidate is judged again at least every 4x the samples
DENOISED_FALL = (0.15, 0.5)   # the denoised error's fall with samples, samples^-alpha: alpha's range


@dataclass
class AutoResult:
    image: np.ndarray
    method: str                    # "raymarch" (over the probes chosen) or "pt"
    scene: Scene                   # the scene rendered (the probes chosen, for raymarch)
    target: float
    estimate: float                # the image's estimated relative RMSE
    standard_error: float          # of that estimate
    met: bool
    pt_spp: int                    # the path tracer's samples per pixel spent (both halves)
    gpu_ms: float                  # everything the image cost on the GPU
    pt_ms: float                   # of which the path tracer's
    wall_s: float
    trials: list[dict] = field(default_factory=list)
    log: list[str] = field(default_factory=list)
    # The image returned alone: its samples per pixel, its render's GPU ms and its probes' bake
    # (the rejected settings' bakes and the path tracing a raymarched image was judged by are
    # in gpu_ms only), for a time per sample that is the image's own.
    image_spp: int = 0
    image_ms: float = 0.0
    image_bake_ms: float = 0.0
    denoised: bool = False         # the path tracer's image through the denoiser (auto's denoise)
    denoise_setup_ms: float = 0.0  # the filter's set-up, once a process (wall ms, not in gpu_ms)

    def report(self, log: bool = True) -> str:
        """The outcome, then (log=True) every trial's line; a caller that printed the lines as
        they came (progress) leaves them out."""
        what = (f"raymarched over {self.scene.probes.grid[0]}^3 probes x "
                f"{self.scene.probes.samples} walks" if METHODS[self.method].needs_probes
                else f"the path tracer at {self.pt_spp} spp"
                + (", denoised" if self.denoised else ""))
        head = (f"auto: {what}: estimated rRMSE {self.estimate:.4f} (+- {self.standard_error:.4f})"
                f", target {self.target:.4f} {'met' if self.met else 'NOT met'}; "
                f"{self.gpu_ms:.1f} ms of GPU time in all ({self.pt_ms:.1f} ms path tracing), "
                f"{self.wall_s:.2f} s wall"
                + (f" (the denoiser's set-up {self.denoise_setup_ms:.0f} ms of it)"
                   if self.denoise_setup_ms else ""))
        return "\n".join([head, *("  " + line for line in (self.log if log else ()))])


def _per_pixel(x: np.ndarray) -> np.ndarray:
    """[H, W, 3] -> [H * W] float64: a pixel's channels summed."""
    return np.asarray(x, np.float64).reshape(-1, x.shape[-1]).sum(axis=1)


class Halves:
    """The path tracer's two independent halves, accumulated on the host."""

    def __init__(self, shape):
        self.sums = [np.zeros(shape, np.float64), np.zeros(shape, np.float64)]
        self.counts = [0, 0]
        self._terms = None             # terms() of the samples so far

    def add(self, half: int, image: np.ndarray, spp: int) -> None:
        self.sums[half] += np.asarray(image, np.float64) * spp
        self.counts[half] += spp
        self._terms = None

    @property
    def spp(self) -> int:
        return sum(self.counts)

    def means(self):
        return [s / max(n, 1) for s, n in zip(self.sums, self.counts)]

    def mean(self) -> np.ndarray:
        return (self.sums[0] + self.sums[1]) / max(self.spp, 1)

    def terms(self):
        """(per-pixel noise terms w (a - b)^2, per-pixel m^2, m): refine.py's sums, per pixel
        (computed once per batch of samples: a round judges the path tracer and its trials on
        the same)."""
        if self._terms is None:
            a, b = self.means()
            m = self.mean()
            self._terms = (_per_pixel(weight(*self.counts) * (a - b) ** 2), _per_pixel(m * m), m)
        return self._terms


def _interval(values: np.ndarray, signal2: float) -> tuple[float, float]:
    """(the relative error sqrt(mean(values) / signal2) clipped at 0, its standard error by the
    delta method from the pixels' spread)."""
    mean = float(values.mean())
    se = float(values.std(ddof=1) / math.sqrt(len(values)))
    est = math.sqrt(max(mean, 0.0) / signal2)
    # d sqrt(x) = dx / (2 sqrt(x)); near 0 the bound sqrt(se / signal2) instead
    err = se / signal2 / (2 * est) if est > 0 else math.sqrt(se / signal2)
    return est, min(err, math.sqrt(se / signal2) + est)


def estimate_pt(halves: Halves) -> tuple[float, float, float]:
    """(the halves' mean's estimated relative RMSE, its standard error, T^2 per pixel)."""
    noise, power, _ = halves.terms()
    signal2 = float(power.mean() - noise.mean())
    if not signal2 > 0:
        return math.inf, math.inf, 0.0
    est, se = _interval(noise, signal2)
    return est, se, signal2


def estimate_image(image: np.ndarray, halves: Halves) -> tuple[float, float]:
    """An image's (independent of the halves) estimated relative RMSE against the exact image and
    its standard error (the module's note)."""
    noise, power, m = halves.terms()
    signal2 = float(power.mean() - noise.mean())
    if not signal2 > 0:
        return math.inf, math.inf
    values = _per_pixel((np.asarray(image, np.float64) - m) ** 2) - noise
    return _interval(values, signal2)


def estimate_denoised(denoised_a: np.ndarray, halves: Halves) -> tuple[float, float]:
    """Half a's image denoised (independent of half b): its estimated relative RMSE against the
    exact image and its standard error (the module's note)."""
    noise, power, _ = halves.terms()
    signal2 = float(power.mean() - noise.mean())
    if not signal2 > 0:
        return math.inf, math.inf
    a, b = halves.means()
    n_a, n_b = halves.counts
    values = (_per_pixel((np.asarray(denoised_a, np.float64) - b) ** 2)
              - (n_a / max(n_a + n_b, 1)) * _per_pixel((a - b) ** 2))
    return _interval(values, signal2)


def candidates(scene: Scene, volume_dims, ladder=LADDER) -> list[Scene]:
    """The ladder's probe settings for `scene`, cheapest first: SH order, precision, fit and
    channels as `auto_probes` sets them; grids of at most PROBES_PER_VOXEL_LIMIT probes a voxel
    along the volume's longest axis."""
    limit = PROBES_PER_VOXEL_LIMIT * max(volume_dims)
    ladder = [(g, n) for g, n in ladder if g <= limit] or [ladder[0]]
    return [scene.replace(probes=replace(scene.probes, grid=(g, g, g), samples=n,
                                         sh_order="auto", precision="rgba16f", fit="visible",
                                         channels="auto"))
            for g, n in ladder]


def _predicted_ms(ladder: list[Scene], k: int, trials: list[dict]) -> float:
    """What setting k is expected to cost: the last trial's cost scaled by probes x walks (the
    bake's work), by at most GROWTH (on the H100 a step of the ladder cost 1.2 to 7x the one
    before, the bakes' fixed costs weighing most at the small ones)."""
    last = trials[-1]
    p = ladder[k].probes

    def work(grid: int, walks: int) -> float:
        return float(grid) ** 3 * walks
    ratio = work(p.grid[0], p.samples) / work(last["grid"], last["walks"])
    return last["ms"] * min(max(ratio, 1.0), GROWTH)


def next_pt_spp(spp: int, estimate: float, standard_error: float, target: float) -> int:
    """The halves' samples in all after the next round: as many as the path tracer's error
    falling as 1 / sqrt(samples) predicts take its upper bound (estimate + Z standard errors)
    to the target, PT_MARGIN over; at most twice `spp` (the trials are judged once a round, and
    an early estimate is rough), at least 2 more. Doubling every round instead spent up to
    twice the samples the target needed (bonsai at 2%: 1024 spp for an error of 1.49%)."""
    upper = estimate + Z * standard_error
    need = spp * (upper / target) ** 2 * PT_MARGIN if math.isfinite(upper) else 2.0 * spp
    return round_samples(need, spp)


def round_samples(need: float, spp: int) -> int:
    """A round's aim of `need` samples in all as the halves take it: whole, even, at least 2 more
    than `spp` and at most twice it."""
    total = min(max(math.ceil(need), spp + 2), 2 * spp)
    return total + total % 2


def should_judge_denoised(judgements: list[tuple[int, float, float]], spp: int,
                          pt_estimate: float, target: float) -> bool:
    """Whether a round judges the denoised candidate (the module's note): `judgements` holds
    (samples, D(a)'s estimate, the raw image's estimate then) of those so far."""
    if not judgements:
        return True
    last_spp, denoised, raw = judgements[-1]
    if spp >= JUDGE_GROWTH * last_spp:
        return True
    ratio = denoised / raw if raw > 0 and math.isfinite(raw) else 1.0
    return ratio * pt_estimate <= target


def denoised_aim(judgements: list[tuple[int, float, float]], upper: float, target: float) -> float:
    """The samples (both halves) where D(a)'s error, now `upper` (estimate + Z standard errors)
    at the last judgement's samples, meets the target if it falls as samples^-alpha, alpha from
    the last two judgements within DENOISED_FALL; inf before two judgements."""
    if len(judgements) < 2 or not math.isfinite(upper):
        return math.inf
    (n0, e0, _), (n1, e1, _) = judgements[-2:]
    alpha = (math.log(e0 / e1) / math.log(n1 / n0)
             if n1 > n0 and e0 > 0 and e1 > 0 else DENOISED_FALL[0])
    alpha = min(max(alpha, DENOISED_FALL[0]), DENOISED_FALL[1])
    return n1 * max(upper / target, 1.0) ** (1.0 / alpha) * PT_MARGIN


def auto_render(renderer, target: float, progress=None, seed: int = 0,
                max_pt_spp: int = MAX_PT_SPP, ladder=LADDER, denoise: bool = False) -> AutoResult:
    """Renders the scene the renderer holds within `target` (estimated relative RMSE) as cheaply
    as the module's note says; leaves the renderer on the scene of the image returned. `denoise`:
    the path tracer denoised is a candidate too (where the denoiser cannot run, a note in the log
    and the search goes on without it)."""
    if not 0 < target <= 1:
        raise ValueError(f"auto target must be a relative RMSE in (0, 1], got {target}")
    start = time.perf_counter()
    original = renderer.scene
    ladder = candidates(original, renderer.resources.volume.dims, ladder)
    log: list[str] = []

    def say(line: str) -> None:
        log.append(line)
        if progress:
            progress(line)

    halves = None
    pt_ms = trial_ms = 0.0
    denoiser = guides = None
    if denoise:
        from radiance_probes.rendering.denoise.filter import shared_denoiser
        denoiser = shared_denoiser()
        if not denoiser.available:
            say(f"denoised candidates left out: {denoiser.failure}")
            denoiser = None
    judgements: list[tuple[int, float, float]] = []   # the denoised candidate's (should_judge_denoised)
    setup_ms = 0.0
    trials: list[dict] = []
    current = None            # (index into ladder, image, bake+render ms) of the probe setting
    k = 0
    batch = 1
    round_ = 0
    while True:
        # the path tracer: a batch for each half (the original scene: probes do not matter)
        if renderer.scene is not original:
            renderer.set_scene(original)
        for half in (0, 1):
            run = renderer.render("pt", spp=batch, seed=seed + 1000 * round_ + half,
                                  samples_per_pass=min(batch, 64))
            if halves is None:
                halves = Halves(run.image.shape)
            halves.add(half, run.image, batch)
            pt_ms += run.render_ms
        pt_est, pt_se, _ = estimate_pt(halves)
        say(f"path tracer {halves.spp} spp: rRMSE {pt_est:.4f} (+- {pt_se:.4f}), "
            f"{pt_ms:.1f} ms")
        if pt_est + Z * pt_se <= target:
            renderer.set_scene(original)
            return AutoResult(halves.mean().astype(np.float32), "pt", original, target, pt_est,
                              pt_se, True, halves.spp, pt_ms + trial_ms, pt_ms,
                              time.perf_counter() - start, trials, log, halves.spp, pt_ms,
                              denoise_setup_ms=setup_ms)
        denoised_upper = math.inf
        if denoiser is not None and should_judge_denoised(judgements, halves.spp, pt_est, target):
            if guides is None:   # the scene's camera and medium: made once, kept
                renderer.begin("pt")
                albedo, normal, guides_ms = renderer.denoise_guides("albedo-normal")
                guides = (albedo, normal)
                trial_ms += guides_ms
                height, width = halves.sums[0].shape[:2]
                setup_ms = denoiser.warm(width, height, ("albedo", "normal"))
                say(f"denoiser ready on {denoiser.device or 'no device'} in {setup_ms:.0f} ms "
                    f"(once a process, not charged)")
            d_a = denoiser(halves.means()[0].astype(np.float32), *guides)
            trial_ms += d_a.total_ms
            if not d_a.denoised:   # the filter failed: the search goes on without it
                say(f"denoised candidates left out: {d_a.note}")
                denoiser = None
            else:
                est, se = estimate_denoised(d_a.image, halves)
                judgements.append((halves.spp, est, pt_est))
                denoised_upper = est + Z * se
                trials.append({"method": "pt+denoise", "pt_spp": halves.spp, "rrmse": est,
                               "standard_error": se, "filter_ms": d_a.total_ms})
                say(f"path tracer denoised: rRMSE {est:.4f} (+- {se:.4f}) from half its "
                    f"{halves.spp} spp, {d_a.total_ms:.1f} ms filter")
            if denoiser is not None and denoised_upper <= target:
                d_m = denoiser(halves.mean().astype(np.float32), *guides)
                trial_ms += d_m.total_ms
                if d_m.note:
                    say(d_m.note)
                renderer.set_scene(original)
                return AutoResult(np.asarray(d_m.image, np.float32), "pt", original, target, est,
                                  se, True, halves.spp, pt_ms + trial_ms, pt_ms,
                                  time.perf_counter() - start, trials, log, halves.spp, pt_ms,
                                  denoised=d_m.denoised, denoise_setup_ms=setup_ms)
        # the path tracer's expected time still to go: its error falls as 1 / sqrt(samples)
        pt_to_go = pt_ms * max((pt_est / target) ** 2 - 1.0, 0.0)
        while k < len(ladder):
            if current is None:
                allowed = EXPLORE_SHARE * (pt_ms + pt_to_go)
                tried = [t for t in trials if "grid" in t]   # the probe settings' trials
                if tried and trial_ms + _predicted_ms(ladder, k, tried) > allowed:
                    break                  # more path tracing first: the trial would not pay
                renderer.set_scene(ladder[k])
                run = renderer.render("raymarch", spp=RAYMARCH_FRAMES, seed=seed + 77,
                                      samples_per_pass=RAYMARCH_FRAMES)
                cost = run.bake_ms + run.render_ms
                trial_ms += cost
                current = (k, run.image, cost, run)
            index, image, cost, chosen = current
            est, se = estimate_image(image, halves)
            p = ladder[index].probes
            trial = {"grid": p.grid[0], "walks": p.samples, "ms": cost, "pt_spp": halves.spp,
                     "rrmse": est, "standard_error": se}
            trials.append(trial)
            say(f"probes {p.grid[0]}^3 x {p.samples}: rRMSE {est:.4f} (+- {se:.4f}) "
                f"after {halves.spp} spp, {cost:.1f} ms")
            if est + Z * se <= target:
                renderer.set_scene(ladder[index])
                return AutoResult(np.asarray(image, np.float32), "raymarch", ladder[index],
                                  target, est, se, True, halves.spp, pt_ms + trial_ms, pt_ms,
                                  time.perf_counter() - start, trials, log, chosen.spp,
                                  chosen.render_ms, chosen.bake_ms, denoise_setup_ms=setup_ms)
            if est - se > target:
                k, current = k + 1, None   # above (a standard error clear): the next setting
                continue
            break                          # not yet told apart: more path tracing narrows it
        if halves.spp >= max_pt_spp:
            renderer.set_scene(original)
            say(f"stopped at {halves.spp} spp, the most allowed")
            return AutoResult(halves.mean().astype(np.float32), "pt", original, target, pt_est,
                              pt_se, False, halves.spp, pt_ms + trial_ms, pt_ms,
                              time.perf_counter() - start, trials, log, halves.spp, pt_ms,
                              denoise_setup_ms=setup_ms)
        total = next_pt_spp(halves.spp, pt_est, pt_se, target)
        aim = denoised_aim(judgements, denoised_upper, target)
        if aim < total:   # the denoised candidate is expected to pass sooner
            total = round_samples(aim, halves.spp)
        batch = max(1, (total - halves.spp) // 2)
        round_ += 1
