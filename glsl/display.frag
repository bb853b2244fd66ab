// The viewer's picture: a method's running mean, tone mapped (exposure, sRGB), or two methods
// side by side with a divider, or the per-pixel error against the path tracer as a heat map.
// Accumulation images store row 0 at the top; the window's rows count from the bottom.
uniform sampler2D image_main;      // the method's accumulation (rgb: mean linear radiance)
uniform sampler2D image_other;     // split: the right-hand method; error: the path tracer
uniform sampler2D heat_colormap;   // N x 1, display RGB
uniform int display_mode;          // 0 image, 1 split, 2 error
uniform vec4 view_rect;            // x, y, width, height of the view in framebuffer pixels
uniform float split_position;      // divider as a fraction of the view's width
uniform float exposure;
uniform float error_scale;         // 1 / (heat_max * rms of the reference)
uniform vec3 background;           // display colour where no image is available
uniform int have_main, have_other;
out vec4 frag_colour;

#include "lib/tonemap.glsl"

vec3 tone_mapped(sampler2D image, int have, vec2 uv)
{
    return have != 0 ? srgb_encode(texture(image, uv).rgb * exposure) : background;
}

void main()
{
    vec2 uv = (gl_FragCoord.xy - view_rect.xy) / view_rect.zw;
    uv.y = 1.0 - uv.y;
    vec3 colour;
    if (display_mode == 1) {
        float divider_x = view_rect.x + split_position * view_rect.z;
        colour = gl_FragCoord.x < divider_x ? tone_mapped(image_main, have_main, uv)
                                            : tone_mapped(image_other, have_other, uv);
        if (abs(gl_FragCoord.x - divider_x) < 1.0)
            colour = vec3(1.0);
    } else if (display_mode == 2) {
        if (have_main == 0 || have_other == 0) {
            colour = background;
        } else {
            vec3 d = texture(image_main, uv).rgb - texture(image_other, uv).rgb;
            float e = sqrt(dot(d, d) / 3.0) * error_scale;
            colour = texture(heat_colormap, vec2(clamp(e, 0.0, 1.0), 0.5)).rgb;
        }
    } else {
        colour = tone_mapped(image_main, have_main, uv);
    }
    frag_colour = vec4(colour, 1.0);
}
