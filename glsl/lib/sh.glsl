// Real orthonormal spherical harmonics up to band SH_ORDER (2, 3 or 4; (SH_ORDER + 1)^2 functions)
// and their convolution with Henyey-Greenstein. NumPy twin: app/twins/sh.py.
//
// SH_ORDER is PROBE_SH_ORDER where that is above 2, else 2 (orders 0 and 1 keep nine coefficients,
// the higher ones reading as zero: lib/probes.glsl).
//
// Convention (Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008), for a unit vector w:
// index k = l*(l+1) + m, order (0,0) (1,-1) (1,0) (1,1) (2,-2) (2,-1) (2,0) (2,1) (2,2) (3,-3) ...;
// no Condon-Shortley phase: Y1-1 = +c1*y, Y10 = +c1*z, Y11 = +c1*x.
//   Y00  = sqrt(1/(4pi))                 Y2-2 = sqrt(15/(4pi)) x y
//   Y1m  = sqrt(3/(4pi)) (y, z, x)       Y2-1 = sqrt(15/(4pi)) y z
//   Y20  = sqrt(5/(16pi)) (3z^2 - 1)     Y21  = sqrt(15/(4pi)) x z
//                                        Y22  = sqrt(15/(16pi)) (x^2 - y^2)
//   Y3-3 = sqrt(35/(32pi)) y (3x^2 - y^2)     Y33 = sqrt(35/(32pi)) x (x^2 - 3y^2)
//   Y3-2 = sqrt(105/(4pi)) x y z              Y32 = sqrt(105/(16pi)) z (x^2 - y^2)
//   Y3-1 = sqrt(21/(32pi)) y (5z^2 - 1)       Y31 = sqrt(21/(32pi)) x (5z^2 - 1)
//   Y30  = sqrt(7/(16pi)) z (5z^2 - 3)
//   Y4-4 = 3/4 sqrt(35/pi) x y (x^2 - y^2)
//   Y44  = 3/16 sqrt(35/pi) (x^2 (x^2 - 3y^2) - y^2 (3x^2 - y^2))
//   Y4-3 = 3/4 sqrt(35/(2pi)) y z (3x^2 - y^2) Y43 = 3/4 sqrt(35/(2pi)) x z (x^2 - 3y^2)
//   Y4-2 = 3/4 sqrt(5/pi) x y (7z^2 - 1)      Y42 = 3/8 sqrt(5/pi) (x^2 - y^2) (7z^2 - 1)
//   Y4-1 = 3/4 sqrt(5/(2pi)) y z (7z^2 - 3)   Y41 = 3/4 sqrt(5/(2pi)) x z (7z^2 - 3)
//   Y40  = 3/16 sqrt(1/pi) (35z^4 - 30z^2 + 3)
//
// Probes store incident radiance L_in(omega), arriving FROM omega. A ray travelling along d sees
// L_s(d) = integral p_HG(dot(omega, d)) L_in(omega) d omega = sum_lm g^l c_lm Y_lm(d)
// (Funk-Hecke; exact when L_in is band-limited to l <= SH_ORDER).
#ifndef SH_ORDER
#ifdef PROBE_SH_ORDER
#if PROBE_SH_ORDER > 2
#define SH_ORDER PROBE_SH_ORDER
#endif
#endif
#endif
#ifndef SH_ORDER
#define SH_ORDER 2
#endif
#define SH_BANDS (SH_ORDER + 1)
#define SH_COUNT (SH_BANDS * SH_BANDS)

const float SH_C0 = 0.282094791773878143;   // sqrt(1/(4pi))
const float SH_C1 = 0.488602511902919921;   // sqrt(3/(4pi))
const float SH_C2 = 1.09254843059207907;    // sqrt(15/(4pi))
const float SH_C20 = 0.315391565252520051;  // sqrt(5/(16pi))
const float SH_C22 = 0.546274215296039535;  // sqrt(15/(16pi))
const float SH_C33 = 0.590043589926643510;  // sqrt(35/(32pi))
const float SH_C32 = 2.89061144264055406;   // sqrt(105/(4pi))
const float SH_C31 = 0.457045799464465739;  // sqrt(21/(32pi))
const float SH_C30 = 0.373176332590115391;  // sqrt(7/(16pi))
const float SH_C32B = 1.44530572132027703;  // sqrt(105/(16pi))
const float SH_C44 = 2.50334294179670454;   // 3/4 sqrt(35/pi)
const float SH_C43 = 1.77013076977993053;   // 3/4 sqrt(35/(2pi))
const float SH_C42 = 0.946174695757560014;  // 3/4 sqrt(5/pi)
const float SH_C41 = 0.669046543557289168;  // 3/4 sqrt(5/(2pi))
const float SH_C40 = 0.105785546915204304;  // 3/16 sqrt(1/pi)
const float SH_C42B = 0.473087347878780007; // 3/8 sqrt(5/pi)
const float SH_C44B = 0.625835735449176135; // 3/16 sqrt(35/pi)

const int SH_WINDOW_NONE = 0, SH_WINDOW_HANN = 1, SH_WINDOW_LANCZOS = 2;

void sh_basis(vec3 w, out float basis[SH_COUNT])
{
    float x = w.x, y = w.y, z = w.z;
    basis[0] = SH_C0;
    basis[1] = SH_C1 * y;
    basis[2] = SH_C1 * z;
    basis[3] = SH_C1 * x;
    basis[4] = SH_C2 * x * y;
    basis[5] = SH_C2 * y * z;
    basis[6] = SH_C20 * (3.0 * z * z - 1.0);
    basis[7] = SH_C2 * x * z;
    basis[8] = SH_C22 * (x * x - y * y);
#if SH_ORDER >= 3
    float x2 = x * x, y2 = y * y, z2 = z * z;
    basis[9] = SH_C33 * y * (3.0 * x2 - y2);
    basis[10] = SH_C32 * x * y * z;
    basis[11] = SH_C31 * y * (5.0 * z2 - 1.0);
    basis[12] = SH_C30 * z * (5.0 * z2 - 3.0);
    basis[13] = SH_C31 * x * (5.0 * z2 - 1.0);
    basis[14] = SH_C32B * z * (x2 - y2);
    basis[15] = SH_C33 * x * (x2 - 3.0 * y2);
#endif
#if SH_ORDER >= 4
    basis[16] = SH_C44 * x * y * (x2 - y2);
    basis[17] = SH_C43 * y * z * (3.0 * x2 - y2);
    basis[18] = SH_C42 * x * y * (7.0 * z2 - 1.0);
    basis[19] = SH_C41 * y * z * (7.0 * z2 - 3.0);
    basis[20] = SH_C40 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0);
    basis[21] = SH_C41 * x * z * (7.0 * z2 - 3.0);
    basis[22] = SH_C42B * (x2 - y2) * (7.0 * z2 - 1.0);
    basis[23] = SH_C43 * x * z * (x2 - 3.0 * y2);
    basis[24] = SH_C44B * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2));
#endif
}

vec3 sh_evaluate(vec3 coeffs[SH_COUNT], vec3 w)
{
    float basis[SH_COUNT];
    sh_basis(w, basis);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < SH_COUNT; ++k)
        sum += coeffs[k] * basis[k];
    return sum;
}

// Per-band multipliers window_l * g^l, l = 0 .. SH_ORDER.
// Windows against ringing (Sloan 2008), width w = SH_ORDER + 1:
//   Hann    window_l = (1 + cos(pi l / w)) / 2          (w = 3: 1, 0.75, 0.25)
//   Lanczos window_l = sinc(l / w) = sin(pi l/w)/(pi l/w) (w = 3: 1, 0.826993343, 0.413496672)
float[SH_BANDS] sh_band_factors(float g, int window)
{
    float factors[SH_BANDS];
    float g_l = 1.0;
    for (int l = 0; l < SH_BANDS; ++l) {
        float x = 3.14159265358979 * float(l) / float(SH_BANDS);
        float window_l = 1.0;
        if (window == SH_WINDOW_HANN)
            window_l = 0.5 * (1.0 + cos(x));
        else if (window == SH_WINDOW_LANCZOS && l > 0)
            window_l = sin(x) / x;
        factors[l] = window_l * g_l;
        g_l *= g;
    }
    return factors;
}

// sum_l band_factors[l] * sum_m c_lm Y_lm(w); not clamped (see sh_clamp_nonnegative).
vec3 sh_evaluate_convolved(vec3 coeffs[SH_COUNT], vec3 w, float band_factors[SH_BANDS])
{
    float basis[SH_COUNT];
    sh_basis(w, basis);
    vec3 sum = vec3(0.0);
    for (int l = 0; l < SH_BANDS; ++l) {
        vec3 band = vec3(0.0);
        for (int k = l * l; k < (l + 1) * (l + 1); ++k)
            band += coeffs[k] * basis[k];
        sum += band_factors[l] * band;
    }
    return sum;
}

vec3 sh_clamp_nonnegative(vec3 radiance)
{
    return max(radiance, vec3(0.0));
}
