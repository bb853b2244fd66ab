// The sun's single scattering over one raymarch segment (NumPy twin: app/twins/segment_sun.py).
//
// A segment of length dt whose extinction sigma_t is taken constant and along which the sun's
// optical depth tau changes linearly, from tau_start at the segment's start to tau_end at its end.
// Light scattered towards the camera at distance s into it is attenuated by exp(-sigma_t s) on the
// way back and arrived through exp(-tau(s)), so the segment's weight (to be multiplied by the
// camera's transmittance at its start, the albedo, the sun and the phase function) is
//   integral_0^dt sigma_t exp(-sigma_t s) exp(-tau(s)) ds
//     = a (exp(-tau_start) - exp(-(tau_end + a))) / (a + b),   a = sigma_t dt, b = tau_end - tau_start.
// With tau constant this is the segment's opacity (1 - exp(-a)) times exp(-tau), what the
// raymarcher took before; where the sun's optical depth changes across the segment it is not: on the
// lit skin of a dense medium (a fully opaque box: a = 156 in a half-voxel step) exp(-tau) taken at
// a point of the segment is 0 while the integral is the skin's whole single scattering
// (mu_s / (mu_s + mu_v) of the sun, a semi-infinite medium's closed form). The raymarcher took 85%
// too little there (bench/h100-bias, the battery's opaque box).
float segment_sun_weight(float sigma_t, float dt, float tau_start, float tau_end)
{
    float a = sigma_t * dt;
    float x = a + (tau_end - tau_start);
    if (abs(x) < 1e-3)   // (1 - exp(-x)) / x by its series: the difference below would cancel
        return a * exp(-tau_start) * (1.0 - x * (0.5 - x / 6.0));
    return a * (exp(-tau_start) - exp(-(tau_end + a))) / x;
}
