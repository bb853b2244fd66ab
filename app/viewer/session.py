"""The viewer's progressive rendering: one Renderer (one copy of the scene on the GPU, one probe
grid) and one accumulation per shown method, advanced a little every frame.

Camera moves only restart the accumulations (the probes' bake key leaves the camera out); any
other scene change restarts them too and, where it touches the bake key, the bake. While probes
bake, each frame gives the bake a budget of GPU time (a slice of chunks of walks, never a whole
bake), and the methods that read probes restart after every slice, so the picture improves with
the probes as they come.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import moderngl
import numpy as np

from ..gl.context import is_software
from ..render.accumulation import Accumulation
from ..render.probes import BakeProgress
from ..render.renderer import Renderer
from ..scene import Scene
from ..volume import Volume

FRAME_HISTORY = 240
FRAME_BUDGET_MS = 15.0        # GPU time a frame may spend adding samples, per shown method
MAX_SAMPLES_PER_FRAME = 64
# GPU time a frame gives the bake (Renderer.bake_step predicts how many probes' walks fit from
# the slices it has timed, so the budget holds on any device): half a 60 Hz frame on a GPU; on
# llvmpipe, where a frame of the picture alone takes tens of ms, about as much again.
BAKE_BUDGET_MS = {"gpu": 8.0, "software": 50.0}


@dataclass
class MethodView:
    """One method's accumulation and the camera it was begun with."""
    method: str
    acc: Accumulation | None = None
    camera: object = None
    ms_per_sample: float = 0.0    # GPU time of one sample per pixel, as last measured

    @property
    def samples(self) -> int:
        return 0 if self.acc is None else self.acc.samples


@dataclass
class FrameTimes:
    """GPU milliseconds of one frame, from timestamp queries."""
    bake_ms: float = 0.0
    render_ms: float = 0.0
    display_ms: float = 0.0

    @property
    def total_ms(self) -> float:
        return self.bake_ms + self.render_ms + self.display_ms


class RenderSession:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None,
                 seed: int = 0):
        self.ctx = ctx
        self.renderer = Renderer(ctx, scene, volume)
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
        self.bake_budget_ms = BAKE_BUDGET_MS["software" if is_software(ctx) else "gpu"]

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
        r._acc = view.acc  # the Renderer keeps one accumulation; each view lends it its own
        view.acc = r.begin(view.method, *self.size, seed=self.seed)
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

    def step(self, max_samples: int, want_probes: bool) -> FrameTimes:
        """One bake slice of `bake_budget_ms` GPU time (while the probes are stale; a whole bake
        never blocks a frame) and samples for every unfinished view: as many as fit in
        FRAME_BUDGET_MS of GPU time. The views that read probes restart after every slice, from
        the probes as they are then."""
        times = FrameTimes()
        r = self.renderer
        if want_probes and not r.probes_current():
            starting = r.probe_grid is None or r._baked_key != r.bake_key()
            times.bake_ms = r.bake_step(self.seed, budget_ms=self.bake_budget_ms)
            if starting:
                self.bake_ms = 0.0
                self.bake_generation += 1
            self.bake_ms += times.bake_ms
            self.bake_passes_run += 1
            if r.probe_grid.next_probe == 0:   # a pass ended: its progress is readable
                self.bake_report = r.probe_grid.progress_report()
            self.restart([m for m in self.views if r.needs_probes(m)])
        for view in self.views.values():
            if view.acc is None or view.acc.samples >= max_samples:
                continue
            if r.needs_probes(view.method) and r.probe_grid is None:
                continue  # nothing to read yet: the first bake pass comes first
            n = min(self.samples_per_frame(view), max_samples - view.acc.samples)
            ms = self._add_samples(view, n)
            view.ms_per_sample = ms / n
            times.render_ms += ms
        self.last = times
        return times

    @staticmethod
    def samples_per_frame(view: MethodView) -> int:
        if view.ms_per_sample <= 0.0:
            return 1
        return int(max(1, min(MAX_SAMPLES_PER_FRAME, FRAME_BUDGET_MS // view.ms_per_sample)))

    def _add_samples(self, view: MethodView, n: int) -> float:
        r = self.renderer
        r._acc, r.method, r.camera, r.seed = view.acc, view.method, view.camera, self.seed
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

