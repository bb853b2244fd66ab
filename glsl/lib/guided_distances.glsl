// `guided`'s free-flight decisions (lib/integrator.glsl, under GUIDED_RESIDUAL with
// GUIDED_DISTANCES 1): at a tentative collision of delta tracking, real or null is chosen with a
// probability that follows what the probes predict each choice brings back, instead of
// sigma_t / majorant alone (Herholz et al. 2019, zero-variance random walks). NumPy twin:
// app/twins/guided_distances.py.
//
// A flight along d from a scattering event estimates the radiance arriving there from d. At a
// tentative collision at x (majorant m, a = sigma_t / m the analog probability of a real
// collision), that radiance is, in expectation,
//     a * albedo * S  +  (1 - a) * B
// S: what scattering at x sends back along -d, per unit sigma_s (lib/guided_source.glsl's
// prediction: the probes' inscattered radiance plus the sun through the light grid); B: the radiance
// arriving at x from d (the probes' radiance in direction d, windowed and clamped at 0), what a
// null collision goes on to find. The zero-variance choice takes "real" with probability
//     z = a albedo S / (a albedo S + (1 - a) B)
// (luminances); where both are 0, z = a. The probability used is the mixture
//     p = (1 - P) a + P z          (P = guided_distance_probability, < 1)
// and the path's throughput takes the weight a / p after a real collision, (1 - a) / (1 - p) after
// a null one: each outcome's probability times its weight is the analog one's, so the flight's
// estimate has delta tracking's mean whatever S and B are (zero probes, ten times too bright,
// another sun's: variance, never bias). Each weight is at most 1 / (1 - P).
//
// A flight's weights multiply, and where the predictions are wrong the product is heavy-tailed:
// with zero probes and P = 0.9 a null collision's weight is 10, and on tests/test_guided.py's
// scene (llvmpipe, 96 seeds) the red image came out 3.5 standard errors dark, its few heavy
// samples missing. So a flight decides as delta tracking does once its product has left
// [1 / GUIDED_FLIGHT_WEIGHT_BOUND, GUIDED_FLIGHT_WEIGHT_BOUND]: which probability a decision uses
// may depend on anything the flight has done so far, so the mean stays the same, and a flight's
// weight stays below GUIDED_FLIGHT_WEIGHT_BOUND / (1 - P).
//
// Where a is 0 or 1 (vacuum, or a majorant met exactly) the choice is the analog one (p = a,
// weight 1) and nothing is fetched. Flights from the camera are not guided: level 1 subtracts
// the probes' prediction at its first event, so its camera ray's variance is not the radiance's.
// Cost: a probe fetch and the light grid's transmittance at every tentative collision in between.
#include "lib/guided_source.glsl"
#include "lib/luminance.glsl"

uniform float guided_distance_probability;   // P in [0, 1)
const float GUIDED_FLIGHT_WEIGHT_BOUND = 4.0;

// Set by path_flight around one flight's delta tracking (lib/integrator.glsl).
bool guided_flight = false;           // whether this flight's decisions are guided
float guided_flight_sun_phase = 0.0;  // the phase function towards the sun, for the flight's d
float guided_flight_weight = 1.0;     // the product of the flight's decision weights so far

// The probability of a real collision: a = sigma_t / m, albedo_source = albedo S and beyond = B
// (luminances, >= 0), P the mixture's share of the zero-variance choice.
float guided_collision_probability(float a, float albedo_source, float beyond, float P)
{
    float real = a * albedo_source, null = (1.0 - a) * beyond;
    float z = real + null > 0.0 ? real / (real + null) : a;
    return (1.0 - P) * a + P * z;
}

bool tracking_collides(vec3 x, vec3 d, float m, inout uint rng)
{
    vec4 classified = classified_at(x);
    float sigma_t = sigma_t_of(classified);
    float a = sigma_t / m;
    if (!guided_flight || !(a > 0.0 && a < 1.0)
        || !(guided_flight_weight <= GUIDED_FLIGHT_WEIGHT_BOUND
             && guided_flight_weight * GUIDED_FLIGHT_WEIGHT_BOUND >= 1.0))
        return rng_next(rng) * m < sigma_t;   // the analog decision, on the same number
    vec3 coeffs[SH_COUNT];
    float probe_sun;
    probe_fetch(x, coeffs, probe_sun);
    vec3 source = guided_predicted_source_from(coeffs, x, d, guided_flight_sun_phase);
    vec3 beyond = sh_clamp_nonnegative(sh_evaluate_convolved(coeffs, d, probe_window_factors));
    float albedo_source = max(dot(albedo_of(classified) * source, REC709_LUMINANCE), 0.0);
    float p = guided_collision_probability(a, albedo_source,
                                           max(dot(beyond, REC709_LUMINANCE), 0.0),
                                           guided_distance_probability);
    if (rng_next(rng) < p) {
        guided_flight_weight *= a / p;
        return true;
    }
    guided_flight_weight *= (1.0 - a) / (1.0 - p);
    return false;
}
