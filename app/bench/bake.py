"""The benchmark's bake mode: what a probe bake costs and where its GPU time goes, against what the
GPU can do.

For each scene and probe setting (grid N^3 fitted to the visible region, walks per probe):
  bake_ms          the whole bake's GPU time (median of `bake_repeats` bakes, one timed span each)
  bake_walk_ms, bake_project_ms, bake_sun_ms
                   GPU time of the walks, the SH projection and the probes' sun transmittance,
                   from timestamps between the dispatches of one more bake (GpuProfile)
  bake_other_ms    the rest of that profiled bake: gaps between dispatches, barriers
  light_ms         the raymarcher's sun-transmittance grid (charged to its images as well)
  walks_per_s      walks asked for (probes x walks per probe) / bake_ms; counted_walks: the walks
                   that ran (fewer with adaptive walks)
  steps_per_walk   tracking iterations per walk (free flight + shadow rays), and each kind apart,
                   scattering events and macrocell crossings, from the shaders' profiling build
  ceiling_steps_per_s
                   this GPU's rate for a trilinear march through the same medium (ceiling.py)
  ceiling_fraction the walks' tracking iterations per second over that ceiling
and the raymarcher's image over the probes: frame time and rRMSE against the reference, with
total_ms = bake + light + render (everything the image cost).

Written to run on earlier code too (the before/after records): what an older Renderer lacks
(the profile, the counters) is recorded as null.
"""
from __future__ import annotations

import inspect
import statistics
from dataclasses import replace

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.bench.records import log as _log, make_record, progressive as _progressive
from radiance_probes.rendering.budgets.ceiling import measure_ceiling


def _profiling_supported(renderer) -> bool:
    return "profile" in inspect.signature(renderer.bake).parameters


def _rebake(renderer, seed: int, **kw) -> float:
    renderer.forget_probes()   # forces a bake of the same setting again
    return renderer.bake(seed=seed, **kw)


def _profile(renderer, seed: int) -> dict:
    """Section times of one bake and the profiling build's counters of another."""
    from radiance_probes.gl.profiler import GpuProfile
    profile = GpuProfile()
    dispatches = renderer.probe_grid.dispatches
    try:
        total = _rebake(renderer, seed, profile=profile)
        ms = profile.totals_ms()
    finally:
        profile.release()
    grid = renderer.probe_grid
    dispatches = grid.dispatches - dispatches
    buffer = grid.walk_counters()
    try:
        _rebake(renderer, seed, counters=buffer)
        counts = grid.read_walk_counters(buffer)
    finally:
        buffer.release()
    walk, project, sun = ms.get("walks", 0.0), ms.get("project", 0.0), ms.get("sun", 0.0)
    walks = max(counts["walks"], 1)
    return {"bake_profiled_ms": total, "bake_walk_ms": walk, "bake_project_ms": project,
            "bake_sun_ms": sun, "bake_other_ms": max(total - walk - project - sun, 0.0),
            "bake_dispatches": dispatches, "counted_walks": counts["walks"],
            "steps_per_walk": (counts["flight_steps"] + counts["shadow_steps"]) / walks,
            "flight_steps_per_walk": counts["flight_steps"] / walks,
            "shadow_steps_per_walk": counts["shadow_steps"] / walks,
            "cell_steps_per_walk": counts["cell_steps"] / walks,
            "events_per_walk": counts["events"] / walks,
            "dispatches_per_walk": counts["dispatch_walks"] / walks,
            "longest_walk_events": counts["longest_walk_events"],
            "longest_walk_steps": counts["longest_walk_steps"]}


def bake_scene(renderer, name: str, config, results, out, device: str,
               reference: np.ndarray, label: str = "current") -> None:
    scene = renderer.scene
    base = {"scene": name, "device": device, "width": config.width, "height": config.height,
            "reference_noise": results.references.get(name, {}).get("noise_rrmse"),
            "mode": "bake", "code": label}
    ceiling = measure_ceiling(renderer, rays=config.ceiling_rays)
    _log(f"  ceiling: trilinear march {ceiling['steps_per_s'] / 1e9:.2f} G steps/s "
         f"({ceiling['ms']:.2f} ms for {ceiling['steps'] / 1e6:.0f} M steps)")
    profiled = _profiling_supported(renderer)
    defaults = renderer.settings
    variants = config.bake_variants
    for (grid, samples), (walk_sun, light_side, adaptive) in ((s, v) for s in config.bake_settings
                                                              for v in variants):
        renderer.configure(walk_sun=walk_sun, light_max_side=light_side, walk_adaptive=adaptive)
        probes = replace(scene.probes, grid=(grid, grid, grid), samples=samples)
        renderer.set_scene(scene.replace(probes=probes))
        _rebake(renderer, 7)    # warm-up (shader compilation, clocks), not timed
        times = [_rebake(renderer, 11) for _ in range(config.bake_repeats)]
        bake_ms = statistics.median(times)
        g = renderer.probe_grid
        walks = g.count * g.samples
        info = {"probe_grid": grid, "probe_samples": samples, "probe_grid_xyz": list(g.grid),
                "probe_bytes": g.gpu_bytes, "bake_repeats_ms": times, "walks": walks,
                "walks_per_s": walks / (bake_ms / 1e3) if bake_ms > 0 else None,
                "ceiling_steps_per_s": ceiling["steps_per_s"], "walk_sun": walk_sun,
                "walk_adaptive": adaptive, "settings": renderer.settings.as_dict()}
        if profiled:
            info.update(_profile(renderer, 11))
            if info["bake_walk_ms"] > 0:
                rate = info["steps_per_walk"] * walks / (info["bake_walk_ms"] / 1e3)
                info["walk_steps_per_s"] = rate
                info["ceiling_fraction"] = rate / ceiling["steps_per_s"]
        else:
            info.update({k: None for k in ("bake_walk_ms", "bake_project_ms", "bake_sun_ms",
                                           "bake_other_ms", "steps_per_walk", "ceiling_fraction")})
        _rebake(renderer, 11)   # the probes the image uses: the plain build's, seed 11
        renderer.forget_light_grid()   # its real time (an attribute gone long ago made it 0)
        light_ms = renderer.bake_light()
        k = config.samples_per_dispatch
        for frames, image, *timing in _progressive(renderer, "raymarch", config.raymarch_frames,
                                                   17, k):
            rec = make_record(base, config, "raymarch", frames, image, reference, timing,
                              bake_ms + light_ms, light_ms=light_ms, probe_bake_ms=bake_ms,
                              light_bytes=renderer.light_grid.gpu_bytes,
                              light_grid=list(renderer.light_grid.texture.size), **info)
            results.add(rec, image, reference)
        tag = f"{label}_{walk_sun}{light_side}_a{adaptive:g}_{grid}x{samples}"
        save_png(out / "images" / f"{name}_bake_{tag}.png", image)
        prof = (f"walks {info['bake_walk_ms']:.1f}, project {info['bake_project_ms']:.1f}, sun "
                f"{info['bake_sun_ms']:.1f}, other {info['bake_other_ms']:.1f} ms; "
                f"{info['steps_per_walk']:.1f} steps/walk, {100 * info.get('ceiling_fraction', 0):.1f}% "
                f"of the ceiling" if profiled else "no profile (older code)")
        _log(f"  {grid}^3 x {samples} ({'x'.join(map(str, g.grid))}) sun {walk_sun} light "
             f"{light_side} adaptive {adaptive}: bake {bake_ms:.1f} ms "
             f"(runs {', '.join(f'{t:.1f}' for t in times)}), {info['walks_per_s'] / 1e6:.0f} M "
             f"walks/s; {prof}; raymarch rRMSE {rec['rrmse']:.4f}")
    renderer.settings = defaults
    renderer.set_scene(scene)
