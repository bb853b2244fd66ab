// The raymarcher as a fragment pass (the design card's): a full-screen triangle, one fragment per
// pixel, the same raymarch_pixel; it writes the accumulation image directly (row 0 at the top).
#include "raymarch_common.glsl"

void main()
{
    ivec2 frag = ivec2(gl_FragCoord.xy);
    raymarch_pixel(ivec2(frag.x, image_size.y - 1 - frag.y));
}
