"""The GPU screenshot sheets' common parts (accuracy_screenshots.py, sh_order_screenshots.py,
gather_screenshots.py): a linear image tone mapped into a square panel, a signed error map, and
panels with two caption lines each laid out in rows under a footer line."""
import math

import numpy as np
from PIL import Image, ImageDraw

from radiance_probes.rendering.tonemap import to_uint8

HEAD = 34     # caption lines above each panel


def ldr(image, size: int, exposure: float = 1.0) -> Image.Image:
    """A linear (H, W, 3) image tone mapped (app/rendering/tonemap.py) into a size x size panel."""
    return Image.fromarray(to_uint8(image, exposure)).resize((size, size), Image.LANCZOS)


def panel_sheet(panels, size: int, cols: int, footer: str) -> Image.Image:
    """panels: (image, label, sub-label) each, size x size; `cols` a row, the footer below."""
    rows = math.ceil(len(panels) / cols)
    sheet = Image.new("RGB", (size * cols, rows * (size + HEAD) + 18), (20, 20, 20))
    draw = ImageDraw.Draw(sheet)
    for i, (img, label, sub) in enumerate(panels):
        x, y = (i % cols) * size, (i // cols) * (size + HEAD)
        sheet.paste(img, (x, y + HEAD))
        draw.text((x + 6, y + 4), label, fill=(235, 235, 235))
        draw.text((x + 6, y + 18), sub, fill=(190, 190, 190))
    draw.text((6, sheet.height - 15), footer, fill=(160, 160, 160))
    return sheet


def signed_error(image, reference, size: int, full: float = 0.25) -> Image.Image:
    """(image - reference) / mean reference per pixel as a size x size panel: red too bright, blue
    too dark, full colour at `full`."""
    err = (image - reference).mean(axis=-1) / max(float(reference.mean()), 1e-12)
    t = np.clip(np.abs(err) / full, 0, 1)
    rgb = np.zeros(err.shape + (3,))
    rgb[..., 0] = np.where(err > 0, t, 0)
    rgb[..., 2] = np.where(err < 0, t, 0)
    rgb[..., 1] = 0.25 * t
    return Image.fromarray((rgb * 255).astype(np.uint8)).resize((size, size), Image.NEAREST)
