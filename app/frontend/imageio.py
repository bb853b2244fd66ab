"""Writing images: tone-mapped PNG, linear float32 .npy and OpenEXR."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from radiance_probes.rendering.tonemap import to_uint8


def save_png(path: str | Path, image: np.ndarray, exposure: float = 1.0) -> Path:
    from PIL import Image
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(to_uint8(image, exposure), "RGB").save(p)
    return p


def save_png8(path: str | Path, pixels: np.ndarray) -> Path:
    """An 8-bit RGB image (H, W, 3) as it is (already tone mapped)."""
    from PIL import Image
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(pixels, np.uint8), "RGB").save(p)
    return p


def save_npy(path: str | Path, image: np.ndarray) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    np.save(p, np.asarray(image, np.float32))
    return p


def save_exr(path: str | Path, image: np.ndarray) -> Path:
    try:
        import OpenEXR
    except ImportError:
        raise RuntimeError("writing EXR needs the OpenEXR package: pip install OpenEXR") from None
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, np.float32)}).write(str(p))
    return p
