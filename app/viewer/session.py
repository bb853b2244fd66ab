"""The viewer's progressive rendering: one Renderer (one copy of the scene on the GPU, one probe
grid) and one accumulation per shown method, advanced a little every frame.

Camera moves only restart the accumulations (the probes' bake key leaves the camera out); any
other scene change restarts them too and, where it touches the bake key, the bake. While probes
bake, each frame gives the bake a budget of GPU time (a slice of chunks of walks, never a whole
bake), and the methods that read probes restart after every slice, so the picture improves with
the probes as they come. Until the bake is done, `probes` and `probes-only` show the raymarcher's
image (its frames cost a few ms; theirs tens of ms at 1080p on an H100, bench/h100-interact) and
switch to their own when the probes are current.

A frame's GPU time is budgeted as a whole (FRAME_BUDGET_MS): the bake slice first, then as many
samples per shown method as the rest of the frame holds by their measured cost, at least one.
"""
from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass

import moderngl
import numpy as np

from ..gl.context import is_software
from ..render.accumulation import Accumulation
from ..render.frame_budget import BAKE_BUDGET_MS, FRAME_BUDGET_MS
from ..render.probes import BakeProgress
from ..render.renderer import PROBE_LIGHTING, Renderer
from ..scene import Scene
from ..volume import Volume

FRAME_HISTORY = 240
MAX_SAMPLES_PER_FRAME = 64
RECENT_DISPATCHES = 5    # dispatches whose GPU ms per sample set the next frame's samples
# What a probe-lit method shows while its probes bake: the raymarcher over the probes as they are.
PREVIEW_WHILE_BAKING = "raymarch"


@dataclass
class MethodView:
    """One method's accumulation and the camera it was begun with."""
    method: str
    acc: Accumulation | None = None
    camera: object = None
    shown: str = ""               # what the accumulation holds: method, or the bake's preview
    # the last RECENT_DISPATCHES dispatches per method shown: {method: [(samples, GPU ms), ...]}
    dispatch_ms: dict = None

    def __post_init__(self):
        self.shown = self.shown or self.method
        self.dispatch_ms = {} if self.dispatch_ms is None else self.dispatch_ms

    @property
    def samples(self) -> int:
        return 0 if self.acc is None else self.acc.samples


@dataclass
class FrameTimes:
    """GPU milliseconds of one frame, from timestamp queries."""
    bake_ms: float = 0.0
    render_ms: float = 0.0
    display_ms: float = 0.0
    samples: int = 0          # samples per pixel dispatched in the frame, over its views

    @property
    def total_ms(self) -> float:
        return self.bake_ms + self.render_ms + self.display_ms


class RenderSession:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None,
                 seed: int = 0, renderer: Renderer | None = None):
        """`renderer`: one to drive instead of a new one (the interact benchmark's replay)."""
        self.ctx = ctx
        self.renderer = renderer if renderer is not None else Renderer(ctx, scene, volume)
        self.seed = seed
        self.views: dict[str, MethodView] = {}
        self.size = (0, 0)
        self.bake_passes_run = 0          # over the session's life: a test sees re-bakes by it
        self.bake_ms = 0.0                # GPU time of the current (or last) bake
        self.bake_report: BakeProgress | None = None
        self.bake_generation = 0          # counts bakes started
        self.restarts = 0
        self.last = FrameTimes()
        self.history: deque[float] = deque(maxlen=FRAME_HISTORY)
        self.filter = moderngl.NEAREST
        device = "software" if is_software(ctx) else "gpu"
        self.bake_budget_ms = BAKE_BUDGET_MS[device]
        self.frame_budget_ms = FRAME_BUDGET_MS[device]

    @property
    def scene(self) -> Scene:
        return self.renderer.scene

    @property
    def volume(self) -> Volume:
        return self.renderer.resources.volume

    @property
    def probe_grid(self):
        return self.renderer.probe_grid

    # ---- configuration -------------------------------------------------------------------------
    def set_scene(self, scene: Scene, volume: Volume | None = None) -> set[str]:
        """Adopts an edited scene; restarts the accumulations when anything visible changed."""
        if scene is self.renderer.scene and volume is None:
            return set()
        changed = self.renderer.set_scene(scene, volume)
        if changed:
            self.restart()
        return changed

    def set_methods(self, methods: list[str]) -> None:
        for name in [m for m in self.views if m not in methods]:
            self._drop(name)
        for name in methods:
            if name not in self.views:
                self.views[name] = MethodView(name)
                self._begin(self.views[name])

    def resize(self, width: int, height: int) -> None:
        size = (max(int(width), 1), max(int(height), 1))
        if size != self.size:
            self.size = size
            self.restart()

    def restart(self, methods=None) -> None:
        for view in self.views.values():
            if methods is None or view.method in methods:
                self._begin(view)
        self.restarts += 1

    def _begin(self, view: MethodView) -> None:
        if self.size == (0, 0):
            return
        r = self.renderer
        view.shown = self.shown_method(view.method)
        r._acc = view.acc  # the Renderer keeps one accumulation; each view lends it its own
        view.acc = r.begin(view.shown, *self.size, seed=self.seed)
        view.acc.texture.filter = (self.filter, self.filter)
        view.camera = r.camera
        r._acc = None

    def _drop(self, name: str) -> None:
        view = self.views.pop(name)
        if view.acc is not None:
            view.acc.release()

    # ---- one frame -----------------------------------------------------------------------------
    def probes_ready(self) -> bool:
        return self.renderer.probe_grid is not None and self.renderer.probes_current()

    def shown_method(self, method: str) -> str:
        """What a view of `method` renders now: the raymarcher while a probe-lit method's probes
        bake (PREVIEW_WHILE_BAKING), else the method itself."""
        r = self.renderer
        if method in PROBE_LIGHTING and r.probe_grid is not None and not r.probes_current():
            return PREVIEW_WHILE_BAKING
        return method

    def step(self, max_samples: int, want_probes: bool) -> FrameTimes:
        """One bake slice of `bake_budget_ms` GPU time (while the probes are stale; a whole bake
        never blocks a frame), then samples for every unfinished view: as many as the rest of
        `frame_budget_ms` holds, shared between the views, at least one each. The views that read
        probes restart after every slice, from the probes as they are then; a probe-lit view
        shows the raymarcher until the bake is done."""
        times = FrameTimes()
        r = self.renderer
        if want_probes and not r.probes_current():
            starting = r.probe_grid is None or r._baked_key != r.bake_key()
            passes = None if starting else r.probe_grid.passes_done
            times.bake_ms = r.bake_step(self.seed, budget_ms=self.bake_budget_ms)
            if starting:
                self.bake_ms = 0.0
                self.bake_generation += 1
            self.bake_ms += times.bake_ms
            self.bake_passes_run += 1
            if r.probe_grid.passes_done not in (0, passes):   # a pass ended: its progress
                self.bake_report = r.probe_grid.progress_report()
            self.restart([m for m in self.views if r.needs_probes(m)])
        # a view whose preview is over (the bake ended, or was never needed) starts its own method
        stale = [v.method for v in self.views.values() if v.shown != self.shown_method(v.method)]
        if stale:
            self.restart(stale)
        todo = [v for v in self.views.values() if v.acc is not None and v.acc.samples < max_samples
                and not (r.needs_probes(v.shown) and r.probe_grid is None)]  # nothing to read yet
        share = max(self.frame_budget_ms - times.bake_ms, 0.0) / max(len(todo), 1)
        for view in todo:
            n = min(self.samples_per_frame(view, share), max_samples - view.acc.samples)
            ms = self._add_samples(view, n)
            recent = view.dispatch_ms.setdefault(view.shown, [])
            recent.append((n, ms))
            del recent[:-RECENT_DISPATCHES]
            times.render_ms += ms
            times.samples += n
        self.last = times
        return times

    @staticmethod
    def samples_per_frame(view: MethodView, budget_ms: float) -> int:
        """Samples per pixel for the view's next dispatch: as many as fit in `budget_ms` at the GPU
        ms per sample of its recent dispatches (the median of ms / samples over the last
        RECENT_DISPATCHES), at least one; one before any is timed. The median keeps a dispatch
        that paid for a shader compile (about 0.3 s on llvmpipe) from setting the pace, and
        ms / samples counts a dispatch's fixed cost in, so the estimate errs towards fewer samples.
        (An earlier model fitted a fixed cost plus a per-sample cost to the dispatches of the two
        largest sample counts, for the 25 ms tail one `probes` dispatch had on an H100 at 1080p
        while its path states were cleared from the host; a compile in a trial dispatch read as
        such a tail, and the llvmpipe replay then ran frames of 16 samples at 70 to 120 ms against
        a 45 ms budget.)"""
        recent = view.dispatch_ms.get(view.shown)
        if not recent:
            return 1
        per = statistics.median(ms / n for n, ms in recent)
        if per <= 0.0:
            return MAX_SAMPLES_PER_FRAME
        return int(max(1, min(MAX_SAMPLES_PER_FRAME, budget_ms // per)))

    def _add_samples(self, view: MethodView, n: int) -> float:
        r = self.renderer
        r._acc, r.method, r.camera, r.seed = view.acc, view.shown, view.camera, self.seed
        try:
            return r.add_samples(n)
        finally:
            r._acc = None

    def record_frame(self, times: FrameTimes) -> None:
        self.history.append(times.total_ms)

    def finished(self, max_samples: int, want_probes: bool) -> bool:
        """True when another step would do nothing (the viewer may then wait for events)."""
        if want_probes and not self.renderer.probes_current():
            return False
        if any(v.shown != self.shown_method(v.method) for v in self.views.values()):
            return False
        return all(v.acc is None or v.acc.samples >= max_samples
                   or (self.renderer.needs_probes(v.method) and self.renderer.probe_grid is None)
                   for v in self.views.values())

    # ---- reading -------------------------------------------------------------------------------
    def texture(self, method: str):
        view = self.views.get(method)
        return None if view is None or view.acc is None else view.acc.texture

    def samples(self, method: str) -> int:
        view = self.views.get(method)
        return 0 if view is None else view.samples

    def label(self, method: str) -> str:
        """A view's caption: its method and samples, and the preview it shows while baking."""
        view = self.views.get(method)
        shown = method if view is None else view.shown
        extra = "" if shown == method else f" (bake {self._bake_percent()}%: {shown} meanwhile)"
        return f"{method}  {self.samples(method)} spp{extra}"

    def _bake_percent(self) -> int:
        g = self.renderer.probe_grid
        if g is None:
            return 0
        total = g.passes_total * g.count
        return int(100 * (total - g.probes_left) / max(total, 1))

    def image(self, method: str) -> np.ndarray | None:
        """The linear RGB image of a shown method, (H, W, 3), row 0 at the top."""
        view = self.views.get(method)
        return None if view is None or view.acc is None else view.acc.read()

    def set_filter(self, linear: bool) -> None:
        self.filter = moderngl.LINEAR if linear else moderngl.NEAREST
        for view in self.views.values():
            if view.acc is not None:
                view.acc.texture.filter = (self.filter, self.filter)

    def release(self) -> None:
        for name in list(self.views):
            self._drop(name)
        self.renderer.release()

