"""Transfer functions people keep: saved and loaded on their own, colour control points, opacity
presets from ramps and histogram peaks, the colour bar drawn into rendered images."""
from __future__ import annotations

import json

import numpy as np
import pytest

from radiance_probes.cli.main import main
from radiance_probes.frontend.colorbar import data_ticks, draw_colorbar
from radiance_probes.io.scene_file import (SceneError, TransferFunctionSpec, load_scene,
                                           load_transfer_function, parse_scene,
                                           parse_transfer_function, save_transfer_function,
                                           scene_to_dict)
from radiance_probes.scene.transfer import colormap_rgb, transfer_table
from radiance_probes.scene.transfer_presets import (colour_points_from, histogram_peaks,
                                                    opacity_presets, peak_opacity)
from radiance_probes.io.volume import Volume

TFS = [
    {"colormap": "viridis", "opacity": [[0, 0], [0.3, 0.1], [1, 0.9]], "resolution": 64},
    {"colors": [[0, 0, 0, 0.5], [0.4, 1, 0.2, 0], [1, 1, 1, 1]], "opacity": [[0, 0], [1, 1]]},
    {"rgba": [[0, 0, 0, 0], [0.2, 0.4, 0.6, 0.5], [1, 1, 1, 1]]},
]


@pytest.mark.parametrize("data", TFS)
def test_transfer_function_file_round_trip(tmp_path, data):
    spec = parse_transfer_function(data)
    path = save_transfer_function(tmp_path / "tf" / "kept.json", spec)
    assert load_transfer_function(path) == spec
    np.testing.assert_array_equal(transfer_table(load_transfer_function(path)), transfer_table(spec))
    # the file holds what a scene's transfer_function key holds
    assert parse_scene({"transfer_function": json.loads(path.read_text())}).transfer_function == spec


def test_scene_names_a_transfer_function_file(tmp_path):
    save_transfer_function(tmp_path / "bone.json", parse_transfer_function(TFS[1]))
    (tmp_path / "scene.json").write_text('{"transfer_function": "bone.json"}')
    scene = load_scene(tmp_path / "scene.json")
    assert scene.transfer_function == parse_transfer_function(TFS[1])
    assert parse_scene(scene_to_dict(scene)) == scene      # written back inline
    (tmp_path / "bad.json").write_text('{"transfer_function": "missing.json"}')
    with pytest.raises(SceneError, match="transfer_function: transfer function file not found"):
        load_scene(tmp_path / "bad.json")


@pytest.mark.parametrize("data, message", [
    ({"colormap": "grey", "colors": [[0, 0, 0, 0]]}, "either a colormap or colour points"),
    ({"colors": [[0, 0, 0]]}, r"transfer_function.colors\[0\]: expected a list of 4 numbers"),
    ({"colors": [[0.5, 0, 0, 0], [0.2, 1, 1, 1]]}, "colors: densities must not decrease"),
    ({"colors": [[0, 0, 2, 0]]}, r"colors\[0\]\[2\]: must be <= 1.0"),
    ({"rgba": [[0, 0, 0, 0], [1, 1, 1, 1]], "colors": [[0, 0, 0, 0]]}, "either rgba rows"),
])
def test_bad_colour_points_name_the_field(data, message):
    with pytest.raises(SceneError, match=message):
        parse_transfer_function(data)


def test_bad_file_names_the_file_and_field(tmp_path):
    p = tmp_path / "tf.json"
    p.write_text('{"colormap": "nope"}')
    with pytest.raises(SceneError, match=r"tf.json: transfer_function.colormap: expected one of"):
        load_transfer_function(p)
    p.write_text("{not json")
    with pytest.raises(SceneError, match="not a valid JSON transfer function"):
        load_transfer_function(p)


def test_colour_points_interpolate_linearly():
    spec = TransferFunctionSpec(colors=((0.0, 0.0, 0.0, 1.0), (0.5, 1.0, 0.0, 0.0),
                                        (1.0, 1.0, 1.0, 1.0)), resolution=5)
    table = transfer_table(spec)
    np.testing.assert_allclose(table[:, :3], [[0, 0, 1], [0.5, 0, 0.5], [1, 0, 0],
                                              [1, 0.5, 0.5], [1, 1, 1]], atol=1e-7)
    # a colormap as colour points, and back: the points sit on the colormap
    points = colour_points_from(colormap_rgb("plasma", 256), 9)
    again = transfer_table(TransferFunctionSpec(colors=points, resolution=9))
    np.testing.assert_allclose(again[:, :3], colormap_rgb("plasma", 9), atol=1e-6)


# ---- opacity presets --------------------------------------------------------------------------

def _two_materials() -> Volume:
    rng = np.random.default_rng(3)
    data = np.zeros((40, 40, 40), np.float32)           # background (air) at 0
    data[5:20] = rng.normal(0.3, 0.02, (15, 40, 40))    # one material
    data[25:35] = rng.normal(0.7, 0.03, (10, 40, 40))   # another
    return Volume(np.clip(data, 0, 1), (1, 1, 1), "two", (0.0, 1000.0), "float32", 0.0, 1000.0)


def test_histogram_peaks_find_the_materials():
    volume = _two_materials()
    peaks = histogram_peaks(volume.histogram(256))
    centres = sorted(c for c, _ in peaks)
    assert len(peaks) == 2                                 # the background at 0 is left out
    assert abs(centres[0] - 0.3) < 0.01 and abs(centres[1] - 0.7) < 0.01
    presets = opacity_presets(volume)
    assert {"ramp", "steep ramp", "all peaks"} <= set(presets)
    names = [n for n in presets if n.startswith("peak at")]
    values = sorted(float(n.split()[-1]) for n in names)    # labelled in data units
    assert len(values) == 2 and abs(values[0] - 300) < 10 and abs(values[1] - 700) < 10
    # each preset is a valid opacity curve whose tent covers its material and not the other
    for name, points in presets.items():
        parse_scene({"transfer_function": {"opacity": [list(p) for p in points]}})
    first = min(names, key=lambda n: float(n.split()[-1]))
    curve = parse_scene({"transfer_function": {"opacity": [list(p) for p in presets[first]]}})
    alpha = transfer_table(curve.transfer_function)[:, 3]
    d = np.linspace(0, 1, len(alpha))
    assert alpha[np.argmin(abs(d - 0.3))] > 0.8 and alpha[np.argmin(abs(d - 0.7))] == 0.0


def test_peak_opacity_keeps_densities_in_order():
    points = peak_opacity([(0.5, 0.3), (0.6, 0.3), (0.01, 0.05)])
    xs = [p[0] for p in points]
    assert xs == sorted(xs) and xs[0] == 0.0 and xs[-1] == 1.0
    parse_scene({"transfer_function": {"opacity": [list(p) for p in points]}})


# ---- the colour bar ----------------------------------------------------------------------------

def test_data_ticks_in_data_units():
    ticks, labels = data_ticks((-1000.0, 3000.0))
    assert labels == ["-1000", "0", "1000", "2000", "3000"]
    np.testing.assert_allclose(ticks, [0, 0.25, 0.5, 0.75, 1.0])


@pytest.mark.parametrize("position", ["right", "bottom"])
def test_colour_bar_draws_the_colours(position):
    image = np.full((256, 320, 3), 40, np.uint8)
    rgb = np.zeros((256, 3))
    rgb[:, 0] = np.linspace(0, 1, 256)        # black to red
    out = draw_colorbar(image, rgb, (0.0, 255.0), "value", position)
    assert out.shape == image.shape and out.dtype == np.uint8
    changed = np.any(out != image, axis=-1)
    assert 0.01 < changed.mean() < 0.3        # a bar, not the whole picture
    reds = out[..., 0].astype(int) - out[..., 1]
    assert reds.max() > 200                   # the bar's red end is there, at full colour
    if position == "right":
        assert changed[:, :160].sum() == 0    # at the right edge
    else:
        assert changed[:128].sum() == 0


def test_render_colorbar_and_transfer_function_option(tmp_path, capsys):
    tf = tmp_path / "green.json"
    save_transfer_function(tf, parse_transfer_function(
        {"colors": [[0, 0, 1, 0], [1, 0, 1, 0]], "opacity": [[0, 0], [0.2, 0], [1, 1]]}))
    plain, barred = tmp_path / "plain.png", tmp_path / "bar.png"
    args = ["render", "--spp", "2", "--width", "64", "--height", "64", "--transfer-function", str(tf)]
    assert main([*args, "--out", str(plain)]) == 0
    assert main([*args, "--out", str(barred), "--colorbar"]) == 0
    from PIL import Image
    a, b = np.asarray(Image.open(plain)), np.asarray(Image.open(barred))
    assert np.any(a != b) and np.all(a[:, :20] == b[:, :20])   # drawn on the right only
    assert main([*args[:-1], str(tmp_path / "missing.json"), "--out", str(plain)]) == 2
    assert "--transfer-function: transfer function file not found" in capsys.readouterr().err
