// Includes shared by raymarch.comp and raymarch.frag (one source, two stages).
#define PROBE_SAMPLING
#include "lib/rng.glsl"
#include "lib/camera.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/light_grid.glsl"
#include "lib/segment_sun.glsl"
#include "lib/cell_walk.glsl"
uniform int max_bounces;
uniform float anisotropy;
#include "lib/running_mean.glsl"
#include "lib/raymarch.glsl"
