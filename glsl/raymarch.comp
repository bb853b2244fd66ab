// The raymarcher as a compute pass: one invocation per pixel.
layout(local_size_x = 8, local_size_y = 8) in;
#include "raymarch_common.glsl"

void main()
{
    raymarch_pixel(ivec2(gl_GlobalInvocationID.xy));
}
