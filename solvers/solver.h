/* The solver interface (docs/design.md, "The solver interface").
 *
 * A GSL-style type table: each method is one file exporting one const
 * rp_solver_type, and solvers/registry.c maps names to tables.  The harness
 * (bench/) owns clocks, files and references: it calls init, then step until
 * its budget runs out, and estimate at checkpoints.  Nothing here prints;
 * messages go through the optional log callback. */
#ifndef RP_SOLVER_H
#define RP_SOLVER_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#ifndef __cplusplus
#include <stdatomic.h>
#endif

#include "../geometry/scene.h"
#include "../geometry/status.h"
#include "comm.h"

#ifdef __cplusplus
extern "C" {
#endif

/* What the harness wants answered. */
enum {
    RP_WANT_IMAGE = 1u << 0,    /* radiance per pixel through the camera */
    RP_WANT_SURFACES = 1u << 1  /* area-averaged radiance per surface */
};

/* A method option: the command line's "--name value" (flags: value "1"). */
typedef struct rp_option_spec {
    const char *name;     /* without dashes: "spp", "sampler", "max-depth" */
    const char *arg;      /* "N", "random|stratified|sobol", NULL for a flag */
    const char *help;     /* one line, shown by --help */
    const char *fallback; /* default value as text, NULL if none */
} rp_option_spec;

typedef void (*rp_log_fn)(void *ctx, const char *message);

/* The cancel flag is a C11 atomic_int; C++ before C++23 has no
 * <stdatomic.h>, so there it is opaque: test it with rp_options_cancelled. */
#ifdef __cplusplus
#define RP_CANCEL_FLAG void
#else
#define RP_CANCEL_FLAG atomic_int
#endif

typedef struct rp_options {
    size_t size;          /* sizeof(rp_options), so the struct can grow */
    unsigned want;        /* RP_WANT_* bits */
    uint64_t seed;
    int threads;          /* 0: OpenMP's default */
    /* Method options by name, as given (validated by the method's init). */
    const char *const *keys;
    const char *const *values;
    size_t count;
    /* Set when the harness stops the run by its own budget (--time): the
     * method then stops by its own rule only when that rule's option was
     * given explicitly, not by its default. */
    int open_ended;
    rp_log_fn log;        /* may be NULL */
    void *log_ctx;
    /* Cancellation (may be NULL): set non-zero by the caller (a signal
     * handler: a lock-free atomic may be written there, C11 7.14.1.1) to
     * stop a run.  Methods poll it in their long loops, in init as in
     * step (per row, per shot, per block: within a second or so), and
     * return RP_ERR_INTERRUPTED when they stop for it; the state is then
     * only good for fini. */
    const RP_CANCEL_FLAG *cancel;
    /* The method's option specs, set by rp_solver_create (a caller of a
     * type's init must set them as it does): an option absent
     * from keys takes its spec's `fallback` in rp_options_double and
     * rp_options_uint, so a default is written once, in the spec that
     * --help shows.  NULL: no fallbacks. */
    const rp_option_spec *specs;
    /* The ranks to split the work over (solvers/comm.h), or NULL: alone.
     * rp_solver_create hands it on only to a type that declares
     * `distributed`; the others see NULL. */
    const rp_comm *comm;
} rp_options;

#ifndef __cplusplus
/* 1 once cancellation has been asked for (cancel may be NULL). */
static inline int rp_cancelled(const atomic_int *cancel)
{
    return cancel && atomic_load_explicit(cancel, memory_order_relaxed) != 0;
}
#endif
/* The same for a method's options, from C or C++ (o may be NULL). */
int rp_options_cancelled(const rp_options *o);
/* 1 when o says what the run wants and an image is not part of it (0 for
 * o NULL or want 0: nothing said, so an image may be asked for). */
int rp_options_image_unwanted(const rp_options *o);

/* Work done by one step (added up by the harness). */
typedef struct rp_step_info {
    double rays;          /* rays cast */
    double paths;         /* camera or probe paths traced */
    double form_factors;  /* form factors computed */
    double iterations;    /* sweeps, shots or sample passes completed */
    double residual;      /* relative residual after the step, or -1 */
    double tolerance;     /* the residual the method's rule aims for, or -1
                             (none): a run stopped before residual <=
                             tolerance has not converged, whatever stopped
                             it (--time, an iteration cap, a signal) */
    double unshot;        /* unshot power fraction, or -1 */
    int converged;        /* the method's own stopping rule is met (its
                             tolerance, or its iteration cap: see tolerance) */
    double progress;      /* fraction of the way to that rule, in [0, 1] */
    double memory;        /* bytes the method holds after the step (matrices,
                             buffers), 0 if not reported */
} rp_step_info;

/* Answers in the common space: radiance, W sr^-1 m^-2, per band.  The
 * harness allocates; the solver fills what is non-NULL. */
typedef struct rp_estimate {
    /* Camera image, width * height * nbands, row-major from the top-left,
     * band fastest. */
    float *radiance;
    float *variance;         /* variance of the pixel mean, NULL if not wanted */
    /* Per surface, nsurfaces * nbands: area-averaged outgoing radiance and
     * (Monte Carlo methods) its standard error, 0 for deterministic ones. */
    double *surface_radiance;
    double *surface_stderr;
    double samples;          /* samples per pixel / per surface, or sweeps */
} rp_estimate;

typedef struct rp_solver_type {
    const char *name;
    const char *summary;          /* one line for --help */
    const rp_option_spec *options; /* terminated by a {NULL} entry */
    size_t state_size;
    rp_status (*init)(void *state, const rp_scene *scene, const rp_options *options,
                      rp_error *err);
    rp_status (*step)(void *state, rp_step_info *info, rp_error *err);
    rp_status (*estimate)(const void *state, rp_estimate *estimate, rp_error *err);
    void (*fini)(void *state);
    /* What one iteration is, plural, for messages ("sweeps", "shots");
     * NULL: "iterations". */
    const char *iteration_name;
    /* Optional (NULL: the method cannot be checkpointed).  save writes the
     * state accumulated so far to f as the method's own little-endian
     * fields; load reads them back into a state fresh from init with the
     * same scene and options (RP_ERR_INPUT, naming what differs, when they
     * do not match, or when f is truncated), and reports in info what a
     * step would: converged, progress and iterations so far.  Neither
     * opens, names or closes f: bench/ owns files.  Call them through
     * rp_solver_save / rp_solver_load, which frame and checksum the fields. */
    rp_status (*save)(const void *state, FILE *f, rp_error *err);
    rp_status (*load)(void *state, FILE *f, rp_step_info *info, rp_error *err);
    /* What the harness needs to know of a method, declared here rather than
     * guessed from its name.  monte_carlo: its answers are random (benches
     * run it with several seeds; it reports standard errors).  samples_name:
     * what rp_estimate.samples counts, for tables and chart axes ("samples
     * per pixel", "sweeps"); NULL: iteration_name.  surfaces_cost: answering
     * for surface averages costs it extra work (the path tracer's probe
     * paths), so the harness asks for them only when needed. */
    int monte_carlo;
    const char *samples_name;
    int surfaces_cost;
    /* distributed: given rp_options.comm, the method splits its work over
     * the ranks by global index and every rank's step, estimate and save
     * are collective, with answers identical for any rank count (see
     * comm.h).  Types without it run on one rank. */
    int distributed;
} rp_solver_type;

/* What one sample of the type counts, plural ("samples per pixel"). */
const char *rp_solver_samples_name(const rp_solver_type *type);

/* A solver instance: its type and its state. */
typedef struct rp_solver rp_solver;

const rp_solver_type *rp_solver_lookup(const char *name);
/* NULL-terminated list of every registered type: the built-in ones, then
 * those registered at run time. */
const rp_solver_type *const *rp_solver_types(void);
/* Adds a method (a plugin's, solvers/plugin.h); its name must be new and
 * of a-z, 0-9, '-', '_'.  Not thread-safe: register before running. */
rp_status rp_solver_register(const rp_solver_type *type, rp_error *err);

rp_status rp_solver_create(const rp_solver_type *type, const rp_scene *scene,
                           const rp_options *options, rp_solver **out, rp_error *err);
rp_status rp_solver_step(rp_solver *s, rp_step_info *info, rp_error *err);
rp_status rp_solver_estimate(const rp_solver *s, rp_estimate *estimate, rp_error *err);
const rp_solver_type *rp_solver_type_of(const rp_solver *s);

/* The communicator the solver splits its work over, NULL when alone. */
const rp_comm *rp_solver_comm(const rp_solver *s);
/* The method's state, for method-specific queries such as
 * rp_hierarchical_stats (solvers/radiosity/hierarchical.h). */
const void *rp_solver_state(const rp_solver *s);
void rp_solver_destroy(rp_solver *s);

/* Checkpoint and resume (optional per method, see save / load above).
 * rp_solver_save appends one record to f: magic "RPSTATE1", the method's
 * name, the length of the method's fields, the fields, and their 64-bit
 * FNV-1a checksum, all little-endian.  rp_solver_load reads one record
 * back into s, which must be fresh from rp_solver_create; a record of
 * another method, a bad checksum or a short file is RP_ERR_INPUT.  Both are
 * RP_ERR_UNSUPPORTED for a method without save / load.  After a failed load
 * the solver's state is undefined: destroy it. */
int rp_solver_can_checkpoint(const rp_solver_type *type);
rp_status rp_solver_save(const rp_solver *s, FILE *f, rp_error *err);
rp_status rp_solver_load(rp_solver *s, FILE *f, rp_step_info *info, rp_error *err);

/* Little-endian field helpers for methods' save / load: n values each;
 * they return -1 on a write error or a short read, else 0. */
int rp_solver_put_u64(FILE *f, const uint64_t *v, size_t n);
int rp_solver_put_f64(FILE *f, const double *v, size_t n);
int rp_solver_get_u64(FILE *f, uint64_t *v, size_t n);
int rp_solver_get_f64(FILE *f, double *v, size_t n);

/* Option look-up for methods: the value given for name, or NULL. */
const char *rp_options_get(const rp_options *o, const char *name);
/* A word option's value as given, else its spec's fallback (when the
 * options carry the specs), else NULL. */
const char *rp_options_word(const rp_options *o, const char *name);

/* Parses a numeric option into *out; absent, its spec's fallback (when the
 * options carry the specs and the fallback is a number), else *out is left
 * alone.  A malformed or out-of-range value is RP_ERR_INPUT with a message
 * naming the option. */
rp_status rp_options_double(const rp_options *o, const char *name, double lo, double hi,
                            double *out, rp_error *err);
rp_status rp_options_uint(const rp_options *o, const char *name, unsigned long lo,
                          unsigned long hi, unsigned long *out, rp_error *err);
/* RP_ERR_INPUT if an option is not in the type's spec list. */
rp_status rp_options_check(const rp_options *o, const rp_solver_type *type, rp_error *err);

/* --ray-offset EPS: the self-intersection offset of rays leaving a surface,
 * relative to the largest coordinate of the point they leave, measured from
 * the centre of the lit part of the scene (geometry/raycast.h); methods that
 * cast rays list it and apply it to their raycaster.  Absent, the raycaster
 * keeps its default (bit-identical to not having the option). */
#define RP_RAY_OFFSET_OPTION                                                                 \
    {"ray-offset", "EPS",                                                                    \
     "rays leaving a surface point p start EPS x |p - c|_inf off the surface (c: the centre of " \
     "the faces that reflect or emit; 1e-5 is about 170 float ulps of p); hits on faces whose " \
     "plane holds p are rejected at any EPS (0: no offset; for experiments on leaks)",      \
     "1e-5"}
struct rp_raycast;
rp_status rp_options_ray_offset(const rp_options *o, struct rp_raycast *rc, rp_error *err);

/* --simplify off|auto|R: the finite-element methods may solve on a simplified
 * copy of the scene's dense triangle meshes while camera rays and final
 * gathers see the full ones (geometry/simplify.h).  rp_options_simplify
 * reads the option: *out is NULL when it is off, else the
 * solution mesh to solve on (rp_solution_scene), which the caller destroys
 * with rp_solution_destroy.  Messages (what each mesh became) go to
 * o->log.  When o->want asks for no image, the solution has no maps back
 * to the full scene (rp_solution_drop_maps).  Where it is expanded,
 * geometry/simplify.h must be included (its constants name the numbers). */
#define RP_SIMPLIFY_OPTION(fallback)                                                         \
    {"simplify", "off|auto|R",                                                                \
     "solve on a simplified copy of each triangle mesh of " RP_SIMPLIFY_TEXT(RP_SIMPLIFY_MIN_FACES) \
     " triangles or more (CGAL edge collapse, Garland-Heckbert quadrics; borders kept; cut where " \
     "it is not a 2-manifold): auto collapses while the quadric error times the mean triangle "   \
     "area stays below (" RP_SIMPLIFY_TEXT(RP_SIMPLIFY_AUTO_TOLERANCE) " x the scene's "           \
     "diagonal)^4, whatever the tessellation; R in (0,1) keeps that fraction of the "             \
     "edges; camera rays and final gathers still see the full meshes",                       \
     fallback}
struct rp_solution;
rp_status rp_options_simplify(const rp_options *o, const rp_scene *scene, struct rp_solution **out,
                              rp_error *err);

#ifdef __cplusplus
}
#endif

#endif
