"""Display encoding: exposure and the sRGB transfer curve. Comparisons use linear values."""
from __future__ import annotations

import numpy as np


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tonemap(image: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear RGB (H, W, 3) to display sRGB in [0, 1]: scale by exposure, clip, encode."""
    with np.errstate(over="ignore"):   # a huge exposure overflows to inf, which clips to 1
        return srgb_encode(np.asarray(image, np.float64) * exposure)


def to_uint8(image: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    return np.round(tonemap(image, exposure) * 255.0).astype(np.uint8)
