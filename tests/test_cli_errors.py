"""Bad input to the command line: each ends in one line naming the option (or the scene field) and
the problem, and a non-zero exit; never a traceback, never a render of garbage. Everything a
command can check is checked before the first GPU call: those cases run with GL made to fail."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from radiance_probes.cli.main import main


@pytest.fixture
def no_gpu(monkeypatch):
    """Any GL context made in the test fails it: the checks must come first."""
    import radiance_probes.gl.context

    def refuse(*_a, **_k):
        raise AssertionError("a GL context was created before the input was checked")
    monkeypatch.setattr(radiance_probes.gl.context, "create_headless_context", refuse)


def run(argv, capsys) -> tuple[int, list[str], str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:   # argparse exits
        rc = exc.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "Traceback" not in out
    return rc, [line for line in err.splitlines() if line.strip()], out


def one_error_line(argv, capsys, *needles: str) -> str:
    rc, lines, _ = run(argv, capsys)
    assert rc not in (0, None), f"{argv} was accepted"
    assert len(lines) == 1, f"{argv}: expected one line, got {lines}"
    for needle in needles:
        assert needle in lines[0], f"{argv}: {needle!r} not in {lines[0]!r}"
    return lines[0]


@pytest.fixture
def scene(tmp_path) -> Path:
    p = tmp_path / "tiny.json"
    p.write_text(json.dumps({"volume": {"builtin": "sphere", "size": [8, 8, 8]},
                             "camera": {"width": 8, "height": 8}, "density_scale": 5.0}))
    return p


BAD_RENDER_OPTIONS = [
    (["--width", 200000, "--height", 200000, "--spp", 1], ["--width", "16384"]),
    (["--width", 0], ["--width", "from 1 to"]),
    (["--height", "12.5"], ["--height"]),
    (["--method", "raymarch", "--raymarch-step", 0], ["--raymarch-step", "finite number > 0"]),
    (["--method", "raymarch", "--raymarch-step", -1], ["--raymarch-step"]),
    (["--method", "raymarch", "--raymarch-step", "inf"], ["--raymarch-step"]),
    (["--method", "raymarch", "--raymarch-step", "nan"], ["--raymarch-step"]),
    # finer than the shader's 8192 steps across this 8^3 box allow: it would silently coarsen
    (["--method", "raymarch", "--raymarch-step", 0.001], ["--raymarch-step", "too fine",
                                                            "at least 0.00169"]),
    (["--exposure", "nan"], ["--exposure", "finite number > 0"]),
    (["--exposure", "-inf"], ["--exposure"]),
    (["--exposure", 0], ["--exposure"]),
    (["--exposure", "bright"], ["--exposure", "expected a number"]),
    (["--spp", 0], ["--spp"]),
    (["--spp", 1 << 40], ["--spp", "2147483647"]),
    (["--samples-per-pass", -3], ["--samples-per-pass"]),
    (["--probe-grid", 0], ["--probe-grid"]),
    (["--probe-grid", 300], ["--probe-grid", "probes.grid", "256"]),
    (["--probe-grid", "4,4"], ["--probe-grid", "NX,NY,NZ"]),
    (["--probe-samples", 1 << 30], ["--probe-samples", "probes.samples"]),
    (["--probe-layout", "warped"], ["--probe-layout", "invalid choice"]),
    (["--adaptive-strength", 1.5], ["--adaptive-strength", "probes.adaptive_strength", "<= 1.0"]),
    (["--adaptive-strength", "nan"], ["--adaptive-strength", "finite"]),
    (["--adaptive-indicator", "gradient"], ["--adaptive-indicator", "invalid choice"]),
    (["--method", "probes", "--auto-probes", 2], ["--auto-probes", "(0, 1]"]),
    (["--method", "probes", "--auto-probes", "nan"], ["--auto-probes"]),
    (["--auto-probes", 0.05], ["--auto-probes", "probe method"]),
    (["--auto", 0], ["--auto", "> 0"]),
    (["--auto", 2], ["--auto", "(0, 1]"]),
    (["--auto", 0.05, "--method", "raymarch", "--auto-probes", 0.05], ["--auto", "--auto-probes"]),
    (["--auto", 0.05, "--method", "probes", "--gather-event", 2], ["--gather-event", "--auto"]),
    (["--method", "magic"], ["--method", "invalid choice"]),
    (["--gather-event", 2], ["--gather-event", "probes method", "not pt"]),
    (["--method", "raymarch", "--gather-event", 2], ["--gather-event", "not raymarch"]),
    (["--method", "probes", "--gather-event", 9], ["--gather-event", "from 1 to 8"]),
    (["--method", "probes", "--gather-event", 0], ["--gather-event"]),
    (["--gl-backend", "vulkan"], ["--gl-backend", "invalid choice"]),
    (["--out", "/proc/x.png"], ["--out /proc/x.png", "cannot write there"]),
    (["--out", "picture.jpg"], ["--out picture.jpg", ".png"]),
    (["--linear", "image.txt"], ["--linear image.txt", ".npy"]),
    (["--exr", "image.png"], ["--exr image.png", ".exr"]),
    (["--exr", "/proc/a.exr"], ["--exr /proc/a.exr", "cannot write there"]),
]


@pytest.mark.parametrize("options, needles", BAD_RENDER_OPTIONS,
                         ids=[" ".join(map(str, o)) for o, _ in BAD_RENDER_OPTIONS])
def test_bad_render_option_is_one_line_before_any_gpu_work(options, needles, scene, tmp_path,
                                                          capsys, no_gpu):
    one_error_line(["render", scene, "--out", tmp_path / "o.png", *options], capsys, *needles)


def test_a_huge_exposure_clips_to_white_without_numpy_warnings():
    import warnings
    from radiance_probes.rendering.tonemap import to_uint8
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = to_uint8(np.full((2, 2, 3), 5.0, np.float32), 1e308)
    assert (out == 255).all()


def test_output_that_is_a_folder_or_under_a_file(scene, tmp_path, capsys, no_gpu):
    one_error_line(["render", scene, "--out", tmp_path], capsys, "is a folder")
    (tmp_path / "plain").write_text("x")
    one_error_line(["render", scene, "--out", tmp_path / "plain" / "o.png"], capsys,
                   "is a file, not a folder")
    assert not (tmp_path / "o.png").exists()


def test_checking_an_output_leaves_no_file(scene, tmp_path, capsys, no_gpu):
    """--out is checked by creating it; a render refused later must not leave an empty file."""
    one_error_line(["render", scene, "--out", tmp_path / "sub" / "o.png", "--exposure", "nan"],
                   capsys, "--exposure")
    one_error_line(["render", scene, "--out", tmp_path / "sub" / "o.png", "--width", 0], capsys)
    assert not (tmp_path / "sub" / "o.png").exists()


def test_bad_scene_is_one_line(tmp_path, capsys, no_gpu):
    p = tmp_path / "s.json"
    for text, needle in (('{"camera": {"width": 1e6}}', "camera.width"),
                         ('{"density_scale": NaN}', "density_scale"),
                         ('{"volume": {"path": "nowhere.raw"}}', "not found"),
                         ("{", "not valid JSON")):
        p.write_text(text)
        one_error_line(["render", p, "--out", tmp_path / "o.png"], capsys, needle)
    one_error_line(["render", tmp_path / "missing.json"], capsys, "not found")
    one_error_line(["render", tmp_path / "volume.xyz"], capsys, "not found")


def test_bad_view_options(capsys, no_gpu):
    for options, needle in ((["--render-scale", 0], "--render-scale"),
                            (["--render-scale", "nan"], "--render-scale"),
                            (["--render-scale", 100], "(0, 4.0]"),
                            (["--exposure", "nan"], "--exposure"),
                            (["--window", "10x10"], "--window"),
                            (["--window", "200000x200000"], "--window"),
                            (["--probe-grid", 1000], "--probe-grid"),
                            (["--file-dialog", "qt"], "--file-dialog")):
        one_error_line(["view", *options], capsys, needle)


def test_unknown_gl_backend_from_the_environment(scene, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("RP_GL_BACKEND", "vulkan")
    one_error_line(["render", scene, "--out", tmp_path / "o.png"], capsys, "RP_GL_BACKEND",
                   "vulkan")


class FakeContext:
    def __init__(self, **info):
        self.info = {"GL_RENDERER": "a test device", "GL_MAX_TEXTURE_SIZE": 16384,
                     "GL_MAX_VIEWPORT_DIMS": (16384, 16384),
                     "GL_MAX_COMPUTE_WORK_GROUP_COUNT": (65535, 65535, 65535), **info}
        self.extensions = set()


def test_image_size_against_the_device_limits(monkeypatch):
    from radiance_probes.rendering.limits import DeviceLimitError, check_image_size
    check_image_size(FakeContext(), 1024, 768)
    with pytest.raises(DeviceLimitError, match=r"image 5000 x 10: .*GL_MAX_TEXTURE_SIZE = 4096"):
        check_image_size(FakeContext(GL_MAX_TEXTURE_SIZE=4096), 5000, 10)
    with pytest.raises(DeviceLimitError, match=r"GL_MAX_VIEWPORT_DIMS = 2048"):
        check_image_size(FakeContext(GL_MAX_VIEWPORT_DIMS=(2048, 4096)), 10, 3000)
    with pytest.raises(DeviceLimitError, match=r"GL_MAX_COMPUTE_WORK_GROUP_COUNT = 100"):
        check_image_size(FakeContext(GL_MAX_COMPUTE_WORK_GROUP_COUNT=(100, 100, 100)), 801, 10)
    # Memory: a software renderer's comes from the host, checked before any allocation.
    import radiance_probes.gl.memory
    monkeypatch.setattr(radiance_probes.gl.memory, "host_available_bytes", lambda: 100 * 2**20)
    soft = FakeContext(GL_RENDERER="llvmpipe (LLVM 15.0.7, 256 bits)")
    check_image_size(soft, 256, 256)
    with pytest.raises(DeviceLimitError, match=r"4096 x 4096: needs about .* GiB.*host memory"):
        check_image_size(soft, 4096, 4096)


def test_image_beyond_the_device_is_one_line_before_the_scene_is_uploaded(scene, tmp_path, capsys,
                                                                          monkeypatch):
    import radiance_probes.rendering.renderer
    import radiance_probes.rendering.limits
    monkeypatch.setattr(radiance_probes.rendering.limits, "_limit",
                        lambda ctx, name, default: 64 if name == "GL_MAX_TEXTURE_SIZE" else 1 << 20)

    def refuse(*_a, **_k):
        raise AssertionError("the renderer was built before the image size was checked")
    monkeypatch.setattr(radiance_probes.rendering.renderer, "Renderer", refuse)
    one_error_line(["render", scene, "--out", tmp_path / "o.png", "--width", 65, "--height", 8],
                   capsys, "image 65 x 8", "GL_MAX_TEXTURE_SIZE = 64")


def test_renderer_options_are_checked(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.rendering.settings import RenderSettings
    from radiance_probes.io.scene_file import parse_scene
    scene = parse_scene({"volume": {"builtin": "sphere", "size": [4, 4, 4]},
                         "camera": {"width": 4, "height": 4}})
    for bad in (0, -1.0, math.nan, math.inf, "0.5", True):
        with pytest.raises(ValueError, match="raymarch step"):
            RenderSettings(raymarch_step=bad)
    with pytest.raises(ValueError, match="raymarch stage"):
        RenderSettings(raymarch_stage="geometry")
    for bad in ({"walk_sun": "sky"}, {"walk_adaptive": -1.0}, {"light_precision": "f8"},
                {"gather_event": 0}, {"light_max_side": 0}, {"sun_lobe": 1}):
        with pytest.raises(ValueError, match=next(iter(bad)).split("_")[-1]):
            RenderSettings(**bad)
    with pytest.raises(ValueError, match="unknown render setting.*walk_sunn"):
        RenderSettings.from_dict({"walk_sunn": "ray"})
    r = Renderer(ctx, scene, settings=RenderSettings(raymarch_step=2, empty_space_skipping=False))
    try:
        assert r.raymarch_step_voxels == 2.0 and not r.resources.use_majorant_grid
        with pytest.raises(ValueError, match="raymarch step"):
            r.configure(raymarch_step=math.nan)
        assert r.raymarch_step_voxels == 2.0
        r.configure(raymarch_step=1e-4)   # finer than 8192 steps across a 4^3 box: said, not hidden
        assert r.effective_raymarch_step_voxels == pytest.approx(3 ** 0.5 / 8192 * 4)
    finally:
        r.release()


def test_a_failed_write_after_the_render_says_where_the_image_went(scene, tmp_path, capsys,
                                                                   monkeypatch):
    """The output was writable when checked but not when the render ended (here: a save that
    fails for the asked path): the image is written to the temporary folder instead, the error
    line says where, and the exit is non-zero."""
    import radiance_probes.frontend.imageio
    real_save_png = radiance_probes.frontend.imageio.save_png
    wanted = tmp_path / "o.png"

    def failing_save_png(path, image, exposure=1.0):
        if Path(path) == wanted:
            raise OSError(28, "No space left on device")
        return real_save_png(path, image, exposure)
    monkeypatch.setattr(radiance_probes.frontend.imageio, "save_png", failing_save_png)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "rescue"))
    (tmp_path / "rescue").mkdir()
    rc, lines, out = run(["render", scene, "--out", wanted, "--spp", 1, "--linear",
                          tmp_path / "o.npy"], capsys)
    errors = [line for line in lines if line.startswith("error:")]
    assert rc == 1 and len(errors) == 1, lines
    assert "No space left on device" in errors[0] and "written to" in errors[0]
    rescued = Path(errors[0].rsplit("written to ", 1)[1].split(" instead")[0])
    assert rescued.parent == tmp_path / "rescue" and rescued.suffix == ".png" and rescued.is_file()
    assert not wanted.exists()
    assert np.load(tmp_path / "o.npy").shape == (8, 8, 3)   # the other output is unaffected


def test_default_raymarch_step_lengthened_by_the_shader_is_said(tmp_path, capsys):
    """On a box 1000 times longer than its voxels are thin, the default 0.5-voxel step would need
    more than the shader's 8192 steps: the render goes ahead and says which step it took."""
    p = tmp_path / "thin.json"
    p.write_text(json.dumps({"volume": {"builtin": "sphere", "size": [8, 8, 8],
                                        "spacing": [1, 1, 1000]},
                             "camera": {"width": 4, "height": 4},
                             "probes": {"grid": 2, "samples": 1}}))
    rc, lines, out = run(["render", p, "--method", "raymarch", "--spp", 1,
                          "--out", tmp_path / "o.png"], capsys)
    assert rc == 0 and not [line for line in lines if line.startswith("error")]
    assert "note: raymarch step 0.977 voxels, not the default 0.5" in out
    one_error_line(["render", p, "--method", "raymarch", "--raymarch-step", 0.5, "--out",
                    tmp_path / "o.png"], capsys, "--raymarch-step", "at least 0.977")


@pytest.mark.parametrize("max_bounces, event, said",
                         [(3, 2, True), (3, 3, True), (3, 1, False), (3, 4, False), (64, 3, False)])
def test_a_gather_past_a_small_max_bounces_is_said(tmp_path, capsys, max_bounces, event, said):
    """The probes hold max_bounces - 1 events whatever the gather event, so a later gather lets
    a path scatter past max_bounces; where that is large enough to see, the render says so."""
    p = tmp_path / "s.json"
    p.write_text(json.dumps({"volume": {"builtin": "cloud", "size": [8, 8, 8]},
                             "max_bounces": max_bounces, "camera": {"width": 4, "height": 4},
                             "probes": {"grid": 2, "samples": 1}}))
    rc, lines, out = run(["render", p, "--method", "probes", "--spp", 1, "--gather-event", event,
                          "--out", tmp_path / "o.png"], capsys)
    assert rc == 0 and (event > 1) == ("final gather: the probes read at scattering event" in out)
    note = [line for line in lines if line.startswith("note: the probes hold")]
    assert bool(note) == said
    if said:
        assert f"up to {max_bounces + event - 1} times, not {max_bounces}" in note[0]


def test_view_with_a_missing_volume_is_one_line_before_any_window(tmp_path, capsys, no_gpu,
                                                                  monkeypatch):
    import radiance_probes.viewer.xvfb
    monkeypatch.setattr(radiance_probes.viewer.xvfb.Xvfb, "start", lambda self: (_ for _ in ()).throw(
        AssertionError("an X server was started before the volume was checked")))
    one_error_line(["view", tmp_path / "nowhere.raw", "--frames", 1], capsys, "nowhere.raw",
                   "not found")


def test_view_screenshot_path_is_checked_before_any_window(scene, capsys, no_gpu, monkeypatch):
    import radiance_probes.viewer.xvfb
    monkeypatch.setattr(radiance_probes.viewer.xvfb.Xvfb, "start", lambda self: (_ for _ in ()).throw(
        AssertionError("an X server was started before --screenshot was checked")))
    one_error_line(["view", scene, "--screenshot", "/proc/shot.png", "--frames", 1], capsys,
                   "--screenshot /proc/shot.png", "cannot write there")
    one_error_line(["view", scene, "--screenshot", "shot.jpg"], capsys, ".png")


def test_view_bad_script_is_one_line_before_any_window(scene, tmp_path, capsys, no_gpu,
                                                       monkeypatch):
    import radiance_probes.viewer.xvfb
    monkeypatch.setattr(radiance_probes.viewer.xvfb.Xvfb, "start", lambda self: (_ for _ in ()).throw(
        AssertionError("an X server was started before the script was read")))
    (tmp_path / "s.json").write_text('{"not": "a list"}')
    one_error_line(["view", scene, "--script", tmp_path / "s.json"], capsys, "s.json",
                   "a JSON list of objects")
    one_error_line(["view", scene, "--script", tmp_path / "missing.json"], capsys,
                   "cannot read the script")


def test_bad_new_format_volumes_are_one_line(tmp_path, capsys, no_gpu, monkeypatch):
    """A TIFF, NIfTI or DICOM folder the loaders refuse ends `render` and `view` like any bad
    volume: one line naming it, before any GPU work or window."""
    (tmp_path / "empty").mkdir()
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "a.txt").write_text("no images here")
    (tmp_path / "bad.nii.gz").write_bytes(b"\x1f\x8b" + bytes(30))
    for path, needle in ((tmp_path / "empty", "holds no files"),
                         (tmp_path / "notes", "holds no DICOM files"),
                         (tmp_path / "bad.nii.gz", "cannot read NIfTI")):
        one_error_line(["render", path, "--out", tmp_path / "o.png"], capsys, str(path), needle)
    import radiance_probes.viewer.xvfb
    monkeypatch.setattr(radiance_probes.viewer.xvfb.Xvfb, "start", lambda self: (_ for _ in ()).throw(
        AssertionError("an X server was started before the volume was checked")))
    one_error_line(["view", tmp_path / "empty", "--frames", 1], capsys, "holds no files")
