/* Helpers shared by the experiment files of bench/ (experiments.c,
 * exp_stability.c); not a public interface. */
#ifndef RP_EXP_INTERNAL_H
#define RP_EXP_INTERNAL_H

#include "geometry/status.h"
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

/* radpt experiment stability (exp_stability.c). */
rp_status rp_exp_stability(const rp_experiment_params *p, rp_error *err);

/* radpt experiment realscenes (exp_realscenes.c). */
rp_status rp_exp_realscenes(const rp_experiment_params *p, rp_error *err);

#endif
