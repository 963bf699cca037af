/* radpt experiment discontinuity: where the elements go.
 *
 * Gauss-Seidel radiosity on uniform meshes and on discontinuity meshes
 * (elements that follow contact lines and the umbra and penumbra
 * boundaries of the lights: Heckbert 1992, "Discontinuity meshing for
 * radiosity"; Lischinski, Tampieri & Greenberg 1992) at equal element
 * counts, and hierarchical radiosity (refined where B x F asks: Hanrahan,
 * Salzman & Aupperle 1991), on the Cornell box and on McGuire's
 * CornellBox-Original (two boxes standing on the floor: contact shadows),
 * each scored against its path-traced reference; hierarchical radiosity
 * with the constant basis and with the linear one (--basis linear, Zatz
 * 1993).  Gauss-Seidel's images are flat (element values) or Gouraud
 * (values interpolated from the vertices: a linear reconstruction of the
 * constant solution).  The meshes at the middle count are drawn over the
 * reference (wireframe.h). */
#include "bench/experiments/exp_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/report/files.h"
#include "bench/report/wireframe.h"
#include "bench/run/journal.h"
#include "geometry/mesh.h"

#define DC_SCENES 2
#define DC_MODES 2
#define DC_MAXCOUNTS 3
#define DC_HR 4
/* The full form's refinement sweep of hierarchical radiosity from the
 * discontinuity mesh, constant and linear bases (error against time). */
#define DC_SWEEP 4
static const double dc_sweep_bf[DC_SWEEP] = {0.1, 0.05, 0.02, 0.01};
static const char *const dc_basis[2] = {"constant", "linear"};

static const char *const dc_scene_file[DC_SCENES] = {"cornell.scene", "real/CornellBox-Original.obj"};
static const char *const dc_scene_id[DC_SCENES] = {"cornell", "original"};
static const char *const dc_mode[DC_MODES] = {"uniform", "discontinuity"};
static const char *const dc_recon[2] = {"flat", "gouraud"};

typedef struct dc_row {
    size_t elements;
    double rmse[2];     /* flat, gouraud */
    double surface_err; /* the same for both reconstructions */
    double seconds;     /* the flat run's solver time */
    int converged;
} dc_row;

typedef struct dc_scene {
    rp_exp_start x;
    rp_reference *ref;
    dc_row rows[DC_MODES][DC_MAXCOUNTS];
    /* hierarchical radiosity from the faces and from their discontinuity
     * mesh (dc_hr) */
    double hr_rmse[DC_HR], hr_surface_err[DC_HR], hr_seconds[DC_HR];
    int hr_converged[DC_HR];
    /* the sweep (full form): [basis][bf-epsilon] */
    double sw_rmse[2][DC_SWEEP], sw_surface_err[2][DC_SWEEP], sw_seconds[2][DC_SWEEP];
    int sw_converged[2][DC_SWEEP];
} dc_scene;

static const char *const dc_hr_spec[DC_HR] = {"hierarchical", "hierarchical:mesh=discontinuity",
                                              "hierarchical:basis=linear",
                                              "hierarchical:mesh=discontinuity:basis=linear"};
/* the quick form's setting, run until the sweeps converge */
static const char dc_hr_quick[] = ":bf-epsilon=0.05:min-area=1e-4:tolerance=1e-6";
static const char *const dc_hr_name[DC_HR] = {"hierarchical", "hierarchical-discontinuity", "hierarchical-linear",
                                              "hierarchical-discontinuity-linear"};

/* One run of spec to its rule (or the budget), read back from the journal
 * when recorded: v = rmse, surface_err, seconds, converged. */
static rp_status dc_unit(const rp_experiment_params *p, dc_scene *s, const char *id, const char *spec, double budget,
                         double v[4], rp_error *err)
{
    char key[256];
    snprintf(key, sizeof key, "discontinuity %s %s budget %.17g", id, spec, budget);
    if (rp_exp_unit(p, key, v, 4))
        return RP_OK;
    if (rp_cancelled(p->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    rp_method_spec m;
    rp_status st = rp_method_spec_parse(spec, &m, err);
    if (st != RP_OK)
        return st;
    rp_exp_log(p, "discontinuity: %s on %s", spec, s->x.path);
    rp_harness_params hp = {.size = sizeof hp, .budget = budget, .levels = 1, .threads = p->threads,
                            .stop_when_converged = 1, .progress = p->progress, .progress_ctx = p->progress_ctx,
                            .cancel = p->cancel};
    rp_trial run;
    if ((st = rp_harness_run(s->x.scene, s->ref, &m, 1, &hp, &run, err)) != RP_OK)
        return st;
    if (run.status != RP_OK)
        st = rp_error_set(err, run.status, "%s: %s", spec, run.error);
    else if (!run.ncp)
        st = rp_error_set(err, RP_ERR_RUNTIME, "%s: no result within the budget", spec);
    else {
        const rp_checkpoint *cp = &run.cp[run.ncp - 1];
        v[0] = cp->rmse;
        v[1] = cp->surface_err;
        v[2] = cp->wall_s;
        v[3] = cp->converged;
        st = rp_journal_put_doubles(p->journal, key, v, 4, err);
        rp_exp_log(p, "  RMSE %.4g, surface error %.4g (%.2f s)", cp->rmse, cp->surface_err, cp->wall_s);
    }
    rp_trial_free(&run);
    return st;
}

/* The scene's mesh of mode at count elements, drawn over its reference. */
static rp_status dc_overlay(const rp_experiment_params *p, const dc_scene *s, int mode, unsigned count,
                            const char *file, rp_error *err)
{
    rp_mesh_params mp = {.size = sizeof mp, .target_count = count, .mode = mode ? RP_MESH_DISCONTINUITY : 0};
    rp_mesh *mesh = NULL;
    rp_status st = rp_mesh_create(s->x.scene, &mp, &mesh, err);
    if (st != RP_OK)
        return st;
    const rp_reference *r = s->ref;
    size_t npix = (size_t)r->width * r->height;
    float *planes[3] = {NULL, NULL, NULL};
    int have = r->radiance && r->nbands == 3;
    for (int c = 0; have && c < 3; c++)
        if (!(planes[c] = malloc(npix * sizeof(float))))
            have = 0;
    for (size_t i = 0; have && i < npix; i++)
        for (int c = 0; c < 3; c++)
            planes[c][i] = r->radiance[i * 3 + c];
    char path[1024];
    st = rp_wireframe_png(rp_path_join(path, sizeof path, p->out_dir, file), s->x.scene, mesh,
                          have ? (const float *const *)planes : NULL, NULL, err);
    for (int c = 0; c < 3; c++)
        free(planes[c]);
    rp_mesh_destroy(mesh);
    return st;
}

static rp_status dc_write(const rp_experiment_params *p, dc_scene *sc, const unsigned *counts, size_t nc,
                          rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "discontinuity.csv"), err);
    if (st != RP_OK)
        return st;
    fputs("scene,mesh,target_elements,elements,rmse_flat,rmse_gouraud,surface_err,seconds,converged\n", o.f);
    for (int s = 0; s < DC_SCENES; s++) {
        for (int m = 0; m < DC_MODES; m++)
            for (size_t c = 0; c < nc; c++) {
                const dc_row *w = &sc[s].rows[m][c];
                fprintf(o.f, "%s,%s,%u,%zu,", dc_scene_id[s], dc_mode[m], counts[c], w->elements);
                double v[4] = {w->rmse[0], w->rmse[1], w->surface_err, w->seconds};
                for (int k = 0; k < 4; k++) {
                    rp_exp_fnum(o.f, v[k]);
                    fputc(',', o.f);
                }
                fprintf(o.f, "%d\n", w->converged);
            }
        for (int h = 0; h < DC_HR; h++) {
            fprintf(o.f, "%s,%s,,,", dc_scene_id[s], dc_hr_name[h]);
            double v[4] = {NAN, sc[s].hr_rmse[h], sc[s].hr_surface_err[h], sc[s].hr_seconds[h]};
            for (int k = 0; k < 4; k++) {
                rp_exp_fnum(o.f, v[k]);
                fputc(',', o.f);
            }
            fprintf(o.f, "%d\n", sc[s].hr_converged[h]);
        }
        for (int b = 0; b < 2 && !p->quick; b++)
            for (int k = 0; k < DC_SWEEP; k++) {
                fprintf(o.f, "%s,hierarchical-discontinuity-%s-bf%g,,,", dc_scene_id[s], dc_basis[b], dc_sweep_bf[k]);
                double v[4] = {NAN, sc[s].sw_rmse[b][k], sc[s].sw_surface_err[b][k], sc[s].sw_seconds[b][k]};
                for (int i = 0; i < 4; i++) {
                    rp_exp_fnum(o.f, v[i]);
                    fputc(',', o.f);
                }
                fprintf(o.f, "%d\n", sc[s].sw_converged[b][k]);
            }
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    /* gnuplot data, one block per scene and mesh: elements, rmse_flat,
     * rmse_gouraud, surface_err, seconds; then hierarchical's point */
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "discontinuity.dat"), err)) != RP_OK)
        return st;
    for (int s = 0; s < DC_SCENES; s++) {
        for (int m = 0; m < DC_MODES; m++) {
            fprintf(o.f, "# %s %s\n", dc_scene_id[s], dc_mode[m]);
            for (size_t c = 0; c < nc; c++) {
                const dc_row *w = &sc[s].rows[m][c];
                fprintf(o.f, "%zu ", w->elements);
                double v[4] = {w->rmse[0], w->rmse[1], w->surface_err, w->seconds};
                for (int k = 0; k < 4; k++) {
                    rp_exp_dnum(o.f, v[k]);
                    fputc(k < 3 ? ' ' : '\n', o.f);
                }
            }
            fputs("\n\n", o.f);
        }
        for (int h = 0; h < DC_HR; h++) {
            fprintf(o.f, "# %s %s\n? ", dc_scene_id[s], dc_hr_name[h]);
            double v[4] = {sc[s].hr_rmse[h], sc[s].hr_rmse[h], sc[s].hr_surface_err[h], sc[s].hr_seconds[h]};
            for (int k = 0; k < 4; k++) {
                rp_exp_dnum(o.f, v[k]);
                fputc(k < 3 ? ' ' : '\n', o.f);
            }
            fputs("\n\n", o.f);
        }
    }
    /* the sweep's blocks last (full form): index 12 + 2 s + basis */
    for (int s = 0; s < DC_SCENES && !p->quick; s++)
        for (int b = 0; b < 2; b++) {
            fprintf(o.f, "# %s hierarchical-discontinuity %s, bf-epsilon", dc_scene_id[s], dc_basis[b]);
            for (int k = 0; k < DC_SWEEP; k++)
                fprintf(o.f, " %g", dc_sweep_bf[k]);
            fputc('\n', o.f);
            for (int k = 0; k < DC_SWEEP; k++) {
                fputs("? ", o.f);
                double v[4] = {sc[s].sw_rmse[b][k], sc[s].sw_rmse[b][k], sc[s].sw_surface_err[b][k],
                               sc[s].sw_seconds[b][k]};
                for (int i = 0; i < 4; i++) {
                    rp_exp_dnum(o.f, v[i]);
                    fputc(i < 3 ? ' ' : '\n', o.f);
                }
            }
            fputs("\n\n", o.f);
        }
    return rp_out_close(&o, 1, err);
}

rp_status rp_exp_discontinuity(const rp_experiment_params *p, rp_error *err)
{
    static const unsigned counts_full[] = {250, 1000, 4000};
    static const unsigned counts_quick[] = {250, 1000};
    const unsigned *counts = p->quick ? counts_quick : counts_full;
    const size_t nc = p->quick ? 2 : 3, mid = 1;
    dc_scene *sc = calloc(DC_SCENES, sizeof *sc);
    if (!sc)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_status st = RP_OK;
    for (int s = 0; s < DC_SCENES && st == RP_OK; s++) {
        if ((st = rp_exp_begin(p, dc_scene_file[s], &sc[s].x, err)) != RP_OK)
            break;
        rp_reference_params rp = rp_exp_ref_params(p, sc[s].x.set.reference_spp);
        st = rp_reference_get(sc[s].x.scene, sc[s].x.path, &rp, &sc[s].ref, err);
    }
    /* Gauss-Seidel stops at its tolerance (budget: a cap); hierarchical
     * refines until its budget, 20 s, at its defaults.  The quick form runs
     * it to convergence at the coarse setting (dc_hr_quick: about 0.4 to
     * 1 s a run), not at the defaults cut short: a solve stopped part way
     * had 17 to 50% surface error, a figure of the budget, not the method */
    const double budget = sc[0].x.set.budget, hr_budget = 20;
    for (int s = 0; s < DC_SCENES && st == RP_OK; s++) {
        for (int m = 0; m < DC_MODES && st == RP_OK; m++)
            for (size_t c = 0; c < nc && st == RP_OK; c++) {
                dc_row *w = &sc[s].rows[m][c];
                rp_mesh_params mp = {.size = sizeof mp, .target_count = counts[c],
                                     .mode = m ? RP_MESH_DISCONTINUITY : RP_MESH_UNIFORM};
                rp_mesh *mesh = NULL;
                if ((st = rp_mesh_create(sc[s].x.scene, &mp, &mesh, err)) != RP_OK)
                    break;
                w->elements = rp_mesh_nelements(mesh);
                rp_mesh_destroy(mesh);
                for (int r = 0; r < 2 && st == RP_OK; r++) {
                    char spec[160];
                    snprintf(spec, sizeof spec, "gauss-seidel:elements=%u:mesh=%s:tolerance=1e-5:reconstruct=%s",
                             counts[c], dc_mode[m], dc_recon[r]);
                    double v[4];
                    if ((st = dc_unit(p, &sc[s], dc_scene_id[s], spec, budget, v, err)) != RP_OK)
                        break;
                    w->rmse[r] = v[0];
                    if (r == 0) {
                        w->surface_err = v[1];
                        w->seconds = v[2];
                        w->converged = (int)v[3];
                    }
                }
            }
        for (int h = 0; h < DC_HR && st == RP_OK; h++) {
            double v[4];
            char spec[160];
            snprintf(spec, sizeof spec, "%s%s", dc_hr_spec[h], p->quick ? dc_hr_quick : "");
            if ((st = dc_unit(p, &sc[s], dc_scene_id[s], spec, hr_budget, v, err)) == RP_OK) {
                sc[s].hr_rmse[h] = v[0];
                sc[s].hr_surface_err[h] = v[1];
                sc[s].hr_seconds[h] = v[2];
                sc[s].hr_converged[h] = (int)v[3];
            }
        }
        for (int b = 0; b < 2 && st == RP_OK && !p->quick; b++)
            for (int k = 0; k < DC_SWEEP && st == RP_OK; k++) {
                char spec[160];
                double v[4];
                /* a tolerance given: the run stops at convergence, its
                 * time is the time to converge (open-ended, hierarchical
                 * refines and sweeps until the budget) */
                snprintf(spec, sizeof spec, "hierarchical:mesh=discontinuity:bf-epsilon=%g:basis=%s:tolerance=1e-6",
                         dc_sweep_bf[k], dc_basis[b]);
                if ((st = dc_unit(p, &sc[s], dc_scene_id[s], spec, hr_budget, v, err)) == RP_OK) {
                    sc[s].sw_rmse[b][k] = v[0];
                    sc[s].sw_surface_err[b][k] = v[1];
                    sc[s].sw_seconds[b][k] = v[2];
                    sc[s].sw_converged[b][k] = (int)v[3];
                }
            }
    }
    if (st == RP_OK && rp_exp_handing_out(p))
        goto done;
    if (st == RP_OK)
        st = rp_mkdirs(p->out_dir, err);
    if (st == RP_OK)
        st = dc_write(p, sc, counts, nc, err);
    for (int s = 0; s < DC_SCENES && st == RP_OK; s++)
        for (int m = 0; m < DC_MODES && st == RP_OK; m++) {
            char file[96];
            snprintf(file, sizeof file, "mesh-%s-%s.png", dc_scene_id[s], dc_mode[m]);
            st = dc_overlay(p, &sc[s], m, counts[mid], file, err);
        }
    char note[256] = "";
    if (st == RP_OK) {
        char body[8192];
        snprintf(body, sizeof body,
                 "\n@PNG\nset output 'discontinuity.png'\nset logscale xy\nset format y '%%g'\n"
                 "set xlabel 'elements'\nset ylabel 'surface-average relative error (RMS)'\n"
                 "set title 'Gauss-Seidel at convergence: uniform and discontinuity meshes'\n"
                 "set key outside right\n"
                 "plot 'discontinuity.dat' index 0 using 1:4 with linespoints lw 2 pt 7 title 'Cornell, uniform', "
                 "'' index 1 using 1:4 with linespoints lw 2 pt 7 title 'Cornell, discontinuity', "
                 "'' index 6 using 1:4 with linespoints lw 2 pt 5 title 'Original, uniform', "
                 "'' index 7 using 1:4 with linespoints lw 2 pt 5 title 'Original, discontinuity'\n"
                 "@SVG\nset output 'discontinuity.svg'\nreplot\n"
                 "@PNG\nset output 'discontinuity_time.png'\nset xlabel 'solver wall time (s)'\n"
                 "set title 'Error against time (hierarchical: adaptive refinement)'\n"
                 "plot 'discontinuity.dat' index 0 using 5:4 with linespoints lw 2 pt 7 title 'Cornell, uniform', "
                 "'' index 1 using 5:4 with linespoints lw 2 pt 7 title 'Cornell, discontinuity', "
                 "'' index 2 using 5:4 with points pt 9 ps 2 title 'Cornell, hierarchical', "
                 "'' index 3 using 5:4 with points pt 8 ps 2 title 'Cornell, hierarchical from the discontinuity mesh', "
                 "'' index 4 using 5:4 with points pt 13 ps 2 title 'Cornell, hierarchical, linear basis', "
                 "'' index 5 using 5:4 with points pt 12 ps 2 title 'Cornell, hierarchical, discontinuity mesh, linear basis', "
                 "'' index 6 using 5:4 with linespoints lw 2 pt 5 title 'Original, uniform', "
                 "'' index 7 using 5:4 with linespoints lw 2 pt 5 title 'Original, discontinuity', "
                 "'' index 8 using 5:4 with points pt 11 ps 2 title 'Original, hierarchical', "
                 "'' index 9 using 5:4 with points pt 10 ps 2 title 'Original, hierarchical from the discontinuity mesh', "
                 "'' index 10 using 5:4 with points pt 15 ps 2 title 'Original, hierarchical, linear basis', "
                 "'' index 11 using 5:4 with points pt 14 ps 2 title 'Original, hierarchical, discontinuity mesh, linear basis'\n"
                 "@SVG\nset output 'discontinuity_time.svg'\nreplot\n%s"
                 "unset output\n",
                 p->quick ? ""
                          : "@PNG\nset output 'discontinuity_bases.png'\nset xlabel 'solver wall time (s)'\n"
                            "set title 'Hierarchical radiosity from the discontinuity mesh, bf-epsilon 0.1 to 0.01'\n"
                            "plot 'discontinuity.dat' index 12 using 5:4 with linespoints lw 2 pt 7 title 'Cornell, "
                            "constant basis', "
                            "'' index 13 using 5:4 with linespoints lw 2 pt 5 title 'Cornell, linear basis', "
                            "'' index 14 using 5:4 with linespoints lw 2 pt 9 title 'Original, constant basis', "
                            "'' index 15 using 5:4 with linespoints lw 2 pt 11 title 'Original, linear basis'\n"
                            "@SVG\nset output 'discontinuity_bases.svg'\nreplot\n");
        st = rp_exp_draw(p, body, note, sizeof note, err);
    }
    rp_out o;
    char path[1024];
    if (st == RP_OK && (st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err)) == RP_OK) {
        FILE *f = o.f;
        fprintf(f, "# Experiment discontinuity: where the elements go\n\n"
                   "Gauss-Seidel radiosity run to a relative residual of 1e-5 on uniform meshes (a regular grid per "
                   "face) and on discontinuity meshes (triangles whose edges follow the lines where surfaces touch, "
                   "D0, and the umbra and penumbra boundaries of the lights, D1: Heckbert 1992; Lischinski, "
                   "Tampieri & Greenberg 1992) at about the same element counts (the table lists those made), and "
                   "hierarchical radiosity (elements split where B x F asks: adaptive) %s for %g s at most, "
                   "its quadtrees starting from the faces as given and from the faces cut along their D0 and D1 "
                   "lines (`--mesh discontinuity`, no points inside a face), each with the constant basis (an element's "
                   "mean) and the linear one (`--basis linear`: Galerkin with linear elements, Zatz 1993); in the "
                   "full form also from the discontinuity mesh at `--bf-epsilon` 0.1, 0.05, 0.02 and 0.01 with each "
                   "basis, each run to convergence (error against time, `discontinuity_bases.png`). "
                   "Scenes: the Cornell box (`%s`) and "
                   "McGuire's CornellBox-Original (`%s`, two boxes standing on the floor). Each is scored against "
                   "its path-traced reference (surface error: RMS relative error of the surface averages; image "
                   "RMSE over the measured pixels). Gauss-Seidel's images are flat (element values) or Gouraud (vertex "
                   "values interpolated: a linear reconstruction of the constant solution).\n\n",
                p->quick ? "at `--bf-epsilon 0.05 --min-area 1e-4`, run until a sweep changes the energy by "
                           "less than 1e-6 (the quick form)"
                         : "with its defaults",
                hr_budget, sc[0].x.path, sc[1].x.path);
        if (p->command)
            fprintf(f, "Command: `%s`\n\n", p->command);
        for (int s = 0; s < DC_SCENES; s++)
            fprintf(f, "Reference for %s: `%s` (RMSE standard error %.3g, surface averages' RMS relative standard "
                       "error %.3g).\n\n",
                    dc_scene_id[s], sc[s].ref->exr_path, sc[s].ref->rmse_se, sc[s].ref->surface_rel_se);
        if (!note[0])
            fprintf(f, "![surface error against elements](discontinuity.png)\n\n"
                       "![surface error against time](discontinuity_time.png)\n\n%s",
                    p->quick ? "" : "![constant and linear bases, surface error against time](discontinuity_bases.png)\n\n");
        else
            fprintf(f, "**Note:** %s\n\n", note);
        fprintf(f, "| scene | mesh | elements | surface error | RMSE flat | RMSE Gouraud | seconds |\n"
                   "|---|---|---|---|---|---|---|\n");
        int holds = 1;
        for (int s = 0; s < DC_SCENES; s++) {
            for (int m = 0; m < DC_MODES; m++)
                for (size_t c = 0; c < nc; c++) {
                    const dc_row *w = &sc[s].rows[m][c];
                    fprintf(f, "| %s | %s | %zu | %.4g | %.4g | %.4g | %.3g |\n", dc_scene_id[s], dc_mode[m],
                            w->elements, w->surface_err, w->rmse[0], w->rmse[1], w->seconds);
                }
            for (int h = 0; h < DC_HR; h++)
                fprintf(f, "| %s | %s | | %.4g | | %.4g | %.3g |\n", dc_scene_id[s], dc_hr_name[h],
                        sc[s].hr_surface_err[h], sc[s].hr_rmse[h], sc[s].hr_seconds[h]);
            for (int b = 0; b < 2 && !p->quick; b++)
                for (int k = 0; k < DC_SWEEP; k++)
                    fprintf(f, "| %s | hierarchical-discontinuity, %s basis, bf-epsilon %g | | %.4g | | %.4g | %.3g |\n",
                            dc_scene_id[s], dc_basis[b], dc_sweep_bf[k], sc[s].sw_surface_err[b][k],
                            sc[s].sw_rmse[b][k], sc[s].sw_seconds[b][k]);
            for (size_t c = 0; c < nc; c++)
                holds &= sc[s].rows[1][c].surface_err < sc[s].rows[0][c].surface_err;
        }
        fprintf(f, "\nClaim: at the same element count asked the discontinuity mesh's surface error is below the uniform "
                   "mesh's on both scenes: **%s** in these runs.\n\n",
                holds ? "holds" : "does not hold");
        fprintf(f, "Meshes at %u elements over the reference (element boundaries in yellow):\n\n", counts[mid]);
        for (int s = 0; s < DC_SCENES; s++)
            fprintf(f, "| uniform | discontinuity |\n|---|---|\n| ![](mesh-%s-uniform.png) | "
                       "![](mesh-%s-discontinuity.png) |\n\n",
                    dc_scene_id[s], dc_scene_id[s]);
        int lin_holds = 1;
        for (int s = 0; s < DC_SCENES; s++)
            lin_holds &= sc[s].hr_surface_err[3] < sc[s].hr_surface_err[1];
        fprintf(f, "Claim: hierarchical radiosity from the discontinuity mesh has a lower surface error with the linear "
                   "basis than with the constant one on both scenes: **%s** in these runs%s.\n\n",
                lin_holds ? "holds" : "does not hold", p->quick ? " (at the quick form's coarse setting)" : "");
        fprintf(f, "Columns of discontinuity.csv: scene; mesh (uniform, discontinuity, hierarchical, "
                   "hierarchical-discontinuity, hierarchical-linear, hierarchical-discontinuity-linear, and in the "
                   "full form hierarchical-discontinuity-BASIS-bfEPS, the sweep); "
                   "target_elements (asked); elements (made); rmse_flat, rmse_gouraud (W sr^-1 m^-2); surface_err; "
                   "seconds (solver time of the flat run); converged. Hierarchical's image is its own "
                   "vertex reconstruction (rmse_gouraud column).\n");
        st = rp_out_close(&o, 1, err);
    }
done:
    for (int s = 0; s < DC_SCENES; s++) {
        rp_reference_destroy(sc[s].ref);
        rp_scene_destroy(sc[s].x.scene);
    }
    free(sc);
    return st;
}
