"""refine shows the raymarcher's clean but biased image, then guided's (denoised) once the halves
say it is the better. Would a blend of the two, weighted by their errors as the halves estimate
them, be better than either while guided is still noisy?

For each guided sample count N: halves a and b of N/2 samples, their mean m, the raymarched image
R (the same probes), D(m) and D(a) through the denoiser (OIDN, the probes' image as guide where
choose_guides gives it). The blend B = (1 - w) R + w D(m), w from the halves alone
(refine.blend_from_sums' algebra, without its snap to 0 or 1: the three inner products of
R - b and D(a) - b, less b's noise). Errors:
rRMSE against a path-traced reference of REF_SPP samples, corrected for its noise; "best" is the
blend at the weight the reference would choose. CPU (llvmpipe, OIDN's CPU device):
    python lab/experiments/refine_blend.py OUT.json [scene] [size] [ref_spp] [probe_grid] [walks]
"""
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / ".pkg"))
from radiance_probes.bench.scenes import bench_scene                      # noqa: E402
from radiance_probes.gl.context import create_headless_context           # noqa: E402
from radiance_probes.rendering.denoise.filter import choose_guides, shared_denoiser  # noqa: E402
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse  # noqa: E402
from radiance_probes.rendering.renderer import Renderer                  # noqa: E402


def weight_from_halves(r, d_a, a, b, n_a, n_b):
    """w minimising E|(1 - w) R + w D - t|^2, each term estimated against the independent half b:
    E<X - b, Y - b> = <X - t, Y - t> + E|b - t|^2 for X, Y independent of b."""
    noise_b = n_a / (n_a + n_b) * np.mean((a - b) ** 2)
    e_rr = np.mean((r - b) ** 2) - noise_b
    e_dd = np.mean((d_a - b) ** 2) - noise_b
    e_rd = np.mean((r - b) * (d_a - b)) - noise_b
    den = e_rr + e_dd - 2.0 * e_rd
    w = (e_rr - e_rd) / den if den > 0 else 1.0
    return float(np.clip(w, 0.0, 1.0)), float(e_rr), float(e_dd), float(e_rd)


def main():
    out = Path(sys.argv[1])
    name = sys.argv[2] if len(sys.argv) > 2 else "bonsai"
    size = int(sys.argv[3]) if len(sys.argv) > 3 else 128
    ref_spp = int(sys.argv[4]) if len(sys.argv) > 4 else 4096
    grid = int(sys.argv[5]) if len(sys.argv) > 5 else 32
    walks = int(sys.argv[6]) if len(sys.argv) > 6 else 64
    scene = bench_scene(name, size, size)
    scene = scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks))
    ctx = create_headless_context()
    r = Renderer(ctx, scene)
    t = time.time()
    ra = r.render("pt", spp=ref_spp // 2, seed=1001).image
    rb = r.render("pt", spp=ref_spp // 2, seed=1002).image
    ref, noise = 0.5 * (ra + rb), reference_noise(ra, rb)
    print(f"reference {ref_spp} spp in {time.time() - t:.0f} s, noise {noise:.4f}", flush=True)
    ray = r.render("raymarch", spp=16, seed=7).image
    den = shared_denoiser("cpu")
    names = choose_guides("auto", 1, True)
    albedo, normal, _ = r.denoise_guides(names, camera=r.camera)

    def err(img):
        return corrected_rrmse(rrmse(img, ref), noise)

    rows = []
    for n in (2, 4, 8, 16, 32, 64, 128):
        a = r.render("guided", spp=n // 2, seed=11 + n).image
        b = r.render("guided", spp=n // 2, seed=5000 + n).image
        m = 0.5 * (a + b)
        d_m = den(m, albedo, normal, signed=True).image
        d_a = den(a, albedo, normal, signed=True).image
        w, e_rr, e_dd, e_rd = weight_from_halves(ray, d_a, a, b, n // 2, n // 2)
        blend = (1 - w) * ray + w * d_m
        ws = np.linspace(0, 1, 101)
        best = min(ws, key=lambda x: rrmse((1 - x) * ray + x * d_m, ref))
        t2 = float(np.mean(ref) ** 2)
        row = {"scene": name, "size": size, "spp": n, "weight": w, "best_weight": float(best),
               "raymarch": err(ray), "raw": err(m), "denoised": err(d_m),
               "denoised_half": err(d_a), "blend": err(blend),
               "best_blend": err((1 - best) * ray + best * d_m),
               "est_raymarch": float(np.sqrt(max(e_rr, 0) / t2)),
               "est_denoised_half": float(np.sqrt(max(e_dd, 0) / t2)),
               "error_correlation": float(e_rd / np.sqrt(max(e_rr * e_dd, 1e-30)))}
        rows.append(row)
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}),
              flush=True)
        out.write_text(json.dumps({"reference_spp": ref_spp, "reference_noise": noise,
                                   "probe_grid": grid, "walks": walks, "rows": rows}, indent=1))
    r.release()


if __name__ == "__main__":
    main()
