// The viewer's `refine` (app/rendering/refine.py, NumPy twin `half_buffer_sums`): two independent
// `guided` accumulations, the halves A and B, each level 1 (residual) plus level 0, combined into
// the image shown, their count-weighted mean m = (nA a + nB b) / (nA + nB); and, when asked, the
// sums over pixels and channels that estimate its error, reduced on the GPU to 16 bytes:
//   x: sum (a - b)^2        y: sum m^2        z: sum (r - m)^2 (r: the raymarcher's image)
// STAGE 1 (16 x 16 pixels a workgroup): combines, and writes its workgroup's three sums to
// partial[workgroup]; STAGE 2 (one workgroup): adds the partials into sums.
#if !defined(STAGE)
#define STAGE 1
#endif
#define GROUP 256
layout(local_size_x = 16, local_size_y = 16) in;

layout(std430, binding = 0) buffer Partials { vec4 partial[]; };
layout(std430, binding = 1) buffer Sums { vec4 sums; };
shared vec4 group_sums[GROUP];

#if STAGE == 1
layout(rgba32f, binding = 0) readonly uniform image2D residual_a;
layout(rgba32f, binding = 1) readonly uniform image2D level0_a;
layout(rgba32f, binding = 2) readonly uniform image2D residual_b;
layout(rgba32f, binding = 3) readonly uniform image2D level0_b;
layout(rgba32f, binding = 4) readonly uniform image2D raymarched;
layout(rgba32f, binding = 5) writeonly uniform image2D combined;
uniform float weight_a;          // nA / (nA + nB)
uniform float total_samples;     // nA + nB, stored as the shown image's count (alpha)
uniform int reduce;              // 0: combine only
uniform int have_raymarch;       // 0: z is 0

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
