/* radpt experiment furnace: iterative solvers and the path tracer in the white furnace. */
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

/* -------------------------------------------------------------- furnace */

typedef struct furnace_row {
    double rho;
    const char *method;
    int reached;
    double seconds, iterations, sweeps, steps, error, rel_stderr, theory_sweeps;
} furnace_row;

/* Runs one method on a furnace until its surface error (deterministic
 * methods) or its relative standard error (Monte Carlo) is at most tol, or
 * the budget runs out.  The estimate is not timed. */
/* The furnace's stopping test after each step of the driver: the surface
 * error (deterministic methods) or the relative standard error (Monte
 * Carlo, after two steps) at most tol.  The estimate is not timed. */
typedef struct furnace_check {
    const rp_scene *scene;
    double L, tol;
    int mc;
    double *x, *se;
    furnace_row *row;
} furnace_check;

static int furnace_after_step(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    furnace_check *fc = ctx;
    rp_estimate e = {.surface_radiance = fc->x, .surface_stderr = fc->se};
    if ((*st = rp_solver_estimate(s, &e, err)) != RP_OK)
        return 1;
    size_t n = rp_scene_nsurfaces(fc->scene) * rp_scene_nbands(fc->scene);
    double worst = 0, worst_se = 0;
    for (size_t i = 0; i < n; i++) {
        double d = fabs(fc->x[i] - fc->L) / fc->L, r = fc->se[i] / fc->L;
        worst = d > worst ? d : worst;
        worst_se = r > worst_se ? r : worst_se;
    }
    fc->row->error = worst;
    fc->row->rel_stderr = fc->mc ? worst_se : 0;
    fc->row->reached = fc->mc ? worst_se <= fc->tol && t->steps >= 2 : worst <= fc->tol;
    return fc->row->reached;
}

/* Runs one method on a furnace until it meets the tolerance or the budget
 * runs out. */
static rp_status furnace_run(const rp_scene *scene, double L, const rp_method_spec *m, double tol, double budget,
                             const rp_experiment_params *p, size_t nelements, furnace_row *row, rp_error *err)
{
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = p->threads, .keys = m->keys,
                    .values = m->values, .count = m->count, .open_ended = 1, .cancel = p->cancel};
    rp_solver *s = NULL;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_status st = rp_drive_create(m->type, scene, &o, &s, &tot, err);
    size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    furnace_check fc = {.scene = scene, .L = L, .tol = tol, .mc = rp_method_is_monte_carlo(m),
                        .x = calloc(ns * nb, sizeof *fc.x), .se = calloc(ns * nb, sizeof *fc.se), .row = row};
    row->reached = 0;
    row->error = row->rel_stderr = NAN;
    if (st == RP_OK && (!fc.x || !fc.se))
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_drive_params dp = {.size = sizeof dp, .budget = budget, .budget_base = tot.wall_s, .cancel = p->cancel,
                          .after_step = furnace_after_step, .ctx = &fc};
    if (st == RP_OK)
        st = rp_drive(s, &dp, &tot, err);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    row->seconds = tot.wall_s;
    row->iterations = tot.sum.iterations;
    row->steps = tot.steps;
    /* comparable sweeps: a progressive shot updates one element */
    row->sweeps = strcmp(m->name, "southwell") == 0 ? tot.sum.iterations / (double)nelements
                                                    : (fc.mc ? NAN : tot.sum.iterations);
    free(fc.x);
    free(fc.se);
    rp_solver_destroy(s);
    return st;
}

rp_status rp_exp_furnace(const rp_experiment_params *p, rp_error *err)
{
    static const double rhos_full[] = {0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99};
    static const double rhos_quick[] = {0.3, 0.7, 0.9};
    const double *rhos = p->quick ? rhos_quick : rhos_full;
    size_t nrho = p->quick ? 3 : 7;
    const double tol = p->quick ? 1e-2 : 1e-3;
    rp_experiment_setting set;
    rp_status st0 = rp_experiment_setting_of(p, &set, err);
    if (st0 != RP_OK)
        return st0;
    const double budget = set.budget;
    /* exact form factors matter here: a row-sum error d moves the answer by
     * about rho d / (1 - rho), which at rho = 0.99 is 100 d */
    static const char *const specs[] = {"jacobi:elements=150:ff-tolerance=1e-8",
                                        "gauss-seidel:elements=150:ff-tolerance=1e-8",
                                        "southwell:elements=150:ff-tolerance=1e-8", "pathtrace"};
    const size_t nm = 4;
    rp_method_spec m[4];
    rp_status st = RP_OK;
    for (size_t i = 0; i < nm && st == RP_OK; i++)
        st = rp_method_spec_parse(specs[i], &m[i], err);
    if (st != RP_OK)
        return st;
    furnace_row *rows = calloc(nrho * nm, sizeof *rows);
    if (!rows)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    size_t nrows = 0, nelements = 0;
    for (size_t r = 0; r < nrho && st == RP_OK; r++) {
        char text[512];
        snprintf(text, sizeof text,
                 "bands grey\nmaterial wall reflect %.17g emit 1\nbox enclosure wall 0 0 0 1 1 1 inward\n"
                 "camera eye 0.3 0.6 0.3 look 1 0 1 up 0 1 0 fov 70 size 64 64\n",
                 rhos[r]);
        char name[64];
        snprintf(name, sizeof name, "furnace rho %g", rhos[r]);
        rp_scene *scene = NULL;
        if ((st = rp_scene_parse(text, name, NULL, &scene, err)) != RP_OK)
            break;
        double L;
        int exact = rp_reference_furnace(scene, &L, err);
        if (exact != 1)
            st = exact < 0 ? RP_ERR_RUNTIME
                           : rp_error_set(err, RP_ERR_RUNTIME, "%s: not recognised as a furnace", name);
        if (st == RP_OK && !nelements) {
            rp_mesh *mesh = NULL;
            rp_mesh_params mp = {.size = sizeof mp, .target_count = 150};
            if ((st = rp_mesh_create(scene, &mp, &mesh, err)) == RP_OK)
                nelements = rp_mesh_nelements(mesh);
            rp_mesh_destroy(mesh);
        }
        for (size_t i = 0; i < nm && st == RP_OK; i++) {
            furnace_row *row = &rows[nrows];
            row->rho = rhos[r];
            row->method = specs[i];
            /* Jacobi from B = E: relative error rho^(k+1) after k sweeps */
            row->theory_sweeps = log(tol) / log(rhos[r]) - 1;
            /* a row finished before an interruption is read back from the
             * study's journal, not run again */
            char key[160];
            snprintf(key, sizeof key, "furnace rho %.17g %s tol %.17g budget %.17g", rhos[r], specs[i], tol, budget);
            double v[8];
            if (rp_exp_unit(p, key, v, 8)) { /* recorded, or another rank's */
                row->reached = (int)v[0];
                row->seconds = v[1];
                row->iterations = v[2];
                row->sweeps = v[3];
                row->steps = v[4];
                row->error = v[5];
                row->rel_stderr = v[6];
                nrows++;
                continue;
            }
            if (rp_cancelled(p->cancel)) {
                st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted after %zu of %zu furnace runs", nrows,
                                  nrho * nm);
                break;
            }
            rp_exp_log(p, "furnace rho %g: %s", rhos[r], specs[i]);
            st = furnace_run(scene, L, &m[i], tol, budget, p, nelements, row, err);
            if (st == RP_OK) {
                double rec[8] = {row->reached, row->seconds, row->iterations, row->sweeps, row->steps, row->error,
                                 row->rel_stderr, row->theory_sweeps};
                st = rp_journal_put_doubles(p->journal, key, rec, 8, err);
            }
            if (st == RP_OK) {
                nrows++;
                rp_exp_log(p, "  %s after %.3g s, %.0f iterations, error %.3g", row->reached ? "reached" : "NOT reached",
                     row->seconds, row->iterations, row->error);
            }
        }
        rp_scene_destroy(scene);
    }
    if (st == RP_OK)
        st = rp_mkdirs(p->out_dir, err);
    char path[1024];
    rp_out o;
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "furnace.csv"), err)) == RP_OK) {
        fputs("rho,method,reached,seconds,iterations,sweeps,steps,error,rel_stderr,theory_sweeps\n", o.f);
        for (size_t i = 0; i < nrows; i++) {
            const furnace_row *w = &rows[i];
            fprintf(o.f, "%g,%s,%d,", w->rho, w->method, w->reached);
            double v[] = {w->seconds, w->iterations, w->sweeps, w->steps, w->error, w->rel_stderr, w->theory_sweeps};
            for (size_t k = 0; k < 7; k++) {
                rp_exp_fnum(o.f, v[k]);
                fputc(k < 6 ? ',' : '\n', o.f);
            }
        }
        st = rp_out_close(&o, 1, err);
    }
    /* one data block per method for gnuplot */
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "furnace.dat"), err)) == RP_OK) {
        for (size_t i = 0; i < nm; i++) {
            fprintf(o.f, "# %s: rho seconds(reached) sweeps(reached) theory_sweeps\n", specs[i]);
            for (size_t k = 0; k < nrows; k++)
                if (rows[k].method == specs[i]) {
                    fprintf(o.f, "%g ", rows[k].rho);
                    rp_exp_dnum(o.f, rows[k].reached ? rows[k].seconds : NAN);
                    fputc(' ', o.f);
                    rp_exp_dnum(o.f, rows[k].reached ? rows[k].sweeps : NAN);
                    fputc(' ', o.f);
                    rp_exp_dnum(o.f, rows[k].theory_sweeps);
                    fputc('\n', o.f);
                }
            fputs("\n\n", o.f);
        }
        st = rp_out_close(&o, 1, err);
    }
    char note[256] = "";
    if (st == RP_OK) {
        char body[4096];
        size_t used = (size_t)snprintf(body, sizeof body,
                                       "\n@PNG\nset output 'furnace_time.png'\nset logscale y\n"
                                       "set xlabel 'reflectance rho (every surface)'\n"
                                       "set ylabel 'solver wall time to tolerance (s)'\n"
                                       "set title 'Furnace: time to reach relative error %g'\nplot ",
                                       tol);
        for (size_t i = 0; i < nm && used < sizeof body; i++)
            used += (size_t)snprintf(body + used, sizeof body - used,
                                     "%s'furnace.dat' index %zu using 1:2 with linespoints lw 2 pt 7 title '%s'",
                                     i ? ", " : "", i, specs[i]);
        if (used < sizeof body)
            used += (size_t)snprintf(body + used, sizeof body - used,
                                     "\n@SVG\nset output 'furnace_time.svg'\nreplot\nunset output\n"
                                     "\n@PNG\nset output 'furnace_sweeps.png'\n"
                                     "set ylabel 'sweeps to tolerance (southwell: shots / elements)'\n"
                                     "set title 'Furnace: sweeps to relative error %g against theory'\nplot ",
                                     tol);
        for (size_t i = 0; i < 3 && used < sizeof body; i++)
            used += (size_t)snprintf(body + used, sizeof body - used,
                                     "'furnace.dat' index %zu using 1:3 with linespoints lw 2 pt 7 title '%s', ", i,
                                     specs[i]);
        if (used < sizeof body)
            snprintf(body + used, sizeof body - used,
                     "'furnace.dat' index 0 using 1:4 with lines dt 2 lw 2 lc rgb '#555555' "
                     "title 'Jacobi theory: ln(tol) / ln(rho) - 1'\n"
                     "@SVG\nset output 'furnace_sweeps.svg'\nreplot\nunset output\n");
        st = rp_exp_draw(p, body, note, sizeof note, err);
    }
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err)) == RP_OK) {
        FILE *f = o.f;
        fprintf(f, "# Experiment furnace: reflectance sweep\n\n"
                   "A closed unit box, every face with reflectance rho and emitted radiance 1, so the exact answer "
                   "is L = 1 / (1 - rho) everywhere (docs/ground-truth.md). Each method runs until its surface "
                   "average is within a relative error of %g (radiosity: the actual error; path tracer: its "
                   "estimated relative standard error, the rule a Monte Carlo run can apply), or %g s of solver "
                   "time. Radiosity uses 150 elements (%zu made) and analytic form factors to 1e-8 (a row-sum error "
                   "d shifts the answer by about rho d / (1 - rho)). For Jacobi the error after k sweeps is "
                   "rho^(k+1): ln(tol) / ln(rho) - 1 sweeps; Gauss-Seidel is never slower (Stein-Rosenberg).\n\n",
                tol, budget, nelements);
        if (p->command)
            fprintf(f, "Command: `%s`\n\n", p->command);
        if (!note[0])
            fprintf(f, "![time to tolerance](furnace_time.png)\n\n![sweeps to tolerance](furnace_sweeps.png)\n\n");
        else
            fprintf(f, "**Note:** %s\n\n", note);
        fprintf(f, "Rows of furnace.csv:\n\n| rho | method | reached | seconds | iterations | sweeps | error | "
                   "rel. stderr | theory sweeps |\n|---|---|---|---|---|---|---|---|---|\n");
        for (size_t i = 0; i < nrows; i++) {
            const furnace_row *w = &rows[i];
            fprintf(f, "| %g | `%s` | %s | %.4g | %.6g | ", w->rho, w->method, w->reached ? "yes" : "**no**", w->seconds,
                    w->iterations);
            if (isfinite(w->sweeps))
                fprintf(f, "%.4g", w->sweeps);
            else
                fputs("n/a", f);
            fprintf(f, " | %.3g | ", w->error);
            if (isfinite(w->rel_stderr) && w->rel_stderr > 0)
                fprintf(f, "%.3g", w->rel_stderr);
            else
                fputs("0", f);
            fprintf(f, " | %.4g |\n", w->theory_sweeps);
        }
        fprintf(f, "\nColumns of furnace.csv: rho; method (spec); reached (1 if the tolerance was met within the "
                   "budget); seconds (solver wall time, estimates excluded); iterations (sweeps, shots or sample "
                   "batches); sweeps (southwell: shots / elements; n/a for the path tracer); steps; error (largest "
                   "relative error of a surface average against 1 / (1 - rho)); rel_stderr (path tracer's "
                   "estimated relative standard error); theory_sweeps (ln(tol) / ln(rho) - 1).\n");
        st = rp_out_close(&o, 1, err);
    }
    free(rows);
    return st;
}

