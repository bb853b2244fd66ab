import numpy as np
import pytest

from radiance_probes.twins.directions import (fibonacci_direction, fibonacci_directions,
                                              random_rotation)
from radiance_probes.twins.sh import sh_project_function, sh_project_samples
from glsl_harness import run_kernel

FIBONACCI_KERNEL = """
#include "lib/directions.glsl"
layout(std430, binding = 0) readonly buffer Index { uint index[]; };
layout(std430, binding = 1) writeonly buffer Out { float result[]; };
uniform uint n;
void main() {
    uint k = gl_GlobalInvocationID.x;
    if (k >= count) return;
    vec3 w = fibonacci_direction(index[k], n);
    result[3 * k] = w.x; result[3 * k + 1] = w.y; result[3 * k + 2] = w.z;
}
"""

# Rows of R (GLSL indexes R[column][row]), then R applied to fibonacci_direction(k % n, n).
ROTATION_KERNEL = """
#include "lib/directions.glsl"
layout(std430, binding = 0) readonly buffer U { float u[]; };
layout(std430, binding = 1) writeonly buffer Out { float result[]; };
uniform uint n;
void main() {
    uint k = gl_GlobalInvocationID.x;
    if (k >= count) return;
    mat3 R = random_rotation(u[3 * k], u[3 * k + 1], u[3 * k + 2]);
    for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 3; ++col)
            result[12 * k + 3 * row + col] = R[col][row];
    vec3 w = R * fibonacci_direction(k % n, n);
    result[12 * k + 9] = w.x; result[12 * k + 10] = w.y; result[12 * k + 11] = w.z;
}
"""


@pytest.mark.parametrize("n", [7, 256, 4096])
def test_glsl_fibonacci_matches_numpy(ctx, n):
    i = np.arange(n, dtype=np.uint32)
    got = run_kernel(ctx, FIBONACCI_KERNEL, [i], (n, 3), uniforms={"n": n})
    np.testing.assert_allclose(got, fibonacci_direction(i, n), rtol=0, atol=2e-6)


def test_glsl_fibonacci_exact_for_large_index(ctx):
    """Large i, close to n = 2^22: the fixed-point fraction stays exact in GLSL."""
    n = 1 << 22
    i = np.concatenate([np.arange(n - 512, n), np.arange(1_000_000, 1_000_256)]).astype(np.uint32)
    got = run_kernel(ctx, FIBONACCI_KERNEL, [i], (len(i), 3), uniforms={"n": n})
    np.testing.assert_allclose(got, fibonacci_direction(i, n), rtol=0, atol=2e-6)
    # phi follows the exact golden ratio up to the drift of its 32-bit value, i * 2pi * 1.2e-10
    i64 = i.astype(np.float64)
    phi_exact = 2 * np.pi * np.mod(i64 * (np.sqrt(5) - 1) / 2, 1.0)
    drift = 2 * np.pi * i64 * abs(0x9E3779B9 / 2**32 - (np.sqrt(5) - 1) / 2)
    wrap = lambda a: np.angle(np.exp(1j * a))
    dphi = wrap(np.arctan2(got[:, 1], got[:, 0]) - phi_exact)
    assert np.all(np.abs(dphi) < drift + 1e-5)
    # whereas float32 fract(i * 0.618...) is off by far more
    naive = np.float32(i) * np.float32((np.sqrt(5) - 1) / 2)
    naive_phi = 2 * np.pi * (naive - np.floor(naive)).astype(np.float64)
    assert np.abs(wrap(naive_phi - phi_exact)).max() > 10 * (drift.max() + 1e-5)


@pytest.mark.parametrize("n", [7, 256, 4096])
def test_fibonacci_unit_and_z_layout(n):
    w = fibonacci_directions(n)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(w[:, 2], 1 - (2 * np.arange(n) + 1) / n, atol=1e-15)


def test_fibonacci_is_nearly_uniform():
    n = 256
    w = fibonacci_directions(n)
    assert np.linalg.norm(w.mean(axis=0)) < 1e-3
    c = sh_project_samples(w, np.ones(n))
    assert abs(c[0] - np.sqrt(4 * np.pi)) < 1e-3 * np.sqrt(4 * np.pi)
    assert np.abs(c[1:]).max() < 1e-3 * c[0]
    # a non-constant signal: the clamped cosine, against quadrature
    clamped_cosine = lambda v: np.maximum(0.0, v[:, 2])
    np.testing.assert_allclose(sh_project_samples(w, clamped_cosine(w)),
                               sh_project_function(clamped_cosine), atol=2e-3)


def test_random_rotation_is_proper_numpy():
    u = np.random.default_rng(0).random((2000, 3))
    R = random_rotation(u[:, 0], u[:, 1], u[:, 2])
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # edge values of the uniforms
    for u1, u2, u3 in [(0, 0, 0), (0.999999, 0.5, 1.0), (0.25, 0.75, 0.5)]:
        Q = random_rotation(u1, u2, u3)
        np.testing.assert_allclose(Q.T @ Q, np.eye(3), atol=1e-12)
        assert np.linalg.det(Q) == pytest.approx(1.0)


def test_random_rotation_is_haar_distributed():
    """Under the uniform (Haar) measure on SO(3): E[R] = 0, E[tr R] = 0, E[(tr R)^2] = 1."""
    u = np.random.default_rng(1).random((200_000, 3))
    R = random_rotation(u[:, 0], u[:, 1], u[:, 2])
    trace = np.trace(R, axis1=-2, axis2=-1)
    assert np.abs(R.mean(axis=0)).max() < 0.01
    assert abs(trace.mean()) < 0.01
    assert abs((trace ** 2).mean() - 1.0) < 0.02
    # a rotated fixed axis is uniform on the sphere: second moments I/3
    axis = R[:, :, 2]
    np.testing.assert_allclose(axis.T @ axis / len(axis), np.eye(3) / 3, atol=0.01)


def test_glsl_random_rotation_matches_numpy(ctx):
    m, n = 1000, 256
    u = np.random.default_rng(2).random((m, 3)).astype(np.float32)
    got = run_kernel(ctx, ROTATION_KERNEL, [u], (m, 12), count=m, uniforms={"n": n})
    R_glsl = got[:, :9].reshape(m, 3, 3).astype(np.float64)
    R = random_rotation(u[:, 0], u[:, 1], u[:, 2])
    np.testing.assert_allclose(R_glsl, R, atol=2e-6)
    np.testing.assert_allclose(np.swapaxes(R_glsl, -1, -2) @ R_glsl,
                               np.broadcast_to(np.eye(3), R.shape), atol=1e-5)
    np.testing.assert_allclose(np.linalg.det(R_glsl), 1.0, atol=1e-5)
    # rotated Fibonacci directions stay unit, and equal R applied to the NumPy set
    rotated = got[:, 9:]
    np.testing.assert_allclose(np.linalg.norm(rotated, axis=1), 1.0, atol=1e-5)
    expected = np.einsum("kij,kj->ki", R, fibonacci_direction(np.arange(m) % n, n))
    np.testing.assert_allclose(rotated, expected, atol=4e-6)


def test_rotated_fibonacci_set_remains_unit_numpy():
    w = fibonacci_directions(4096)
    R = random_rotation(0.3, 0.7, 0.2)
    np.testing.assert_allclose(np.linalg.norm(w @ R.T, axis=1), 1.0, atol=1e-14)
