"""Side-by-side images from a benchmark run's images/ folder (the reference, the path tracer at equal
samples, and the three probe methods at the showcase setting):
    python scripts/screenshots/bench_montage.py IMAGES_DIR OUT_DIR [SIZE]"""
import sys
from pathlib import Path

from PIL import Image, ImageDraw

images, out = Path(sys.argv[1]), Path(sys.argv[2])
size = int(sys.argv[3]) if len(sys.argv) > 3 else 256
out.mkdir(parents=True, exist_ok=True)
for ref in sorted(images.glob("*_reference.png")):
    scene = ref.name[: -len("_reference.png")]
    panels = [(ref, "reference (path tracer, 32768 spp)")]
    panels += [(p, "path tracer, 64 spp") for p in images.glob(f"{scene}_pt_*spp.png")]
    for method in ("probes", "probes-only", "raymarch"):
        for p in images.glob(f"{scene}_{method}_*x*.png"):
            grid, samples = p.stem.rsplit("_", 1)[1].split("x")
            frames = "16 frames" if method == "raymarch" else "64 frames"
            panels.append((p, f"{method}, {grid}^3 probes x {samples}, {frames}"))
    sheet = Image.new("RGB", (size * len(panels), size + 22), (20, 20, 20))
    draw = ImageDraw.Draw(sheet)
    for i, (path, label) in enumerate(panels):
        sheet.paste(Image.open(path).convert("RGB").resize((size, size), Image.LANCZOS), (i * size, 22))
        draw.text((i * size + 6, 5), label, fill=(235, 235, 235))
    target = out / f"methods_{scene}.png"
    sheet.save(target, optimize=True)
    print(f"wrote {target}")
