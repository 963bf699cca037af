/* The CGAL shim: the only C++ in radpt, behind this C header.
 *
 * Reads polygon meshes (OBJ, OFF, PLY) with CGAL's stream readers,
 * triangulates polygons, repairs nothing silently: degenerate faces and
 * inconsistent orientation are reported.  Reads Wavefront OBJ with its MTL
 * library (tinyobjloader) as a whole scene.  Decides whether a triangle
 * soup is closed.  Every extern "C" function catches all exceptions. */
#ifndef RP_CGAL_IMPORT_H
#define RP_CGAL_IMPORT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A triangle mesh in flat arrays, owned by the caller after a successful
 * read; release with rp_tri_mesh_free. */
typedef struct rp_tri_mesh {
    double *xyz;          /* 3 * nvertices */
    size_t nvertices;
    uint32_t *tri;        /* 3 * ntriangles, counter-clockwise from the front */
    size_t ntriangles;
    /* OBJ scenes only (NULL / 0 otherwise): */
    uint32_t *tri_group;  /* group (o/g name) of each triangle */
    char **group_names;   /* ngroups names */
    size_t ngroups;
    uint32_t *tri_material; /* material of each triangle, UINT32_MAX if none */
    char **material_names;
    double *material_kd;  /* 3 * nmaterials, linear RGB */
    double *material_ke;  /* 3 * nmaterials */
    size_t nmaterials;
    /* Diagnostics from the reader. */
    size_t degenerate_faces;     /* zero-area faces dropped */
    size_t orientation_conflicts; /* edges used twice in the same direction */
} rp_tri_mesh;

/* Reads an .obj, .off or .ply (by extension).  Returns 0 on success;
 * on failure non-zero, with a "FILE: what is wrong" message in msg.
 * Degenerate faces are dropped and counted; with reject_degenerate set
 * they are an error instead. */
int rp_cgal_read_mesh(const char *path, int reject_degenerate, rp_tri_mesh *out,
                      char *msg, size_t msglen);

/* Reads an OBJ with its MTL library as a scene: groups and materials
 * filled in.  Returns 0 on success. */
int rp_obj_read_scene(const char *path, rp_tri_mesh *out, char *msg, size_t msglen);

void rp_tri_mesh_free(rp_tri_mesh *m);

/* Closedness of a triangle soup after welding vertices closer than
 * weld_tolerance: 1 closed (every edge shared by exactly two triangles),
 * 0 open, -1 on failure. */
int rp_cgal_is_closed(const double *xyz, size_t nvertices, const uint32_t *tri,
                      size_t ntriangles, double weld_tolerance);

#ifdef __cplusplus
}
#endif

#endif
