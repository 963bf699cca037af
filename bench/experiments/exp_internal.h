/* Helpers shared by the experiment files of bench/experiments/ (one file
 * per experiment, exp_NAME.c; experiments.c holds the registry and these
 * helpers); not a public interface. */
#ifndef RP_EXP_INTERNAL_H
#define RP_EXP_INTERNAL_H

#include <stdio.h>

#include "geometry/status.h"
#include "bench/report/plot.h"
#include "bench/run/harness.h"
#include "bench/run/reference.h"
#include "bench/experiments/experiments.h"

/* Howell's catalog C-11: parallel, directly opposed rectangles a x b at
 * distance c. */
double howell_parallel(double a, double b, double c);
/* C-14: perpendicular rectangles with a common edge of length l, from A1
 * (width w) to A2 (height h). */
double howell_perpendicular(double w, double h, double l);

/* A message through p->log (if set), printf-style. */
void rp_exp_log(const rp_experiment_params *p, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Writes DIR/plots.gp from body (after the shared chart preamble) and runs
 * gnuplot on it; a missing gnuplot is a note (nn chars), not a failure. */
rp_status rp_exp_draw(const rp_experiment_params *p, const char *body, char *note, size_t nn, rp_error *err);

/* What every experiment starts from. */
typedef struct rp_exp_start {
    rp_experiment_setting set; /* the declared quick or full setting, with --budget / --seeds */
    char methods[1024];        /* set.methods described for report texts (rp_exp_describe_methods) */
    char path[1024];           /* the scene file found */
    rp_scene *scene;           /* loaded (warnings printed, default camera where it has none) */
} rp_exp_start;

/* The start every experiment shares: the setting in force and, when
 * scene_file is not NULL, scenes/scene_file found and loaded.  The caller
 * destroys x->scene. */
rp_status rp_exp_begin(const rp_experiment_params *p, const char *scene_file, rp_exp_start *x, rp_error *err);

/* What a method list runs, for report texts generated from what ran:
 * "pathtrace (sampler=random, defaults); southwell (elements=250,
 * elements=1000); hierarchical". */
void rp_exp_describe_methods(const char *list, char *out, size_t n);

/* Reference parameters for an experiment: spp, its threads, cache, log
 * and progress. */
rp_reference_params rp_exp_ref_params(const rp_experiment_params *p, unsigned long spp);

/* Gets the scene's reference, runs a bench over a method list with
 * checkpoints at budget x 2^-k, k < levels (budget in seconds or, with
 * RP_SCHEDULE_ITERATIONS, in iterations) and writes the standard output
 * into dir (in rp_experiment_run's hand-out pass, only the reference:
 * *bench_out is then NULL); bench_out and ref_out (may be NULL) receive the bench and the
 * reference. */
rp_status rp_exp_run_bench_scheduled(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                                     const char *list, rp_schedule schedule, double budget, unsigned levels,
                                     unsigned nseeds, unsigned long ref_spp, const rp_bench_output *out,
                                     const char *dir, rp_bench **bench_out, rp_reference **ref_out, rp_error *err);
/* rp_exp_run_bench_scheduled by time, 9 checkpoints. */
rp_status rp_exp_run_bench(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                           const char *list, double budget, unsigned nseeds, unsigned long ref_spp,
                           const rp_bench_output *out, const char *dir, rp_bench **bench_out,
                           rp_reference **ref_out, rp_error *err);

/* A unit of an experiment's own tables (one row: a method at one
 * setting), named by key in the study's journal.  Returns
 *    1  recorded: read back (v: its n numbers; v NULL: the caller reads
 *       the text payload with rp_journal_get), not run again;
 *    0  to be computed here, then recorded with rp_journal_put_doubles
 *       (or rp_journal_put) under the same key;
 *   -1  in rp_experiment_run's hand-out pass, a unit another rank
 *       computes: skip it (v is filled with NaN; nothing is written in
 *       that pass, and the next pass reads it back).
 * The units an experiment asks for, and their order, must not depend on
 * the numbers of other units, so that every rank counts the same units
 * (were they to differ, the second pass computes what is missing). */
int rp_exp_unit(const rp_experiment_params *p, const char *key, double *v, size_t n);
/* 1 in the hand-out pass (the numbers of units other ranks own are NaN:
 * no conclusion may be drawn from them). */
int rp_exp_handing_out(const rp_experiment_params *p);

/* A CSV number; not reached or not measured: an empty field. */
void rp_exp_fnum(FILE *f, double v);
/* The same in gnuplot data: "?" (the plots' `set datafile missing`). */
void rp_exp_dnum(FILE *f, double v);

/* The experiments, one file each. */
rp_status rp_exp_cornell(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_samplers(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_furnace(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_formfactors(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_meshing(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_discontinuity(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_progressive(const rp_experiment_params *p, rp_error *err);
rp_status rp_exp_hierarchy(const rp_experiment_params *p, rp_error *err);

/* radpt experiment stability (exp_stability.c). */
rp_status rp_exp_stability(const rp_experiment_params *p, rp_error *err);

/* radpt experiment realscenes (exp_realscenes.c). */
rp_status rp_exp_realscenes(const rp_experiment_params *p, rp_error *err);

/* radpt experiment modelsize (exp_modelsize.c). */
rp_status rp_exp_modelsize(const rp_experiment_params *p, rp_error *err);

#endif
