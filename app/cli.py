"""The console command ``radiance-probes`` (also ``python -m app``)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .scene import Scene, SceneError, default_scene, load_scene


def _scene_from_arg(arg: str | None) -> Scene:
    if arg is None:
        return default_scene()
    p = Path(arg)
    if p.suffix.lower() == ".json":
        return load_scene(p)
    # A volume file: the default scene with that volume.
    from .scene import parse_scene
    return parse_scene({"volume": {"path": str(p)}})


def _progress(label: str):
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


def cmd_view(args: argparse.Namespace) -> int:
    from .viewer.launch import run_view  # imports glfw and imgui only when a window may open
    return run_view(args)


def cmd_render(args: argparse.Namespace) -> int:
    from .gl.context import create_headless_context, describe
    from .imageio import save_exr, save_npy, save_png
    from .render.renderer import Renderer

    scene = _scene_from_arg(args.scene)
    probe_changes = {}
    if args.probe_grid:
        probe_changes["grid"] = args.probe_grid
    if args.probe_samples:
        probe_changes["samples"] = args.probe_samples
    if args.sh_window:
        probe_changes["sh_window"] = args.sh_window
    if args.probe_precision:
        probe_changes["precision"] = args.probe_precision
    if probe_changes:
        from .scene import parse_scene, scene_to_dict
        data = scene_to_dict(scene)
        data["probes"].update(probe_changes)
        scene = parse_scene(data, base_dir=scene.base_dir)
    if args.width or args.height:
        cam = scene.camera
        w = args.width or cam.width
        h = args.height or cam.height
        from dataclasses import replace
        scene = scene.replace(camera=replace(cam, width=w, height=h))
    ctx = create_headless_context()
    renderer = Renderer(ctx, scene)
    if getattr(args, "auto_probes", None) is not None:
        if args.method == "pt":
            raise SceneError("--auto-probes chooses probe settings: use it with a probe method")
        from .render.auto_probes import choose_probes
        choice = choose_probes(renderer, args.auto_probes, args.method,
                               progress=lambda m: print(f"auto: {m}", file=sys.stderr, flush=True))
        print(choice.report())
        scene = choice.scene
        renderer.set_scene(scene)
    renderer.raymarch_stage = args.raymarch_stage
    renderer.raymarch_step_voxels = args.raymarch_step
    spp = args.spp
    bake_report = _progress("probe bake passes")

    def on_bake_pass(grid) -> None:
        bake_report(grid.passes_done, grid.passes_total)

    result = renderer.render(args.method, spp=spp, seed=args.seed,
                             samples_per_pass=args.samples_per_pass,
                             progress=_progress(f"{args.method} samples"), bake_progress=on_bake_pass)
    out = save_png(args.out, result.image, args.exposure)
    print(f"device: {describe(ctx)}")
    cam = scene.camera
    print(f"method: {result.method}  image: {cam.width}x{cam.height}  spp: {result.spp}")
    if renderer.probe_grid is not None and args.method != "pt":
        g = renderer.probe_grid
        rep = g.progress_report()
        print(f"probes: {g.grid[0]}x{g.grid[1]}x{g.grid[2]}, {g.samples} walks each, "
              f"{g.precision}, window {scene.probes.sh_window}; textures {g.gpu_bytes / 2**20:.1f} MiB; "
              f"bake GPU time: {result.bake_ms:.1f} ms; last pass changed the probes by "
              f"{100 * rep.relative_change:.2f}% (est. standard error "
              f"{'n/a, one pass' if rep.passes_done < 2 else f'{100 * rep.standard_error:.2f}%'})")
    print(f"render GPU time: {result.render_ms:.1f} ms  ({result.ms_per_sample:.3f} ms per sample "
          "per pixel of the whole image)")
    if result.stats.get("truncated_paths") or result.stats.get("nonfinite_samples"):
        print(f"warning: {result.stats['truncated_paths']} paths ran out of their step budget and "
              f"{result.stats['nonfinite_samples']} samples were not finite; both were left out",
              file=sys.stderr)
    if args.linear:
        print(f"linear image: {save_npy(args.linear, result.image)}")
    if args.exr:
        print(f"EXR image: {save_exr(args.exr, result.image)}")
    print(f"wrote {out.resolve()}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from .bench.config import PRESETS
    from .bench.report import write_report
    from .bench.scenes import ALL_SCENES
    out = Path(args.out)
    if args.merge:
        from .bench.report import merge
        merge(args.merge, out / "results.json")
    elif not args.report_only:
        from .bench.runner import run_bench
        config = PRESETS[args.preset]
        changes = {}
        if args.scenes:
            unknown = [s for s in args.scenes if s not in ALL_SCENES]
            if unknown:
                raise SystemExit(f"error: unknown bench scene(s) {', '.join(unknown)} "
                                 f"(known: {', '.join(ALL_SCENES)})")
            changes["scenes"] = tuple(args.scenes)
        if args.ref_spp:
            changes["ref_spp"] = args.ref_spp
        if args.code_label:
            changes["code_label"] = args.code_label
        if args.ref_dir:
            if not (Path(args.ref_dir) / "results.json").is_file():
                raise SystemExit(f"error: --ref-dir {args.ref_dir} has no results.json")
            changes["reference_dir"] = args.ref_dir
        config = config.scaled(**changes)
        run_bench(config, out, command="radiance-probes " + " ".join(sys.argv[1:]))
    results = out / "results.json"
    if not results.is_file():
        raise SystemExit(f"error: no results at {results}")
    print(f"results: {results.resolve()}")
    print(f"report: {write_report(results, out).resolve()}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="radiance-probes",
                                     description="Volume rendering with radiance probes and a "
                                                 "reference volumetric path tracer.")
    sub = parser.add_subparsers(dest="command", required=True)

    from .render.renderer import METHODS
    r = sub.add_parser("render", help="render a scene headless to a PNG (and linear .npy/.exr)")
    r.add_argument("scene", nargs="?", help="scene JSON or a volume file (default: built-in scene)")
    r.add_argument("--method", choices=METHODS, default="pt")
    r.add_argument("--spp", type=_positive_int, default=64, help="samples per pixel (default 64)")
    r.add_argument("--samples-per-pass", type=_positive_int, default=1,
                   help="samples per pixel in one GPU dispatch (default 1)")
    r.add_argument("--out", default="render.png", help="PNG path (default render.png)")
    r.add_argument("--linear", help="also write the linear float32 (H, W, 3) image as .npy")
    r.add_argument("--exr", help="also write the linear image as OpenEXR")
    r.add_argument("--probe-grid", type=_grid_arg, help="probes per axis: N or NX,NY,NZ (1..256)")
    r.add_argument("--probe-samples", type=_positive_int, help="walks per probe")
    r.add_argument("--sh-window", choices=("none", "hann", "lanczos"))
    r.add_argument("--probe-precision", choices=("rgba32f", "rgba16f"))
    r.add_argument("--auto-probes", type=float, metavar="TARGET",
                   help="choose the cheapest probe setting whose image is within this relative "
                        "RMSE of a path-traced pilot (e.g. 0.05), report why, then render")
    r.add_argument("--raymarch-stage", choices=("compute", "fragment"), default="compute",
                   help="raymarch as a compute (default) or fragment shader")
    r.add_argument("--raymarch-step", type=float, default=0.5,
                   help="raymarch step in voxels (default 0.5)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--width", type=_positive_int)
    r.add_argument("--height", type=_positive_int)
    r.add_argument("--exposure", type=float, default=1.0, help="PNG exposure (default 1)")
    r.set_defaults(func=cmd_render)

    from .bench.config import PRESETS
    from .bench.scenes import ALL_SCENES
    b = sub.add_parser("bench", help="speed against error for every method; writes results.json, "
                                     "report.md and plots")
    b.add_argument("--preset", choices=sorted(PRESETS), default="gpu",
                   help="gpu: the full sweep for the lent GPU; quick: small sizes for llvmpipe")
    b.add_argument("--scenes", type=lambda t: t.split(","), default=None,
                   help=f"comma-separated subset of {','.join(ALL_SCENES)}")
    b.add_argument("--out", default="bench/out", help="output folder (default bench/out)")
    b.add_argument("--ref-spp", type=_positive_int, help="reference samples per pixel")
    b.add_argument("--ref-dir", help="reuse the references (refs/*.npy and their measured noise "
                                     "in results.json) of an earlier run's output folder")
    b.add_argument("--code-label", help="names the code a run measures in its records (bake "
                                        "mode: 'before' and 'after' records side by side)")
    b.add_argument("--merge", nargs="+", metavar="RESULTS_JSON",
                   help="combine these results.json files into OUT/results.json, then report")
    b.add_argument("--report-only", action="store_true",
                   help="rewrite report.md and plots from an existing results.json")
    b.set_defaults(func=cmd_bench)

    from .viewer.arguments import add_view_parser
    add_view_parser(sub, cmd_view, _grid_arg, _positive_int)
    return parser


def _grid_arg(text: str) -> list[int]:
    parts = text.split(",")
    if len(parts) not in (1, 3):
        raise argparse.ArgumentTypeError(f"expected N or NX,NY,NZ, got {text!r}")
    values = [_positive_int(p) for p in parts]
    return values * 3 if len(values) == 1 else values


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .gl.context import ContextError
    from .gl.shaders import ShaderError
    from .volume import VolumeError
    try:
        return args.func(args)
    except (SceneError, VolumeError, ContextError, ShaderError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
