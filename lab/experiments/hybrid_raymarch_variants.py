"""Where does the raymarch frame's time go with hybrid scattering (issue 43: at most 2.5 ms at
1080p)? Builds copies of the current tree with one piece of lib/raymarch.glsl's hybrid branch
replaced by a text edit each, and times 16 raymarched frames of each bench scene at 1080p:
    python lab/experiments/hybrid_raymarch_variants.py OUT.json WORKDIR [scenes] [k,k] [precision]
        [variants] [WxH] [method]
(precision: the probes' texture format, "auto" as the scenes have it; variants: a comma-separated
subset of the names below, all of them by default; WxH: the image, 1920x1080 by default; method:
what is timed, raymarch by default, or guided, whose level 0 is a raymarch pass)
  head        the tree as it is: the gradient read from the opacity-gradient grid (one fetch),
              the phase function's and the surface's light mixed by P at every sample, the
              roulette below transmittance 2e-2, the phase function's light from band 0 where
              g = 0 (PHASE_ISOTROPIC), the sun's GGX kernel in one division, the probes' scale
              on the mixed light
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
  roulette-T  the roulette below transmittance T instead of 2e-2 (unbiased; noisier a frame the
              higher T is)
  unpack      the order-2 colour unpack written out, every index a constant (no faster: kept out)
  no-iso      PHASE_ISOTROPIC off: the phase function's full SH sum where g = 0 too
  lambda-ggx  the sun's specular kernel through the two Smith Lambdas (four divisions), as before
  no-spec     the specular lobe never taken (F0 read as 0)
  no-sun-kernel  the sun's surface kernel never mixed in
  scale-early the probes' radiance scale on the 27 coefficients, not on the mixed light
  cosine-folded  the surface's two SH sums with A_l / pi folded into the basis's constants
  before-iso  roulette-1e-3, no-iso, lambda-ggx and scale-early: the code before those four
  level0-plain  `guided`'s level 0 in the march without surfaces' 8 x 4 work groups (not 8 x 8)
Timing probes only: the edited copies but head, no-roulette, grad-exact, wgXxY, roulette-T,
unpack, no-iso, lambda-ggx, scale-early, cosine-folded, before-iso and level0-plain render wrong
images. Each row also has a frame's noise: `frame_noise`, the rRMSE of one frame
(seed 7: every build's rays and jitter the same) against the 64-frame image of the no-roulette
build where the run has one (else its own), so the builds' noise a frame is compared with their
time a frame. (The march that drew each sample's surface-or-phase choice, 3.10-3.13 ms on the foot
against 3.01 for the mix, and its variants are in the history: bench/h200-hybrid-cost.)"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bake_variants import (child_rows, edited_tree, keep_rows)  # noqa: E402  (the same copies, other edits)
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
        probe_fetch_scaled(x, coeffs, probe_sun, 1.0);
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
# the raymarch pass's work-group shape for every build (app/rendering/methods/raymarch.py group_shape:
# 8 x 4 without surfaces, 8 x 8 with them, as shipped; every pixel's arithmetic the same, so the
# images are too); sides that do not divide the bands' tiles are let through (timing only)
for gx, gy in ((8, 8), (16, 8), (8, 4), (16, 16), (32, 4), (4, 8), (16, 4), (8, 2), (4, 4),
               (32, 2)):
    EDITS[f"wg{gx}x{gy}"] = [
        ("app/rendering/methods/raymarch.py", "GROUP_PLAIN = (8, 4)", f"GROUP_PLAIN = ({gx}, {gy})"),
        ("app/rendering/methods/raymarch.py", "GROUP_WIDE = (8, 8)", f"GROUP_WIDE = ({gx}, {gy})"),
        ("app/rendering/methods/raymarch.py", "if any(side <= 0 or TILE % side for side in shape):",
         "if False:")]
for threshold in ("1e-3", "3e-3", "1e-2", "3e-2", "1e-1"):
    EDITS[f"roulette-{threshold}"] = [
        ("glsl/lib/hybrid_scattering.glsl",
         "const float HYBRID_MARCH_ROULETTE_TRANSMITTANCE = 2e-2;",
         f"const float HYBRID_MARCH_ROULETTE_TRANSMITTANCE = {threshold};")]
# the order-2 colour unpack written out (every index a constant), as orders 0 and 1 have it
EDITS["unpack"] = [("glsl/lib/probes.glsl", """#else
    vec4 texel[PROBE_TEXTURE_COUNT];   // slot = texture number from here on""", """#elif !PROBE_GREY && PROBE_SH_ORDER == 2
    vec4 t0 = PROBE_TEXEL(0), t1 = PROBE_TEXEL(1), t2 = PROBE_TEXEL(2), t3 = PROBE_TEXEL(3);
    vec4 t4 = PROBE_TEXEL(4), t5 = PROBE_TEXEL(5), t6 = PROBE_TEXEL(6);
    coeffs[0] = t0.rgb;
    coeffs[1] = vec3(t0.a, t1.rg);
    coeffs[2] = vec3(t1.ba, t2.r);
    coeffs[3] = t2.gba;
    coeffs[4] = t3.rgb;
    coeffs[5] = vec3(t3.a, t4.rg);
    coeffs[6] = vec3(t4.ba, t5.r);
    coeffs[7] = t5.gba;
    coeffs[8] = t6.rgb;
    sun_transmittance = clamp(t6.a, 0.0, 1.0);
#else
    vec4 texel[PROBE_TEXTURE_COUNT];   // slot = texture number from here on""")]
# the phase function's full SH sum where g = 0 too (PHASE_ISOTROPIC off: the same image to rounding)
EDITS["no-iso"] = [("app/rendering/resources.py",
                    'if "HYBRID_SCATTERING" in defines and self.scene.anisotropy == 0.0:',
                    "if False:")]
# the sun's specular kernel through the two Smith Lambdas (four divisions), as before it took one
EDITS["lambda-ggx"] = [("glsl/lib/hybrid_scattering.glsl", """        float s_v = sqrt(n_v * n_v * (1.0 - a2) + a2), s_l = sqrt(n_l * n_l * (1.0 - a2) + a2);
        float n_h = dot(n, h);
        float t = n_h * n_h * (a2 - 1.0) + 1.0;
        kernel += f0 * (a2 * n_l / (2.0 * PI * t * t * (n_l * s_v + n_v * s_l)));""", """        float g2 = 1.0 / (1.0 + ggx_lambda(n_v, a2) + ggx_lambda(n_l, a2));
        kernel += f0 * (ggx_distribution(dot(n, h), a2) * g2 / (4.0 * n_v));""")]
# timing only: the specular lobe never taken (F0 read as 0), the sun's surface kernel never mixed
EDITS["no-spec"] = [("glsl/lib/hybrid_scattering.glsl", "    if (s > 0.0) {\n        for",
                     "    if (s > 1e30) {\n        for"),
                    ("glsl/lib/hybrid_scattering.glsl", "    if (s > 0.0) {\n        //",
                     "    if (s > 1e30) {\n        //")]
EDITS["no-sun-kernel"] = [("glsl/lib/raymarch.glsl", """            sun_kernel = mix(sun_kernel, surface_kernel(n, -d, sun_direction, surface_roughness,
                                                        surface_specular), vec3(surface_share));""",
                           "            sun_kernel *= 1.0 - 0.5 * surface_share;")]
# the surface's two SH sums with the clamped cosine's bands over pi folded into the basis's
# constants (SH order 2; the same sums reassociated)
EDITS["cosine-folded"] = [("glsl/lib/hybrid_scattering.glsl", """vec3 surface_probe_radiance(vec3 coeffs[SH_COUNT], vec3 n, vec3 v, vec3 f0)
{
""", """#if SH_ORDER == 2
vec3 sh_cosine_over_pi(vec3 c[SH_COUNT], vec3 w)
{
    const float K1 = 2.0 / 3.0 * SH_C1, K2 = 0.25 * SH_C2, K20 = 0.25 * SH_C20;
    const float K22 = 0.25 * SH_C22;
    float x = w.x, y = w.y, z = w.z;
    return SH_C0 * c[0] + K1 * (y * c[1] + z * c[2] + x * c[3])
           + K2 * (x * y * c[4] + y * z * c[5] + x * z * c[7])
           + K20 * (3.0 * z * z - 1.0) * c[6] + K22 * (x * x - y * y) * c[8];
}
#endif
vec3 surface_probe_radiance(vec3 coeffs[SH_COUNT], vec3 n, vec3 v, vec3 f0)
{
#if SH_ORDER == 2
    float s0 = surface_specular_weight(f0);
    vec3 folded = (1.0 - s0) * max(sh_cosine_over_pi(coeffs, n), vec3(0.0));
    if (s0 > 0.0)
        folded += f0 * max(sh_cosine_over_pi(coeffs, 2.0 * dot(n, v) * n - v), vec3(0.0));
    return folded;
#endif
""")]
# the probes' radiance scale on the 27 coefficients (probe_fetch), not on the mixed light, as before
EDITS["scale-early"] = [("glsl/lib/raymarch.glsl", "probe_fetch_scaled(x, coeffs, probe_sun, 1.0);",
                         "probe_fetch(x, coeffs, probe_sun);"),
                        ("glsl/lib/raymarch.glsl", "        inscattered *= probe_radiance_scale;\n",
                         "")]
EDITS["level0-plain"] = [("app/rendering/methods/raymarch.py",
                          'elif "HYBRID_SCATTERING" in defines or "GUIDED_LEVEL0" in defines:',
                          'elif "HYBRID_SCATTERING" in defines:')]
# the code before those four changes (bench/h200-hybrid-cost: timed against them in one run)
EDITS["before-iso"] = (EDITS["roulette-1e-3"] + EDITS["no-iso"] + EDITS["lambda-ggx"]
                       + EDITS["scale-early"])
CHILD = r'''
import json, sys
from dataclasses import replace
from pathlib import Path
import numpy as np
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
        # compiles, and brings the GPU's clocks up; kept as the build's converged image
        method = sys.argv[6]
        converged = r.render(method, spp=64, seed=1).image
        res = r.render(method, spp=32, seed=3)
        frame = r.render(method, spp=1, seed=7).image
        stem = Path(sys.argv[1]).name + f"_{name}_{k}"
        np.save(Path(sys.argv[1]).parent / f"{stem}_64.npy", converged)
        np.save(Path(sys.argv[1]).parent / f"{stem}_1.npy", frame)
        grid = r.opacity_gradient_grid   # the gradient grid baked (k > 0), None before
        print("RESULT " + json.dumps({"root": sys.argv[1], "scene": name, "k": k, "stem": stem,
                                      "size": [width, height],
                                      "method": method, "ms_per_sample": res.ms_per_sample,
                                      **({"raymarch_ms_per_frame": res.ms_per_sample}
                                         if method == "raymarch" else {}),
                                      "gradient_grid_ms": grid.cost_ms if grid else 0.0,
                                      "gradient_grid_bytes": grid.gpu_bytes if grid else 0}),
              flush=True)
        r.release()
'''


def frame_noise(work: Path, rows: list[dict]) -> None:
    """Adds each row's `frame_noise` (its frame against the no-roulette build's 64 frames of the
    same scene and k, else its own build's) and drops the images."""
    import numpy as np
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from app.rendering.metrics import rrmse
    for row in rows:
        if "stem" not in row:
            continue
        tail = row["stem"][len(Path(row["root"]).name):]
        reference = work / f"no-roulette{tail}_64.npy"
        if not reference.exists():
            reference = work / f"{row['stem']}_64.npy"
        row["frame_noise"] = rrmse(np.load(work / f"{row['stem']}_1.npy"), np.load(reference))
        row["frame_noise_against"] = reference.stem[:-3]
    for f in work.glob("*.npy"):
        f.unlink()


def main() -> None:
    out, work = Path(sys.argv[1]), Path(sys.argv[2])
    scenes = sys.argv[3] if len(sys.argv) > 3 else "foot,bonsai"
    ks = sys.argv[4] if len(sys.argv) > 4 else "0,0.05,0.2"
    precision = sys.argv[5] if len(sys.argv) > 5 else "auto"   # the scenes' own, rgba32f, rgba16f
    names = sys.argv[6].split(",") if len(sys.argv) > 6 and sys.argv[6] else ("head", *EDITS)
    size = sys.argv[7] if len(sys.argv) > 7 else "1920x1080"
    method = sys.argv[8] if len(sys.argv) > 8 else "raymarch"
    unknown = set(names) - {"head", *EDITS}
    if unknown:
        raise SystemExit(f"unknown variants {sorted(unknown)}: head, {', '.join(EDITS)}")
    rows = []
    for name in names:
        root = edited_tree(work, name, EDITS.get(name, []))
        got = child_rows(CHILD, str(root), str(root), scenes, ks, precision, size, method)
        keep_rows(out, rows, got)
    frame_noise(work, rows)
    out.write_text(json.dumps(rows, indent=1))
    for row in rows:
        if "frame_noise" in row:
            print(Path(row["root"]).name, row["scene"], row["k"],
                  f"{row['ms_per_sample']:.3f} ms", f"noise {row['frame_noise']:.5f}")


if __name__ == "__main__":
    main()
