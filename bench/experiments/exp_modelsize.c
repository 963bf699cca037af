/* radpt experiment modelsize: which model each scene needs, and what each
 * method pays for the rest (issue 18).
 *
 * Part 1, scanned meshes in rooms (the bunny scene, CGAL's armadillo and
 * elephant in McGuire's box): the path tracer's probe and hierarchical
 * radiosity on the full meshes (clustered: Smits, Arvo & Greenberg 1994)
 * and on simplified solution meshes (--simplify: Garland & Heckbert 1997
 * edge collapse, geometry/simplify.h), each asked for surface averages
 * only, as `radpt probe --surface-averages` does.  Per run: solver time,
 * the memory the method holds, the model (faces solved on, leaves, links),
 * and the largest relative error of a surface average (per band, over the
 * surfaces that hold 2% of the area or more and do not only emit) against
 * the path-traced reference's surface averages.
 *
 * Part 2, growth: the bunny in its room at face counts from 10^3.5 to
 * 10^5 (10^6 in full): the published 75,408-triangle mesh, CGAL
 * simplifications of it below, and midpoint subdivisions above (the same
 * surface, four times the faces each).  Hierarchical radiosity with
 * --simplify auto and the path tracer at a fixed number of probe points:
 * time and memory against faces, with the fitted log-log slope and its 95%
 * interval (GSL least squares, rp_fit_loglog).  Every member is scored
 * against the published bunny's reference (the subdivided ones are the same
 * surface, the simplified ones within the distances logged). */
#include "bench/experiments/exp_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/cgal/simplify.h"
#include "geometry/scene.h"
#include "geometry/simplify.h"
#include "solvers/radiosity/hierarchical.h"
#include "bench/report/files.h"
#include "bench/report/gnuplot.h"
#include "bench/run/driver.h"
#include "bench/run/journal.h"
#include "bench/run/load.h"
#include "bench/run/metrics.h"

#define MS_AREA_SHARE 0.02
#define MS_MAXSCENES 3
#define MS_MAXMETHODS 5
#define MS_MAXSIZES 6
#define MS_NUM 6 /* seconds, MiB, faces, leaves, links, cluster links */

typedef struct ms_scene {
    const char *id, *file, *what;
} ms_scene;

static const ms_scene ms_scenes[MS_MAXSCENES] = {
    {"bunny", "bunny.scene", "the Stanford bunny (75,408 triangles) on the floor of a room lit by a ceiling panel"},
    {"elephant", "real/elephant-box.scene", "CGAL's elephant (5,558 triangles) in McGuire's CornellBox-Original"},
    {"armadillo", "real/armadillo-box.scene", "CGAL's armadillo (52,000 triangles) in McGuire's CornellBox-Original"},
};

typedef struct ms_method {
    const char *id;    /* methods.csv */
    const char *label; /* tables and charts */
    const char *type;
    const char *options; /* key=value pairs, ':'-separated; the quick setting adds MS_QUICK_HR */
} ms_method;

static const ms_method ms_methods[MS_MAXMETHODS] = {
    {"pathtrace", "path tracer", "pathtrace", ""},
    {"hierarchical:simplify=off", "hierarchical, full mesh", "hierarchical", "simplify=off"},
    {"hierarchical:simplify=auto", "hierarchical, simplify auto", "hierarchical", "simplify=auto"},
    {"hierarchical:simplify=0.02", "hierarchical, simplify 0.02", "hierarchical", "simplify=0.02"},
    {"gauss-seidel:simplify=0.02", "Gauss-Seidel, simplify 0.02", "gauss-seidel", "simplify=0.02"},
};

/* The quick form's hierarchical setting (the fast one of README). */
#define MS_QUICK_HR "bf-epsilon=0.05:min-area=2e-4"

typedef struct ms_run {
    double v[MS_NUM];
    double max_rel;      /* largest |relative error| of a compared surface average, any band */
    char worst[64];      /* that surface */
    int ran;
} ms_run;

/* Options "k=v:k=v" into arrays (at most 8). */
static size_t ms_split(char *text, const char **keys, const char **vals)
{
    size_t n = 0;
    for (char *tok = strtok(text, ":"); tok && n < 8; tok = strtok(NULL, ":")) {
        char *eq = strchr(tok, '=');
        if (!eq)
            continue;
        *eq = '\0';
        keys[n] = tok;
        vals[n] = eq + 1;
        n++;
    }
    return n;
}

/* One probe run to the method's rule: v[MS_NUM] then the surface averages
 * (ns x nb) into out. */
static rp_status ms_solve(const rp_experiment_params *p, const rp_scene *scene, const char *type_name,
                          const char *options, double *v, double *surf, rp_error *err)
{
    const rp_solver_type *t = rp_solver_lookup(type_name);
    if (!t)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "method '%s' is not registered", type_name);
    char text[256];
    snprintf(text, sizeof text, "%s", options);
    const char *keys[8], *vals[8];
    size_t n = ms_split(text, keys, vals);
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 1, .threads = p->threads, .keys = keys,
                    .values = vals, .count = n, .cancel = p->cancel, .log = p->log, .log_ctx = p->log_ctx};
    rp_solver *s = NULL;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_status st = rp_drive_create(t, scene, &o, &s, &tot, err);
    rp_drive_params dp = {.size = sizeof dp, .budget = 1e6, .schedule = RP_SCHEDULE_STEPS, .stop_at_rule = 1,
                          .cancel = p->cancel, .progress = p->progress, .progress_ctx = p->progress_ctx,
                          .label = type_name};
    if (st == RP_OK)
        st = rp_drive(s, &dp, &tot, err);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    if (st == RP_OK) {
        rp_estimate e = {.surface_radiance = surf};
        st = rp_solver_estimate(s, &e, err);
    }
    if (st == RP_OK) {
        v[0] = tot.wall_s;
        v[1] = tot.last.memory / (1 << 20);
        /* faces solved on: known for the path tracer (all) and hierarchical radiosity */
        v[2] = strcmp(type_name, "pathtrace") == 0 ? (double)rp_scene_nfaces(scene) : NAN;
        v[3] = v[4] = v[5] = NAN;
        if (t == &rp_solver_hierarchical) {
            rp_hier_stats hs;
            rp_hierarchical_stats(rp_solver_state(s), &hs);
            v[2] = (double)hs.faces;
            v[3] = (double)hs.leaves;
            v[4] = (double)hs.links;
            v[5] = (double)hs.cluster_links;
        }
    }
    rp_solver_destroy(s);
    return st;
}

/* The largest relative error of a compared surface's average, any band. */
static void ms_score(const rp_scene *scene, const rp_reference *ref, const double *surf, ms_run *r)
{
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    const rp_surface *sf = rp_scene_surfaces(scene);
    const rp_material *mat = rp_scene_materials(scene);
    const double total = rp_scene_total_area(scene);
    r->max_rel = 0;
    r->worst[0] = '\0';
    for (size_t i = 0; i < ns; i++) {
        if (sf[i].area < MS_AREA_SHARE * total || !ref->surface_mask[i] ||
            rp_material_pure_emitter(&mat[sf[i].material], nb))
            continue;
        for (size_t b = 0; b < nb; b++) {
            double rv = ref->surface_radiance[i * nb + b];
            if (!(rv > 0))
                continue;
            double e = fabs(surf[i * nb + b] / rv - 1);
            if (!(e <= r->max_rel)) {
                r->max_rel = e;
                snprintf(r->worst, sizeof r->worst, "%.60s", sf[i].name);
            }
        }
    }
}

/* A unit: one method on one scene, read back from the journal when
 * recorded. */
static rp_status ms_unit(const rp_experiment_params *p, const char *key, const rp_scene *scene,
                         const rp_reference *ref, const char *type, const char *options, ms_run *r, rp_error *err)
{
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene), nv = MS_NUM + ns * nb;
    double *v = calloc(nv, sizeof *v);
    if (!v)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_status st = RP_OK;
    int got = rp_exp_unit(p, key, v, nv);
    if (got == 0) {
        if (rp_cancelled(p->cancel))
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
        else {
            rp_exp_log(p, "modelsize: %s", key);
            st = ms_solve(p, scene, type, options, v, v + MS_NUM, err);
        }
        if (st == RP_OK)
            st = rp_journal_put_doubles(p->journal, key, v, nv, err);
    }
    if (st == RP_OK && got >= 0) {
        memcpy(r->v, v, sizeof r->v);
        ms_score(scene, ref, v + MS_NUM, r);
        r->ran = 1;
    }
    free(v);
    return st;
}

/* ---- the growth family ---- */

/* The scene with its mesh surface at about `faces` triangles. */
static rp_status family_member(const rp_scene *bunny, uint32_t surface, double faces, rp_scene **out,
                              char *note, size_t nn, rp_error *err)
{
    const rp_surface *sf = &rp_scene_surfaces(bunny)[surface];
    const rp_face *fc = rp_scene_faces(bunny);
    const rp_vec3 *V = rp_scene_vertices(bunny);
    const size_t nt = sf->nfaces, nall = rp_scene_nvertices(bunny);
    /* the surface's own vertices, renumbered */
    double *xyz = malloc(3 * nall * sizeof *xyz);
    uint32_t *tri = malloc(3 * nt * sizeof *tri), *slot = malloc(nall * sizeof *slot);
    if (!xyz || !tri || !slot) {
        free(xyz), free(tri), free(slot);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    size_t nvs = 0;
    for (size_t i = 0; i < nall; i++)
        slot[i] = RP_NONE;
    for (size_t f = 0; f < nt; f++)
        for (int k = 0; k < 3; k++) {
            uint32_t v = fc[sf->first_face + f].v[k];
            if (slot[v] == RP_NONE) {
                slot[v] = (uint32_t)nvs;
                xyz[3 * nvs] = V[v].x;
                xyz[3 * nvs + 1] = V[v].y;
                xyz[3 * nvs + 2] = V[v].z;
                nvs++;
            }
            tri[3 * f + k] = slot[v];
        }
    free(slot);
    rp_status st = RP_OK;
    rp_surface_triangles r = {xyz, nvs, tri, nt};
    rp_simplified simp;
    memset(&simp, 0, sizeof simp);
    double *sx = NULL;
    uint32_t *stt = NULL;
    if (faces < 0.9 * (double)nt) {
        char msg[256] = "";
        rp_simplify_params sp = {.ratio = faces / (double)nt, .tolerance = 0};
        if (rp_cgal_simplify(xyz, nvs, tri, nt, &sp, &simp, msg, sizeof msg) != 0)
            st = rp_error_set(err, RP_ERR_RUNTIME, "simplifying the bunny: %s", msg);
        else {
            r = (rp_surface_triangles){simp.xyz, simp.nvertices, simp.tri, simp.ntriangles};
            snprintf(note, nn, "CGAL simplification, within %.2g of the published mesh",
                     fmax(simp.max_distance_in, simp.max_distance_out));
        }
    } else if (faces > 1.5 * (double)nt) {
        double *cx = xyz;
        uint32_t *ct = tri;
        size_t cnv = nvs, cnt = nt;
        while ((double)cnt < 0.6 * faces && st == RP_OK) {
            double *nx;
            uint32_t *ntri;
            size_t nnv, nnt;
            if (!rp_triangles_subdivide(cx, cnv, ct, cnt, &nx, &nnv, &ntri, &nnt))
                st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
            else {
                if (cx != xyz)
                    free(cx), free(ct);
                cx = nx, ct = ntri, cnv = nnv, cnt = nnt;
            }
        }
        sx = cx != xyz ? cx : NULL;
        stt = ct != tri ? ct : NULL;
        r = (rp_surface_triangles){cx, cnv, ct, cnt};
        snprintf(note, nn, "midpoint subdivision of the published mesh (the same surface)");
    } else
        snprintf(note, nn, "the published mesh");
    if (st == RP_OK) {
        const size_t ns = rp_scene_nsurfaces(bunny);
        const rp_surface_triangles **rep = calloc(ns, sizeof *rep);
        if (!rep)
            st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        else {
            rep[surface] = &r;
            st = rp_scene_with_surfaces(bunny, rep, out, NULL, err);
            free(rep);
        }
    }
    rp_simplified_free(&simp);
    free(sx);
    free(stt);
    free(xyz);
    free(tri);
    return st;
}

/* ---- output ---- */

static void fnum(FILE *f, double v, const char *fmt)
{
    if (isfinite(v))
        fprintf(f, fmt, v);
    else
        fprintf(f, "-");
}

rp_status rp_exp_modelsize(const rp_experiment_params *p, rp_error *err)
{
    rp_experiment_setting set;
    rp_status st = rp_experiment_setting_of(p, &set, err);
    if (st == RP_OK)
        st = rp_mkdirs(p->out_dir, err);
    if (st != RP_OK)
        return st;
    const unsigned long samples = p->quick ? 65536 : 262144;
    const size_t nscenes = p->quick ? 2 : 3;
    /* The growth family: the elephant in quick (cheap), the bunny in full;
     * the published mesh is one member (its runs are part 1's). */
    static const double sizes_quick[] = {1400, 5558, 22232}, sizes_full[] = {3000, 10000, 30000, 75408, 301632, 1206528};
    const size_t grow_scene = p->quick ? 1 : 0;
    const char *grow_surface = p->quick ? "elephant" : "bunny";
    const double *sizes = p->quick ? sizes_quick : sizes_full;
    const size_t nsizes = p->quick ? 3 : 6;
    char pt_opts[128], hr_extra[64];
    snprintf(pt_opts, sizeof pt_opts, "samples=%lu:batch=8192", samples);
    snprintf(hr_extra, sizeof hr_extra, "%s", p->quick ? MS_QUICK_HR : "");

    ms_run runs[MS_MAXSCENES][MS_MAXMETHODS];
    ms_run grow[MS_MAXSIZES][2];
    memset(runs, 0, sizeof runs);
    memset(grow, 0, sizeof grow);
    double ref_se[MS_MAXSCENES] = {0};
    unsigned long ref_samples[MS_MAXSCENES] = {0};
    char grow_note[MS_MAXSIZES][160];
    memset(grow_note, 0, sizeof grow_note);
    double grow_faces[MS_MAXSIZES] = {0};

    for (size_t si = 0; si < nscenes && st == RP_OK; si++) {
        char path[1024];
        rp_scene *scene = NULL;
        rp_reference *ref = NULL;
        if ((st = rp_experiment_scene_path(p, ms_scenes[si].file, path, sizeof path, err)) != RP_OK ||
            (st = rp_load_scene(path, NULL, 1, &scene, err)) != RP_OK)
            break;
        rp_reference_params rp = rp_exp_ref_params(p, 4);
        rp.samples = p->quick ? 262144 : 2097152;
        if ((st = rp_reference_get(scene, path, &rp, &ref, err)) == RP_OK) {
            ref_se[si] = ref->surface_rel_se;
            ref_samples[si] = ref->samples;
        }
        for (size_t m = 0; m < MS_MAXMETHODS && st == RP_OK; m++) {
            const ms_method *mm = &ms_methods[m];
            if (p->quick && ((si == 0 && (m == 1 || m == 3)) || m == 4))
                continue; /* the bunny's full mesh (35-90 s) and 0.02, Gauss-Seidel: full form only */
            int hr = strcmp(mm->type, "hierarchical") == 0, gs = strcmp(mm->type, "gauss-seidel") == 0;
            char opts[256];
            snprintf(opts, sizeof opts, "%s%s%s", hr || gs ? mm->options : pt_opts,
                     hr && *mm->options && *hr_extra ? ":" : "", hr ? hr_extra : "");
            char key[512];
            snprintf(key, sizeof key, "modelsize %s %s %s", ms_scenes[si].id, mm->type, opts);
            st = ms_unit(p, key, scene, ref, mm->type, opts, &runs[si][m], err);
        }
        /* The growth family. */
        if (si == grow_scene && st == RP_OK) {
            uint32_t bunny = rp_scene_find_surface(scene, grow_surface);
            for (size_t k = 0; k < nsizes && st == RP_OK && bunny != RP_NONE; k++) {
                rp_scene *member = NULL;
                if (fabs(sizes[k] - (double)rp_scene_surfaces(scene)[bunny].nfaces) < 0.5) {
                    /* the published mesh: part 1's runs (simplify auto, the path tracer) */
                    grow_faces[k] = sizes[k];
                    grow[k][0] = runs[si][2];
                    grow[k][1] = runs[si][0];
                    snprintf(grow_note[k], sizeof grow_note[k], "the published mesh");
                    continue;
                }
                if ((st = family_member(scene, bunny, sizes[k], &member, grow_note[k], sizeof grow_note[k], err)) !=
                    RP_OK)
                    break;
                grow_faces[k] = (double)rp_scene_surfaces(member)[bunny].nfaces;
                char hopts[256];
                snprintf(hopts, sizeof hopts, "simplify=auto%s%s", *hr_extra ? ":" : "", hr_extra);
                const char *type[2] = {"hierarchical", "pathtrace"}, *opt[2] = {hopts, pt_opts};
                for (int m = 0; m < 2 && st == RP_OK; m++) {
                    char key[512];
                    snprintf(key, sizeof key, "modelsize growth %s %.0f %s %s", grow_surface, sizes[k], type[m], opt[m]);
                    st = ms_unit(p, key, member, ref, type[m], opt[m], &grow[k][m], err);
                }
                rp_scene_destroy(member);
            }
        }
        rp_reference_destroy(ref);
        rp_scene_destroy(scene);
    }
    if (st != RP_OK || rp_exp_handing_out(p))
        return st;

    /* Tables and charts. */
    char path[1200];
    rp_out o;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "methods.csv"), err)) != RP_OK)
        return st;
    fprintf(o.f, "scene,method,seconds,memory_mib,faces,leaves,links,cluster_links,max_surface_err,worst_surface\n");
    for (size_t si = 0; si < nscenes; si++)
        for (size_t m = 0; m < MS_MAXMETHODS; m++) {
            const ms_run *r = &runs[si][m];
            fprintf(o.f, "%s,%s", ms_scenes[si].id, ms_methods[m].id);
            for (int k = 0; k < MS_NUM; k++) {
                fputc(',', o.f);
                rp_exp_fnum(o.f, r->v[k]);
            }
            fputc(',', o.f);
            rp_exp_fnum(o.f, r->max_rel);
            fprintf(o.f, ",%s\n", r->worst);
        }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "growth.csv"), err)) != RP_OK)
        return st;
    fprintf(o.f, "faces,hr_seconds,hr_memory_mib,hr_faces_solved,hr_links,hr_max_surface_err,pt_seconds,pt_memory_mib,"
                 "pt_max_surface_err\n");
    for (size_t k = 0; k < nsizes; k++) {
        fprintf(o.f, "%.0f", grow_faces[k]);
        const double cols[8] = {grow[k][0].v[0], grow[k][0].v[1], grow[k][0].v[2], grow[k][0].v[4],
                                grow[k][0].max_rel, grow[k][1].v[0], grow[k][1].v[1], grow[k][1].max_rel};
        for (int c = 0; c < 8; c++) {
            fputc(',', o.f);
            rp_exp_fnum(o.f, cols[c]);
        }
        fputc('\n', o.f);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;

    /* One data block per method for the scatter charts (gnuplot index). */
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "methods.dat"), err)) != RP_OK)
        return st;
    for (size_t m = 0; m < MS_MAXMETHODS; m++) {
        fprintf(o.f, "# %s: scene seconds memory_mib max_surface_err_percent\n", ms_methods[m].label);
        for (size_t si = 0; si < nscenes; si++) {
            fprintf(o.f, "%s ", ms_scenes[si].id);
            rp_exp_dnum(o.f, runs[si][m].v[0]);
            fputc(' ', o.f);
            /* a method that reports no memory of its own (the path tracer) has no point on the memory chart */
            rp_exp_dnum(o.f, runs[si][m].v[1] > 0 ? runs[si][m].v[1] : NAN);
            fputc(' ', o.f);
            rp_exp_dnum(o.f, runs[si][m].ran ? 100 * runs[si][m].max_rel : NAN);
            fputc('\n', o.f);
        }
        fprintf(o.f, "\n\n");
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;

    double gx[MS_MAXSIZES], gt[2][MS_MAXSIZES], gm[2][MS_MAXSIZES];
    for (size_t k = 0; k < nsizes; k++) {
        gx[k] = grow_faces[k];
        for (int m = 0; m < 2; m++) {
            gt[m][k] = grow[k][m].v[0];
            gm[m][k] = grow[k][m].v[1];
        }
    }
    rp_fit ft[2], fm[2];
    for (int m = 0; m < 2; m++) {
        rp_fit_loglog(gx, gt[m], nsizes, 0.95, &ft[m]);
        rp_fit_loglog(gx, gm[m], nsizes, 0.95, &fm[m]);
    }

    /* error_time, error_memory: one point per scene and method */
    char pts[2][1600];
    for (int c = 0; c < 2; c++) {
        size_t at = 0;
        pts[c][0] = '\0';
        for (size_t m = 0; m < MS_MAXMETHODS; m++)
            at += (size_t)snprintf(pts[c] + at, at < sizeof pts[c] ? sizeof pts[c] - at : 0,
                                   "%s'methods.dat' index %zu using %d:4 with points pt %zu ps 1.5 title '%s', "
                                   "'methods.dat' index %zu using %d:4:1 with labels offset 1,0.6 font ',8' notitle",
                                   m ? ", \\\n       " : "", m, 2 + c, 5 + 2 * m, ms_methods[m].label, m, 2 + c);
    }
    char body[8000];
    snprintf(body, sizeof body,
             "set logscale x\nset key outside right\nset grid\n"
             "do for [t in 'png svg'] {\n"
             "  if (t eq 'png') { @PNG; set output 'error_time.png' } else { @SVG; set output 'error_time.svg' }\n"
             "  set title 'Surface averages: largest error against the path-traced reference, and solver time'\n"
             "  set xlabel 'solver seconds'\n  set ylabel 'largest surface error (%%)'\n"
             "  plot %s\n"
             "  if (t eq 'png') { @PNG; set output 'error_memory.png' } else { @SVG; set output 'error_memory.svg' }\n"
             "  set title 'Surface averages: largest error and the memory the method holds'\n"
             "  set xlabel 'MiB held by the method'\n"
             "  plot %s\n"
             "  if (t eq 'png') { @PNG; set output 'growth.png' } else { @SVG; set output 'growth.svg' }\n"
             "  set logscale xy\n  set datafile separator ','\n"
             "  set title 'One scanned mesh in its room at more and more faces'\n"
             "  set xlabel 'faces of the mesh'\n  set ylabel 'solver seconds, MiB'\n"
             "  plot 'growth.csv' skip 1 using 1:2 with linespoints pt 7 title sprintf('hierarchical, simplify auto: "
             "seconds (slope %%.2f)', %.6g), \\\n"
             "       'growth.csv' skip 1 using 1:3 with linespoints pt 5 title sprintf('hierarchical: MiB (slope "
             "%%.2f)', %.6g), \\\n"
             "       'growth.csv' skip 1 using 1:7 with linespoints pt 9 title sprintf('path tracer: seconds (slope "
             "%%.2f)', %.6g), \\\n"
             "       (x/%.6g)**0.5 * %.6g with lines dt 2 title 'faces^{0.5} (the target)'\n"
             "  unset logscale y\n  set datafile separator whitespace\n"
             "}\n",
             pts[0], pts[1], ft[0].slope, fm[0].slope, ft[1].slope, gx[0], gt[0][0]);
    char note[512] = "";
    if ((st = rp_exp_draw(p, body, note, sizeof note, err)) != RP_OK)
        return st;

    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "report.md"), err)) != RP_OK)
        return st;
    FILE *f = o.f;
    fprintf(f, "# Experiment modelsize: which model each scene needs\n\n");
    if (p->command)
        fprintf(f, "`%s`\n\n", p->command);
    fprintf(f,
            "Every run answers for surface averages only, as `radpt probe --surface-averages` does, and runs to "
            "its own stopping rule: the path tracer to %lu probe points per surface, hierarchical radiosity to "
            "its tolerance%s. Errors are the largest relative error of a surface average, in any band, over the "
            "surfaces holding %.0f%% of the area or more that do not only emit, against the path-traced "
            "reference's surface averages (independent samples; their standard error is given per scene). Time "
            "is solver time (set-up and steps, simplification included); memory is what the method reports "
            "holding (for hierarchical radiosity: nodes, radiosities and links; not the ray-casting structures; the path "
            "tracer reports none of its own beyond those, so it shows - and has no point on the memory chart).\n\n",
            samples, p->quick ? " at the fast setting `--bf-epsilon 0.05 --min-area 2e-4` (quick form)" : " (defaults)",
            100 * MS_AREA_SHARE);
    if (*note)
        fprintf(f, "%s\n\n", note);
    fprintf(f, "## What each method pays\n\n![error against time](error_time.png)\n\n"
               "![error against memory](error_memory.png)\n\n");
    for (size_t si = 0; si < nscenes; si++) {
        fprintf(f, "### %s\n\n%s. Reference: %lu probe points per surface, RMS relative standard error %.3f%%.\n\n",
                ms_scenes[si].id, ms_scenes[si].what, ref_samples[si], 100 * ref_se[si]);
        fprintf(f, "| method | seconds | MiB | faces solved on | leaves | links | cluster links | largest error "
                   "| on |\n|---|---|---|---|---|---|---|---|---|\n");
        for (size_t m = 0; m < MS_MAXMETHODS; m++) {
            const ms_run *r = &runs[si][m];
            if (!r->ran) {
                fprintf(f, "| %s | not run%s |  |  |  |  |  |  |  |\n", ms_methods[m].label,
                        p->quick ? " (full form only)" : "");
                continue;
            }
            fprintf(f, "| %s | ", ms_methods[m].label);
            fnum(f, r->v[0], "%.2f");
            fprintf(f, " | ");
            fnum(f, r->v[1] > 0 ? r->v[1] : NAN, "%.1f");
            fprintf(f, " | ");
            fnum(f, r->v[2], "%.0f");
            fprintf(f, " | ");
            fnum(f, r->v[3], "%.0f");
            fprintf(f, " | ");
            fnum(f, r->v[4], "%.0f");
            fprintf(f, " | ");
            fnum(f, r->v[5], "%.0f");
            fprintf(f, " | %.2f%% | %s |\n", 100 * r->max_rel, r->worst);
        }
        fprintf(f, "\n");
    }
    fprintf(f, "## Growth with the face count\n\n![growth](growth.png)\n\n"
               "The %s in its room (%s), at face counts made from the published mesh; hierarchical radiosity with "
               "`--simplify auto`%s, the path tracer at %lu probe points per surface; errors against the published "
               "mesh's reference.\n\n"
               "| faces | mesh | hierarchical s | MiB | faces solved on | links | largest error | on | path tracer s | "
               "largest error |\n|---|---|---|---|---|---|---|---|---|---|\n",
            grow_surface, ms_scenes[grow_scene].file, *hr_extra ? " at the fast setting" : "", samples);
    for (size_t k = 0; k < nsizes; k++) {
        fprintf(f, "| %.0f | %s | ", grow_faces[k], grow_note[k]);
        fnum(f, grow[k][0].v[0], "%.2f");
        fprintf(f, " | ");
        fnum(f, grow[k][0].v[1], "%.1f");
        fprintf(f, " | ");
        fnum(f, grow[k][0].v[2], "%.0f");
        fprintf(f, " | ");
        fnum(f, grow[k][0].v[4], "%.0f");
        fprintf(f, " | %.2f%% | %s | ", 100 * grow[k][0].max_rel, grow[k][0].worst);
        fnum(f, grow[k][1].v[0], "%.2f");
        fprintf(f, " | %.2f%% |\n", 100 * grow[k][1].max_rel);
    }
    const char *what[2] = {"hierarchical radiosity (simplify auto)", "the path tracer"};
    fprintf(f, "\nFitted log-log slopes against faces (GSL least squares, 95%% interval; the target is 0.5 or "
               "less):\n\n");
    for (int m = 0; m < 2; m++) {
        if (ft[m].ok)
            fprintf(f, "- %s, time: %.3f [%.3f, %.3f]\n", what[m], ft[m].slope, ft[m].lo, ft[m].hi);
        if (fm[m].ok && m == 0)
            fprintf(f, "- %s, memory: %.3f [%.3f, %.3f]\n", what[m], fm[m].slope, fm[m].lo, fm[m].hi);
    }
    return rp_out_close(&o, 1, err);
}
