"""The napari plugin (app/napari_plugin/, docs/napari.md) in a real napari viewer on a private
Xvfb (Mesa llvmpipe): its image against radiance_probes.render of the same array, camera and
window; the camera mapping against napari's own projection (vispy's view transform); bad layers;
a camera move re-rendering off napari's event loop; the manifest, sample data and imports."""
from __future__ import annotations

import ast
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CANVAS = (300, 240)      # napari's window is sized so its canvas is small (llvmpipe)


def _release_current_egl_context() -> None:
    """No EGL context current on this thread: the suite's session context (conftest.py makes it
    current for every test) would take the GL calls of napari's GLX context (libglvnd dispatches
    by the current context), and vispy's first query then fails."""
    import ctypes
    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return
    egl.eglGetCurrentContext.restype = ctypes.c_void_p
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    if egl.eglGetCurrentContext():
        egl.eglMakeCurrent(egl.eglGetCurrentDisplay(), None, None, None)


@pytest.fixture(autouse=True)
def _no_egl_context_current():
    """After conftest's per-test fixture has made the session context current (autouse fixtures
    of a test module run after conftest's)."""
    _release_current_egl_context()
    yield


@pytest.fixture(scope="module")
def napari_env(display):
    """napari's Qt on the session's Xvfb (GLX through llvmpipe): Qt's offscreen platform has no
    OpenGL for vispy."""
    old = {k: os.environ.get(k) for k in ("DISPLAY", "QT_QPA_PLATFORM")}
    _release_current_egl_context()   # (the module's fixtures run before the tests' own)
    os.environ["DISPLAY"] = display
    os.environ["QT_QPA_PLATFORM"] = "xcb"
    yield display
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture(scope="module")
def viewer(napari_env):
    import napari
    v = napari.Viewer(show=True)
    v.window._qt_window.resize(620, 420)
    yield v
    v.close()


def cam(viewer):
    from radiance_probes.napari_plugin.camera_map import napari_camera
    return napari_camera(viewer)


def process(seconds: float = 0.2) -> None:
    from qtpy.QtWidgets import QApplication
    app = QApplication.instance()
    end = time.monotonic() + seconds
    while True:
        app.processEvents()
        if time.monotonic() >= end:
            return
        time.sleep(0.01)


def wait_for(predicate, timeout: float = 240.0) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, "timed out"
        process(0.02)


def render_to_end(widget, samples: int, scale: float, method: str | None = None) -> None:
    """The widget's render, started and waited for to its last sample, with no problem shown."""
    if method is not None:
        widget.method.setCurrentText(method)
    widget.samples.setValue(samples)
    widget.render_scale.setValue(scale)
    widget.start()
    wait_for(lambda: done(widget))
    assert not widget.problem, widget.message


def smooth_volume(shape=(20, 24, 28), seed=1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    blob = np.exp(-((x - 0.2) ** 2 + (y + 0.1) ** 2 * 2 + z ** 2) * 3)
    return (blob * 1000 + rng.normal(0, 20, shape)).astype(np.float32)


@pytest.fixture
def fresh(viewer):
    viewer.layers.clear()
    viewer.dims.ndisplay = 3
    yield viewer
    viewer.layers.clear()


def make_widget(viewer):
    from radiance_probes.napari_plugin.widget import GlobalIlluminationWidget
    w = GlobalIlluminationWidget(viewer)
    viewer.window.add_dock_widget(w, name="Global illumination")
    process(0.3)
    return w


def done(widget) -> bool:
    f = widget.last_frame
    return widget.problem or (f is not None and f.stage == "done"
                              and f.serial == widget._engine.latest)


def rrmse(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


# ---- (a) the plugin's image is render()'s ----------------------------------------------------------

def test_plugin_image_matches_render_of_the_same_array(fresh, tmp_path):
    import radiance_probes
    from radiance_probes.napari_plugin.camera_map import camera_from_viewer
    from radiance_probes.napari_plugin.overlay import canvas_size
    viewer = fresh
    data = smooth_volume()
    viewer.add_image(data, scale=(1.5, 1.0, 0.8), translate=(4, -2, 1), contrast_limits=(100, 900),
                     colormap="viridis", gamma=0.8, opacity=0.9)
    cam(viewer).angles = (15, -30, 70)
    cam(viewer).perspective = 30
    cam(viewer).zoom = cam(viewer).zoom * 1.1
    widget = make_widget(viewer)
    try:
        render_to_end(widget, 2, 0.25, "raymarch")
        frame = widget.last_frame
        request = widget._request
        # the camera and window it maps to, from napari's model as it stands
        w, h = canvas_size(viewer)
        camera = camera_from_viewer(viewer, w, h, widget._layer_scene().placement, 0.25)
        assert camera == request.camera
        assert request.options["value_range"] == [100.0, 900.0]
        expected = radiance_probes.render(widget._layer_scene().data, "raymarch", 2, seed=0,
                                          camera=camera, **request.options)
        assert frame.image.shape == expected.linear.shape == (camera["height"], camera["width"], 3)
        assert expected.linear.mean() > 0.01   # the volume is in view, not only the background
        assert rrmse(frame.image, expected.linear) < 0.01
        # the saved scene renders the same from the command line's loader
        scene = widget.save_scene(str(tmp_path / "scene.json"))
        again = radiance_probes.render(str(scene), "raymarch", 2, seed=0)
        assert rrmse(again.linear, expected.linear) < 0.01
        # a turntable through `animate`, in a process of its own (two frames here)
        movie = widget.record_turntable(str(tmp_path / "turn.mp4"), frames=2)
        assert movie.wait(300) == 0, movie.stderr.read()
        wait_for(lambda: widget._movie is None, 30)
        assert "Turntable written" in widget.message and (tmp_path / "turn.mp4").stat().st_size > 0
        assert widget.save_image(str(tmp_path / "shot.png")).stat().st_size > 0
        assert widget.save_image(str(tmp_path / "shot.exr")).stat().st_size > 0
        assert widget.save_image(str(tmp_path / "shot.tif")) is None and widget.problem
    finally:
        widget.close_engine()


def test_visible_layers_become_channels_rendered_as_render_does(fresh):
    import radiance_probes
    viewer = fresh
    data = smooth_volume((16, 18, 20))
    viewer.add_image(data, contrast_limits=(100, 900), colormap="green", name="a")
    viewer.add_image(data[:, ::-1].copy(), contrast_limits=(50, 700), colormap="magenta",
                     opacity=0.5, name="b")
    viewer.add_image(data, name="hidden", visible=False)
    cam(viewer).angles = (5, 20, 40)
    widget = make_widget(viewer)
    try:
        render_to_end(widget, 1, 0.2)
        request = widget._request
        channels = request.options["channels"]
        assert [c["name"] for c in channels] == ["a", "b"]          # the hidden layer is not
        assert [c["value_range"] for c in channels] == [[100.0, 900.0], [50.0, 700.0]]
        assert max(row[3] for row in channels[1]["transfer_function"]["rgba"]) == 0.5
        expected = radiance_probes.render(widget._layer_scene().data,
                                          "raymarch", 1, seed=0, camera=request.camera,
                                          **request.options)
        assert rrmse(widget.last_frame.image, expected.linear) < 0.01
    finally:
        widget.close_engine()


def test_estimated_error_of_a_mean_from_its_halves():
    """engine.half_error: for independent halves of known noise the estimate is the mean's true
    rRMSE (within a few percent, 2e5 pixels)."""
    from radiance_probes.napari_plugin.engine import half_error
    rng = np.random.default_rng(0)
    truth = np.full((200, 1000, 1), 2.0)
    even, odd = (truth + rng.normal(0, 0.3, truth.shape) for _ in range(2))
    mean = (even + odd) / 2
    true_error = np.sqrt(np.mean((mean - truth) ** 2)) / np.sqrt(np.mean(truth ** 2))
    assert abs(half_error(even, odd, mean) / true_error - 1) < 0.03
    assert half_error(np.zeros(4), np.zeros(4), np.zeros(4)) is None


# ---- (b) the camera mapping against napari's own projection -----------------------------------------

def napari_pixels(viewer, layer, indices) -> np.ndarray:
    """Where napari draws the voxels' centres: napari's data-to-world, then vispy's view
    transform (scene -> canvas pixels) as napari's canvas holds it."""
    canvas = viewer.window._qt_viewer.canvas
    world = np.array([layer.data_to_world(i) for i in indices])          # z, y, x
    scene = np.column_stack([world[:, ::-1], np.ones(len(world))])       # vispy's x, y, z
    mapped = canvas.view.scene.transform.map(scene)
    return mapped[:, :2] / mapped[:, 3:4]


def our_pixels(camera: dict, points) -> np.ndarray:
    """Where our pinhole camera (app/twins/camera.py's frame, inverted) puts world points."""
    from radiance_probes.scene.types import CameraSpec
    from radiance_probes.twins.camera import camera_frame
    spec = CameraSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in camera.items()})
    f = camera_frame(spec)
    d = np.asarray(points, np.float64) - f.eye
    t = d @ f.forward
    nx = (d @ f.right) / (t * float(f.right @ f.right))
    ny = (d @ f.up) / (t * float(f.up @ f.up))
    return np.column_stack([(nx + 1) * f.width / 2, (1 - ny) * f.height / 2])


@pytest.mark.parametrize("perspective", [0.0, 40.0])
def test_camera_mapping_matches_napari_view(fresh, perspective):
    from radiance_probes.napari_plugin.camera_map import camera_from_viewer, camera_to_napari
    from radiance_probes.napari_plugin.layers import layer_scene
    from radiance_probes.napari_plugin.overlay import canvas_size
    viewer = fresh
    shape = (10, 14, 18)
    layer = viewer.add_image(np.zeros(shape, np.float32), scale=(3.0, 1.0, 0.5),
                             translate=(5.0, -7.0, 2.0))
    corners = [(k, j, i) for k in (0, shape[0] - 1) for j in (0, shape[1] - 1)
               for i in (0, shape[2] - 1)] + [(3, 5, 11), (7, 2, 4)]
    for angles in [(0.0, 0.0, 90.0), (20.0, -35.0, 60.0), (-50.0, 25.0, 150.0)]:
        cam(viewer).angles = angles
        cam(viewer).perspective = perspective
        cam(viewer).center = (16.0, -1.0, 6.0)
        process(0.2)
        w, h = canvas_size(viewer)
        placement = layer_scene(viewer).placement
        # our world places the voxel centres where napari's world does
        ours = placement.voxel_to_ours(np.array(corners))
        mapped = placement.point_to_ours(np.array([layer.data_to_world(c) for c in corners]))
        assert np.allclose(ours, mapped, atol=1e-9)
        camera = camera_from_viewer(viewer, w, h, placement)
        theirs = napari_pixels(viewer, layer, corners)
        assert np.ptp(theirs[:, 0]) > 0.2 * w      # the box spans much of the canvas
        tolerance = 0.6 if perspective else 1.0    # orthographic: ORTHO_FOV_DEG's narrow pinhole
        assert np.abs(our_pixels(camera, ours) - theirs).max() < tolerance, angles
        # and back: our camera set on napari's camera shows the voxels where ours does
        back = camera_to_napari(camera, placement, perspective)
        cam(viewer).angles = (0.0, 0.0, 0.0)
        cam(viewer).center = back["center"]
        cam(viewer).zoom = back["zoom"]
        cam(viewer).perspective = back["perspective"]
        cam(viewer).set_view_direction(back["view_direction"], back["up_direction"])
        process(0.2)
        assert np.allclose(cam(viewer).angles, angles, atol=1e-6) or np.allclose(
            napari_pixels(viewer, layer, corners), theirs, atol=0.1)
        assert np.abs(napari_pixels(viewer, layer, corners) - theirs).max() < 0.1


# ---- (c) bad layers --------------------------------------------------------------------------------

def test_bad_layers_get_a_message_not_a_traceback(fresh):
    viewer = fresh
    widget = make_widget(viewer)
    try:
        cases = [
            (lambda: viewer.add_image(np.zeros((16, 16), np.float32), name="flat"), "2D"),
            (lambda: viewer.add_image(np.zeros((8, 16, 16, 3), np.uint8), rgb=True, name="colour"),
             "RGB"),
            (lambda: viewer.add_labels(np.zeros((8, 8, 8), np.int32), name="cells"), "Labels"),
        ]
        for add, word in cases:
            viewer.layers.clear()
            viewer.dims.ndisplay = 3
            add()
            widget.start()
            process(0.1)
            assert widget.problem and word in widget.message, widget.message
            assert widget._engine is None      # nothing was sent to the renderer
        # a 4D layer whose leading axis napari shows, so that no slider picks the time step
        viewer.layers.clear()
        viewer.add_image(np.zeros((3, 8, 8, 8), np.float32), name="series")
        viewer.dims.ndisplay = 3
        viewer.dims.order = (3, 2, 1, 0)
        widget.start()
        process(0.1)
        assert widget.problem and "slider" in widget.message, widget.message
        viewer.dims.order = (0, 1, 2, 3)
        widget.start()   # the same layer with its time slider: no problem with the layer
        process(0.1)
        assert not widget.problem, widget.message
        widget.stop()
        viewer.dims.ndisplay = 2
        widget.start()
        process(0.1)
        assert widget.problem and "3D" in widget.message
        viewer.layers.clear()
        viewer.dims.ndisplay = 3
        widget.start()
        assert widget.problem and "no visible layer" in widget.message
    finally:
        widget.close_engine()


# ---- (d) a camera move re-renders off the event loop ---------------------------------------------------

def test_camera_move_rerenders_without_blocking_the_event_loop(fresh):
    from qtpy.QtCore import QTimer
    viewer = fresh
    viewer.add_image(smooth_volume((24, 24, 24)), contrast_limits=(100, 900))
    widget = make_widget(viewer)
    try:
        render_to_end(widget, 6, 0.5, "pt")
        first = widget._engine.latest
        first_camera = widget._request.camera
        ticks: list[float] = []
        timer = QTimer()
        timer.setInterval(10)
        timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
        timer.start()
        t0 = time.perf_counter()
        cam(viewer).angles = (30.0, 40.0, 10.0)      # napari's API, as a mouse drag sets it
        set_ms = 1e3 * (time.perf_counter() - t0)
        wait_for(lambda: widget._engine.latest > first)
        busy_from = time.perf_counter()
        while widget._engine.busy():
            process(0.01)
        busy_s = time.perf_counter() - busy_from
        wait_for(lambda: done(widget), 30)   # the last frame crosses to Qt's thread
        timer.stop()
        assert set_ms < 100, set_ms
        frame = widget.last_frame
        assert frame.serial > first and frame.stage == "done"   # it re-rendered, to the end
        assert widget._request.camera["eye"] != first_camera["eye"] and frame.samples == 6
        # the renderer is another process: napari's event loop ran all along its render (the
        # gaps are napari's own redraws and this shared machine's load, never the render)
        assert widget._engine._process.pid != os.getpid()
        during = np.array([t for t in ticks if t >= busy_from])
        gaps = np.diff(np.concatenate([[busy_from], during])) * 1e3
        assert len(during) >= 4 and gaps.max() < 500 * busy_s, (len(during), gaps.max(), busy_s)
    finally:
        widget.close_engine()


# ---- the manifest, samples, imports ---------------------------------------------------------------

def test_manifest_and_sample_data(napari_env):
    import npe2
    pm = npe2.PluginManager.instance()
    pm.discover()
    manifest = pm.get_manifest("radiance-probes")
    assert [w.display_name for w in manifest.contributions.widgets] == ["Global illumination"]
    assert {s.key for s in manifest.contributions.sample_data} == {"cloud", "ct_head", "cells"}
    from radiance_probes.napari_plugin import samples
    (ct, meta, kind), = samples.ct_head()
    assert kind == "image" and ct.dtype == np.int16 and ct.ndim == 3
    assert ct.min() == -1000 and ct.max() >= 1000           # air and bone in Hounsfield units
    cells = samples.cells(size=24)
    assert len(cells) == 2 and all(c[0].shape == (24, 24, 24) for c in cells)
    (cloud, _, _), = samples.cloud()
    assert cloud.ndim == 3 and cloud.max() > 0


def test_only_the_plugin_imports_napari_and_qt():
    banned = ("napari", "qtpy", "PyQt5", "PyQt6", "PySide2", "PySide6", "vispy", "superqt",
              "magicgui")
    offenders = []
    for path in (ROOT / "app").rglob("*.py"):
        if "napari_plugin" in path.parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f"{path.relative_to(ROOT)}: {n}" for n in names
                          if n.split(".")[0] in banned]
    assert offenders == []
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'forbidden_modules = ["radiance_probes.napari_plugin"]' in pyproject
    assert '"radiance_probes.napari_plugin:napari.yaml"' in pyproject


def test_controls_share_the_viewers_records():
    """The widget's controls and the viewer's panels read app/frontend/controls.py (no literal ranges)."""
    from radiance_probes.frontend import controls
    panels = ((ROOT / "app/viewer/panels/sidebar.py").read_text()
              + (ROOT / "app/viewer/panels/tf_editor.py").read_text())
    widget = (ROOT / "app/napari_plugin/widget.py").read_text()
    for c in controls.CONTROLS:
        name = next(k for k, v in vars(controls).items() if v is c)
        assert f"C.{name}" in widget, name
        assert f"C.{name}" in panels or name in ("ENVIRONMENT_STRENGTH", "SUN_STRENGTH"), name
        assert f'"{c.label}", ' not in panels     # the label is the record's, never a literal
    assert "C.SUN_STRENGTH.hi" in panels and "C.ENVIRONMENT_STRENGTH.hi" in panels
