"""NumPy twin of glsl/probe_albedo_guide.comp: the raymarched probes image made the denoiser's
albedo guide, its scale the quantile of the pixels' largest channel read from a histogram of
their float32 bits (32 bins an octave) rather than a sort (radiance_as_albedo, the host's)."""
from __future__ import annotations

import numpy as np

HISTOGRAM_BIN_SHIFT = 18
HISTOGRAM_BINS = 1 << (31 - HISTOGRAM_BIN_SHIFT)


def _usable(image: np.ndarray) -> np.ndarray:
    """lib/usable_radiance.glsl unsigned: non-finite and negative components 0 (float32 RGB)."""
    rgb = np.asarray(image, np.float32)[..., :3]
    return np.where(np.isfinite(rgb), np.maximum(rgb, np.float32(0.0)), np.float32(0.0))


def largest_channel(image: np.ndarray) -> np.ndarray:
    return _usable(image).max(axis=-1)


def peak_histogram(image: np.ndarray) -> np.ndarray:
    """Pass 0: each bin's count of pixels whose largest channel's bits >> HISTOGRAM_BIN_SHIFT
    fall in it."""
    bins = largest_channel(image).ravel().view(np.uint32) >> HISTOGRAM_BIN_SHIFT
    return np.bincount(bins, minlength=HISTOGRAM_BINS).astype(np.uint32)


def guide_scale(image: np.ndarray, quantile: float) -> float:
    """Pass 1: the value at np.quantile's rank quantile * (n - 1), interpolated linearly in the
    bin that holds it (its count spread evenly over the bin); 0 where that bin is bin 0."""
    counts = peak_histogram(image).astype(np.int64)
    n = int(counts.sum())
    if n == 0:
        return 0.0
    rank = np.float32(quantile) * np.float32(n - 1)
    k = int(np.floor(rank))
    cumulative = np.cumsum(counts)
    bin_ = int(np.searchsorted(cumulative, k, side="right"))
    if bin_ == 0:
        return 0.0
    below = int(cumulative[bin_ - 1])
    low = np.array([bin_ << HISTOGRAM_BIN_SHIFT], np.uint32).view(np.float32)[0]
    high = np.array([(bin_ + 1) << HISTOGRAM_BIN_SHIFT], np.uint32).view(np.float32)[0]
    t = np.clip((rank - np.float32(below) + np.float32(0.5)) / np.float32(counts[bin_]), 0, 1)
    return float(low + np.float32(t) * (high - low))


def albedo_guide(image: np.ndarray, quantile: float) -> np.ndarray:
    """Pass 2: (H, W, 3) float32, the usable radiance over the scale clamped to [0, 1] (0
    throughout where the scale is 0)."""
    usable = _usable(image)
    scale = np.float32(guide_scale(image, quantile))
    if not scale > 0:
        return np.zeros(usable.shape, np.float32)
    return np.clip(usable / scale, 0.0, 1.0).astype(np.float32)
