// The lights of SPEC.md: a directional sun and a constant environment (or, with ENVIRONMENT_MAP
// defined, an environment map: lib/environment_map.glsl).
uniform vec3 sun_direction;   // unit vector from the scene towards the sun
uniform vec3 sun_irradiance;  // RGB irradiance on a plane facing the sun
#if defined(ENVIRONMENT_MAP)
#include "lib/environment_map.glsl"
#else
uniform vec3 environment;     // RGB radiance arriving from every direction
#endif
