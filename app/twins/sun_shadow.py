"""NumPy twin of glsl/lib/sun_shadow.glsl along one line: the sun's shadow ray's transmittance by
ratio tracking (control None) or residual ratio tracking with a control optical depth (the light
grid's), over macrocells of piecewise-constant majorants and the control's lattice of spacing h.
Vectorised over independent estimates; the random numbers are NumPy's, not the shader's, so the
twin and the GLSL agree in distribution (mean, variance), not estimate by estimate."""
from __future__ import annotations

from typing import Callable

import numpy as np

RATIO_ROULETTE_BELOW = 0.1   # lib/tracking.glsl


def control_pieces(edges: np.ndarray, majorants: np.ndarray,
                   control_depth: Callable[[np.ndarray], np.ndarray] | None, h: float):
    """The ray's pieces [a, b) in order, each with its majorant m, clamped control extinction c
    and the roulette's reference P = exp(-(tau(t0) - tau(t_k))) (1 without a control):
    the cells (edges[i], edges[i + 1]) of majorant majorants[i] cut at the lattice
    t0 + k h (t0 = edges[0]); on lattice segment k, c = (tau(t_k) - tau(t_k+1)) / (t_k+1 - t_k),
    tau the control's optical depth (>= 0; 0 at the ray's end t1 = edges[-1]), clamped to [0, m]
    in each cell (0 in empty cells). control_depth None: c = 0 everywhere (ratio tracking)."""
    edges = np.asarray(edges, np.float64)
    majorants = np.asarray(majorants, np.float64)
    t0, t1 = float(edges[0]), float(edges[-1])
    count = int(np.ceil((t1 - t0) / h)) if control_depth is not None else 1
    nodes = np.minimum(t0 + np.arange(count + 1) * h, t1) if control_depth is not None \
        else np.array([t0, t1])
    if control_depth is not None:
        tau = np.maximum(np.asarray(control_depth(nodes), np.float64), 0.0)
        tau[nodes >= t1] = 0.0
        lengths = np.diff(nodes)
        slopes = np.where(lengths > 0, (tau[:-1] - tau[1:]) / np.where(lengths > 0, lengths, 1), 0)
    else:
        tau = np.zeros(2)
        slopes = np.zeros(1)
    cuts = np.unique(np.concatenate([edges, nodes]))
    a, b = cuts[:-1], cuts[1:]
    mid = 0.5 * (a + b)
    cell = np.clip(np.searchsorted(edges, mid, side="right") - 1, 0, len(majorants) - 1)
    segment = np.clip(np.searchsorted(nodes, mid, side="right") - 1, 0, len(slopes) - 1)
    m = majorants[cell]
    c = np.clip(slopes[segment], 0.0, np.maximum(m, 0.0))
    # the roulette's reference: the control's transmittance from t0 to the segment's start
    reference = np.exp(-np.maximum(tau[0] - tau[segment], 0.0))
    keep = b > a
    return a[keep], b[keep], m[keep], c[keep], reference[keep]


def sun_transmittance(sigma_t: Callable[[np.ndarray], np.ndarray], edges, majorants,
                      control_depth: Callable[[np.ndarray], np.ndarray] | None, h: float,
                      n: int, rng: np.random.Generator,
                      roulette_below: float = RATIO_ROULETTE_BELOW) -> np.ndarray:
    """n independent estimates of exp(-integral of sigma_t over [edges[0], edges[-1]]): sigma_t(t)
    the extinction at ray distances t (<= the cell's majorant), the control as control_pieces
    takes it. Per piece the control's factor exp(-c dt) is applied as t advances and each
    tentative collision (rate m) multiplies by 1 - (sigma_t - c) / m; Russian roulette below
    roulette_below times the piece's reference P (without a control P = 1: lib/tracking.glsl
    ratio_roulette)."""
    transmittance = np.ones(n)
    alive = np.ones(n, bool)
    for a, b, m, c, reference in zip(*control_pieces(edges, majorants, control_depth, h)):
        if m <= 0.0:
            continue   # an empty cell: control 0, nothing drawn
        t = np.full(n, a)
        live = alive.copy()
        while live.any():
            idx = np.flatnonzero(live)
            t_new = t[idx] - np.log(1.0 - rng.random(len(idx))) / m
            past = t_new >= b
            done, hit = idx[past], idx[~past]
            transmittance[done] *= np.exp(-c * (b - t[done]))
            live[done] = False
            if len(hit) == 0:
                break
            th = t_new[~past]
            transmittance[hit] *= np.exp(-c * (th - t[hit]))
            transmittance[hit] *= np.maximum(0.0, 1.0 - (np.asarray(sigma_t(th)) - c) / m)
            t[hit] = th
            below = roulette_below * reference
            low = hit[transmittance[hit] < below]
            if len(low):
                survive = rng.random(len(low)) * below < transmittance[low]
                ended = low[~survive]
                transmittance[ended] = 0.0
                transmittance[low[survive]] = below
                alive[ended] = False
                live[ended] = False
    return transmittance
