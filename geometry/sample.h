/* Uniform area sampling of surfaces and emitters.  A discrete choice among
 * faces by weight (area, or emitted power) uses GSL's Walker alias table
 * (gsl_ran_discrete_preproc); the choice is driven by a caller-supplied
 * uniform number so samplers (random, stratified, Sobol') can feed it. */
#ifndef RP_SAMPLE_H
#define RP_SAMPLE_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_area_sampler rp_area_sampler;

typedef enum rp_area_weight {
    RP_WEIGHT_AREA,   /* faces in proportion to area */
    RP_WEIGHT_POWER   /* emitting faces in proportion to emitted power
                         (area times the band-mean of Le) */
} rp_area_weight;

typedef struct rp_area_sample {
    rp_vec3 p;
    rp_vec3 n;        /* the face's unit front normal */
    uint32_t face;
    uint32_t surface;
    double pdf_area;  /* density with respect to area, 1/m^2 */
} rp_area_sample;

/* Over all faces of the scene (surface == RP_NONE) or of one surface. */
rp_status rp_area_sampler_create(const rp_scene *scene, uint32_t surface, rp_area_weight weight,
                                 rp_area_sampler **out, rp_error *err);
void rp_area_sampler_destroy(rp_area_sampler *s);

/* Number of faces with non-zero weight (0: nothing to sample). */
size_t rp_area_sampler_count(const rp_area_sampler *s);

/* u0 chooses the face, (u1, u2) the point uniformly on it; all in [0, 1). */
void rp_area_sampler_sample(const rp_area_sampler *s, double u0, double u1, double u2,
                            rp_area_sample *out);

/* The area density with which the sampler picks a point on face f. */
double rp_area_sampler_pdf(const rp_area_sampler *s, uint32_t face);

/* A uniform point on one face from (u1, u2) in [0, 1)^2. */
rp_vec3 rp_face_sample_uniform(const rp_scene *scene, uint32_t face, double u1, double u2);

#ifdef __cplusplus
}
#endif

#endif
