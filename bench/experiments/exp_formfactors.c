/* radpt experiment formfactors: form factors against Howell's closed forms. */
#include "bench/experiments/exp_internal.h"

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

/* ---------------------------------------------------------- formfactors */

/* Howell's catalog C-11: parallel, directly opposed rectangles a x b at
 * distance c (docs/ground-truth.md). */
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
         * scratch: the hemicube keeps the row it rasterised there.  The
         * loop also stops after 0.2 s in all, scratches included: under
         * mpirun Open MPI's memory hooks make each scratch's allocation a
         * system call, and 100,000 of them took minutes. */
        double spent = 0, v = 0, loop0 = rp_clock();
        size_t reps = 0;
        while (st == RP_OK && spent < 0.02 && reps < 100000 && rp_clock() - loop0 < 0.2) {
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

/* ff_measure for one row of the tables, recorded in the study's journal
 * as it finishes and read back on --resume (timings as first measured). */
static rp_status ff_unit(const rp_experiment_params *p, const ff_setup *s, const rp_ff_params *prm, unsigned nseeds,
                         double *F, double *rel_rms, double *seconds, rp_error *err)
{
    char key[200];
    snprintf(key, sizeof key, "formfactors %s exact %.17g %s tolerance %.17g samples %u resolution %u seeds %u",
             s->name, s->exact, rp_ff_method_name(prm->method), prm->tolerance, (unsigned)prm->samples,
             (unsigned)prm->resolution, nseeds);
    double rec[3];
    if (rp_exp_unit(p, key, rec, 3)) { /* recorded, or another rank's */
        *F = rec[0];
        *rel_rms = rec[1];
        *seconds = rec[2];
        return RP_OK;
    }
    if (rp_cancelled(p->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    rp_status st = ff_measure(s, prm, nseeds, F, rel_rms, seconds, err);
    if (st == RP_OK) {
        double v[3] = {*F, *rel_rms, *seconds};
        st = rp_journal_put_doubles(p->journal, key, v, 3, err);
    }
    return st;
}

rp_status rp_exp_formfactors(const rp_experiment_params *p, rp_error *err)
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
                if ((st = ff_unit(p, &su, &prm, ns, &F, &e, &secs, err)) != RP_OK)
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
            st = ff_unit(p, &su, &prm, ns, &F, &e, &secs, err);
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

