"""The scene file's JSON Schema (app/io/scene_schema.py): the committed docs/scene.schema.json and
docs/scene-format.md's key table are what the scene's types generate; every scene in assets/
validates (and every scene the other tests parse: tests/conftest.py checks them when the session
ends); a wrong key fails the schema and the loader, the loader's own message naming it; the loader
and the schema agree at the bounds of every range."""
from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

from radiance_probes.io.scene_file import SceneError, load_scene, parse_scene
from radiance_probes.io.scene_schema import (TABLE_END, TABLE_START, key_table, scene_schema,
                                             schema_text)

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_FILE = ROOT / "docs" / "scene.schema.json"


@pytest.fixture(scope="module")
def validator():
    schema = scene_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_the_committed_schema_is_the_generated_one():
    assert SCHEMA_FILE.read_text() == schema_text(), (
        "docs/scene.schema.json is stale: radiance-probes schema --update-docs")


def test_the_format_page_holds_the_generated_key_table():
    page = (ROOT / "docs" / "scene-format.md").read_text()
    assert TABLE_START in page and TABLE_END in page
    table = page[page.index(TABLE_START) + len(TABLE_START):page.index(TABLE_END)].strip()
    assert table == key_table().strip(), (
        "docs/scene-format.md's key table is stale: radiance-probes schema --update-docs")


def test_every_asset_scene_validates_and_loads(validator):
    scenes = sorted((ROOT / "assets" / "scenes").glob("*.json"))
    assert len(scenes) >= 5
    for path in scenes:
        data = json.loads(path.read_text())
        errors = [e.message for e in validator.iter_errors(data)]
        assert not errors, f"{path.name}: {errors}"
        load_scene(path)


def test_the_default_scene_and_a_saved_one_validate(validator):
    from radiance_probes.io.scene_file import default_scene, scene_to_dict
    validator.validate({})
    validator.validate(scene_to_dict(default_scene()))
    full = parse_scene({"volume": {"path": "ct/", "window": "bone", "series": 2,
                                   "orientation": "patient"},
                        "environment": {"map": "sky.exr", "rotation": 30},
                        "probes": {"grid": 32, "sh_order": 3, "channels": 1},
                        "transfer_function": {"colors": [[0, 0, 0, 1], [1, 1, 0.5, 0]]},
                        "crop": {"min": [2, 0, 1], "max": [10, 16, 9], "units": "voxels"},
                        "clip_plane": {"normal": [0, 1, 0.3], "distance": 0.1, "enabled": False},
                        "bookmarks": [{"name": "front", "eye": [0, 0.3, 2.2], "fov_y": 30},
                                      {"name": "top", "eye": [0, 2.2, 0.3]}],
                        "viewer": {"method": "raymarch", "display": "split", "exposure": 2.0,
                                   "show_box": True},
                        "$schema": "../docs/scene.schema.json"})
    saved = scene_to_dict(full)
    assert {"crop", "clip_plane", "bookmarks", "viewer"} <= set(saved)
    validator.validate(saved)


def test_the_optional_keys_and_a_transfer_function_file(validator, tmp_path):
    """null for the optional objects, a transfer function named by its file: the loader takes
    them, so the schema does; a voxel crop's corners are integers for both, a crop needs both
    corners and a bookmark its eye for both."""
    (tmp_path / "bone_tf.json").write_text(json.dumps({"colormap": "grey",
                                                       "opacity": [[0, 0], [1, 1]]}))
    for data in ({"crop": None, "clip_plane": None, "bookmarks": None, "viewer": None},
                 {"transfer_function": "bone_tf.json"},
                 {"crop": {"min": [-0.5, -0.5, -0.1], "max": [0.5, 0.5, 0.4]}}):
        validator.validate(data)
        parse_scene(data, base_dir=tmp_path)
    for data, message in (
            ({"crop": {"min": [0, 0, 0.5], "max": [4, 4, 4], "units": "voxels"}},
             "crop.min[2]: expected an integer"),
            ({"crop": {"min": [0, 0, 0], "max": [4, 4, 4], "units": "voxels", "size": 2}},
             "unknown field crop.size"),
            ({"crop": {"min": [0, 0, 0]}}, "crop.max: missing"),
            ({"clip_plane": {"distance": 0.1}}, "clip_plane.normal: missing"),
            ({"bookmarks": [{"name": "a"}]}, "bookmarks[0].eye: missing"),
            ({"transfer_function": ""}, "transfer_function"),
            ({"viewer": {"method": "guided?"}}, "viewer.method")):
        assert list(validator.iter_errors(data)), f"the schema took {data}"
        with pytest.raises(SceneError) as err:
            parse_scene(data, base_dir=tmp_path)
        assert message in str(err.value), str(err.value)


@pytest.mark.parametrize("data, path", [
    ({"camera": {"fovy": 40}}, "camera.fovy"),
    ({"volume": {"builtin": "cloud", "sise": [8, 8, 8]}}, "volume.sise"),
    ({"density": 3}, "density"),
    ({"probes": {"grid": 8, "walks": 64}}, "probes.walks"),
])
def test_a_wrong_key_fails_with_the_loaders_message(validator, tmp_path, data, path):
    assert list(validator.iter_errors(data)), f"the schema took {data}"
    (tmp_path / "s.json").write_text(json.dumps(data))
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / "s.json")
    text = str(err.value)
    assert f"unknown field {path} (" in text and "(allowed: " in text and "s.json" in text, text


def _numeric_keys(schema: dict, prefix: str = ""):
    """(dotted key, its number schema, whether it is an array's item) for every bounded number."""
    for name, sub in schema.get("properties", {}).items():
        path = f"{prefix}{name}"
        if "properties" in sub:      # an object (the optional ones may also be null)
            yield from _numeric_keys(sub, f"{path}.")
            continue
        for option in sub.get("oneOf", [sub]):
            if option.get("type") in ("number", "integer"):
                yield path, option, None
            elif option.get("type") == "array" and option.get("items", {}).get("type") in (
                    "number", "integer"):
                yield path, option["items"], option["minItems"]


def _scene_with(path: str, value) -> dict:
    parts = path.split(".")
    data: dict = {}
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value
    if path.startswith("volume.") and path.split(".")[1] in ("dims", "series"):
        data["volume"]["path"] = "a.raw"   # keys of a file's volume
    for key, required in (("crop", {"min": [0, 0, 0], "max": [1, 1, 1]}),
                          ("clip_plane", {"normal": [0, 1, 0]})):
        if key in data:                    # the keys these objects cannot be without
            data[key] = {**required, **data[key]}
    return data


def test_loader_and_schema_agree_at_every_bound(validator):
    """At each bound the loader accepts what the schema does; just past it both refuse, and the
    loader names the key."""
    checked = 0
    for path, number, items in _numeric_keys(scene_schema()):
        if path.startswith(("series", "environment")):
            continue   # covered through volume.series; environment's bounds: its map's file
        for bound, open_key, step in (("minimum", "exclusiveMinimum", -1), ("maximum",
                                                                           "exclusiveMaximum", 1)):
            limit = number.get(bound, number.get(open_key))
            if limit is None:
                continue
            delta = 1 if number.get("type") == "integer" else max(abs(limit) * 1e-6, 1e-9)
            inside = limit if bound in number else limit - step * delta
            outside = limit + step * delta if bound in number else limit
            for value, ok in ((inside, True), (outside, False)):
                v = [value] * items if items else value
                if path == "light.direction" or (items and path == "camera.up"):
                    continue
                data = _scene_with(path, v)
                schema_ok = not list(validator.iter_errors(data))
                try:
                    parse_scene(data)
                    loader_ok, message = True, ""
                except SceneError as exc:
                    loader_ok, message = False, str(exc)
                assert schema_ok == ok == loader_ok, (path, value, schema_ok, loader_ok, message)
                if not ok:
                    assert message.startswith(path.replace("probes.grid", "probes.grid")), message
                checked += 1
    assert checked >= 40


def test_choices_agree(validator):
    """Every value the schema lists for a choice loads, and one it does not list is refused by
    both."""
    def choices(schema, prefix=""):
        for name, sub in schema.get("properties", {}).items():
            if "properties" in sub:
                yield from choices(sub, f"{prefix}{name}.")
            elif "enum" in sub and sub.get("type") == "string":
                yield f"{prefix}{name}", sub["enum"]
    seen = 0
    for path, values in choices(scene_schema()):
        for value in values:
            data = _scene_with(path, value)
            validator.validate(data)
            parse_scene(data)
        data = _scene_with(path, "no-such-choice")
        assert list(validator.iter_errors(data))
        with pytest.raises(SceneError, match=path.split(".")[-1]):
            parse_scene(data)
        seen += 1
    assert seen >= 14   # the probes', the volume's, the crop's units and the viewer's modes
