"""`--preset interact`: a scripted viewer session replayed through the viewer's own loop
(app/viewer/frame/session.py RenderSession, without a window), per scene, image size and probe setting:

    load; orbit the camera through N frames; drag a transfer-function opacity point; rotate the sun
    by 30 degrees; change the density scale; change the albedo; switch probes to the raymarcher.

Every frame is RenderSession.step with the viewer's budgets: a bake slice while the probes are stale
(light-grid layers, then probes' walks; after it the picture restarts from the probes as they are;
probe-lit methods show the raymarcher until the bake is done), then the samples the rest of the
frame holds. For each event it records the first frame after it, frame-time p50 and p99 over the
frames until convergence (bake done and the target samples reached), and the rRMSE (corrected for
the reference's noise) against the time since the event, measured against a path-traced reference
of the state after the event (cached by name under refs/, so --ref-dir reuses them). Times are GPU
timestamps and, beside them, wall-clock time of the whole frame (the edit's CPU work included, and
the frame's wait for its timers), which is what a person at the viewer feels. Edits run twice: `warm` (the bake starts from
the previous probes) and `cold`, each from the previous state's finished probes. At the end, the
per-dispatch tail: GPU ms per sample at 1 and at k samples per dispatch."""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import replace

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.scene.transfer import opacity_points, rgba_with_opacity
from radiance_probes.rendering.budgets.ceiling import (SPEED_CHECK_STEPS, measure_ceiling,
                                                       speed_check_ms)
from radiance_probes.rendering.image_error import ImageError
from radiance_probes.rendering.metrics import corrected_rrmse, rrmse
from radiance_probes.scene.area_lights import enabled_lights
from radiance_probes.bench.records import log as _log

TARGETS = (0.10, 0.05, 0.03, 0.02)
# The error curve has a point at least every CURVE_WALL_MS of the frames' wall time (issue 56),
# besides the first frames and a log-spaced set: a time to 2% read, not guessed. Measuring (the
# shown image's error against the reference, on the GPU: shown_error) is outside the frames' wall
# time and is recorded apart (measure_wall_ms); the filter's thread is held meanwhile (no job
# starts). Read back to the host instead, a 4K point kept the GPU idle for 0.5 s and the replay
# then ran at the H200's idle clock (bench/h200-raymarch-4k).
CURVE_WALL_MS = 100.0
# `refine` (the viewer's raymarcher, then `guided`) is judged by this: within 2% of the reference
# within 1 s of every event (report: interact_report.py)
REFINE_GOAL = (0.02, 1000.0)
# Wall seconds of GPU work before each event's frames (warm_clock). After the replay's host work
# (a 4K reference's noise, a PNG) the H200 sat at its idle 345 of 1980 MHz, and an event's first
# 5-10 frames (about 250 ms) ran up to 5.7x slower (bench/h200-raymarch-4k/README.md).
CLOCK_WARM_S = 0.5
EDITS = ("tf_drag", "sun_30deg", "density", "albedo")
# and where the scene has an area light on: the first one moved 30 degrees about the volume's
# vertical axis (a drag in the viewer), which rebuilds what depends on the lights
LIGHT_EDITS = ("light_move",)


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
    if event == "light_move":
        lights = list(scene.area_lights)
        lights[0] = replace(lights[0], position=_rotate_y(lights[0].position, 30.0))
        return scene.replace(area_lights=tuple(lights))
    raise ValueError(event)


def edits_for(scene) -> tuple[str, ...]:
    """The replay's edits of a scene: EDITS, and LIGHT_EDITS where an area light is on."""
    return EDITS + (LIGHT_EDITS if enabled_lights(scene) else ())


def time_to(curve: list[tuple[float, float]], target: float) -> float | None:
    """GPU ms since the event when the error first reached `target` (None: never)."""
    return next((t for t, e in curve if e <= target), None)


def shown_error(session, method: str, reference, noise: float, meter=None) -> float:
    """The rRMSE of the image a view shows against `reference`, corrected for the reference's
    noise, with the filter's thread held: on the GPU where `meter` (image_error.ImageError) is
    given and the view shows one texture, else read back and compared on the host."""
    with session.denoise.held():
        view = session.views.get(method)
        if meter is not None and view is not None and hasattr(view.acc, "texture"):
            meter.set_reference(reference)
            return corrected_rrmse(meter.rrmse(session.texture(method)), noise)
        return corrected_rrmse(rrmse(session.shown_image(method), reference), noise)


def warm_clock(renderer, rays: int) -> float:
    """On a GPU with a clock to raise (not a CPU rasteriser), GPU work (ceiling.py's march of
    `rays`, the speed check's) for CLOCK_WARM_S of wall time, so that an event's frames start at
    the clock the GPU holds while a person works in the viewer, not at the idle clock the
    replay's own host work left it at (records.warm_up does the same before a timed run).
    Returns the wall ms spent."""
    from radiance_probes.gl.context import is_software
    if is_software(renderer.ctx):
        return 0.0
    start = time.perf_counter()
    while time.perf_counter() - start < CLOCK_WARM_S:
        measure_ceiling(renderer, rays, SPEED_CHECK_STEPS)
    return 1e3 * (time.perf_counter() - start)


def run_frames(session, method: str, config, reference, noise: float, seed: int,
               scenes: list | None = None, orbit: bool = False, meter=None) -> dict:
    """Frames as the viewer makes them until convergence (or interact_max_frames). `scenes`: the
    event, one scene per frame from the first (the orbit's moves, or the edited scene), each set
    inside its frame's wall time. Timed from the event (the orbit: from its last move). `meter`:
    the error measured on the GPU (shown_error)."""
    s = session
    r = s.renderer
    needs = s.needs_probes(method)
    target_spp = dict(config.interact_target_spp).get(method, 16)
    s.seed = seed
    s.set_methods([method])
    s.restart()
    scenes = list(scenes or [])
    lead = len(scenes) - 1 if orbit else 0     # frames before the one the timing starts at
    frames, walls, curve, trace = [], [], [], []
    t = wall_t = 0.0
    checks = {0, 1, 2, 3}
    k = 4
    while k < config.interact_max_frames + 64:
        checks.add(k)
        k = int(k * 1.4) + 1
    converged = False
    measure_ms, last_point, filter_ms, parts = [], None, [], []
    if meter is not None:
        meter.set_reference(reference)   # its upload before the frames, not after the first
    warm_ms = warm_clock(r, config.speed_check_rays)
    for f in range(lead + config.interact_max_frames):
        start = time.perf_counter()
        if f < len(scenes):
            s.set_scene(scenes[f])
        times = s.step(target_spp, needs)
        wall = (time.perf_counter() - start) * 1e3
        ms = times.total_ms + times.denoise_ms   # the Denoise switch's work in the frame (wall)
        frames.append(ms)
        walls.append(wall)
        view = s.views[method]
        trace.append([round(times.bake_ms, 3), round(times.render_ms, 3), times.samples,
                      view.shown,   # refine: "raymarch" or "guided", and guided's blend weight
                      *([round(view.weight, 3) if view.shown == "guided" else 0.0]
                        if hasattr(view, "blending") else []),
                      round(times.denoise_ms, 2)])
        # the filter's ms on its thread for what landed in the frame (off the frame), and each
        # part's [GPU ms or None, wall ms] (app/viewer/frame/frame_parts.py; GPU ms filled in at the
        # next frame)
        filter_ms.append(round(times.filter_ms, 2))
        parts.append(times.parts)
        t, wall_t = t + ms, wall_t + wall
        after = f - lead
        if after < 0:
            continue
        if after == 0:
            t, wall_t = ms, wall
        view = s.views[method]
        converged = (not needs or r.probes_current()) and s.view_done(method, target_spp)
        # a point now where the next frame (as long as the longest of the last 8) would leave a
        # gap over CURVE_WALL_MS since the last (a frame longer than that is a gap of its own)
        gap_due = (last_point is None
                   or wall_t + max(walls[-8:]) - last_point > CURVE_WALL_MS)
        if (after in checks or gap_due or converged
                or f == lead + config.interact_max_frames - 1):
            m0 = time.perf_counter()
            error = shown_error(s, method, reference, noise, meter)
            measure_ms.append(1e3 * (time.perf_counter() - m0))
            curve.append((t, wall_t, error))
            last_point = wall_t
        if converged:
            break
    s.parts.resolve()   # the last frame's GPU ms into its trace
    parts = [{k: [None if g is None else round(g, 3), round(w, 3)] for k, (g, w) in p.items()}
             for p in parts]
    # every frame counts for frame times (the orbit's are camera moves); errors from the event on
    return {"frames": frames, "walls": walls, "curve": curve, "converged": converged,
            "trace": trace, "measure_ms": measure_ms, "filter_ms": filter_ms, "parts": parts,
            "clock_warm_ms": warm_ms}


def still_flicker(session, method: str, config, reference, noise: float, seed: int,
                  from_wall_ms: float | None = None, meter=None) -> dict:
    """How much a view's shown image changes from frame to frame on a still camera once it is
    good (issue 56): frames from a restart with the viewer's sample limit (state.MAX_SAMPLES),
    until (from_wall_ms None) its error first reaches REFINE_GOAL's with its own estimator shown
    (refine: guided, not the raymarcher), or it stops; else until that much wall time of frames.
    Then the next config.interact_flicker_frames frames, each shown image against the one
    before: the RMS of the change over the reference's RMS (rRMSE's scale).
    Returns the wall ms the window began at, whether the view had stopped by then (its sample
    limit reached: nothing changes after), its frames, the change's mean and largest, and the
    error at the window's start."""
    from radiance_probes.viewer.state import MAX_SAMPLES as limit
    s = session
    needs = s.needs_probes(method)
    s.seed = seed
    s.set_methods([method])
    s.restart()
    wall, last_check, error, stopped = 0.0, -1e9, None, False
    # (to a wall time: as many frames as it takes, unless the view stops first)
    for _ in range(config.interact_max_frames if from_wall_ms is None else 1 << 20):
        start = time.perf_counter()
        s.step(limit, needs)
        wall += 1e3 * (time.perf_counter() - start)
        stopped = s.finished(limit, needs)
        if stopped or (from_wall_ms is not None and wall >= from_wall_ms):
            break
        # the error, measured outside the frames' wall time
        if from_wall_ms is None and wall - last_check >= CURVE_WALL_MS:
            error = shown_error(s, method, reference, noise, meter)
            last_check = wall
            # refine: once guided shows (its raymarcher's frames stop after 16 and hold still)
            if error <= REFINE_GOAL[0] and getattr(s.views[method], "shown", method) != "raymarch":
                break
    with s.denoise.held():
        before = s.shown_image(method)
    if error is None:
        error = corrected_rrmse(rrmse(before, reference), noise)
    scale = float(np.sqrt(np.mean(np.asarray(reference, np.float64) ** 2)))
    changes = []
    for _ in range(config.interact_flicker_frames):
        s.step(limit, needs)
        with s.denoise.held():
            now = s.shown_image(method)
        diff = now.astype(np.float64) - before
        changes.append(float(np.sqrt(np.mean(diff * diff))) / scale)
        before = now
    return {"from_wall_ms": wall, "stopped": stopped, "frames": len(changes), "error": error,
            "change_mean": float(np.mean(changes)), "change_max": float(max(changes)),
            "frames_changed": int(sum(c > 0.0 for c in changes))}


def flicker_record(base: dict, session, method: str, config, reference, noise: float,
                   meter=None) -> dict:
    """refine's frame-to-frame change on a still camera once within 2% (still_flicker), against
    the raw path tracer's (the Denoise switch off) from the same wall time after its restart."""
    shown = still_flicker(session, method, config, reference, noise, seed=21, meter=meter)
    on = session.denoise.enabled
    session.denoise.set_enabled(False)
    try:
        pt = still_flicker(session, "pt", config, reference, noise, seed=21,
                           from_wall_ms=shown["from_wall_ms"])
    finally:
        session.denoise.set_enabled(on)
    ratio = shown["change_mean"] / pt["change_mean"] if pt["change_mean"] > 0 else None
    return dict(base, event="flicker", method=method, variant=None, flicker=shown, flicker_pt=pt,
                flicker_ratio=ratio)


def record(base: dict, event: str, method: str, variant, run: dict, **extra) -> dict:
    frames, walls, curve = run["frames"], run["walls"], run["curve"]
    rec = dict(base, event=event, method=method, variant=variant,
               first_frame_ms=frames[0], frame_ms_p50=float(np.percentile(frames, 50)),
               frame_ms_p99=float(np.percentile(frames, 99)),
               frame_ms_max=float(max(frames)), frame_wall_ms_max=float(max(walls)),
               first_frame_wall_ms=walls[0], frame_wall_ms_p50=float(np.percentile(walls, 50)),
               frame_wall_ms_p99=float(np.percentile(walls, 99)), frames=len(frames),
               converged=run["converged"], final_rrmse=curve[-1][2] if curve else None,
               total_ms=sum(frames), total_wall_ms=sum(walls),
               curve=[[float(a), float(c)] for a, _, c in curve],
               wall_curve=[[float(b), float(c)] for _, b, c in curve],
               # per frame: bake slice ms, samples' ms, samples per pixel, the method shown (a
               # probe-lit view shows the raymarcher while it bakes; refine: then guided's blend
               # weight), the Denoise switch's wall ms in the frame
               frame_trace=run.get("trace", []),
               # per frame too: its wall ms, the filter's ms on its thread for what landed in it
               # (off the frame), and its parts by name, {part: [GPU ms or None, wall ms]}
               frame_walls=[round(w, 2) for w in walls], frame_filter_ms=run.get("filter_ms", []),
               frame_parts=run.get("parts", []),
               # the error's measurements (outside the frames' wall time): how many, their wall
               # ms in all and at most, and the largest wall-time gap between two points
               measure_points=len(run.get("measure_ms", [])),
               measure_wall_ms=float(sum(run.get("measure_ms", []))),
               measure_wall_ms_max=float(max(run.get("measure_ms", []) or [0.0])),
               clock_warm_ms=run.get("clock_warm_ms", 0.0),   # GPU work before it (warm_clock)
               curve_wall_gap_ms_max=float(max(
                   (b2 - b1 for (_, b1, _), (_, b2, _) in zip(curve, curve[1:])), default=0.0)))
    for target in TARGETS:
        pct = round(target * 100)
        rec[f"ms_to_{pct}pct"] = time_to([(a, c) for a, _, c in curve], target)
        rec[f"wall_ms_to_{pct}pct"] = time_to([(b, c) for _, b, c in curve], target)
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


def replay_session(renderer, config):
    """The replay's RenderSession over `renderer` and its scene, GPU and wall times apart, with
    `config`'s bake and frame budgets (the viewer's); the lab's frame profiles build theirs here
    too, so that they profile the frames the replay times."""
    from radiance_probes.viewer.frame.session import RenderSession
    session = RenderSession(renderer.ctx, renderer.scene, renderer=renderer, clock="gpu")
    session.bake_budget_ms = config.interact_bake_budget_ms
    session.bake_fills_frame = config.interact_bake_fills_frame   # as the viewer's
    session.frame_budget_ms = config.interact_frame_budget_ms
    return session


def require_denoiser(config) -> None:
    """A replay with the Denoise switch on refuses to run where the denoiser cannot: the viewer
    would switch Denoise off at its first filtered image and the records, taken as denoised,
    would hold raw images (an H200 run of the chest whose machine lacked OIDN gave refine's
    raw guided as its Denoise-on figures)."""
    if not config.interact_denoise:
        return
    from radiance_probes.viewer.frame import denoise_view
    denoiser = denoise_view.shared_denoiser()
    if not denoiser.available:
        raise RuntimeError("this replay has the Denoise switch on, but the denoiser cannot run: "
                           f"{denoiser.failure}")


def interact_scene(renderer, name: str, config, results, out, device: str, reference_of) -> None:
    """`reference_of(renderer, key, config)`: the runner's cached path-traced reference of the
    renderer's current scene under `key` (refs/KEY.npy, reused from --ref-dir)."""
    r = renderer
    start = r.scene
    session = replay_session(r, config)
    meter = ImageError(r.ctx)   # the error curve's points measured on the GPU (shown_error)
    require_denoiser(config)
    if config.interact_denoise is not None:
        session.denoise.set_enabled(config.interact_denoise)
    for width, height in config.interact_sizes:
        ref_spp = dict(config.interact_ref_spp_by_scene).get(name, config.interact_ref_spp)
        size_cfg = config.scaled(width=width, height=height, ref_spp=ref_spp)
        session.resize(width, height)
        tag = f"{name}_{width}x{height}"
        refs: dict = {}

        def ref(key):
            """The state's reference, rendered once per run (every method is measured on it)."""
            if key not in refs:
                img = reference_of(r, f"{tag}_{key}", size_cfg)
                refs[key] = img, results.references.get(f"{tag}_{key}", {}).get("noise_rrmse", 0.0)
            return refs[key]

        def add(rec):
            # the device's speed (ceiling.py)
            rec["speed_check_ms"] = speed_check_ms(r, config.speed_check_rays)
            results.add(rec)
            shown = ", ".join(f"{t}: {rec[f'ms_to_{t}pct']}" for t in (10, 5, 3))
            _log(f"  {tag} {rec['probe_grid']}^3x{rec['probe_samples']} {rec['event']} "
                 f"{rec['method']} {rec['variant'] or ''}: first {rec['first_frame_ms']:.2f} ms "
                 f"(wall {rec['first_frame_wall_ms']:.1f}), p50 {rec['frame_ms_p50']:.2f}, p99 "
                 f"{rec['frame_ms_p99']:.2f} ms (wall {rec['frame_wall_ms_p99']:.1f}), final rRMSE "
                 f"{rec['final_rrmse']:.4f}, ms to {shown}")

        def want(event: str) -> bool:
            return config.interact_events is None or event in config.interact_events

        def flicker(base, method, reference, noise):
            if method != "refine" or not config.interact_flicker_frames or not want("flicker"):
                return
            rec = flicker_record(base, session, method, config, reference, noise, meter)
            rec["speed_check_ms"] = speed_check_ms(r, config.speed_check_rays)
            results.add(rec)
            f, p = rec["flicker"], rec["flicker_pt"]
            _log(f"  {tag} flicker {method}: {f['change_mean']:.5f} a frame from "
                 f"{f['from_wall_ms']:.0f} ms (error {f['error']:.4f}), raw pt "
                 f"{p['change_mean']:.5f} (error {p['error']:.4f}): ratio {rec['flicker_ratio']}")

        for grid, walks in config.interact_probes:
            probes = replace(start.probes, grid=(grid, grid, grid), samples=walks)
            scene = start.replace(probes=probes,
                                  camera=replace(start.camera, width=width, height=height))
            base = {"mode": "interact", "scene": name, "device": device, "width": width,
                    "height": height, "probe_grid": grid, "probe_samples": walks,
                    "bake_budget_ms": config.interact_bake_budget_ms,
                    "denoise": session.denoise.enabled,
                    "frame_budget_ms": config.interact_frame_budget_ms}
            for method in config.interact_methods:
                if not want("load"):   # (the flicker alone: on the loaded scene)
                    r.set_scene(scene)
                    session.set_scene(scene)
                    reference, noise = ref("load")
                    flicker(base, method, reference, noise)
                    continue
                # load: nothing baked yet
                r.set_scene(scene)
                reference, noise = ref("load")
                r.invalidate()
                if r.probe_grid is not None:   # a fresh load has no probes at all
                    r.probe_grid.release()
                    r.probe_grid = None
                add(record(base, "load", method, None,
                           run_frames(session, method, config, reference, noise, seed=1,
                                      meter=meter)))
                # orbit: camera moves never re-bake
                moves = [orbit(scene, 60.0 * (i + 1) / config.interact_orbit_frames)
                         for i in range(config.interact_orbit_frames)]
                state = moves[-1]
                r.set_scene(state)
                reference, noise = ref("orbit")
                run = run_frames(session, method, config, reference, noise, seed=2, scenes=moves,
                                 orbit=True, meter=meter)
                add(record(base, "orbit", method, None, run, orbit_frames=len(moves)))
                for i, event in enumerate(edits_for(state)):
                    before, after = state, edit(state, event)
                    r.set_scene(after)
                    reference, noise = ref(event)
                    for variant in ("warm", "cold"):
                        session.set_scene(before)
                        r.configure(bake_warm=False)
                        r.bake(seed=100 + i)        # the state before the edit, finished (untimed)
                        r.configure(bake_warm=variant == "warm")
                        run = run_frames(session, method, config, reference, noise, seed=3 + i,
                                         scenes=[after], meter=meter)
                        add(record(base, event, method, variant, run))
                    state = after
                save_png(out / "images" / f"{tag}_{grid}_{method}_final.png", session.image(method))
                flicker(base, method, reference, noise)   # on the last edit's state
            if not want("raymarch_switch"):
                continue
            r.configure(bake_warm=True)
            # switch probes -> raymarcher: the same state, so the albedo reference serves
            run = run_frames(session, "raymarch", config, reference, noise, seed=9, meter=meter)
            add(record(base, "raymarch_switch", "raymarch", None, run))
            # one sample's dispatch of the raymarcher is what a camera move costs
            for method in ("raymarch", "probes", "pt"):
                tail = dispatch_tail(r, method, config.interact_tail_k)
                results.add(dict(base, event="dispatch_tail", method=method, variant=None, **tail))
                _log(f"  {tag} dispatch tail {method}: {tail['ms_per_sample_1']:.3f} ms/sample at "
                     f"1, {tail['ms_per_sample_k']:.3f} at {tail['k']} per dispatch")
    session.set_methods([])
    meter.release()
    r.set_scene(start)
