// refine's blend with the Denoise switch on (app/rendering/refine/refine.py, NumPy twin `blend_images`):
// the image shown, (1 - w) r + w D, of the raymarcher's image r and guided denoised D, with the
// weight w its last judgement estimated. Alpha is D's (guided's sample count).
layout(local_size_x = 16, local_size_y = 16) in;
layout(rgba32f, binding = 0) readonly uniform image2D raymarched;
layout(rgba32f, binding = 1) readonly uniform image2D denoised;
layout(rgba32f, binding = 2) writeonly uniform image2D blended;
uniform float weight;   // w, of D

void main()
{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(blended))))
        return;
    vec4 d = imageLoad(denoised, p);
    imageStore(blended, p, vec4(mix(imageLoad(raymarched, p).rgb, d.rgb, weight), d.a));
}
