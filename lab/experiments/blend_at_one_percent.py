"""At 1% on bonsai the denoiser gains only 2x over the path tracer (bench/h200-denoise: pt +
OIDN 1.12% at 1024 samples, 0.93% at 2048; the raw path tracer 1.05% at 2048, 0.74% at 4096):
the filter's blur is then most of its error. Does refine's blend (app/rendering/refine/refine.py:
(1 - w) r + w D(m), w from the halves alone) of a fine raymarcher r (clean, biased ~2%) with the
denoised path tracer reach 1% sooner, its errors being nearly independent at few samples?

For each sample count N: the path tracer in halves a, b of N/2 (m their mean), D(m) and D(a)
through OIDN (colour alone), w = blend_from_sums's weight, and the blend; r the raymarcher at
each probe setting (bake and 64 frames). Errors: rRMSE against a REF_SPP reference, corrected for
its noise; "best" the weight the reference would choose; cost: GPU ms of bake, frames and
samples, wall ms of each filter run (GPU: OIDN's CUDA device). GUIDE "probes": the filter
guided by each setting's raymarched image as its albedo (radiance_as_albedo, the bench's "probes"
guide; the same image is r), so D(m) and D(a) are made once per setting; "none" (default): the
colour alone.
    python lab/experiments/blend_at_one_percent.py OUT.json [scene] [size] [ref_spp] [N,N] [G:W,G:W]
        [GUIDE]
"""
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / ".pkg"))
from radiance_probes.bench.scenes import bench_scene                      # noqa: E402
from radiance_probes.gl.context import create_headless_context           # noqa: E402
from radiance_probes.rendering.denoise.filter import (radiance_as_albedo, shared_denoiser)  # noqa: E402
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse  # noqa: E402
from radiance_probes.rendering.refine.refine import (blend_from_sums, blend_images,  # noqa: E402
                                                     half_buffer_sums, judge_sums)
from radiance_probes.rendering.renderer import Renderer                  # noqa: E402


def reference(r, ref_spp: int):
    """The path tracer's reference (two halves of ref_spp / 2 samples) and its noise, printed."""
    halves = [r.render("pt", spp=ref_spp // 2, seed=1001 + i, samples_per_pass=64).image
              for i in range(2)]
    ref, noise = 0.5 * (halves[0] + halves[1]), reference_noise(*halves)
    print(f"reference {ref_spp} spp, noise {noise:.4f}", flush=True)
    return ref, noise


def timed_filter(den):
    """filtered(image, albedo=None) -> (the denoised image, the run's wall ms); exits where the
    filter did not run (it would hand back the raw image, recorded as denoised)."""
    def filtered(img, albedo=None):
        t0 = time.perf_counter()
        d = den(np.asarray(img, np.float32), albedo)
        if not d.denoised:
            raise SystemExit(f"the filter did not run: {d.note}")
        return d.image, 1e3 * (time.perf_counter() - t0)
    return filtered


def pt_halves(r, n: int):
    """The path tracer's two independent halves of n / 2 samples each (their renders)."""
    return (r.render("pt", spp=n // 2, seed=11 + n, samples_per_pass=16),
            r.render("pt", spp=n // 2, seed=5000 + n, samples_per_pass=16))


def open_run(default_counts: str) -> SimpleNamespace:
    """The command line the one-percent experiments share (OUT.json [scene] [size] [ref_spp]
    [N,N], each script's own arguments after) and what each sets up from it: the scene, its
    renderer `r`, the reference and its noise, the warmed filter `den`, `filtered` (timed_filter)
    and `err` (an image's rRMSE against the reference, corrected for its noise)."""
    name = sys.argv[2] if len(sys.argv) > 2 else "bonsai"
    size = int(sys.argv[3]) if len(sys.argv) > 3 else 512
    ref_spp = int(sys.argv[4]) if len(sys.argv) > 4 else 16384
    counts = [int(v) for v in (sys.argv[5] if len(sys.argv) > 5 else default_counts).split(",")]
    scene = bench_scene(name, size, size)
    r = Renderer(create_headless_context(), scene)
    ref, noise = reference(r, ref_spp)
    den = shared_denoiser()
    den.warm(size, size)

    def err(img):
        return corrected_rrmse(rrmse(img, ref), noise)
    return SimpleNamespace(out=Path(sys.argv[1]), name=name, size=size, ref_spp=ref_spp,
                           counts=counts, scene=scene, r=r, ref=ref, noise=noise, den=den,
                           filtered=timed_filter(den), err=err)


def write_row(out: Path, rows: list, row: dict, ref_spp: int, noise: float) -> None:
    """Adds a row, prints it (rounded) and writes every row so far."""
    rows.append(row)
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}),
          flush=True)
    out.write_text(json.dumps({"reference_spp": ref_spp, "reference_noise": noise, "rows": rows},
                              indent=1))


def main():
    run = open_run("256,512,1024")
    out, name, size, ref_spp, noise = run.out, run.name, run.size, run.ref_spp, run.noise
    r, scene, ref, filtered, err = run.r, run.scene, run.ref, run.filtered, run.err
    settings = [tuple(int(x) for x in v.split(":"))
                for v in (sys.argv[6] if len(sys.argv) > 6 else "64:128,128:64").split(",")]
    guide = sys.argv[7] if len(sys.argv) > 7 else "none"
    run.den.warm(size, size, ("albedo",))

    rays = []
    for grid, walks in settings:
        r.set_scene(scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks)))
        r.render("raymarch", spp=4, seed=5)    # compiles
        r.invalidate()
        res = r.render("raymarch", spp=64, seed=7)
        rays.append({"grid": grid, "walks": walks, "image": res.image,
                     "ms": res.bake_ms + res.render_ms, "error": err(res.image)})
        print(f"raymarch {grid}^3 x {walks}: {rays[-1]['ms']:.0f} ms, {rays[-1]['error']:.4f}",
              flush=True)
    r.set_scene(scene)
    rows = []
    for n in run.counts:
        ra, rb = pt_halves(r, n)
        a, b = ra.image, rb.image
        m = 0.5 * (a + b)
        pt_ms = ra.render_ms + rb.render_ms
        if guide == "none":
            d_m, ms_m = filtered(m)
            d_a, ms_a = filtered(a)
        for ray in rays:
            if guide == "probes":
                albedo = radiance_as_albedo(ray["image"])
                d_m, ms_m = filtered(m, albedo)
                d_a, ms_a = filtered(a, albedo)
            got = blend_from_sums(half_buffer_sums(a, b, n // 2, n // 2),
                                  judge_sums(d_a, b, ray["image"]), n // 2, n // 2)
            blend = blend_images(ray["image"], d_m, got.weight)
            ws = np.linspace(0.0, 1.0, 51)
            best = min(ws, key=lambda w: rrmse(blend_images(ray["image"], d_m, w), ref))
            row = {"scene": name, "size": size, "spp": n, "guide": guide, "probe_grid": ray["grid"],
                   "probe_walks": ray["walks"], "raw": err(m), "denoised": err(d_m),
                   "raymarch": ray["error"], "blend": err(blend), "weight": got.weight,
                   "best_weight": float(best),
                   "best_blend": err(blend_images(ray["image"], d_m, best)),
                   "pt_ms": pt_ms, "raymarch_ms": ray["ms"], "filter_ms": ms_m, "judge_ms": ms_a,
                   "denoised_total_ms": pt_ms + ms_m,
                   "blend_total_ms": pt_ms + ray["ms"] + ms_m + ms_a}
            write_row(out, rows, row, ref_spp, noise)
    r.release()


if __name__ == "__main__":
    main()
