"""Where the anisotropic cloud's last 3.5% comes from (bench/h100-anisotropic-floor). Renders the
bench's g = 0.8 cloud at 512^2, raymarched from 128^3 x 256 probes at SH order 3 (16 frames), with
one thing changed at a time: the raymarch step, the light grid's resolution and precision; and the
same scene with single scattering only (max_bounces 1: the sun from the light grid, the environment
through the probes) against a single-scattering path trace. Errors are rRMSE against two path-traced
halves, measured and corrected for the reference's noise (app/rendering/metrics.py); `rim_*` are over
the brightest tenth of the reference's pixels: mean of image / mean of reference, and that tenth's
share of the squared error.
Usage (GPU): python lab/experiments/experiment_anisotropic_floor.py OUT.json [REFERENCE_SPP_PER_HALF]"""
import json
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, ".")
import radiance_probes.rendering.grids.light_transmittance as light_module
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

out_path = sys.argv[1]
half_spp = int(sys.argv[2]) if len(sys.argv) > 2 else 4096
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
base = bench_scene("anisotropic", 512, 512)
volume = load_volume(base.volume, base.base_dir)
rows = []


def luminance(img):
    return img[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def measure(label, r, scene, reference, noise, **extra):
    r.set_scene(scene)
    r.invalidate()
    bake_ms = r.bake(seed=11)
    res = r.render("raymarch", spp=16, seed=11, samples_per_pass=16)
    img = res.image[..., :3].astype(np.float64)
    ref = reference[..., :3].astype(np.float64)
    lum = luminance(ref)
    rim = lum >= np.quantile(lum, 0.9)
    sq = ((img - ref) ** 2).sum(axis=-1)
    e = rrmse(res.image, reference)
    row = dict(label=label, rrmse=e, rrmse_corrected=corrected_rrmse(e, noise),
               rim_ratio=float(img[rim].mean() / ref[rim].mean()),
               rim_share=float(sq[rim].sum() / sq.sum()),
               rest_ratio=float(img[~rim].mean() / ref[~rim].mean()),
               bake_ms=bake_ms, render_ms=res.render_ms, **extra)
    print(json.dumps(row), flush=True)
    rows.append(row)


for bounces in (None, 1):
    scene = base if bounces is None else base.replace(max_bounces=bounces)
    scene = scene.replace(probes=replace(scene.probes, grid=(128,) * 3, samples=256, sh_order=3))
    r = Renderer(ctx, scene, volume)
    halves = [r.render("pt", spp=half_spp, seed=s, samples_per_pass=16).image
              for s in (1000003, 2000003)]
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    rows.append(dict(label="reference", max_bounces=scene.max_bounces, spp=2 * half_spp,
                     noise=noise))
    tag = "all bounces" if bounces is None else "single scattering"
    measure(f"{tag}: default", r, scene, reference, noise)
    if bounces is None:
        r.configure(raymarch_step=0.25)
        measure(f"{tag}: raymarch step 0.25", r, scene, reference, noise)
        r.configure(raymarch_step=0.5)
        saved_precision = r.settings.light_precision
        r.configure(light_precision="f4")
        measure(f"{tag}: light grid 32-bit", r, scene, reference, noise)
        r.configure(light_precision=saved_precision)
        saved = light_module.VOLUME_UPSAMPLING
        light_module.VOLUME_UPSAMPLING = 4
        measure(f"{tag}: light grid 4 texels a voxel", r, scene, reference, noise)
        light_module.VOLUME_UPSAMPLING = saved
        for grid, walks in ((192, 256), (128, 1024)):
            s = scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks))
            measure(f"{tag}: {grid}^3 x {walks}", r, s, reference, noise)
    r.release()
json.dump(dict(device=device, rows=rows), open(out_path, "w"), indent=1)
