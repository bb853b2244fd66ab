"""The viewer's `refine` mode (app/viewer/frame/session.py): `guided` accumulated as two independent
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
below that (app/viewer/frame/session.py).

The sums are reduced on the GPU (a workgroup's in shared memory, then one workgroup over the
partials) and 16 bytes read back, only at the checks the session schedules (REFINE_CHECK_FRAMES):
the combine itself runs every frame with no read-back.

The blend (the Denoise switch on: the view then shows guided denoised, D(m), not m). The
raymarcher's image r is biased but clean, D(m) noisy and blurred but unbiased in the limit, and
their errors are nearly independent (on bonsai at 128^2 their correlation was -0.02 to 0.09:
lab/experiments/refine_blend.py), so a blend (1 - w) r + w D beats either while they are of one
size. The error of the blend is |(1 - w)(r - t) + w (D - t)|^2, whose minimum over w is at
w* = <r - t, r - D> / |r - D|^2. Half A denoised, D(a), is independent of half b, and so is r, so
E[<r - b, r - D(a)>] = <r - t, r - D(a)> (b's noise has mean 0): the weight comes from the halves
alone as w = sum (r - b) . (r - D(a)) / sum (r - D(a))^2, clamped to [0, 1] (`blend_from_sums`;
each term: glsl/refine_halves.comp STAGE 3, twin `judge_sums`). D(m) holds twice D(a)'s samples,
so w errs towards the raymarcher (0.37 against the best 0.48 at 16 samples there, the blend 6.3%
against the best 6.2%, the raymarcher 8.5%, D(m) 8.9%). Each error is estimated as
against half b: E[mean((X - b)^2)] = mean((X - t)^2) + mean(Var(b)).
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.rendering.image_ops import clear_image, copy_image
from radiance_probes.methods import METHODS
from radiance_probes.rendering.methods.accumulation import Accumulation, SumAccumulation
from radiance_probes.rendering.denoise.filter import choose_guides, shared_denoiser
from radiance_probes.rendering.denoise.kept_means import KeptMeans, denoise_on_gl
from radiance_probes.rendering.methods.pathtracer import groups

GROUP_SIDE = 16
# The raymarcher's frames refine accumulates at most (its image is then as good as its bias lets
# it be; the rest goes to `guided`); the guided samples each half needs before its estimate may
# replace the raymarcher's image; the seed offset of the second half. The viewer's session and a
# still image (render_refine) share them.
REFINE_RAYMARCH_FRAMES = 16
REFINE_MIN_HALF_SAMPLES = 4
REFINE_HALF_SEED = 0x68E31DA4
# A blend weight within this of 0 or 1 is taken as 0 (the raymarcher alone) or 1 (guided alone):
# 2% of a 2% error is below what the estimate resolves.
BLEND_SNAP = 0.02


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


@dataclass(frozen=True)
class RefineBlend:
    """refine's blend judged from the halves (blend_from_sums): the weight w of guided denoised
    in (1 - w) r + w D (snapped to 0 or 1 within BLEND_SNAP), and the estimated relative RMSEs of
    the blend (of a weight chosen on the same halves: it errs low where their noise dominates,
    15% at noise twice the signal in tests/test_refine.py), of half A denoised (D(m)'s errs high)
    and of the raymarcher (against half b)."""
    weight: float
    blend: float
    denoised: float
    raymarch: float


def judge_sums(denoised_a: np.ndarray, b: np.ndarray,
               raymarched: np.ndarray) -> tuple[float, float, float, int]:
    """The judgement's sums (glsl/refine_halves.comp STAGE 3; float64): sum (D - b)^2,
    sum (r - b)^2, sum (r - b) . (D - b), and the count of values."""
    b = np.asarray(b, np.float64)
    d = np.asarray(denoised_a, np.float64) - b
    e = np.asarray(raymarched, np.float64) - b
    return float(np.sum(d * d)), float(np.sum(e * e)), float(np.sum(e * d)), b.size


def blend_from_sums(sums, judged, n_a: int, n_b: int) -> RefineBlend:
    """The blend's weight and estimates (the module's docstring) from the check's sums
    (half_buffer_sums: sum (a - b)^2, sum m^2, ...) and the judgement's (judge_sums). NaN
    estimates and weight 0 where a half is empty or the signal is not positive."""
    diff, mean_sq, _, count = sums
    dd, rr, rd, _ = judged
    nan = float("nan")
    w_m = weight(n_a, n_b)
    if w_m <= 0.0 or count <= 0:
        return RefineBlend(0.0, nan, nan, nan)
    signal2 = mean_sq / count - w_m * diff / count
    if not signal2 > 0.0:
        return RefineBlend(0.0, nan, nan, nan)
    noise_b = n_a / (n_a + n_b) * diff / count          # mean(Var(b))
    e_dd, e_rr, e_rd = dd / count - noise_b, rr / count - noise_b, rd / count - noise_b
    apart = (rr + dd - 2.0 * rd) / count                # mean((r - D)^2): no noise term
    w = (rr - rd) / count / apart if apart > 0.0 else (1.0 if e_dd <= e_rr else 0.0)
    w = min(max(w, 0.0), 1.0)
    w = 0.0 if w < BLEND_SNAP else 1.0 if w > 1.0 - BLEND_SNAP else w
    blend2 = (1.0 - w) ** 2 * e_rr + w * w * e_dd + 2.0 * w * (1.0 - w) * e_rd

    def rel(x: float) -> float:
        return math.sqrt(max(x, 0.0) / signal2)
    return RefineBlend(w, rel(blend2), rel(e_dd), rel(e_rr))


def blend_images(raymarched: np.ndarray, denoised: np.ndarray, w: float) -> np.ndarray:
    """(1 - w) r + w D (glsl/refine_blend.comp's twin)."""
    return (1.0 - w) * np.asarray(raymarched, np.float32) + w * np.asarray(denoised, np.float32)


class BlendPass:
    """glsl/refine_blend.comp: (1 - w) r + w D into a texture, on the GPU (the viewer's display of
    a blending refine view)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = compute_program(ctx, "refine_blend.comp")

    def run(self, raymarched: moderngl.Texture, denoised: moderngl.Texture,
            blended: moderngl.Texture, w: float) -> None:
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        raymarched.bind_to_image(0, read=True, write=False)
        denoised.bind_to_image(1, read=True, write=False)
        blended.bind_to_image(2, read=False, write=True)
        set_uniforms(self.program, {"weight": float(w)})
        width, height = blended.size
        self.program.run(*groups(width, height, (GROUP_SIDE, GROUP_SIDE)))
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

    def release(self) -> None:
        self.program.release()


def judged_blend(renderer, halves: "HalfBuffers", raymarched: Accumulation, camera,
                 kept: KeptMeans, guides: str = "auto",
                 sums: tuple[float, float, float, int] | None = None) -> RefineBlend | None:
    """refine's judgement on the GPU: the check's sums (a 16-byte read-back) and half A written
    alone, put through the denoiser with the guides (`guides`; "auto": as choose_guides
    picks) a denoised image of `camera` gets (kept_means.denoise_on_gl: the image stays on the
    GPU), judged with the raymarcher's image against half B (STAGE 3: 16 bytes more), and
    the blend of the module's docstring. `sums`: the check's own, where its combine
    (reduce and write_half_a, with `raymarched`) has just run, so neither is done again. None
    where the filter cannot run. The viewer (app/viewer/frame/session.py) and a still image
    (render_refine) both judge through this."""
    n_a, n_b = halves.counts
    if min(n_a, n_b) <= 0:
        return None
    if sums is None:
        halves.combine(raymarched, reduce=True, write_half_a=True)
        sums = halves.read_sums()
    names = choose_guides(guides, n_a, renderer.probes_shown())
    albedo, normal, _ = renderer.denoise_guides(names, camera=camera)
    denoiser = shared_denoiser()
    staged = denoiser.staging(halves.width, halves.height, names)
    if staged is None:
        return None
    d = denoise_on_gl(kept, denoiser, halves.half_a.texture, staged, albedo, normal,
                      METHODS["guided"].signed, halves.denoised_a, finish=False)
    if not d.denoised:
        return None
    return blend_from_sums(sums, halves.judge(raymarched), n_a, n_b)


def half_buffer_error(a: np.ndarray, b: np.ndarray, n_a: int = 1, n_b: int = 1,
                      raymarched: np.ndarray | None = None) -> RefineEstimate:
    """The estimated relative RMSE of the halves' mean (and of `raymarched`, when given)."""
    return error_from_sums(half_buffer_sums(a, b, n_a, n_b, raymarched), n_a, n_b,
                           n_a + n_b, raymarched is not None)


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
        # half A's image alone (combine(write_half_a=True) writes it, for the denoiser), half A
        # through the denoiser (RGBA32F, judged_blend's) and half B's snapshot: made with the
        # view and cleared, so that the driver gives them memory now (made at the first
        # judgement, they cost that frame 36-45 ms of host work on the H200 at 1080p: issue 56)
        self.half_a = Accumulation(ctx, width, height)
        self.half_a.reset()
        self.denoised_a = ctx.texture((width, height), 4, dtype="f4")
        clear_image(self.denoised_a)
        self.groups = groups(width, height, (GROUP_SIDE, GROUP_SIDE))
        self.partials = ctx.buffer(reserve=16 * self.groups[0] * self.groups[1])
        self.sums = ctx.buffer(reserve=16)
        self._combine = compute_program(ctx, "refine_halves.comp", {"STAGE": 1})
        self._reduce = compute_program(ctx, "refine_halves.comp", {"STAGE": 2})
        # compiled with the view, not at its first judgement (which follows an edit)
        self._judge = compute_program(ctx, "refine_halves.comp", {"STAGE": 3})
        self.judge_sums = ctx.buffer(reserve=16)
        self.reads = 0            # read-backs since the last reset (a test counts them)
        self.reduced_counts: tuple[int, int] | None = None   # the counts the last sums are of
        # half B as it was at a judgement's check (snapshot_b), judged against on a later frame
        self._b_snapshot = [Accumulation(self.ctx, self.width, self.height) for _ in range(2)]
        for a in self._b_snapshot:
            a.reset()

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
        self.reduced_counts = None

    def next_half(self) -> int:
        """The half the next batch of samples goes to: the one with fewer (A on a tie)."""
        a, b = self.counts
        return 0 if a <= b else 1

    def copy_denoised_a(self, texture: moderngl.Texture) -> None:
        """`denoised_a` copied into `texture` (RGBA32F of its size) on the GPU."""
        copy_image(self.denoised_a, texture)

    def combine(self, raymarched: Accumulation | None = None, reduce: bool = False,
                write_half_a: bool = False) -> None:
        """Writes the halves' mean into `combined` (no host transfer); with `reduce`, also the
        estimator's sums into a 16-byte buffer that `read_sums` reads; with `write_half_a`,
        half A's image alone into `half_a`."""
        n_a, n_b = self.counts
        total = n_a + n_b
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        units = [self.halves[0].residual, self.halves[0].level0, self.halves[1].residual,
                 self.halves[1].level0, raymarched or self.halves[0].residual]
        for unit, acc in enumerate(units):
            acc.texture.bind_to_image(unit, read=True, write=False)
        self.combined.texture.bind_to_image(5, read=False, write=True)
        (self.half_a if write_half_a else self.combined).texture.bind_to_image(6, read=False,
                                                                              write=True)
        self.partials.bind_to_storage_buffer(0)
        self.sums.bind_to_storage_buffer(1)
        set_uniforms(self._combine, {"weight_a": n_a / total if total else 0.5,
                                     "total_samples": float(total), "reduce": int(reduce),
                                     "have_raymarch": int(raymarched is not None),
                                     "write_half_a": int(write_half_a), "samples_a": float(n_a)})
        self._combine.run(*self.groups)
        self.combined.samples = total
        if write_half_a:
            self.half_a.samples = n_a
        if reduce:
            self._reduce_partials(self.sums)
            self.reduced_counts = (n_a, n_b)
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

    def snapshot_b(self) -> None:
        """Half B's two levels copied on the GPU as they are now: a judgement begun at this
        check judges against them (dispatch_judge(from_snapshot=True)) on whichever later frame
        its filtered half A comes back, while half B grows on."""
        for target, source in zip(self._b_snapshot, (self.halves[1].residual,
                                                     self.halves[1].level0)):
            copy_image(source.texture, target.texture)

    def dispatch_judge(self, raymarched: Accumulation, from_snapshot: bool = False) -> None:
        """STAGE 3 and its reduction into `judge_sums` (read it with a read-back of that buffer):
        `denoised_a` and the raymarcher's image against half B (`from_snapshot`: half B as
        snapshot_b copied it)."""
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        b = self._b_snapshot if from_snapshot else (self.halves[1].residual,
                                                    self.halves[1].level0)
        b[0].texture.bind_to_image(2, read=True, write=False)
        b[1].texture.bind_to_image(3, read=True, write=False)
        raymarched.texture.bind_to_image(4, read=True, write=False)
        self.denoised_a.bind_to_image(6, read=True, write=False)
        self.partials.bind_to_storage_buffer(0)
        self._judge.run(*self.groups)
        self._reduce_partials(self.judge_sums)
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

    def _reduce_partials(self, into: moderngl.Buffer) -> None:
        """STAGE 2: the workgroups' partial sums (STAGE 1's or 3's) added into `into`."""
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        into.bind_to_storage_buffer(1)
        set_uniforms(self._reduce, {"partial_count": self.groups[0] * self.groups[1]})
        self._reduce.run(1, 1)

    def _read(self, sums: moderngl.Buffer) -> tuple[float, float, float, int]:
        """A reduction's three sums (a 16-byte read-back) and the count of values."""
        self.reads += 1
        x, y, z, _ = struct.unpack("4f", sums.read())
        return x, y, z, 3 * self.width * self.height

    def read_sums(self) -> tuple[float, float, float, int]:
        """The last reduction's sums (a 16-byte read-back) and the count of values."""
        return self._read(self.sums)

    def judge(self, raymarched: Accumulation) -> tuple[float, float, float, int]:
        """judge_sums on the GPU: `denoised_a` (half A filtered) and the raymarcher's image
        against half B, reduced to 16 bytes and read back."""
        self.dispatch_judge(raymarched)
        return self._read(self.judge_sums)

    def sums_of(self, values) -> tuple[float, float, float, int]:
        """A reduction's sums from its 16 bytes read back on a later frame (a read-back of
        `sums` or `judge_sums`), with the count of values."""
        self.reads += 1
        x, y, z = (float(v) for v in list(values)[:3])
        return x, y, z, 3 * self.width * self.height

    def estimate_from(self, sums: tuple[float, float, float, int],
                      with_raymarch: bool) -> RefineEstimate:
        """The halves' error estimate from their reduction's sums (read_sums), at the counts the
        sums were reduced at."""
        n_a, n_b = self.reduced_counts or self.counts
        return error_from_sums(sums, n_a, n_b, n_a + n_b, with_raymarch)

    def release(self) -> None:
        for half in self.halves:
            half.release()
        self.combined.release()
        for obj in (self.half_a, self.denoised_a, self._judge, self.partials, self.sums,
                    self.judge_sums, self._combine, self._reduce, *self._b_snapshot):
            obj.release()


@dataclass
class RefineImage:
    """A still image of `refine` (render_refine): the image of the method shown ("raymarch" or
    "guided"), the estimate that chose it, and GPU ms of each part. Where a judgement ran (the
    image to be denoised), `blend` holds it; where guided is shown and w = blend.weight < 1,
    `raymarch_image` holds the raymarcher's image and the image to show is
    (1 - w) raymarch_image + w denoise(image)."""
    image: np.ndarray
    shown: str
    estimate: RefineEstimate
    raymarch_ms: float
    guided_ms: float
    blend: RefineBlend | None = None
    raymarch_image: np.ndarray | None = None


def render_refine(renderer, spp: int, seed: int, width: int | None = None,
                  height: int | None = None, denoise_guides: str | None = None) -> RefineImage:
    """`refine` as a still image, as the viewer's view ends once the samples are spent: the
    raymarcher's image (min(spp, REFINE_RAYMARCH_FRAMES) frames) and `spp` samples of `guided` in
    two independent halves; the halves' mean is shown where its estimated error is below the
    raymarcher's (each half with at least REFINE_MIN_HALF_SAMPLES), else the raymarcher's image.
    `denoise_guides` (the image will be denoised with these guides; as the viewer's Denoise
    switch): the halves are judged (judged_blend) and guided is shown, blended with the
    raymarcher's image, wherever its weight is above 0. The probes and the light grid must be in
    hand (Renderer.render bakes them)."""
    r = renderer
    ray = halves = kept = None
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
        enough = min(halves.counts) >= REFINE_MIN_HALF_SAMPLES
        judge = enough and denoise_guides is not None
        halves.combine(ray, reduce=True, write_half_a=judge)   # half A too where it is judged
        sums = halves.read_sums()
        estimate = halves.estimate_from(sums, with_raymarch=True)
        guided = enough and estimate.guided < estimate.raymarch   # (False while either is NaN)
        blend = None
        if judge:
            kept = KeptMeans(r.ctx)
            blend = judged_blend(r, halves, ray, camera, kept, denoise_guides, sums)
            if blend is not None:
                guided = blend.weight > 0.0
        image = (halves.combined if guided else ray).read()
        mixed = guided and blend is not None and blend.weight < 1.0   # r in the image shown
        return RefineImage(image, "guided" if guided else "raymarch", estimate, raymarch_ms,
                           guided_ms, blend, ray.read() if mixed else None)
    finally:
        if kept is not None:
            kept.release()
        if ray is not None:
            ray.release()
        if halves is not None:
            halves.release()
