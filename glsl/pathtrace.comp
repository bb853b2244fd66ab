// Reference path tracer, and with PROBE_LIGHTING the probe renderers (1: probes, the sun by a
// shadow ray; 2: probes-only). Each invocation owns one pixel: it continues the pixel's path in
// flight, starts new samples until the pixel has target_samples of them, and stops when the
// dispatch's loop budget runs low (the host dispatches again while pixels_with_work > 0).
layout(local_size_x = 8, local_size_y = 8) in;

#include "lib/rng.glsl"
#include "lib/camera.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/tracking.glsl"
#include "lib/sun_shadow.glsl"
#if defined(PROBE_LIGHTING) || defined(GUIDED_RESIDUAL)
#define PROBE_SAMPLING
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#endif
#if defined(GUIDED_RESIDUAL)
#include "lib/guided_source.glsl"
#if !defined(GUIDED_DIRECTION_CONTROL) || PROBE_SH_ORDER < 1
#undef GUIDED_DIRECTION_CONTROL   // order 0 probes hold no direction: the control would be 0
#define GUIDED_DIRECTION_CONTROL 0
#endif
#if GUIDED_DIRECTION_CONTROL
#include "lib/guided_direction_control.glsl"
#endif
#endif
#include "lib/integrator.glsl"

layout(rgba32f, binding = 0) uniform image2D accumulation;  // rgb: running mean, a: sample count

struct PixelState {
    PathState path;
    uint next_sample;   // samples started so far; keys the random stream of the next one
    uint pad0, pad1, pad2;
};
layout(std430, binding = 1) buffer PixelStates { PixelState pixel_states[]; };
layout(std430, binding = 2) buffer Progress { uint pixels_with_work; };

uniform uint seed;
uniform uint target_samples;   // samples per pixel this render wants in all
uniform int loop_budget;       // loop iterations one invocation may run in this dispatch
uniform int loop_reserve;      // suspend a path when the budget falls to this
// 1 in a render's first dispatch: every pixel starts from no path and no sample, whatever its
// stored state holds (the host used to clear the states buffer instead: at 1920x1080 a 199 MB
// memset and upload on every restart, that is every camera move in the viewer).
uniform int restart;
// The first pixel (column, row) of this dispatch: a large image is dispatched in bands of rows,
// so that no dispatch runs long (app/rendering/budgets/dispatch_budget.py), and a sample longer than a
// viewer's frame in bands of work groups over frames (app/rendering/budgets/sample_bands.py).
uniform ivec2 tile_offset;

void main()
{
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + tile_offset;
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    uint key = uint(pixel.y * image_size.x + pixel.x);
    CHECK_INDEX(key, pixel_states.length(), CHECK_SITE_PATH_INDEX);
    CHECK_TEXEL(pixel, imageSize(accumulation), CHECK_SITE_IMAGE_TEXEL);
    PixelState state = pixel_states[key];
    if (restart != 0) {
        state.path.status = PATH_IDLE;   // path_begin sets every other field before use
        state.next_sample = 0u;
    }
    vec4 mean_and_count = imageLoad(accumulation, pixel);
    int budget = loop_budget;
    while (budget > loop_reserve) {
        budget -= 1;
        if (state.path.status == PATH_IDLE) {
            if (state.next_sample >= target_samples)
                break;
            uint rng = rng_seed(key, state.next_sample, seed);
            vec2 jitter = vec2(rng_next(rng), rng_next(rng));  // box filter over the pixel's area
            path_begin(state.path, camera_eye, camera_ray_direction(vec2(pixel) + jitter), rng);
            state.next_sample += 1u;
        }
        int result = path_continue(state.path, budget, loop_reserve);
        if (result == PATH_SUSPENDED)
            break;
        state.path.status = PATH_IDLE;
        path_finish(mean_and_count, state.path, result);
    }
    if (state.path.status != PATH_IDLE || state.next_sample < target_samples)
        atomicAdd(pixels_with_work, 1u);
    pixel_states[key] = state;
    imageStore(accumulation, pixel, mean_and_count);
}
