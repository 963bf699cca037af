/* Elements for finite-element radiosity.  The uniform mesh subdivides
 * every face of every surface into a regular grid of elements (quads into
 * n x m quads, triangles into k^2 triangles).  Edge subdivision counts are
 * chosen per class of edges that must agree (opposite sides of a quad, all
 * sides of a triangle, edges shared by two faces of one surface), so the
 * mesh is conforming inside each surface: no T-vertices.  The
 * discontinuity mesh (RP_MESH_DISCONTINUITY, mesh_disc.c) cuts the faces
 * that reflect or emit into triangles whose edges follow contact lines,
 * the outlines of faces hovering just over them and shadow boundaries,
 * and keeps the same sharing of a surface's edge vertices.  Either way
 * vertices are shared between the elements of a surface and adjacency is
 * recorded, so a solver can average element values to vertices and
 * interpolate (Gouraud). */
#ifndef RP_MESH_H
#define RP_MESH_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_mesh rp_mesh;

/* How faces are cut. */
typedef enum rp_mesh_mode {
    RP_MESH_UNIFORM = 0,      /* regular grids of quads or triangles */
    RP_MESH_DISCONTINUITY = 1 /* triangles conforming to contact lines (D0),
                                 near-contact outlines (GAP) and the
                                 umbra/penumbra boundaries of area lights
                                 (D1): discontinuity.h, mesh_disc.c */
} rp_mesh_mode;

typedef struct rp_mesh_params {
    size_t size;          /* sizeof(rp_mesh_params), so the struct can grow */
    double max_edge;      /* target longest element edge, scene units; 0: unused */
    size_t target_count;  /* target total element count; 0: unused */
    /* Since 0.16 (a caller whose size ends before a field gets its default): */
    int mode;             /* rp_mesh_mode; default uniform */
    size_t max_segments;  /* discontinuity: D1 segments kept per face; 0: the
                             default, RP_DISC_DEFAULT_MAX_PER_FACE */
} rp_mesh_params;

/* Default: about 1,000 elements for the whole scene. */
#define RP_MESH_DEFAULT_COUNT 1000

/* A memory cap: meshes above this many elements (about 2.5 GB with their
 * vertices and adjacency, before any solver state) are refused with a clear
 * error rather than left to fail an allocation. */
#define RP_MESH_MAX_ELEMENTS ((size_t)1 << 24)

typedef struct rp_element {
    uint32_t v[4];     /* mesh vertex indices, counter-clockwise from the front;
                          v[3] == RP_NONE for triangles */
    uint32_t nverts;   /* 3 or 4 */
    uint32_t face;     /* scene face it subdivides */
    uint32_t surface;
    rp_vec3 centroid;
    rp_vec3 normal;    /* the face's unit front normal */
    double area;
} rp_element;

typedef struct rp_mesh_quality {
    double min_aspect, mean_aspect, max_aspect; /* longest edge / shortest altitude-like
                                                   measure; 1 is best (see mesh.c) */
    double min_area, max_area;
} rp_mesh_quality;

/* Subdivides every face of the scene.  In discontinuity mode every face
 * that reflects or emits is triangulated (constrained Delaunay, in its
 * plane) so that every discontinuity segment on it (discontinuity.h) is a
 * union of element edges, with Steiner points on a triangular lattice of
 * spacing h between them; h is set by max_edge or calibrated so the total
 * comes near target_count.  Vertices on an edge shared by faces of one
 * surface are shared as in the uniform mesh (no T-vertices inside a
 * surface); rp_mesh_locate goes through a bucket grid instead of the
 * grid inversion.  With both max_edge and target_count
 * zero, aims at RP_MESH_DEFAULT_COUNT elements more than the scene's faces.  Exactly one of them may be set.  Faces
 * of surfaces black in every band (rho = Le = 0) are never cut: one element
 * each, counted in target_count; the rest of the count goes to the faces
 * that reflect or emit, so a black ground plane changes nothing else. */
rp_status rp_mesh_create(const rp_scene *scene, const rp_mesh_params *params,
                         rp_mesh **out, rp_error *err);
void rp_mesh_destroy(rp_mesh *mesh);

size_t rp_mesh_nelements(const rp_mesh *mesh);
/* 1 when a discontinuity mesh's shadow-boundary (D1) tracing stopped at its
 * work cap (RP_DISC_MAX_PAIRS in discontinuity.h): some boundaries are
 * missing from the mesh.  0 otherwise, and for a uniform mesh. */
int rp_mesh_disc_truncated(const rp_mesh *mesh);
const rp_element *rp_mesh_elements(const rp_mesh *mesh);
size_t rp_mesh_nvertices(const rp_mesh *mesh);
const rp_vec3 *rp_mesh_vertices(const rp_mesh *mesh);

/* Elements of one face are contiguous: [first, first + count). */
void rp_mesh_face_elements(const rp_mesh *mesh, uint32_t face, uint32_t *first, uint32_t *count);
/* Elements of one surface are contiguous too. */
void rp_mesh_surface_elements(const rp_mesh *mesh, uint32_t surface, uint32_t *first, uint32_t *count);

/* Neighbour across each edge of element e (edge i runs v[i] -> v[i+1]),
 * RP_NONE on a surface boundary.  out has room for 4. */
void rp_mesh_neighbors(const rp_mesh *mesh, uint32_t e, uint32_t out[4]);

/* Elements incident to vertex v: *count entries from the returned array. */
const uint32_t *rp_mesh_vertex_elements(const rp_mesh *mesh, uint32_t v, size_t *count);

/* The element of a face that contains point p (a point on the face,
 * e.g. a ray hit).  A grid face: constant time, inverting the grid; a
 * triangulated face: a bucket grid over its elements (a scan of the face's
 * elements where no bucket holds p). */
uint32_t rp_mesh_locate(const rp_mesh *mesh, uint32_t face, rp_vec3 p);

/* Barycentric weights of p among the element's vertices (3 or 4 weights,
 * bilinear for quads), for interpolating vertex values.  w has room for 4. */
void rp_mesh_element_weights(const rp_mesh *mesh, uint32_t e, rp_vec3 p, double w[4]);

void rp_mesh_quality_get(const rp_mesh *mesh, rp_mesh_quality *q);

#ifdef __cplusplus
}
#endif

#endif
