"""Which clock paces the viewer's frames (app/viewer/frame/session.py), and the work a frame may take.

GPU timestamps pace a frame where they can be believed: the frame's work gets FRAME_BUDGET_MS of
GPU time. Where they cannot, the wall clock does. That is a software renderer from the start (in
llvmpipe's window the timestamps read 0.2 to 4.5 ms for frames that took seconds, and the pacing
that trusted them dispatched 64 samples at once, 20 to 55 s of wall time), and a GPU whose
timestamps stay far below the wall time of its whole frames (DISTRUST_FRAMES working frames in a
row longer than DISTRUST_RATIO x their GPU time + DISTRUST_SLACK_MS). Paced by the wall clock, each
dispatch is timed from its call to its end (a glFinish), and the work of a frame gets what
WALL_FRAME_MS leaves after the rest of the frame (the display, the panels, the swap: the median
over recent frames of their wall time less their work's); a sample longer than that is
dispatched in bands of rows over several frames (RenderSession._add_paced)."""
from __future__ import annotations

import statistics
from collections import deque

# A frame's whole wall time that the wall-clock pacing aims at (frames over ~250 ms stall a
# person's drag; issue 44 asks for about 100 ms on any device): its work gets what is left of it
# after the rest of the frame, at least WALL_MIN_WORK_MS, and at most the session's frame budget
# (FRAME_BUDGET_MS, now in wall ms). A sample that takes longer is split into bands of rows over
# frames (app/rendering/budgets/sample_bands.py), so the frame holds to it whatever the picture costs.
WALL_FRAME_MS = 100.0
WALL_MIN_WORK_MS = 20.0
DISTRUST_FRAMES = 8
DISTRUST_RATIO = 4.0
DISTRUST_SLACK_MS = 50.0
RECENT_FRAMES = 9         # frames whose overhead (wall time less the work's) sets the next budget


class FramePacer:
    """The clock ("gpu" or "wall"), why, and what a frame's work may take by it. `clock` given
    ("gpu", "wall"): that clock always (the interact benchmark records GPU time and wall time
    apart); None: by the device, and the wall clock once the timestamps are found out."""

    def __init__(self, software: bool, device: str = "", clock: str | None = None):
        self.fixed = clock is not None
        self.clock = clock or ("wall" if software else "gpu")
        self.reason = ("the clock asked for" if self.fixed else
                       f"{device or 'a software renderer'}: a software renderer, whose GPU "
                       "timestamps are not its work's time" if software else "")
        self.overhead_ms: deque[float] = deque(maxlen=RECENT_FRAMES)
        self.frame_ms: float | None = None     # the last working frame's wall time
        self._suspect = 0

    @property
    def wall(self) -> bool:
        return self.clock == "wall"

    def work_budget_ms(self, budget_ms: float) -> float:
        """What the next frame's work (bake slice and samples) may take, in the pacing clock's
        ms: the session's budget, and by the wall clock no more than the frame's target leaves."""
        if not self.wall:
            return budget_ms
        overhead = statistics.median(self.overhead_ms) if self.overhead_ms else 0.0
        return min(budget_ms, max(WALL_FRAME_MS - overhead, WALL_MIN_WORK_MS))

    def observe(self, frame_wall_ms: float, gpu_ms: float, work_wall_ms: float | None) -> None:
        """A working frame's whole wall time, the GPU time its timestamps gave, and (paced by the
        wall clock) its work's wall time; switches to the wall clock where the timestamps stay
        far below the wall."""
        self.frame_ms = frame_wall_ms
        if self.wall or self.fixed:
            if work_wall_ms is not None:
                self.overhead_ms.append(max(frame_wall_ms - work_wall_ms, 0.0))
            return
        if frame_wall_ms > DISTRUST_RATIO * gpu_ms + DISTRUST_SLACK_MS:
            self._suspect += 1
        else:
            self._suspect = 0
        if self._suspect >= DISTRUST_FRAMES:
            self.clock = "wall"
            self.reason = (f"GPU timestamps far below the wall clock ({gpu_ms:.1f} ms against a "
                           f"{frame_wall_ms:.0f} ms frame, {DISTRUST_FRAMES} frames in a row)")
