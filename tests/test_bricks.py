"""Bricked volumes from a store (app/io/bricks.py): a Zarr array read brick by brick, constant bricks
read once and never uploaded (counted), the majorant grid from the bricks' ranges; the memory cap
(a coarser level, with a note; a cap below one brick refused); a volume longer than
GL_MAX_3D_TEXTURE_SIZE bricked, not refused."""
from __future__ import annotations

import re

import numpy as np
import pytest

from radiance_probes.io.brick_sources import ArraySource, box_filtered
from radiance_probes.io.bricks import BrickStore, LazyData
from radiance_probes.io.brick_layout import constant_bricks
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.rendering.levels.volume_placement import place_volume
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.scene.types import VolumeSpec
from radiance_probes.twins.brick_pool import CONSTANT, brick_ranges, pack
from radiance_probes.twins.majorant_grid import brick_density_range_grid, density_range_grid
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import volume_from_array
from radiance_probes.io.load import load_scene_volume, load_volume

BRICK = 8
CAMERA = {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 35.0,
          "width": 16, "height": 12}


def _blob(shape=(24, 24, 64)) -> np.ndarray:
    """uint16 [z, y, x]: zero but for a smooth blob in one corner region (most bricks empty)."""
    z, y, x = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    r2 = (x - 54.0) ** 2 + (y - 10.0) ** 2 + (z - 8.0) ** 2
    d = np.where(r2 < 49.0, 40000.0 * np.exp(-r2 / 30.0), 0.0)
    return np.round(d).astype(np.uint16)


def _written(raw, fill=0) -> np.ndarray:
    """[bz, by, bx] 1 where a brick of BRICK voxels holds a raw value other than `fill` (in a
    channel of raw [z, y, x(, c)]), else 0: with chunks of one brick, the bricks whose chunks Zarr
    wrote (it leaves out a chunk equal to the fill value), the only ones the range pass reads."""
    lo, hi = brick_ranges(raw, BRICK)
    off = (lo != fill) | (hi != fill)
    return (off if off.ndim == 3 else off.any(axis=-1)).astype(np.int64)


def _varied(raw, brick=BRICK) -> np.ndarray:
    """[bz, by, bx] 1 where a brick holds more than one raw value (in a channel of raw [z, y,
    x(, c)]), else 0: the bricks the upload reads (a resident brick of one value, next to one that
    varies, is that value without a read)."""
    lo, hi = brick_ranges(raw, brick)
    return (lo != hi).reshape(lo.shape[:3] + (-1,)).any(axis=-1).astype(np.int64)


def _zarr(tmp_path, data, chunks=(8, 8, 8)):
    import zarr
    path = tmp_path / "blob.zarr"
    zarr.create_array(str(path), shape=data.shape, dtype=data.dtype, chunks=chunks)[...] = data
    return path


def test_zarr_store_reads_constant_bricks_once_and_uploads_only_the_others(ctx, tmp_path):
    data = _blob()
    path = _zarr(tmp_path, data)
    volume = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK)
    assert isinstance(volume.data, LazyData) and volume.dims == (64, 24, 24)
    store = volume.bricks
    # the range pass: every brick Zarr wrote once; the others (all 0, the fill value, so never
    # written) not at all
    written = _written(data)
    assert 0 < written.sum() < written.size
    np.testing.assert_array_equal(store.reads, written)
    assert (volume.raw_min, volume.raw_max) == (0.0, float(data.max()))
    shown, pool = place_volume(ctx, volume, brick_size=BRICK)
    try:
        constant = store.constant()
        assert constant.sum() >= constant.size // 2       # mostly empty
        # read once more, to upload, where it holds more than one value (every such brick is
        # resident; one of a single value next to it is uploaded, not read); constant ones never
        varied = _varied(data)
        assert np.any(~constant & (varied == 0))
        np.testing.assert_array_equal(store.reads, written + varied)
        assert pool.uploads == int((~constant).sum())
        assert pool.writes == -(-pool.uploads // pool.grid[0])   # a row of slots a write
        # what was uploaded is the whole loader's volume, bricked
        whole = load_volume(VolumeSpec(path=str(path), builtin=None))
        assert isinstance(whole.data, np.ndarray)
        want = pack(whole.data, BRICK)
        table = np.frombuffer(pool.table.read(), np.uint32).reshape(want.table.shape)
        np.testing.assert_array_equal(table, want.table)
        atlas = np.frombuffer(pool.atlas.read(), np.float32).reshape(want.atlas.shape)
        np.testing.assert_array_equal(atlas, want.atlas)
    finally:
        pool.release()


def test_zarr_store_renders_as_the_whole_volume(ctx, tmp_path):
    data = _blob()
    path = _zarr(tmp_path, data)
    scene = parse_scene({"volume": {"path": str(path)}, "camera": CAMERA, "density_scale": 40.0,
                         "probes": {"grid": [3, 3, 3], "samples": 32}})
    images = []
    # one global majorant: the grid from the bricks' ranges is looser than the voxels' (the same
    # medium, other null collisions), which would change the random choices
    for brick in (None, BRICK):
        r = Renderer(ctx, scene, settings=RenderSettings(brick_size=brick,
                                                         empty_space_skipping=False))
        try:
            assert r.resources.bricked == (brick is not None)
            assert isinstance(r.resources.volume.data, np.ndarray) == (brick is None)
            images.append(r.render("raymarch", spp=1, seed=2).image)
        finally:
            r.release()
    assert images[0].max() > 0
    err = np.sqrt(np.mean((images[1] - images[0]) ** 2) / np.mean(images[0] ** 2))
    assert err < 1e-5, err


@pytest.mark.parametrize("channels", [1, 3])
def test_majorant_ranges_from_bricks_contain_the_whole_arrays(channels):
    """Each macrocell's range from the bricks' contains the voxels' (of several channels, each
    channel's: [C, cz, cy, cx], as channel_density_ranges)."""
    r = np.random.default_rng(1)
    data = r.uniform(0, 1, (21, 29, 37) + ((channels,) if channels > 1 else ())
                     ).astype(np.float32)
    data[:, :16, :24] = 0.0
    store = BrickStore(ArraySource(data), BRICK)
    for got, want in zip(store.ranges(), brick_ranges(data, BRICK)):   # partial bricks too
        np.testing.assert_array_equal(got, want)
    lo_b, hi_b = brick_density_range_grid(*store.ranges(), store.dims, BRICK)
    if channels > 1:
        grids = [density_range_grid(data[..., c]) for c in range(channels)]
        lo, hi = np.stack([g[0] for g in grids]), np.stack([g[1] for g in grids])
    else:
        lo, hi = density_range_grid(data)
    assert lo_b.shape == lo.shape
    assert np.all(lo_b <= lo) and np.all(hi_b >= hi)
    assert np.any(hi_b == 0.0)            # empty bricks keep empty cells skipped
    assert np.all(store.reads == 1)


@pytest.mark.parametrize("shape, channels", [((19, 13, 30), 1), ((16, 8, 24), 1),
                                               ((11, 17, 9), 2)])
def test_resident_bricks_with_aprons_equal_clamped_reads(shape, channels):
    """The upload's bricks (each read once, its apron from its neighbours' voxels or a constant
    brick's value) equal a read of the brick with its apron clamped to the volume (the edge voxel
    repeated), with partial bricks at the far faces, constant regions of a nonzero value, and
    several channels; and each resident brick is read once more, no constant brick."""
    rng = np.random.default_rng(5)
    data = np.full(shape + ((channels,) if channels > 1 else ()), 0.25, np.float32)
    data[: shape[0] // 2, : shape[1] // 2] = 0.0
    z0, y0, x0 = (n // 3 for n in shape)
    data[z0:z0 + 5, y0:y0 + 4, x0:x0 + 6] = rng.random((5, 4, 6) + data.shape[3:])
    data[-1, -1, -1] = 0.9                    # a lone voxel in a far, partial brick
    store = BrickStore(ArraySource(data), 4)
    _, _, _, resident = store.layout(4096)
    assert 0 < len(resident) < np.prod(store.counts)
    before = store.reads.copy()
    seen = 0
    for z, (y, x), block in store.resident_layers(resident):
        np.testing.assert_array_equal(block, store.pencil(z, y, x, x + 1, 1))
        seen += 1
    assert seen == len(resident)
    # pencil() above counted once more each; resident_layers once each where it holds more
    # than one value, constant ones never
    added = store.reads - before
    is_resident = np.zeros(added.shape, bool)
    is_resident[tuple(resident.T)] = True
    varied = _varied(data, 4)
    assert np.any(is_resident & (varied == 0))       # resident, of one value: not read
    np.testing.assert_array_equal(added, is_resident + varied)


def test_box_filtered_level_averages_pairs():
    d = np.arange(3 * 4 * 5, dtype=np.float32).reshape(3, 4, 5)
    c = box_filtered(d)
    assert c.shape == (2, 2, 3)
    assert c[0, 0, 0] == pytest.approx(d[:2, :2, :2].mean())
    assert c[1, 1, 2] == pytest.approx(d[2, 2:4, 4].mean())   # odd axes: the edge repeated


def _sphere_scene():
    return parse_scene({"volume": {"builtin": "sphere", "size": [32, 32, 32]},
                        "camera": CAMERA, "density_scale": 20.0,
                        "probes": {"grid": [3, 3, 3], "samples": 32}})


def test_cap_shows_a_coarser_level_and_says_so(ctx):
    from radiance_probes.io.brick_layout import slot_bytes
    one = slot_bytes(BRICK, 1, False)
    r = Renderer(ctx, _sphere_scene(), settings=RenderSettings(brick_size=BRICK,
                                                               volume_memory_bytes=12 * one))
    try:
        v = r.resources.volume
        assert v.dims == (16, 16, 16)              # level 0's bricks do not fit 12 slots
        assert any(n.startswith("level 1, 2x coarser") and "cap" in n for n in v.notes)
        assert np.allclose(v.half_extent, 0.5)     # the same world box
        assert r.resources.volume_tex.nbytes <= 12 * one
        image = r.render("raymarch", spp=1).image
        assert np.isfinite(image).all() and image.max() > 0
        r.configure(volume_memory_bytes=None)       # no cap: level 0 again
        assert r.resources.volume.dims == (32, 32, 32)
        assert not any(n.startswith("level") for n in r.resources.volume.notes)
    finally:
        r.release()


def test_cap_below_one_brick_is_refused(ctx):
    with pytest.raises(VolumeError, match="below one brick"):
        Renderer(ctx, _sphere_scene(), settings=RenderSettings(volume_memory_bytes=1000))


def test_cap_that_holds_the_whole_texture_keeps_it(ctx):
    r = Renderer(ctx, _sphere_scene(), settings=RenderSettings(volume_memory_bytes=1 << 30))
    try:
        assert not r.resources.bricked and "VOLUME_BRICKED" not in r.resources.medium_defines()
    finally:
        r.release()


def test_volume_longer_than_the_texture_limit_is_bricked(ctx):
    long = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]) + 40
    x = np.arange(long)
    data = np.broadcast_to((np.sin(x / 50.0) > 0.5).astype(np.float32), (4, 4, long)).copy()
    volume = volume_from_array(data, value_range=(0.0, 1.0), name="long")
    scene = parse_scene({"camera": {**CAMERA, "eye": [0.0, 0.0, 1.5]}, "density_scale": 200.0,
                         "probes": {"grid": [3, 3, 3], "samples": 32}})
    r = Renderer(ctx, scene, volume)
    try:
        assert r.resources.bricked and r.resources.volume.dims == (long, 4, 4)
        table = np.frombuffer(r.resources.volume_tex.table.read(), np.uint32)
        assert np.any(table & CONSTANT)
        image = r.render("raymarch", spp=1).image
        assert np.isfinite(image).all() and image.max() > 0
    finally:
        r.release()


def test_brick_bench_quick(tmp_path):
    """lab/experiments/brick_bench.py --quick (the GPU run's code at llvmpipe's size): a capped OME-Zarr
    volume shown at a coarser level with its note and timings, its error against level 0, and a
    volume longer than the texture limit rendered bricked."""
    import importlib.util
    import json
    import sys
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("brick_bench", ROOT / "lab" / "experiments" / "brick_bench.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("brick_bench", bench)
    spec.loader.exec_module(bench)
    assert bench.main([str(tmp_path / "out"), "--quick"]) == 0
    rec = json.loads((tmp_path / "out" / "results.json").read_text())
    capped = rec["capped"]
    assert capped["bricked"] and capped["level_dims"][0] < 48
    assert any("coarser" in n for n in capped["notes"])
    assert capped["pool_bytes"] <= capped["cap_bytes"]
    assert capped["first_image_s"] > 0 and capped["fps"] > 0
    b = capped["open_breakdown"]            # where the open's time went
    assert b["level0_range_pass_s"] > 0 and b["shown_range_pass_s"] > 0 and b["upload_s"] > 0
    assert 0 < b["texture_writes"] <= b["bricks_written"] and b["texture_write_s"] > 0
    assert 0 < rec["rrmse_vs_uncapped"]["rrmse"] < 1.0
    assert rec["long"]["bricked"] and rec["long"]["finite"] and rec["long"]["mean_radiance"] > 0
    assert rec["long"]["dims"][0] > rec["long"]["max_3d_texture_size"]
    assert "fps" in (tmp_path / "out" / "report.md").read_text()


def test_histogram_of_a_lazy_store_reads_a_small_coarser_level_whole(tmp_path):
    """A store read brick by brick takes its histogram from its own coarser level (read whole,
    never a strided sample of level 0 that decodes a row of chunks a plane)."""
    import importlib.util
    import sys
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("brick_bench", ROOT / "lab" / "experiments" / "brick_bench.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("brick_bench", bench)
    spec.loader.exec_module(bench)
    path = tmp_path / "v.zarr"
    bench.write_ome_zarr(path, (32, 32, 32), 8, 3)
    volume = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK)
    assert isinstance(volume.data, LazyData) and volume.levels
    level1 = volume.levels[0]
    assert level1.shape[:3] == (16, 16, 16)
    reads = []
    original = volume.data.sample
    volume.data.sample = lambda *a, **k: reads.append(1) or original(*a, **k)
    counts = volume.histogram(bins=16)
    assert not reads
    data = level1.density(level1.read(0, 16, 0, 16, 0, 16))
    np.testing.assert_array_equal(counts, np.histogram(data, bins=16, range=(0.0, 1.0))[0])
    assert counts.sum() == 16 ** 3


@pytest.mark.parametrize("channels", [1, 3])
def test_reads_in_processes_equal_threads(tmp_path, monkeypatch, channels):
    """A large Zarr store is read in processes (Zarr decodes under the GIL): the same ranges and
    the same bricks with aprons as the threads' reads, each brick counted as often (one channel,
    and several read as [z, y, x, c])."""
    import radiance_probes.io.brick_reading as brick_reading
    raw = _blob() if channels == 1 else np.moveaxis(_channel_blobs(channels), 0, -1)
    path = (_zarr(tmp_path, raw) if channels == 1
            else _zarr_channels(tmp_path, _channel_blobs(channels)))
    threads = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK).bricks
    monkeypatch.setattr(brick_reading, "PROCESS_READ_VOXELS", 1)
    monkeypatch.setattr(brick_reading, "reader_processes", lambda: 2)
    procs = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK).bricks
    assert procs._in_processes()       # (the first store, read before the patch, used threads)
    assert procs.channels == channels
    for a, b in zip(threads.raw_ranges(), procs.raw_ranges()):
        np.testing.assert_array_equal(a, b)
    written = _written(raw)     # (the bricks whose chunks were never written are not read)
    np.testing.assert_array_equal(procs.reads, written)
    # the upload's reads too: each resident brick with its apron as a clamped read gives it,
    # read once more; constant bricks not at all
    _, _, _, resident = procs.layout(4096)
    seen = 0
    for z, (y, x), block in procs.resident_layers(resident):
        np.testing.assert_array_equal(block, threads.pencil(z, y, x, x + 1, 1))
        seen += 1
    assert seen == len(resident) > 0
    np.testing.assert_array_equal(procs.reads, written + _varied(raw))


# ---- several channels: a bricked Zarr store reads the scene's channels ---------------------------

def _channel_blobs(count: int, shape=(24, 16, 40), dtype=np.uint16) -> np.ndarray:
    """[c, z, y, x]: channel c a smooth blob of its own place and height (0 elsewhere); channel 1
    also one nonzero value over a corner of 2 x 2 x 2 bricks of 8 (constant bricks of several
    values), where channel 0 has a ramp in the corner brick: constant in channel 1 alone, so not
    constant (constant only where every channel is)."""
    z, y, x = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    out = []
    for c in range(count):
        cz, cy, cx = 6.0 + 4 * c, 5.0 + 3 * (c % 2), 8.0 + 9 * c
        r2 = (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2
        out.append(np.where(r2 < 30.0, (100.0 + 70 * c) * np.exp(-r2 / 20.0), 0.0))
    data = np.stack(out)
    if count > 1:
        data[1, 8:, :, 24:] = 77.0
    data[0, 16:, 8:, 32:] = np.linspace(1.0, 90.0, 8)   # channel 1 constant there, 0 not
    if np.dtype(dtype).kind == "f":
        return data.astype(dtype)
    return np.round(data).astype(dtype)


def _zarr_channels(tmp_path, data, axes="czyx", name="channels.zarr"):
    """A Zarr 3 store of data [c, z, y, x] with its axes named, chunks of 8 voxels and one
    channel."""
    import zarr
    stored = np.ascontiguousarray(np.moveaxis(data, 0, axes.index("c")))
    chunks = tuple(1 if a == "c" else 8 for a in axes)
    path = tmp_path / name
    zarr.create_array(str(path), shape=stored.shape, dtype=stored.dtype, chunks=chunks,
                      dimension_names=list(axes))[...] = stored
    return path


def _same_volume(lazy, whole):
    """A volume read brick by brick is the whole loader's: its densities, channels and ranges."""
    assert isinstance(lazy.data, LazyData) and isinstance(whole.data, np.ndarray)
    assert lazy.data.shape == whole.data.shape and lazy.channel_count == whole.channel_count
    for key in ("value_range", "raw_dtype", "channel_ranges", "exact_uint8", "spacing"):
        assert getattr(lazy, key) == getattr(whole, key), key
    # a store whose channels the scene's ranges map reads its extremes only when asked
    assert lazy.raw_extents(read=True) == whole.raw_extents()
    np.testing.assert_array_equal(np.asarray(lazy.data), whole.data)
    for c in range(whole.channel_count):
        np.testing.assert_array_equal(np.asarray(lazy.channel(c)), whole.channel(c))
        if not lazy.levels:   # (else from its coarser level: a test below)
            np.testing.assert_array_equal(lazy.histogram(32, c), whole.histogram(32, c))


def _uploaded_is_packed(ctx, volume, densities, **place):
    """place_volume's pool holds the twin's pack of `densities` (the bricks, their aprons and
    the page table); returns the volume shown."""
    from radiance_probes.gl.brick_pool import atlas_payload
    shown, pool = place_volume(ctx, volume, brick_size=BRICK, **place)
    try:
        want = pack(densities, BRICK)
        table = np.frombuffer(pool.table.read(), np.uint32).reshape(want.table.shape)
        np.testing.assert_array_equal(table, want.table)
        assert pool.channels == (1 if densities.ndim == 3 else densities.shape[3])
        assert pool.atlas.read() == atlas_payload(want.atlas, shown.exact_uint8)
        assert pool.uploads == int(np.count_nonzero(~(want.table & CONSTANT).astype(bool)))
    finally:
        pool.release()
    return shown


@pytest.mark.parametrize("count, axes, dtype", [(2, "czyx", np.uint16), (3, "zcyx", np.float32),
                                                (3, "czyx", np.uint8)])
def test_bricked_zarr_store_of_channels_is_the_whole_loaders_volume(ctx, tmp_path, count, axes,
                                                                     dtype):
    """2 and 3 channels (the channel axis first or between z and y; ranges from the range pass
    for 16-bit and float data, the type's for 8-bit data): read brick by brick as [z, y, x, c],
    the same densities, ranges and histograms as the whole loader's; every brick read once by the
    range pass; a brick constant only where every channel is; the upload the twin's pack of the
    whole volume (R16 for 8-bit data)."""
    data = _channel_blobs(count, dtype=dtype)
    path = _zarr_channels(tmp_path, data, axes)
    spec = VolumeSpec(path=str(path), builtin=None)
    lazy = load_volume(spec, brick=BRICK)
    whole = load_volume(spec)
    _same_volume(lazy, whole)
    assert lazy.channel_count == count and lazy.bricks.channels == count
    assert lazy.exact_uint8 == (dtype == np.uint8)
    written = _written(np.moveaxis(data, 0, -1))   # the range pass reads these alone, once
    np.testing.assert_array_equal(lazy.bricks.reads, written)
    constant = lazy.bricks.constant()
    lo, hi = lazy.bricks.ranges()
    assert np.any(constant_bricks(lo[..., 1], hi[..., 1]) & ~constant)   # one channel alone
    np.testing.assert_array_equal(constant, constant_bricks(*brick_ranges(whole.data, BRICK)))
    _uploaded_is_packed(ctx, lazy, whole.data)
    np.testing.assert_array_equal(lazy.bricks.reads, written + _varied(np.moveaxis(data, 0, -1)))


@pytest.mark.parametrize("channels", [
    # out of order (orthogonal reads), their own ranges and windows, one switched off
    [{"index": 3, "value_range": [10, 300]}, {"index": 1, "enabled": False,
                                              "window": {"level": 100, "width": 120}},
     {"index": 0}],
    [{"index": 1}, {"index": 2}],          # in order from channel 1 (a slice)
    [{"index": 2, "value_range": [0, 500]}],   # one channel of several: [z, y, x]
    [{"index": 0}],
])
def test_bricked_zarr_store_shows_the_scenes_channels(tmp_path, channels):
    data = _channel_blobs(4)
    path = _zarr_channels(tmp_path, data)
    scene = parse_scene({"volume": {"path": str(path)}, "channels": channels})
    lazy = load_scene_volume(scene, brick=BRICK)
    whole = load_scene_volume(scene)
    _same_volume(lazy, whole)
    assert lazy.channel_count == len(channels)
    if len(channels) == 1:      # the file's channel, not channel 0
        np.testing.assert_array_equal(lazy.bricks.source.read(0, 24, 0, 16, 0, 40),
                                      data[channels[0]["index"]])


def _ome_channels(path, data, axes, scale=(2.0, 1.0, 0.5)):
    """An OME-Zarr 0.4 image of data ([t,] c, z, y, x) with two levels: level 1 the 2 x 2 x 2
    mean of level 0, rounded (its own values, not a subsample)."""
    import zarr
    g = zarr.open_group(str(path), mode="w", zarr_format=2)
    kinds = {"t": "time", "c": "channel"}
    lead = [1.0] * (len(axes) - 3)
    g.attrs["multiscales"] = [{
        "version": "0.4", "axes": [{"name": a, "type": kinds.get(a, "space")} for a in axes],
        "datasets": [{"path": str(level), "coordinateTransformations": [
            {"type": "scale", "scale": lead + [s * 2 ** level for s in scale]}]}
            for level in (0, 1)]}]
    g.create_array("0", shape=data.shape, dtype=data.dtype, chunks=(1,) * (len(axes) - 3)
                   + (8, 8, 8))[...] = data
    n = data.shape[:-3] + tuple(s // 2 for s in data.shape[-3:])
    coarse = data.astype(np.float64).reshape(n[:-3] + (n[-3], 2, n[-2], 2, n[-1], 2))
    coarse = np.round(coarse.mean(axis=(-5, -3, -1))).astype(data.dtype)
    g.create_array("1", shape=coarse.shape, dtype=data.dtype, chunks=(1,) * (len(axes) - 3)
                   + (8, 8, 8))[...] = coarse
    return coarse


@pytest.mark.parametrize("axes", ["czyx", "tczyx"])
def test_bricked_ome_zarr_levels_read_the_same_channels_with_the_same_ranges(ctx, tmp_path, axes):
    """An OME-Zarr image of 2 channels and 2 levels: level 0 read brick by brick is the whole
    loader's volume (a time step of a series where the scene gives the channels' ranges); its
    coarser level reads the same channels, normalised by level 0's ranges (each channel's
    histogram from it); a cap that shows level 1 uploads those densities, with its channels."""
    from radiance_probes.rendering.levels.volume_placement import level_bytes
    data = _channel_blobs(3)[[0, 2]].astype(np.uint16)
    scene = {}
    if axes == "tczyx":
        data = np.stack([np.flip(data, axis=-1), data])    # time step 1 is `data`
        scene = {"time": 1, "channels": [{"index": 0, "value_range": [5, 250]},
                                         {"index": 1, "window": {"level": 200, "width": 300}}]}
    path = tmp_path / "image.zarr"
    coarse = _ome_channels(path, data, axes)
    parsed = parse_scene({"volume": {"path": str(path)}, **scene})
    lazy = load_scene_volume(parsed, brick=BRICK)
    whole = load_scene_volume(parsed)
    _same_volume(lazy, whole)
    assert lazy.spacing == (0.5, 1.0, 2.0) and lazy.channel_count == 2
    assert (lazy.time, lazy.time_steps) == ((1, 2) if axes == "tczyx" else (0, 1))
    (level1,) = lazy.levels
    assert level1.shape == (12, 8, 20, 2)
    step = coarse[1] if axes == "tczyx" else coarse
    want = np.stack([np.clip((step[c].astype(np.float64) - lo) / (hi - lo), 0, 1)
                     for c, (lo, hi) in enumerate(lazy.channel_ranges)], axis=-1)
    got = level1.density(level1.read(0, 12, 0, 8, 0, 20))
    np.testing.assert_allclose(got, want.astype(np.float32), rtol=0, atol=1e-7)
    for c in range(2):    # each channel's histogram from that level, read whole
        np.testing.assert_array_equal(lazy.histogram(16, c), np.histogram(
            got[..., c], bins=16, range=(0.0, 1.0))[0])
    level0 = level_bytes(lazy.bricks, 2, False, 2048)
    cap = level_bytes(BrickStore(level1, BRICK), 2, False, 2048)
    assert cap < level0
    shown = _uploaded_is_packed(ctx, lazy, got, memory_bytes=cap)
    assert shown.dims == (20, 8, 12) and shown.channel_count == 2
    assert shown.channel_ranges == lazy.channel_ranges
    assert any(n.startswith("level 1, 2x coarser") for n in shown.notes)


def _refused(load) -> str:
    with pytest.raises(VolumeError) as info:
        load()
    return str(info.value)


def test_bricked_zarr_store_refuses_channels_as_the_whole_loader_does(tmp_path):
    """More than 4 channels without a choice, a channel the store lacks, more than 4 chosen, and
    a channel of one value with no range: refused, each message the whole loader's."""
    from radiance_probes.scene.types import ChannelSpec
    data = _channel_blobs(6)
    data[4] = 7
    path = _zarr_channels(tmp_path, data)
    spec = VolumeSpec(path=str(path), builtin=None)
    for channels, message in [
            (None, r"the volume has 6 channels; at most 4 are shown at once: choose them with "
                   r"the scene's channels list"),
            ([{"index": 0}, {"index": 6}], r"channels\[1\] shows the file's channel 6, but the "
                                           r"volume has 6 channels \(0 to 5\)"),
            ([{"index": 1}, {"index": 4}], r"\(channel 4\): every voxel is 7\.0; give "
                                           r"volume\.value_range")]:
        scene = parse_scene({"volume": {"path": str(path)},
                             **({"channels": channels} if channels else {})})
        lazy = _refused(lambda: load_scene_volume(scene, brick=BRICK))
        assert lazy == _refused(lambda: load_scene_volume(scene))
        assert lazy.startswith(str(path)), lazy
        assert re.search(message, lazy), lazy
    five = tuple(ChannelSpec(transfer_function=None, index=i) for i in range(5))
    message = _refused(lambda: load_volume(spec, channels=five, brick=BRICK))
    assert message == f"{path}: 5 channels, at most 4 are shown at once (choose them with " \
                      "channels[i].index, --channel I[,J,...])"


class _Blocks:
    """app.bricks.shared_memory with the names of the blocks the caller's process creates
    recorded (the readers, forked, attach to them)."""

    def __init__(self):
        from multiprocessing import shared_memory
        self.module = shared_memory
        self.names = []
        self.pid = __import__("os").getpid()

    def SharedMemory(self, *args, **kw):
        block = self.module.SharedMemory(*args, **kw)
        if kw.get("create") and __import__("os").getpid() == self.pid:
            self.names.append(block.name)
        return block

    def left(self):
        from pathlib import Path
        return [n for n in self.names if (Path("/dev/shm") / n.lstrip("/")).exists()]


def _processes(monkeypatch):
    import radiance_probes.io.brick_reading as brick_reading
    monkeypatch.setattr(brick_reading, "PROCESS_READ_VOXELS", 1)
    monkeypatch.setattr(brick_reading, "reader_processes", lambda: 2)
    blocks = _Blocks()
    monkeypatch.setattr(brick_reading, "shared_memory", blocks)
    return blocks


@pytest.mark.skipif(not __import__("os").path.isdir("/dev/shm"), reason="no /dev/shm to look in")
@pytest.mark.parametrize("dtype, value_range", [("uint16", None), ("uint8", None),
                                                ("float32", (-0.3, 1.7))])
def test_upload_from_processes_maps_there_and_moves_bricks_through_shared_memory(
        ctx, tmp_path, monkeypatch, dtype, value_range):
    """A store read in processes: each reader maps its bricks to densities (uint16 and uint8 in
    float32 arithmetic, app/io/volume.py float32_exact; float32 data with a fractional range in
    float64, as normalise does) and hands them over in shared memory blocks, every one unlinked
    afterwards; the atlas equals the whole loader's volume bit for bit (tolerance 0: the float32
    mapping is exact there), the reads are counted as the threads' are, and the atlas is written
    a row of slots at a time. uint8 with its type's range is the R16 atlas (exact_uint8)."""
    from radiance_probes.gl.brick_pool import atlas_payload
    data = _blob()
    if dtype == "uint8":
        data = (data // 200).astype(np.uint8)
    elif dtype == "float32":
        data = data.astype(np.float32) / 20000.0
    path = _zarr(tmp_path, data)
    spec = VolumeSpec(path=str(path), builtin=None, value_range=value_range)
    whole = load_volume(spec)
    blocks = _processes(monkeypatch)
    volume = load_volume(spec, brick=BRICK)
    store = volume.bricks
    assert store._in_processes()
    shown, pool = place_volume(ctx, volume, brick_size=BRICK)
    try:
        assert blocks.names and not blocks.left()
        assert store.handed == {"shared": len(blocks.names), "pickled": 0}
        assert pool.exact_uint8 == (dtype == "uint8")
        constant = store.constant()
        np.testing.assert_array_equal(store.reads, _written(data) + _varied(data))
        n = int((~constant).sum())
        assert pool.uploads == n and pool.writes == -(-n // pool.grid[0]) < n   # a row a write
        want = pack(whole.data, BRICK)
        table = np.frombuffer(pool.table.read(), np.uint32).reshape(want.table.shape)
        np.testing.assert_array_equal(table, want.table)
        texel = np.uint16 if pool.exact_uint8 else np.float32
        atlas = np.frombuffer(pool.atlas.read(), texel).reshape(want.atlas.shape)
        encoded = np.frombuffer(atlas_payload(want.atlas, pool.exact_uint8), texel)
        np.testing.assert_array_equal(atlas, encoded.reshape(want.atlas.shape))
        assert store.seconds["upload_read"] > 0 and store.seconds["range_pass"] > 0
        assert pool.write_seconds > 0 and pool.upload_seconds >= pool.write_seconds
    finally:
        pool.release()


class _FailingSource:
    """A Zarr source whose read of one layer fails (in the reading process)."""
    process_safe = True

    def __init__(self, source, z0):
        self.source, self.z0 = source, z0
        self.shape = source.shape

    def read(self, z0, *rest):
        if z0 == self.z0:
            raise VolumeError(f"layer at {z0} unreadable")
        return self.source.read(z0, *rest)

    def density(self, raw):
        return self.source.density(raw)


@pytest.mark.skipif(not __import__("os").path.isdir("/dev/shm"), reason="no /dev/shm to look in")
def test_shared_memory_is_unlinked_when_a_read_fails_or_the_upload_stops(tmp_path, monkeypatch):
    """Every shared memory block is unlinked when a reader fails, when the caller stops early
    (KeyboardInterrupt in the loop) and when it closes the generator."""
    data = _blob((40, 24, 64))
    path = _zarr(tmp_path, data)
    blocks = _processes(monkeypatch)
    store = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK).bricks
    _, _, _, resident = store.layout(4096)
    layers = sorted(set(resident[:, 0].tolist()))
    assert len(layers) >= 3

    def dest(z, y, x):
        return np.empty((BRICK + 2,) * 3, np.float32)

    lo, hi = store.raw_ranges()       # (a brick of one value is not read: fail where one varies)
    varied = sorted(set(np.argwhere(lo != hi)[:, 0].tolist()))
    assert len(varied) >= 2
    failing = BrickStore(_FailingSource(store.source, varied[-1] * BRICK), BRICK)
    failing._ranges = store.raw_ranges()
    with pytest.raises(VolumeError, match="unreadable"):
        for _ in failing.write_resident(resident, dest, densities=True):
            pass
    assert blocks.names and not blocks.left()
    blocks.names.clear()
    with pytest.raises(KeyboardInterrupt):
        for _ in store.write_resident(resident, dest, densities=True):
            raise KeyboardInterrupt
    assert blocks.names and not blocks.left()
    blocks.names.clear()
    layers = store.write_resident(resident, dest, densities=True)
    next(layers)
    layers.close()
    assert blocks.names and not blocks.left()


@pytest.mark.parametrize("channels", [1, 3])
def test_upload_writes_rows_of_slots_equal_to_the_twins_pack(ctx, channels):
    """upload_store from an array in memory (threads), one and several channels: the atlas
    written a row of slots at a time (the last row partial) equals the twin's pack brick by
    brick; a block past the end of its row is refused."""
    from radiance_probes.gl.brick_pool import upload_store
    rng = np.random.default_rng(7)
    data = np.zeros((20, 19, 33, channels), np.float32)
    data[2:17, 3:15, 4:30] = rng.random((15, 12, 26, channels))
    data = data[..., 0] if channels == 1 else data
    store = BrickStore(ArraySource(data), 4)
    pool = upload_store(ctx, store, False, 4096)
    try:
        want = pack(data, 4, 4096)
        n = int(np.count_nonzero(want.brick_of_slot != 0xFFFFFFFF))
        assert pool.uploads == n and n % pool.grid[0] != 0     # a partial last row
        assert pool.writes == -(-n // pool.grid[0])
        np.testing.assert_array_equal(pool.brick_of_slot, want.brick_of_slot)
        atlas = np.frombuffer(pool.atlas.read(), np.float32).reshape(want.atlas.shape)
        np.testing.assert_array_equal(atlas, want.atlas)
        side = 6
        with pytest.raises(ValueError, match="rows of"):
            pool.write_slots(pool.grid[0] - 1, [0, 1],
                             np.zeros((side, side, 2 * side) + data.shape[3:], np.float32))
    finally:
        pool.release()


@pytest.mark.parametrize("room", ["none", "one layer"])
def test_readers_without_shared_memory_to_spare_send_their_bricks_pickled(
        tmp_path, monkeypatch, room):
    """Layers whose blocks would take the shared memory past its budget (half of /dev/shm's
    free space: none here, or room for the bricks of the layer reading most) come back from the
    processes pickled, as before: the same bricks with aprons as the threads' reads, each read
    once more (those of one value not at all)."""
    import radiance_probes.io.brick_reading as brick_reading
    data = _blob()
    varied = _varied(data)
    read_layers = int(np.count_nonzero(varied.any(axis=(1, 2))))    # the layers the upload reads
    budget = 0 if room == "none" else int(varied.sum(axis=(1, 2)).max()) * BRICK ** 3 * 4
    path = _zarr(tmp_path, data)
    threads = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK).bricks
    blocks = _processes(monkeypatch)
    monkeypatch.setattr(brick_reading, "_shared_budget", lambda: budget)
    procs = load_volume(VolumeSpec(path=str(path), builtin=None), brick=BRICK).bricks
    _, _, _, resident = procs.layout(4096)
    seen = 0
    for z, (y, x), block in procs.resident_layers(resident, densities=True):
        want = threads.source.density(threads.pencil(z, y, x, x + 1, 1))
        np.testing.assert_array_equal(block, want)
        seen += 1
    assert seen == len(resident)
    assert (len(blocks.names) == 0) if budget == 0 else (0 < len(blocks.names) < read_layers)
    assert procs.handed == {"shared": len(blocks.names),
                            "pickled": read_layers - len(blocks.names)}
    assert not blocks.left()
    np.testing.assert_array_equal(procs.reads, _written(data) + varied)


@pytest.mark.parametrize("channels", [1, 2])
def test_bricked_time_series_is_normalised_by_the_whole_series_range(tmp_path, channels):
    """SPEC.md, Time series: where the scene gives no range, every step is normalised by the
    whole series' least and largest value, read brick by brick as read whole (each step's range
    differs here, so a step's own range would give other densities)."""
    import zarr
    from radiance_probes.io import lazy_zarr
    r = np.random.default_rng(5)
    shape = (3, channels, 16, 12, 20) if channels > 1 else (3, 16, 12, 20)
    data = r.integers(100, 1000, shape).astype(np.uint16)
    data[0] += 2000                       # step 0 holds the series' largest values
    data[2] //= 4                         # step 2 its least
    path = tmp_path / "series.zarr"
    arr = zarr.create_array(str(path), shape=data.shape, dtype=data.dtype, chunks=(1,) + (8,) * (data.ndim - 1))
    arr[...] = data
    axes = "tczyx" if channels > 1 else "tzyx"
    parsed = parse_scene({"volume": {"path": str(path), "axes": axes}, "time": 1})
    lazy_zarr._SERIES_EXTREMES.clear()
    lazy = load_scene_volume(parsed, brick=BRICK)
    whole = load_scene_volume(parsed)
    _same_volume(lazy, whole)
    lo, hi = float(data.min()), float(data.max())
    assert lazy.value_range == (lo, hi) if channels == 1 else lazy.channel_ranges[0][1] == \
        float(data[:, 0].max())
    # another step reuses the series' extremes (no other step's range pass again)
    calls = []
    original = BrickStore.raw_ranges
    BrickStore.raw_ranges = lambda self: calls.append(1) or original(self)
    try:
        step2 = load_scene_volume(parsed.replace(time=2), brick=BRICK)
    finally:
        BrickStore.raw_ranges = original
    assert len(calls) == 1 and step2.value_range == lazy.value_range


# ---- a Zarr store's unwritten chunks: never read, the fill value -------------------------------

def _sparse(fill: int, channels: int) -> np.ndarray:
    """uint16 [z, y, x(, c)] of 24^3 (3 x 3 x 3 bricks of 8): the fill value but for a ramp across
    two bricks, a brick of one other value, a few voxels in a far corner brick and, of several
    channels, a small block in channel 2 alone (so a brick whose other channels are unwritten)."""
    raw = np.full((24, 24, 24, channels), fill, np.uint16)
    ramp = np.arange(5 * 5 * 11, dtype=np.uint16).reshape(5, 5, 11, 1)
    raw[9:14, 10:15, 2:13] = fill + 1 + ramp + 10 * np.arange(channels, dtype=np.uint16)
    raw[16:24, 0:8, 16:24] = fill + 77
    raw[0:3, 20:24, 20:24] = fill + 5
    if channels > 1:
        raw[16:20, 16:20, 0:4, 2] = fill + 9
    return raw[..., 0] if channels == 1 else raw


def _sparse_store(path, raw: np.ndarray, fill: int, zarr_format: int, chunk: int, shard,
                  separator: str):
    """raw [z, y, x(, c)] as a Zarr array ([c, z, y, x] of several channels, a channel a chunk)
    of chunks of `chunk` voxels (in shards of `shard`, or none), the fill value `fill` and chunk
    keys separated by `separator`: Zarr writes only the chunks holding another value."""
    import zarr
    many = raw.ndim == 4
    stored = np.ascontiguousarray(np.moveaxis(raw, -1, 0)) if many else raw
    lead = (1,) if many else ()
    extra = {"dimension_names": list("czyx")} if many and zarr_format == 3 else {}
    if shard:
        extra["shards"] = lead + (shard,) * 3
    name = "default" if zarr_format == 3 else "v2"
    array = zarr.create_array(str(path), shape=stored.shape, dtype=stored.dtype,
                              chunks=lead + (chunk,) * 3, fill_value=fill,
                              zarr_format=zarr_format,
                              chunk_key_encoding={"name": name, "separator": separator}, **extra)
    if many and zarr_format == 2:
        array.attrs["_ARRAY_DIMENSIONS"] = list("czyx")
    array[...] = stored
    return path


def _bricks_with_stored_chunks(raw: np.ndarray, fill: int, stored: int) -> np.ndarray:
    """[bz, by, bx] 1 where a brick of BRICK voxels overlaps a stored chunk (or shard) of
    `stored` voxels holding a value other than the fill value in a channel, else 0: the bricks
    a read of a store Zarr wrote so must read (counted voxel by voxel, not as app/io/bricks.py
    does)."""
    off = raw != fill
    if off.ndim == 4:
        off = off.any(axis=-1)
    present = np.zeros_like(off)
    for z, y, x in np.ndindex(*(-(-n // stored) for n in off.shape)):
        at = (slice(z * stored, (z + 1) * stored), slice(y * stored, (y + 1) * stored),
              slice(x * stored, (x + 1) * stored))
        present[at] = off[at].any()
    out = np.zeros((3, 3, 3), np.int64)
    for z, y, x in np.ndindex(3, 3, 3):
        out[z, y, x] = present[z * BRICK:(z + 1) * BRICK, y * BRICK:(y + 1) * BRICK,
                               x * BRICK:(x + 1) * BRICK].any()
    return out


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("fill", [0, 300])
@pytest.mark.parametrize("zarr_format, chunk, shard, separator", [
    (3, 8, None, "/"), (3, 4, None, "."), (3, 16, None, "/"), (3, 4, 8, "/"),
    (2, 8, None, "."), (2, 4, None, "/"), (2, 16, None, ".")])
def test_unwritten_chunks_are_not_read_and_read_as_the_fill_value(
        ctx, tmp_path, monkeypatch, channels, fill, zarr_format, chunk, shard, separator):
    """A store whose chunks are partly unwritten (zarr format 3 and 2, chunks smaller than a
    brick, of one and larger, in shards, keys separated by '/' and '.', a fill value of 0 and
    another, one channel and three): the range pass reads only the bricks that overlap a stored
    chunk (of a sharded array, a stored shard), once, and the upload only those of more than one
    value; the ranges, the constant bricks, the pool's plan and the upload are those of the
    plain read (the same store with its listing failing: every brick read, as before) and of the
    whole loader's volume, packed by the twin."""
    import radiance_probes.io.brick_sources as brick_sources
    raw = _sparse(fill, channels)
    path = _sparse_store(tmp_path / "sparse.zarr", raw, fill, zarr_format, chunk, shard,
                         separator)
    spec = VolumeSpec(path=str(path), builtin=None)
    lazy = load_volume(spec, brick=BRICK)
    store = lazy.bricks
    written = _bricks_with_stored_chunks(raw, fill, shard or chunk)
    assert 0 < written.sum() < written.size
    np.testing.assert_array_equal(store.reads, written)

    def unlisted(array):
        raise OSError("no listing")
    with monkeypatch.context() as m:
        m.setattr(brick_sources, "_array_keys", unlisted)
        plain = load_volume(spec, brick=BRICK).bricks
    assert np.all(plain.reads == 1)                  # as before: every brick read once
    for got, want in zip(store.raw_ranges() + store.ranges(), plain.raw_ranges() + plain.ranges()):
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(store.constant(), plain.constant())
    for got, want in zip(store.layout(4096), plain.layout(4096)):
        np.testing.assert_array_equal(got, want)

    whole = load_volume(spec)
    assert isinstance(whole.data, np.ndarray)
    _same_volume(lazy, whole)
    _uploaded_is_packed(ctx, lazy, whole.data)
    np.testing.assert_array_equal(store.reads, written + _varied(raw))


def test_unwritten_bricks_of_a_time_step_and_the_channels_shown(tmp_path):
    """A brick is unwritten where every chunk it overlaps of the time step read and of the
    channels shown (in the scene's order, not the file's) was never written; the range pass
    reads the others alone and gives the raw ranges of the step's voxels."""
    import zarr
    from radiance_probes.io.brick_sources import ZarrSource
    from radiance_probes.io.volume import normalise
    data = np.zeros((2, 4, 24, 24, 24), np.uint16)         # [t, c, z, y, x]
    data[1, 2, 0:8, 0:8, 0:8] = 5                          # brick (0, 0, 0): step 1, channel 2
    data[1, 1, 8:16, 0:8, 0:8] = 6                         # brick (1, 0, 0): step 1, channel 1
    data[0, 0, 16:24, 0:8, 0:8] = 7                        # brick (2, 0, 0): step 0, channel 0
    data[1, 0, 20:24, 20:24, 20:24] = 8                    # brick (2, 2, 2): step 1, channel 0
    path = tmp_path / "series.zarr"
    zarr.create_array(str(path), shape=data.shape, dtype=data.dtype, chunks=(1, 1, 8, 8, 8),
                      dimension_names=list("tczyx"))[...] = data
    array = zarr.open(str(path), mode="r")

    def written(*bricks):
        out = np.zeros((3, 3, 3), np.int64)
        for b in bricks:
            out[b] = 1
        return out

    for time, channel, shown, want in [
            (1, 0, [2, 0], written((0, 0, 0), (2, 2, 2))),
            (1, 1, None, written((1, 0, 0))),
            (0, 0, [2, 0], written((2, 0, 0))),
            (0, 3, None, written())]:
        source = ZarrSource(array, "tczyx", time, channel, None, str(path), None, normalise,
                            channels=shown, value_ranges=None if shown is None else [None] * 2)
        mask, fill = source.unwritten_bricks(BRICK)
        np.testing.assert_array_equal(mask, ~want.astype(bool))
        assert fill.shape == (() if shown is None else (2,)) and fill.dtype == np.uint16
        store = BrickStore(source, BRICK)
        step = data[time, shown if shown else [channel]]
        step = np.moveaxis(step, 0, -1) if shown else step[0]
        for got, expected in zip(store.raw_ranges(), brick_ranges(step, BRICK)):
            np.testing.assert_array_equal(got, expected)
        np.testing.assert_array_equal(store.reads, want)


def test_a_store_not_listed_is_read_whole(tmp_path):
    """Where the chunks cannot be listed completely (a linked directory inside the array, a
    store the listing does not know), every brick is read, as before."""
    import os
    import zarr
    from radiance_probes.io.brick_sources import ZarrSource, stored_chunks
    from radiance_probes.io.volume import normalise
    raw = _sparse(0, 1)
    path = _sparse_store(tmp_path / "linked.zarr", raw, 0, 3, 8, None, "/")
    array = zarr.open(str(path), mode="r")
    assert stored_chunks(array) is not None
    os.rename(path / "c" / "1", tmp_path / "elsewhere")
    os.symlink(tmp_path / "elsewhere", path / "c" / "1")
    for opened in (zarr.open(str(path), mode="r"),
                   zarr.open_array(zarr.storage.LoggingStore(zarr.storage.LocalStore(str(path))),
                                   mode="r")):
        assert stored_chunks(opened) is None
        store = BrickStore(ZarrSource(opened, "zyx", 0, 0, None, str(path), None, normalise),
                           BRICK)
        for got, want in zip(store.raw_ranges(), brick_ranges(raw, BRICK)):
            np.testing.assert_array_equal(got, want)
        assert np.all(store.reads == 1)


def test_unwritten_chunks_of_a_non_finite_fill_value(tmp_path):
    """A float store whose fill value is NaN: its unwritten bricks hold the scene's
    replace_nonfinite value without a read (the whole loader's volume); without one, the store
    is refused as the whole loader refuses it."""
    import zarr
    raw = _sparse(0, 1).astype(np.float32)
    raw[raw == 0] = np.nan
    path = tmp_path / "nan.zarr"
    zarr.create_array(str(path), shape=raw.shape, dtype=raw.dtype, chunks=(8, 8, 8),
                      fill_value=np.nan)[...] = raw
    spec = VolumeSpec(path=str(path), builtin=None, replace_nonfinite=0.5)
    lazy = load_volume(spec, brick=BRICK)
    whole = load_volume(spec)
    # the densities and their range (raw_min differs, as it did before: the whole loader's is of
    # the finite values, a bricked store's after the replacement)
    assert lazy.value_range == whole.value_range == (0.5, float(np.nanmax(raw)))
    np.testing.assert_array_equal(np.asarray(lazy.data), whole.data)
    written = _bricks_with_stored_chunks(np.nan_to_num(raw, nan=0.0), 0.0, 8)
    assert 0 < written.sum() < written.size
    np.testing.assert_array_equal(lazy.bricks.reads, written)
    refused = VolumeSpec(path=str(path), builtin=None)
    with pytest.raises(VolumeError, match="NaN"):
        load_volume(refused, brick=BRICK)
    with pytest.raises(VolumeError, match="NaN"):
        load_volume(refused)


def test_bricks_overlapping_chunks_of_any_size():
    """bricks_overlapping against each brick's voxels, chunks smaller and larger than a brick,
    aligned or not, partial at the far faces."""
    from radiance_probes.io.brick_sources import bricks_overlapping
    rng = np.random.default_rng(3)
    for _ in range(100):
        shape = tuple(int(n) for n in rng.integers(1, 30, 3))
        chunks = tuple(int(n) for n in rng.integers(1, 12, 3))
        brick = int(rng.integers(1, 10))
        grid = rng.random(tuple(-(-n // c) for n, c in zip(shape, chunks))) < 0.2
        voxels = np.zeros(shape, bool)
        for cell in np.argwhere(grid):
            voxels[tuple(slice(i * c, (i + 1) * c) for i, c in zip(cell, chunks))] = True
        want = np.zeros(tuple(-(-n // brick) for n in shape), bool)
        for b in np.ndindex(*want.shape):
            want[b] = voxels[tuple(slice(i * brick, (i + 1) * brick) for i in b)].any()
        np.testing.assert_array_equal(bricks_overlapping(grid, chunks, brick, shape), want)
