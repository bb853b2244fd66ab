// Includes shared by probe_sphere.vert and probe_sphere.frag: the probe grid over the volume box
// (lib/probes.glsl), written once for the bake, the renderers and the viewer.
#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/directions.glsl"
#include "lib/sh.glsl"
#include "lib/probes.glsl"
