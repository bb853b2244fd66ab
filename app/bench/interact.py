"""`--preset interact`: a scripted viewer session replayed through the progressive Renderer API the
viewer uses (bake_step with a GPU-time budget, begin, add_samples), per scene and image size:

    load; orbit the camera through N frames; drag a transfer-function opacity point; rotate the sun
    by 30 degrees; change the density scale; change the albedo; switch probes to the raymarcher.

Every frame is what RenderSession.step does: a bake slice while the probes are stale (after which
the picture restarts from the probes as they are), then samples. For each event it records the GPU
time of the first frame after it, frame-time p50 and p99 over the frames until convergence (bake
done and the target samples reached), and the rRMSE (corrected for the reference's noise) against
the GPU time since the event, measured against a path-traced reference of the state after the event
(cached by name under refs/, so --ref-dir reuses them). Edits run twice: `warm` (the bake starts from
the previous probes) and `cold`, each from the previous state's finished probes. At the end, the
per-dispatch tail: GPU ms per sample at 1 and at k samples per dispatch."""
from __future__ import annotations

import math
import statistics
from dataclasses import replace

import numpy as np

from ..imageio import save_png
from ..transfer import opacity_points, rgba_with_opacity
from .metrics import corrected_rrmse, rrmse
from .records import log as _log

TARGETS = (0.10, 0.05, 0.03)
EDITS = ("tf_drag", "sun_30deg", "density", "albedo")


def _rotate_y(v, degrees: float) -> tuple[float, float, float]:
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    x, y, z = v
    return (c * x + s * z, y, -s * x + c * z)


def orbit(scene, degrees: float):
    cam = scene.camera
    rel = tuple(e - t for e, t in zip(cam.eye, cam.target))
    eye = tuple(t + r for t, r in zip(cam.target, _rotate_y(rel, degrees)))
    return scene.replace(camera=replace(cam, eye=eye))


def drag_opacity(scene, amount: float = 0.15):
    """Drags the opacity curve's middle control point up by `amount` (as the editor does)."""
    tf = scene.transfer_function
    points, _ = opacity_points(tf)
    points = [list(p) for p in points]
    i = len(points) // 2
    points[i][1] = min(1.0, max(0.0, points[i][1] + amount))
    points = tuple(tuple(p) for p in points)
    if tf.rgba is not None:
        return scene.replace(transfer_function=replace(tf, rgba=rgba_with_opacity(tf, points)))
    return scene.replace(transfer_function=replace(tf, opacity=points))


def edit(scene, event: str):
    if event == "tf_drag":
        return drag_opacity(scene)
    if event == "sun_30deg":
        return scene.replace(light=replace(scene.light, direction=_rotate_y(scene.light.direction, 30.0)))
    if event == "density":
        return scene.replace(density_scale=scene.density_scale * 1.3)
    if event == "albedo":
        return scene.replace(albedo=max(0.0, scene.albedo - 0.15))
    raise ValueError(event)


def time_to(curve: list[tuple[float, float]], target: float) -> float | None:
    """GPU ms since the event when the error first reached `target` (None: never)."""
    return next((t for t, e in curve if e <= target), None)


def run_frames(r, method: str, config, reference, noise: float, seed: int,
               moves: list | None = None) -> dict:
    """Frames as the viewer makes them until convergence (or interact_max_frames). `moves`: one
    scene per frame before the rest (the orbit), each restarting the picture."""
    budget = config.interact_bake_budget_ms
    spf = config.interact_samples_per_frame
    target_spp = dict(config.interact_target_spp).get(method, 16)
    frames: list[float] = []
    curve: list[tuple[float, float]] = []
    t = 0.0
    r.begin(method, seed=seed)
    checks = {0, 1, 2, 3}
    k = 4
    while k < config.interact_max_frames + 64:
        checks.add(k)
        k = int(k * 1.4) + 1
    moves = list(moves or [])
    for f in range(len(moves) + config.interact_max_frames):
        if f < len(moves):
            r.set_scene(moves[f])
            r.begin(method, seed=seed)
        bake_ms = 0.0
        if r.needs_probes(method) and not r.probes_current():
            bake_ms = r.bake_step(seed, budget_ms=budget)
            r.begin(method, seed=seed)   # the picture restarts from the probes as they are now
        ms = bake_ms + r.add_samples(spf)
        frames.append(ms)
        t += ms
        after = f - len(moves)
        if after < 0:
            continue
        if after == 0:
            t = ms   # the orbit's error is timed from its last move
        converged = (not r.needs_probes(method) or r.probes_current()) and r.samples >= target_spp
        if after in checks or converged or f == len(moves) + config.interact_max_frames - 1:
            curve.append((t, corrected_rrmse(rrmse(r.image(), reference), noise)))
        if converged:
            break
    return {"frames": frames, "curve": curve, "converged": converged}


def record(base: dict, event: str, method: str, variant, run: dict, **extra) -> dict:
    frames, curve = run["frames"], run["curve"]
    rec = dict(base, event=event, method=method, variant=variant,
               first_frame_ms=frames[0], frame_ms_p50=float(np.percentile(frames, 50)),
               frame_ms_p99=float(np.percentile(frames, 99)), frames=len(frames),
               converged=run["converged"], final_rrmse=curve[-1][1] if curve else None,
               total_ms=sum(frames), curve=[[float(a), float(b)] for a, b in curve])
    for target in TARGETS:
        rec[f"ms_to_{round(target * 100)}pct"] = time_to(curve, target)
    rec.update(extra)
    return rec


def dispatch_tail(r, method: str, k: int, seed: int = 99) -> dict:
    """GPU ms per sample at 1 and at k samples per dispatch (medians, after a warm-up)."""
    r.begin(method, seed=seed)
    r.add_samples(1)
    one = [r.add_samples(1) for _ in range(6)]
    many = [r.add_samples(k) / k for _ in range(3)]
    return {"ms_per_sample_1": statistics.median(one), "ms_per_sample_k": statistics.median(many),
            "k": k}


def interact_scene(renderer, name: str, config, results, out, device: str, reference_of) -> None:
    """`reference_of(renderer, key, config)`: the runner's cached path-traced reference of the
    renderer's current scene under `key` (refs/KEY.npy, reused from --ref-dir)."""
    r = renderer
    start = r.scene
    grid, walks = config.interact_probes
    start = start.replace(probes=replace(start.probes, grid=(grid, grid, grid), samples=walks))
    for width, height in config.interact_sizes:
        size_cfg = config.scaled(width=width, height=height, ref_spp=config.interact_ref_spp)
        scene = start.replace(camera=replace(start.camera, width=width, height=height))
        base = {"mode": "interact", "scene": name, "device": device, "width": width,
                "height": height, "probe_grid": grid, "probe_samples": walks,
                "bake_budget_ms": config.interact_bake_budget_ms,
                "samples_per_frame": config.interact_samples_per_frame}
        tag = f"{name}_{width}x{height}"

        refs: dict = {}

        def ref(key):
            """The state's reference, rendered once per run (every method is measured on it)."""
            if key not in refs:
                img = reference_of(r, f"{tag}_{key}", size_cfg)
                refs[key] = img, results.references.get(f"{tag}_{key}", {}).get("noise_rrmse", 0.0)
            return refs[key]

        def add(rec, image=None):
            results.add(rec)
            shown = ", ".join(f"{t}: {rec[f'ms_to_{t}pct']}" for t in (10, 5, 3))
            _log(f"  {tag} {rec['event']} {rec['method']} {rec['variant'] or ''}: first "
                 f"{rec['first_frame_ms']:.2f} ms, p50 {rec['frame_ms_p50']:.2f}, p99 "
                 f"{rec['frame_ms_p99']:.2f} ms, final rRMSE {rec['final_rrmse']:.4f}, ms to "
                 f"{shown}")

        for method in config.interact_methods:
            # load: nothing baked yet
            r.set_scene(scene)
            reference, noise = ref("load")
            r.invalidate()
            if r.probe_grid is not None:   # a fresh load has no probes at all
                r.probe_grid.release()
                r.probe_grid = None
            add(record(base, "load", method, None, run_frames(r, method, config, reference,
                                                                     noise, seed=1)))
            # orbit: camera moves never re-bake
            moves = [orbit(scene, 60.0 * (i + 1) / config.interact_orbit_frames)
                     for i in range(config.interact_orbit_frames)]
            state = moves[-1]
            r.set_scene(state)
            reference, noise = ref("orbit")
            run = run_frames(r, method, config, reference, noise, seed=2, moves=moves)
            add(record(base, "orbit", method, None, run, orbit_frames=len(moves)))
            for i, event in enumerate(EDITS):
                before, after = state, edit(state, event)
                r.set_scene(after)
                reference, noise = ref(event)
                for variant in ("warm", "cold"):
                    r.set_scene(before)
                    r.bake_warm = False
                    r.bake(seed=100 + i)        # the state before the edit, finished (not timed)
                    r.set_scene(after)
                    r.bake_warm = variant == "warm"
                    run = run_frames(r, method, config, reference, noise, seed=3 + i)
                    add(record(base, event, method, variant, run))
                state = after
            save_png(out / "images" / f"{tag}_{method}_final.png", r.image())
        r.bake_warm = True
        # switch probes -> raymarcher: the same state, so the albedo reference serves
        run = run_frames(r, "raymarch", config, reference, noise, seed=9)
        add(record(base, "raymarch_switch", "raymarch", None, run))
        save_png(out / "images" / f"{tag}_raymarch_final.png", r.image())
        for method in ("probes", "pt"):
            tail = dispatch_tail(r, method, config.interact_tail_k)
            results.add(dict(base, event="dispatch_tail", method=method, variant=None, **tail))
            _log(f"  {tag} dispatch tail {method}: {tail['ms_per_sample_1']:.3f} ms/sample at 1, "
                 f"{tail['ms_per_sample_k']:.3f} at {tail['k']} per dispatch")
    r.set_scene(start)
