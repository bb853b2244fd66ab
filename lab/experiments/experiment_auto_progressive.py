"""Does `auto` without a search (app/rendering/refine/auto_progressive.py) reach a target error for less than
the path tracer, and how near the best fixed setting? For each scene at 512^2 and each target:
the image `auto_render` returns, its error against a path-traced reference (two independent halves,
corrected for their noise), and everything it cost (GPU ms: path-traced samples, every trial's bake,
light grid and raymarched frames; and wall seconds). The best fixed setting and the path tracer's
own time to each target are in bench/h100/report.md (the same scenes, size and device kind).
Run on the GPU:
    python lab/experiments/experiment_auto_progressive.py OUT_DIR
        [--scenes fuel,hydrogen,foot,bonsai,thick,anisotropic,grey] [--targets 0.05,0.02,0.01]
        [--ref-spp 4096] [--size 512] [--denoise]
On llvmpipe, in seconds: --quick (a 20^3 cloud at 48^2, targets 0.2,0.1).
The table against a benchmark run (its path tracer's and its fastest setting's time to each target,
app/bench/report.py time_to_error), from the records alone:
    python lab/experiments/experiment_auto_progressive.py OUT_DIR --compare bench/h100"""
import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse  # noqa: E402
from radiance_probes.bench.scenes import bench_scene  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.refine.auto_progressive import auto_render  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.io.load import load_volume  # noqa: E402

QUICK = {"volume": {"builtin": "cloud", "size": [20, 20, 20]}, "density_scale": 40.0,
         "camera": {"eye": [0, 0.3, 2.2], "width": 48, "height": 48}}

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="fuel,hydrogen,foot,bonsai,thick,anisotropic,grey")
parser.add_argument("--targets", default="0.05,0.02,0.01")
parser.add_argument("--ref-spp", type=int, default=4096, help="samples per reference half")
parser.add_argument("--size", type=int, default=512)
parser.add_argument("--quick", action="store_true")
parser.add_argument("--denoise", action="store_true",
                    help="auto's denoised path tracer a candidate too (render --auto --denoise)")
parser.add_argument("--compare", type=Path, help="write OUT_DIR/report.md against this bench run")
args = parser.parse_args()
out = Path(args.out)


def compare(out: Path, bench: Path) -> None:
    """report.md: each row of OUT_DIR/results.json beside the bench run's time to its target."""
    from radiance_probes.bench.report import load, main_records, time_to_error
    data = load(bench)
    rows = json.loads((out / "results.json").read_text())
    lines = [f"# `render --auto` against fixed settings ({rows['device']})", "",
             f"Fixed settings' times from `{bench}` (the path tracer's, and the fastest "
             "of every method and setting there, to the same target: time_to_error of its "
             "records, bake included). `auto`: everything its image cost (GPU ms).", "",
             "The bench's path tracer steps by 4x in samples, so its time to a target is "
             "coarse; `exact pt` is the path tracer at the samples the target needs (the bench "
             "record's time and error at the first step that reaches it, the error falling as "
             "1 / sqrt(time)).", "",
             "| scene | target | auto chose | auto's error (measured) | auto | path tracer | "
             "auto / path tracer | exact pt | auto / exact pt | fastest fixed | auto / fastest |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows["rows"]:
        recs = main_records(data, r["scene"])
        pt = time_to_error([x for x in recs if x["method"] == "pt"], r["target"])
        best = time_to_error(recs, r["target"])
        chose = (f"raymarch {r['grid']}^3 x {r['walks']}" if r["method"] == "raymarch"
                 else f"pt {r['pt_spp']} spp" + (", denoised" if r.get("denoised") else ""))

        def ms(x):
            return "not reached" if x is None else f"{x['total_ms']:.3g} ms"

        def ratio(x):
            return "-" if x is None else f"{r['gpu_ms'] / x['total_ms']:.2f}"
        exact = None if pt is None else {
            "total_ms": pt["total_ms"] * (pt["error"] / r["target"]) ** 2}
        lines.append(f"| {r['scene']} | {r['target']:g} | {chose} | {r['rrmse']:.4f} | "
                     f"{r['gpu_ms']:.3g} ms | {ms(pt)} | {ratio(pt)} | {ms(exact)} | "
                     f"{ratio(exact)} | {ms(best)} | {ratio(best)} |")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'report.md'}")


if args.compare is not None:
    compare(out, args.compare)
    sys.exit(0)
out.mkdir(parents=True, exist_ok=True)
targets = [float(v) for v in args.targets.split(",")]
if args.quick:
    targets = [0.2, 0.1]
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
rows = []
names = ["quick-cloud"] if args.quick else args.scenes.split(",")
for name in names:
    base = parse_scene(QUICK) if args.quick else bench_scene(name, args.size, args.size)
    if base is None:
        print(f"{name}: dataset absent, skipped", flush=True)
        continue
    r = Renderer(ctx, base, load_volume(base.volume, base.base_dir))
    ref_spp = 256 if args.quick else args.ref_spp
    halves = [r.render("pt", spp=ref_spp, seed=s, samples_per_pass=64).image
              for s in (1000003, 2000003)]
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    print(f"{name}: reference 2 x {ref_spp} spp, noise {noise:.4f}", flush=True)
    for target in targets:
        r.set_scene(base)
        r.render("raymarch", spp=1, seed=1)   # shaders compiled before the clock starts
        r.set_scene(base)
        start = time.perf_counter()
        got = auto_render(r, target, seed=11, denoise=args.denoise)
        wall = time.perf_counter() - start
        measured = rrmse(got.image, reference)
        row = {"scene": name, "target": target, "method": got.method,
               "denoise": args.denoise, "denoised": got.denoised,
               "grid": got.scene.probes.grid[0] if got.method == "raymarch" else None,
               "walks": got.scene.probes.samples if got.method == "raymarch" else None,
               "estimate": got.estimate, "standard_error": got.standard_error,
               "rrmse_measured": measured, "rrmse": corrected_rrmse(measured, noise),
               "reference_noise": noise, "met": corrected_rrmse(measured, noise) <= target,
               "gpu_ms": got.gpu_ms, "pt_ms": got.pt_ms, "trial_ms": got.gpu_ms - got.pt_ms,
               "pt_spp": got.pt_spp, "wall_s": wall, "trials": got.trials,
               "denoise_setup_ms": got.denoise_setup_ms,
               "total_includes": "path-traced samples + every trial's bake, light grid and "
                                 "raymarched frames (GPU time); with denoise the guides (GPU "
                                 "time) and every filter run (its wall time; the filter's "
                                 "set-up, once a process, in denoise_setup_ms and wall_s only)"}
        rows.append(row)
        print(f"  {target:g}: {got.method} {row['grid']}^3 x {row['walks']}: estimated "
              f"{got.estimate:.4f}, measured {row['rrmse']:.4f} "
              f"({'met' if row['met'] else 'NOT met'}); {got.gpu_ms:.1f} GPU ms "
              f"({got.pt_ms:.1f} path tracing, {got.pt_spp} spp), {wall:.2f} s wall", flush=True)
        (out / "results.json").write_text(json.dumps({"device": device, "rows": rows}, indent=1))
    r.release()
print(f"wrote {out / 'results.json'}")
