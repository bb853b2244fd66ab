// The viewer's `refine` (app/rendering/refine/refine.py, NumPy twin `half_buffer_sums`): two independent
// `guided` accumulations, the halves A and B, each level 1 (residual) plus level 0, combined into
// the image shown, their count-weighted mean m = (nA a + nB b) / (nA + nB); and, when asked, the
// sums over pixels and channels that estimate its error, reduced on the GPU to 16 bytes:
//   x: sum (a - b)^2        y: sum m^2        z: sum (r - m)^2 (r: the raymarcher's image)
// STAGE 1 (16 x 16 pixels a workgroup): combines (and, when asked, writes half A's image alone,
// for the denoiser), and writes its workgroup's three sums to partial[workgroup]; STAGE 2 (one
// workgroup): adds the partials into sums. STAGE 3 (refine's blend with the Denoise switch on;
// NumPy twin `judge_sums`): half A denoised, D, and the raymarcher's r judged against half B:
//   x: sum (D - b)^2        y: sum (r - b)^2        z: sum (r - b) . (D - b)
// into partial[workgroup], which STAGE 2 then adds.
#if !defined(STAGE)
#define STAGE 1
#endif
#define GROUP 256
layout(local_size_x = 16, local_size_y = 16) in;

layout(std430, binding = 0) buffer Partials { vec4 partial[]; };
layout(std430, binding = 1) buffer Sums { vec4 sums; };
shared vec4 group_sums[GROUP];

// The workgroup's sum of s into partial[workgroup] (every invocation calls it).
void store_group_sum(vec4 s)
{
    uint i = gl_LocalInvocationIndex;
    group_sums[i] = s;
    barrier();
    for (uint half_size = GROUP / 2u; half_size > 0u; half_size >>= 1) {
        if (i < half_size)
            group_sums[i] += group_sums[i + half_size];
        barrier();
    }
    if (i == 0u)
        partial[gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x] = group_sums[0];
}

#if STAGE == 1
layout(rgba32f, binding = 0) readonly uniform image2D residual_a;
layout(rgba32f, binding = 1) readonly uniform image2D level0_a;
layout(rgba32f, binding = 2) readonly uniform image2D residual_b;
layout(rgba32f, binding = 3) readonly uniform image2D level0_b;
layout(rgba32f, binding = 4) readonly uniform image2D raymarched;
layout(rgba32f, binding = 5) writeonly uniform image2D combined;
layout(rgba32f, binding = 6) writeonly uniform image2D half_a;   // a, alpha nA (write_half_a)
uniform float weight_a;          // nA / (nA + nB)
uniform float total_samples;     // nA + nB, stored as the shown image's count (alpha)
uniform int reduce;              // 0: combine only
uniform int have_raymarch;       // 0: z is 0
uniform int write_half_a;        // 1: half A's image into half_a
uniform float samples_a;         // nA

void main()
{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(combined);
    vec4 s = vec4(0.0);
    if (all(lessThan(p, size))) {
        vec3 a = imageLoad(residual_a, p).rgb + imageLoad(level0_a, p).rgb;
        vec3 b = imageLoad(residual_b, p).rgb + imageLoad(level0_b, p).rgb;
        vec3 m = weight_a * a + (1.0 - weight_a) * b;
        imageStore(combined, p, vec4(m, total_samples));
        if (write_half_a != 0)
            imageStore(half_a, p, vec4(a, samples_a));
        if (reduce != 0) {
            vec3 d = a - b;
            s.x = dot(d, d);
            s.y = dot(m, m);
            if (have_raymarch != 0) {
                vec3 e = imageLoad(raymarched, p).rgb - m;
                s.z = dot(e, e);
            }
        }
    }
    if (reduce == 0)
        return;
    store_group_sum(s);
}
#elif STAGE == 3
layout(rgba32f, binding = 2) readonly uniform image2D residual_b;
layout(rgba32f, binding = 3) readonly uniform image2D level0_b;
layout(rgba32f, binding = 4) readonly uniform image2D raymarched;
layout(rgba32f, binding = 6) readonly uniform image2D denoised_a;

void main()
{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    vec4 s = vec4(0.0);
    if (all(lessThan(p, imageSize(denoised_a)))) {
        vec3 b = imageLoad(residual_b, p).rgb + imageLoad(level0_b, p).rgb;
        vec3 d = imageLoad(denoised_a, p).rgb - b;
        vec3 e = imageLoad(raymarched, p).rgb - b;
        s.xyz = vec3(dot(d, d), dot(e, e), dot(e, d));
    }
    store_group_sum(s);
}
#else
uniform int partial_count;

void main()
{
    uint i = gl_LocalInvocationIndex;
    vec4 s = vec4(0.0);
    for (int k = int(i); k < partial_count; k += GROUP)
        s += partial[k];
    group_sums[i] = s;
    barrier();
    for (uint half_size = GROUP / 2u; half_size > 0u; half_size >>= 1) {
        if (i < half_size)
            group_sums[i] += group_sums[i + half_size];
        barrier();
    }
    if (i == 0u)
        sums = group_sums[0];
}
#endif
