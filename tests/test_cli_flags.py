"""Scene keys on the command line: `--set KEY=VALUE` and the named flags (--spacing, --value-range,
--dims, --dtype, --axes, --replace-nonfinite, --colormap, --opacity, --time, --channel); every
message that names a scene key names the flag that sets it; every flag has help text."""
from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

import numpy as np
import pytest

from radiance_probes.cli.main import build_parser, main
from radiance_probes.frontend.scene_options import apply_options, scene_from_arg
from radiance_probes.frontend.option_types import set_value
from radiance_probes.scene.flags import FLAGS, flag_for, with_flag
from radiance_probes.io.load import load_scene_volume

APP = Path(__file__).resolve().parents[1] / "app"
# A scene key as a message names it: dotted, from one of the scene's objects or lists.
KEY = re.compile(r"\b(?:volume|transfer_function|camera|probes|light|crop|clip_plane|channels|"
                 r"bookmarks|viewer)(?:\[[a-z0-9]*\])?(?:\.[a-z_]+)+|\bchannels\[[a-z0-9]*\]")


@pytest.fixture
def no_gpu(monkeypatch):
    """Any GL context made in the test fails it: every case here fails before the GPU."""
    import radiance_probes.gl.context

    def refuse(*_a, **_k):
        raise AssertionError("a GL context was created before the input was checked")
    monkeypatch.setattr(radiance_probes.gl.context, "create_headless_context", refuse)


def run(argv, capsys) -> tuple[int, str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:   # argparse exits
        rc = exc.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err + out
    return rc, err.strip()


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def options(parser: argparse.ArgumentParser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings}


# ---- help and the flags the messages name -----------------------------------------------------

def test_every_flag_of_every_command_has_help_text():
    missing = [f"{name} {a.option_strings or a.dest}" for name, p in subparsers().items()
               for a in p._actions if not a.help and not isinstance(a, argparse._HelpAction)]
    assert not missing, f"flags without help: {missing}"


def test_the_flags_the_messages_name_exist():
    """Every flag app/scene/flags.py names exists on render; the scene-key flags and --set on
    render, view and animate alike."""
    commands = subparsers()
    for key, (flag, _) in FLAGS.items():
        assert flag in options(commands["render"]), f"{key}: render has no {flag}"
    shared = {"--set", "--spacing", "--value-range", "--dims", "--dtype", "--axes",
              "--replace-nonfinite", "--colormap", "--opacity", "--time", "--channel",
              "--series", "--data-window", "--orientation", "--crop", "--clip-plane"}
    for name in ("render", "view", "animate"):
        assert shared <= options(commands[name]), f"{name} lacks {shared - options(commands[name])}"


# ---- the messages, from the source ---------------------------------------------------------------

def _message_text(node: ast.AST) -> tuple[str, bool]:
    """A string literal's text with "{}" for its formatted values, and whether one of them is
    with_flag(...) or flag_for(...) (which always name a flag)."""
    if isinstance(node, ast.Constant):
        return node.value, False
    text, flagged = [], False
    for v in node.values:
        if isinstance(v, ast.Constant):
            text.append(v.value)
        elif (isinstance(v.value, ast.Call) and isinstance(v.value.func, ast.Name)
              and v.value.func.id in ("with_flag", "flag_for")):
            flagged = True
            text.append("{flag}")
        else:
            text.append("{}")
    return "".join(text), flagged


def unflagged_messages(source: str) -> list[tuple[int, str]]:
    """String literals of a module (not docstrings, not a flag's own help) that name a scene key
    other than as their leading subject ("volume.axes: expected ...", a parse error naming the
    field it is about) and name no flag."""
    tree = ast.parse(source)
    skip: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)):
            skip.add(id(body[0].value))
        if isinstance(node, ast.keyword) and node.arg == "help":
            skip.update(id(n) for n in ast.walk(node.value))
        if isinstance(node, ast.JoinedStr):
            skip.update(id(v) for v in node.values)
    found = []
    for node in ast.walk(tree):
        if id(node) in skip or not (isinstance(node, ast.JoinedStr) or (
                isinstance(node, ast.Constant) and isinstance(node.value, str))):
            continue
        text, flagged = _message_text(node)
        keys = [m for m in KEY.finditer(text)
                if not (m.start() == 0 and text[m.end():m.end() + 1] in (":", "[", ".", ""))]
        if keys and not flagged and "--" not in text:
            found.append((node.lineno, text))
    return found


def test_the_walk_finds_a_message_that_names_a_key_without_its_flag():
    """The checker itself: a planted message is caught; with its flag, or as a parse error's
    subject, it passes."""
    assert unflagged_messages('raise VolumeError(f"{p}: give volume.spacing")')
    assert unflagged_messages('raise VolumeError("x; see channels[i].index")')
    assert not unflagged_messages('raise VolumeError(f"{p}: give {with_flag(\'volume.spacing\')}")')
    assert not unflagged_messages('raise SceneError(f"volume.axes: expected letters")')
    assert not unflagged_messages('x = {"volume.series": "--series"}')
    assert not unflagged_messages('p.add_argument("--x", help="sets volume.spacing")')


def test_every_message_that_names_a_scene_key_names_the_flag_that_sets_it():
    """Over every module the command line reaches (the viewer's and the napari plugin's own labels and the bench's
    reports aside: neither is read at a command line)."""
    bad = []
    for path in sorted(APP.rglob("*.py")):
        rel = path.relative_to(APP).as_posix()
        if rel.startswith(("bench/", "viewer/", "napari_plugin/")) or rel in ("io/scene_schema.py", "scene/flags.py"):
            continue
        bad += [f"app/{rel}:{line}: {text!r}" for line, text in unflagged_messages(path.read_text())]
    assert not bad, "messages naming a scene key but no flag:\n" + "\n".join(bad)


def test_flag_for_names_the_named_flag_else_set():
    assert with_flag("volume.spacing") == "volume.spacing (--spacing X,Y,Z)"
    assert flag_for("channels[2].index") == "--channel I[,J,...]"
    assert flag_for("channels[i].transfer_function") == "--set channels[i].transfer_function=VALUE"
    assert flag_for("light.direction") == "--set light.direction=VALUE"


# ---- the messages, triggered, and the flag they name fixing what they name ---------------------

def _files(tmp_path: Path) -> dict[str, Path]:
    rng = np.random.default_rng(0)
    raw = tmp_path / "scan.raw"
    np.arange(4 * 5 * 6, dtype=np.uint16).tofile(raw)
    nan = rng.random((6, 5, 4)).astype(np.float32)
    nan[1, 2, 3] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    np.save(tmp_path / "flat.npy", np.full((6, 5, 4), 3.0, np.float32))
    np.save(tmp_path / "four.npy", rng.random((2, 6, 5, 4)).astype(np.float32))
    return {"raw": raw, "nan": tmp_path / "nan.npy", "flat": tmp_path / "flat.npy",
            "four": tmp_path / "four.npy"}


# (file, flags already given, the flag the error must name, that flag's value that fixes it)
REFUSALS = [
    ("raw", [], "--dims", ["--dims", "4,5,6", "--dtype", "uint16"]),
    ("raw", ["--dims", "4,5,6"], "--dtype", ["--dtype", "uint16"]),
    ("nan", [], "--replace-nonfinite", ["--replace-nonfinite", "0"]),
    ("flat", [], "--value-range", ["--value-range", "0,10"]),
    ("four", [], "--axes", ["--axes", "tzyx"]),
    ("four", ["--axes", "tzyx", "--time", "2"], "--time", ["--time", "1"]),
    ("four", ["--axes", "czyx", "--channel", "2"], "--channel", ["--channel", "1"]),
]


@pytest.mark.parametrize("name, given, flag, fix", REFUSALS)
def test_a_refusal_names_the_flag_and_the_flag_fixes_it(name, given, flag, fix, tmp_path, capsys,
                                                       no_gpu):
    path = _files(tmp_path)[name]
    rc, err = run(["render", path, *given], capsys)
    assert rc == 2 and err.startswith("error: ") and flag in err, err
    merged = {**dict(zip(given[::2], given[1::2])), **dict(zip(fix[::2], fix[1::2]))}
    args = build_parser().parse_args(["render", str(path), *[x for kv in merged.items() for x in kv]])
    volume = load_scene_volume(apply_options(scene_from_arg(args.scene), args))
    assert volume.dims == (4, 5, 6)


# ---- --set and the named flags -----------------------------------------------------------------

def scene_of(*argv: str, command: str = "render"):
    args = build_parser().parse_args([command, *argv])
    return apply_options(scene_from_arg(args.scene), args)


def test_set_values_are_json_else_numbers_else_text():
    assert set_value("1,1,2") == [1, 1, 2]
    assert set_value("0.5,2") == [0.5, 2.0]
    assert set_value("[1, 2]") == [1, 2]
    assert set_value("3") == 3 and set_value("true") is True and set_value("null") is None
    assert set_value('{"level": 40, "width": 400}') == {"level": 40, "width": 400}
    assert set_value("czyx") == "czyx" and set_value("grey") == "grey"


@pytest.mark.parametrize("command", ["render", "view", "animate"])
def test_set_and_the_named_flags_set_their_keys(command, tmp_path):
    four = _files(tmp_path)["four"]
    scene = scene_of(str(four), "--set", "volume.spacing=1,1,2", "--axes", "tzyx", "--time", "1",
                     "--value-range", "0,2", "--colormap", "grey",
                     "--opacity", "0,0,0.5,0.2,1,1", "--set", "camera.fov_y=30",
                     "--set", "light.direction=0,1,0", command=command)
    assert scene.volume.spacing == (1, 1, 2) and scene.volume.axes == "tzyx" and scene.time == 1
    assert scene.volume.value_range == (0, 2)
    assert scene.transfer_function.colormap == "grey"
    assert scene.transfer_function.opacity == ((0, 0), (0.5, 0.2), (1, 1))
    assert scene.camera.fov_y == 30 and scene.light.direction == (0, 1, 0)
    # --set comes after the named flags; a window replaces the scene's range, and back
    assert scene_of(str(four), "--spacing", "2", "--set", "volume.spacing=[3,3,3]",
                    command=command).volume.spacing == (3, 3, 3)
    assert scene_of(str(four), "--value-range", "0,1", "--set", "volume.window=bone",
                    command=command).volume.value_range is None
    assert scene_of(str(four), "--data-window", "40,400", "--set", "volume.window=null",
                    command=command).volume.window is None


def test_raw_flags_read_a_raw_file_its_name_does_not_describe(tmp_path):
    raw = _files(tmp_path)["raw"]
    volume = load_scene_volume(scene_of(str(raw), "--dims", "4,5,6", "--dtype", "uint16",
                                        "--spacing", "1,1,3"))
    assert volume.dims == (4, 5, 6) and volume.spacing == (1.0, 1.0, 3.0)
    assert volume.value_range == (0.0, 4 * 5 * 6 - 1.0)


def test_colormap_grey_and_gray_are_a_grey_ramp():
    from radiance_probes.scene.transfer import transfer_table
    for name in ("grey", "gray"):
        table = transfer_table(scene_of("--colormap", name).transfer_function)
        assert np.allclose(table[:, 0], table[:, 1]) and np.allclose(table[:, 1], table[:, 2])
        assert table[0, 0] < 0.05 and table[-1, 0] > 0.95 and np.all(np.diff(table[:, 0]) >= 0)


def test_channel_picks_channels_and_the_colormap_goes_to_a_single_one(tmp_path):
    four = str(_files(tmp_path)["four"])
    scene = scene_of(four, "--axes", "czyx", "--channel", "1", "--colormap", "grey")
    assert [c.index for c in scene.channels] == [1]
    assert scene.channels[0].transfer_function.colormap == "grey"
    volume = load_scene_volume(scene)
    assert volume.channel_count == 1
    scene = scene_of(four, "--axes", "czyx", "--channel", "1,0",
                     "--set", "channels[1].transfer_function.colormap=viridis")
    assert [c.index for c in scene.channels] == [1, 0]
    assert scene.channels[1].transfer_function.colormap == "viridis"
    assert load_scene_volume(scene).channel_count == 2


BAD_FLAGS = [
    (["--spacing", "1,2"], "--spacing"),
    (["--spacing", "1,0,1"], "--spacing"),
    (["--value-range", "2,1"], "--value-range"),
    (["--value-range", "0,1", "--data-window", "bone"], "--value-range"),
    (["--dims", "4,5"], "--dims"),
    (["--dims", "4,5,6.5"], "--dims"),
    (["--dtype", "complex"], "--dtype"),
    (["--axes", "czyxx"], "--axes"),
    (["--axes", "abc"], "--axes"),
    (["--replace-nonfinite", "nan"], "--replace-nonfinite"),
    (["--colormap", "jet"], "--colormap"),
    (["--opacity", "0,0,1"], "--opacity"),
    (["--opacity", "0.5,0,0.2,1"], "--opacity"),
    (["--time", "-1"], "--time"),
    (["--channel", "a"], "--channel"),
    (["--channel", "1,1"], "--channel"),
    (["--channel", "0,1", "--colormap", "grey"], "--colormap"),
    (["--set", "spacing"], "--set"),
    (["--set", "volume.foo=1"], "--set volume.foo=1"),
    (["--set", "volume.spacing=1,2"], "--set volume.spacing=1,2"),
    (["--set", "time=-1"], "--set time=-1"),
    (["--set", "channels[3].enabled=false"], "--set channels[3].enabled=false"),
]


@pytest.mark.parametrize("argv, flag", BAD_FLAGS)
def test_a_bad_value_is_one_line_naming_the_flag(argv, flag, capsys, no_gpu):
    rc, err = run(["render", *argv], capsys)
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert flag in err, err


def test_render_reports_the_raymarchers_frames_not_spp(tmp_path, capsys):
    """Issue 55: `render --method raymarch` said "spp: 64"; the raymarcher renders frames."""
    from radiance_probes.cli.main import main
    np.save(tmp_path / "v.npy", np.arange(8 ** 3, dtype=np.float32).reshape(8, 8, 8))
    assert main(["render", str(tmp_path / "v.npy"), "--method", "raymarch", "--spp", "2",
                 "--width", "16", "--height", "16", "--out", str(tmp_path / "a.png")]) == 0
    captured = capsys.readouterr()
    out = captured.out + captured.err
    assert "frames: 2" in out and "raymarch frames: 2/2" in out and "ms per frame" in out
    assert "spp" not in out and "per pixel" not in out
