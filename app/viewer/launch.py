"""``radiance-probes view``: opens the window, or runs a script or N frames and saves a
screenshot; with no display at all it renders the scene headless and says so."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from radiance_probes.frontend.scene_options import SCENE_KEY_DESTS, apply_options, scene_from_arg
from radiance_probes.frontend.render_files import check_output, render_defaults, render_to_files
from radiance_probes.io.scene_file import Scene
from radiance_probes.rendering.budgets.device_defaults import (RENDER_SCALE, probes_named,
                                                               with_device_probes)
from radiance_probes.viewer.files import bundled_scene_for
from radiance_probes.viewer.state import ViewerState
from radiance_probes.viewer.xvfb import Xvfb, XvfbError, has_display


def initial_state(scene: Scene, args: argparse.Namespace) -> ViewerState:
    state = ViewerState.for_scene(scene)   # shown as the scene's "viewer" key says, if it has one
    if args.method:
        state.set_method(args.method)
    if args.split:
        state.split_method = args.split
        state.set_display("split")
    if args.error_view:
        state.set_display("error")
    if args.probe_view:
        state.probe_view = args.probe_view
    if args.slices:
        state.slice_view = args.slices
    if args.slice_colours:
        state.slice_colours = "window" if args.slice_colours == "window" else "transfer function"
    state.show_box = args.box or state.show_box
    if args.exposure is not None:
        state.exposure = args.exposure
    if args.spp:
        state.max_samples = args.spp
    if args.scene and args.scene.lower().endswith(".json"):
        state.scene_path = args.scene
    return state


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene argument (as `render` reads it) with the --probe-* options applied."""
    from radiance_probes.io.volume import is_volume_path
    from radiance_probes.viewer.files import scene_for_path
    if args.scene and is_volume_path(Path(args.scene)):
        # A volume file opens as it does when dropped: with its bundled scene where there is one.
        scene, _ = scene_for_path(args.scene, scene_from_arg(None))
    else:
        scene = scene_from_arg(args.scene)
    return apply_options(scene, args)


def view_aspect(window: tuple[int, int], slices: str | None = None) -> float:
    """The picture's aspect in a window of this size (the panel on its left, the slice column,
    where `slices` is on, on its right)."""
    from radiance_probes.viewer.layout import SIDEBAR_WIDTH
    from radiance_probes.viewer.slice_view import column_width
    width, height = window
    column = column_width(slices or "off", window, SIDEBAR_WIDTH)
    return max(width - SIDEBAR_WIDTH - column, 1) / max(height, 1)


def run_view(args: argparse.Namespace) -> int:
    from radiance_probes.io.environment_map import load_scene_environment
    from radiance_probes.scene.framing import frame_default_camera
    from radiance_probes.scene.clinical_presets import opening_scene
    from radiance_probes.io.load import load_scene_volume, reads_lazily, zarr_preview
    scene = scene_from_args(args)
    progressive = False
    if args.screenshot:
        check_output(args.screenshot, "--screenshot")   # before a long scripted run, not after
    steps = None
    if args.script:
        from radiance_probes.viewer.script import ScriptError, load_script
        try:
            steps = load_script(args.script)   # a bad script fails before anything opens
        except ScriptError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 3
    scripted = bool(args.screenshot or args.script or args.frames)
    if has_display() or scripted:
        # A volume that does not load fails here, before a window, an X server or a GL context;
        # a Zarr store read brick by brick loads on a thread once the window is open, a preview
        # of it shown meanwhile (app/rendering/levels/progressive_open.py).
        volume = (zarr_preview(scene, memory_bytes=getattr(args, "volume_memory", None))
                  if reads_lazily(scene) else None)
        progressive = volume is not None
        if volume is None:
            volume = load_scene_volume(scene)
            scene = opening_scene(scene, volume)   # a CT opens with its clinical preset
        scene = frame_default_camera(scene, volume.half_extent,
                                     view_aspect(args.window, args.slices))
        load_scene_environment(scene)   # and an environment map (kept in its cache)
        for note in volume.notes:
            print(f"view: note: {note}", file=sys.stderr)
    else:
        volume = None   # the headless fallback loads it
    xvfb = None
    if not has_display():
        if not scripted:
            return headless_fallback(args, "DISPLAY is not set")
        xvfb = Xvfb(*args.window)
        try:
            os.environ["DISPLAY"] = xvfb.start()
            print(f"view: no display; running in a private Xvfb ({os.environ['DISPLAY']})", file=sys.stderr)
        except XvfbError as exc:
            return headless_fallback(args, f"DISPLAY is not set and Xvfb could not be started ({exc})")
    try:
        return _run_window(args, scene, volume, steps, scripted, progressive)
    finally:
        if xvfb is not None:
            xvfb.stop()


def _run_window(args: argparse.Namespace, scene: Scene, volume, steps, scripted: bool,
                progressive: bool = False) -> int:
    from radiance_probes.viewer.script import ScriptError, ScriptRunner
    from radiance_probes.viewer.window import ViewerWindow, WindowError
    state = initial_state(scene, args)
    width, height = args.window
    try:
        settings = None
        if getattr(args, "volume_memory", None):
            from radiance_probes.rendering.settings import RenderSettings
            settings = RenderSettings(volume_memory_bytes=args.volume_memory)
        window = ViewerWindow(state, width, height, vsync=not scripted,
                              file_dialog=args.file_dialog, volume=volume, settings=settings)
    except WindowError as exc:
        return headless_fallback(args, str(exc))
    software = any(n in window.viewer.device.lower() for n in ("llvmpipe", "softpipe", "lavapipe"))
    device = "software" if software else "gpu"
    state.render_scale = args.render_scale or RENDER_SCALE[device]
    print(f"view: {window.viewer.device}", file=sys.stderr)
    bundled = (bundled_scene_for(Path(args.scene).expanduser())
               if args.scene and not args.scene.lower().endswith(".json") else None)
    named = probes_named(args.scene, args.probe_grid, args.probe_samples, bundled)
    state.scene, said = with_device_probes(state.scene, device, named)
    if said:
        print(f"view: {said}", file=sys.stderr)
    rc = 0
    if progressive:
        window.viewer.open_in_background(state.scene)
        if scripted and steps is None:   # --frames / --screenshot show the volume, not its preview
            window.viewer.finish_opening()
    try:
        if steps is not None:
            ScriptRunner(window, Path.cwd()).run(steps)
        if args.frames:  # the screenshot's frame is the last of them
            ScriptRunner(window, Path.cwd()).frame(args.frames - (1 if args.screenshot else 0))
        if args.screenshot:
            frames, waited = _wait_for_a_whole_image(window)
            window.viewer.request_screenshot(args.screenshot)
            window.poll()
            window.frame()
            _say_whether_whole(window, args.screenshot, frames, waited)
            _, saved, error = window.viewer.last_screenshot
            if error:   # written elsewhere (or lost): said once, as the command's error
                state.errors.remove(error)
                print(f"error: --{error}", file=sys.stderr)
                rc = 1
            else:
                print(f"wrote {saved}")
        if not scripted:
            window.run()
        for text in state.errors:
            print(f"view: error shown in the window: {text}", file=sys.stderr)
    except ScriptError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        return 130
    finally:
        window.close()
    return rc


# `--screenshot` after `--frames N`: frames go on while a view's first sample is still in bands
# (a software renderer's sample takes several frames), at most this long; past it the image is
# saved as it is, and a line says it is partial.
SCREENSHOT_WAIT_S = 120.0


def _partial_views(window) -> list[str]:
    """The views whose display shows no whole image yet (all, before a first frame)."""
    session = window.viewer.session
    if not session.views:
        return ["(no frame yet)"]
    return [m for m in session.views if not session.shows_whole(m)]


def _wait_for_a_whole_image(window) -> tuple[int, float]:
    """Frames until every view shows a whole image (RenderSession.shows_whole) or
    SCREENSHOT_WAIT_S have passed: how many, and their seconds."""
    import time
    start, frames = time.perf_counter(), 0
    while (_partial_views(window) and time.perf_counter() - start < SCREENSHOT_WAIT_S
           and not window.should_close()):
        window.poll()
        window.frame()
        frames += 1
    return frames, time.perf_counter() - start


def _say_whether_whole(window, out: str, frames: int, waited: float) -> None:
    """One line on stderr where the screenshot had to wait for a whole image, or is partial."""
    session = window.viewer.session
    left = _partial_views(window)
    if left:
        parts = ", ".join(f"{m}'s first {'frame' if m == 'raymarch' else 'sample'} "
                          f"{100 * session.part_done(m):.0f}% done" for m in left)
        print(f"view: warning: {out} is partial ({parts}, {frames} frames and {waited:.0f} s "
              f"past --frames); a larger --frames, a smaller --window or --render-scale gives a "
              f"whole image", file=sys.stderr)
    elif frames:
        print(f"view: note: {frames} more frames ({waited:.1f} s) for a whole image: one sample "
              f"takes several frames on this device", file=sys.stderr)


def headless_fallback(args: argparse.Namespace, reason: str) -> int:
    """Renders the scene as `render` does when no window can be opened."""
    out = args.screenshot or "view.png"
    method = args.method or "pt"
    print(f"view: no display available ({reason}), so no window can open. Rendering the scene "
          f"headless instead ({method}, {args.spp or 64} spp) to {out}.", file=sys.stderr)
    options = render_defaults()
    options.update(scene=args.scene, method=method, spp=args.spp or 64, out=out,
                   probe_grid=args.probe_grid, probe_samples=args.probe_samples,
                   sh_window=args.sh_window, probe_precision=args.probe_precision, seed=args.seed,
                   exposure=args.exposure or 1.0, gl_backend=args.gl_backend,
                   **{k: getattr(args, k, None) for k in ("series", "orientation", "data_window",
                                                          "crop", "crop_voxels", "clip_plane",
                                                          "transfer_function",
                                                          "volume_memory", *SCENE_KEY_DESTS)},
                   no_crop=getattr(args, "no_crop", False),
                   no_clip_plane=getattr(args, "no_clip_plane", False))
    return render_to_files(argparse.Namespace(**options))
