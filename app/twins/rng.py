"""NumPy twin of glsl/lib/rng.glsl (PCG-RXS-M-XS 32), bit for bit."""
from __future__ import annotations

import numpy as np

_MUL = np.uint32(747796405)
_INC = np.uint32(2891336453)
_OUT = np.uint32(277803737)


def _permute(state: np.ndarray) -> np.ndarray:
    word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * _OUT
    return (word >> np.uint32(22)) ^ word


def pcg_hash(v) -> np.ndarray:
    with np.errstate(over="ignore"):
        state = np.asarray(v, np.uint32) * _MUL + _INC
        return _permute(state)


def rng_seed(key, sample_index, seed) -> np.ndarray:
    k = np.asarray(key, np.uint32)
    s = np.asarray(sample_index, np.uint32)
    return pcg_hash(k ^ pcg_hash(s ^ pcg_hash(np.asarray(seed, np.uint32))))


def rng_next_uint(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Returns (new_state, value)."""
    with np.errstate(over="ignore"):
        state = np.asarray(state, np.uint32) * _MUL + _INC
        return state, _permute(state)


def rng_next(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Returns (new_state, uniform float32 in [0, 1))."""
    state, v = rng_next_uint(state)
    return state, ((v >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0))
