// Pinhole camera of SPEC.md. The Python side (app/twins/camera.py) passes the basis already scaled:
// camera_right by tan(fov_y / 2) * aspect, camera_up by tan(fov_y / 2).
uniform vec3 camera_eye;
uniform vec3 camera_forward;
uniform vec3 camera_right;
uniform vec3 camera_up;
uniform ivec2 image_size;

// Direction through a point on the image plane given in pixels, (0, 0) at the top-left corner.
vec3 camera_ray_direction(vec2 pixel_position)
{
    vec2 ndc = vec2(2.0 * pixel_position.x / float(image_size.x) - 1.0,
                    1.0 - 2.0 * pixel_position.y / float(image_size.y));
    return normalize(camera_forward + ndc.x * camera_right + ndc.y * camera_up);
}
