"""screenshots/denoise_*.png from a denoise bench run's images (bench --preset denoise, GPU):
the path tracer at 64 samples raw, through the denoiser with no guide and with the probes' image as
its guide, and the reference; a zoomed crop of each under it shows what fine detail survives.
Usage: python scripts/screenshots/denoise_screenshots.py RUN_DIR/images [OUT_DIR]   (default screenshots/)"""
from __future__ import annotations

import sys
from pathlib import Path

from PIL import Image, ImageDraw

PANELS = {"bonsai": [("bonsai_pt_64_raw.png", "path tracer, 64 spp"),
                     ("bonsai_pt_64_none.png", "64 spp denoised"),
                     ("bonsai_pt_64_probes_64x128.png", "64 spp denoised, probes guide"),
                     ("bonsai_reference.png", "reference, 16384 spp")],
          "anisotropic": [("anisotropic_pt_64_raw.png", "path tracer, 64 spp"),
                          ("anisotropic_pt_64_none.png", "64 spp denoised")]}
CROPS = {"bonsai": (96, 64, 224, 192), "anisotropic": (180, 180, 308, 308)}   # x0, y0, x1, y1


def montage(folder: Path, name: str) -> Image.Image:
    panels = [(Image.open(folder / f).convert("RGB"), label) for f, label in PANELS[name]
              if (folder / f).is_file()]
    w, h = panels[0][0].size
    crop = CROPS[name]
    zoom = w // (crop[2] - crop[0])
    out = Image.new("RGB", (w * len(panels), 2 * h + 24), (24, 24, 24))
    draw = ImageDraw.Draw(out)
    for i, (im, label) in enumerate(panels):
        out.paste(im, (i * w, 24))
        detail = im.crop(crop).resize((w, h), Image.NEAREST)
        out.paste(detail, (i * w, 24 + h))
        draw.text((i * w + 6, 6), label, fill=(235, 235, 235))
        draw.rectangle([i * w + crop[0], 24 + crop[1], i * w + crop[2], 24 + crop[3]],
                       outline=(255, 255, 255))
    draw.text((6, 24 + h + 4), f"detail, {zoom}x", fill=(235, 235, 235))
    return out


def main(argv: list[str]) -> int:
    folder = Path(argv[0])
    out = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parents[2] / "screenshots"
    for name in PANELS:
        if (folder / PANELS[name][0][0]).is_file():
            path = out / f"denoise_{name}.png"
            montage(folder, name).save(path)
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
