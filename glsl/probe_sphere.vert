// The viewer's probe-grid view: one small sphere per probe, instanced; instance i is probe i.
#include "probe_common.glsl"

layout(location = 0) in vec3 sphere_point;   // on the unit sphere: position and normal
uniform mat4 view_projection;                // world to clip, the renderers' camera (app/viewer/orbit.py)
uniform float sphere_radius;                 // world units
flat out vec3 probe_centre;
out vec3 normal;

void main()
{
    probe_centre = probe_position(uint(gl_InstanceID));
    normal = sphere_point;
    gl_Position = view_projection * vec4(probe_centre + sphere_radius * sphere_point, 1.0);
}
