"""A still image to files, as the CLI's ``render`` runs it (the viewer's ``--screenshot`` shares
the output checks): the outputs checked before a long render, the render itself, and a result
that cannot be written saved elsewhere. The option types are app/frontend/option_types.py's, the
scene from the command line app/frontend/scene_options.py's.

The rule: every option and scene value is checked before any GPU work, and a bad one ends in one
line naming the option (or the scene field) and the problem. Values are checked where they are
parsed (argument types below; the scene's fields in app/io/scene_file.py); what depends on the device
(image sizes against its GL limits) right after the context exists and before the scene is
uploaded (app/rendering/limits.py); where the outputs go before the render starts. A render whose
output cannot be written at the end is not lost: it is written elsewhere and the error says where."""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from radiance_probes.methods import METHODS
from radiance_probes.frontend.option_types import DEFAULT_RAYMARCH_STEP, OptionError
from radiance_probes.frontend.scene_options import (SCENE_KEY_DESTS, apply_options, check_clip,
                                                    scene_from_arg)


OUTPUT_SUFFIXES = {"--out": ".png", "--linear": ".npy", "--exr": ".exr", "--screenshot": ".png"}


def check_output(path: str, option: str) -> Path:
    """Raises OptionError unless `path` can be written: the right suffix, not a folder, its folder
    creatable and writable. Creates the missing folders (the write would) but leaves no file."""
    p = Path(path).expanduser()
    if p.is_dir():
        raise OptionError(f"{option} {path}: is a folder; give a file name")
    suffix = OUTPUT_SUFFIXES.get(option)
    if suffix and p.suffix.lower() != suffix:
        raise OptionError(f"{option} {path}: expected a {suffix} file name")
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OptionError(f"{option} {path}: {parent} is a file, not a folder")
            break
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        existed = p.exists()
        with open(p, "ab"):
            pass
        if not existed:
            p.unlink()
    except OSError as exc:
        raise OptionError(f"{option} {path}: cannot write there ({exc.strerror or exc})") from None
    return p


def check_outputs(args: argparse.Namespace) -> None:
    for option in OUTPUT_SUFFIXES:
        value = getattr(args, option[2:], None)
        if value:
            check_output(value, option)


def save_or_rescue(save, path: str, option: str, *payload) -> tuple[Path | None, str | None]:
    """Writes an output with `save(path, *payload)`. When that fails (the disk filled up, the
    folder went away during the render), writes it to the temporary folder instead. Returns
    (where it went, an error line or None)."""
    try:
        return save(path, *payload).resolve(), None
    except OSError as exc:
        reason = exc.strerror or str(exc)
    rescue = Path(tempfile.gettempdir()) / f"radiance-probes-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{Path(path).name}"
    try:
        where = save(rescue, *payload).resolve()
    except OSError as exc:
        return None, (f"{option} {path}: could not write it ({reason}), nor a copy at {rescue} "
                      f"({exc.strerror or exc}); the image is lost")
    return where, f"{option} {path}: could not write it ({reason}); it was written to {where} instead"


def progress_printer(label: str):
    interactive = sys.stderr.isatty()
    last = [-1]

    def report(done: int, total: int) -> None:
        pct = int(100 * done / max(total, 1))
        if interactive:
            print(f"\r{label}: {done}/{total} ({pct}%)", end="" if done < total else "\n",
                  file=sys.stderr, flush=True)
        elif pct // 10 != last[0] // 10 or done == total:
            print(f"{label}: {done}/{total} ({pct}%)", file=sys.stderr, flush=True)
        last[0] = pct
    return report


def render_defaults() -> dict:
    """Every option `render` has, at its default: what the viewer's headless fallback starts from."""
    return dict(scene=None, method="pt", spp=64, samples_per_pass=1, out="render.png", linear=None,
                exr=None, probe_grid=None, probe_samples=None, sh_window=None, probe_precision=None,
                auto_probes=None, auto=None, denoise=False, denoise_guides="auto",
                raymarch_stage="compute", raymarch_step=None, seed=0, width=None,
                height=None, exposure=1.0, gl_backend=None, empty_space_skipping=True,
                gather_event=None, series=None, orientation=None, data_window=None, crop=None,
                crop_voxels=None, clip_plane=None, no_crop=False, no_clip_plane=False,
                transfer_function=None, clinical_preset=None, surface=None, colorbar=None,
                colorbar_title="value", volume_memory=None, **dict.fromkeys(SCENE_KEY_DESTS))


def render_to_files(args: argparse.Namespace) -> int:
    """Renders the scene the arguments name and writes the PNG (and the linear .npy/.exr); every
    check comes before the first GPU call. Returns the exit status."""
    from radiance_probes.gl.context import create_headless_context, describe
    from radiance_probes.frontend.imageio import save_exr, save_npy, save_png
    from radiance_probes.rendering.limits import check_image_size
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.rendering.methods.raymarch import check_step
    from radiance_probes.io.environment_map import load_scene_environment
    from radiance_probes.scene.framing import frame_default_camera
    from radiance_probes.io.load import load_scene_volume
    from radiance_probes.scene.clinical_presets import opening_scene

    auto = getattr(args, "auto", None)
    if auto is not None:
        if args.auto_probes is not None:
            raise OptionError("--auto and --auto-probes: --auto chooses the probes itself (or "
                              "the path tracer); give one of them")
        if getattr(args, "gather_event", None) is not None:
            raise OptionError("--gather-event: --auto renders the raymarcher or the path tracer, "
                              "neither reads it")
        if args.method != "pt" or args.spp != 64:
            print("note: --auto chooses the method and the samples: --method and --spp are not "
                  "used", file=sys.stderr)
    if args.auto_probes is not None and not METHODS[args.method].needs_probes:
        raise OptionError("--auto-probes chooses probe settings: use it with a probe method")
    gather_event = getattr(args, "gather_event", None)
    if gather_event is not None:
        from radiance_probes.rendering.settings import check_gather_event
        if "gather_event" not in METHODS[args.method].options:
            raise OptionError(f"--gather-event: the probes method's option (a final gather), "
                              f"not {args.method}'s")
        try:
            check_gather_event(gather_event)
        except ValueError as exc:
            raise OptionError(f"--gather-event: {exc}") from None
    scene = apply_options(scene_from_arg(args.scene), args)
    check_outputs(args)
    volume = load_scene_volume(scene)      # a file that does not load fails before the GPU starts
    scene = frame_default_camera(scene, volume.half_extent)   # a default view sees the whole box
    for note in volume.notes:
        print(f"note: {note}", file=sys.stderr)
    scene = opening_scene(scene, volume)   # a CT with no transfer function: its clinical preset
    if scene.transfer_function.preset is not None:
        print(f"note: transfer function: the clinical preset {scene.transfer_function.preset} "
              f"(--clinical-preset)", file=sys.stderr)
    if getattr(args, "colorbar", None) and volume.channel_count > 1:
        raise OptionError(f"--colorbar: a colour bar shows one transfer function; this volume has "
                          f"{volume.channel_count} channels, each with its own")
    load_scene_environment(scene)          # so does an environment map (kept in its cache)
    check_clip(scene, volume, args)        # and a crop that does not fit the volume
    from radiance_probes.scene.area_lights import check_area_lights
    check_area_lights(scene, volume.half_extent)   # and an area light in the volume box
    if "raymarch_step" in METHODS[args.method].options and args.raymarch_step is not None:
        try:
            check_step(args.raymarch_step, volume)   # a step asked for is taken, or refused
        except ValueError as exc:
            raise OptionError(f"--raymarch-step: {exc}") from None
    ctx = create_headless_context(args.gl_backend)
    check_image_size(ctx, scene.camera.width, scene.camera.height)
    from radiance_probes.rendering.settings import RenderSettings
    renderer = Renderer(ctx, scene, volume, RenderSettings(
        raymarch_stage=args.raymarch_stage,
        raymarch_step=args.raymarch_step or DEFAULT_RAYMARCH_STEP,
        empty_space_skipping=args.empty_space_skipping,
        gather_event=gather_event if gather_event is not None else 1,
        volume_memory_bytes=getattr(args, "volume_memory", None)))
    for note in renderer.resources.volume.notes:   # where bricking showed a coarser level
        if note not in volume.notes:
            print(f"note: {note}", file=sys.stderr)
    if args.auto_probes is not None:
        from radiance_probes.rendering.probes.auto import choose_probes
        choice = choose_probes(renderer, args.auto_probes, args.method,
                               progress=lambda m: print(f"auto: {m}", file=sys.stderr, flush=True))
        print(choice.report(trials=False))   # each trial was printed as it came
        scene = choice.scene
        renderer.set_scene(scene)
    bake_report = progress_printer("probe bake passes")

    def on_bake_pass(grid) -> None:
        bake_report(grid.passes_done, grid.passes_total)

    if auto is not None:
        from radiance_probes.rendering.refine.auto_progressive import auto_render
        from radiance_probes.rendering.still_images import RenderResult
        got = auto_render(renderer, auto, seed=args.seed,
                          progress=lambda m: print(f"auto: {m}", file=sys.stderr, flush=True),
                          denoise=getattr(args, "denoise", False))
        print(got.report(log=False))         # each trial was printed as it came
        scene, args.method = got.scene, got.method
        # the image's own render and bake: the rejected settings' are in the report's total
        result = RenderResult(got.image, got.method, got.image_spp, got.image_ms,
                              got.image_bake_ms)
    else:
        result = renderer.render(args.method, spp=args.spp, seed=args.seed,
                                 samples_per_pass=args.samples_per_pass,
                                 progress=progress_printer(
                                     f"{args.method} "
                                     f"{'frames' if not METHODS[args.method].noisy else 'samples'}"),
                                 bake_progress=on_bake_pass,
                                 denoise=getattr(args, "denoise", False),
                                 denoise_guides=getattr(args, "denoise_guides", "auto"))
    denoise = getattr(args, "denoise", False)
    if denoise and auto is not None and not got.denoised and METHODS[got.method].noisy:
        # auto returned the path tracer's raw image: denoise that one (a denoised one it chose,
        # or a raymarched image, which is clean, stays as it is)
        from radiance_probes.rendering.denoise.filter import choose_guides
        renderer.begin(args.method)
        guides = choose_guides(args.denoise_guides, result.spp,
                               renderer.needs_probes(args.method) and renderer.probes_shown())
        d, _ = renderer.denoise(result.image, guides)
        result.image, result.denoised = d.image, d
    if denoise:
        d = result.denoised
        if d is not None and d.denoised:
            print(f"denoised on OIDN's {d.device} device (guides: {args.denoise_guides}): "
                  f"filter {d.ms['filter_ms']:.1f} ms")
        elif d is not None:
            print(f"note: {d.note}", file=sys.stderr)
    errors = []
    if getattr(args, "colorbar", None):
        from radiance_probes.frontend.colorbar import scene_colorbar
        from radiance_probes.frontend.imageio import save_png8
        from radiance_probes.rendering.tonemap import to_uint8
        pixels = scene_colorbar(to_uint8(result.image, args.exposure), scene,
                                renderer.resources.volume, args.colorbar, args.colorbar_title)
        out, err = save_or_rescue(save_png8, args.out, "--out", pixels)
    else:
        out, err = save_or_rescue(save_png, args.out, "--out", result.image, args.exposure)
    errors.append(err)
    print(f"device: {describe(ctx)}")
    cam = scene.camera
    word = METHODS[result.method].sample_word if result.method in METHODS else "spp"
    print(f"method: {result.method}  image: {cam.width}x{cam.height}  {word}: {result.spp}")
    shown = result.stats.get("shown")   # a composite method's part shown (refine)
    if shown is not None:
        est = result.stats["refine_estimate"]
        w = est.get("blend_weight")
        what = (f"{shown}'s image" if w is None or w in (0.0, 1.0) else
                f"guided denoised blended with the raymarcher's image (weight {w:.2f}, estimated "
                f"rRMSE of the blend {est['blend']:.4f})")
        print(f"{result.method} shows {what} (estimated rRMSE: guided {est['guided']:.4f}, "
              f"raymarch {est['raymarch']:.4f})")
    if renderer.probe_grid is not None and METHODS[args.method].needs_probes:
        g = renderer.probe_grid
        rep = g.progress_report()
        print(f"probes: {g.grid[0]}x{g.grid[1]}x{g.grid[2]}, {g.samples} walks each, "
              f"{g.precision}, window {scene.probes.sh_window}; textures {g.gpu_bytes / 2**20:.1f} MiB; "
              f"bake GPU time: {result.bake_ms:.1f} ms; last pass changed the probes by "
              f"{100 * rep.relative_change:.2f}% (est. standard error "
              f"{'n/a, one pass' if rep.passes_done < 2 else f'{100 * rep.standard_error:.2f}%'})")
        if renderer.bake_note():
            print(f"note: {renderer.bake_note()}")
        if "gather_event" in METHODS[args.method].options and renderer.probe_gather_event > 1:
            k = renderer.probe_gather_event
            print(f"final gather: the probes read at scattering event {k}, the events before it "
                  f"path traced" + (f" (past max_bounces {scene.max_bounces}: no path reaches "
                                    f"it, the path tracer's image)" if k > scene.max_bounces
                                    else ""))
            most = renderer.gather_bounces_past_limit()
            if most is not None:
                print(f"note: the probes hold up to max_bounces - 1 = {scene.max_bounces - 1} "
                      f"scattering events whatever the gather event, so with {k} a path may "
                      f"scatter up to {most} times, not {scene.max_bounces} "
                      f"(a few percent brighter where max_bounces is this small; --gather-event 1 "
                      f"keeps the limit exactly)", file=sys.stderr)
        if scene.probes.layout == "adaptive":
            spacing = ("evenly spaced (no variation to follow)" if g.planes is None else
                       "spacing per axis from " + ", ".join(
                           f"{min(np.diff(p)) * len(p):.2f}-{max(np.diff(p)) * len(p):.2f}"
                           if len(p) > 1 else "1" for p in g.planes) + " x the uniform one")
            print(f"probe layout: adaptive ({scene.probes.adaptive_indicator}, strength "
                  f"{scene.probes.adaptive_strength:g}): {spacing}; "
                  f"{renderer.last_layout_ms:.0f} ms on the host")
    if "raymarch_step" in METHODS[args.method].options and (
            renderer.effective_raymarch_step_voxels > renderer.raymarch_step_voxels):
        print(f"note: raymarch step {renderer.effective_raymarch_step_voxels:.3g} voxels, not the "
              f"default {renderer.raymarch_step_voxels:g}: the shader takes at most 8192 steps "
              "across this volume's box")
    per = ("frame" if word == "frames" else "sample per pixel") + " of the whole image"
    print(f"render GPU time: {result.render_ms:.1f} ms  ({result.ms_per_sample:.3f} ms per {per})")
    if result.stats.get("truncated_paths") or result.stats.get("nonfinite_samples"):
        print(f"warning: {result.stats['truncated_paths']} paths ran out of their step budget and "
              f"{result.stats['nonfinite_samples']} samples were not finite; both were left out",
              file=sys.stderr)
    if args.linear:
        where, err = save_or_rescue(save_npy, args.linear, "--linear", result.image)
        errors.append(err)
        if where:
            print(f"linear image: {where}")
    if args.exr:
        where, err = save_or_rescue(save_exr, args.exr, "--exr", result.image)
        errors.append(err)
        if where:
            print(f"EXR image: {where}")
    if out:
        print(f"wrote {out}")
    errors = [e for e in errors if e]
    for e in errors:
        print(f"error: {e}", file=sys.stderr)
    return 1 if errors else 0
