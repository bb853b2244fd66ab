import numpy as np
import pytest

from radiance_probes.twins.directions import fibonacci_directions
from radiance_probes.twins.phase import phase_hg
from radiance_probes.twins.sh import (SH_WINDOW_HANN, SH_WINDOW_LANCZOS, SH_WINDOW_NONE,
                                      sh_band_factors, sh_basis, sh_clamp_nonnegative, sh_evaluate,
                                      sh_evaluate_convolved, sh_project_function,
                                      sh_project_samples, sphere_quadrature)
from glsl_harness import run_kernel

WINDOWS = [SH_WINDOW_NONE, SH_WINDOW_HANN, SH_WINDOW_LANCZOS]

ORDERS = [2, 3, 4]   # SH_ORDER of lib/sh.glsl builds

# Directions as a flat float[] (std430 vec3 arrays would pad to 16 bytes), coefficients as
# 3 * SH_COUNT floats.
KERNEL_IO = """
#include "lib/sh.glsl"
layout(std430, binding = 0) readonly buffer Dirs { float dirs[]; };
layout(std430, binding = 1) readonly buffer Coeffs { float coeff_data[3 * SH_COUNT]; };
layout(std430, binding = 2) writeonly buffer Out { float result[]; };
vec3 direction(uint i) { return vec3(dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]); }
void load_coeffs(out vec3 c[SH_COUNT])
{
    for (int k = 0; k < SH_COUNT; ++k)
        c[k] = vec3(coeff_data[3 * k], coeff_data[3 * k + 1], coeff_data[3 * k + 2]);
}
"""


def random_directions(n, seed=0):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def f32(a):
    return np.ascontiguousarray(a, np.float32)


def test_basis_convention_matches_sloan_constants():
    x, y, z = 0.36, -0.48, 0.8
    expected = [0.282095, 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y,
                1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z,
                0.546274 * (x * x - y * y)]
    np.testing.assert_allclose(sh_basis([x, y, z]), expected, atol=1e-6)


def test_basis_band_3_and_4_match_closed_forms():
    """Sloan's tables (no Condon-Shortley phase) at one direction, written out independently."""
    x, y, z = 0.36, -0.48, 0.8
    pi = np.pi
    band3 = [np.sqrt(35 / (32 * pi)) * y * (3 * x * x - y * y), np.sqrt(105 / (4 * pi)) * x * y * z,
             np.sqrt(21 / (32 * pi)) * y * (4 * z * z - x * x - y * y),
             np.sqrt(7 / (16 * pi)) * z * (2 * z * z - 3 * x * x - 3 * y * y),
             np.sqrt(21 / (32 * pi)) * x * (4 * z * z - x * x - y * y),
             np.sqrt(105 / (16 * pi)) * z * (x * x - y * y), np.sqrt(35 / (32 * pi)) * x * (x * x - 3 * y * y)]
    band4_m0 = 3 / (16 * np.sqrt(pi)) * (35 * z ** 4 - 30 * z ** 2 + 3)
    band4_m4 = 3 / 16 * np.sqrt(35 / pi) * (x ** 4 - 6 * x * x * y * y + y ** 4)
    got = sh_basis([x, y, z], 4)
    np.testing.assert_allclose(got[9:16], band3, atol=1e-12)
    np.testing.assert_allclose([got[20], got[24]], [band4_m0, band4_m4], atol=1e-12)
    np.testing.assert_array_equal(sh_basis([x, y, z], 2), got[:9])


@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
def test_orthonormal_by_quadrature(order):
    k = (order + 1) ** 2
    gram = sh_project_function(lambda w: sh_basis(w, order), n=8, order=order)
    np.testing.assert_allclose(gram, np.eye(k), atol=1e-6)


def test_each_band_is_harmonic_funk_hecke():
    """int P_l(w . d) Y_lm(w) dw = 4 pi / (2l + 1) Y_lm(d) for band l, 0 for the others: the basis
    functions of band l are degree-l spherical harmonics (not just any orthonormal set)."""
    from numpy.polynomial.legendre import legval
    dirs, weights = sphere_quadrature(24)
    d = random_directions(5, seed=11)
    basis = sh_basis(dirs, 4)
    band = np.floor(np.sqrt(np.arange(25) + 0.5))
    for l in range(5):
        kernel = legval(d @ dirs.T, np.eye(5)[l])                       # (5, M)
        lhs = (kernel * weights) @ basis
        rhs = 4 * np.pi / (2 * l + 1) * sh_basis(d, 4) * (band == l)
        np.testing.assert_allclose(lhs, rhs, atol=1e-10)


def test_projection_of_constant():
    c = sh_project_function(lambda w: np.full(len(w), 2.5))
    expected = np.zeros(9)
    expected[0] = 2.5 * np.sqrt(4 * np.pi)
    np.testing.assert_allclose(c, expected, atol=1e-9)


def test_projection_of_clamped_cosine():
    c = sh_project_function(lambda w: np.maximum(0.0, w[:, 2]))
    expected = np.zeros(9)
    expected[0] = np.sqrt(np.pi) / 2
    expected[2] = np.sqrt(np.pi / 3)
    expected[6] = np.sqrt(5 * np.pi) / 8
    np.testing.assert_allclose(c, expected, atol=1e-9)


def test_project_samples_recovers_band_limited_signal():
    coeffs = np.random.default_rng(3).normal(size=(9, 3))
    # equal weights 4pi/N over a nearly uniform set: accurate to O(1/N) here
    fib = fibonacci_directions(4096)
    got = sh_project_samples(fib, sh_evaluate(coeffs, fib))
    np.testing.assert_allclose(got, coeffs, atol=2e-4)


@pytest.mark.parametrize("order", ORDERS)
def test_glsl_basis_matches_numpy(ctx, order):
    w = random_directions(1000)
    k = (order + 1) ** 2
    got = run_kernel(ctx, KERNEL_IO + """
        void main() {
            uint i = gl_GlobalInvocationID.x;
            if (i >= count) return;
            float basis[SH_COUNT];
            sh_basis(direction(i), basis);
            for (int k = 0; k < SH_COUNT; ++k) result[SH_COUNT * i + k] = basis[k];
        }
    """, [f32(w), np.zeros(3 * k, np.float32)], (len(w), k), count=len(w),
        defines={"SH_ORDER": order})
    np.testing.assert_allclose(got, sh_basis(w, order), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("order", ORDERS)
def test_glsl_evaluate_matches_numpy(ctx, order):
    w = random_directions(1000, seed=1)
    coeffs = np.random.default_rng(2).normal(size=((order + 1) ** 2, 3))
    got = run_kernel(ctx, KERNEL_IO + """
        void main() {
            uint i = gl_GlobalInvocationID.x;
            if (i >= count) return;
            vec3 c[SH_COUNT];
            load_coeffs(c);
            vec3 value = sh_evaluate(c, direction(i));
            result[3 * i] = value.r; result[3 * i + 1] = value.g; result[3 * i + 2] = value.b;
        }
    """, [f32(w), f32(coeffs)], (len(w), 3), count=len(w), defines={"SH_ORDER": order})
    expected = sh_evaluate(f32(coeffs), f32(w))
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5 * np.abs(expected).max())


def test_band_factors_values():
    np.testing.assert_allclose(sh_band_factors(0.5, SH_WINDOW_NONE), [1, 0.5, 0.25])
    np.testing.assert_allclose(sh_band_factors(1.0, SH_WINDOW_HANN), [1, 0.75, 0.25])
    np.testing.assert_allclose(sh_band_factors(1.0, SH_WINDOW_LANCZOS),
                               [1, np.sin(np.pi / 3) / (np.pi / 3),
                                np.sin(2 * np.pi / 3) / (2 * np.pi / 3)])
    np.testing.assert_allclose(sh_band_factors(0.0, SH_WINDOW_HANN), [1, 0, 0])
    np.testing.assert_allclose(sh_band_factors(0.5, SH_WINDOW_NONE, 4), [1, 0.5, 0.25, 0.125, 0.0625])
    # the windows' width follows the order: Hann w = 5 at order 4
    np.testing.assert_allclose(sh_band_factors(1.0, SH_WINDOW_HANN, 4),
                               0.5 * (1 + np.cos(np.pi * np.arange(5) / 5)))


@pytest.mark.parametrize("order", ORDERS)
def test_glsl_convolved_matches_numpy(ctx, order):
    w = random_directions(500, seed=4)
    coeffs = np.random.default_rng(5).normal(size=((order + 1) ** 2, 3))
    bands = order + 1
    kernel = KERNEL_IO + """
        uniform float g;
        uniform int window;
        void main() {
            uint i = gl_GlobalInvocationID.x;
            if (i >= count) return;
            vec3 c[SH_COUNT];
            load_coeffs(c);
            float factors[SH_BANDS] = sh_band_factors(g, window);
            vec3 value = sh_evaluate_convolved(c, direction(i), factors);
            result[(3 + SH_BANDS) * i] = value.r;
            result[(3 + SH_BANDS) * i + 1] = value.g;
            result[(3 + SH_BANDS) * i + 2] = value.b;
            for (int l = 0; l < SH_BANDS; ++l)
                result[(3 + SH_BANDS) * i + 3 + l] = factors[l];
        }
    """
    for window in WINDOWS:
        for g in [-0.7, 0.0, 0.3, 0.9]:
            got = run_kernel(ctx, kernel, [f32(w), f32(coeffs)], (len(w), 3 + bands),
                             count=len(w), uniforms={"g": g, "window": window},
                             defines={"SH_ORDER": order})
            factors = sh_band_factors(g, window, order)
            np.testing.assert_allclose(got[:, 3:], np.broadcast_to(factors, (len(w), bands)),
                                       rtol=1e-6, atol=1e-7)
            expected = sh_evaluate_convolved(f32(coeffs), f32(w), factors)
            np.testing.assert_allclose(got[:, :3], expected, rtol=1e-5,
                                       atol=1e-5 * np.abs(expected).max())


@pytest.mark.parametrize("order", [2, 4])
@pytest.mark.parametrize("g", [-0.9, -0.5, 0.0, 0.5, 0.9])
def test_hg_convolution_matches_brute_force(g, order):
    """L_s(d) = integral p_HG(dot(omega, d)) L_in(omega) d omega, by quadrature over omega."""
    coeffs = np.random.default_rng(6).normal(size=((order + 1) ** 2, 3))
    d = random_directions(24, seed=7)
    omega, weights = sphere_quadrature(128)
    brute = (phase_hg(d @ omega.T, g) * weights) @ sh_evaluate(coeffs, omega)
    funk_hecke = sh_evaluate_convolved(coeffs, d, sh_band_factors(g, SH_WINDOW_NONE, order))
    np.testing.assert_allclose(funk_hecke, brute, rtol=0, atol=1e-8)


def delta_lobe_coeffs():
    """A single bright direction: the projection of power * delta(omega - w0)."""
    w0 = np.array([0.3, -0.5, 0.6])
    w0 /= np.linalg.norm(w0)
    return sh_basis(w0)[:, None] * np.array([1.0, 2.0, 0.5])


def test_ringing_windows_reduce_negative_lobe():
    coeffs = delta_lobe_coeffs()
    w = fibonacci_directions(4096)
    relative_min = {}
    for window in WINDOWS:
        value = sh_evaluate_convolved(coeffs, w, sh_band_factors(1.0, window))
        relative_min[window] = value.min() / value.max()
        assert sh_clamp_nonnegative(value).min() >= 0.0
    assert relative_min[SH_WINDOW_NONE] < -0.1
    assert relative_min[SH_WINDOW_NONE] < relative_min[SH_WINDOW_HANN] < 0.0
    assert relative_min[SH_WINDOW_NONE] < relative_min[SH_WINDOW_LANCZOS] < 0.0


def test_glsl_ringing_clamped_nonnegative(ctx):
    coeffs = delta_lobe_coeffs()
    w = fibonacci_directions(4096)
    kernel = KERNEL_IO + """
        uniform int window;
        void main() {
            uint i = gl_GlobalInvocationID.x;
            if (i >= count) return;
            vec3 c[SH_COUNT];
            load_coeffs(c);
            vec3 value = sh_evaluate_convolved(c, direction(i), sh_band_factors(1.0, window));
            vec3 clamped = sh_clamp_nonnegative(value);
            result[6 * i] = value.r; result[6 * i + 1] = value.g; result[6 * i + 2] = value.b;
            result[6 * i + 3] = clamped.r; result[6 * i + 4] = clamped.g; result[6 * i + 5] = clamped.b;
        }
    """
    for window in WINDOWS:
        got = run_kernel(ctx, kernel, [f32(w), f32(coeffs)], (len(w), 6), count=len(w),
                         uniforms={"window": window})
        expected = sh_evaluate_convolved(coeffs, w, sh_band_factors(1.0, window))
        np.testing.assert_allclose(got[:, :3], expected, atol=1e-5 * np.abs(expected).max())
        assert got[:, :3].min() < 0.0  # the unclamped reconstruction rings below zero
        assert got[:, 3:].min() >= 0.0
        np.testing.assert_array_equal(got[:, 3:], np.maximum(got[:, :3], 0.0))


def test_forward_lobe_error_falls_with_order():
    """Known answer: incident radiance an HG lobe of g_L around s, seen through HG(g): the
    convolution is exactly HG(g * g_L) around s (Legendre coefficients multiply). Truncated at
    order N, the squared error over the sphere is the tail sum_{l > N} (2l+1) (g g_L)^(2l) / (4 pi)
    (Legendre orthogonality); each added band must lower it, and match that closed form."""
    g_lobe, g = 0.8, 0.8
    s = np.array([-0.3, 0.35, -0.89])
    s /= np.linalg.norm(s)
    omega, weights = sphere_quadrature(96)
    exact = phase_hg(omega @ s, g * g_lobe)
    norm = np.sqrt(weights @ exact ** 2)
    errors = []
    for order in range(5):
        coeffs = sh_project_function(lambda w: phase_hg(w @ s, g_lobe), n=96, order=order)
        got = sh_evaluate_convolved(coeffs, omega, sh_band_factors(g, SH_WINDOW_NONE, order))
        errors.append(np.sqrt(weights @ (got - exact) ** 2) / norm)
        l = np.arange(order + 1, 200)
        tail = np.sum((2 * l + 1) * (g * g_lobe) ** (2 * l)) / (4 * np.pi)
        np.testing.assert_allclose(errors[-1], np.sqrt(tail) / norm, rtol=1e-6)
    assert all(b < a for a, b in zip(errors, errors[1:]))
    assert errors[4] < 0.5 * errors[2]
