/* Named experiments (experiments.h). */
#include "bench/experiments/experiments.h"

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

/* ------------------------------------------------------------- helpers */

void rp_exp_log(const rp_experiment_params *p, const char *fmt, ...)
{
    if (!p->log)
        return;
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    p->log(p->log_ctx, msg);
}

static int is_file(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
}

rp_status rp_experiment_scene_path(const rp_experiment_params *p, const char *name, char *out, size_t n,
                                   rp_error *err)
{
    if (p->scenes_dir) {
        rp_path_join(out, n, p->scenes_dir, name);
        if (is_file(out))
            return RP_OK;
        return rp_error_set(err, RP_ERR_INPUT, "%s: no such scene", out);
    }
    rp_path_join(out, n, "scenes", name);
    if (is_file(out))
        return RP_OK;
    /* next to the binary: radpt lives at the top of the source tree */
    char exe[1024];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (len > 0) {
        exe[len] = '\0';
        char *slash = strrchr(exe, '/');
        for (int up = 0; slash && up < 3; up++) {
            *slash = '\0';
            char dir[1100];
            snprintf(dir, sizeof dir, "%s/scenes", exe);
            rp_path_join(out, n, dir, name);
            if (is_file(out))
                return RP_OK;
            slash = strrchr(exe, '/');
        }
    }
    return rp_error_set(err, RP_ERR_INPUT, "scenes/%s not found (run from the source tree or give --scenes DIR)", name);
}

static rp_reference_params ref_params(const rp_experiment_params *p, unsigned long spp)
{
    rp_reference_params r = {.size = sizeof r, .spp = spp, .threads = p->threads, .cache_dir = p->cache_dir,
                             .log = p->log, .log_ctx = p->log_ctx, .progress = p->progress,
                             .progress_ctx = p->progress_ctx};
    return r;
}

/* Gets the scene's reference, runs a bench over a method list with
 * checkpoints at budget x 2^-k, k < levels (budget in seconds or, with
 * RP_SCHEDULE_ITERATIONS, in iterations) and writes the standard output
 * into dir. */
static rp_status run_bench_scheduled(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                                     const char *list, rp_schedule schedule, double budget, unsigned levels,
                                     unsigned nseeds, unsigned long ref_spp, const rp_bench_output *out,
                                     const char *dir, rp_bench **bench_out, rp_reference **ref_out, rp_error *err)
{
    rp_method_spec *methods = NULL;
    size_t n = 0;
    rp_reference *ref = NULL;
    rp_bench *b = NULL;
    rp_status st = rp_method_list_parse(list, &methods, &n, err);
    if (st == RP_OK) {
        rp_reference_params rp = ref_params(p, ref_spp);
        st = rp_reference_get(scene, scene_name, &rp, &ref, err);
    }
    if (st == RP_OK) {
        rp_bench_params bp = {.size = sizeof bp, .nseeds = nseeds, .seed = 1, .log = p->log, .log_ctx = p->log_ctx};
        bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = budget, .levels = levels,
                                     .schedule = schedule, .threads = p->threads, .keep_image = 1,
                                     .progress = p->progress, .progress_ctx = p->progress_ctx};
        st = rp_bench_run(scene, scene_name, ref, methods, n, &bp, &b, err);
    }
    if (st == RP_OK) {
        char note[256];
        rp_bench_output o = *out;
        if (!o.exposure)
            o.exposure = p->exposure;
        st = rp_bench_write(b, dir, &o, note, err);
        if (st == RP_OK && note[0])
            rp_exp_log(p, "%s", note);
    }
    free(methods);
    if (st == RP_OK && bench_out) {
        *bench_out = b;
        b = NULL;
    }
    if (st == RP_OK && ref_out) {
        *ref_out = ref;
        ref = NULL;
    }
    rp_bench_destroy(b);
    rp_reference_destroy(ref);
    return st;
}

/* run_bench_scheduled by time, 9 checkpoints. */
static rp_status run_bench(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                           const char *list, double budget, unsigned nseeds, unsigned long ref_spp,
                           const rp_bench_output *out, const char *dir, rp_bench **bench_out,
                           rp_reference **ref_out, rp_error *err)
{
    return run_bench_scheduled(p, scene, scene_name, list, RP_SCHEDULE_TIME, budget, 9, nseeds, ref_spp, out, dir,
                               bench_out, ref_out, err);
}

/* The path-traced references the Cornell experiments share (one cache
 * entry each for the default and the quick size). */
#define REF_SPP(p) ((p)->quick ? 256ul : 2048ul)

/* -------------------------------------------------------------- cornell */

static rp_status exp_cornell(const rp_experiment_params *p, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    double budget = p->budget > 0 ? p->budget : (p->quick ? 1.0 : 6.0);
    unsigned seeds = p->nseeds ? p->nseeds : (p->quick ? 2 : 3);
    /* the reference needs about 9 x the path tracer's samples for its
     * standard error to stay below a third of the error measured */
    unsigned long ref_spp = REF_SPP(p);
    const char *list = p->quick ? "pathtrace:sampler=random,pathtrace,southwell:elements=150,southwell:elements=600,"
                                  "hierarchical:bf-epsilon=0.05:min-area=1e-4,stochastic-jacobi"
                                : "pathtrace:sampler=random,pathtrace,southwell:elements=250,"
                                  "southwell:elements=1000,gauss-seidel:elements=1000:reconstruct=gouraud,"
                                  "hierarchical,stochastic-jacobi";
    char preface[1600];
    snprintf(preface, sizeof preface,
             "Every method on the Cornell box at equal time (%g s per run): Monte Carlo path tracing "
             "(next-event estimation with MIS, Russian roulette) against finite-element radiosity: "
             "progressive refinement and Gauss-Seidel at two mesh sizes, hierarchical radiosity (Hanrahan, "
             "Salzman & Aupperle 1991, Gouraud images from vertex values gathered through its links) and "
             "Monte Carlo radiosity (stochastic Jacobi). The path tracer runs twice: "
             "with independent random numbers (`sampler=random`, plain Monte Carlo, whose error falls as "
             "N^-1/2: slope -0.5) and with its default Owen-scrambled Sobol' points, which converge "
             "somewhat faster where the integrand is smooth (see `radpt experiment samplers`). A "
             "radiosity curve flattens at its mesh's discretisation error, lower for the finer mesh.",
             budget);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment cornell: all methods at equal time",
                           .preface = preface, .sheet = 1, .command = p->command};
    st = run_bench(p, scene, path, list, budget, seeds, ref_spp, &out, p->out_dir, NULL, NULL, err);
    rp_scene_destroy(scene);
    return st;
}

/* ------------------------------------------------------------- samplers */

static rp_status exp_samplers(const rp_experiment_params *p, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    double budget = p->budget > 0 ? p->budget : (p->quick ? 1.0 : 10.0);
    unsigned seeds = p->nseeds ? p->nseeds : (p->quick ? 2 : 3);
    unsigned long ref_spp = REF_SPP(p);
    const char *list = "pathtrace:sampler=random,pathtrace:sampler=stratified,pathtrace:sampler=sobol";
    char preface[1200];
    snprintf(preface, sizeof preface,
             "The path tracer's three samplers on the Cornell box, %g s per run, %u seeds: independent "
             "uniform numbers (random), a jittered grid per pair of dimensions (stratified) and Owen-scrambled "
             "Sobol' points. Plain Monte Carlo error falls as N^-1/2 (slope -0.5 against samples); "
             "stratification and scrambled Sobol' do better where the integrand is smooth (data/ground-truth.md: "
             "about N^-0.75 where visibility edges cross a pixel), less so for the many-dimensional indirect "
             "light. Slopes are fitted against samples per pixel (all rows of all seeds).",
             budget, seeds);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment samplers: random, stratified and Sobol'",
                           .preface = preface, .samples_chart = 1, .sheet = 1, .command = p->command};
    st = run_bench(p, scene, path, list, budget, seeds, ref_spp, &out, p->out_dir, NULL, NULL, err);
    rp_scene_destroy(scene);
    return st;
}

/* -------------------------------------------------------------- gnuplot */

/* Writes DIR/plots.gp from body (after the shared preamble) and runs it;
 * a missing gnuplot is a note, not a failure. */
rp_status rp_exp_draw(const rp_experiment_params *p, const char *body, char *note, size_t nn, rp_error *err)
{
    char path[1024];
    rp_out o;
    note[0] = '\0';
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "plots.gp"), err);
    if (st != RP_OK)
        return st;
    rp_gnuplot_preamble(o.f, rp_gnuplot_png_terminal());
    fputs(body, o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    rp_error gerr;
    if (rp_gnuplot_run(p->out_dir, "plots.gp", &gerr) != RP_OK) {
        snprintf(note, nn, "charts not drawn: %.200s", gerr.message);
        rp_exp_log(p, "%s", note);
    }
    return RP_OK;
}

/* A CSV number; not reached or not measured: an empty field. */
static void fnum(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
}

/* The same in gnuplot data: "?" (the plots' `set datafile missing`). */
static void dnum(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
    else
        fputc('?', f);
}

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
static rp_status furnace_run(const rp_scene *scene, double L, const rp_method_spec *m, double tol, double budget,
                             int threads, size_t nelements, furnace_row *row, rp_error *err)
{
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = threads, .keys = m->keys,
                    .values = m->values, .count = m->count, .open_ended = 1};
    rp_solver *s = NULL;
    double t0 = rp_clock();
    rp_status st = rp_solver_create(m->type, scene, &o, &s, err);
    double wall = rp_clock() - t0, iters = 0, steps = 0;
    size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    double *x = calloc(ns * nb, sizeof *x), *se = calloc(ns * nb, sizeof *se);
    int mc = rp_method_is_monte_carlo(m);
    row->reached = 0;
    row->error = row->rel_stderr = NAN;
    if (st == RP_OK && (!x || !se))
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    while (st == RP_OK) {
        rp_step_info info;
        memset(&info, 0, sizeof info);
        t0 = rp_clock();
        st = rp_solver_step(s, &info, err);
        wall += rp_clock() - t0;
        if (st != RP_OK)
            break;
        iters += info.iterations;
        steps++;
        rp_estimate e = {.surface_radiance = x, .surface_stderr = se};
        if ((st = rp_solver_estimate(s, &e, err)) != RP_OK)
            break;
        double worst = 0, worst_se = 0;
        for (size_t i = 0; i < ns * nb; i++) {
            double d = fabs(x[i] - L) / L, r = se[i] / L;
            worst = d > worst ? d : worst;
            worst_se = r > worst_se ? r : worst_se;
        }
        row->error = worst;
        row->rel_stderr = mc ? worst_se : 0;
        if ((mc ? worst_se <= tol && steps >= 2 : worst <= tol)) {
            row->reached = 1;
            break;
        }
        if (wall >= budget)
            break;
    }
    row->seconds = wall;
    row->iterations = iters;
    row->steps = steps;
    /* comparable sweeps: a progressive shot updates one element */
    row->sweeps = strcmp(m->name, "southwell") == 0 ? iters / (double)nelements : (mc ? NAN : iters);
    free(x);
    free(se);
    rp_solver_destroy(s);
    return st;
}

static rp_status exp_furnace(const rp_experiment_params *p, rp_error *err)
{
    static const double rhos_full[] = {0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99};
    static const double rhos_quick[] = {0.3, 0.7, 0.9};
    const double *rhos = p->quick ? rhos_quick : rhos_full;
    size_t nrho = p->quick ? 3 : 7;
    const double tol = p->quick ? 1e-2 : 1e-3;
    const double budget = p->budget > 0 ? p->budget : (p->quick ? 2.0 : 20.0);
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
            rp_exp_log(p, "furnace rho %g: %s", rhos[r], specs[i]);
            st = furnace_run(scene, L, &m[i], tol, budget, p->threads, nelements, row, err);
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
                fnum(o.f, v[k]);
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
                    dnum(o.f, rows[k].reached ? rows[k].seconds : NAN);
                    fputc(' ', o.f);
                    dnum(o.f, rows[k].reached ? rows[k].sweeps : NAN);
                    fputc(' ', o.f);
                    dnum(o.f, rows[k].theory_sweeps);
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
                   "is L = 1 / (1 - rho) everywhere (data/ground-truth.md). Each method runs until its surface "
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

/* ---------------------------------------------------------- formfactors */

/* Howell's catalog C-11: parallel, directly opposed rectangles a x b at
 * distance c (data/ground-truth.md). */
double howell_parallel(double a, double b, double c)
{
    double X = a / c, Y = b / c;
    double t = 0.5 * log((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)) +
               X * sqrt(1 + Y * Y) * atan(X / sqrt(1 + Y * Y)) + Y * sqrt(1 + X * X) * atan(Y / sqrt(1 + X * X)) -
               X * atan(X) - Y * atan(Y);
    return 2 / (RP_PI * X * Y) * t;
}

/* C-14: perpendicular rectangles with a common edge of length l, from A1
 * (width w) to A2 (height h). */
double howell_perpendicular(double w, double h, double l)
{
    double W = w / l, H = h / l, W2 = W * W, H2 = H * H, S = sqrt(H2 + W2);
    double g = (1 + W2) * (1 + H2) / (1 + W2 + H2) * pow(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)), W2) *
               pow(H2 * (1 + W2 + H2) / ((1 + H2) * (W2 + H2)), H2);
    return 1 / (RP_PI * W) * (W * atan(1 / W) + H * atan(1 / H) - S * atan(1 / S) + 0.25 * log(g));
}

typedef struct ff_setup {
    rp_scene *scene;
    rp_mesh *mesh;
    uint32_t i, j; /* the element of A and of B */
    double exact;
    char name[64];
} ff_setup;

static void ff_setup_free(ff_setup *s)
{
    rp_mesh_destroy(s->mesh);
    rp_scene_destroy(s->scene);
    memset(s, 0, sizeof *s);
}

/* Unit squares A (z = 0, facing +z) and B: parallel at distance c, or
 * perpendicular with a shared edge (c <= 0). */
static rp_status ff_setup_make(double c, ff_setup *s, rp_error *err)
{
    memset(s, 0, sizeof *s);
    char text[512];
    if (c > 0) {
        snprintf(text, sizeof text,
                 "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
                 "quad a w 0 0 0  1 0 0  1 1 0  0 1 0\nquad b l 0 0 %.17g  0 1 %.17g  1 1 %.17g  1 0 %.17g\n",
                 c, c, c, c);
        s->exact = howell_parallel(1, 1, c);
        snprintf(s->name, sizeof s->name, "parallel c=%g", c);
    } else {
        snprintf(text, sizeof text,
                 "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
                 "quad a w 0 0 0  1 0 0  1 1 0  0 1 0\nquad b l 0 0 0  0 1 0  0 1 1  0 0 1\n");
        s->exact = howell_perpendicular(1, 1, 1);
        snprintf(s->name, sizeof s->name, "perpendicular");
    }
    rp_status st = rp_scene_parse(text, s->name, NULL, &s->scene, err);
    rp_mesh_params mp = {.size = sizeof mp, .max_edge = 10};
    if (st == RP_OK)
        st = rp_mesh_create(s->scene, &mp, &s->mesh, err);
    if (st == RP_OK) {
        uint32_t count;
        rp_mesh_surface_elements(s->mesh, rp_scene_find_surface(s->scene, "a"), &s->i, &count);
        if (count == 1)
            rp_mesh_surface_elements(s->mesh, rp_scene_find_surface(s->scene, "b"), &s->j, &count);
        if (count != 1)
            st = rp_error_set(err, RP_ERR_RUNTIME, "formfactors: expected one element per square");
    }
    if (st != RP_OK)
        ff_setup_free(s);
    return st;
}

/* F from A's element to B's: mean over seeds, RMS relative error against
 * the closed form, seconds per pair. */
static rp_status ff_measure(const ff_setup *s, const rp_ff_params *base, unsigned nseeds, double *F, double *rel_rms,
                            double *seconds, rp_error *err)
{
    double sum = 0, sq = 0, t = 0;
    size_t calls = 0;
    rp_status st = RP_OK;
    for (unsigned k = 0; k < nseeds && st == RP_OK; k++) {
        rp_ff_params prm = *base;
        prm.seed = 1 + k;
        rp_ff_context *ctx = NULL;
        rp_ff_scratch *scr = NULL;
        st = rp_ff_context_create(s->scene, s->mesh, NULL, &prm, &ctx, err);
        /* Repeated until the clock can see it, each call with a fresh
         * scratch: the hemicube keeps the row it rasterised there. */
        double spent = 0, v = 0;
        size_t reps = 0;
        while (st == RP_OK && spent < 0.02 && reps < 100000) {
            if ((st = rp_ff_scratch_create(ctx, &scr, err)) != RP_OK)
                break;
            double t0 = rp_clock();
            v = rp_ff_pair(ctx, scr, s->i, s->j, NULL, NULL);
            spent += rp_clock() - t0;
            reps++;
            rp_ff_scratch_destroy(scr);
            scr = NULL;
        }
        if (st == RP_OK && reps) {
            t += spent / (double)reps;
            calls++;
            double e = (v - s->exact) / s->exact;
            sum += v;
            sq += e * e;
        }
        rp_ff_context_destroy(ctx);
    }
    *F = calls ? sum / (double)calls : NAN;
    *rel_rms = calls ? sqrt(sq / (double)calls) : NAN;
    *seconds = calls ? t / (double)calls : NAN;
    return st;
}

static rp_status exp_formfactors(const rp_experiment_params *p, rp_error *err)
{
    const int quick = p->quick;
    static const double tol_full[] = {1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8};
    static const unsigned samples_full[] = {16, 64, 256, 1024, 4096, 16384};
    static const unsigned res_full[] = {16, 32, 64, 128, 256, 512, 1024};
    size_t ntol = quick ? 4 : 7, nsam = quick ? 4 : 6, nres = quick ? 4 : 7;
    const unsigned mc_seeds = quick ? 8 : 32;
    static const double dist_full[] = {0.1, 0.2, 0.5, 1, 2, 5, 10};
    size_t ndist = quick ? 4 : 7;
    static const double dist_quick[] = {0.2, 0.5, 1, 2};
    const double *dist = quick ? dist_quick : dist_full;
    rp_status st = rp_mkdirs(p->out_dir, err);
    if (st != RP_OK)
        return st;
    char path[1024];
    rp_out csv, dat;
    if ((st = rp_out_open(&csv, rp_path_join(path, sizeof path, p->out_dir, "formfactors.csv"), err)) != RP_OK)
        return st;
    if ((st = rp_out_open(&dat, rp_path_join(path, sizeof path, p->out_dir, "formfactors.dat"), err)) != RP_OK) {
        rp_out_close(&csv, 0, err);
        return st;
    }
    fputs("experiment,configuration,distance,method,parameter,value,exact,form_factor,rel_error,seconds_per_pair,"
          "seeds\n",
          csv.f);
    /* block 0..2: cost sweeps (unit squares at distance 1 and perpendicular)
     * per method; blocks 3..5: distance sweeps per method */
    static const rp_ff_method methods[3] = {RP_FF_ANALYTIC, RP_FF_MONTECARLO, RP_FF_HEMICUBE};
    static const char *const pname[3] = {"tolerance", "samples", "resolution"};
    const double configs[2] = {1.0, 0.0};
    double first_exact[2] = {0, 0};
    for (int cfg = 0; cfg < 2 && st == RP_OK; cfg++) {
        ff_setup su;
        if ((st = ff_setup_make(configs[cfg], &su, err)) != RP_OK)
            break;
        first_exact[cfg] = su.exact;
        for (int mi = 0; mi < 3 && st == RP_OK; mi++) {
            fprintf(dat.f, "# cost: %s, %s: seconds rel_error\n", su.name, rp_ff_method_name(methods[mi]));
            size_t np = mi == 0 ? ntol : (mi == 1 ? nsam : nres);
            rp_exp_log(p, "formfactors: %s, %s", su.name, rp_ff_method_name(methods[mi]));
            for (size_t k = 0; k < np && st == RP_OK; k++) {
                rp_ff_params prm = {.size = sizeof prm, .method = methods[mi]};
                double param;
                if (mi == 0)
                    param = prm.tolerance = tol_full[k];
                else if (mi == 1)
                    param = prm.samples = samples_full[k];
                else
                    param = prm.resolution = res_full[k];
                double F, e, secs;
                unsigned ns = mi == 1 ? mc_seeds : 1;
                if ((st = ff_measure(&su, &prm, ns, &F, &e, &secs, err)) != RP_OK)
                    break;
                fprintf(csv.f, "cost,%s,%g,%s,%s=%g,%g,%.10f,%.10f,%.4g,%.4g,%u\n",
                        cfg == 0 ? "parallel" : "perpendicular", configs[cfg], rp_ff_method_name(methods[mi]),
                        pname[mi], param, param, su.exact, F, e, secs, ns);
                fprintf(dat.f, "%.6g %.6g %g\n", secs, e > 1e-16 ? e : 1e-16, param);
            }
            fprintf(dat.f, "\n\n");
        }
        ff_setup_free(&su);
    }
    /* distance: default settings, parallel squares */
    for (int mi = 0; mi < 3 && st == RP_OK; mi++) {
        fprintf(dat.f, "# distance: %s at its default: c exact rel_error\n", rp_ff_method_name(methods[mi]));
        rp_exp_log(p, "formfactors: distance sweep, %s", rp_ff_method_name(methods[mi]));
        for (size_t d = 0; d < ndist && st == RP_OK; d++) {
            ff_setup su;
            if ((st = ff_setup_make(dist[d], &su, err)) != RP_OK)
                break;
            rp_ff_params prm = {.size = sizeof prm, .method = methods[mi]};
            double F, e, secs;
            unsigned ns = mi == 1 ? mc_seeds : 1;
            st = ff_measure(&su, &prm, ns, &F, &e, &secs, err);
            if (st == RP_OK) {
                fprintf(csv.f, "distance,parallel,%g,%s,default,,%.10f,%.10f,%.4g,%.4g,%u\n", dist[d],
                        rp_ff_method_name(methods[mi]), su.exact, F, e, secs, ns);
                fprintf(dat.f, "%g %.10f %.6g\n", dist[d], su.exact, e > 1e-16 ? e : 1e-16);
            }
            ff_setup_free(&su);
        }
        fprintf(dat.f, "\n\n");
    }
    rp_status st2 = rp_out_close(&csv, st == RP_OK, err);
    rp_status st3 = rp_out_close(&dat, st == RP_OK, err);
    if (st == RP_OK)
        st = st2 != RP_OK ? st2 : st3;
    char note[256] = "";
    if (st == RP_OK) {
        const char *body =
            "\n@PNG\nset output 'ff_cost_parallel.png'\nset logscale xy\nset format y '%g'\n"
            "set xlabel 'seconds per form factor (one element pair)'\nset ylabel 'relative error (RMS over seeds)'\n"
            "set title 'Unit squares 1 apart (Howell C-11): error against cost'\n"
            "plot 'formfactors.dat' index 0 using 1:2 with linespoints lw 2 pt 7 title 'analytic (tolerance sweep)', "
            "'' index 1 using 1:2 with linespoints lw 2 pt 7 title 'montecarlo (samples sweep)', "
            "'' index 2 using 1:2 with linespoints lw 2 pt 7 title 'hemicube (resolution sweep)'\n"
            "@SVG\nset output 'ff_cost_parallel.svg'\nreplot\nunset output\n"
            "\n@PNG\nset output 'ff_cost_perpendicular.png'\n"
            "set title 'Perpendicular unit squares sharing an edge (Howell C-14): error against cost'\n"
            "plot 'formfactors.dat' index 3 using 1:2 with linespoints lw 2 pt 7 title 'analytic (tolerance sweep)', "
            "'' index 4 using 1:2 with linespoints lw 2 pt 7 title 'montecarlo (samples sweep)', "
            "'' index 5 using 1:2 with linespoints lw 2 pt 7 title 'hemicube (resolution sweep)'\n"
            "@SVG\nset output 'ff_cost_perpendicular.svg'\nreplot\nunset output\n"
            "\n@PNG\nset output 'ff_distance.png'\nset xlabel 'distance between the unit squares'\n"
            "set title 'Parallel unit squares: error against distance (default settings)'\n"
            "plot 'formfactors.dat' index 6 using 1:3 with linespoints lw 2 pt 7 title 'analytic', "
            "'' index 7 using 1:3 with linespoints lw 2 pt 7 title 'montecarlo (256 samples)', "
            "'' index 8 using 1:3 with linespoints lw 2 pt 7 title 'hemicube (256)'\n"
            "@SVG\nset output 'ff_distance.svg'\nreplot\nunset output\n";
        st = rp_exp_draw(p, body, note, sizeof note, err);
    }
    if (st == RP_OK && (st = rp_out_open(&csv, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err)) == RP_OK) {
        FILE *f = csv.f;
        fprintf(f, "# Experiment formfactors: analytic, Monte Carlo and hemicube against Howell's closed forms\n\n"
                   "Form factors between two unit squares, one element each (solvers/radiosity/formfactor.h, no "
                   "occluders), against Howell's catalog: C-11 parallel opposed squares (distance 1: F = %.10f) and "
                   "C-14 perpendicular squares sharing an edge (F = %.10f). Cost is the wall time of one "
                   "rp_ff_pair call (repeated until 20 ms have passed); Monte Carlo errors are RMS over %u seeds. "
                   "The analytic method sweeps its tolerance, Monte Carlo its point pairs, the hemicube its "
                   "resolution. The hemicube measures from the element's centre: its error tends to that of the "
                   "point-to-area form factor, not to zero, and is largest when the squares are close. Monte Carlo "
                   "area sampling has infinite variance for squares sharing an edge (the 1/r^2 kernel is not square "
                   "integrable there), so its error there does not fall as N^-1/2.\n\n",
                first_exact[0], first_exact[1], mc_seeds);
        if (p->command)
            fprintf(f, "Command: `%s`\n\n", p->command);
        if (!note[0])
            fprintf(f, "![cost, parallel](ff_cost_parallel.png)\n\n![cost, perpendicular](ff_cost_perpendicular.png)\n\n"
                       "![distance](ff_distance.png)\n\n");
        else
            fprintf(f, "**Note:** %s\n\n", note);
        fprintf(f, "All rows are in formfactors.csv (columns: experiment cost|distance, configuration, distance, "
                   "method, parameter, value, exact, form_factor (mean over seeds), rel_error (RMS over seeds), "
                   "seconds_per_pair, seeds).\n");
        st = rp_out_close(&csv, 1, err);
    }
    return st;
}

/* -------------------------------------------------------------- meshing */

static rp_status exp_meshing(const rp_experiment_params *p, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    /* below about 150 elements the Cornell box's 27 surfaces get one or two
     * elements each and the error is not yet in its asymptotic regime */
    static const unsigned counts_full[] = {250, 500, 1000, 2000, 4000};
    static const unsigned counts_quick[] = {150, 300, 600};
    const unsigned *counts = p->quick ? counts_quick : counts_full;
    size_t nc = p->quick ? 3 : 5;
    static const char *const recon[2] = {"flat", "gouraud"};
    const double budget = p->budget > 0 ? p->budget : (p->quick ? 20.0 : 300.0);
    rp_reference *ref = NULL;
    rp_reference_params rp = ref_params(p, REF_SPP(p));
    st = rp_reference_get(scene, path, &rp, &ref, err);
    const double area = rp_scene_total_area(scene);
    typedef struct mrow {
        unsigned target;
        size_t elements;
        double h, rmse[2], surface_err, seconds;
        int converged;
    } mrow;
    mrow rows[8];
    size_t nrows = 0;
    for (size_t c = 0; c < nc && st == RP_OK; c++) {
        mrow *w = &rows[nrows];
        memset(w, 0, sizeof *w);
        w->target = counts[c];
        rp_mesh *mesh = NULL;
        rp_mesh_params mp = {.size = sizeof mp, .target_count = counts[c]};
        if ((st = rp_mesh_create(scene, &mp, &mesh, err)) != RP_OK)
            break;
        w->elements = rp_mesh_nelements(mesh);
        rp_mesh_destroy(mesh);
        /* the characteristic element size */
        w->h = sqrt(area / (double)w->elements);
        for (int r = 0; r < 2 && st == RP_OK; r++) {
            char spec[128];
            snprintf(spec, sizeof spec, "gauss-seidel:elements=%u:tolerance=1e-5:reconstruct=%s", counts[c], recon[r]);
            rp_method_spec m;
            if ((st = rp_method_spec_parse(spec, &m, err)) != RP_OK)
                break;
            rp_exp_log(p, "meshing: %s", spec);
            rp_harness_params hp = {.size = sizeof hp, .budget = budget, .levels = 1, .threads = p->threads,
                                    .stop_when_converged = 1, .progress = p->progress,
                                    .progress_ctx = p->progress_ctx};
            rp_trial run;
            if ((st = rp_harness_run(scene, ref, &m, 1, &hp, &run, err)) != RP_OK)
                break;
            if (run.status != RP_OK)
                st = rp_error_set(err, run.status, "%s: %s", spec, run.error);
            else if (run.ncp) {
                const rp_checkpoint *cp = &run.cp[run.ncp - 1];
                w->rmse[r] = cp->rmse;
                if (r == 0) {
                    w->surface_err = cp->surface_err;
                    w->seconds = cp->wall_s;
                    w->converged = cp->converged;
                }
                rp_exp_log(p, "  %zu elements, h %.4g: RMSE %.4g, surface error %.4g (%.1f s)", w->elements, w->h,
                     cp->rmse,
                     cp->surface_err, cp->wall_s);
            }
            rp_trial_free(&run);
        }
        if (st == RP_OK)
            nrows++;
    }
    rp_fit fit[3];
    if (st == RP_OK) {
        double h[8], y[3][8];
        for (size_t i = 0; i < nrows; i++) {
            h[i] = rows[i].h;
            y[0][i] = rows[i].rmse[0];
            y[1][i] = rows[i].rmse[1];
            y[2][i] = rows[i].surface_err;
        }
        for (int k = 0; k < 3; k++)
            rp_fit_loglog(h, y[k], nrows, 0.95, &fit[k]);
        st = rp_mkdirs(p->out_dir, err);
    }
    rp_out o;
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "meshing.csv"), err)) == RP_OK) {
        fputs("target_elements,elements,h,rmse_flat,rmse_gouraud,surface_err,seconds,converged\n", o.f);
        for (size_t i = 0; i < nrows; i++)
            fprintf(o.f, "%u,%zu,%.6g,%.6g,%.6g,%.6g,%.4g,%d\n", rows[i].target, rows[i].elements, rows[i].h,
                    rows[i].rmse[0], rows[i].rmse[1], rows[i].surface_err, rows[i].seconds, rows[i].converged);
        st = rp_out_close(&o, 1, err);
    }
    char note[256] = "";
    if (st == RP_OK) {
        const char *body =
            "\n@PNG\nset output 'meshing.png'\nset logscale xy\nset format y '%g'\n"
            "set xlabel 'element size h = sqrt(total area / elements) (mm)'\n"
            "set ylabel 'error at convergence'\nset title 'Cornell box, Gauss-Seidel: discretisation error against "
            "element size'\nset datafile separator ','\n"
            "plot 'meshing.csv' using 3:4 every ::1 with linespoints lw 2 pt 7 title 'image RMSE, flat (W sr^-1 m^-2)', "
            "'' using 3:5 every ::1 with linespoints lw 2 pt 7 title 'image RMSE, gouraud (W sr^-1 m^-2)', "
            "'' using 3:6 every ::1 with linespoints lw 2 pt 7 title 'surface-average relative error'\n"
            "@SVG\nset output 'meshing.svg'\nreplot\nunset output\nset datafile separator whitespace\n";
        st = rp_exp_draw(p, body, note, sizeof note, err);
    }
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err)) == RP_OK) {
        FILE *f = o.f;
        fprintf(f, "# Experiment meshing: error against element size\n\n"
                   "Gauss-Seidel radiosity on the Cornell box, run to a relative residual of 1e-5 at each mesh "
                   "size, scored against the path-traced reference `%s` (RMSE standard error %.3g). The image is "
                   "reconstructed flat (element values) or Gouraud (vertex-interpolated); the surface error is the "
                   "RMS relative error of surface averages. Piecewise-constant radiosity has pointwise error O(h) "
                   "away from edges; surface averages converge faster (data/ground-truth.md). Observed order: the "
                   "slope of log error against log h.\n\n",
                ref->exr_path, ref->rmse_se);
        if (p->command)
            fprintf(f, "Command: `%s`\n\n", p->command);
        if (!note[0])
            fprintf(f, "![error against element size](meshing.png)\n\n");
        else
            fprintf(f, "**Note:** %s\n\n", note);
        fprintf(f, "| elements | h (mm) | RMSE flat | RMSE gouraud | surface error | seconds |\n|---|---|---|---|---|---|\n");
        for (size_t i = 0; i < nrows; i++)
            fprintf(f, "| %zu | %.4g | %.4g | %.4g | %.4g | %.3g |\n", rows[i].elements, rows[i].h, rows[i].rmse[0],
                    rows[i].rmse[1], rows[i].surface_err, rows[i].seconds);
        static const char *const what[3] = {"image RMSE, flat", "image RMSE, gouraud", "surface error"};
        fprintf(f, "\nObserved order (slope of log error against log h, 95%% CI):\n\n| error | order | 95%% CI |\n|---|---|---|\n");
        for (int k = 0; k < 3; k++) {
            if (fit[k].ok)
                fprintf(f, "| %s | %.3f | [%.3f, %.3f] |\n", what[k], fit[k].slope, fit[k].lo, fit[k].hi);
            else
                fprintf(f, "| %s | n/a | |\n", what[k]);
        }
        fprintf(f, "\nColumns of meshing.csv: target_elements (the --elements asked), elements (made), h, "
                   "rmse_flat, rmse_gouraud (W sr^-1 m^-2), surface_err, seconds (solver time of the flat run), "
                   "converged.\n");
        st = rp_out_close(&o, 1, err);
    }
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    return st;
}

/* ---------------------------------------------------------- progressive */

static rp_status exp_progressive(const rp_experiment_params *p, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    unsigned elements = p->quick ? 150 : 500;
    double shots = p->budget > 0 ? p->budget : (p->quick ? 300 : 4000);
    char list[512];
    snprintf(list, sizeof list,
             "southwell:elements=%u,southwell:elements=%u:ambient,southwell:elements=%u:overshoot=1.5,"
             "southwell:elements=%u:ambient:overshoot=1.5",
             elements, elements, elements, elements);
    char preface[1200];
    snprintf(preface, sizeof preface,
             "Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988) on the Cornell box with "
             "%u elements, checkpoints every doubling of the number of shots up to %g: classic shooting, with "
             "the ambient term shown (unshot power spread uniformly, sec. 4 of the paper), with overshooting "
             "(1.5 x the unshot radiosity), and both. The ambient term makes early images close to the answer "
             "in the mean; overshooting speeds the convergence of the residual. The chart against samples is "
             "the error per shot (samples = shots here).",
             elements, shots);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment progressive: error per shot",
                           .preface = preface, .samples_chart = 1, .samples_label = "shots",
                           .sheet = 1, .command = p->command};
    st = run_bench_scheduled(p, scene, path, list, RP_SCHEDULE_ITERATIONS, shots, 10, 1, REF_SPP(p), &out,
                             p->out_dir, NULL, NULL, err);
    rp_scene_destroy(scene);
    return st;
}

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
        char eps[32], area[32];
        snprintf(eps, sizeof eps, "%g", bf[k]);
        snprintf(area, sizeof area, "%g", bf[k] * 1e-4);
        const char *keys[2] = {"bf-epsilon", "min-area"};
        const char *values[2] = {eps, area};
        rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = p->threads,
                        .keys = keys, .values = values, .count = 2};
        rp_solver *s = NULL;
        double t0 = rp_clock();
        st = rp_solver_create(&rp_solver_hierarchical, scene, &o, &s, err);
        for (int i = 0; st == RP_OK && i < 1000; i++) {
            rp_step_info info;
            st = rp_solver_step(s, &info, err);
            if (st == RP_OK && info.converged)
                break;
        }
        if (st == RP_OK) {
            rp_hier_stats hs;
            rp_hierarchical_stats(rp_solver_state(s), &hs);
            leaves[k] = (double)hs.leaves;
            links[k] = (double)hs.links;
            seconds[k] = rp_clock() - t0;
            if (p->log) {
                char line[160];
                snprintf(line, sizeof line, "  hierarchical bf-epsilon %g: %zu leaves, %zu links, %.2f s", bf[k],
                         hs.leaves, hs.links, seconds[k]);
                p->log(p->log_ctx, line);
            }
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
        if (rp_gnuplot_run(p->out_dir, "links.gp", &gerr) != RP_OK && p->log)
            p->log(p->log_ctx, gerr.message);
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
                                 const char *key, const char *value, int threads, ffrow *row, rp_error *err)
{
    const char *keys[1] = {key}, *values[1] = {value};
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = threads, .keys = keys,
                    .values = values, .count = 1};
    size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    double *x = calloc(ns * nb, sizeof *x);
    if (!x)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_solver *s = NULL;
    double t0 = rp_clock();
    rp_status st = rp_solver_create(t, scene, &o, &s, err);
    row->form_factors = 0;
    for (int i = 0; st == RP_OK && i < 100000; i++) {
        rp_step_info info;
        memset(&info, 0, sizeof info);
        st = rp_solver_step(s, &info, err);
        row->form_factors += info.form_factors;
        if (st == RP_OK && info.converged)
            break;
    }
    row->seconds = rp_clock() - t0;
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
    rp_status st = hierarchy_solve(scene, ref, gs, "elements", elements, p->threads, &rows[0], err);
    for (size_t k = 0; k < n && st == RP_OK; k++)
        st = hierarchy_solve(scene, ref, &rp_solver_hierarchical, "bf-epsilon", bf[k], p->threads, &rows[k + 1],
                             err);
    if (st != RP_OK)
        return st;
    if (p->log)
        for (size_t k = 0; k <= n; k++) {
            char line[256];
            snprintf(line, sizeof line, "  %.63s: %.4g form factors, surface error %.3f%%, %.2f s", rows[k].spec,
                     rows[k].form_factors, 100 * rows[k].error, rows[k].seconds);
            p->log(p->log_ctx, line);
        }
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

static rp_status exp_hierarchy(const rp_experiment_params *p, rp_error *err)
{
    const rp_solver_type *t = rp_solver_lookup("hierarchical");
    if (!t)
        return rp_error_set(err, RP_ERR_UNSUPPORTED,
                            "experiment hierarchy: the method 'hierarchical' is not registered in this build; "
                            "not available");
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    double budget = p->budget > 0 ? p->budget : (p->quick ? 2.0 : 20.0);
    const char *list = p->quick ? "hierarchical,gauss-seidel:elements=250"
                                : "hierarchical,gauss-seidel:elements=1000,southwell:elements=1000";
    rp_bench_output out = {.size = sizeof out, .title = "Experiment hierarchy: hierarchical radiosity",
                           .preface = "Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991) against the "
                                      "classic solvers at equal time on the Cornell box.",
                           .sheet = 1, .command = p->command};
    rp_reference *ref = NULL;
    st = run_bench(p, scene, path, list, budget, 1, REF_SPP(p), &out, p->out_dir, NULL, &ref, err);
    if (st == RP_OK)
        st = hierarchy_form_factors(p, scene, ref, err);
    if (st == RP_OK)
        st = hierarchy_links(p, scene, err);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    return st;
}

/* ------------------------------------------------------------- registry */

static const rp_experiment experiments[] = {
    {"cornell", "all methods at equal time on the Cornell box", exp_cornell},
    {"samplers", "random, stratified and Sobol' sampling: RMSE against spp and slopes", exp_samplers},
    {"furnace", "reflectance 0.1 to 0.99: sweeps and time to tolerance, iterative solvers and path tracer",
     exp_furnace},
    {"formfactors", "analytic, Monte Carlo and hemicube form factors against Howell's closed forms",
     exp_formfactors},
    {"meshing", "radiosity error against element size, observed order", exp_meshing},
    {"progressive", "progressive radiosity with and without ambient term and overshooting: error per shot",
     exp_progressive},
    {"hierarchy", "hierarchical radiosity against the classic solvers, and links against leaves as bf-epsilon "
                  "shrinks (when registered)", exp_hierarchy},
    {"stability", "the stability atlas: each method pushed past its comfort zone (reflectance near 1, tiny lights, "
                  "corners, contact, shadows, thin geometry, non-physical input)", rp_exp_stability},
    {"realscenes", "published OBJ/MTL scenes and scanned meshes: every method against the path tracer per "
                   "surface, time and memory", rp_exp_realscenes},
};

static const rp_experiment *const experiment_list[] = {&experiments[0], &experiments[1], &experiments[2],
                                                       &experiments[3], &experiments[4], &experiments[5],
                                                       &experiments[6], &experiments[7], &experiments[8], NULL};

const rp_experiment *const *rp_experiments(void) { return experiment_list; }

const rp_experiment *rp_experiment_lookup(const char *name)
{
    for (const rp_experiment *const *e = experiment_list; *e; e++)
        if (strcmp((*e)->name, name) == 0)
            return *e;
    return NULL;
}
