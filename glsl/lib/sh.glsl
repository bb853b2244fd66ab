// Real orthonormal spherical harmonics up to l = 2 (9 functions) and their convolution with
// Henyey-Greenstein. NumPy twin: app/sh.py.
//
// Convention (Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008), for a unit vector w:
// index k = l*(l+1) + m, order (0,0) (1,-1) (1,0) (1,1) (2,-2) (2,-1) (2,0) (2,1) (2,2);
// no Condon-Shortley phase: Y1-1 = +c1*y, Y10 = +c1*z, Y11 = +c1*x.
//   Y00  = sqrt(1/(4pi))                 Y2-2 = sqrt(15/(4pi)) x y
//   Y1m  = sqrt(3/(4pi)) (y, z, x)       Y2-1 = sqrt(15/(4pi)) y z
//   Y20  = sqrt(5/(16pi)) (3z^2 - 1)     Y21  = sqrt(15/(4pi)) x z
//                                        Y22  = sqrt(15/(16pi)) (x^2 - y^2)
//
// Probes store incident radiance L_in(omega), arriving FROM omega. A ray travelling along d sees
// L_s(d) = integral p_HG(dot(omega, d)) L_in(omega) d omega = sum_lm g^l c_lm Y_lm(d)
// (Funk-Hecke; exact when L_in is band-limited to l <= 2).

const float SH_C0 = 0.282094791773878143;   // sqrt(1/(4pi))
const float SH_C1 = 0.488602511902919921;   // sqrt(3/(4pi))
const float SH_C2 = 1.09254843059207907;    // sqrt(15/(4pi))
const float SH_C20 = 0.315391565252520051;  // sqrt(5/(16pi))
const float SH_C22 = 0.546274215296039535;  // sqrt(15/(16pi))

const int SH_WINDOW_NONE = 0, SH_WINDOW_HANN = 1, SH_WINDOW_LANCZOS = 2;

void sh_basis(vec3 w, out float basis[9])
{
    basis[0] = SH_C0;
    basis[1] = SH_C1 * w.y;
    basis[2] = SH_C1 * w.z;
    basis[3] = SH_C1 * w.x;
    basis[4] = SH_C2 * w.x * w.y;
    basis[5] = SH_C2 * w.y * w.z;
    basis[6] = SH_C20 * (3.0 * w.z * w.z - 1.0);
    basis[7] = SH_C2 * w.x * w.z;
    basis[8] = SH_C22 * (w.x * w.x - w.y * w.y);
}

vec3 sh_evaluate(vec3 coeffs[9], vec3 w)
{
    float basis[9];
    sh_basis(w, basis);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < 9; ++k)
        sum += coeffs[k] * basis[k];
    return sum;
}

// Per-band multipliers (band0, band1, band2) = window_l * g^l.
// Windows against ringing (Sloan 2008), width w = lmax + 1 = 3:
//   Hann    window_l = (1 + cos(pi l / w)) / 2          -> 1, 0.75, 0.25
//   Lanczos window_l = sinc(l / w) = sin(pi l/w)/(pi l/w) -> 1, 0.826993343, 0.413496672
vec3 sh_band_factors(float g, int window)
{
    vec3 window_l = vec3(1.0);
    if (window == SH_WINDOW_HANN)
        window_l = vec3(1.0, 0.75, 0.25);
    else if (window == SH_WINDOW_LANCZOS)
        window_l = vec3(1.0, 0.826993343132688, 0.413496671566344);
    return window_l * vec3(1.0, g, g * g);
}

// sum_l band_factors[l] * sum_m c_lm Y_lm(w); not clamped (see sh_clamp_nonnegative).
vec3 sh_evaluate_convolved(vec3 coeffs[9], vec3 w, vec3 band_factors)
{
    float basis[9];
    sh_basis(w, basis);
    vec3 band0 = coeffs[0] * basis[0];
    vec3 band1 = coeffs[1] * basis[1] + coeffs[2] * basis[2] + coeffs[3] * basis[3];
    vec3 band2 = coeffs[4] * basis[4] + coeffs[5] * basis[5] + coeffs[6] * basis[6]
               + coeffs[7] * basis[7] + coeffs[8] * basis[8];
    return band_factors.x * band0 + band_factors.y * band1 + band_factors.z * band2;
}

vec3 sh_clamp_nonnegative(vec3 radiance)
{
    return max(radiance, vec3(0.0));
}
