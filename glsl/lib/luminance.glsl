// Rec. 709 luminance weights: the one number a guiding decision makes of an RGB radiance
// (lib/guided_directions.glsl, lib/guided_distances.glsl).
const vec3 REC709_LUMINANCE = vec3(0.2126, 0.7152, 0.0722);
