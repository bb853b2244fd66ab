"""Past a few hundred samples the denoiser's own error (blurred detail) is what is left, and at
1% on bonsai it gains only 2x over the raw path tracer (bench/h200-denoise). Does a blend of the
raw image and the denoised one do better, with the blend weight estimated from the image alone?

For each sample count N: two independent halves a and b of N/2 samples, their mean m, and D(m)
through the denoiser (OIDN, the colour alone, tile means kept). Per 32-pixel tile, the raw
mean's noise s2 = mean((a - b)^2) / 4 and the denoised image's error e2, estimated from D(a)
against the independent half b (refine.blend_from_sums' algebra per tile: mean((D(a) - b)^2)
- mean((a - b)^2) / 2), scaled by 1/2 to stand for D(m)'s; the blend alpha D(m) + (1 - alpha) m with
alpha = s2 / (s2 + e2) per tile (as if the two errors were independent), interpolated smoothly
between tiles as the kept means are. Errors: rRMSE against a reference of REF_SPP samples,
corrected for its noise. CPU (llvmpipe, OIDN's CPU device):
    python lab/experiments/denoise_blend.py OUT.json [scene] [size] [ref_spp]
"""
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from radiance_probes.bench.scenes import bench_scene                      # noqa: E402
from radiance_probes.gl.context import create_headless_context           # noqa: E402
from radiance_probes.rendering.denoise.filter import (KEEP_MEANS_BLOCK, KEEP_MEANS_CELL,
                                                      _block_means, _cell_field, shared_denoiser)  # noqa: E402
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse  # noqa: E402
from radiance_probes.rendering.renderer import Renderer                  # noqa: E402


def tile_blend(m, d_m, a, b, d_a):
    h, w, _ = m.shape
    s2 = _block_means((a - b) ** 2 / 4.0, KEEP_MEANS_BLOCK)
    e2_half = _block_means((d_a - b) ** 2 - (a - b) ** 2 / 2.0, KEEP_MEANS_BLOCK)
    e2 = np.maximum(e2_half, 0.0) / 2.0
    alpha = s2 / np.maximum(s2 + e2, 1e-30)
    field = _cell_field(alpha, h, w, KEEP_MEANS_BLOCK, KEEP_MEANS_CELL)
    full = np.repeat(np.repeat(field, KEEP_MEANS_CELL, 0), KEEP_MEANS_CELL, 1)[:h, :w]
    return full * d_m + (1.0 - full) * m, float(alpha.mean())


def main():
    out = Path(sys.argv[1])
    name = sys.argv[2] if len(sys.argv) > 2 else "bonsai"
    size = int(sys.argv[3]) if len(sys.argv) > 3 else 96
    ref_spp = int(sys.argv[4]) if len(sys.argv) > 4 else 8192
    ctx = create_headless_context()
    r = Renderer(ctx, bench_scene(name, size, size))
    t = time.time()
    ra = r.render("pt", spp=ref_spp // 2, seed=1001).image
    rb = r.render("pt", spp=ref_spp // 2, seed=1002).image
    ref, noise = 0.5 * (ra + rb), reference_noise(ra, rb)
    print(f"reference {ref_spp} spp in {time.time() - t:.0f} s, noise {noise:.4f}", flush=True)
    den = shared_denoiser("cpu")
    rows = []
    for n in (16, 64, 256, 1024, 2048):
        a = r.render("pt", spp=n // 2, seed=11 + n).image
        b = r.render("pt", spp=n // 2, seed=12 + n).image
        m = 0.5 * (a + b)
        d_m = den(m).image
        d_a = den(a).image
        blend, alpha = tile_blend(m, d_m, a, b, d_a)
        row = {"scene": name, "size": size, "spp": n, "alpha_mean": alpha,
               **{k: corrected_rrmse(rrmse(img, ref), noise)
                  for k, img in (("raw", m), ("denoised", d_m), ("blend", blend))}}
        rows.append(row)
        print(json.dumps(row), flush=True)
        out.write_text(json.dumps({"reference_spp": ref_spp, "reference_noise": noise,
                                   "rows": rows}, indent=1))
    r.release()


if __name__ == "__main__":
    main()
