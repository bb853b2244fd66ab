"""Opacity presets (the viewer's transfer-function panel): ramps, and tents over the peaks of the
volume's histogram (the materials a CT or a scan holds), and colour points from a colormap to
edit one by one. Densities are normalised ([0, 1] over the value range or window).

A histogram peak is a local maximum of the log counts (smoothed over a few bins) that stands out
from the valleys on both sides by PEAK_PROMINENCE of the log range; the bins below
BACKGROUND_DENSITY hold air or padding in most scans and are left out. A peak's tent spans the
half-prominence width on each side (at least MIN_HALF_WIDTH), peaking at opacity 1.
"""
from __future__ import annotations

import numpy as np

HISTOGRAM_BINS = 256
BACKGROUND_DENSITY = 0.02
PEAK_PROMINENCE = 0.05
MIN_HALF_WIDTH = 0.02
MAX_PEAKS = 4
COLOUR_POINTS = 5        # colour points a colormap becomes when its colours are edited as points

RAMPS = {
    "ramp": ((0.0, 0.0), (1.0, 1.0)),
    "ramp upper half": ((0.0, 0.0), (0.5, 0.0), (1.0, 1.0)),
    "steep ramp": ((0.0, 0.0), (0.3, 0.0), (0.45, 1.0), (1.0, 1.0)),
    "flat": ((0.0, 0.0), (0.1, 0.0), (0.1, 0.5), (1.0, 0.5)),
}


def _smooth(values: np.ndarray, radius: int = 2) -> np.ndarray:
    x = np.arange(-2 * radius, 2 * radius + 1)
    kernel = np.exp(-0.5 * (x / max(radius, 1)) ** 2)
    kernel /= kernel.sum()
    padded = np.pad(values, 2 * radius, mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def histogram_peaks(counts: np.ndarray, max_peaks: int = MAX_PEAKS) -> list[tuple[float, float]]:
    """(centre, half width) in normalised density of the histogram's peaks, most prominent first.
    `counts` over equal bins of [0, 1]."""
    counts = np.asarray(counts, np.float64)
    n = len(counts)
    if n < 3 or counts.sum() <= 0:
        return []
    log = _smooth(np.log1p(counts))
    span = log.max() - log.min()
    if span <= 0:
        return []
    centres = (np.arange(n) + 0.5) / n
    peaks = []
    for i in range(1, n - 1):
        if not (log[i] > log[i - 1] and log[i] >= log[i + 1]) or centres[i] < BACKGROUND_DENSITY:
            continue
        # prominence: the peak over the higher of the lowest points on each side before a higher peak
        left = i
        low_left = log[i]
        while left > 0 and log[left - 1] <= log[i]:
            left -= 1
            low_left = min(low_left, log[left])
        right = i
        low_right = log[i]
        while right < n - 1 and log[right + 1] <= log[i]:
            right += 1
            low_right = min(low_right, log[right])
        prominence = log[i] - max(low_left, low_right)
        if prominence < PEAK_PROMINENCE * span:
            continue
        half = log[i] - prominence / 2
        lo = i
        while lo > 0 and log[lo - 1] > half:
            lo -= 1
        hi = i
        while hi < n - 1 and log[hi + 1] > half:
            hi += 1
        width = max((hi - lo + 1) / (2 * n), MIN_HALF_WIDTH)
        peaks.append((prominence, float(centres[i]), float(width)))
    peaks.sort(reverse=True)
    return [(c, w) for _, c, w in peaks[:max_peaks]]


def peak_opacity(peaks: list[tuple[float, float]], height: float = 1.0
                 ) -> tuple[tuple[float, float], ...]:
    """An opacity curve of tents over the given peaks (centre, half width), 0 elsewhere."""
    points: list[tuple[float, float]] = [(0.0, 0.0)]
    for centre, width in sorted(peaks):
        lo, hi = max(centre - width, 0.0), min(centre + width, 1.0)
        lo = max(lo, points[-1][0])
        points += [(lo, 0.0), (max(centre, lo), float(height)), (max(hi, centre, lo), 0.0)]
    points.append((1.0, 0.0))
    # drop points that repeat their neighbour exactly
    out = [points[0]]
    for p in points[1:]:
        if p != out[-1]:
            out.append(p)
    return tuple((float(x), float(y)) for x, y in out)


def opacity_presets(volume=None, channel: int = 0) -> dict[str, tuple[tuple[float, float], ...]]:
    """Preset name -> opacity control points: the ramps, and with a volume one tent per histogram
    peak ("peak at <value>") and all its peaks together (of several channels, channel's)."""
    presets = dict(RAMPS)
    if volume is None:
        return presets
    counts = volume.histogram(HISTOGRAM_BINS, channel)
    peaks = histogram_peaks(counts)
    lo, hi = volume.channel_ranges[channel] if volume.channel_ranges else volume.value_range
    for centre, width in peaks:
        presets[f"peak at {lo + centre * (hi - lo):.4g}"] = peak_opacity([(centre, width)])
    if len(peaks) > 1:
        presets["all peaks"] = peak_opacity(peaks)
    return presets


def colour_points_from(rgb: np.ndarray, count: int = COLOUR_POINTS
                       ) -> tuple[tuple[float, float, float, float], ...]:
    """`count` evenly spaced colour points (density, r, g, b) sampled from a colour table (n, 3)."""
    rgb = np.asarray(rgb, np.float64)
    src = np.linspace(0.0, 1.0, len(rgb))
    xs = np.linspace(0.0, 1.0, count)
    cols = np.stack([np.interp(xs, src, rgb[:, c]) for c in range(3)], axis=1)
    return tuple((float(x), *map(float, np.clip(c, 0.0, 1.0))) for x, c in zip(xs, cols))
