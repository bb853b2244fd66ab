"""Probe layout that follows the scene (app/rendering/probes/layout.py): the visible region bounds
every point where sigma_t > 0, a cubic request follows the region's aspect, SH order 0 gives the
same images as order 2 when g = 0 (the phase convolution zeroes bands 1 and 2), and a fitted grid
renders as well as the box grid."""
import dataclasses

import numpy as np
import pytest

from radiance_probes.twins.medium import sigma_t_at
from radiance_probes.rendering.probes.layout import (AUTO_BAND_WEIGHT, AUTO_MAX_ORDER,
                                                     AUTO_WALKS_PER_HIGH_BAND,
                                                     GREY_TEXTURES_FOR_ORDER, TEXTURES_FOR_ORDER,
                                                     colour_channel, fitted_grid, resolve_sh_order,
                                                     unpack_coefficients, visible_region)
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import SceneError, parse_scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.io.scene_file import TransferFunctionSpec
from radiance_probes.io.volume import Volume


def _volume(data: np.ndarray, spacing=(1.0, 1.0, 1.0)) -> Volume:
    return Volume(data.astype(np.float32), spacing, "test", (0.0, 1.0), "float32", 0.0, 1.0)


def _table(opacity) -> np.ndarray:
    return transfer_table(TransferFunctionSpec(colormap="grey", opacity=tuple(map(tuple, opacity))))


@pytest.mark.parametrize("opacity", [
    [[0, 0], [0.3, 0], [1, 1]],                       # a threshold
    [[0, 0], [0.45, 0], [0.5, 1], [0.55, 0], [1, 0]],  # a narrow spike between two voxel values
    [[0, 1], [0.1, 0], [1, 0]],                       # only the lowest densities are visible
])
def test_sigma_t_is_zero_outside_the_visible_region(opacity):
    rng = np.random.default_rng(3)
    data = np.zeros((12, 10, 14))
    data[3:6, 2:5, 8:12] = rng.uniform(0.2, 1.0, (3, 3, 4))
    data[7, 6, 2] = 1.0   # one bright voxel: between it and its 0 neighbours every value occurs
    vol = _volume(data, spacing=(1.0, 2.0, 0.5))
    table = _table(opacity)
    low, high = visible_region(vol.data, vol.half_extent, table[:, 3], 10.0)
    half = vol.half_extent.astype(np.float64)
    assert np.all(low >= -half - 1e-9) and np.all(high <= half + 1e-9) and np.all(low <= high)
    points = rng.uniform(-half, half, (200_000, 3))
    outside = np.any((points < low - 1e-6) | (points > high + 1e-6), axis=1)
    assert np.all(sigma_t_at(vol, table, 10.0, points[outside]) == 0.0)
    if opacity[0][1] == 0:   # the region is tight: most of the box is left out
        assert outside.sum() > 1000 and np.prod(high - low) < 0.8 * np.prod(2 * half)
    else:                    # empty space itself is visible: the whole box
        np.testing.assert_allclose(high - low, 2 * half)
    assert np.any(sigma_t_at(vol, table, 10.0, points[~outside]) > 0.0)


def test_nothing_visible_gives_the_whole_box():
    vol = _volume(np.zeros((4, 4, 4)))
    low, high = visible_region(vol.data, vol.half_extent, _table([[0, 0], [0.5, 0], [1, 1]])[:, 3], 5.0)
    np.testing.assert_allclose(high, vol.half_extent)
    np.testing.assert_allclose(low, -vol.half_extent)


def test_fitted_grid_follows_the_region_aspect():
    assert fitted_grid((16, 16, 16), np.array([0, 0, 0]), np.array([1.0, 0.25, 0.5])) == (16, 4, 8)
    assert fitted_grid((16, 16, 16), np.array([0, 0, 0]), np.array([1.0, 0.001, 1.0])) == (16, 1, 16)
    assert fitted_grid((4, 8, 2), np.array([0, 0, 0]), np.array([1.0, 0.2, 1.0])) == (4, 8, 2)


def test_sh_order_choice_and_validation():
    assert resolve_sh_order("auto", 0.0) == 0 and resolve_sh_order("auto", 0.3) == 2
    # "auto" keeps the bands the phase function keeps: |g|^l >= AUTO_BAND_WEIGHT, at least 2
    for g in (0.1, 0.5, 0.6, 0.8, -0.8, 0.99):
        order = resolve_sh_order("auto", g)
        assert 2 <= order <= AUTO_MAX_ORDER
        assert order == AUTO_MAX_ORDER or abs(g) ** (order + 1) < AUTO_BAND_WEIGHT
        assert order == 2 or abs(g) ** order >= AUTO_BAND_WEIGHT
    assert resolve_sh_order("auto", 0.8) == 3 and resolve_sh_order("auto", 0.5) == 2
    # higher bands only for probes with the walks to resolve them
    assert resolve_sh_order("auto", 0.8, AUTO_WALKS_PER_HIGH_BAND) == 3
    assert resolve_sh_order("auto", 0.8, AUTO_WALKS_PER_HIGH_BAND - 1) == 2
    assert resolve_sh_order("auto", 0.0, 4096) == 0 and resolve_sh_order(4, 0.8, 16) == 4
    assert resolve_sh_order(1, 0.0) == 1
    assert [len(TEXTURES_FOR_ORDER[o]) for o in range(5)] == [2, 4, 7, 13, 19]
    assert [len(GREY_TEXTURES_FOR_ORDER[o]) for o in range(5)] == [1, 2, 3, 5, 7]
    parse_scene({"probes": {"sh_order": 4}})
    for bad in (5, -1, 2.5, True, "3"):
        with pytest.raises(SceneError, match="probes.sh_order"):
            parse_scene({"probes": {"sh_order": bad}})
    with pytest.raises(SceneError, match="probes.fit"):
        parse_scene({"probes": {"fit": "tight"}})


BASE = {"volume": {"builtin": "cloud", "size": [24, 24, 24]}, "density_scale": 60.0,
        "camera": {"eye": [0, 0.3, 2.2], "width": 20, "height": 20},
        "probes": {"grid": 4, "samples": 64}}


@pytest.mark.parametrize("method", ["probes", "probes-only", "raymarch"])
def test_order_zero_renders_what_orders_two_and_four_render_when_g_is_zero(ctx, method):
    images, nbytes = {}, {}
    for order in (0, 2, 4):
        scene = parse_scene({**BASE, "probes": {**BASE["probes"], "sh_order": order}})
        r = Renderer(ctx, scene)
        try:
            images[order] = r.render(method, spp=4, seed=3).image
            nbytes[order] = r.probe_grid.gpu_bytes
        finally:
            r.release()
    assert nbytes[0] * 7 == nbytes[2] * 2 and nbytes[0] * 19 == nbytes[4] * 2
    np.testing.assert_allclose(images[0], images[2], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(images[0], images[4], rtol=1e-5, atol=1e-7)


def test_packing_channels_are_distinct_and_dense():
    """The colour packing (lib/probe_packing.glsl) puts every coefficient and colour of order 4 in
    its own channel, keeps orders 0 to 2 where the seven textures had them, and the sun at 27."""
    channels = [colour_channel(k, c) for k in range(25) for c in range(3)]
    assert sorted(channels + [27]) == list(range(76))
    assert [colour_channel(k, c) for k in range(9) for c in range(3)] == list(range(27))
    packed = np.arange(76.0)
    coeffs, sun = unpack_coefficients(packed, 4)
    assert coeffs.shape == (25, 3) and sun == 27 and coeffs[9, 0] == 28 and coeffs[24, 2] == 75


@pytest.mark.parametrize("grey", [False, True])
@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
def test_textures_hold_the_running_means_in_their_packing(ctx, order, grey):
    """What the bake publishes (probe_project.comp, and probe_publish.comp past eight textures)
    read back texel by texel: each texture's channels are the running means' channels that
    lib/probe_packing.glsl names for it, divided by the radiance scale (the sun's as it is)."""
    tf = {"colormap": "grey"} if grey else {"colormap": "plasma"}
    scene = parse_scene({**BASE, "transfer_function": tf, "anisotropy": 0.5,
                         "probes": {"grid": [3, 2, 4], "samples": 64, "sh_order": order,
                                    "channels": 1 if grey else 3, "fit": "box"}})
    r = Renderer(ctx, scene)
    try:
        r.bake(seed=4)
        grid = r.probe_grid
        assert grid.grey == grey
        means = grid.coefficients().reshape(grid.count, -1)
        coeffs, sun = unpack_coefficients(means, max(order, 2))
        kept = (order + 1) ** 2
        expected = {}   # texture number -> (count, 4) expected texels
        for number in grid.texture_ids:
            texel = np.zeros((grid.count, 4))
            for component in range(4):
                f = 4 * number + component
                if grey:
                    k = f if f < 3 else f - 1
                    value = sun if f == 3 else (coeffs[:, k, 0] / grid.radiance_scale
                                                if k < kept else 0.0)
                else:
                    value = means[:, f] if f == 27 else means[:, f] / grid.radiance_scale
                texel[:, component] = value
            expected[number] = texel
        assert len(grid.textures) == len((GREY_TEXTURES_FOR_ORDER if grey else TEXTURES_FOR_ORDER)[order])
        for number, tex in zip(grid.texture_ids, grid.textures):
            got = np.frombuffer(tex.read(), np.float32).reshape(grid.count, 4)
            np.testing.assert_allclose(got, expected[number], rtol=1e-6, atol=1e-7,
                                       err_msg=f"texture {number}")
        assert np.abs(coeffs[:, 9:] if order >= 3 else coeffs[:, 4:9]).max() > 0   # bands baked
    finally:
        r.release()


def test_fitted_grid_bakes_inside_the_visible_region(ctx):
    scene = parse_scene(BASE)
    r = Renderer(ctx, scene)
    try:
        r.bake()
        low, high = r.visible_region()
        grid = r.probe_grid
        assert grid.box is not None and grid.grid == fitted_grid((4, 4, 4), low, high)
        plan = r.probe_plan()   # a frozen dataclass, equal to what was baked
        assert (plan.grid, plan.box, plan.sh_order, plan.grey) == (grid.grid, grid.box,
                                                                   grid.sh_order, grid.grey)
        # the layout's defines; the grid's add the medium's (a reader gets those from the scene)
        assert {**plan.defines(), **grid.medium} == grid.defines() and plan == r.probe_plan()
        with pytest.raises(dataclasses.FrozenInstanceError):
            plan.grid = (1, 1, 1)
        assert grid.grid != (4, 4, 4)   # the cloud is flatter than its box
        np.testing.assert_allclose(grid.box[0], low)
        # the camera never re-bakes; a transfer-function change that moves the region does
        r.set_scene(scene.replace(camera=scene.camera.__class__(eye=(0.3, 0.3, 2.0), width=20,
                                                                height=20)))
        assert r.probes_current()
        r.set_scene(scene.replace(probes=scene.probes.__class__(grid=(4, 4, 4), samples=64,
                                                                fit="box")))
        assert not r.probes_current()
        r.bake()
        assert r.probe_grid.box is None and r.probe_grid.grid == (4, 4, 4)
    finally:
        r.release()


def test_grey_scenes_are_detected():
    from radiance_probes.rendering.probes.layout import scene_is_grey
    grey = _table([[0, 0], [1, 1]])
    assert scene_is_grey(grey, (3, 3, 3), (0.1, 0.1, 0.1))
    assert not scene_is_grey(grey, (3, 3, 2.9), (0.1, 0.1, 0.1))
    assert not scene_is_grey(grey, (3, 3, 3), (0.1, 0.1, 0.12))
    colour = transfer_table(TransferFunctionSpec(colormap="plasma"))
    assert not scene_is_grey(colour, (3, 3, 3), (0.1, 0.1, 0.1))
    with pytest.raises(SceneError, match="probes.channels"):
        parse_scene({"probes": {"channels": 2}})


GREY = {**BASE, "transfer_function": {"colormap": "grey"}, "anisotropy": 0.6}


@pytest.mark.parametrize("method", ["probes", "probes-only", "raymarch"])
@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
def test_one_channel_renders_what_three_render_in_a_grey_scene(ctx, method, order):
    images, textures = {}, {}
    for channels in (1, 3):
        scene = parse_scene({**GREY, "probes": {**GREY["probes"], "sh_order": order,
                                                "channels": channels}})
        r = Renderer(ctx, scene)
        try:
            images[channels] = r.render(method, spp=2, seed=3).image
            textures[channels] = len(r.probe_grid.textures)
            assert r.probe_grid.grey == (channels == 1)
        finally:
            r.release()
    assert textures[1] == (1, 2, 3, 5, 7)[order] and textures[3] == (2, 4, 7, 13, 19)[order]
    assert images[3].max() > 0
    np.testing.assert_allclose(images[1], images[3], rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("case", range(6))
def test_the_gpu_visible_region_is_its_twin(ctx, case):
    """glsl/visible_region.comp against app/twins/visible_region.py: random float volumes and
    8-bit volumes (densities on the table's nodes, where the segment logic matters), thresholds,
    spikes and tables that are transparent on nodes but not between them; nothing visible."""
    rng = np.random.default_rng(case)
    shape = tuple(int(v) for v in rng.integers(5, 19, 3))
    data = np.zeros(shape)
    z, y, x = (rng.integers(0, s, 2) for s in shape)
    block = (slice(z.min(), z.max() + 1), slice(y.min(), y.max() + 1), slice(x.min(), x.max() + 1))
    if case % 2:
        data[block] = rng.integers(0, 256, data[block].shape) / 255.0       # 8-bit, on the nodes
    else:
        data[block] = rng.uniform(0.0, 1.0, data[block].shape)
    opacity = [[[0, 0], [0.3, 0], [1, 1]],
               [[0, 0], [0.49, 0], [0.5, 1], [0.51, 0], [1, 0]],
               [[0, 0], [100 / 255, 0], [101 / 255, 0.7], [102 / 255, 0], [1, 0]],
               [[0, 1], [0.1, 0], [1, 0]],
               [[0, 0], [1, 0]],
               [[0, 0], [0.9, 0], [0.95, 0.5], [1, 0]]][case]
    scene = parse_scene({**BASE, "density_scale": 7.0})
    vol = _volume(data, spacing=(1.0, 1.5, 0.75))
    r = Renderer(ctx, scene, vol)
    try:
        r.set_scene(scene.replace(transfer_function=TransferFunctionSpec(
            colormap="grey", opacity=tuple(map(tuple, opacity)))))
        table_alpha = r.resources.table[:, 3]
        want = visible_region(r.resources.volume.data, r.resources.volume.half_extent, table_alpha, 7.0)
        got = r.visible_region()
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        if case == 4:
            np.testing.assert_array_equal(got[1], r.resources.volume.half_extent)
    finally:
        r.release()


@pytest.mark.parametrize("grey", [False, True])
@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
def test_probe_fetch_unpacks_every_coefficient(ctx, order, grey):
    """lib/probes.glsl probe_fetch at the probes' texel centres against the NumPy unpacking of
    random textures in the packing of lib/probe_packing.glsl: every coefficient up to the order
    (times the radiance scale), zeros above it, and the sun's transmittance."""
    from glsl_harness import PROBE_FETCH_KERNEL, probe_texel_centres, probe_textures, run_kernel
    from radiance_probes.rendering.probes.bake import probe_unit
    grid = (3, 2, 4)
    count = grid[0] * grid[1] * grid[2]
    ids = (GREY_TEXTURES_FOR_ORDER if grey else TEXTURES_FOR_ORDER)[order]
    rng = np.random.default_rng(order + 10 * grey)
    texels = {t: rng.uniform(0.05, 1.0, (count, 4)).astype(np.float32) for t in ids}
    textures = probe_textures(ctx, grid, texels)
    x = probe_texel_centres(grid).astype(np.float32)
    sh_count = (max(order, 2) + 1) ** 2
    try:
        out = run_kernel(ctx, PROBE_FETCH_KERNEL, [x.ravel()], (count, 3 * sh_count + 1),
                         defines={"PROBE_SH_ORDER": order, "PROBE_GREY": int(grey)},
                         uniforms={"probe_textures": tuple(probe_unit(t) for t in ids),
                                   "probe_grid": grid, "probe_box_min": (-1.0, -1.0, -1.0),
                                   "probe_box_size": (2.0, 2.0, 2.0),
                                   "probe_radiance_scale": 3.0})
    finally:
        for tex in textures:
            tex.release()
    channel = {4 * t + c: texels[t][:, c] for t in ids for c in range(4)}
    coeffs = out[:, :-1].reshape(count, sh_count, 3)
    kept = (order + 1) ** 2
    for k in range(sh_count):
        for c in range(3):
            f = (k if k < 3 else k + 1) if grey else colour_channel(k, c)
            expected = 3.0 * channel[f] if k < kept else np.zeros(count)
            np.testing.assert_allclose(coeffs[:, k, c], expected, rtol=1e-6, err_msg=f"k={k} c={c}")
    np.testing.assert_allclose(out[:, -1], channel[3 if grey else 27], rtol=1e-6)


def test_auto_precision_is_16_bit_only_where_surfaces_read_the_probes(ctx):
    """probes.precision "auto" (the default): rgba16f where surfaces need the probes' directions
    (k > 0: seven textures a sample instead of two, halved in size), rgba32f otherwise, so that
    k = 0 bakes exactly what it did; an explicit precision is kept either way; an unknown one is
    refused by name."""
    from radiance_probes.rendering.probes.layout import resolve_precision
    assert resolve_precision("auto") == "rgba32f"
    assert resolve_precision("auto", directions=True) == "rgba16f"
    assert resolve_precision("rgba32f", directions=True) == "rgba32f"
    assert resolve_precision("rgba16f") == "rgba16f"
    base = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "camera": {"width": 8, "height": 8},
            "probes": {"grid": [2, 2, 2], "samples": 8, "fit": "box"}}
    assert parse_scene(base).probes.precision == "auto"
    for surface, precision, want in (({}, None, "rgba32f"), ({"gradient_factor": 0.2}, None, "rgba16f"),
                                     ({"gradient_factor": 0.2}, "rgba32f", "rgba32f")):
        d = {**base, "surface": surface,
             "probes": {**base["probes"], **({"precision": precision} if precision else {})}}
        r = Renderer(ctx, parse_scene(d))
        try:
            r.bake(seed=1)
            assert r.probe_grid.precision == want, (surface, precision)
        finally:
            r.release()
    with pytest.raises(SceneError, match="probes.precision"):
        parse_scene({"probes": {"precision": "rgba8"}})
