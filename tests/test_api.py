"""The Python API (radiance_probes): render() on arrays of any dtype, files and DICOM folders with
sane defaults; a Renderer that keeps its probes across frames; its own GL context, released; the
Image type (inline PNG in Jupyter, saved files); the orbit widget's logic; view() on an array.
Small sizes throughout (llvmpipe)."""
from __future__ import annotations

import io
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PILImage

import radiance_probes as rp
from radiance_probes.io.scene_file import SceneError
from radiance_probes.scene.types import VolumeError

ROOT = Path(__file__).resolve().parents[1]
SMALL = dict(width=24, height=20, probes={"grid": 4, "samples": 16})


def blob(dtype=np.float64, shape=(12, 14, 16)) -> np.ndarray:
    """A ball of high values in a low background, every axis a different length, and one outlier
    voxel (the kind of value the default window leaves out)."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    data = np.where(r < 0.6, 200, 10) + 5 * np.cos(7 * x)
    data.flat[0] = 250 if dtype == np.uint8 else 5000
    return data.astype(dtype)


def covered(image) -> float:
    """The fraction of pixels that differ from the background (the environment, 0.1)."""
    a = np.asarray(image)
    return float((np.abs(a - a[0, 0]).max(axis=-1) > 1e-3).mean())


def test_render_an_array_with_defaults():
    image = rp.render(blob(), method="raymarch", spp=1, **SMALL)
    assert image.shape == (20, 24, 3) and image.dtype == np.float32
    assert np.isfinite(image.linear).all() and 0.05 < covered(image) < 0.95   # framed, visible
    assert image.method == "raymarch" and image.spp == 1 and image.bake_ms > 0
    assert any("percentiles" in n for n in image.notes)
    lo, hi = image.scene.volume.value_range
    assert 4 < lo < 20 and 150 < hi < 210                # windowed to the data, not the outlier


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32, np.float16, np.int64,
                                   bool])
def test_any_dtype_makes_a_volume(dtype):
    from radiance_probes.api.render import build_scene
    data = blob(np.float64) > 100 if dtype is bool else blob(dtype)
    scene, volume = build_scene(data, None, {"spacing": (1, 1, 2)})
    assert volume.dims == (16, 14, 12) and volume.spacing == (1.0, 1.0, 2.0)
    assert volume.data.dtype == np.float32 and volume.data.min() == 0 and volume.data.max() == 1
    assert scene.volume.spacing == (1.0, 1.0, 2.0)


@pytest.mark.parametrize("data, needle", [
    (np.zeros((4, 4)), "expected a 3D array [z, y, x], got shape (4, 4)"),
    (np.zeros((2, 2, 2), complex), "complex values"),
    (np.zeros((0, 2, 2)), "empty"),
    (np.array([[["a"]]]), "expected numbers"),
])
def test_bad_arrays_are_refused_plainly(data, needle):
    with pytest.raises(VolumeError) as err:
        rp.render(data)
    assert needle in str(err.value)


def test_options_are_scene_keys_and_named_when_wrong():
    from radiance_probes.api.render import build_scene
    scene, volume = build_scene(blob(), None, dict(colormap="viridis", width=40, albedo=0.5,
                                                   window=(100, 100), camera={"fov_y": 20}))
    assert scene.transfer_function.colormap == "viridis" and scene.camera.width == 40
    assert scene.albedo == 0.5 and scene.camera.fov_y == 20.0
    assert volume.value_range == (50.0, 150.0) and not volume.notes   # a window given: no auto
    with pytest.raises(SceneError, match="unknown option 'colour_map'"):
        build_scene(blob(), None, {"colour_map": "viridis"})
    with pytest.raises(SceneError, match="albedo: must be <= 1.0"):
        build_scene(blob(), None, {"albedo": 2})


def test_render_a_file_a_dicom_folder_and_a_scene_file(tmp_path):
    from test_volume_formats import write_dicom_series
    np.save(tmp_path / "v.npy", blob(np.int16))
    assert rp.render(tmp_path / "v.npy", spp=1, **SMALL).shape == (20, 24, 3)
    write_dicom_series(tmp_path / "ct" / "a", blob(np.int16), uid="1.2.3.60")
    write_dicom_series(tmp_path / "ct" / "b", blob(np.int16, (2, 4, 5)), uid="1.2.3.61", seed=5)
    image = rp.render(str(tmp_path / "ct"), spp=1, **SMALL)
    assert any("holds 2 DICOM series" in n for n in image.notes)
    assert [s.slices for s in rp.dicom_series(tmp_path / "ct")] == [12, 2]
    scene = tmp_path / "s.json"
    scene.write_text('{"volume": {"builtin": "sphere", "size": [8, 8, 8]}, '
                     '"camera": {"width": 16, "height": 16}}')
    image = rp.render(scene, method="pt", spp=2)
    assert image.shape == (16, 16, 3) and image.scene.volume.builtin == "sphere"


def test_a_renderer_keeps_its_probes_across_frames():
    with rp.Renderer(blob(), **SMALL) as r:
        first = r.render(spp=1)
        r.orbit(60, 20)
        second = r.render(spp=1)
        assert r.bakes == 1 and first.bake_ms > 0 and second.bake_ms == 0
        assert np.abs(first.linear - second.linear).mean() > 1e-3          # a new view
        third = r.render(spp=1, colormap="viridis")                        # a new light path
        assert r.bakes == 2 and third.bake_ms > 0
        r.render(method="pt", spp=1)
        assert r.bakes == 2                                                 # pt needs none
        r.update(spacing=(1, 1, 3))                                         # the volume again
        assert r.volume.spacing == (1.0, 1.0, 3.0) and r.scene.camera == third.scene.camera
        assert "llvmpipe" in r.device or r.device
    assert r._ctx is None
    r.close()   # idempotent


def test_the_api_releases_its_context(monkeypatch):
    """render() makes a context of its own and releases it, also when the render fails."""
    import radiance_probes.gl.context
    made = []
    real = radiance_probes.gl.context.create_headless_context

    def recording(*args, **kw):
        made.append(real(*args, **kw))
        return made[-1]
    monkeypatch.setattr(radiance_probes.gl.context, "create_headless_context", recording)
    rp.render(blob(), spp=1, **SMALL)
    with pytest.raises(ValueError, match="method"):
        rp.render(blob(), method="nope", **SMALL)
    assert len(made) == 2
    assert all(type(c.mglo).__name__ == "InvalidObject" for c in made)   # released


def test_image_shows_inline_and_saves(tmp_path):
    image = rp.render(None, method="pt", spp=1, width=16, height=12)
    png = image._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    shown = np.asarray(PILImage.open(io.BytesIO(png)))
    np.testing.assert_array_equal(shown, image.srgb8())
    assert image.save(tmp_path / "a.png").is_file() and image.save(tmp_path / "a.npy").is_file()
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), image.linear)
    with pytest.raises(ValueError, match=".png, .npy or .exr"):
        image.save(tmp_path / "a.jpg")
    assert "16x12 pt" in repr(image)


class FakeSlider:
    def __init__(self, value, **kw):
        self.value, self.kw, self.callbacks = value, kw, []

    def observe(self, callback, names):
        assert names == "value"
        self.callbacks.append(callback)

    def move(self, value):
        self.value = value
        for c in self.callbacks:
            c({"new": value})


def fake_ipywidgets() -> types.ModuleType:
    """The few ipywidgets names the widget uses, so that its logic runs where ipywidgets is not
    installed."""
    mod = types.ModuleType("ipywidgets")
    mod.FloatSlider = FakeSlider
    mod.Image = lambda value, format: types.SimpleNamespace(value=value, format=format)
    mod.VBox = lambda children: types.SimpleNamespace(children=children)
    mod.HBox = lambda children: types.SimpleNamespace(children=children)
    return mod


def test_orbit_widget_turns_the_camera_without_a_rebake(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", fake_ipywidgets())
    with rp.Renderer(blob(), **SMALL) as r:
        box = r.widget(spp=1)
        picture, (azimuth, elevation, distance) = box.children[0], box.children[1].children
        first = picture.value
        assert first[:4] == b"\x89PNG" and (azimuth.value, elevation.value) == (0, 8)
        azimuth.move(90)
        assert picture.value != first and r.bakes == 1
        on_x = distance.value * np.cos(np.radians(elevation.value))
        assert r.scene.camera.eye[0] == pytest.approx(on_x, rel=1e-6)               # on +x


def test_orbit_widget_without_ipywidgets_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    with rp.Renderer(None, width=8, height=8) as r:
        with pytest.raises(ImportError, match="pip install ipywidgets"):
            r.widget()


def test_view_on_an_array_without_a_display(tmp_path, monkeypatch):
    """With no display the viewer renders headless and says where (here: the working folder)."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    proc = rp.view(blob(), method="pt", block=False, width=16, height=16)
    assert proc.wait(timeout=300) == 0
    assert (tmp_path / "view.png").is_file()
    assert PILImage.open(tmp_path / "view.png").size == (16, 16)


def test_the_issues_one_liner(tmp_path):
    """The target as written: import, render a random 64^3 array, its shape (llvmpipe, headless:
    no DISPLAY)."""
    code = ("import radiance_probes, numpy as np; "
            "print(radiance_probes.render(np.random.rand(64, 64, 64)).shape)")
    env = {k: v for k, v in __import__("os").environ.items() if k != "DISPLAY"}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(512, 512, 3)"


def test_the_api_takes_render_settings():
    """The Renderer's settings object goes through the API unchanged: a final gather changes the
    probes image, never the bake."""
    with rp.Renderer(blob(), settings=rp.RenderSettings(gather_event=1), **SMALL) as r:
        first = r.render("probes", spp=2)
        r.configure(gather_event=2)
        assert r.settings.gather_event == 2
        second = r.render("probes", spp=2)
        assert r.bakes == 1 and np.abs(first.linear - second.linear).mean() > 0


def test_crop_clip_and_colour_points_are_scene_options():
    """Issue 32's scene keys pass through **scene_options: a voxel crop renders less of the
    volume, a crop beyond it or keeping nothing is refused before the GPU (naming the key), colour
    points are a transfer-function shortcut, and a colormap given later replaces them."""
    from radiance_probes.api.render import build_scene
    half = {"min": [0, 0, 0], "max": [8, 14, 12], "units": "voxels"}
    scene, _ = build_scene(blob(), None, {"crop": half, "clip_plane": {"normal": [0, 1, 0]},
                                          "colors": [[0, 0, 0, 1], [1, 1, 0, 0]]})
    assert scene.crop.max == (8, 14, 12) and scene.clip_plane.distance == 0.0
    assert scene.transfer_function.colors[1] == (1.0, 1.0, 0.0, 0.0)
    with pytest.raises(SceneError, match=r"crop.max\[0\]: 99 is beyond the volume's 16 voxels"):
        build_scene(blob(), None, {"crop": {**half, "max": [99, 14, 12]}})
    with pytest.raises(SceneError, match="crop: keeps no voxel"):
        build_scene(blob(), None, {"crop": {"min": [0.6, 0.6, 0.6], "max": [0.7, 0.7, 0.7]}})
    with rp.Renderer(blob(), colors=[[0, 0, 0, 1], [1, 1, 0, 0]], **SMALL) as r:
        whole = r.render(spp=1)
        cropped = r.render(spp=1, crop=half)
        assert covered(cropped) < covered(whole) - 0.05        # the x half beyond 8 is gone
        r.update(colormap="viridis")                           # replaces the colour points
        assert r.scene.transfer_function.colors is None
        assert r.scene.transfer_function.colormap == "viridis"
        with pytest.raises(SceneError, match="keeps no voxel"):
            r.update(crop={"min": [0.6, 0.6, 0.6], "max": [0.7, 0.7, 0.7], "units": "world"})


def test_arrays_of_channels_and_time_steps_name_their_axes():
    """A 4D array says which axis is which (axes=, as volume.axes): channels each in their own
    colour (or the scene's channels), a time series' step; without axes it is refused plainly."""
    a, b = blob(np.float32), blob(np.float32)[:, :, ::-1]
    both = np.stack([a, b])
    image = rp.render(both, axes="czyx", **SMALL, spp=1)
    assert image.shape == (20, 24, 3) and image.linear.max() > 0
    only_b = rp.render(both, axes="czyx", channels=[{"index": 1}], window=None, **SMALL, spp=1)
    green = [[0.0, 0.25, 1.0, 0.25]]            # channel 0's default colour
    alone = rp.render(np.ascontiguousarray(b), window=None, **SMALL, spp=1, colors=green,
                      value_range=[float(b.min()), float(b.max())])
    np.testing.assert_allclose(only_b.linear, alone.linear, rtol=1e-5, atol=1e-6)
    # a camera given with the render keeps the array's channels (its scene names no file: parsed
    # again it named the built-in cloud, whose one channel refused channels[1])
    camera = {"eye": [0.4, 0.3, 2.0], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 40.0,
              "width": 24, "height": 20}
    moved = rp.render(both, axes="czyx", probes=SMALL["probes"], spp=1, camera=camera)
    placed = rp.render(both, axes="czyx", probes=SMALL["probes"], spp=1, **camera)
    np.testing.assert_allclose(moved.linear, placed.linear, rtol=1e-5, atol=1e-6)
    step = rp.render(both, axes="tzyx", time=1, window=None, **SMALL, spp=1, colors=green,
                     value_range=[float(b.min()), float(b.max())])
    # (a time series' probes cover the whole box: the same as fit "box" for one volume)
    boxed = rp.render(np.ascontiguousarray(b), window=None, **{**SMALL, "probes": {
        **SMALL["probes"], "fit": "box"}}, spp=1, colors=green,
        value_range=[float(b.min()), float(b.max())])
    np.testing.assert_allclose(step.linear, boxed.linear, rtol=1e-5, atol=1e-6)
    with pytest.raises(VolumeError, match="say which axis is which with axes="):
        rp.render(both, **SMALL)
