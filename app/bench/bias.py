"""The bias table (`bench --preset bias`): every shortcut the bake and the renderers take by
default, measured against its exact (or finest) variant on every scene of the stress battery.

For each scene: a path-traced reference (two independent halves, whose difference measures its
own noise); then, for the defaults and for each variant (the defaults with one shortcut taken
away, or a non-default shortcut switched on), `bias_seeds` independent bakes at the bench's probe
settings, each raymarched to `bias_frames` frames (and rendered with `probes`). Per seed: the
image's mean over linear RGB, its rRMSE against the reference and its rRMSE over 16-pixel blocks
(what the held-out check reports). The same seeds serve every variant, so the differences are
paired: a variant's row reports, with standard errors over the seeds,
  - mean ratio: mean(image with the default shortcut) / mean(image with the variant) - 1, the
    shortcut's bias on the image's mean (for a non-default shortcut, the other way round: its
    image against the default one);
  - rRMSE change: the default's rRMSE minus the variant's (positive: the shortcut costs error).
The defaults' own rows give each scene's error and image mean against the path tracer.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from radiance_probes.rendering.metrics import block_rrmse, rrmse
from radiance_probes.bench.records import log as _log


@dataclass(frozen=True)
class Variant:
    name: str            # row label
    shortcut: str        # what the row measures
    settings: dict       # RenderSettings changes
    probes: dict         # the scene's probes changes
    default_on: bool     # True: the variant takes a default shortcut away (the default is the
                         # shortcut); False: it switches a non-default shortcut on
    exact: bool = True   # the variant is the exact (or finer) version of the same estimate; False:
                         # another approximation (SH order, lobe, probe box), judged against the
                         # path tracer rather than against each other


VARIANTS = (
    Variant("adaptive walks off", "adaptive walks (walk_adaptive 1)", {"walk_adaptive": 0.0}, {},
            True),
    Variant("walks' sun by shadow rays", "the walks' sun from the light grid",
            {"walk_sun": "ray"}, {}, True),
    Variant("light grid 512 texels", "the light grid's resolution",
            {"light_min_side": 512, "light_max_side": 512}, {}, True),
    Variant("light grid float32", "the light grid's 16-bit texels", {"light_precision": "f4"},
            {}, True),
    Variant("no sun lobe", "the sun lobe (order-3 probes, g > 0)", {"sun_lobe": False}, {}, True,
            False),
    Variant("SH order 2", "SH order auto (against order 2)", {}, {"sh_order": 2}, True, False),
    Variant("SH order 3", "SH order auto (against order 3)", {}, {"sh_order": 3}, True, False),
    Variant("no empty-space skipping", "empty-space skipping", {"empty_space_skipping": False},
            {}, True),
    Variant("probes over the whole box", "the fitted visible region", {}, {"fit": "box"}, True,
            False),
    Variant("walks' sun from the grid alone", "the walks' sun correction off (not the default)",
            {"walk_sun_correction": 0.0}, {}, False),
    Variant("16-bit probes", "16-bit probes (rgba16f; not the default)", {},
            {"precision": "rgba16f"}, False),
)


def _paired(a: list[float], b: list[float]) -> tuple[float, float]:
    """Mean of a - b over paired seeds and its standard error."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    se = float(d.std(ddof=1) / math.sqrt(len(d))) if len(d) > 1 else float("nan")
    return float(d.mean()), se


def _ratio(a: list[float], b: list[float]) -> tuple[float, float]:
    """mean(a) / mean(b) - 1 over paired seeds, with the standard error of the per-seed ratios."""
    r = np.asarray(a, np.float64) / np.maximum(np.asarray(b, np.float64), 1e-30) - 1.0
    se = float(r.std(ddof=1) / math.sqrt(len(r))) if len(r) > 1 else float("nan")
    return float(np.mean(a) / max(np.mean(b), 1e-30) - 1.0), se


def _measure(renderer, config, reference, name: str, variant: str, seeds, out) -> dict:
    """Per seed, the raymarched and `probes` images' mean, rRMSE and block rRMSE."""
    from radiance_probes.frontend.imageio import save_png
    from radiance_probes.gl.dispatch_log import active_log
    rows = {"raymarch": [], "probes": []}
    bake_ms = []
    log = active_log()
    for seed in seeds:
        renderer.invalidate()
        result = renderer.render("raymarch", spp=config.bias_frames, seed=seed,
                                 samples_per_pass=config.bias_frames)
        bake_ms.append(result.bake_ms)
        images = {"raymarch": result.image,
                  "probes": renderer.render("probes", spp=config.bias_probe_spp, seed=seed,
                                            samples_per_pass=config.samples_per_dispatch).image}
        for method, image in images.items():
            rows[method].append({"mean": float(np.mean(image, dtype=np.float64)),
                                 "rrmse": rrmse(image, reference),
                                 "block_rrmse": block_rrmse(image, reference, 16)})
        if seed == seeds[0]:
            save_png(out / "images" / f"{name}_{variant.replace(' ', '_')}.png", result.image)
    longest = log.take() if log is not None else (None, None)
    return {"rows": rows, "bake_ms": float(np.median(bake_ms)), "longest_dispatch": longest}


def bias_scene(renderer, name: str, config, results, out, device: str,
               reference: np.ndarray, reference_noise: float) -> None:
    scene = renderer.scene
    defaults = renderer.settings
    seeds = list(range(11, 11 + config.bias_seeds))
    ref_mean = float(np.mean(reference, dtype=np.float64))
    for grid, samples in config.bias_settings:
        base_probes = replace(scene.probes, grid=(grid, grid, grid), samples=samples)
        renderer.set_scene(scene.replace(probes=base_probes))
        measured = {"defaults": _measure(renderer, config, reference, name, f"{grid}_defaults",
                                         seeds, out)}
        plan = renderer.probe_plan()
        for v in VARIANTS:
            if v.name == "no sun lobe" and not renderer.probe_grid.sun_lobe:
                continue   # no lobe in this scene's probes: nothing to take away
            renderer.settings = replace(defaults, **v.settings)
            renderer.set_scene(scene.replace(probes=replace(base_probes, **v.probes)))
            measured[v.name] = _measure(renderer, config, reference, name,
                                        f"{grid}_{v.name}", seeds, out)
            renderer.settings = defaults
        renderer.set_scene(scene.replace(probes=base_probes))
        base = measured["defaults"]
        for method in ("raymarch", "probes"):
            d = base["rows"][method]
            results.records.append({
                "scene": name, "device": device, "mode": "bias", "variant": "defaults",
                "method": method, "probe_grid": grid, "probe_samples": samples,
                "sh_order": plan.sh_order, "bake_ms": base["bake_ms"],
                "reference_noise": reference_noise,
                "mean_ratio_to_reference": float(np.mean([r["mean"] for r in d])) / ref_mean - 1,
                "rrmse": float(np.mean([r["rrmse"] for r in d])),
                "block_rrmse": float(np.mean([r["block_rrmse"] for r in d])),
                "seeds": len(seeds), "per_seed": d,
                "longest_dispatch_ms": base["longest_dispatch"][0],
                "longest_dispatch": base["longest_dispatch"][1]})
            for v in VARIANTS:
                if v.name not in measured:
                    continue
                other = measured[v.name]["rows"][method]
                shortcut, exact = (d, other) if v.default_on else (other, d)
                ratio, ratio_se = _ratio([r["mean"] for r in shortcut], [r["mean"] for r in exact])
                change, change_se = _paired([r["rrmse"] for r in shortcut],
                                            [r["rrmse"] for r in exact])
                block, block_se = _paired([r["block_rrmse"] for r in shortcut],
                                          [r["block_rrmse"] for r in exact])
                results.records.append({
                    "scene": name, "device": device, "mode": "bias", "variant": v.name,
                    "shortcut": v.shortcut, "default_on": v.default_on, "exact": v.exact,
                    "method": method,
                    "shortcut_mean_vs_reference":
                        float(np.mean([r["mean"] for r in shortcut])) / ref_mean - 1,
                    "exact_mean_vs_reference":
                        float(np.mean([r["mean"] for r in exact])) / ref_mean - 1,
                    "probe_grid": grid, "probe_samples": samples,
                    "bake_ms": measured[v.name]["bake_ms"],
                    "mean_bias": ratio, "mean_bias_se": ratio_se,
                    "rrmse_change": change, "rrmse_change_se": change_se,
                    "block_rrmse_change": block, "block_rrmse_change_se": block_se,
                    "rrmse": float(np.mean([r["rrmse"] for r in other])),
                    "seeds": len(seeds), "per_seed": other,
                    "longest_dispatch_ms": measured[v.name]["longest_dispatch"][0],
                    "longest_dispatch": measured[v.name]["longest_dispatch"][1]})
            rm = results.records[-1 - sum(1 for v in VARIANTS if v.name in measured)]
            _log(f"  {name} {grid}^3 x {samples} {method}: rRMSE {rm['rrmse']:.4f}, blocks "
                 f"{rm['block_rrmse']:.4f}, mean vs reference {100 * rm['mean_ratio_to_reference']:+.2f}%")
        results.flush()


# The bound each default shortcut states for its bias on an image's mean, and for the rRMSE it
# may add (absolute, as a fraction of the reference's RMS), over every battery scene: the issue's
# targets (mean bias at most 0.3%), tested against this table by tests/test_bench.py's report test
# and stated in docs/bias.md.
MEAN_BIAS_BOUND = 0.003


def bias_report_lines(data: dict) -> list[str]:
    """The report's bias table: per default shortcut and method, its worst mean bias and rRMSE
    change over the battery, then per scene."""
    recs = [r for r in data["records"] if r.get("mode") == "bias"]
    if not recs:
        return []
    lines = ["## Bias of each shortcut", "",
             "Each row: the defaults against the defaults with one shortcut taken away (or, for a "
             "shortcut that is not a default, switched on), over the same seeds (paired). Mean bias: "
             "image mean with the shortcut / without - 1. rRMSE change: with minus without "
             "(positive: the shortcut adds error). Standard errors over the seeds in brackets; "
             f"**bold**: a mean bias beyond {100 * MEAN_BIAS_BOUND:.1f}% and 3 standard errors.", ""]
    for method in ("raymarch", "probes"):
        rows = [r for r in recs if r["method"] == method and r["variant"] != "defaults"]
        if not rows:
            continue
        lines += [f"### {method}: worst case over the battery", "",
                  "Against its exact (or finer) variant:", "",
                  "| shortcut | default | worst mean bias (scene) | worst rRMSE change (scene) |",
                  "| --- | --- | --- | --- |"]
        for shortcut in dict.fromkeys(r["shortcut"] for r in rows if r.get("exact", True)):
            group = [r for r in rows if r["shortcut"] == shortcut]
            worst = max(group, key=lambda r: abs(r["mean_bias"]))
            worst_change = max(group, key=lambda r: r["rrmse_change"])
            flag = (abs(worst["mean_bias"]) > MEAN_BIAS_BOUND
                    and abs(worst["mean_bias"]) > 3 * (worst["mean_bias_se"] or 0))
            bias = f"{100 * worst['mean_bias']:+.2f}% ({100 * worst['mean_bias_se']:.2f})"
            lines.append(f"| {shortcut} | {'yes' if worst['default_on'] else 'no'} | "
                         f"{'**' + bias + '**' if flag else bias} ({worst['scene']}, "
                         f"{worst['probe_grid']}^3) | "
                         f"{100 * worst_change['rrmse_change']:+.2f} points "
                         f"({100 * worst_change['rrmse_change_se']:.2f}) "
                         f"({worst_change['scene']}, {worst_change['probe_grid']}^3) |")
        approximations = [r for r in rows if not r.get("exact", True)]
        if approximations:
            lines += ["", "Approximations against another approximation: each one's image mean "
                      "against the path tracer (worst over the battery) and the rRMSE the default "
                      "saves (negative) or costs (positive) over the alternative:", "",
                      "| default | alternative | worst mean vs reference, default (scene) | "
                      "worst mean vs reference, alternative (scene) | rRMSE change: best / worst |",
                      "| --- | --- | --- | --- | --- |"]
            for variant in dict.fromkeys(r["variant"] for r in approximations):
                group = [r for r in approximations if r["variant"] == variant]
                d = max(group, key=lambda r: abs(r["shortcut_mean_vs_reference"]))
                a = max(group, key=lambda r: abs(r["exact_mean_vs_reference"]))
                lo = min(group, key=lambda r: r["rrmse_change"])
                hi = max(group, key=lambda r: r["rrmse_change"])
                lines.append(f"| {group[0]['shortcut']} | {variant} | "
                             f"{100 * d['shortcut_mean_vs_reference']:+.2f}% ({d['scene']}) | "
                             f"{100 * a['exact_mean_vs_reference']:+.2f}% ({a['scene']}) | "
                             f"{100 * lo['rrmse_change']:+.2f} ({lo['scene']}) / "
                             f"{100 * hi['rrmse_change']:+.2f} ({hi['scene']}) |")
        lines.append("")
    lines += ["### The defaults against the path tracer", "",
              "| scene | probes | method | rRMSE | 16 px blocks | image mean vs reference | "
              "bake ms |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in recs:
        if r["variant"] == "defaults":
            lines.append(f"| {r['scene']} | {r['probe_grid']}^3 x {r['probe_samples']} | "
                         f"{r['method']} | {100 * r['rrmse']:.2f}% | {100 * r['block_rrmse']:.2f}% | "
                         f"{100 * r['mean_ratio_to_reference']:+.2f}% | {r['bake_ms']:.1f} |")
    lines += ["", "### Every row", "",
              "| scene | probes | method | variant | mean bias | rRMSE change | block rRMSE change |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in recs:
        if r["variant"] != "defaults":
            lines.append(f"| {r['scene']} | {r['probe_grid']}^3 | {r['method']} | {r['variant']} | "
                         f"{100 * r['mean_bias']:+.2f}% ({100 * r['mean_bias_se']:.2f}) | "
                         f"{100 * r['rrmse_change']:+.2f} ({100 * r['rrmse_change_se']:.2f}) | "
                         f"{100 * r['block_rrmse_change']:+.2f} "
                         f"({100 * r['block_rrmse_change_se']:.2f}) |")
    return lines + [""]


def write_bias_report(data: dict, out) -> "Path":
    from radiance_probes.bench.records import caveat
    meta = data["meta"]
    lines = ["# Bias of the default shortcuts on the stress battery", "",
             f"Device: **{meta['device']}**. Started {meta.get('started')}, finished "
             f"{meta.get('finished', 'not finished (partial run)')}.", "", *caveat(meta),
             f"Command: `{meta.get('command', '')}`", "",
             f"Image {meta['config']['width']}x{meta['config']['height']}; references of "
             f"{meta['config']['ref_spp']} spp; {meta['config']['bias_seeds']} seeds per variant; "
             f"raymarch {meta['config']['bias_frames']} frames, probes "
             f"{meta['config']['bias_probe_spp']} spp. Longest dispatch of the run: "
             f"{meta.get('longest_dispatch_ms', float('nan')):.1f} ms "
             f"({meta.get('longest_dispatch')}).", "",
             *bias_report_lines(data)]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
