/* Scenes for tests: loaded from the source tree or parsed from text, with a
 * Criterion assertion (naming the file and the parser's message) when the
 * scene is refused. */
#ifndef RP_TEST_SCENE_UTIL_H
#define RP_TEST_SCENE_UTIL_H

#include <stddef.h>
#include <stdint.h>

#include "geometry/scene.h"

/* rel is relative to the source directory: "scenes/cornell.scene". */
rp_scene *rp_test_load(const char *rel);
/* A scene from text; includes and meshes resolve against dir (NULL: the
 * current directory). */
rp_scene *rp_test_parse_in(const char *text, const char *dir);
rp_scene *rp_test_parse(const char *text);

/* A triangle mesh made by a test (flat arrays, owned). */
typedef struct rp_test_mesh {
    double *xyz;   /* 3 * nv */
    uint32_t *tri; /* 3 * nt */
    size_t nv, nt;
} rp_test_mesh;
void rp_test_mesh_free(rp_test_mesh *m);
/* Appends triangle (a, b, c); the caller sized m->tri. */
void rp_test_mesh_push(rp_test_mesh *m, uint32_t a, uint32_t b, uint32_t c);
/* A unit sphere at the origin of `slices` x `stacks` (poles as fans), rings
 * of latitude first..last only (0..stacks: the whole sphere), every
 * triangle wound outward, or inward when `inward`. */
rp_test_mesh rp_test_uv_sphere(int slices, int stacks, int first, int last, int inward);
/* Writes m as an OFF file (asserts it could). */
void rp_test_write_off(const char *path, const rp_test_mesh *m);

#endif
