// The benchmark's ceiling: how fast this GPU runs a trilinear 3D-texture march through the scene's
// own medium. Each invocation walks `steps` steps of a voxel along a random direction from a random
// point (as incoherent as the bake's walks), reading sigma_t exactly as a tracking step does
// (lib/medium.glsl: the density texture, trilinear, then the transfer-function table), and wraps
// around the box instead of leaving it. No random numbers, no logarithms, no branches: the cost of
// the fetches alone, which is what every tracking step of a walk must pay at least.
//
// DEPENDENT_CHAIN (defined or not): each step's position waits on the sigma_t the step before read,
// as a walk's next tracking step waits on the last (its distance and its accept test depend on
// it). Run with as many invocations as a small bake has walks, this is the latency floor of a walk
// of `steps` tracking steps: what no exact walk of that many steps can beat, however it is coded.
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/directions.glsl"

layout(std430, binding = 0) writeonly buffer Sums { float sums[]; };
uniform uint rays;
uniform int steps;
uniform float step_length;

void main()
{
    uint ray = gl_GlobalInvocationID.x;
    if (ray >= rays)
        return;
    uint rng = rng_seed(ray, 0u, 0x9e3779b9u);
    vec3 x = (vec3(rng_next(rng), rng_next(rng), rng_next(rng)) * 2.0 - 1.0) * box_half_extent;
    vec3 d = fibonacci_direction(uint(rng_next(rng) * 65536.0), 65536u);
    vec3 box = 2.0 * box_half_extent;
    float sum = 0.0;
    for (int i = 0; i < steps; ++i) {
#if defined(DEPENDENT_CHAIN)
        x += (step_length + 1e-30 * sum) * d;   // waits on the last fetch (1e-30: no real move)
#else
        x += step_length * d;
#endif
        x -= box * floor(x / box + 0.5);   // wrap into [-half, half)
        sum += sigma_t_at(x);
    }
    sums[ray] = sum;
}
