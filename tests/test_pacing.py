"""Frame pacing that trusts only what it can (app/viewer/frame/pacing.py, app/viewer/frame/session.py): a
software renderer's frames are paced by the wall clock from the start, a GPU's by its timestamps
until they stay far below the wall time of its frames, and then by the wall clock; a frame's work
is what the frame's wall-time target leaves after the rest of the frame."""
from __future__ import annotations

import time

from radiance_probes.gl.timer import DeferredSpans, WallTimer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.viewer.frame.pacing import (DISTRUST_FRAMES, WALL_FRAME_MS, WALL_MIN_WORK_MS,
                                                 FramePacer)
from radiance_probes.viewer.frame.session import MAX_SAMPLES_PER_FRAME, RenderSession

SCENE = {"volume": {"builtin": "cloud", "size": [16, 16, 16]}, "density_scale": 20.0,
         "camera": {"width": 32, "height": 32}}


def test_a_software_renderer_is_paced_by_the_wall_clock_and_says_why():
    pacer = FramePacer(True, "llvmpipe (LLVM 15.0.6, 256 bits)")
    assert pacer.wall and "llvmpipe" in pacer.reason and "software renderer" in pacer.reason
    assert pacer.work_budget_ms(65.0) == 65.0                # no overhead seen yet
    for _ in range(5):
        pacer.observe(600.0, 0.2, 550.0)                     # 50 ms of display, panels, swap
    assert pacer.work_budget_ms(65.0) == 50.0 == WALL_FRAME_MS - 50.0
    for _ in range(9):
        pacer.observe(900.0, 0.2, 300.0)                     # the rest of the frame is slow
    assert pacer.work_budget_ms(65.0) == WALL_MIN_WORK_MS


def test_a_gpu_whose_timestamps_are_far_below_the_wall_clock_is_found_out():
    """llvmpipe in a window: 0.2 to 4.5 ms read for frames of seconds."""
    pacer = FramePacer(False, "some GPU")
    for _ in range(200):                                     # honest: 12 ms of a 16.7 ms frame
        pacer.observe(16.7, 12.0, None)
    assert not pacer.wall and pacer.work_budget_ms(14.0) == 14.0
    for _ in range(DISTRUST_FRAMES - 1):                     # a compile's slow frames, then honest
        pacer.observe(900.0, 4.5, None)
    pacer.observe(16.7, 12.0, None)
    assert not pacer.wall
    for k in range(DISTRUST_FRAMES):
        assert not pacer.wall
        pacer.observe(2000.0 + k, 0.2 + k / 2, None)
    assert pacer.wall and "far below the wall clock" in pacer.reason
    fixed = FramePacer(False, "some GPU", clock="gpu")       # the benchmark's: its clock kept
    for _ in range(3 * DISTRUST_FRAMES):
        fixed.observe(2000.0, 0.2, None)
    assert not fixed.wall


class LyingTimer:
    """GPU timestamps as llvmpipe's window gave them: a fraction of a millisecond, whatever ran."""
    available = True

    def start(self):
        pass

    def stop(self):
        pass

    @property
    def elapsed_ms(self) -> float:
        return 0.2

    def release(self):
        pass


class LyingSpans(DeferredSpans):
    """The frame's deferred spans read from the same lying timestamps."""

    def start(self):
        return LyingTimer()


def test_the_session_stops_believing_lying_timestamps_and_paces_by_the_wall_clock(ctx):
    """Believed, 0.2 ms a dispatch sets 64 samples a frame; found out, the frames' samples come
    from the wall clock: what the frame's budget holds at a sample's wall time."""
    s = RenderSession(ctx, parse_scene(SCENE), clock=None)
    try:
        assert s.pacer.wall and isinstance(s.renderer.timer, WallTimer)   # llvmpipe: from the start
        s.pacer = FramePacer(False, "a GPU")                  # as a GPU would start
        s.renderer.timer.release()
        s.renderer.timer = LyingTimer()
        s.frame_spans.spans = LyingSpans(ctx)   # (a frame's timers read at its end: the same timestamps)
        s.resize(32, 32)
        s.set_methods(["pt"])
        believed = []
        while not s.pacer.wall:
            times = s.step(100000, False)
            time.sleep(0.06)            # the rest of a slow window's frame: 60 ms against 0.2
            s.record_frame(times)
            believed.append(times.samples)
            assert len(believed) <= DISTRUST_FRAMES + 1
        assert believed[2:] == [MAX_SAMPLES_PER_FRAME] * (len(believed) - 2)
        assert isinstance(s.renderer.timer, WallTimer)
        assert "far below the wall clock" in s.pacer.reason
        s.frame_budget_ms = 30.0
        paced = []
        for _ in range(6):
            times = s.step(100000, False)
            s.record_frame(times)
            assert times.clock == "wall"
            paced.append((times.samples, times.render_ms))
        per_sample = min(ms / n for n, ms in paced[2:])
        for n, ms in paced[3:]:   # what 30 ms holds at the sample's wall time (at least one)
            # (at most the cap: an idle machine fits about 50 of them in 30 ms here)
            assert n <= MAX_SAMPLES_PER_FRAME and (n == 1 or n * per_sample <= 30.0 * 1.5), paced
    finally:
        s.release()


def test_the_wall_timer_counts_the_work_between_its_ends(ctx):
    timer = WallTimer(ctx)
    timer.start()
    time.sleep(0.02)
    timer.stop()
    assert 19.0 <= timer.elapsed_ms < 200.0
    timer.release()


def test_a_frames_samples_are_paced_by_the_slow_end_of_recent_dispatches():
    """session.paced_ms_per_sample: one slow outlier (a shader compile) does not set the pace,
    but the frame is planned for the slower of the rest, not their median."""
    from radiance_probes.viewer.frame.session import paced_ms_per_sample
    assert paced_ms_per_sample([7.0, 7.5, 17.0, 16.0, 300.0]) == 17.0
    assert paced_ms_per_sample([5.0, 9.0]) == 9.0
    assert paced_ms_per_sample([4.0]) == 4.0
