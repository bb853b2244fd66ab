"""Error metrics of SPEC.md: relative RMSE over linear RGB and FLIP on the tone-mapped image."""
from __future__ import annotations

import numpy as np

from ..render.tonemap import tonemap


def rrmse(image: np.ndarray, reference: np.ndarray) -> float:
    """sqrt(mean((x - ref)^2)) / sqrt(mean(ref^2)) over all pixels and channels (float64)."""
    x = np.asarray(image, np.float64)
    ref = np.asarray(reference, np.float64)
    if x.shape != ref.shape:
        raise ValueError(f"image shape {x.shape} differs from the reference's {ref.shape}")
    denom = np.sqrt(np.mean(ref * ref))
    if not denom > 0:
        raise ValueError("the reference image is black: relative RMSE is undefined")
    return float(np.sqrt(np.mean((x - ref) ** 2)) / denom)


def reference_noise(half_a: np.ndarray, half_b: np.ndarray) -> float:
    """Relative RMS noise of the mean of two independent, equal-sized halves of a Monte Carlo
    estimate: var(a - b) = 4 var(mean), so it is rrmse(a, b) / 2 (relative to the mean's RMS)."""
    mean = 0.5 * (np.asarray(half_a, np.float64) + np.asarray(half_b, np.float64))
    return rrmse(half_a, half_b) * np.sqrt(np.mean(np.asarray(half_b, np.float64) ** 2)) \
        / np.sqrt(np.mean(mean ** 2)) / 2.0


def flip(image: np.ndarray, reference: np.ndarray, exposure: float = 1.0) -> float | None:
    """Mean LDR-FLIP (NVIDIA's flip-evaluator) between the tone-mapped sRGB images; None when the
    package is missing (it is an optional, benchmark-only dependency)."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    ref = tonemap(reference, exposure).astype(np.float32)
    test = tonemap(image, exposure).astype(np.float32)
    _, mean_error, _ = flip_evaluator.evaluate(ref, test, "LDR", inputsRGB=True, applyMagma=False)
    return float(mean_error)
