"""The viewer's Denoise switch: each shown view of a noisy method (the path tracer, `probes`,
`probes-only`, and `refine` once `guided` shows) through the denoiser (app/rendering/denoise/filter.py),
with the guides Renderer.denoise_guides makes for the view's camera ("auto": the probes' image
where the view has probes, else the albedo and normal at few samples).

The filter runs on the newest accumulated image, not every frame: whenever the samples have
doubled since the last filtered image (1, 2, 4, ...), and at least every INTERVAL_S while they
grow. A view shows its raw image until its first filtered one, and again after any restart until
the next. On the H200 a 1080p filter with its read-back and upload costs about 25 ms
(bench/h200-denoise), so the doubling keeps its share of a 14 ms frame small after the first
second. OIDN has no temporal mode: the filtered images of a still camera change as samples come
(docs/denoising.md measures the flicker).

The accumulation is read straight into the filter's colour, its tile means made on the GPU
(app/rendering/denoise/kept_means.py), and the filter's output uploaded and given back those means by two
GL passes into the RGBA32F texture the display shows: the host neither sums the images nor
checks the output (kept_means.denoise_on_gl).

A `refine` view blending guided with the raymarcher's image (RefineView.blending: the weight its
last judgement gave, app/rendering/refine/refine.py) shows (1 - w) r + w D, made on the GPU
(refine.BlendPass) whenever D, r or w has changed."""
from __future__ import annotations

import time
from dataclasses import dataclass

import moderngl

from radiance_probes.methods import METHODS
from radiance_probes.rendering.denoise.filter import choose_guides, shared_denoiser
from radiance_probes.rendering.denoise.kept_means import KeptMeans, denoise_on_gl
from radiance_probes.rendering.refine.refine import BlendPass

INTERVAL_S = 0.5


@dataclass
class _Filtered:
    texture: object
    generation: tuple      # (the accumulation's id, the session's restarts) it was made from
    samples: int           # samples of the image it filtered
    at: float              # when (monotonic seconds)
    blended: object = None   # refine's blend with the raymarcher's image, and what it was made of
    blend_key: tuple | None = None


class ViewDenoise:
    def __init__(self, ctx: moderngl.Context, enabled: bool):
        self.ctx = ctx
        self.enabled = enabled
        self.images: dict[str, _Filtered] = {}
        self.note: str | None = None     # why it switched itself off (the library, the filter)
        self.last_ms = 0.0               # wall ms of the last update's filtering
        self.runs = 0                    # filtered images made (tests, the Stats panel)
        self.kept_means: KeptMeans | None = None   # the tile means' passes, made on first use
        # compiled with the session where the switch starts on, not at a view's first blend
        self.blend_pass: BlendPass | None = BlendPass(ctx) if enabled else None

    def kept(self) -> KeptMeans:
        """The tile means' passes (refine's judgement filters through them too)."""
        if self.kept_means is None:
            self.kept_means = KeptMeans(self.ctx)
        return self.kept_means

    def set_enabled(self, on: bool) -> None:
        self.enabled = bool(on)
        if on:
            self.note = None

    def _due(self, name: str, generation: tuple, samples: int, now: float) -> bool:
        old = self.images.get(name)
        if old is None or old.generation != generation:
            return samples > 0
        return samples >= 2 * old.samples or (samples > old.samples and now - old.at >= INTERVAL_S)

    def update(self, session) -> float:
        """Filters each view that is due; returns the wall ms it took."""
        self.last_ms = 0.0
        if not self.enabled:
            return 0.0
        start = time.perf_counter()
        r = session.renderer
        denoiser = shared_denoiser()
        for name, view in session.views.items():
            acc, shown = view.acc, view.shown
            generation = (id(acc), session.restarts)
            if acc is None or not METHODS[shown].noisy or acc.samples == 0:
                self._forget(name)
                continue
            now = time.monotonic()
            if not self._due(name, generation, acc.samples, now):
                continue
            has_probes = session.needs_probes(name) and r.probes_current()
            guides = choose_guides("auto", acc.samples, has_probes)
            albedo, normal, _ = r.denoise_guides(guides, camera=view.camera)
            names = tuple(n for n, g in (("albedo", albedo), ("normal", normal)) if g is not None)
            staged = denoiser.staging(acc.width, acc.height, names)
            if staged is None:
                self.note, self.enabled = denoiser.failure, False
                self.release()
                break
            old = self.images.get(name)
            texture = self._sized(None if old is None else old.texture, acc.texture)
            d = denoise_on_gl(self.kept(), denoiser, acc.texture, staged, albedo, normal,
                              METHODS[shown].signed, texture, finish=False)
            if not d.denoised:
                texture.release()
                self.note, self.enabled = d.note, False
                self.release()
                break
            blended = old.blended if old is not None else None
            self.images[name] = _Filtered(texture, generation, acc.samples, now, blended)
            self.runs += 1
        if self.enabled:
            self._blend(session)
        self.last_ms = 1e3 * (time.perf_counter() - start)
        return self.last_ms

    def adopt(self, name: str, halves, restarts: int) -> None:
        """refine's judgement filtered half A (refine.judged_blend): that image becomes the view's
        filtered image (a GPU copy), counted as of the halves' whole sample count, so the view is
        filtered again at the next doubling (or INTERVAL_S), not a second time in this frame."""
        combined = halves.combined
        old = self.images.get(name)
        texture = self._sized(None if old is None else old.texture, combined.texture)
        halves.copy_denoised_a(texture)
        blended = old.blended if old is not None else None
        self.images[name] = _Filtered(texture, (id(combined), restarts), combined.samples,
                                      time.monotonic(), blended)

    def _sized(self, texture, like):
        """`texture`, or where it is missing or not of `like`'s size (it is then released) a new
        RGBA32F texture of that size and filter: the restore and blend passes store into it, the
        display reads rgb."""
        if texture is not None and texture.size == like.size:
            return texture
        if texture is not None:
            texture.release()
        texture = self.ctx.texture(like.size, 4, dtype="f4")
        texture.filter = like.filter
        return texture

    def _forget(self, name: str) -> None:
        got = self.images.pop(name, None)
        if got is not None:
            got.texture.release()
            if got.blended is not None:
                got.blended.release()

    def _blend(self, session) -> None:
        """Each blending refine view's (1 - w) r + w D, where its inputs have changed."""
        for name, view in session.views.items():
            got = self.images.get(name)
            if not getattr(view, "blending", False) or got is None:
                continue
            if got.generation != (id(view.acc), session.restarts):
                continue
            key = (got.samples, got.at, view.weight, view.ray.samples)
            if got.blend_key == key:
                continue
            got.blended = self._sized(got.blended, got.texture)
            if self.blend_pass is None:
                self.blend_pass = BlendPass(self.ctx)
            self.blend_pass.run(view.ray.texture, got.texture, got.blended, view.weight)
            got.blend_key = key

    def texture(self, name: str, view, restarts: int):
        """The view's filtered image, where one of its current accumulation exists."""
        if not self.enabled or view is None or view.acc is None:
            return None
        got = self.images.get(name)
        if got is None or got.generation != (id(view.acc), restarts):
            return None
        if getattr(view, "blending", False):
            return got.blended if got.blend_key is not None else None
        return got.texture

    def release(self) -> None:
        for name in list(self.images):
            self._forget(name)
        if self.blend_pass is not None:
            self.blend_pass.release()
            self.blend_pass = None
        if self.kept_means is not None:
            self.kept_means.release()
            self.kept_means = None
