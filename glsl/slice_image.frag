// A slice of the volume (app/viewer/panels/slice_panel.py): its texture drawn into a rectangle of the
// window, one texel a voxel, unfiltered (texelFetch: no sampler state can blur it); row 0 of the
// texture at the top.
uniform sampler2D slice_image;
uniform vec4 image_rect;   // x, y, width, height in framebuffer pixels (GL's bottom-left origin)
out vec4 frag_colour;

void main()
{
    vec2 f = (gl_FragCoord.xy - image_rect.xy) / image_rect.zw;
    if (any(lessThan(f, vec2(0.0))) || any(greaterThanEqual(f, vec2(1.0))))
        discard;
    ivec2 size = textureSize(slice_image, 0);
    ivec2 texel = min(ivec2(vec2(f.x, 1.0 - f.y) * vec2(size)), size - 1);
    frag_colour = texelFetch(slice_image, texel, 0);
}
