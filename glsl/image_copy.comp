// Copies an RGBA32F image into another of its size, texel for texel, or with CLEAR zeroes one
// (host side app/rendering/image_ops.py: an accumulation's restart, snapshots, refine's copies).
// A compute pass, not a framebuffer clear or blit: on the H200 at 3840x2160 those went through
// the graphics pipeline at 2.4 and 2.6 ms of GPU time against 0.04 and 0.06 ms here
// (lab/experiments/clear_cost.py), and the viewer restarts its accumulations after every bake
// slice and camera move.
layout(local_size_x = 16, local_size_y = 16) in;

layout(rgba32f, binding = 1) writeonly uniform image2D target;
#ifndef CLEAR
layout(rgba32f, binding = 0) readonly uniform image2D source;
#endif

void main()
{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(target))))
        return;
#ifdef CLEAR
    imageStore(target, p, vec4(0.0));
#else
    imageStore(target, p, imageLoad(source, p));
#endif
}
