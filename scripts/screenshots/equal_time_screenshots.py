"""The methods at equal time (issues 29, 42): on bonsai and the anisotropic cloud at 512^2, the
path tracer raw and denoised, the raymarcher, and `refine` denoised (the viewer's refine with the
Denoise switch: the raymarcher's image blended with guided denoised, weighted by the errors its
halves estimate) each given 100 ms and 1 s, everything its image cost included (bake, light grid, samples,
the denoiser's guides, read-back and filter), with a signed error map per image against a
path-traced reference ((image - reference) / mean reference: red too bright, blue too dark, full
colour at 10%) and its rRMSE corrected for the reference's noise.

Each method runs at the setting a benchmark run found best for that budget on that scene
(the lowest error among its records whose total time is within the budget; bench/h100 by
default, bench/h200-denoise for the denoised ones, which also give the guides): the setting is chosen from records, the time and error here are measured anew. Samples
are added while the next batch is predicted (from the samples' measured GPU time) to keep the
image within the budget. Run on the GPU (about a minute a scene with REF_DIR, two without):
    python scripts/screenshots/equal_time_screenshots.py screenshots [REF_DIR|-] [scene ...] [--records DIR]
REF_DIR: a bench run's folder whose refs/NAME.npy and measured noise are the reference (as
`bench --ref-dir`); without it a reference of 32768 spp in two halves is rendered. Writes
screenshots/equal_time_NAME.png."""
import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import (corrected_rrmse, flip, reference_noise, rrmse)  # noqa: E402
from radiance_probes.bench.records import error_of, floor                          # noqa: E402
from radiance_probes.bench.report import (equal_time, load as load_results, main_records)  # noqa: E402
from radiance_probes.bench.scenes import bench_scene                                 # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe             # noqa: E402
from radiance_probes.rendering.renderer import Renderer                                 # noqa: E402
from radiance_probes.io.load import load_volume                                       # noqa: E402
from panel_sheet import ldr, panel_sheet, signed_error                   # noqa: E402

SIZE, PANEL, REF_SPP = 512, 256, 32768
BUDGETS_MS = (100.0, 1000.0)
# "+denoise": the same method through the denoiser, its setting and guides the best of the
# denoise records (--denoise-records) within the budget; the denoiser's whole wall time (guides,
# read-back, filter, tile means) is charged. `refine` takes guided's setting (its probes and
# guides); its whole call (bake, raymarcher, guided's halves, the judgement, the filter and the
# blend) is charged on the wall clock.
METHODS = ("pt", "pt+denoise", "raymarch", "refine+denoise")
MAX_RAYMARCH_FRAMES = 64   # past its jitter's averaging a raymarched image stops changing
FULL = 0.1


def best_setting(data: dict, scene: str, method: str, budget_ms: float) -> dict | None:
    """The record of `method` on `scene` with the lowest error within `budget_ms`, among the
    run's main sweep with uniform probes (its report's equal-time table; None: none fits)."""
    return equal_time([r for r in main_records(data, scene) if r["method"] == method
                       and r.get("probe_layout", "uniform") == "uniform"], budget_ms)


def best_denoised(data: dict, scene: str, method: str, budget_ms: float,
                  probes: bool = True) -> dict | None:
    """The denoise record of `method` on `scene` with the lowest error within `budget_ms` (probes
    False: among those whose guides are not the probes' image)."""
    lo = floor(data, scene)
    recs = [{**r, "error": max(error_of(data, r), lo)} for r in data["records"]
            if r["scene"] == scene and r["method"] == method and r.get("denoise")
            and r.get("gather_event", 1) == 1
            and (probes or not r["denoise"].startswith("probes"))]
    return equal_time(recs, budget_ms)


def denoise_within(r: Renderer, guides: str) -> tuple[np.ndarray, float]:
    """The accumulation in hand through the denoiser with `guides`: (image, wall ms of the whole
    step: guides, read-back, filter, tile means)."""
    r.ctx.finish()
    t0 = time.perf_counter()
    d, _ = r.denoise(guides=guides)
    r.ctx.finish()
    ms = 1e3 * (time.perf_counter() - t0)
    if not d.denoised:
        raise SystemExit(f"the denoiser did not run: {d.note}")
    return d.image, ms


def render_within(r: Renderer, method: str, budget_ms: float, size: int, seed: int,
                  guides: str | None = None):
    """The image `method` makes within budget_ms of GPU time: bake and light grid first (fresh,
    so that they count), then samples in batches the measured time per sample predicts fit;
    with `guides`, denoised at the end, its measured wall time charged (a first denoise at this
    size, untimed, gives the estimate the samples leave room for).
    Returns (image, total ms, bake ms, samples)."""
    # once small and untimed first, so that no shader's first use (a driver may compile it then)
    # is charged to the image
    r.render(method, spp=1, width=16, height=16, seed=seed)
    r.invalidate()
    reserve = 0.0
    if guides is not None:   # twice: the first call sets the filter up, the second is the estimate
        for _ in range(2):
            r.begin(method, size, size, seed)
            if r.needs_probes(method):
                r.bake(seed=11)
            if r.needs_light(method):
                r.bake_light()
            r.add_samples(1)
            reserve = denoise_within(r, guides)[1]
            r.invalidate()
    acc = r.begin(method, size, size, seed)
    bake_ms = r.bake(seed=11) if r.needs_probes(method) else 0.0
    if r.needs_light(method):
        bake_ms += r.bake_light()
    last = r.add_samples(1)
    spent, last_n = bake_ms + last, 1
    limit = MAX_RAYMARCH_FRAMES if method == "raymarch" else 1 << 20
    while acc.samples < limit:
        # the dearer of the mean and the last batch's (`guided` adds a level-0 frame now and then)
        per_sample = max((spent - bake_ms) / acc.samples, last / last_n)
        n = min(int((budget_ms - reserve - spent) / per_sample), acc.samples,
                limit - acc.samples)
        if n < 1:
            break
        last, last_n = r.add_samples(n), n
        spent += last
    if guides is None:
        return r.image(), spent, bake_ms, acc.samples
    image, ms = denoise_within(r, guides)
    return image, spent + ms, bake_ms, acc.samples


def refine_within(r: Renderer, budget_ms: float, size: int, seed: int, guides: str):
    """A still image of `refine`, denoised, within budget_ms on the wall clock (render's whole
    call after a GL finish, the bake included): guided's samples first as render_within finds
    they fit, then fewer while the call runs over. Returns (RenderResult, ms, samples)."""
    r.render("refine", spp=8, width=16, height=16, seed=seed, denoise=True,
             denoise_guides=guides)   # untimed: every shader's and the filter's first use
    n = max(render_within(r, "guided", budget_ms, size, seed, guides)[3], 8)
    while True:
        r.invalidate()
        r.ctx.finish()
        t0 = time.perf_counter()
        result = r.render("refine", spp=n, width=size, height=size, seed=seed, denoise=True,
                          denoise_guides=guides)
        r.ctx.finish()
        ms = 1e3 * (time.perf_counter() - t0)
        if ms <= budget_ms or n <= 8:
            return result, ms, n
        n = max(8, int(n * 0.9 * budget_ms / ms))


def caption(method: str, rec: dict | None) -> str:
    if method == "pt" or rec is None:
        return method
    text = f"{method} {rec['probe_grid']}^3 x {rec['probe_samples']}"
    if rec.get("gather_event", 1) > 1:
        text += f", gather {rec['gather_event']}"
    if method == "raymarch" and rec.get("raymarch_step", 0.5) != 0.5:
        text += f", step {rec['raymarch_step']:g}"
    return text


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("ref_dir", nargs="?", default="-")
    ap.add_argument("scenes", nargs="*", default=["bonsai", "anisotropic"])
    ap.add_argument("--records", default="bench/h100", help="the bench run choosing the settings")
    ap.add_argument("--denoise-records", default="bench/h200-denoise",
                    help="the denoise run choosing the denoised variants' settings and guides")
    ap.add_argument("--size", type=int, default=SIZE, help="image side (a quick check: 64)")
    ap.add_argument("--ref-spp", type=int, default=REF_SPP)
    args = ap.parse_args()
    size = args.size
    data = load_results(args.records)
    denoised_data = load_results(args.denoise_records)
    ctx = create_headless_context()
    device = describe(ctx)
    for name in args.scenes:
        scene = bench_scene(name, size, size)
        if scene is None:
            print(f"{name}: dataset absent, skipped")
            continue
        r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
        if args.ref_dir != "-":
            ref_dir = Path(args.ref_dir)
            ref = np.load(ref_dir / "refs" / f"{name}.npy")
            known = load_results(ref_dir)["references"][name]
            noise, spp = known["noise_rrmse"], known["spp"]
        else:
            halves = [r.render("pt", spp=args.ref_spp // 2, seed=100 + i,
                               samples_per_pass=128).image for i in range(2)]
            ref, noise = 0.5 * (halves[0] + halves[1]), reference_noise(*halves)
            spp = args.ref_spp
        panels = []
        for budget in BUDGETS_MS:
            row, maps = [], []
            for column in METHODS:
                method, _, denoise = column.partition("+")
                if denoise:
                    rec = best_denoised(denoised_data, name,
                                        "guided" if method == "refine" else method, budget)
                    if rec is not None and method == "pt" and rec["denoise"].startswith("probes"):
                        rec = best_denoised(denoised_data, name, method, budget, probes=False)
                else:
                    rec = None if method == "pt" else best_setting(data, name, method, budget)
                guides = rec["denoise"].split()[0] if denoise and rec is not None else None
                if (method != "pt" or denoise) and rec is None:
                    print(f"{name} {method} {budget:g} ms: no setting of {args.records} fits")
                    blank = Image.new("RGB", (PANEL, PANEL), (20, 20, 20))
                    row.append((blank, method, f"no setting within {budget:g} ms"))
                    maps.append((blank, f"error, {method}", ""))
                    continue
                r.configure(gather_event=1, raymarch_step=0.5)
                if rec is not None and method != "pt":
                    r.set_scene(scene.replace(probes=replace(
                        scene.probes, grid=(rec["probe_grid"],) * 3, samples=rec["probe_samples"])))
                    r.configure(gather_event=rec.get("gather_event", 1),
                                raymarch_step=rec.get("raymarch_step", 0.5))
                else:
                    r.set_scene(scene)
                if method == "refine":
                    result, ms, n = refine_within(r, budget, size, 3, guides)
                    image, bake_ms = result.image, result.bake_ms
                    w = result.stats["refine_estimate"]["blend_weight"]
                    shown = (f"blend w {w:.2f}" if w is not None and 0.0 < w < 1.0
                             else result.stats["shown"])
                else:
                    image, ms, bake_ms, n = render_within(r, method, budget, size, seed=3,
                                                          guides=guides)
                e = corrected_rrmse(rrmse(image, ref), noise)
                unit = "spp" if method in ("pt", "guided", "refine") else "frames"
                title = caption(method, rec) + (f", denoised ({guides})" if denoise else "")
                if method == "refine":
                    title += f"; {shown}"
                f = flip(image, ref)
                print(f"{name} {budget:g} ms {title}: {ms:.1f} ms (bake {bake_ms:.1f}), {n} "
                      f"{unit}, rRMSE {e:.4f}, FLIP {'n/a' if f is None else f'{f:.4f}'}",
                      flush=True)
                row.append((ldr(image, PANEL), title,
                            f"{ms:.0f} ms ({n} {unit}), rRMSE {100 * e:.2f}%"))
                maps.append((signed_error(image, ref, PANEL, FULL), f"error, {title}",
                             f"within {budget:g} ms"))
            blank = Image.new("RGB", (PANEL, PANEL), (20, 20, 20))
            panels += [(ldr(ref, PANEL), f"{name}: {budget:g} ms of GPU time",
                        f"reference: path tracer, {spp} spp"), *row]
            panels += [(blank, "error maps: red too bright,", f"blue too dark, full at {FULL:.0%}"),
                       *maps]
        sheet = panel_sheet(panels, PANEL, 1 + len(METHODS),
                            f"equal time, bake and denoiser included; settings: the best of "
                            f"{args.records} (raw) and {args.denoise_records} (denoised) within "
                            f"each budget; {size}x{size}, {device}")
        Path(args.out).mkdir(parents=True, exist_ok=True)
        target = Path(args.out) / f"equal_time_{name}.png"
        sheet.save(target, optimize=True)
        print(f"wrote {target}")
        r.release()


if __name__ == "__main__":
    main()
