// Where each probe quantity lives in the probe textures (NumPy twin: app/rendering/probes/layout.py).
//
// PROBE_SH_ORDER (0 .. 4; default 2) keeps bands up to that order, PROBE_SH_COEFFS = (order + 1)^2
// coefficients a colour. Channel f = 4 * texture + component (component rgba).
//
// Colour packing (also the bake's running means, lib/probe_accum.glsl, at order 2 or more):
//   coefficient k < 9 (bands 0..2), colour c: f = 3 k + c        (f < 27, textures 0..6)
//   the sun's transmittance from the probe:  f = 27              (texture 6, alpha)
//   coefficient k >= 9 (bands 3, 4):          f = 28 + 3 (k - 9) + c
// so orders 0 to 2 use the seven textures of the design card (order 0 textures 0 and 6, order 1
// textures 0, 1, 2 and 6, order 2 all seven), order 3 thirteen (49 channels) and order 4 nineteen
// (76 channels).
// Grey packing (PROBE_GREY 1: r = g = b, one channel a coefficient): coefficient k at f = k for
// k < 3, the sun's transmittance at f = 3, coefficient k >= 3 at f = k + 1; textures 0 .. 6 as
// needed (order 0: one texture, order 2: three, order 4: seven).
//
// A build reads only the textures its order needs, as "slots" 0 .. PROBE_TEXTURE_COUNT - 1 in the
// order of their texture numbers (lib/probes.glsl probe_textures[], the bake's images).
#ifndef PROBE_SH_ORDER
#define PROBE_SH_ORDER 2
#endif
#ifndef PROBE_GREY
#define PROBE_GREY 0
#endif
// PROBE_SUN_LOBE 1: beside the bands, each colour's amplitude of a lobe about the sun's direction
// (lib/sun_lobe.glsl), packed as the coefficient after the last (PROBE_LOBE_COEFFICIENT): at order
// 3 the channels that the last texture had spare (colour 49 .. 51 of texture 12, grey 17 of
// texture 4). Only order 3 so far (order 4's colour textures have no spare channel).
#ifndef PROBE_SUN_LOBE
#define PROBE_SUN_LOBE 0
#endif
#if PROBE_SUN_LOBE && PROBE_SH_ORDER != 3
#error "PROBE_SUN_LOBE: SH order 3 only"
#endif
#define PROBE_SH_COEFFS ((PROBE_SH_ORDER + 1) * (PROBE_SH_ORDER + 1))
#define PROBE_LOBE_COEFFICIENT PROBE_SH_COEFFS
#if PROBE_SH_ORDER <= 2
#define PROBE_COLOUR_TEXTURES 7
#else
#define PROBE_COLOUR_TEXTURES ((28 + 3 * (PROBE_SH_COEFFS - 9) + 3) / 4)
#endif
#define PROBE_COLOUR_CHANNELS (4 * PROBE_COLOUR_TEXTURES)
#if PROBE_GREY
#define PROBE_TEXTURE_COUNT ((PROBE_SH_COEFFS + 1 + 3) / 4)
#elif PROBE_SH_ORDER == 0
#define PROBE_TEXTURE_COUNT 2
#elif PROBE_SH_ORDER == 1
#define PROBE_TEXTURE_COUNT 4
#else
#define PROBE_TEXTURE_COUNT PROBE_COLOUR_TEXTURES
#endif

const int PROBE_SUN_CHANNEL = 27;   // colour packing

int probe_colour_channel(int k, int colour)
{
    return k < 9 ? 3 * k + colour : 28 + 3 * (k - 9) + colour;
}

// The colour packing's channel f: the coefficient it holds, or PROBE_SUN_COEFFICIENT for the
// sun's transmittance (channel 27).
const int PROBE_SUN_COEFFICIENT = -1;
int probe_colour_coefficient(int f)
{
    if (f == PROBE_SUN_CHANNEL)
        return PROBE_SUN_COEFFICIENT;
    return f < 27 ? f / 3 : 9 + (f - 28) / 3;
}

// The grey packing's channel f: the colour packing's channel that holds it (red), or -1 if unused.
int probe_grey_source(int f)
{
    if (f == 3)
        return PROBE_SUN_CHANNEL;
    int k = f < 3 ? f : f - 1;
#if PROBE_SUN_LOBE
    if (k == PROBE_LOBE_COEFFICIENT)
        return probe_colour_channel(k, 0);
#endif
    return k < PROBE_SH_COEFFS ? probe_colour_channel(k, 0) : -1;
}

// Slot -> texture number: the slots of colour orders 0 and 1 skip textures (lib/probes.glsl reads
// those two written out).
int probe_texture_number(int slot)
{
#if !PROBE_GREY && PROBE_SH_ORDER == 0
    return slot == 1 ? 6 : 0;
#elif !PROBE_GREY && PROBE_SH_ORDER == 1
    return slot == 3 ? 6 : slot;
#else
    return slot;
#endif
}
