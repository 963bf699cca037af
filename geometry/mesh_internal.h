/* The mesh's private structure, shared by the two files that build meshes:
 * mesh.c (uniform grids, welding, topology, queries) and mesh_disc.c
 * (discontinuity meshes: constrained Delaunay triangles per face). */
#ifndef RP_MESH_INTERNAL_H
#define RP_MESH_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "mesh.h"

typedef struct face_grid {
    rp_vec3 c[4];       /* the face's corners (scene coordinates) */
    rp_vec3 normal;     /* unit front normal */
    uint32_t nverts;    /* 3 or 4 */
    uint32_t n, m;      /* quad: cells along u and v; triangle: k in both */
    uint32_t first;     /* first element of the face */
    uint32_t count;     /* n m (quad) or k^2 (triangle); a triangulated face: its triangles */
    /* A triangulated face (discontinuity mesh): its elements are found
     * through a bucket grid over the face's plane, origin c[0], axes ax, ay
     * (rp_v3_basis of the normal); bucket (i, j) lists the elements whose
     * bounding box meets it. */
    int triangulated;
    rp_vec3 ax, ay;
    double x0, y0, cell;
    uint32_t gx, gy;
    uint32_t *bstart;   /* gx gy + 1 offsets into belems */
    uint32_t *belems;
} face_grid;

struct rp_mesh {
    size_t nelements, nvertices, nfaces, nsurfaces;
    rp_element *elements;
    rp_vec3 *vertices;
    uint32_t *neighbors;  /* 4 per element */
    size_t *vstart;       /* nvertices + 1 offsets into velems */
    uint32_t *velems;
    face_grid *faces;
    uint32_t *surf_first, *surf_count;
    double max_edge;      /* the edge length the subdivision used */
    size_t nconstraints;  /* discontinuity mesh: segments it conforms to */
    int disc_truncated;   /* discontinuity mesh: D1 tracing hit its work cap */
};

/* Union-find over uint32_t indices (parent[x] == x at the roots), with
 * path halving; the smaller index becomes the root, so the result does not
 * depend on the order of the unions (mesh.c; also discontinuity.c's
 * welding of vertices). */
uint32_t rp_uf_find(uint32_t *parent, uint32_t x);
void rp_uf_union(uint32_t *parent, uint32_t a, uint32_t b);

/* What the discontinuity mesher needs of rp_mesh_create's welding: the
 * welded corner of face-corner slot 4 f + c, the unique edge of face-edge
 * slot 4 f + e (edges of one surface that join the same welded corners are
 * one), the unique edges' welded ends (ue_a < ue_b) and the welded corner
 * positions, which become the first mesh vertices. */
typedef struct rp_mesh_weld {
    const uint32_t *wid, *edge_of, *ue_a, *ue_b;
    size_t nue, nweld;
    const rp_vec3 *wpos;
} rp_mesh_weld;

/* Fills mesh->elements, ->vertices and the faces' element ranges and
 * locate grids with a discontinuity mesh (mesh_disc.c); mesh->faces[f].c,
 * .normal and .nverts are set.  Exactly one of max_edge, target is > 0. */
rp_status rp_mesh_build_disc(rp_mesh *mesh, const rp_scene *scene, const rp_mesh_weld *w, double max_edge,
                             size_t target, size_t max_per_face, rp_error *err);

/* The element of triangulated face fg nearest to containing p. */
uint32_t rp_mesh_locate_disc(const rp_mesh *mesh, const face_grid *fg, rp_vec3 p);

#endif
