"""The viewer's Denoise switch: each shown view of a noisy method (the path tracer, `probes`,
`probes-only`, and `refine` once `guided` shows) through the denoiser (app/rendering/denoise/filter.py),
with the guides Renderer.denoise_guides makes for the view's camera ("auto": the probes' image
where the view has probes, else the albedo and normal at few samples; refine's probes guide is
its own raymarched image, read back beside it).

No frame waits for the filter (issue 56). A view's filtered image is made in three steps over
frames: its accumulation read back through a pixel buffer with a fence (app/gl/fence.py), the
host copy taken on the first later frame that finds the fence signalled; the filter on its own
thread (app/rendering/denoise/filter_worker.py: OIDN alone, the colour's tile means and refine's probes
guide made on the GPU beside the read-back); and the filter's output uploaded on the frame that
finds it done, if the view has not restarted since (else it is dropped), and given back the raw
tile means on the GPU (KeptMeans.restore_given). The display shows the newest finished filtered image of the current accumulation, and
the raw image until the first. A new filtered image is started whenever the samples have doubled
since the last one started (1, 2, 4, ...), and at least every INTERVAL_S while they grow, one at
a time per view. OIDN has no temporal mode: the filtered images of a still camera change as
samples come (docs/denoising.md measures the flicker). So an image that lands less than a doubling
after the one shown (the INTERVAL_S images of a still view, where the accumulation has converged
enough that a doubling takes longer) is shown mixed with it, STILL_MIX of the new (on the GPU,
refine.BlendPass); a doubling's image replaces it.

A `refine` view blending guided with the raymarcher's image (RefineView.blending: the weight its
last judgement gave, app/rendering/refine/refine.py) shows (1 - w) r + w D, made on the GPU
(refine.BlendPass) whenever D, r or w has changed."""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass

import moderngl

from radiance_probes.gl.fence import (ChunkedUpload, HostArrays, PendingRead, TransferBudget,
                                      staging_buffer, start_read)
from radiance_probes.methods import METHODS
from radiance_probes.rendering.denoise.filter import choose_guides, shared_denoiser
from radiance_probes.rendering.denoise.filter_worker import FilterJob, FilterWorker
from radiance_probes.rendering.denoise.kept_means import KeptMeans, tile_grid
from radiance_probes.rendering.denoise.probe_guide import ProbeAlbedoGuide
from radiance_probes.rendering.image_ops import clear_image
from radiance_probes.rendering.refine.refine import BlendPass
from radiance_probes.viewer.frame.frame_parts import FrameParts

INTERVAL_S = 0.5
# Bytes a frame copies between the host and GL for the switch and refine's judgements (fence.py
# TransferBudget): a 1080p RGBA32F image is 33 MB, its read-back's host copy or its upload
# several ms of a frame, so each is spread over a few frames. On the H200 an upload of 16 MB from
# host memory took 12.4 ms of a frame's wall time (bench/h200-interact-refine-56/before-pacing);
# through a pixel buffer (ChunkedUpload) 8 MB takes 2.5 ms (median; 1.4 ms a read-back's 8 MB),
# and at 16 MB a frame a judgement's transfers take half the frames: bonsai's edits reached 2% in
# 0.29-0.96 s of wall time against 0.29-1.12 s at 8 MB, p99 frames 22.5-24.9 ms of wall time
# against 22.3-23.5 (bench/h200-interact-refine-56/transfers-16mb, level0-bands).
TRANSFER_BYTES_PER_FRAME = 16 << 20
# The new image's weight where a filtered image lands less than a doubling of the samples after
# the one shown (the same accumulation): the shown image is then STILL_MIX new + (1 - STILL_MIX)
# the one before, itself such a mix. Each filtered image's residual noise is partly new (the
# filter answers a few more samples with a different pattern): replacing the image moves it by
# that whole difference, the flicker a person sees on a still camera; the mix moves it by half of
# it and averages the patterns. Its cost: the image shown lags behind the newest by that half,
# an image of at least half its samples. 1: no mix (each landing replaces).
STILL_MIX = 0.5


def tile_means_of(means: PendingRead | None, image):
    """A tile means read-back's values as (tiles down, across, 4: the means, then each tile's
    least component, glsl/tile_means.comp), for an image of `image`'s shape; None where there
    is none."""
    if means is None:
        return None
    height, width = image.shape[:2]
    across, down = tile_grid(width, height)
    return means.out[:4 * across * down].reshape(down, across, 4)


@dataclass
class _Filtered:
    texture: object
    generation: tuple      # (the accumulation's id, the session's restarts) it was made from
    samples: int           # samples of the image it filtered
    at: float              # when it was started (monotonic seconds)
    blended: object = None   # refine's blend with the raymarcher's image, and what it was made of
    blend_key: tuple | None = None


FRESH_TEXTURES = 4   # a view's filtered image, its spare, its still mix's and its blend (refine)
FRESH_RGB_TEXTURES = 2   # the filter's outputs going up (a view's, a judgement's)


@dataclass
class _InFlight:
    """A filtered image under way: its read-backs (the colour; refine's probes guide), then the
    filter's job on the thread."""
    generation: tuple
    samples: int
    at: float
    reads: list
    signed: bool
    albedo: object = None
    normal: object = None
    probe_guide: bool = False
    means: PendingRead | None = None   # the colour's tile means (glsl/tile_means.comp)
    filtering: bool = False
    filter: tuple = (moderngl.NEAREST, moderngl.NEAREST)   # the view's, for the image shown

    @property
    def transfers(self) -> list:
        """Its read-backs, the tile means' included."""
        return self.reads + ([self.means] if self.means is not None else [])


class ViewDenoise:
    def __init__(self, ctx: moderngl.Context, enabled: bool):
        self.ctx = ctx
        self.enabled = enabled
        self.images: dict[str, _Filtered] = {}
        self.inflight: dict[str, _InFlight] = {}
        self.note: str | None = None     # why it switched itself off (the library, the filter)
        self.last_ms = 0.0               # wall ms of the last update (the frame's share)
        self.runs = 0                    # filtered images shown (tests, the Stats panel)
        self.parts = FrameParts()        # the frame's parts (the session hands in its own)
        self.filter_ms = 0.0             # the filter's ms on its thread, of results landed
        self.kept_means: KeptMeans | None = None   # the tile means' passes, made on first use
        self.probe_guide: ProbeAlbedoGuide | None = None   # refine's probes guide's passes
        # compiled with the session where the switch starts on, not at a view's first blend
        self.blend_pass: BlendPass | None = BlendPass(ctx) if enabled else None
        self._worker: FilterWorker | None = None
        self._staging: dict[tuple, moderngl.Buffer] = {}
        self._means_gpu: dict[tuple, moderngl.Buffer] = {}   # means_on_gpu's buffers
        self.host = HostArrays()   # the read-backs' host copies, reused
        self.budget = TransferBudget(TRANSFER_BYTES_PER_FRAME)   # the frame's host transfers
        # a filtered image being uploaded in bands into a texture of its own, then shown:
        # {name: (ChunkedUpload into an RGB32F texture, _InFlight, the RGBA32F texture it is
        # restored into, FilterResult)}; and each view's spare texture for the next
        self.landing: dict[str, tuple] = {}
        self._spare: dict[str, moderngl.Texture] = {}
        self._mix: dict[str, moderngl.Texture] = {}   # each view's next still mix's target
        # made at warm(), before any frame needs them, and touched so that the driver gives
        # them memory then: the uploads' pixel buffer and RGBA32F textures of the view's size
        # (made at their first use, they cost a load's frames 26 and 45 ms on the H200 at 1080p)
        self.upload_buffer: moderngl.Buffer | None = None
        self._fresh: list[moderngl.Texture] = []
        self._rgb_free: list[moderngl.Texture] = []   # RGB32F: uploads' targets not in use

    # ---- the filter's thread -------------------------------------------------------------------
    def worker(self) -> FilterWorker | None:
        """The filter's thread over shared_denoiser() (a new one where that changed); None, with
        the switch off and its note, where the denoiser says it cannot run."""
        denoiser = shared_denoiser()
        failure = getattr(denoiser, "failure", None)
        if failure is not None:
            self.note, self.enabled = failure, False
            self.release()
            return None
        if self._worker is None or self._worker.denoiser is not denoiser:
            if self._worker is not None:
                self._worker.close()
            self._worker = FilterWorker(denoiser)
        return self._worker

    def warm(self, width: int, height: int) -> None:
        """Readies the filter for images of this size on its thread (OIDN's first use there)."""
        if self.enabled and width > 0 and height > 0:
            worker = self.worker()
            if worker is not None:
                # refine's guided is signed: its negative part's filter made now too
                worker.warm(width, height, ("albedo",), signed=True)
            self._stock(width, height)
            self.kept()   # its passes compiled now, not at the first filtered image
            self.albedo_guide()

    def _stock(self, width: int, height: int) -> None:
        """FRESH_TEXTURES touched textures of this size, and the uploads' pixel buffer."""
        for texture in self._fresh:
            texture.release()
        self._fresh = []
        for _ in range(FRESH_TEXTURES):
            texture = self.ctx.texture((width, height), 4, dtype="f4")
            clear_image(texture)
            self._fresh.append(texture)
        for texture in self._rgb_free:
            texture.release()
        self._rgb_free = []
        for _ in range(FRESH_RGB_TEXTURES):
            texture = self.rgb_texture((width, height))
            texture.write(bytes(12 * width * height))
            self._rgb_free.append(texture)
        if self.upload_buffer is None:
            self.upload_buffer = self.ctx.buffer(reserve=TRANSFER_BYTES_PER_FRAME)
            self.upload_buffer.write(bytes(TRANSFER_BYTES_PER_FRAME))

    @contextmanager
    def held(self):
        """No filter job starts within the block (FilterWorker.hold)."""
        worker = self._worker
        if worker is not None:
            worker.hold(True)
        try:
            yield
        finally:
            if worker is not None:
                worker.hold(False)

    def idle(self) -> bool:
        """No filtered image under way (read-backs, the filter's thread)."""
        return not self.inflight and (self._worker is None or self._worker.idle())

    def drop_job(self, key: str) -> None:
        """Forgets the filter's job and result under `key` (a refine judgement begun before a
        restart)."""
        if self._worker is not None:
            self._worker.drop(key)

    def kept(self) -> KeptMeans:
        """The tile means' passes (a still refine's judgement filters through them)."""
        if self.kept_means is None:
            self.kept_means = KeptMeans(self.ctx)
        return self.kept_means

    def set_enabled(self, on: bool) -> None:
        self.enabled = bool(on)
        if on:
            self.note = None
            if self.blend_pass is None:
                self.blend_pass = BlendPass(self.ctx)
            # the passes a filtered image takes, compiled at the switch, not in its first frames
            self.kept()
            self.albedo_guide()

    def albedo_guide(self) -> ProbeAlbedoGuide:
        """refine's probes guide's passes (made on first use)."""
        if self.probe_guide is None:
            self.probe_guide = ProbeAlbedoGuide(self.ctx)
        return self.probe_guide

    def rgb_texture(self, size) -> moderngl.Texture:
        """An RGB32F texture of `size` for a filter's output to go up into (one not in use, or
        a new one); give it back with give_rgb_texture once restored."""
        size = tuple(size)
        for i, texture in enumerate(self._rgb_free):
            if texture.size == size:
                return self._rgb_free.pop(i)
        texture = self.ctx.texture(size, 3, dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return texture

    def give_rgb_texture(self, texture: moderngl.Texture) -> None:
        if len(self._rgb_free) < FRESH_RGB_TEXTURES:
            self._rgb_free.append(texture)
        else:
            texture.release()

    def restore_result(self, upload: ChunkedUpload, result, out: moderngl.Texture) -> None:
        """A filter's output, now whole in `upload`'s RGB32F texture, given back its raw tile
        means into `out` (RGBA32F; checked finite and, unless signed, non-negative there), its
        texture and host array given back for the next."""
        self.kept().restore_given(upload.texture, result.raw_means, out, result.signed)
        self._give_back(upload)

    def _give_back(self, upload: ChunkedUpload) -> None:
        """A filter output's upload done with (restored, or dropped by a restart): its RGB32F
        texture and its host array given back for the next."""
        upload.release()
        self.give_rgb_texture(upload.texture)
        if self._worker is not None:
            self._worker.recycle(upload.image)

    def means_on_gpu(self, key: tuple, texture) -> moderngl.Buffer:
        """The tile means of `texture` dispatched into a GL buffer kept under `key` (for a
        read-back beside the image: FilterJob.raw_means), so that the filter's thread neither
        sums the image nor looks for non-finite pixels (a non-finite mean says there is one)."""
        across, down = tile_grid(*texture.size)
        kept = self._means_gpu.get(key)
        buf = self._means_gpu[key] = staging_buffer(self.ctx, kept, 16 * across * down)
        self.kept().dispatch_means_into(texture, buf)
        return buf

    def read(self, key: tuple, source) -> PendingRead:
        """A read-back of `source` started into the staging buffer kept under `key`."""
        return start_read(self.ctx, source, self._staging, self.host, key)

    def _due(self, name: str, generation: tuple, samples: int, now: float) -> bool:
        old = self.images.get(name)
        if old is None or old.generation != generation:
            return samples > 0
        return samples >= 2 * old.samples or (samples > old.samples and now - old.at >= INTERVAL_S)

    # ---- a frame -------------------------------------------------------------------------------
    def update(self, session) -> float:
        """For each view: lands a finished filtered image, hands finished read-backs to the
        filter, and starts the read-back of the next image where one is due; never waits.
        Returns the wall ms it took."""
        self.last_ms = 0.0
        self.filter_ms = 0.0
        if not self.enabled:
            return 0.0
        start = time.perf_counter()
        worker = self.worker()
        if worker is None:
            return 0.0
        for name, view in session.views.items():
            acc, shown = view.acc, view.shown
            generation = (id(acc), session.restarts)
            if acc is None or not METHODS[shown].noisy or acc.samples == 0:
                self._forget(name)
                continue
            self._land(name, worker, generation)
            if not self.enabled:
                break
            self._upload(name, generation)
            self._advance(name, worker, generation)
            # one image under way a view: read back, filtered, uploaded, then the next
            if (name not in self.inflight and name not in self.landing
                    and self._due(name, generation, acc.samples, time.monotonic())):
                self._start(name, session, view, generation)
        if self.enabled:
            with self.parts.part("blend"):
                self._blend(session)
        self.last_ms = 1e3 * (time.perf_counter() - start)
        return self.last_ms

    def _land(self, name: str, worker: FilterWorker, generation: tuple) -> None:
        """The view's finished filtered image uploaded, where it is of the current accumulation."""
        result = worker.take(name)
        if result is None:
            return
        flight = self.inflight.pop(name, None)
        self.filter_ms += result.ms.get("filter_ms", 0.0) + result.ms.get("guide_ms", 0.0)
        if result.rgb is None:
            self.note, self.enabled = result.note, False
            self.release()
            return
        if flight is None or flight.generation != generation:
            worker.recycle(result.rgb)
            return   # the view restarted while it was filtered: not an image of what it shows
        h, w = result.rgb.shape[:2]
        texture = self._spare[name] = self._sized(self._spare.get(name), (w, h))
        texture.filter = flight.filter
        upload = ChunkedUpload(self.rgb_texture((w, h)), result.rgb, self.upload_buffer)
        self.landing[name] = (upload, flight, texture, result)

    def _upload(self, name: str, generation: tuple) -> None:
        """A band of the filtered image being uploaded; once whole, it is what the view shows
        (the texture it replaces becomes the spare)."""
        got = self.landing.get(name)
        if got is None:
            return
        upload, flight, texture, result = got
        if flight.generation != generation:
            del self.landing[name]
            self._give_back(upload)
            return
        with self.parts.part("upload"):
            whole = upload.step(self.budget)
            if whole:
                self.restore_result(upload, result, texture)
        if not whole:
            return
        del self.landing[name]
        old = self.images.get(name)
        self._spare.pop(name, None)
        shown = texture
        if (old is not None and STILL_MIX < 1.0 and old.generation == generation
                and flight.samples < 2 * old.samples and old.texture.size == texture.size):
            # a still view's image less than a doubling on: mixed with the one shown
            with self.parts.part("upload"):
                shown = self._sized(self._mix.pop(name, None), texture.size)
                shown.filter = texture.filter
                if self.blend_pass is None:
                    self.blend_pass = BlendPass(self.ctx)
                self.blend_pass.run(old.texture, texture, shown, STILL_MIX)
            self._spare[name] = texture
            self._mix[name] = old.texture
        elif old is not None:
            self._spare[name] = old.texture
        blended = old.blended if old is not None else None
        self.images[name] = _Filtered(shown, generation, flight.samples, flight.at,
                                      blended)
        self.runs += 1

    def _advance(self, name: str, worker: FilterWorker, generation: tuple) -> None:
        """An image whose read-backs are all in: its host copies handed to the filter."""
        flight = self.inflight.get(name)
        if flight is None or flight.filtering:
            return
        reads = flight.transfers
        if flight.generation != generation:   # restarted before its read-back came
            for r in reads:
                r.release()
            del self.inflight[name]
            return
        if not all(r.ready() for r in reads):
            return
        with self.parts.part("readback", gpu=False):
            done = all(r.read_some(self.budget) for r in reads)   # in order, in parts
        if not done:
            return
        images = [r.out for r in flight.reads]
        worker.submit(name, FilterJob(images[0], flight.albedo, flight.normal,
                                      probe_albedo=images[1] if flight.probe_guide else None,
                                      signed=flight.signed, tag=flight.samples,
                                      raw_means=tile_means_of(flight.means, images[0])))
        flight.filtering = True

    def _start(self, name: str, session, view, generation: tuple) -> None:
        """The read-back of the view's image (and of refine's raymarched image, its probes
        guide) started; other guides made now (Renderer.denoise_guides keeps them per camera)."""
        r = session.renderer
        acc = view.acc
        has_probes = session.needs_probes(name) and r.probes_current()
        guides = choose_guides("auto", acc.samples, has_probes)
        ray = getattr(view, "ray", None)
        probe_guide = guides == "probes" and ray is not None and ray.samples > 0
        albedo = normal = None
        if not probe_guide:
            with self.parts.part("guide"):
                albedo, normal, _ = r.denoise_guides(guides, camera=view.camera)
        # the tile means first, so that the colour's fence covers their pass too
        means = self.read((name, "means"), self.means_on_gpu((name, "means"), acc.texture))
        reads = [self.read((name, "colour"), acc.texture)]
        if probe_guide:   # made on the GPU, read back packed beside the colour
            with self.parts.part("guide"):
                guide = self.albedo_guide().dispatch((name, "guide"), ray.texture)
            reads.append(self.read((name, "guide"), guide))
        self.inflight[name] = _InFlight(generation, acc.samples, time.monotonic(), reads,
                                        METHODS[view.shown].signed, albedo, normal, probe_guide,
                                        means, filter=acc.texture.filter)

    def adopt(self, name: str, halves, restarts: int) -> None:
        """refine's judgement filtered half A: that image becomes the view's filtered image (a GPU
        copy), counted as of the halves' whole sample count, so the view is filtered again at
        the next doubling (or INTERVAL_S), not at once."""
        combined = halves.combined
        old = self.images.get(name)
        texture = self._sized(None if old is None else old.texture, combined.texture.size)
        texture.filter = combined.texture.filter
        halves.copy_denoised_a(texture)
        blended = old.blended if old is not None else None
        self.images[name] = _Filtered(texture, (id(combined), restarts), combined.samples,
                                      time.monotonic(), blended)

    def _sized(self, texture, size):
        """`texture`, or where it is missing or not of `size` (it is then released) a new
        RGBA32F texture of that size: the upload and the blend pass store into it, the display
        reads rgb."""
        if texture is not None and texture.size == tuple(size):
            return texture
        if texture is not None:
            texture.release()
        fresh = next((t for t in self._fresh if t.size == tuple(size)), None)
        if fresh is not None:
            self._fresh.remove(fresh)
            return fresh
        return self.ctx.texture(tuple(size), 4, dtype="f4")

    def _forget(self, name: str) -> None:
        landing = self.landing.pop(name, None)
        if landing is not None:
            self._give_back(landing[0])
        for kept in (self._spare, self._mix):
            spare = kept.pop(name, None)
            if spare is not None:
                spare.release()
        got = self.images.pop(name, None)
        if got is not None:
            got.texture.release()
            if got.blended is not None:
                got.blended.release()
        flight = self.inflight.pop(name, None)
        if flight is not None:
            for r in flight.transfers:
                r.release()
        if self._worker is not None:
            self._worker.drop(name)

    def _blend(self, session) -> None:
        """Each blending refine view's (1 - w) r + w D, where its inputs have changed."""
        for name, view in session.views.items():
            got = self.images.get(name)
            if not getattr(view, "blending", False) or got is None:
                continue
            if got.generation != (id(view.acc), session.restarts):
                continue
            key = (got.samples, got.at, id(got.texture), view.weight, view.ray.samples)
            if got.blend_key == key:
                continue
            got.blended = self._sized(got.blended, got.texture.size)
            got.blended.filter = got.texture.filter
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
        for name in list(self.images) + list(self.inflight) + list(self._spare) + list(self._mix):
            self._forget(name)
        for buf in (*self._staging.values(), *self._means_gpu.values()):
            buf.release()
        self._staging.clear()
        self._means_gpu.clear()
        self.host.clear()
        for texture in (*self._fresh, *self._rgb_free):
            texture.release()
        self._fresh, self._rgb_free = [], []
        if self.probe_guide is not None:
            self.probe_guide.release()
            self.probe_guide = None
        if self.blend_pass is not None:
            self.blend_pass.release()
            self.blend_pass = None
        if self.kept_means is not None:
            self.kept_means.release()
            self.kept_means = None

    def close(self) -> None:
        """release(), the uploads' pixel buffer (a check's upload may hold it until then) and
        the filter's thread ended."""
        self.release()
        if self.upload_buffer is not None:
            self.upload_buffer.release()
            self.upload_buffer = None
        if self._worker is not None:
            self._worker.close()
            self._worker = None
