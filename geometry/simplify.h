/* A solution mesh separate from the ray mesh (issue 18: "model no more than
 * a scene needs").
 *
 * A dense scanned mesh carries far more faces than the light on it needs.
 * rp_solution_create simplifies each dense triangle-mesh surface of a scene
 * (the CGAL shim's Garland-Heckbert edge collapse, geometry/cgal/simplify.h)
 * and returns the coarser scene a finite-element method solves on, with a
 * map from the full scene's faces back into it:
 *
 *   - a face of a surface left as it is maps to its copy (same plane, so a
 *     point on one is a point on the other);
 *   - a vertex of a simplified surface maps to its closest point on the
 *     simplified surface (a face of the solution scene and barycentric
 *     weights there); the solution at a point of a full face is then the
 *     linear interpolation of the solution at its three vertices' images,
 *     which is continuous across the full mesh: no cracks, whatever the
 *     method's own reconstruction on the coarse faces.
 *
 * Camera rays, final gathers and everything a user sees keep the full
 * geometry; the solver's own visibility uses the solution scene (a ray
 * leaving a simplified face would start on the wrong side of the full
 * surface about half of the time).
 *
 * Which surfaces: those of the scene's `mesh` statements (and OBJ groups)
 * with at least RP_SIMPLIFY_MIN_FACES consistently wound triangles (where
 * they are not a 2-manifold, an edge with a third triangle or parts that
 * meet at a vertex, the shim cuts them there into one, borders kept; since
 * stop 37: CGAL's diplodocus, pinched at two points, was solved
 * whole before); the others are kept, and a surface that cannot be simplified
 * is named in a message.  How far: `ratio` keeps that fraction of the
 * edges; `auto` (ratio 0) collapses while the Garland-Heckbert quadric
 * error (a sum of squared distances to the merged input planes) times the
 * input's mean triangle area stays below (RP_SIMPLIFY_AUTO_TOLERANCE x the
 * scene's diagonal)^4 (geometry/cgal/simplify.cpp): relative to the scene,
 * so it depends neither on its size and units nor on how finely the surface
 * is tessellated (the bunny: 7,706 triangles from its 75,408, 7,576 from a
 * midpoint subdivision to 301,632; with the bound on the sum alone before
 * stop 37 it was 7,800, 12,922 and 20,164 from 75,408, 301,632 and
 * 1,206,528).  1.1e-3 of the diagonal keeps the published bunny as stop 36
 * did and every surface of eleven CGAL meshes in the bunny's room within
 * the path tracer's seed spread (docs/design.md, stop 37). */
#ifndef RP_SIMPLIFY_H
#define RP_SIMPLIFY_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"
#include "status.h"

#ifdef __cplusplus
extern "C" {
#endif

#define RP_SIMPLIFY_MIN_FACES 1000
#define RP_SIMPLIFY_AUTO_TOLERANCE 1.1e-3
/* The two as text, for --simplify's help (solvers/solver.h). */
#define RP_SIMPLIFY_TEXT_(x) #x
#define RP_SIMPLIFY_TEXT(x) RP_SIMPLIFY_TEXT_(x)

typedef struct rp_solution rp_solution;

/* ratio in (0, 1): keep that fraction of each dense surface's edges;
 * 0: auto (see above).  tolerance_rel > 0 overrides the auto tolerance
 * (a fraction of the scene's diagonal; with a ratio, both limits hold).
 * threads: for the closest-point queries of the map back (0: OpenMP's
 * default; the answers do not depend on it).  On success *out is the
 * solution (rp_solution_scene is the scene itself, copied, when no surface
 * was simplified); messages (one per dense surface: what it became, or why
 * it was kept) go to log when non-NULL. */
rp_status rp_solution_create(const rp_scene *full, double ratio, double tolerance_rel, int threads, rp_solution **out,
                             void (*log)(void *ctx, const char *message), void *log_ctx, rp_error *err);
void rp_solution_destroy(rp_solution *sol);

/* The scene to solve on. */
const rp_scene *rp_solution_scene(const rp_solution *sol);
/* Surfaces simplified, and the largest distance measured between a full
 * and a simplified surface at their vertices (both ways), scene units. */
size_t rp_solution_nsimplified(const rp_solution *sol);
double rp_solution_max_distance(const rp_solution *sol);

/* The solution's value at full-scene points.  eval(ctx, face, p, out) gives
 * nb values at point p of solution face `face`.  rp_solution_vertex_values
 * evaluates it once at every full vertex of a simplified surface (into
 * values, nvertices(full) x nb; other rows are left alone);
 * rp_solution_eval then gives the value at point p of full face `face`:
 * the solution face's own value for a kept surface, the interpolation of
 * the vertex values for a simplified one. */
typedef void (*rp_solution_eval_fn)(const void *ctx, uint32_t face, rp_vec3 p, double *out);
void rp_solution_vertex_values(const rp_solution *sol, size_t nb, rp_solution_eval_fn eval, const void *ctx,
                               double *values);
void rp_solution_eval(const rp_solution *sol, size_t nb, rp_solution_eval_fn eval, const void *ctx,
                      const double *values, uint32_t face, rp_vec3 p, double *out);
/* Frees the maps back to the full scene, which only images read (1.3 MB
 * for the bunny's 75k triangles): rp_solution_vertex_values and
 * rp_solution_eval may not be called after it. */
void rp_solution_drop_maps(rp_solution *sol);

/* Midpoint subdivision of a triangle mesh (xyz: 3 x nv, tri: 3 x nt): every
 * triangle into four, one new vertex at the middle of each edge, so the
 * same surface at four times the triangles (the tessellation studies of
 * `radpt experiment modelsize`, tests/test_simplify.c).  On success *oxyz
 * (3 x *onv) and *otri (3 x *ont) are the caller's to free; 0 when out of
 * memory. */
int rp_triangles_subdivide(const double *xyz, size_t nv, const uint32_t *tri, size_t nt, double **oxyz, size_t *onv,
                           uint32_t **otri, size_t *ont);

#ifdef __cplusplus
}
#endif

#endif
