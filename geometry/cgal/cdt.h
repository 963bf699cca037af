/* The CGAL shim's 2-D constrained Delaunay triangulation, behind a C header
 * (C++17 and CGAL only in cdt.cpp).
 *
 * Used by the discontinuity mesh (geometry/discontinuity.h, mesh.c): one
 * scene face at a time, in 2-D coordinates of the face's plane, a closed
 * boundary polygon, interior points and constraint segments (shadow and
 * contact lines: Heckbert 1992, Lischinski, Tampieri & Greenberg 1992) are
 * triangulated so that every constraint is a union of triangle edges.
 * Constraints may cross: CGAL computes the crossing points (exact
 * predicates, inexact constructions: Exact_predicates_tag) and those points
 * come back as new vertices.  Every extern "C" function catches all
 * exceptions. */
#ifndef RP_CGAL_CDT_H
#define RP_CGAL_CDT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_cdt_input {
    const double *xy;          /* 2 * npoints coordinates */
    size_t npoints;
    size_t nboundary;          /* points 0 .. nboundary-1 are the boundary
                                  polygon, counter-clockwise, closed (last to
                                  first); the rest lie strictly inside */
    const uint32_t *segments;  /* 2 * nsegments point indices: constraints */
    size_t nsegments;
} rp_cdt_input;

/* The triangulation of the inside of the boundary, owned by the caller after
 * a successful call; release with rp_cdt_output_free. */
typedef struct rp_cdt_output {
    double *xy;                /* 2 * nvertices */
    int64_t *input;            /* per vertex: the input point it is, or -1 for a
                                  point CGAL made (constraints crossing) */
    size_t nvertices;
    uint32_t *tri;             /* 3 * ntriangles vertex indices, counter-clockwise */
    size_t ntriangles;
} rp_cdt_output;

/* Returns 0 on success; non-zero with a message in msg on failure (bad
 * index, out of memory, a CGAL exception). */
int rp_cgal_cdt(const rp_cdt_input *in, rp_cdt_output *out, char *msg, size_t msglen);

void rp_cdt_output_free(rp_cdt_output *out);

#ifdef __cplusplus
}
#endif

#endif
