"""The benchmark's "cost that follows the scene" mode: each saving measured against a baseline
that models the whole box at full generality, at equal nominal settings, with its error beside it.

Variants of the probe layout (app/rendering/probes/layout.py) and precision:
  baseline      grid over the whole box, SH order 2, RGBA32F
  fit visible   grid over the visible region only, aspect following it
  sh order auto order 0 when g = 0
  channels auto one channel when the scene is grey
  rgba16f       half-precision probe textures
  all           all of them together (the defaults, plus 16F)
and, where the renderer has it, empty-space skipping on and off for the path tracer and the bake.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.methods import METHODS
from radiance_probes.bench.records import log as _log, make_record, progressive as _progressive

PROBE_VARIANTS = (
    ("baseline", {"fit": "box", "sh_order": 2, "precision": "rgba32f", "channels": 3}),
    ("fit visible", {"fit": "visible", "sh_order": 2, "precision": "rgba32f", "channels": 3}),
    ("sh order auto", {"fit": "box", "sh_order": "auto", "precision": "rgba32f", "channels": 3}),
    ("channels auto", {"fit": "box", "sh_order": 2, "precision": "rgba32f", "channels": "auto"}),
    ("rgba16f", {"fit": "box", "sh_order": 2, "precision": "rgba16f", "channels": 3}),
    ("all", {"fit": "visible", "sh_order": "auto", "precision": "rgba16f", "channels": "auto"}),
)


def skipping_modes(renderer) -> tuple[bool, ...]:
    """Empty-space skipping on and off where the renderer can switch it, else just as it is."""
    return (True, False) if hasattr(renderer, "configure") else (None,)


def _set_skipping(renderer, on) -> None:
    if on is not None:
        renderer.configure(empty_space_skipping=on)


def cost_scene(renderer, name: str, config, results, out, device: str,
               reference: np.ndarray) -> None:
    scene = renderer.scene
    k = config.samples_per_dispatch
    base = {"scene": name, "device": device, "width": config.width, "height": config.height,
            "reference_noise": results.references.get(name, {}).get("noise_rrmse"),
            "mode": "cost"}

    def record(method, frames, image, timing, bake_ms=0.0, **extra):
        rec = make_record(base, config, method, frames, image, reference, timing, bake_ms, **extra)
        results.add(rec, image, reference)
        return rec

    for skipping in skipping_modes(renderer):
        _set_skipping(renderer, skipping)
        renderer.set_scene(scene)
        for spp, image, *timing in _progressive(renderer, "pt", (config.cost_pt_spp,), 5, k):
            r = record("pt", spp, image, timing, variant="pt", empty_space_skipping=skipping)
        _log(f"  pt skipping={skipping}: {r['frame_ms']:.3f} ms/spp, rRMSE {r['rrmse']:.4f}")

    for grid, samples in config.cost_settings:
        for skipping in skipping_modes(renderer):
            _set_skipping(renderer, skipping)
            variants = PROBE_VARIANTS if skipping in (True, None) else PROBE_VARIANTS[:1]
            for label, changes in variants:
                probes = replace(scene.probes, grid=(grid, grid, grid), samples=samples, **changes)
                renderer.set_scene(scene.replace(probes=probes))
                # the light grid (the walks' sun and the raymarcher's): charged to every setting
                light_ms = renderer.light_grid_ms()
                walk_light_ms = light_ms if renderer.settings.walk_sun == "grid" else 0.0
                bake_ms = renderer.bake(seed=11) + walk_light_ms
                g = renderer.probe_grid
                info = {"variant": label, "empty_space_skipping": skipping, "probe_grid": grid,
                        "probe_samples": samples, "probe_grid_xyz": list(g.grid),
                        "sh_order": g.sh_order, "precision": g.precision, "fit": probes.fit,
                        "channels": 1 if g.grey else 3,
                        "probe_bytes": g.gpu_bytes}
                line = [f"  {grid}^3x{samples} {label} skipping={skipping}: grid {g.grid}, "
                        f"bake {bake_ms:.1f} ms, {g.gpu_bytes / 2**20:.1f} MiB"]
                for method, frames in (("probes", config.cost_probe_frames),
                                       ("raymarch", config.cost_raymarch_frames)):
                    # the image's own light grid, where the method reads it beyond the walks
                    extra_ms = (light_ms - walk_light_ms if METHODS[method].needs_light_grid
                                else 0.0)
                    for n, image, *timing in _progressive(renderer, method, (frames,), 13, k):
                        r = record(method, n, image, timing, bake_ms + extra_ms, **info)
                        if label == "all" and (grid, samples) == tuple(config.cost_settings[0]):
                            save_png(out / "images" / f"{name}_{method}_cost_all.png", image)
                    line.append(f"{method} {r['frame_ms']:.3f} ms/fr rRMSE {r['rrmse']:.4f}")
                _log(", ".join(line))
    _set_skipping(renderer, skipping_modes(renderer)[0])   # back to the default
    renderer.set_scene(scene)
    for target in config.cost_auto_targets:
        auto_scene(renderer, target, config, record, _log, _progressive)
    renderer.set_scene(scene)


def auto_scene(renderer, target: float, config, record, log, progressive) -> None:
    """`auto` chooses at its pilot resolution; this checks the choice at full resolution."""
    from radiance_probes.rendering.probes.auto import choose_probes
    scene = renderer.scene
    # from nothing, as `render --auto-probes` starts: the search pays for every light grid and
    # bake it uses, also one an earlier setting of this run left current
    renderer.invalidate()
    choice = choose_probes(renderer, target, "raymarch", pilot_side=config.auto_pilot_side,
                           frames=config.auto_pilot_frames)
    renderer.set_scene(choice.scene)
    # The chosen setting's probes are the search's last trial (the camera never re-bakes): their
    # bake is already paid inside search_ms, and bake_ms says what it was.
    renderer.bake(seed=11)
    light_ms = renderer.bake_light()   # 0 when the search's last trial baked this light grid
    # What the chosen probes and the image's light grid cost. Walks that read the light grid at
    # bake level 0 baked the image's own, inside the bake's time (Renderer.bake_walk_light):
    # counted once.
    light_in_bake = renderer.probe_grid.needs_light and not renderer.baked_level
    bake_ms = renderer.last_bake_ms + (light_ms or (0.0 if light_in_bake
                                                    else renderer.light_cost_ms))
    g = renderer.probe_grid
    for n, image, *timing in progressive(renderer, "raymarch", config.auto_check_frames, 13,
                                         config.samples_per_dispatch):
        r = record("raymarch", n, image, timing, bake_ms, variant=f"auto {target:g}",
                   probe_grid=choice.scene.probes.grid[0], probe_samples=choice.scene.probes.samples,
                   probe_grid_xyz=list(g.grid), sh_order=g.sh_order, precision=g.precision,
                   fit="visible", probe_bytes=g.gpu_bytes, auto_target=target,
                   auto_pilot_rrmse=choice.rrmse, auto_met_on_pilot=choice.met,
                   auto_trials=choice.trials, auto_pilot_spp=choice.pilot_spp,
                   auto_pilot_side=config.auto_pilot_side,
                   auto_pilot_frames=config.auto_pilot_frames,
                   auto_search_ms=choice.search_ms)
        # Everything this image cost: the whole search (pilot path traces, each trial's bake and
        # pilot render, the chosen bake among them), the light grid if it was baked now, the
        # frames up to this one.
        r["total_ms"] = choice.search_ms + light_ms + r["render_ms"]
        r["total_includes"] = "auto search (pilot path traces, trial bakes and renders) + render"
        r["auto_met"] = r["rrmse"] <= target
        log(f"  auto {target:g}: {choice.scene.probes.grid[0]}^3 x {choice.scene.probes.samples} -> "
            f"grid {g.grid}; pilot rRMSE {choice.rrmse:.4f}, full-resolution rRMSE {r['rrmse']:.4f} "
            f"at {n} frames ({'met' if r['auto_met'] else 'NOT met'})")
    renderer.set_scene(scene)
