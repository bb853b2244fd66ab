"""Where the bake's time went between the previous stop's run (bench/archive/h100-v11) and this
code's (bench/h100): the walks bake 3.4 to 3.7x slower at every large setting, and even an 8^3 x 16
bake costs 1.2 ms more. Each of the issue-30 changes that touch the walks is switched off alone
(RenderSettings), and the bake is timed per section on the GPU (GpuProfile: the sun, the walks, the
projection and publishing), with its dispatch count.

    python lab/experiments/experiment_bake_cost_split.py OUT_DIR [--quick]

Variants: the defaults; walk_sun_correction 0 (the light grid's sun alone, biased); walk_adaptive
0 (every probe takes all its walks); both; walk_sun "ray" (a shadow ray at every event). Each
bake is timed REPEATS times (the median kept), the probes forced stale between repeats.
Writes OUT_DIR/results.json and OUT_DIR/report.md.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.bench.scenes import bench_scene  # noqa: E402
from radiance_probes.gl.profiler import GpuProfile  # noqa: E402
from radiance_probes.gl.context import is_software  # noqa: E402
from radiance_probes.rendering.budgets.dispatch_budget import DISPATCH_TARGET_MS  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402

VARIANTS = {
    "defaults": {},
    "no sun correction": {"walk_sun_correction": 0.0},
    "no adaptive walks": {"walk_adaptive": 0.0},
    "neither": {"walk_sun_correction": 0.0, "walk_adaptive": 0.0},
    "sun by ray": {"walk_sun": "ray"},
    # the bake's walk chunks cut at another target (app/rendering/budgets/dispatch_budget.py; inf: one
    # dispatch a pass, as before the bounded dispatches)
    "chunks of 50 ms": {"_target": 50.0},
    "uncut": {"_target": float("inf")},
    "uncut, neither": {"_target": float("inf"), "walk_sun_correction": 0.0, "walk_adaptive": 0.0},
}
REPEATS = 3


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("out", type=Path)
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    scenes = ("thick",) if args.quick else ("bonsai", "fuel", "thick", "anisotropic")
    settings = ((4, 16),) if args.quick else ((8, 16), (64, 128), (128, 64))
    size = 32 if args.quick else 512
    from radiance_probes.gl.context import create_headless_context, describe
    ctx = create_headless_context()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in scenes:
        scene = bench_scene(name, size, size)
        if scene is None:
            continue
        r = Renderer(ctx, scene)
        try:
            for grid, walks in settings:
                r.set_scene(scene.replace(probes=replace(scene.probes, grid=(grid,) * 3,
                                                         samples=walks)))
                for label, change in VARIANTS.items():
                    change = dict(change)
                    import radiance_probes.rendering.renderer as renderer_module
                    target = change.pop("_target", DISPATCH_TARGET_MS)
                    renderer_module.dispatch_target_ms = (
                        lambda _r, t=target: t if not is_software(_r.ctx) else float("inf"))
                    r.settings = replace(type(r.settings)(), **change)
                    r.bake_light()
                    times, sections, dispatches = [], [], 0
                    for k in range(REPEATS):
                        r._baked_key = None   # stale: bake again
                        profile = GpuProfile()
                        ms = r.bake(seed=11 + k, profile=profile)
                        times.append(ms)
                        sections.append(profile.totals_ms() if profile.available else {})
                        dispatches = r.probe_grid.dispatches
                        profile.release()
                    best = statistics.median(times)
                    i = times.index(sorted(times)[len(times) // 2])
                    row = {"scene": name, "grid": grid, "walks": walks, "variant": label,
                           "bake_ms": best, "sections_ms": sections[i], "dispatches": dispatches,
                           "passes": r.probe_grid.passes_total}
                    rows.append(row)
                    print(json.dumps(row), flush=True)
        finally:
            r.release()
    (args.out / "results.json").write_text(json.dumps({"device": describe(ctx), "rows": rows},
                                                      indent=1))
    lines = [f"# The bake's cost split ({describe(ctx)})", "",
             "| scene | probes | variant | bake ms | sun | walks | project | dispatches |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        s = row["sections_ms"]
        lines.append(f"| {row['scene']} | {row['grid']}^3 x {row['walks']} | {row['variant']} | "
                     f"{row['bake_ms']:.3g} | {s.get('sun', 0):.3g} | {s.get('walks', 0):.3g} | "
                     f"{s.get('project', 0):.3g} | {row['dispatches']} |")
    (args.out / "report.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
