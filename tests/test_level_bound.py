"""The lower bound on a level's bricks that are not constant, from a coarser level
(app/io/level_bound.py), and the placement that passes over a level too large for the cap without
its range pass (app/rendering/levels/volume_placement.py)."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.io.brick_sources import ArraySource, box_filtered
from radiance_probes.io.bricks import BrickStore
from radiance_probes.io.brick_layout import constant_bricks
from radiance_probes.io.level_bound import bound_level, inside_ranges, varying_bricks
from radiance_probes.rendering.levels.volume_placement import level_bytes, plan_placement
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.io.load import load_scene_volume

LIMITS = (2048, None, "the test's device")


def _blocky(shape, block: int, seed: int) -> np.ndarray:
    """[z, y, x] uint16: constant in most blocks of `block` voxels (zero or another value), and
    noisy or a ramp in the others; block edges are not brick edges where block is not the
    brick."""
    rng = np.random.default_rng(seed)
    counts = [-(-n // block) for n in shape]
    kind = rng.integers(0, 5, size=counts)
    value = rng.integers(1, 60000, size=counts)
    out = np.zeros(shape, np.float64)
    for (bz, by, bx), k in np.ndenumerate(kind):
        sl = tuple(slice(b * block, (b + 1) * block) for b in (bz, by, bx))
        part = out[sl]
        if k == 1:
            part[...] = value[bz, by, bx]
        elif k == 2:
            part[...] = rng.integers(0, 65535, size=part.shape)
        elif k == 3:
            part[...] = np.linspace(0, 50000, part.shape[2])[None, None, :]
    return out.astype(np.uint16), kind


def _pyramids(fine: np.ndarray):
    """Coarser levels of `fine` [z, y, x] made as pyramids are: a rounded 2 x 2 x 2 mean, a
    strided sample, and a [1, 2, 1] blur along each axis before the stride (it reaches one voxel
    beyond the footprint); once (2x coarser: 4 voxels inside a brick of 16) and twice (4x: 2
    inside, or 1 where the dims do not divide, and then the bound says nothing)."""
    def mean(a):
        return np.round(box_filtered(a.astype(np.float32))).astype(np.uint16)

    def stride(a):
        return a[::2, ::2, ::2]

    def blur(a):
        b = a.astype(np.float64)
        for axis in range(3):
            p = np.pad(b, [(1, 1) if i == axis else (0, 0) for i in range(3)], mode="edge")
            n = b.shape[axis]
            b = (np.take(p, range(0, n), axis) + 2 * np.take(p, range(1, n + 1), axis)
                 + np.take(p, range(2, n + 2), axis)) / 4
        return np.round(b[::2, ::2, ::2]).astype(np.uint16)

    for make in (mean, stride, blur):
        yield make.__name__, 2, make(fine)
        yield make.__name__, 4, make(make(fine))


@pytest.mark.parametrize("shape", [(64, 48, 80), (61, 50, 77)])
def test_bricks_seen_varying_in_a_coarser_level_are_never_constant(shape):
    """Whatever the pyramid (mean, strided, blurred) and however the bricks fall (partial bricks
    at the far faces, dims not a multiple of 4), every brick the bound counts is one the range
    pass finds not constant; and where blocks are bricks, it counts every brick that varies inside."""
    brick = 16
    for seed, block in ((1, 16), (2, 12), (3, 20)):
        fine, kind = _blocky(shape, block, seed)
        store = BrickStore(ArraySource(fine.astype(np.float32) / 65535), brick)
        constant = constant_bricks(*store.ranges())
        dims = fine.shape[::-1]
        for name, ratio, coarse in _pyramids(fine):
            varying = varying_bricks(coarse.astype(np.float32) / 65535, dims, brick)
            assert varying.shape == constant.shape
            assert not np.any(varying & constant), (name, seed)
            if ratio == 2 and block == brick and not any(n % brick for n in shape):
                # blocks are bricks: the bound sees exactly those of noise or a ramp
                np.testing.assert_array_equal(varying, (kind == 2) | (kind == 3))
            elif ratio == 2:
                assert varying.sum() > 0, (name, seed)


def test_several_channels_vary_where_any_one_does():
    fine = np.zeros((32, 32, 32, 2), np.float32)
    fine[:16, :16, :16, 1] = np.linspace(0, 1, 16)[None, None, :]   # channel 1 varies in brick 0
    coarse = box_filtered(fine)
    varying = varying_bricks(coarse, (32, 32, 32), 16)
    assert varying[0, 0, 0] and varying.sum() == 1


def test_inside_ranges_keep_to_the_brick_inside_whatever_the_ratio():
    for n_fine, n_coarse, brick, margin in ((2048, 256, 64, 16), (100, 13, 16, 4),
                                            (1000, 501, 64, 16), (77, 20, 16, 4)):
        j0, j1 = inside_ranges(n_fine, n_coarse, brick, margin)
        s = n_fine / n_coarse
        for b, (a, e) in enumerate(zip(j0, j1)):
            lo, hi = b * brick + margin, min(b * brick + brick, n_fine) - margin
            for j in range(a, e):
                assert j * s >= lo - 1e-9 and (j + 1) * s <= hi + 1e-9
            # and no coarse voxel that lies inside is left out
            for j in (a - 1, e):
                if 0 <= j < n_coarse:
                    assert j * s < lo - 1e-9 or (j + 1) * s > hi + 1e-9
    j0, j1 = inside_ranges(2048, 256, 64, 16)
    assert np.all(j1 - j0 == 4)


def test_bound_level_is_the_coarsest_that_still_sees_inside_a_brick():
    class Level:
        def __init__(self, n):
            self.shape = (n, n, n)
    levels = [Level(1024), Level(512), Level(256), Level(128)]
    # bricks of 64 at 2048: 32 voxels inside, 4 of them at 256 (8x), 2 at 128
    assert bound_level((2048, 2048, 2048), levels, 64) is levels[2]
    assert bound_level((2048, 2048, 2048), levels[3:], 64) is None
    # a level of over BOUND_VOXELS is not read whole: 1024^3 sees 16 voxels inside a brick
    assert bound_level((2048, 2048, 2048), levels[:1], 64) is None


def _store(tmp_path, value_range=True, size=96, levels=3):
    """An OME-Zarr store (lab/experiments/brick_bench.py's procedural ball, mostly zero outside) and its
    scene; chunks of 16 voxels."""
    import importlib.util
    import sys
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("brick_bench", ROOT / "lab" / "experiments" / "brick_bench.py")
    bench = sys.modules.get("brick_bench")
    if bench is None:
        bench = importlib.util.module_from_spec(spec)
        sys.modules["brick_bench"] = bench
        spec.loader.exec_module(bench)
    path = tmp_path / "ball.zarr"
    bench.write_ome_zarr(path, (size, size, size), 16, levels)
    volume = {"path": str(path)}
    if value_range:
        volume["value_range"] = [0, 65535]
    return parse_scene({"volume": volume})


def test_a_cap_passes_over_level_0_without_its_range_pass_and_places_the_same(tmp_path):
    """With the scene's value range, opening reads no brick; under a cap that level 0's bound
    exceeds, level 0's range pass is never read, and the placement is the one the range pass
    gives: the same level, page table, constants and bricks."""
    brick = 16
    scene = _store(tmp_path)
    lazy = load_scene_volume(scene, brick=brick)
    level0 = lazy.bricks
    assert not level0.ranges_read and np.all(level0.reads == 0)
    assert lazy.raw_extents() is None
    level1 = BrickStore(lazy.levels[0], brick)
    cap = level_bytes(level1, 1, False, 2048)
    placed = plan_placement(lazy, LIMITS, cap, brick)
    assert not level0.ranges_read and np.all(level0.reads == 0)
    assert placed.shown.dims == (48, 48, 48)
    (note,) = [n for n in placed.shown.notes if n.startswith("level 1")]
    assert "at least" in note and "48 x 48 x 48 level" in note
    # the same as with level 0's range pass read
    again = load_scene_volume(scene, brick=brick)
    assert again.raw_extents(read=True) == ((0.0, float(again.bricks.raw_ranges()[1].max())),)
    want = plan_placement(again, LIMITS, cap, brick)
    assert level_bytes(again.bricks, 1, False, 2048) > cap
    assert want.shown.dims == placed.shown.dims
    np.testing.assert_array_equal(want.plan.table, placed.plan.table)
    np.testing.assert_array_equal(want.plan.constants, placed.plan.constants)
    assert want.plan.grid == placed.plan.grid
    # the extremes, once level 0's range pass is asked for, are the data's
    assert lazy.raw_extents(read=True) == again.raw_extents()


def test_level_0_that_fits_is_read_and_placed_whole(tmp_path):
    brick = 16
    scene = _store(tmp_path)
    lazy = load_scene_volume(scene, brick=brick)
    need = level_bytes(BrickStore(lazy.bricks.source, brick), 1, False, 2048)
    placed = plan_placement(lazy, LIMITS, need, brick)
    assert placed.shown.dims == (96, 96, 96) and lazy.bricks.ranges_read


def test_without_a_value_range_the_open_reads_the_range_pass(tmp_path):
    scene = _store(tmp_path, value_range=False)
    lazy = load_scene_volume(scene, brick=16)
    assert lazy.bricks.ranges_read
    (extent,) = lazy.raw_extents()
    assert extent[0] == 0.0 and extent[1] > 60000


def test_mixed_levels_read_no_finer_range_pass_where_no_brick_is_worth_a_slot(tmp_path):
    """Levels mixed by the camera: seen from far (no voxel of level 1 over the footprint that
    earns a slot), level 0's range pass is still not read: the pool is a mix (its bricks of level
    0 streamed in as the camera comes near: app/rendering/levels/level_stream.py) where every brick of
    level 0 reads level 1, level 1 whole."""
    from dataclasses import replace
    brick = 16
    scene = _store(tmp_path)
    lazy = load_scene_volume(scene, brick=brick)
    from radiance_probes.io.brick_layout import slot_bytes
    cap = level_bytes(BrickStore(lazy.levels[0], brick), 1, False, 2048) + 4 * slot_bytes(
        brick, 1, False)           # room for a few of level 0's bricks, not for level 0
    far = replace(scene.camera, eye=(0.0, 0.0, 40.0), target=(0.0, 0.0, 0.0))
    placed = plan_placement(lazy, LIMITS, cap, brick, camera=far)
    assert not lazy.bricks.ranges_read
    plan = placed.plan
    assert plan.level_dims == ((96, 96, 96), (48, 48, 48)) and plan.mix.const_f is None
    assert np.all(plan.table[:6] == (0x40000000 | 1)) and plan.mix.f_slots >= 3
    assert [len(r) for _, r, _ in plan.parts] == [plan.mix.c_slots, 0]
    near = replace(scene.camera, eye=(0.0, 0.0, 0.9), target=(0.0, 0.0, 0.0))
    placed = plan_placement(lazy, LIMITS, cap, brick, camera=near)
    assert lazy.bricks.ranges_read            # here some bricks are worth one: it is read
