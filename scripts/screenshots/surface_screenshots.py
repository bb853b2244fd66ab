"""Surfaces inside volumes (issue 43): the chest CT and the foot with the `ct_bone` preset (its
surface shading, k = 0.05) under a sphere light and a dim sun, rendered by the path tracer, the
raymarcher over the probes, and `guided` denoised with the probes' image as its guide (what the
viewer's `refine` accumulates and shows), each panel with its time and error against the path
tracer's image of `--ref-spp` samples. Run on the GPU (about a minute):
    python scripts/screenshots/surface_screenshots.py screenshots [--size 512] [--ref-spp 2048]
Writes screenshots/surfaces_chest_ct.png and surfaces_foot.png. Datasets from ../shared/datasets
(skipped when absent).

Both files are 8-bit exports without their units, so each scene states the mapping back to
Hounsfield units (volume.rescale, stored * slope + intercept): the chest CT's 8 bits span
[-1000, 1000] HU (under that map its lung and soft-tissue peaks fall at about -850 and +40 HU);
the foot's calibration is unknown, and [-1000, 2000] HU is assumed (air at -1000, its brightest
voxels cortical bone)."""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, ".")
from radiance_probes.gl.context import create_headless_context, describe   # noqa: E402
from radiance_probes.rendering.metrics import rrmse                          # noqa: E402
from radiance_probes.rendering.renderer import Renderer                     # noqa: E402
from radiance_probes.io.scene_file import parse_scene                               # noqa: E402
from panel_sheet import ldr, panel_sheet                                     # noqa: E402

DATA = Path("..") / "shared" / "datasets"
LIGHTS = {"light": {"direction": [0.3, 0.5, 0.8], "irradiance": [0.6, 0.6, 0.6]},
          "area_lights": [{"shape": "sphere", "position": [-1.3, 1.4, 1.6], "size": 0.35,
                           "colour": [1.0, 0.95, 0.88], "strength": 60.0}]}
SCENES = {
    "chest_ct": ("lidc2_chest_ct_256x256x133.nrrd",
                 {"rescale": [2000.0 / 255.0, -1000.0], "orientation": "patient"},
                 "chest CT, 8 bits as [-1000, 1000] HU"),
    "foot": ("foot_256x256x256_uint8.raw", {"rescale": [3000.0 / 255.0, -1000.0]},
             "foot, 8 bits as [-1000, 2000] HU (assumed)"),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--pt-spp", type=int, default=64)
    ap.add_argument("--guided-spp", type=int, default=64)
    ap.add_argument("--probes", type=int, default=64, help="probe grid N^3 (128 walks each)")
    args = ap.parse_args()
    ctx = create_headless_context()
    device = describe(ctx)
    panel = min(args.size, 384)
    for name, (file, volume, title) in SCENES.items():
        path = DATA / file
        if not path.exists():
            print(f"{name}: {path} absent, skipped")
            continue
        scene = parse_scene({"volume": {"path": str(path.resolve()), **volume},
                             "transfer_function": {"preset": "ct_bone"}, "density_scale": 150.0,
                             "albedo": 0.9, **LIGHTS,
                             "probes": {"grid": args.probes, "samples": 128},
                             "camera": {"width": args.size, "height": args.size}})
        r = Renderer(ctx, scene)
        ref = r.render("pt", spp=args.ref_spp, seed=1, samples_per_pass=64).image
        rows = [(ldr(ref, panel), f"{title}: ct_bone, sphere light",
                 f"path tracer {args.ref_spp} spp (the reference)")]
        for method, spp, denoise in (("pt", args.pt_spp, False), ("raymarch", 16, False),
                                     ("guided", args.guided_spp, True)):
            res = r.render(method, spp=spp, seed=3, denoise=denoise,
                           denoise_guides="probes" if denoise else "auto")
            ms = res.render_ms + res.bake_ms + res.guides_ms + (
                res.denoised.total_ms if res.denoised is not None else 0.0)
            e = rrmse(res.image, ref)
            label = {"pt": f"path tracer, {spp} spp", "raymarch": f"raymarch, {spp} frames",
                     "guided": f"refine: guided {spp} spp, denoised"}[method]
            note = "" if not denoise or res.denoised is None or res.denoised.denoised else \
                f" (not denoised: {res.denoised.note})"
            print(f"{name} {label}: {ms:.0f} ms, rRMSE {100 * e:.2f}%{note}", flush=True)
            rows.append((ldr(res.image, panel), label, f"{ms:.0f} ms, rRMSE {100 * e:.2f}%"))
        sheet = panel_sheet(rows, panel, 4, f"surfaces inside the volume (ct_bone: gradient factor "
                            f"0.05); probes {args.probes}^3 x 128; times include bake, light grid "
                            f"and denoiser; {args.size}^2, {device}")
        Path(args.out).mkdir(parents=True, exist_ok=True)
        target = Path(args.out) / f"surfaces_{name}.png"
        sheet.save(target, optimize=True)
        print(f"wrote {target}")
        r.release()


if __name__ == "__main__":
    main()
