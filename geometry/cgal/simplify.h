/* The CGAL shim's mesh simplification, behind a C header (C++17 and CGAL
 * only in simplify.cpp).
 *
 * Edge-collapse simplification of a triangle mesh (CGAL's
 * Surface_mesh_simplification) with Garland & Heckbert's plane quadrics
 * (Garland & Heckbert 1997, "Surface simplification using quadric error
 * metrics"): each collapse costs the sum of squared distances from the new
 * vertex to the planes of the original faces merged into it, and collapses
 * run cheapest first.  Border edges are never collapsed, so an open mesh keeps
 * its outline.  Used to give radiosity a solution mesh coarser than the mesh
 * the rays hit (issue 18, "a solution mesh separate from the ray mesh").
 *
 * After simplifying, every input vertex is mapped to its closest point on the
 * simplified mesh (CGAL's AABB tree), which is how a solution on the coarse
 * mesh is carried back to the full one, and the distances both ways are
 * measured at the vertices.  Every extern "C" function catches all
 * exceptions. */
#ifndef RP_CGAL_SIMPLIFY_H
#define RP_CGAL_SIMPLIFY_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_simplify_params {
    /* Stop once at most this fraction of the input's edges is left, in
     * (0, 1]; 1: no count limit. */
    double ratio;
    /* Stop before the first collapse whose quadric error times the input's
     * mean triangle area (an estimate of the squared distance integrated
     * over the area merged) exceeds tolerance^4; 0: no error limit.  In
     * scene units. */
    double tolerance;
    /* OpenMP threads for the closest-point queries of the map back and the
     * distances; 0: OpenMP's default. */
    int threads;
} rp_simplify_params;

/* A simplified mesh and the map back, owned by the caller after a
 * successful call; release with rp_simplified_free. */
typedef struct rp_simplified {
    double *xyz;            /* 3 * nvertices */
    size_t nvertices;
    uint32_t *tri;          /* 3 * ntriangles, same orientation as the input */
    size_t ntriangles;
    /* Per input vertex: the simplified triangle holding its closest point,
     * and that point's barycentric coordinates in it (3 per vertex). */
    uint32_t *vertex_tri;
    double *vertex_bary;
    /* Largest distance from an input vertex to the simplified surface, and
     * from a simplified vertex to the input surface (scene units). */
    double max_distance_in;
    double max_distance_out;
    size_t border_edges;    /* edges kept because they lie on a border */
    size_t cut_points;      /* points duplicated where the input was not a
                               2-manifold (an edge with a third triangle,
                               parts meeting at a vertex), cut there into
                               borders; 0 when it was one */
    size_t degenerate;      /* input triangles with two corners at one
                               position, left out of the collapse */
} rp_simplified;

/* Simplifies the mesh (xyz: 3 * nvertices, tri: 3 * ntriangles indices,
 * counter-clockwise from the front).  Vertices at the same position are one
 * vertex.  Returns 0 on success; 1 when the mesh cannot be simplified as it
 * is (not an oriented 2-manifold: an edge used by more than two faces or
 * twice the same way), with the reason in msg and *out empty; -1 on
 * failure (out of memory, a CGAL exception), with a message. */
int rp_cgal_simplify(const double *xyz, size_t nvertices, const uint32_t *tri, size_t ntriangles,
                     const rp_simplify_params *params, rp_simplified *out, char *msg,
                     size_t msglen);

void rp_simplified_free(rp_simplified *s);

#ifdef __cplusplus
}
#endif

#endif
