"""The probe view's slab (app/viewer/probe_view.py): one plane of a large grid's visible probes,
spheres sized by the spacing; the probe under the mouse found by the spheres' image disks; what it
holds in words. No GL: the selection, the picking and the words are NumPy."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins.camera import camera_frame
from radiance_probes.viewer import orbit
from radiance_probes.viewer.probe_view import (MAX_SPHERES, describe_probe, probe_centres,
                                               probe_under, select_probes, slab_plane,
                                               sphere_radius)


def test_a_slab_of_a_64_grid_draws_its_plane_of_visible_probes_unthinned():
    grid = (64, 64, 64)
    k, j, i = np.meshgrid(*(np.arange(64),) * 3, indexing="ij")
    visible = (i - 32) ** 2 + (j - 32) ** 2 + (k - 32) ** 2 < 28 ** 2    # a ball of medium
    whole = select_probes(grid, visible)
    assert whole.stride > 1                      # the whole grid is thinned to a lattice
    plane = slab_plane(grid, "z", 0.5)
    assert plane == 32
    slab = select_probes(grid, visible, slab=("z", plane))
    assert slab.stride == 1 and 0 < len(slab.indices) <= MAX_SPHERES
    kk = slab.indices // (64 * 64)
    assert np.all(kk == plane)                   # one plane
    assert len(slab.indices) == visible[plane].sum()   # all of its visible probes, none else
    # every axis, and a plane outside the ball holds none
    for axis in "xyz":
        assert len(select_probes(grid, visible, slab=(axis, 0)).indices) == 0
    y = select_probes(grid, visible, slab=("y", slab_plane(grid, "y", 0.25)))
    assert np.all((y.indices // 64) % 64 == 16)
    # 256^2 in a slab is thinned within the plane only
    big = select_probes((256, 256, 8), np.ones((8, 256, 256), bool), slab=("z", 3))
    assert big.stride == 4 and np.all(big.indices // (256 * 256) == 3)
    assert slab_plane(grid, "x", 1.0) == 63 and slab_plane(grid, "x", -1.0) == 0


def _view(width=64, height=48):
    scene = parse_scene({"camera": {"eye": [0.2, 0.3, 2.0], "width": width, "height": height}})
    frame = camera_frame(scene.camera, width, height)
    return scene, orbit.view_projection(frame), frame


def test_the_probe_under_the_mouse_is_the_nearest_whose_sphere_holds_it():
    scene, matrix, frame = _view()
    grid = (8, 8, 8)
    half = np.array([0.5, 0.5, 0.5])
    centres = probe_centres(grid, half)
    radius = sphere_radius(grid, half)
    pixels = orbit.project(matrix, centres, 64, 48)
    eye = np.asarray(scene.camera.eye)
    for index in (0, 100, 511):
        hit = probe_under(pixels[index], centres, matrix, 64, 48, radius, eye)
        # a probe at that pixel: the given one or one in front of it along the same line of sight
        assert hit is not None
        assert np.linalg.norm(centres[hit] - eye) <= np.linalg.norm(centres[index] - eye) + 1e-9
        assert np.hypot(*(pixels[hit] - pixels[index])) < 5.0
    # a lone probe: hit at its centre and just inside its disk, missed well outside
    one = centres[[100]]
    at = pixels[100]
    assert probe_under(at, one, matrix, 64, 48, radius, eye) == 0
    assert probe_under(at + np.array([40.0, 0.0]), one, matrix, 64, 48, radius, eye) is None
    assert probe_under(at, np.zeros((0, 3)), matrix, 64, 48, radius, eye) is None


def test_a_probe_is_described_by_what_it_holds():
    from radiance_probes.rendering.probes.layout import colour_channel
    channels = np.zeros(28)
    c00 = np.array([2.0, 1.0, 0.5]) * np.sqrt(4 * np.pi)     # mean radiance (2, 1, 0.5)
    for c in range(3):
        channels[colour_channel(0, c)] = c00[c]
        channels[colour_channel(3, c)] = 0.5 * c00[c]         # Y11 ~ x: light from +x
    channels[27] = 0.25
    lines = describe_probe(5 + 8 * (2 + 8 * 7), (8, 8, 8), (0.1, -0.2, 0.3), channels, 1)
    text = "\n".join(lines)
    assert "probe (5, 2, 7) of 8 x 8 x 8 at (0.100, -0.200, 0.300)" in text
    assert "mean radiance arriving: 2 1 0.5" in text
    assert "most light from (1.00, 0.00, 0.00)" in text
    assert "sun transmittance: 0.25" in text
    assert "most light" not in "\n".join(describe_probe(0, (8, 8, 8), (0, 0, 0), channels, 0))


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_the_slab_keeps_the_probe_spacing_as_its_sphere_size(axis):
    """A slab draws every probe of its plane (stride 1), so its spheres are sized by the spacing
    itself (the whole grid's lattice grows them by its stride)."""
    grid = (64, 64, 64)
    visible = np.ones((64, 64, 64), bool)
    slab = select_probes(grid, visible, slab=(axis, 10))
    assert slab.stride == 1
    assert len(slab.indices) == 64 * 64
    assert sphere_radius(grid, np.array([0.5, 0.5, 0.5])) * slab.stride == pytest.approx(
        0.28 / 64)
