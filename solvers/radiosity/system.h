/* The state shared by the classic radiosity solvers (jacobi, gauss-seidel,
 * southwell, direct): elements, materials, form factors and the current
 * solution of the discrete radiosity system (Cohen & Wallace 1993, eq. 3.8)
 *
 *     B_i = E_i + rho_i sum_j F_ij B_j,   E_i = pi Le_i,   per band,
 *
 * plus the plumbing every such solver needs: option parsing, the storage
 * decision for F (dense single-precision matrix or rows on the fly), the
 * checks that refuse a divergent system, residual norms, the stopping rule
 * and the answers in the common space (reconstruct.h).
 *
 * Not a public module: only solvers/radiosity/ (and its tests) include it.
 * Every classic solver's state struct begins with an rp_rad_system, so a
 * test holding the state can read the solution (tests/test_radiosity.c). */
#ifndef RP_RAD_SYSTEM_H
#define RP_RAD_SYSTEM_H

#include <stddef.h>
#include <stdint.h>

#include "../../geometry/discontinuity.h"
#include "../../geometry/mesh.h"
#include "../../geometry/raycast.h"
#include "../../geometry/scene.h"
#include "../solver.h"
#include "formfactor.h"
#include "reconstruct.h"

/* A dense matrix is kept when n^2 * sizeof(float) is below this (auto). */
#define RP_RAD_DENSE_CAP ((size_t)512 << 20)
/* Row sums of F above 1 + this are form-factor error (a row of a closed
 * scene sums to 1, of an open one to less): such a row is scaled to sum 1,
 * and the solver says so once.  The quadrature closes rows to a few 1e-5;
 * the visibility estimate, where elements of very unequal sizes meet, to
 * 1.1% at worst (a closed box whose walls are one element each around a
 * cube 1e-3 above the floor: tests/test_formfactor.c) and 3% at worst,
 * 0.3% on average, for CGAL's elephant (5,558 triangles) in such a box. */
#define RP_RAD_ROW_SUM_TOL 0.02
/* Per-element band arrays on the stack. */
#define RP_RAD_MAX_BANDS 256

typedef enum rp_rad_storage {
    RP_RAD_STORAGE_AUTO,  /* dense below RP_RAD_DENSE_CAP, rows above */
    RP_RAD_STORAGE_DENSE, /* the whole n x n matrix, float */
    RP_RAD_STORAGE_ROWS   /* rows recomputed whenever they are needed */
} rp_rad_storage;

/* What a solver allows of the common options. */
typedef struct rp_rad_config {
    const char *name;       /* method name, for messages */
    int storage_option;     /* the method reads --matrix */
    int reciprocity_option; /* the method reads --reciprocity */
    rp_rad_storage storage; /* forced storage when it does not */
    unsigned long default_max_iterations; /* 0: 100 x the element count */
    size_t row_bytes;       /* rows mode: memory for computed rows (0: a block
                               of 64; at least one row per thread) */
    size_t max_elements;    /* refuse meshes with more elements (0: no cap) */
    const char *max_elements_why; /* the reason, for the message */
} rp_rad_config;

typedef struct rp_rad_system {
    const char *name;
    const rp_scene *scene;
    size_t n, nb;
    /* The ranks the rows are split over (solvers/comm.h; NULL: alone).
     * Row i belongs to rank i mod K (rp_comm_owns), which alone computes
     * and stores it, as local row i / K of F: a dense F holds nloc rows
     * of n here, so memory per rank falls as 1/K and no rank ever holds
     * the whole matrix.  B, E, G and the per-element arrays are whole on
     * every rank; what a rank computes for its rows is combined with
     * rp_comm_sum, each element having one contributor, hence exactly. */
    const rp_comm *comm;
    size_t nloc;            /* rows this rank owns (n when alone) */
    int threads;            /* > 0 */
    unsigned want;
    int open_ended;
    rp_log_fn log;
    void *log_ctx;

    rp_mesh *mesh;
    rp_raycast *rc;         /* built with the mesh: hits name elements */
    rp_ff_context *ff;
    rp_ff_params ffp;
    rp_ff_scratch **scratch; /* one per thread */
    float *rowbuf;          /* rowbuf_rows rows of n, for rows on the fly */
    size_t rowbuf_rows;

    int reciprocity;        /* dense F from pairs i < j, mirrored */
    int dense;              /* F is stored */
    float *F;               /* nloc x n, row-major (rp_rad_local_row), when dense
                               and computed; n x n when alone */
    int matrix_ready;

    double *area;           /* n */
    double *rho;            /* n x nb */
    double *E;              /* n x nb: emitted exitance pi Le */
    double *B;              /* n x nb: the current iterate */
    double *G;              /* n x nb: scratch for F B */
    double e_norm[RP_RAD_MAX_BANDS];   /* sum_i A_i E_ib */
    double rho_max[RP_RAD_MAX_BANDS];  /* max_i rho_ib */
    double max_row_sum;     /* largest sum_j F_ij checked so far (dense: all rows),
                               before any scaling; all ranks' */
    double *row_sum;        /* n: sum_j F_ij of each row as computed, before scaling
                               (split: this rank's rows; all rows once the
                               dense matrix is done) */
    unsigned char *row_scaled; /* n: 1 if rp_rad_scale_row scaled the row (as row_sum) */
    size_t rows_scaled;     /* how many, once reported */
    int rows_reported;      /* rp_rad_report_scaled has run */
    const atomic_int *cancel;

    double tolerance;
    int tolerance_given;
    unsigned long max_iterations;
    int max_iterations_given;
    unsigned long iterations;
    double residual;        /* after the last step, -1 before */

    rp_recon_params recon;
    size_t bytes;           /* memory the solver holds (arrays, matrix, buffers) */
} rp_rad_system;

#define RP_RAD_STR_(x) #x
#define RP_RAD_STR(x) RP_RAD_STR_(x)

/* The mesh kind (mesh.h, rp_mesh_mode) and the discontinuity mesh's cap,
 * shared with stochastic-jacobi. */
#define RP_RAD_MESH_MODE_OPTIONS                                                             \
    {"mesh", "uniform|discontinuity",                                                        \
     "uniform: a regular grid per face; discontinuity: triangles (CGAL constrained Delaunay) " \
     "whose edges follow contact lines (D0), the outlines of faces hovering just over a face " \
     "(GAP: a lamp 1 cm below a ceiling) and the umbra/penumbra boundaries of area lights "   \
     "(D1: EV and VE wedges of silhouette edges, kept where a sampled visibility test finds " \
     "them real; Heckbert 1992, Lischinski et al. 1992), about as many elements as asked",   \
     "uniform"},                                                                             \
    {"mesh-segments", "N",                                                                   \
     "discontinuity mesh: D1 segments kept per face, the longest first (D0 and GAP all kept)", \
     RP_RAD_STR(RP_DISC_DEFAULT_MAX_PER_FACE)},                                \
    RP_SIMPLIFY_OPTION("off")

/* Option specs every classic solver takes; a method's spec array lists
 * these, then its own, then {NULL}. */
#define RP_RAD_MESH_OPTIONS                                                                  \
    {"elements", "N",                                                                        \
     "target element count for the whole scene: one per face black in every band, the rest " \
     "spread over the faces that reflect or emit (exclusive with --max-edge)",               \
     "the faces + 1000"},                                                                                \
    {"max-edge", "L", "target longest element edge in scene units (exclusive with --elements)", \
     NULL},                                                                                  \
    RP_RAD_MESH_MODE_OPTIONS,                                                                \
    {"ff", "analytic|montecarlo|hemicube",                                                   \
     "form factors: contour integral x ray visibility, area sampling, or hemicube",          \
     "analytic"},                                                                            \
    {"ff-samples", "N", "montecarlo form factors: point pairs per element pair", "256"},       \
    {"ff-rays", "N",                                                                         \
     "analytic form factors: visibility rays per element pair (default 4, 9 or 16, more for " \
     "closer pairs; none where nothing can block)",                                         \
     NULL},                                                                                  \
    {"hemicube-resolution", "R", "hemicube form factors: pixels along the top face (even)", "256"}, \
    {"ff-tolerance", "EPS", "analytic form factors: relative error goal per element pair",      \
     RP_RAD_STR(RP_FF_DEFAULT_TOLERANCE)},                                                  \
    RP_RAY_OFFSET_OPTION

#define RP_RAD_RECIPROCITY_OPTION                                                           \
    {"reciprocity", NULL,                                                                    \
     "kept for old scripts: analytic and montecarlo form factors are always computed once per " \
     "pair and mirrored, A_i F_ij = A_j F_ji; refused with the hemicube (whole rows)",        \
     NULL}

#define RP_RAD_SOLVE_OPTIONS                                                                  \
    {"tolerance", "EPS",                                                                     \
     "stop when the relative residual (power norm, worst band) falls to EPS", "1e-6"}

#define RP_RAD_IMAGE_OPTIONS                                                                 \
    {"reconstruct", "flat|gouraud|gather",                                                   \
     "image: element value, vertex-interpolated values, or a one-bounce final gather",      \
     "flat"},                                                                                \
    {"spp", "N", "image: camera rays per pixel (stratified, box filter)", "16"},            \
    {"gather-rays", "N", "image with --reconstruct gather: cosine-distributed rays per camera ray", \
     "16"}

/* 1 if this rank owns (computes and stores) row i. */
static inline int rp_rad_owns(const rp_rad_system *s, size_t i)
{
    return rp_comm_owns(s->comm, i);
}

/* The global index of this rank's local row l (l < nloc). */
static inline size_t rp_rad_global_row(const rp_rad_system *s, size_t l)
{
    return (size_t)rp_comm_rank(s->comm) + l * (size_t)rp_comm_size(s->comm);
}

/* Row i of the stored matrix (this rank must own it). */
static inline float *rp_rad_local_row(const rp_rad_system *s, size_t i)
{
    return s->F + i / (size_t)rp_comm_size(s->comm) * s->n;
}

/* 1 when the rows are split over more than one rank. */
static inline int rp_rad_split(const rp_rad_system *s)
{
    return rp_comm_size(s->comm) > 1;
}

/* Under a split: makes every rank return the same outcome of a
 * collective phase.  *stop (this rank was cancelled) becomes 1 on every
 * rank if it is on any; *bad (the first failing row this rank found,
 * LONG_MAX for none) becomes the first over all ranks.  Collective; a
 * no-op alone. */
void rp_rad_agree(const rp_rad_system *s, int *stop, long *bad);

/* Under a split: status and message of rank `root` to every rank
 * (collective); alone, st unchanged. */
rp_status rp_rad_share_error(const rp_rad_system *s, rp_status st, rp_error *err, int root);

/* The communicator in o (NULL when o is NULL or predates the field). */
const rp_comm *rp_rad_options_comm(const rp_options *o);

/* The end of a split method's init: every rank returns the status and
 * message of the lowest rank that failed (a rank short of memory would
 * otherwise leave the others waiting in the first step's collectives).
 * Collective over c; init must make no other collective before it. */
rp_status rp_rad_init_agree(const rp_comm *c, rp_status st, rp_error *err);

/* Parses the common options, meshes the scene, builds the ray caster and the
 * form-factor context and fills the material arrays.  B starts at E.  On
 * failure the caller calls rp_rad_system_fini (which accepts a partly built
 * system). */
/* The element-count options every uniform-mesh radiosity method takes,
 * --elements N or --max-edge L (not both), into mesh parameters; messages
 * name the method. */
rp_status rp_rad_mesh_params(const char *method, const rp_options *o, rp_mesh_params *mp,
                             rp_error *err);

/* --mesh-segments N, the D1 segments the discontinuity mesh keeps per face
 * (RP_DISC_DEFAULT_MAX_PER_FACE when not given), into *segs; ignored with a
 * warning (o->log) unless the method meshes by discontinuities (disc).  Shared with hierarchical's
 * --mesh discontinuity start mesh. */
rp_status rp_rad_mesh_segments(const char *method, const rp_options *o, int disc, unsigned long *segs,
                               rp_error *err);

rp_status rp_rad_system_init(rp_rad_system *s, const rp_rad_config *cfg, const rp_scene *scene,
                             const rp_options *o, rp_error *err);
void rp_rad_system_fini(rp_rad_system *s);

/* Computes and checks the dense matrix if the system stores one and it is
 * not there yet (in parallel over rows).  Adds form factors and rays cast to
 * info (this rank's, under a split).  Split over ranks it is collective:
 * each rank computes its share of the pairs and the ranks exchange the
 * mirrored halves (system.c, rad_fill_split). */
rp_status rp_rad_system_matrix(rp_rad_system *s, rp_step_info *info, rp_error *err);

/* Row i of F (owned by this rank): the stored row, or computed into buf (n floats) and scaled
 * as the stored rows are (rp_rad_scale_row; *raw_sum gets its sum before,
 * -1 for a stored row); adds the work to *ff and *rays when it computes.
 * A computed row is not checked: the caller passes it to rp_rad_check_row
 * (cheap beside computing it). */
const float *rp_rad_row(const rp_rad_system *s, uint32_t i, rp_ff_scratch *scratch, float *buf,
                        double *ff, double *rays);

/* Scales row i to sum 1 when its sum exceeds 1 + RP_RAD_ROW_SUM_TOL or it
 * would break the contraction rp_rad_check_row asks for (rho_i sum_j F_ij
 * or sum_j rho_j F_ij >= 1 in some band): form-factor error, not light.
 * Records the sum before (row_sum[i]) and whether it scaled (row_scaled[i]). */
void rp_rad_scale_row(const rp_rad_system *s, uint32_t i, float *row);

/* After a pass over every row (dense: the matrix; rows on the fly: the
 * first sweep): one warning through the log callback naming how many rows
 * were scaled and the worst, the first time there are any.  Under a split
 * the first call is collective (it counts every rank's rows). */
void rp_rad_report_scaled(rp_rad_system *s);

/* Refuses a row that would make the iteration diverge: RP_ERR_INPUT when
 * max_b rho_ib sum_j F_ij >= 1 (the Jacobi/Gauss-Seidel contraction in the
 * max norm) or max_b sum_j rho_jb F_ij >= 1 (the shooting contraction in
 * the power norm); RP_ERR_RUNTIME on a negative or non-finite entry.
 * *row_sum gets sum_j F_ij. */
rp_status rp_rad_check_row(const rp_rad_system *s, uint32_t i, const float *row, double *row_sum,
                           rp_error *err);

/* Y = F X (n x nb each), in parallel over rows; rows are computed (and
 * checked) on the fly when F is not stored.  Split over ranks, each rank
 * computes its rows and Y is summed over the ranks (exact: one rank per
 * row), so every rank gets the whole Y, the same as alone; collective. */
rp_status rp_rad_matvec(rp_rad_system *s, const double *X, double *Y, rp_step_info *info,
                        rp_error *err);

/* acc[b] = sum_{j < n} row[j] X[j, b] (X: nb values per element). */
static inline void rp_rad_dot(const float *row, const double *X, size_t n, size_t nb, double *acc)
{
    if (nb == 1) {
        double a = 0;
        for (size_t j = 0; j < n; j++)
            a += row[j] * X[j];
        acc[0] = a;
        return;
    }
    if (nb == 3) {
        double a0 = 0, a1 = 0, a2 = 0;
        for (size_t j = 0; j < n; j++) {
            double f = row[j];
            a0 += f * X[3 * j];
            a1 += f * X[3 * j + 1];
            a2 += f * X[3 * j + 2];
        }
        acc[0] = a0;
        acc[1] = a1;
        acc[2] = a2;
        return;
    }
    for (size_t b = 0; b < nb; b++)
        acc[b] = 0;
    for (size_t j = 0; j < n; j++) {
        double f = row[j];
        for (size_t b = 0; b < nb; b++)
            acc[b] += f * X[j * nb + b];
    }
}

/* Relative residual of X: max over bands of
 *   sum_i A_i |E_ib + rho_ib FX_ib - X_ib| / sum_i A_i E_ib
 * given FX = F X (bands with no emission count only if X is non-zero). */
double rp_rad_residual(const rp_rad_system *s, const double *X, const double *FX);

/* Ends a step: records the residual and sets info->residual, ->converged,
 * ->progress, ->iterations (adds one) and ->memory. */
void rp_rad_step_done(rp_rad_system *s, double residual, rp_step_info *info);

/* Answers from a solution Bd (n x nb, radiosity): surface averages and the
 * image, as the caller's estimate asks. */
rp_status rp_rad_estimate(const rp_rad_system *s, const double *Bd, rp_estimate *e, rp_error *err);

/* The number of threads to use. */
int rp_rad_threads(const rp_rad_system *s);

/* Sends a formatted message to the log callback, if any. */
void rp_rad_log(const rp_rad_system *s, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

#endif
