/* Benchmark output: runs.csv, summary.json, report.md, gnuplot scripts and
 * the charts drawn from them, the image sheet.  (Files: files.h; gnuplot
 * and colours: gnuplot.h.)
 *
 * Every table in report.md is printed from the same rows as runs.csv (no
 * number is computed twice), and every chart reads data files written from
 * those rows. */
#ifndef RP_PLOT_H
#define RP_PLOT_H

#include <stddef.h>
#include <stdio.h>

#include "geometry/status.h"
#include "bench/run/harness.h"
#include "bench/report/image.h"
#include "bench/report/files.h"
#include "bench/report/gnuplot.h"

/* What a benchmark's output shows beyond the defaults. */
typedef struct rp_bench_output {
    size_t size;            /* sizeof(rp_bench_output) */
    const char *title;      /* report heading (NULL: "radpt bench: SCENE") */
    const char *preface;    /* markdown put after the heading, may be NULL */
    int samples_chart;      /* also RMSE against samples (spp), with fits */
    const char *samples_label; /* its x label (NULL: "samples per pixel") */
    int sheet;              /* draw the image sheet (needs kept images) */
    const char *command;    /* the command line, for the report */
    const rp_exposure *exposure; /* the sheet's (--exposure); NULL: automatic, from the reference */
} rp_bench_output;

/* Writes DIR/runs.csv, DIR/summary.json, DIR/data/, DIR/plots.gp, the
 * charts (PNG and SVG) when gnuplot is there, DIR/sheet.png and
 * DIR/report.md.  *note (may be NULL; 256 chars) gets a warning to show,
 * e.g. that gnuplot is missing. */
rp_status rp_bench_write(const rp_bench *b, const char *dir, const rp_bench_output *opt, char *note,
                         rp_error *err);

/* Writes DIR/runs.csv alone (atomically): the rows of the runs finished
 * so far, e.g. after each run of a long study. */
rp_status rp_bench_write_runs_csv(const rp_bench *b, const char *dir, rp_error *err);

/* The columns of runs.csv, one per line "name: meaning" (for --help and
 * the README). */
extern const char *const rp_runs_csv_columns;

#endif
