/* The one driver: runs a solver's steps to a budget.  Every command and
 * experiment that runs a solver goes through rp_drive (render, probe,
 * reference, the benchmark harness, throughput, the experiments), so the
 * clock, the stopping rules, cancellation and progress are defined once
 * (docs/design.md, "The solver interface": the harness alone owns clocks).
 *
 * Clock: solver time is the wall time (CLOCK_MONOTONIC) and CPU time (all
 * threads) spent inside rp_solver_step only; whatever after_step does
 * (estimates, error metrics, writing checkpoints) runs with the clock
 * stopped.  Creation is timed by rp_drive_create into the same totals.
 *
 * After each step, in this order:
 *   1. the totals are updated (sums of rays, paths, form factors,
 *      iterations; the last step's info);
 *   2. cancellation: when *cancel is set the run stops at once (stop =
 *      RP_STOP_SIGNAL), after_step is not called for that step;
 *   3. tot->stop is set when the run will end after this step: the method's
 *      rule is met (converged, where stop_at_rule is set, or converged with
 *      a step that did no work: nothing is left to do) or the budget is
 *      spent (budget_base + this call's solver time, or the iterations, >=
 *      budget);
 *   4. progress (a fraction and a detail with an ETA, rate-limited);
 *   5. after_step (may record a checkpoint, estimate, or end the run by
 *      returning 1: stop = RP_STOP_CALLER);
 *   6. the loop ends when tot->stop is set. */
#ifndef RP_DRIVER_H
#define RP_DRIVER_H

#include <stdatomic.h>
#include <stddef.h>

#include "solvers/solver.h"
#include "bench/run/reference.h"

typedef enum rp_schedule {
    RP_SCHEDULE_TIME,       /* budget in seconds of solver time */
    RP_SCHEDULE_ITERATIONS, /* budget in the method's iterations (steps' sum) */
    RP_SCHEDULE_STEPS       /* budget in calls of step (a cap) */
} rp_schedule;

/* Why a run ended (RP_STOP_NONE: it has not). */
typedef enum rp_stop {
    RP_STOP_NONE,
    RP_STOP_RULE,    /* the method's own rule (converged) */
    RP_STOP_BUDGET,  /* the time or iteration budget */
    RP_STOP_SIGNAL,  /* the cancel flag */
    RP_STOP_CALLER   /* after_step said so */
} rp_stop;

/* What a run has done; carried over by a resumed run. */
typedef struct rp_drive_totals {
    rp_step_info sum;       /* rays, paths, form_factors, iterations added up */
    rp_step_info last;      /* the last step's info (residual, progress, ...) */
    double wall_s, cpu_s;   /* solver time: creation and steps */
    double steps;
    rp_stop stop;
} rp_drive_totals;

typedef struct rp_drive_params {
    size_t size;            /* sizeof(rp_drive_params) */
    double budget;          /* seconds or iterations; 0: no budget */
    rp_schedule schedule;
    double budget_base;     /* solver seconds already spent that count
                               toward a time budget (e.g. set-up) */
    int stop_at_rule;       /* end the run when the method's rule is met */
    const atomic_int *cancel;
    /* Called after each step (see above) with the clock stopped; returns
     * 1 to end the run, 0 to go on; an error goes to *st and err (the run
     * then ends with it). */
    int (*after_step)(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err);
    void *ctx;
    rp_progress_fn progress; /* may be NULL */
    void *progress_ctx;
    const char *label;      /* the start of the progress detail, may be NULL */
} rp_drive_params;

/* Creates the solver, its time added to tot (which may carry totals). */
rp_status rp_drive_create(const rp_solver_type *type, const rp_scene *scene, const rp_options *options,
                          rp_solver **out, rp_drive_totals *tot, rp_error *err);

/* Steps s as described above.  tot comes in zeroed (bar creation time) or
 * with a resumed run's totals, which it carries on; tot->stop says why the
 * run ended.  A failing step, or after_step's error, is returned. */
rp_status rp_drive(rp_solver *s, const rp_drive_params *p, rp_drive_totals *tot, rp_error *err);

#endif
