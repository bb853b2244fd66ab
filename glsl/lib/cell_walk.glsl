// Walking the macrocells of the majorant grid along a ray with a 3D DDA (Amanatides and Woo): the
// cells in order, each one's exit distance and majorant (glsl/majorant_grid.comp builds them;
// every cell's majorant bounds sigma_t in it). Tracking (lib/tracking.glsl) draws free flights per
// cell.
// Needs box_half_extent (lib/medium.glsl). Absent where GLOBAL_MAJORANT is defined.
#include "lib/checks.glsl"
#if !defined(GLOBAL_MAJORANT)
uniform sampler3D majorant_grid;    // R32F per macrocell (texelFetch), >= sigma_t in the cell
uniform float majorant_grid_bound;  // >= every cell's majorant; 0: the whole volume is vacuum
uniform int use_majorant_grid;      // 0: the global majorant instead (comparison, benchmark)

// The macrocells along a ray, front to back.
struct CellWalk {
    vec3 o;           // ray origin in macrocell units (cell i spans [i, i + 1) per axis)
    vec3 inv;         // 1 / direction in macrocell units (0 where the direction has no component)
    ivec3 dir_step;   // +1 / -1 per axis (0 where the direction has no component)
    ivec3 cell;       // current macrocell
    ivec3 cells;      // grid size
    vec3 t_next;      // ray distance of the current cell's exit face along each axis
};

const float CELL_WALK_NEVER = 1e30;   // t_next along an axis the ray never crosses
// Faces closer than this (in macrocells, along their axis) count as reached; see cell_walk_cross.
// Far above float rounding of positions in macrocell units (about 1e-5 for origins within a few
// hundred macrocells), below how far beyond its cell a majorant holds (SUPPORT_SLACK = 1/32 voxel:
// app/twins/majorant_grid.py; 1/256 of a macrocell of 8 voxels, 1/1024 of one of 32 voxels, which is what a
// 2048-voxel axis gets).
const float CELL_WALK_SNAP = 1e-4;

void cell_walk_exits(inout CellWalk w)
{
    vec3 face = vec3(w.cell) + vec3(greaterThan(w.dir_step, ivec3(0)));
    w.t_next = mix((face - w.o) * w.inv, vec3(CELL_WALK_NEVER), equal(w.dir_step, ivec3(0)));
}

// Crosses every exit face at or just ahead of t (within CELL_WALK_SNAP: faces that rounding may
// put on either side of t, and corners). Both the walk and a walk started afresh at t use this
// rule, so a resumed walk is in the same cell as the uninterrupted one and never spends a step or a
// random number on a sliver of a cell. False once the walk has left the grid.
bvec3 cell_walk_faces_at(CellWalk w, float t)
{
    return lessThanEqual(w.t_next, vec3(t) + CELL_WALK_SNAP * abs(w.inv));
}

bool cell_walk_cross(inout CellWalk w, float t)
{
    w.cell += ivec3(cell_walk_faces_at(w, t)) * w.dir_step;
    cell_walk_exits(w);
    return all(greaterThanEqual(w.cell, ivec3(0))) && all(lessThan(w.cell, w.cells));
}

// Sets the walk up at origin + t * direction in the macrocell holding that point (clamped into the
// grid), before crossing any face: cell_walk_begin's first half.
void cell_walk_start(vec3 origin, vec3 direction, float t, out CellWalk w)
{
    w.cells = textureSize(majorant_grid, 0);
    vec3 per_world = vec3(w.cells) / (2.0 * box_half_extent);   // macrocells per unit length
    w.o = (origin + box_half_extent) * per_world;
    vec3 d = direction * per_world;
    bvec3 still = equal(d, vec3(0.0));
    w.inv = mix(1.0 / mix(d, vec3(1.0), still), vec3(0.0), still);
    w.dir_step = ivec3(sign(d));
    w.cell = clamp(ivec3(floor(w.o + t * d)), ivec3(0), w.cells - 1);
    cell_walk_exits(w);
}

// Starts the walk at origin + t * direction; false when that point is leaving the grid (within
// CELL_WALK_SNAP of its last face: tracking keeps that last cell's majorant for the sliver left,
// lib/tracking.glsl).
bool cell_walk_begin(vec3 origin, vec3 direction, float t, out CellWalk w)
{
    cell_walk_start(origin, direction, t, w);
    return cell_walk_cross(w, t);
}

float cell_walk_exit(CellWalk w)
{
    return min(min(w.t_next.x, w.t_next.y), w.t_next.z);
}

float cell_majorant(CellWalk w)
{
    CHECK_TEXEL(w.cell, w.cells, CHECK_SITE_MAJORANT_CELL);
    return texelFetch(majorant_grid, w.cell, 0).r;
}
#endif
