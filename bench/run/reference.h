/* References: the converged answer a run is scored against (docs/design.md,
 * "Ground truth").
 *
 * Two kinds:
 *   exact     - the scene has a closed form.  The furnace (data/
 *               docs/ground-truth.md): a closed enclosure, seen from inside,
 *               whose surfaces all share one reflectance rho and one
 *               emitted radiance Le, has L = Le / (1 - rho) everywhere.
 *               Detected from the scene itself (closedness, orientation,
 *               materials), never from its file name.
 *   pathtrace - otherwise a long path-traced render (independent random
 *               numbers, a fixed seed that no benchmark run uses) with its
 *               per-pixel variance, and surface averages with standard
 *               errors.
 *
 * Either kind is cached on disk as CACHE/<scenehash>-<optionshash>.exr
 * (radiance and variance channels; everything needed to reuse it in the
 * header) plus a .json with the parameters and the surface averages for
 * people and other tools.  A cached file is reused only when its stored key
 * (the scene hash and the canonical option text) matches.
 *
 * Pixels measured ("the mask"): those fully covered by front faces of
 * surfaces that reflect light; pixels that see a pure emitter (Le > 0,
 * rho = 0 in every band: its radiance is Le for every method), the
 * background or a back face in any of 4 x 4 sub-pixel rays are left out.
 * A surface that emits and reflects is measured: what it reflects differs
 * between methods.  Surfaces measured: every surface that is not a pure
 * emitter. */
#ifndef RP_REFERENCE_H
#define RP_REFERENCE_H

#include <signal.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "geometry/scene.h"
#include "geometry/status.h"
#include "solvers/solver.h"

typedef enum rp_reference_kind {
    RP_REFERENCE_EXACT,
    RP_REFERENCE_PATHTRACE
} rp_reference_kind;

/* Progress of a long reference render, fraction in [0, 1]. */
typedef void (*rp_progress_fn)(void *ctx, double fraction, const char *detail);

typedef struct rp_reference_params {
    size_t size;               /* sizeof(rp_reference_params) */
    unsigned long spp;         /* image samples per pixel (0: RP_REFERENCE_DEFAULT_SPP) */
    unsigned long samples;     /* probe points per surface (0: 256 x spp) */
    uint64_t seed;             /* 0: RP_REFERENCE_SEED */
    int threads;               /* 0: OpenMP's default */
    const char *cache_dir;     /* NULL: "refs" */
    int force;                 /* recompute even when cached */
    rp_log_fn log;             /* "using cached reference ...", may be NULL */
    void *log_ctx;
    rp_progress_fn progress;   /* may be NULL */
    void *progress_ctx;
    /* Checkpointing a long path-traced reference (resume.h; not used for an
     * exact or a cached one).  checkpoint: a file the render's state is
     * written to every checkpoint_every seconds (0: after every step), at
     * the end, and when *stop turns non-zero, which ends the render with
     * RP_ERR_RUNTIME.  resume: a checkpoint of the same scene and key to
     * continue from.  Each may be NULL. */
    const char *checkpoint;
    double checkpoint_every;
    const char *resume;
    volatile sig_atomic_t *stop;
    /* Cancellation of a render being made (may be NULL): passed to the
     * path tracer (rp_options.cancel) and checked between its steps; the
     * reference is then not written and the call returns
     * RP_ERR_INTERRUPTED. */
    const atomic_int *cancel;
} rp_reference_params;

/* The reference seed: far from the seeds benchmarks use (1, 2, 3, ...). */
#define RP_REFERENCE_SEED UINT64_C(0x7e7e7e7e)
#define RP_REFERENCE_DEFAULT_SPP 2048

/* The reference's sampler: independent random numbers, whose variance
 * estimate (sample variance / N) is unbiased, so the error of a run
 * against the truth can be estimated through the reference (metrics.h,
 * rp_metrics_debiased_image).  Owen-scrambled Sobol' points would give a
 * less noisy image at equal samples (2.4x lower variance measured on the
 * Cornell box at 128 spp), but their sample variance overestimates the
 * error by as much, which would bias every debiased error low. */
#define RP_REFERENCE_SAMPLER "random"

typedef struct rp_reference {
    rp_reference_kind kind;
    char scene_hash[17];
    char options_hash[17];
    char key[256];             /* canonical option text, stored in the file */
    uint32_t width, height;    /* 0 when the scene has no camera */
    size_t nbands, nsurfaces;
    float *radiance;           /* width * height * nbands, NULL without camera */
    float *variance;           /* per value, variance of the pixel mean;
                                  NULL for an exact reference */
    unsigned char *mask;       /* width * height: 1 = measured pixel */
    size_t mask_count;
    double *surface_radiance;  /* nsurfaces * nbands */
    double *surface_stderr;    /* nsurfaces * nbands (0 when exact) */
    unsigned char *surface_mask; /* nsurfaces: 1 = measured surface */
    double rmse_se;            /* standard error of an RMSE measured against
                                  it: sqrt(mean variance) over the mask */
    double surface_rel_se;     /* RMS of stderr / value over measured surfaces */
    double exact_L[64];        /* exact: Le / (1 - rho) per band (first 64) */
    unsigned long spp, samples;
    uint64_t seed;
    double seconds;            /* time the render took when it was made */
    int cached;                /* 1: read from the cache */
    char exr_path[1024], json_path[1024];
} rp_reference;

/* 1 if the furnace closed form applies, with L[b] = Le_b / (1 - rho_b)
 * (L has room for nbands values); 0 if not; -1 with err set on failure;
 * -2 with err set when the scene is a furnace that reflects everything
 * (rho = 1 in some band), whose L is infinite or undetermined (bad input). */
int rp_reference_furnace(const rp_scene *scene, double *L, rp_error *err);

/* The pixel mask described above (mask: width * height); *count gets the
 * number of pixels in it. */
rp_status rp_reference_pixel_mask(const rp_scene *scene, unsigned char *mask, size_t *count,
                                  rp_error *err);

/* The canonical key text and its hash for a scene and parameters, without
 * computing anything (the cache file is CACHE/<scene_hash>-<options_hash>). */
rp_status rp_reference_key(const rp_scene *scene, const rp_reference_params *params, char *key,
                           size_t keylen, char options_hash[17], rp_error *err);

/* Gets the reference: from the cache when a matching file is there
 * (ref->cached = 1, logged as "using cached reference PATH ..."),
 * otherwise computes it and writes the cache files atomically. */
rp_status rp_reference_get(const rp_scene *scene, const char *scene_name,
                           const rp_reference_params *params, rp_reference **out, rp_error *err);
void rp_reference_destroy(rp_reference *ref);

/* A 64-bit FNV-1a hash of a string, as 16 hex digits. */
void rp_hash_text(const char *text, char out[17]);

#endif
