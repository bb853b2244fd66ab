// Majorant per macrocell for empty-space skipping (NumPy twin: app/majorant.py majorant_grid).
// Rebuilt whenever the transfer function or density_scale changes: density_scale times the largest
// opacity of the transfer function over the cell's density range. The opacity is piecewise linear
// in the density, so its maximum over [lo, hi] is at lo, at hi, or at a table node between them.
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;

#include "lib/medium.glsl"

// RG32F per macrocell: the smallest and largest density trilinear filtering can return inside it
// (already widened for rounding; app/majorant.py density_range_grid).
uniform sampler3D density_range;
uniform ivec3 cells;
uniform float majorant_safety;   // app/majorant.py MAJORANT_SAFETY
layout(r32f, binding = 0) uniform writeonly image3D majorant_out;

void main()
{
    ivec3 c = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(c, cells)))
        return;
    vec2 range = texelFetch(density_range, c, 0).rg;
    float lo = clamp(range.x, 0.0, 1.0);
    float hi = clamp(range.y, 0.0, 1.0);
    float a = max(transfer_at(lo).a, transfer_at(hi).a);
    float last_node = float(transfer_size - 1);
    int i = int(ceil(lo * last_node));
    int last = min(int(floor(hi * last_node)), transfer_size - 1);
    // Four nodes per iteration: at most 1024 iterations for the largest table (4096 rows), well
    // inside llvmpipe's loop limit even at 16 lanes per SIMD batch.
    for (; i <= last; i += 4) {
        CHECK_INDEX(i, transfer_size, CHECK_SITE_TRANSFER_ENTRY);
        a = max(a, TRANSFER_ENTRY(i).a);
        a = max(a, TRANSFER_ENTRY(min(i + 1, last)).a);
        a = max(a, TRANSFER_ENTRY(min(i + 2, last)).a);
        a = max(a, TRANSFER_ENTRY(min(i + 3, last)).a);
    }
    CHECK_TEXEL(c, imageSize(majorant_out), CHECK_SITE_IMAGE_TEXEL);
    imageStore(majorant_out, c, vec4(density_scale * a * majorant_safety));
}
