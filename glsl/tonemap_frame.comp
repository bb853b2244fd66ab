// A running-mean image tone mapped into 8-bit sRGB on the GPU, for movie frames (app/movie/frames.py):
// exposure, clip, sRGB (lib/tonemap.glsl, the twin of app/rendering/tonemap.py to_uint8). Reading
// back 4 bytes a pixel instead of the float image, and leaving NumPy's float64 pow out, is what
// lets a 1080p frame go to the encoder in a millisecond or two.
layout(local_size_x = 16, local_size_y = 16) in;
#include "lib/tonemap.glsl"

layout(rgba32f, binding = 0) readonly uniform image2D accumulation;
layout(rgba8, binding = 1) writeonly uniform image2D frame;
uniform float exposure;

void main()
{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(frame))))
        return;
    imageStore(frame, p, vec4(srgb_encode(imageLoad(accumulation, p).rgb * exposure), 1.0));
}
