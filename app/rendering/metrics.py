"""Error metrics of SPEC.md: relative RMSE over linear RGB and FLIP on the tone-mapped image."""
from __future__ import annotations

import math

import numpy as np

from radiance_probes.rendering.tonemap import tonemap


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


def block_rrmse(image: np.ndarray, reference: np.ndarray, block: int = 16) -> float:
    """rRMSE of the images' means over block x block pixel tiles (partial tiles at the right and
    bottom edges left out): the error a person sees at the scale of features rather than of
    pixels, and what the held-out checks report (16 px blocks)."""
    x = np.asarray(image, np.float64)
    ref = np.asarray(reference, np.float64)
    if x.shape != ref.shape:
        raise ValueError(f"image shape {x.shape} differs from the reference's {ref.shape}")
    h, w = (x.shape[0] // block) * block, (x.shape[1] // block) * block
    if h == 0 or w == 0:
        raise ValueError(f"image {x.shape[1]}x{x.shape[0]} is smaller than one {block}-pixel block")

    def tiles(a):
        a = a[:h, :w]
        return a.reshape(h // block, block, w // block, block, -1).mean(axis=(1, 3))
    return rrmse(tiles(x), tiles(ref))


def reference_noise(half_a: np.ndarray, half_b: np.ndarray) -> float:
    """Relative RMS noise of the mean of two independent, equal-sized halves of a Monte Carlo
    estimate: var(a - b) = 4 var(mean), so it is rrmse(a, b) / 2 (relative to the mean's RMS)."""
    mean = 0.5 * (np.asarray(half_a, np.float64) + np.asarray(half_b, np.float64))
    return rrmse(half_a, half_b) * np.sqrt(np.mean(np.asarray(half_b, np.float64) ** 2)) \
        / np.sqrt(np.mean(mean ** 2)) / 2.0


def corrected_rrmse(measured: float, noise: float) -> float:
    """The relative RMSE against the true image, estimated from the one measured against a noisy
    reference (float; negative when the measurement cannot tell the error from zero).

    With the reference r = t + n (t the converged image, n its Monte Carlo noise, independent of
    the image x under test and of mean zero), per value
        E[(x - r)^2] = (x - t)^2 + var(n)   and   E[r^2] = t^2 + var(n),
    so mean((x - t)^2) = mean((x - r)^2) - v and mean(t^2) = mean(r^2) - v, v = mean(var(n)).
    The reference is the mean of two independent halves a, b, so n = (n_a + n_b) / 2 and
    E[(a - b)^2] = 4 var(n): v = mean((a - b)^2) / 4, which reference_noise reports relative to
    the reference, noise^2 = v / mean(r^2). Dividing both by mean(r^2):
        e_true^2 = (measured^2 - noise^2) / (1 - noise^2).
    The sign is kept (sqrt of the magnitude), so a caller can tell an error below the noise."""
    num = measured * measured - noise * noise
    value = math.sqrt(abs(num) / max(1.0 - noise * noise, 1e-12))
    return value if num >= 0 else -value


def corrected_floor(noise: float, values: int, sigmas: float = 3.0) -> float:
    """The smallest true relative RMSE that corrected_rrmse resolves: where the corrected mean
    square error is `sigmas` standard errors above zero. With Gaussian noise of relative variance
    noise^2 per value and a true error c, mean((x - r)^2) over N values has variance
    (4 c^2 noise^2 + 2 noise^4) / N, and the noise estimate from the halves adds 2 noise^4 / N;
    at c = 0 the standard error is 2 noise^2 / sqrt(N), so the floor is
    noise * sqrt(2 sigmas / sqrt(N)). N is the pixel count (a pixel's channels share a path, so
    their noise is not independent): at 512^2 this is about a tenth of the reference's noise."""
    return noise * math.sqrt(2.0 * sigmas / math.sqrt(max(values, 1)))


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
