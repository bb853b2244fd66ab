"""The anisotropic cloud (g = 0.8, backlit) at SH orders 2, 3 (without and with the lobe about
the sun's direction, lib/sun_lobe.glsl, which order 3 holds by default) and 4: the raymarcher after 16
frames with 128^3 x 256 probes against a path-traced reference of 8192 spp (two halves), each with
its GPU time (bake + 16 frames), rRMSE (corrected for the reference's noise) and a signed error
map ((image - reference) / mean reference: red too bright, blue too dark, full colour at 25%).
Run on the GPU (about half a minute):
    python scripts/screenshots/sh_order_screenshots.py screenshots
writes screenshots/sh_orders_anisotropic.png."""
import sys
from dataclasses import replace
from pathlib import Path

from PIL import Image

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume
from panel_sheet import ldr, panel_sheet, signed_error

out = Path(sys.argv[1])
SIZE, PANEL, REF_SPP = 512, 320, 8192
ctx = create_headless_context()
device = describe(ctx)


scene = bench_scene("anisotropic", SIZE, SIZE)
r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
halves = [r.render("pt", spp=REF_SPP // 2, seed=100 + i, samples_per_pass=64).image
          for i in range(2)]
ref = 0.5 * (halves[0] + halves[1])
noise = rrmse(halves[0], halves[1]) / 2
shots = []
for order, lobe in ((2, False), (3, False), (3, True), (4, False)):
    r.configure(sun_lobe=lobe)
    r.set_scene(scene.replace(probes=replace(scene.probes, grid=(128,) * 3, samples=256,
                                             sh_order=order)))
    res = r.render("raymarch", spp=16, seed=3, samples_per_pass=16)
    assert (r.probe_grid.sun_lobe > 0) == lobe
    e = corrected_rrmse(rrmse(res.image, ref), noise)
    ms = res.bake_ms + res.render_ms
    name = f"{order} + sun lobe" if lobe else f"{order}"
    print(f"order {name}: {ms:.1f} ms, rRMSE {e:.4f}", flush=True)
    shots.append((name, ms, e, res.image))
panels = [(ldr(ref, PANEL), f"reference, path tracer {REF_SPP} spp", "g = 0.8, lit from behind")]
panels += [(ldr(img, PANEL), f"SH order {o}: 128^3 x 256", f"{ms:.0f} ms GPU, rRMSE {100 * e:.2f}%")
           for o, ms, e, img in shots]
panels += [(Image.new("RGB", (PANEL, PANEL), (20, 20, 20)), "error maps, (image - reference)",
            "/ mean: red too bright, blue too dark")]
panels += [(signed_error(img, ref, PANEL), f"error, order {o}", "full colour at 25%")
           for o, _, _, img in shots]
sheet = panel_sheet(panels, PANEL, 5,
                    f"anisotropic cloud, raymarcher 16 frames, {SIZE}x{SIZE}, {device}")
out.mkdir(parents=True, exist_ok=True)
target = out / "sh_orders_anisotropic.png"
sheet.save(target, optimize=True)
print(f"wrote {target}")
