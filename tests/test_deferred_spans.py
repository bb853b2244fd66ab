"""A viewer frame reads its timers once, at its end (gl/timer.DeferredSpans; issue 56): by the
GPU's clock, once each timed block's cost is known, no block of the frame waits for its timer,
and what the frame sums from the estimates (its bake and render ms, the pacing's history) is
corrected by the measured ms before the step returns."""
from __future__ import annotations

import pytest

from radiance_probes.gl.timer import DeferredSpans
from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
         "albedo": 0.9, "camera": {"width": 32, "height": 24},
         "probes": {"grid": [3, 3, 3], "samples": 16, "fit": "box"}}


def test_spans_return_their_estimate_and_resolve_to_the_measured_time(ctx):
    spans = DeferredSpans(ctx)
    learned = []
    spans.tag = "a"
    t = spans.start()
    assert spans.stop(t, 2.5, learned.append) == 2.5
    spans.tag = "b"
    t = spans.start()
    spans.stop(t, 1.0)
    t = spans.start()
    spans.stop(t, 7.0, tag="inner")
    assert spans.pending == 3
    got = spans.resolve()
    assert spans.pending == 0
    assert set(got) == {"a", "b", "inner"}
    assert got["a"][1] == 2.5 and got["b"][1] == 1.0 and got["inner"][1] == 7.0
    assert len(learned) == 1 and learned[0] == pytest.approx(got["a"][0])
    assert all(measured >= 0.0 for measured, _ in got.values())
    spans.release()


class CountingTimer:
    """The renderer's own timer, its reads counted (each is a wait for the GPU)."""

    def __init__(self, timer):
        self.timer, self.reads = timer, 0

    def start(self):
        self.timer.start()

    def stop(self):
        self.timer.stop()

    @property
    def elapsed_ms(self):
        self.reads += 1
        return self.timer.elapsed_ms

    def release(self):
        self.timer.release()


@pytest.mark.parametrize("method", ["refine", "pt"])
def test_a_frame_by_the_gpu_clock_waits_for_no_timer_until_its_end(ctx, monkeypatch, method):
    """After frames that learned each block's cost, a frame reads none of the renderer's timers
    (every block deferred); its render ms and the pacing's last entry are the measured ones
    (DeferredSpans.resolve's), not the estimates."""
    from radiance_probes.viewer.frame import frame_spans as spans_module
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE), clock="gpu")
    s.resize(32, 24)
    s.set_methods([method])
    r = s.renderer
    r.bake(seed=1)
    for _ in range(6):   # the bake done, each block's cost learned
        s.step(512, True)
    counting = CountingTimer(r.timer)
    r.timer = counting
    resolved = []
    real = DeferredSpans.resolve

    def spy(self):
        got = real(self)
        resolved.append(got)
        return got
    monkeypatch.setattr(DeferredSpans, "resolve", spy)
    for _ in range(4):
        times = s.step(512, True)
        assert counting.reads == 0
        assert resolved, "the frame's spans were not resolved"
        got = resolved[-1]
        samples = [v for k, v in got.items() if isinstance(k, tuple) and k[0] == "samples"]
        assert samples and times.samples > 0
        assert times.render_ms == pytest.approx(sum(m for m, _ in samples), abs=1e-6)
        view = s.views[method]
        shown = "guided" if method == "refine" else view.shown
        n, ms = view.dispatch_ms[shown][-1]
        assert ms == pytest.approx(samples[-1][0], abs=1e-6)
        assert "wait" in times.parts
        resolved.clear()
    r.timer = counting.timer
    assert spans_module.DeferredSpans is DeferredSpans   # (the class the spy patched)


def test_the_wall_clock_defers_nothing(ctx):
    """Paced by the wall clock (llvmpipe's viewer) every block is timed as it ends, as before."""
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE), clock="wall")
    s.resize(32, 24)
    s.set_methods(["pt"])
    for _ in range(4):
        s.step(512, False)
        assert s.frame_spans.spans.pending == 0 and s.renderer.deferred is None
