"""A sample split into bands over frames (issue 44: the viewer keeps pace without a GPU). The
planning is pure Python (app/rendering/budgets/sample_bands.py), tested on a fake device whose
dispatches advance a fake clock: bands are cut from the wall time the earlier ones took, whole
samples are taken where they fit. On llvmpipe: bands of work groups give the image of whole
samples, bit for bit and count for count (Renderer.add_groups, PathTracer.run's bands), and the
viewer's session shows the last whole image while a first sample is part done and lets a camera
move wait for it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.rendering.budgets.sample_bands import (UNTIMED_ABOVE_FACTOR, UNTIMED_FACTOR,
                                                            FrameWork, TileCosts, fill_frame,
                                                            next_work, tile_rects)


class FakeClock:
    def __init__(self):
        self.now = 0.0   # ms


class FakeDevice:
    """An accumulation of tiles_x x tiles_y tiles on a device whose tiles cost `tile_ms` each (ms
    of the fake clock, raster order) plus `dispatch_ms` a call; `slowdown` scales everything
    (another program's load)."""

    def __init__(self, clock: FakeClock, tiles_x: int, tile_ms, dispatch_ms: float = 0.5):
        self.clock, self.tile_ms, self.dispatch_ms = clock, list(tile_ms), dispatch_ms
        self.tiles_x, self.count = tiles_x, len(self.tile_ms)
        self.samples = self.groups_done = 0
        self.slowdown = 1.0
        self.calls: list[tuple] = []

    def costs(self) -> TileCosts:
        return TileCosts(self.tiles_x, self.count // self.tiles_x)

    def _spend(self, ms: float) -> float:
        start = self.clock.now
        self.clock.now += self.slowdown * (ms + self.dispatch_ms)
        return self.clock.now - start

    def add_samples(self, n: int) -> float:
        assert self.groups_done == 0
        self.calls.append(("samples", n))
        self.samples += n
        return self._spend(n * sum(self.tile_ms))

    def add_groups(self, end: int) -> float:
        first = self.groups_done
        assert first < end <= self.count
        self.calls.append(("tiles", first, end))
        ms = self._spend(sum(self.tile_ms[first:end]))
        if end == self.count:
            self.samples, self.groups_done = self.samples + 1, 0
        else:
            self.groups_done = end
        return ms


def foot(tiles_x: int = 57, tiles_y: int = 50, sample_ms: float = 600.0) -> FakeDevice:
    """455 x 400 pixels; the tiles through a volume in the middle cost 10x the background's."""
    weights = [10.0 if tiles_y / 4 <= y < 3 * tiles_y / 4 and tiles_x / 4 <= x < 3 * tiles_x / 4
               else 1.0 for y in range(tiles_y) for x in range(tiles_x)]
    scale = sample_ms / sum(weights)
    return FakeDevice(FakeClock(), tiles_x, [w * scale for w in weights])


def frames(device: FakeDevice, costs: TileCosts, budget_ms: float, count: int,
           max_samples: int = 10 ** 6) -> list[FrameWork]:
    clock, out = device.clock, []
    for _ in range(count):
        start = clock.now
        done = fill_frame(device, costs, budget_ms, max_samples)
        assert math.isclose(done.ms, clock.now - start)   # what the frame's work took, by the clock
        out.append(done)
    return out


def frames_per_sample(work: list[FrameWork]) -> float:
    return len(work) / max(sum(w.samples for w in work), 1)


def test_a_sample_longer_than_the_budget_is_cut_into_bands_that_fit_it():
    device = foot()
    costs = device.costs()
    work = frames(device, costs, 60.0, 160)
    assert device.calls[0] == ("tiles", 0, 1)           # nothing timed: one tile (a compile)
    # once the tiles were timed (the first two samples), no frame's work overran its 60 ms by
    # more than the error of the tiles' predictions, and each did some
    learned = work[40:]
    ms = [w.ms for w in learned]
    assert all(ms) and max(ms) <= 60.0 * 1.25 and np.percentile(ms, 90) <= 60.0 * 1.1, ms
    assert all(w.samples <= 1 for w in work) and device.samples >= 14
    # a sample of 600 ms at 60 ms a frame: ten frames a sample at least, and not many more;
    # never whole samples
    assert 10.0 <= frames_per_sample(learned) <= 11.0, frames_per_sample(learned)
    assert not any(c[0] == "samples" for c in device.calls)
    # the tiles through the volume cost ten times more: a frame does fewer of them (some 900
    # tiles from the top row, 160 through the middle, where the volume is 28 of the 57 tiles)
    bands = [(c[1], c[2] - c[1]) for c in device.calls[-60:]]
    top = [n for first, n in bands if first < 57 * 8]
    middle = [n for first, n in bands if 57 * 15 <= first < 57 * 30]
    assert top and middle and max(top) > 4 * max(middle), (top, middle)


def test_the_band_count_follows_the_wall_time():
    """The same picture on a device twice as slow (another program's load): twice the frames a
    sample; and a machine that slows down mid-run is caught up with within a sample."""
    per = {}
    for slowdown in (1.0, 2.0):
        device = foot()
        device.slowdown = slowdown
        work = frames(device, device.costs(), 60.0, 200)
        per[slowdown] = frames_per_sample(work[60:])
    assert 1.8 <= per[2.0] / per[1.0] <= 2.2, per
    device = foot()
    costs = device.costs()
    frames(device, costs, 60.0, 40)
    device.slowdown = 3.0
    work = frames(device, costs, 60.0, 120)
    assert max(w.ms for w in work[:3]) > 2 * 60.0    # the first bands were planned at the old speed
    ms = [w.ms for w in work[30:]]                   # (a sample is 30 frames now)
    assert max(ms) <= 60.0 * 1.5 and np.percentile(ms, 90) <= 60.0 * 1.2, ms
    assert 29.0 <= frames_per_sample(work[30:]) <= 34.0


def test_whole_samples_where_they_fit_and_no_more_than_asked():
    device = FakeDevice(FakeClock(), 5, [4.0 / 25] * 25, dispatch_ms=0.0)   # 4 ms a sample
    costs = device.costs()
    per_frame = []
    for _ in range(6):
        before = len(device.calls)
        done = fill_frame(device, costs, 60.0, 50)
        per_frame.append((done, device.calls[before:]))
    first, calls = per_frame[0]
    # a tile timed, the rest of the sample, then whole samples
    assert calls[:2] == [("tiles", 0, 1), ("tiles", 1, 25)] and calls[2][0] == "samples"
    for done, calls in per_frame[:3]:
        # whole samples as many as fit (15 of 4 ms in 60), the rest of the budget a band
        assert done.ms <= 60.0 + 1e-9 and done.samples >= 13, calls
        assert any(c[0] == "samples" and c[1] >= 13 for c in calls), calls
    assert device.samples == 50 and sum(done.samples for done, _ in per_frame) == 50
    assert per_frame[-1][1] == [] and per_frame[-1][0].ms == 0.0   # done: the frame does nothing


def test_a_frame_always_does_one_tile_and_stops_after_the_budget():
    device = FakeDevice(FakeClock(), 4, [8.0] * 16, dispatch_ms=0.0)   # 8 ms a tile
    costs = device.costs()
    frames(device, costs, 1.0, 3)                       # over budget: one tile a frame
    assert device.calls == [("tiles", 0, 1), ("tiles", 1, 2), ("tiles", 2, 3)]
    assert next_work(costs, 3, 1.0, started=True, samples_left=5) is None
    assert next_work(costs, 3, 1.0, started=False, samples_left=5) == ("tiles", 4)
    # an untimed tile is predicted at UNTIMED_FACTOR x the timed ones' median (32 ms)
    assert costs.tile_ms(3) == UNTIMED_FACTOR * 8.0
    assert next_work(costs, 3, 40.0, started=True, samples_left=5) == ("tiles", 4)
    assert next_work(costs, 3, 30.0, started=True, samples_left=5) is None
    costs.observe(3, 6, 24.0)                           # timed: three of them fit in 30 ms
    assert costs.ms[3:6] == [8.0, 8.0, 8.0]
    assert next_work(costs, 3, 30.0, started=True, samples_left=5) == ("tiles", 6)
    assert next_work(costs, 0, 10 ** 4, started=True, samples_left=5) == ("samples", 5)
    assert next_work(costs, 0, 10 ** 4, started=True, samples_left=0) is None


def test_tile_costs_spread_a_band_by_what_its_tiles_were_predicted_to_cost():
    costs = TileCosts(3, 1)
    assert costs.count == 3 and costs.predict(0, 3) is None and not costs.known
    assert costs.plan(0, 99.0) == 1                     # nothing known: one tile
    costs.observe(0, 2, 10.0)                           # evenly
    assert costs.ms == [5.0, 5.0, None]
    assert costs.sample_ms() == 10.0 + UNTIMED_FACTOR * 5.0
    costs.observe(0, 3, 12.0)                           # 5 : 5 : 20, the untimed one 4x the mean
    assert costs.ms == pytest.approx([3.5, 3.5, 8.0])   # cheaper: halfway down; new: as seen
    costs.observe(1, 2, 9.0)                            # dearer: at once
    assert costs.ms == pytest.approx([3.5, 9.0, 8.0]) and costs.sample_ms() == pytest.approx(20.5)
    assert costs.plan(0, 12.5) == 2 and costs.plan(0, 12.4) == 1 and costs.plan(2, 0.1) == 3
    big = TileCosts(4, 1)                               # the median: one compile's 800 ms in a
    for tile, ms in enumerate((800.0, 1.0, 2.0)):       # tile does not set the untimed ones'
        big.observe(tile, tile + 1, ms)
    assert big.tile_ms(3) == UNTIMED_FACTOR * 2.0
    rows = TileCosts(3, 2)                              # below a dear tile: at least 1.5x it
    rows.observe(0, 2, 2.0)
    rows.observe(2, 3, 30.0)
    assert rows.ms[:3] == [1.0, 1.0, 30.0]
    assert rows.tile_ms(3) == UNTIMED_FACTOR * 1.0
    assert rows.tile_ms(5) == UNTIMED_ABOVE_FACTOR * 30.0 == 45.0
    assert rows.predict(3, 6) == 4.0 + 4.0 + 45.0


def test_a_run_of_tiles_is_at_most_three_rectangles():
    assert tile_rects(5, 3, 17) == [(3, 0, 2, 1), (0, 1, 5, 2), (0, 3, 2, 1)]
    assert tile_rects(5, 0, 10) == [(0, 0, 5, 2)]
    assert tile_rects(5, 2, 4) == [(2, 0, 2, 1)]
    assert tile_rects(5, 5, 7) == [(0, 1, 2, 1)]
    assert tile_rects(5, 3, 10) == [(3, 0, 2, 1), (0, 1, 5, 1)]
    for first in range(0, 20):
        for end in range(first + 1, 21):
            covered = [y * 5 + x for x0, y0, nx, ny in tile_rects(5, first, end)
                       for y in range(y0, y0 + ny) for x in range(x0, x0 + nx)]
            assert sorted(covered) == list(range(first, end))


# ---- on llvmpipe --------------------------------------------------------------------------------
SCENE = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 25.0,
         "albedo": 0.9, "camera": {"width": 24, "height": 21}}   # 3 x 3 tiles, the last part empty


def done_pixels(end: int) -> np.ndarray:
    """The pixels of tiles [0, end) of the 24 x 21 image, (21, 24) booleans."""
    tiles = np.arange(9).reshape(3, 3) < end
    return np.repeat(np.repeat(tiles, 8, axis=0), 8, axis=1)[:21, :24]


@pytest.fixture
def renderer(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    r = Renderer(ctx, parse_scene(SCENE))
    yield r
    r.release()


def _whole(r, method: str, samples: int, seed: int = 7) -> np.ndarray:
    with r.lend(None):
        acc = r.begin(method, 24, 21, seed=seed)
        r.add_samples(samples)
        return acc.read_rgba()


def test_bands_of_tiles_give_the_whole_samples_image_bit_for_bit(renderer):
    r = renderer
    whole = _whole(r, "pt", 3)
    assert np.all(whole[..., 3] == 3) and whole[..., :3].max() > 0
    with r.lend(None):
        acc = r.begin("pt", 24, 21, seed=7)
        cuts = [[2, 7, 9], [9], [4, 5, 9]]              # three samples, cut three ways
        for sample, cut in enumerate(cuts):
            for end in cut:
                assert acc.samples == sample
                r.add_groups(end)
                assert acc.groups_done == (0 if end == 9 else end)
                if end != 9:   # a part-done sample: its tiles hold one sample more, no pixel twice
                    counts, done = acc.read_rgba()[..., 3], done_pixels(end)
                    assert np.all(counts[done] == sample + 1) and np.all(counts[~done] == sample)
        banded = acc.read_rgba()
    assert acc.samples == 3
    np.testing.assert_array_equal(banded, whole)
    # a sample part done and then whole samples: the tiles done are not begun again
    with r.lend(None):
        acc = r.begin("pt", 24, 21, seed=7)
        r.add_groups(4)
        r.add_samples(3)
        mixed = acc.read_rgba()
    np.testing.assert_array_equal(mixed, whole)
    with pytest.raises(ValueError, match="work groups"):
        with r.lend(None):
            r.begin("pt", 24, 21)
            r.add_groups(0)


def test_the_probe_renderers_and_the_raymarcher_in_bands_give_their_whole_image(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    r = Renderer(ctx, parse_scene({**SCENE, "probes": {"grid": [4, 4, 4], "samples": 32}}))
    try:
        r.bake(0)
        for method in ("probes", "probes-only", "raymarch"):
            whole = _whole(r, method, 3)
            with r.lend(None):
                acc = r.begin(method, 24, 21, seed=7)
                for end in (2, 9, 5, 9):
                    r.add_groups(end)
                assert acc.samples == 2 and acc.groups_done == 0
                r.add_groups(4)           # a third part done, then made whole by add_samples
                r.add_samples(1)
                banded = acc.read_rgba()
            assert acc.samples == 3 and whole[..., :3].max() > 0
            np.testing.assert_array_equal(banded, whole, err_msg=method)
        with r.lend(None):   # guided's two levels stay whole, and the raymarcher's fragment pass
            r.begin("guided", 24, 21)
            with pytest.raises(ValueError, match="bands of work groups"):
                r.add_groups(2)
        r.configure(raymarch_stage="fragment")
        assert not r.can_band("raymarch") and r.can_band("pt")
    finally:
        r.release()


def test_a_pass_cut_into_bands_counts_every_pixel_once(renderer):
    """PathTracer.run's bands (a GPU's long samples): a band ending inside a group of 8 rows also
    ran the next band's first rows, whose fresh start then counted their first samples twice."""
    from radiance_probes.rendering.methods.pathtracer import band_edges
    r = renderer
    whole = _whole(r, "pt", 2)
    for bands in (2, 3):
        with r.lend(None):
            acc = r.begin("pt", 24, 21, seed=7)
            r.pass_for("pt").run(r.resources, r.camera, acc, 2, 7, None, bands)
            np.testing.assert_array_equal(acc.read_rgba(), whole)
    assert band_edges(21, 2) == [0, 8, 21] and band_edges(20, 3) == [0, 8, 16, 20]
    assert band_edges(21, 99) == [0, 8, 16, 21] and band_edges(5, 3) == [0, 5]


def test_the_session_paced_by_the_wall_clock_splits_samples_and_shows_whole_images(ctx):
    """A budget far below a sample: one tile a frame. The accumulation
    after them is the whole samples' image; while the first sample of a restart is part done
    the display shows the last whole image; a camera move waits for the first sample in
    progress, then begins."""
    from dataclasses import replace

    from radiance_probes.io.scene_file import parse_scene
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE), seed=7)
    try:
        assert s.pacer.wall                               # llvmpipe
        s.frame_budget_ms = 1e-3
        s.resize(24, 21)
        s.set_methods(["pt"])
        view = s.views["pt"]
        seen = []
        while view.acc.samples < 2:
            times = s.step(100, False)
            s.record_frame(times)
            seen.append((times.samples, times.tiles, times.bands, view.acc.groups_done))
            assert view.held is None and s.texture("pt") is view.acc.texture
            assert len(seen) < 40
        assert seen[:3] == [(0, 1, 1, 1), (0, 1, 1, 2), (0, 1, 1, 3)]
        assert seen[8] == (1, 1, 1, 0) and len(seen) == 9 + 9
        assert s.label("pt") == "pt  2 spp"
        whole = _whole(s.renderer, "pt", 2)
        np.testing.assert_array_equal(view.acc.read_rgba(), whole)
        first_image = view.acc
        # an edit that is not a camera move: begun at once, the two-sample image shown meanwhile
        s.set_scene(s.scene.replace(albedo=0.5))
        assert view.held is first_image and view.acc is not first_image
        s.record_frame(s.step(100, False))
        assert view.acc.groups_done == 1 and view.shows_held
        assert s.texture("pt") is first_image.texture and "the last whole image" in s.label("pt")
        np.testing.assert_array_equal(s.shown_image("pt"), whole[..., :3])
        # a camera move while that first sample is part done waits for it
        cam = s.scene.camera
        s.set_scene(s.scene.replace(camera=replace(cam, eye=(cam.eye[0] + 0.3, *cam.eye[1:]))))
        assert view.restart_pending and view.acc.groups_done == 1
        second, old_eye = view.acc, view.camera.eye.copy()
        frames_left = 0
        while view.restart_pending:
            s.record_frame(s.step(100, False))
            frames_left += 1
            assert frames_left < 20
        assert frames_left == 8                           # the other 8 tiles, then it begins
        assert view.held is second and second.samples == 1
        assert view.acc.samples == 0 and view.acc.groups_done == 0
        assert s.texture("pt") is second.texture
        assert view.camera.eye[0] == pytest.approx(old_eye[0] + 0.3)
    finally:
        s.release()


def test_a_frame_makes_at_most_most_samples_whole_over_all_its_steps():
    """`most` caps the frame, not each step: a device whose samples are far cheaper than the
    budget, after a band left a sample part done, still gets at most `most` whole samples a frame
    (the session's MAX_SAMPLES_PER_FRAME; a fast idle machine made 67 in one frame)."""
    device = FakeDevice(FakeClock(), 5, [0.01] * 25, dispatch_ms=0.0)   # 0.25 ms a sample
    costs = device.costs()
    for budget in (30.0, 60.0, 1000.0):
        for _ in range(4):
            done = fill_frame(device, costs, budget, 100000, most=64)
            assert 1 <= done.samples <= 64, (budget, done)
    # a band in progress first (a sample part done), then whole samples: still at most 64
    device.add_groups(7)
    done = fill_frame(device, costs, 1000.0, 100000, most=64)
    assert done.samples <= 64 and device.groups_done == 0


def test_a_bake_slice_never_lands_inside_a_banded_sample_that_reads_the_probes(ctx):
    """Issue 55: the raymarcher's first frame in bands over a bake's slices read two states of
    the probes (a seam in the image). Paced by the wall clock, the bake now waits while such a
    sample is in bands and takes its turn between whole samples; both still finish."""
    from radiance_probes.io.scene_file import parse_scene
    from radiance_probes.viewer.frame.session import RenderSession
    scene = parse_scene({**SCENE, "probes": {"grid": [4, 4, 4], "samples": 32}})
    s = RenderSession(ctx, scene, seed=7)
    try:
        assert s.pacer.wall                               # llvmpipe
        s.frame_budget_ms = s.bake_budget_ms = 1e-3       # one tile, one slice's least a frame
        s.resize(24, 21)
        s.set_methods(["raymarch"])
        view = s.views["raymarch"]
        slices_in_bands, whole_seen, frames = 0, 0, 0
        while not (s.probes_ready() and view.acc.samples >= 2):
            in_bands = view.acc.groups_done > 0
            times = s.step(100, True)
            s.record_frame(times)
            slices_in_bands += in_bands and times.bake_ms > 0
            whole_seen += s.shows_whole("raymarch")
            frames += 1
            assert frames < 600
        assert slices_in_bands == 0
        assert s.bake_passes_run > 1 and whole_seen > 0   # the slices and the frames took turns
        # its image is exactly the raymarcher's whole frames over the finished probes
        np.testing.assert_array_equal(view.acc.read_rgba(), _whole(s.renderer, "raymarch", 2))
        assert s.label("raymarch") == "raymarch  2 frames"
    finally:
        s.release()
