"""RenderSettings.bake_level (app/rendering/probes/bake_level.py): the probes' bake walks a coarser level
than the image. Level 0 is the bake as it was; a level whose medium equals the level shown gives
the same probes from the same seeds; the coarse level is what coarser() makes; changing the level
re-bakes and a camera move does not; what the image reads directly (the path tracer, the
raymarcher's light grid) stays on the level shown; bad values and levels too large for one
texture are refused naming bake_level."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.io.brick_sources import box_filtered
from radiance_probes.rendering.probes.bake_level import coarse_volume, level_dims, spacing_level
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins.majorant_grid import density_range_grid, macrocell_counts
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import volume_from_array

SCENE = {"volume": {"builtin": "cloud", "size": [16, 16, 16]}, "density_scale": 30.0,
         "albedo": 0.8, "max_bounces": 8, "camera": {"width": 16, "height": 12},
         "probes": {"grid": [4, 4, 4], "samples": 64, "fit": "box"}}


def _coefficients(r) -> np.ndarray:
    return r.probe_grid.coefficients()


def _ramp(n: int = 16) -> np.ndarray:
    """Density affine along x (0 to 1 over the voxel centres), constant along y and z: its
    2 x 2 x 2 averages are the affine function at the coarse voxels' centres, and trilinear
    filtering reproduces an affine function, so both levels hold one medium except within one
    fine voxel of the x faces, where the levels clamp to their edge voxels differently; the
    transfer function (RAMP_TF) gives no opacity there. (A volume constant in 2 x 2 x 2 blocks
    does not do: trilinear filtering of the fine level ramps between blocks over one fine voxel,
    of the coarse level over two.)"""
    x = (np.arange(n) + 0.5) / n
    return np.broadcast_to(x[None, None, :], (n, n, n)).astype(np.float32).copy()


RAMP_TF = {"opacity": [[0.0, 0.0], [0.2, 0.0], [0.5, 1.0], [0.8, 0.0], [1.0, 0.0]],
           "colormap": "grey"}


def test_level_0_is_the_bake_as_it_was(ctx):
    """At bake_level 0 the bake reads the scene's resources and the image's light grid, and
    gives bit for bit the probes of a ProbeGrid baked over them directly (the path before
    bake_level)."""
    scene = parse_scene(SCENE)
    r = Renderer(ctx, scene)
    try:
        assert r.settings.bake_level == 0 and r.bake_level() == 0
        r.bake(seed=4)
        assert r.bake_resources() is r.resources and r.walk_light() is r._light
        assert r._bake_medium is None
        probes = _coefficients(r)
        grid = r.probe_grid
        direct = ProbeGrid(ctx, grid.grid, grid.samples, grid.precision, grid.sh_order, grid.box,
                           grid.grey, sun=grid.sun, adaptive=grid.adaptive,
                           sun_correction=grid.sun_correction, sun_lobe=grid.sun_lobe,
                           medium=r.resources.medium_defines())
        direct.restart(4)
        while not direct.done:
            direct.bake_pass(r.resources, light=r._light)
        assert np.array_equal(direct.coefficients(), probes)
        direct.release()
    finally:
        r.release()


def test_a_coarser_level_that_holds_the_same_medium_gives_the_same_probes(ctx):
    """On the ramp (the same medium at levels 0 and 1, _ramp) with one global majorant (the
    majorant grids' cells differ between levels, and so would the walks' random numbers) and
    shadow rays for the walks' sun (the light grid's texels follow the level's voxels), level 1
    gives level 0's probes from the same seeds, up to float rounding of the filtering (measured
    below 1e-4 of the largest coefficient), and the probes' own sun to its march's quadrature."""
    scene = parse_scene({**SCENE, "volume": {"builtin": "cloud", "size": [16, 16, 16]},
                         "transfer_function": RAMP_TF, "density_scale": 20.0})
    volume = volume_from_array(_ramp(), value_range=(0.0, 1.0), name="ramp")
    settings = RenderSettings(empty_space_skipping=False, walk_sun="ray", walk_adaptive=0.0)
    probes = {}
    for level in (0, 1):
        r = Renderer(ctx, scene, volume, replace(settings, bake_level=level))
        try:
            r.bake(seed=7)
            probes[level] = _coefficients(r)
            if level:
                assert r.bake_resources().volume.dims == (8, 8, 8)
        finally:
            r.release()
    a, b = probes[0], probes[1]
    assert np.abs(a).max() > 0
    walks = a[..., :27]   # the SH coefficients: the walks
    diff = np.abs(walks - b[..., :27]).max() / np.abs(walks).max()
    assert diff < 1e-4, diff
    # channel 27, the probes' own sun, is marched at half a voxel of each level: the quadrature of
    # the transfer function's kinks differs by up to 1.4% (measured) at twice the step
    np.testing.assert_allclose(b[..., 27], a[..., 27], rtol=2e-2, atol=1e-5)


def test_the_coarse_level_is_coarser_and_its_majorant_grid_its_own(ctx):
    """The bake's texture holds coarser()'s level (2 x 2 x 2 averages, twice for level 2) and
    its majorant grid is built over it, at the level shown's macrocells; it changes the probes of a varied volume (the cloud)."""
    scene = parse_scene(SCENE)
    r = Renderer(ctx, scene, settings=RenderSettings(bake_level=2))
    try:
        r.bake(seed=1)
        medium = r._bake_medium
        data = r.resources.volume.data
        expected = box_filtered(box_filtered(data))
        got = np.frombuffer(medium.volume_tex.read(), np.float32).reshape(expected.shape)
        assert np.array_equal(got, expected)
        # its densities over the level shown's macrocells
        assert medium.majorant_grid.cells == r.resources.majorant_grid.cells == macrocell_counts(
            (16, 16, 16))
        low, high = density_range_grid(expected, medium.majorant_grid.cells)
        assert np.array_equal(medium.majorant_grid.d_max, high)
        assert medium.majorant_grid.builds == 1 and medium.gpu_bytes > 4 * 4 ** 3
        coarse = _coefficients(r)
        note = r.bake_note()   # what `render` prints and the API's notes hold
        assert "level 2 coarser" in note and "(4 x 4 x 4" in note and "bake_level" in note
        r.configure(bake_level=0)
        r.bake(seed=1)
        assert r.bake_note() is None
        assert not np.allclose(_coefficients(r), coarse, rtol=1e-3)
    finally:
        r.release()


def test_changing_the_level_rebakes_and_a_camera_move_does_not(ctx):
    scene = parse_scene(SCENE)
    r = Renderer(ctx, scene)
    try:
        r.bake(seed=2)
        assert r.probes_current()
        r.configure(bake_level=1)
        assert not r.probes_current()
        assert r.bake(seed=2) > 0 and r.probes_current()
        medium = r._bake_medium
        builds = medium.majorant_grid.builds
        r.set_scene(scene.replace(camera=replace(scene.camera, eye=(0.3, 0.4, 2.2))))
        assert r.probes_current() and r.bake(seed=2) == 0.0
        assert medium.majorant_grid.builds == builds
        # a transfer-function edit re-bakes and rebuilds the coarse level's majorant grid
        r.set_scene(scene.replace(density_scale=40.0))
        assert not r.probes_current()
        r.bake(seed=2)
        assert medium.majorant_grid.builds == builds + 1 and r._bake_medium is medium
        # by the probes' spacing: 16 voxels, 4 probes: level 1 (a voxel of 2, half a spacing)
        r.configure(bake_level=-1)
        assert r.bake_level() == 1 and r.probes_current()   # the same level: nothing to redo
        r.configure(bake_level=2)
        assert not r.probes_current()
    finally:
        r.release()


def test_what_the_image_reads_stays_on_the_level_shown(ctx):
    """The path tracer's image is the same at every bake level (the same seed), and the
    raymarcher's light grid is the level shown's, bit for bit; the walks' is the coarse one's."""
    scene = parse_scene(SCENE)
    images, lights = {}, {}
    for level in (0, 2):
        r = Renderer(ctx, scene, settings=RenderSettings(bake_level=level))
        try:
            r.render("raymarch", spp=1, seed=5)   # bakes the probes and both light grids
            images[level] = r.render("pt", spp=2, seed=5).image
            lights[level] = (r._light.grid, r._light.read())
            if level:
                assert r.walk_light() is not r._light
                assert max(r.walk_light().grid) < max(r._light.grid)
        finally:
            r.release()
    assert np.array_equal(images[0], images[2])
    assert lights[0][0] == lights[2][0] and np.array_equal(lights[0][1], lights[2][1])


def test_a_bricked_level_shown_bakes_from_one_coarse_texture(ctx):
    """Shown as a brick pool (bricks of 8), the bake's level 1 is one texture, and its probes
    are those of the same level under the volume shown whole (the bake reads the same medium)."""
    scene = parse_scene(SCENE)
    probes = {}
    for brick in (None, 8):
        r = Renderer(ctx, scene, settings=RenderSettings(bake_level=1, brick_size=brick))
        try:
            assert r.resources.bricked == (brick is not None)
            r.bake(seed=3)
            assert not r.bake_resources().bricked
            assert "VOLUME_BRICKED" not in r.probe_grid.medium
            probes[brick] = _coefficients(r)
        finally:
            r.release()
    assert np.array_equal(probes[None], probes[8])


@pytest.mark.parametrize("value", [True, 9, -2, 1.5, "auto", None])
def test_bad_values_are_refused_naming_bake_level(ctx, value):
    with pytest.raises(ValueError, match="bake_level"):
        RenderSettings(bake_level=value)


def test_a_level_beyond_one_texture_is_refused_with_its_sizes():
    volume = volume_from_array(_ramp(16), value_range=(0.0, 1.0), name="ramp")
    with pytest.raises(VolumeError, match=r"bake_level 1: the bake's level \(8 x 8 x 8.*16 x 16 x 16"):
        coarse_volume(volume, 1, max_side=4, available=None, where="")
    with pytest.raises(VolumeError, match="bake_level 2.*more than the"):
        coarse_volume(volume, 2, max_side=64, available=100, where="test")


def test_the_probes_spacing_rule():
    """The coarsest level whose voxel is at most half the probe spacing along every axis."""
    volume = volume_from_array(np.zeros((16, 32, 64), np.float32), value_range=(0.0, 1.0))
    assert level_dims(volume, 3) == [(64, 32, 16), (32, 16, 8), (16, 8, 4), (8, 4, 2)]
    # x: 64 voxels over 4 probes: a spacing of 16 voxels, half is 8: level 3 along x; y: 32 over
    # 4, level 2; z: 16 over 4, level 1. Every axis: level 1.
    assert spacing_level(volume, (4, 4, 4)) == 1
    assert spacing_level(volume, (4, 4, 2)) == 2
    assert spacing_level(volume, (32, 16, 8)) == 0       # a probe every two voxels
    assert spacing_level(volume, (64, 64, 64)) == 0      # finer than the voxels: level 0
    assert spacing_level(volume, (1, 1, 1)) == 3         # a 2-voxel z axis at level 3
    # a probe box half the volume's along x halves the spacing there
    he = volume.half_extent
    box = ((-he[0] / 2, -he[1], -he[2]), (he[0] / 2, he[1], he[2]))
    assert spacing_level(volume, (4, 1, 1), box) == 2
    # odd axes round up (coarser()'s padding): 15 -> 8 -> 4
    odd = volume_from_array(np.zeros((15, 15, 15), np.float32), value_range=(0.0, 1.0))
    assert level_dims(odd, 2)[1:] == [(8, 8, 8), (4, 4, 4)]


def test_a_sliced_bake_at_a_coarser_level_ends_at_the_whole_bake(ctx):
    """The viewer's budgeted slices (bake_step) bake the bake's own light grid a slab at a time,
    then the walks, and end at the probes of one whole bake; the image's light grid is left to
    the image (the raymarcher bakes it when it needs it)."""
    r = Renderer(ctx, parse_scene(SCENE), settings=RenderSettings(bake_level=1))
    try:
        r.bake(seed=5)
        whole = _coefficients(r)
        r.invalidate()
        light = r._walk_light.light
        slabs = 0
        while not r.walk_light_current():
            assert r.bake_step(5, budget_ms=1e-6) > 0
            slabs += 1
        assert slabs == light.layers > 1
        while not r.probes_current():
            r.bake_step(5, budget_ms=1e-6)
        assert np.array_equal(_coefficients(r), whole)
        assert not r.light_current()
        r.render("raymarch", spp=1, seed=5)
        assert r.light_current() and r._light is not light
    finally:
        r.release()
