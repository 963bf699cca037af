/* radpt experiment hierarchy: hierarchical radiosity, links against leaves. */
#include "bench/experiments/exp_internal.h"
#include "bench/run/driver.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/radiosity/formfactor.h"
#include "solvers/radiosity/hierarchical.h"
#include "bench/run/metrics.h"
#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "bench/run/harness.h"
#include "bench/report/plot.h"
#include "bench/experiments/exp_internal.h"

/* ------------------------------------------------------------ hierarchy */

/* Links against leaves as --bf-epsilon shrinks (min-area scaled with it so
 * the refinement is limited by the oracle, not the floor).  Hanrahan et al.
 * 1991 argue the link count grows linearly with the leaves; Garmann 1995
 * argues worse for fixed geometry: the fitted slope of log links against
 * log leaves says which.  Writes links.csv, links.png/svg and links.md. */
static rp_status hierarchy_links(const rp_experiment_params *p, const rp_scene *scene, rp_error *err)
{
    static const double bf_full[] = {0.3, 0.1, 0.03, 0.01, 0.003};
    static const double bf_quick[] = {0.3, 0.1, 0.03};
    const double *bf = p->quick ? bf_quick : bf_full;
    size_t n = p->quick ? 3 : 5;
    double leaves[5], links[5], seconds[5];
    rp_status st = RP_OK;
    for (size_t k = 0; k < n && st == RP_OK; k++) {
        /* a row finished before an interruption is read back from the
         * study's journal, not run again */
        char key[96];
        snprintf(key, sizeof key, "hierarchy links bf-epsilon %.17g", bf[k]);
        double rec[3];
        if (rp_exp_unit(p, key, rec, 3)) { /* recorded, or another rank's */
            leaves[k] = rec[0];
            links[k] = rec[1];
            seconds[k] = rec[2];
            continue;
        }
        if (rp_cancelled(p->cancel)) {
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
            break;
        }
        char eps[32], area[32];
        snprintf(eps, sizeof eps, "%g", bf[k]);
        snprintf(area, sizeof area, "%g", bf[k] * 1e-4);
        const char *keys[2] = {"bf-epsilon", "min-area"};
        const char *values[2] = {eps, area};
        rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = p->threads,
                        .keys = keys, .values = values, .count = 2, .cancel = p->cancel};
        rp_solver *s = NULL;
        rp_drive_totals tot;
        memset(&tot, 0, sizeof tot);
        st = rp_drive_create(&rp_solver_hierarchical, scene, &o, &s, &tot, err);
        /* to the method's rule, at most 1000 steps */
        rp_drive_params dp = {.size = sizeof dp, .budget = 1000, .schedule = RP_SCHEDULE_STEPS, .stop_at_rule = 1,
                              .cancel = p->cancel};
        if (st == RP_OK)
            st = rp_drive(s, &dp, &tot, err);
        if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
        if (st == RP_OK) {
            rp_hier_stats hs;
            rp_hierarchical_stats(rp_solver_state(s), &hs);
            leaves[k] = (double)hs.leaves;
            links[k] = (double)hs.links;
            seconds[k] = tot.wall_s;
            double v[3] = {leaves[k], links[k], seconds[k]};
            st = rp_journal_put_doubles(p->journal, key, v, 3, err);
            rp_exp_log(p, "  hierarchical bf-epsilon %g: %zu leaves, %zu links, %.2f s", bf[k], hs.leaves, hs.links,
                       seconds[k]);
        }
        rp_solver_destroy(s);
    }
    if (st != RP_OK)
        return st;
    rp_fit fit;
    rp_fit_loglog(leaves, links, n, 0.95, &fit);

    char path[1200];
    rp_out o;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "links.csv"), err)) != RP_OK)
        return st;
    fprintf(o.f, "bf_epsilon,min_area,leaves,links,seconds\n");
    for (size_t k = 0; k < n; k++)
        fprintf(o.f, "%g,%g,%.0f,%.0f,%.4f\n", bf[k], bf[k] * 1e-4, leaves[k], links[k], seconds[k]);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;

    const char *png = rp_gnuplot_png_terminal();
    if (png) {
        if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "links.gp"), err)) != RP_OK)
            return st;
        rp_gnuplot_preamble(o.f, png);
        fprintf(o.f,
                "set datafile separator ','\nset logscale xy\n"
                "set title 'Hierarchical radiosity: links against leaf elements as bf-epsilon shrinks'\n"
                "set xlabel 'leaf elements'\nset ylabel 'links'\n"
                "f(x) = exp(%.17g) * x**%.17g\n"
                "do for [t in 'png svg'] {\n"
                "  if (t eq 'png') { @PNG; set output 'links.png' } else { @SVG; set output 'links.svg' }\n"
                "  plot 'links.csv' skip 1 using 3:4 with linespoints pt 7 title 'hierarchical, Cornell box', \\\n"
                "       f(x) with lines dt 2 title sprintf('fit: links ~ leaves^{%%.2f}', %.17g), \\\n"
                "       x * (%.17g) with lines dt 3 title 'linear growth (slope 1)'\n"
                "}\n",
                fit.intercept, fit.slope, fit.slope, links[0] / leaves[0]);
        if ((st = rp_out_close(&o, 1, err)) != RP_OK)
            return st;
        rp_error gerr;
        if (rp_gnuplot_run(p->out_dir, "links.gp", &gerr) != RP_OK)
            rp_exp_log(p, "%s", gerr.message);
    }

    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "links.md"), err)) != RP_OK)
        return st;
    fprintf(o.f,
            "# Links against leaves (hierarchical radiosity, Cornell box)\n\n"
            "Each row is one converged hierarchical solve with `--bf-epsilon` as given and `--min-area` = "
            "bf-epsilon x 1e-4 (so the oracle, not the area floor, limits refinement). Hanrahan, Salzman & "
            "Aupperle (1991) argue links grow linearly with leaves; Garmann (1995) argues worse for fixed "
            "geometry.\n\n![links against leaves](links.png)\n\n"
            "| bf-epsilon | leaves | links | links per leaf | seconds |\n|---|---|---|---|---|\n");
    for (size_t k = 0; k < n; k++)
        fprintf(o.f, "| %g | %.0f | %.0f | %.1f | %.2f |\n", bf[k], leaves[k], links[k], links[k] / leaves[k],
                seconds[k]);
    if (fit.ok)
        fprintf(o.f, "\nFitted slope of log links against log leaves (GSL least squares): %.3f, 95%% interval "
                     "[%.3f, %.3f] over %zu points (bf-epsilon %g to %g, data in links.csv).\n",
                fit.slope, fit.lo, fit.hi, fit.n, bf[0], bf[n - 1]);
    return rp_out_close(&o, 1, err);
}

/* Issue 5's comparison: the form factors each method computes to reach a
 * surface-average error (RMS over surfaces and bands of the relative error
 * against the reference's surface averages), uniform Gauss-Seidel at a
 * fixed mesh against hierarchical radiosity as --bf-epsilon shrinks.
 * Appends a table to report.md and writes form_factors.csv. */
typedef struct ffrow {
    char spec[64];
    double form_factors, error, seconds;
} ffrow;

static rp_status hierarchy_solve(const rp_scene *scene, const rp_reference *ref, const rp_solver_type *t,
                                 const char *key, const char *value, int threads, const atomic_int *cancel,
                                 ffrow *row, rp_error *err)
{
    const char *keys[1] = {key}, *values[1] = {value};
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = threads, .keys = keys,
                    .values = values, .count = 1, .cancel = cancel};
    size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    double *x = calloc(ns * nb, sizeof *x);
    if (!x)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_solver *s = NULL;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_status st = rp_drive_create(t, scene, &o, &s, &tot, err);
    /* to the method's rule, at most 100000 steps */
    rp_drive_params dp = {.size = sizeof dp, .budget = 100000, .schedule = RP_SCHEDULE_STEPS, .stop_at_rule = 1,
                          .cancel = cancel};
    if (st == RP_OK)
        st = rp_drive(s, &dp, &tot, err);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    row->form_factors = tot.sum.form_factors;
    row->seconds = tot.wall_s;
    if (st == RP_OK) {
        rp_estimate e = {.surface_radiance = x};
        st = rp_solver_estimate(s, &e, err);
    }
    if (st == RP_OK)
        row->error = rp_metrics_surface_error(x, ref->surface_radiance, ref->surface_mask, ns, nb, NULL);
    snprintf(row->spec, sizeof row->spec, "%.20s:%.20s=%.20s", t->name, key, value);
    rp_solver_destroy(s);
    free(x);
    return st;
}

static rp_status hierarchy_form_factors(const rp_experiment_params *p, const rp_scene *scene,
                                        const rp_reference *ref, rp_error *err)
{
    const rp_solver_type *gs = rp_solver_lookup("gauss-seidel");
    if (!gs || !ref->surface_radiance)
        return RP_OK;
    static const char *bf_full[] = {"0.04", "0.03", "0.02", "0.015", "0.01"};
    static const char *bf_quick[] = {"0.05", "0.02"};
    const char *const *bf = p->quick ? bf_quick : bf_full;
    size_t n = p->quick ? 2 : 5;
    const char *elements = p->quick ? "1200" : "4800";
    ffrow rows[6];
    rp_status st = RP_OK;
    for (size_t k = 0; k <= n && st == RP_OK; k++) {
        const rp_solver_type *t = k ? &rp_solver_hierarchical : gs;
        const char *key = k ? "bf-epsilon" : "elements", *value = k ? bf[k - 1] : elements;
        /* a row finished before an interruption is read back from the
         * study's journal, not run again */
        char jkey[96];
        snprintf(jkey, sizeof jkey, "hierarchy form factors %s %s=%s", t->name, key, value);
        double rec[3];
        if (rp_exp_unit(p, jkey, rec, 3)) { /* recorded, or another rank's */
            rows[k].form_factors = rec[0];
            rows[k].error = rec[1];
            rows[k].seconds = rec[2];
            snprintf(rows[k].spec, sizeof rows[k].spec, "%.20s:%.20s=%.20s", t->name, key, value);
            continue;
        }
        if (rp_cancelled(p->cancel))
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
        if (st == RP_OK)
            st = hierarchy_solve(scene, ref, t, key, value, p->threads, p->cancel, &rows[k], err);
        if (st == RP_OK) {
            double v[3] = {rows[k].form_factors, rows[k].error, rows[k].seconds};
            st = rp_journal_put_doubles(p->journal, jkey, v, 3, err);
        }
    }
    if (st != RP_OK)
        return st;
    for (size_t k = 0; k <= n; k++)
        rp_exp_log(p, "  %.63s: %.4g form factors, surface error %.3f%%, %.2f s", rows[k].spec, rows[k].form_factors,
                   100 * rows[k].error, rows[k].seconds);
    char path[1200];
    rp_out o;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "form_factors.csv"), err)) != RP_OK)
        return st;
    fprintf(o.f, "spec,form_factors,surface_error,seconds\n");
    for (size_t k = 0; k <= n; k++)
        fprintf(o.f, "%s,%.0f,%.6g,%.4f\n", rows[k].spec, rows[k].form_factors, rows[k].error, rows[k].seconds);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    /* report.md as rp_bench_write left it, plus this section (rewritten
     * whole, through a temporary file). */
    rp_path_join(path, sizeof path, p->out_dir, "report.md");
    char *old = NULL;
    size_t len = 0;
    FILE *f = fopen(path, "rb");
    if (f) {
        if (fseek(f, 0, SEEK_END) == 0) {
            long m = ftell(f);
            if (m > 0 && (old = malloc((size_t)m)) != NULL) {
                rewind(f);
                len = fread(old, 1, (size_t)m, f);
            }
        }
        fclose(f);
    }
    if ((st = rp_out_open(&o, path, err)) != RP_OK) {
        free(old);
        return st;
    }
    if (old)
        fwrite(old, 1, len, o.f);
    free(old);
    fprintf(o.f,
            "\n## Form factors to reach the uniform solution's surface error\n\n"
            "Each row is one converged solve. Surface error: RMS over surfaces and bands of the relative "
            "error of the surface averages against the reference's (itself uncertain by %.2f%% RMS, which "
            "adds in quadrature to every row). Form factors: the sum of `rp_step_info.form_factors` (the "
            "uniform solver counts every element pair, the hierarchical one every link it estimated, kept or "
            "not).\n\n| method | form factors | surface error | ratio to uniform | seconds |\n|---|---|---|---|---|\n",
            100 * ref->surface_rel_se);
    const ffrow *best = NULL;
    for (size_t k = 0; k <= n; k++) {
        fprintf(o.f, "| `%s` | %.4g | %.3f%% | %.3f | %.2f |\n", rows[k].spec, rows[k].form_factors,
                100 * rows[k].error, rows[k].form_factors / rows[0].form_factors, rows[k].seconds);
        if (k > 0 && rows[k].error <= rows[0].error && (!best || rows[k].form_factors < best->form_factors))
            best = &rows[k];
    }
    if (best)
        fprintf(o.f, "\nCheapest hierarchical run at or below the uniform error: `%s`, %.1f%% of the uniform "
                     "solver's form factors.\n",
                best->spec, 100 * best->form_factors / rows[0].form_factors);
    else
        fprintf(o.f, "\nNo hierarchical run reached the uniform solver's surface error.\n");
    return rp_out_close(&o, 1, err);
}

rp_status rp_exp_hierarchy(const rp_experiment_params *p, rp_error *err)
{
    const rp_solver_type *t = rp_solver_lookup("hierarchical");
    if (!t)
        return rp_error_set(err, RP_ERR_UNSUPPORTED,
                            "experiment hierarchy: the method 'hierarchical' is not registered in this build; "
                            "not available");
    rp_exp_start x;
    rp_status st = rp_exp_begin(p, "cornell.scene", &x, err);
    if (st != RP_OK)
        return st;
    char preface[1600];
    snprintf(preface, sizeof preface,
             "Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991) against the classic solvers at equal "
             "time (%g s per run) on the Cornell box: %s.",
             x.set.budget, x.methods);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment hierarchy: hierarchical radiosity",
                           .preface = preface, .sheet = 1, .command = p->command};
    rp_reference *ref = NULL;
    st = rp_exp_run_bench(p, x.scene, x.path, x.set.methods, x.set.budget, 1, x.set.reference_spp, &out, p->out_dir, NULL,
                          &ref, err);
    if (st == RP_OK)
        st = hierarchy_form_factors(p, x.scene, ref, err);
    if (st == RP_OK)
        st = hierarchy_links(p, x.scene, err);
    rp_reference_destroy(ref);
    rp_scene_destroy(x.scene);
    return st;
}

