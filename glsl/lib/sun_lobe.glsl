// A lobe about the sun's direction beside the probes' SH bands (PROBE_SUN_LOBE 1; NumPy twin:
// app/twins/sun_lobe.py). Light that scattered once from the sun at small angles arrives at a probe
// peaked about the sun's direction s, with the shape of the phase function; with g = 0.8 the bands
// above the probes' order still carry much of that peak, which truncated SH spread and ring.
//
// The probes store L ~ P_n L + a r(omega . s), P_n L the SH projection up to order n, and
// r = b - P_n b the part of the lobe b(mu) = HG_h(mu) above band n (h = sun_lobe_g).
// Zonal functions: HG_h(mu) = sum_l (2l+1)/(4 pi) h^l P_l(mu), so <r, r> = sum_{l>n} (2l+1)/(4 pi)
// h^(2l) and, Funk-Hecke, the phase function HG_g convolved with r is r's series with (g h)^l:
// HG_{g h}(mu) minus its bands up to n, evaluated in closed form.
//
// Which a: the renderers never see L, only L convolved with the phase function, which scales band l
// by g^l. So a minimises what they see wrong, sum_{l>n} g^(2l) |L_l - a r_l|^2 (L_l: band l of
// L; the bands up to n are the same either way, r being orthogonal to them):
//     a = sum_{l>n} g^(2l) <L_l, r_l> / sum_{l>n} g^(2l) |r_l|^2 = <L, r'> / <r_gh, r_gh>,
// r' = the part above band n of HG_{g^2 h} (its band-l coefficient g^(2l) h^l), r_gh that of
// HG_{g h}. One more projection of the walks, onto r' / <r_gh, r_gh>; a lobe of amplitude A
// (L_l = A r_l above n) still gives a = A, and L with nothing of the lobe beyond band n gives 0.
// (Fitting L itself, a = <L, r> / <r, r>, weights the high bands the renderer damps as much as the
// low ones; projecting onto the broader r' also has less noise: bench/h100-sun-lobe.)
#include "lib/phase.glsl"
uniform float sun_lobe_g;         // h, the lobe's Henyey-Greenstein g (> 0)
uniform float sun_lobe_phase_g;   // the scene's phase-function g: the lobe is fitted for it and convolved with it

// sum_{l <= n} (2l+1)/(4 pi) x^l P_l(mu) (Legendre recurrence)
float sun_lobe_low_bands(float mu, float x, int n)
{
    float p_prev = 1.0, p = mu, x_l = x;
    float sum = 1.0;
    if (n >= 1)
        sum += 3.0 * x * mu;
    for (int l = 2; l <= n; ++l) {
        float p_next = (float(2 * l - 1) * mu * p - float(l - 1) * p_prev) / float(l);
        x_l *= x;
        sum += float(2 * l + 1) * x_l * p_next;
        p_prev = p;
        p = p_next;
    }
    return INV_4PI * sum;
}

// HG_x(mu) above band n
float sun_lobe_residual(float mu, float x, int n)
{
    return phase_hg(mu, x) - sun_lobe_low_bands(mu, x, n);
}

// <r, r> for lobe g h above band n: (1/4pi) ((1 + h^2) / (1 - h^2)^2 - sum_{l<=n} (2l+1) h^(2l))
float sun_lobe_norm(float h, int n)
{
    float x = h * h, x_l = 1.0, low = 0.0;
    for (int l = 0; l <= n; ++l) {
        low += float(2 * l + 1) * x_l;
        x_l *= x;
    }
    return INV_4PI * ((1.0 + x) / ((1.0 - x) * (1.0 - x)) - low);
}

// The function the walks are projected onto for a lobe h and a phase function of g:
// r'(mu) / <r_gh, r_gh>, mu = walk direction . s.
float sun_lobe_basis(float mu, float g, float h, int n)
{
    return sun_lobe_residual(mu, g * g * h, n) / sun_lobe_norm(g * h, n);
}

// The phase function (g) convolved with r, at mu = d . s: what a lobe of amplitude a in-scatters
// towards a ray along d is a times this.
float sun_lobe_convolved(float mu, float g, int n)
{
    return sun_lobe_residual(mu, g * sun_lobe_g, n);
}
