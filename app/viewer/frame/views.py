"""What a session shows: a method's view (its accumulation, its shown image held while a restart
refills it), refine's view (two halves of `guided`, the raymarcher's image, the check and the
blend in flight), a frame's times, and the pacing's view of a method."""
from __future__ import annotations

from dataclasses import dataclass

from radiance_probes.gl.fence import HostArrays
from radiance_probes.rendering.methods.accumulation import Accumulation
from radiance_probes.rendering.refine.refine import HalfBuffers, RefineBlend, RefineEstimate
from radiance_probes.viewer.frame.refine_judgement import RefineCheck


REFINE = "refine"


REFINE_HISTORY = 64     # frames after a restart whose shown image a refine view remembers (tests)
RECENT_DISPATCHES = 5    # dispatches whose GPU ms per sample set the next frame's samples


@dataclass
class MethodView:
    """One method's accumulation and the camera it was begun with."""
    method: str
    acc: Accumulation | None = None
    camera: object = None
    shown: str = ""               # what the accumulation holds: method, or the bake's preview
    # the last RECENT_DISPATCHES dispatches per method shown: {method: [(samples, GPU ms), ...]}
    dispatch_ms: dict = None
    # Paced by the wall clock, a sample may take several frames in bands of work groups
    # (sample_bands.py): the wall ms of its tiles per method shown ({method: TileCosts}); the last
    # whole image (the accumulation before the last restart, with a sample at least), shown while
    # the new accumulation's first sample is part done; and a camera move that waits for that
    # first sample to be whole (a drag then shows whole images of the cameras it passes).
    tile_costs: dict = None
    held: Accumulation | None = None
    restart_pending: bool = False

    def __post_init__(self):
        self.shown = self.shown or self.method
        self.dispatch_ms = {} if self.dispatch_ms is None else self.dispatch_ms
        self.tile_costs = {} if self.tile_costs is None else self.tile_costs

    @property
    def shows_held(self) -> bool:
        """Whether the display shows the last whole image (the first sample is part done)."""
        return self.held is not None and self.acc is not None and self.acc.samples == 0

    @property
    def samples(self) -> int:
        return 0 if self.acc is None else self.acc.samples


class RefineView:
    """The `refine` view: the raymarcher's accumulation (`ray`), `guided`'s two halves and their
    mean (`halves`), and which of the two the display shows (`shown`: "raymarch" or "guided").
    With the Denoise switch on, "guided" is blended with the raymarcher's image by `weight` (of
    guided denoised; 1: guided alone), as the last judgement (refine.judged_blend) estimated."""

    def __init__(self, method: str = REFINE):
        self.method = method
        self.ray: Accumulation | None = None
        self.halves: HalfBuffers | None = None
        self.camera = None
        self.shown = "raymarch"
        self.dispatch_ms: dict = {}
        self.estimate: RefineEstimate | None = None   # the last check's
        self.frames_since_check = 0
        self.checked_stage = 0          # bit_length of guided's samples at the last check
        self.judged_stage = 0           # ... at the last judgement of the blend
        self.blend: RefineBlend | None = None   # that judgement
        self.weight = 1.0               # of guided (denoised) in the image shown, while "guided"
        self.switched_at: int | None = None   # guided's samples when it replaced the raymarcher
        self.frames = 0                 # frames stepped since the last restart
        self.shown_frames: list[str] = []   # what each of the first REFINE_HISTORY of them showed
        self.check: RefineCheck | None = None   # a check (or judgement) under way over frames
        self.staging: dict = {}         # its read-backs' buffers, by name (refine_judgement)
        self.host = HostArrays()        # their host copies, reused

    @property
    def acc(self) -> Accumulation | None:
        """What the display shows: the raymarcher's accumulation or the halves' mean."""
        if self.ray is None:
            return None
        return self.halves.combined if self.shown == "guided" else self.ray

    @property
    def samples(self) -> int:
        acc = self.acc
        return 0 if acc is None else acc.samples

    @property
    def blending(self) -> bool:
        """Guided shown, blended with the raymarcher's image (the raymarcher still judged)."""
        return self.shown == "guided" and self.weight < 1.0

    @property
    def guided_samples(self) -> int:
        return 0 if self.halves is None else self.halves.samples

    def drop_check(self) -> None:
        if self.check is not None:
            self.check.release()
            self.check = None

    def release(self) -> None:
        self.drop_check()
        for buf in self.staging.values():
            buf.release()
        self.staging.clear()
        self.host.clear()
        if self.ray is not None:
            self.ray.release()
        if self.halves is not None:
            self.halves.release()
        self.ray = self.halves = None


@dataclass
class FrameTimes:
    """GPU milliseconds of one frame, from timestamp queries."""
    bake_ms: float = 0.0
    render_ms: float = 0.0
    display_ms: float = 0.0
    samples: int = 0          # samples per pixel dispatched in the frame, over its views
    tiles: int = 0            # 8x8 tiles of samples split into bands (the wall clock's pacing),
    bands: int = 0            # and how many bands they were (sample_bands.py)
    denoise_ms: float = 0.0   # wall ms the Denoise switch took in the frame (not GPU time): its
    #                           read-backs' host copies, guides, uploads, blend passes, refine's
    #                           checks and judgements (the filter itself runs on its own thread)
    filter_ms: float = 0.0    # the filter's ms on its thread for the results landed in the frame
    #                           (off the frame: not in total_ms)
    parts: dict = None        # {part: [GPU ms or None, wall ms]} (app/viewer/frame/frame_parts.py)
    clock: str = "gpu"        # what bake_ms and render_ms are: GPU time, or "wall" clock time
    frame_wall_ms: float | None = None   # the whole frame's wall time (its display and panels too)

    @property
    def total_ms(self) -> float:
        return self.bake_ms + self.render_ms + self.display_ms

    @property
    def work_ms(self) -> float:
        return self.bake_ms + self.render_ms


class _PacedView:
    """A banded view as sample_bands.fill_frame drives it: its accumulation's counts, whole
    samples through the session, bands through Renderer.add_groups (with the view's own
    method, camera and seed)."""

    def __init__(self, session: "RenderSession", view: MethodView):
        self.session, self.view = session, view

    @property
    def samples(self) -> int:
        return self.view.acc.samples

    @property
    def groups_done(self) -> int:
        return self.view.acc.groups_done

    def add_samples(self, n: int) -> float:
        return self.session._add_samples(self.view, n)

    def add_groups(self, end: int) -> float:
        s, v = self.session, self.view
        with s.renderer.lend(v.acc, v.shown, v.camera, s.seed) as r:
            return r.add_groups(end)
