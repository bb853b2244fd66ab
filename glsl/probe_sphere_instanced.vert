// The viewer's probe-grid view: one small sphere per drawn probe, instanced. The probes drawn
// (those in the visible region, every stride-th along each axis on large grids) and their
// centres come from the host (app/viewer/probe_view.py), so this file needs no probe layout;
// the sphere's colour is glsl/probe_sphere.frag's (the probe's SH radiance, tone mapped).
layout(location = 0) in vec3 sphere_point;    // on the unit sphere: position and normal
layout(location = 1) in vec3 instance_centre; // per instance: the probe's world position
uniform mat4 view_projection;                 // world to clip, the renderers' camera
uniform float sphere_radius;                  // world units
flat out vec3 probe_centre;
out vec3 normal;

void main()
{
    probe_centre = instance_centre;
    normal = sphere_point;
    gl_Position = view_projection * vec4(probe_centre + sphere_radius * sphere_point, 1.0);
}
