/* The benchmark harness: runs solvers through the solver interface with
 * checkpoints spaced geometrically in time and scores every checkpoint
 * against a reference (docs/design.md, "The solver interface": the harness alone
 * owns clocks and references).
 *
 * Clocks: a run's solver time is the wall time spent in rp_solver_create
 * and rp_solver_step only; estimates and error metrics run with the clock
 * stopped.  CPU time (CLOCK_PROCESS_CPUTIME_ID, all threads) is added up
 * over the same intervals.  Checkpoint k is taken at the first step
 * boundary where solver time >= budget * 2^-k (k = levels - 1 .. 0); when
 * one step passes several thresholds only the last of them is recorded.  A
 * run that ends early (the method's own rule, see harness params) records
 * its end as a final row carrying the next k.
 *
 * Memory: before each run the peak resident set is reset (Linux
 * /proc/self/clear_refs, "5") so VmHWM is that run's peak; where that is
 * not possible getrusage's ru_maxrss (the process's lifetime peak) is
 * reported instead.  The solver's own count (rp_step_info.memory) is
 * recorded beside it. */
#ifndef RP_HARNESS_H
#define RP_HARNESS_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "geometry/scene.h"
#include "solvers/solver.h"
#include "bench/run/clock.h"
#include "bench/run/driver.h"
#include "bench/run/journal.h"
#include "bench/run/metrics.h"
#include "bench/run/reference.h"

#define RP_SPEC_MAX_OPTIONS 32

/* "southwell:elements=4000:ambient": a method and its options (an option
 * without "=" is a flag, value "1"). */
typedef struct rp_method_spec {
    char text[256];
    char name[64];
    const rp_solver_type *type;
    size_t count;
    const char *keys[RP_SPEC_MAX_OPTIONS];
    const char *values[RP_SPEC_MAX_OPTIONS];
    char buf[256];  /* storage for keys and values */
} rp_method_spec;

/* Parses one spec and checks the method and its option names
 * (RP_ERR_INPUT with a message otherwise). */
rp_status rp_method_spec_parse(const char *text, rp_method_spec *out, rp_error *err);
/* A comma-separated list; *out is malloc'd. */
rp_status rp_method_list_parse(const char *list, rp_method_spec **out, size_t *n, rp_error *err);
/* The value a spec gives an option, or NULL. */
const char *rp_method_spec_get(const rp_method_spec *m, const char *key);
/* Monte Carlo methods (the type's monte_carlo: pathtrace,
 * stochastic-jacobi) run with several seeds. */
int rp_method_is_monte_carlo(const rp_method_spec *m);

/* One row of runs.csv. */
typedef struct rp_checkpoint {
    int index;            /* k: scheduled at budget * 2^-k */
    double target;        /* budget * 2^-k (seconds, or iterations) */
    double wall_s, cpu_s; /* solver time so far */
    double steps, rays, paths, iterations, form_factors;
    double samples;       /* rp_estimate.samples: spp, sweeps or shots */
    double residual, unshot;
    double peak_rss_mb, solver_mb;
    double rmse, relmse, mae, surface_err;
    /* sqrt of the debiased MSE (metrics.h, rp_metrics_debiased_image),
     * NaN (not resolved) where that is not positive.  The reference r is
     * independent of the run, so E[(x - r)^2] = E[(x - L)^2] + E[(r - L)^2]
     * against the truth L: rmse overestimates the error against L by the
     * reference's own error, and subtracting the reference's estimated
     * variance (unbiased: its samples are independent, reference.h)
     * removes it. */
    double rmse_debiased;
    double measure_s;     /* time the estimate and metrics took (not counted) */
    int ref_flag;         /* the reference does not resolve this error (rp_metrics_resolved) */
    int converged, final;
} rp_checkpoint;


typedef struct rp_harness_params {
    size_t size;            /* sizeof(rp_harness_params) */
    double budget;          /* seconds (or iterations) */
    unsigned levels;        /* checkpoints per run (0: 9, i.e. k = 8 .. 0) */
    rp_schedule schedule;
    int threads;
    int surfaces_for_mc;    /* ask Monte Carlo methods for surface averages
                               too (they cost them extra paths) */
    int stop_when_converged;/* end a run when the method's rule is met */
    int keep_image;         /* keep the final image in the run */
    rp_progress_fn progress;
    void *progress_ctx;
    /* Set (by a signal handler) to stop: passed to the solver
     * (rp_options.cancel) and checked at every step boundary; the run then
     * ends with status RP_ERR_INTERRUPTED and its rows so far.  May be
     * NULL. */
    const atomic_int *cancel;
} rp_harness_params;

/* One method with one seed. */
typedef struct rp_trial {
    size_t method;          /* index into the bench's methods */
    uint64_t seed;
    rp_checkpoint *cp;
    size_t ncp;
    float *image;           /* final image (keep_image), npix * nbands */
    double *surfaces;       /* final surface averages, nsurfaces * nbands */
    rp_status status;       /* RP_OK, or why the run stopped */
    char error[1024];
    int rank, threads;      /* the MPI rank (0 alone) and threads it ran on */
} rp_trial;

/* Runs one method with one seed against ref (which gives the mask and the
 * scores).  Returns RP_OK even when the run failed: run->status and
 * run->error say so, and the rows before the failure stay. */
rp_status rp_harness_run(const rp_scene *scene, const rp_reference *ref, const rp_method_spec *m,
                         uint64_t seed, const rp_harness_params *params, rp_trial *run, rp_error *err);
void rp_trial_free(rp_trial *run);

/* Mean over the seeds of one checkpoint (or of the final rows). */
typedef struct rp_agg {
    int index;
    size_t n;               /* rows averaged */
    double wall_s, wall_sd, cpu_s, work, samples, iterations, rays, form_factors;
    double peak_rss_mb;
    double rmse, rmse_sd, relmse, relmse_sd, mae, mae_sd, surface_err, surface_err_sd;
    double rmse_debiased, rmse_debiased_sd;
    int ref_flag;           /* any row flagged */
} rp_agg;

typedef struct rp_method_summary {
    rp_agg *pts;            /* by increasing time (decreasing k) */
    size_t npts;
    rp_agg final;           /* mean of each run's final row */
    rp_fit fit_time;        /* log RMSE against log wall time, every row */
    rp_fit fit_work;        /* ... against log (rays + form factors) */
    rp_fit fit_samples;     /* ... against log samples */
    double time_to_target;  /* seconds to reach the target RMSE (mean curve) */
    int target_before;      /* reached before the first checkpoint */
    size_t runs_ok, runs;
} rp_method_summary;

struct rp_bench;

typedef struct rp_bench_params {
    size_t size;            /* sizeof(rp_bench_params) */
    rp_harness_params run;
    unsigned nseeds;        /* for Monte Carlo methods (0: 3) */
    uint64_t seed;          /* first seed (0: 1) */
    double target;          /* RMSE for time-to-error (0: automatic) */
    rp_log_fn log;
    void *log_ctx;
    /* The study's journal (may be NULL): each finished run is recorded
     * under "<journal_prefix><spec> seed <s>" the moment it ends, and a run
     * already recorded (--resume) is read back instead of run again, so a
     * resumed bench equals an uninterrupted one except its timings.  Kept
     * final images (keep_image) go to <image_dir>/runs/ beside it. */
    rp_journal *journal;
    const char *journal_prefix;
    const char *image_dir;
    /* Called after each finished run (e.g. to rewrite runs.csv); may be
     * NULL. */
    void (*on_run)(void *ctx, const struct rp_bench *b);
    void *on_run_ctx;
} rp_bench_params;

typedef struct rp_bench {
    rp_bench_params params;
    size_t planned;               /* runs the study has: methods x seeds */
    size_t resumed;               /* runs read back from the journal */
    int interrupted;              /* stopped by params.run.cancel: runs holds
                                     the finished runs only */
    int threads;                  /* threads the runs used */
    const char *scene_name;
    char scene_hash[17];
    const rp_scene *scene;
    const rp_reference *ref;      /* borrowed */
    rp_method_spec *methods;      /* owned copy */
    size_t nmethods;
    rp_trial *runs;
    size_t nruns;
    rp_method_summary *summary;   /* nmethods */
    double target;                /* the RMSE used for time-to-error */
    int target_auto;
    size_t failures;
} rp_bench;

/* Runs every method (Monte Carlo ones with nseeds seeds) and summarises.
 * Cancelled (params.run.cancel), it returns RP_OK with b->interrupted set
 * and the runs finished so far. */
rp_status rp_bench_run(const rp_scene *scene, const char *scene_name, const rp_reference *ref,
                       const rp_method_spec *methods, size_t nmethods, const rp_bench_params *params,
                       rp_bench **out, rp_error *err);
/* Recomputes the summaries from the runs (after editing params.target). */
void rp_bench_summarise(rp_bench *b);
void rp_bench_destroy(rp_bench *b);


#endif
