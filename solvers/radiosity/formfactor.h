/* Element-to-element form factors with visibility (Cohen & Wallace 1993,
 * ch. 4), three ways:
 *   analytic   - Lambert's differential-area-to-polygon contour integral
 *                (Baum, Rushmeier & Winget 1989) integrated over the receiver
 *                by Gauss quadrature, times a visibility fraction from rays;
 *   montecarlo - uniform area sampling of both elements, with a standard
 *                error;
 *   hemicube   - Cohen & Greenberg 1985, rasterised on the CPU.
 *
 *   F_ij = 1/A_i int_Ai int_Aj cos(ti) cos(tj) V / (pi r^2) dAj dAi.
 *
 * A context is built once and shared read-only by threads; every call that
 * computes takes a caller-owned scratch workspace (one per thread). */
#ifndef RP_FORMFACTOR_H
#define RP_FORMFACTOR_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "../../geometry/mesh.h"
#include "../../geometry/raycast.h"
#include "../../geometry/scene.h"

typedef enum rp_ff_method {
    RP_FF_ANALYTIC,
    RP_FF_MONTECARLO,
    RP_FF_HEMICUBE
} rp_ff_method;

typedef struct rp_ff_params {
    size_t size;              /* sizeof(rp_ff_params) */
    rp_ff_method method;
    unsigned samples;         /* montecarlo: point pairs per element pair */
    unsigned resolution;      /* hemicube: pixels along the top face */
    unsigned visibility_rays; /* analytic: rays for the visibility fraction */
    uint64_t seed;
    double tolerance;         /* analytic: error goal per pair, relative to
                                 max(F_ij, min(1, A_j / (pi d_ij^2)))
                                 (0: RP_FF_DEFAULT_TOLERANCE) */
    /* Cancellation (rp_options.cancel; may be NULL): once set, rp_ff_row
     * stops within a few pairs and leaves the rest of the row 0; the
     * caller, polling the same flag, discards it. */
    const atomic_int *cancel;
} rp_ff_params;

#define RP_FF_DEFAULT_TOLERANCE 1e-5

/* Parses "analytic" | "montecarlo" | "hemicube". */
rp_status rp_ff_method_parse(const char *name, rp_ff_method *out, rp_error *err);
const char *rp_ff_method_name(rp_ff_method m);

typedef struct rp_ff_context rp_ff_context;
typedef struct rp_ff_scratch rp_ff_scratch;

/* rc may be NULL: then every pair is taken as fully visible. */
rp_status rp_ff_context_create(const rp_scene *scene, const rp_mesh *mesh, const rp_raycast *rc,
                               const rp_ff_params *params, rp_ff_context **out, rp_error *err);
void rp_ff_context_destroy(rp_ff_context *ctx);
/* The parameters in use, defaults filled in (samples, resolution,
 * tolerance). */
void rp_ff_context_params(const rp_ff_context *ctx, rp_ff_params *out);

rp_status rp_ff_scratch_create(const rp_ff_context *ctx, rp_ff_scratch **out, rp_error *err);
void rp_ff_scratch_destroy(rp_ff_scratch *s);

/* Form factors from element i to every element: row[j], j < nelements
 * (cut short by params.cancel).
 * Deterministic for a given (params.seed, i).  *rays (may be NULL) gets the
 * visibility rays cast added to it (analytic: a pair's visibility is cast
 * once and shared, so the count, not the row, depends on which rows ran
 * before). */
void rp_ff_row(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, float *row, double *rays);

/* Analytic and Monte Carlo form factors come in reciprocal pairs: of F_ij
 * and F_ji one is computed (the primary) and the other follows from
 * A_i F_ij = A_j F_ji, so rp_ff_row, rp_ff_pair and rp_ff_pair_both give
 * the same value for a pair whichever side asks, and a full matrix costs
 * half the pairs.  The analytic primary is the pair seen from its smaller
 * element (the smaller bounding radius; ties: the lower index): its
 * integral over the receiver is the cheaper and the more accurate one.
 * Monte Carlo's is i < j.  rp_ff_reciprocal is 0 for the hemicube, whose
 * rows are computed whole. */
int rp_ff_reciprocal(const rp_ff_context *ctx);
int rp_ff_primary(const rp_ff_context *ctx, uint32_t i, uint32_t j);
/* F_ji from the primary F_ij, as rp_ff_pair(j, i) gives it. */
double rp_ff_mirror(const rp_ff_context *ctx, uint32_t i, uint32_t j, double fij);
/* F_ij and F_ji, the pair's one computation (both by rows for the
 * hemicube). */
void rp_ff_pair_both(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, uint32_t j,
                     double *fij, double *fji, double *rays);

/* One pair; *stderr_out (may be NULL) gets the Monte Carlo standard error
 * (0 for the deterministic methods).  Hemicube computes the whole row. */
double rp_ff_pair(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, uint32_t j,
                  double *stderr_out, double *rays);

#endif
