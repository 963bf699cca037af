/* gnuplot (charts are gnuplot scripts run where gnuplot is installed) and
 * the colour helpers of previews: false colour, image planes to RGB. */
#ifndef RP_GNUPLOT_H
#define RP_GNUPLOT_H

#include <stdio.h>

#include "geometry/scene.h"
#include "geometry/status.h"

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

/* A gnuplot line style for a method spec: a colour fixed by the method's
 * name (the same in every report) and, for a spec with options, a dash type
 * of its own ("lc rgb '#1b9e77' dt 3").  Valid until 8 more calls. */
const char *rp_plot_method_style(const char *spec);

#endif
