"""Streaming a mixed pool's finer level as the camera moves (app/rendering/levels/level_stream.py): after a
restream the pool is what a fresh placement for that camera gives (page table per brick, the
bricks' texels, the constants, the majorant grid, the images), each brick loaded is read once,
the pool never holds more than its slots, the same camera writes nothing, a budget spreads the
work over calls with the medium changing only at commits, and the checking build finds no page
miss."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.io.brick_layout import CONSTANT, REDIRECT
from radiance_probes.io.brick_sources import box_filtered
from radiance_probes.rendering.levels.level_mix import coarse_ranges_read, mixed_density_ranges
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.renderer import METHODS
from radiance_probes.twins.brick_pool import brick_block, bricked_sample, mixed_reference
from radiance_probes.twins.majorant_grid import brick_density_range_grid, macrocell_counts
from test_level_mix import BRICK, _cap, _gpu_packed, _renderer
from test_level_mix import _scene as _mix_scene


def _scene(width=48, height=36):
    """test_level_mix's scene with 256 walks a probe instead of 2048: these tests compare two
    renderers baked alike, or check reads, and the walks' re-bakes after every restream took
    most of their time on llvmpipe (45 s in test_no_page_miss_after_restreams alone)."""
    scene = _mix_scene(width, height)
    return scene.replace(probes=replace(scene.probes, samples=256))


# Level 0's slots (16 of its 27 bricks that are not constant) taken from:
EYE_A = (-0.9, 0.55, 1.0)      # the -x +y +z corner (26 bricks worth a slot)
EYE_B = (0.9, -0.55, -1.0)     # the opposite corner: 2 of A's 16 bricks kept, 14 others
EYE_C = (0.9, 0.55, 1.0)       # 9 of A's kept
EYE_FAR = (0.0, 0.0, 6.0)      # no brick worth a slot


def _at(scene, eye):
    return scene.replace(camera=replace(scene.camera, eye=eye))


def _bricks(pool) -> dict:
    """{(level, z, y, x): what the brick reads} of a pool read back from the GPU: ("C",) for a
    brick of level 0 that reads level 1, ("constant", its value) for a constant, ("slot", its
    texels) for a resident brick (whichever slot holds it), ("unmapped",)."""
    packed = _packed_any(pool)
    out = {}
    side = pool.brick + 2
    for level in (0, 1):
        z0 = packed.level_table_z[level]
        bx, by, bz = packed.counts_of(level)
        for z, y, x in np.ndindex(bz, by, bx):
            e = int(packed.table[z0 + z, y, x])
            if e & CONSTANT:
                what = ("constant", tuple(packed.constants[e & ~CONSTANT]))
            elif e & REDIRECT:
                what = ("C",) if e != 0x3FFFFFFF else ("unmapped",)
            else:
                o = packed.slot_texels(np.int64(e))
                what = ("slot", packed.atlas[o[2]:o[2] + side, o[1]:o[1] + side,
                                             o[0]:o[0] + side].copy())
            out[(level, z, y, x)] = what
    return out


def _assert_same_bricks(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert a[key][0] == b[key][0], (key, a[key][0], b[key][0])
        if a[key][0] == "slot":
            np.testing.assert_array_equal(a[key][1], b[key][1], err_msg=str(key))
        else:
            assert a[key] == b[key], key


def _levels(r):
    source = r.resources.volume.bricks.source
    nz, ny, nx = source.shape[:3]
    data = np.asarray(source.density(source.read(0, nz, 0, ny, 0, nx)), np.float32)
    return [data, box_filtered(data)]


def _check_twin(r) -> None:
    """The pool read back is the twin's mixed medium for the level each brick reads, and each
    resident brick's texels are the twin's block of it (brick_block, as pack_levels packs)."""
    pool = r.resources.volume_tex
    packed = _gpu_packed(pool)
    bz = pool.plan.mix.fine.counts[2]
    which = np.where((packed.table[:bz] & (CONSTANT | REDIRECT)) == REDIRECT, 1, 0)
    levels = _levels(r)
    uvw = np.random.default_rng(4).uniform(-0.02, 1.02, (20000, 3))
    assert np.abs(bricked_sample(packed, uvw) - mixed_reference(levels, which, BRICK, uvw)).max() \
        < 1e-5
    for (level, z, y, x), what in _bricks(pool).items():
        if what[0] == "slot":
            np.testing.assert_array_equal(what[1], brick_block(levels[level], (x, y, z), BRICK))


def _within_cap(r, scene) -> None:
    pool = r.resources.volume_tex
    stream = r.resources.stream
    assert pool.nbytes <= _cap(scene)
    assert stream.resident <= stream.mix.f_slots
    held = int(np.count_nonzero(pool.brick_of_slot != 0xFFFFFFFF))
    assert held == stream.resident + stream.mix.c_slots <= stream.mix.capacity


@pytest.mark.parametrize("placed, to", [(EYE_A, EYE_B), (EYE_A, EYE_C), (EYE_FAR, EYE_B)])
def test_restream_gives_the_fresh_placements_pool_and_images(ctx, placed, to):
    scene = _at(_scene(), placed)
    r = _renderer(ctx, scene)
    fresh = _renderer(ctx, _at(scene, to))
    try:
        stream = r.resources.stream
        assert stream is not None
        version = r.resources.volume_version
        r.set_scene(_at(scene, to))
        assert r.restream() is True
        assert r.resources.volume_version > version and stream.pending is None
        _within_cap(r, scene)
        _assert_same_bricks(_bricks(r.resources.volume_tex), _bricks(fresh.resources.volume_tex))
        _check_twin(r)
        cells = macrocell_counts(r.resources.volume.dims)
        for got, want in zip(r.resources.volume.derived[("density ranges", cells)],
                             fresh.resources.volume.derived[("density ranges", cells)]):
            np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(r.resources.majorant_grid.read(),
                                      fresh.resources.majorant_grid.read())
        for method in ("raymarch", "pt"):
            a = r.render(method, spp=2, seed=3).image
            b = fresh.render(method, spp=2, seed=3).image
            # the same texels at other slots: only the texture coordinates' rounding differs
            assert np.sqrt(np.mean((a - b) ** 2)) <= 1e-5 * max(np.sqrt(np.mean(b ** 2)), 1e-9), \
                method
    finally:
        r.release()
        fresh.release()


def test_bricks_leave_and_come_back_read_once_a_load_within_the_slots(ctx):
    scene = _at(_scene(), EYE_A)
    r = _renderer(ctx, scene)
    try:
        stream = r.resources.stream
        pool = r.resources.volume_tex
        fine = stream.fine
        at_a = set(stream.slot_of)
        # a brick of one value (its apron not: else it is constant) is loaded from its range,
        # not read (app/io/bricks.py: the upload reads bricks of more than one value)
        lo, hi = (np.asarray(a) for a in fine.ranges())
        one_value = np.all(lo == hi, axis=-1) if lo.ndim == 4 else lo == hi
        for eye in (EYE_B, EYE_C, EYE_A, EYE_FAR, EYE_A):
            before = fine.reads.copy()
            resident = set(stream.slot_of)
            assert r.restream(_at(scene, eye).camera) is True
            loaded = set(stream.slot_of) - resident
            delta = fine.reads - before
            assert delta.max() <= 1                       # every brick read once at most
            for b in loaded:
                assert delta[b] == (0 if one_value[b] else 1)
            assert stream.last["loaded"] == len(loaded)
            assert stream.last["evicted"] == len(resident - set(stream.slot_of))
            _within_cap(r, scene)
        assert set(stream.slot_of) == at_a               # A's bricks back
        assert stream.evicted > 0 and stream.loaded > 0
        # the same camera again: nothing chosen, read or written; nothing stale
        uploads, table_writes = pool.uploads, pool.table_writes
        reads, version = fine.reads.copy(), r.resources.volume_version
        assert r.restream(_at(scene, EYE_A).camera) is False
        assert (pool.uploads, pool.table_writes) == (uploads, table_writes)
        np.testing.assert_array_equal(fine.reads, reads)
        assert r.resources.volume_version == version
    finally:
        r.release()


def test_a_camera_move_that_keeps_the_mix_bakes_nothing_again_and_one_that_changes_it_does(ctx):
    scene = _at(_scene(), EYE_A)
    r = _renderer(ctx, scene)
    try:
        r.render("probes", spp=1, seed=1)
        key = r.bake_key()
        # a little further along the same line: the same bricks deserve F's slots
        nudged = _at(scene, tuple(1.01 * v for v in EYE_A))
        r.set_scene(nudged)
        assert r.restream() is False
        assert r.bake_key() == key and r.probes_current()
        r.set_scene(_at(scene, EYE_B))
        r.render("raymarch", spp=1, seed=1)           # render() restreams
        assert r.bake_key() != key
        assert r.resources.stream.camera == r.scene.camera
    finally:
        r.release()


def test_a_budget_spreads_the_loads_and_the_medium_changes_only_at_commits(ctx):
    scene = _at(_scene(), EYE_FAR)
    r = _renderer(ctx, scene)
    fresh = _renderer(ctx, _at(scene, EYE_B))
    try:
        stream = r.resources.stream
        pool = r.resources.volume_tex
        table = _gpu_packed(pool).table.copy()
        version = r.resources.volume_version
        cam = _at(scene, EYE_B).camera
        calls = 0
        while True:
            calls += 1
            changed = r.restream(cam, budget_s=0.0)     # one brick a call
            if changed:
                break
            # written into free slots, nothing reads them yet
            np.testing.assert_array_equal(_gpu_packed(pool).table, table)
            assert r.resources.volume_version == version
            assert "streaming" in stream.status()
        assert calls == stream.last["loaded"] + 1 and stream.last["commits"] == 1
        assert stream.status() is None
        _assert_same_bricks(_bricks(pool), _bricks(fresh.resources.volume_tex))
        # A's loads need B's slots: B's bricks are evicted first (a commit), then A's written
        at_b = set(stream.slot_of)
        assert r.restream(_at(scene, EYE_A).camera, budget_s=0.0) is True
        assert stream.pending is not None and set(stream.slot_of) < at_b
        # back to B half way: the A brick written and not committed is forgotten, B's loaded
        assert r.restream(_at(scene, EYE_B).camera) is True
        assert stream.pending is None
        _assert_same_bricks(_bricks(pool), _bricks(fresh.resources.volume_tex))
        _within_cap(r, scene)
    finally:
        r.release()
        fresh.release()


def test_no_page_miss_after_restreams(checked_ctx):
    ctx, checks = checked_ctx
    scene = _at(_scene(32, 24), EYE_A)
    r = _renderer(ctx, scene)
    try:
        checks.reset()
        for eye in (EYE_B, EYE_FAR, EYE_C, EYE_A):
            r.set_scene(_at(scene, eye))
            for method in METHODS:
                image = r.render(method, spp=1, seed=1).image
                assert np.isfinite(image).all(), (eye, method)
                assert checks.hits() == {}, (eye, method, checks.hits())
    finally:
        r.release()


def test_mixed_density_ranges_are_the_brick_by_brick_ranges(ctx):
    """coarse_ranges_read (array operations) against the bricks reached, brick by brick."""
    from radiance_probes.io.bricks import BrickStore
    from radiance_probes.io.brick_sources import ArraySource
    from radiance_probes.io.brick_layout import around, bricks_reached
    rng = np.random.default_rng(1)
    fine_data = rng.uniform(0, 1, (27, 21, 37)).astype(np.float32)
    fine_data[:, :9] = 0.0
    fine = BrickStore(ArraySource(fine_data), BRICK)
    coarse = BrickStore(ArraySource(box_filtered(fine_data)), BRICK)
    level_of = rng.integers(0, 2, fine.counts[::-1])
    lo_c, hi_c = (around(np.asarray(v, np.float32), op) for v, op in
                  zip(coarse.ranges(), (np.minimum, np.maximum)))
    lo_f, hi_f = (around(np.asarray(v, np.float32), op) for v, op in
                  zip(fine.ranges(), (np.minimum, np.maximum)))
    got_lo, got_hi = coarse_ranges_read(fine, coarse)
    want_lo, want_hi = lo_f.copy(), hi_f.copy()
    for z, y, x in np.ndindex(*fine.counts[::-1]):
        a, b = bricks_reached(fine.dims, coarse.dims, BRICK, (x, y, z), (x, y, z))
        sl = (slice(a[2], b[2] + 1), slice(a[1], b[1] + 1), slice(a[0], b[0] + 1))
        assert got_lo[z, y, x] == lo_c[sl].min() and got_hi[z, y, x] == hi_c[sl].max()
        if level_of[z, y, x] == 1:
            want_lo[z, y, x], want_hi[z, y, x] = lo_c[sl].min(), hi_c[sl].max()
    cells = macrocell_counts(fine.dims)
    for got, want in zip(mixed_density_ranges(fine, coarse, level_of, cells),
                         brick_density_range_grid(want_lo, want_hi, fine.dims, BRICK, cells)):
        np.testing.assert_array_equal(got, want)


def _packed_any(pool):
    """_gpu_packed for any brick size."""
    from radiance_probes.twins.brick_pool import Packed
    gz, gy, gx = pool.grid[::-1]
    side = pool.brick + 2
    atlas = np.frombuffer(pool.atlas.read(), np.float32).reshape(gz * side, gy * side, gx * side)
    table = np.frombuffer(pool.table.read(), np.uint32).reshape(pool.table.size[::-1])
    constants = np.frombuffer(pool.constants.read(), np.float32).reshape(-1, 4)
    return Packed(atlas, table, constants, pool.grid, pool.brick, pool.dims, pool.brick_of_slot,
                  pool.level_dims, pool.level_table_z)


def test_a_store_placed_from_far_reads_level_0_when_the_camera_comes_near(ctx, tmp_path):
    """An OME-Zarr store placed for a far camera: level 0's range pass unread, every brick of
    level 0 reads level 1. Restreamed for a near camera, the range pass is read then, level 0's
    constant bricks become constants and its bricks worth a slot are loaded: the pool and image
    of a fresh placement for the near camera."""
    from radiance_probes.io.bricks import BrickStore
    from radiance_probes.io.brick_layout import slot_bytes
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.rendering.settings import RenderSettings
    from radiance_probes.rendering.levels.volume_placement import level_bytes
    from radiance_probes.io.load import load_scene_volume
    from test_level_bound import _store
    brick = 16
    scene = _store(tmp_path)
    cam = replace(scene.camera, width=64, height=48, target=(0.0, 0.0, 0.0))
    far = scene.replace(camera=replace(cam, eye=(0.0, 0.0, 40.0)))
    near = scene.replace(camera=replace(cam, eye=(0.0, 0.0, 0.9)))
    level1 = BrickStore(load_scene_volume(scene, brick=brick).levels[0], brick)
    cap = level_bytes(level1, 1, False, 2048) + 4 * slot_bytes(brick, 1, False)
    settings = RenderSettings(brick_size=brick, volume_memory_bytes=cap)
    r = Renderer(ctx, far, settings=settings, lab=LabOptions(mixed_levels=True))
    fresh = Renderer(ctx, near, settings=settings, lab=LabOptions(mixed_levels=True))
    try:
        stream = r.resources.stream
        assert stream.const_f is None and not stream.fine.ranges_read and stream.resident == 0
        r.set_scene(near)
        assert r.restream() is True and stream.const_f is not None and stream.resident > 0
        _assert_same_bricks(_bricks(r.resources.volume_tex), _bricks(fresh.resources.volume_tex))
        assert r.resources.volume_tex.nbytes <= cap
        a = r.render("raymarch", spp=1, seed=3).image
        b = fresh.render("raymarch", spp=1, seed=3).image
        assert np.sqrt(np.mean((a - b) ** 2)) <= 1e-5 * max(np.sqrt(np.mean(b ** 2)), 1e-9)
    finally:
        r.release()
        fresh.release()


def test_the_viewer_restreams_once_the_camera_settles_a_budget_a_frame(ctx, monkeypatch):
    """Viewer._restream: nothing while the camera keeps moving; once it has not moved for
    RESTREAM_SETTLE_S, a restream goes on a frame at a time (the Volume panel's status line)
    and, when it commits, the session's accumulations restart."""
    from radiance_probes.rendering.settings import RenderSettings
    from radiance_probes.viewer import viewer as viewer_module
    from radiance_probes.viewer.state import ViewerState
    scene = _at(_scene(32, 24), EYE_A)
    settings = RenderSettings(brick_size=BRICK, volume_memory_bytes=_cap(scene))
    v = viewer_module.Viewer(ctx, ViewerState(scene, scene.camera), settings=settings,
                             lab=LabOptions(mixed_levels=True))
    clock = [100.0]
    monkeypatch.setattr(viewer_module.time, "perf_counter", lambda: clock[0])
    monkeypatch.setattr(viewer_module, "OPEN_WRITE_BUDGET_S", 0.0)   # one brick a frame
    monkeypatch.setattr(v, "_mouse_held", lambda: False)               # (no ImGui frame)
    try:
        v.session.resize(32, 24)
        v.session.set_methods(["raymarch"])
        stream = v.session.renderer.resources.stream
        v._restream()                       # the placement's camera, not yet settled
        assert stream.camera is None and v.stream_wanted()
        clock[0] += 1.0
        v._restream()                       # settled: the mix already held, nothing written
        assert stream.camera == v.stream_camera() and not v.stream_wanted()
        uploads = v.session.renderer.resources.volume_tex.uploads
        # a drag: a camera change each frame, no restream
        for i in range(5):
            v.state.set_camera(replace(v.state.scene.camera,
                                       eye=tuple(EYE_B[k] + 0.01 * i for k in range(3))))
            v.session.set_scene(v.state.scene)
            clock[0] += 0.05
            v._restream()
            assert stream.pending is None
        assert v.session.renderer.resources.volume_tex.uploads == uploads
        restarts = v.session.restarts
        clock[0] += 1.0
        frames = 0
        while v.stream_wanted():
            v._restream()
            frames += 1
            assert frames < 100
            if stream.pending is not None:
                assert stream.status().startswith("streaming")
                assert v.snapshot()["streaming"]["status"] == stream.status()
        assert frames > 2 and v.session.restarts > restarts
        assert v.snapshot()["streaming"]["commits"] >= 1
    finally:
        v.release()


def test_a_mix_with_no_finer_brick_yet_is_the_coarser_level_alone_marched_as_it(ctx):
    """Seen from far (no brick worth a slot), a streamed mix reads the coarser level everywhere:
    the raymarcher steps at that level's half voxel and its image is the coarser level's placed
    alone (mixed_levels off; the texture coordinates' rounding aside); once a brick of the finer
    level is in, the step is the finer level's. (The path tracer's samples differ: its majorant
    cells are the finer level's.)"""
    scene = _at(_scene(), EYE_FAR)
    r = _renderer(ctx, scene)
    alone = _renderer(ctx, scene, mixed_levels=False)
    try:
        assert r.resources.stream is not None and r.resources.stream.resident == 0
        assert alone.resources.volume.dims == r.resources.stream.coarse.dims
        assert r.resources.march_step == pytest.approx(alone.resources.march_step)
        a = r.render("raymarch", spp=2, seed=3).image
        b = alone.render("raymarch", spp=2, seed=3).image
        assert np.sqrt(np.mean((a - b) ** 2)) <= 1e-3 * np.sqrt(np.mean(b ** 2))
        r.set_scene(_at(scene, EYE_A))
        r.restream()
        assert r.resources.stream.resident > 0
        assert r.resources.march_step == pytest.approx(alone.resources.march_step / 2)
    finally:
        r.release()
        alone.release()
