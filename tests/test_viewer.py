"""The viewer: its maths and state in NumPy, then the real viewer in a real window (GLFW, Dear
ImGui, Mesa llvmpipe) on a private Xvfb, driven through its own input callbacks by scripts, with
assertions on its screenshots and state dumps."""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.twins.camera import camera_frame
from radiance_probes.io.scene_file import CameraSpec, load_scene, parse_scene
from radiance_probes.twins.sh import sh_evaluate
from radiance_probes.viewer import layout, orbit
from radiance_probes.viewer.probe_view import (RADIUS_PER_SPACING, box_edges, probe_centres,
                                               uv_sphere)
from radiance_probes.viewer.state import (ViewerState, add_point, angles_from_direction,
                                          direction_from_angles, move_point, remove_point)
from viewer_harness import dump, png, srgb8, view, view_pixels, write_script
from radiance_probes.rendering.probes.layout import TEXTURES_FOR_ORDER
from radiance_probes.scene.transfer import transfer_table

# The test scene scatters isotropically (g = 0), so "auto" stores SH order 0: two textures.
PROBE_TEXTURES_G0 = len(TEXTURES_FOR_ORDER[0])

# ---- maths and state (no window) ------------------------------------------------------------------


def _distance(cam: CameraSpec) -> float:
    return float(np.linalg.norm(np.subtract(cam.eye, cam.target)))


def test_view_projection_is_the_raytracers_camera():
    frame = camera_frame(CameraSpec(eye=(0.4, 0.3, 2.0), target=(0.1, -0.1, 0.0), fov_y=40.0), 160, 90)
    px, py = np.meshgrid(np.linspace(0.5, 159.5, 7), np.linspace(0.5, 89.5, 5))
    points = frame.eye + frame.ray_directions(px, py) * np.linspace(0.5, 3.0, 5)[:, None, None]
    pixels = orbit.project(orbit.view_projection(frame), points, 160, 90)
    np.testing.assert_allclose(pixels[..., 0], px, atol=1e-3)
    np.testing.assert_allclose(pixels[..., 1], py, atol=1e-3)


def test_orbit_keeps_target_and_distance_and_turns_the_right_way():
    cam = CameraSpec()
    turned = orbit.orbit(cam, 50.0, 0.0)
    assert turned.target == cam.target
    assert math.isclose(_distance(turned), _distance(cam), rel_tol=1e-12)
    assert turned.eye[0] < cam.eye[0]          # dragging right: the eye swings left
    tilted = orbit.orbit(cam, 0.0, 50.0)
    assert tilted.eye[1] > cam.eye[1]          # dragging down: the eye rises
    assert orbit.orbit(cam, 0.0, 0.0).eye == pytest.approx(cam.eye)


def test_orbit_never_crosses_the_pole():
    cam = CameraSpec()
    for _ in range(20):
        cam = orbit.orbit(cam, 0.0, 400.0)
    forward = np.subtract(cam.target, cam.eye) / _distance(cam)
    assert np.degrees(np.arccos(np.clip(-forward[1], -1, 1))) >= orbit.POLE_MARGIN_DEGREES - 1e-6
    parse_scene({"camera": {"eye": list(cam.eye), "target": list(cam.target)}})  # still valid


def test_pan_moves_the_target_with_the_cursor():
    cam = CameraSpec(width=200, height=100)
    moved = orbit.pan(cam, 30.0, -10.0, viewport_height=100)
    forward = np.subtract(cam.target, cam.eye)
    np.testing.assert_allclose(np.subtract(moved.target, moved.eye), forward, atol=1e-12)
    # The old target, seen from the moved camera, lands where the cursor went: 30 px right, 10 up.
    frame = camera_frame(moved, 200, 100)
    (x, y), = orbit.project(orbit.view_projection(frame), np.array([cam.target]), 200, 100)
    assert (x, y) == pytest.approx((100 + 30, 50 - 10), abs=1e-6)


def test_zoom_keeps_the_view_direction_and_limits():
    cam = CameraSpec()
    closer = orbit.zoom(cam, 2.0)
    assert math.isclose(_distance(closer), _distance(cam) * orbit.ZOOM_PER_WHEEL_STEP ** 2)
    np.testing.assert_allclose(np.subtract(closer.target, closer.eye) / _distance(closer),
                               np.subtract(cam.target, cam.eye) / _distance(cam), atol=1e-12)
    assert _distance(orbit.zoom(cam, 1000.0)) == pytest.approx(orbit.MIN_DISTANCE)


def test_light_angles_round_trip():
    for az, el in ((0.0, 0.0), (30.0, 45.0), (-120.0, -20.0), (179.0, 80.0)):
        d = direction_from_angles(az, el)
        assert np.linalg.norm(d) == pytest.approx(1.0)
        assert angles_from_direction(d) == pytest.approx((az, el))


def test_state_edits_replace_the_scene():
    state = ViewerState.for_scene(parse_scene({"transfer_function": {"rgba": [[0, 0, 0, 0], [1, 1, 1, 1]]}}))
    first = state.scene
    state.step_probe_grid(+1)
    assert state.scene.probes.grid == (24, 24, 24) and first.probes.grid == (16, 16, 16)
    state.step_probe_grid(-1)
    state.step_probe_grid(-1)
    assert state.scene.probes.grid == (12, 12, 12)
    state.cycle_colormap()
    # a colormap replaces an explicit table's colours and keeps its opacity curve
    assert state.scene.transfer_function.rgba is None
    assert state.scene.transfer_function.opacity == ((0.0, 0.0), (1.0, 1.0))
    state.turn_light(15.0, 0.0)
    assert angles_from_direction(state.scene.light.direction)[0] == pytest.approx(
        angles_from_direction(first.light.direction)[0] + 15.0)
    state.set_camera(replace(state.scene.camera, fov_y=50.0))
    state.reset_camera()
    assert state.scene.camera == first.camera


def test_editing_an_explicit_tables_opacity_keeps_it_explicit():
    rows = [[0, 0, 1, 0], [1, 0.5, 0, 0.5], [0.2, 1, 0.2, 1]]
    state = ViewerState.for_scene(parse_scene({"transfer_function": {"rgba": rows}}))
    state.set_transfer(opacity=((0.0, 0.0), (0.5, 0.1), (1.0, 0.2)))
    tf = state.scene.transfer_function
    assert tf.rgba is not None and tf.rgba[0][:3] == (0.0, 0.0, 1.0) and tf.rgba[-1] == (0.2, 1.0, 0.2, 0.2)
    assert parse_scene(state.scene.to_dict()) == state.scene     # still a valid scene


def test_probe_view_draws_the_visible_probes_and_thins_large_grids():
    from radiance_probes.twins.medium import sigma_t_at
    from radiance_probes.viewer.probe_view import MAX_SPHERES, select_probes, visible_cells
    from radiance_probes.io.load import load_volume
    scene = parse_scene({"volume": {"builtin": "sphere", "size": [40, 40, 40]},
                         "transfer_function": {"opacity": [[0, 0], [0.5, 0], [0.6, 1], [1, 1]]}})
    volume = load_volume(scene.volume)
    alpha = transfer_table(scene.transfer_function)[:, 3]
    grid = (32, 32, 32)
    visible = visible_cells(grid, None, volume, alpha, scene.density_scale)
    # brute force: a probe's cell holds a voxel centre where the medium is visible
    centres = probe_centres(grid, volume.half_extent)
    assert visible.sum() > 0 and visible.sum() < visible.size / 2
    he = np.asarray(volume.half_extent)
    z, y, x = np.meshgrid(*[(np.arange(n) + 0.5) / n * 2 * h - h
                            for n, h in zip(volume.dims[::-1], he[::-1])], indexing="ij")
    points = np.stack([x, y, z], -1).reshape(-1, 3)
    seen = sigma_t_at(volume, transfer_table(scene.transfer_function), scene.density_scale,
                      points) > 0
    cell = np.floor((points[seen] + he) / (2 * he) * 32).astype(int)
    expected = np.zeros((32, 32, 32), bool)
    expected[cell[:, 2], cell[:, 1], cell[:, 0]] = True
    assert (visible >= expected).all() and (visible & ~expected).sum() <= 0.1 * expected.sum()
    chosen = select_probes(grid, visible)
    assert chosen.stride == 1 and len(chosen.indices) == visible.sum() <= MAX_SPHERES
    assert visible.ravel()[chosen.indices].all() and len(centres) == chosen.total == 32 ** 3
    # a grid with more visible probes than MAX_SPHERES: the smallest stride that fits
    full = np.ones((64, 64, 64), bool)
    thinned = select_probes((64, 64, 64), full)
    assert len(thinned.indices) <= MAX_SPHERES < len(select_probes((64, 64, 64), full,
                                                                   10 ** 9).indices)
    assert thinned.stride == 4 and len(thinned.indices) == 16 ** 3
    # nothing visible (an empty volume): every probe, so the view is not blank
    nothing = select_probes((4, 4, 4), np.zeros((4, 4, 4), bool))
    assert len(nothing.indices) == 64 and nothing.visible == 0


def test_shown_methods_and_probe_needs():
    state = ViewerState.for_scene(parse_scene({}))
    assert state.shown_methods() == ["pt"] and not state.wants_probes()
    state.toggle_display("split")
    assert state.split_method != state.method and state.shown_methods() == ["pt", "probes"]
    state.set_method("probes")
    state.set_display("error")
    assert state.shown_methods() == ["probes", "pt"] and state.wants_probes()
    state.set_method("pt")
    state.probe_view = "alone"
    assert state.shown_methods() == [] and state.wants_probes()


def test_opacity_points_stay_ordered_and_in_range():
    pts = ((0.0, 0.0), (0.3, 0.2), (1.0, 1.0))
    assert move_point(pts, 1, 1.5, -1.0) == ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0))
    assert move_point(pts, 1, 0.5, 0.7)[1] == (0.5, 0.7)
    assert add_point(pts, 0.6, 0.4) == ((0.0, 0.0), (0.3, 0.2), (0.6, 0.4), (1.0, 1.0))
    assert remove_point(pts, 1) == ((0.0, 0.0), (1.0, 1.0))
    assert remove_point(remove_point(pts, 1), 0) == ((0.0, 0.0), (1.0, 1.0))  # two stay


def test_layout_on_normal_and_hidpi_screens():
    assert layout.view_rect_window((1280, 800), 370) == (370, 0, 910, 800)
    assert layout.view_rect_framebuffer((1280, 800), (1280, 800), 370) == (370, 0, 910, 800)
    # A 2x framebuffer (macOS points): the picture keeps its place, with twice the pixels.
    assert layout.view_rect_framebuffer((1280, 800), (2560, 1600), 370) == (740, 0, 1820, 1600)
    assert layout.render_size((740, 0, 1820, 1600), 0.5) == (910, 800)
    assert layout.ui_scale(2.0, 1280, 1280) == 2.0   # X11 / Windows: coordinates are pixels
    assert layout.ui_scale(2.0, 1280, 2560) == 1.0   # macOS: the framebuffer is denser already


def test_sphere_mesh_faces_outwards_and_probe_centres_follow_the_spec():
    vertices, triangles = uv_sphere()
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c)
    assert (outward >= -1e-9).all() and (outward > 1e-9).sum() > len(triangles) * 0.8
    centres = probe_centres((2, 3, 4), (0.5, 0.25, 0.4))
    assert centres.shape == (24, 3)
    np.testing.assert_allclose(centres[0], [-0.25, -0.25 * 2 / 3, -0.3])
    np.testing.assert_allclose(centres[1], [0.25, -0.25 * 2 / 3, -0.3])  # x fastest
    assert len(box_edges((0.5, 0.5, 0.5))) == 24


def test_a_screenshot_still_partial_after_the_wait_says_so_in_one_line(capsys, monkeypatch):
    """`view --screenshot --frames N`: where a view's first frame is still in bands when the wait
    (SCREENSHOT_WAIT_S) runs out, one line says the image is partial and how to get a whole one;
    where it had to wait, one line says how long. (The waiting itself: the Xvfb test below.)"""
    from types import SimpleNamespace

    from radiance_probes.viewer import launch

    class Session:
        views = {"raymarch": None}
        whole = False

        def shows_whole(self, method):
            return self.whole

        def part_done(self, method):
            return 0.7
    session = Session()
    window = SimpleNamespace(viewer=SimpleNamespace(session=session), should_close=lambda: False,
                             poll=lambda: None, frame=lambda: None)
    monkeypatch.setattr(launch, "SCREENSHOT_WAIT_S", 0.0)
    frames, waited = launch._wait_for_a_whole_image(window)
    launch._say_whether_whole(window, "out.png", frames, waited)
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "out.png is partial" in err[0] and "70% done" in err[0], err
    assert "--frames" in err[0] and "raymarch's first frame" in err[0]
    session.whole = True
    launch._say_whether_whole(window, "out.png", 12, 3.4)
    err = capsys.readouterr().err.splitlines()
    assert err == ["view: note: 12 more frames (3.4 s) for a whole image: one sample takes "
                   "several frames on this device"]


def test_headless_commands_do_not_import_the_window_toolkit():
    code = ("import sys, radiance_probes.cli.main; radiance_probes.cli.main.build_parser(); "
            "print(any(m.split('.')[0] in ('glfw', 'imgui_bundle') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ---- the real viewer in a window --------------------------------------------------------------------

SCENE = {"volume": {"builtin": "cloud", "size": [24, 24, 24]},
         "probes": {"grid": [4, 4, 4], "samples": 64, "fit": "box"},
         "camera": {"width": 64, "height": 64}}
WINDOW = "720x440"
SPP = 4


def _is_background(pixels: np.ndarray, colour, tol: int = 6) -> np.ndarray:
    return (np.abs(pixels - np.asarray(colour)) <= tol).all(axis=-1)


ENVIRONMENT_SRGB = srgb8([0.1, 0.1, 0.1])


@pytest.fixture(scope="module")
def run(display, tmp_path_factory):
    """One scripted session of the viewer; the tests below read what it left behind."""
    out = tmp_path_factory.mktemp("viewer")
    (out / "scene.json").write_text(json.dumps(SCENE))
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (12, 16, 20)), indexing="ij")
    blob = np.clip(1.2 - 2 * np.sqrt(x * x + y * y + z * z), 0, 1).astype(np.float32)
    np.save(out / "blob.npy", blob)
    import nibabel as nib   # the new formats open like any volume: a NIfTI file, a TIFF folder
    import tifffile
    nib.save(nib.Nifti1Image(np.ascontiguousarray(blob.transpose(2, 1, 0)), np.eye(4)),
             str(out / "blob.nii.gz"))
    (out / "stack").mkdir()
    for k, page in enumerate((blob[:, :, :10] * 1000).astype(np.uint16)):
        tifffile.imwrite(out / "stack" / f"z{k:03d}.tif", page)
    steps = [
        {"until": "done"}, {"screenshot": "pt.png"}, {"dump": "pt.json"},
        {"key": "2"}, {"until": "done"}, {"screenshot": "probes.png"}, {"dump": "probes.json"},
        {"key": "1"}, {"click": "view split"}, {"until": "done"},
        {"screenshot": "split.png"}, {"dump": "split.json"},
        {"drag": {"view": [0.5, 0.6]}, "to": {"view": [0.3, 0.6]}}, {"dump": "divider.json"},
        {"key": "2"}, {"key": "e"}, {"until": "done"}, {"screenshot": "error.png"}, {"dump": "error.json"},
        {"key": "e"}, {"drag": {"view": [0.5, 0.5]}, "by": [40, 15]}, {"dump": "orbit.json"},
        {"until": "done"}, {"screenshot": "orbit.png"},
        {"drag": {"view": [0.5, 0.5]}, "by": [30, 0], "button": "right"},
        {"scroll": {"view": [0.5, 0.5]}, "steps": 2}, {"dump": "pan_zoom.json"}, {"key": "r"},
        {"key": "g"}, {"until": "done"}, {"screenshot": "grid_over.png"}, {"dump": "grid_over.json"},
        {"key": "g"}, {"frames": 2}, {"screenshot": "grid_alone.png"}, {"dump": "grid_alone.json"},
        {"key": "g"}, {"key": "]"}, {"until": "baked"}, {"dump": "finer.json"},
        {"key": "right"}, {"dump": "light_key.json"},
        {"drag": "Sun elevation", "by": [-60, 0]}, {"dump": "light_slider.json"},
        {"drag": "opacity point 1", "by": [0, -25]}, {"dump": "opacity.json"},
        {"key": "c"}, {"dump": "colormap.json"}, {"until": "done"}, {"screenshot": "edited.png"},
        {"resize": [640, 480]}, {"frames": 1}, {"screenshot": "resized.png"}, {"dump": "resized.json"},
        {"drop": ["blob.npy"]}, {"frames": 1}, {"dump": "dropped.json"},
        {"key": "ctrl+s"}, {"key": "f12"}, {"dump": "saved.json"},
        {"key": "f1"}, {"screenshot": "help.png"}, {"dump": "help.json"}, {"key": "f1"},
        {"click": "Data"}, {"click": "Open file..."}, {"click": "browser scene.json"},
        {"dump": "browsed.json"},
        {"drop": ["blob.nii.gz"]}, {"frames": 1}, {"dump": "dropped_nifti.json"},
        {"drop": ["stack"]}, {"frames": 1}, {"dump": "dropped_folder.json"},
        {"close": True},
    ]
    script = write_script(out / "script.json", steps)
    proc = view(["scene.json", "--script", str(script), "--window", WINDOW, "--spp", str(SPP),
                 "--render-scale", "0.5", "--file-dialog", "builtin"], out, display,
                harness=["--release-check"])
    return out, proc


def test_pt_screenshot_shows_the_volume_and_the_panels(run):
    out, _ = run
    d, image = dump(out / "pt.json"), png(out / "pt.png")
    assert image.shape == (440, 720, 3)
    assert d["samples"] == {"pt": SPP} and d["frame_ms"] > 0
    picture = view_pixels(image, d)
    volume = ~_is_background(picture, ENVIRONMENT_SRGB, tol=12)
    assert 0.05 < volume.mean() < 0.9                          # the cloud, not an empty frame
    h, w = volume.shape
    assert volume[h // 3: 2 * h // 3, w // 3: 2 * w // 3].mean() > 0.3
    sidebar = image[:, : d["view_rect_framebuffer"][0]]
    assert len(np.unique(sidebar.reshape(-1, 3), axis=0)) > 50  # text and widgets
    # every radio button of the panel lies whole inside it ("refine" was cut to "refi")
    edge = d["view_rect_window"][0]
    for name in ("pt", "probes", "probes-only", "raymarch", "refine", "view error", "probes alone"):
        x0, _, x1, _ = d["widgets"][name]
        assert 0 <= x0 < x1 <= edge, (name, d["widgets"][name], edge)


def medium_difference(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference of two pictures over the pixels where either shows something
    other than its corner's background: how far they differ where the volume is, whatever share
    of the picture it fills (framed by its bounding sphere, a margin around it: issue 55)."""
    shown = (a != a[0, 0]).any(axis=-1) | (b != b[0, 0]).any(axis=-1)
    assert shown.mean() > 0.05
    return float(np.abs(a - b)[shown].mean())


def test_probe_method_bakes_once_and_renders(run):
    out, _ = run
    d = dump(out / "probes.json")
    assert d["method"] == "probes" and d["samples"] == {"probes": SPP}
    assert d["probes_ready"] and d["bakes_started"] == 1 and d["probe_grid"] == [4, 4, 4]
    assert 1 <= d["bake_passes_run"] <= 4       # light-grid layers in slices, then the walks
    assert d["probe_bytes"] == PROBE_TEXTURES_G0 * 64 * 16 and d["bake_ms"] > 0
    a, b = view_pixels(png(out / "pt.png"), d), view_pixels(png(out / "probes.png"), d)
    assert medium_difference(a, b) > 0.5                       # another method, another image


def test_split_view_halves_are_the_two_methods(run):
    out, _ = run
    d = dump(out / "split.json")
    assert d["display"] == "split" and d["method"] == "pt" and d["split_method"] == "probes"
    assert d["samples"] == {"pt": SPP, "probes": SPP}
    split = view_pixels(png(out / "split.png"), d)
    pt, probes = view_pixels(png(out / "pt.png"), d), view_pixels(png(out / "probes.png"), d)
    divider = int(round(d["split_position"] * split.shape[1]))
    left, right = slice(0, divider - 2), slice(divider + 2, None)
    np.testing.assert_array_equal(split[:, left], pt[:, left])
    np.testing.assert_array_equal(split[:, right], probes[:, right])
    assert medium_difference(split[:, right], pt[:, right]) > 0.5
    assert (split[:, divider - 1: divider + 1] == 255).all()   # the divider line
    assert dump(out / "divider.json")["split_position"] == pytest.approx(0.3, abs=0.02)


def test_error_view_is_a_heat_map_with_its_relative_rmse(run):
    out, _ = run
    d = dump(out / "error.json")
    assert d["display"] == "error" and d["samples"] == {"probes": SPP, "pt": SPP}
    assert 0.0 < d["rel_rmse"] < 1.5
    heat = view_pixels(png(out / "error.png"), d)
    from radiance_probes.viewer.display import heat_colours
    palette = np.round(heat_colours(256) * 255)
    nearest = np.abs(heat.reshape(-1, 1, 3) - palette[None]).sum(-1).min(-1)
    assert (nearest <= 12).mean() > 0.97                        # every pixel is a heat colour
    assert (heat.sum(-1) > 60).mean() > 0.02                    # and the error is somewhere


def test_orbit_restarts_the_image_but_never_rebakes(run):
    out, _ = run
    before, after = dump(out / "error.json"), dump(out / "orbit.json")
    eye0, eye1 = np.array(before["scene"]["camera"]["eye"]), np.array(after["scene"]["camera"]["eye"])
    target = np.array(after["scene"]["camera"]["target"])
    assert np.linalg.norm(eye1 - eye0) > 0.1
    assert np.linalg.norm(eye1 - target) == pytest.approx(np.linalg.norm(eye0 - target), rel=1e-9)
    assert after["restarts"] >= before["restarts"] + 6          # every move restarted the image
    assert after["bake_passes_run"] == before["bake_passes_run"]
    assert after["bakes_started"] == before["bakes_started"] == 1
    assert medium_difference(view_pixels(png(out / "orbit.png"), after),
                             view_pixels(png(out / "probes.png"), after)) > 0.5


def _sphere_colours_checked(image: np.ndarray, d: dict) -> int:
    """Compares the centre pixel of the nearest probes' spheres with the probe's SH radiance at
    the normal facing the camera (app/twins/sh.py, tone mapped); returns how many were compared."""
    x0, _, w, h = d["view_rect_framebuffer"]
    coeffs = np.array(d["probe_coefficients"])[:, :27].reshape(-1, 9, 3)
    # the textures hold the bands up to the grid's SH order only (the running means hold all)
    coeffs[:, (d["probe_sh_order"] + 1) ** 2:] = 0.0
    centres = probe_centres(tuple(d["probe_grid"]), d["half_extent"])
    eye = np.array(d["camera_eye"])
    checked = 0
    drawn = d["probes_drawn"]["indices"]
    radius = (RADIUS_PER_SPACING * d["probes_drawn"]["stride"]
              * (2 * np.asarray(d["half_extent"]) / np.asarray(d["probe_grid"])).min())

    def hidden(i: int) -> bool:
        """Another drawn sphere lies on the ray from the eye to this probe's centre, before it."""
        ray = (centres[i] - eye) / np.linalg.norm(centres[i] - eye)
        t = (centres[drawn] - eye) @ ray
        miss = np.linalg.norm(centres[drawn] - eye - t[:, None] * ray, axis=1)
        return bool(np.any((t < t[drawn.index(i)] - 1e-9) & (miss < 1.05 * radius)))

    nearest = [i for i in np.argsort(np.linalg.norm(centres - eye, axis=1))
               if i in drawn and not hidden(i)]
    for i in nearest[:16]:  # nearest of those drawn that nothing hides
        px, py = d["probe_pixels"][i]
        if not (x0 + 5 < px < x0 + w - 5 and 40 < py < h - 5):
            continue
        normal = (eye - centres[i]) / np.linalg.norm(eye - centres[i])
        expected = srgb8(np.maximum(sh_evaluate(coeffs[i], normal), 0.0) * d["exposure"])
        got = image[int(py), int(px)]
        assert np.abs(got - expected).max() <= 12, (i, got, expected)
        checked += 1
    return checked


def test_pan_zoom_and_reset(run):
    out, _ = run
    orbited, moved = dump(out / "orbit.json"), dump(out / "pan_zoom.json")
    cam0, cam1 = orbited["scene"]["camera"], moved["scene"]["camera"]
    assert np.linalg.norm(np.subtract(cam1["target"], cam0["target"])) > 0.01   # right drag pans
    d0 = np.linalg.norm(np.subtract(cam0["eye"], cam0["target"]))
    d1 = np.linalg.norm(np.subtract(cam1["eye"], cam1["target"]))
    assert d1 == pytest.approx(d0 * orbit.ZOOM_PER_WHEEL_STEP ** 2)           # two wheel notches
    assert moved["bake_passes_run"] == orbited["bake_passes_run"]
    assert dump(out / "grid_over.json")["scene"]["camera"] == dump(out / "pt.json")["scene"]["camera"]


def test_probe_spheres_show_each_probes_sh_radiance(run):
    out, _ = run
    from radiance_probes.viewer.display import BACKGROUND
    alone = dump(out / "grid_alone.json")
    image = png(out / "grid_alone.png")
    assert alone["probe_view"] == "alone" and _sphere_colours_checked(image, alone) >= 4
    spheres = ~_is_background(view_pixels(image, alone), np.round(np.array(BACKGROUND) * 255))
    assert 0.05 < spheres.mean() < 0.9                         # spheres on an empty background
    over = dump(out / "grid_over.json")
    drawn = png(out / "grid_over.png")
    assert over["probe_view"] == "over" and _sphere_colours_checked(drawn, over) >= 4
    volume = view_pixels(png(out / "probes.png"), over)
    assert medium_difference(view_pixels(drawn, over), volume) > 1.0  # drawn over the volume


def test_probe_density_key_rebakes_a_finer_grid(run):
    out, _ = run
    d = dump(out / "finer.json")
    assert d["probe_grid"] == [6, 6, 6] and d["scene"]["probes"]["grid"] == [6, 6, 6]
    assert d["probes_ready"] and d["bake_passes_run"] > 1
    assert d["probe_bytes"] == PROBE_TEXTURES_G0 * 216 * 16


def test_light_and_transfer_function_edits(run):
    out, _ = run
    before, key = dump(out / "finer.json"), dump(out / "light_key.json")
    az0, el0 = angles_from_direction(before["scene"]["light"]["direction"])
    az1, el1 = angles_from_direction(key["scene"]["light"]["direction"])
    assert az1 == pytest.approx(az0 + 15.0) and el1 == pytest.approx(el0)
    slider = dump(out / "light_slider.json")
    assert angles_from_direction(slider["scene"]["light"]["direction"])[1] < el1 - 5.0
    opacity = dump(out / "opacity.json")["scene"]["transfer_function"]["opacity"]
    assert opacity[1][1] > 0.1 and opacity[0] == [0.0, 0.0] and opacity[2] == [1.0, 1.0]
    d = dump(out / "colormap.json")
    assert d["scene"]["transfer_function"]["colormap"] == "viridis"
    assert d["bakes_started"] > before["bakes_started"]         # light and TF changes re-bake
    assert np.abs(png(out / "edited.png") - png(out / "probes.png")).mean() > 1.0


def test_resize_drop_save_and_close(run):
    out, proc = run
    d = dump(out / "resized.json")
    assert d["window_size"] == [640, 480] and png(out / "resized.png").shape == (480, 640, 3)
    assert d["render_size"] == [round((640 - d["view_rect_framebuffer"][0]) * 0.5), 240]
    dropped = dump(out / "dropped.json")
    assert dropped["volume"] == {"name": "blob.npy", "dims": [20, 16, 12]}
    saved = load_scene(out / "viewer_scene.json")
    assert saved.volume.path.endswith("blob.npy") and saved.camera.width == d["render_size"][0]
    assert png(out / "screenshot.png").shape == (480, 640, 3)
    assert dump(out / "saved.json")["errors"] == []
    assert dump(out / "help.json")["show_help"]
    assert np.abs(png(out / "help.png") - png(out / "screenshot.png")).mean() > 1.0
    browsed = dump(out / "browsed.json")                       # the built-in file browser
    assert browsed["volume"]["dims"] == [24, 24, 24] and browsed["scene_path"].endswith("scene.json")
    nifti, folder = dump(out / "dropped_nifti.json"), dump(out / "dropped_folder.json")
    assert nifti["volume"] == {"name": "blob.nii.gz", "dims": [20, 16, 12]} and nifti["errors"] == []
    assert folder["volume"] == {"name": "stack", "dims": [10, 16, 12]} and folder["errors"] == []
    assert "release check:" in proc.stdout and ", 0 still alive" in proc.stdout


def test_unseen_volume_with_an_explicit_table_and_a_fine_probe_grid(display, tmp_path):
    """The issue's case: a head-like volume the viewer has not seen, an explicit RGBA transfer
    function that leaves the air transparent, the probe view at 32^3. The editor shows the
    table's own opacity, and the probe view draws the probes in the visible head only, so most
    of the picture is still the volume."""
    from radiance_probes.scene.transfer import opacity_points
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (40, 48, 40)), indexing="ij")
    r = np.sqrt(x * x + (y / 1.1) ** 2 + z * z)
    head = np.where(r < 0.7, 0.55 + 0.3 * (r < 0.6), 0.02 * np.cos(9 * x) ** 2)
    np.save(tmp_path / "head.npy", head.astype(np.float32))
    d = np.linspace(0, 1, 64)
    rows = [[float(v), float(v) * 0.8, 0.7, float(np.clip((v - 0.3) * 2.5, 0, 1) * 0.8)] for v in d]
    scene = {"volume": {"path": "head.npy"}, "transfer_function": {"rgba": rows},
             "camera": {"width": 64, "height": 64}, "density_scale": 40}
    (tmp_path / "head.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"until": "baked"}, {"frames": 2}, {"dump": "over.json"}, {"screenshot": "over.png"},
        {"key": "g"}, {"frames": 2}, {"dump": "alone.json"}, {"screenshot": "alone.png"},
        {"click": "Empty-space skipping"}, {"until": "baked"}, {"dump": "global.json"},
        {"close": True}])
    view(["head.json", "--script", str(script), "--method", "raymarch", "--probe-view",
          "--probe-grid", "32", "--probe-samples", "1", "--window", "640x400"], tmp_path, display)
    over, alone = dump(tmp_path / "over.json"), dump(tmp_path / "alone.json")
    expected, _ = opacity_points(load_scene(tmp_path / "head.json").transfer_function)
    assert [tuple(p) for p in over["opacity_points"]] == [tuple(p) for p in expected]
    assert over["opacity_points"] != [[0.0, 0.0], [1.0, 1.0]] and len(expected) <= 6
    drawn = alone["probes_drawn"]
    assert drawn["total"] == math.prod(alone["probe_grid"]) and max(alone["probe_grid"]) == 32
    assert 0 < drawn["visible"] < drawn["total"] and drawn["stride"] >= 1
    assert len(drawn["indices"]) <= min(drawn["visible"], 4096)
    from radiance_probes.viewer.display import BACKGROUND
    image = view_pixels(png(tmp_path / "alone.png"), alone)
    covered = ~_is_background(image, np.round(np.array(BACKGROUND) * 255))
    assert 0.02 < covered.mean() < 0.5, covered.mean()   # a lattice in the head, not a wall
    # the Render panel's switch: one global majorant; the probes re-bake (their key holds it)
    switched = dump(tmp_path / "global.json")
    assert over["empty_space_skipping"] and not switched["empty_space_skipping"]
    assert switched["bakes_started"] == over["bakes_started"] + 1 and switched["probes_ready"]


def test_gather_slider_regathers_without_a_rebake(display, tmp_path):
    """The Render panel's "Gather at event" (probes): dragging it right reads the probes at a later
    event; the image starts again, the probes stay, and the picture changes."""
    scene = {"volume": {"builtin": "cloud", "size": [16, 12, 14]}, "density_scale": 30.0,
             "camera": {"width": 48, "height": 48}, "probes": {"grid": [3, 3, 3], "samples": 16}}
    (tmp_path / "cloud.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"until": "done"}, {"dump": "first.json"}, {"screenshot": "first.png"},
        {"drag": "Gather at event", "by": [200, 0]}, {"until": "done"}, {"dump": "later.json"},
        {"screenshot": "later.png"}, {"close": True}])
    view(["cloud.json", "--script", str(script), "--method", "probes", "--spp", "8",
          "--window", "640x400"], tmp_path, display)
    first, later = dump(tmp_path / "first.json"), dump(tmp_path / "later.json")
    assert first["gather_event"] == 1 and later["gather_event"] > 1
    assert later["bakes_started"] == first["bakes_started"] and later["probes_ready"]
    assert later["samples"] == {"probes": 8}
    a = view_pixels(png(tmp_path / "first.png"), first)
    b = view_pixels(png(tmp_path / "later.png"), later)
    assert np.abs(a.astype(float) - b).mean() > 0.2


def test_ct_series_with_a_window_and_its_level_dragged(display, tmp_path):
    """A DICOM CT series opened through its scene with the bone window: the panel shows the
    window, and dragging its level re-normalises the volume (the scene's window changes, no
    error)."""
    from test_volume_formats import write_dicom_series
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (10, 12, 14)), indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    hu = np.where(r < 0.5, 1200, np.where(r < 0.8, 40, -1000)).astype(np.int16)
    write_dicom_series(tmp_path / "ct", hu)
    scene = {"volume": {"path": "ct", "window": "bone"}, "camera": {"width": 48, "height": 48},
             "transfer_function": {"colormap": "grey", "opacity": [[0, 0], [0.5, 0], [1, 1]]}}
    (tmp_path / "ct.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"frames": 2}, {"dump": "before.json"},
        {"drag": "Level", "by": [-40, 0]}, {"frames": 2}, {"dump": "after.json"},
        {"close": True}])
    view(["ct.json", "--script", str(script), "--method", "raymarch", "--window", "640x400"],
         tmp_path, display)
    before, after = dump(tmp_path / "before.json"), dump(tmp_path / "after.json")
    assert before["errors"] == [] and after["errors"] == []
    assert before["volume"] == {"name": "ct", "dims": [14, 12, 10]}
    assert before["scene"]["volume"]["window"] == {"level": 400.0, "width": 1800.0}
    level, width = after["scene"]["volume"]["window"].values()
    assert level < 400.0 and width == 1800.0


def test_dicom_folder_lists_its_series_and_another_is_picked(display, tmp_path):
    """A folder of two DICOM series opens the larger with a note; the Data panel lists both, and
    clicking the other loads it (the volume's size follows, no error). The patient orientation
    radio reloads it turned."""
    from test_volume_formats import write_dicom_series
    write_dicom_series(tmp_path / "study" / "a", np.arange(4 * 4 * 5, dtype=np.int16).reshape(4, 4, 5),
                       uid="1.2.3.50", description="Axial")
    write_dicom_series(tmp_path / "study" / "b", np.arange(2 * 6 * 6, dtype=np.int16).reshape(2, 6, 6),
                       uid="1.2.3.51", description="Small", seed=5)
    script = write_script(tmp_path / "s.json", [
        {"click": "Data"}, {"frames": 2}, {"dump": "first.json"},
        {"click": "series 2"}, {"frames": 2}, {"dump": "second.json"},
        {"click": "orientation patient"}, {"frames": 2}, {"dump": "turned.json"}, {"close": True}])
    proc = view(["study", "--script", str(script), "--method", "raymarch", "--window", "640x400"],
                tmp_path, display)
    assert "holds 2 DICOM series" in proc.stderr
    first, second = dump(tmp_path / "first.json"), dump(tmp_path / "second.json")
    turned = dump(tmp_path / "turned.json")
    assert first["dicom_series"] == 1 and first["volume"]["dims"] == [5, 4, 4]
    assert "series 1" in first["widgets"] and "series 2" in first["widgets"]
    assert second["errors"] == [] and second["dicom_series"] == 2
    assert second["volume"]["dims"] == [6, 6, 2]
    assert second["scene"]["volume"]["series"] == "1.2.3.51"
    # axial slices (x left, y posterior, z superior): patient order puts z on y, y on z
    assert turned["errors"] == [] and turned["volume"]["dims"] == [6, 2, 6]


def test_cli_screenshot_starts_its_own_display(display, tmp_path):
    """`view SCENE --screenshot --frames N --method M --probe-view` with no DISPLAY at all: the
    viewer runs in its own Xvfb and saves the window's image. (`display` only skips the test
    where Xvfb is missing; this run does not use it.)"""
    (tmp_path / "scene.json").write_text(json.dumps(SCENE))
    proc = view(["scene.json", "--screenshot", "shot.png", "--frames", "3", "--method", "probes",
                 "--probe-view", "--window", "640x400"], tmp_path, display=None)
    assert "private Xvfb" in proc.stderr
    image = png(tmp_path / "shot.png")
    assert image.shape == (400, 640, 3)
    picture = image[40:, 400:]
    assert len(np.unique(picture.reshape(-1, 3), axis=0)) > 100  # volume and shaded spheres


def test_cli_screenshot_after_too_few_frames_is_a_whole_image(display, tmp_path):
    """Issue 55: `view ct.npy --method raymarch --screenshot out.png --frames N` on llvmpipe
    saved the first frame 70% done (its bottom black) and said nothing. After one frame (which
    does a band of one tile: it pays for the compile) the screenshot waits for the frame in
    bands and says so in one line; the picture has no unrendered pixel."""
    z, y, x = np.mgrid[:32, :32, :32]
    hu = np.where(np.sqrt((x - 16) ** 2 + (y - 16) ** 2 + (z - 16) ** 2) < 13, 40, -1000)
    np.save(tmp_path / "ct.npy", hu.astype(np.int16))
    proc = view(["ct.npy", "--method", "raymarch", "--screenshot", "out.png", "--frames", "1",
                 "--window", "640x400"], tmp_path, display)
    lines = [line for line in proc.stderr.splitlines() if "whole image" in line]
    assert len(lines) == 1 and "more frames" in lines[0] and "partial" not in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and "wrote" in proc.stdout
    picture = png(tmp_path / "out.png")[40:, 400:]
    assert not (picture.max(axis=-1) < 8).any()   # the background's grey or the volume, never black


def test_shader_error_is_shown_not_a_crash(display, tmp_path):
    glsl = tmp_path / "glsl"
    from radiance_probes.paths import GLSL_DIR
    shutil.copytree(GLSL_DIR, glsl)
    frag = glsl / "probe_sphere.frag"
    frag.write_text(frag.read_text().replace("frag_colour = vec4(", "frag_colour = vec5("))
    (tmp_path / "scene.json").write_text(json.dumps(SCENE))
    script = write_script(tmp_path / "s.json", [{"frames": 3}, {"dump": "d.json"}, {"screenshot": "s.png"}])
    proc = view(["scene.json", "--script", str(script), "--probe-view", "--window", "640x400"],
                tmp_path, display, harness=["--glsl", str(glsl)])
    d = dump(tmp_path / "d.json")
    assert any("probe_sphere" in e and "spheres" in e for e in d["errors"]), d["errors"]
    assert "error shown in the window" in proc.stderr
    image = png(tmp_path / "s.png")
    panel = image[120:, 300:]
    assert ((panel[..., 0] > 100) & (panel[..., 1] < 60)).sum() > 200   # the red error panel
    assert d["samples"]["pt"] >= 1                              # and the volume kept rendering


def test_no_display_falls_back_to_a_headless_render(tmp_path):
    scene = dict(SCENE, camera={"width": 24, "height": 24})
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    proc = view(["scene.json", "--spp", "2"], tmp_path, display=None)
    assert "no display available" in proc.stderr and "headless" in proc.stderr
    assert (tmp_path / "view.png").is_file() and "wrote" in proc.stdout


def test_environment_map_shows_rotates_and_goes_back_to_a_colour(display, tmp_path):
    """A scene with an environment map: the map is the background, the Light panel's rotation
    slider turns it (the picture changes, the scene's rotation follows), and the constant-colour
    button goes back to the scene's colour."""
    h = 16
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    img = np.zeros((h, 2 * h, 3), np.float32)
    img[...] = np.stack([0.2 + 0.6 * u, 0.3 + 0.0 * u, 0.8 - 0.6 * u], -1)[None]   # varies along u
    np.save(tmp_path / "sky.npy", img)
    scene = {**SCENE, "environment": {"map": "sky.npy", "scale": 1.0, "rotation": 0.0}}
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    steps = [{"until": "done"}, {"screenshot": "map.png"}, {"dump": "map.json"},
             {"drag": "Environment rotation", "by": [25, 0]}, {"until": "done"},
             {"screenshot": "turned.png"}, {"dump": "turned.json"},
             {"click": "Constant environment"}, {"until": "done"}, {"dump": "constant.json"},
             {"close": True}]
    script = write_script(tmp_path / "script.json", steps)
    view(["scene.json", "--script", str(script), "--window", "720x800", "--spp", str(SPP),
          "--render-scale", "0.5"], tmp_path, display)
    d0, d1, d2 = (dump(tmp_path / f"{n}.json") for n in ("map", "turned", "constant"))
    assert d0["errors"] == [] and d1["errors"] == []
    assert d0["scene"]["environment"] == {"map": "sky.npy", "scale": 1.0, "rotation": 0.0}
    assert 10.0 < d1["scene"]["environment"]["rotation"] <= 180.0
    picture0 = view_pixels(png(tmp_path / "map.png"), d0)
    picture1 = view_pixels(png(tmp_path / "turned.png"), d1)
    # The background is the map (red and blue trade places along u), not the default grey.
    assert not _is_background(picture0, ENVIRONMENT_SRGB, tol=12).any()
    assert np.abs(picture1 - picture0).mean() > 3.0
    assert d2["scene"]["environment"] == [0.1, 0.1, 0.1]


def test_probe_view_shows_where_an_adaptive_layout_put_the_probes(display, tmp_path):
    """A dense slab across y and an adaptive layout: the spheres sit at the adaptive planes (the
    bake's probe_position), none at the uniform grid's outer y planes, which it moved inwards."""
    d = np.full((16, 16, 16), 0.1, np.float32)
    d[:, 7:9, :] = 1.0
    np.save(tmp_path / "slab.npy", d)
    scene = {"volume": {"path": "slab.npy"}, "density_scale": 40,
             "transfer_function": {"rgba": [[1, 1, 1, 0], [1, 1, 1, 1]]},
             "camera": {"eye": [0.0, 0.1, 1.6], "target": [0, 0, 0], "width": 64, "height": 64},
             "probes": {"grid": 4, "samples": 16, "fit": "box", "layout": "adaptive",
                        "adaptive_strength": 1.0}}
    (tmp_path / "slab.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"until": "baked"}, {"key": "g"}, {"frames": 2}, {"dump": "alone.json"},
        {"screenshot": "alone.png"}, {"close": True}])
    view(["slab.json", "--script", str(script), "--method", "raymarch", "--probe-view",
          "--window", "640x400"], tmp_path, display)
    alone = dump(tmp_path / "alone.json")
    planes = alone["probe_planes"]
    assert alone["probes_ready"] and planes is not None
    y = np.asarray(planes[1])
    assert y.min() > 0.2 and y.max() < 0.8            # drawn towards the slab
    from radiance_probes.viewer.display import BACKGROUND
    image = png(tmp_path / "alone.png")
    background = np.round(np.array(BACKGROUND) * 255)
    pixels = np.asarray(alone["probe_pixels"])
    assert len(pixels) == 64
    x0, _, rw, rh = alone["view_rect_framebuffer"]
    top = image.shape[0] - rh

    def in_view(px, py):
        return x0 + 3 < px < x0 + rw - 3 and top + 40 < py < image.shape[0] - 3

    shown = [~_is_background(image[int(py), int(px)][None], background)[0]
             for px, py in pixels if in_view(px, py)]
    assert len(shown) >= 16 and np.mean(shown) > 0.8   # spheres where the probes are
    # where the uniform grid's outer y planes would have put spheres: background
    uniform = probe_centres(tuple(alone["probe_grid"]), alone["half_extent"])
    outer = np.isclose(np.abs(uniform[:, 1]), 0.375)
    w, h = alone["render_size"]
    cam = alone["scene"]["camera"]
    matrix = orbit.view_projection(camera_frame(replace(
        CameraSpec(), eye=tuple(cam["eye"]), target=tuple(cam["target"]), up=tuple(cam["up"]),
        fov_y=cam["fov_y"]), w, h))
    checked = 0
    for px, py in orbit.project(matrix, uniform[outer], w, h).tolist():
        fx, fy = x0 + px / w * rw, top + py / h * rh
        if in_view(fx, fy):
            assert _is_background(image[int(fy), int(fx)][None], background)[0]
            checked += 1
    assert checked >= 8


def test_channel_panels_switch_a_channel_and_drag_its_window(display, tmp_path):
    """A volume of three channels: one panel a channel; switching channel 1 off and dragging
    channel 0's window level edit only those channels (no error), and the picture changes."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (12, 12, 12)), indexing="ij")
    blobs = [np.clip(1.0 - 2.5 * np.sqrt((x - cx) ** 2 + y ** 2 + z ** 2), 0, 1)
             for cx in (-0.45, 0.0, 0.45)]
    np.save(tmp_path / "three.npy", (1000 * np.stack(blobs)).astype(np.uint16))
    scene = {"volume": {"path": "three.npy", "axes": "czyx"},
             "channels": [{"name": "left", "window": {"level": 500, "width": 1000}},
                          {"name": "middle"}, {"name": "right"}],
             "density_scale": 40, "camera": {"width": 48, "height": 48}}
    (tmp_path / "three.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"frames": 3}, {"dump": "before.json"}, {"screenshot": "before.png"},
        {"click": "channel 1 shown"}, {"frames": 3}, {"dump": "off.json"},
        {"screenshot": "off.png"},
        {"drag": "channel 0 Level", "by": [60, 0]}, {"frames": 2}, {"dump": "level.json"},
        {"close": True}])
    view(["three.json", "--script", str(script), "--method", "raymarch", "--window", "900x800"],
         tmp_path, display)
    before, off, level = (dump(tmp_path / f"{n}.json") for n in ("before", "off", "level"))
    assert before["errors"] == [] and off["errors"] == [] and level["errors"] == []
    assert [c["enabled"] for c in before["scene"]["channels"]] == [True, True, True]
    assert [c["enabled"] for c in off["scene"]["channels"]] == [True, False, True]
    assert off["scene"]["channels"][0] == before["scene"]["channels"][0]
    moved = level["scene"]["channels"][0]["window"]
    assert moved["level"] > 500.0 and moved["width"] == 1000.0
    assert level["scene"]["channels"][1:] == off["scene"]["channels"][1:]
    assert np.abs(png(tmp_path / "off.png") - png(tmp_path / "before.png")).mean() > 0.5


def test_time_series_plays_steps_and_pauses(display, tmp_path):
    """A 4-step series: the Time panel's play button plays it (the step shown changes, each a
    warm restart of the bake, no undo step), '.' steps on and pauses, the slider sets a step."""
    from test_time_series import moving_blob
    np.save(tmp_path / "series.npy", moving_blob(steps=4))
    scene = {"volume": {"path": "series.npy", "axes": "tzyx"}, "density_scale": 40,
             "camera": {"width": 48, "height": 48}, "probes": {"grid": 4, "samples": 16}}
    (tmp_path / "series.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"frames": 2}, {"dump": "start.json"}, {"screenshot": "start.png"},
        # (a step each 0.1 s of wall time: frames enough to span that on a fast machine too; 4
        # frames of llvmpipe once took less)
        {"click": "Play"}, {"frames": 10}, {"dump": "playing.json"},
        {"key": "."}, {"frames": 2}, {"dump": "stepped.json"},
        {"drag": "Time step", "by": [-400, 0]}, {"frames": 1}, {"dump": "slider.json"},
        {"close": True}])
    # (an eighth of the pixels: on llvmpipe every step played restarts the image, and a quarter
    # took 2.6 s a frame)
    view(["series.json", "--script", str(script), "--method", "raymarch", "--window", "900x640",
          "--render-scale", "0.125"], tmp_path, display)
    start, playing, stepped, slider = (dump(tmp_path / f"{n}.json")
                                       for n in ("start", "playing", "stepped", "slider"))
    assert all(d["errors"] == [] for d in (start, playing, stepped, slider))
    assert start["volume"]["time_steps"] == 4 and start["volume"]["time"] == 0
    assert playing["playing"] and playing["bakes_started"] > start["bakes_started"]
    assert playing["undo_steps"] == 0                      # playing is not an edit
    assert not stepped["playing"]
    assert stepped["volume"]["time"] == (playing["volume"]["time"] + 1) % 4
    assert stepped["scene"].get("time", 0) == stepped["volume"]["time"]
    assert slider["scene"].get("time", 0) == 0 and slider["volume"]["time"] == 0
    assert "Time step" in start["widgets"]


def test_refine_shows_the_raymarcher_at_once_after_an_edit_then_guided(display, tmp_path):
    """Key 5 (refine) in the real window: after the switch and after an orbit, the first frame
    shows the raymarcher's image and later frames guided's (its caption with the error estimated
    from the halves); the estimate's read-backs are fewer than the frames."""
    scene = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
             "albedo": 0.9, "camera": {"width": 48, "height": 48},
             "probes": {"grid": [2, 2, 2], "samples": 64, "fit": "box"}}
    (tmp_path / "cloud.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"key": "5"}, {"until": "done"}, {"dump": "first.json"},
        {"screenshot": "first.png"},
        {"drag": {"view": [0.5, 0.5]}, "by": [40, 0]}, {"until": "done"}, {"dump": "orbit.json"},
        {"screenshot": "orbit.png"}, {"close": True}])
    view(["cloud.json", "--script", str(script), "--spp", "128", "--window", "640x400",
          "--render-scale", "0.125"],
         tmp_path, display)
    first, orbit = dump(tmp_path / "first.json"), dump(tmp_path / "orbit.json")
    for d in (first, orbit):
        assert d["method"] == "refine" and not d["errors"]
        st = d["refine"]
        assert st["shown"] == "guided" and st["guided_samples"] == 128
        assert st["shown_frames"][0] == "raymarch"                 # at once after the edit
        assert "guided" in st["shown_frames"]                      # later frames: guided
        k = st["shown_frames"].index("guided")
        assert set(st["shown_frames"][:k]) == {"raymarch"} and set(st["shown_frames"][k:]) == {"guided"}
        est = st["estimated_rrmse"]
        assert 0 < est["guided"] < 0.5 and st["reads"] < st["frames"]
        assert "guided 128 spp, est. error" in d["labels"]["refine"]
        assert d["samples"] == {"refine": 128}
        # the frame before the dump, named part by part (app/viewer/frame/frame_parts.py)
        assert {"display", "imgui", "swap"} <= set(d["frame_parts"])
        assert all(wall >= 0.0 for _, wall in d["frame_parts"].values())
    assert orbit["restarts"] > first["restarts"] and orbit["bakes_started"] == first["bakes_started"]
    assert orbit["scene"]["camera"]["eye"] != first["scene"]["camera"]["eye"]
    a = view_pixels(png(tmp_path / "first.png"), first)
    b = view_pixels(png(tmp_path / "orbit.png"), orbit)
    assert np.abs(a.astype(float) - b).mean() > 0.2                # the orbit's other image


def test_large_zarr_store_opens_on_a_thread_behind_its_preview(display, tmp_path):
    """A Zarr store read brick by brick (forced here: the harness lowers the size that makes a
    store "large") opens with a small level of it shown, the Volume panel saying how far the
    loading is; the store itself replaces it once its bricks are written."""
    import importlib.util
    from conftest import ROOT
    spec = importlib.util.spec_from_file_location("brick_bench", ROOT / "lab" / "experiments" / "brick_bench.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("brick_bench", bench)
    spec.loader.exec_module(bench)
    bench.write_ome_zarr(tmp_path / "big.zarr", (40, 32, 24), 8, 3)
    scene = {"volume": {"path": "big.zarr"}, "density_scale": 30,
             "camera": {"width": 48, "height": 48}, "probes": {"grid": 4, "samples": 16}}
    (tmp_path / "big.json").write_text(json.dumps(scene))
    script = write_script(tmp_path / "s.json", [
        {"dump": "start.json"}, {"until": "loaded", "max_frames": 2000}, {"frames": 2},
        {"dump": "loaded.json"}, {"close": True}])
    view(["big.json", "--script", str(script), "--method", "raymarch", "--window", "900x640",
          "--render-scale", "0.25", "--volume-memory", "64M"], tmp_path, display,
         harness=["--lazy-bytes", "1", "--open-delay", "1.0"])   # the first dump sees it loading
    start, loaded = dump(tmp_path / "start.json"), dump(tmp_path / "loaded.json")
    assert start["errors"] == [] and loaded["errors"] == []
    assert start["volume"]["dims"] == [20, 16, 12] and "preview" in start["volume_notes"][0]
    assert start["opening"] is not None and "loading big.zarr" in start["opening"]
    assert loaded["opening"] is None and loaded["volume"]["dims"] == [40, 32, 24]
    assert not any("preview" in n for n in loaded["volume_notes"])
    assert any(m.startswith("loaded big.zarr in") for m in loaded["messages"])
    np.testing.assert_allclose(loaded["half_extent"], start["half_extent"])
    assert loaded["settings"]["volume_memory_bytes"] == 64 << 20      # view --volume-memory


def test_a_file_opened_is_read_on_a_thread_while_the_window_draws(display, tmp_path):
    """Opening a file in the window (a drop, the file dialogs, the Data panel): it is read and
    made ready for the GPU on a thread (app/viewer/opening.py; the harness holds it back until
    the first dump is written) while
    the scene shown keeps drawing and the Data panel says how far; the volume shows once read,
    and a file that cannot be read says why, the scene shown kept."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (12, 16, 20)), indexing="ij")
    np.save(tmp_path / "blob.npy", np.clip(1.2 - 2 * np.sqrt(x * x + y * y + z * z), 0, 1))
    (tmp_path / "bad.npy").write_text("not an array")
    script = write_script(tmp_path / "s.json", [
        {"frames": 1}, {"drop": ["blob.npy"], "wait": False}, {"frames": 3},
        {"dump": "loading.json"}, {"until": "loaded", "max_frames": 5000}, {"frames": 1},
        {"dump": "loaded.json"}, {"drop": ["bad.npy"]}, {"frames": 1}, {"dump": "bad.json"},
        {"close": True}])
    view(["--script", str(script), "--window", "640x480", "--render-scale", "0.25",
          "--spp", "4"], tmp_path, display,
         harness=["--load-after", str(tmp_path / "loading.json")])
    loading, loaded, bad = (dump(tmp_path / f"{n}.json") for n in ("loading", "loaded", "bad"))
    assert loading["loading"].startswith("opening ") and "blob.npy" in loading["loading"]
    assert loading["volume"]["name"].startswith("builtin") and loading["errors"] == []
    assert loaded["loading"] is None and loaded["errors"] == []
    assert loaded["volume"] == {"name": "blob.npy", "dims": [20, 16, 12]}
    assert loading["frame"] >= 5 and loaded["frame"] > loading["frame"]   # drawn while read
    assert any(m.startswith("opened ") and "blob.npy" in m for m in loaded["messages"])
    assert bad["volume"]["name"] == "blob.npy" and bad["loading"] is None
    assert any("could not open" in e and "bad.npy" in e for e in bad["errors"]), bad["errors"]
