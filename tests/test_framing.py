"""The default camera frames the volume's whole box (app/scene/framing.py) by its bounding sphere: every
corner inside the image from every direction at that distance (an orbit keeps it), at the
camera's field of view and the image's aspect, for tall, flat, long and cubic boxes in landscape
and portrait images; a sphere that fits keeps the default eye; a camera the scene gives is left
alone. Projected with the renderers' own camera (app/twins/camera.py)."""
from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from radiance_probes.scene.framing import frame_default_camera, framed_camera, is_default_view
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.scene.types import CameraSpec
from radiance_probes.twins.camera import camera_frame


def corners_ndc(camera: CameraSpec, half_extent) -> np.ndarray:
    """The box's corners in the image's normalised coordinates (-1..1 is inside)."""
    f = camera_frame(camera)
    out = []
    for signs in itertools.product((-1.0, 1.0), repeat=3):
        p = np.array(signs) * np.asarray(half_extent) - f.eye
        depth = p @ f.forward
        assert depth > 0
        out.append(((p @ f.right) / (depth * (f.right @ f.right)),
                    (p @ f.up) / (depth * (f.up @ f.up))))
    return np.array(out)


BOXES = [(0.5, 0.5, 0.5), (0.125, 0.5, 0.125), (0.5, 0.1, 0.5), (0.5, 0.5, 0.05),
         (0.05, 0.05, 0.5), (0.5, 0.25, 0.25)]


def orbited(camera: CameraSpec, azimuth: float, elevation: float) -> CameraSpec:
    """The camera on its sphere about the target at that azimuth and elevation (the Python API's
    Renderer.orbit: the distance kept, +y up)."""
    target = np.asarray(camera.target, np.float64)
    d = float(np.linalg.norm(np.asarray(camera.eye) - target))
    az, el = np.radians(azimuth), np.radians(elevation)
    offset = d * np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    return CameraSpec(eye=tuple(target + offset), target=camera.target, up=(0.0, 1.0, 0.0),
                      fov_y=camera.fov_y, width=camera.width, height=camera.height)


DIRECTIONS = [(az, el) for az in range(0, 360, 30) for el in (-80, -45, -20, 0, 20, 45, 80)]


@pytest.mark.parametrize("size", [(512, 512), (256, 512), (960, 400), (100, 800)])
@pytest.mark.parametrize("half", BOXES)
def test_the_framed_default_camera_sees_every_corner_from_every_direction(half, size):
    """Issue 55: framed for the default direction alone, the box touched the image's edges once
    orbited (azimuths 120 and 240). Framed by its bounding sphere, it fits from everywhere."""
    camera = CameraSpec(width=size[0], height=size[1])
    framed = framed_camera(camera, half)
    for az, el in DIRECTIONS:
        ndc = corners_ndc(orbited(framed, az, el), half)
        assert np.abs(ndc).max() <= 0.97 + 1e-9, (az, el, ndc)
    distance = np.linalg.norm(framed.eye)
    if framed is not camera:   # moved back along its direction, only as far as the sphere needs
        assert distance > np.linalg.norm(camera.eye)
        direction = np.asarray(framed.eye) / distance
        np.testing.assert_allclose(direction, np.asarray(camera.eye) / np.linalg.norm(camera.eye))
        radius = np.linalg.norm(half)
        silhouette = np.tan(np.arcsin(radius / distance))   # the sphere's, as a tangent
        narrower = np.tan(np.radians(camera.fov_y) / 2) * min(1.0, size[0] / size[1])
        assert silhouette == pytest.approx(0.97 * narrower, rel=1e-9)


def test_the_unframed_default_clips_a_cube_in_a_portrait_image_and_a_thin_rod_stays():
    """The default eye cuts a cube in a tall image, and a cube in a square one once orbited (its
    corners fit only from the default direction); a rod whose bounding sphere fits keeps the
    default eye, and its images stay."""
    assert np.abs(corners_ndc(CameraSpec(width=256), (0.5, 0.5, 0.5))).max() > 1.5
    assert max(np.abs(corners_ndc(orbited(CameraSpec(), az, 20), (0.5, 0.5, 0.5))).max()
               for az in (0, 120, 240)) > 1.0
    assert framed_camera(CameraSpec(), (0.05, 0.05, 0.5)) == CameraSpec()


def test_the_readme_example_keeps_the_box_in_the_image_as_it_orbits():
    """The README's Python example: a 48 x 64 x 64 array, 160 x 160, orbited to azimuths 0, 120
    and 240 at elevation 20 (issue 55: x 0 to 143 and 16 to 159). Every corner inside, and the
    renderers agree: the medium stays off the image's edges (rendered small: the same framing)."""
    import radiance_probes as rp
    volume = np.random.default_rng(1).normal(size=(48, 64, 64)).cumsum(axis=0)
    with rp.Renderer(volume, colormap="viridis", width=160, height=160) as r:
        half = r.volume.half_extent
        for azimuth in (0, 120, 240):
            camera = r.orbit(azimuth, 20)
            ndc = corners_ndc(camera, half)
            assert np.abs(ndc).max() < 0.98, (azimuth, ndc)
        image = r.render("pt", spp=1, width=40, height=40).linear   # azimuth 240
    medium = np.abs(image - image[0, 0]).max(axis=-1) > 1e-3
    assert medium.mean() > 0.2
    assert not (medium[0].any() or medium[-1].any() or medium[:, 0].any() or medium[:, -1].any())


def test_a_three_channel_cube_stays_inside_the_image(tmp_path):
    """Issue 55: a 3-channel cube read with --axes c3zyx (96 pages, 3 channels of 32) touched the
    image's bottom edge: its near corners lay 0.4% inside it. The margin now holds, and the
    renderers agree (the medium off every edge)."""
    import tifffile

    import radiance_probes as rp
    z, y, x = np.mgrid[:32, :32, :32]
    pages = np.concatenate([x, y, z]).astype(np.uint16) + 1   # 96 pages: channel-major
    tifffile.imwrite(tmp_path / "cells.tif", pages)
    with rp.Renderer(str(tmp_path / "cells.tif"), axes="c3zyx", width=40, height=40) as r:
        assert r.volume.channel_count == 3
        assert np.abs(corners_ndc(r.scene.camera, r.volume.half_extent)).max() < 0.98
        for azimuth in (0, 120, 240):
            assert np.abs(corners_ndc(r.orbit(azimuth, 20), r.volume.half_extent)).max() < 0.98
        image = r.render("pt", spp=1).linear
    medium = np.abs(image - image[0, 0]).max(axis=-1) > 1e-3
    assert medium.mean() > 0.2
    assert not (medium[0].any() or medium[-1].any() or medium[:, 0].any() or medium[:, -1].any())


def test_a_camera_the_scene_gives_is_its_own():
    given = parse_scene({"camera": {"eye": [0, 0, 1.2], "width": 32, "height": 64}})
    assert frame_default_camera(given, (0.5, 0.5, 0.5)) is given
    default = parse_scene({"camera": {"width": 32, "height": 64}})
    framed = frame_default_camera(default, (0.5, 0.5, 0.5))
    assert framed.camera != default.camera and is_default_view(framed.camera)
    assert frame_default_camera(framed, (0.5, 0.5, 0.5)) is framed        # framed once


def test_render_frames_a_tall_volume_it_is_given(tmp_path, capsys):
    """The command line's default view of a file: the whole box in the image (the volume's
    silhouette stays off the image's edges) at the image's aspect."""
    from radiance_probes.cli.main import main
    np.save(tmp_path / "cube.npy", np.ones((24, 24, 24), np.float32))
    out = tmp_path / "lin.npy"
    assert main(["render", str(tmp_path / "cube.npy"), "--width", "48", "--height", "96",
                 "--spp", "1", "--value-range", "0,2", "--out", str(tmp_path / "a.png"),
                 "--linear", str(out)]) == 0
    image = np.load(out).sum(axis=-1)
    medium = np.abs(image - image[0, 0]) > 1e-3
    assert medium.any()
    rows, cols = np.where(medium.any(axis=1))[0], np.where(medium.any(axis=0))[0]
    # inside the edges (the unframed default cut both sides), the narrower width holding the
    # box's bounding sphere (so any orbit fits too), the box itself over half of it
    assert 0 < cols.min() and cols.max() < 47 and cols.max() - cols.min() > 24, (cols.min(),
                                                                              cols.max())
    assert 0 < rows.min() and rows.max() < 95
