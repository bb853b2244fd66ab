"""The API's image: linear RGB radiance (float32, height x width x 3, row 0 at the top) with what
made it; shown inline in Jupyter (``_repr_png_``), saved as PNG, .npy or OpenEXR."""
from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Image:
    linear: np.ndarray             # (H, W, 3) float32 linear RGB radiance
    method: str
    spp: int                       # samples (frames, for the raymarcher) per pixel
    scene: object                  # the app.scene.Scene it was rendered from
    render_ms: float = 0.0         # GPU time of the render passes
    bake_ms: float = 0.0           # GPU time of the probe bake this image waited for (0: reused)
    exposure: float = 1.0          # what PNGs and the inline view use
    notes: tuple[str, ...] = field(default=())   # how the data was read (series, orientation)

    # ---- an array, for NumPy ---------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, ...]:
        return self.linear.shape

    @property
    def dtype(self):
        return self.linear.dtype

    def __array__(self, dtype=None, copy=None):
        return self.linear if dtype is None else self.linear.astype(dtype)

    def __getitem__(self, index):
        return self.linear[index]

    def __len__(self) -> int:
        return len(self.linear)

    # ---- what a person sees ------------------------------------------------------------------
    def srgb8(self, exposure: float | None = None) -> np.ndarray:
        """The tone-mapped 8-bit sRGB picture (H, W, 3)."""
        from radiance_probes.rendering.tonemap import to_uint8
        return to_uint8(self.linear, self.exposure if exposure is None else exposure)

    def png_bytes(self, exposure: float | None = None) -> bytes:
        from PIL import Image as PILImage
        buffer = io.BytesIO()
        PILImage.fromarray(self.srgb8(exposure), "RGB").save(buffer, format="PNG")
        return buffer.getvalue()

    def _repr_png_(self) -> bytes:
        return self.png_bytes()

    def __repr__(self) -> str:
        h, w, _ = self.linear.shape
        return (f"<radiance_probes.Image {w}x{h} {self.method}, {self.spp} spp, "
                f"render {self.render_ms:.1f} ms, bake {self.bake_ms:.1f} ms>")

    def save(self, path: str | Path, exposure: float | None = None) -> Path:
        """Writes the image by its suffix: .png (tone-mapped), .npy or .exr (linear)."""
        from radiance_probes.frontend.imageio import save_exr, save_npy, save_png
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".png":
            return save_png(p, self.linear, self.exposure if exposure is None else exposure)
        if suffix == ".npy":
            return save_npy(p, self.linear)
        if suffix == ".exr":
            return save_exr(p, self.linear)
        raise ValueError(f"{p}: expected a .png, .npy or .exr file name")
