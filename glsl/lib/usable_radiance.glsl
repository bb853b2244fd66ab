// A radiance value a later pass can use: non-finite components 0 and, unless `signed_radiance`,
// negative ones 0 (the denoiser's output as keep_tile_means.comp takes and leaves it). NumPy
// twins: app/rendering/denoise/filter.py _make_usable, and np.nan_to_num for a signed image.

// Finite by its exponent bits (not all ones), so that no compiler's fast maths can fold it away.
bool finite_component(float x)
{
    return (floatBitsToUint(x) & 0x7F800000u) != 0x7F800000u;
}

vec3 usable_radiance(vec3 value, bool signed_radiance)
{
    vec3 finite = vec3(finite_component(value.r) ? value.r : 0.0,
                       finite_component(value.g) ? value.g : 0.0,
                       finite_component(value.b) ? value.b : 0.0);
    return signed_radiance ? finite : max(finite, vec3(0.0));
}
