"""Where a sample's variance comes from on a scene that refine cannot bring to 2% in time (the chest
CT with `ct_bone` under a sphere light: lab/experiments/refine_floor.py found its denoised error
sample-bound, 2.35% at guided's 256 samples, the denoiser 1.2-1.6x below the raw image).

The path tracer (and `guided`) render K independent images of S samples a pixel of the scene as
it is and of parts of it: one light source at a time (the sphere lights alone, the sun alone, the
environment alone) and the paths cut at 1 or 2 scattering events. Each row's
    v = S * sum over pixels of var_k(image_k) / sum over pixels of mean(full image)^2
is one sample's squared rRMSE measured against the whole scene's image, so the parts' v add up
to about the whole's where their noise is independent; with ms a sample, 1 / (v * ms) is the
efficiency (None for a part the scene lacks: its area lights where it has none; records made
before that say 1e30 there). Also each row's image mean over the whole scene's.
    python lab/experiments/chest_variance.py OUT.json [scene] [width] [height] [S] [K]
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
from radiance_probes.rendering.renderer import Renderer                  # noqa: E402

PROBES = (128, 64)      # the replay's probe grid and walks


def main():
    out = Path(sys.argv[1])
    name = sys.argv[2] if len(sys.argv) > 2 else "chest"
    width = int(sys.argv[3]) if len(sys.argv) > 3 else 1920
    height = int(sys.argv[4]) if len(sys.argv) > 4 else 1080
    spp = int(sys.argv[5]) if len(sys.argv) > 5 else 32
    count = int(sys.argv[6]) if len(sys.argv) > 6 else 4
    full = bench_scene(name, width, height)
    full = full.replace(probes=replace(full.probes, grid=(PROBES[0],) * 3, samples=PROBES[1]))
    dark = (0.0, 0.0, 0.0)
    parts = {
        "all": full,
        "area_lights_only": full.replace(light=replace(full.light, irradiance=dark),
                                         environment=dark),
        "sun_only": full.replace(area_lights=(), environment=dark),
        "environment_only": full.replace(area_lights=(),
                                         light=replace(full.light, irradiance=dark)),
        "area_lights_bounces_1": full.replace(light=replace(full.light, irradiance=dark),
                                              environment=dark, max_bounces=1),
        "bounces_1": full.replace(max_bounces=1),
        "bounces_2": full.replace(max_bounces=2),
    }
    rows, norm = [], None
    ctx = create_headless_context()
    for key, scene in parts.items():
        r = Renderer(ctx, scene)
        for method in (("pt", "guided") if key == "all" else ("pt",)):
            images, ms = [], 0.0
            t0 = time.perf_counter()
            for k in range(count):
                res = r.render(method, spp=spp, seed=101 + 7919 * k, samples_per_pass=8)
                images.append(np.asarray(res.image, np.float64)[..., :3])
                ms += res.render_ms
            stack = np.stack(images)
            mean = stack.mean(axis=0)
            if norm is None:
                norm = (float(np.sum(mean ** 2)), float(mean.mean()))
            v = float(spp * np.sum(stack.var(axis=0, ddof=1)) / norm[0])
            ms_sample = ms / (count * spp)
            rows.append({"part": key, "method": method, "v": v, "ms_per_sample": ms_sample,
                         # None where the part is empty (a scene with no area light)
                         "efficiency": 1.0 / (v * ms_sample) if v > 0.0 else None,
                         "mean_over_all": float(mean.mean()) / norm[1],
                         "rrmse_at_256": float(np.sqrt(v / 256)),
                         "wall_s": time.perf_counter() - t0})
            print(json.dumps({k: round(x, 5) if isinstance(x, float) else x
                              for k, x in rows[-1].items()}), flush=True)
        r.release()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"scene": name, "size": [width, height], "spp": spp, "images": count,
                               "probes": PROBES, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
