// Display encoding (the twin of app/rendering/tonemap.py): exposure is applied by the caller, then
// clip to [0, 1] and the sRGB transfer curve.
vec3 srgb_encode(vec3 linear)
{
    vec3 x = clamp(linear, 0.0, 1.0);
    return mix(1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, 12.92 * x, lessThanEqual(x, vec3(0.0031308)));
}
