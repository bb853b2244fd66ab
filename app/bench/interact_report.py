"""The interact mode's report (app/bench/interact.py): per event, the first frame's GPU time, frame
p50/p99 and the GPU time to each error target since the event; warm against cold bakes; the
per-dispatch tail; and a plot of error against time since each event."""
from __future__ import annotations

import math
from pathlib import Path

from radiance_probes.bench.records import caveat, speed_checks


def _ms(v) -> str:
    if v is None:
        return "not reached"
    return f"{v:.3g} ms" if v < 1000 else f"{v / 1000:.3g} s"


def _probes(r: dict) -> str:
    return f"{r.get('probe_grid')}^3x{r.get('probe_samples')}"


def plot_interact(data: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    recs = [r for r in data["records"] if r.get("mode") == "interact" and r.get("curve")]
    groups = list(dict.fromkeys((r["scene"], r["width"], r["height"], _probes(r)) for r in recs))
    events = list(dict.fromkeys(r["event"] for r in recs))
    if not groups:
        return
    fig, axes = plt.subplots(len(groups), len(events), squeeze=False,
                             figsize=(3.0 * len(events), 2.8 * len(groups)))
    for gi, (scene, w, h, probes) in enumerate(groups):
        for ei, event in enumerate(events):
            ax = axes[gi][ei]
            for r in recs:
                if (r["scene"], r["width"], r["height"], _probes(r), r["event"]) != (
                        scene, w, h, probes, event):
                    continue
                xs = [max(t, 1e-3) for t, _ in r["curve"]]
                ys = [max(e, 1e-4) for _, e in r["curve"]]
                ax.plot(xs, ys, marker=".", lw=1, label=f"{r['method']} {r['variant'] or ''}")
            for target in (0.10, 0.05, 0.03):
                ax.axhline(target, color="grey", lw=0.5, ls=":")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_title(f"{scene} {w}x{h} {probes}: {event}", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(True, which="both", alpha=0.2)
            if gi == len(groups) - 1:
                ax.set_xlabel("GPU ms since the event", fontsize=7)
            if ei == 0:
                ax.set_ylabel("rRMSE", fontsize=7)
            ax.legend(fontsize=5)
    fig.suptitle(f"Error against time since each event: {data['meta']['device']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def interact_section(data: dict, out: Path) -> list[str]:
    recs = [r for r in data["records"] if r.get("mode") == "interact"]
    if not recs:
        return []
    plot_interact(data, out / "interact.png")
    cfg = data["meta"]["config"]
    budget = cfg.get("interact_frame_budget_ms")
    lines = ["## Interaction (`--preset interact`)", "",
             "A scripted session replayed through the viewer's own loop (RenderSession, no window): "
             f"load, orbit ({cfg.get('interact_orbit_frames')} frames), drag an opacity point, the "
             "sun 30 degrees, density scale, albedo, then the raymarcher. A frame has "
             f"{budget} ms of GPU time: the bake's slice ({cfg.get('interact_bake_budget_ms')} ms: "
             "light-grid layers, then probes' walks) and as many samples as the rest holds "
             "(at least one); after a bake slice the picture restarts from the probes as they are, "
             "and `probes` shows the raymarcher until its bake is done. Times are GPU timestamps "
             "since the event (the orbit: since its last move) and, in brackets, wall-clock time of "
             "whole frames (the edit's CPU work included: what a person feels); errors are rRMSE "
             "corrected for the noise of a path-traced reference of the state after the event "
             f"({cfg.get('interact_ref_spp')} spp{_by_scene(cfg)}). Warm: the bake starts from "
             "the previous probes; cold: from nothing (both end at the same probes).", "",
             "![error against time since each event](interact.png)", "",
             "| scene | size | probes | event | method | bake | first frame | p50 | p99 | to 10% "
             "| to 5% | to 3% | to 2% | final rRMSE | frames |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- "
             "| --- |"]

    def both(r, key, wall_key):
        wall = r.get(wall_key, "absent")
        return _ms(r[key]) if wall == "absent" else f"{_ms(r[key])} ({_ms(wall)})"

    for r in recs:
        if r["event"] in ("dispatch_tail", "flicker"):
            continue
        lines.append(
            f"| {r['scene']} | {r['width']}x{r['height']} | {_probes(r)} | {r['event']} | "
            f"{r['method']} | {r['variant'] or '-'} | "
            f"{both(r, 'first_frame_ms', 'first_frame_wall_ms')} | "
            f"{both(r, 'frame_ms_p50', 'frame_wall_ms_p50')} | "
            f"{both(r, 'frame_ms_p99', 'frame_wall_ms_p99')} | "
            f"{both(r, 'ms_to_10pct', 'wall_ms_to_10pct')} | "
            f"{both(r, 'ms_to_5pct', 'wall_ms_to_5pct')} | "
            f"{both(r, 'ms_to_3pct', 'wall_ms_to_3pct')} | "
            f"{both(r, 'ms_to_2pct', 'wall_ms_to_2pct') if 'ms_to_2pct' in r else '-'} | "
            f"{r['final_rrmse']:.4f} | {r['frames']}"
            f"{'' if r['converged'] else ' (not converged)'} |")
    lines += goal_section(recs)
    lines += flicker_section(recs)
    lines += longest_frames_section(recs)
    tails = [r for r in recs if r["event"] == "dispatch_tail"]
    if tails:
        lines += ["", "### The per-dispatch tail", "",
                  "GPU ms per sample per pixel at one sample per dispatch against k per dispatch "
                  "(the final state; medians):", "",
                  "| scene | size | probes | method | 1 per dispatch | k per dispatch | k | saved |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in tails:
            one, many = r["ms_per_sample_1"], r["ms_per_sample_k"]
            saved = f"{100 * (1 - many / one):.0f}%" if one > 0 else "-"
            lines.append(f"| {r['scene']} | {r['width']}x{r['height']} | {_probes(r)} | {r['method']} | "
                         f"{one:.3f} ms | {many:.3f} ms | {r['k']} | {saved} |")
    lines.append("")
    return lines


def _by_scene(cfg: dict) -> str:
    by = cfg.get("interact_ref_spp_by_scene") or []
    return "".join(f"; {scene}: {spp}" for scene, spp in by)


def flicker_section(recs: list[dict]) -> list[str]:
    """interact.flicker_record's: refine's frame-to-frame change on a still camera once within 2%
    against the raw path tracer's from the same wall time (issue 56's target: at most a quarter)."""
    runs = [r for r in recs if r["event"] == "flicker"]
    if not runs:
        return []
    lines = ["", "### Flicker on a still camera", "",
             "From a restart of the replay's last state (the last edit's; or the loaded scene "
             "where the flicker runs alone), frames until the view's error first reaches 2% with "
             "guided shown (or it stops), then the next frames: each shown image "
             "against the one before, the RMS of the change over the reference's RMS, averaged "
             "over the frames. The raw path tracer (the Denoise switch off) is measured the same "
             "way over the same number of frames from the same wall time since its restart.", "",
             "| scene | method | from (wall) | its error | frames (changed) | change a frame "
             "(largest) | raw pt: change a frame | ratio |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in runs:
        f, p = r["flicker"], r["flicker_pt"]
        ratio = r.get("flicker_ratio")
        lines.append(f"| {r['scene']} | {r['method']} | {_ms(f['from_wall_ms'])} | "
                     f"{100 * f['error']:.2f}% | {f['frames']} ({f['frames_changed']}) | "
                     f"{100 * f['change_mean']:.3f}% ({100 * f['change_max']:.3f}%) | "
                     f"{100 * p['change_mean']:.3f}% | "
                     f"{'-' if ratio is None else f'{ratio:.2f}'} |")
    return lines


def longest_frames_section(recs: list[dict]) -> list[str]:
    """Per event: its longest frame on the wall clock and the parts that took it (frame_parts:
    [GPU ms or None, wall ms] by part; the largest four by wall), the filter's ms on its thread
    that frame (off the frame), the largest wall-time gap between two points of the error
    curve, and what measuring the error cost (outside the frames' time). Records made before
    the frames had parts (issue 56) have none of this and are left out."""
    runs = [r for r in recs if r.get("frame_parts") and r.get("frame_walls")]
    if not runs:
        return []
    lines = ["", "### The longest frame of each event, by part", "",
             "Each event's longest frame on the wall clock and its four largest parts, GPU ms / "
             "wall ms (app/viewer/frame/frame_parts.py: bake, samples, guide, readback, combine, "
             "judgement, upload, blend; no window here, so no display, imgui or swap); the "
             "filter's ms on its own thread for the results that landed in that frame (off the "
             "frame); the error curve's largest gap on the wall clock; the error's measurements "
             "(outside the frames' time, the filter's thread held meanwhile).", "",
             "| scene | event | variant | longest frame (wall) | its parts | filter (thread) "
             "| curve gap | measured |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]

    def pair(gpu, wall) -> str:
        return f"{'-' if gpu is None else f'{gpu:.1f}'} / {wall:.1f}"

    for r in runs:
        walls = r["frame_walls"]
        i = max(range(len(walls)), key=walls.__getitem__)
        parts = sorted(r["frame_parts"][i].items(), key=lambda kv: -kv[1][1])[:4]
        named = ", ".join(f"{k} {pair(g, w)}" for k, (g, w) in parts) or "-"
        filt = (r.get("frame_filter_ms") or [0.0] * len(walls))[i]
        lines.append(f"| {r['scene']} | {r['event']} | {r['variant'] or '-'} | "
                     f"{walls[i]:.1f} ms | {named} | {filt:.1f} ms | "
                     f"{r.get('curve_wall_gap_ms_max', 0.0):.0f} ms | "
                     f"{r.get('measure_points', 0)} points, {r.get('measure_wall_ms', 0.0):.0f} ms "
                     f"(at most {r.get('measure_wall_ms_max', 0.0):.0f}) |")
    return lines


def goal_section(recs: list[dict]) -> list[str]:
    """Per scene, size, probes and method: whether every event (load, orbit, each edit warm and
    cold) reached the goal's error (interact.REFINE_GOAL: 2%) within its time (1 s) since the
    event, by GPU time and by wall-clock time, and the worst event."""
    from radiance_probes.bench.interact import REFINE_GOAL
    target, limit = REFINE_GOAL
    pct = round(target * 100)
    key, wall_key = f"ms_to_{pct}pct", f"wall_ms_to_{pct}pct"
    runs = [r for r in recs if r["event"] not in ("dispatch_tail", "raymarch_switch")
            and key in r]
    groups = list(dict.fromkeys((r["scene"], r["width"], r["height"], _probes(r), r["method"])
                                for r in runs))
    if not groups:
        return []
    lines = ["", f"### Within {pct}% within {limit / 1000:g} s of every event", "",
             f"Per method, the worst event's time to {pct}% (GPU time; wall-clock in brackets) "
             "and whether every event got there in time (an event that never did counts as "
             "late).", "",
             "| scene | size | probes | method | events | worst event | its time | all in time "
             "(GPU) | all in time (wall) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]

    def late(value) -> float:
        return math.inf if value is None else value

    for scene, w, h, probes, method in groups:
        group = [r for r in runs if (r["scene"], r["width"], r["height"], _probes(r),
                                     r["method"]) == (scene, w, h, probes, method)]
        worst = max(group, key=lambda r: (late(r[key]), late(r.get(wall_key))))
        gpu_ok = all(late(r[key]) <= limit for r in group)
        wall_ok = all(late(r.get(wall_key)) <= limit for r in group)
        name = f"{worst['event']} {worst['variant'] or ''}".strip()
        lines.append(f"| {scene} | {w}x{h} | {probes} | {method} | {len(group)} | {name} | "
                     f"{_ms(worst[key])} ({_ms(worst.get(wall_key))}) | "
                     f"{'yes' if gpu_ok else 'no'} | {'yes' if wall_ok else 'no'} |")
    return lines


def write_interact_report(data: dict, out: Path) -> Path:
    meta = data["meta"]
    lines = ["# Interaction", "", f"Device: **{meta['device']}**. Started {meta.get('started')}, "
             f"finished {meta.get('finished', 'not finished (partial run)')}.", "",
             f"Command: `{meta.get('command', '')}`", "", *caveat(meta), *interact_section(data, out)]
    scenes = list(dict.fromkeys(r["scene"] for r in data["records"]))
    lines += speed_checks(data, scenes, "after each event's frames")
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
