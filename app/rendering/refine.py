"""The viewer's `refine` mode (app/viewer/session.py): `guided` accumulated as two independent
halves, their combined mean shown, and its error estimated from the two halves alone.

The estimator (NumPy: `half_buffer_error`; GPU: glsl/refine_halves.comp, which gives the same
three sums for `error_from_sums`):

Let a and b be the two halves' per-pixel means over n_a and n_b independent samples of an
unbiased estimator with per-pixel mean t and variance s^2 (each channel a value; `guided` is
unbiased, so noise is its whole error). The image shown is m = (n_a a + n_b b) / (n_a + n_b), so
Var(m) = s^2 / (n_a + n_b). The halves are independent with the same mean, so

    E[(a - b)^2] = Var(a) + Var(b) = s^2 (1/n_a + 1/n_b) = s^2 (n_a + n_b) / (n_a n_b)

and Var(m) = w E[(a - b)^2] with w = n_a n_b / (n_a + n_b)^2 (1/4 when n_a = n_b). Averaged over
pixels, N^2 = w mean((a - b)^2) estimates mean(Var(m)) = E[mean((m - t)^2)], the square of the
numerator of the relative RMSE (app/bench/metrics.rrmse). Its denominator is mean(t^2); since
E[m^2] = t^2 + Var(m), T^2 = mean(m^2) - N^2 estimates it without the upward bias mean(m^2) has
at few samples. The estimate is sqrt(N^2 / T^2): with n_a = n_b and the noise small, the brief's
sqrt(mean((a - b)^2)) / (2 sqrt(mean(((a + b) / 2)^2))).

The raymarcher's image r (biased, and independent of the halves) is judged against the same
unbiased m: E[mean((r - m)^2)] = mean((r - t)^2) + mean(Var(m)), so its relative error is
sqrt((mean((r - m)^2) - N^2) / T^2). `refine` shows the halves' mean once its estimated error is
below that (app/viewer/session.py).

The sums are reduced on the GPU (a workgroup's in shared memory, then one workgroup over the
partials) and 16 bytes read back, only at the checks the session schedules (REFINE_CHECK_FRAMES):
the combine itself runs every frame with no read-back.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import moderngl
import numpy as np

from ..gl.shaders import compute_program, set_uniforms
from ..methods import METHODS
from .accumulation import Accumulation, SumAccumulation
from .denoise import choose_guides, shared_denoiser

GROUP_SIDE = 16
# The raymarcher's frames refine accumulates at most (its image is then as good as its bias lets
# it be; the rest goes to `guided`); the guided samples each half needs before its estimate may
# replace the raymarcher's image; the seed offset of the second half. The viewer's session and a
# still image (render_refine) share them.
REFINE_RAYMARCH_FRAMES = 16
REFINE_MIN_HALF_SAMPLES = 4
REFINE_HALF_SEED = 0x68E31DA4


@dataclass(frozen=True)
class RefineEstimate:
    """Estimated relative RMSEs against the exact image: the halves' mean (`guided`) and the
    raymarcher's (NaN where not measured), and the guided samples they were measured at."""
    guided: float
    raymarch: float
    samples: int


def weight(n_a: int, n_b: int) -> float:
    """w = n_a n_b / (n_a + n_b)^2: Var(m) = w E[(a - b)^2] (0 while a half is empty)."""
    n = n_a + n_b
    return n_a * n_b / (n * n) if n_a > 0 and n_b > 0 else 0.0


def half_buffer_sums(a: np.ndarray, b: np.ndarray, n_a: int, n_b: int,
                     raymarched: np.ndarray | None = None) -> tuple[float, float, float, int]:
    """The shader's sums (float64): sum (a - b)^2, sum m^2, sum (r - m)^2 (0 without r), and the
    count of values (pixels times channels)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    m = (n_a * a + n_b * b) / max(n_a + n_b, 1)
    ray = 0.0 if raymarched is None else float(np.sum((np.asarray(raymarched, np.float64) - m) ** 2))
    return float(np.sum((a - b) ** 2)), float(np.sum(m * m)), ray, a.size


def error_from_sums(sums, n_a: int, n_b: int, samples: int = 0,
                    with_raymarch: bool = True) -> RefineEstimate:
    """The estimates of the module's docstring from the three sums and the count of values."""
    diff, mean_sq, ray, count = sums
    w = weight(n_a, n_b)
    if w <= 0.0 or count <= 0:
        return RefineEstimate(float("nan"), float("nan"), samples)
    noise2 = w * diff / count
    signal2 = mean_sq / count - noise2
    if not signal2 > 0.0:
        return RefineEstimate(float("nan"), float("nan"), samples)
    guided = math.sqrt(noise2 / signal2)
    raymarch = (math.sqrt(max(ray / count - noise2, 0.0) / signal2) if with_raymarch
                else float("nan"))
    return RefineEstimate(guided, raymarch, samples)


def half_buffer_error(a: np.ndarray, b: np.ndarray, n_a: int = 1, n_b: int = 1,
                      raymarched: np.ndarray | None = None) -> RefineEstimate:
    """The estimated relative RMSE of the halves' mean (and of `raymarched`, when given)."""
    return error_from_sums(half_buffer_sums(a, b, n_a, n_b, raymarched), n_a, n_b,
                           n_a + n_b, raymarched is not None)


def _mean_square(x: np.ndarray) -> float:
    """mean(x^2) of a float32 array through one BLAS dot (float32 products and sums, the partial
    sums blocked: a relative error near 1e-6 at a 1080p image's 6 million values), not a float64
    copy: at 1080p that copy made the estimate 0.4 s on a 2-core machine."""
    flat = np.ascontiguousarray(x, np.float32).ravel()
    return float(np.dot(flat, flat)) / max(flat.size, 1)


def denoised_half_error(denoised_a: np.ndarray, a: np.ndarray, b: np.ndarray, n_a: int,
                        n_b: int) -> float:
    """The estimated relative RMSE of half a's image through the denoiser (`denoised_a`, a
    function of half a alone), judged against the independent half b: E[mean((D(a) - b)^2)] =
    mean((D(a) - t)^2) + mean(Var(b)), and mean(Var(b)) = s^2 / n_b = n_a / (n_a + n_b) times
    E[mean((a - b)^2)]; the denominator T^2 as error_from_sums makes it. The image shown, the
    denoised mean of both halves, holds more samples than half a, so this errs high. NaN where
    a half is empty or the signal is not positive. float32 arithmetic (_mean_square)."""
    w = weight(n_a, n_b)
    if w <= 0.0:
        return float("nan")
    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    diff2 = _mean_square(a - b)
    m = a * np.float32(n_a / (n_a + n_b))
    m += b * np.float32(n_b / (n_a + n_b))
    signal2 = _mean_square(m) - w * diff2
    if not signal2 > 0.0:
        return float("nan")
    error2 = _mean_square(np.asarray(denoised_a, np.float32) - b) - n_a / (n_a + n_b) * diff2
    return math.sqrt(max(error2, 0.0) / signal2)


def denoised_halves_error(renderer, halves: "HalfBuffers", camera,
                          guides: str = "auto") -> float:
    """Half a read back and put through the denoiser with the guides (`guides`, "auto": as
    choose_guides picks) a denoised image of `camera` gets, its error estimated against half b
    (denoised_half_error); NaN where the filter cannot run. refine's judgement of guided
    denoised, in the viewer (app/viewer/session.py) and for a still image (render_refine)."""
    n_a, n_b = halves.counts
    a, b = halves.halves[0].read(), halves.halves[1].read()
    names = choose_guides(guides, n_a, renderer.probes_shown())
    albedo, normal, _ = renderer.denoise_guides(names, camera=camera)
    d = shared_denoiser()(a, albedo, normal, signed=METHODS["guided"].signed)
    return denoised_half_error(d.image, a, b, n_a, n_b) if d.denoised else float("nan")


class HalfBuffers:
    """Two independent `guided` accumulations (each a SumAccumulation: level 1 and level 0) and
    the image shown, their count-weighted mean (an Accumulation: rgb the mean, alpha the count),
    combined on the GPU."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int):
        self.ctx = ctx
        self.width, self.height = width, height
        self.halves = [SumAccumulation(Accumulation(ctx, width, height),
                                       Accumulation(ctx, width, height)) for _ in range(2)]
        self.combined = Accumulation(ctx, width, height)
        self.groups = ((width + GROUP_SIDE - 1) // GROUP_SIDE, (height + GROUP_SIDE - 1) // GROUP_SIDE)
        self.partials = ctx.buffer(reserve=16 * self.groups[0] * self.groups[1])
        self.sums = ctx.buffer(reserve=16)
        self._combine = compute_program(ctx, "refine_halves.comp", {"STAGE": 1})
        self._reduce = compute_program(ctx, "refine_halves.comp", {"STAGE": 2})
        self.reads = 0            # read-backs since the last reset (a test counts them)

    @property
    def counts(self) -> tuple[int, int]:
        return self.halves[0].samples, self.halves[1].samples

    @property
    def samples(self) -> int:
        return sum(self.counts)

    def reset(self) -> None:
        for half in self.halves:
            half.residual.reset()
            half.level0.reset()
        self.combined.reset()
        self.reads = 0   # counted per restart, as the session's frames are

    def next_half(self) -> int:
        """The half the next batch of samples goes to: the one with fewer (A on a tie)."""
        a, b = self.counts
        return 0 if a <= b else 1

    def combine(self, raymarched: Accumulation | None = None, reduce: bool = False) -> None:
        """Writes the halves' mean into `combined` (no host transfer); with `reduce`, also the
        estimator's sums into a 16-byte buffer that `read_estimate` reads."""
        n_a, n_b = self.counts
        total = n_a + n_b
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        units = [self.halves[0].residual, self.halves[0].level0, self.halves[1].residual,
                 self.halves[1].level0, raymarched or self.halves[0].residual]
        for unit, acc in enumerate(units):
            acc.texture.bind_to_image(unit, read=True, write=False)
        self.combined.texture.bind_to_image(5, read=False, write=True)
        self.partials.bind_to_storage_buffer(0)
        self.sums.bind_to_storage_buffer(1)
        set_uniforms(self._combine, {"weight_a": n_a / total if total else 0.5,
                                     "total_samples": float(total), "reduce": int(reduce),
                                     "have_raymarch": int(raymarched is not None)})
        self._combine.run(*self.groups)
        self.combined.samples = total
        if reduce:
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            set_uniforms(self._reduce, {"partial_count": self.groups[0] * self.groups[1]})
            self._reduce.run(1, 1)
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

    def read_sums(self) -> tuple[float, float, float, int]:
        """The last reduction's sums (a 16-byte read-back) and the count of values."""
        self.reads += 1
        x, y, z, _ = struct.unpack("4f", self.sums.read())
        return x, y, z, 3 * self.width * self.height

    def read_estimate(self, with_raymarch: bool) -> RefineEstimate:
        n_a, n_b = self.counts
        return error_from_sums(self.read_sums(), n_a, n_b, n_a + n_b, with_raymarch)

    def release(self) -> None:
        for half in self.halves:
            half.release()
        self.combined.release()
        for obj in (self.partials, self.sums, self._combine, self._reduce):
            obj.release()


@dataclass
class RefineImage:
    """A still image of `refine` (render_refine): the image shown, which method it is ("raymarch"
    or "guided"), the estimate that chose it, and GPU ms of each part."""
    image: np.ndarray
    shown: str
    estimate: RefineEstimate
    raymarch_ms: float
    guided_ms: float
    denoised_estimate: float = float("nan")   # guided denoised's, where `denoised` was asked


def render_refine(renderer, spp: int, seed: int, width: int | None = None,
                  height: int | None = None, denoise_guides: str | None = None) -> RefineImage:
    """`refine` as a still image, as the viewer's view ends once the samples are spent: the
    raymarcher's image (min(spp, REFINE_RAYMARCH_FRAMES) frames) and `spp` samples of `guided` in
    two independent halves; the halves' mean is shown where its estimated error is below the
    raymarcher's (each half with at least REFINE_MIN_HALF_SAMPLES), else the raymarcher's image.
    `denoise_guides` (the image will be denoised with these guides; as the viewer's Denoise
    switch): where the raw estimate does not pass, guided is shown if denoised_halves_error
    passes. The probes and the light grid must be in hand (Renderer.render bakes them)."""
    r = renderer
    ray = halves = None
    try:
        with r.lend(None) as lent:   # an accumulation of its own, released here
            ray = lent.begin("raymarch", width, height, seed)
            camera = lent.camera
            raymarch_ms = lent.add_samples(min(spp, REFINE_RAYMARCH_FRAMES))
        halves = HalfBuffers(r.ctx, camera.width, camera.height)
        halves.reset()
        guided_ms = 0.0
        for index, n in ((0, (spp + 1) // 2), (1, spp // 2)):
            if n:
                half = halves.halves[index]
                with r.lend(half.residual, "guided", camera, seed ^ (REFINE_HALF_SEED if index else 0),
                            level0=half.level0, slot=index) as lent:
                    guided_ms += lent.add_samples(n)
        halves.combine(ray, reduce=True)
        estimate = halves.read_estimate(with_raymarch=True)
        enough = min(halves.counts) >= REFINE_MIN_HALF_SAMPLES
        guided = enough and estimate.guided < estimate.raymarch   # (False while either is NaN)
        judged = float("nan")
        if enough and not guided and denoise_guides is not None:
            judged = denoised_halves_error(r, halves, camera, denoise_guides)
            guided = judged < estimate.raymarch
        image = (halves.combined if guided else ray).read()
        return RefineImage(image, "guided" if guided else "raymarch", estimate, raymarch_ms,
                           guided_ms, judged)
    finally:
        if ray is not None:
            ray.release()
        if halves is not None:
            halves.release()
