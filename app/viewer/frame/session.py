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
Where GPU timestamps cannot be believed (a software renderer; a GPU whose timestamps stay far
below the wall clock) the renderer's timer becomes the wall clock and a frame's work gets what
WALL_FRAME_MS leaves after the rest of the frame (app/viewer/frame/pacing.py); a sample longer than
that goes in bands over frames, and the bake and a banded view that reads the probes take turns
(BAKE_TURN_RATIO), so no sample mixes two states of the probes.

`refine` (RefineView) is two renderers in one view: after any edit the raymarcher's image shows
at once; once the probes are current, `guided` samples accumulate beside it in two independent
halves (app/rendering/refine/refine.py), and the view switches to their mean when its error, estimated from
the halves, falls below the raymarcher's, estimated against that same unbiased mean. `guided`
waits for the bake: its two levels must read the same probes for the whole accumulation."""
from __future__ import annotations

import math
import statistics
import time
from collections import deque

import moderngl
import numpy as np

from radiance_probes.gl.context import is_software
from radiance_probes.gl.timer import WallTimer
from radiance_probes.viewer.frame.frame_spans import FrameSpans
from radiance_probes.rendering.budgets.frame_budget import BAKE_BUDGET_MS, FRAME_BUDGET_MS
from radiance_probes.rendering.probes.bake import BakeProgress
from radiance_probes.methods import METHODS
from radiance_probes.rendering.refine.refine import (REFINE_HALF_SEED, REFINE_MIN_HALF_SAMPLES,
                                                     REFINE_RAYMARCH_FRAMES, HalfBuffers,
                                                     RefineBlend)
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.budgets.sample_bands import TileCosts, fill_frame, tile_grid
from radiance_probes.io.scene_file import Scene
from radiance_probes.io.volume import Volume
from radiance_probes.viewer.frame.denoise_view import ViewDenoise
from radiance_probes.viewer.frame.frame_parts import FrameParts
from radiance_probes.viewer.frame.pacing import FramePacer
from radiance_probes.viewer.frame.refine_judgement import (advance_check, begin_check,
                                                           prepare_staging)
from radiance_probes.viewer.frame.views import (RECENT_DISPATCHES, FrameTimes, MethodView, REFINE,
                                                REFINE_HISTORY, RefineView, _PacedView)


FRAME_HISTORY = 240


MAX_SAMPLES_PER_FRAME = 64


# What a probe-lit method shows while its probes bake: the raymarcher over the probes as they are.
PREVIEW_WHILE_BAKING = "raymarch"


# `refine`: a reduction of the halves' error (a 16-byte read-back) whenever guided's samples
# double and at least every REFINE_CHECK_FRAMES frames with guided samples (about 4 a second at
# 60 Hz), never every frame; the raymarcher's frames, the guided samples a half needs before its
# estimate may switch the view and the second half's seed are app/rendering/refine/refine.py's (a still
# image of refine shares them).
REFINE_CHECK_FRAMES = 16


# refine judges its blend when guided's samples have grown 2^JUDGE_STAGES times since the last
# judgement (_judge_due).
JUDGE_STAGES = 2
# Paced by the wall clock, a bake slice never lands inside a banded sample of a view that reads the
# probes (its bands would read two states of the probes: the seam of issue 55); the bake and such
# a view take turns instead, the bake this many times the wall time of the view's last whole
# sample before the next begins: the share of a frame the budgets give each (50 ms of 65).
BAKE_TURN_RATIO = BAKE_BUDGET_MS["software"] / (FRAME_BUDGET_MS["software"]
                                                - BAKE_BUDGET_MS["software"])


def paced_ms_per_sample(rates: list[float]) -> float:
    """The GPU ms per sample a frame's samples are counted by, from its recent dispatches: the
    second largest where there are three or more (one dispatch that paid for a shader compile
    does not set the pace, and the frame is planned for the slow end of what the view costs, not
    its middle: on the H200 the median let refine's guided run two samples, 34 ms, in a frame of
    14), else the largest."""
    ordered = sorted(rates)
    return ordered[-2] if len(ordered) >= 3 else ordered[-1]


class RenderSession:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None,
                 seed: int = 0, renderer: Renderer | None = None, settings=None,
                 clock: str | None = None, lab=None):
        """`renderer`: one to drive instead of a new one (the interact benchmark's replay);
        `settings`: the new one's RenderSettings (None: the defaults); `lab`: its LabOptions
        (tests and the bench only; None: the product's); `clock`: "gpu" or "wall" to pace by that
        clock always (None: by the device, app/viewer/frame/pacing.py)."""
        self.ctx = ctx
        self.renderer = (renderer if renderer is not None else
                         Renderer(ctx, scene, volume, settings=settings, lab=lab))
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
        # Denoise: on by default on a GPU; on a CPU rasteriser the filter (OIDN's CPU device)
        # takes as long as several frames, so it waits to be switched on
        self.denoise = ViewDenoise(ctx, enabled=device == "gpu")
        self.parts = FrameParts(ctx)      # the frame's parts, GPU and wall time
        # the bake takes the frame but one preview sample while every view restarts after its
        # slices (_bake_budget); the viewer and the interact replay turn it on
        self.bake_fills_frame = False
        self.denoise.parts = self.parts
        self._refine_ms = 0.0   # wall ms of refine's checks and judgements this frame
        self.pacer = FramePacer(device == "software", ctx.info.get("GL_RENDERER", ""), clock)
        self._frame_began: float | None = None   # when the last working frame's step began
        self._bake_turn_ms = 0.0   # wall ms of bake slices before a banded probe view's next sample
        self._baked_this_frame = False   # step(): this frame ran a bake slice
        # the frame's timed blocks read once at its end (DeferredSpans; by the GPU's clock only)
        self.frame_spans = FrameSpans(ctx)
        if self.pacer.wall:
            self._use_wall_clock()

    def _use_wall_clock(self) -> None:
        """The renderer's timer becomes the wall clock (bake slices and samples timed by it)."""
        r = self.renderer
        if not isinstance(r.timer, WallTimer):
            r.timer = WallTimer(self.ctx, replaces=r.timer)

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
    def set_scene(self, scene: Scene, volume: Volume | None = None, placed=None) -> set[str]:
        """Adopts an edited scene; restarts the accumulations when anything visible changed.
        `placed`: `volume` already placed (app/rendering/levels/progressive_open.py)."""
        if scene is self.renderer.scene and volume is None:
            return set()
        changed = self.renderer.set_scene(scene, volume, placed)
        if changed:
            self.restart(wait=changed == {"camera"})
        return changed

    def restream(self, camera, budget_s: float | None = None) -> bool:
        """Moves a mixed pool towards the bricks `camera` deserves (Renderer.restream, with a
        budget of seconds of writes); restarts the accumulations when the medium changed."""
        changed = self.renderer.restream(camera, budget_s)
        if changed:
            self.restart()
        return changed

    def set_methods(self, methods: list[str]) -> None:
        for name in [m for m in self.views if m not in methods]:
            self._drop(name)
        for name in methods:
            if name not in self.views:
                self.views[name] = RefineView(name) if name == REFINE else MethodView(name)
                self._begin(self.views[name])

    def resize(self, width: int, height: int) -> None:
        size = (max(int(width), 1), max(int(height), 1))
        if size != self.size:
            self.size = size
            self.denoise.warm(*size)   # OIDN's first use, on the filter's thread
            self.restart()

    def restart(self, methods=None, wait: bool = False) -> None:
        """Begins the views (of `methods`; None: all) afresh. `wait`: a restart that may wait
        for a first sample part done in bands (_begin): a camera move, a bake slice's probes."""
        for view in self.views.values():
            if methods is None or view.method in methods:
                self._begin(view, wait)
        self.restarts += 1

    def _begin(self, view: MethodView, wait: bool = False) -> None:
        """The view's accumulation afresh, with the scene's camera. Paced by the wall clock, the
        image it held with a sample at least is kept to show until the new first sample is whole
        (two accumulations swap, nothing is copied); and where the restart may `wait` (a camera
        move, the probes of another bake slice), a first sample part done finishes first
        (restart_pending: step() begins the view again once it is whole), with its own camera
        and the probes as they come: otherwise a drag, which moves the camera every frame, or a
        bake, which restarts the views that read probes every frame, would never see a sample
        of the picture whole. (A bake slice itself waits for a banded sample that reads the
        probes, step(): the bands of one sample read one state of the probes.)"""
        if self.size == (0, 0):
            return
        if isinstance(view, RefineView):
            return self._begin_refine(view)
        r = self.renderer
        acc = view.acc
        view.restart_pending = False
        if self.pacer.wall and acc is not None and (acc.width, acc.height) == self.size:
            if (wait and acc.samples == 0 and acc.groups_done > 0
                    and view.shown == self.shown_method(view.method)):
                view.restart_pending = True
                return
            if acc.samples > 0:
                view.held, acc = acc, view.held   # the whole image shows; the other is begun
        elif view.held is not None:
            view.held.release()
            view.held = None
        view.shown = self.shown_method(view.method)
        with r.lend(acc):   # the Renderer keeps one accumulation; each view lends it its own
            view.acc = r.begin(view.shown, *self.size, seed=self.seed)
            view.camera = r.camera
        view.acc.texture.filter = (self.filter, self.filter)

    def _begin_refine(self, view: RefineView) -> None:
        """Both of refine's renderers afresh: the raymarcher's image is what shows."""
        r = self.renderer
        with r.lend(view.ray):
            view.ray = r.begin("raymarch", *self.size, seed=self.seed)
            view.camera = r.camera
        w, h = view.camera.width, view.camera.height
        if view.halves is None or (view.halves.width, view.halves.height) != (w, h):
            if view.halves is not None:
                view.halves.release()
            view.halves = HalfBuffers(self.ctx, w, h)
            prepare_staging(self, view)
        view.halves.reset()
        for acc in (view.ray, view.halves.combined):
            acc.texture.filter = (self.filter, self.filter)
        view.shown = "raymarch"
        view.estimate, view.switched_at = None, None
        view.frames_since_check, view.checked_stage = 0, 0
        view.judged_stage, view.blend, view.weight = 0, None, 1.0
        view.frames, view.shown_frames = 0, []
        if view.check is not None:   # a check of the images before: its results unwanted
            view.drop_check()
            self.denoise.drop_job(f"{view.method}:judge")

    def _drop(self, name: str) -> None:
        view = self.views.pop(name)
        if isinstance(view, RefineView):
            view.release()
            return
        for acc in (view.acc, view.held):
            if acc is not None:
                acc.release()

    # ---- one frame -----------------------------------------------------------------------------
    def probes_ready(self) -> bool:
        return self.renderer.probe_grid is not None and self.renderer.probes_current()

    def needs_probes(self, method: str) -> bool:
        """Whether a view of `method` reads the probes (refine: its raymarcher and `guided` do)."""
        return METHODS[method].needs_probes

    def shown_method(self, method: str) -> str:
        """What a view of `method` renders now: the raymarcher while a probe-lit method's probes
        bake (PREVIEW_WHILE_BAKING), else the method itself."""
        r = self.renderer
        if METHODS[method].probe_lighting and r.probe_grid is not None and not r.probes_current():
            return PREVIEW_WHILE_BAKING
        return method

    def step(self, max_samples: int, want_probes: bool) -> FrameTimes:
        """One bake slice of `bake_budget_ms` GPU time (while the probes are stale; a whole bake
        never blocks a frame), then samples for every unfinished view: as many as the rest of
        `frame_budget_ms` holds, shared between the views, at least one each. The views that read
        probes restart after every slice, from the probes as they are then; a probe-lit view
        shows the raymarcher until the bake is done."""
        times = FrameTimes(clock=self.pacer.clock)
        try:
            self.renderer.deferred = None if self.pacer.wall else self.frame_spans.spans
            self._step(times, max_samples, want_probes)
        finally:
            self.renderer.deferred = None
        bake = self.frame_spans.resolve(times, self.parts)
        self.bake_ms += bake
        self._bake_turn_ms -= bake
        self.last = times
        return times

    def _step(self, times: FrameTimes, max_samples: int, want_probes: bool) -> None:
        self.parts.gpu = not self.pacer.wall   # timestamps believed: the parts' GPU ms too
        times.parts = self.parts.begin_frame()
        self.denoise.budget.begin_frame()   # the frame's host transfers (fence.TransferBudget)
        r = self.renderer
        budget = self.pacer.work_budget_ms(self.frame_budget_ms)
        baking = want_probes and not r.probes_current()
        self._baked_this_frame = False
        if baking and not any(self._reads_probes_in_bands(v) and v.acc.groups_done
                              for v in self.views.values()):   # (else the bake waits its turn)
            starting = not r.bake_started_for_scene()
            passes = None if starting else r.probe_grid.passes_done
            t = time.perf_counter()
            with self.frame_spans.tagged("bake"):
                times.bake_ms = r.bake_step(self.seed, budget_ms=self._bake_budget(budget))
            self._baked_this_frame = True
            self.parts.add("bake", 1e3 * (time.perf_counter() - t),
                           None if self.pacer.wall else times.bake_ms)
            if starting:
                self.bake_ms = 0.0
                self._bake_turn_ms = 0.0   # a first preview of the new bake soon
                self.bake_generation += 1
                with self.parts.part("prepare", gpu=False):   # (the probes' layout now known)
                    for view in self.views.values():   # what runs once they are baked
                        if isinstance(view, RefineView):
                            r.prepare("guided", *self.size, slots=(0, 1))
                        elif self.needs_probes(view.method):
                            r.prepare(view.method, *self.size)
            self.bake_ms += times.bake_ms
            self._bake_turn_ms -= times.bake_ms
            self.bake_passes_run += 1
            if r.probe_grid.passes_done not in (0, passes):   # a pass ended: its progress
                self.bake_report = r.probe_grid.progress_report()
            self.restart([m for m in self.views if self.needs_probes(m)], wait=True)
        # a view whose preview is over (the bake ended, or was never needed) starts its own method
        stale = [v.method for v in self.views.values() if not isinstance(v, RefineView)
                 and v.shown != self.shown_method(v.method)]
        if stale:
            self.restart(stale)
        todo = [v for v in self.views.values() if v.acc is not None
                and not (r.needs_probes(v.shown) and r.probe_grid is None)   # nothing to read yet
                and (not self._refine_done(v, max_samples) if isinstance(v, RefineView)
                     else v.acc.samples < max_samples)
                and not (baking and self._waits_for_bake(v))]
        share = max(budget - times.bake_ms, 0.0) / max(len(todo), 1)
        self._refine_ms = 0.0
        t_work = time.perf_counter()
        for view in todo:
            if isinstance(view, RefineView):
                ms, n = self._step_refine(view, share, max_samples)
                times.render_ms += ms
                times.samples += n
                continue
            if self.banded(view):
                ms, n, tiles, bands = self._add_paced(view, share, max_samples)
                if (baking and n and view.acc.groups_done == 0
                        and self._reads_probes_in_bands(view)):   # whole: the bake's turn
                    whole_ms = view.tile_costs[view.shown].sample_ms() or 0.0
                    self._bake_turn_ms = BAKE_TURN_RATIO * whole_ms
                times.render_ms += ms
                times.samples += n
                times.tiles += tiles
                times.bands += bands
                continue
            n = min(self.samples_per_frame(view, share), max_samples - view.acc.samples)
            with self.frame_spans.tagged(self.frame_spans.sample_tag()) as tag:
                ms = self._add_samples(view, n)
            self._note_dispatch(view, view.shown, n, ms, tag)
            times.render_ms += ms
            times.samples += n
        # the samples' wall ms: the views' work less refine's combines and checks (their own parts)
        self.parts.add("samples", 1e3 * (time.perf_counter() - t_work) - self._refine_ms,
                       None if self.pacer.wall else times.render_ms)
        times.denoise_ms = self.denoise.update(self) + self._refine_ms
        times.filter_ms = self.denoise.filter_ms

    def _bake_budget(self, budget: float) -> float:
        """The bake's slice of a frame whose work may take `budget`: bake_budget_ms; and where
        `bake_fills_frame` is on and every view shown restarts after the slice (it reads the
        probes: its samples beyond the first are thrown away a frame later), all of the frame
        but one sample of each view's preview at its recent cost (issue 56: a load's bake ends
        sooner, so guided starts sooner)."""
        base = min(self.bake_budget_ms, budget)
        views = [v for v in self.views.values() if v.acc is not None]
        if not self.bake_fills_frame or not views or not all(
                self.needs_probes(v.method) for v in views):
            return base
        keep = 0.0
        for view in views:
            recent = view.dispatch_ms.get("raymarch" if isinstance(view, RefineView)
                                          else view.shown)
            if not recent:
                return base          # a preview not yet timed: the slice as ever
            keep += statistics.median(ms / n for n, ms in recent)
        return max(base, budget - keep)

    def _reads_probes_in_bands(self, view) -> bool:
        """A view whose samples go in bands over frames and read the probes."""
        return (not isinstance(view, RefineView) and view.acc is not None and self.banded(view)
                and self.renderer.needs_probes(view.shown))

    def _waits_for_bake(self, view) -> bool:
        """While the probes bake: a banded view that reads them and has a whole image to show
        begins its next sample only once the bake has had its turn (BAKE_TURN_RATIO)."""
        return (self._bake_turn_ms > 0.0 and self._reads_probes_in_bands(view)
                and view.acc.groups_done == 0 and view.held is not None)

    def shows_whole(self, method: str) -> bool:
        """Whether the display shows a whole image of the view: the last whole image while a
        first sample is in bands, or an accumulation with a sample at least (every pixel a
        mean of whole samples; a sample in bands adds one to some pixels' means). False while
        the view's first sample is part done and it has no whole image before it."""
        view = self.views.get(method)
        if view is None or isinstance(view, RefineView):
            return view is None or view.acc is not None   # refine's samples are whole
        return view.acc is not None and (view.shows_held or view.acc.samples > 0)

    def part_done(self, method: str) -> float:
        """The fraction of the sample in bands of a view (0 where none is)."""
        view = self.views.get(method)
        acc = None if view is None or isinstance(view, RefineView) else view.acc
        if acc is None or not acc.groups_done:
            return 0.0
        return acc.groups_done / math.prod(tile_grid(acc.width, acc.height))

    def banded(self, view: MethodView) -> bool:
        """Whether the view's samples may be split into bands over frames: paced by the
        wall clock (where a GPU's timestamps are believed, whole samples as before), and a
        method whose pixels are each its own running mean (Renderer.can_band)."""
        return self.pacer.wall and self.renderer.can_band(view.shown)

    def _add_paced(self, view: MethodView, budget_ms: float,
                   max_samples: int) -> tuple[float, int, int, int]:
        """A frame's work for a banded view within `budget_ms` of wall time: whole samples where
        they fit, else bands of the sample in progress, as sample_bands.next_work says from the
        tiles' times so far. Where a restart waits for the first sample (restart_pending), the
        view is begun again as soon as that sample is whole. Returns (ms, whole samples
        finished, tiles dispatched in bands, bands)."""
        acc = view.acc
        grid = tile_grid(acc.width, acc.height)
        costs = view.tile_costs.get(view.shown)
        if costs is None or (costs.tiles_x, costs.tiles_y) != grid:
            costs = view.tile_costs[view.shown] = TileCosts(*grid)
        done = fill_frame(_PacedView(self, view), costs, budget_ms, max_samples,
                          MAX_SAMPLES_PER_FRAME, stop=lambda: view.restart_pending
                          and acc.samples > 0)
        if view.restart_pending and acc.samples > 0:
            self._begin(view)
        return done.ms, done.samples, done.tiles, done.bands

    @staticmethod
    def samples_per_frame(view: MethodView, budget_ms: float, shown: str | None = None) -> int:
        """Samples per pixel for the view's next dispatch: as many as fit in `budget_ms` at the GPU
        ms per sample of its recent dispatches (the second largest of ms / samples over the last
        RECENT_DISPATCHES, paced_ms_per_sample), at least one; one before any is timed. That keeps a
        dispatch that paid for a shader compile (about 0.3 s on llvmpipe) from setting the pace, and
        ms / samples counts a dispatch's fixed cost in, so the estimate errs towards fewer samples.
        (An earlier model fitted a fixed cost plus a per-sample cost to the dispatches of the two
        largest sample counts, for the 25 ms tail one `probes` dispatch had on an H100 at 1080p
        while its path states were cleared from the host; a compile in a trial dispatch read as
        such a tail, and the llvmpipe replay then ran frames of 16 samples at 70 to 120 ms against
        a 45 ms budget.)"""
        recent = view.dispatch_ms.get(shown or view.shown)
        if not recent:
            return 1
        per = paced_ms_per_sample([ms / n for n, ms in recent])
        if per <= 0.0:
            return MAX_SAMPLES_PER_FRAME
        return int(max(1, min(MAX_SAMPLES_PER_FRAME, budget_ms // per)))

    def _refine_done(self, view: RefineView, max_samples: int) -> bool:
        """Nothing left for refine: probes current, guided at max_samples, and the raymarcher
        either replaced or at its last frame."""
        return (self.renderer.probes_current() and view.guided_samples >= max_samples
                and view.check is None
                and (view.shown == "guided"
                     or (view.ray.samples >= min(REFINE_RAYMARCH_FRAMES, max_samples)
                         and not self._check_pending(view))))

    def _check_pending(self, view: RefineView) -> bool:
        """Guided samples since the last check while the raymarcher is shown (or blended in)."""
        return ((view.shown == "raymarch" or view.blending) and view.guided_samples > 0
                and view.frames_since_check > 0 and self.renderer.probes_current())

    def _step_refine(self, view: RefineView, budget_ms: float, max_samples: int) -> tuple[float, int]:
        """One frame of refine within `budget_ms`: first a step of the check under way
        (_collect_refine: its sums, filter or judgement, whichever has come back; never a wait);
        raymarched frames while the raymarcher is shown and short of REFINE_RAYMARCH_FRAMES;
        `guided` samples once the probes are current (half the budget each while both run; at
        least one sample each), split between the halves (the emptier first), then the halves
        combined on the GPU and, at a check, their sums' read-back begun (refine_judgement: the
        view switches to guided once they show its estimate below the raymarcher's); with the
        Denoise switch on, the blend judged instead (once a 4x growth), guided shown from a
        weight above 0. The frame of a restart (any edit) always shows the raymarcher: guided may
        take over from a later frame on. Returns GPU ms and samples per pixel dispatched."""
        self._collect_refine(view)
        r = self.renderer
        view.frames += 1
        ray_cap = min(REFINE_RAYMARCH_FRAMES, max_samples)
        ray_todo = (view.shown == "raymarch" or view.blending) and view.ray.samples < ray_cap
        # (not in a frame that ran a bake slice: guided's first sample pays a whole level-0
        # frame, 20 ms at 1080p on the H200, which on top of the slice made the frame's longest)
        guided_todo = (r.probes_current() and view.guided_samples < max_samples
                       and not self._baked_this_frame)
        share = budget_ms / 2 if ray_todo and guided_todo else budget_ms
        ms_total, n_total = 0.0, 0
        if ray_todo:
            n = min(self.samples_per_frame(view, share, "raymarch"), ray_cap - view.ray.samples)
            with self.frame_spans.tagged(self.frame_spans.sample_tag()) as tag:
                ms = self._lend(view.ray, None, "raymarch", view.camera, self.seed, 0, n)
            self._note_dispatch(view, "raymarch", n, ms, tag)
            ms_total, n_total = ms_total + ms, n_total + n
        halves = view.halves
        n, ms = 0, 0.0
        if guided_todo:
            n = min(self.samples_per_frame(view, share, "guided"), max_samples - halves.samples)
            first = halves.next_half()
            with self.frame_spans.tagged(self.frame_spans.sample_tag()) as tag:
                for index, k in ((first, (n + 1) // 2), (1 - first, n // 2)):
                    if k:
                        half = halves.halves[index]
                        seed = self.seed ^ (REFINE_HALF_SEED if index else 0)
                        ms += self._lend(half.residual, half.level0, "guided", view.camera,
                                         seed, index, k)
            self._note_dispatch(view, "guided", n, ms, tag)
            view.frames_since_check += 1
            stage = halves.samples.bit_length()
            check = (stage != view.checked_stage or view.frames_since_check >= REFINE_CHECK_FRAMES
                     or halves.samples >= max_samples)
        elif self._check_pending(view):   # guided has stopped: its last samples not yet judged
            stage, check = halves.samples.bit_length(), True
        else:
            self._note_shown(view)
            return ms_total, n_total
        check = check and view.frames > 1   # an edit's own frame shows the raymarcher
        if view.blending and not self.denoise.enabled:   # the switch went off: no blend to show
            view.shown, view.weight = "raymarch", 1.0
        with_ray = view.shown == "raymarch" or view.blending
        # one check under way at a time: its sums come back on a later frame (refine_judgement)
        check = check and view.check is None
        judgeable = (check and with_ray and view.frames > 1
                     and min(halves.counts) >= REFINE_MIN_HALF_SAMPLES)
        judge = judgeable and self._judge_due(view, stage)
        t = time.perf_counter()
        with self.parts.part("combine"):
            # a judgement's half A written by the check's own combine, its sums read once
            halves.combine(view.ray if with_ray else None, reduce=check, write_half_a=judge)
            if check:
                if judge:
                    view.judged_stage = halves.samples.bit_length()
                view.check = begin_check(self, view, with_ray, judgeable, judge, stage)
                view.frames_since_check, view.checked_stage = 0, stage
        self._refine_ms += 1e3 * (time.perf_counter() - t)
        self._note_shown(view)
        return ms_total + ms, n_total + n

    def _collect_refine(self, view: RefineView) -> None:
        """The check under way (refine_judgement.advance_check), one step, never waiting: its
        sums, once in, give the estimate and (without a judgement) the raw switch; a judgement,
        once done, the blend and the weight shown."""
        check = view.check
        if check is None:
            return
        t = time.perf_counter()
        with self.parts.part("judgement", gpu=False):
            state, value = advance_check(self, view, check)
        if state == "sums":
            view.estimate = view.halves.estimate_from(value, check.with_ray)
            est = view.estimate
            if check.judgeable and not check.judge and view.shown == "raymarch" \
                    and est.guided < est.raymarch:   # (NaN: False)
                view.shown, view.weight = "guided", 1.0
                view.switched_at = view.halves.samples
        elif state == "judged":
            self._apply_judgement(view, value)
        if check.stage == "done":
            view.check = None
        self._refine_ms += 1e3 * (time.perf_counter() - t)

    def _judge_due(self, view: RefineView, stage: int) -> bool:
        """Whether to judge the blend at this check: where the Denoise switch is on (the view then
        shows guided denoised), at the first check that may, then each time guided's samples
        have grown 4x (JUDGE_STAGES): each judgement is a filter run (40-50 ms at 1080p on the
        H200 machine, bench/h200-interact-refine, now on the filter's thread), and the weight
        moves slowly (0.48, 0.58, 0.68, 0.77 at 8 to 64 samples on bonsai): between judgements
        the last one's stands."""
        return self.denoise.enabled and (view.judged_stage == 0
                                         or stage >= view.judged_stage + JUDGE_STAGES)

    def _apply_judgement(self, view: RefineView, blend: RefineBlend | None) -> None:
        """A judgement done (refine_judgement: half A filtered on the filter's thread, judged with
        the raymarcher's image against half B of its check): guided shown from a weight above 0,
        the weight following the judgement after; half A denoised stands for the view's
        filtered image until its next one. None (the filter could not run): nothing changes.
        Judging guided by its raw noise kept the raymarcher on screen for ever after some bonsai
        edits at 1080p; judging in the frame (the filter, its read-back, the sums) made hitches
        of 100 to 440 ms (bench/h200-interact-refine)."""
        if blend is None:
            return
        view.blend = blend
        if blend.weight > 0.0 and view.shown == "raymarch":
            view.shown, view.switched_at = "guided", view.halves.samples
        if view.shown == "guided":   # (a weight may fall again: the blend follows)
            view.weight = blend.weight
        if blend.weight > 0.0:
            self.denoise.adopt(view.method, view.halves, self.restarts)

    @staticmethod
    def _note_shown(view: RefineView) -> None:
        if len(view.shown_frames) < REFINE_HISTORY:
            view.shown_frames.append(view.shown)

    def _note_dispatch(self, view, shown: str, n: int, ms: float, tag=None) -> None:
        """n samples of `shown` took `ms` (an estimate where its spans are deferred: `tag`'s
        measured ms replace it at the frame's end)."""
        recent = view.dispatch_ms.setdefault(shown, [])
        entry = [n, ms]
        recent.append(entry)
        del recent[:-RECENT_DISPATCHES]
        if tag is not None:
            self.frame_spans.watch(tag, entry)

    def _lend(self, acc, acc0, method: str, camera, seed: int, slot: int, n: int) -> float:
        """n samples of `method` into accumulations the Renderer borrows for the call (acc0:
        guided's level 0; slot: the path states of refine's half)."""
        with self.renderer.lend(acc, method, camera, seed, level0=acc0, slot=slot) as r:
            return r.add_samples(n, level0_bands=True)

    def _add_samples(self, view: MethodView, n: int) -> float:
        """n samples into the view (guided's level 0 in bands over them, as in refine: no frame
        pays a whole level-0 frame but a view's first, app/rendering/methods/guided_level0.py)."""
        with self.renderer.lend(view.acc, view.shown, view.camera, self.seed) as r:
            return r.add_samples(n, level0_bands=True)

    def record_frame(self, times: FrameTimes) -> None:
        """A frame drawn: its times kept for the Stats panel, and (where it did work, and so did
        the frame before it) its whole wall time, from this step to the next, told to the pacer,
        which may stop believing the GPU's timestamps (the renderer's timer then becomes the wall
        clock)."""
        now = time.perf_counter()
        working = times.samples > 0 or times.tiles > 0 or times.bake_ms > 0
        if working and self._frame_began is not None:
            wall = 1000.0 * (now - self._frame_began)
            self.pacer.observe(wall, times.total_ms,
                               times.work_ms if times.clock == "wall" else None)
            if self.pacer.wall:
                self._use_wall_clock()
        self._frame_began = now if working else None
        times.frame_wall_ms = self.pacer.frame_ms
        self.history.append(self.pacer.frame_ms if self.pacer.wall and self.pacer.frame_ms
                            else times.total_ms)

    def finished(self, max_samples: int, want_probes: bool) -> bool:
        """True when another step would do nothing (the viewer may then wait for events)."""
        if want_probes and not self.renderer.probes_current():
            return False
        if any(v.shown != self.shown_method(v.method) for v in self.views.values()
               if not isinstance(v, RefineView)):
            return False
        return all(v.acc is None
                   or (self._refine_done(v, max_samples) if isinstance(v, RefineView)
                       else v.acc.samples >= max_samples)
                   or (self.needs_probes(v.method) and self.renderer.probe_grid is None)
                   for v in self.views.values())

    def view_done(self, method: str, target_spp: int) -> bool:
        """A view shows its own method's image with at least `target_spp` samples (refine:
        `guided`'s mean has replaced the raymarcher's image and holds that many)."""
        view = self.views.get(method)
        if view is None:
            return False
        if isinstance(view, RefineView):
            return view.shown == "guided" and view.guided_samples >= target_spp
        return view.shown == method and view.samples >= target_spp

    # ---- reading -------------------------------------------------------------------------------
    def texture(self, method: str):
        """What the display shows of a view: its filtered image where the Denoise switch has
        one for the current accumulation, else the accumulation."""
        view = self.views.get(method)
        if view is None or view.acc is None:
            return None
        if getattr(view, "shows_held", False):   # a first sample part done: the last whole image
            return view.held.texture
        return self.denoise.texture(method, view, self.restarts) or view.acc.texture

    def samples(self, method: str) -> int:
        view = self.views.get(method)
        return 0 if view is None else view.samples

    def label(self, method: str) -> str:
        """A view's caption: its method and samples, and the preview it shows while baking."""
        view = self.views.get(method)
        if isinstance(view, RefineView):
            return self._refine_label(view)
        shown = method if view is None else view.shown
        extra = "" if shown == method else f" (bake {self._bake_percent()}%: {shown} meanwhile)"
        acc = None if view is None else view.acc
        word = METHODS[shown].sample_word   # the raymarcher's samples are frames
        if acc is not None and acc.groups_done:   # a sample in bands over frames
            total = math.prod(tile_grid(acc.width, acc.height))
            part = (f"{100 * acc.groups_done // total}% of "
                    f"{'frame' if word == 'frames' else 'sample'} {acc.samples + 1}")
            extra += (f" ({part}; the last whole image meanwhile)" if view.shows_held
                      else f" ({part})")
        n = self.samples(method)
        return f"{method}  {n} {'frame' if (word, n) == ('frames', 1) else word}{extra}"

    def _refine_label(self, view: RefineView) -> str:
        """refine's caption: what it shows, and the errors estimated from guided's halves."""
        est = view.estimate

        def pct(x) -> str:
            return "?" if x is None or not math.isfinite(x) else f"{100 * x:.1f}%"
        guided = pct(None if est is None else est.guided)
        if view.blending:
            blend = pct(None if view.blend is None else view.blend.blend)
            return (f"{view.method}  guided {view.guided_samples} spp denoised, blended "
                    f"{100 * view.weight:.0f}% with the raymarcher: est. error {blend}")
        if view.shown == "guided":
            return f"{view.method}  guided {view.guided_samples} spp, est. error {guided}"
        text = f"{view.method}  raymarch {0 if view.ray is None else view.ray.samples} spp"
        if not self.renderer.probes_current():
            return f"{text} (bake {self._bake_percent()}%, then guided)"
        return (f"{text}, est. error {pct(None if est is None else est.raymarch)}; guided "
                f"{view.guided_samples} spp, est. {guided}")

    def refine_state(self, method: str = REFINE) -> dict | None:
        """What a refine view holds (for the viewer's snapshot and the benchmark)."""
        view = self.views.get(method)
        if not isinstance(view, RefineView):
            return None
        est = view.estimate
        return {"shown": view.shown, "raymarch_samples": 0 if view.ray is None else view.ray.samples,
                "guided_samples": view.guided_samples,
                "half_samples": [] if view.halves is None else list(view.halves.counts),
                "estimated_rrmse": None if est is None else
                {"guided": est.guided, "raymarch": est.raymarch, "samples": est.samples},
                "switched_at": view.switched_at, "frames": view.frames,
                "weight": view.weight if view.shown == "guided" else 0.0,
                "blend": None if view.blend is None else
                {"weight": view.blend.weight, "blend": view.blend.blend,
                 "denoised": view.blend.denoised, "raymarch": view.blend.raymarch},
                "shown_frames": list(view.shown_frames),
                "reads": 0 if view.halves is None else view.halves.reads}

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

    def shown_image(self, method: str) -> np.ndarray | None:
        """What the display shows of a view (texture()), as a linear RGB image (H, W, 3): its
        filtered image where the Denoise switch has one, else its accumulation."""
        view = self.views.get(method)
        if view is None or view.acc is None:
            return None
        if getattr(view, "shows_held", False):
            return view.held.read()
        texture = self.denoise.texture(method, view, self.restarts)
        if texture is None:
            return view.acc.read()
        w, h = texture.size
        rgba = np.frombuffer(texture.read(), np.float32).reshape(h, w, 4)   # (RGBA32F)
        return rgba[..., :3].copy()

    def set_filter(self, linear: bool) -> None:
        self.filter = moderngl.LINEAR if linear else moderngl.NEAREST
        for view in self.views.values():
            accs = ([view.ray, view.halves and view.halves.combined]
                    if isinstance(view, RefineView) else [view.acc, view.held])
            for acc in accs:
                if acc is not None:
                    acc.texture.filter = (self.filter, self.filter)

    def release(self) -> None:
        for name in list(self.views):
            self._drop(name)
        self.denoise.close()
        self.parts.release()
        self.renderer.release()
