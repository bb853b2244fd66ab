"""The crop box and the clip plane (SPEC.md, Crop and clip; app/scene/clip_region.py,
glsl/lib/clip_region.glsl): the scene keys, the GLSL test against its NumPy twin, the majorant
grid and the visible region with a crop, the light grid fitted to the kept box, and the known
answer: a crop renders as the cropped volume does, with every method.

The known answer's convention (docs/crop-and-movies.md): the cropped volume is its own scene,
centred at the origin with its longest side 1 (SPEC.md). A crop that keeps the volume's longest
side whole keeps the scale, so the cropped volume's world is the crop's moved by the kept box's
centre; its camera is moved by the same. The crop is on voxel boundaries and the density inside
it is clamped to the kept voxels (as the cropped volume is clamped to its own edge voxels), so
the two are the same medium at the same place, and their images differ by noise alone."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from radiance_probes.scene.clip_region import clip_region
from radiance_probes.gl.textures import TransferTable, volume_texture
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.io.scene_file import SceneError, parse_scene, scene_to_dict
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.twins.majorant_grid import density_range_grid, macrocell_counts, majorant_grid
from radiance_probes.twins.medium import box_intersect, density_at, sigma_t_at
from radiance_probes.twins.visible_region import visible_region
from radiance_probes.io.volume import Volume
from glsl_harness import run_kernel

# ---- scene keys ------------------------------------------------------------------------------


def test_crop_and_clip_keys_round_trip():
    data = {"crop": {"min": [2, 0, 1], "max": [10, 16, 9], "units": "voxels"},
            "clip_plane": {"normal": [1, 1, 0], "distance": 0.1, "enabled": False}}
    s = parse_scene(data)
    assert s.crop.units == "voxels" and s.crop.min == (2, 0, 1) and s.crop.enabled
    assert s.clip_plane.normal == (1.0, 1.0, 0.0) and not s.clip_plane.enabled
    assert parse_scene(scene_to_dict(s)) == s
    # a scene without them writes neither key (older scenes stay as they were)
    assert "crop" not in scene_to_dict(parse_scene({}))


@pytest.mark.parametrize("data, message", [
    ({"crop": {"min": [0, 0, 0]}}, "crop.max: missing"),
    ({"crop": {"min": [0, 0, 0], "max": [0.5, 0.5, 0.0]}}, r"crop.max\[2\]: must be > crop.min\[2\]"),
    ({"crop": {"min": [0, 0, 0], "max": [1, 1, 1], "units": "inches"}}, "crop.units: expected one of"),
    ({"crop": {"min": [0, 0, 0.5], "max": [4, 4, 4], "units": "voxels"}}, r"crop.min\[2\]: expected an integer"),
    ({"crop": {"min": [0, 0, 0], "max": [1, 1, 1], "size": 3}}, "unknown field crop.size"),
    ({"crop": {"min": [0, 0, 0], "max": [1, 1, 1], "enabled": "yes"}}, "crop.enabled: expected true or false"),
    ({"clip_plane": {"distance": 0.2}}, "clip_plane.normal: missing"),
    ({"clip_plane": {"normal": [0, 0, 0]}}, "clip_plane.normal: must not be the zero vector"),
    ({"clip_plane": {"normal": [1, 0, 0], "distance": "far"}}, "clip_plane.distance: expected a number"),
])
def test_bad_crop_or_clip_names_the_field(data, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(data)


def test_voxel_crop_beyond_the_volume_names_the_field():
    s = parse_scene({"crop": {"min": [0, 0, 0], "max": [8, 9, 4], "units": "voxels"}})
    with pytest.raises(SceneError, match=r"crop.max\[1\]: 9 is beyond the volume's 8 voxels along y"):
        clip_region(s, (8, 8, 8), (0.5, 0.5, 0.5))


def test_voxel_crop_lies_on_voxel_boundaries():
    s = parse_scene({"crop": {"min": [2, 0, 1], "max": [6, 8, 4], "units": "voxels"}})
    he = np.array([0.5, 0.5, 0.25])
    region = clip_region(s, (8, 8, 4), he)
    # voxel boundary i of n sits at (i / n * 2 - 1) * half_extent
    np.testing.assert_allclose(region.box_min, [-0.25, -0.5, -0.125])
    np.testing.assert_allclose(region.box_max, [0.25, 0.5, 0.25])
    assert region.voxel_first == (2, 0, 1) and region.voxel_count == (4, 8, 3)
    # the density is clamped to the centres of the outermost kept voxels, on cut sides only
    np.testing.assert_allclose(region.sample_min[0], -0.1875)
    assert region.sample_min[1] < -1e29 and region.sample_max[1] > 1e29   # y is not cut
    assert region.sample_max[2] > 1e29                                     # z's top is not cut
    # the same crop in world units keeps the same voxels and box
    w = parse_scene({"crop": {"min": list(region.box_min), "max": list(region.box_max)}})
    assert clip_region(w, (8, 8, 4), he) == region


def test_world_crop_keeps_the_voxels_whose_centres_it_holds():
    s = parse_scene({"crop": {"min": [-0.3, -2, -2], "max": [0.07, 2, 2]}})
    region = clip_region(s, (8, 8, 8), (0.5, 0.5, 0.5))
    # centres at -0.4375 + k / 8: -0.3125 is out, -0.1875 .. 0.0625 in (voxels 2..4)
    assert region.voxel_first[0] == 2 and region.voxel_count[0] == 3
    assert region.box_min[0] == -0.3 and region.box_max[0] == 0.07
    assert region.box_min[1] == -0.5 and region.box_max[1] == 0.5   # within the volume box
    empty = clip_region(parse_scene({"crop": {"min": [0.01, -1, -1], "max": [0.05, 1, 1]}}),
                        (8, 8, 8), (0.5, 0.5, 0.5))
    assert empty.empty and not empty.kept(np.zeros((1, 3)))[0]


# ---- the GLSL test against its twin ------------------------------------------------------------

CLIP_KERNEL = """
#include "lib/medium.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 x = vec3(p[6u * i], p[6u * i + 1u], p[6u * i + 2u]);
    vec3 d = vec3(p[6u * i + 3u], p[6u * i + 4u], p[6u * i + 5u]);
    vec4 c = classified_at(x);
    float t0, t1;
    bool hit = box_intersect(x, d, t0, t1);
    o[6u * i] = kept_at(x) ? 1.0 : 0.0;
    o[6u * i + 1u] = density_at(x);
    o[6u * i + 2u] = sigma_t_at(x);
    o[6u * i + 3u] = c.a;
    o[6u * i + 4u] = hit ? t0 : -1.0;
    o[6u * i + 5u] = hit ? t1 : -1.0;
}
"""
DENSITY_SCALE = 23.0


def _random_volume(shape=(10, 16, 12), seed=1, spacing=(1.0, 1.0, 1.0)):
    data = np.random.default_rng(seed).uniform(size=shape).astype(np.float32)
    return Volume(data, spacing, "random", (0.0, 1.0), "float32", 0.0, 1.0)


CLIPS = {
    "voxel crop": {"crop": {"min": [3, 0, 2], "max": [10, 16, 10], "units": "voxels"}},
    "world crop": {"crop": {"min": [-0.21, -0.33, -0.5], "max": [0.27, 0.4, 0.1]}},
    "oblique plane": {"clip_plane": {"normal": [1, -2, 0.5], "distance": 0.05}},
    "crop and plane": {"crop": {"min": [1, 2, 0], "max": [11, 13, 7], "units": "voxels"},
                       "clip_plane": {"normal": [0, 1, 1], "distance": -0.1}},
}


@pytest.mark.parametrize("name", list(CLIPS))
def test_clip_region_glsl_matches_numpy(ctx, name):
    volume = _random_volume()
    table = np.random.default_rng(3).uniform(size=(9, 4)).astype(np.float32)
    region = clip_region(parse_scene(CLIPS[name]), volume.dims, volume.half_extent)
    he = volume.half_extent.astype(np.float64)
    r = np.random.default_rng(5)
    pts = (r.uniform(-1.1, 1.1, (6000, 3)) * he).astype(np.float32).astype(np.float64)
    dirs = r.normal(size=pts.shape)
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32).astype(np.float64)
    vt, tt = volume_texture(ctx, volume), TransferTable(ctx, table)
    try:
        vt.use(0)
        tt.use(1)
        uniforms = {"volume_density": 0, "transfer_function": 1, "transfer_size": len(table),
                    "density_scale": DENSITY_SCALE, "albedo": 0.9,
                    "box_half_extent": tuple(float(v) for v in volume.half_extent),
                    **region.uniforms()}
        rays = np.concatenate([pts, dirs], 1).astype(np.float32)
        out = run_kernel(ctx, CLIP_KERNEL, [rays.ravel()], (len(pts), 6), uniforms=uniforms,
                         count=len(pts))
    finally:
        vt.release()
        tt.release()
    kept = region.kept(pts)
    assert 0.1 < kept.mean() < 0.9     # both sides of the cut are tested
    # kept_at: exact but for points within rounding of a face
    lo, hi = np.asarray(region.box_min), np.asarray(region.box_max)
    n, d = np.asarray(region.plane[:3]), region.plane[3]
    margin = np.minimum(np.abs(pts - lo).min(1), np.abs(pts - hi).min(1))
    margin = np.minimum(margin, np.abs(pts @ n - d))
    clear = margin > 1e-5
    np.testing.assert_array_equal(out[clear, 0] > 0.5, kept[clear])
    # the density read at the clamped point; sigma_t (and the raymarcher's alpha) 0 where cut
    np.testing.assert_allclose(out[:, 1], density_at(volume, pts, region), atol=2e-5)
    want = sigma_t_at(volume, table, DENSITY_SCALE, pts, region)
    np.testing.assert_allclose(out[clear, 2], want[clear], rtol=1e-4, atol=2e-3)
    np.testing.assert_allclose(out[:, 2], DENSITY_SCALE * out[:, 3], rtol=1e-6)
    assert np.all(out[~kept & clear, 2] == 0.0) and np.all(out[kept & clear, 2] > 0.0)
    # rays are clipped to the kept box
    t0, t1, hit = box_intersect(he, pts, dirs, region)
    sure = np.abs(t1 - t0) > 1e-4
    np.testing.assert_array_equal(out[sure, 4] >= 0, hit[sure])
    both = sure & hit & (out[:, 4] >= 0)
    np.testing.assert_allclose(out[both, 4], t0[both], atol=1e-5)
    np.testing.assert_allclose(out[both, 5], t1[both], atol=1e-5)


def test_no_clip_region_changes_nothing(ctx):
    """clip_region_on unset (0) keeps every point and reads the density where it is."""
    volume = _random_volume()
    table = np.random.default_rng(3).uniform(size=(9, 4)).astype(np.float32)
    pts = (np.random.default_rng(7).uniform(-1, 1, (500, 3)) * volume.half_extent).astype(np.float32)
    rays = np.concatenate([pts, np.tile([0, 0, 1], (len(pts), 1))], 1).astype(np.float32)
    vt, tt = volume_texture(ctx, volume), TransferTable(ctx, table)
    try:
        vt.use(0)
        tt.use(1)
        out = run_kernel(ctx, CLIP_KERNEL, [rays.ravel()], (len(pts), 6), count=len(pts),
                         uniforms={"volume_density": 0, "transfer_function": 1,
                                   "transfer_size": len(table), "density_scale": DENSITY_SCALE,
                                   "box_half_extent": tuple(float(v) for v in volume.half_extent)})
    finally:
        vt.release()
        tt.release()
    assert np.all(out[:, 0] == 1.0)
    np.testing.assert_allclose(out[:, 1], density_at(volume, pts.astype(np.float64)), atol=2e-6)


# ---- empty-space skipping and the fitted grids ---------------------------------------------------

def _renderer(ctx, volume, data: dict) -> Renderer:
    base = {"transfer_function": {"colormap": "viridis",
                                  "opacity": [[0, 0], [0.35, 0], [0.6, 0.8], [1, 1]]},
            "density_scale": DENSITY_SCALE}
    return Renderer(ctx, parse_scene({**base, **data}), volume)


@pytest.mark.parametrize("name", list(CLIPS))
def test_majorant_grid_with_a_crop_bounds_sigma_t(ctx, name):
    volume = _random_volume(shape=(20, 33, 27), seed=4)
    r = _renderer(ctx, volume, CLIPS[name])
    try:
        res = r.resources
        gpu = res.majorant_grid.read()
        d_min, d_max = density_range_grid(volume.data, macrocell_counts(volume.dims))
        twin = majorant_grid(d_min, d_max, res.table, DENSITY_SCALE, res.clip, volume.half_extent)
        plain = majorant_grid(d_min, d_max, res.table, DENSITY_SCALE)
        assert (twin == 0).sum() > (plain == 0).sum()          # cells cut away are skipped
        # float32 on the GPU, float64 in the twin: where a crop face lies on a cell face the GPU
        # may take the neighbour's range in or leave it out; it lies between the two readings
        tight = majorant_grid(d_min, d_max, res.table, DENSITY_SCALE, res.clip,
                              volume.half_extent, rounding=-1e-5)
        loose = majorant_grid(d_min, d_max, res.table, DENSITY_SCALE, res.clip,
                              volume.half_extent, rounding=1e-5)
        assert np.all(gpu >= tight * (1 - 1e-6)) and np.all(gpu <= loose * (1 + 1e-6))
        assert np.isclose(gpu, twin, rtol=1e-6, atol=0).mean() > 0.8
        np.testing.assert_array_equal(gpu == 0, twin == 0)
        # every cell bounds sigma_t at points of it (the cut and the clamped density included)
        cells = np.array(gpu.shape[::-1])
        he = volume.half_extent.astype(np.float64)
        rng = np.random.default_rng(9)
        u = rng.uniform(size=(200000, 3))
        pts = (u * 2 - 1) * he
        idx = np.minimum((u * cells).astype(int), cells - 1)
        sigma = sigma_t_at(volume, res.table, DENSITY_SCALE, pts, res.clip)
        bound = gpu[idx[:, 2], idx[:, 1], idx[:, 0]]
        assert np.all(sigma <= bound * (1 + 1e-4) + 1e-6)
    finally:
        r.release()


def test_visible_region_with_a_crop_matches_numpy(ctx):
    volume = _random_volume(shape=(18, 24, 20), seed=6)
    for name in CLIPS:
        r = _renderer(ctx, volume, CLIPS[name])
        try:
            res = r.resources
            low, high = r.visible_region()
            want = visible_region(volume.data, volume.half_extent, res.table[:, 3], DENSITY_SCALE,
                                  res.clip)
            np.testing.assert_allclose(low, want[0], atol=1e-6, err_msg=name)
            np.testing.assert_allclose(high, want[1], atol=1e-6, err_msg=name)
            # inside the kept box
            assert np.all(low >= np.asarray(res.clip.box_min) - 1e-6)
            assert np.all(high <= np.asarray(res.clip.box_max) + 1e-6)
        finally:
            r.release()


# ---- the known answer: a crop renders as the cropped volume --------------------------------------

SHAPE = (10, 16, 12)                       # z, y, x: y (16) the longest side, kept whole
CROP = ((3, 0, 2), (10, 16, 10))           # x 3..9, y all, z 2..9 (voxels, max exclusive)
SIZE = 36
SCENE = {"transfer_function": {"colormap": "plasma",
                               "opacity": [[0, 0], [0.3, 0], [0.55, 0.7], [1, 1]]},
         "density_scale": 40.0, "albedo": 0.95,
         "light": {"direction": [-0.6, 0.7, 0.35], "irradiance": [3, 3, 3]},
         "environment": [0.15, 0.15, 0.2],
         # from the cut's side (-x, +z): the cut faces are what the camera sees
         "camera": {"eye": [-1.5, 0.5, 1.3], "target": [0.0, 0.0, 0.0], "fov_y": 38.0,
                    "width": SIZE, "height": SIZE},
         "probes": {"grid": 4, "samples": 64}}


def _crop_volume() -> Volume:
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in SHAPE), indexing="ij")
    rng = np.random.default_rng(11)
    blob = 1.15 - 0.9 * (x ** 2 + y ** 2 + z ** 2) + 0.35 * rng.uniform(size=SHAPE)
    return Volume(np.clip(blob, 0, 1).astype(np.float32), (1.0, 1.0, 1.0), "blob",
                  (0.0, 1.0), "float32", 0.0, 1.0)


def _cropped(volume: Volume, lo, hi) -> Volume:
    data = volume.data[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]].copy()
    return dataclasses.replace(volume, data=data, name="cropped")


def _moved(scene: dict, offset) -> dict:
    cam = dict(scene["camera"])
    cam["eye"] = list(np.asarray(cam["eye"], float) - offset)
    cam["target"] = list(np.asarray(cam["target"], float) - offset)
    return {**scene, "camera": cam}


RENDERS = {  # method, raymarch stage, samples
    "pt": ("pt", "compute", 48),
    "probes": ("probes", "compute", 24),
    "probes-only": ("probes-only", "compute", 24),
    "raymarch": ("raymarch", "compute", 16),
    "raymarch fragment": ("raymarch", "fragment", 16),
}


def _render(ctx, volume, scene: dict, method, stage, spp, seed) -> tuple[np.ndarray, Renderer]:
    r = Renderer(ctx, parse_scene(scene), volume, RenderSettings(raymarch_stage=stage))
    return r.render(method, spp=spp, seed=seed).image, r


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


@pytest.fixture(scope="module")
def crop_case():
    volume = _crop_volume()
    crop_scene = {**SCENE, "crop": {"min": list(CROP[0]), "max": list(CROP[1]), "units": "voxels"}}
    region = clip_region(parse_scene(crop_scene), volume.dims, volume.half_extent)
    cropped = _cropped(volume, *CROP)
    # the longest side is kept, so the scale is the same and the cropped world is the crop's moved
    np.testing.assert_allclose(cropped.half_extent, region.half_extent, rtol=1e-6)
    return volume, crop_scene, cropped, _moved(SCENE, region.centre), region.centre


@pytest.mark.parametrize("name", list(RENDERS))
def test_a_crop_renders_as_the_cropped_volume(ctx, crop_case, name):
    volume, crop_scene, cropped, cropped_scene, offset = crop_case
    method, stage, spp = RENDERS[name]
    a, ra = _render(ctx, volume, crop_scene, method, stage, spp, seed=1)
    b, rb = _render(ctx, cropped, cropped_scene, method, stage, spp, seed=2)
    c, rc = _render(ctx, cropped, cropped_scene, method, stage, spp, seed=3)
    try:
        if method != "pt":
            # the probe grid and the light grid fit the kept box: the cropped volume's, moved
            pa, pb = ra.probe_plan(), rb.probe_plan()
            assert pa.grid == pb.grid
            np.testing.assert_allclose(np.asarray(pa.box) - offset, pb.box, atol=1e-6)
            la, lb = ra._light.layout, rb._light.layout
            assert la.size == lb.size
            np.testing.assert_allclose(la.box_half_extent, lb.box_half_extent, rtol=1e-6)
            np.testing.assert_allclose(np.asarray(la.centre) - offset, lb.centre, atol=1e-6)
            np.testing.assert_allclose(ra._light.read(), rb._light.read(), rtol=2e-3, atol=2e-3)
    finally:
        for r in (ra, rb, rc):
            r.release()
    assert np.mean(b) > 0.02                     # the medium is there and lit
    noise = _rms(b, c)                           # two independent renders of the cropped volume
    diff = _rms(a, b)
    assert diff <= 1.3 * noise + 1e-4 * np.sqrt(np.mean(b ** 2)), (diff, noise)


def test_the_known_answer_sees_a_crop_one_voxel_off(ctx, crop_case):
    """The comparison above could fail: the cropped volume one voxel further along x (its camera
    moved to match its box) differs from the crop by far more than noise."""
    volume, crop_scene, _, _, _ = crop_case
    lo, hi = (CROP[0][0] + 1, *CROP[0][1:]), (CROP[1][0] + 1, *CROP[1][1:])
    shifted = _cropped(volume, lo, hi)
    region = clip_region(parse_scene({"crop": {"min": list(lo), "max": list(hi), "units": "voxels"}}),
                         volume.dims, volume.half_extent)
    scene = _moved(SCENE, region.centre)
    a, ra = _render(ctx, volume, crop_scene, "pt", "compute", 48, seed=1)
    b, rb = _render(ctx, shifted, scene, "pt", "compute", 48, seed=2)
    c, rc = _render(ctx, shifted, scene, "pt", "compute", 48, seed=3)
    for r in (ra, rb, rc):
        r.release()
    assert _rms(a, b) > 2.0 * _rms(b, c)


def test_clipped_matter_neither_scatters_nor_shadows(ctx):
    """A clip plane at a voxel boundary where the slabs on both sides hold the same values (so the
    cut reads no other voxel than the crop's clamp does) renders as the crop keeping that side."""
    volume = _crop_volume()
    data = volume.data.copy()
    data[:, :, 2] = data[:, :, 3]     # the slab cut away at the boundary equals the one kept
    volume = dataclasses.replace(volume, data=data)
    boundary = (3 / volume.dims[0] * 2 - 1) * float(volume.half_extent[0])
    plane = {**SCENE, "clip_plane": {"normal": [-2, 0, 0], "distance": -2 * boundary}}
    crop = {**SCENE, "crop": {"min": [3, 0, 0], "max": [12, 16, 10], "units": "voxels"}}
    a, ra = _render(ctx, volume, plane, "pt", "compute", 48, seed=1)
    b, rb = _render(ctx, volume, crop, "pt", "compute", 48, seed=2)
    c, rc = _render(ctx, volume, crop, "pt", "compute", 48, seed=3)
    full, rf = _render(ctx, volume, SCENE, "pt", "compute", 48, seed=4)
    for r in (ra, rb, rc, rf):
        r.release()
    assert _rms(a, b) <= 1.3 * _rms(b, c) + 1e-4
    assert _rms(full, b) > 2.0 * _rms(b, c)   # and the cut is not nothing


@pytest.mark.parametrize("args, message", [
    (["--crop", "0", "0", "0", "0", "1", "1"], r"--crop: crop.max\[0\]: must be > crop.min\[0\]"),
    (["--crop", "nan", "0", "0", "1", "1", "1"], r"--crop: crop.min\[0\]: must be finite"),
    (["--crop-voxels", "0", "0", "0", "65", "64", "64"],
     r"--crop-voxels: crop.max\[0\]: 65 is beyond the volume's 64 voxels along x"),
    (["--crop", "0.2", "-1", "-1", "0.21", "1", "1"], "--crop: crop: keeps no voxel of the volume"),
    (["--crop", "0", "0", "0", "1", "1", "1", "--crop-voxels", "0", "0", "0", "1", "1", "1"],
     "give one of them"),
    (["--clip-plane", "0", "0", "0", "1"], "--clip-plane: clip_plane.normal: must not be the zero"),
])
def test_crop_and_clip_options_refused_with_the_option_named(tmp_path, capsys, args, message):
    import re
    from radiance_probes.cli.main import main
    rc = main(["render", "--spp", "1", "--width", "8", "--height", "8",
               "--out", str(tmp_path / "x.png"), *args])
    err = capsys.readouterr().err
    assert rc == 2 and re.search(message, err), err
    assert err.count("\n") == 1                      # one line


@pytest.mark.parametrize("method", ["pt", "raymarch"])
def test_a_crop_set_after_the_first_image_is_honoured(ctx, crop_case, method):
    """A scene without crop or clip compiles the tests out (NO_CLIP_REGION); a crop set later (the
    viewer's edit) rebuilds every pass, so the image equals a renderer's that had the crop from
    the start, bit for bit, and the denoiser's guides see the crop too."""
    volume, crop_scene, *_ = crop_case
    fresh = Renderer(ctx, parse_scene(crop_scene), volume)
    edited = Renderer(ctx, parse_scene(SCENE), volume)
    try:
        whole = edited.render(method, spp=4, seed=5).image
        albedo_whole = edited.denoise_guides("albedo")[0]
        assert "NO_CLIP_REGION" in edited.resources.medium_defines()
        edited.set_scene(parse_scene(crop_scene))
        assert "NO_CLIP_REGION" not in edited.resources.medium_defines()
        got = edited.render(method, spp=4, seed=5).image
        want = fresh.render(method, spp=4, seed=5).image
        assert not np.array_equal(got, whole)
        np.testing.assert_array_equal(got, want)
        albedo_got, albedo_want = edited.denoise_guides("albedo")[0], fresh.denoise_guides("albedo")[0]
        assert not np.array_equal(albedo_got, albedo_whole)
        np.testing.assert_array_equal(albedo_got, albedo_want)
    finally:
        fresh.release()
        edited.release()
