"""`bench --preset movie`: a turntable movie timed from the bake to the last encoded frame, its
per-frame error against path-traced references of a few of its frames, and the path tracer's
time for the same frames at the same error.

One record per scene:
- the movie (app/movie/frames.py), rendered by a fresh Renderer after an untimed warm-up (shader
  compiles): wall-clock seconds in all (bake, every frame, the GPU tone map, read-back and the
  MP4 encoder's tail), the bake's and the frames' GPU ms, the probes baked once, and the frames
  ffmpeg decodes back from the file;
- at each check frame: a path-traced reference in two independent halves (their difference
  measures its noise), the movie frame's relative RMSE against it corrected for that noise
  (metrics.corrected_rrmse), and the path tracer's samples and GPU ms to reach the same error
  in one progressive run (snapshots at powers of two, and the 1/sqrt(spp) estimate between the
  last two);
- the path tracer's movie: the frames times its mean GPU time per check frame at the movie's
  error (GPU only: no bake, no read-back, no encoding), beside the movie's wall time.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.movie.frames import render_movie
from radiance_probes.movie.writer import MovieWriter, count_frames
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.records import log


def _reference(renderer, camera, config) -> tuple[np.ndarray, float, float]:
    """(image, relative noise, GPU ms) of the path tracer at config.movie_ref_spp in two halves."""
    scene = renderer.scene
    renderer.set_scene(scene.replace(camera=camera))
    halves, ms = [], 0.0
    try:
        for seed in (1_000_003, 2_000_003):
            r = renderer.render("pt", spp=config.movie_ref_spp // 2, seed=seed,
                                samples_per_pass=config.ref_samples_per_pass)
            halves.append(r.image)
            ms += r.render_ms
    finally:
        renderer.set_scene(scene)
    return 0.5 * (halves[0] + halves[1]), reference_noise(*halves), ms


def _pt_to_error(renderer, camera, reference, noise, target: float, config) -> dict:
    """The path tracer's samples and GPU ms to reach `target` (corrected relative RMSE) at this
    camera: one progressive run with snapshots at powers of two up to config.movie_pt_max_spp."""
    scene = renderer.scene
    renderer.set_scene(scene.replace(camera=camera))
    try:
        acc = renderer.begin("pt", seed=77)
        ms, spp, previous = 0.0, 1, None
        while True:
            while acc.samples < spp:
                ms += renderer.add_samples(min(config.samples_per_dispatch, spp - acc.samples))
            err = corrected_rrmse(rrmse(acc.read(), reference), noise)
            if err <= target or spp >= config.movie_pt_max_spp:
                estimate = spp
                if previous is not None and err <= target and previous[1] > target:
                    # error ~ 1/sqrt(spp) between the last two snapshots
                    estimate = max(previous[0], previous[0] * (previous[1] / target) ** 2)
                per_spp = ms / spp
                return {"spp": spp, "error": err, "gpu_ms": ms, "reached": err <= target,
                        "spp_estimate": estimate, "gpu_ms_estimate": per_spp * estimate}
            previous = (spp, err)
            spp *= 2
    finally:
        renderer.set_scene(scene)


def movie_scene(renderer, name: str, config, results, out: Path, device: str) -> None:
    from radiance_probes.scene.camera_path import turntable
    from radiance_probes.rendering.renderer import Renderer
    scene = renderer.scene
    grid, walks = config.movie_probes
    scene = scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks))
    cameras = turntable(scene.camera, config.movie_degrees, config.movie_frames)
    check = [i for i in config.movie_check_frames if i < len(cameras)]
    # warm-up, not timed: the shaders compile and the GPU clocks up
    warm = Renderer(renderer.ctx, scene, renderer.resources.volume, renderer.settings)
    try:
        render_movie(warm, cameras[:2], None, "raymarch", config.movie_spp)
    finally:
        warm.release()
    movie_path = out / f"{name}_movie.mp4"
    timed = Renderer(renderer.ctx, scene, renderer.resources.volume, renderer.settings)
    try:
        start = time.perf_counter()   # from the encoder's start to its last frame written
        writer = MovieWriter(str(movie_path), scene.camera.width, scene.camera.height,
                             fps=config.movie_fps)
        movie = render_movie(timed, cameras, writer, "raymarch", config.movie_spp,
                             samples_per_pass=config.movie_spp, keep=tuple(check))
        movie.wall_s = time.perf_counter() - start
        probes = timed.probe_grid
        probe_info = {"probe_grid": list(probes.grid), "probe_samples": probes.samples,
                      "probe_box": probes.box, "light_grid": list(timed._light.texture.size)}
    finally:
        timed.release()
    decoded = count_frames(movie_path)
    log(f"  movie: {movie.summary()}; ffmpeg reads {decoded} frames")
    frames = []
    renderer.set_scene(scene)
    for index in check:
        reference, noise, ref_ms = _reference(renderer, cameras[index], config)
        image = movie.kept[index]
        measured = rrmse(image, reference)
        error = corrected_rrmse(measured, noise)
        save_png(out / "images" / f"{name}_movie_frame{index:03d}.png", image)
        save_png(out / "images" / f"{name}_movie_frame{index:03d}_reference.png", reference)
        pt = _pt_to_error(renderer, cameras[index], reference, noise,
                          error if error > 0 else measured, config)
        frames.append({"frame": index, "rrmse": error, "rrmse_measured": measured,
                       "reference_spp": config.movie_ref_spp, "reference_noise": noise,
                       "reference_gpu_ms": ref_ms, "pt": pt})
        log(f"  frame {index}: rRMSE {error:.4f} (reference noise {noise:.4f}); the path tracer "
            f"reaches it at {pt['spp']} spp ({pt['gpu_ms']:.1f} ms GPU; estimate "
            f"{pt['spp_estimate']:.0f} spp, {pt['gpu_ms_estimate']:.1f} ms)")
    errors = [f["rrmse"] for f in frames]
    pt_frame_ms = float(np.mean([f["pt"]["gpu_ms_estimate"] for f in frames])) if frames else math.nan
    pt_movie_s = pt_frame_ms * movie.frames / 1000.0
    record = {
        "mode": "movie", "scene": name, "device": device, "width": scene.camera.width,
        "height": scene.camera.height, "method": "raymarch", "frames": movie.frames,
        "degrees": config.movie_degrees, "spp_per_frame": config.movie_spp, **probe_info,
        "movie_path": str(movie_path), "movie_bytes": movie_path.stat().st_size,
        "frames_decoded": decoded, "total_s": movie.wall_s, "bake_ms": movie.bake_ms,
        "bakes": movie.bakes, "render_ms": movie.render_ms,
        "render_ms_per_frame": movie.render_ms / max(movie.frames, 1),
        "check_frames": frames, "max_rrmse": max(errors) if errors else None,
        "target_rrmse": config.movie_target,
        "within_target": bool(errors) and max(errors) <= config.movie_target,
        "pt_frame_gpu_ms_at_same_error": pt_frame_ms, "pt_movie_gpu_s_at_same_error": pt_movie_s,
        "speedup_vs_pt": pt_movie_s / movie.wall_s if movie.wall_s > 0 else None,
        # GPU time alone, the path tracer's measure: bake and frames
        "gpu_s": (movie.bake_ms + movie.render_ms) / 1000.0,
    }
    results.add(record)
    log(f"  {name}: {movie.frames} frames in {movie.wall_s:.2f} s (bake {movie.bake_ms:.1f} ms GPU), "
        f"worst check frame {record['max_rrmse']:.4f}; the path tracer at the same error: "
        f"{pt_movie_s:.2f} s GPU")


def write_movie_report(data: dict, out: Path) -> Path:
    """report.md of a movie run: one table row per scene, then its check frames."""
    meta = data["meta"]
    lines = ["# Movie: a turntable raymarched over probes baked once", "",
             f"Device: **{meta['device']}**. Command: `{meta.get('command', '')}`.", "",
             "Time is the whole movie on the host's clock (bake, frames, GPU tone map, read-back, "
             "MP4 encoding); errors are relative RMSE against path-traced references of the check "
             "frames, corrected for the references' noise; the path tracer's time is its GPU time "
             "per frame to the same error (mean over the check frames) times the frames.", "",
             "| scene | size | frames | spp/frame | probes | total s | GPU s | bake ms | worst "
             "frame rRMSE | path tracer GPU s at that error | speed-up (total; GPU) | frames "
             "decoded |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in data["records"]:
        worst = r["max_rrmse"]
        lines.append(
            f"| {r['scene']} | {r['width']}x{r['height']} | {r['frames']} | {r['spp_per_frame']} | "
            f"{'x'.join(map(str, r['probe_grid']))} x {r['probe_samples']} | {r['total_s']:.2f} | "
            f"{r['gpu_s']:.2f} | {r['bake_ms']:.1f} | {worst:.4f} | "
            f"{r['pt_movie_gpu_s_at_same_error']:.2f} | {r['speedup_vs_pt']:.1f}x; "
            f"{r['pt_movie_gpu_s_at_same_error'] / max(r['gpu_s'], 1e-9):.1f}x | "
            f"{r['frames_decoded']} |")
    for r in data["records"]:
        lines += ["", f"## {r['scene']}: check frames", "",
                  "| frame | rRMSE | reference spp (noise) | path tracer spp to reach it | GPU ms |",
                  "| --- | --- | --- | --- | --- |"]
        for f in r["check_frames"]:
            pt = f["pt"]
            reached = "" if pt["reached"] else " (not reached)"
            lines.append(f"| {f['frame']} | {f['rrmse']:.4f} | {f['reference_spp']} "
                         f"({f['reference_noise']:.4f}) | {pt['spp']} (est. "
                         f"{pt['spp_estimate']:.0f}){reached} | {pt['gpu_ms_estimate']:.1f} |")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
