"""The final gather (Renderer.probe_gather_event, lib/integrator.glsl) on the anisotropic cloud and
bonsai: a path-traced reference (8192 spp in two halves), `probes` reading 128^3 x 64 probes at
scattering event 1 (the paper's renderer), 2 and 3 after 1024 frames each, with GPU time (bake +
frames), rRMSE corrected for the reference's noise, and a signed error map per image
((image - reference) / mean reference: red too bright, blue too dark, full colour at 10%).
Run on the GPU (about a minute):
    python scripts/screenshots/gather_screenshots.py screenshots
writes screenshots/final_gather.png."""
import sys
from dataclasses import replace
from pathlib import Path

from PIL import Image

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume
from panel_sheet import ldr, panel_sheet, signed_error

out = Path(sys.argv[1])
SIZE, PANEL, REF_SPP, FRAMES, GRID, WALKS = 512, 256, 8192, 1024, 128, 64
EVENTS = (1, 2, 3)
FULL = 0.1   # error map: full colour at 10% of the mean
ctx = create_headless_context()
device = describe(ctx)
panels = []
for name in ("anisotropic", "bonsai"):
    scene = bench_scene(name, SIZE, SIZE)
    if scene is None:
        print(f"{name}: dataset absent, skipped")
        continue
    r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
    halves = [r.render("pt", spp=REF_SPP // 2, seed=100 + i, samples_per_pass=64).image
              for i in range(2)]
    ref = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    r.set_scene(scene.replace(probes=replace(scene.probes, grid=(GRID,) * 3, samples=WALKS)))
    bake_ms = r.bake(seed=11)   # once: the gather event is read-side, each image pays for it
    shots = []
    for event in EVENTS:
        r.configure(gather_event=event)
        res = r.render("probes", spp=FRAMES, seed=3, samples_per_pass=16)
        e = corrected_rrmse(rrmse(res.image, ref), noise)
        ms = bake_ms + res.render_ms
        print(f"{name} gather {event}: {ms:.0f} ms, rRMSE {e:.4f}", flush=True)
        shots.append((event, ms, e, res.image))
    panels += [(ldr(ref, PANEL), f"{name}: path tracer", f"reference, {REF_SPP} spp")]
    panels += [(ldr(img, PANEL), f"probes, gather at event {k}",
                f"{ms:.0f} ms GPU, rRMSE {100 * e:.2f}%") for k, ms, e, img in shots]
    panels += [(Image.new("RGB", (PANEL, PANEL), (20, 20, 20)), "error maps: red too bright,",
                f"blue too dark, full colour at {FULL:.0%}")]
    panels += [(signed_error(img, ref, PANEL, FULL), f"error, gather at event {k}",
                {1: "the paper's renderer", 2: "event 1 path traced"}.get(
                    k, f"events 1-{k - 1} path traced")) for k, _, _, img in shots]
    r.release()
sheet = panel_sheet(panels, PANEL, 1 + len(EVENTS),
                    f"probes {GRID}^3 x {WALKS}, {FRAMES} frames each, {SIZE}x{SIZE}, {device}")
out.mkdir(parents=True, exist_ok=True)
target = out / "final_gather.png"
sheet.save(target, optimize=True)
print(f"wrote {target}")
