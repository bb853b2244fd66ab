"""A colour bar drawn into a rendered image (`render --colorbar`, `animate --colorbar`): the
transfer function's colours from density 0 to 1, labelled in the data's units (the volume's
value range or window maps them), on a dark panel at the image's right (or bottom) edge.
It is drawn on the tone-mapped 8-bit image, never on the linear one comparisons use."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

POSITIONS = ("right", "bottom")


def data_ticks(value_range: tuple[float, float], target: int = 5) -> tuple[list[float], list[str]]:
    """Ticks for an axis drawn over normalised density [0, 1] but labelled in data units (HU for
    CT): round data values in the range (steps of 1, 2 or 5 times a power of ten) and where they
    fall on [0, 1], as value_range (or the window) maps them."""
    lo, hi = (float(v) for v in value_range)
    span = hi - lo
    if not (math.isfinite(span) and span > 0):
        return [0.0, 1.0], [f"{lo:.4g}", f"{hi:.4g}"]
    raw = span / max(target - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw)
    first = math.ceil(lo / step - 1e-9)
    values = [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]
    return [(val - lo) / span for val in values], [f"{val:.4g}" for val in values]


@lru_cache(maxsize=8)
def _font(pixels: int):
    from PIL import ImageFont
    try:
        import imgui_bundle
        from pathlib import Path
        path = Path(imgui_bundle.__file__).parent / "assets" / "fonts" / "Roboto" / "Roboto-Regular.ttf"
        if path.is_file():
            return ImageFont.truetype(str(path), pixels)
    except (ImportError, OSError):
        pass
    try:
        return ImageFont.load_default(size=pixels)
    except TypeError:   # Pillow without FreeType's default font
        return ImageFont.load_default()


class ColorbarOverlay:
    """A colour bar drawn once for an image size (an RGBA patch and where it goes), laid over any
    number of frames of that size cheaply (a movie's every frame)."""

    def __init__(self, patch: np.ndarray, top: int, left: int):
        self.patch = patch.astype(np.float32)
        self.alpha = self.patch[..., 3:4] / 255.0
        self.top, self.left = top, left

    def apply(self, image: np.ndarray) -> np.ndarray:
        out = np.array(image, np.uint8, copy=True)
        h, w = self.patch.shape[:2]
        region = out[self.top:self.top + h, self.left:self.left + w].astype(np.float32)
        blended = region * (1.0 - self.alpha) + self.patch[..., :3] * self.alpha
        out[self.top:self.top + h, self.left:self.left + w] = np.round(blended).astype(np.uint8)
        return out


def draw_colorbar(image: np.ndarray, rgb: np.ndarray, value_range: tuple[float, float],
                  title: str = "value", position: str = "right") -> np.ndarray:
    """`image` (H, W, 3) uint8 with a colour bar of `rgb` (N, 3) colours in [0, 1] (density 0 to 1)
    drawn in, ticks in data units from `value_range`. Returns a new array."""
    h, w = image.shape[:2]
    return colorbar_overlay(w, h, rgb, value_range, title, position).apply(image)


def colorbar_overlay(w: int, h: int, rgb: np.ndarray, value_range: tuple[float, float],
                     title: str = "value", position: str = "right") -> ColorbarOverlay:
    """The colour bar of draw_colorbar for images of w x h pixels."""
    from PIL import Image, ImageDraw
    if position not in POSITIONS:
        raise ValueError(f"colour bar position: expected one of {', '.join(POSITIONS)}, "
                         f"got {position!r}")
    overlay = Image.new("RGBA", (w, h), (0, 0, 0, 0))
    draw = ImageDraw.Draw(overlay)
    scale = max(min(w, h) / 512.0, 0.35)
    font = _font(max(8, int(round(15 * scale))))
    pad = max(3, int(round(8 * scale)))
    thick = max(6, int(round(16 * scale)))
    colours = (np.clip(np.asarray(rgb, np.float64), 0, 1) * 255 + 0.5).astype(np.uint8)
    ticks, labels = data_ticks(value_range)
    label_w = max(draw.textbbox((0, 0), t, font=font)[2] for t in labels + [title])
    text_h = draw.textbbox((0, 0), "0", font=font)[3]
    if position == "right":
        length = int(h * 0.6)
        panel_w = thick + 3 * pad + label_w
        x0, y0 = w - panel_w - pad, (h - length) // 2
        draw.rounded_rectangle((x0, y0 - 2 * pad - text_h, x0 + panel_w, y0 + length + pad),
                               radius=pad, fill=(0, 0, 0, 150))
        draw.text((x0 + pad, y0 - pad - text_h), title, font=font, fill=(255, 255, 255, 255))
        bx = x0 + pad
        for k in range(length):   # density 1 at the top
            c = colours[int((length - 1 - k) / max(length - 1, 1) * (len(colours) - 1) + 0.5)]
            draw.line((bx, y0 + k, bx + thick, y0 + k), fill=(*map(int, c), 255))
        draw.rectangle((bx, y0, bx + thick, y0 + length), outline=(255, 255, 255, 200))
        for t, text in zip(ticks, labels):
            y = y0 + (1.0 - t) * length
            draw.line((bx + thick, y, bx + thick + pad, y), fill=(255, 255, 255, 230))
            draw.text((bx + thick + 2 * pad, y - text_h / 2), text, font=font,
                      fill=(255, 255, 255, 255))
    else:
        length = int(w * 0.6)
        panel_h = thick + 3 * pad + text_h
        x0, y0 = (w - length) // 2, h - panel_h - pad
        draw.rounded_rectangle((x0 - 2 * pad - label_w, y0, x0 + length + 2 * pad + label_w // 2,
                                y0 + panel_h), radius=pad, fill=(0, 0, 0, 150))
        draw.text((x0 - pad - label_w, y0 + pad), title, font=font, fill=(255, 255, 255, 255))
        by = y0 + pad
        for k in range(length):
            c = colours[int(k / max(length - 1, 1) * (len(colours) - 1) + 0.5)]
            draw.line((x0 + k, by, x0 + k, by + thick), fill=(*map(int, c), 255))
        draw.rectangle((x0, by, x0 + length, by + thick), outline=(255, 255, 255, 200))
        for t, text in zip(ticks, labels):
            x = x0 + t * length
            tw = draw.textbbox((0, 0), text, font=font)[2]
            draw.line((x, by + thick, x, by + thick + pad // 2), fill=(255, 255, 255, 230))
            draw.text((x - tw / 2, by + thick + pad // 2), text, font=font,
                      fill=(255, 255, 255, 255))
    # Pillow draws onto the transparent canvas without blending: each pixel holds the colour and
    # alpha last drawn, which is what is laid over the image.
    rgba = np.asarray(overlay)
    rows = np.flatnonzero(rgba[..., 3].any(axis=1))
    cols = np.flatnonzero(rgba[..., 3].any(axis=0))
    if rows.size == 0:
        return ColorbarOverlay(np.zeros((0, 0, 4), np.uint8), 0, 0)
    patch = rgba[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    return ColorbarOverlay(patch, int(rows[0]), int(cols[0]))


def scene_colorbar_overlay(width: int, height: int, scene, volume, position: str = "right",
                           title: str = "value") -> ColorbarOverlay:
    """The colour bar of a scene's transfer function over its volume's value range (or window)."""
    from radiance_probes.scene.transfer import transfer_table
    if getattr(volume, "channel_count", 1) > 1:
        raise ValueError(f"a colour bar shows one transfer function; this volume has "
                         f"{volume.channel_count} channels, each with its own")
    table = transfer_table(scene.transfer_function if not scene.channels
                           else scene.channels[0].transfer_function)
    return colorbar_overlay(width, height, table[:, :3], volume.value_range, title, position)


def scene_colorbar(image: np.ndarray, scene, volume, position: str = "right",
                   title: str = "value") -> np.ndarray:
    h, w = image.shape[:2]
    return scene_colorbar_overlay(w, h, scene, volume, position, title).apply(image)
