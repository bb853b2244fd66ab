"""Turns results.json into report.md and plots: error against time per scene with the Pareto front,
time-to-error, equal-time error and a Table-1-style grid of bake times."""
from __future__ import annotations

import gzip
import json
import math
from collections import defaultdict
from pathlib import Path

from radiance_probes.methods import ACCUMULATED
from radiance_probes.bench.records import (caveat, error_of, floor, header as _header,
                                           ms_text as _ms, reference_noise_of as _noise,
                                           run_pixels as _pixels, speed_checks)  # noqa: F401

METHOD_ORDER = ACCUMULATED   # the registry's order (app/methods.py)
COLOURS = {"pt": "#222222", "probes": "#1f77b4", "probes-only": "#2ca02c", "raymarch": "#d62728",
           "guided": "#9467bd"}
TARGETS = (0.20, 0.10, 0.05, 0.02, 0.01, 0.005)


def results_path(folder: str | Path) -> Path:
    """A run folder's records: results.json, or results.json.gz where a superseded run was
    archived (compressed, so that the checkout, which travels whole to the lent GPU machine with
    its 64 MiB limit, keeps room for the datasets). results.json when neither is there."""
    folder = Path(folder)
    archived = folder / "results.json.gz"
    return archived if archived.is_file() and not (folder / "results.json").is_file() else \
        folder / "results.json"


def load(path: str | Path) -> dict:
    """A run's results: a results.json or results.json.gz file, or a run folder holding either."""
    p = Path(path)
    if p.is_dir():
        p = results_path(p)
    if p.suffix == ".gz":
        return json.loads(gzip.decompress(p.read_bytes()))
    return json.loads(p.read_text())


def merge(paths: list[str | Path], out: str | Path) -> Path:
    """Combines results.json files of runs on one device (e.g. scenes split over several calls)."""
    runs = [load(p) for p in paths]
    devices = {r["meta"]["device"] for r in runs}
    if len(devices) != 1:
        raise ValueError(f"results come from different devices: {sorted(devices)}")
    merged = {"meta": dict(runs[0]["meta"]), "references": {}, "records": []}
    merged["meta"]["command"] = " ; ".join(r["meta"].get("command", "") for r in runs)
    merged["meta"]["finished"] = runs[-1]["meta"].get("finished")
    for r in runs:
        merged["references"].update(r["references"])
        merged["records"] += r["records"]
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The runs' clock logs (each beside its results), one after the other, and their summary:
    # the first run's alone would speak for the others' records too.
    logs = [Path(p).parent / "nvidia-smi.csv" for p in paths]
    merged["meta"].pop("gpu_clock", None)
    if logs and all(log.is_file() for log in logs):
        from radiance_probes.bench.clock_log import summary
        combined = path.parent / "nvidia-smi.csv"
        text = "".join(log.read_text() for log in logs)
        combined.write_text(text)
        clock = summary(combined)
        if clock is not None:
            merged["meta"]["gpu_clock"] = clock
    path.write_text(json.dumps(merged, indent=1))
    return path


def sweep_precision(data: dict) -> str:
    """The probe precision of a run's main sweep (bench --probe-precision; 32F by default)."""
    return data.get("meta", {}).get("config", {}).get("probe_precision") or "rgba32f"


def sweep_steps(data: dict) -> tuple[float, ...]:
    """The raymarch steps every probe setting ran with (runs before sweep_raymarch_steps: 0.5)."""
    return tuple(data["meta"].get("config", {}).get("sweep_raymarch_steps", (0.5,)))


def main_records(data: dict, scene: str) -> list[dict]:
    """A scene's records of the main sweep (its precision, no window, compute stage, default step),
    each with `error`: its rRMSE corrected for the reference's noise, raised to the floor where
    below it."""
    lo = floor(data, scene)
    precision = sweep_precision(data)
    steps = sweep_steps(data)
    out = []
    for r in data["records"]:
        if r["scene"] != scene or r.get("mode") == "cost":
            continue
        if r["method"] != "pt" and (r.get("precision") or "rgba32f") != precision:
            continue
        if r.get("sh_window", "none") != "none" or r.get("sh_order_variant"):
            continue
        if r["method"] == "raymarch" and (r.get("stage") != "compute"
                                          or r.get("raymarch_step") not in steps):
            continue
        e = error_of(data, r)
        out.append(dict(r, error=max(e, lo), below_floor=e < lo))
    return out


def shown(record: dict, data: dict) -> str:
    """A record's error as the report writes it: corrected for the reference's noise, or `<floor`."""
    lo, e = floor(data, record["scene"]), error_of(data, record)
    return f"<{lo:.4f}" if e < lo else f"{e:.4f}"


def err(r: dict) -> str:
    return f"<{r['error']:.4f}" if r.get("below_floor") else f"{r['error']:.4f}"


def pareto(records: list[dict]) -> list[dict]:
    """Records no other record beats in both total time and error, by increasing time."""
    front, best = [], math.inf
    for r in sorted(records, key=lambda r: (r["total_ms"], r["error"])):
        if r["error"] < best:
            front.append(r)
            best = r["error"]
    return front


def gathered(r: dict) -> bool:
    """A `probes` record that read the probes after more than one scattering event (a final
    gather): in the time-to-error tables and the front, kept out of the per-setting tables."""
    return r.get("gather_event", 1) > 1


def label(r: dict) -> str:
    if r["method"] == "pt":
        return f"pt {r['spp']} spp"
    step = r.get("raymarch_step", 0.5) if r["method"] == "raymarch" else 0.5
    return (f"{r['method']} {r['probe_grid']}^3x{r['probe_samples']}, {r['spp']} fr"
            + (f", step {step:g}" if step != 0.5 else "")
            + (f", gather {r['gather_event']}" if gathered(r) else ""))


def time_to_error(records: list[dict], target: float) -> dict | None:
    ok = [r for r in records if r["error"] <= target]
    return min(ok, key=lambda r: r["total_ms"]) if ok else None


def equal_time(records: list[dict], budget_ms: float) -> dict | None:
    ok = [r for r in records if r["total_ms"] <= budget_ms]
    return min(ok, key=lambda r: (r["error"], r["total_ms"])) if ok else None


def _fmt(v, digits=4) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def _scene_figure(scenes: list[str], cols: int, size: tuple[float, float]):
    """A figure with one axes per scene, `cols` a row, each `size` inches: (fig, axes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = min(cols, len(scenes))
    rows = math.ceil(len(scenes) / cols)
    return plt.subplots(rows, cols, figsize=(size[0] * cols, size[1] * rows), squeeze=False)


def _save_scene_figure(fig, axes, scenes: list[str], title: str, path: Path, legend_size: float,
                       title_size: float) -> None:
    """The axes beyond the scenes hidden, the first one's legend, the title; saved and closed."""
    import matplotlib.pyplot as plt
    for ax in list(axes.flat)[len(scenes):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=legend_size)
    fig.suptitle(title, fontsize=title_size)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot(data: dict, scenes: list[str], path: Path) -> None:
    fig, axes = _scene_figure(scenes, 3, (5.2, 4.2))
    for ax, scene in zip(axes.flat, scenes):
        recs = main_records(data, scene)
        for m in METHOD_ORDER:
            pts = [r for r in recs if r["method"] == m]
            if pts:
                for below, marker in ((False, "o"), (True, "v")):
                    sel = [r for r in pts if r["below_floor"] == below]
                    if sel:
                        ax.scatter([r["total_ms"] for r in sel], [r["error"] for r in sel], s=10,
                                   marker=marker, color=COLOURS[m], alpha=0.5,
                                   label=None if below else m)
                f = pareto(pts)
                ax.plot([r["total_ms"] for r in f], [r["error"] for r in f], color=COLOURS[m], lw=1)
        front = pareto(recs)
        ax.plot([r["total_ms"] for r in front], [r["error"] for r in front], "k--", lw=1.5,
                label="Pareto front (all)")
        if floor(data, scene) > 0:
            ax.axhline(floor(data, scene), color="grey", lw=0.8, ls=":",
                       label="floor of the noise-corrected error; v: below it")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(scene)
        ax.set_xlabel("time to image, bake included (GPU ms)")
        ax.set_ylabel("relative RMSE")
        ax.grid(True, which="both", alpha=0.2)
    _save_scene_figure(fig, axes, scenes, f"Error against time: {data['meta']['device']}", path,
                       7, 10)


def dispatch_lines(data: dict, scenes: list[str]) -> list[str]:
    """The longest single dispatch per scene and method (every record holds the longest since the
    record before it: app/gl/dispatch_log.py), against DISPATCH_BOUND_MS."""
    from radiance_probes.rendering.budgets.dispatch_budget import DISPATCH_BOUND_MS
    recs = [r for r in data["records"] if r.get("longest_dispatch_ms") is not None]
    if not recs:
        return []
    meta = data["meta"]
    lines = ["", "## The longest dispatch", "",
             f"Every compute dispatch of the run was timed (GPU timestamps). The longest: "
             f"**{meta.get('longest_dispatch_ms', max(r['longest_dispatch_ms'] for r in recs)):.1f} "
             f"ms** ({meta.get('longest_dispatch')}), against a bound of {DISPATCH_BOUND_MS:g} ms; "
             f"{meta.get('dispatches', 'n/a')} dispatches in all. Per scene and method (the "
             "longest since the record before, so a method's row includes its bake):", "",
             "| scene | method | longest dispatch | program |", "|---|---|---|---|"]
    for s in scenes:
        for m in dict.fromkeys(r["method"] for r in recs if r["scene"] == s):
            worst = max((r for r in recs if r["scene"] == s and r["method"] == m),
                        key=lambda r: r["longest_dispatch_ms"])
            lines.append(f"| {s} | {m} | {worst['longest_dispatch_ms']:.2f} ms | "
                         f"{worst.get('longest_dispatch')} |")
    return lines


def write_report(results_path: str | Path, out_dir: str | Path | None = None) -> Path:
    data = load(results_path)
    out = Path(out_dir or Path(results_path).parent)
    out.mkdir(parents=True, exist_ok=True)
    scenes = [s for s in dict.fromkeys(r["scene"] for r in data["records"])]
    meta = data["meta"]
    if all(r.get("mode") == "cost" for r in data["records"]) and data["records"]:
        return _write_cost_report(data, out, scenes)
    if all(r.get("mode") == "bake" for r in data["records"]) and data["records"]:
        return _write_bake_report(data, out, scenes)
    if all(r.get("mode") == "bias" for r in data["records"]) and data["records"]:
        from radiance_probes.bench.bias import write_bias_report
        return write_bias_report(data, out)
    if all(r.get("mode") == "interact" for r in data["records"]) and data["records"]:
        from radiance_probes.bench.interact_report import write_interact_report
        return write_interact_report(data, out)
    if all(r.get("mode") == "denoise" for r in data["records"]) and data["records"]:
        from radiance_probes.bench.denoise import write_denoise_report
        return write_denoise_report(data, out)
    if all(r.get("mode") == "movie" for r in data["records"]) and data["records"]:
        from radiance_probes.bench.movie import write_movie_report
        return write_movie_report(data, out)
    lines = [f"# Speed against error", "",
             f"Device: **{meta['device']}**. Started {meta.get('started')}, finished "
             f"{meta.get('finished', 'not finished (partial run)')}.", "", *caveat(meta),
             f"Command: `{meta.get('command', '')}`", "",
             f"Image {meta['config']['width']}x{meta['config']['height']}. Times are GPU times from "
             "timestamp queries: bake is the sum over bake passes; every progressive method adds "
             f"{meta['config'].get('samples_per_dispatch', 1)} samples per pixel per dispatch; "
             "frame is the median GPU time per sample per pixel over those dispatches after a "
             "warm-up; total = bake + the summed GPU time of the dispatches up to that sample count. "
             "Errors are relative RMSE over linear RGB and mean LDR-FLIP of the tone-mapped images "
             "(SPEC.md) against a path-traced reference. The raymarcher runs every probe "
             f"setting at steps of {', '.join(f'{x:g}' for x in sweep_steps(data))} voxels "
             "(a label names the step where it is not the default 0.5).", ""]
    if scenes:
        plot(data, scenes, out / "error_vs_time.png")
        lines += ["![error against time](error_vs_time.png)", ""]
    lines += ["## References", "",
              "Each reference is two independent path-traced halves; its relative noise is "
              "rRMSE(half A, half B) / 2. Every error in this report is the measured rRMSE "
              "corrected for that noise, sqrt((e^2 - noise^2) / (1 - noise^2)) (derived in "
              "app/rendering/metrics.py, tested on synthetic images with known error; results.json "
              "keeps the measured `rrmse`). The correction resolves errors down to 3 standard "
              "errors of its own estimate (the floor, about a tenth of the noise at 512^2): a "
              "smaller error is written `<floor` and plotted on the floor as a triangle, and "
              "targets below the floor are not ranked.", "",
              "| scene | spp | GPU time | relative noise | floor | smallest error measured | "
              "records below the floor |", "|---|---|---|---|---|---|---|"]
    for s in scenes:
        ref = data["references"].get(s, {})
        recs = main_records(data, s)
        smallest = min(recs, key=lambda r: r["rrmse"], default=None)
        below = sum(r["below_floor"] for r in recs)
        lines.append(f"| {s} | {ref.get('spp')} | {_ms(ref.get('gpu_ms', 0))} | "
                     f"{ref.get('noise_rrmse', 0):.2e} | {floor(data, s):.4f} | {'n/a' if smallest is None else err(smallest)} | "
                     f"{below} of {len(recs)} |")
    lines += ["", "## Time to reach an error (bake included)", "",
              "| scene | target rRMSE | " + " | ".join(METHOD_ORDER) + " | fastest probe method vs pt |",
              "|---|---|" + "---|" * (len(METHOD_ORDER) + 1)]
    for s in scenes:
        recs = main_records(data, s)
        for t in TARGETS:
            if t < floor(data, s):
                lines.append(f"| {s} | {100 * t:g}% | " + " | ".join("-" for _ in METHOD_ORDER)
                             + f" | below the reference floor {floor(data, s):.4f} |")
                continue
            cells, best = [], {}
            for m in METHOD_ORDER:
                r = time_to_error([x for x in recs if x["method"] == m], t)
                best[m] = r
                cells.append("not reached" if r is None else f"{_ms(r['total_ms'])} ({label(r)})")
            probe_best = min((best[m] for m in METHOD_ORDER[1:] if best[m]),
                             key=lambda r: r["total_ms"], default=None)
            if best["pt"] and probe_best:
                verdict = f"{best['pt']['total_ms'] / probe_best['total_ms']:.1f}x faster" \
                    if probe_best["total_ms"] < best["pt"]["total_ms"] else \
                    f"{probe_best['total_ms'] / best['pt']['total_ms']:.1f}x slower"
            elif probe_best:
                verdict = "pt does not reach it"
            elif best["pt"]:
                verdict = "no probe method reaches it"
            else:
                verdict = "-"
            lines.append(f"| {s} | {100 * t:g}% | " + " | ".join(cells) + f" | {verdict} |")
    lines += ["", "## Equal-time error", "",
              "At the time the path tracer needs for each of its sample counts: the lowest error "
              "each method reaches within that time, bake included.", "",
              "| scene | budget (pt spp) | " + " | ".join(METHOD_ORDER) + " |",
              "|---|---|" + "---|" * len(METHOD_ORDER)]
    for s in scenes:
        recs = main_records(data, s)
        for p in sorted((r for r in recs if r["method"] == "pt"), key=lambda r: r["spp"]):
            cells = []
            for m in METHOD_ORDER:
                r = equal_time([x for x in recs if x["method"] == m], p["total_ms"])
                cells.append("-" if r is None else f"{err(r)} ({label(r)})")
            lines.append(f"| {s} | {_ms(p['total_ms'])} ({p['spp']}) | " + " | ".join(cells) + " |")
    lines += speed_checks(data, scenes)
    lines += dispatch_lines(data, scenes)
    lines += _table1(data, scenes)
    lines += _sweeps(data, scenes)
    lines += _layouts(data, scenes)
    lines += _sh_orders(data, scenes)
    lines += _gathers(data, scenes)
    lines += convergence_lines(data, scenes, out)
    lines += ["", "## Raw results", "", "`results.json`: one record per scene, method and setting "
              "(`scene, method, probe_grid, probe_samples, spp, bake_ms, frame_ms, total_ms, rrmse, "
              "flip, gpu_bytes, device`, and the sweep's own fields)."]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _table1(data: dict, scenes: list[str]) -> list[str]:
    """The paper's Table 1 axes: bake time and error per probe grid and samples per probe."""
    lines = ["", "## Probe grid x samples per probe (the paper's Table 1 axes)", "",
             "Bake GPU time; `probes` frame time and rRMSE after the most frames measured.", ""]
    precision = sweep_precision(data)
    for s in scenes:
        recs = [r for r in data["records"] if r["scene"] == s and r["method"] == "probes"
                and r.get("mode") != "cost" and r.get("precision") == precision
                and r.get("sh_window") == "none" and not r.get("sh_order_variant")
                and r.get("probe_layout", "uniform") == "uniform" and not gathered(r)]
        if not recs:
            continue
        frames = max(r["spp"] for r in recs)
        recs = [r for r in recs if r["spp"] == frames]
        grids = sorted({r["probe_grid"] for r in recs})
        samples = sorted({r["probe_samples"] for r in recs})
        cell = {(r["probe_grid"], r["probe_samples"]): r for r in recs}
        lines += [f"### {s} ({frames} frames)", "",
                  "| grid \\ samples | " + " | ".join(str(x) for x in samples) + " |",
                  "|---|" + "---|" * len(samples)]
        for g in grids:
            row = []
            for n in samples:
                r = cell.get((g, n))
                row.append("" if r is None else f"bake {_ms(r['bake_ms'])}, {r['frame_ms']:.3g} ms/fr, "
                           f"{shown(r, data)}, "
                           f"{r.get('probe_bytes', 0) / 2**20:.1f} MiB probes")
            lines.append(f"| {g}^3 | " + " | ".join(row) + " |")
        lines.append("")
    return lines


def _setting_records(data: dict) -> list[dict]:
    """The probe records that the layout and SH-order tables compare: the sweep's precision, no
    SH window, the raymarcher's compute stage at its default step."""
    precision = sweep_precision(data)
    return [r for r in data["records"] if r.get("mode") != "cost" and r["method"] != "pt"
            and not gathered(r) and r.get("precision", "rgba32f") == precision
            and r.get("sh_window", "none") == "none"
            and (r["method"] != "raymarch" or (r.get("stage") == "compute"
                                              and r.get("raymarch_step") == 0.5))]


def _latest_by_setting(recs: list[dict], scene: str, variant) -> dict:
    """{(grid, walks, variant(record)): {method: its record after the most frames}} of a scene."""
    cells = defaultdict(dict)
    for r in recs:
        if r["scene"] != scene:
            continue
        key = (r["probe_grid"], r["probe_samples"], variant(r))
        best = cells[key].get(r["method"])
        if best is None or r["spp"] > best["spp"]:
            cells[key][r["method"]] = r
    return cells


def _errors(by_method: dict, data: dict) -> str:
    return " | ".join(shown(by_method[m], data) if m in by_method else ""
                      for m in ("probes", "probes-only", "raymarch"))


def _layouts(data: dict, scenes: list[str]) -> list[str]:
    """Probe layouts at the same probe count (bench --probe-layouts): each setting's error and
    bake time per layout, after the most frames measured."""
    recs = [r for r in _setting_records(data) if not r.get("sh_order_variant")]
    if not any(r.get("probe_layout", "uniform") != "uniform" for r in recs):
        return []
    lines = ["", "## Probe layouts at the same probe count", "",
             "| scene | grid x walks | layout | bake | probes rRMSE | probes-only rRMSE | "
             "raymarch rRMSE |", "|---|---|---|---|---|---|---|"]
    for s in scenes:
        cells = _latest_by_setting(recs, s, lambda r: r.get("probe_layout", "uniform"))
        settings = {(g, n) for (g, n, layout) in cells if layout != "uniform"}
        for (g, n, layout), by_method in sorted(cells.items()):
            if (g, n) not in settings:
                continue
            any_r = next(iter(by_method.values()))
            lines.append(f"| {s} | {g}^3 x {n} | {layout} | {_ms(any_r['bake_ms'])} | "
                         f"{_errors(by_method, data)} |")
    return lines


def _sh_orders(data: dict, scenes: list[str]) -> list[str]:
    """SH orders at the same probe setting (bench --sh-orders): each order's bake, frame time,
    probe memory and error, after the most frames measured, beside the scene's own order."""
    recs = [r for r in _setting_records(data)
            if r.get("probe_layout", "uniform") == "uniform" and "sh_order" in r]
    if not any(r.get("sh_order_variant") for r in recs):
        return []
    lines = ["", "## SH orders at the same probe setting", "",
             "The scene's own order (the main sweep's) and the `--sh-orders` variants; frame time "
             "of the raymarcher; errors after the most frames measured.", "",
             "| scene | grid x walks | SH order | bake | raymarch ms / frame | probe memory | "
             "probes rRMSE | probes-only rRMSE | raymarch rRMSE |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in scenes:
        cells = _latest_by_setting(recs, s, lambda r: r["sh_order"])
        settings = {(g, n) for (g, n, o), by in cells.items()
                    if any(r.get("sh_order_variant") for r in by.values())}
        for (g, n, order), by_method in sorted(cells.items()):
            if (g, n) not in settings:
                continue
            any_r = next(iter(by_method.values()))
            rm = by_method.get("raymarch")
            frame = "" if rm is None else f"{rm['frame_ms']:.3f}"
            lines.append(f"| {s} | {g}^3 x {n} | {order} | {_ms(any_r['bake_ms'])} | {frame} | "
                         f"{any_r.get('probe_bytes', 0) / 2**20:.1f} MiB | "
                         f"{_errors(by_method, data)} |")
    return lines


def _gathers(data: dict, scenes: list[str]) -> list[str]:
    """`probes` at each gather event (1: the first scattering event, the main sweep's), at the
    settings the gathers ran at: error and total time after each number of frames."""
    recs = [r for r in _setting_records(data) + [r for r in data["records"] if gathered(r)]
            if r["method"] == "probes" and r.get("probe_layout", "uniform") == "uniform"
            and not r.get("sh_order_variant")]
    if not any(gathered(r) for r in recs):
        return []
    lines = ["", "## Final gather", "",
             "`probes` reading the probes at scattering event k: events before k are traced as "
             "the path tracer traces them (lib/integrator.glsl). Error (total time, bake "
             "included) after each number of frames.", ""]
    for s in scenes:
        cells = defaultdict(dict)
        for r in recs:
            if r["scene"] == s:
                cells[(r["probe_grid"], r["probe_samples"], r.get("gather_event", 1))][r["spp"]] = r
        settings = {(g, n) for (g, n, k) in cells if k > 1}
        if not settings:
            continue
        frames = sorted({f for (g, n, k), by in cells.items() if (g, n) in settings for f in by})
        lines += [f"### {s}", "", "| grid x walks | gather | " + " | ".join(f"{f} fr" for f in frames)
                  + " |", "|---|---|" + "---|" * len(frames)]
        for (g, n, k), by in sorted(cells.items()):
            if (g, n) not in settings:
                continue
            row = [f"{shown(by[f], data)} ({_ms(by[f]['total_ms'])})" if f in by else ""
                   for f in frames]
            lines.append(f"| {g}^3 x {n} | {k} | " + " | ".join(row) + " |")
        lines.append("")
    return lines


# A series levels off (a bias floor) where its error falls by less than this power of the time
# its samples took, over the last 16x of samples; an unbiased estimator's falls as time^-0.5.
FLOOR_SLOPE = -0.25
SLOPE_SPAN = 16            # the slope is measured over the last this-many times the samples


def series(records: list[dict]) -> dict[tuple, list[dict]]:
    """A scene's progressive runs: its records grouped by method and setting (grid, walks, gather
    event, raymarch step), each group by increasing samples per pixel."""
    groups = defaultdict(list)
    for r in records:
        key = (r["method"], r.get("probe_grid"), r.get("probe_samples"), r.get("gather_event", 1),
               r.get("raymarch_step", 0.5) if r["method"] == "raymarch" else 0.5)
        groups[key].append(r)
    return {k: sorted(v, key=lambda r: r["spp"]) for k, v in groups.items()}


def tail_slope(run: list[dict]) -> float | None:
    """d log(error) / d log(time of the samples) over the run's last SLOPE_SPAN times its samples
    (the bake, a fixed cost, left out): -0.5 for an unbiased estimator's noise, towards 0 where a
    bias floor is reached. None where the run is shorter than that, or an end is below the
    reference's floor (its error is then not resolved)."""
    last = run[-1]
    first = next((r for r in run if r["spp"] * SLOPE_SPAN >= last["spp"]), None)
    if first is None or first is last or last["spp"] < SLOPE_SPAN * run[0]["spp"]:
        return None
    if first["below_floor"] or last["below_floor"]:
        return None
    t0, t1 = first["total_ms"] - first["bake_ms"], last["total_ms"] - last["bake_ms"]
    if t0 <= 0 or t1 <= t0:
        return None
    return math.log(last["error"] / first["error"]) / math.log(t1 / t0)


def _longest_runs(data: dict, scene: str) -> dict[str, list[dict]]:
    """Per method, the run (one setting) that reached the lowest error, `probes` with a final
    gather apart from `probes` without."""
    best: dict[str, list[dict]] = {}
    for (method, _g, _n, event, _step), run in series(main_records(data, scene)).items():
        name = "probes, gather" if method == "probes" and event > 1 else method
        if name not in best or run[-1]["error"] < best[name][-1]["error"]:
            best[name] = run
    return best


CONVERGENCE_ORDER = ("pt", "guided", "probes, gather", "probes", "probes-only", "raymarch")


def convergence_lines(data: dict, scenes: list[str], out: Path) -> list[str]:
    """Does each method's error keep falling? Per scene and method, the setting that got lowest:
    its lowest error, the time it took, and the slope of its error against its samples' time over
    its last 16x of samples (tail_slope), with convergence.png. Only where some run is that long."""
    rows = []
    for s in scenes:
        for name, run in sorted(_longest_runs(data, s).items(),
                                key=lambda kv: CONVERGENCE_ORDER.index(kv[0])):
            slope = tail_slope(run)
            if slope is None:
                continue
            verdict = "levelling off (a floor)" if slope > FLOOR_SLOPE else "still falling"
            rows.append(f"| {s} | {name} | {label(run[-1])} | {err(run[-1])} | "
                        f"{_ms(run[-1]['total_ms'])} | {slope:+.2f} | {verdict} |")
    if not rows:
        return []
    plot_convergence(data, scenes, out / "convergence.png")
    return ["", "## Convergence: which errors keep falling", "",
            "![error against time, the longest run of each method](convergence.png)", "",
            "Per scene and method, the setting that reached the lowest error: that error, the "
            "total time it took (bake included), and the slope of log(error) against log(the "
            f"samples' GPU time) over its last {SLOPE_SPAN}x of samples. An unbiased estimator's "
            "noise falls as time^-0.5; a slope above "
            f"{FLOOR_SLOPE:g} means the run is levelling off at its bias floor; a biased method "
            "still falling at its last sample may yet level off further on (its run ends "
            "there).", "",
            "| scene | method | longest run | lowest error | time | slope | |",
            "|---|---|---|---|---|---|---|", *rows]


def plot_convergence(data: dict, scenes: list[str], path: Path) -> None:
    colours = {**COLOURS, "probes, gather": "#17becf"}
    fig, axes = _scene_figure(scenes, 4, (4.4, 3.8))
    for ax, scene in zip(axes.flat, scenes):
        runs = _longest_runs(data, scene)
        for name in CONVERGENCE_ORDER:
            if name not in runs:
                continue
            run = runs[name]
            ax.plot([r["total_ms"] for r in run], [r["error"] for r in run], marker="o", ms=3,
                    lw=1.2, color=colours[name], label=name)
        if "pt" in runs:
            last = runs["pt"][-1]
            t = [last["total_ms"] / 256, last["total_ms"] * 4]
            ax.plot(t, [last["error"] * (x / last["total_ms"]) ** -0.5 for x in t], ls=":",
                    color="grey", lw=1, label="time^-1/2")
        ax.axhline(0.005, color="grey", lw=0.6, ls="--")
        if floor(data, scene) > 0:
            ax.axhline(floor(data, scene), color="grey", lw=0.6, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(scene, fontsize=9)
        ax.set_xlabel("time, bake included (GPU ms)", fontsize=8)
        ax.set_ylabel("relative RMSE", fontsize=8)
        ax.grid(True, which="both", alpha=0.2)
    _save_scene_figure(fig, axes, scenes,
                       f"The longest run of each method (dashed: 0.5%): {data['meta']['device']}",
                       path, 6, 9)


def _sweeps(data: dict, scenes: list[str]) -> list[str]:
    """Raymarch step and stage, 16F against 32F, SH window: at the showcase setting."""
    lines = ["## Raymarch step and stage, precision and SH window (showcase setting)", "",
             "| scene | variant | frame | bake | rRMSE | FLIP | GPU memory |", "|---|---|---|---|---|---|---|"]
    precision = sweep_precision(data)
    for s in scenes:
        by_variant = defaultdict(list)
        for r in data["records"]:
            if (r["scene"] != s or r["method"] == "pt" or r.get("mode") == "cost"
                    or r.get("sh_order_variant") or gathered(r)):
                continue
            if r["method"] == "raymarch":
                key = (f"raymarch {r.get('stage')} step {r.get('raymarch_step')} vox, "
                       f"{r.get('precision')} window {r.get('sh_window')}")
            else:
                key = f"{r['method']} {r.get('precision')} window {r.get('sh_window')}"
            if r.get("probe_layout", "uniform") != "uniform":
                key += f", {r['probe_layout']} layout"
            by_variant[(key, r["probe_grid"], r["probe_samples"])].append(r)
        grids = {(g, n) for (_, g, n), rs in by_variant.items()
                 if any(r.get("precision") != precision or r.get("stage") == "fragment"
                        for r in rs)}
        for (key, g, n), rs in sorted(by_variant.items()):
            if (g, n) not in grids:
                continue
            r = max(rs, key=lambda r: r["spp"])
            lines.append(f"| {s} | {key}, {g}^3x{n}, {r['spp']} fr | {r['frame_ms']:.3g} ms | "
                         f"{_ms(r['bake_ms'])} | {shown(r, data)} | {_fmt(r.get('flip'))} | "
                         f"{r['gpu_bytes'] / 2**20:.1f} MiB |")
    return lines


def _write_cost_report(data: dict, out: Path, scenes: list[str]) -> Path:
    """The cost mode's report (app/bench/cost.py): each saving against the baseline, error beside."""
    meta = data["meta"]
    lines = [*_header("# Cost that follows the scene", meta),
             "Each variant against the baseline at the same nominal probe grid and walks per probe: "
             "bake GPU time, GPU time per frame (median, "
             f"{meta['config'].get('samples_per_dispatch', 1)} samples per dispatch), probe texture "
             "memory, and relative RMSE against the path-traced reference (corrected for the reference's noise, written `<floor` "
             "below what the correction resolves; see the main report). Ratios are baseline / variant: above 1 is a gain. "
             "Bake times of identical work differ by up to about 20% between runs (the chunked "
             "dispatches are issued from Python), so bake ratios within 0.8 to 1.25 are noise.",
             "", "`auto` rows: the setting `auto` chose for a target (against its 96-px pilot) and "
             "that setting's error at full resolution against the reference.", ""]
    for s in scenes:
        recs = [r for r in data["records"] if r["scene"] == s]
        lines += [f"## {s}", ""]
        pts = [r for r in recs if r["method"] == "pt"]
        if pts:
            lines += ["| path tracer | empty-space skipping | ms / spp | rRMSE |", "|---|---|---|---|"]
            for r in pts:
                lines.append(f"| {r['spp']} spp | {r.get('empty_space_skipping')} | "
                             f"{r['frame_ms']:.3f} | {shown(r, data)} |")
            lines.append("")
        autos = [r for r in recs if str(r.get("variant", "")).startswith("auto")]
        if autos:
            lines += ["| auto target | chosen (grid, walks) | pilot rRMSE | frames | full-resolution "
                      "rRMSE | met | bake | raymarch ms/fr | probe memory |",
                      "|---|---|---|---|---|---|---|---|---|"]
            for r in autos:
                met = "yes" if r["rrmse"] <= r["auto_target"] else "**no**"
                if r["bake_ms"] < 1.0:   # runs before this fix reused the pilot's bake unrecorded
                    r = dict(r, bake_ms=r["bake_ms"] + next(
                        (t["bake_ms"] for t in r.get("auto_trials", [])
                         if (t["grid"], t["walks"]) == (r["probe_grid"], r["probe_samples"])), 0.0))
                lines.append(f"| {r['auto_target']:g} | {'x'.join(map(str, r['probe_grid_xyz']))}, "
                             f"{r['probe_samples']} | {r['auto_pilot_rrmse']:.4f} | {r['spp']} | "
                             f"{shown(r, data)} | {met} | {_ms(r['bake_ms'])} | "
                             f"{r['frame_ms']:.3f} | {r['probe_bytes'] / 2**20:.2f} MiB |")
            lines.append("")
        settings = sorted({(r["probe_grid"], r["probe_samples"]) for r in recs
                           if r["method"] != "pt" and not str(r.get("variant", "")).startswith("auto")})
        for g, n in settings:
            rows = [r for r in recs if (r["probe_grid"], r["probe_samples"]) == (g, n)
                    and not str(r.get("variant", "")).startswith("auto")]
            base = {m: next((r for r in rows if r["method"] == m and r["variant"] == "baseline"
                             and r.get("empty_space_skipping") in (True, None)), None)
                    for m in ("probes", "raymarch")}
            lines += [f"### {g}^3 x {n} walks", "",
                      "| variant | skipping | grid | bake (x) | probes ms/fr (x) | raymarch ms/fr (x) "
                      "| probe memory (x) | probes rRMSE | raymarch rRMSE |",
                      "|---|---|---|---|---|---|---|---|---|"]
            keys = list(dict.fromkeys((r["variant"], r.get("empty_space_skipping")) for r in rows))
            for variant, skipping in keys:
                pr = next(r for r in rows if r["method"] == "probes" and r["variant"] == variant
                          and r.get("empty_space_skipping") == skipping)
                rm = next(r for r in rows if r["method"] == "raymarch" and r["variant"] == variant
                          and r.get("empty_space_skipping") == skipping)

                def x(value, ref):
                    return f"{ref / value:.2f}x" if ref and value else "-"
                bp, br = base["probes"], base["raymarch"]
                lines.append(
                    f"| {variant} | {skipping} | {'x'.join(map(str, pr['probe_grid_xyz']))} | "
                    f"{_ms(pr['bake_ms'])} ({x(pr['bake_ms'], bp and bp['bake_ms'])}) | "
                    f"{pr['frame_ms']:.3f} ({x(pr['frame_ms'], bp and bp['frame_ms'])}) | "
                    f"{rm['frame_ms']:.3f} ({x(rm['frame_ms'], br and br['frame_ms'])}) | "
                    f"{pr['probe_bytes'] / 2**20:.2f} MiB ({x(pr['probe_bytes'], bp and bp['probe_bytes'])}) | "
                    f"{shown(pr, data)} | {shown(rm, data)} |")
            lines.append("")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _write_bake_report(data: dict, out: Path, scenes: list[str]) -> Path:
    """The bake mode's report (app/bench/bake.py): bake time, where it goes, and the ceiling."""
    meta = data["meta"]
    lines = [*_header("# The probe bake: time, profile and ceiling", meta),
             "Per scene and probe setting (N^3 nominal, fitted to the visible region; walks per "
             "probe): the bake's GPU time (median of "
             f"{meta['config'].get('bake_repeats', 3)} bakes), walks per second, its split into "
             "walks, SH projection, the probes' sun transmittance and the rest (timestamps between "
             "the dispatches of one more bake), tracking iterations per walk (free flight + shadow "
             "rays; macrocell crossings and scattering events apart) from the shaders' profiling "
             "build, and the walks' tracking iterations per second as a fraction of the GPU's "
             "measured trilinear-march rate (the ceiling). Then the raymarcher over those probes: "
             "GPU ms per frame and rRMSE against the path-traced reference after "
             f"{meta['config'].get('raymarch_frames', [16])[-1]} frames, corrected for the "
             "reference's noise (each record for the reference it was measured against; `<floor` "
             "below what the correction resolves); total = bake + the "
             "raymarcher's light grid + render. `code` names the code measured (before/after).", ""]
    for s in scenes:
        recs = [r for r in data["records"] if r["scene"] == s]
        if not recs:
            continue
        ceiling = recs[0].get("ceiling_steps_per_s")
        lines += [f"## {s}", "", f"Ceiling: {ceiling / 1e9:.2f} G trilinear steps/s." if ceiling
                  else "", "",
                  "| code | setting (fitted) | bake | walks/s | walks / project / sun / other ms "
                  "| steps per walk (flight + shadow; cells; events) | of ceiling | light | "
                  "raymarch ms/fr | rRMSE | total |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in recs:
            light = "x".join(map(str, r["light_grid"])) if r.get("light_grid") else "-"
            setting = (f"{r['probe_grid']}^3 x {r['probe_samples']} "
                       f"({'x'.join(map(str, r['probe_grid_xyz']))}); sun {r.get('walk_sun', 'ray')}"
                       f", light {light}")
            if r.get("walk_adaptive"):
                setting += (f"; adaptive {r['walk_adaptive']:g} "
                            f"({100 * r['counted_walks'] / r['walks']:.0f}% of walks)")
            if r.get("bake_walk_ms") is not None:
                split = (f"{r['bake_walk_ms']:.1f} / {r['bake_project_ms']:.1f} / "
                         f"{r['bake_sun_ms']:.1f} / {r['bake_other_ms']:.1f}")
                steps = (f"{r['steps_per_walk']:.1f} ({r['flight_steps_per_walk']:.1f} + "
                         f"{r['shadow_steps_per_walk']:.1f}; {r['cell_steps_per_walk']:.1f}; "
                         f"{r['events_per_walk']:.2f})")
                frac = f"{100 * r['ceiling_fraction']:.1f}%" if r.get("ceiling_fraction") else "-"
            else:
                split, steps, frac = "-", "-", "-"
            wps = f"{r['walks_per_s'] / 1e6:.0f} M" if r.get("walks_per_s") else "-"
            lines.append(f"| {r.get('code', '')} | {setting} | {_ms(r['probe_bake_ms'])} | {wps} | "
                         f"{split} | {steps} | {frac} | {_ms(r['light_ms'])} | "
                         f"{r['frame_ms']:.3f} | {shown(r, data)} | {_ms(r['total_ms'])} |")
        lines.append("")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
