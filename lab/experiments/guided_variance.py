"""Issue 29, step 1 and the steps after it: where each unbiased estimator's noise goes, and what it
costs, measured from two independent images per estimator (no reference needed).

    python lab/experiments/guided_variance.py OUT_DIR [--quick] [--scenes fuel,foot,...] [--spp 64]
        [--probes 64,128] [--width 512 --height 512] [--estimators ROWS]

Per scene the probes are baked once (GPU ms recorded), then each estimator renders two images of
SPP samples per pixel with independent seeds:

- `pt`, the path tracer, and `pt` with max_bounces 1 (its first event alone: the camera ray's free
  flight and the sun there) and 2, for the share of the variance each part of the path holds;
- `guided` with the control at the first event only (level 1 minus the probes' prediction there:
  RenderSettings.guided_direction_control False), with the direction control at every event
  (the default, lib/guided_direction_control.glsl), and that with one frame of level 0 a sample
  of level 1 instead of 0.25 (guided_level0_ratio); for `guided` each level's share of its
  variance. (The rows `guided, guided directions` and `guided, guided distances` of
  bench/h100-guided-directions and bench/h100-guided-distances measured two guiding schemes that
  took no variance away; both were removed: docs/experiments.md.)

For two independent images a, b of SPP samples, E[(a - b)^2] / 2 is one image's variance, so a
sample's relative variance is  v = SPP * sum((a - b)^2) / 2 / sum(((a + b) / 2)^2)  (the image's
squared rRMSE at one sample, the reference's own noise aside). With t the GPU ms a sample costs,
the time to a relative error e is  v t / e^2  (plus the bake for `guided`): the records state
that for 5%, 2%, 1% and 0.5% and the speed-up over the path tracer. Each estimator's image mean is
also given, so an estimator whose mean differs from the path tracer's by more than its noise
shows it (a check, not a proof: tests/test_guided.py tests the mean).

Writes OUT_DIR/results.json and OUT_DIR/report.md. --quick: the anisotropic cloud at 48x40
with 8^3 probes (llvmpipe; tests/test_guided_control.py runs it).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.bench.records import progressive  # noqa: E402
from radiance_probes.bench.scenes import ALL_SCENES, bench_scene  # noqa: E402
from radiance_probes.rendering.probes.layout import resolve_sh_order  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.rendering.settings import RenderSettings  # noqa: E402

TARGETS = (0.05, 0.02, 0.01, 0.005)
# `guided` first, right after the bake (a scene change for the pt rows would make the probes and
# the light grid stale, and their re-bake would be counted in the next render)
ESTIMATORS = ("guided, first event", "guided", "guided, level-0 ratio 1", "pt", "pt, 1 bounce",
              "pt, 2 bounces")


def relative_variance(a: np.ndarray, b: np.ndarray, spp: int) -> float:
    """One sample's relative variance from two independent images of spp samples each."""
    a = np.asarray(a, np.float64)[..., :3]
    b = np.asarray(b, np.float64)[..., :3]
    mean = (a + b) / 2.0
    return float(spp * np.sum((a - b) ** 2) / 2.0 / max(np.sum(mean ** 2), 1e-300))


def _estimate(renderer: Renderer, method: str, spp: int, per_dispatch: int, seed: int):
    """Two images of spp samples (seeds seed, seed + 1): (image a, image b, GPU ms a sample,
    for `guided` each run's (level 0, level 1) images)."""
    images, ms, levels = [], [], []
    # untimed first, so that a new variant's shaders are compiled before the timed runs (whose
    # warm-up, records.warm_up, then brings the GPU's clock back up: the compile's seconds left the
    # H100 at its idle clock, and a row came out 1.6 to 3x slow before the warm-up waited for it)
    renderer.render(method, spp=per_dispatch, seed=seed + 17, samples_per_pass=per_dispatch)
    for s in (seed, seed + 1):
        for _, image, _frame_ms, total_ms in progressive(renderer, method, (spp,), s, per_dispatch):
            images.append(image)
            ms.append(total_ms / spp)
        if method == "guided":   # each level's image as the run left it
            levels.append((renderer._acc0.read(), renderer._acc.read()))
    return images[0], images[1], float(np.mean(ms)), levels


def measure_scene(ctx, name: str, width: int, height: int, grid: int, walks: int, spp: int,
                  per_dispatch: int, log, estimators: tuple[str, ...] = ESTIMATORS) -> dict | None:
    scene = bench_scene(name, width, height)
    if scene is None:
        log(f"{name}: dataset absent, skipped")
        return None
    # One probe bake for every row, of the order that holds directions (where g = 0 "auto" gives
    # 2 rather than 0), as the earlier records' rows had it: at g = 0 the rows then have the
    # direction control, which order 0 compiles out.
    order = resolve_sh_order(scene.probes.sh_order, scene.anisotropy, walks, directions=True)
    scene = scene.replace(probes=replace(scene.probes, grid=(grid, grid, grid), samples=walks,
                                         sh_order=order))
    out = {"scene": name, "width": width, "height": height, "probe_grid": grid,
           "probe_samples": walks, "sh_order": order, "spp": spp,
           "max_bounces": scene.max_bounces, "estimators": {}}
    renderer = Renderer(ctx, scene)
    try:
        bake_ms = renderer.bake(seed=1)
        light_ms = renderer.bake_light()
        out["bake_ms"], out["light_ms"] = bake_ms, light_ms
        for est in estimators:
            t0 = time.perf_counter()
            if est.startswith("pt, "):
                bounces = int(est.split()[1])
                if bounces >= scene.max_bounces:
                    continue
                renderer.set_scene(scene.replace(max_bounces=bounces))
                method = "pt"
            else:
                method = "guided" if est.startswith("guided") else "pt"
                if method == "guided" and not renderer.probes_current():
                    raise RuntimeError("the probes went stale before a guided row")
            renderer.settings = replace(
                renderer.settings, guided_direction_control=est != "guided, first event",
                guided_level0_ratio=1.0 if est.endswith("ratio 1") else 0.25)
            a, b, ms, levels = _estimate(renderer, method, spp, per_dispatch, seed=1000)
            v = relative_variance(a, b, spp)
            level_share = None
            if levels:
                # each level's part of the image's variance (the levels are independent)
                norm = np.sum((((np.asarray(a, np.float64) + b) / 2.0)[..., :3]) ** 2)
                level_share = [float(np.sum((np.asarray(x, np.float64)[..., :3] - y[..., :3]) ** 2)
                                     / 2.0 / norm * spp / v)
                               for x, y in zip(levels[0], levels[1])]
            mean = ((np.asarray(a, np.float64) + b) / 2.0)[..., :3].mean(axis=(0, 1))
            rec = {"relative_variance": v, "ms_per_sample": ms, "mean_rgb": mean.tolist(),
                   "negative_pixels": float(np.mean(np.minimum(a, b)[..., :3] < 0.0)),
                   "finite": bool(np.all(np.isfinite(a)) and np.all(np.isfinite(b))),
                   "level_share_of_variance": level_share}
            fixed = bake_ms + light_ms if method == "guided" else 0.0
            rec["time_to"] = {f"{t:g}": fixed + v * ms / t ** 2 for t in TARGETS}
            out["estimators"][est] = rec
            log(f"{name}: {est}: v {v:.4g}, {ms:.4g} ms a sample, "
                f"to 1% {rec['time_to']['0.01']:.4g} ms ({time.perf_counter() - t0:.1f} s wall)")
        renderer.set_scene(scene)
    finally:
        renderer.release()
    pt = out["estimators"]["pt"]
    full = pt["relative_variance"]
    for est, rec in out["estimators"].items():
        if est.startswith("pt, "):
            rec["share_of_pt_variance"] = rec["relative_variance"] / full
        rec["speedup"] = {t: pt["time_to"][t] / rec["time_to"][t] for t in rec["time_to"]}
    return out


def report(results: list[dict], device: str) -> str:
    lines = ["# Where the unbiased estimators' noise goes (lab/experiments/guided_variance.py)", "",
             f"Device: {device}. Two independent images per estimator; v is one sample's relative "
             "variance (squared rRMSE at one sample), t the GPU ms a sample costs, the time to an "
             "error e is v t / e^2, plus the bake and light grid for `guided`. Speed-ups are "
             "against the path tracer's own v t / e^2.", ""]
    if not results:
        return "\n".join(lines + ["No scene ran."]) + "\n"
    r0 = results[0]
    lines += [f"{r0['width']}x{r0['height']}, {r0['spp']} spp a image, probes "
              f"{r0['probe_grid']}^3 x {r0['probe_samples']}.", "",
              "| scene | estimator | v | ms a sample | share of pt's v (guided: of its own) | to 2% | to 1% | to 0.5% "
              "| speed-up at 1% |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in results:
        for est, rec in r["estimators"].items():
            share = rec.get("share_of_pt_variance")
            levels = rec.get("level_share_of_variance")
            note = ("" if share is None else f"{share:.0%}") if not levels else (
                f"levels 0/1: {levels[0]:.0%}/{levels[1]:.0%}")
            lines.append(
                f"| {r['scene']} | {est} | {rec['relative_variance']:.3g} | "
                f"{rec['ms_per_sample']:.3g} | {note} | "
                f"{rec['time_to']['0.02']:.4g} ms | {rec['time_to']['0.01']:.4g} ms | "
                f"{rec['time_to']['0.005']:.4g} ms | {rec['speedup']['0.01']:.2g}x |")
    lines += ["", "## `guided`'s two levels and their best split", "",
              "From the two level-0 ratios r (0.25 and 1): a sample's variance is V1 + V0 / r and "
              "its cost C1 + r C0, so V0 = (v(0.25) - v(1)) / 3, V1 = v(1) - V0, C0 = (t(1) - "
              "t(0.25)) / 0.75, C1 = t(0.25) - C0 / 4. The best ratio is r* = sqrt(V0 C1 / (V1 "
              "C0)), where v t = (sqrt(V1 C1) + sqrt(V0 C0))^2: `guided`'s best with these "
              "probes, against the path tracer's v t. (Derived from two noisy estimates: a "
              "guide, not a record.)", "",
              "| scene | V0 (a level-0 frame) | C0 ms | V1 (a level-1 sample) | C1 ms | r* "
              "| best v t / pt's v t |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in results:
        split = level_split(r)
        if split is None:
            continue
        lines.append(f"| {r['scene']} | {split['V0']:.3g} | {split['C0']:.3g} | "
                     f"{split['V1']:.3g} | {split['C1']:.3g} | {split['best_ratio']:.3g} | "
                     f"{split['best_vt_over_pt']:.2f} |")
    return "\n".join(lines) + "\n"


def level_split(r: dict) -> dict | None:
    """V0, C0, V1, C1 of `guided`'s levels from its rows at level-0 ratios 0.25 and 1, the best
    ratio and the v t it gives over the path tracer's (None where a row is missing or the
    estimates are not positive)."""
    e = r["estimators"]
    a, b, pt = e.get("guided"), e.get("guided, level-0 ratio 1"), e.get("pt")
    if not (a and b and pt):
        return None
    v0 = (a["relative_variance"] - b["relative_variance"]) / 3.0
    v1 = b["relative_variance"] - v0
    c0 = (b["ms_per_sample"] - a["ms_per_sample"]) / 0.75
    c1 = a["ms_per_sample"] - c0 / 4.0
    if min(v0, v1, c0, c1) <= 0.0:
        return None
    best = (np.sqrt(v1 * c1) + np.sqrt(v0 * c0)) ** 2
    return {"V0": v0, "V1": v1, "C0": c0, "C1": c1, "best_ratio": float(np.sqrt(v0 * c1 / (v1 * c0))),
            "best_vt_over_pt": float(best / (pt["relative_variance"] * pt["ms_per_sample"]))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scenes", default=",".join(ALL_SCENES))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--probes", default="64,128", help="grid,walks per probe")
    p.add_argument("--width", type=int, default=512)
    p.add_argument("--height", type=int, default=512)
    p.add_argument("--per-dispatch", type=int, default=16)
    p.add_argument("--estimators", default=",".join(ESTIMATORS).replace(", ", ": "),
                   help="the rows to run, ',' between rows and ': ' for ', ' in a row's name")
    args = p.parse_args(argv)
    if args.quick:
        args.scenes, args.spp, args.probes = "anisotropic", 8, "8,32"
        args.width, args.height, args.per_dispatch = 48, 40, 8
    grid, walks = (int(v) for v in args.probes.split(","))
    estimators = tuple(e.strip().replace(": ", ", ") for e in args.estimators.split(","))
    unknown = [e for e in estimators if e not in ESTIMATORS]
    if unknown or "pt" not in estimators:
        p.error(f"--estimators: {unknown or 'pt is needed (every speed-up is against it)'}; "
                f"rows: {', '.join(ESTIMATORS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    from radiance_probes.gl.context import create_headless_context, describe
    ctx = create_headless_context()
    device = describe(ctx)
    log_file = (args.out / "log.txt").open("w")

    def log(msg):
        print(msg, flush=True)
        log_file.write(msg + "\n")
        log_file.flush()

    results = []
    for name in args.scenes.split(","):
        r = measure_scene(ctx, name, args.width, args.height, grid, walks, args.spp,
                          args.per_dispatch, log, estimators)
        if r is not None:
            results.append(r)
    (args.out / "results.json").write_text(json.dumps({"device": device, "results": results},
                                                      indent=1))
    (args.out / "report.md").write_text(report(results, device))
    log(f"wrote {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
