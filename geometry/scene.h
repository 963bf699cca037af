/* The scene model both solvers read (docs/design.md, "Scene model", "Scene files").
 *
 * A scene is surfaces made of planar faces (triangles and convex quads), each
 * surface with one diffuse material (reflectance rho and emitted radiance Le
 * per spectral band), and an optional pinhole camera.  Surfaces are
 * one-sided: the back of a face is black.  The scene is immutable once
 * loaded, except its camera (rp_scene_set_camera, to be called before
 * anything hashes the scene or reads its camera); every accessor returns
 * borrowed, read-only data. */
#ifndef RP_SCENE_H
#define RP_SCENE_H

#include <stddef.h>
#include <stdint.h>

#include "status.h"
#include "vec.h"

#ifdef __cplusplus
extern "C" {
#endif

#define RP_NONE UINT32_MAX

typedef struct rp_scene rp_scene;

typedef enum rp_band_kind {
    RP_BANDS_GREY,     /* one band, image channel Y */
    RP_BANDS_RGB,      /* three bands, channels R, G, B */
    RP_BANDS_SPECTRAL  /* N sampled wavelengths in nm, ascending */
} rp_band_kind;

typedef struct rp_material {
    const char *name;
    const double *rho;  /* diffuse reflectance per band, in [0, 1] */
    const double *Le;   /* emitted radiance per band, >= 0 */
    int emitter;        /* some band of Le is > 0 */
} rp_material;

typedef enum rp_surface_kind {
    RP_SURFACE_TRIANGLE,
    RP_SURFACE_QUAD,
    RP_SURFACE_BOX,
    RP_SURFACE_MESH
} rp_surface_kind;

typedef struct rp_surface {
    const char *name;
    rp_surface_kind kind;
    uint32_t material;    /* index into rp_scene_materials */
    uint32_t first_face;  /* faces [first_face, first_face + nfaces) */
    uint32_t nfaces;
    double area;
    const char *file;     /* where the surface was declared */
    int line;
} rp_surface;

typedef struct rp_face {
    uint32_t v[4];    /* vertex indices, counter-clockwise seen from the front;
                         v[3] == RP_NONE for a triangle */
    uint32_t nverts;  /* 3 or 4 */
    uint32_t surface;
    rp_vec3 normal;   /* unit front normal: (v1 - v0) x (v3 - v0) for quads,
                         (v1 - v0) x (v2 - v0) for triangles */
    double area;
} rp_face;

typedef struct rp_camera {
    rp_vec3 eye, look, up;
    double fov_deg;         /* vertical field of view */
    uint32_t width, height; /* pixels */
} rp_camera;

/* Loads a scene file (format 1) or a Wavefront OBJ (with its MTL) when the
 * name ends in ".obj".  On failure returns RP_ERR_INPUT (bad scene) or
 * RP_ERR_RUNTIME/RP_ERR_NOMEM, with "FILE:LINE: what is wrong" in err.
 * What was read but not used (dropped faces, ignored MTL statements, ...)
 * is kept as warnings: rp_scene_warning. */
rp_status rp_scene_load(const char *path, rp_scene **out, rp_error *err);

/* Parses scene text held in memory; name is used in messages and relative
 * paths (include, mesh) resolve against dir (NULL: current directory). */
rp_status rp_scene_parse(const char *text, const char *name, const char *dir,
                         rp_scene **out, rp_error *err);

void rp_scene_destroy(rp_scene *scene);

rp_band_kind rp_scene_band_kind(const rp_scene *scene);
size_t rp_scene_nbands(const rp_scene *scene);
/* Wavelengths in nm for spectral scenes, NULL otherwise. */
const double *rp_scene_wavelengths(const rp_scene *scene);

size_t rp_scene_nmaterials(const rp_scene *scene);
const rp_material *rp_scene_materials(const rp_scene *scene);
size_t rp_scene_nsurfaces(const rp_scene *scene);
const rp_surface *rp_scene_surfaces(const rp_scene *scene);
size_t rp_scene_nfaces(const rp_scene *scene);
const rp_face *rp_scene_faces(const rp_scene *scene);
size_t rp_scene_nvertices(const rp_scene *scene);
const rp_vec3 *rp_scene_vertices(const rp_scene *scene);

/* The material of a face (shortcut through its surface). */
const rp_material *rp_scene_face_material(const rp_scene *scene, uint32_t face);

/* 1 if m emits and reflects nothing in any of its nb bands: an area light. */
int rp_material_pure_emitter(const rp_material *m, size_t nb);

/* NULL when the scene declares no camera. */
const rp_camera *rp_scene_camera(const rp_scene *scene);

/* Gives the scene a camera, or replaces its own (the camera is part of the
 * scene hash, so set it before hashing).  RP_ERR_INPUT if cam is not a
 * usable pinhole camera (eye = look, up parallel to the view, fov outside
 * (0, 180), size outside [1, 65536]). */
rp_status rp_scene_set_camera(rp_scene *scene, const rp_camera *cam, rp_error *err);

/* Parses camera words, the scene format's camera statement without (or
 * with) its keyword: "eye X Y Z look X Y Z up X Y Z fov F size W H", each
 * once, in any order.  what names the source in messages ("--camera:
 * camera lacks 'fov'").  Same code and checks as the `camera` statement. */
rp_status rp_camera_parse(const char *words, const char *what, rp_camera *out, rp_error *err);

/* Warnings found while reading, each "FILE:LINE: what" (what was dropped
 * or ignored, and where); i < rp_scene_nwarnings, NULL otherwise. */
size_t rp_scene_nwarnings(const rp_scene *scene);
const char *rp_scene_warning(const rp_scene *scene, size_t i);

/* Index of the surface with that name, or RP_NONE. */
uint32_t rp_scene_find_surface(const rp_scene *scene, const char *name);

/* Emitted power (flux) of a surface per band: pi * Le * area, W. */
void rp_scene_surface_power(const rp_scene *scene, uint32_t surface, double *power);

/* Total surface area. */
double rp_scene_total_area(const rp_scene *scene);

/* Axis-aligned bounds and the length of their diagonal (the scene scale). */
void rp_scene_bounds(const rp_scene *scene, rp_vec3 *lo, rp_vec3 *hi);
double rp_scene_diagonal(const rp_scene *scene);

/* A 64-bit FNV-1a hash of the scene's resolved content (bands, materials,
 * geometry, camera), as 16 hex digits plus NUL in out[17]. */
void rp_scene_hash(const rp_scene *scene, char out[17]);

/* 1 if the scene is closed (every edge shared by exactly two faces after
 * welding coincident vertices), 0 if open, -1 if it could not be decided. */
int rp_scene_is_closed(const rp_scene *scene);

/* A point on a face from barycentric-like coordinates: for triangles
 * p = v0 + u (v1 - v0) + v (v2 - v0); for quads the bilinear patch
 * p = (1-u)(1-v) v0 + u(1-v) v1 + uv v2 + (1-u)v v3. */
rp_vec3 rp_scene_face_point(const rp_scene *scene, uint32_t face, double u, double v);

/* New triangles for one surface (rp_scene_with_surfaces). */
typedef struct rp_surface_triangles {
    const double *xyz;     /* 3 * nvertices */
    size_t nvertices;
    const uint32_t *tri;   /* 3 * ntriangles, counter-clockwise from the front */
    size_t ntriangles;
} rp_surface_triangles;

/* A copy of scene (bands, materials, surfaces in the same order and with the
 * same names, camera, warnings) in which each surface k with replace[k] !=
 * NULL has those triangles for faces instead of its own (replace may be
 * NULL: a plain copy).  Triangles of no area are left out and counted in
 * *dropped (may be NULL).  The copy is what a solver solves on when it
 * models a surface more coarsely than the rays see it (geometry/simplify.h).
 * Fails only for lack of memory. */
rp_status rp_scene_with_surfaces(const rp_scene *scene, const rp_surface_triangles *const *replace,
                                 rp_scene **out, size_t *dropped, rp_error *err);

#ifdef __cplusplus
}
#endif

#endif
