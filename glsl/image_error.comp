// The two sums of an image's relative RMSE against a reference (NumPy twin: `rrmse` in
// app/rendering/metrics.py; host side app/rendering/image_error.py), one 16 x 16-pixel workgroup a
// tile: x: sum over the tile's pixels and RGB of (image - reference)^2, y: sum of reference^2,
// into partial[workgroup]; the host adds the partials in float64. Both images are read with
// texelFetch (texel (x, y) is pixel x of row y, alpha ignored), so an accumulation, a filtered
// image and the uploaded reference all serve. The bench's error curve then reads 16 bytes a tile,
// not the image: measured on the CPU, a 3840x2160 point kept the GPU idle for about 0.5 s, long
// enough for the H200 to fall to its idle clock (bench/h200-raymarch-4k).
#define GROUP_SIDE 16
#define GROUP (GROUP_SIDE * GROUP_SIDE)
layout(local_size_x = GROUP_SIDE, local_size_y = GROUP_SIDE) in;

uniform sampler2D image;
uniform sampler2D reference;
layout(std430, binding = 0) writeonly buffer Partials { vec2 partial[]; };
shared vec2 group_sums[GROUP];

void main()
{
    ivec2 size = textureSize(reference, 0);
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    vec2 s = vec2(0.0);
    if (all(lessThan(p, size))) {
        vec3 r = texelFetch(reference, p, 0).rgb;
        vec3 d = texelFetch(image, p, 0).rgb - r;
        s = vec2(dot(d, d), dot(r, r));
    }
    uint lane = gl_LocalInvocationIndex;
    group_sums[lane] = s;
    memoryBarrierShared();
    barrier();
    for (uint stride = uint(GROUP) / 2u; stride > 0u; stride >>= 1) {
        if (lane < stride)
            group_sums[lane] += group_sums[lane + stride];
        memoryBarrierShared();
        barrier();
    }
    if (lane == 0u)
        partial[gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x] = group_sums[0];
}
