"""Probes with a lobe about the sun's direction beside their SH bands (lib/sun_lobe.glsl) against
the same probes without it (bench/h100-sun-lobe): the bench's g = 0.8 cloud at 512^2, and the
same with other phase functions, lights and albedos; order 3, raymarched 16 frames, against two
path-traced halves; error corrected for the reference's noise, rim = the brightest tenth of the
reference's pixels (image / reference there, its share of the squared error), bake and frame ms.
Usage (GPU): python lab/experiments/experiment_sun_lobe.py OUT.json SETTINGS REFERENCE_SPP_PER_HALF LOBES
[CHANGES ...]
  SETTINGS  GRIDxWALKS,...   e.g. 128x256,64x512
  LOBES     lobe g = (scene's g)^p for each p, 0 for none, "auto" for the shape the pilot chooses
            (lab/sun_lobe_fit.py); e.g. 0,3,auto (the bands above the order extrapolated
            from the top two instead were measured too: bench/h100-sun-lobe)
  CHANGES   scene changes as JSON, each its own scene: '{"anisotropy": 0.9}',
            '{"light": [1, 0.2, 0]}' (the sun's direction), '{"albedo": 0.8}', and probe
            settings '{"probes": {"layout": "adaptive", "adaptive_indicator": "sun"}}'"""
import json
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, ".")
import radiance_probes.rendering.probes.layout as layout_module
from lab.sun_lobe_fit import SunLobeFitter
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

out_path = sys.argv[1]
settings = [tuple(int(v) for v in s.split("x")) for s in sys.argv[2].split(",")]
half_spp = int(sys.argv[3])
lobes = [p if p == "auto" else float(p) for p in sys.argv[4].split(",")]
changes = [json.loads(a) for a in sys.argv[5:]] or [{}]
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
bench = bench_scene("anisotropic", 512, 512)
volume = load_volume(bench.volume, bench.base_dir)
rows = []
for n_change, change in enumerate(changes):
    base = bench
    if "anisotropy" in change:
        base = base.replace(anisotropy=float(change["anisotropy"]))
    if "light" in change:
        d = np.asarray(change["light"], float)
        base = base.replace(light=replace(base.light, direction=tuple(d / np.linalg.norm(d))))
    if "albedo" in change:
        base = base.replace(albedo=float(change["albedo"]))
    r = Renderer(ctx, base, volume)
    halves = [r.render("pt", spp=half_spp, seed=s, samples_per_pass=16).image
              for s in (1000003, 2000003)]
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    rows.append(dict(label="reference", change=change, spp=2 * half_spp, noise=noise))
    ref = reference[..., :3].astype(np.float64)
    lum = ref @ np.array([0.2126, 0.7152, 0.0722])
    rim = lum >= np.quantile(lum, 0.9)
    for grid, walks in settings:
        for lobe in lobes:
            s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks, sh_order=3,
                                            **change.get("probes", {})))
            auto = lobe == "auto"
            layout_module.SUN_LOBE_POWER = 3.0 if auto else lobe
            layout_module.SUN_LOBE_MIN_G = 0.0
            r.configure(sun_lobe=auto or lobe > 0)
            r.set_scene(s)
            fit = None
            if auto:   # the pilot's choice (it was RenderSettings.sun_lobe_fit), its time the bake's
                fitter = SunLobeFitter(ctx)
                fit = fitter.fit_for(r, seed=11)
                fitter.release()
                layout_module.SUN_LOBE_POWER = fit.power
            r.invalidate()
            r.bake(seed=11)
            r.invalidate()
            bake_ms = r.bake(seed=11) + (fit.gpu_ms if fit is not None else 0.0)
            res = r.render("raymarch", spp=16, seed=11, samples_per_pass=16)
            img = res.image[..., :3].astype(np.float64)
            sq = ((img - ref) ** 2).sum(axis=-1)
            e = rrmse(res.image, reference)
            row = dict(change=change, grid=grid, walks=walks, sun_lobe=lobe, rrmse=e,
                       rrmse_corrected=corrected_rrmse(e, noise),
                       rim_ratio=float(img[rim].mean() / ref[rim].mean()),
                       rim_share=float(sq[rim].sum() / sq.sum()),
                       bake_ms=bake_ms, render_ms=res.render_ms, frame_ms=res.render_ms / 16)
            if fit is not None:
                row.update(fit_h=fit.h, fit_candidates=fit.candidates, fit_gains=fit.gains,
                           fit_ms=fit.gpu_ms)
            print(json.dumps(row), flush=True)
            rows.append(row)
            if n_change == 0 and grid == 128 and walks == 256:
                np.save(out_path.replace(".json", f"_128x256_lobe{lobe}.npy"), img.astype(np.float16))
    if n_change == 0:
        np.save(out_path.replace(".json", "_reference.npy"), ref.astype(np.float16))
    r.release()
json.dump(dict(device=device, scene="anisotropic", rows=rows), open(out_path, "w"), indent=1)
