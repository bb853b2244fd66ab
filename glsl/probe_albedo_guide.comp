// The raymarched probes image made the denoiser's albedo guide on the GPU
// (app/rendering/denoise/probe_guide.py; NumPy twin app/twins/probe_albedo_guide.py): each pixel's
// usable radiance divided by one scale, the ALBEDO_GUIDE_QUANTILE quantile of the pixels' largest
// channel, and clamped to [0, 1] (what radiance_as_albedo makes on the host, with the quantile
// read from a histogram instead of a sort). Three passes, chosen by GUIDE_PASS:
//   0: the largest channels' histogram. A bin is a positive float32's top bits (its exponent and
//      the top 5 bits of its mantissa: HISTOGRAM_BIN_SHIFT): 32 bins an octave, each 1.6-3.1% of
//      its values wide; exact integers, the same in NumPy. Counted in shared memory per
//      workgroup, then added into the storage buffer.
//   1: one workgroup: the bin holding the quantile's rank, the scale interpolated in it (the
//      bin's counts taken as spread evenly), written beside the histogram; the histogram cleared
//      for the next image (no host clear).
//   2: the guide, written packed (3 floats a pixel, pixel x of row y at 3 (x + width y)): the
//      layout the filter's guide memory takes with one copy.
#if !defined(GUIDE_PASS) || !defined(ALBEDO_GUIDE_QUANTILE)
#error "GUIDE_PASS (0, 1 or 2) and ALBEDO_GUIDE_QUANTILE, defined by the host"
#endif
#include "lib/usable_radiance.glsl"

#define HISTOGRAM_BIN_SHIFT 18
#define HISTOGRAM_BINS 8192          // 2^(31 - HISTOGRAM_BIN_SHIFT): every non-negative float32
#define SCAN_THREADS 1024
#define BINS_PER_THREAD (HISTOGRAM_BINS / SCAN_THREADS)

layout(std430, binding = 0) buffer PeakHistogram {
    float guide_scale;                   // pass 1's result, read by pass 2
    uint histogram_pad[3];
    uint peak_count[HISTOGRAM_BINS];     // zero between images (pass 1 clears it)
};

float largest_channel(vec3 radiance)
{
    vec3 usable = usable_radiance(radiance, false);
    return max(max(usable.r, usable.g), usable.b);
}

#if GUIDE_PASS == 0
// 16 x 16 invocations, each 4 x 4 pixels: a workgroup's 64 x 64 pixels
#define PIXELS_PER_SIDE 4
layout(local_size_x = 16, local_size_y = 16) in;
uniform sampler2D probe_image;
shared uint group_count[HISTOGRAM_BINS];

void main()
{
    uint lane = gl_LocalInvocationIndex;
    for (uint b = lane; b < uint(HISTOGRAM_BINS); b += 256u)
        group_count[b] = 0u;
    memoryBarrierShared();
    barrier();
    ivec2 size = textureSize(probe_image, 0);
    ivec2 origin = ivec2(gl_GlobalInvocationID.xy) * PIXELS_PER_SIDE;
    for (int dy = 0; dy < PIXELS_PER_SIDE; ++dy) {
        for (int dx = 0; dx < PIXELS_PER_SIDE; ++dx) {
            ivec2 p = origin + ivec2(dx, dy);
            if (all(lessThan(p, size))) {
                float peak = largest_channel(texelFetch(probe_image, p, 0).rgb);
                atomicAdd(group_count[floatBitsToUint(peak) >> HISTOGRAM_BIN_SHIFT], 1u);
            }
        }
    }
    memoryBarrierShared();
    barrier();
    for (uint b = lane; b < uint(HISTOGRAM_BINS); b += 256u) {
        uint n = group_count[b];
        if (n != 0u)
            atomicAdd(peak_count[b], n);
    }
}

#elif GUIDE_PASS == 1
layout(local_size_x = SCAN_THREADS) in;
uniform uint pixel_count;
shared uint before[SCAN_THREADS];     // the counts of the bins below each invocation's first

void main()
{
    uint lane = gl_LocalInvocationIndex;
    uint first = lane * uint(BINS_PER_THREAD);
    uint own[BINS_PER_THREAD];
    uint total = 0u;
    for (int i = 0; i < BINS_PER_THREAD; ++i) {
        own[i] = peak_count[first + uint(i)];
        peak_count[first + uint(i)] = 0u;   // its own bins: no other invocation reads them
        total += own[i];
    }
    before[lane] = total;
    memoryBarrierShared();
    barrier();
    // inclusive scan (Hillis and Steele), then made exclusive
    for (uint stride = 1u; stride < uint(SCAN_THREADS); stride <<= 1) {
        uint add = lane >= stride ? before[lane - stride] : 0u;
        barrier();
        before[lane] += add;
        memoryBarrierShared();
        barrier();
    }
    uint below = before[lane] - total;
    // np.quantile's rank (linear interpolation between order statistics) and its whole part
    float rank = ALBEDO_GUIDE_QUANTILE * float(pixel_count - 1u);
    uint k = uint(floor(rank));
    if (pixel_count == 0u || k < below || k >= below + total)
        return;
    uint cumulative = below;
    for (int i = 0; i < BINS_PER_THREAD; ++i) {
        uint n = own[i];
        if (k < cumulative + n) {
            uint bin = first + uint(i);
            float scale = 0.0;
            if (bin != 0u) {   // bin 0: zero and the smallest subnormals
                float low = uintBitsToFloat(bin << HISTOGRAM_BIN_SHIFT);
                float high = uintBitsToFloat((bin + 1u) << HISTOGRAM_BIN_SHIFT);
                float t = clamp((rank - float(cumulative) + 0.5) / float(n), 0.0, 1.0);
                scale = low + t * (high - low);
            }
            guide_scale = scale;
            return;
        }
        cumulative += n;
    }
}

#elif GUIDE_PASS == 2
layout(local_size_x = 16, local_size_y = 16) in;
uniform sampler2D probe_image;
layout(std430, binding = 1) writeonly buffer AlbedoGuide { float albedo_guide[]; };

void main()
{
    ivec2 size = textureSize(probe_image, 0);
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, size)))
        return;
    float scale = guide_scale;
    vec3 usable = usable_radiance(texelFetch(probe_image, p, 0).rgb, false);
    vec3 albedo = scale > 0.0 ? clamp(usable / scale, 0.0, 1.0) : vec3(0.0);
    uint at = 3u * uint(p.x + size.x * p.y);
    albedo_guide[at] = albedo.r;
    albedo_guide[at + 1u] = albedo.g;
    albedo_guide[at + 2u] = albedo.b;
}
#else
#error "GUIDE_PASS must be 0, 1 or 2"
#endif
