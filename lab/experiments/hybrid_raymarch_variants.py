"""Where does the raymarch frame's time go with hybrid scattering (issue 43: at most 2.5 ms at
1080p)? Builds copies of the current tree with one piece of lib/raymarch.glsl's hybrid branch
replaced by a text edit each, and times 16 raymarched frames of each bench scene at 1080p:
    python lab/experiments/hybrid_raymarch_variants.py OUT.json WORKDIR [scenes] [k,k] [precision]
        [variants] [WxH]
(precision: the probes' texture format, "auto" as the scenes have it; variants: a comma-separated
subset of the names below, all of them by default; WxH: the image, 1920x1080 by default)
  head        the tree as it is: the gradient read from the opacity-gradient grid (one fetch),
              the phase function's and the surface's light mixed by P at every sample, the
              roulette below transmittance 1e-3
  no-roulette the roulette off (the stop at 1e-6, HYBRID_MARCH_NO_ROULETTE): what it saves
  grad-exact  the exact 6-lookup gradient at every sample (the raymarcher before the grid; the
              grid is still baked, outside the frames timed): head against it is what the grid saves
  no-grad     the gradient replaced by a constant (the surface branch still runs)
  no-surface  the gradient read, the surface shading never mixed in
  no-coeffs   the probes read as k = 0 reads them (no array of coefficients held; surface light 0)
  grad-forward  the gradient by forward differences (four lookups, not six) in place of the grid
  no-light    the light grid's optical depth a constant (what its lookups cost)
  no-probes   k = 0's probe read a constant (what the probes cost the phase-function march)
  stop-1e-3   the march stops at transmittance 1e-3, not 1e-6
  wgXxY       the raymarch pass's work groups X x Y pixels in every build (the same images;
              as shipped: 8 x 4 without surfaces, 8 x 8 with them)
Timing probes only: the edited copies but head, no-roulette, grad-exact and wgXxY render wrong
images. (The march that drew each sample's surface-or-phase choice, 3.10-3.13 ms on the foot
against 3.01 for the mix, and its variants are in the history: bench/h200-hybrid-cost.)"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bake_variants import child_rows, edited_tree, keep_rows   # noqa: E402  (the same copies, other edits)
# the line of lib/raymarch.glsl that reads the gradient (lib/opacity_gradient_grid.glsl)
GRADIENT_READ = "vec3 gradient = raymarch_opacity_gradient(x);"
EDITS = {
    "no-roulette": [("glsl/lib/raymarch.glsl",
                     "#if defined(HYBRID_SCATTERING) && !defined(HYBRID_MARCH_NO_ROULETTE)",
                     "#if 0")],
    "grad-exact": [("glsl/lib/raymarch.glsl", GRADIENT_READ,
                    "vec3 gradient = opacity_gradient(x);")],
    "no-grad": [("glsl/lib/raymarch.glsl", GRADIENT_READ,
                 "vec3 gradient = vec3(0.0, 0.0, 30.0);")],
    "no-surface": [("glsl/lib/raymarch.glsl", "if (surface_share > 0.0) {",
                    "if (surface_share > 1e30) {")],
    "no-coeffs": [("glsl/lib/raymarch.glsl", """        vec3 coeffs[SH_COUNT];
        float probe_sun;
        probe_fetch(x, coeffs, probe_sun);
        vec3 inscattered = probe_inscattered_from(coeffs, d);""", """        float probe_sun;
        vec3 inscattered = probe_inscattered(x, d, probe_sun);
        vec3 coeffs[SH_COUNT];
        for (int c = 0; c < SH_COUNT; ++c) coeffs[c] = vec3(0.0);""")],
}
EDITS["no-grad-no-coeffs"] = EDITS["no-grad"] + EDITS["no-coeffs"]
# forward differences from the point itself: four lookups instead of six (timing only: a
# different normal from the path tracer's), computed in the raymarcher in place of the grid's read
EDITS["grad-forward"] = EDITS["grad-exact"] + [("glsl/lib/hybrid_scattering.glsl", """    vec3 g;
    g.x = classified_at(x + vec3(h.x, 0.0, 0.0)).a - classified_at(x - vec3(h.x, 0.0, 0.0)).a;
    g.y = classified_at(x + vec3(0.0, h.y, 0.0)).a - classified_at(x - vec3(0.0, h.y, 0.0)).a;
    g.z = classified_at(x + vec3(0.0, 0.0, h.z)).a - classified_at(x - vec3(0.0, 0.0, h.z)).a;
    return g / (2.0 * h);""", """    vec3 g;
    float a0 = classified_at(x).a;
    g.x = classified_at(x + vec3(h.x, 0.0, 0.0)).a - a0;
    g.y = classified_at(x + vec3(0.0, h.y, 0.0)).a - a0;
    g.z = classified_at(x + vec3(0.0, 0.0, h.z)).a - a0;
    return g / h;""")]
EDITS["no-light"] = [("glsl/lib/raymarch.glsl",
                      "float tau_end = light_grid_optical_depth(origin + (t0 + float(i + 1) * dt) * d);",
                      "float tau_end = 0.5 * float(i + 1) * dt;")]
EDITS["no-probes"] = [("glsl/lib/raymarch.glsl", "vec3 inscattered = probe_inscattered(x, d, probe_sun);",
                       "vec3 inscattered = vec3(0.1); probe_sun = 0.5;")]
EDITS["stop-1e-3"] = [("glsl/lib/raymarch.glsl", "i < n && transmittance > 1e-6;",
                       "i < n && transmittance > 1e-3;")]
# the raymarch pass's work-group shape for every build (app/rendering/raymarch.py group_shape:
# 8 x 4 without surfaces, 8 x 8 with them, as shipped; every pixel's arithmetic the same, so the
# images are too); sides that do not divide the bands' tiles are let through (timing only)
for gx, gy in ((8, 8), (16, 8), (8, 4), (16, 16), (32, 4), (4, 8), (16, 4), (8, 2), (4, 4),
               (32, 2)):
    EDITS[f"wg{gx}x{gy}"] = [
        ("app/rendering/raymarch.py", "GROUP_PLAIN = (8, 4)", f"GROUP_PLAIN = ({gx}, {gy})"),
        ("app/rendering/raymarch.py", "GROUP_WIDE = (8, 8)", f"GROUP_WIDE = ({gx}, {gy})"),
        ("app/rendering/raymarch.py", "if any(side <= 0 or TILE % side for side in shape):",
         "if False:")]
CHILD = r'''
import json, sys
from dataclasses import replace
sys.path.insert(0, sys.argv[1])
from app.bench.scenes import bench_scene
from app.gl.context import create_headless_context
from app.rendering.renderer import Renderer
from app.scene import SurfaceSpec
ctx = create_headless_context()
width, height = (int(v) for v in sys.argv[5].split("x"))
for name in sys.argv[2].split(","):
    for k in (float(v) for v in sys.argv[3].split(",")):
        scene = bench_scene(name, width, height)
        scene = scene.replace(surface=SurfaceSpec(gradient_factor=k, roughness=0.4,
                                                  specular=(0.04,) * 3))
        if sys.argv[4] != "auto":   # the probes' texture format
            scene = scene.replace(probes=replace(scene.probes, precision=sys.argv[4]))
        r = Renderer(ctx, scene)
        r.render("raymarch", spp=64, seed=1)   # compiles, and brings the GPU's clocks up
        res = r.render("raymarch", spp=32, seed=3)
        grid = r.opacity_gradient_grid   # the gradient grid baked (k > 0), None before
        print("RESULT " + json.dumps({"root": sys.argv[1], "scene": name, "k": k,
                                      "size": [width, height],
                                      "raymarch_ms_per_frame": res.ms_per_sample,
                                      "gradient_grid_ms": grid.cost_ms if grid else 0.0,
                                      "gradient_grid_bytes": grid.gpu_bytes if grid else 0}),
              flush=True)
        r.release()
'''


def main() -> None:
    out, work = Path(sys.argv[1]), Path(sys.argv[2])
    scenes = sys.argv[3] if len(sys.argv) > 3 else "foot,bonsai"
    ks = sys.argv[4] if len(sys.argv) > 4 else "0,0.05,0.2"
    precision = sys.argv[5] if len(sys.argv) > 5 else "auto"   # the scenes' own, rgba32f, rgba16f
    names = sys.argv[6].split(",") if len(sys.argv) > 6 and sys.argv[6] else ("head", *EDITS)
    size = sys.argv[7] if len(sys.argv) > 7 else "1920x1080"
    unknown = set(names) - {"head", *EDITS}
    if unknown:
        raise SystemExit(f"unknown variants {sorted(unknown)}: head, {', '.join(EDITS)}")
    rows = []
    for name in names:
        root = edited_tree(work, name, EDITS.get(name, []))
        got = child_rows(CHILD, str(root), str(root), scenes, ks, precision, size)
        keep_rows(out, rows, got)


if __name__ == "__main__":
    main()
