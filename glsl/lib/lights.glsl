// The lights of SPEC.md: a directional sun and a constant environment.
uniform vec3 sun_direction;   // unit vector from the scene towards the sun
uniform vec3 sun_irradiance;  // RGB irradiance on a plane facing the sun
uniform vec3 environment;     // RGB radiance arriving from every direction
