/* radpt experiment realscenes: published OBJ/MTL scenes, and scanned meshes
 * placed in one, rendered and probed by the path tracer and by every
 * radiosity method that applies; per-surface agreement, time and memory.
 *
 * The path-traced reference (rp_reference_get: independent samples, its
 * own standard errors) is the yardstick, as the issue that asked for this
 * experiment judges: hierarchical radiosity within 3% and Gauss-Seidel
 * within 5% on every surface holding 2% or more of the scene's area.
 * Surfaces are compared on the mean over bands of their area-averaged
 * outgoing radiance; a difference within 4 standard errors of the
 * reference (the reference's own noise) counts as agreement whatever its
 * relative size, so a nearly black surface is not failed on noise. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/mesh.h"
#include "geometry/scene.h"
#include "solvers/radiosity/system.h"
#include "bench/report/files.h"
#include "bench/run/load.h"
#include "bench/experiments/exp_internal.h"
#include "bench/run/harness.h"
#include "bench/report/plot.h"
#include "bench/run/reference.h"

typedef struct real_scene {
    const char *id;    /* output subdirectory */
    const char *file;  /* under scenes/ */
    const char *what;  /* one line for the report */
} real_scene;

/* Origins and licences: scenes/README.md. */
static const real_scene real_scenes[] = {
    {"cornell-original", "real/CornellBox-Original.obj",
     "Morgan McGuire's CornellBox-Original, OBJ/MTL exactly as published (CRLF line endings, two exact "
     "duplicate faces, specular statements radpt ignores, a light that also reflects: Kd 0.78, Ke 17 12 4)"},
    {"cornell-sphere", "real/CornellBox-Sphere.obj",
     "McGuire's CornellBox-Sphere as published: two tessellated spheres (Kd 0.01: nearly black) in the box"},
    {"teapot", "real/teapot-box.scene",
     "The Utah teapot (McGuire's closed 15,704-triangle version) in McGuire's empty red-green box, placed by a "
     "format-1 scene (`mesh box mtl CornellBox-Empty-RG.obj`): a closed mesh above the clustering threshold"},
    {"elephant", "real/elephant-box.scene",
     "CGAL's elephant (5,558 faces, a closed scanned mesh) in McGuire's original box"},
    {"armadillo", "real/armadillo-box.scene",
     "CGAL's armadillo (52,000 faces) in McGuire's original box"},
};
#define NREAL (sizeof real_scenes / sizeof real_scenes[0])

/* What each method must reach on surfaces holding 2% or more of the area
 * (0: reported, no target). */
typedef struct real_method {
    const char *spec;
    const char *label;
    double target;
} real_method;

/* The harness runs methods open-ended (their default stopping rule does not
 * apply under a time budget), so each rule is given explicitly, at its
 * default value: a method stops where `radpt probe` would stop it. */
static const real_method real_methods[] = {
    {"hierarchical:tolerance=1e-6", "hierarchical", 0.03},
    {"gauss-seidel:reconstruct=gouraud:tolerance=1e-6", "Gauss-Seidel", 0.05},
    {"southwell:tolerance=1e-6", "progressive refinement", 0},
    {"stochastic-jacobi:regular=10", "stochastic Jacobi", 0},
    {"pathtrace", "path tracer, equal time", 0},
};
#define NMETHODS (sizeof real_methods / sizeof real_methods[0])

#define AREA_SHARE 0.02   /* surfaces compared against the targets */
#define SE_MULTIPLE 4.0   /* agreement within this many standard errors */

/* One surface of one scene against one method. */
typedef struct real_cmp {
    double value, rel, se_rel;
    int agree;     /* within SE_MULTIPLE reference SE, or relative diff under the target */
    int measured;  /* the method answered for surfaces */
} real_cmp;

typedef struct real_result {
    size_t nsurfaces, nfaces;
    double total_area;
    char **names;
    double *area_share;
    double *ref, *ref_se;          /* band means */
    int *compared;                 /* area share >= AREA_SHARE and not a pure emitter */
    real_cmp *cmp;                 /* nsurfaces * NMETHODS */
    double seconds[NMETHODS], peak_mb[NMETHODS];
    int converged[NMETHODS], ran[NMETHODS];
    char error[NMETHODS][160];
    char skipped[NMETHODS][200];   /* why a method was not run, or "" */
    char spec[NMETHODS][256];      /* the spec as run */
    double max_rel[NMETHODS], rms_rel[NMETHODS];
    size_t fails[NMETHODS];
    unsigned long ref_spp, ref_samples;
} real_result;

static void result_free(real_result *r)
{
    for (size_t i = 0; r->names && i < r->nsurfaces; i++)
        free(r->names[i]);
    free(r->names);
    free(r->area_share);
    free(r->ref);
    free(r->ref_se);
    free(r->compared);
    free(r->cmp);
    memset(r, 0, sizeof *r);
}

static double band_mean(const double *v, size_t nb)
{
    double s = 0;
    for (size_t b = 0; b < nb; b++)
        s += v[b];
    return s / (double)nb;
}

/* Compares the surface averages of every run with the reference. */
static rp_status compare(const rp_scene *scene, const rp_reference *ref, const rp_bench *b, const size_t *map,
                         real_result *r, rp_error *err)
{
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    r->nsurfaces = ns;
    r->nfaces = rp_scene_nfaces(scene);
    r->total_area = rp_scene_total_area(scene);
    r->names = calloc(ns + 1, sizeof *r->names);
    r->area_share = calloc(ns + 1, sizeof *r->area_share);
    r->ref = calloc(ns + 1, sizeof *r->ref);
    r->ref_se = calloc(ns + 1, sizeof *r->ref_se);
    r->compared = calloc(ns + 1, sizeof *r->compared);
    r->cmp = calloc((ns + 1) * NMETHODS, sizeof *r->cmp);
    if (!r->names || !r->area_share || !r->ref || !r->ref_se || !r->compared || !r->cmp)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    for (size_t i = 0; i < ns; i++) {
        if (!(r->names[i] = strdup(surf[i].name)))
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        r->area_share[i] = surf[i].area / r->total_area;
        r->ref[i] = band_mean(ref->surface_radiance + i * nb, nb);
        /* bands of one path share their paths: their errors are correlated,
         * so the band mean's SE is taken as the mean SE (no 1/sqrt(nb)) */
        r->ref_se[i] = band_mean(ref->surface_stderr + i * nb, nb);
        r->compared[i] = r->area_share[i] >= AREA_SHARE && ref->surface_mask[i];
    }
    r->ref_spp = ref->spp;
    r->ref_samples = ref->samples;
    for (size_t bm = 0; bm < b->nmethods; bm++) {
        const size_t m = map[bm];
        const rp_trial *t = NULL;
        for (size_t k = 0; k < b->nruns; k++)
            if (b->runs[k].method == bm) {
                t = &b->runs[k];
                break;
            }
        if (!t)
            continue;
        r->ran[m] = 1;
        snprintf(r->spec[m], sizeof r->spec[m], "%s", b->methods[bm].text);
        if (t->status != RP_OK)
            snprintf(r->error[m], sizeof r->error[m], "%.150s", t->error);
        if (t->ncp) {
            const rp_checkpoint *cp = &t->cp[t->ncp - 1];
            r->seconds[m] = cp->wall_s;
            r->peak_mb[m] = cp->peak_rss_mb;
            r->converged[m] = cp->converged;
        }
        double ss = 0;
        size_t n = 0;
        r->max_rel[m] = NAN;
        for (size_t i = 0; i < ns && t->surfaces; i++) {
            real_cmp *c = &r->cmp[i * NMETHODS + m];
            c->measured = 1;
            c->value = band_mean(t->surfaces + i * nb, nb);
            double d = c->value - r->ref[i];
            c->rel = r->ref[i] > 0 ? d / r->ref[i] : (d == 0 ? 0 : INFINITY);
            c->se_rel = r->ref[i] > 0 ? r->ref_se[i] / r->ref[i] : 0;
            int within_se = fabs(d) <= SE_MULTIPLE * r->ref_se[i];
            double target = real_methods[m].target;
            c->agree = within_se || (target > 0 && fabs(c->rel) <= target);
            if (!r->compared[i])
                continue;
            if (isnan(r->max_rel[m]) || fabs(c->rel) > r->max_rel[m])
                r->max_rel[m] = fabs(c->rel);
            if (isfinite(c->rel)) {
                ss += c->rel * c->rel;
                n++;
            }
            if (target > 0 && !c->agree)
                r->fails[m]++;
        }
        r->rms_rel[m] = n ? sqrt(ss / (double)n) : NAN;
    }
    return RP_OK;
}

static void pct(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%+.2f%%", 100 * v);
    else
        fputs("n/a", f);
}

/* Writes DIR/agreement.csv (one row per surface and method) and the data
 * file the chart reads. */
static rp_status write_csv(const rp_experiment_params *p, const real_result *res, size_t nres, rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "agreement.csv"), err);
    if (st != RP_OK)
        return st;
    fputs("scene,surface,area_share,compared,reference,reference_se,method,value,relative_difference,agree\n", o.f);
    for (size_t s = 0; s < nres; s++)
        for (size_t i = 0; i < res[s].nsurfaces; i++)
            for (size_t m = 0; m < NMETHODS; m++) {
                const real_cmp *c = &res[s].cmp[i * NMETHODS + m];
                if (!c->measured)
                    continue;
                fprintf(o.f, "%s,", real_scenes[s].id);
                /* names may hold commas or quotes: CSV-quote them */
                fputc('"', o.f);
                for (const char *q = res[s].names[i]; *q; q++) {
                    if (*q == '"')
                        fputc('"', o.f);
                    fputc(*q, o.f);
                }
                fputc('"', o.f);
                fprintf(o.f, ",%.6g,%d,%.9g,%.3g,%s,%.9g,", res[s].area_share[i], res[s].compared[i], res[s].ref[i],
                        res[s].ref_se[i], res[s].spec[m], c->value);
                if (isfinite(c->rel))
                    fprintf(o.f, "%.6g", c->rel);
                fprintf(o.f, ",%d\n", c->agree);
            }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    /* chart data: one block per method (gnuplot `index`), ratio against
     * area share, compared surfaces only */
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "agreement.dat"), err)) != RP_OK)
        return st;
    for (size_t m = 0; m < NMETHODS; m++) {
        fprintf(o.f, "# %s\n", real_methods[m].spec);
        int any = 0;
        for (size_t s = 0; s < nres; s++)
            for (size_t i = 0; i < res[s].nsurfaces; i++) {
                const real_cmp *c = &res[s].cmp[i * NMETHODS + m];
                if (c->measured && res[s].compared[i] && isfinite(c->rel)) {
                    fprintf(o.f, "%.6g %.6g %.6g\n", res[s].area_share[i], 1 + c->rel, c->se_rel);
                    any = 1;
                }
            }
        if (!any)
            fputs("? ? ?\n", o.f);
        fputs("\n\n", o.f);
    }
    return rp_out_close(&o, 1, err);
}

static rp_status write_report(const rp_experiment_params *p, const real_result *res, size_t nres,
                              const char *chart_note, rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    fprintf(f, "# Experiment realscenes: scenes nobody in the project wrote\n\n"
               "Published OBJ/MTL scenes as their authors wrote them (duplicate and zero-area faces dropped "
               "with a warning, specular terms ignored with a warning: radpt models diffuse surfaces), and "
               "scanned meshes from CGAL's data set placed in one. Each is probed by a long path trace (the "
               "reference, with its standard errors) and by every radiosity method, each run to its own "
               "convergence rule or to %g s. Surfaces are compared on the mean over bands of their "
               "area-averaged radiance. Targets on every surface holding %.0f%% or more of the scene's area: "
               "hierarchical radiosity within 3%%, Gauss-Seidel within 5%%; a difference within %.0f reference "
               "standard errors also counts as agreement. Pure emitters are not compared (every method returns "
               "their Le). Origins and licences of the scenes: scenes/README.md.\n\n",
            p->budget > 0 ? p->budget : (p->quick ? 8.0 : 60.0), 100 * AREA_SHARE, SE_MULTIPLE);
    if (p->command)
        fprintf(f, "Command: `%s`\n\n", p->command);
    if (!chart_note[0])
        fprintf(f, "![method / path tracer per surface](agreement.png)\n\n");
    else
        fprintf(f, "**Note:** %s\n\n", chart_note);
    fprintf(f, "## Summary\n\n| scene | faces | method | seconds | peak MB | converged | largest difference | "
               "RMS difference | target | surfaces outside |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (size_t s = 0; s < nres; s++)
        for (size_t m = 0; m < NMETHODS; m++) {
            if (!res[s].ran[m])
                continue;
            fprintf(f, "| %s | %zu | %s | %.3g | %.0f | %s | ", real_scenes[s].id, res[s].nfaces, real_methods[m].label,
                    res[s].seconds[m], res[s].peak_mb[m],
                    res[s].error[m][0] ? "failed" : (res[s].converged[m] ? "yes" : "**no** (budget)"));
            pct(f, res[s].max_rel[m]);
            fputs(" | ", f);
            pct(f, res[s].rms_rel[m]);
            if (real_methods[m].target > 0)
                fprintf(f, " | %.0f%% | %zu |\n", 100 * real_methods[m].target, res[s].fails[m]);
            else
                fputs(" | | |\n", f);
        }
    for (size_t s = 0; s < nres; s++) {
        const real_result *r = &res[s];
        fprintf(f, "\n## %s\n\n%s. `scenes/%s`: %zu surfaces, %zu faces. Reference: %lu spp, %lu probe points "
                   "per surface. Per-method reports, charts and the image sheet: [%s/report.md](%s/report.md).\n\n",
                real_scenes[s].id, real_scenes[s].what, real_scenes[s].file, r->nsurfaces, r->nfaces, r->ref_spp,
                r->ref_samples, real_scenes[s].id, real_scenes[s].id);
        for (size_t m = 0; m < NMETHODS; m++) {
            if (r->error[m][0])
                fprintf(f, "* %s failed: %s\n", real_methods[m].label, r->error[m]);
            if (r->skipped[m][0])
                fprintf(f, "* %s %s.\n", real_methods[m].label, r->skipped[m]);
        }
        fprintf(f, "\n| surface | area | path tracer (SE) |");
        for (size_t m = 0; m < NMETHODS; m++)
            if (r->ran[m])
                fprintf(f, " %s |", real_methods[m].label);
        fprintf(f, "\n|---|---|---|");
        for (size_t m = 0; m < NMETHODS; m++)
            if (r->ran[m])
                fputs("---|", f);
        fputc('\n', f);
        for (size_t i = 0; i < r->nsurfaces; i++) {
            if (!(r->area_share[i] >= AREA_SHARE))
                continue;
            fputs("| `", f);
            for (const char *q = r->names[i]; *q; q++)
                fputc(*q == '|' ? '/' : *q, f);
            fprintf(f, "` | %.1f%% | %.4g (%.2f%%)%s |", 100 * r->area_share[i], r->ref[i],
                    r->ref[i] > 0 ? 100 * r->ref_se[i] / r->ref[i] : 0, r->compared[i] ? "" : " emitter");
            for (size_t m = 0; m < NMETHODS; m++) {
                if (!r->ran[m])
                    continue;
                const real_cmp *c = &r->cmp[i * NMETHODS + m];
                fputc(' ', f);
                if (!c->measured)
                    fputs("n/a", f);
                else {
                    int bad = r->compared[i] && real_methods[m].target > 0 && !c->agree;
                    if (bad)
                        fputs("**", f);
                    pct(f, c->rel);
                    if (bad)
                        fputs("**", f);
                }
                fputs(" |", f);
            }
            fputc('\n', f);
        }
        size_t small = 0;
        for (size_t i = 0; i < r->nsurfaces; i++)
            small += !(r->area_share[i] >= AREA_SHARE);
        if (small)
            fprintf(f, "\n%zu smaller surfaces are in agreement.csv.\n", small);
    }
    fprintf(f, "\nColumns of agreement.csv: scene, surface, area_share (of the scene's total area), compared "
               "(1: at least %.0f%% of the area and not a pure emitter), reference and reference_se (band mean "
               "of the path-traced surface average and its standard error, W sr^-1 m^-2), method (the spec as "
               "run), value (its band mean), relative_difference ((value - reference) / reference), agree "
               "(within the target or %.0f standard errors).\n",
            100 * AREA_SHARE, SE_MULTIPLE);
    return rp_out_close(&o, 1, err);
}

/* Builds the method list for one scene (map: bench index -> real_methods
 * index): --quick runs hierarchical radiosity at its fast setting (README:
 * the Cornell box's 0.25 s point), which converges within the quick budget
 * where the defaults do not.  Gauss-Seidel is left out, with the reason,
 * when its default mesh's matrix exceeds the dense cap: its rows would be
 * recomputed every sweep, and one sweep alone would outlast any budget
 * (the harness stops a run only between steps). */
static size_t method_list(const rp_experiment_params *p, const rp_scene *scene, char *buf, size_t n, size_t *map,
                          real_result *res)
{
    size_t elements = 0;
    rp_mesh *mesh = NULL;
    if (rp_mesh_create(scene, NULL, &mesh, NULL) == RP_OK)
        elements = rp_mesh_nelements(mesh);
    rp_mesh_destroy(mesh);
    const double matrix_bytes = 4.0 * (double)elements * (double)elements;
    buf[0] = '\0';
    size_t count = 0;
    for (size_t m = 0; m < NMETHODS; m++) {
        const char *spec = real_methods[m].spec;
        if (!strncmp(spec, "gauss-seidel", 12) && matrix_bytes >= (double)RP_RAD_DENSE_CAP) {
            snprintf(res->skipped[m], sizeof res->skipped[m],
                     "not run: its default mesh has %zu elements, a %.1f GiB form-factor matrix over the %zu MiB "
                     "cap, and one sweep of rows computed on the fly would outlast the budget",
                     elements, matrix_bytes / (1 << 30), (size_t)(RP_RAD_DENSE_CAP >> 20));
            continue;
        }
        if (p->quick && !strncmp(spec, "hierarchical:", 13))
            spec = "hierarchical:bf-epsilon=0.05:min-area=1e-4:tolerance=1e-6";
        size_t len = strlen(buf);
        snprintf(buf + len, n - len, "%s%s", count ? "," : "", spec);
        map[count++] = m;
    }
    return count;
}

static rp_status run_scene(const rp_experiment_params *p, const real_scene *rs, real_result *res, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, rs->file, path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_load_scene(path, NULL, 1, &scene, err)) != RP_OK)
        return st;
    rp_exp_log(p, "realscenes: %s (%zu faces)", rs->id, rp_scene_nfaces(scene));
    rp_experiment_setting set;
    if ((st = rp_experiment_setting_of(p, &set, err)) != RP_OK) {
        rp_scene_destroy(scene);
        return st;
    }
    const double budget = set.budget;
    rp_reference_params rp = {.size = sizeof rp, .spp = set.reference_spp, .cancel = p->cancel, .samples = p->quick ? 4096 : 65536,
                              .threads = p->threads, .cache_dir = p->cache_dir, .log = p->log, .log_ctx = p->log_ctx,
                              .progress = p->progress, .progress_ctx = p->progress_ctx};
    rp_reference *ref = NULL;
    rp_bench *b = NULL;
    rp_method_spec *methods = NULL;
    size_t nmethods = 0;
    char list[512];
    size_t map[NMETHODS];
    method_list(p, scene, list, sizeof list, map, res);
    st = rp_reference_get(scene, path, &rp, &ref, err);
    if (st == RP_OK)
        st = rp_method_list_parse(list, &methods, &nmethods, err);
    char dir[1024], prefix[128];
    rp_path_join(dir, sizeof dir, p->out_dir, rs->id);
    snprintf(prefix, sizeof prefix, "realscenes %s | ", rs->id);
    if (st == RP_OK)
        st = rp_mkdirs(dir, err);
    if (st == RP_OK) {
        rp_bench_params bp = {.size = sizeof bp, .nseeds = 1, .seed = 1, .log = p->log, .log_ctx = p->log_ctx,
                              .journal = p->journal, .journal_prefix = prefix, .image_dir = dir};
        bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = budget, .levels = 1,
                                     .schedule = RP_SCHEDULE_TIME, .threads = p->threads, .surfaces_for_mc = 1,
                                     .stop_when_converged = 1, .keep_image = 1, .progress = p->progress,
                                     .progress_ctx = p->progress_ctx, .cancel = p->cancel};
        st = rp_bench_run(scene, path, ref, methods, nmethods, &bp, &b, err);
    }
    if (st == RP_OK) {
        char title[256], note[256];
        snprintf(title, sizeof title, "Experiment realscenes: %s", rs->id);
        rp_bench_output out = {.size = sizeof out, .title = title, .preface = rs->what, .sheet = 1,
                               .command = p->command};
        st = rp_bench_write(b, dir, &out, note, err);
        if (st == RP_OK && b->interrupted)
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted after %zu of %zu runs", rs->id, b->nruns,
                              b->planned);
    }
    if (st == RP_OK)
        st = compare(scene, ref, b, map, res, err);
    free(methods);
    rp_bench_destroy(b);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    return st;
}

rp_status rp_exp_realscenes(const rp_experiment_params *p, rp_error *err)
{
    /* --quick: the two OBJ scenes as published */
    const size_t nscenes = p->quick ? 2 : NREAL;
    real_result res[NREAL];
    memset(res, 0, sizeof res);
    rp_status st = rp_mkdirs(p->out_dir, err);
    size_t done = 0;
    for (; done < nscenes && st == RP_OK; done++)
        st = run_scene(p, &real_scenes[done], &res[done], err);
    if (st == RP_OK)
        st = write_csv(p, res, nscenes, err);
    char note[256] = "";
    if (st == RP_OK) {
        char body[4096];
        size_t len = (size_t)snprintf(
            body, sizeof body,
            "\n@PNG\nset output 'agreement.png'\nset logscale x\nset format x '%%g'\n"
            "set xlabel 'surface area / scene area'\nset ylabel 'method / path tracer (band mean)'\n"
            "set title 'Real scenes: each method against the path-traced reference, per surface'\n"
            "set key outside right\nset yrange [0.85:1.15]\n"
            "plot 1.03 with lines dt 2 lc rgb '#888888' title '3%%', 0.97 with lines dt 2 lc rgb '#888888' "
            "notitle, 1.05 with lines dt 3 lc rgb '#444444' title '5%%', 0.95 with lines dt 3 lc rgb "
            "'#444444' notitle");
        for (size_t m = 0; m < NMETHODS && len < sizeof body; m++)
            len += (size_t)snprintf(body + len, sizeof body - len,
                                    ", 'agreement.dat' index %zu using 1:2 with points pt %zu ps 1.2 title '%s'", m,
                                    5 + 2 * m, real_methods[m].label);
        if (len < sizeof body)
            snprintf(body + len, sizeof body - len, "\n@SVG\nset output 'agreement.svg'\nreplot\nunset output\n");
        st = rp_exp_draw(p, body, note, sizeof note, err);
    }
    if (st == RP_OK)
        st = write_report(p, res, nscenes, note, err);
    for (size_t s = 0; s < NREAL; s++)
        result_free(&res[s]);
    return st;
}
