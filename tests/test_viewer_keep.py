"""The viewer's crop handles, bookmarks, colour points, transfer-function files, undo and redo,
its state saved with the scene, and its movie recorder: the state first (no window), then one
scripted session of the real viewer on a private Xvfb (tests/viewer_harness.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from radiance_probes.io.scene_file import (CameraSpec, load_scene, load_transfer_function,
                                           parse_scene)
from radiance_probes.viewer.crop_handles import dragged, drag_start, handles, plane_polygon
from radiance_probes.viewer.history import SceneHistory
from radiance_probes.viewer.state import ViewerState
from radiance_probes.io.volume import Volume
from viewer_harness import dump, png, view, view_pixels, write_script

# ---- undo and redo (no window) ---------------------------------------------------------------------


def test_undo_and_redo_scene_edits_but_not_the_camera():
    state = ViewerState.for_scene(parse_scene({}))
    h = state.history
    original = state.scene
    state.edit(density_scale=50.0)
    h.observe(state.scene)
    state.set_camera(CameraSpec(eye=(1.0, 1.0, 2.0)))     # navigation, not an edit
    h.observe(state.scene)
    state.set_transfer(colormap="viridis")
    h.observe(state.scene, busy=True)                    # a drag under way: not a step yet
    state.set_transfer(colormap="magma")
    h.observe(state.scene)                               # let go: one step
    assert len(h.undo_steps) == 2
    camera = state.scene.camera
    state.undo()
    assert state.scene.transfer_function.colormap == original.transfer_function.colormap
    assert state.scene.density_scale == 50.0 and state.scene.camera == camera
    state.undo()
    assert state.scene.density_scale == original.density_scale and state.scene.camera == camera
    state.undo()                                         # nothing left: the scene stays
    assert "nothing to undo" in state.messages[-1]
    state.redo()
    state.redo()
    assert state.scene.transfer_function.colormap == "magma" and state.scene.density_scale == 50.0
    state.undo()
    state.edit(albedo=0.5)                               # a new edit forgets what could be redone
    h.observe(state.scene)
    assert h.redo_steps == []


def test_bookmarks_and_viewer_state_in_the_scene():
    state = ViewerState.for_scene(parse_scene({}))
    state.set_camera(CameraSpec(eye=(2.0, 0.0, 0.0)))
    state.save_bookmark(1)
    state.set_camera(CameraSpec(eye=(0.0, 2.0, 0.5)))
    state.save_bookmark()                                # a new last one
    state.save_bookmark(1, name="side")                  # replaces the first
    assert [b.name for b in state.scene.bookmarks] == ["side", "view 2"]
    state.reset_camera()
    state.go_to_bookmark(2)
    assert state.scene.camera.eye == (0.0, 2.0, 0.5)
    state.set_method("raymarch")
    state.exposure = 2.5
    scene = state.scene.replace(viewer=state.viewer_spec())
    again = ViewerState.for_scene(parse_scene(scene.to_dict()))
    assert again.method == "raymarch" and again.exposure == 2.5
    assert again.scene.bookmarks == state.scene.bookmarks


def _volume(dims=(20, 16, 12)) -> Volume:
    data = np.zeros(dims[::-1], np.float32)
    return Volume(data, (1, 1, 1), "zeros", (0.0, 1.0), "float32", 0.0, 1.0)


def test_crop_handles_move_faces_by_whole_voxels():
    volume = _volume()
    state = ViewerState.for_scene(parse_scene({}))
    state.toggle_clipping(volume.dims)                   # x with no crop: the whole volume
    assert state.scene.crop.min == (0, 0, 0) and state.scene.crop.max == (20, 16, 12)
    marks = handles(state.scene, volume)
    assert len(marks) == 6
    x_min = next(m for m in marks if m.axis == 0 and m.side == 0)
    start = drag_start(state.scene, x_min)
    voxel = 2 * float(volume.half_extent[0]) / 20
    moved = dragged(state.scene, volume, x_min, start, 3.4 * voxel)
    assert moved.crop.min == (3, 0, 0)
    squeezed = dragged(state.scene, volume, x_min, start, 100.0)
    assert squeezed.crop.min[0] == 19                    # one voxel short of the other face
    state.toggle_clipping(volume.dims)
    assert not state.scene.crop.enabled and handles(state.scene, volume) == []


def test_clip_plane_outline_and_handle():
    outline = plane_polygon((1.0, 1.0, 0.0), 0.0, -np.ones(3) * 0.5, np.ones(3) * 0.5)
    assert len(outline) == 4
    np.testing.assert_allclose(outline @ np.array([1.0, 1.0, 0.0]), 0.0, atol=1e-12)
    assert len(plane_polygon((1.0, 0.0, 0.0), 0.9, -np.ones(3) * 0.5, np.ones(3) * 0.5)) == 0
    volume = _volume()
    scene = parse_scene({"clip_plane": {"normal": [0, 2, 0], "distance": 0.2}})
    (mark,) = handles(scene, volume)
    assert mark.kind == "plane" and mark.position[1] == pytest.approx(0.1)
    moved = dragged(scene, volume, mark, drag_start(scene, mark), 0.05)
    assert moved.clip_plane.distance == pytest.approx(0.3)   # 0.05 along the unit normal


# ---- the real viewer -----------------------------------------------------------------------------

WINDOW = "760x560"
SCENE = {"volume": {"builtin": "cloud", "size": [24, 20, 16]}, "density_scale": 60.0,
         "camera": {"eye": [0.0, 0.3, 3.2]}, "probes": {"grid": 4, "samples": 32},
         "environment": [0.1, 0.1, 0.1]}


@pytest.fixture(scope="module")
def session(display, tmp_path_factory):
    out = tmp_path_factory.mktemp("viewer_keep")
    (out / "scene.json").write_text(json.dumps(SCENE))
    steps = [
        {"until": "done"}, {"dump": "start.json"},
        {"key": "x"}, {"frames": 1}, {"dump": "crop_on.json"},
        {"drag": "handle crop x min", "by": [60, 0]}, {"frames": 2}, {"until": "done"},
        {"dump": "cropped.json"}, {"screenshot": "cropped.png"},
        {"key": "ctrl+z"}, {"frames": 1}, {"dump": "undone.json"},
        {"key": "ctrl+y"}, {"frames": 1}, {"dump": "redone.json"},
        {"key": "x"}, {"frames": 1}, {"dump": "crop_off.json"}, {"key": "x"},
        {"key": "ctrl+1"}, {"drag": {"view": [0.5, 0.5]}, "by": [80, 0]}, {"key": "ctrl+2"},
        {"key": "shift+1"}, {"frames": 1}, {"dump": "bookmark1.json"},
        {"click": "Edit colours as points"}, {"frames": 1}, {"dump": "points.json"},
        {"drag": "colour point 2", "by": [-30, 0]}, {"frames": 1}, {"dump": "point_moved.json"},
        {"click": "Save TF"}, {"key": "c"}, {"frames": 1}, {"dump": "other_tf.json"},
        {"click": "Load TF"}, {"frames": 1}, {"dump": "loaded_tf.json"},
        {"key": "4"}, {"key": "ctrl+s"},
        {"click": "Bookmarks and movie"}, {"drag": "Frames", "by": [-400, 0]},
        {"drag": "Samples per frame", "by": [-400, 0]},
        {"click": "Record movie"}, {"frames": 4}, {"dump": "recorded.json"},
        {"close": True},
    ]
    script = write_script(out / "script.json", steps)
    proc = view(["scene.json", "--script", str(script), "--window", WINDOW, "--spp", "4",
                 "--render-scale", "0.5"], out, display)
    return out, proc


def test_crop_handle_drag_crops_and_undo_restores(session):
    out, _ = session
    on, cropped = dump(out / "crop_on.json"), dump(out / "cropped.json")
    assert on["scene"]["crop"] == {"min": [0, 0, 0], "max": [24, 20, 16], "units": "voxels",
                                   "enabled": True}
    assert len(on["handles"]) == 6
    assert cropped["scene"]["crop"]["min"][0] > 2                 # the x min face moved in
    assert cropped["clip_region"]["box_min"][0] > on["clip_region"]["box_min"][0]
    assert cropped["errors"] == []
    assert dump(out / "undone.json")["scene"]["crop"]["min"] == [0, 0, 0]
    assert dump(out / "redone.json")["scene"]["crop"] == cropped["scene"]["crop"]
    off = dump(out / "crop_off.json")
    assert not off["scene"]["crop"]["enabled"] and off["clip_region"] is None
    assert off["handles"] == {}


def test_bookmarks_recalled_by_key(session):
    out, _ = session
    d = dump(out / "bookmark1.json")
    marks = d["scene"]["bookmarks"]
    assert [m["name"] for m in marks] == ["view 1", "view 2"]
    assert marks[0]["eye"] != marks[1]["eye"]                     # the orbit between them
    np.testing.assert_allclose(d["camera_eye"], marks[0]["eye"])


def test_colour_points_edited_and_transfer_function_file(session):
    out, _ = session
    points = dump(out / "points.json")["scene"]["transfer_function"]["colors"]
    assert len(points) == 5 and points[0][0] == 0.0 and points[-1][0] == 1.0
    moved = dump(out / "point_moved.json")["scene"]["transfer_function"]["colors"]
    assert moved[2][0] < points[2][0] and moved[2][1:] == points[2][1:]
    saved = load_transfer_function(out / "transfer_function.json")
    assert [list(p) for p in saved.colors] == moved
    assert dump(out / "other_tf.json")["scene"]["transfer_function"].get("colors") is None
    assert dump(out / "loaded_tf.json")["scene"]["transfer_function"]["colors"] == moved


def test_scene_saved_with_the_viewer_state_and_a_movie_recorded(session):
    out, _ = session
    saved = load_scene(out / "viewer_scene.json")
    assert saved.viewer.method == "raymarch"
    assert [b.name for b in saved.bookmarks] == ["view 1", "view 2"]
    assert saved.crop is not None and saved.crop.enabled
    rec = dump(out / "recorded.json")
    assert rec["recording"] is None and rec["errors"] == []
    assert any("recorded 2 frames" in m for m in rec["messages"])
    from radiance_probes.movie.writer import count_frames
    assert count_frames(out / "movie.mp4") == 2


def test_the_crop_shows_in_the_picture(session):
    out, _ = session
    start = dump(out / "start.json")
    image = png(out / "cropped.png")
    assert image.shape == (560, 760, 3)
    assert np.abs(view_pixels(image, start)).sum() > 0
