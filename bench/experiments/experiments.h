/* Named experiments (radpt experiment NAME): each builds its scenes (from
 * scenes/ or as text in memory), runs methods through the harness or the
 * form-factor module, and writes its CSV, charts and report.md into a
 * directory.  Default sizes take a few minutes; quick ones well under a
 * minute (for CI). */
#ifndef RP_EXPERIMENTS_H
#define RP_EXPERIMENTS_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdio.h>
#include <stdint.h>

#include "geometry/status.h"
#include "solvers/solver.h"
#include "bench/report/image.h"
#include "bench/run/journal.h"
#include "bench/run/reference.h"

typedef struct rp_experiment_params {
    size_t size;               /* sizeof(rp_experiment_params) */
    int quick;
    const char *out_dir;
    const char *cache_dir;     /* references (NULL: "refs") */
    const char *scenes_dir;    /* NULL: ./scenes, else next to the binary */
    int threads;
    double budget;             /* seconds per run; 0: the experiment's default */
    unsigned nseeds;           /* 0: the experiment's default */
    const char *command;       /* the command line, for the report */
    rp_log_fn log;
    void *log_ctx;
    rp_progress_fn progress;
    void *progress_ctx;
    const rp_exposure *exposure; /* --exposure for the PNGs; NULL: each chooses */
    /* Set (by SIGINT / SIGTERM) to stop: experiments pass it to their runs
     * (rp_options.cancel, rp_harness_params.cancel), stop between units of
     * work, write what finished (report marked incomplete) and return
     * RP_ERR_INTERRUPTED.  May be NULL. */
    const atomic_int *cancel;
    /* The study's journal in out_dir (may be NULL): each finished unit is
     * recorded as it finishes, and units already recorded (--resume DIR)
     * are read back instead of run again (journal.h). */
    rp_journal *journal;
    /* The experiment being run (set by whoever runs it): its declared
     * settings, see rp_experiment_setting_of. */
    const struct rp_experiment *experiment;
    /* Set by rp_experiment_run under mpirun while it hands the units of an
     * experiment's own tables out to ranks (exp_internal.h, rp_exp_unit);
     * NULL otherwise. */
    struct rp_exp_handout *handout;
} rp_experiment_params;

/* One size of an experiment (its --quick or its full form).  Zero / NULL
 * fields do not apply to that experiment. */
typedef struct rp_experiment_setting {
    double budget;               /* seconds (or the experiment's unit) per run */
    unsigned seeds;              /* seeds per Monte Carlo method */
    unsigned long reference_spp; /* path-traced reference, samples per pixel */
    const char *methods;         /* method list, "m[:opt=v...],..." */
} rp_experiment_setting;

/* An experiment, declared: what it runs and what its report checks. */
typedef struct rp_experiment {
    const char *name;
    const char *summary;         /* one line */
    const char *scenes;          /* scenes it runs on: files under scenes/, or what it builds */
    const char *claim;           /* the claim its report checks in numbers (and its test) */
    rp_experiment_setting quick, full;
    const char *budget_unit;     /* what budget counts, NULL: seconds per run */
    /* 1: the experiment runs units of its own (rows of its tables, not
     * harness runs) through rp_exp_unit, so that rp_experiment_run can hand
     * them out to MPI ranks.  0: its runs are benches, which hand out their
     * runs themselves (harness.h). */
    int own_units;
    /* RP_ERR_UNSUPPORTED: the experiment cannot run here (e.g. its method
     * is not registered). */
    rp_status (*run)(const rp_experiment_params *p, rp_error *err);
} rp_experiment;

/* Runs p->experiment.  Under mpirun (more than one rank) an experiment
 * with own_units runs twice: a hand-out pass, in which each rank computes
 * the units it owns (unit k of those not yet in the journal goes to rank
 * k mod K) with every file output discarded, then an exchange that puts
 * every rank's new records into every rank's journal (rank 0 writes them
 * to DIR/journal.txt), then the ordinary pass, which reads every unit back
 * and writes the reports on rank 0.  Results equal a single process's,
 * timings aside.  Otherwise it calls p->experiment->run. */
rp_status rp_experiment_run(const rp_experiment_params *p, rp_error *err);

/* The identity of p's journal (rp_journal_open): the experiment and what
 * changes its results, the form and the budget and seeds asked. */
void rp_experiment_identity(const rp_experiment_params *p, char *buf, size_t n);

/* NULL-terminated list, and look-up by name. */
const rp_experiment *const *rp_experiments(void);
const rp_experiment *rp_experiment_lookup(const char *name);

/* Prints the declaration of e (summary, scenes, claim, quick and full
 * settings) for `radpt help experiment NAME`. */
void rp_experiment_describe(const rp_experiment *e, FILE *f);

/* The setting in force: p->experiment's quick or full one, with
 * p->budget and p->nseeds (when non-zero) in place of its budget and
 * seeds.  Into *out; RP_ERR_INPUT when p->experiment is NULL. */
rp_status rp_experiment_setting_of(const rp_experiment_params *p, rp_experiment_setting *out, rp_error *err);

/* Finds scenes/NAME: under p->scenes_dir if set, else ./scenes, else the
 * scenes directory next to the running binary. */
rp_status rp_experiment_scene_path(const rp_experiment_params *p, const char *name, char *out, size_t n,
                                   rp_error *err);

#endif
