"""A sample split into bands of rows over frames (issue 44: the viewer keeps pace without a GPU).
The planning is pure Python (app/rendering/sample_bands.py), tested on a fake device whose
dispatches advance a fake clock: bands are cut from the wall time the earlier ones took, whole
samples are taken where they fit. On llvmpipe: bands give the image of whole samples, bit for bit
and count for count (Renderer.add_rows, PathTracer.run's bands), and the viewer's session shows
the last whole image while a first sample is part done and lets a camera move wait for it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.rendering.sample_bands import (ROW_GROUP, FrameWork, RowCosts, fill_frame,
                                                    next_work)


class FakeClock:
    def __init__(self):
        self.now = 0.0   # ms


class FakeDevice:
    """An accumulation on a device whose rows cost `row_ms` each (ms of the fake clock) plus
    `dispatch_ms` per call; `slowdown` scales everything (another program's load)."""

    def __init__(self, clock: FakeClock, row_ms, dispatch_ms: float = 0.5):
        self.clock, self.row_ms, self.dispatch_ms = clock, list(row_ms), dispatch_ms
        self.height = len(self.row_ms)
        self.samples = self.rows_done = 0
        self.slowdown = 1.0
        self.calls: list[tuple] = []

    def _spend(self, ms: float) -> float:
        start = self.clock.now
        self.clock.now += self.slowdown * (ms + self.dispatch_ms)
        return self.clock.now - start

    def add_samples(self, n: int) -> float:
        assert self.rows_done == 0
        self.calls.append(("samples", n))
        self.samples += n
        return self._spend(n * sum(self.row_ms))

    def add_rows(self, end: int) -> float:
        first = self.rows_done
        assert first % ROW_GROUP == 0 and (end % ROW_GROUP == 0 or end == self.height)
        assert first < end <= self.height
        self.calls.append(("rows", first, end))
        ms = self._spend(sum(self.row_ms[first:end]))
        if end == self.height:
            self.samples, self.rows_done = self.samples + 1, 0
        else:
            self.rows_done = end
        return ms


def foot_rows(height: int = 400, sample_ms: float = 600.0) -> list[float]:
    """Rows through a volume in the middle of the picture cost 10x the background's."""
    weights = [10.0 if height / 4 <= r < 3 * height / 4 else 1.0 for r in range(height)]
    scale = sample_ms / sum(weights)
    return [w * scale for w in weights]


def frames(device: FakeDevice, costs: RowCosts, budget_ms: float, count: int,
           max_samples: int = 10 ** 6) -> list[FrameWork]:
    clock, out = device.clock, []
    for _ in range(count):
        start = clock.now
        done = fill_frame(device, costs, budget_ms, max_samples)
        assert math.isclose(done.ms, clock.now - start)   # what the frame's work took, by the clock
        out.append(done)
    return out


def bands_per_sample(device: FakeDevice, skip_samples: int) -> list[int]:
    """The bands of each whole sample after the first `skip_samples`."""
    counts, n, whole = [], 0, 0
    for call in device.calls:
        if call[0] == "rows":
            n += 1
            if call[2] == device.height:
                whole += 1
                if whole > skip_samples:
                    counts.append(n)
                n = 0
    return counts


def test_a_sample_longer_than_the_budget_is_cut_into_bands_that_fit_it():
    clock = FakeClock()
    device = FakeDevice(clock, foot_rows(400, 600.0))
    costs = RowCosts(400)
    work = frames(device, costs, 60.0, 120)
    assert device.calls[0] == ("rows", 0, 48)          # nothing timed: an eighth of the rows
    # once every row was timed (the first sample), no frame's work overran its 60 ms by more than
    # the variation inside a band's groups, and each did some
    learned = work[12:]
    assert all(0 < w.ms <= 60.0 * 1.15 for w in learned), [round(w.ms) for w in learned]
    assert device.samples >= 8 and all(w.samples <= 1 for w in work)
    # a sample of 600 ms at 60 ms a frame: ten bands at least; more where whole groups of rows
    # (22 ms each through the volume: two fit in 60 ms, not three) fill a frame unevenly; never
    # whole samples
    counts = bands_per_sample(device, 3)                # (the first three learn the rows' costs)
    assert len(counts) >= 5 and all(10 <= n <= 16 for n in counts), counts
    assert not any(c[0] == "samples" for c in device.calls)
    # the rows through the volume cost ten times more: their bands are shorter
    rows = {}
    for call in device.calls[-20:]:
        if call[0] == "rows":
            rows[call[1]] = call[2] - call[1]
    top = [n for first, n in rows.items() if first + n <= 100]
    middle = [n for first, n in rows.items() if first >= 100 and first + n <= 300]
    assert top and middle and min(top) > 3 * max(middle), rows


def test_the_band_count_follows_the_wall_time():
    """The same picture on a device twice as slow (another program's load): twice the bands."""
    counts = {}
    for slowdown in (1.0, 2.0):
        device = FakeDevice(FakeClock(), foot_rows(400, 600.0))
        device.slowdown = slowdown
        frames(device, RowCosts(400), 60.0, 100)
        counts[slowdown] = np.median(bands_per_sample(device, 1))
    assert 1.7 <= counts[2.0] / counts[1.0] <= 2.3, counts
    # and a machine that slows down mid-run cuts shorter bands from the next sample on
    device = FakeDevice(FakeClock(), foot_rows(400, 600.0))
    costs = RowCosts(400)
    frames(device, costs, 60.0, 40)
    device.slowdown, before = 3.0, len(device.calls)
    work = frames(device, costs, 60.0, 80)
    assert max(w.ms for w in work[-40:]) <= 60.0 * 1.15
    assert np.median(bands_per_sample(device, device.samples - 2)) >= 25
    assert len(device.calls) - before > 80


def test_whole_samples_where_they_fit_and_no_more_than_asked():
    device = FakeDevice(FakeClock(), [4.0 / 40] * 40, dispatch_ms=0.0)   # 4 ms a sample
    costs = RowCosts(40)
    per_frame = []
    for _ in range(6):
        before = len(device.calls)
        done = fill_frame(device, costs, 60.0, 50)
        per_frame.append((done, device.calls[before:]))
    first, calls = per_frame[0]
    # the first sample a group at a time (each timed alone), then whole samples
    assert calls[:5] == [("rows", r, r + 8) for r in range(0, 40, 8)]
    assert calls[5][0] == "samples" and calls[5][1] >= 13
    for done, calls in per_frame[:3]:
        # whole samples as many as fit (15 of 4 ms in 60), the rest of the budget a band
        assert done.ms <= 60.0 + 1e-9 and done.samples >= 13, calls
        assert any(c[0] == "samples" and c[1] >= 13 for c in calls), calls
    assert device.samples == 50 and sum(done.samples for done, _ in per_frame) == 50
    assert per_frame[-1][1] == [] and per_frame[-1][0].ms == 0.0   # done: the frame does nothing


def test_a_frame_always_does_one_group_and_stops_after_the_budget():
    device = FakeDevice(FakeClock(), [1.0] * 64, dispatch_ms=0.0)   # 8 ms a group
    costs = RowCosts(64)
    frames(device, costs, 1.0, 3)                       # over budget: one group a frame
    assert device.calls[1:] == [("rows", 8, 16), ("rows", 16, 24)]
    assert next_work(costs, 24, 1.0, started=True, samples_left=5) is None
    assert next_work(costs, 24, 1.0, started=False, samples_left=5) == ("rows", 32)
    assert next_work(costs, 24, 30.0, started=True, samples_left=5) == ("rows", 32)  # untimed
    costs.ms[3:6] = [8.0, 8.0, 8.0]                     # timed: three of them fit in 30 ms
    assert next_work(costs, 24, 30.0, started=True, samples_left=5) == ("rows", 48)
    assert costs.plan(24, 1000.0) == 48                 # and group 6 is not timed yet
    assert next_work(costs, 0, 70.0, started=True, samples_left=5) == ("samples", 1)
    assert next_work(costs, 0, 70.0, started=True, samples_left=0) is None


def test_row_costs_spread_a_band_by_what_its_groups_were_predicted_to_cost():
    costs = RowCosts(20)                                # groups of 8, 8 and 4 rows
    assert costs.count == 3 and costs.predict(0, 20) is None
    costs.observe(0, 16, 10.0)                          # nothing known: evenly
    assert costs.ms == [5.0, 5.0, None] and costs.predict(0, 20) == 15.0
    costs.ms = [1.0, 3.0, None]
    costs.observe(0, 20, 12.0)                          # 1 : 3 : 2 (the unknown one the mean)
    assert costs.ms == pytest.approx([2.0, 6.0, 4.0])
    costs.observe(0, 20, 6.0)                           # cheaper: halfway down
    assert costs.ms == pytest.approx([1.5, 4.5, 3.0])
    costs.observe(8, 16, 9.0)                           # dearer: at once
    assert costs.ms == pytest.approx([1.5, 9.0, 3.0])
    assert costs.plan(0, 10.5) == 16 and costs.plan(8, 1.0) == 16 and costs.plan(16, 99) == 20
    assert costs.plan(0, 10.4) == 8 and costs.sample_ms() == pytest.approx(13.5)


# ---- on llvmpipe --------------------------------------------------------------------------------
SCENE = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 25.0,
         "albedo": 0.9, "camera": {"width": 24, "height": 21}}


@pytest.fixture
def renderer(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.scene import parse_scene
    r = Renderer(ctx, parse_scene(SCENE))
    yield r
    r.release()


def _whole(r, method: str, samples: int, seed: int = 7) -> np.ndarray:
    with r.lend(None):
        acc = r.begin(method, 24, 21, seed=seed)
        r.add_samples(samples)
        return acc.read_rgba()


def test_bands_of_rows_give_the_whole_samples_image_bit_for_bit(renderer):
    r = renderer
    whole = _whole(r, "pt", 3)
    assert np.all(whole[..., 3] == 3) and whole[..., :3].max() > 0
    with r.lend(None):
        acc = r.begin("pt", 24, 21, seed=7)
        ends = [[8, 16, 21], [21], [16, 21]]            # three samples, cut three ways
        for sample, cut in enumerate(ends):
            for end in cut:
                assert acc.samples == sample
                r.add_rows(end)
                assert acc.rows_done == (0 if end == 21 else end)
                if end != 21:   # a part-done sample: its rows hold one sample more, no pixel twice
                    counts = acc.read_rgba()[..., 3]
                    assert np.all(counts[:end] == sample + 1) and np.all(counts[end:] == sample)
        banded = acc.read_rgba()
    assert acc.samples == 3
    np.testing.assert_array_equal(banded, whole)
    # a sample part done and then whole samples: the rows done are not begun again
    with r.lend(None):
        acc = r.begin("pt", 24, 21, seed=7)
        r.add_rows(8)
        r.add_samples(3)
        mixed = acc.read_rgba()
    np.testing.assert_array_equal(mixed, whole)
    with pytest.raises(ValueError, match="multiple of 8"):
        with r.lend(None):
            r.begin("pt", 24, 21)
            r.add_rows(12)


def test_the_probe_renderers_and_the_raymarcher_in_bands_give_their_whole_image(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.scene import parse_scene
    r = Renderer(ctx, parse_scene({**SCENE, "probes": {"grid": [4, 4, 4], "samples": 32}}))
    try:
        r.bake(0)
        for method in ("probes", "probes-only", "raymarch"):
            whole = _whole(r, method, 3)
            with r.lend(None):
                acc = r.begin(method, 24, 21, seed=7)
                for end in (8, 21, 16, 21):
                    r.add_rows(end)
                assert acc.samples == 2 and acc.rows_done == 0
                r.add_rows(8)            # a third part done, then made whole by add_samples
                r.add_samples(1)
                banded = acc.read_rgba()
            assert acc.samples == 3 and whole[..., :3].max() > 0
            np.testing.assert_array_equal(banded, whole, err_msg=method)
        with r.lend(None):   # guided's two levels stay whole, and the raymarcher's fragment pass
            r.begin("guided", 24, 21)
            with pytest.raises(ValueError, match="bands of rows"):
                r.add_rows(8)
        r.configure(raymarch_stage="fragment")
        assert not r.can_band("raymarch") and r.can_band("pt")
    finally:
        r.release()


def test_a_pass_cut_into_bands_counts_every_pixel_once(renderer):
    """PathTracer.run's bands (a GPU's long samples): a band ending inside a group of 8 rows also
    ran the next band's first rows, whose fresh start then counted their first samples twice."""
    from radiance_probes.rendering.pathtracer import band_edges
    r = renderer
    whole = _whole(r, "pt", 2)
    for bands in (2, 3):
        with r.lend(None):
            acc = r.begin("pt", 24, 21, seed=7)
            r.pass_for("pt").run(r.resources, r.camera, acc, 2, 7, None, bands)
            np.testing.assert_array_equal(acc.read_rgba(), whole)
    assert band_edges(21, 2) == [0, 8, 21] and band_edges(20, 3) == [0, 8, 16, 20]
    assert band_edges(21, 99) == [0, 8, 16, 21] and band_edges(5, 3) == [0, 5]
