"""The default camera frames the volume's whole box (app/scene/framing.py): every corner inside the
image, at the camera's field of view and the image's aspect, for tall, flat, long and cubic boxes
in landscape and portrait images; a box that fits keeps the default eye; a camera the scene gives
is left alone. Projected with the renderers' own camera (app/twins/camera.py)."""
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


@pytest.mark.parametrize("size", [(512, 512), (256, 512), (960, 400), (100, 800)])
@pytest.mark.parametrize("half", BOXES)
def test_the_framed_default_camera_sees_every_corner(half, size):
    camera = CameraSpec(width=size[0], height=size[1])
    framed = framed_camera(camera, half)
    ndc = corners_ndc(framed, half)
    assert np.abs(ndc).max() <= 1.0 + 1e-9, ndc
    if framed is not camera:   # moved back: no farther than the box needs and its margin
        assert np.abs(ndc).max() == pytest.approx(0.97, abs=0.01)
        assert np.linalg.norm(framed.eye) > np.linalg.norm(camera.eye)
        direction = np.asarray(framed.eye) / np.linalg.norm(framed.eye)
        np.testing.assert_allclose(direction, np.asarray(camera.eye) / np.linalg.norm(camera.eye))
    else:
        assert np.abs(corners_ndc(camera, half)).max() <= 1.0


def test_the_unframed_default_clips_a_cube_in_a_portrait_image_and_a_square_one_stays():
    """What the issue saw: the default eye cuts a box in a tall image; a cube in a square image
    fits (its near corners 0.4% inside the edge), so its default view, and image, stay."""
    assert np.abs(corners_ndc(CameraSpec(width=256), (0.5, 0.5, 0.5))).max() > 1.5
    assert np.abs(corners_ndc(CameraSpec(), (0.5, 0.5, 0.5))).max() == pytest.approx(0.996, abs=1e-3)
    assert framed_camera(CameraSpec(), (0.5, 0.5, 0.5)) == CameraSpec()


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
    # inside the edges (the unframed default cut both sides), yet filling the width it limits
    assert cols.min() <= 2 and cols.max() >= 45, (cols.min(), cols.max())
    assert medium[:, 0].sum() <= 3 and medium[:, -1].sum() <= 3, (medium[:, 0].sum(),
                                                                  medium[:, -1].sum())
    assert 0 < rows.min() and rows.max() < 95
