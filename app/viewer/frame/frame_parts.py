"""What each part of a viewer frame took, by name, in GPU and in wall time (issue 56): a frame
over budget then says why. The parts: "bake" (the bake's slice), "prepare" (in the frame a bake
begins: the programs and path states of what will read its probes, Renderer.prepare), "samples"
(every view's samples), "guide" (denoise guides made on the GL side), "readback" (host copies of
read-backs found finished), "combine" (refine's halves combined, a check begun), "judgement" (a check's
step: sums read, half A handed to the filter, the judge pass), "upload" (a filtered image
uploaded), "blend" (refine's blend pass), "wait" (the frame's one wait for its GPU work, where
its timers are read at its end: gl/timer.DeferredSpans), "display" (the picture drawn), and in the
window "imgui" (the panels built and drawn) and "swap". The filter runs on its own thread: its ms are
the frame's `filter_ms`, off the frame.

Each part is a pair [GPU ms, wall ms]. GPU ms come from timestamp queries around the part, read
at the start of the next frame (their results are in by then, so reading them waits for nothing
the frame did not already hand the GPU); None where no GPU time was taken (the host copies) or
the part's timestamps cannot be believed (the wall-clock pacing, app/viewer/frame/pacing.py)."""
from __future__ import annotations

import time
from contextlib import contextmanager

from radiance_probes.gl.timer import GpuTimer

PARTS = ("bake", "prepare", "samples", "guide", "readback", "combine", "judgement", "upload", "blend",
         "wait", "display", "imgui", "swap")


class FrameParts:
    """The current frame's parts (`current`, {name: [GPU ms or None, wall ms]}), their GPU
    timestamps read into that dict at the next begin_frame(). `ctx` None: wall time only."""

    def __init__(self, ctx=None):
        self.ctx = ctx
        self.current: dict = {}
        self.last: dict = {}      # the frame before's, whole (its window parts and GPU ms in)
        self._free: list[GpuTimer] = []
        self._pending: list[tuple[dict, str, GpuTimer]] = []
        self._nested: list[float] = []   # wall ms of the parts inside each open part
        self.gpu = ctx is not None

    def begin_frame(self) -> dict:
        """The last frame's GPU times read into its dict; a new dict for this frame."""
        self.resolve()
        self.last, self.current = self.current, {}
        return self.current

    def resolve(self) -> None:
        for parts, name, timer in self._pending:
            entry = parts.get(name)
            if entry is not None:
                entry[0] = (entry[0] or 0.0) + timer.elapsed_ms
            self._free.append(timer)
        self._pending.clear()

    def add(self, name: str, wall_ms: float, gpu_ms: float | None = None) -> None:
        """A part timed elsewhere (the bake's slice, the samples: their own timers)."""
        entry = self.current.setdefault(name, [None, 0.0])
        entry[1] += wall_ms
        if gpu_ms is not None:
            entry[0] = (entry[0] or 0.0) + gpu_ms

    @contextmanager
    def part(self, name: str, gpu: bool = True):
        """Times the block as part `name` (wall; and GPU where `gpu` and the context allows). A
        part inside another counts its wall ms to itself alone (the outer part's are the rest);
        an outer part's GPU time would hold the inner's, so callers time GPU at one level."""
        timer = None
        if gpu and self.gpu:
            timer = self._free.pop() if self._free else GpuTimer(self.ctx)
            timer.start()
        t0 = time.perf_counter()
        self._nested.append(0.0)
        try:
            yield
        finally:
            wall = 1e3 * (time.perf_counter() - t0)
            inner = self._nested.pop()
            if self._nested:
                self._nested[-1] += wall
            entry = self.current.setdefault(name, [None, 0.0])
            entry[1] += wall - inner
            if timer is not None:
                timer.stop()
                self._pending.append((self.current, name, timer))

    def release(self) -> None:
        self._pending.clear()
        for timer in self._free:
            timer.release()
        self._free.clear()
