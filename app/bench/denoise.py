"""`bench --preset denoise`: every noisy method raw and through the denoiser (app/rendering/denoise/filter.py)
with each set of guides, against the scene's path-traced reference.

Each snapshot of a progressive run (records.progressive: the path tracer, `probes` at its first
event and with a gather, `guided`) is recorded raw, then once per guide set of
`config.denoise_guides` as its denoised twin (`denoise` names the guides). Each twin runs the
flow the viewer and Renderer.denoise run (app/rendering/denoise/kept_means.py denoise_on_gl): the
snapshot, a host array here, is first written into a scratch RGBA32F texture (not charged: it
stands for the accumulation, which is in GL already), and the corrected image is read back from
its texture afterwards for the metrics (not charged: the viewer shows it from there). A twin's
total is the raw image's total plus everything the denoised image cost beyond it:
  - the guides' GPU time (glsl/denoise_guide_images.comp; for the "probes" guide the raymarched frames,
    and the bake and light grid of its probes where the method had not paid for them already);
  - the read-back of the image from GL into the filter's colour and the upload of the filter's
    output into a texture (io_ms);
  - the tile means kept: the GL passes (the raw image's tile means with their small read-back,
    and the restore: the filtered image's own means, the correction, the output made finite,
    and a ctx.finish; means_ms);
  - the filter's own wall time (OIDN's execute, synchronous; for a signed image its two runs),
    and the host check of its output (check_ms: 0 here, the restore pass does it).
The flow runs FLOW_REPEATS times on each snapshot and the twin is charged the run of median total
(a single run's wall time swung by up to 2 ms). Not charged: the denoiser's prepare_ms (here
mostly the guides' upload, which the bench repeats as it switches guide sets and a viewer makes
once a camera). filter_parts_ms keeps every part.
The raymarcher's images (noise-free already) are recorded raw beside them.

Also measured once a run (meta.denoise_cost): the whole cost of that flow at 512^2, 1920x1080
and 3840x2160 for each of OIDN's quality settings; and per scene, the denoiser's own bias (a
denoised image's mean against the raw one's, and its error at the longest run's samples against
the raw image's)."""
from __future__ import annotations

import statistics
import time

import numpy as np

from radiance_probes.frontend.imageio import save_png
from radiance_probes.methods import METHODS
from radiance_probes.rendering.denoise.filter import QUALITIES, shared_denoiser
from radiance_probes.rendering.denoise.kept_means import KeptMeans, denoise_on_gl
from radiance_probes.bench.records import (error_of, floor, header as _header, log, make_record,
                                           ms_text as _ms, progressive)

NOISY = ("pt", "probes", "guided")
COST_SIZES = ((512, 512), (1920, 1080), (3840, 2160))


def _with_probes(scene, grid: int, walks: int):
    from dataclasses import replace
    return scene.replace(probes=replace(scene.probes, grid=(grid, grid, grid), samples=walks))


def denoise_cost(renderer, sizes=COST_SIZES, qualities=QUALITIES, repeats: int = 5) -> list[dict]:
    """The whole cost of one denoised frame at each size and quality, guided by an albedo and a
    normal already on the filter's device (they change with the camera, not every frame), as
    Renderer.denoise and the viewer make it (kept_means.denoise_on_gl), each part in wall ms:
    readback_ms (GL straight into the filter's colour), the raw tile means' GL pass and its
    read-back (raw_means_ms), prepare_ms, filter_ms, check_ms (0: the restore pass checks),
    upload_result_ms (the output into an RGB32F texture), the restore passes with a ctx.finish
    (restore_ms); means_ms = raw_means_ms + restore_ms, and total_ms the whole flow. Medians of
    `repeats` after one untimed frame (which builds the filter and uploads the guides)."""
    from radiance_probes.rendering.methods.accumulation import Accumulation
    ctx = renderer.ctx
    rng = np.random.default_rng(0)
    kept = KeptMeans(ctx)
    rows = []
    try:
        for width, height in sizes:
            acc = Accumulation(ctx, width, height)
            acc.texture.write(rng.exponential(1.0, (height, width, 4)).astype(np.float32))
            result = kept.result_texture(width, height)
            albedo = np.full((height, width, 3), 0.5, np.float32)
            normal = np.zeros_like(albedo)
            normal[..., 2] = 1.0
            try:
                for quality in qualities:
                    denoiser = shared_denoiser("auto", quality)
                    staged = denoiser.staging(width, height, ("albedo", "normal"))
                    if staged is None:
                        return [{"note": denoiser.failure}]
                    parts = []
                    for i in range(repeats + 1):
                        ctx.finish()
                        t0 = time.perf_counter()
                        d = denoise_on_gl(kept, denoiser, acc.texture, staged, albedo, normal,
                                          False, result)
                        t1 = time.perf_counter()
                        if not d.denoised:
                            return [{"note": d.note}]
                        if i:
                            parts.append({**d.ms, **d.means_parts_ms,
                                          "total_ms": 1e3 * (t1 - t0)})
                    row = {"width": width, "height": height, "quality": quality,
                           "device": denoiser.device}
                    for k in parts[0]:
                        row[k] = statistics.median(p[k] for p in parts)
                    rows.append(row)
                    log(f"  denoise cost {width}x{height} {quality} on {denoiser.device}: "
                        f"filter {row['filter_ms']:.2f} ms, tile means (GL) "
                        f"{row['means_ms']:.2f} ms, total {row['total_ms']:.2f} ms")
            finally:
                acc.release()
    finally:
        kept.release()
    return rows


# Runs of the GL flow a denoised record times (the same image each run; the record is charged the
# run of median total)
FLOW_REPEATS = 3


def denoise_scene(renderer, name: str, config, results, out, device: str,
                  reference: np.ndarray) -> None:
    scene = renderer.scene
    base = {"scene": name, "device": device, "width": config.width, "height": config.height,
            "mode": "denoise",
            "reference_noise": results.references.get(name, {}).get("noise_rrmse")}
    denoiser = shared_denoiser("auto", config.denoise_quality)
    if not denoiser.available:
        raise SystemExit(f"bench --preset denoise: {denoiser.failure}")
    if "denoise_cost" not in results.meta and config.denoise_cost:
        results.meta["denoise_cost"] = denoise_cost(renderer)
    k = config.samples_per_dispatch

    # The "probes" guide at each of config.denoise_guide_probes (grid, walks), baked once each:
    # what a setting's bake cost is charged to every record whose method did not bake it itself.
    guides = {}   # guide set -> (albedo, normal, GPU ms)
    guide_bake_ms = {}
    for g in config.denoise_guides:
        settings = config.denoise_guide_probes if g == "probes" else ((0, 0),)
        for grid, walks in settings:
            guide = g if g != "probes" else f"probes {grid}x{walks}"
            if g == "probes":
                renderer.set_scene(_with_probes(scene, grid, walks))
                renderer.invalidate()
                guide_bake_ms[guide] = renderer.bake(seed=11) + renderer.bake_light()
            renderer.begin("raymarch")   # the scene's camera at the run's size
            guides[guide] = renderer.denoise_guides(g)
            log(f"  guides {guide}: {guides[guide][2]:.2f} ms")
    renderer.set_scene(scene)
    ctx = renderer.ctx
    kept = KeptMeans(ctx)
    source = ctx.texture((config.width, config.height), 4, dtype="f4")   # stands for the accumulation
    result = kept.result_texture(config.width, config.height)

    def denoise_charged(image: np.ndarray, albedo, normal, signed: bool):
        """The GL flow over `image`: (the corrected image, its Denoised)."""
        height, width = image.shape[:2]
        rgba = np.ones((height, width, 4), np.float32)
        rgba[..., :3] = image
        source.write(rgba)                       # not charged: the accumulation is in GL already
        names = tuple(n for n, g in (("albedo", albedo), ("normal", normal)) if g is not None)
        staged = denoiser.staging(width, height, names)
        runs = []
        for _ in range(FLOW_REPEATS):
            d = (denoise_on_gl(kept, denoiser, source, staged, albedo, normal, signed, result)
                 if staged is not None else None)
            if d is None or not d.denoised:
                raise SystemExit(f"bench --preset denoise: {denoiser.failure}")
            runs.append(d)
        # the run of median total: one run's wall time swung by 2 ms (a 1 ms restore read 2.6 ms
        # once, bench/h200-denoise), more than the flow's own parts differ between images
        d = sorted(runs, key=lambda r: r.ms["filter_ms"] + r.ms["means_ms"] + r.ms["readback_ms"]
                   + r.ms["upload_result_ms"])[len(runs) // 2]
        out = np.frombuffer(result.read(), np.float32).reshape(height, width, 4)   # not charged
        return out[..., :3].copy(), d

    # one untimed flow first: a driver may build a program at its first dispatch (llvmpipe took
    # 90 ms there), which the first record would otherwise pay
    denoise_charged(np.zeros((config.height, config.width, 3), np.float32), None, None, False)

    def add(method: str, frames: int, image: np.ndarray, timing, bake_ms: float,
            own_probes: tuple | None, **extra) -> None:
        rec = make_record(base, config, method, frames, image, reference, timing, bake_ms, **extra)
        flip = frames in config.flip_frames or frames == max(config.pt_spp)
        results.add(rec, image if flip else None, reference)
        for g, (albedo, normal, guide_ms) in guides.items():
            denoised, d = denoise_charged(image, albedo, normal, METHODS[method].signed)
            charged = guide_ms + (0.0 if g not in guide_bake_ms or own_probes == g
                                  else guide_bake_ms[g])
            io = d.ms["readback_ms"] + d.ms["upload_result_ms"]
            twin = make_record(base, config, method, frames, denoised, reference, timing, bake_ms,
                               **extra)
            twin.update(denoise=g, denoise_device=d.device, guides_ms=charged, io_ms=io,
                        filter_parts_ms={**d.ms, **d.means_parts_ms},
                        mean_ratio=float(denoised.mean() / max(image.mean(), 1e-30)))
            twin["total_ms"] = (rec["total_ms"] + charged + io + d.ms["filter_ms"]
                                + d.ms["check_ms"] + d.ms["means_ms"])
            results.add(twin, denoised if flip else None, reference)
            if frames == config.image_frames:
                save_png(out / "images" / f"{name}_{method}_{frames}_{g.replace(' ', '_')}.png",
                         denoised)
        if frames == config.image_frames:
            save_png(out / "images" / f"{name}_{method}_{frames}_raw.png", image)

    for frames, image, *timing in progressive(renderer, "pt", config.pt_spp, 5, k):
        add("pt", frames, image, timing, 0.0, None)
    flicker(renderer, name, config, results, guides, denoiser)
    log(f"  pt: {max(config.pt_spp)} spp")
    for (grid, walks), events, frames_list in (
            (config.denoise_probe_setting, (1,), config.probe_frames),
            (config.denoise_gather_setting, config.gather_events, config.gather_frames)):
        renderer.set_scene(_with_probes(scene, grid, walks))
        renderer.invalidate()
        bake_ms = renderer.bake(seed=11)
        own = f"probes {grid}x{walks}"
        for event in events:
            renderer.configure(gather_event=event)
            for frames, image, *timing in progressive(renderer, "probes", frames_list, 13, k):
                add("probes", frames, image, timing, bake_ms, own, probe_grid=grid,
                    probe_samples=walks, gather_event=event)
        renderer.configure(gather_event=1)
        log(f"  probes {grid}^3 x {walks}, events {events}")
    grid, walks = config.denoise_guided_setting
    renderer.set_scene(_with_probes(scene, grid, walks))
    renderer.invalidate()
    bake_ms = renderer.bake(seed=11) + renderer.bake_light()
    own = f"probes {grid}x{walks}"
    for frames, image, *timing in progressive(renderer, "guided", config.guided_frames, 19, k):
        add("guided", frames, image, timing, bake_ms, own, probe_grid=grid, probe_samples=walks)
    log(f"  guided {grid}^3 x {walks}")
    # the clean base: the raymarcher over the first guide setting's probes (raw only)
    grid, walks = config.denoise_guide_probes[0]
    renderer.set_scene(_with_probes(scene, grid, walks))
    renderer.invalidate()
    bake_ms = renderer.bake(seed=11) + renderer.bake_light()
    for frames, image, *timing in progressive(renderer, "raymarch", config.raymarch_frames, 17, k):
        rec = make_record(base, config, "raymarch", frames, image, reference, timing, bake_ms,
                          probe_grid=grid, probe_samples=walks)
        results.add(rec, image if frames in config.flip_frames else None, reference)
    renderer.set_scene(scene)
    source.release()
    kept.release()


def flicker(renderer, name: str, config, results, guides: dict, denoiser) -> None:
    """OIDN has no temporal mode: on a still camera, successive images of the same view (the path
    tracer's, independent seeds) differ, raw and denoised. Flicker = mean over pixels of the
    standard deviation over the images, over the mean image's mean (meta.denoise_flicker)."""
    rows = []
    for spp in config.denoise_flicker_spp:
        raw, filtered = [], {g: [] for g in guides}
        for i in range(config.denoise_flicker_frames):
            image = renderer.render("pt", spp=spp, seed=7000 + i).image
            raw.append(image)
            for g, (albedo, normal, _) in guides.items():
                filtered[g].append(denoiser(image, albedo, normal).image)

        def measure(images):
            stack = np.stack(images)
            return float(stack.std(axis=0).mean() / max(stack.mean(), 1e-30))
        rows.append({"spp": spp, "frames": config.denoise_flicker_frames, "raw": measure(raw),
                     **{g: measure(v) for g, v in filtered.items()}})
    results.meta.setdefault("denoise_flicker", {})[name] = rows


# ---- the report ---------------------------------------------------------------------------------
def variant(r: dict) -> str:
    name = r["method"]
    if r["method"] == "probes" and r.get("gather_event", 1) > 1:
        name = f"probes, gather {r['gather_event']}"
    if r["method"] in ("probes", "guided", "raymarch") and r.get("probe_grid"):
        name += f" {r['probe_grid']}^3x{r['probe_samples']}"
    return name + (f" + OIDN({r['denoise']})" if r.get("denoise") else "")


def _ms_or_dash(ms) -> str:
    """A cost part in ms; '-' where an older record did not time it apart."""
    return "-" if ms is None else f"{ms:.2f}"


def write_denoise_report(data: dict, out):
    meta = data["meta"]
    recs = data["records"]
    scenes = list(dict.fromkeys(r["scene"] for r in recs))
    targets = (0.05, 0.02, 0.01)
    lines = [*_header("# Denoised and raw: time to each error", meta),
             f"Image {meta['config']['width']}x{meta['config']['height']}. Errors are relative RMSE "
             "against the path-traced reference, corrected for its noise (SPEC.md), and mean "
             "LDR-FLIP where measured. A denoised record's total is its raw image's GPU total plus "
             "the guides' GPU time (and, for the probes guide, its probes' bake where the method "
             "did not bake them), the read-back from GL into the filter's colour, the filter's "
             "wall time (OIDN, synchronous), the upload of its output, and the tile means kept "
             "(newer records: the GL passes with a finish; older ones: host NumPy). The snapshot "
             "is written into a texture first and the result read back after, neither charged "
             "(the accumulation is in GL, the viewer shows the result from there); newer "
             "records charge the median of three runs of that flow. "
             "`OIDN(g)`: the filter guided by g (none: the colour "
             "alone; albedo and albedo-normal: glsl/denoise_guide_images.comp; probes: the raymarched "
             "probes as albedo).", ""]
    for s in scenes:
        rs = [r for r in recs if r["scene"] == s]
        lines += [f"## {s}", "", "| target | path tracer | best raw | best of all | speed-up over "
                  "the path tracer |", "|---|---|---|---|---|"]
        for t in targets:
            def best(pred):
                hits = [r for r in rs if pred(r) and error_of(data, r) <= t]
                return min(hits, key=lambda r: r["total_ms"]) if hits else None
            pt = best(lambda r: r["method"] == "pt" and not r.get("denoise"))
            raw = best(lambda r: not r.get("denoise"))
            top = best(lambda r: True)

            def cell(r):
                if r is None:
                    return "never"
                f = f", FLIP {r['flip']:.3f}" if r.get("flip") is not None else ""
                return f"{variant(r)} @ {r['spp']}: {_ms(r['total_ms'])}{f}"
            speed = (f"{pt['total_ms'] / top['total_ms']:.1f}x" if pt and top else
                     "path tracer never" if top else "-")
            lines.append(f"| {t:.0%} | {cell(pt)} | {cell(raw)} | {cell(top)} | {speed} |")
        lines += ["", "Every variant's error by samples (raw / denoised with each guide set):", ""]
        groups: dict[str, dict] = {}
        for r in rs:
            key = variant(dict(r, denoise=None))
            groups.setdefault(key, {}).setdefault(r["spp"], {})[r.get("denoise") or "raw"] = r
        guide_names = list(dict.fromkeys(r["denoise"] for r in rs if r.get("denoise")))
        cols = ["raw", *guide_names]
        lines += ["| variant | spp | " + " | ".join(cols) + " | total ms (raw; denoised) |",
                  "|---|---|" + "---|" * len(cols) + "---|"]
        for key, by_spp in groups.items():
            for spp in sorted(by_spp):
                row = by_spp[spp]
                vals = []
                for c in cols:
                    r = row.get(c)
                    if r is None:
                        vals.append("-")
                        continue
                    e = error_of(data, r)
                    v = f"{e:.4f}" if e >= floor(data, s) else f"<{floor(data, s):.4f}"
                    if r.get("flip") is not None:
                        v += f" (FLIP {r['flip']:.3f})"
                    vals.append(v)
                totals = "; ".join(_ms(row[c]["total_ms"]) for c in cols if c in row)
                lines.append(f"| {key} | {spp} | " + " | ".join(vals) + f" | {totals} |")
        flick = data["meta"].get("denoise_flicker", {}).get(s)
        if flick:
            names = [k for k in flick[0] if k not in ("spp", "frames")]
            lines += ["", f"Flicker on a still camera (the path tracer, {flick[0]['frames']} "
                      "independent images of the view: per-pixel standard deviation over them, "
                      "mean over the image, relative to its mean):", "",
                      "| spp | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
            for row in flick:
                lines.append(f"| {row['spp']} | " + " | ".join(f"{row[n]:.4f}" for n in names)
                             + " |")
        # the denoiser's own bias
        bias = [r for r in rs if r.get("denoise")]
        if bias:
            worst = max(bias, key=lambda r: abs(r["mean_ratio"] - 1.0))
            longest = max(r["spp"] for r in rs if r["method"] == "pt")
            raw_long = next((r for r in rs if r["method"] == "pt" and r["spp"] == longest
                             and not r.get("denoise")), None)
            lines += ["", f"Denoiser bias: the largest change of an image's mean by the filter is "
                      f"{100 * (worst['mean_ratio'] - 1):+.2f}% ({variant(worst)} @ {worst['spp']}). "
                      f"At {longest} spp the raw path tracer is at "
                      f"{error_of(data, raw_long):.4f}" if raw_long else ""]
            if raw_long:
                lines[-1] += ", denoised: " + ", ".join(
                    f"{r['denoise']} {error_of(data, r):.4f}" for r in rs
                    if r["method"] == "pt" and r["spp"] == longest and r.get("denoise")) + "."
        lines.append("")
    cost = meta.get("denoise_cost") or []
    if cost and "note" not in cost[0]:
        gl = "raw_means_ms" in cost[0]
        lines += ["## The denoiser's whole cost", "", "Wall ms, medians; guided by an albedo and a "
                  "normal. Read-back: an RGBA32F image from GL; upload: the result into a texture. "
                  + ("Tile means kept: the GL passes (the raw image's tile means and their "
                     "read-back, then the restore with a ctx.finish; the output check is that "
                     "pass)." if gl else "Tile means kept: host NumPy."),
                  "", "| size | quality | device | read-back into the filter's colour | "
                  "prepare | filter | output check | tile means kept | upload | total |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for c in cost:
            lines.append(f"| {c['width']}x{c['height']} | {c['quality']} | {c['device']} | "
                         f"{c['readback_ms']:.2f} | {c.get('prepare_ms', c.get('upload_ms', 0)):.2f} | "
                         f"{c['filter_ms']:.2f} | {c.get('check_ms', c.get('download_ms', 0)):.2f} | "
                         f"{_ms_or_dash(c.get('means_ms'))} | "
                         f"{c['upload_result_ms']:.2f} | {c['total_ms']:.2f} |")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    _plot(data, scenes, out / "denoise.png")
    return path


def _plot(data: dict, scenes: list[str], path) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    cols = min(3, len(scenes)) or 1
    rows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4 * rows), squeeze=False)
    for ax, s in zip(axes.flat, scenes):
        rs = [r for r in data["records"] if r["scene"] == s]
        series: dict[str, list] = {}
        for r in rs:
            series.setdefault(variant(r), []).append(r)
        for name, run in series.items():
            run = sorted(run, key=lambda r: r["total_ms"])
            xs = [r["total_ms"] for r in run]
            ys = [max(error_of(data, r), 1e-4) for r in run]
            ax.loglog(xs, ys, "-" if "OIDN" in name else "--", marker=".", label=name, lw=1)
        ax.set_title(s)
        ax.set_xlabel("total ms")
        ax.set_ylabel("rRMSE")
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=6)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
