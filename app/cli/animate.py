"""``radiance-probes animate SCENE``: a turntable or a flight through the scene's bookmarks, to
MP4, GIF or numbered PNGs, with a progress bar; the probes are baked once for the whole movie
(app/movie/frames.py). Every option is checked before the GPU starts, as `render`'s are."""
from __future__ import annotations

import argparse
import sys

from radiance_probes.methods import METHODS as REGISTRY
from radiance_probes.frontend.option_types import (OptionError, grid_arg, positive_float,
                                                   positive_int)
from radiance_probes.frontend.scene_options import (add_colorbar_options, add_scene_edit_options,
                                                    add_volume_options, apply_options, check_clip,
                                                    scene_from_arg)

DEFAULT_FRAMES = 120
DEFAULT_SPP = 16
MAX_FRAMES = 100_000


def bookmark_list(text: str) -> list[str]:
    """`--keyframes`: bookmark names separated by commas (none: all of the scene's, in order)."""
    return [t.strip() for t in text.split(",") if t.strip()]


def add_animate_parser(sub, func) -> argparse.ArgumentParser:
    from radiance_probes.movie.writer import DEFAULT_CRF
    from radiance_probes.rendering.renderer import RAYMARCH_STAGES
    from radiance_probes.methods import MOVIE_METHODS as METHODS
    a = sub.add_parser("animate", help="render a movie: a turntable, or a flight through the "
                                       "scene's bookmarks (MP4, GIF or numbered PNGs)")
    a.add_argument("scene", nargs="?", help="scene JSON, a volume file or a folder (TIFF, DICOM; "
                                            "default: the built-in scene)")
    path = a.add_mutually_exclusive_group()
    path.add_argument("--turntable", type=float, metavar="DEGREES",
                      help="turn the camera about its up axis through the target by DEGREES over "
                           "the movie (default 360: a loop)")
    path.add_argument("--keyframes", nargs="?", const="", type=bookmark_list, metavar="A,B,...",
                      help="fly smoothly through these bookmarks of the scene (default: all, in "
                           "order)")
    a.add_argument("--frames", type=lambda t: positive_int(t, MAX_FRAMES), default=None,
                   help=f"frames in the movie (default {DEFAULT_FRAMES}; with --time-series, one "
                        "a step)")
    a.add_argument("--time-series", action="store_true",
                   help="play the volume's time steps, first to last, over the movie (the camera "
                        "still unless --turntable or --keyframes moves it); each step's probes "
                        "are baked before its first frame")
    a.add_argument("--fps", type=positive_float, default=30.0, help="frames a second (default 30)")
    a.add_argument("--out", default="movie.mp4",
                   help="movie.mp4, movie.gif, a folder for numbered PNGs, or a pattern such as "
                        "frames/f_%%04d.png (default movie.mp4)")
    a.add_argument("--method", choices=METHODS, default="raymarch",
                   help="render method (default raymarch, over probes baked once)")
    a.add_argument("--spp", type=positive_int, default=DEFAULT_SPP,
                   help=f"samples per pixel per frame (raymarch: jittered frames; default "
                        f"{DEFAULT_SPP})")
    a.add_argument("--samples-per-pass", type=positive_int, default=16,
                   help="samples per pixel in one GPU dispatch (default 16)")
    a.add_argument("--denoise", action="store_true",
                   help="pass every frame through the denoiser (Open Image Denoise, guided by "
                        "the probes' image or the albedo and normal): no temporal filtering, so "
                        "a noisy method's frames can flicker (docs/denoising.md)")
    a.add_argument("--width", type=positive_int,
                   help="frame width in pixels (camera.width; default: the scene's, 512)")
    a.add_argument("--height", type=positive_int,
                   help="frame height in pixels (camera.height; default: the scene's, 512)")
    a.add_argument("--exposure", type=positive_float, default=1.0,
                   help="exposure of the tone-mapped frames (default 1)")
    a.add_argument("--seed", type=int, default=0,
                   help="random seed of the samples (default 0): the same seed, the same image")
    a.add_argument("--quality", type=lambda t: positive_int(t, 51), default=DEFAULT_CRF,
                   metavar="CRF", help=f"MP4: H.264 constant rate factor, lower is better "
                                       f"(default {DEFAULT_CRF})")
    a.add_argument("--probe-grid", type=grid_arg, help="probes per axis: N or NX,NY,NZ (1..256)")
    a.add_argument("--probe-samples", type=positive_int, help="walks per probe")
    a.add_argument("--raymarch-stage", choices=RAYMARCH_STAGES, default="compute",
                   help="raymarch as a compute (default) or fragment shader")
    a.add_argument("--raymarch-step", type=positive_float, help="raymarch step in voxels")
    add_volume_options(a)
    add_scene_edit_options(a)
    add_colorbar_options(a)
    from radiance_probes.gl.context import BACKENDS
    a.add_argument("--gl-backend", choices=BACKENDS,
                   help=f"headless OpenGL backend (default: the first that works of "
                        f"{', '.join(BACKENDS)})")
    a.set_defaults(func=func)
    return a


def run_animate(args: argparse.Namespace) -> int:
    from radiance_probes.frontend.colorbar import scene_colorbar_overlay
    from radiance_probes.io.environment_map import load_scene_environment
    from radiance_probes.frontend.option_types import DEFAULT_RAYMARCH_STEP
    from radiance_probes.gl.context import create_headless_context, describe, is_software
    from radiance_probes.movie.frames import (frame_count_note, movie_cameras, render_movie,
                                              series_steps)
    from radiance_probes.movie.writer import MovieError, MovieWriter, check_movie_output
    from radiance_probes.frontend.progress import ProgressBar
    from radiance_probes.rendering.limits import check_image_size
    from radiance_probes.rendering.methods.raymarch import check_step
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.rendering.budgets.device_defaults import probes_named, with_device_probes
    from radiance_probes.io.load import load_scene_volume

    from radiance_probes.scene.framing import frame_default_camera
    scene = apply_options(scene_from_arg(args.scene), args)
    volume = load_scene_volume(scene)
    scene = frame_default_camera(scene, volume.half_extent)   # a default view sees the whole box
    cam = scene.camera
    frames = args.frames
    times = None
    if args.time_series:
        if volume.time_steps < 2:
            raise OptionError(f"--time-series: {volume.name} has no time axis (one step)")
        frames = frames or volume.time_steps
        times = series_steps(volume.time_steps, frames)
    frames = frames or DEFAULT_FRAMES
    try:
        check_movie_output(args.out, cam.width, cam.height)
        still = args.time_series and args.turntable is None and args.keyframes is None
        cameras = movie_cameras(scene, frames,
                                None if args.keyframes is not None else (
                                    0.0 if still else
                                    360.0 if args.turntable is None else args.turntable),
                                args.keyframes)
    except MovieError as exc:
        raise OptionError(str(exc)) from None
    except ValueError as exc:
        raise OptionError(f"--keyframes: {exc}") from None
    for note in volume.notes:
        print(f"note: {note}", file=sys.stderr)
    load_scene_environment(scene)
    if getattr(args, "colorbar", None) and volume.channel_count > 1:
        raise OptionError(f"--colorbar: a colour bar shows one transfer function; this volume has "
                          f"{volume.channel_count} channels, each with its own")
    check_clip(scene, volume, args)
    if "raymarch_step" in REGISTRY[args.method].options and args.raymarch_step is not None:
        try:
            check_step(args.raymarch_step, volume)
        except ValueError as exc:
            raise OptionError(f"--raymarch-step: {exc}") from None
    ctx = create_headless_context(args.gl_backend)
    check_image_size(ctx, cam.width, cam.height)
    device = "software" if is_software(ctx) else "gpu"
    scene, said = with_device_probes(scene, device,
                                     probes_named(args.scene, args.probe_grid, args.probe_samples))
    if said and REGISTRY[args.method].needs_probes:
        print(f"animate: {said}", file=sys.stderr)
    from radiance_probes.rendering.settings import RenderSettings
    renderer = Renderer(ctx, scene, volume, RenderSettings(
        raymarch_stage=args.raymarch_stage,
        raymarch_step=args.raymarch_step or DEFAULT_RAYMARCH_STEP))
    overlay = (scene_colorbar_overlay(cam.width, cam.height, scene, volume, args.colorbar,
                                      args.colorbar_title) if args.colorbar else None)
    bar = ProgressBar("animate", len(cameras))
    writer = MovieWriter(args.out, cam.width, cam.height, fps=args.fps, crf=args.quality)
    try:
        if renderer.needs_probes(args.method):
            print("animate: baking the probes " + (
                f"for each of {len(set(times))} time steps" if times else
                "once for the whole movie"), file=sys.stderr)
        result = render_movie(renderer, cameras, writer, args.method, args.spp, args.seed,
                              args.exposure, args.samples_per_pass, overlay,
                              progress=lambda done, total: bar.update(done), times=times,
                              denoise=getattr(args, "denoise", False))
    except MovieError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    finally:
        renderer.release()
    if result.denoise_note:
        print(f"note: {result.denoise_note}", file=sys.stderr)
    print(f"device: {describe(ctx)}")
    print(f"movie: {result.summary()}")
    note = frame_count_note(result.path, result.frames)
    print(f"wrote {result.path}")
    if note is not None:
        print(note, file=sys.stderr if note.startswith("error") else sys.stdout)
        if note.startswith("error"):
            return 1
    return 0
