"""Movies (app/movie/frames.py, app/scene/camera_path.py, app/movie/writer.py, `radiance-probes animate`): the
camera paths, the frames a media player reads back, the probes baked once per movie."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.scene.camera_path import keyframes, turntable
from radiance_probes.cli.main import main
from radiance_probes.movie.writer import MovieError, MovieWriter, count_frames, movie_format
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import BookmarkSpec, CameraSpec, parse_scene

# ---- camera paths ------------------------------------------------------------------------------


def test_turntable_turns_about_up_through_the_target():
    cam = CameraSpec(eye=(0.0, 0.5, 2.0), target=(0.1, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    cams = turntable(cam, 360.0, 4)
    assert cams[0].eye == pytest.approx(cam.eye)
    eyes = np.array([c.eye for c in cams]) - np.array(cam.target)
    # the distance to the target and the height along up stay; the angle steps by 90 degrees
    np.testing.assert_allclose(np.linalg.norm(eyes, axis=1), np.linalg.norm(eyes[0]))
    np.testing.assert_allclose(eyes[:, 1], 0.5)
    angles = np.degrees(np.arctan2(eyes[:, 0], eyes[:, 2]))
    np.testing.assert_allclose(np.diff(np.unwrap(np.radians(angles))), math.pi / 2)
    assert all(c.target == cam.target and c.width == cam.width for c in cams)


def test_keyframes_pass_through_bookmarks_on_an_orbit():
    base = CameraSpec(width=64, height=48)
    a = BookmarkSpec("a", eye=(2.0, 0.0, 0.0)).camera(base)
    b = BookmarkSpec("b", eye=(0.0, 0.0, 2.0), fov_y=20.0).camera(base)
    c = BookmarkSpec("c", eye=(-2.0, 0.0, 0.0)).camera(base)
    cams = keyframes([a, b, c], 41, base)
    assert cams[0].eye == pytest.approx(a.eye) and cams[-1].eye == pytest.approx(c.eye)
    assert cams[20].eye == pytest.approx(b.eye, abs=1e-9) and cams[20].fov_y == pytest.approx(20.0)
    # an orbit: the distance to the target stays 2 (straight lines between eyes would not)
    eyes = np.array([x.eye for x in cams])
    np.testing.assert_allclose(np.linalg.norm(eyes, axis=1), 2.0, rtol=1e-9)
    # smooth: eased in and out, no jumps between frames
    steps = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    assert steps[0] < 0.3 * steps.max() and steps[-1] < 0.3 * steps.max()
    assert np.all(np.abs(np.diff(steps)) < 0.2 * steps.max())
    assert all((x.width, x.height) == (64, 48) for x in cams)


# ---- writing and reading back ----------------------------------------------------------------------

def test_movie_formats_and_bad_outputs(tmp_path):
    assert movie_format("a.mp4") == "mp4" and movie_format("b.GIF") == "gif"
    assert movie_format(str(tmp_path / "frames")) == "png"
    assert movie_format("shots/f_%04d.png") == "png"
    with pytest.raises(MovieError, match="number field"):
        movie_format("f.png")
    with pytest.raises(MovieError, match="expected a .mp4 or .gif"):
        movie_format("movie.avi")
    with pytest.raises(MovieError, match="even width and height, got 33x32"):
        MovieWriter(str(tmp_path / "odd.mp4"), 33, 32)


@pytest.mark.parametrize("name", ["m.mp4", "m.gif", "frames"])
def test_writer_frames_read_back(tmp_path, name):
    frames = [np.full((32, 48, 3), 10 * i, np.uint8) for i in range(7)]
    writer = MovieWriter(str(tmp_path / name), 48, 32, fps=12)
    for f in frames:
        writer.add(f)
    path = writer.close()
    if name == "frames":
        assert sorted(p.name for p in path.iterdir()) == [f"frame_{i:04d}.png" for i in range(7)]
    else:
        assert count_frames(path) == 7


def test_frame_readback_is_the_png_tone_map(ctx):
    from radiance_probes.rendering.methods.accumulation import Accumulation
    from radiance_probes.rendering.frame_readback import FrameReadback
    from radiance_probes.rendering.tonemap import to_uint8
    rng = np.random.default_rng(1)
    image = (rng.uniform(0, 1.5, (21, 37, 4)) ** 2).astype(np.float32)
    acc = Accumulation(ctx, 37, 21)
    readback = FrameReadback(ctx)
    try:
        acc.texture.write(image.tobytes())
        got = readback.read(acc, exposure=1.7)
    finally:
        acc.release()
        readback.release()
    want = to_uint8(image[..., :3], 1.7)
    assert got.shape == want.shape
    assert np.abs(got.astype(int) - want).max() <= 1


# ---- animate: frames counted back, probes baked once -------------------------------------------------

TINY = ["--width", "32", "--height", "32", "--probe-grid", "4", "--probe-samples", "16"]


@pytest.fixture
def bake_counter(monkeypatch):
    """Counts Renderer.start_bake calls: every probe bake starts there."""
    calls = []
    original = Renderer.start_bake

    def counting(self, *args, **kwargs):
        calls.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Renderer, "start_bake", counting)
    return calls


def test_animate_turntable_to_mp4_bakes_once(tmp_path, capsys, bake_counter):
    out = tmp_path / "turn.mp4"
    rc = main(["animate", "--frames", "12", "--spp", "2", "--out", str(out), "--colorbar", *TINY])
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert count_frames(out) == 12                  # what a media player decodes
    assert len(bake_counter) == 1                   # one bake for the whole movie
    assert "probes baked 1x" in text.out and "12 frames as a media player reads them" in text.out
    assert "animate [" in text.err                  # the progress bar


def test_animate_keyframes_to_gif_and_pngs(tmp_path, capsys, bake_counter):
    scene = tmp_path / "scene.json"
    scene.write_text('{"camera": {"width": 32, "height": 32}, "bookmarks": ['
                     '{"name": "front", "eye": [0, 0.3, 2.2]},'
                     '{"name": "side", "eye": [2.2, 0.3, 0]},'
                     '{"name": "back", "eye": [0, 0.3, -2.2], "fov_y": 25}]}')
    gif = tmp_path / "fly.gif"
    assert main(["animate", str(scene), "--keyframes", "--frames", "6", "--spp", "1",
                 "--method", "probes-only", "--out", str(gif), *TINY]) == 0
    assert count_frames(gif) == 6 and len(bake_counter) == 1
    pngs = tmp_path / "pngs"
    assert main(["animate", str(scene), "--keyframes", "side,front", "--frames", "3",
                 "--spp", "1", "--method", "pt", "--out", str(pngs), *TINY]) == 0
    assert len(list(pngs.glob("frame_*.png"))) == 3
    assert len(bake_counter) == 1                   # the path tracer bakes nothing
    capsys.readouterr()


@pytest.mark.parametrize("args, message", [
    (["--keyframes"], "the scene has no bookmarks"),
    (["--width", "33", "--height", "32"], "even width and height"),
    (["--out", "movie.avi"], "expected a .mp4 or .gif"),
])
def test_animate_refuses_before_rendering(tmp_path, capsys, args, message):
    rc = main(["animate", "--frames", "2", *args])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_keyframes_name_a_missing_bookmark(tmp_path, capsys):
    scene = tmp_path / "s.json"
    scene.write_text('{"bookmarks": [{"name": "a", "eye": [0, 0, 2]}]}')
    assert main(["animate", str(scene), "--keyframes", "a,b", "--frames", "2"]) == 2
    assert "no bookmark named 'b'" in capsys.readouterr().err


def test_bench_movie_preset_at_tiny_size(tmp_path, capsys):
    """`bench --preset movie` (the issue's 120-frame 1080p bonsai on the GPU) at llvmpipe size:
    the movie's record holds its time, its probes baked once, the frames ffmpeg decodes, the check
    frames' errors and the path tracer's time to the same errors."""
    import json
    assert main(["bench", "--preset", "movie-quick", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    data = json.loads((tmp_path / "results.json").read_text())
    (record,) = data["records"]
    assert record["mode"] == "movie" and record["frames"] == 12
    assert record["frames_decoded"] == 12 and record["bakes"] == 1
    assert record["total_s"] > 0 and record["bake_ms"] > 0
    assert [f["frame"] for f in record["check_frames"]] == [0, 6]
    for f in record["check_frames"]:
        assert 0 < f["rrmse"] < 0.5 and f["pt"]["spp"] >= 1 and f["pt"]["gpu_ms"] > 0
    assert record["pt_movie_gpu_s_at_same_error"] > 0
    assert "| tiny | 48x32 | 12 |" in (tmp_path / "report.md").read_text()
