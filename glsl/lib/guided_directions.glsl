// `guided`'s choice of the next direction at a scattering event of its level-1 paths
// (lib/integrator.glsl, under GUIDED_RESIDUAL with GUIDED_DIRECTIONS 1): one-sample MIS between
// the phase function (Henyey-Greenstein, g) and the phase function times the probes' radiance.
// NumPy twin: app/twins/guided_directions.py.
//
// sample_hg (lib/phase.glsl) maps a point u = (u1, u2) of the unit square to a direction w(u):
// u1 gives cos theta by HG's inverse CDF, u2 the azimuth. The map is one to one (up to a set of
// measure 0) and carries the uniform density on the square to p_HG(w) on the sphere, so any
// density q(u) on the square is carried to
//     pdf(w) = p_HG(w) q(u(w))                                   (u(w): hg_primary_sample)
// and a direction drawn so has the path weight phase(w) / pdf(w) = 1 / q(u). The product
// p_HG(w) h(w) (h: the probes' radiance arriving from w) is therefore, on the square, just
// q proportional to h(w(u)): this file tabulates h on GUIDED_CELLS_COS x GUIDED_CELLS_PHI cells
// of the square (h's luminance at each cell's centre direction, windowed as the direction control
// windows it), draws a cell by the table's CDF and a point uniformly within it. Each cell's value
// is at least GUIDED_CELL_FLOOR times the mean of the clamped values (SH ringing goes negative),
// and a table whose values are all 0 (zero probes, or radiance that rings below 0 everywhere) is
// uniform: every cell keeps mass, so every direction HG can draw keeps a positive pdf. The
// product is mixed with plain HG (one-sample MIS, the balance heuristic's single-sample form):
//     q(u) = (1 - P) + P N m_k(u) / M
// with P = guided_direction_probability, N the cells, m_k the mass of u's cell k and M the sum of
// the masses. pdf is exact and cheap to evaluate anywhere (the table, the cell, one division), so
// the estimate is unbiased whatever the probes hold (zero, ten times too bright, baked for another
// sun): wrong probes only cost variance, at most a factor 1 / (1 - P) on the weight.
//
// The masses are kept as their running sums (the CDF): the draw compares a uniform number against
// those very sums, so a cell's probability is the difference of its neighbouring sums, the mass
// that q is evaluated with (no second rounding of a separate table).
//
// Cost per event: one probe fetch (shared with the direction control), N evaluations of the SH
// basis (the coefficients are reduced to luminance first), a 6-step binary search. Not at the
// last event a path may scatter at: what follows it is an escape alone, which h does not track.
const int GUIDED_CELLS_COS = 8;
const int GUIDED_CELLS_PHI = 8;
const int GUIDED_CELLS = GUIDED_CELLS_COS * GUIDED_CELLS_PHI;
const float GUIDED_CELL_FLOOR = 0.05;
#include "lib/luminance.glsl"
// Loop iterations one table may take at most, with the probe fetch before it and the draw after
// (its cells times the SH loop, the fetch's and the reductions' loops, the search), charged to
// the path's step budget as the map's samples are (lib/integrator.glsl): Mesa's llvmpipe ends an
// invocation's loops past its limit, and uncharged loops of 700 iterations an event overran it.
const int GUIDED_DIRECTION_TABLE_STEPS = GUIDED_CELLS * (SH_COUNT + 2) + 4 * SH_COUNT + 64;

uniform float guided_direction_probability;   // P: the share of directions drawn from the table

// The table's running sums at an event reached along w_in: cdf[k] = m_0 + ... + m_k, cell
// k = row * GUIDED_CELLS_PHI + column (row: u1, column: u2). coeffs: the probes' SH at the event.
void guided_direction_table(vec3 coeffs[SH_COUNT], vec3 w_in, float g,
                            out float cdf[GUIDED_CELLS])
{
    float luminance[SH_COUNT];   // window_l times the coefficients' luminance
    for (int l = 0; l < SH_BANDS; ++l)
        for (int k = l * l; k < (l + 1) * (l + 1); ++k)
            luminance[k] = probe_window_factors[l] * dot(coeffs[k], REC709_LUMINANCE);
    vec3 b1, b2;
    orthonormal_basis(w_in, b1, b2);
    float sum = 0.0;
    for (int row = 0; row < GUIDED_CELLS_COS; ++row) {
        float cos_theta = sample_hg_cos_theta((float(row) + 0.5) / float(GUIDED_CELLS_COS), g);
        float sin_theta = sqrt(max(0.0, 1.0 - cos_theta * cos_theta));
        for (int column = 0; column < GUIDED_CELLS_PHI; ++column) {
            float phi = 2.0 * PI * (float(column) + 0.5) / float(GUIDED_CELLS_PHI);
            vec3 w = sin_theta * (cos(phi) * b1 + sin(phi) * b2) + cos_theta * w_in;
            float basis[SH_COUNT];
            sh_basis(w, basis);
            float h = 0.0;
            for (int k = 0; k < SH_COUNT; ++k)
                h += luminance[k] * basis[k];
            h = max(h, 0.0);
            cdf[row * GUIDED_CELLS_PHI + column] = h;
            sum += h;
        }
    }
    float floor_value = GUIDED_CELL_FLOOR * sum / float(GUIDED_CELLS);
    float running = 0.0;
    for (int k = 0; k < GUIDED_CELLS; ++k) {
        running += sum > 0.0 ? max(cdf[k], floor_value) : 1.0;
        cdf[k] = running;
    }
}

// The cell of a point of the unit square.
int guided_direction_cell(vec2 u)
{
    int row = clamp(int(u.x * float(GUIDED_CELLS_COS)), 0, GUIDED_CELLS_COS - 1);
    int column = clamp(int(u.y * float(GUIDED_CELLS_PHI)), 0, GUIDED_CELLS_PHI - 1);
    return row * GUIDED_CELLS_PHI + column;
}

// q(u): the mixture's density on the unit square (see above); pdf(w) = p_HG(w) q(u(w)).
float guided_direction_density(float cdf[GUIDED_CELLS], vec2 u)
{
    int k = guided_direction_cell(u);
    float mass = k > 0 ? cdf[k] - cdf[k - 1] : cdf[0];
    return 1.0 - guided_direction_probability
           + guided_direction_probability * float(GUIDED_CELLS) * mass / cdf[GUIDED_CELLS - 1];
}

// A point of the unit square drawn from q with three uniform numbers: xi_choice picks the table
// (below P) or plain HG; the table's branch reuses it, rescaled, to pick the cell.
vec2 guided_direction_primary(float cdf[GUIDED_CELLS], float xi_choice, float xi1, float xi2)
{
    float p = guided_direction_probability;
    if (!(xi_choice < p))
        return vec2(xi1, xi2);
    float target = min(xi_choice / p, 1.0) * cdf[GUIDED_CELLS - 1];
    int lo = 0, hi = GUIDED_CELLS - 1;   // the first cell whose running sum exceeds target
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (cdf[mid] > target)
            hi = mid;
        else
            lo = mid + 1;
    }
    int row = lo / GUIDED_CELLS_PHI, column = lo % GUIDED_CELLS_PHI;
    // (float(row) + xi1) / N stays below (row + 1) / N for xi1 < 1 up to one rounding; the
    // density is evaluated at the point drawn, whichever cell that rounding puts it in.
    return vec2((float(row) + xi1) / float(GUIDED_CELLS_COS),
                (float(column) + xi2) / float(GUIDED_CELLS_PHI));
}

// pdf(w) / p_HG(w) = q(u(w)) for any direction w at an event reached along w_in: what the
// environment map's samples weigh themselves against (lib/integrator.glsl).
float guided_direction_density_at(vec3 coeffs[SH_COUNT], vec3 w_in, float g, vec3 w)
{
    float cdf[GUIDED_CELLS];
    guided_direction_table(coeffs, w_in, g, cdf);
    return guided_direction_density(cdf, hg_primary_sample(w_in, g, w));
}
