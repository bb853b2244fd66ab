// The kept region of SPEC.md's "Crop and clip" (app/scene/clip_region.py resolves a scene's crop box
// and clip plane against its volume into these uniforms; NumPy twin: ClipRegion.kept,
// sample_points and cuts_box there). Cut-away matter is gone for every ray: lib/medium.glsl's
// classified_at, which sigma_t_at and the raymarcher read, is 0 where kept_at is false, and
// box_intersect clips rays to the kept box. clip_region_on == 0 (the default value of an unset
// uniform) keeps everything, and then nothing here changes a single bit of any image.
#if defined(NO_CLIP_REGION)
// The scene has no crop box or clip plane (SceneResources.medium_defines): every test below folds
// to "kept" at compile time. As a uniform left 0 it cost the bake's walks 7% on an H200
// (bench/h200-bake-speed), though it never cut anything.
const int clip_region_on = 0;
#else
uniform int clip_region_on;
#endif
uniform vec3 kept_box_min;      // the crop box within the volume box, world units
uniform vec3 kept_box_max;
uniform vec3 kept_sample_min;   // the density is read at points clamped to these: the centres of
uniform vec3 kept_sample_max;   // the outermost kept voxels on a side the crop cuts, else +-1e30
uniform vec4 clip_plane;        // unit normal n and distance d: keeps dot(n, x) <= d

bool kept_at(vec3 x)
{
    return clip_region_on == 0
        || (all(greaterThanEqual(x, kept_box_min)) && all(lessThanEqual(x, kept_box_max))
            && dot(clip_plane.xyz, x) <= clip_plane.w);
}

// Where the density of a kept point is read: inside the crop's outermost voxel centres, so that
// trilinear filtering never blends in a voxel the crop cut away (a crop then renders exactly as
// the cropped volume does, which is clamped to its edge voxels in the same way).
vec3 kept_sample_point(vec3 x)
{
    return clip_region_on == 0 ? x : clamp(x, kept_sample_min, kept_sample_max);
}

// True when no point of the box [lo, hi] is kept (the majorant grid's cells cut away whole).
bool clip_region_cuts_box(vec3 lo, vec3 hi)
{
    if (clip_region_on == 0)
        return false;
    if (any(lessThan(hi, kept_box_min)) || any(greaterThan(lo, kept_box_max)))
        return true;
    vec3 nearest = mix(hi, lo, greaterThanEqual(clip_plane.xyz, vec3(0.0)));
    return dot(clip_plane.xyz, nearest) > clip_plane.w;
}
