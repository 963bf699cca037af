/* gnuplot and colour helpers (gnuplot.h). */
#include "bench/report/gnuplot.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "bench/report/files.h"
#include "bench/report/spectrum.h"

/* Runs argv with cwd dir, stdout and stderr to log (may be NULL: /dev/null);
 * returns the exit status, or -1 when it could not run. */
static int run_program(const char *dir, char *const argv[], const char *log)
{
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0) {
        if (dir && chdir(dir) != 0)
            _exit(127);
        int fd = open(log ? log : "/dev/null", O_WRONLY | O_CREAT | O_TRUNC, 0666);
        if (fd >= 0) {
            dup2(fd, 1);
            dup2(fd, 2);
            close(fd);
        }
        execvp(argv[0], argv);
        _exit(127);
    }
    int status;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR)
            return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

const char *rp_gnuplot_png_terminal(void)
{
    static int probed;
    static const char *term;
    if (probed)
        return term;
    probed = 1;
    /* `set terminal pngcairo` fails when cairo is not built in */
    char *const cairo[] = {"gnuplot", "-e", "set terminal pngcairo", NULL};
    char *const png[] = {"gnuplot", "-e", "set terminal png", NULL};
    if (run_program(NULL, cairo, NULL) == 0)
        term = "pngcairo";
    else if (run_program(NULL, png, NULL) == 0)
        term = "png";
    return term;
}

rp_status rp_gnuplot_run(const char *dir, const char *script, rp_error *err)
{
    if (rp_files_discarded(dir)) /* not the rank that writes files, or not now (files.h) */
        return RP_OK;
    if (!rp_gnuplot_png_terminal())
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "gnuplot is not installed (Debian: gnuplot-nox)");
    char *const argv[] = {"gnuplot", (char *)script, NULL};
    int rc = run_program(dir, argv, "gnuplot.log");
    if (rc != 0)
        return rp_error_set(err, RP_ERR_RUNTIME, "gnuplot %s failed (exit %d); see %s/gnuplot.log", script, rc, dir);
    return RP_OK;
}

void rp_gnuplot_preamble(FILE *f, const char *png)
{
    fprintf(f, "# Written by radpt; run `gnuplot plots.gp` in this directory to redraw.\n"
               "set macros\n"
               "PNG = \"set terminal %s size 1280,720 noenhanced font ',11'\"\n"
               "SVG = \"set terminal svg size 1280,720 dynamic noenhanced font 'sans,11'\"\n"
               "set grid xtics ytics mxtics mytics lc rgb '#dddddd'\n"
               /* the key in its own column right of the plot, so long method
                * specs neither squeeze nor cover it */
               "set key outside right top vertical Left reverse box\n"
               "set format x '%%g'\nset format y '%%g'\n"
               "set datafile missing '?'\n"
               "set border 3\nset tics nomirror\n",
            png ? png : "pngcairo");
}

void rp_colormap(double t, float rgb[3])
{
    /* Dark blue -> purple -> orange -> yellow, given in sRGB and decoded
     * to linear so the PNG writer's sRGB curve restores it. */
    static const double stops[5][3] = {
        {0.05, 0.03, 0.25}, {0.35, 0.07, 0.55}, {0.80, 0.20, 0.35}, {0.98, 0.55, 0.10}, {0.99, 0.95, 0.35}};
    if (!(t > 0))
        t = 0;
    if (t > 1)
        t = 1;
    double x = t * 4;
    int i = (int)x;
    if (i > 3)
        i = 3;
    double f = x - i;
    for (int c = 0; c < 3; c++) {
        double s = stops[i][c] + f * (stops[i + 1][c] - stops[i][c]);
        rgb[c] = (float)(s <= 0.04045 ? s / 12.92 : pow((s + 0.055) / 1.055, 2.4));
    }
}

void rp_image_to_rgb(const rp_scene *scene, const float *img, size_t npix, float *r, float *g, float *b)
{
    size_t nb = rp_scene_nbands(scene);
    rp_band_kind kind = rp_scene_band_kind(scene);
    double m[3 * 256];
    if (kind == RP_BANDS_SPECTRAL && nb <= 256)
        rp_spectrum_rgb_weights(rp_scene_wavelengths(scene), nb, m);
    for (size_t i = 0; i < npix; i++) {
        const float *p = img + i * nb;
        if (kind == RP_BANDS_RGB) {
            r[i] = p[0];
            g[i] = p[1];
            b[i] = p[2];
        } else if (kind == RP_BANDS_GREY || nb > 256) {
            r[i] = g[i] = b[i] = p[0];
        } else {
            double c[3] = {0, 0, 0};
            for (int k = 0; k < 3; k++)
                for (size_t j = 0; j < nb; j++)
                    c[k] += m[k * nb + j] * p[j];
            r[i] = (float)c[0];
            g[i] = (float)c[1];
            b[i] = (float)c[2];
        }
    }
}


/* Fixed colours per method name (Dark2 and Set1 hues), the same in every
 * chart of every report; variants of one method (its options) keep the
 * colour and take a dash type from a hash of the spec. */
const char *rp_plot_method_style(const char *spec)
{
    static const struct {
        const char *name, *colour;
    } colours[] = {
        {"pathtrace", "#1b9e77"},     {"gauss-seidel", "#d95f02"}, {"jacobi", "#e6ab02"},
        {"southwell", "#7570b3"},     {"stochastic-jacobi", "#e7298a"}, {"hierarchical", "#66a61e"},
        {"direct", "#a6761d"},
    };
    static char buf[8][64];
    static int next;
    size_t len = strcspn(spec, ":");
    const char *colour = "#666666";
    for (size_t i = 0; i < sizeof colours / sizeof colours[0]; i++)
        if (strlen(colours[i].name) == len && strncmp(colours[i].name, spec, len) == 0)
            colour = colours[i].colour;
    int dt = 1;
    if (spec[len] == ':') {
        unsigned h = 2166136261u;
        for (const char *c = spec + len; *c; c++)
            h = (h ^ (unsigned char)*c) * 16777619u;
        dt = 2 + (int)(h % 4);
    }
    char *out = buf[next++ % 8];
    snprintf(out, sizeof buf[0], "lc rgb '%s' dt %d", colour, dt);
    return out;
}
