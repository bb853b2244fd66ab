"""A still image from the Renderer: `render` of any method (composites such as `refine` too), with
the denoiser and its guides where asked, and the RenderResult it returns. A mixin of Renderer
(app/rendering/renderer.py)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from radiance_probes.methods import METHODS as REGISTRY, method as registered
from radiance_probes.twins.camera import camera_frame
from radiance_probes.rendering.methods.accumulation import Accumulation
from radiance_probes.rendering.grids.area_light_grid import AREA_GRID_METHODS
from radiance_probes.rendering.denoise.filter import (GUIDE_SETS, Denoised, choose_guides,
                                                      radiance_as_albedo, sanitize, shared_denoiser)
from radiance_probes.rendering.denoise.guides import GUIDE_FRAMES, DenoiseGuides
from radiance_probes.rendering.denoise.kept_means import KeptMeans, denoise_on_gl
from radiance_probes.rendering.refine.refine import blend_images, render_refine


@dataclass
class RenderResult:
    image: np.ndarray          # linear RGB float32 (H, W, 3)
    method: str
    spp: int
    render_ms: float           # GPU time of the render passes (timestamp queries)
    bake_ms: float = 0.0       # GPU time of probe baking, where the method has one
    stats: dict = field(default_factory=dict)
    # With denoise: the raw image, what the denoiser did (Denoised: device, note, ms of its parts)
    # and the guides' GPU ms (their passes, counted apart from render_ms)
    raw_image: np.ndarray | None = None
    denoised: Denoised | None = None
    guides_ms: float = 0.0

    @property
    def ms_per_sample(self) -> float:
        return self.render_ms / max(self.spp, 1)


class StillImages:
    """The Renderer's still images: render, the composites, the denoiser and its guides."""

    def render(self, method: str = "pt", spp: int = 64, seed: int = 0,
               width: int | None = None, height: int | None = None, samples_per_pass: int = 1,
               progress: Callable[[int, int], None] | None = None,
               bake_progress: Callable | None = None, denoise: bool = False,
               denoise_guides: str = "auto") -> RenderResult:
        """Renders the current scene from scratch with `spp` samples per pixel; with `denoise`,
        the image goes through the denoiser with `denoise_guides` (RenderResult.raw_image keeps
        the raw one; .denoised says what ran, or why not; "auto": denoise.choose_guides). A
        streamed mix
        of levels (LabOptions.mixed_levels under a cap) is first made the one this camera
        and image size deserve (restream, all of it)."""
        if self.resources.stream is not None:
            cam = self.scene.camera
            self.restream(replace(cam, width=width or cam.width, height=height or cam.height))
        if registered(method).composite:
            return self._render_composite(method, spp, seed, width, height, bake_progress,
                                          denoise, denoise_guides)
        acc = self.begin(method, width, height, seed)
        bake_ms = 0.0
        if self.needs_probes(method):
            bake_ms = self.bake(seed, progress=bake_progress)
        if self.needs_light(method):
            bake_ms += self.bake_light()
        if method == "raymarch":
            bake_ms += self.bake_gradient_grid()
        if method in AREA_GRID_METHODS:
            bake_ms += self.bake_area_light_grid()
        render_ms = 0.0
        chunk = max(samples_per_pass, 1)
        while acc.samples < spp:
            render_ms += self.add_samples(min(chunk, spp - acc.samples))
            if progress is not None:
                progress(acc.samples, spp)
        rgba = acc.read_rgba()
        stats = self.resources.read_stats()
        stats["min_samples"] = int(rgba[..., 3].min())
        image = rgba[..., :3].copy()
        if not denoise:
            return RenderResult(image, method, spp, render_ms, bake_ms, stats=stats)
        guides = choose_guides(denoise_guides, spp, self.needs_probes(method) and self.probes_shown())
        denoised, guides_ms = self.denoise(None, guides)
        return RenderResult(denoised.image, method, spp, render_ms, bake_ms, stats=stats,
                            raw_image=image, denoised=denoised, guides_ms=guides_ms)

    def _render_composite(self, method: str, spp: int, seed: int, width: int | None,
                          height: int | None, bake_progress: Callable | None, denoise: bool,
                          denoise_guides: str) -> RenderResult:
        """render() of a method made of others' images (the registry's `parts`): `refine`, as
        its view in the viewer ends (refine.render_refine). stats["shown"] names the part shown
        and stats["refine_estimate"] the estimated errors that chose it."""
        if method != "refine":
            raise NotImplementedError(f"render(): no still image of {method} yet")
        # the raymarcher's opacity-gradient grid too (surfaces on), so that the image's bake
        # time holds it (the raymarch inside render_refine then finds it current)
        bake_ms = (self.bake(seed, progress=bake_progress) + self.bake_light()
                   + self.bake_gradient_grid())
        self.resources.reset_stats()
        done = render_refine(self, spp, seed, width, height,
                             denoise_guides=denoise_guides if denoise else None)
        self.camera = camera_frame(self.scene.camera, width, height)   # the guides' camera
        stats = self.resources.read_stats()
        stats["shown"] = done.shown
        blend = done.blend
        stats["refine_estimate"] = {"guided": done.estimate.guided,
                                    "raymarch": done.estimate.raymarch,
                                    "samples": done.estimate.samples,
                                    "blend_weight": None if blend is None else blend.weight,
                                    "blend": None if blend is None else blend.blend,
                                    "guided_denoised": None if blend is None else blend.denoised}
        render_ms = done.raymarch_ms + done.guided_ms
        if not denoise:
            return RenderResult(done.image, method, spp, render_ms, bake_ms, stats=stats)
        if done.shown == "raymarch":   # nothing noisy shown: the filter has nothing to do
            return RenderResult(done.image, method, spp, render_ms, bake_ms, stats=stats)
        guides = choose_guides(denoise_guides, spp, self.probes_shown())
        denoised, guides_ms = self.denoise(done.image, guides, signed=REGISTRY[done.shown].signed)
        image, raw = denoised.image, done.image
        if blend is not None and blend.weight < 1.0 and denoised.denoised:
            image = blend_images(done.raymarch_image, denoised.image, blend.weight)
            raw = blend_images(done.raymarch_image, done.image, blend.weight)
        return RenderResult(image, method, spp, render_ms, bake_ms, stats=stats,
                            raw_image=raw, denoised=denoised, guides_ms=guides_ms)

    # ---- the denoiser's guides (denoise_guides.py) and the denoiser (denoise.py) ----------------
    def denoise_guides(self, guides: str = "albedo-normal", frames: int = GUIDE_FRAMES,
                       probe_frames: int = 16, camera=None
                       ) -> tuple[np.ndarray | None, np.ndarray | None, float]:
        """The noise-free guides of `camera` (a CameraFrame; None: the camera begun, else the
        scene's) as the denoiser
        takes them: (albedo, normal, GPU ms), each None where the set has none. "albedo" and
        "albedo-normal": where each ray first scatters in expectation (glsl/denoise_guide_images.comp,
        `frames` jittered rays a pixel); "probes": the raymarched image over the probes in hand
        (`probe_frames` frames; bake first), scaled into [0, 1], in the albedo's place. Kept
        while the camera, the medium and the probes stay: the same arrays again and 0 ms (the
        denoiser then keeps them on its device too)."""
        if guides not in GUIDE_SETS:
            raise ValueError(f"unknown denoise guides {guides!r} (known: {', '.join(GUIDE_SETS)})")
        if guides == "none":
            return None, None, 0.0
        camera = camera or self.camera or camera_frame(self.scene.camera)
        step = self.raymarch_step_voxels * 2 * self.resources.march_step
        key = (guides, tuple(camera.uniforms().items()), self.resources.bake_key(), step,
               frames, probe_frames,
               (self._baked_key, self.probe_grid.passes_done, self.probe_grid.next_probe)
               if guides == "probes" and self.probe_grid is not None else None)
        if self._guides_key == key:
            albedo, normal = self._guides_kept
            return albedo, normal, 0.0
        if guides == "probes":
            if not self.probes_shown():
                raise RuntimeError("the probes guide needs probes: bake first")
            acc = self._guide_acc
            if acc is None or (acc.width, acc.height) != (camera.width, camera.height):
                if acc is not None:
                    acc.release()
                acc = self._guide_acc = Accumulation(self.ctx, camera.width, camera.height)
            acc.reset()
            light_ms = self.bake_light() + self.bake_gradient_grid()
            extra = self.probe_uniforms()
            self.timer.start()
            self.raymarcher().run(self.resources, camera, acc, probe_frames, self.seed ^ 0x2545F491,
                                  step, {**extra, **self._light.uniforms()})
            self.timer.stop()
            albedo, normal, ms = radiance_as_albedo(acc.read()), None, light_ms + self.timer.elapsed_ms
        else:
            medium = self.resources.medium_defines()
            if self._guides is None or self._guides.defines != medium:
                if self._guides is not None:   # a crop, channels or surfaces changed the build
                    self._guides.release()
                self._guides = DenoiseGuides(self.ctx, medium)
            self.timer.start()
            self._guides.run(self.resources, camera, step, frames, self.seed)
            self.timer.stop()
            albedo, normal = self._guides.read()
            normal = normal if guides == "albedo-normal" else None
            ms = self.timer.elapsed_ms
        self._guides_key, self._guides_kept = key, (albedo, normal)
        return albedo, normal, ms

    def denoise(self, image: np.ndarray | None = None, guides: str = "albedo-normal",
                quality: str = "high", copy: bool = True,
                signed: bool | None = None) -> tuple[Denoised, float]:
        """The image of the camera begun (None: the accumulation in hand, read from GL straight
        into the denoiser's memory) through the denoiser with `guides`: (Denoised, the guides'
        GPU ms). Where the denoiser cannot run, Denoised holds the raw image and a note.
        `signed`: whether the image may dip below zero (None: the method begun's, app/methods.py).

        From the accumulation (every method but `guided`, whose image is the sum of two) the
        raw tile means are made and given back on the GPU (kept_means.denoise_on_gl: Denoised.ms
        has readback_ms, means_ms for the GL passes with a ctx.finish, upload_result_ms, and
        result_readback_ms, the corrected image read back for the host image returned, which a
        viewer does not pay); an image given here keeps the host path (keep_block_means)."""
        denoiser = shared_denoiser("auto", quality)
        if not denoiser.available:
            raw = self.image() if image is None else image
            return Denoised(sanitize(raw), None, denoiser.failure), 0.0
        albedo, normal, guides_ms = self.denoise_guides(guides)
        if image is None:
            acc = self._acc
            names = tuple(n for n, g in (("albedo", albedo), ("normal", normal)) if g is not None)
            staged = (denoiser.staging(acc.width, acc.height, names)
                      if self.method != "guided" else None)
            signed = REGISTRY[self.method].signed if signed is None else signed
            if staged is not None:
                if self._kept_means is None:
                    self._kept_means = KeptMeans(self.ctx)
                kept = self._kept_means
                return denoise_on_gl(kept, denoiser, acc.texture, staged, albedo, normal, signed,
                                     kept.result_texture(acc.width, acc.height),
                                     read_result=True), guides_ms
            image = self.image()
        signed = REGISTRY[self.method].signed if signed is None else signed
        return denoiser(image, albedo, normal, copy=copy, signed=signed), guides_ms
