"""Mixed levels under a cap (app/rendering/levels/level_mix.py, lib/brick_pool.glsl BRICK_LEVELS): the pool
holds the finer level where the camera sees it largest and the coarser elsewhere, within the cap;
what the GPU holds is the twin's mixed medium; the majorant grid bounds it; every method reads it
with no page miss; and it is nearer the uncapped image than the coarser level alone."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from radiance_probes.rendering.metrics import rrmse
from radiance_probes.bench.scenes import battery_scene
from radiance_probes.io.brick_sources import box_filtered
from radiance_probes.io.brick_layout import slot_bytes
from radiance_probes.rendering.levels.level_mix import MIX_FOOTPRINT_PX, footprints
from radiance_probes.rendering.renderer import METHODS, Renderer
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.twins.brick_pool import Packed, bricked_sample, mixed_reference
from radiance_probes.twins.majorant_grid import macrocell_counts

BRICK = 8


def _scene(width=48, height=36):
    scene = battery_scene("speck", side=32, width=width, height=height, grid=3, samples=2048)
    # near the volume's -x, +y, +z corner: the bricks there are seen largest
    cam = replace(scene.camera, eye=(-0.9, 0.55, 1.0), target=(0.0, 0.0, 0.0))
    return scene.replace(camera=cam, max_bounces=min(scene.max_bounces, 8))


def _cap(scene) -> int:
    """Level 1 whole and a dozen bricks more; level 0 (27 bricks not constant) does not fit."""
    return 24 * slot_bytes(BRICK, 1, False) + 4096


def _renderer(ctx, scene, mixed_levels: bool = True, **settings):
    return Renderer(ctx, scene, settings=RenderSettings(brick_size=BRICK,
                                                        volume_memory_bytes=_cap(scene),
                                                        **settings),
                    lab=LabOptions(mixed_levels=mixed_levels))


def _levels(r) -> list[np.ndarray]:
    """The pool's two levels as whole arrays (the shown volume's level and its 2x box filter,
    as volume_placement.coarser builds it for a volume in memory)."""
    source = r.resources.volume.bricks.source
    nz, ny, nx = source.shape[:3]
    data = np.asarray(source.density(source.read(0, nz, 0, ny, 0, nx)), np.float32)
    return [data, box_filtered(data)]


def _gpu_packed(pool) -> Packed:
    """The twin's view of what the GPU pool holds (its textures read back)."""
    gz, gy, gx = pool.grid[::-1]
    side = BRICK + 2
    atlas = np.frombuffer(pool.atlas.read(), np.float32).reshape(gz * side, gy * side, gx * side)
    table = np.frombuffer(pool.table.read(), np.uint32).reshape(pool.table.size[::-1])
    constants = np.frombuffer(pool.constants.read(), np.float32).reshape(-1, 4)
    return Packed(atlas, table, constants, pool.grid, BRICK, pool.dims, pool.brick_of_slot,
                  pool.level_dims, pool.level_table_z)


def test_footprints_are_largest_nearest_the_camera_and_off_outside_the_frustum():
    scene = _scene()
    px = footprints((32, 32, 32), BRICK, (0.5, 0.5, 0.5), scene.camera)
    near, far = px[3, 3, 0], px[0, 0, 3]            # [bz, by, bx]: -x +y +z against +x -y -z
    assert near > far > 0
    behind = replace(scene.camera, eye=(0.0, 0.0, 3.0), target=(0.0, 0.0, 4.0))
    assert np.all(footprints((32, 32, 32), BRICK, (0.5, 0.5, 0.5), behind) == -1.0)


def test_mixed_pool_holds_the_twins_medium_within_the_cap(ctx):
    scene = _scene()
    r = _renderer(ctx, scene)
    try:
        pool = r.resources.volume_tex
        shown = r.resources.volume
        assert pool.levels == 2 and pool.defines()["BRICK_LEVELS"] == 2
        assert pool.nbytes <= _cap(scene)
        assert any("mixed" in n for n in shown.notes), shown.notes
        assert shown.dims == (32, 32, 32) and pool.level_dims[1] == (16, 16, 16)
        packed = _gpu_packed(pool)
        top = packed.table[:4]
        which = np.where((top & 0xC0000000) == 0x40000000, 1, 0)
        assert 0 < np.count_nonzero(which == 0) and np.count_nonzero(which == 1) > 0
        levels = _levels(r)
        uvw = np.random.default_rng(4).uniform(-0.02, 1.02, (20000, 3))
        got = bricked_sample(packed, uvw)
        want = mixed_reference(levels, which, BRICK, uvw)
        assert np.abs(got - want).max() < 1e-5
        # the majorant grid's ranges hold every density its cells' points take
        cells = macrocell_counts(shown.dims)
        lo, hi = shown.derived[("density ranges", cells)]
        c = np.clip(np.floor(np.clip(uvw, 0, 1) * np.asarray(cells)).astype(int), 0,
                    np.asarray(cells) - 1)
        d = want[:, 0]
        assert np.all(d >= lo[c[:, 2], c[:, 1], c[:, 0]] - 1e-7)
        assert np.all(d <= hi[c[:, 2], c[:, 1], c[:, 0]] + 1e-7)
    finally:
        r.release()


def test_bricks_worth_a_slot_come_first_and_the_rest_stay_coarse(ctx):
    scene = _scene()
    r = _renderer(ctx, scene)
    try:
        top = _gpu_packed(r.resources.volume_tex).table[:4]
        fine = (top & 0xC0000000) == 0   # a slot of level 0 (constant ones cost nothing)
        px = footprints((32, 32, 32), BRICK, r.resources.volume.half_extent, scene.camera) * 2
        varying = ~r.resources.volume.bricks.constant()
        assert px[fine & varying].min() >= px[~fine & varying].max() or \
            not np.any(~fine & varying & (px > MIX_FOOTPRINT_PX))
    finally:
        r.release()


def test_every_method_reads_the_mixed_pool_with_no_page_miss(checked_ctx):
    ctx, checks = checked_ctx
    r = _renderer(ctx, _scene(32, 24))
    try:
        assert r.resources.volume_tex.levels == 2
        checks.reset()
        for method in METHODS:
            image = r.render(method, spp=1, seed=1).image
            assert np.isfinite(image).all() and image.max() > 0, method
            assert checks.hits() == {}, (method, checks.hits())
    finally:
        r.release()


def test_mixed_levels_are_nearer_the_uncapped_image_than_the_coarser_level(ctx):
    scene = _scene()
    images = {}
    for name, settings in (("mixed", {}), ("coarse", {"mixed_levels": False})):   # (LabOptions)
        r = _renderer(ctx, scene, **settings)
        try:
            assert r.resources.volume_tex.levels == (2 if name == "mixed" else 1)
            images[name] = r.render("raymarch", spp=4, seed=2).image
        finally:
            r.release()
    r = Renderer(ctx, scene, settings=RenderSettings(brick_size=BRICK))
    try:
        full = r.render("raymarch", spp=4, seed=2).image
    finally:
        r.release()
    # the same seeds: the images differ by their media (measured 2.55% against 2.92%)
    assert rrmse(images["mixed"], full) < 0.95 * rrmse(images["coarse"], full)
