/* From an element radiosity solution to the common space (solver.h): the
 * area-averaged radiance of each surface, and a camera image.
 *
 * The image is filtered exactly as the path tracer's: spp camera rays
 * spread over each pixel (box filter, stratified jitter that depends only on
 * (seed, pixel, sample)), through the shared pinhole camera (camera.h).  A
 * ray that hits the front of a face sees outgoing radiance L = B / pi,
 * reconstructed one of three ways (Cohen & Wallace 1993, ch. 9):
 *
 *   flat     B of the element hit;
 *   gouraud  B at the element's corners (the area-weighted mean of the
 *            incident elements of the same surface and smoothing group,
 *            rp_recon_corners), interpolated with rp_mesh_element_weights;
 *   gather   one bounce of final gathering (rp_recon_final_gather): L = Le
 *            + rho/pi E(x), the irradiance from the emitters sampled
 *            directly and from cosine-distributed rays that see the flat B
 *            of the element they hit.
 *
 * Backs of faces and misses are black.  Every pixel's value is a pure
 * function of (seed, pixel), so images are identical for any thread count. */
#ifndef RP_RAD_RECONSTRUCT_H
#define RP_RAD_RECONSTRUCT_H

#include <stddef.h>
#include <stdint.h>

#include "../../geometry/mesh.h"
#include "../../geometry/raycast.h"
#include "../../geometry/sample.h"
#include "../../geometry/scene.h"
#include "../../geometry/simplify.h"
#include "../solver.h"

typedef enum rp_recon_mode {
    RP_RECON_FLAT,
    RP_RECON_GOURAUD,
    RP_RECON_GATHER
} rp_recon_mode;

/* --simplify (solver.h, geometry/simplify.h) for a finite-element method:
 * the solution lives on sol's scene, the camera and final gathers see
 * `scene`, the scene given, through rc.  Without it sol is NULL and rc is
 * the method's own raycaster. */
typedef struct rp_recon_view {
    struct rp_solution *sol;
    const rp_scene *scene;
    rp_raycast *rc;
} rp_recon_view;

/* Reads --simplify into v (v->scene = scene) and sets *solve to the scene
 * the method solves on: sol's, or scene itself when the option is off. */
rp_status rp_recon_view_init(rp_recon_view *v, const rp_options *o, const rp_scene *scene, const rp_scene **solve,
                             rp_error *err);
/* The camera's raycaster: the method's rc, or with --simplify one over the
 * full scene (with o's --ray-offset), owned by v; none when o->want asks
 * for no image. */
rp_status rp_recon_view_rays(rp_recon_view *v, const rp_options *o, rp_raycast *rc, rp_error *err);
/* RP_ERR_UNSUPPORTED when v has no camera raycaster (an image was not
 * wanted at init). */
rp_status rp_recon_view_check(const rp_recon_view *v, rp_error *err);
/* Releases what the two made (v zeroed or half made is fine). */
void rp_recon_view_fini(rp_recon_view *v);

typedef struct rp_recon_params {
    rp_recon_mode mode;
    unsigned spp;          /* camera rays per pixel, >= 1 */
    unsigned gather_rays;  /* gather: rays per camera ray, >= 1 */
    uint64_t seed;
    int threads;           /* > 0 */
    /* --simplify: when view.sol is set the image takes the solution at the
     * full mesh's vertices (flat or gouraud as asked, the gather's rays the
     * flat values) and interpolates it over the full faces. */
    rp_recon_view view;
} rp_recon_params;

/* Parses "flat" | "gouraud" | "gather". */
rp_status rp_recon_mode_parse(const char *name, rp_recon_mode *out, rp_error *err);
const char *rp_recon_mode_name(rp_recon_mode m);

/* Area-weighted mean of B / pi over each surface's elements:
 * out[surface * nb + b].  B is nelements x nb. */
void rp_recon_surfaces(const rp_scene *scene, const rp_mesh *mesh, size_t nb, const double *B,
                       double *out);

/* Faces of one surface are interpolated across their shared edges only
 * where their normals are within 30 degrees (a smoothing group: a curved
 * mesh stays smooth, a `box` room's floor and walls keep their own values
 * along their edges).  hier_image.c uses the same angle. */
#define RP_RECON_SMOOTH_COS 0.86602540378443865

/* Gouraud values at each element's corners (nelements x 4 x nb; unused
 * slots of triangles untouched): the area-weighted mean of B over the
 * elements incident to the corner's vertex (all on one surface, since
 * vertices are shared within a surface only) that lie in the element's
 * smoothing group there.  0 when out of memory. */
int rp_recon_corners(const rp_mesh *mesh, size_t nb, const double *B, double *out);

/* The camera loop shared by the finite-element methods: spp camera rays
 * per pixel (box filter, stratified jitter keyed by (seed, pixel)), each
 * hit shaded by the method's own rule.  shade fills L (nb) with the
 * radiance leaving h towards the camera (0 for backs); key seeds any random
 * numbers it draws (gather), xy (2 x samples) and perm (samples) are
 * scratch for rp_recon_strata, and *rays counts the rays it casts. */
typedef struct rp_recon_shader {
    void (*shade)(const void *ctx, const rp_hit *h, uint64_t key, double *xy, uint32_t *perm, double *L,
                  unsigned long long *rays);
    const void *ctx;
    unsigned samples; /* 2-D samples the shader draws per hit, >= 1 */
} rp_recon_shader;

/* Fills out (and variance, may be NULL) as rp_recon_image documents. */
rp_status rp_recon_camera(const rp_scene *scene, const rp_raycast *rc, unsigned spp, uint64_t seed,
                          int threads, size_t nb, const rp_recon_shader *shader, float *out,
                          float *variance, double *rays, rp_error *err);

/* The final gather (Reichert 1992) shared by the finite-element methods:
 *
 *     L(x) = Le + rho / pi (E_light + E_rest)
 *
 * E_rest from `rays` cosine-distributed rays, each seeing the solution's
 * radiosity where it lands, E = pi / G sum L = 1 / G sum B (pdf cos / pi);
 * E_light from as many points on the emitters (every face with Le > 0,
 * pure area lights and surfaces that emit and reflect alike), chosen by
 * power through `lights`, Le cos cos / (r^2 pdf) each, with a shadow ray.
 * A cosine ray that lands on an emitter counts its reflected part
 * B - pi Le in full (a pure emitter: 0), and its emitted part pi Le is
 * shared with the light samples by multiple importance sampling (power
 * heuristic, Veach 1997), so nothing is counted twice: direct light from a
 * small lamp is sampled where it is, and the 1/r^2 of light samples on a
 * large emitter next to x is left to the cosine rays.  Without `lights`
 * (NULL: rp_recon_lights found emission uniform over the whole scene, a
 * furnace) everything is gathered by the cosine rays, which is exact in a
 * closed uniform enclosure.  radiosity gives the method's B (nb values) at
 * the front-facing hit g. */
typedef struct rp_recon_gather {
    const rp_scene *scene;
    const rp_raycast *rc;
    const rp_area_sampler *lights; /* emitters by power (rp_recon_lights), NULL: none */
    unsigned rays;
    size_t nb;
    void (*radiosity)(const void *ctx, const rp_hit *g, double *B);
    const void *ctx;
} rp_recon_gather;

/* L (nb) at the front of hit h; xy (2 x rays) and perm (rays) are scratch,
 * key seeds the samples, *rays counts the rays cast. */
void rp_recon_final_gather(const rp_recon_gather *g, const rp_hit *h, uint64_t key, double *xy, uint32_t *perm,
                           double *L, unsigned long long *rays);

/* The light sampler for rp_recon_final_gather: every emitting face by
 * power.  *out is NULL when nothing emits, or when every face emits the
 * same Le (a furnace): then every cosine ray lands on the same emission,
 * which sampling it by area could only make noisier (the furnace's gather
 * image, Gauss-Seidel, 96 elements, 4 x 4 rays: RMSE 0 gathered, 0.036
 * with MIS light samples, 0.50 with light samples alone). */
rp_status rp_recon_lights(const rp_scene *scene, rp_area_sampler **out, rp_error *err);

/* Stratified positions of n samples in the unit square from key: a
 * jittered sqrt(n) x sqrt(n) grid when n is a square, otherwise n-rooks
 * (one sample per row and per column, columns permuted); perm has room for
 * n.  Both are unbiased for the box filter. */
void rp_recon_strata(uint64_t key, unsigned n, uint32_t *perm, double *xy);

/* The camera image, width x height x nb radiance (row-major from the
 * top-left, band fastest), into out; variance (may be NULL) gets the
 * variance of each pixel mean, estimated from its spp camera samples.  rc
 * must have been built with mesh.  *rays (may be NULL) gets the rays cast
 * added.  RP_ERR_INPUT without a camera, RP_ERR_NOMEM if scratch memory
 * runs out. */
rp_status rp_recon_image(const rp_scene *scene, const rp_mesh *mesh, const rp_raycast *rc,
                         const rp_recon_params *p, size_t nb, const double *B, float *out,
                         float *variance, double *rays, rp_error *err);

#endif
