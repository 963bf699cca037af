/* Benchmark output: runs.csv, summary.json, report.md, gnuplot scripts and
 * the charts drawn from them, the image sheet, and the small file helpers
 * the rest of bench/ shares (directories, atomic text files).
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


/* gnuplot: which terminal draws PNGs ("pngcairo", or "png" when cairo is
 * missing), NULL when gnuplot is not installed.  Probed once. */
const char *rp_gnuplot_png_terminal(void);

/* Runs gnuplot on script (a path) with dir as the working directory.
 * RP_ERR_UNSUPPORTED when gnuplot is missing; RP_ERR_RUNTIME when it fails
 * (its stderr goes to DIR/gnuplot.log). */
rp_status rp_gnuplot_run(const char *dir, const char *script, rp_error *err);

/* Prints the preamble every chart script shares: terminal choice, fonts,
 * grid, and the macro `out(name)` convention (PNG then SVG of one plot is
 * made by plotting twice).  See plot.c. */
void rp_gnuplot_preamble(FILE *f, const char *png_terminal);

/* A false-colour ramp for error maps (0 -> dark blue, 1 -> yellow), linear
 * RGB so that the sRGB PNG writer shows the intended colours. */
void rp_colormap(double t, float rgb[3]);

/* Tone-mapped linear RGB planes of an image (npix * nbands, band fastest)
 * for a preview: grey copies Y, rgb splits, spectral goes through the CIE
 * 1931 observer.  r, g, b have npix values each. */
void rp_image_to_rgb(const rp_scene *scene, const float *img, size_t npix, float *r, float *g, float *b);

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

/* The columns of runs.csv, one per line "name: meaning" (for --help and
 * the README). */
extern const char *const rp_runs_csv_columns;

#endif
