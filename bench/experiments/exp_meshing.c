/* radpt experiment meshing: radiosity error against element size. */
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

/* -------------------------------------------------------------- meshing */

rp_status rp_exp_meshing(const rp_experiment_params *p, rp_error *err)
{
    rp_exp_start x;
    rp_status st = rp_exp_begin(p, "cornell.scene", &x, err);
    if (st != RP_OK)
        return st;
    /* below about 150 elements the Cornell box's 27 surfaces get one or two
     * elements each and the error is not yet in its asymptotic regime */
    static const unsigned counts_full[] = {250, 500, 1000, 2000, 4000};
    static const unsigned counts_quick[] = {150, 300, 600};
    const unsigned *counts = p->quick ? counts_quick : counts_full;
    size_t nc = p->quick ? 3 : 5;
    static const char *const recon[2] = {"flat", "gouraud"};
    const double budget = x.set.budget;
    rp_reference *ref = NULL;
    rp_reference_params rp = rp_exp_ref_params(p, x.set.reference_spp);
    st = rp_reference_get(x.scene, x.path, &rp, &ref, err);
    const double area = rp_scene_total_area(x.scene);
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
        if ((st = rp_mesh_create(x.scene, &mp, &mesh, err)) != RP_OK)
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
            /* a run finished before an interruption is read back from the
             * study's journal, not run again */
            char key[200];
            snprintf(key, sizeof key, "meshing %s budget %.17g", spec, budget);
            double rec[4];
            if (rp_exp_unit(p, key, rec, 4)) { /* recorded, or another rank's */
                w->rmse[r] = rec[0];
                if (r == 0) {
                    w->surface_err = rec[1];
                    w->seconds = rec[2];
                    w->converged = (int)rec[3];
                }
                continue;
            }
            if (rp_cancelled(p->cancel)) {
                st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
                break;
            }
            rp_exp_log(p, "meshing: %s", spec);
            rp_harness_params hp = {.size = sizeof hp, .budget = budget, .levels = 1, .threads = p->threads,
                                    .stop_when_converged = 1, .progress = p->progress,
                                    .progress_ctx = p->progress_ctx, .cancel = p->cancel};
            rp_trial run;
            if ((st = rp_harness_run(x.scene, ref, &m, 1, &hp, &run, err)) != RP_OK)
                break;
            if (run.status == RP_OK && run.ncp) {
                const rp_checkpoint *cp = &run.cp[run.ncp - 1];
                double v[4] = {cp->rmse, cp->surface_err, cp->wall_s, cp->converged};
                st = rp_journal_put_doubles(p->journal, key, v, 4, err);
            }
            if (st == RP_OK && run.status != RP_OK)
                st = rp_error_set(err, run.status, "%s: %s", spec, run.error);
            else if (st == RP_OK && run.ncp) {
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
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(x.path, sizeof x.path, p->out_dir, "meshing.csv"), err)) == RP_OK) {
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
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(x.path, sizeof x.path, p->out_dir, "report.md"), err)) == RP_OK) {
        FILE *f = o.f;
        fprintf(f, "# Experiment meshing: error against element size\n\n"
                   "Gauss-Seidel radiosity on the Cornell box, run to a relative residual of 1e-5 at each mesh "
                   "size, scored against the path-traced reference `%s` (RMSE standard error %.3g). The image is "
                   "reconstructed flat (element values) or Gouraud (vertex-interpolated); the surface error is the "
                   "RMS relative error of surface averages. Piecewise-constant radiosity has pointwise error O(h) "
                   "away from edges; surface averages converge faster (docs/ground-truth.md). Observed order: the "
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
    rp_scene_destroy(x.scene);
    return st;
}

