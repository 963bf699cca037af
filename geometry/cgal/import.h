/* The CGAL shim: the only C++ in radpt, behind this C header.
 *
 * Reads polygon meshes (OBJ, OFF, PLY) with CGAL's stream readers,
 * triangulates polygons, repairs nothing silently: zero-area and duplicate
 * faces are dropped and counted, inconsistent orientation is reported.
 * Reads Wavefront OBJ with its MTL libraries as a whole scene (its own
 * line-numbered parser).  Decides whether a triangle
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
    uint32_t *tri_line;   /* line of the face each triangle comes from (0: unknown,
                             e.g. a binary file) */
    /* OBJ scenes only (NULL / 0 otherwise): */
    uint32_t *tri_group;  /* group (o/g name) of each triangle */
    char **group_names;   /* ngroups names ("" for faces before any o/g) */
    size_t ngroups;
    uint32_t *tri_material; /* material of each triangle, UINT32_MAX if none */
    char **material_names;
    double *material_kd;  /* 3 * nmaterials, linear RGB in [0, 1] */
    double *material_ke;  /* 3 * nmaterials, >= 0 */
    size_t nmaterials;
    /* What the reader dropped, each with the line of its first instance
     * (0: unknown).  Zero-area faces: every triangle of the face has zero
     * area (a zero-area sliver of a face with area carries nothing and is
     * not counted).  Duplicates: a face with the same vertex positions in
     * the same cyclic order as an earlier one (an oppositely wound copy is a
     * two-sided sheet and is kept). */
    size_t degenerate_faces, degenerate_line;
    size_t duplicate_faces, duplicate_line;
    /* Edges used twice in the same direction after the drops, and the line
     * of the first face found using an edge the way an earlier face did. */
    size_t orientation_conflicts, orientation_line;
    /* Other things the reader did not use, as "FILE:LINE: ..." messages
     * (one per file: ignored statements; materials that are black here). */
    char **warnings;
    size_t nwarnings;
} rp_tri_mesh;

/* Reads an .obj, .off or .ply (by extension).  Returns 0 on success;
 * on failure non-zero, with a "FILE: what is wrong" message in msg.
 * Degenerate faces are dropped and counted; with reject_degenerate set
 * they are an error instead. */
int rp_cgal_read_mesh(const char *path, int reject_degenerate, rp_tri_mesh *out,
                      char *msg, size_t msglen);

/* Reads an OBJ with its MTL libraries as a scene: groups and materials
 * filled in.  Both files are read by radpt's own parser, so every error
 * names FILE:LINE (of the .obj or the .mtl).  MTL as the specification
 * says: one value of Kd, Ke or Ka means grey; Kd must lie in [0, 1], Ke be
 * >= 0.  Returns 0 on success. */
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
