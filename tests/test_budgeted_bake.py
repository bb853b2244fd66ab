"""The budgeted bake (issue 12): slices of chunks give the same probes as whole passes; a warm
restart after an edit ends at the cold bake's probes; an edit in the middle of a bake restarts it
for the new state, and the old state's partial probes never count as finished."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [8, 8, 8]}, "density_scale": 30.0,
         "albedo": 0.8, "camera": {"width": 24, "height": 16},
         "probes": {"grid": [4, 4, 4], "samples": 192, "fit": "box"}}


def _textures(r) -> list[np.ndarray]:
    return [np.frombuffer(t.read(), np.float32).copy() for t in r.probe_grid.textures]


@pytest.fixture
def renderer(ctx):
    r = Renderer(ctx, parse_scene(SCENE))
    yield r
    r.release()


def _small_chunks(r, probes=5):
    """Many chunks per pass (the grid's buffers are sized for more, so fewer is safe)."""
    r.start_bake(0)
    r.probe_grid.chunk_probes = probes


def test_slices_give_the_probes_of_one_whole_bake(renderer):
    r = renderer
    _small_chunks(r)
    grid = r.probe_grid
    assert grid.count == 64 and grid.passes_total == 3
    r.invalidate()
    r.bake(seed=5)
    whole = _textures(r)
    r.invalidate()
    # the light grid the walks read comes first, a slab of sun rays a slice at this budget
    depth = r._light.layers
    assert depth > 1
    for layer in range(depth):
        assert not r.light_current() and r.bake_step(5, budget_ms=1e-6) > 0
        assert r._light.next_layer == layer + 1 and grid.next_probe == 0 and grid.passes_done == 0
    assert r.light_current()
    slices = 0
    while not r.probes_current():
        ms = r.bake_step(5, budget_ms=1e-6)      # FIRST_SLICE_PROBES, then one probe a slice
        assert ms > 0
        slices += 1
        if slices == 1:
            assert grid.next_probe == 0 and grid.passes_done == 1
        if slices == 2:
            assert grid.next_probe == 1 and not grid.done
    assert slices == 1 + 2 * 64
    assert all(np.array_equal(a, b) for a, b in zip(whole, _textures(r)))
    assert np.abs(whole[0]).max() > 0
    # uneven slices across pass ends (a dispatch per 5 probes within each)
    r.invalidate()
    r.start_bake(5)
    light = r._light
    for n in (7, 60, 3, 64, 50):
        grid.bake_probes(r.resources, n, light=light)
    assert grid.probes_left == 3 * 64 - 184
    grid.bake_probes(r.resources, 1000, light=light)
    assert grid.done and all(np.array_equal(a, b) for a, b in zip(whole, _textures(r)))


def test_budget_follows_the_measured_probe_time(renderer):
    r = renderer
    _small_chunks(r)
    r.invalidate()
    r.bake_light()
    r.bake_step(1, budget_ms=1e-6)
    r.bake_step(1, budget_ms=1e-6)
    per_probe = next(iter(r._probe_ms.values()))
    before = r.probe_grid.probes_left
    r.bake_step(1, budget_ms=per_probe * 20.5)   # about 20 probes fit
    ran = before - r.probe_grid.probes_left
    assert ran == 20


def test_sliced_light_grid_is_the_whole_one(ctx):
    """Slabs of sun rays give the grid of one dispatch, bit for bit; an edit in the middle of a
    sliced bake restarts it for the new state; the raymarcher reads a sliced bake as it is."""
    r = Renderer(ctx, parse_scene({**SCENE, "volume": {"builtin": "cloud", "size": [12, 10, 9]}}))
    try:
        r.bake_light()
        whole = r._light.read().copy()
        assert whole.max() > 0
        r.invalidate()
        ms = r.bake_light(budget_ms=1e-6)          # the first slab: 1/16 of the layers, at least 1
        assert ms > 0 and r.light_baking() and not r.light_current()
        assert r._light.next_layer == 1
        per_layer = next(iter(r._layer_ms.values()))
        r.bake_light(budget_ms=per_layer * 3.5)    # about three layers fit
        assert r._light.next_layer == 4
        # the raymarcher renders from the grid as it is, without finishing it
        r.begin("raymarch", 8, 8)
        r.bake()                                   # (the probes; this finishes the light grid)
        assert r.light_current()
        r.invalidate()
        r.bake_light(budget_ms=1e-6)
        r.begin("raymarch", 8, 8)
        r.add_samples(1)
        assert r.light_baking() and r._light.next_layer == 1
        while not r.light_current():
            r.bake_light(budget_ms=1e-6)
        assert np.array_equal(whole, r._light.read())
        assert r.light_cost_ms > 0
        # an edit mid-bake: the new state's grid from its first layer
        r.invalidate()
        r.bake_light(budget_ms=1e-6)
        r.bake_light(budget_ms=1e-6)
        assert r._light.next_layer == 2
        r.set_scene(r.scene.replace(density_scale=r.scene.density_scale * 2))
        r.bake_light(budget_ms=1e-6)
        assert r._light.next_layer == 1
        r.bake_light()
        doubled = r._light.read()
        np.testing.assert_allclose(doubled, 2 * whole, rtol=1e-4, atol=1e-6)
        # the sun moves: a new sheared layout, baked slice by slice into a texture of its own
        # while readers keep the previous grid whole (the old rays would be read at the wrong
        # places in the new layout); the last slice hands it over, equal to one whole bake
        from dataclasses import replace
        old_layout, before = r._light.layout, r._light.read().copy()
        r.set_scene(r.scene.replace(light=replace(r.scene.light, direction=(0.7, 0.2, -0.6))))
        r.bake_light(budget_ms=1e-6)
        light = r._light
        assert light.target_layout is not None and light.target_layout != old_layout
        assert r.light_baking() and not r.light_current() and light.next_layer == 1
        assert light.layout == old_layout and np.array_equal(light.read(), before)
        assert light.uniforms()["light_grid_shear"] == old_layout.shear
        assert light.gpu_bytes > 2 * before.size   # both textures, 16-bit texels
        slices = 1
        while not r.light_current():
            r.bake_light(budget_ms=1e-6)
            slices += 1
        assert slices == light.layers and light.target_layout is None
        assert light.layout != old_layout
        moved = light.read().copy()
        r.invalidate()
        r.bake_light()
        np.testing.assert_array_equal(moved, r._light.read())
    finally:
        r.release()


def test_warm_restart_ends_at_the_cold_bake(renderer):
    r = renderer
    r.bake(seed=2)
    old = _textures(r)
    edited = r.scene.replace(density_scale=36.0)
    r.set_scene(edited)
    r.configure(bake_warm=False)
    r.bake(seed=9)
    cold = _textures(r)
    r.set_scene(r.scene.replace(density_scale=30.0))
    r.bake(seed=2)
    assert all(np.array_equal(a, b) for a, b in zip(old, _textures(r)))
    r.set_scene(edited)
    r.configure(bake_warm=True)
    r.bake_step(9)          # the first pass: blended with the old probes
    first = _textures(r)
    assert r.probe_grid.warm_walks > 0
    while not r.probes_current():
        r.bake_step(9)
    warm = _textures(r)
    assert all(np.array_equal(a, b) for a, b in zip(cold, warm))
    # while it ran, the shown probes lay between the old ones and the new mean
    assert not np.array_equal(first[0], cold[0]) and not np.array_equal(first[0], old[0])


def test_an_edit_in_the_middle_of_a_bake_is_not_lost(renderer):
    r = renderer
    _small_chunks(r)
    r.invalidate()
    r.bake_step(4, budget_ms=1e-6)
    r.bake_step(4, budget_ms=1e-6)
    assert not r.probes_current()
    edited = r.scene.replace(albedo=0.5)
    r.set_scene(edited)
    assert not r.probes_current()       # the old state's partial probes are not final
    while not r.probes_current():
        r.bake_step(4, budget_ms=1e-6)
    assert r._baked_key == r.bake_key()
    got = _textures(r)
    r.configure(bake_warm=False)
    r.invalidate()
    r.bake(seed=4)
    assert all(np.array_equal(a, b) for a, b in zip(got, _textures(r)))


def test_the_interact_replay_runs_end_to_end(ctx, tmp_path):
    """--preset interact at a tiny size: every event's record with its fields, warm and cold
    edits, the dispatch tail, the references cached by name and reused, the report and plot."""
    import json

    from radiance_probes.bench.config import PRESETS
    from radiance_probes.bench.report import write_report
    from radiance_probes.bench.runner import run_bench
    config = PRESETS["interact"].scaled(
        scenes=("tiny",), interact_sizes=((24, 16),), interact_probes=((3, 64),),
        interact_ref_spp=64, ref_samples_per_pass=32, interact_orbit_frames=3,
        interact_max_frames=6, interact_frame_budget_ms=1.0,
        interact_target_spp=(("probes", 4), ("raymarch", 2)), interact_tail_k=2,
        speed_check_rays=1 << 10)
    path = run_bench(config, tmp_path / "a")
    data = json.loads(path.read_text())
    recs = data["records"]
    events = [(r["event"], r["method"], r["variant"]) for r in recs]
    session = lambda m: [("load", m, None), ("orbit", m, None),  # noqa: E731
                         *[(e, m, v) for e in ("tf_drag", "sun_30deg", "density", "albedo")
                           for v in ("warm", "cold")]]
    # the session replayed with each method, against the same references (rendered once)
    assert events == [*session("probes"), *session("raymarch"), ("raymarch_switch", "raymarch", None),
                      ("dispatch_tail", "raymarch", None), ("dispatch_tail", "probes", None),
                      ("dispatch_tail", "pt", None)]
    for r in recs:
        assert r["mode"] == "interact" and r["scene"] == "tiny" and (r["width"], r["height"]) == (24, 16)
        if r["event"] == "dispatch_tail":
            assert r["ms_per_sample_1"] > 0 and r["ms_per_sample_k"] > 0
            continue
        for key in ("frame_ms_p50", "frame_ms_p99", "first_frame_ms", "final_rrmse",
                    "first_frame_wall_ms", "frame_wall_ms_p50", "frame_wall_ms_p99"):
            assert r[key] is not None and np.isfinite(r[key]), key
        assert r["frame_ms_p99"] >= r["frame_ms_p50"] > 0
        assert r["speed_check_ms"] > 0   # the device's speed after the event's frames
        for key in ("ms_to_10pct", "ms_to_5pct", "ms_to_3pct"):
            assert key in r
            assert r[key] is None or r[key] > 0
            if r[key] is None:   # never reached: the final error says by how much
                assert r["final_rrmse"] > float(key[6:-3]) / 100
        times = [t for t, _ in r["curve"]]
        assert times == sorted(times)
        walls = [t for t, _ in r["wall_curve"]]
        assert walls == sorted(walls) and len(walls) == len(times)
        # one trace entry per frame: its bake slice and samples add up to the frame's GPU time
        trace = r["frame_trace"]
        assert len(trace) == r["frames"]
        assert abs(sum(f[0] + f[1] + f[-1] for f in trace) - r["total_ms"]) < 1e-2 * max(1.0, r["total_ms"])
        assert all(f[2] >= 1 and f[3] in ("probes", "raymarch") for f in trace)
        if r["event"] in ("tf_drag", "sun_30deg", "density", "albedo"):
            assert trace[0][0] > 0    # the re-bake's first slice
    assert recs[-4]["method"] == "raymarch" and recs[1]["orbit_frames"] == 3
    assert recs[1]["frames"] >= 3
    # the edit's re-bake happened in the timed frames: its first frame pays a bake slice
    assert all(r["first_frame_ms"] > 0 for r in recs[:-3])
    assert set(data["references"]) == {f"tiny_24x16_{k}" for k in
                                       ("load", "orbit", "tf_drag", "sun_30deg", "density",
                                        "albedo")}
    text = write_report(path).read_text()
    assert "Interaction" in text and "| tiny | 24x16 | 3^3x64 | tf_drag | probes | warm |" in text
    assert "The device's speed during the run" in text
    assert (tmp_path / "a" / "interact.png").is_file()
    again = run_bench(config.scaled(reference_dir=str(tmp_path / "a")), tmp_path / "b")
    refs = json.loads(again.read_text())["references"]
    assert all("loaded_from" in v for v in refs.values()) and len(refs) == 6


def _baking_step(s):
    """Frames until one bakes a slice: paced by the wall clock (llvmpipe) the bake waits for a
    raymarched sample in bands to be whole (viewer/session.py, BAKE_TURN_RATIO)."""
    for _ in range(200):
        times = s.step(64, True)
        if times.bake_ms > 0:
            return times
        assert s.pacer.wall   # (paced by GPU time, samples are whole: every frame bakes)
    raise AssertionError("no frame baked")


def test_the_viewer_session_bakes_in_slices_and_shows_probes_after_each(ctx):
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE))
    try:
        s.resize(24, 16)
        s.set_methods(["raymarch"])
        s.renderer.start_bake(0)
        s.renderer.probe_grid.chunk_probes = 5
        s.renderer.invalidate()
        s.step(64, True)                             # a slab of the light grid comes first
        grid = s.renderer.probe_grid
        assert s.renderer.light_baking() and grid.next_probe == 0 and grid.passes_done == 0
        s.renderer.bake_light()                      # (the rest of it at once)
        _baking_step(s)
        assert not grid.done and grid.next_probe == 0 and grid.passes_done == 1
        per_probe = next(iter(s.renderer._probe_ms.values()))
        s.bake_budget_ms = per_probe * 10.5          # about 10 probes a frame
        _baking_step(s)
        assert grid.passes_done == 1 and 5 <= grid.next_probe <= 20   # a budget, not a pass
        # the picture from the probes it has (paced by the wall clock, as on llvmpipe, a sample
        # may be part done in bands, and between whole samples the bake takes its turn while the
        # last whole image shows: tests/test_sample_bands.py)
        view = s.views["raymarch"]
        assert (s.samples("raymarch") > 0 or view.acc.groups_done > 0
                or (view.held is not None and s.shows_whole("raymarch")))
        frames, rendered = 1, 0
        while not s.probes_ready():
            times = s.step(64, True)
            rendered += times.samples > 0 or times.tiles > 0
            frames += 1
            if frames == 4:                          # an edit in the middle of the bake
                s.set_scene(s.scene.replace(albedo=0.6))
        assert frames > 4 and s.bake_generation == 2 and s.renderer._baked_key == s.renderer.bake_key()
        assert rendered > 0                          # the picture kept up with the probes
        assert s.bake_report is not None and s.bake_report.passes_done == grid.passes_total
    finally:
        s.release()


def test_probe_methods_show_the_raymarcher_while_baking_then_their_own(ctx):
    """While the probes bake, a `probes` view accumulates the raymarcher over the probes as they
    are (and says so in its caption); when the bake ends it restarts as `probes` and converges
    to the image of a finished bake. The frame's budget left after the slice sets the samples.
    Paced by GPU time, as on a GPU (paced by the wall clock, as llvmpipe is, a sample may be cut
    into bands of rows: tests/test_sample_bands.py)."""
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE), clock="gpu")
    try:
        s.resize(24, 16)
        s.set_methods(["probes"])
        s.bake_budget_ms = 1e-6                      # one light layer or one probe a frame
        s.step(8, True)
        view = s.views["probes"]
        assert view.shown == "raymarch" and "raymarch meanwhile" in s.label("probes")
        frames = 1
        while not s.renderer.probes_current():
            s.step(8, True)
            frames += 1
            assert view.shown == "raymarch" or s.renderer.probes_current()
        assert frames > 10
        assert not s.finished(8, True)
        s.step(8, True)
        assert view.shown == "probes" and s.label("probes").startswith("probes  ")
        while not s.finished(8, True):
            s.step(8, True)
        assert view.samples == 8
        want = s.renderer.render("probes", spp=8, seed=s.seed).image
        np.testing.assert_allclose(s.image("probes"), want, rtol=1e-5, atol=1e-6)
        # samples per frame from the budget the slice left: none left -> one each
        s.set_scene(s.scene.replace(albedo=0.5))
        s.frame_budget_ms = 0.0
        s.views["probes"].dispatch_ms["raymarch"] = [(1, 1.0), (4, 4.0)]
        s.step(8, True)
        assert view.samples == 1
        s.frame_budget_ms = 1e6
        s.bake_budget_ms = 0.0
        before = view.samples
        s.step(8, True)                              # a restart after the slice, then 8 at once
        assert view.samples == 8 and before == 1
    finally:
        s.release()


def test_samples_per_frame_follow_the_recent_dispatches_cost_per_sample():
    """As many samples as fit in the budget at the median GPU ms per sample of the last
    RECENT_DISPATCHES dispatches: a dispatch that paid for a shader compile does not set the pace,
    and a change of cost (an edit) takes over within a few frames."""
    from radiance_probes.viewer.frame.session import RECENT_DISPATCHES, RenderSession
    from radiance_probes.viewer.frame.views import MethodView
    view = MethodView("probes")
    per_frame = RenderSession.samples_per_frame
    assert per_frame(view, 6.0) == 1                                   # nothing timed yet
    view.dispatch_ms["probes"] = [(1, 0.8), (8, 6.4)]                  # 0.8 ms a sample
    assert per_frame(view, 14.0) == 17 and per_frame(view, 0.5) == 1
    view.dispatch_ms["probes"] += [(16, 400.0), (16, 12.8)]            # one compile among them
    assert per_frame(view, 14.0) == 17
    view.dispatch_ms["probes"] += [(8, 12.8), (8, 12.8), (8, 12.8)]    # an edit: 1.6 ms a sample
    view.dispatch_ms["probes"] = view.dispatch_ms["probes"][-RECENT_DISPATCHES:]
    assert per_frame(view, 14.0) == 8
    view.dispatch_ms["raymarch"] = [(1, 2.0), (3, 6.0)]                # per method shown
    view.shown = "raymarch"
    assert per_frame(view, 12.5) == 6 and per_frame(view, 1.0) == 1
