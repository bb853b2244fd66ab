"""The console command ``radiance-probes`` (also ``python -m radiance_probes``)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from radiance_probes.frontend.option_types import (ArgumentParser, OptionError, memory_size,
                                                   fraction, grid_arg, positive_float, positive_int)
from radiance_probes.frontend.scene_options import (add_colorbar_options, add_scene_edit_options,
                                                    add_volume_options)
from radiance_probes.frontend.render_files import render_to_files
from radiance_probes.methods import VIEWER_METHODS
from radiance_probes.io.scene_file import PROBE_PRECISIONS, SceneError



def cmd_view(args: argparse.Namespace) -> int:
    from radiance_probes.viewer.launch import (run_view)  # imports glfw and imgui only when a window may open
    return run_view(args)


def cmd_render(args: argparse.Namespace) -> int:
    return render_to_files(args)


def cmd_schema(args: argparse.Namespace) -> int:
    """The scene file's JSON Schema (or its key table), generated from the scene's types."""
    from radiance_probes.io.scene_schema import key_table, schema_text, update_docs
    if args.update_docs:
        from radiance_probes.paths import ASSETS_DIR
        for written in update_docs(ASSETS_DIR.parent / "docs"):
            print(f"wrote {written}")
        return 0
    text = key_table() if args.table else schema_text()
    if args.out:
        Path(args.out).write_text(text)
        print(f"wrote {Path(args.out).resolve()}")
    else:
        sys.stdout.write(text)
    return 0


def cmd_series(args: argparse.Namespace) -> int:
    """Lists a DICOM folder tree's or DICOMDIR's series, and which one opens by default."""
    from radiance_probes.io.dicom import list_series
    from radiance_probes.scene.types import VolumeError
    listing = list_series(args.path)
    try:
        default = listing.largest().number
    except VolumeError:
        default = None
    print(f"{listing.where}: {len(listing.series)} DICOM series")
    for s in listing.series:
        mark = "*" if s.number == default else " "
        print(f"{mark} {s.label()}")
        print(f"      SeriesInstanceUID {s.uid}")
    note = listing.skip_note()
    if note:
        print(f"note: {note}", file=sys.stderr)
    print("* opens by default (the largest that makes a volume); open another with --series N or "
          "--series UID" if default is not None else "none of them makes one volume")
    return 0


def cmd_animate(args: argparse.Namespace) -> int:
    from radiance_probes.cli.animate import run_animate
    return run_animate(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from radiance_probes.bench.config import PRESETS
    from radiance_probes.bench.report import write_report
    from radiance_probes.bench.scenes import ALL_SCENES, BATTERY_SCENES, LIT_DATASET_SCENES
    out = Path(args.out)
    if args.merge:
        from radiance_probes.bench.report import merge
        merge(args.merge, out / "results.json")
    elif not args.report_only:
        from radiance_probes.bench.runner import run_bench
        config = PRESETS[args.preset]
        changes = {}
        if args.scenes:
            unknown = [s for s in args.scenes if s not in (*ALL_SCENES, *LIT_DATASET_SCENES, *BATTERY_SCENES)]
            if unknown:
                raise SystemExit(f"error: unknown bench scene(s) {', '.join(unknown)} "
                                 f"(known: {', '.join((*ALL_SCENES, *LIT_DATASET_SCENES, *BATTERY_SCENES))})")
            changes["scenes"] = tuple(args.scenes)
        if args.ref_spp:
            changes["ref_spp"] = args.ref_spp
        if args.code_label:
            changes["code_label"] = args.code_label
        if args.probe_layouts:
            changes["probe_layouts"] = args.probe_layouts
        if args.probe_precision:
            changes["probe_precision"] = args.probe_precision
        if args.sh_orders:
            changes["sh_orders"] = args.sh_orders
        if args.auto_targets:
            changes["cost_auto_targets"] = args.auto_targets
        if args.methods:
            if config.mode != "interact":
                raise SystemExit(f"error: --methods is for the interact presets (--preset "
                                 f"{args.preset} is {config.mode})")
            changes["interact_methods"] = args.methods
        if args.adaptive_strength is not None:
            if not 0.0 <= args.adaptive_strength <= 1.0:
                raise SystemExit(f"error: --adaptive-strength {args.adaptive_strength}: expected "
                                 "a number in [0, 1]")
            changes["adaptive_strength"] = args.adaptive_strength
        if args.ref_dir:
            from radiance_probes.bench.report import results_path
            if not results_path(args.ref_dir).is_file():
                raise SystemExit(f"error: --ref-dir {args.ref_dir} has no results.json")
            changes["reference_dir"] = args.ref_dir
        config = config.scaled(**changes)
        run_bench(config, out, command="radiance-probes " + " ".join(sys.argv[1:]))
    from radiance_probes.bench.report import results_path
    results = results_path(out) if args.report_only else out / "results.json"
    if not results.is_file():
        raise SystemExit(f"error: no results at {results}")
    print(f"results: {results.resolve()}")
    print(f"report: {write_report(results, out).resolve()}")
    return 0


def interact_methods_arg(text: str) -> tuple:
    """`bench --methods`: a comma-separated list of the viewer's methods."""
    return _comma_list(text, str, lambda m: m in VIEWER_METHODS,
                       f"one of {', '.join(VIEWER_METHODS)}")


def _comma_list(text: str, convert, valid, expected: str) -> tuple:
    """The bench's list options: comma-separated items, each converted and checked, duplicates
    dropped in order; an empty list, an item that does not convert or fails the check names what
    was expected."""
    try:
        items = tuple(convert(t.strip()) for t in text.split(",") if t.strip())
    except ValueError:
        items = ()
    if not items or not all(valid(item) for item in items):
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of {expected}, "
                                         f"got {text!r}")
    return tuple(dict.fromkeys(items))


def probe_layouts_arg(text: str) -> tuple[str, ...]:
    """`bench --probe-layouts`: a comma-separated list of BENCH_PROBE_LAYOUTS."""
    from radiance_probes.bench.config import BENCH_PROBE_LAYOUTS
    return _comma_list(text, str, lambda t: t in BENCH_PROBE_LAYOUTS,
                       ", ".join(BENCH_PROBE_LAYOUTS))


def auto_targets_arg(text: str) -> tuple[float, ...]:
    """`bench --auto-targets`: a comma-separated list of relative RMSE targets in (0, 1)."""
    return _comma_list(text, float, lambda t: 0 < t < 1,
                       "relative RMSE targets in (0, 1), e.g. 0.05,0.02")


def sh_orders_arg(text: str) -> tuple[int, ...]:
    """`bench --sh-orders`: a comma-separated list of SH orders 0 to 4."""
    from radiance_probes.scene.types import SH_ORDERS
    return _comma_list(text, int, lambda o: o in SH_ORDERS,
                       f"SH orders {SH_ORDERS[0]} to {SH_ORDERS[-1]}")


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="radiance-probes",
                                     description="Volume rendering with radiance probes and a "
                                                 "reference volumetric path tracer.")
    sub = parser.add_subparsers(dest="command", required=True)

    from radiance_probes.rendering.denoise.filter import GUIDE_CHOICES
    from radiance_probes.methods import NAMES, listing
    from radiance_probes.rendering.renderer import RAYMARCH_STAGES
    from radiance_probes.scene.types import PROBE_INDICATORS, PROBE_INTERPOLATIONS, PROBE_LAYOUTS
    r = sub.add_parser("render", help="render a scene headless to a PNG (and linear .npy/.exr)")
    r.add_argument("scene", nargs="?", help="scene JSON or a volume file (default: built-in scene)")
    r.add_argument("--method", choices=NAMES, default="pt",
                   help="render method (default pt; README's 'Which method when'): " + listing())
    r.add_argument("--spp", type=positive_int, default=64, help="samples per pixel (default 64)")
    r.add_argument("--samples-per-pass", type=positive_int, default=1,
                   help="samples per pixel in one GPU dispatch (default 1)")
    r.add_argument("--out", default="render.png", help="PNG path (default render.png)")
    r.add_argument("--linear", help="also write the linear float32 (H, W, 3) image as .npy")
    r.add_argument("--exr", help="also write the linear image as OpenEXR")
    r.add_argument("--probe-grid", type=grid_arg, help="probes per axis: N or NX,NY,NZ (1..256)")
    r.add_argument("--probe-samples", type=positive_int, help="walks per probe")
    r.add_argument("--sh-window", choices=("none", "hann", "lanczos"),
                   help="window on the probes' spherical harmonics against ringing near sharp "
                        "light (probes.sh_window; default none)")
    r.add_argument("--probe-precision", choices=PROBE_PRECISIONS,
                   help="the probe textures' format; rgba16f takes half the memory "
                        "(probes.precision; default auto: rgba16f with surfaces, else rgba32f)")
    r.add_argument("--probe-layout", choices=PROBE_LAYOUTS,
                   help="probe planes evenly spaced (uniform) or denser where the indicator "
                        "varies (adaptive); default: the scene's (uniform)")
    r.add_argument("--adaptive-strength", type=float, metavar="S",
                   help="adaptive layout: 0 uniform .. 1 the indicator alone (default 0.5)")
    r.add_argument("--adaptive-indicator", choices=PROBE_INDICATORS,
                   help="adaptive layout: sigma_t's variation (extinction, default) or the sun's "
                        "transmittance's (sun)")
    r.add_argument("--probe-interpolation", choices=PROBE_INTERPOLATIONS,
                   help="how a point blends its 8 probes: trilinear (default) or weighted by "
                        "visibility (no light or darkness through dense matter; 1.8-2.8x the "
                        "raymarch frame)")
    r.add_argument("--gather-event", type=positive_int, metavar="K",
                   help="probes: read the probes at scattering event K, path tracing the events "
                        "before it (a final gather: less of the probes' error, K-1 more flights "
                        "and shadow rays per sample; default 1, the paper's renderer)")
    r.add_argument("--auto-probes", type=fraction, metavar="TARGET",
                   help="choose the cheapest probe setting whose image is within this relative "
                        "RMSE of a path-traced pilot (e.g. 0.05), report why, then render")
    r.add_argument("--auto", type=fraction, metavar="TARGET",
                   help="render the cheapest image whose estimated relative RMSE is within "
                        "TARGET (e.g. 0.02): raymarched over probes where a probe setting reaches "
                        "it, else the path tracer's, judged against the path tracer's own two "
                        "halves as they accumulate (chooses the method and samples itself)")
    r.add_argument("--raymarch-stage", choices=RAYMARCH_STAGES, default="compute",
                   help="raymarch as a compute (default) or fragment shader")
    r.add_argument("--raymarch-step", type=positive_float,
                   help="raymarch step in voxels (default 0.5, or the finest the shader's 8192 "
                        "steps across the box allow, whichever is longer)")
    r.add_argument("--denoise", action="store_true",
                   help="pass the image through the denoiser (Open Image Denoise; its CUDA device "
                        "on an NVIDIA GPU, else the CPU): far less noise from few samples, fine "
                        "detail may soften (docs/denoising.md)")
    r.add_argument("--denoise-guides", choices=GUIDE_CHOICES, default="auto",
                   help="what guides the denoiser: auto (default: the probes' raymarched image "
                        "where the method has probes, else the albedo and normal at few samples), "
                        "none, albedo, albedo-normal, probes")
    r.add_argument("--seed", type=int, default=0,
                   help="random seed of the samples (default 0): the same seed, the same image")
    r.add_argument("--width", type=positive_int,
                   help="image width in pixels (camera.width; default: the scene's, 512)")
    r.add_argument("--height", type=positive_int,
                   help="image height in pixels (camera.height; default: the scene's, 512)")
    r.add_argument("--exposure", type=positive_float, default=1.0, help="PNG exposure (default 1)")
    r.add_argument("--no-empty-space-skipping", dest="empty_space_skipping", action="store_false",
                   help="track with one global majorant instead of the macrocell grid (the same "
                        "image; for comparisons)")
    r.add_argument("--volume-memory", type=memory_size, metavar="BYTES",
                   help="the volume's GPU memory at most (e.g. 4G, 512M): where one 3D texture "
                        "exceeds it, the finest level whose bricks fit is rendered, with a note")
    add_volume_options(r)
    add_scene_edit_options(r)
    add_colorbar_options(r)
    add_gl_backend(r)
    r.set_defaults(func=cmd_render)

    s = sub.add_parser("series", help="list the series of a DICOM folder tree or DICOMDIR "
                                      "(description, modality, size, slices) and which opens")
    s.add_argument("path", help="a folder (searched recursively), a DICOMDIR file or a "
                                "multi-frame DICOM file")
    s.set_defaults(func=cmd_series)

    j = sub.add_parser("schema", help="the scene file's JSON Schema (docs/scene.schema.json), "
                                      "generated from the scene's types")
    j.add_argument("--out", help="write it to this file instead of stdout")
    j.add_argument("--table", action="store_true",
                   help="the key table of docs/scene-format.md (markdown) instead")
    j.add_argument("--update-docs", action="store_true",
                   help="rewrite docs/scene.schema.json and docs/scene-format.md's key table in "
                        "this checkout")
    j.set_defaults(func=cmd_schema)

    from radiance_probes.cli.animate import add_animate_parser
    add_animate_parser(sub, cmd_animate)

    from radiance_probes.bench.config import PRESETS
    from radiance_probes.bench.scenes import ALL_SCENES, BATTERY_SCENES
    b = sub.add_parser("bench", help="speed against error for every method; writes results.json, "
                                     "report.md and plots")
    b.add_argument("--preset", choices=sorted(PRESETS), default="gpu",
                   help="gpu: the full sweep for the lent GPU; quick: small sizes for llvmpipe")
    b.add_argument("--scenes", type=lambda t: t.split(","), default=None,
                   help=f"comma-separated subset of {','.join(ALL_SCENES)} or of the stress "
                        f"battery ({','.join(BATTERY_SCENES)}; --preset bias)")
    b.add_argument("--out", default="bench/out", help="output folder (default bench/out)")
    b.add_argument("--ref-spp", type=positive_int, help="reference samples per pixel")
    b.add_argument("--ref-dir", help="reuse the references (refs/*.npy and their measured noise "
                                     "in results.json) of an earlier run's output folder")
    b.add_argument("--code-label", help="names the code a run measures in its records (bake "
                                        "mode: 'before' and 'after' records side by side)")
    b.add_argument("--merge", nargs="+", metavar="RESULTS_JSON",
                   help="combine these results.json files into OUT/results.json, then report")
    b.add_argument("--probe-layouts", type=probe_layouts_arg, metavar="L[,L...]",
                   help="probe layouts each probe setting of the sweep is run with, at the same "
                        "probe count: uniform, extinction, sun (adaptive with that indicator); "
                        "default uniform")
    b.add_argument("--probe-precision", choices=("rgba32f", "rgba16f"),
                   help="the sweep's probe textures (default: the scene's, rgba32f); the showcase "
                        "setting is also run with the other")
    b.add_argument("--sh-orders", type=sh_orders_arg, metavar="N[,N...]",
                   help="SH orders each probe setting of the sweep is also run with, besides the "
                        "scene's (report: 'SH orders at the same probe setting')")
    b.add_argument("--adaptive-strength", type=float, metavar="S",
                   help="the adaptive layouts' strength in [0, 1] (default: the scene's, 0.5)")
    b.add_argument("--auto-targets", type=auto_targets_arg, metavar="T[,T...]",
                   help="the errors `auto` is asked for and checked at full resolution in the "
                        "cost and auto presets (default 0.05,0.10)")
    b.add_argument("--methods", type=interact_methods_arg, metavar="M[,M...]",
                   help="the methods the interact presets replay the viewer's session with: "
                        "any of the viewer's (" + ", ".join(VIEWER_METHODS) + "); default "
                        "probes,raymarch (interact-refine: refine)")
    b.add_argument("--report-only", action="store_true",
                   help="rewrite report.md and plots from an existing results.json")
    b.set_defaults(func=cmd_bench)

    from radiance_probes.viewer.arguments import add_view_parser
    add_gl_backend(add_view_parser(sub, cmd_view))
    return parser


def add_gl_backend(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    from radiance_probes.gl.context import BACKENDS
    parser.add_argument("--gl-backend", choices=BACKENDS,
                        help="headless OpenGL backend (default: the first that works of "
                             f"{', '.join(BACKENDS)}; RP_GL_BACKEND sets it for tests)")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import moderngl

    from radiance_probes.gl.context import ContextError
    from radiance_probes.gl.shaders import ShaderError
    from radiance_probes.rendering.limits import DeviceLimitError
    from radiance_probes.io.volume import VolumeError
    try:
        return args.func(args)
    except (SceneError, VolumeError, OptionError, DeviceLimitError, ContextError,
            ShaderError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except moderngl.Error as exc:  # e.g. the device ran out of memory allocating a buffer
        print(f"error: OpenGL: {str(exc).strip().splitlines()[0] if str(exc).strip() else exc!r}",
              file=sys.stderr)
        return 1
    except MemoryError:
        print("error: out of host memory (try a smaller image, volume or probe grid)",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
