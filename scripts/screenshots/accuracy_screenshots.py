"""Before and after on fine structure (issue 11): bonsai and the foot at 512^2 against a path-traced
reference, the raymarcher after 16 frames with
  - before: 64^3 probes x 512 walks, the light grid capped at 128 texels per axis (the state the
    issue measured),
  - after: the same probes with today's light grid (the sheared column march, 6 texels per probe
    spacing), and 192^3 x 64 (the most accurate setting of the benchmark within 500 ms, bake
    included: bench/h100),
each with its GPU time (bake + 16 frames) and rRMSE (corrected for the reference's noise), a heat
map of the per-pixel error (|image - reference| / mean reference, 0 to 50%), and the probe layout:
the probes of the 64^3 grid whose cells hold visible medium, every 4th per axis, projected over
the image. Run on the GPU (about a minute):
    python scripts/screenshots/accuracy_screenshots.py screenshots [REF_DIR|-] [scene ...]
REF_DIR: a bench run's folder, whose refs/NAME.npy and measured noise are the reference (as
`bench --ref-dir`); without it a reference of 8192 spp in two halves is rendered."""
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from panel_sheet import ldr, panel_sheet

from radiance_probes.rendering.metrics import corrected_rrmse, rrmse
from radiance_probes.bench.report import load as load_results
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.twins.camera import camera_frame
from radiance_probes.viewer.orbit import project, view_projection
from radiance_probes.viewer.probe_view import probe_centres, visible_cells
from radiance_probes.io.load import load_volume

out = Path(sys.argv[1])
ref_dir = Path(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[2] != "-" else None
ref_spp = 8192
SIZE, PANEL = 512, 320
ctx = create_headless_context()
device = describe(ctx)


def heat(image, ref) -> Image.Image:
    import matplotlib.cm as cm
    err = np.abs(image - ref).mean(axis=-1) / max(float(ref.mean()), 1e-12)
    rgb = (cm.inferno(np.clip(err / 0.5, 0, 1))[..., :3] * 255).astype(np.uint8)
    return Image.fromarray(rgb).resize((PANEL, PANEL), Image.NEAREST)


def layout_panel(r, image) -> Image.Image:
    """The probes (every 4th per axis) whose cells hold visible medium, over the dimmed image."""
    grid = r.probe_grid
    res = r.resources
    cells = visible_cells(grid.grid, grid.box, res.volume, res.table[:, 3], r.scene.density_scale,
                          grid.planes)
    stride = 4
    cells = cells[::stride, ::stride, ::stride]
    centres = probe_centres(grid.grid, res.volume.half_extent, grid.box, grid.planes)
    centres = np.asarray(centres).reshape(grid.grid[2], grid.grid[1], grid.grid[0], 3)
    centres = centres[::stride, ::stride, ::stride][cells]
    frame = camera_frame(r.scene.camera, SIZE, SIZE)
    px = project(view_projection(frame), centres, PANEL, PANEL)
    base = ldr(image, PANEL)
    base = Image.blend(base, Image.new("RGB", base.size), 0.55)
    draw = ImageDraw.Draw(base)
    for x, y in px[np.isfinite(px).all(axis=1)]:
        draw.ellipse((x - 1.2, y - 1.2, x + 1.2, y + 1.2), fill=(110, 220, 255))
    return base


for name in sys.argv[3:] or ("bonsai", "foot"):
    scene = bench_scene(name, SIZE, SIZE)
    if scene is None:
        print(f"{name}: dataset absent, skipped")
        continue
    vol = load_volume(scene.volume, scene.base_dir)
    r = Renderer(ctx, scene, vol)
    if ref_dir is not None:
        ref = np.load(ref_dir / "refs" / f"{name}.npy")
        known = load_results(ref_dir)["references"][name]
        noise, spp = known["noise_rrmse"], known["spp"]
    else:
        halves = [r.render("pt", spp=ref_spp // 2, seed=100 + i, samples_per_pass=64).image
                  for i in range(2)]
        ref = 0.5 * (halves[0] + halves[1])
        noise, spp = rrmse(halves[0], halves[1]) / 2, ref_spp
    shots = []
    for label, grid, walks, before in (("before: 64^3 x 512, light grid <= 128", 64, 512, True),
                                       ("after: 64^3 x 512", 64, 512, False),
                                       ("after: 192^3 x 64", 192, 64, False)):
        r.set_scene(scene.replace(probes=replace(scene.probes, grid=(grid,) * 3, samples=walks)))
        r.configure(light_max_side=128 if before else 512)
        r.configure(light_follows_probes=not before)
        res = r.render("raymarch", spp=16, seed=3, samples_per_pass=16)
        e = corrected_rrmse(rrmse(res.image, ref), noise)
        ms = res.bake_ms + res.render_ms
        print(f"{name} {label}: {ms:.1f} ms, rRMSE {e:.4f}, light grid {r._light.grid}", flush=True)
        shots.append((f"{label}", f"{ms:.0f} ms GPU, rRMSE {100 * e:.1f}%", res.image))
        if grid == 64 and not before:
            layout = layout_panel(r, res.image)
    panels = [(ldr(ref, PANEL), f"reference, path tracer {spp} spp", "")]
    panels += [(ldr(img, PANEL), label, sub) for label, sub, img in shots]
    panels += [(layout, "probe layout: 64^3 uniform", "every 4th probe per axis in matter")]
    panels += [(heat(img, ref), "error, " + label.split(", light")[0], "0 to 50% of the mean")
               for label, _, img in shots]
    sheet = panel_sheet(panels, PANEL, 4, f"{name}, raymarcher 16 frames, {SIZE}x{SIZE}, {device}")
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"accuracy_{name}.png"
    sheet.save(target, optimize=True)
    print(f"wrote {target}")
    r.release()
