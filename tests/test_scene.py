"""Scene parsing (SPEC.md "Scene file"): defaults, round trip, and errors that name the field."""
import copy
import json
import math
import re

import numpy as np
import pytest

from radiance_probes.io.scene_file import (CameraSpec, LightSpec, Scene, SceneError, default_scene,
                                           load_scene, parse_scene, scene_to_dict)

# SPEC.md's example scene.
FULL = {
    "volume": {"path": "../shared/datasets/bonsai_256x256x256_uint8.raw", "spacing": [1, 1, 1],
               "value_range": [0, 255]},
    "transfer_function": {"colormap": "plasma", "opacity": [[0.0, 0.0], [0.2, 0.0], [1.0, 1.0]]},
    "density_scale": 100.0,
    "albedo": 0.9,
    "anisotropy": 0.0,
    "light": {"direction": [0.5, 0.8, 0.3], "irradiance": [3.0, 3.0, 3.0]},
    "environment": [0.1, 0.1, 0.1],
    "max_bounces": 64,
    "camera": {"eye": [0.0, 0.3, 2.2], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 35.0,
               "width": 512, "height": 512},
    "probes": {"grid": [16, 16, 16], "samples": 256},
}

# Other non-default scenes, to cover the fields FULL leaves at their defaults.
OTHERS = [
    {"volume": {"builtin": "sphere", "size": [9, 7, 5], "spacing": [1, 2, 0.5]},
     "transfer_function": {"rgba": [[0, 0, 0, 0], [1, 0.5, 0.25, 1]], "resolution": 64},
     "light": {"direction": [0.0, 0.0, -7.0]}, "anisotropy": -0.7, "max_bounces": 0,
     "camera": {"eye": [3, 1, -2], "target": [0.1, 0, 0], "up": [0, 0, 1], "fov_y": 179,
                "width": 33, "height": 17},
     "probes": {"grid": 8, "samples": 3, "sh_window": "lanczos", "precision": "rgba16f"}},
    {"volume": {"path": "x_2x2x2_float32.raw", "dims": [2, 2, 2], "dtype": "float32",
                "replace_nonfinite": 0.0, "value_range": [-1.5, 2]},
     "transfer_function": {"colormap": "cool-warm", "opacity": [[0.5, 0.25]]}},
]


def test_empty_object_is_the_default_scene():
    s = parse_scene({})
    assert s == default_scene()
    # The dataclass defaults are the same scene (the light direction is a unit vector either way).
    assert s == Scene()
    assert s.volume.builtin == "cloud" and s.volume.path is None
    assert s.density_scale == 100.0 and s.albedo == 0.9 and s.max_bounces == 64
    assert s.camera == CameraSpec()
    assert math.isclose(np.linalg.norm(s.light.direction), 1.0, rel_tol=0, abs_tol=1e-15)
    assert np.allclose(s.light.direction, np.array([0.5, 0.8, 0.3]) / np.linalg.norm([0.5, 0.8, 0.3]))


@pytest.mark.parametrize("data", [{}, FULL, *OTHERS])
def test_round_trip(data):
    s = parse_scene(data)
    d = scene_to_dict(s)
    json.dumps(d)  # JSON-ready
    assert parse_scene(d) == s
    assert parse_scene(json.loads(json.dumps(d))) == s


def test_full_scene_values():
    s = parse_scene(FULL)
    assert s.volume.path == FULL["volume"]["path"] and s.volume.builtin is None
    assert s.volume.value_range == (0.0, 255.0)
    assert s.volume.spacing == (1.0, 1.0, 1.0)
    assert s.probes.grid == (16, 16, 16)
    assert s != default_scene()


def test_round_trip_keeps_light_direction_bit_for_bit():
    rng = np.random.default_rng(1)
    for _ in range(2000):
        v = (rng.normal(size=3) * rng.uniform(0.01, 100)).tolist()
        s = parse_scene({"light": {"direction": v}})
        assert parse_scene(scene_to_dict(s)) == s


def test_light_direction_is_normalised():
    s = parse_scene({"light": {"direction": [0, 3, 4]}})
    assert s.light.direction == pytest.approx((0.0, 0.6, 0.8), abs=1e-15)
    assert LightSpec(direction=(0, 0, 2)).direction == (0.0, 0.0, 1.0)


def test_scene_replace():
    s = default_scene().replace(albedo=0.5)
    assert s.albedo == 0.5 and s != default_scene()


# ---------------------------------------------------------------------------------------------
# Unknown fields

def _with(path: str, value):
    """FULL with the dotted path set to value."""
    d = copy.deepcopy(FULL)
    if path == "transfer_function.rgba":  # rgba rows replace colormap and opacity
        d["transfer_function"] = {}
    keys = path.split(".")
    node = d
    for k in keys[:-1]:
        node = node.setdefault(k, {})
    node[keys[-1]] = value
    return d


UNKNOWN = ["colour", "volume.colour", "transfer_function.colour", "light.colour", "camera.colour",
           "probes.colour", "base_dir"]


@pytest.mark.parametrize("path", UNKNOWN)
def test_unknown_field_is_named(path):
    with pytest.raises(SceneError, match=r"unknown field " + re.escape(path) + r"\b"):
        parse_scene(_with(path, 1))


@pytest.mark.parametrize("data, suggestion", [
    ({"transfer_functon": {}}, "(did you mean transfer_function?)"),
    ({"camera": {"fovy": 40}}, "(did you mean fov_y?)"),
    ({"light": {"irradiance": 1, "dirction": [0, 1, 0]}}, "(did you mean direction?)"),
    ({"volume": {"builtin": "cloud", "sise": [8, 8, 8]}}, "(did you mean size?)"),
    ({"colour": 1}, None),   # nothing close: no guess
])
def test_a_typo_in_a_key_says_what_it_is_close_to(data, suggestion):
    """Issue 55: a misspelt key listed the allowed keys, without the one meant."""
    with pytest.raises(SceneError) as err:
        parse_scene(data)
    text = str(err.value)
    assert "(allowed: " in text and "\n" not in text
    assert (suggestion in text) if suggestion else "did you mean" not in text, text


def test_an_api_option_with_a_typo_says_what_it_is_close_to():
    import numpy as np

    import radiance_probes as rp
    with pytest.raises(SceneError, match=r"'colormpa' \(did you mean colormap\?\)"):
        rp.render(np.ones((4, 4, 4)), colormpa="grey")


def test_not_an_object():
    with pytest.raises(SceneError, match="scene"):
        parse_scene([1, 2])
    with pytest.raises(SceneError, match=r"camera"):
        parse_scene({"camera": [1, 2]})


# ---------------------------------------------------------------------------------------------
# Bad values name the field

BAD = [
    ("density_scale", -1.0, "density_scale"),
    ("albedo", 1.01, "albedo"),
    ("albedo", -0.1, "albedo"),
    ("anisotropy", 1.0, "anisotropy"),
    ("anisotropy", -1.0, "anisotropy"),
    ("light.direction", [0, 0, 0], "light.direction"),
    ("light.direction", [1, 0], "light.direction"),
    ("light.irradiance", [1, -1, 1], r"light.irradiance\[1\]"),
    ("camera.fov_y", 0, "camera.fov_y"),
    ("camera.fov_y", 180, "camera.fov_y"),
    ("camera.width", 0, "camera.width"),
    ("camera.height", 2.5, "camera.height"),
    ("probes.grid", 0, r"probes.grid\[0\]"),
    ("probes.grid", 257, r"probes.grid\[0\]"),
    ("probes.grid", [16, 257, 16], r"probes.grid\[1\]"),
    ("probes.samples", 0, "probes.samples"),
    ("probes.sh_window", "box", "probes.sh_window"),
    ("density_scale", "100", "density_scale"),
    ("albedo", "high", "albedo"),
    ("camera.eye", [0, "1", 2], r"camera.eye\[1\]"),
    ("density_scale", True, "density_scale"),
    ("density_scale", 10 ** 400, "density_scale"),
    ("max_bounces", -1, "max_bounces"),
    ("environment", [0.1, 0.1], "environment"),
    ("transfer_function.colormap", "nope", "transfer_function.colormap"),
    ("transfer_function.opacity", [[0.5, 0.0], [0.2, 1.0]], "transfer_function.opacity"),
    ("transfer_function.opacity", [[0.5, 1.5]], r"transfer_function.opacity\[0\]"),
    ("transfer_function.rgba", [[0, 0, 0, 0]], "transfer_function.rgba"),
    ("transfer_function.rgba", [[0, 0, 0, 0]] * 4097, "transfer_function.rgba"),
    ("transfer_function.rgba", [[0, 0, 0, 0], [0, 0, 2, 0]], r"transfer_function.rgba\[1\]\[2\]"),
    ("transfer_function.resolution", 1, "transfer_function.resolution"),
    ("volume.spacing", [1, 0, 1], r"volume.spacing\[1\]"),
    ("volume.value_range", [5, 5], "volume.value_range"),
    ("volume.dims", [4, 0, 2], r"volume.dims\[1\]"),
    ("volume.dtype", "float16", "volume.dtype"),
]


@pytest.mark.parametrize("path, value, pattern", BAD,
                         ids=[f"{p}={v!r}"[:40] for p, v, _ in BAD])
def test_bad_value_names_the_field(path, value, pattern):
    with pytest.raises(SceneError, match=pattern):
        parse_scene(_with(path, value))


def test_non_finite_number_from_json():
    # json.loads accepts NaN and Infinity; the scene must not.
    with pytest.raises(SceneError, match="albedo"):
        parse_scene(json.loads('{"albedo": NaN}'))
    with pytest.raises(SceneError, match="density_scale"):
        parse_scene(json.loads('{"density_scale": Infinity}'))


def test_camera_eye_equal_to_target():
    with pytest.raises(SceneError, match="camera.target"):
        parse_scene({"camera": {"eye": [1, 2, 3], "target": [1, 2, 3]}})


@pytest.mark.parametrize("up", [[0, 0, 1], [0, 0, -3], [0, 0, 0], [0, 1e-9, 1]])
def test_camera_up_parallel_to_view(up):
    with pytest.raises(SceneError, match="camera.up"):
        parse_scene({"camera": {"eye": [0, 0, 0], "target": [0, 0, 5], "up": up}})


def test_camera_up_parallel_to_view_at_any_scale():
    # The test is on the angle, not on the lengths of the vectors.
    with pytest.raises(SceneError, match="camera.up"):
        parse_scene({"camera": {"eye": [0, 0, 0], "target": [0, 0, 1e4], "up": [0, 1e-9, 1e3]}})
    s = parse_scene({"camera": {"eye": [0, 0, 0], "target": [0, 0, 1e-6], "up": [0, 1e-3, 0]}})
    assert s.camera.up == (0.0, 1e-3, 0.0)


def test_both_path_and_builtin():
    with pytest.raises(SceneError, match=r"volume\.path.*volume\.builtin"):
        parse_scene({"volume": {"path": "a.raw", "builtin": "cloud"}})


def test_both_rgba_and_colormap():
    with pytest.raises(SceneError, match="transfer_function"):
        parse_scene({"transfer_function": {"rgba": [[0, 0, 0, 0], [1, 1, 1, 1]], "colormap": "plasma"}})


# ---------------------------------------------------------------------------------------------
# Files

def test_load_scene(tmp_path):
    f = tmp_path / "scene.json"
    f.write_text(json.dumps(FULL))
    s = load_scene(f)
    assert s == parse_scene(FULL)
    assert s.base_dir == str(tmp_path.resolve())


def test_load_scene_missing_file(tmp_path):
    f = tmp_path / "nope.json"
    with pytest.raises(SceneError, match="nope.json"):
        load_scene(f)


@pytest.mark.parametrize("text", ['{"albedo": 0.5,}', "", "not json", '{"a": [1, 2'])
def test_load_scene_invalid_json(tmp_path, text):
    f = tmp_path / "broken.json"
    f.write_text(text)
    with pytest.raises(SceneError, match="broken.json"):
        load_scene(f)


def test_load_scene_binary_file(tmp_path):
    f = tmp_path / "binary.json"
    f.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(SceneError, match="binary.json"):
        load_scene(f)


def test_load_scene_bad_field_names_file_and_field(tmp_path):
    f = tmp_path / "bad.json"
    f.write_text('{"camera": {"fov_y": 0}}')
    with pytest.raises(SceneError, match=r"bad\.json.*camera\.fov_y"):
        load_scene(f)
