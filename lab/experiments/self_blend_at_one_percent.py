"""At 1% on bonsai the filter removes little: the path tracer raw 1.05% at 2048 samples, denoised
0.93% (bench/h200-denoise). Its error is then mostly the filter's blur, which is nearly independent
of the raw image's noise. Does a blend of the raw mean m with its own denoised image, (1 - w) m +
w D(m), reach 1% sooner?

For each sample count N: halves a, b of N/2 (m their mean), D(m) and D(a) through OIDN (colour
alone). Weights: "best", the one the reference chooses (the most any global weight can give);
"halves", <a - b, a - D(a)> / |a - D(a)|^2, whose numerator is in expectation <a - x, a - D(a)>
for the exact image x (b is independent of a): the best weight for half the samples, which errs
high for m (less noise: less to take away). Errors: rRMSE against a REF_SPP reference, corrected
for its noise. Cost: the path tracer's GPU ms and the wall ms of each filter run.
    python lab/experiments/self_blend_at_one_percent.py OUT.json [scene] [size] [ref_spp] [N,N]
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / ".pkg"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from blend_at_one_percent import open_run, pt_halves, write_row  # noqa: E402
from radiance_probes.rendering.metrics import rrmse                      # noqa: E402
from radiance_probes.rendering.refine.refine import blend_images                # noqa: E402


def main():
    run = open_run("512,1024,2048")
    r, ref, filtered, err = run.r, run.ref, run.filtered, run.err
    rows = []
    for n in run.counts:
        ra, rb = pt_halves(r, n)
        a, b = ra.image.astype(np.float64), rb.image.astype(np.float64)
        m = 0.5 * (a + b)
        d_m, ms_m = filtered(m)
        d_a, ms_a = filtered(a)
        u = a - d_a
        w_halves = float(np.sum((a - b) * u) / np.sum(u * u))
        ws = np.linspace(0.0, 1.0, 101)
        best = float(min(ws, key=lambda w: rrmse(blend_images(d_m, m, 1 - w), ref)))
        row = {"scene": run.name, "size": run.size, "spp": n, "raw": err(m), "denoised": err(d_m),
               "best_weight": best, "best_blend": err(blend_images(d_m, m, 1 - best)),
               "halves_weight": w_halves,
               "halves_blend": err(blend_images(d_m, m, 1 - min(max(w_halves, 0), 1))),
               "error_correlation": float(np.sum((m - ref) * (d_m - ref))
                                          / np.sqrt(np.sum((m - ref) ** 2)
                                                    * np.sum((d_m - ref) ** 2))),
               "pt_ms": ra.render_ms + rb.render_ms, "filter_ms": ms_m, "judge_ms": ms_a}
        write_row(run.out, rows, row, run.ref_spp, run.noise)
    r.release()


if __name__ == "__main__":
    main()
