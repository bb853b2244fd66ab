"""A Zarr store read brick by brick opens on a thread (app/rendering/levels/progressive_open.py) with a
preview of a small level shown meanwhile (app/io/volume.py zarr_preview): the result is place_volume's,
the preview sits in the same world box, and errors surface on the context's thread."""
from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from radiance_probes.io.bricks import LazyData
from radiance_probes.rendering.levels.progressive_open import ProgressiveOpen
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.rendering.levels.volume_placement import place_volume
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_scene_volume, reads_lazily, zarr_preview

BRICK = 8
CAMERA = {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 35.0,
          "width": 16, "height": 12}


def _bench():
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("brick_bench", ROOT / "lab" / "experiments" / "brick_bench.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("brick_bench", bench)
    spec.loader.exec_module(bench)
    return bench


@pytest.fixture
def store(tmp_path):
    path = tmp_path / "v.zarr"
    _bench().write_ome_zarr(path, (40, 32, 24), 8, 3)   # levels of 40x32x24, 20x16x12, 10x8x6
    return path


def _scene(path, **extra):
    return parse_scene({"volume": {"path": str(path), "spacing": [0.5, 1.0, 2.0]},
                        "camera": CAMERA, "density_scale": 30.0,
                        "probes": {"grid": [3, 3, 3], "samples": 16}, **extra})


def test_progressive_open_gives_place_volumes_pool(ctx, store):
    scene = _scene(store)
    assert reads_lazily(scene, BRICK) and not reads_lazily(scene)   # a small store: read whole
    opening = ProgressiveOpen(ctx, scene, memory_bytes=None, brick_size=BRICK)
    given, shown, pool = opening.wait(budget_s=0.001)
    assert opening.done and opening.written == opening.bricks_total > 0
    want_shown, want = place_volume(ctx, load_scene_volume(scene, BRICK), brick_size=BRICK)
    try:
        assert isinstance(given.data, LazyData) and shown.dims == want_shown.dims == (40, 32, 24)
        assert shown.notes == want_shown.notes
        for got, ref in ((pool.table, want.table), (pool.atlas, want.atlas),
                         (pool.constants, want.constants)):
            assert got.read() == ref.read()
        np.testing.assert_array_equal(pool.brick_of_slot, want.brick_of_slot)
    finally:
        pool.release()
        want.release()


def test_progressive_open_under_a_cap_shows_the_level_place_volume_shows(ctx, store):
    from radiance_probes.io.brick_layout import slot_bytes
    scene = _scene(store)
    cap = 6 * slot_bytes(BRICK, 1, False) + 4096     # only a coarser level fits
    want_shown, want = place_volume(ctx, load_scene_volume(scene, BRICK), cap, BRICK)
    want.release()
    given, shown, pool = ProgressiveOpen(ctx, scene, cap, BRICK).wait()
    try:
        assert shown.dims == want_shown.dims != given.dims
        assert shown.notes == want_shown.notes and "coarser" in shown.notes[-1]
    finally:
        pool.release()


def test_renderer_adopts_the_placed_volume_and_renders_as_if_it_placed_it(ctx, store):
    scene = _scene(store)
    images = []
    settings = RenderSettings(brick_size=BRICK, empty_space_skipping=False)
    preview = zarr_preview(scene)
    r = Renderer(ctx, scene, preview, settings=settings)
    try:
        assert r.resources.volume.dims == preview.dims == (20, 16, 12)
        placed = ProgressiveOpen(ctx, scene, None, BRICK).wait()
        r.set_scene(scene, placed[0], placed[1:])
        assert r.resources.bricked and r.resources.volume.dims == (40, 32, 24)
        images.append(r.render("raymarch", spp=1, seed=3).image)
    finally:
        r.release()
    r = Renderer(ctx, scene, settings=settings)
    try:
        images.append(r.render("raymarch", spp=1, seed=3).image)
    finally:
        r.release()
    assert images[0].max() > 0
    np.testing.assert_array_equal(images[0], images[1])


def test_preview_is_the_finest_small_level_in_the_same_world_box(store):
    scene = _scene(store)
    full = load_scene_volume(scene, BRICK)
    preview = zarr_preview(scene, max_voxels=20 * 16 * 12)
    assert preview.dims == (20, 16, 12)
    np.testing.assert_allclose(preview.half_extent, full.half_extent)
    assert "preview" in preview.notes[0] and "provisional" in preview.notes[0]
    level = full.levels[0]
    raw = level.read(0, 12, 0, 16, 0, 20).astype(np.float64)
    np.testing.assert_allclose(preview.data, (raw - raw.min()) / (raw.max() - raw.min()),
                               atol=1e-6)
    # with a value range the densities are the store's own mapping, not provisional
    ranged = _scene(store)
    ranged = ranged.replace(volume=ranged.volume.__class__(**{**ranged.volume.__dict__,
                                                              "value_range": (0.0, 65535.0)}))
    p2 = zarr_preview(ranged, max_voxels=20 * 16 * 12)
    assert "provisional" not in p2.notes[0]
    np.testing.assert_allclose(p2.data, raw / 65535.0, atol=1e-6)
    # no level small enough: an empty box of the same extent
    empty = zarr_preview(scene, max_voxels=10)
    assert empty.dims == (2, 2, 2) and not empty.data.any()
    np.testing.assert_allclose(empty.half_extent, full.half_extent)


def test_an_error_on_the_thread_is_raised_by_poll(ctx, tmp_path):
    import zarr
    path = tmp_path / "flat.zarr"
    zarr.create_array(str(path), shape=(16, 16, 16), dtype="uint16", chunks=(8, 8, 8))[...] = 7
    opening = ProgressiveOpen(ctx, _scene(path), None, BRICK)
    with pytest.raises(VolumeError, match="every voxel is 7"):
        opening.wait()
    assert opening.done and opening.pool is None


def test_cancel_stops_the_thread_and_frees_the_pool(ctx, store):
    opening = ProgressiveOpen(ctx, _scene(store), None, BRICK)
    while opening.pool is None:
        assert opening.poll(0.0) is None
    opening.cancel()
    opening._thread.join(timeout=30)
    assert not opening._thread.is_alive() and opening.pool is None
