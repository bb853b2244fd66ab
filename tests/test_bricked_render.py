"""Bricked volumes render what one texture renders: every method, the same seeds, a small brick
size forced so that several bricks (constant ones among them) and their seams are crossed; and
the checking build's page-miss count stays 0."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.bench.scenes import battery_scene
from radiance_probes.rendering.renderer import METHODS, Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.twins.brick_pool import CONSTANT


def _scene(name="head", side=20):
    scene = battery_scene(name, side=side, width=16, height=12, grid=3, samples=64)
    return scene.replace(max_bounces=min(scene.max_bounces, 16))


def _render(ctx, scene, method, brick, seed=3, **settings):
    r = Renderer(ctx, scene, settings=RenderSettings(brick_size=brick, **settings))
    try:
        assert r.resources.bricked == (brick is not None)
        if brick is not None:
            table = np.frombuffer(r.resources.volume_tex.table.read(), np.uint32)
            assert np.any(~table & CONSTANT)
            if scene.volume.builtin == "speck":   # haze around a ball: constant bricks too
                assert np.any(table & CONSTANT)
            assert "VOLUME_BRICKED" in r.resources.medium_defines()
        else:
            assert "VOLUME_BRICKED" not in r.resources.medium_defines()
        return r.render(method, spp=2, seed=seed).image
    finally:
        r.release()


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name, side", [("head", 20), ("speck", 32)])
def test_bricked_volume_renders_the_same_image(ctx, method, name, side):
    scene = _scene(name, side)
    whole = _render(ctx, scene, method, None)
    bricked = _render(ctx, scene, method, 8)
    assert np.abs(whole).max() > 0
    same = np.all(np.abs(bricked - whole) <= 1e-5 * (1 + np.abs(whole)), axis=-1)
    err = np.sqrt(np.mean((bricked - whole) ** 2) / np.mean(whole ** 2))
    assert same.mean() >= 0.99, (method, same.mean())
    assert err < 1e-5, (method, err)


def test_bricked_volume_renders_the_same_image_in_the_fragment_raymarcher(ctx):
    scene = _scene("speck", 32)
    whole = _render(ctx, scene, "raymarch", None, raymarch_stage="fragment")
    bricked = _render(ctx, scene, "raymarch", 8, raymarch_stage="fragment")
    assert np.abs(whole).max() > 0
    err = np.sqrt(np.mean((bricked - whole) ** 2) / np.mean(whole ** 2))
    assert err < 1e-5, err


def test_page_miss_check_stays_zero_with_every_method(checked_ctx):
    """The checking build (lib/brick_pool.glsl CHECK_SITE_PAGE_MISS) over every method and the
    bake of a bricked volume: no slot holds another brick than the page table says."""
    ctx, checks = checked_ctx
    r = Renderer(ctx, _scene("speck", 32), settings=RenderSettings(brick_size=8))
    try:
        assert r.resources.bricked
        checks.reset()
        for method in METHODS:
            r.render(method, spp=1, seed=1)
            assert checks.hits() == {}, (method, checks.hits())
    finally:
        r.release()


def test_page_miss_check_counts_a_wrong_slot(checked_ctx):
    """The check fires: a page table that sends a brick to a slot holding another brick, and
    one that names a constant past the table, are counted at page_miss."""
    ctx, checks = checked_ctx
    r = Renderer(ctx, _scene("head", 20), settings=RenderSettings(brick_size=8))
    try:
        pool = r.resources.volume_tex
        table = np.frombuffer(pool.table.read(), np.uint32).copy()
        resident = np.nonzero(~table & CONSTANT)[0]
        assert len(resident) >= 2
        table[resident[0]], table[resident[1]] = table[resident[1]], table[resident[0]]
        pool.table.write(table.tobytes())
        checks.reset()
        r.render("raymarch", spp=1, seed=1)
        assert checks.hits().get("page_miss", 0) > 0
        table[resident[0]] = CONSTANT | pool.constant_count   # one past the constants
        table[resident[1]] = table[resident[0]]
        pool.table.write(table.tobytes())
        checks.reset()
        r.render("raymarch", spp=1, seed=2)
        assert checks.hits().get("page_miss", 0) > 0
    finally:
        r.release()


def _channels_zarr(tmp_path) -> str:
    """A Zarr store [c, z, y, x] of 3 uint16 channels, smooth blobs of their own places (and a
    haze of one value in channel 1: constant bricks that are not vacuum), chunks of 8."""
    import zarr
    shape = (16, 16, 48)          # the blobs in the -x half: constant bricks at +x
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    out = []
    for cx, cy, cz in ((-0.6, 0.0, 0.1), (-0.3, -0.2, -0.2), (-0.45, 0.3, 0.0)):
        r = np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2)
        out.append(np.clip(1.0 - 2.5 * r, 0, 1) * 3000.0)
    data = np.round(np.stack(out)).astype(np.uint16)
    data[1][data[1] == 0] = 150
    path = tmp_path / "channels.zarr"
    zarr.create_array(str(path), shape=data.shape, dtype=data.dtype, chunks=(1, 8, 8, 8),
                      dimension_names=["c", "z", "y", "x"])[...] = data
    return str(path)


@pytest.mark.parametrize("method", ["pt", "probes", "raymarch"])
def test_bricked_zarr_store_of_channels_renders_the_same_image(ctx, tmp_path, method):
    """A Zarr store of 3 channels (one switched off, one in its own window) read brick by brick
    renders what the whole loader's volume renders in one texture."""
    from radiance_probes.io.bricks import LazyData
    from radiance_probes.io.scene_file import parse_scene
    scene = parse_scene({
        "volume": {"path": _channels_zarr(tmp_path)},
        "channels": [{"index": 0}, {"index": 1, "value_range": [0, 2000]},
                     {"index": 2, "enabled": False}],
        "camera": {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "up": [0, 1, 0],
                   "fov_y": 35.0, "width": 16, "height": 12},
        "density_scale": 30.0, "max_bounces": 8, "probes": {"grid": [3, 3, 3], "samples": 32}})
    images = []
    for brick in (None, 8):
        # one global majorant: the grid from the bricks' ranges is looser than the voxels' (the
        # same medium, other null collisions), which would change the random choices
        r = Renderer(ctx, scene, settings=RenderSettings(brick_size=brick,
                                                         empty_space_skipping=False))
        try:
            volume = r.resources.volume
            assert r.resources.bricked == (brick is not None)
            assert isinstance(volume.data, LazyData) == (brick is not None)
            assert volume.channel_count == 3 and r.resources.tables.on == (True, True, False)
            if brick is not None:
                table = np.frombuffer(r.resources.volume_tex.table.read(), np.uint32)
                assert np.any(table & CONSTANT) and np.any(~table & CONSTANT)
            images.append(r.render(method, spp=2, seed=3).image)
        finally:
            r.release()
    whole, bricked = images
    assert np.abs(whole).max() > 0
    err = np.sqrt(np.mean((bricked - whole) ** 2) / np.mean(whole ** 2))
    assert err < 1e-5, (method, err)
