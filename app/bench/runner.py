"""Runs the benchmark: a converged reference per scene, then every method and setting measured
against it. Each record is written to results.json as soon as it exists, so a partial run keeps
what it measured. GPU times come from timestamp queries; frame times are medians over the frames
of a progressive run after one warm-up frame."""
from __future__ import annotations

import json
import multiprocessing
import os
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.methods import PROBE_LIT, REFERENCE
from radiance_probes.rendering.budgets.ceiling import speed_check_ms
from radiance_probes.bench.clock_log import ClockLog
from radiance_probes.bench.config import BenchConfig
from radiance_probes.rendering.metrics import flip, reference_noise
from radiance_probes.gl.checks import checks_for
from radiance_probes.gl.dispatch_log import DispatchLog
from radiance_probes.bench.records import log as _log, make_record, progressive as _progressive
from radiance_probes.bench.report import load as load_results
from radiance_probes.rendering.probes.layout import resolve_precision, resolve_sh_order
from radiance_probes.bench.scenes import bench_scene

PROBE_METHODS = PROBE_LIT   # the path tracer's probe-lit variants (app/methods.py)


# Seconds between two writes of results.json while records come in. Writing it after every record
# took 0.05 to 0.14 s once it held a few scenes (json.dumps of 1 to 2 MB), and the GPU sat idle
# meanwhile: between the snapshots of one timed run its clock fell to 390-1665 MHz (nvidia-smi,
# bench/archive/h100-runs-2), so records of the later scenes were timed on a clocked-down GPU.
FLUSH_EVERY_S = 30.0


class Results:
    """The growing list of records, written to JSON at most every FLUSH_EVERY_S seconds, after each
    scene and at the end (FLIP fills in later)."""

    def __init__(self, path: Path, meta: dict):
        self.path = path
        self.meta = meta
        self.flush_every_s = FLUSH_EVERY_S
        self._flushed_at: float | None = None   # monotonic time of the last write
        self.records: list[dict] = []
        self.pending: list[tuple[dict, Future]] = []
        self.references: dict[str, dict] = {}
        workers = max(1, min(8, (os.cpu_count() or 2) - 1))
        self.pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))

    def add(self, record: dict, image: np.ndarray | None = None,
            reference: np.ndarray | None = None) -> None:
        record.setdefault("flip", None)
        self.records.append(record)
        if image is not None:
            self.pending.append((record, self.pool.submit(flip, image, reference)))
        if self._flushed_at is None or time.monotonic() - self._flushed_at >= self.flush_every_s:
            self.flush()

    def flush(self, wait: bool = False) -> None:
        still = []
        for record, fut in self.pending:
            if wait or fut.done():
                record["flip"] = fut.result()
            else:
                still.append((record, fut))
        self.pending = still
        data = {"meta": self.meta, "references": self.references, "records": self.records}
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=1))
        tmp.replace(self.path)
        self._flushed_at = time.monotonic()

    def close(self) -> None:
        self.flush(wait=True)
        self.pool.shutdown()


def _with_probes(scene, grid: int, samples: int, **changes):
    probes = replace(scene.probes, grid=(grid, grid, grid), samples=samples, **changes)
    return scene.replace(probes=probes)


def _layout_variant(name: str, config: BenchConfig) -> dict:
    """The probe settings of a --probe-layouts entry: an adaptive layout with that indicator."""
    variant = {"layout": "adaptive", "adaptive_indicator": name}
    if config.adaptive_strength is not None:
        variant["adaptive_strength"] = config.adaptive_strength
    return variant


def _layout_info(renderer) -> dict:
    """What a record says of its probe layout: "uniform" or "adaptive-INDICATOR" (with its
    strength), the planes that came out (None: evenly spaced) and the host ms they took."""
    spec, grid = renderer.scene.probes, renderer.probe_grid
    if spec.layout == "uniform":
        return {"probe_layout": "uniform"}
    return {"probe_layout": f"adaptive-{spec.adaptive_indicator}",
            "adaptive_strength": spec.adaptive_strength,
            "probe_planes": None if grid.planes is None else [list(p) for p in grid.planes],
            "layout_ms": renderer.last_layout_ms}


def run_bench(config: BenchConfig, out_dir: str | Path, command: str = "") -> Path:
    from radiance_probes.gl.context import create_headless_context, describe
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.load import load_volume

    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "refs").mkdir(parents=True, exist_ok=True)
    ctx = create_headless_context()
    device = describe(ctx)
    meta = {"device": device, "command": command, "config": asdict(config),
            "started": time.strftime("%Y-%m-%d %H:%M:%S")}
    results = Results(out / "results.json", meta)
    _log(f"device: {device}; writing {out / 'results.json'}")
    clock_log = ClockLog(out / "nvidia-smi.csv")
    if clock_log.start():
        _log(f"GPU clock logged to {clock_log.path}")
    dispatches = DispatchLog().__enter__()   # every record's longest dispatch (records.py)
    try:
        for si, name in enumerate(config.scenes):
            scene = bench_scene(name, config.width, config.height)
            if scene is None:
                _log(f"scene {name}: dataset missing, skipped")
                continue
            _log(f"scene {si + 1}/{len(config.scenes)}: {name}")
            volume = load_volume(scene.volume, scene.base_dir)
            renderer = Renderer(ctx, scene, volume)
            meta.setdefault("settings", renderer.settings.as_dict())
            try:
                _bench_scene(renderer, name, config, results, out, device)
            finally:
                renderer.release()
            checks = checks_for(ctx)   # the checking build (RADIANCE_PROBES_SHADER_CHECKS=1)
            if checks is not None:
                hits = checks.hits()
                meta.setdefault("shader_check_hits", {})[name] = hits
                _log(f"  checking build: {hits or 'no hits'}")
                checks.reset()
            results.flush()
    finally:
        dispatches.take()
        dispatches.__exit__(None, None, None)
        meta["longest_dispatch_ms"] = dispatches.longest_ms
        meta["longest_dispatch"] = dispatches.longest_name
        meta["dispatches"] = dispatches.dispatches
        gpu_clock = clock_log.stop()
        if gpu_clock:
            meta["gpu_clock"] = gpu_clock
        results.close()
        meta["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
        results.flush()
        # Its own context stays current until released: a caller's context (the tests' one) would
        # otherwise receive GL calls meant for this one, and objects made in the caller's context
        # before (cached programs) would name nothing in it.
        ctx.release()
    return out / "results.json"


def _reference(renderer, name: str, config: BenchConfig, results: Results, out: Path) -> np.ndarray:
    """The scene's converged path-traced reference: loaded from config.reference_dir (an earlier
    run's refs/NAME.npy and its measured noise in results.json) when there, else rendered as two
    independent halves whose difference measures the reference's own noise."""
    if config.reference_dir:
        src = Path(config.reference_dir)
        path = src / "refs" / f"{name}.npy"
        known = load_results(src)["references"].get(name)
        if path.is_file() and known:
            reference = np.load(path)
            if reference.shape != (config.height, config.width, 3):
                raise ValueError(f"reference {path} is {reference.shape}, the run renders "
                                 f"{config.height}x{config.width}")
            results.references[name] = dict(known, loaded_from=str(path))
            save_png(out / "images" / f"{name}_reference.png", reference)
            _log(f"  reference: loaded {path} (relative noise {known['noise_rrmse']:.2e})")
            return reference
    half = config.ref_spp // 2
    halves = []
    ref_ms = 0.0
    for seed in (1_000_003, 2_000_003):
        r = renderer.render("pt", spp=half, seed=seed, samples_per_pass=config.ref_samples_per_pass)
        halves.append(r.image)
        ref_ms += r.render_ms
        _log(f"  reference half: {half} spp, {r.render_ms / 1000:.1f} s GPU, stats {r.stats}")
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    results.references[name] = {"spp": config.ref_spp, "gpu_ms": ref_ms, "noise_rrmse": noise}
    np.save(out / "refs" / f"{name}.npy", reference.astype(np.float32))
    save_png(out / "images" / f"{name}_reference.png", reference)
    _log(f"  reference: {config.ref_spp} spp, relative noise {noise:.2e}")
    return reference


def _bench_scene(renderer, name: str, config: BenchConfig, results: Results, out: Path,
                 device: str) -> None:
    if config.mode == "cost":
        from radiance_probes.bench.cost import cost_scene
        return cost_scene(renderer, name, config, results, out, device,
                          _reference(renderer, name, config, results, out))
    if config.mode == "interact":
        from radiance_probes.bench.interact import interact_scene
        return interact_scene(renderer, name, config, results, out, device,
                              lambda r, key, cfg: _reference(r, key, cfg, results, out))
    if config.mode == "movie":
        from radiance_probes.bench.movie import movie_scene
        return movie_scene(renderer, name, config, results, out, device)
    if config.mode == "bias":
        from radiance_probes.bench.bias import bias_scene
        reference = _reference(renderer, name, config, results, out)
        return bias_scene(renderer, name, config, results, out, device, reference,
                          results.references[name]["noise_rrmse"])
    if config.mode == "denoise":
        from radiance_probes.bench.denoise import denoise_scene
        return denoise_scene(renderer, name, config, results, out, device,
                             _reference(renderer, name, config, results, out))
    if config.mode == "bake":
        from radiance_probes.bench.bake import bake_scene
        return bake_scene(renderer, name, config, results, out, device,
                          _reference(renderer, name, config, results, out), config.code_label)
    scene = renderer.scene
    defaults = renderer.settings
    reference = _reference(renderer, name, config, results, out)
    base = {"scene": name, "device": device, "width": config.width, "height": config.height,
            "reference_noise": results.references.get(name, {}).get("noise_rrmse")}

    def record(method: str, frames: int, image: np.ndarray, timing: tuple[float, float],
               bake_ms: float = 0.0, flip: bool = True, **extra) -> None:
        rec = make_record(base, config, method, frames, image, reference, timing, bake_ms, **extra)
        changed = defaults.differences(renderer.settings)   # the run's defaults in meta.settings
        if changed:
            rec["settings"] = changed
        results.add(rec, image if flip and (frames in config.flip_frames or method == REFERENCE)
                    else None, reference)

    # Path tracer: one progressive run, snapshots at each spp.
    k = config.samples_per_dispatch
    base["speed_check_ms"] = speed_check_ms(renderer, config.speed_check_rays)
    for spp, image, *timing in _progressive(renderer, "pt", config.pt_spp, 5, k):
        record("pt", spp, image, timing)
        if spp == config.image_frames:
            save_png(out / "images" / f"{name}_pt_{spp}spp.png", image)
    _log(f"  pt: {config.pt_spp[-1]} spp, {results.records[-1]['frame_ms']:.3f} ms per frame, "
         f"rRMSE {results.records[-1]['rrmse']:.4f}")

    # The sweep's probe precision (--probe-precision; the scene's by default), and the other one as
    # the showcase setting's variant.
    precision = resolve_precision(config.probe_precision or scene.probes.precision,
                                  scene.surface.gradient_factor > 0.0)
    other_precision = "rgba32f" if precision == "rgba16f" else "rgba16f"
    settings = [(g, s) for g in config.probe_grids for s in config.probe_samples]
    settings += [gs for gs in config.large_grids if gs not in settings]
    for grid, samples in settings:
        showcase = (grid, samples) == tuple(config.showcase)
        bake_ms = 0.0
        variants = [{}] + ([{"precision": other_precision}] if showcase else [])
        if showcase and scene.anisotropy != 0.0:
            # With g = 0 the phase convolution zeroes bands 1 and 2: a window changes nothing.
            variants.append({"sh_window": "hann"})
        variants += [_layout_variant(name, config) for name in config.probe_layouts
                     if name != "uniform"]
        main_order = resolve_sh_order(scene.probes.sh_order, scene.anisotropy, samples)
        if scene.anisotropy != 0.0:   # with g = 0 every order renders order 0's image
            variants += [{"sh_order": order} for order in config.sh_orders if order != main_order]
        for variant in variants:
            base["speed_check_ms"] = speed_check_ms(renderer, config.speed_check_rays)
            renderer.set_scene(_with_probes(scene, grid, samples,
                                            **{"precision": precision, **variant}))
            # The light grid this setting's images use (its size follows the probe grid; the
            # walks read it too): what it cost, also when an earlier setting baked the same one.
            light_ms = renderer.light_grid_ms()
            baked_ms = renderer.bake(seed=11)
            # An SH window is applied at render time: the probes stay, and so does their cost.
            bake_ms = baked_ms if baked_ms > 0 else bake_ms
            walk_light_ms = light_ms if renderer.settings.walk_sun == "grid" else 0.0
            probe_info = {"probe_grid": grid, "probe_samples": samples,
                          "precision": renderer.probe_grid.precision,
                          "sh_window": renderer.scene.probes.sh_window,
                          "probe_bytes": renderer.probe_grid.gpu_bytes,
                          "sh_order": renderer.probe_grid.sh_order,
                          **({"sh_order_variant": True} if "sh_order" in variant else {}),
                          **_layout_info(renderer)}
            for method in PROBE_METHODS:
                for frames, image, *timing in _progressive(renderer, method, config.probe_frames,
                                                           13, k):
                    record(method, frames, image, timing, bake_ms + walk_light_ms,
                           light_ms=walk_light_ms, **probe_info)
                    if showcase and not variant and frames == config.image_frames:
                        save_png(out / "images" / f"{name}_{method}_{grid}x{samples}.png", image)
            if not variant and (grid, samples) in config.gather_settings:
                for event in config.gather_events:
                    renderer.configure(gather_event=event)
                    for frames, image, *timing in _progressive(renderer, "probes",
                                                               config.gather_frames, 13, k):
                        record("probes", frames, image, timing, bake_ms + walk_light_ms,
                               light_ms=walk_light_ms, gather_event=event, **probe_info)
                renderer.configure(gather_event=1)
            if not variant and (grid, samples) in config.guided_settings:
                # the light grid is read by both of guided's levels: charged to it as well
                for frames, image, *timing in _progressive(renderer, "guided",
                                                           config.guided_frames, 19, k):
                    record("guided", frames, image, timing, bake_ms + light_ms,
                           light_ms=light_ms, **probe_info)
            steps = (config.sweep_raymarch_steps if not showcase or variant else
                     sorted({*config.sweep_raymarch_steps, *config.raymarch_steps}))
            stages = ("compute", "fragment") if showcase and not variant else ("compute",)
            for stage in stages:
                for step in (steps if stage == "compute" else (0.5,)):
                    renderer.configure(raymarch_stage=stage, raymarch_step=step)
                    for frames, image, *timing in _progressive(renderer, "raymarch",
                                                               config.raymarch_frames, 17, k):
                        # FLIP (CPU time) for the default step's images and the showcase's
                        record("raymarch", frames, image, timing, bake_ms + light_ms,
                               flip=step == 0.5 or showcase, raymarch_step=step, stage=stage,
                               light_ms=light_ms,
                               light_bytes=renderer.light_grid.gpu_bytes,
                               light_grid=list(renderer.light_grid.texture.size),
                               **probe_info)
                        if (showcase and not variant and stage == "compute" and step == 0.5
                                and frames == config.raymarch_frames[-1]):
                            save_png(out / "images" / f"{name}_raymarch_{grid}x{samples}.png", image)
            renderer.configure(raymarch_stage="compute", raymarch_step=0.5)
            last = {m: next(r for r in reversed(results.records) if r["method"] == m)
                    for m in (*PROBE_METHODS, "raymarch")}
            _log(f"  {grid}^3 x {samples} {variant or ''}: bake {bake_ms:.1f} ms, "
                 + ", ".join(f"{m} {r['frame_ms']:.3f} ms/frame rRMSE {r['rrmse']:.4f}"
                             for m, r in last.items()))
    renderer.set_scene(scene)
