"""Several channels (SPEC.md, Channels): the mixture in glsl/lib/medium.glsl against its twin
(app/twins/medium.py), the majorant grid and the visible region of the summed medium, a channel
switched off against the scene without it, a one-channel scene through the channels' path against
the classic scene, and a known answer: single scattering of a thin slab of three constant
channels, each alone and all three mixed, with the path tracer and the raymarcher."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.scene.channels import ChannelTables, channel_uniforms
from radiance_probes.gl.textures import TransferTable, volume_texture
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.scene.types import ChannelSpec, SceneError, TransferFunctionSpec, VolumeError
from radiance_probes.twins.majorant_grid import (channel_density_ranges, macrocell_counts,
                                                 majorant_grid)
from radiance_probes.twins.medium import (albedo_at, classified_at, density_at, mixed_transfer_at,
                                          sigma_t_at)
from radiance_probes.twins.visible_region import visible_region
from radiance_probes.io.volume import Volume
from radiance_probes.io.load import load_scene_volume
from glsl_harness import run_kernel

DENSITY_SCALE = 23.0
ALBEDO = 0.85

MIXED_KERNEL = """
#include "lib/medium.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 x = vec3(p[3u * i], p[3u * i + 1u], p[3u * i + 2u]);
    vec4 d = densities_at(x);
    vec4 c = classified_at(x);
    vec3 a = albedo_at(x);
    uint k = 12u * i;
    o[k] = d.r; o[k + 1u] = d.g; o[k + 2u] = d.b; o[k + 3u] = d.a;
    o[k + 4u] = c.r; o[k + 5u] = c.g; o[k + 6u] = c.b; o[k + 7u] = c.a;
    o[k + 8u] = sigma_t_at(x);
    o[k + 9u] = a.r; o[k + 10u] = a.g; o[k + 11u] = a.b;
}
"""


def _volume(channels: int, shape=(5, 4, 6), seed=1) -> Volume:
    data = np.random.default_rng(seed).uniform(size=shape + (channels,)).astype(np.float32)
    ranges = ((0.0, 1.0),) * channels
    return Volume(data, (1.0, 1.3, 0.8), "random", (0.0, 1.0), "float32", 0.0, 1.0, ranges,
                  ranges)


def _tables(sizes, on, seed=3) -> ChannelTables:
    rng = np.random.default_rng(seed)
    return ChannelTables(tuple(rng.uniform(size=(n, 4)).astype(np.float32) for n in sizes),
                         tuple(on))


def _points(volume, n=3000, seed=4):
    he = volume.half_extent.astype(np.float64)
    r = np.random.default_rng(seed)
    pts = np.concatenate([r.uniform(-1, 1, (n, 3)) * he, r.uniform(-1.1, 1.1, (n // 4, 3)) * he])
    return pts.astype(np.float32).astype(np.float64)


@pytest.mark.parametrize("from_buffer", [0, 1])
def test_mixture_matches_its_twin(ctx, from_buffer):
    """Densities, the mixture's RGBA, sigma_t and albedo at random points: the mixture computed
    from the densities the shader read agrees with the twin to float rounding, and the full twin
    (its own trilinear densities) within the texture unit's filtering error."""
    volume = _volume(3)
    tables = _tables((7, 5, 9), (True, False, True))
    vt = volume_texture(ctx, volume)
    tt = TransferTable(ctx, tables)
    pts = _points(volume)
    try:
        vt.use(0)
        tt.use(1)
        uniforms = {"volume_density": 0, "transfer_function": 1, "density_scale": DENSITY_SCALE,
                    "albedo": ALBEDO,
                    "box_half_extent": tuple(float(v) for v in volume.half_extent),
                    **channel_uniforms(tables)}
        out = run_kernel(ctx, MIXED_KERNEL, [np.ascontiguousarray(pts, np.float32).ravel()],
                         (len(pts), 12), uniforms=uniforms, count=len(pts),
                         defines={"MEDIUM_CHANNELS": 3, "TRANSFER_FROM_BUFFER": from_buffer})
    finally:
        vt.release()
        tt.release()
    d = out[:, :3].astype(np.float64)
    want_d = density_at(volume, pts)
    assert np.abs(d - want_d).max() < 2e-2    # trilinear filtering's fixed-point weights
    mixed = mixed_transfer_at(tables, d)
    inside = np.ones(len(pts), bool)   # (beyond the box, clamped to the edge voxel)
    np.testing.assert_allclose(out[:, 4:8], mixed, rtol=2e-5, atol=2e-6)
    np.testing.assert_allclose(out[inside, 8], DENSITY_SCALE * mixed[inside, 3], rtol=2e-5,
                               atol=1e-4)
    np.testing.assert_allclose(out[inside, 9:12], ALBEDO * mixed[inside, :3], rtol=2e-5,
                               atol=2e-6)
    # the twin at its own densities stays within the filtering error
    twin_sigma = sigma_t_at(volume, tables, DENSITY_SCALE, pts[inside])
    slope = max(np.abs(np.diff(t[:, 3].astype(np.float64))).max() * (len(t) - 1)
                for t in tables.tables)
    assert np.all(np.abs(out[inside, 8] - twin_sigma) <= DENSITY_SCALE * (2 * slope * 2e-2 + 1e-5))
    # the SPEC's formula, written out: sigma_t the sum, albedo the sigma_t-weighted mix
    a = [tables.tables[c] for c in (0, 2)]
    from radiance_probes.scene.transfer import lookup
    rows = [lookup(t, d[inside][:, c]) for t, c in zip(a, (0, 2))]
    sigma = sum(DENSITY_SCALE * r[:, 3] for r in rows)
    np.testing.assert_allclose(out[inside, 8], sigma, rtol=2e-5, atol=1e-4)
    mix = sum(DENSITY_SCALE * r[:, 3:4] * r[:, :3] for r in rows) / sigma[:, None]
    ok = sigma > 1e-3
    np.testing.assert_allclose(out[inside][ok, 9:12], ALBEDO * mix[ok], rtol=1e-4, atol=1e-5)
    assert albedo_at(volume, tables, ALBEDO, pts[:2]).shape == (2, 3)
    assert classified_at(volume, tables, pts[:2]).shape == (2, 4)


# ---- the grids every pass reads: majorant and visible region of the summed medium ---------------

def _opacity_tf(colour, opacity_points) -> dict:
    return {"colors": [[0.0, *colour]], "opacity": opacity_points}


THREE = [{"transfer_function": _opacity_tf((1.0, 0.3, 0.3), [[0, 0], [0.5, 0], [1, 1]])},
         {"transfer_function": _opacity_tf((0.3, 1.0, 0.3), [[0, 0], [0.3, 0.0], [0.7, 0.6]])},
         {"transfer_function": _opacity_tf((0.3, 0.3, 1.0), [[0, 0.0], [0.8, 0], [1, 0.9]])}]


def _blobs(shape=(18, 20, 22), seed=5) -> np.ndarray:
    """Three channels [c, z, y, x] of smooth blobs in different places, 0 elsewhere."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    rng = np.random.default_rng(seed)
    out = []
    for cx, cy, cz in ((-0.5, 0.0, 0.2), (0.4, -0.3, -0.2), (0.1, 0.5, 0.0)):
        r = np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2)
        out.append(np.clip(1.2 - 2.0 * r, 0, 1) * rng.uniform(0.8, 1.0, shape))
    return np.stack(out).astype(np.float32)


def _scene_file(tmp_path, data: np.ndarray, channels, **extra) -> dict:
    path = tmp_path / "channels.npy"
    np.save(path, data)
    return {"volume": {"path": str(path), "axes": "czyx", "value_range": [0, 1]},
            "channels": channels, "density_scale": DENSITY_SCALE, **extra}


@pytest.mark.parametrize("clip", [None, {"crop": {"min": [-0.31, -0.2, -0.4],
                                                  "max": [0.27, 0.41, 0.35]},
                                         "clip_plane": {"normal": [1, 0.5, 0], "distance": 0.1}}])
def test_majorant_grid_bounds_the_summed_sigma_t(ctx, tmp_path, clip):
    channels = [dict(c) for c in THREE]
    channels[1]["enabled"] = False
    r = Renderer(ctx, parse_scene(_scene_file(tmp_path, _blobs(), channels, **(clip or {}))))
    try:
        res = r.resources
        volume, tables = res.volume, res.tables
        assert volume.channel_count == 3 and tables.on == (True, False, True)
        gpu = res.majorant_grid.read()
        d_min, d_max = channel_density_ranges(volume, macrocell_counts(volume.dims))
        twin = majorant_grid(d_min, d_max, tables, DENSITY_SCALE, res.clip, volume.half_extent)
        if clip is None:
            np.testing.assert_allclose(gpu, twin, rtol=1e-6, atol=0)
        else:
            tight = majorant_grid(d_min, d_max, tables, DENSITY_SCALE, res.clip,
                                  volume.half_extent, rounding=-1e-5)
            loose = majorant_grid(d_min, d_max, tables, DENSITY_SCALE, res.clip,
                                  volume.half_extent, rounding=1e-5)
            assert np.all(gpu >= tight * (1 - 1e-6)) and np.all(gpu <= loose * (1 + 1e-6))
            assert (gpu == 0).any()
        # more than either channel alone would need where both are present
        alone = [majorant_grid(d_min, d_max, ChannelTables(tables.tables, on), DENSITY_SCALE)
                 for on in ((True, False, False), (False, False, True))]
        assert np.any(twin > np.maximum(*alone) * 1.01) or clip is not None
        cells = np.array(gpu.shape[::-1])
        he = volume.half_extent.astype(np.float64)
        u = np.random.default_rng(9).uniform(size=(100000, 3))
        pts = (u * 2 - 1) * he
        idx = np.minimum((u * cells).astype(int), cells - 1)
        sigma = sigma_t_at(volume, tables, DENSITY_SCALE, pts, res.clip)
        assert np.all(sigma <= gpu[idx[:, 2], idx[:, 1], idx[:, 0]] * (1 + 1e-4) + 1e-6)
        assert res.majorant >= sigma.max()
    finally:
        r.release()


def test_visible_region_of_the_channels_shown(ctx, tmp_path):
    data = _blobs()
    for on in ((True, True, True), (True, False, False), (False, False, True)):
        channels = [{**c, "enabled": e} for c, e in zip(THREE, on)]
        r = Renderer(ctx, parse_scene(_scene_file(tmp_path, data, channels)))
        try:
            low, high = r.visible_region()
            res = r.resources
            want = visible_region(res.volume.data, res.volume.half_extent, res.tables,
                                  DENSITY_SCALE)
            np.testing.assert_allclose(low, want[0], atol=1e-6, err_msg=str(on))
            np.testing.assert_allclose(high, want[1], atol=1e-6, err_msg=str(on))
            if on == (True, False, False):
                assert high[0] < 0.2      # channel 0 lies at -x
        finally:
            r.release()


# ---- a channel switched off; one channel through the channels' path -----------------------------

SMALL = {"camera": {"width": 20, "height": 16}, "probes": {"grid": 4, "samples": 16},
         "max_bounces": 4}
METHODS = ("pt", "probes", "probes-only", "raymarch")


def _images(ctx, scene, methods=METHODS, spp=2) -> dict:
    r = Renderer(ctx, scene)
    try:
        out = {m: r.render(m, spp=spp, seed=3).image for m in methods}
        r.configure(raymarch_stage="fragment")
        out["raymarch-fragment"] = r.render("raymarch", spp=spp, seed=3).image
        out["region"] = np.asarray(r.visible_region())
        out["majorant"] = r.resources.majorant_grid.read()
        return out
    finally:
        r.release()


def test_a_channel_switched_off_equals_the_scene_without_it(ctx, tmp_path):
    data = _blobs(shape=(10, 12, 14))
    off = [dict(c) for c in THREE]
    off[1]["enabled"] = False
    without = [{**THREE[0], "index": 0}, {**THREE[2], "index": 2}]
    a = _images(ctx, parse_scene(_scene_file(tmp_path, data, off, **SMALL)))
    b = _images(ctx, parse_scene(_scene_file(tmp_path, data, without, **SMALL)))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert a["pt"].max() > 0
    # and switched on it changes the image
    c = _images(ctx, parse_scene(_scene_file(tmp_path, data, THREE, **SMALL)), ("pt",))
    assert np.abs(c["pt"] - a["pt"]).max() > 1e-3


def test_one_channel_through_the_channels_path_is_the_classic_scene(ctx, tmp_path):
    """A one-channel file shown as channels[0] with a transfer function renders bit for bit as
    the one-channel scene with that transfer function (the same code: MEDIUM_CHANNELS 1)."""
    data = _blobs(shape=(10, 12, 14))[:1]
    tf = THREE[0]["transfer_function"]
    a = _images(ctx, parse_scene(_scene_file(tmp_path, data, [{"transfer_function": tf}],
                                             **SMALL)))
    classic = {**_scene_file(tmp_path, data, [], **SMALL), "transfer_function": tf}
    del classic["channels"]
    b = _images(ctx, parse_scene(classic))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


# ---- known answer: three constant channels, each alone and all three mixed -------------------

OPACITY = (0.3, 0.6, 1.0)            # each channel's opacity where its density is 1
COLOURS = ((1.0, 0.25, 0.25), (0.25, 1.0, 0.25), (0.3, 0.3, 1.0))
SLAB_SCALE = 6.0                     # density_scale: optical thickness 0.2 to 1.4 across the slab
IRRADIANCE = 2.0


def _quadrant_slab() -> np.ndarray:
    """[c, z, y, x] 3 x 4 x 32 x 32: a slab 1 x 1 x 1/8 in quadrants, channel 0 alone at (-x, -y),
    1 alone at (+x, -y), 2 alone at (-x, +y), all three at (+x, +y)."""
    data = np.zeros((3, 4, 32, 32), np.float32)
    data[0, :, :16, :16] = 1
    data[1, :, :16, 16:] = 1
    data[2, :, 16:, :16] = 1
    data[:, :, 16:, 16:] = 1
    return data


def _slab_closed_form(scene, rays, channels_at):
    """Single scattering of the sun (straight down the slab's normal, +z towards the light) off
    a homogeneous slab of half thickness h seen along unit rays d: with c = |d_z|, sigma the
    summed extinction and rgb the sigma-weighted colour, radiance = albedo rgb p E
    (1 - exp(-sigma (1 + c) L)) / (1 + c), L = 2h / c the ray's length in the slab, p = 1 / 4 pi."""
    cam, dirs = rays
    h = 0.5 * 4 / 32
    c = np.abs(dirs[..., 2])
    length = 2 * h / c
    eye = cam.eye.astype(np.float64)
    t_front = (eye[2] - h) / c
    hit = eye[None, None, None, :2] + t_front[..., None] * dirs[..., :2]   # where rays enter
    sigma, rgb, label = channels_at(hit)
    radiance = (scene.albedo * rgb * IRRADIANCE / (4 * math.pi)
                * ((1 - np.exp(-sigma * (1 + c) * length)) / (1 + c))[..., None])
    return radiance.mean(axis=-2), label


def _mixture_at(hit):
    """sigma and rgb of the quadrant each entry point lies in; label 0 to 3 per point, -1 near a
    quadrant's edge (where filtering blends quadrants, or rays leave through a side)."""
    x, y = hit[..., 0], hit[..., 1]
    present = np.stack([(x < 0) & (y < 0) | (x > 0) & (y > 0),
                        (x > 0) & (y < 0) | (x > 0) & (y > 0),
                        (x < 0) & (y > 0) | (x > 0) & (y > 0)], -1).astype(np.float64)
    a = present * np.asarray(OPACITY)
    sigma = SLAB_SCALE * a.sum(-1)
    rgb = (a[..., None] * np.asarray(COLOURS)).sum(-2) / a.sum(-1)[..., None]
    label = np.where(x < 0, 0, 1) + np.where(y < 0, 0, 2)
    edge = (np.abs(x) < 0.07) | (np.abs(y) < 0.07) | (np.abs(x) > 0.43) | (np.abs(y) > 0.43)
    return sigma, rgb, np.where(edge, -1, label)


def test_constant_channels_known_answer(ctx, tmp_path):
    """Each channel's colour where it is alone and their mix where all three overlap, against
    the slab's closed form: the path tracer (mean over each quadrant within 3 standard errors
    and 2%) and the raymarcher (within 3%)."""
    from transport_reference import pixel_rays
    channels = [{"transfer_function": {"colors": [[0.0, *col]],
                                       "opacity": [[0.0, 0.0], [1.0, a]]}}
                for col, a in zip(COLOURS, OPACITY)]
    path = tmp_path / "slab.npy"
    np.save(path, _quadrant_slab())
    scene = parse_scene({"volume": {"path": str(path), "axes": "czyx", "value_range": [0, 1]},
                         "channels": channels, "density_scale": SLAB_SCALE, "albedo": 0.9,
                         "anisotropy": 0.0, "max_bounces": 1, "environment": [0, 0, 0],
                         "light": {"direction": [0, 0, 1], "irradiance": [IRRADIANCE] * 3},
                         "camera": {"eye": [0, 0, 2.2], "target": [0, 0, 0], "fov_y": 26.0,
                                    "width": 24, "height": 24},
                         "probes": {"grid": 4, "samples": 16}})
    want, labels = _slab_closed_form(scene, pixel_rays(scene, 3), _mixture_at)
    pixel_label = np.where((labels == labels[..., :1]).all(-1), labels[..., 0], -1)
    r = Renderer(ctx, scene)
    try:
        runs = [r.render("pt", spp=256, seed=s).image for s in (1, 2)]
        raymarch = r.render("raymarch", spp=4).image
    finally:
        r.release()
    pt = 0.5 * (runs[0] + runs[1])
    for q in range(4):
        sel = pixel_label == q
        assert sel.sum() >= 16
        expected = want[sel].mean(0)
        got = pt[sel].mean(0)
        noise = np.abs(runs[0][sel] - runs[1][sel]).mean(0) / math.sqrt(sel.sum())
        assert np.all(np.abs(got - expected) <= 3 * noise + 0.02 * expected), (q, got, expected)
        np.testing.assert_allclose(raymarch[sel].mean(0), expected, rtol=0.03, err_msg=str(q))
    # the colours: channel 0 alone is red, 1 green, 2 blue, all three a mix bluer than red
    means = [want[pixel_label == q].mean(0) for q in range(4)]
    assert np.argmax(means[0]) == 0 and np.argmax(means[1]) == 1 and np.argmax(means[2]) == 2
    assert means[3][2] > means[3][0]


# ---- reading several channels, and the refusals -------------------------------------------------

def _cube_channels(n=32) -> np.ndarray:
    """[c, z, y, x] 3 x n^3 uint16, each channel a different ramp (told apart after reading)."""
    z, y, x = np.meshgrid(*(np.arange(n) for _ in range(3)), indexing="ij")
    return np.stack([x * 100, y * 200 + 7, z * 300 + 11]).astype(np.uint16)


def _load(tmp_path, name, **volume):
    return load_scene_volume(parse_scene({"volume": {"path": str(tmp_path / name), **volume}}))


def _assert_channels(volume, data):
    assert volume.dims == (32, 32, 32) and volume.channel_count == 3
    for c in range(3):
        lo, hi = float(data[c].min()), float(data[c].max())
        np.testing.assert_allclose(volume.channel(c), (data[c] - lo) / (hi - lo), atol=1e-6)
        assert volume.channel_ranges[c] == (lo, hi)


def test_tifffile_channels_in_its_metadata_are_channels_not_slices(tmp_path):
    """The issue's file: a [c, z, y, x] TIFF written by tifffile with its axes in the metadata
    was read as 96 z-slices; it is 3 channels of a 32^3 cube."""
    import tifffile
    data = _cube_channels()
    tifffile.imwrite(tmp_path / "czyx.tif", data, metadata={"axes": "CZYX"})
    _assert_channels(_load(tmp_path, "czyx.tif"), data)
    # ImageJ's hyperstack keeps channels between z and y
    tifffile.imwrite(tmp_path / "imagej.tif", np.ascontiguousarray(data.transpose(1, 0, 2, 3)),
                     imagej=True, metadata={"axes": "ZCYX"})
    _assert_channels(_load(tmp_path, "imagej.tif"), data)
    tifffile.imwrite(tmp_path / "v.ome.tif", data, ome=True, metadata={"axes": "CZYX"})
    _assert_channels(_load(tmp_path, "v.ome.tif"), data)
    # the scene may say the same, not otherwise
    _assert_channels(_load(tmp_path, "czyx.tif", axes="czyx"), data)
    with pytest.raises(VolumeError, match="disagrees with the file's own axes"):
        _load(tmp_path, "czyx.tif", axes="zcyx")


def test_unnamed_axes_are_refused_or_read_as_the_scene_says(tmp_path):
    import tifffile
    data = _cube_channels()
    tifffile.imwrite(tmp_path / "shaped.tif", data)       # no axes: tifffile's QQYX
    with pytest.raises(VolumeError, match=r"leaves 2 of its axes unnamed.*volume\.axes") as err:
        _load(tmp_path, "shaped.tif")
    assert "shaped.tif" in str(err.value)
    _assert_channels(_load(tmp_path, "shaped.tif", axes="czyx"), data)
    np.save(tmp_path / "v.npy", data)
    with pytest.raises(VolumeError, match=r"4D array .* give volume\.axes"):
        _load(tmp_path, "v.npy")
    _assert_channels(_load(tmp_path, "v.npy", axes="czyx"), data)
    with pytest.raises(VolumeError, match="32 channels; at most 4"):   # read as [z, y, x, c]
        _load(tmp_path, "v.npy", axes="zyxc")


def test_channel_refusals_name_the_problem(tmp_path):
    data = np.random.default_rng(0).uniform(size=(6, 4, 5, 6)).astype(np.float32)
    np.save(tmp_path / "six.npy", data)
    spec = {"path": str(tmp_path / "six.npy"), "axes": "czyx"}
    with pytest.raises(VolumeError, match="6 channels; at most 4"):
        load_scene_volume(parse_scene({"volume": spec}))
    v = load_scene_volume(parse_scene({"volume": spec, "channels": [{"index": 5}, {"index": 1}]}))
    np.testing.assert_allclose(v.channel(0), (data[5] - data[5].min()) / np.ptp(data[5]),
                               atol=1e-6)
    with pytest.raises(VolumeError, match=r"channels\[1\] shows the file's channel 6, but the "
                                          r"volume has 6 channels"):
        load_scene_volume(parse_scene({"volume": spec, "channels": [{}, {"index": 6}]}))
    with pytest.raises(SceneError, match="no channels to show"):
        parse_scene({"channels": []})
    with pytest.raises(SceneError, match="no channels to show"):
        parse_scene({"channels": [{"enabled": False}, {"enabled": False}]})
    with pytest.raises(SceneError, match="5 channels, at most 4"):
        parse_scene({"channels": [{}] * 5})
    with pytest.raises(SceneError, match=r"channels\[0\]\.window"):
        parse_scene({"channels": [{"value_range": [0, 1], "window": "bone"}]})
    with pytest.raises(SceneError, match="transfer_function: a scene with channels"):
        parse_scene({"channels": [{}], "transfer_function": {"colormap": "grey"}})
    with pytest.raises(SceneError, match=r"channels\[0\]\.transfer_function\.colormap"):
        parse_scene({"channels": [{"transfer_function": {"colormap": "nope"}}]})
    # a file of several channels and one transfer function for the scene: whose is it?
    np.save(tmp_path / "two.npy", data[:2])
    two = parse_scene({"volume": {**spec, "path": str(tmp_path / "two.npy")},
                       "transfer_function": {"colormap": "grey"}})
    with pytest.raises(SceneError, match="the volume has 2 channels; give each its own"):
        from radiance_probes.scene.channels import effective_channels
        effective_channels(two, load_scene_volume(two).channel_count)


def test_channel_windows_and_defaults(tmp_path):
    data = _cube_channels()
    np.save(tmp_path / "v.npy", data)
    scene = parse_scene({"volume": {"path": str(tmp_path / "v.npy"), "axes": "czyx"},
                         "channels": [{"value_range": [0, 1000]},
                                      {"window": {"level": 3000, "width": 2000}},
                                      {"name": "z", "enabled": False}]})
    v = load_scene_volume(scene)
    np.testing.assert_allclose(v.channel(0), np.clip(data[0] / 1000.0, 0, 1), atol=1e-6)
    np.testing.assert_allclose(v.channel(1), np.clip((data[1] - 2000.0) / 2000.0, 0, 1),
                               atol=1e-6)
    assert v.channel_ranges[1] == (2000.0, 4000.0)
    # defaults: a file's channels each in its own colour
    from radiance_probes.scene.channels import effective_channels
    plain = parse_scene({"volume": {"path": str(tmp_path / "v.npy"), "axes": "czyx"}})
    shown = effective_channels(plain, load_scene_volume(plain).channel_count)
    assert len(shown) == 3 and len({c.transfer_function.colors for c in shown}) == 3
    assert parse_scene(scene.to_dict()) == scene


def test_adaptive_layout_and_probe_view_see_every_channel_shown(ctx, tmp_path):
    """The adaptive layout's extinction indicator is the channels' summed sigma_t, and the
    viewer's probe selection counts a probe visible where any channel shown is."""
    from radiance_probes.rendering.probes.planes import extinction_field
    from radiance_probes.viewer.probe_view import visible_cells as probe_cells
    data = _blobs(shape=(10, 12, 14))
    scene = parse_scene(_scene_file(tmp_path, data, THREE, **{
        **SMALL, "probes": {"grid": 4, "samples": 8, "layout": "adaptive"}}))
    r = Renderer(ctx, scene)
    try:
        res = r.resources
        field = extinction_field(res.volume.data, res.tables, DENSITY_SCALE)
        parts = [extinction_field(res.volume.channel(c), t, DENSITY_SCALE)
                 for c, t in enumerate(res.tables.tables)]
        np.testing.assert_allclose(field, sum(parts), rtol=1e-6)
        assert r.render("probes", spp=1).image.max() > 0
        every = probe_cells((4, 4, 4), None, res.volume, res.tables, DENSITY_SCALE)
        first = probe_cells((4, 4, 4), None, res.volume,
                            ChannelTables(res.tables.tables, (True, False, False)), DENSITY_SCALE)
        assert every.sum() > first.sum() > 0 and np.all(every >= first)
    finally:
        r.release()


def test_colour_bar_and_transfer_function_options_refuse_channels(tmp_path, capsys):
    from radiance_probes.cli.main import main
    np.save(tmp_path / "v.npy", _blobs(shape=(6, 6, 6)))
    scene = {"volume": {"path": str(tmp_path / "v.npy"), "axes": "czyx"},
             "camera": {"width": 8, "height": 8}}
    (tmp_path / "s.json").write_text(__import__("json").dumps(scene))
    code = main(["render", str(tmp_path / "s.json"), "--colorbar", "--out",
                 str(tmp_path / "o.png"), "--spp", "1"])
    assert code != 0 and "--colorbar: a colour bar shows one transfer function; this volume "\
                         "has 3 channels" in capsys.readouterr().err


def test_channels_known_answer_script_quick(tmp_path):
    """lab/experiments/channels_known_answer.py --quick: the GPU record's code at llvmpipe's size (the
    known answer itself is checked above)."""
    import importlib.util
    import json
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("channels_known_answer",
                                                  ROOT / "lab" / "experiments" / "channels_known_answer.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main([str(tmp_path), "--quick"]) == 0
    rec = json.loads((tmp_path / "results.json").read_text())
    for q in "0123":
        assert np.all(np.abs(rec["known_answer"][q]["raymarch"]) < 0.03), q
    assert [row["channels"] for row in rec["cost"]] == [1, 2, 3, 4]
    means = [row["image_mean"] for row in rec["cost"]]       # the same medium split in channels
    assert max(means) - min(means) < 0.1 * max(means)


def test_volume_from_an_array_in_memory():
    """The Python API's way in: a NumPy array with its axes named, channels and time steps as
    from a file, refused where the axes do not fit."""
    from radiance_probes.io.load import volume_from_array
    data = _blobs(shape=(6, 7, 8))
    v = volume_from_array(data, axes="czyx")
    assert v.channel_count == 3 and v.dims == (8, 7, 6)
    np.testing.assert_allclose(v.channel(1), data[1] / data[1].max(), atol=1e-6)
    shown = (ChannelSpec(transfer_function=TransferFunctionSpec(), index=2),)
    one = volume_from_array(data, axes="czyx", channels=shown, value_range=(0, 2))
    assert one.channel_count == 1 and one.value_range == (0.0, 2.0)
    series = volume_from_array(np.stack([data[0], data[1]]), axes="tzyx", time=1)
    assert (series.time, series.time_steps) == (1, 2)
    with pytest.raises(VolumeError, match="names 3 axes but the array has 4"):
        volume_from_array(data, axes="zyx")
    with pytest.raises(VolumeError, match="no time axis"):
        volume_from_array(data[0], time=1)
