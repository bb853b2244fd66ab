"""A viewer frame's deferred spans (RenderSession.step; gl/timer.DeferredSpans): the tags its timed
blocks are summed under, the pacing entries made from their estimates, and at the frame's end the
one wait for its GPU work and the corrections by the measured ms."""
from __future__ import annotations

import time
from contextlib import contextmanager

from radiance_probes.gl.timer import DeferredSpans


class FrameSpans:
    """`spans` (the renderer's `deferred` while a frame runs by the GPU's clock); each dispatch's
    spans under a tag of its own (`sample_tag`), the bake's under "bake"; `watch` keeps a pacing
    entry [n, ms] whose ms the tag's measured ms replace at `resolve`."""

    def __init__(self, ctx):
        self.spans = DeferredSpans(ctx)
        self._entries: list[tuple[object, list]] = []   # (tag, dispatch_ms entry) to correct
        self._samples = 0                                 # the frame's sample tags so far

    @contextmanager
    def tagged(self, tag):
        """Spans begun within the block are summed under `tag`."""
        self.spans.tag = tag
        try:
            yield tag
        finally:
            self.spans.tag = None

    def sample_tag(self) -> tuple:
        """A tag of its own for the spans of the dispatch about to be made."""
        self._samples += 1
        return ("samples", self._samples)

    def watch(self, tag, entry: list) -> None:
        self._entries.append((tag, entry))

    def resolve(self, times, parts) -> float:
        """The frame's spans read (its one wait, for the GPU to finish its work, timed as part
        "wait"), and what was summed from their estimates corrected by their measured ms: the
        frame's bake and render ms, their parts' GPU ms, and each watched entry. Returns the
        bake's correction (the session's own bake totals take it too)."""
        entries, self._entries, self._samples = self._entries, [], 0
        if not self.spans.pending:
            return 0.0
        t = time.perf_counter()
        got = self.spans.resolve()
        parts.add("wait", 1e3 * (time.perf_counter() - t))
        bake = 0.0
        for tag, (measured, estimated) in got.items():
            d = measured - estimated
            if tag == "bake":
                times.bake_ms += d
                bake = d
                part = times.parts.get("bake")
            elif isinstance(tag, tuple) and tag[0] == "samples":
                times.render_ms += d
                part = times.parts.get("samples")
            else:
                continue
            if part is not None and part[0] is not None:
                part[0] += d
        for tag, entry in entries:
            measured, estimated = got.get(tag, (0.0, 0.0))
            entry[1] += measured - estimated
        return bake
