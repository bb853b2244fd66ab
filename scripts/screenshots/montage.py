"""Puts PNGs side by side with a caption strip: python scripts/screenshots/montage.py OUT.png A.png:label ..."""
import sys

from PIL import Image, ImageDraw

out, items = sys.argv[1], [a.rsplit(":", 1) for a in sys.argv[2:]]
images = [Image.open(path).convert("RGB") for path, _ in items]
w, h = images[0].size
sheet = Image.new("RGB", (w * len(images), h + 24), (20, 20, 20))
draw = ImageDraw.Draw(sheet)
for i, (im, (_, label)) in enumerate(zip(images, items)):
    sheet.paste(im, (i * w, 24))
    draw.text((i * w + 8, 6), label, fill=(235, 235, 235))
sheet.save(out)
print(f"wrote {out}")
