"""NumPy twin of glsl/lib/guided_distances.glsl: `guided`'s real-or-null choice at a tentative
collision of delta tracking, the mixture of the analog probability a = sigma_t / majorant and the
zero-variance one that follows what the probes predict each outcome brings back, and the path
weights that keep delta tracking's mean."""
from __future__ import annotations

import numpy as np


def collision_probability(a, albedo_source, beyond, share):
    """The probability of a real collision: a = sigma_t / majorant in (0, 1), albedo_source =
    albedo times the predicted in-scattered luminance S, beyond = the predicted luminance B
    arriving from further along the ray (both >= 0), share = P in [0, 1). Where a S and (1 - a) B
    are both 0 the zero-variance choice is a itself."""
    a = np.asarray(a, np.float64)
    real = a * np.asarray(albedo_source, np.float64)
    null = (1.0 - a) * np.asarray(beyond, np.float64)
    total = real + null
    z = np.where(total > 0.0, real / np.where(total > 0.0, total, 1.0), a)
    return (1.0 - share) * a + share * z


def decision_weights(a, p):
    """The throughput's factor after a real collision (a / p) and after a null one
    ((1 - a) / (1 - p)): each outcome's probability times its factor is the analog one's."""
    a = np.asarray(a, np.float64)
    p = np.asarray(p, np.float64)
    return a / p, (1.0 - a) / (1.0 - p)


# A flight decides as delta tracking does once its weight product leaves [1 / bound, bound].
FLIGHT_WEIGHT_BOUND = 4.0


def track_1d(sigma_t, majorant: float, length: float, source, beyond, share: float,
             rng: np.random.Generator, n: int, bound: float = FLIGHT_WEIGHT_BOUND):
    """n flights from 0 along [0, length] through a medium of extinction sigma_t(x) (vectorised
    callable, <= majorant), decided as the GLSL decides (analog where sigma_t is 0 or the
    majorant, or once the flight's weight has left [1 / bound, bound]). Returns (weight,
    collided, x): the flight's weight product, whether it ended in a real collision, and
    where."""
    x = np.zeros(n)
    weight = np.ones(n)
    alive = np.ones(n, bool)
    collided = np.zeros(n, bool)
    while alive.any():
        i = np.nonzero(alive)[0]
        x[i] -= np.log(1.0 - rng.random(i.size)) / majorant
        out = x[i] >= length
        alive[i[out]] = False
        i = i[~out]
        a = sigma_t(x[i]) / majorant
        guided = (a > 0.0) & (a < 1.0) & (weight[i] <= bound) & (weight[i] * bound >= 1.0)
        p = np.where(guided, collision_probability(a, source(x[i]), beyond(x[i]), share), a)
        real = rng.random(i.size) < p
        w_real, w_null = decision_weights(np.where(guided, a, 0.5), np.where(guided, p, 0.5))
        weight[i] *= np.where(guided, np.where(real, w_real, w_null), 1.0)
        collided[i[real]] = True
        alive[i[real]] = False
    return weight, collided, x
