"""The denoiser off the frame: Open Image Denoise runs on a thread of its own over host arrays, so
that no frame of the viewer waits for it (app/viewer/frame/denoise_view.py, app/viewer/frame/session.py's
refine judgement). The GL context stays on the main thread: a frame hands in an image already
read back (app/gl/fence.py: a pixel buffer and a fence, collected on a later frame) and takes the
filter's RGB output, ready to upload, on whichever later frame finds it done.

One job runs at a time (the filter is the device's, one OIDN filter per size and guides); a job
waiting for its turn is replaced by a newer one of the same key (the newest image is the one worth
filtering), and a finished result is kept until its key's owner takes it. The thread does as
little as it can beside the filter: the colour's tile means come made on the GPU
(glsl/tile_means.comp), a "probes" guide comes made on the GPU too (probe_guide.py) and is
copied into the filter's own guide memory, and the result is the filter's RGB output in an array
of the thread's, without the means given back: its owner uploads it and gives them back on the
GPU (KeptMeans.restore_given, which checks the output as well). On the H200 the host passes these
replaced (the guide's NumPy passes, the means kept, the copy into RGBA) took 130-230 ms of a
173-310 ms job beside the frames (bench/h200-interact-refine-56/host-passes). OIDN's own first
use (its device and weights: about 4 s on the H200 machine the first time) happens in `warm`, on
the thread, at the viewer's start."""
from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from radiance_probes.rendering.denoise.filter import KEEP_MEANS_BLOCK, _block_means, _make_usable


FREE_KEPT = 3   # results' arrays kept for reuse (FilterWorker.recycle)


@dataclass
class FilterJob:
    """An image to filter: `colour` (H, W, 3 or 4 float32, host), guides as host arrays (`albedo`
    in [0, 1] and `normal`; or `probe_albedo`, the probes guide made on the GPU, ProbeAlbedoGuide:
    H x W x 3 float32 values in [0, 1] in any shape, copied into the filter's own guide memory
    on the thread), `signed` (a residual that may dip below 0), `tag`: what its owner wants back
    with the result (the samples, the generation it was read at), and `raw_means`: the colour's
    tile means where the owner made them on the GPU (glsl/tile_means.comp: tiles down, across,
    4, the fourth each tile's least value, which tells a signed colour's negative part without a
    host pass; else, or where one is not finite, the thread makes them from the colour made
    usable)."""
    colour: np.ndarray
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    probe_albedo: np.ndarray | None = None
    signed: bool = False
    tag: object = None
    raw_means: np.ndarray | None = None


@dataclass
class FilterResult:
    """A finished job: `rgb` (H, W, 3 float32, the filter's output as it came: not yet given back
    the raw means nor checked) or None where the filter could not run (`note` says why), its
    tag, `raw_means` (tiles down, across, 3: what KeptMeans.restore_given gives back to it),
    `signed` (filtered as a signed image: restore it so), and wall ms on the thread (`ms`: guide,
    filter, copy)."""
    rgb: np.ndarray | None
    tag: object
    note: str | None = None
    device: str | None = None
    ms: dict = field(default_factory=dict)
    finished_at: float = 0.0
    raw_means: np.ndarray | None = None
    signed: bool = False


class FilterWorker:
    """A daemon thread running `denoiser` (a denoise.Denoiser or a stand-in with its call) on
    submitted jobs. All of its methods return at once (`close` joins the thread)."""

    def __init__(self, denoiser):
        self.denoiser = denoiser
        self._lock = threading.Condition()
        self._queue: dict[str, FilterJob] = {}     # key -> the newest job not yet started
        self._running: str | None = None
        self._results: dict[str, FilterResult] = {}
        self._warm: list[tuple] = []
        self._stop = False
        self._held = 0                              # hold() depth: no job starts meanwhile
        self.runs = 0                               # jobs filtered (tests)
        self._free: list[np.ndarray] = []           # results' arrays given back (recycle)
        self._thread = threading.Thread(target=self._loop, name="denoise-filter", daemon=True)
        self._thread.start()

    # ---- the main thread -----------------------------------------------------------------------
    def submit(self, key: str, job: FilterJob) -> None:
        """Queues `job` under `key` (one of the same key still waiting is dropped)."""
        with self._lock:
            self._queue[key] = job
            self._lock.notify()

    def busy(self, key: str) -> bool:
        """A job of `key` waits or runs (its result not yet taken counts too)."""
        with self._lock:
            return key in self._queue or self._running == key or key in self._results

    def take(self, key: str) -> FilterResult | None:
        """The finished result of `key`'s last job, once (None: none finished)."""
        with self._lock:
            return self._results.pop(key, None)

    def drop(self, key: str) -> None:
        """Forgets `key`'s waiting job and finished result (a running one finishes unseen)."""
        with self._lock:
            self._queue.pop(key, None)
            self._results.pop(key, None)
            if self._running == key:
                self._discard = key

    def warm(self, width: int, height: int, guides: tuple[str, ...] = (),
             signed: bool = False) -> None:
        """Makes the filter for this size and guides (with `signed`, the negative part's too) on
        the thread (Denoiser.warm), before any job needs it."""
        with self._lock:
            self._warm.append((width, height, tuple(guides), signed))
            self._lock.notify()

    def hold(self, on: bool) -> None:
        """While held, no job starts (one running finishes): a measurement outside the frames'
        time (the interact bench's error) gives the filter no time of its own."""
        with self._lock:
            self._held = max(self._held + (1 if on else -1), 0)
            self._lock.notify()

    def recycle(self, rgb: np.ndarray) -> None:
        """Gives back a result's `rgb` its owner is done with (uploaded), for a later result
        to be written into: a 1080p one made anew for each result is 25 MB of fresh pages on the
        thread. The owner must not read it after; at most FREE_KEPT are kept."""
        if (rgb is None or rgb.dtype != np.float32 or rgb.ndim != 3 or rgb.shape[2] != 3
                or not rgb.flags.c_contiguous):
            return
        with self._lock:
            if len(self._free) < FREE_KEPT and not any(a is rgb for a in self._free):
                self._free.append(rgb)

    def _rgb(self, height: int, width: int) -> np.ndarray:
        with self._lock:
            for i, a in enumerate(self._free):
                if a.shape == (height, width, 3):
                    return self._free.pop(i)
            self._free = [a for a in self._free if a.shape[:2] == (height, width)]
        return np.empty((height, width, 3), np.float32)

    def idle(self) -> bool:
        with self._lock:
            return (not self._queue and self._running is None and not self._warm
                    and not self._results)

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._queue.clear()
            self._lock.notify()
        self._thread.join(timeout=30.0)

    # ---- the thread ----------------------------------------------------------------------------
    _discard: str | None = None

    def _loop(self) -> None:
        while True:
            with self._lock:
                while not self._stop and (self._held or not (self._queue or self._warm)):
                    self._lock.wait()
                if self._stop:
                    return
                if self._warm:
                    warm, key, job = self._warm.pop(0), None, None
                else:
                    warm = None
                    key = next(iter(self._queue))
                    job = self._queue.pop(key)
                    self._running, self._discard = key, None
            if warm is not None:
                warmer = getattr(self.denoiser, "warm", None)
                if warmer is not None:
                    try:
                        width, height, guides, signed = warm
                        warmer(width, height, guides, **({"signed": True} if signed else {}))
                    except Exception:   # a failing device says so at its first job
                        pass
                continue
            result = self._filter(job)
            with self._lock:
                if self._discard != key:
                    self._results[key] = result
                self._running = self._discard = None
                self.runs += 1

    def _filter(self, job: FilterJob) -> FilterResult:
        t0 = time.perf_counter()
        staging = getattr(self.denoiser, "guide_staging", None)
        in_place = job.probe_albedo is not None and staging is not None
        # a guide written into the denoiser's memory: its lock (re-entrant) over the write and
        # the call, so that no other caller's image of the size comes between them
        with self.denoiser.lock if in_place else contextlib.nullcontext():
            return self._filter_held(job, t0, staging if in_place else None)

    @staticmethod
    def _means(job: FilterJob) -> tuple[np.ndarray, np.ndarray, bool | None]:
        """(colour, its tile means, whether it has a negative value where the means say: their
        fourth component, each tile's least, else None): the job's own where its means are
        finite; else (none made on the GPU, or a non-finite pixel) the colour made usable (a
        copy: NaN and infinities 0, unless signed negatives 0, as Denoiser makes it) and the
        means of that."""
        means = job.raw_means
        if means is not None:
            means = np.asarray(means, np.float32)
            if np.isfinite(means[..., :3]).all():
                negative = bool(means[..., 3].min() < 0.0) if means.shape[2] >= 4 else None
                return job.colour, means[..., :3], negative
        colour = np.array(job.colour, np.float32)
        if job.signed:
            np.nan_to_num(colour, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
        else:
            _make_usable(colour)
        return colour, _block_means(colour[..., :3], KEEP_MEANS_BLOCK).astype(np.float32), None

    def _filter_held(self, job: FilterJob, t0: float, staging) -> FilterResult:
        try:
            colour, means, negative = self._means(job)
            h, w = colour.shape[:2]
            albedo = job.albedo
            if job.probe_albedo is not None:
                albedo = np.asarray(job.probe_albedo, np.float32).reshape(h, w, 3)
                names = ("albedo",) if job.normal is None else ("albedo", "normal")
                out = None if staging is None else staging(w, h, names, "albedo")
                if out is not None:   # made on the GPU in [0, 1]: one copy, no clip
                    np.copyto(out, albedo)
                    albedo = out
            t1 = time.perf_counter()
            rgb = self._rgb(h, w)
            d = self.denoiser(colour, albedo, job.normal, copy=False, signed=job.signed,
                              keep_means=False, check_output=False, color_finite=True, out=rgb,
                              has_negative=negative)
            t2 = time.perf_counter()
            if not d.denoised:
                self.recycle(rgb)
                return FilterResult(None, job.tag, d.note, None, finished_at=time.perf_counter())
            if d.image is not rgb:   # a stand-in's own array
                np.copyto(rgb, np.asarray(d.image, np.float32)[..., :3])
        except Exception as exc:   # the denoiser's own failures come back as notes
            return FilterResult(None, job.tag, f"the denoiser failed ({exc}). Showing the image "
                                "as rendered.", finished_at=time.perf_counter())
        t3 = time.perf_counter()
        return FilterResult(rgb, job.tag, None, d.device,
                            {"guide_ms": 1e3 * (t1 - t0), "filter_ms": 1e3 * (t2 - t1),
                             "copy_ms": 1e3 * (t3 - t2)}, finished_at=time.perf_counter(),
                            raw_means=means, signed=bool(d.signed))
