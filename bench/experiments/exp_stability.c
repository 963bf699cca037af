/* radpt experiment stability: the stability atlas (issue 7).
 *
 * Scenes built to push each method past its comfort zone, each run by
 * every method that applies, each with the failure signature it shows, in
 * numbers: DIR/report.md (one section per scene family, tables and
 * charts), one CSV per section, gnuplot charts (PNG and SVG), PNG renders
 * and the scene texts in DIR/scenes/.  Every number written is checked:
 * a non-finite one fails the experiment (RP_ERR_RUNTIME) after the report
 * is written, with the offending quantity named.
 *
 * Sections (closed forms from docs/ground-truth.md and Howell's catalog):
 *   1 reflectance -> 1 in a closed room (the furnace, L = Le / (1 - rho));
 *   2 a shrinking light at constant power;
 *   3 corners and nearly touching surfaces (C-11, C-14 and superposition);
 *   4 a block on a floor with a non-conforming mesh (light/shadow leaks);
 *   5 a sharp shadow: error against element size at the boundary;
 *   6 thin and coincident geometry: acne and leaks against --ray-offset;
 *   7 non-physical input: refused, with the messages and exit status. */
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/radiosity/formfactor.h"
#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "bench/experiments/exp_internal.h"
#include "bench/run/driver.h"
#include "bench/run/harness.h"
#include "bench/report/image.h"
#include "bench/run/metrics.h"
#include "bench/report/plot.h"

/* ------------------------------------------------------------- plumbing */

typedef struct stab {
    const rp_experiment_params *p;
    int quick;
    FILE *md;             /* the report body, in memory */
    char *mdbuf;
    size_t mdlen;
    size_t nonfinite;     /* numbers that were not finite */
    char first_bad[160];
    char gp_note[256];
} stab;

/* Prints v with fmt (one conversion of a double); a non-finite v is
 * written as NONFINITE in the conversion's place, with fmt's text around
 * it (the csv separators), and counted (the experiment then fails). */
static void put(stab *S, FILE *f, const char *fmt, double v, const char *what)
{
    /* in the hand-out pass the units of other ranks are NaN, and nothing
     * written is kept (rp_exp_unit) */
    if (isfinite(v) || rp_exp_handing_out(S->p)) {
        fprintf(f, fmt, v);
        return;
    }
    const char *pc = strchr(fmt, '%');
    size_t pre = pc ? (size_t)(pc - fmt) : strlen(fmt);
    const char *post = pc ? pc + 1 + strcspn(pc + 1, "eEfFgGaA") : fmt + pre;
    fprintf(f, "%.*sNONFINITE%s", (int)pre, fmt, *post ? post + 1 : post);
    if (!S->nonfinite++)
        snprintf(S->first_bad, sizeof S->first_bad, "%s", what);
}

static const char *out_path(const stab *S, char *buf, size_t n, const char *name)
{
    return rp_path_join(buf, n, S->p->out_dir, name);
}

/* Saves text as DIR/scenes/NAME.scene (for people to rerun) and parses it. */
static rp_status stab_scene(stab *S, const char *name, const char *text, rp_scene **out, rp_error *err)
{
    char dir[1024], file[1200], path[1300];
    rp_status st = rp_mkdirs(out_path(S, dir, sizeof dir, "scenes"), err);
    if (st != RP_OK)
        return st;
    snprintf(file, sizeof file, "%s.scene", name);
    rp_out o;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, file), err)) != RP_OK)
        return st;
    fputs(text, o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    return rp_scene_parse(text, path, dir, out, err);
}

/* DIR/NAME.gp from the preamble and body, then gnuplot; a missing or
 * failing gnuplot is a note in the report, not a failure. */
static rp_status stab_plot(stab *S, const char *name, const char *body, rp_error *err)
{
    char path[1200], file[256];
    snprintf(file, sizeof file, "%s.gp", name);
    rp_out o;
    rp_status st = rp_out_open(&o, out_path(S, path, sizeof path, file), err);
    if (st != RP_OK)
        return st;
    rp_gnuplot_preamble(o.f, rp_gnuplot_png_terminal());
    fputs("set datafile separator ','\n", o.f);
    fputs(body, o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    rp_error gerr;
    if (rp_gnuplot_run(S->p->out_dir, file, &gerr) != RP_OK && !S->gp_note[0]) {
        snprintf(S->gp_note, sizeof S->gp_note, "charts not drawn: %.200s", gerr.message);
        rp_exp_log(S->p, "%s", S->gp_note);
    }
    return RP_OK;
}

/* A grey image as an sRGB PNG, scaled so that `white` maps to 1 (the
 * images of one family share it, so they compare), or by --exposure. */
static rp_status stab_png(stab *S, const char *name, const float *img, uint32_t w, uint32_t h, double white,
                          rp_error *err)
{
    char path[1200];
    rp_exposure ex = rp_exposure_fixed(white > 0 && isfinite(white) ? -log2(white) : 0);
    return rp_image_write_png(out_path(S, path, sizeof path, name), w, h, img, img, img,
                              S->p->exposure ? S->p->exposure : &ex, err);
}

/* One solver run to its own rule, a step count, a time budget or (exact >
 * 0) until every surface average is within tol of exact. */
typedef struct sopt {
    unsigned want;
    double budget;          /* seconds of solver time */
    unsigned long max_steps;/* 0: none */
    double exact, tol;
    uint64_t seed;          /* 0: 1 */
    int threads;            /* 0: the experiment's */
} sopt;

typedef struct srun {
    double seconds, rays, paths, iterations, ff, steps;
    int converged, reached;
    size_t ns, nb, npix;
    uint32_t w, h;
    double *surf, *se;      /* ns * nb */
    float *img, *var;       /* npix * nb */
} srun;

static void srun_free(srun *r)
{
    free(r->surf);
    free(r->se);
    free(r->img);
    free(r->var);
    memset(r, 0, sizeof *r);
}

static double worst_rel(const srun *r, double exact)
{
    double worst = 0;
    for (size_t i = 0; i < r->ns * r->nb; i++) {
        double d = fabs(r->surf[i] - exact) / exact;
        worst = d > worst || !isfinite(d) ? d : worst;
    }
    return worst;
}

/* After each step of a stability run: with a closed form, stop once the
 * worst surface is within tol of it; stop at max_steps. */
typedef struct stab_check {
    srun *r;
    const sopt *so;
} stab_check;

static int stab_after_step(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    stab_check *sk = ctx;
    if (sk->so->exact > 0) {
        rp_estimate e = {.surface_radiance = sk->r->surf, .surface_stderr = sk->r->se};
        if ((*st = rp_solver_estimate(s, &e, err)) != RP_OK)
            return 1;
        if (worst_rel(sk->r, sk->so->exact) <= sk->so->tol) {
            sk->r->reached = 1;
            return 1;
        }
    }
    return sk->so->max_steps && t->steps >= sk->so->max_steps;
}

/* A run as a journal record: its counts, then the surface averages and
 * their standard errors, then the image and its variance (each array only
 * where the run wants it); doubles as %.17g and floats as %.9g, both of
 * which read back bit-identical. */
static char *srun_pack(const srun *r)
{
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    if (!f)
        return NULL;
    double head[8] = {r->seconds, r->rays, r->paths, r->iterations, r->ff, r->steps, r->converged, r->reached};
    for (int i = 0; i < 8; i++)
        fprintf(f, "%s%.17g", i ? " " : "", head[i]);
    for (size_t i = 0; r->surf && i < r->ns * r->nb; i++)
        fprintf(f, " %.17g %.17g", r->surf[i], r->se[i]);
    for (size_t i = 0; r->img && i < r->npix * r->nb; i++)
        fprintf(f, " %.9g %.9g", r->img[i], r->var[i]);
    if (fclose(f) != 0) {
        free(buf);
        return NULL;
    }
    return buf;
}

/* Reads srun_pack's text into r (its arrays allocated for the same run);
 * 0 when the text does not hold exactly those numbers. */
static int srun_unpack(const char *text, srun *r)
{
    const char *p = text;
    char *end;
    double head[8];
    for (int i = 0; i < 8; i++, p = end)
        if (head[i] = strtod(p, &end), end == p)
            return 0;
    r->seconds = head[0];
    r->rays = head[1];
    r->paths = head[2];
    r->iterations = head[3];
    r->ff = head[4];
    r->steps = head[5];
    r->converged = (int)head[6];
    r->reached = (int)head[7];
    for (size_t i = 0; r->surf && i < r->ns * r->nb; i++) {
        if (r->surf[i] = strtod(p, &end), end == p)
            return 0;
        if (r->se[i] = strtod(p = end, &end), end == p)
            return 0;
        p = end;
    }
    for (size_t i = 0; r->img && i < r->npix * r->nb; i++) {
        if (r->img[i] = strtof(p, &end), end == p)
            return 0;
        if (r->var[i] = strtof(p = end, &end), end == p)
            return 0;
        p = end;
    }
    while (*p == ' ')
        p++;
    return *p == '\0';
}

static void srun_fill_nan(srun *r)
{
    r->seconds = r->rays = r->paths = r->iterations = r->ff = r->steps = NAN;
    for (size_t i = 0; r->surf && i < r->ns * r->nb; i++)
        r->surf[i] = r->se[i] = NAN;
    for (size_t i = 0; r->img && i < r->npix * r->nb; i++)
        r->img[i] = r->var[i] = NAN;
}

static rp_status srun_do(stab *S, const rp_scene *sc, const char *spec, const sopt *so, srun *r, rp_error *err)
{
    memset(r, 0, sizeof *r);
    rp_method_spec m;
    rp_status st = rp_method_spec_parse(spec, &m, err);
    if (st != RP_OK)
        return st;
    rp_options o = {.size = sizeof o, .want = so->want, .seed = so->seed ? so->seed : 1,
                    .threads = so->threads ? so->threads : S->p->threads, .keys = m.keys, .values = m.values, .count = m.count,
                    .cancel = S->p->cancel};
    r->ns = rp_scene_nsurfaces(sc);
    r->nb = rp_scene_nbands(sc);
    const rp_camera *cam = rp_scene_camera(sc);
    if ((so->want & RP_WANT_IMAGE) && !cam)
        return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no camera", spec);
    if (so->want & RP_WANT_IMAGE) {
        r->w = cam->width;
        r->h = cam->height;
        r->npix = (size_t)r->w * r->h;
        r->img = calloc(r->npix * r->nb, sizeof *r->img);
        r->var = calloc(r->npix * r->nb, sizeof *r->var);
    }
    if (so->want & RP_WANT_SURFACES) {
        r->surf = calloc(r->ns * r->nb, sizeof *r->surf);
        r->se = calloc(r->ns * r->nb, sizeof *r->se);
    }
    if (((so->want & RP_WANT_IMAGE) && (!r->img || !r->var)) ||
        ((so->want & RP_WANT_SURFACES) && (!r->surf || !r->se))) {
        srun_free(r);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    /* a run finished before an interruption is read back from the study's
     * journal; in the hand-out pass, another rank's run is skipped */
    char hash[17], key[400];
    rp_scene_hash(sc, hash);
    snprintf(key, sizeof key, "stability run %s scene %s want %u budget %.17g max-steps %lu exact %.17g tol %.17g "
             "seed %llu", spec, hash, so->want, so->budget, so->max_steps, so->exact, so->tol,
             (unsigned long long)o.seed);
    int unit = rp_exp_unit(S->p, key, NULL, 0);
    if (unit < 0) {
        srun_fill_nan(r);
        return RP_OK;
    }
    if (unit > 0) {
        if (srun_unpack(rp_journal_get(S->p->journal, key), r))
            return RP_OK;
        srun_free(r);
        return rp_error_set(err, RP_ERR_INPUT, "%s: the record '%s' does not fit this run",
                            rp_journal_path(S->p->journal), key);
    }
    if (rp_cancelled(S->p->cancel)) {
        srun_free(r);
        return rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    }
    rp_solver *s = NULL;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    st = rp_drive_create(m.type, sc, &o, &s, &tot, err);
    stab_check sk = {.r = r, .so = so};
    rp_drive_params dp = {.size = sizeof dp, .budget = so->budget, .budget_base = tot.wall_s, .stop_at_rule = 1,
                          .cancel = S->p->cancel, .after_step = stab_after_step, .ctx = &sk};
    if (st == RP_OK)
        st = rp_drive(s, &dp, &tot, err);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    r->seconds = tot.wall_s;
    r->steps = tot.steps;
    r->rays = tot.sum.rays;
    r->paths = tot.sum.paths;
    r->iterations = tot.sum.iterations;
    r->ff = tot.sum.form_factors;
    /* met its rule, not stopped first by the closed form's tolerance */
    r->converged = tot.stop == RP_STOP_RULE && !r->reached;
    if (st == RP_OK) {
        rp_estimate e = {.radiance = r->img, .variance = r->var, .surface_radiance = r->surf,
                         .surface_stderr = r->se};
        st = rp_solver_estimate(s, &e, err);
    }
    rp_solver_destroy(s);
    rp_exp_log(S->p, "  %s: %.2f s solver time, %.0f steps", spec, r->seconds, r->steps);
    if (st == RP_OK) {
        char *text = srun_pack(r);
        st = text ? rp_journal_put(S->p->journal, key, text, err) : rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        free(text);
    }
    if (st != RP_OK) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", err ? err->message : "");
        srun_free(r);
        return rp_error_set(err, st, "%s: %s", spec, msg);
    }
    return RP_OK;
}

static double surf_of(const rp_scene *sc, const srun *r, const char *name)
{
    uint32_t i = rp_scene_find_surface(sc, name);
    return i == RP_NONE ? NAN : r->surf[i * r->nb];
}
static double se_of(const rp_scene *sc, const srun *r, const char *name)
{
    uint32_t i = rp_scene_find_surface(sc, name);
    return i == RP_NONE ? NAN : r->se[i * r->nb];
}

/* ------------------------------------------------- closed forms (Howell) */

/* Parallel rectangles in general position (Howell's catalog C-13, by
 * superposition of the corner-to-corner function G): A1 = [x1,x2]x[y1,y2]
 * at z = 0, A2 = [e1,e2]x[n1,n2] at z = c, facing each other; F from A1. */
static double gpar(double x, double y, double c)
{
    double a = sqrt(y * y + c * c), b = sqrt(x * x + c * c);
    return x * a * atan(x / a) + y * b * atan(y / b) - 0.5 * c * c * log(x * x + y * y + c * c);
}

static double ff_parallel_general(double x1, double x2, double y1, double y2, double e1, double e2, double n1,
                                  double n2, double c)
{
    const double xs[2] = {x1, x2}, ys[2] = {y1, y2}, es[2] = {e1, e2}, ns[2] = {n1, n2};
    double sum = 0;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++)
            for (int k = 0; k < 2; k++)
                for (int l = 0; l < 2; l++)
                    sum += ((i + j + k + l) % 2 ? -1.0 : 1.0) * gpar(xs[i] - es[k], ys[j] - ns[l], c);
    return sum / (2 * RP_PI * (x2 - x1) * (y2 - y1));
}

/* Differential area to a parallel rectangle with one corner above it
 * (Howell B-3), odd in a and b, so rectangles anywhere superpose. */
static double fpt_corner(double a, double b, double c)
{
    double A = a / c, B = b / c, sa = sqrt(1 + A * A), sb = sqrt(1 + B * B);
    return (A / sa * atan(B / sa) + B / sb * atan(A / sb)) / (2 * RP_PI);
}

static double ff_point_rect(double x0, double x1, double y0, double y1, double c)
{
    return fpt_corner(x1, y1, c) - fpt_corner(x0, y1, c) - fpt_corner(x1, y0, c) + fpt_corner(x0, y0, c);
}

/* Perpendicular unit squares with a gap g between the floor square and
 * the wall's foot: by superposition of C-14, A1 F12 = (1 + g) F(1 + g)
 * - g F(g), F(w) = howell_perpendicular(w, 1, 1). */
static double ff_perpendicular_gap(double g)
{
    double whole = (1 + g) * howell_perpendicular(1 + g, 1, 1);
    return g > 0 ? whole - g * howell_perpendicular(g, 1, 1) : whole;
}

/* ------------------------------------------------ 1. reflectance -> 1 */

typedef struct refl_row {
    double rho;
    const char *label;
    int reached;
    double seconds, iterations, sweeps, theory, error, rel_se, path_len, predicted;
    int iterative;
} refl_row;

static rp_status sec_reflectance(stab *S, rp_error *err)
{
    static const double rhos[3] = {0.9, 0.99, 0.999};
    const double tol = S->quick ? 1e-3 : 1e-4;
    const double budget = S->quick ? 0.7 : 6.0;
    const unsigned long pt_samples = S->quick ? 256 : 2048;
    const unsigned pt_depth = 20;
    char pts[128], ptd[128];
    snprintf(pts, sizeof pts, "pathtrace:samples=%lu:batch=%lu", pt_samples, pt_samples);
    snprintf(ptd, sizeof ptd, "pathtrace:samples=%lu:batch=%lu:max-depth=%u", pt_samples, pt_samples, pt_depth);
    /* ff-tolerance 1e-8: a row-sum defect d moves the answer by about
     * rho d / (1 - rho) (1000 d at rho = 0.999), below the tolerance */
    struct {
        const char *label, *spec;
        int track;   /* stop at the error tolerance */
    } M[] = {
        {"jacobi", "jacobi:elements=24:ff-tolerance=1e-8:tolerance=1e-14:max-iterations=10000000", 1},
        {"gauss-seidel", "gauss-seidel:elements=24:ff-tolerance=1e-8:tolerance=1e-14:max-iterations=10000000", 1},
        {"southwell", "southwell:elements=24:ff-tolerance=1e-8:tolerance=1e-14:max-iterations=100000000", 1},
        {"hierarchical",
         "hierarchical:bf-epsilon=0.1:min-area=1e-2:tolerance=1e-14:max-iterations=10000000", 1},
        {"direct (ff-tolerance 1e-9)", "direct:elements=24:ff-tolerance=1e-9", 0},
        {"direct (default ff-tolerance)", "direct:elements=24", 0},
        {"stochastic-jacobi", "stochastic-jacobi:elements=24:rays=4000", 0},
        {"pathtrace", pts, 0},
        {"pathtrace max-depth 20", ptd, 0},
    };
    const size_t nm = sizeof M / sizeof M[0];
    refl_row rows[3 * 16];
    size_t nrows = 0, nel = 0;
    double rowsum_default = NAN;
    rp_status st = RP_OK;
    for (size_t r = 0; r < 3 && st == RP_OK; r++) {
        const double rho = rhos[r], L = 1 / (1 - rho);
        char text[512], name[64];
        /* six faces as six surfaces, so the Monte Carlo methods report a
         * spread between them */
        snprintf(text, sizeof text,
                 "# furnace: every face reflects rho and emits 1, so L = 1 / (1 - rho) everywhere\n"
                 "bands grey\nmaterial wall reflect %.17g emit 1\n"
                 "quad floor wall 0 0 0  0 0 1  1 0 1  1 0 0\nquad ceiling wall 0 1 0  1 1 0  1 1 1  0 1 1\n"
                 "quad wx0 wall 0 0 0  0 1 0  0 1 1  0 0 1\nquad wx1 wall 1 0 0  1 0 1  1 1 1  1 1 0\n"
                 "quad wz0 wall 0 0 0  1 0 0  1 1 0  0 1 0\nquad wz1 wall 0 0 1  0 1 1  1 1 1  1 0 1\n",
                 rho);
        snprintf(name, sizeof name, "reflectance-%g", rho);
        rp_scene *sc = NULL;
        if ((st = stab_scene(S, name, text, &sc, err)) != RP_OK)
            break;
        if (!nel) {
            /* the area-weighted row sum of the default analytic form
             * factors (no occluders in a box: no visibility rays) */
            rp_mesh *mesh = NULL;
            rp_mesh_params mp = {.size = sizeof mp, .target_count = 24};
            rp_ff_context *ctx = NULL;
            rp_ff_scratch *scr = NULL;
            rp_ff_params fp = {.size = sizeof fp, .method = RP_FF_ANALYTIC};
            st = rp_mesh_create(sc, &mp, &mesh, err);
            if (st == RP_OK)
                st = rp_ff_context_create(sc, mesh, NULL, &fp, &ctx, err);
            if (st == RP_OK)
                st = rp_ff_scratch_create(ctx, &scr, err);
            if (st == RP_OK) {
                nel = rp_mesh_nelements(mesh);
                const rp_element *el = rp_mesh_elements(mesh);
                float *row = malloc(nel * sizeof *row);
                double num = 0, den = 0;
                for (size_t i = 0; row && i < nel; i++) {
                    rp_ff_row(ctx, scr, (uint32_t)i, row, NULL);
                    double sum = 0;
                    for (size_t j = 0; j < nel; j++)
                        sum += row[j];
                    num += el[i].area * sum;
                    den += el[i].area;
                }
                rowsum_default = row ? num / den : NAN;
                free(row);
            }
            rp_ff_scratch_destroy(scr);
            rp_ff_context_destroy(ctx);
            rp_mesh_destroy(mesh);
        }
        for (size_t k = 0; k < nm && st == RP_OK; k++) {
            rp_exp_log(S->p, "stability/reflectance rho %g: %s", rho, M[k].label);
            /* one thread: 24 elements do not pay for a parallel region
             * per sweep on a shared machine */
            sopt so = {.want = RP_WANT_SURFACES, .budget = budget, .exact = M[k].track ? L : 0, .tol = tol,
                       .threads = 1};
            srun run;
            if ((st = srun_do(S, sc, M[k].spec, &so, &run, err)) != RP_OK)
                break;
            refl_row *w = &rows[nrows++];
            memset(w, 0, sizeof *w);
            w->rho = rho;
            w->label = M[k].label;
            w->seconds = run.seconds;
            w->iterations = run.iterations;
            w->error = worst_rel(&run, L);
            double se = 0;
            for (size_t i = 0; i < run.ns; i++)
                se = run.se[i] / L > se ? run.se[i] / L : se;
            w->rel_se = se;
            w->reached = M[k].track ? run.reached : w->error <= tol;
            w->sweeps = strncmp(M[k].label, "southwell", 9) == 0 ? run.iterations / (double)nel : run.iterations;
            w->theory = log(tol) / log(rho) - 1;
            w->iterative = M[k].track;
            w->path_len = run.paths > 0 ? run.rays / run.paths : NAN;
            w->predicted = NAN;
            if (strstr(M[k].label, "default"))
                w->predicted = (1 - rho) / (1 - rho * rowsum_default) - 1;
            if (strstr(M[k].label, "max-depth"))
                w->predicted = -pow(rho, pt_depth + 1);
            if (strstr(M[k].label, "max-depth")) { /* signed mean error for the bias check */
                double mean = 0;
                for (size_t i = 0; i < run.ns; i++)
                    mean += run.surf[i] / (double)run.ns;
                w->error = (mean - L) / L;
            }
            rp_exp_log(S->p, "  %.3g s, %.0f iterations, error %.3g", run.seconds, run.iterations, w->error);
            srun_free(&run);
        }
        rp_scene_destroy(sc);
    }
    if (st != RP_OK)
        return st;

    char path[1200];
    rp_out o;
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "reflectance.csv"), err)) != RP_OK)
        return st;
    fputs("rho,one_minus_rho,method,within_tolerance,seconds,iterations,sweeps,jacobi_theory_sweeps,error,rel_stderr,"
          "rays_per_path,predicted_error\n",
          o.f);
    for (size_t i = 0; i < nrows; i++) {
        const refl_row *w = &rows[i];
        fprintf(o.f, "%g,%g,%s,%d,", w->rho, 1 - w->rho, w->label, w->reached);
        put(S, o.f, "%.6g,", w->seconds, "reflectance seconds");
        put(S, o.f, "%.8g,", w->iterations, "reflectance iterations");
        if (w->iterative) {
            put(S, o.f, "%.8g,", w->sweeps, "reflectance sweeps");
            put(S, o.f, "%.6g,", w->theory, "reflectance theory");
        } else {
            fputs(",,", o.f);
        }
        put(S, o.f, "%.6g,", w->error, "reflectance error");
        put(S, o.f, "%.6g,", w->rel_se, "reflectance stderr");
        if (isfinite(w->path_len))
            fprintf(o.f, "%.6g,", w->path_len);
        else
            fputs(",", o.f);
        if (isfinite(w->predicted))
            fprintf(o.f, "%.6g\n", w->predicted);
        else
            fputs("\n", o.f);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    /* gnuplot blocks, one per curve (index i) */
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "reflectance.dat"), err)) != RP_OK)
        return st;
    static const char *const curves[6] = {"jacobi", "gauss-seidel", "southwell", "hierarchical", "stochastic-jacobi",
                                          "pathtrace"};
    for (int c = 0; c < 7; c++) {
        fprintf(o.f, "# %s\n", c < 4 ? curves[c] : (c == 4 ? "jacobi theory" : curves[c - 1]));
        for (size_t i = 0; i < nrows; i++) {
            const refl_row *w = &rows[i];
            const char *want = c == 4 ? "jacobi" : curves[c < 4 ? c : c - 1];
            if (strcmp(w->label, want))
                continue;
            double y = c < 4 ? (w->reached ? w->sweeps : NAN) : (c == 4 ? w->theory : w->rel_se);
            if (isfinite(y) && y > 0)
                fprintf(o.f, "%.6g,%.8g\n", 1 / (1 - w->rho), y);
        }
        fputs("\n\n", o.f);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    char body[4096];
    snprintf(body, sizeof body,
             "@PNG\nset output 'reflectance_sweeps.png'\nset logscale xy\n"
             "set xlabel '1 / (1 - rho)'\nset ylabel 'sweeps to a relative error of %g (southwell: shots / elements)'\n"
             "set title 'Closed room, reflectance toward 1: sweeps to tolerance'\n"
             "plot for [i=0:3] 'reflectance.dat' index i using 1:2 with linespoints lw 2 pt 7 "
             "title word('jacobi gauss-seidel southwell hierarchical', i + 1), "
             "'' index 4 using 1:2 with lines dt 2 lw 2 lc rgb '#555555' title 'Jacobi theory ln(tol)/ln(rho) - 1'\n"
             "@SVG\nset output 'reflectance_sweeps.svg'\nreplot\nunset output\n"
             "@PNG\nset output 'reflectance_mc.png'\nset ylabel 'relative standard error (largest face)'\n"
             "set title 'Closed room: Monte Carlo standard error at a fixed budget'\n"
             "plot 'reflectance.dat' index 5 using 1:2 with linespoints lw 2 pt 7 title 'stochastic-jacobi', "
             "'' index 6 using 1:2 with linespoints lw 2 pt 7 title 'pathtrace'\n"
             "@SVG\nset output 'reflectance_mc.svg'\nreplot\nunset output\n",
             tol);
    if ((st = stab_plot(S, "reflectance", body, err)) != RP_OK)
        return st;

    FILE *f = S->md;
    fprintf(f, "## 1. Reflectance toward 1 in a closed room\n\n"
               "A closed unit box (six faces, six surfaces), every face with reflectance rho and emission 1: "
               "the exact answer is L = 1 / (1 - rho) everywhere (the furnace). Error: the largest relative error "
               "of a face's average (signed mean over the faces for `max-depth`); rel. stderr: the largest "
               "estimated relative standard error of a face's average. The iterative solvers (24 elements, analytic form "
               "factors to 1e-8; hierarchical with its own quadtrees) run until every surface average is within %g of it (or %g s); Jacobi from "
               "B = E has error rho^(k+1) after k sweeps, so it needs ln(tol)/ln(rho) - 1 sweeps. `direct` "
               "solves once: with the default form-factor tolerance the area-weighted row sum is s = %.10f, "
               "and a row-sum defect is amplified to (1 - rho)/(1 - rho s) - 1 (the 'predicted' column). The "
               "path tracer takes %lu probe points per surface; `max-depth 20` truncates the Neumann series, a "
               "bias of -rho^21 (predicted). Stochastic Jacobi shoots 4000 rays per iteration. One thread.\n\n",
            tol, budget, rowsum_default, pt_samples);
    fprintf(f, "![sweeps](reflectance_sweeps.png)\n\n![Monte Carlo error](reflectance_mc.png)\n\n");
    fprintf(f, "| rho | method | within tol. | seconds | iterations | sweeps | Jacobi theory | error | rel. stderr | "
               "rays/path | predicted |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (size_t i = 0; i < nrows; i++) {
        const refl_row *w = &rows[i];
        fprintf(f, "| %g | %s | %s | ", w->rho, w->label, w->reached ? "yes" : "**no**");
        put(S, f, "%.3g | ", w->seconds, "reflectance seconds");
        put(S, f, "%.0f | ", w->iterations, "reflectance iterations");
        if (w->iterative) {
            put(S, f, "%.4g | ", w->sweeps, "reflectance sweeps");
            put(S, f, "%.1f | ", w->theory, "reflectance theory");
        } else {
            fputs("n/a | | ", f);
        }
        put(S, f, "%.3g | ", w->error, "reflectance error");
        put(S, f, "%.3g | ", w->rel_se, "reflectance stderr");
        if (isfinite(w->path_len))
            fprintf(f, "%.3g | ", w->path_len);
        else
            fputs("n/a | ", f);
        if (isfinite(w->predicted))
            fprintf(f, "%.3g |\n", w->predicted);
        else
            fputs(" |\n", f);
    }
    fprintf(f, "\n**Failure signature.** Sweeps to a fixed tolerance grow like 1/(1 - rho): Jacobi follows "
               "ln(tol)/ln(rho) - 1 to the sweep (at rho = 0.999 it stops a little early: the form factors' "
               "row sums, amplified 1000-fold, put its fixed point above L by the `direct` row's error), "
               "Gauss-Seidel takes half as many, progressive refinement the same number of sweeps' worth of "
               "shots. A form-factor row-sum defect is amplified by rho/(1 - rho): the direct solve with default "
               "form factors follows the predicted error exactly, and fails the tolerance at 0.999. Russian "
               "roulette caps the path tracer's rays per path near 40 (20 bounces) whatever rho is, so the "
               "weights of surviving paths grow like (rho/0.95)^k: at 0.99 and 0.999 its error is many times "
               "its own standard error estimate (heavy-tailed weights: the estimate itself is unreliable). A "
               "depth cap leaves a bias of exactly -rho^(D+1). Stochastic Jacobi's reported standard error "
               "covers only its replicas' spread, not the power still unshot when its rule or budget stops it: "
               "at 0.999 it runs out of budget with an error several times its standard error (how many "
               "depends on how far the budget got).\n\n");
    return RP_OK;
}

/* --------------------------------------------- 2. shrinking light */

static rp_status sec_small_light(stab *S, rp_error *err)
{
    static const double sizes_full[] = {0.3, 0.1, 0.03, 0.01, 0.003};
    static const double sizes_quick[] = {0.1, 0.01, 0.003};
    const double *sizes = S->quick ? sizes_quick : sizes_full;
    const size_t nsz = S->quick ? 3 : 5;
    const unsigned mc_seeds = S->quick ? 8 : 32;
    const double h = 0.25, dx = 0.013, dy = 0.007;
    char path[1200];
    rp_out o;
    rp_status st = rp_out_open(&o, out_path(S, path, sizeof path, "small_light_ff.csv"), err);
    if (st != RP_OK)
        return st;
    fputs("light_side,exact_area,exact_point,analytic_err,montecarlo_err,hemicube64_vs_point_err,"
          "hemicube256_vs_point_err,hemicube1024_vs_point_err,hemicube256_vs_area_err\n",
          o.f);
    double tab[5][8];
    /* F from a unit receiver square (one element) to a light square of side
     * s at height h, centred over (0.5 + dx, 0.5 + dy) */
    for (size_t k = 0; k < nsz && st == RP_OK; k++) {
        double s = sizes[k], x0 = 0.5 + dx - s / 2, x1 = x0 + s, y0 = 0.5 + dy - s / 2, y1 = y0 + s;
        char text[512], name[64];
        snprintf(text, sizeof text,
                 "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
                 "quad a w 0 0 0  1 0 0  1 1 0  0 1 0\n"
                 "quad b l %.17g %.17g %.17g  %.17g %.17g %.17g  %.17g %.17g %.17g  %.17g %.17g %.17g\n",
                 x0, y0, h, x0, y1, h, x1, y1, h, x1, y0, h);
        snprintf(name, sizeof name, "small-light-ff-%g", s);
        rp_scene *sc = NULL;
        rp_mesh *mesh = NULL;
        if ((st = stab_scene(S, name, text, &sc, err)) != RP_OK)
            break;
        rp_mesh_params mp = {.size = sizeof mp, .max_edge = 10};
        st = rp_mesh_create(sc, &mp, &mesh, err);
        double exact = ff_parallel_general(0, 1, 0, 1, x0, x1, y0, y1, h);
        double exact_pt = ff_point_rect(x0 - 0.5, x1 - 0.5, y0 - 0.5, y1 - 0.5, h);
        double e[6] = {0};
        struct {
            rp_ff_method m;
            unsigned res;
            unsigned seeds;
        } cfg[5] = {{RP_FF_ANALYTIC, 0, 1}, {RP_FF_MONTECARLO, 0, mc_seeds}, {RP_FF_HEMICUBE, 64, 1},
                    {RP_FF_HEMICUBE, 256, 1}, {RP_FF_HEMICUBE, 1024, 1}};
        double hc256 = 0;
        /* the hemicube is scored against the point factor at the
         * receiver's centre, where it looks from (aliasing alone); its
         * error against the area factor is the last column */
        for (int c = 0; c < 5 && st == RP_OK; c++) {
            double ref = cfg[c].m == RP_FF_HEMICUBE ? exact_pt : exact;
            double sq = 0;
            for (unsigned sd = 0; sd < cfg[c].seeds && st == RP_OK; sd++) {
                rp_ff_params fp = {.size = sizeof fp, .method = cfg[c].m, .resolution = cfg[c].res, .seed = 1 + sd};
                rp_ff_context *ctx = NULL;
                rp_ff_scratch *scr = NULL;
                st = rp_ff_context_create(sc, mesh, NULL, &fp, &ctx, err);
                if (st == RP_OK)
                    st = rp_ff_scratch_create(ctx, &scr, err);
                if (st == RP_OK) {
                    double v = rp_ff_pair(ctx, scr, 0, 1, NULL, NULL);
                    double rel = (v - ref) / ref;
                    sq += rel * rel;
                    if (c == 3)
                        hc256 = v;
                }
                rp_ff_scratch_destroy(scr);
                rp_ff_context_destroy(ctx);
            }
            e[c] = sqrt(sq / cfg[c].seeds);
        }
        e[5] = fabs(hc256 - exact) / exact;
        tab[k][0] = s;
        tab[k][1] = exact;
        for (int c = 0; c < 6; c++)
            tab[k][2 + c] = e[c];
        fprintf(o.f, "%g,", s);
        put(S, o.f, "%.10g,", exact, "small light exact");
        put(S, o.f, "%.10g,", exact_pt, "small light exact point");
        for (int c = 0; c < 6; c++)
            put(S, o.f, c < 5 ? "%.6g," : "%.6g\n", e[c], "small light ff error");
        rp_mesh_destroy(mesh);
        rp_scene_destroy(sc);
    }
    if ((st = rp_out_close(&o, st == RP_OK, err)) != RP_OK)
        return st;

    /* the room: constant power, Le = 1 / (pi s^2) */
    const unsigned long samples = S->quick ? 256 : 1024;
    const unsigned spp = S->quick ? 4 : 16;
    typedef struct lrow {
        double s, floor_pt, floor_se, ceil_se, pix_se_max, pix_se_med;
        double gs_an, gs_hc, gs_mc, sj;
    } lrow;
    lrow lr[5];
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "small_light_room.csv"), err)) != RP_OK)
        return st;
    fputs("light_side,Le,pt_floor,pt_floor_rel_stderr,pt_ceiling_rel_stderr,pt_pixel_rel_stderr_median,"
          "pt_pixel_stderr_max_over_mean,gs_analytic_floor_dev,gs_hemicube64_floor_dev,gs_montecarlo_floor_dev,"
          "stochastic_jacobi_floor_dev\n",
          o.f);
    for (size_t k = 0; k < nsz && st == RP_OK; k++) {
        double s = sizes[k], Le = 1 / (RP_PI * s * s);
        double x0 = 0.5 - s / 2, x1 = 0.5 + s / 2, y = 0.999;
        char text[1024], name[64];
        snprintf(text, sizeof text,
                 "# a closed room lit by a square light of side s with constant power pi Le s^2 = 1\n"
                 "bands grey\ncamera eye 0.5 0.25 0.08 look 0.5 0.9 0.6 up 0 1 0 fov 70 size 64 64\n"
                 "material wall reflect 0.5\nmaterial lamp reflect 0 emit %.17g\n"
                 "quad floor wall 0 0 0  0 0 1  1 0 1  1 0 0\n"
                 "quad ceiling wall 0 1 0  1 1 0  1 1 1  0 1 1\n"
                 "quad wx0 wall 0 0 0  0 1 0  0 1 1  0 0 1\nquad wx1 wall 1 0 0  1 0 1  1 1 1  1 1 0\n"
                 "quad wz0 wall 0 0 0  1 0 0  1 1 0  0 1 0\nquad wz1 wall 0 0 1  0 1 1  1 1 1  1 0 1\n"
                 "quad lamp lamp %.17g %.17g %.17g  %.17g %.17g %.17g  %.17g %.17g %.17g  %.17g %.17g %.17g\n",
                 Le, x0, y, x0, x1, y, x0, x1, y, x1, x0, y, x1);
        snprintf(name, sizeof name, "small-light-room-%g", s);
        rp_scene *sc = NULL;
        if ((st = stab_scene(S, name, text, &sc, err)) != RP_OK)
            break;
        lrow *w = &lr[k];
        w->s = s;
        rp_exp_log(S->p, "stability/small light %g: pathtrace", s);
        char spec[256];
        snprintf(spec, sizeof spec, "pathtrace:samples=%lu:batch=%lu:spp=%u", samples, samples, spp);
        sopt so = {.want = RP_WANT_SURFACES | RP_WANT_IMAGE, .budget = 1e9};
        srun pt;
        if ((st = srun_do(S, sc, spec, &so, &pt, err)) != RP_OK) {
            rp_scene_destroy(sc);
            break;
        }
        w->floor_pt = surf_of(sc, &pt, "floor");
        w->floor_se = se_of(sc, &pt, "floor") / w->floor_pt;
        w->ceil_se = se_of(sc, &pt, "ceiling") / surf_of(sc, &pt, "ceiling");
        /* pixels: stderr of the pixel mean relative to the image mean */
        double mean = 0;
        for (size_t i = 0; i < pt.npix; i++)
            mean += pt.img[i];
        mean /= (double)pt.npix;
        double mx = 0;
        double *rel = malloc(pt.npix * sizeof *rel);
        for (size_t i = 0; rel && i < pt.npix; i++) {
            double sd = sqrt(pt.var[i]);
            mx = sd > mx ? sd : mx;
            rel[i] = pt.img[i] > 0 ? sd / pt.img[i] : 0;
        }
        double med = NAN;
        if (rel) {
            /* insertion sort: 4096 values */
            for (size_t a = 1; a < pt.npix; a++) {
                double v = rel[a];
                size_t b = a;
                while (b > 0 && rel[b - 1] > v) {
                    rel[b] = rel[b - 1];
                    b--;
                }
                rel[b] = v;
            }
            med = rel[pt.npix / 2];
        }
        free(rel);
        w->pix_se_med = med;
        w->pix_se_max = mx / mean;
        if (k == 0 || k == nsz - 1) {
            char png[64];
            snprintf(png, sizeof png, "small_light_pt_%g.png", s);
            if ((st = stab_png(S, png, pt.img, pt.w, pt.h, 4 * mean, err)) != RP_OK) {
                srun_free(&pt);
                rp_scene_destroy(sc);
                break;
            }
        }
        srun_free(&pt);
        const char *rad[4] = {"gauss-seidel:elements=150", "gauss-seidel:elements=150:ff=hemicube:hemicube-resolution=64",
                              "gauss-seidel:elements=150:ff=montecarlo:ff-samples=64",
                              S->quick ? "stochastic-jacobi:elements=150:rays=20000"
                                       : "stochastic-jacobi:elements=150:rays=100000"};
        double *dst[4] = {&w->gs_an, &w->gs_hc, &w->gs_mc, &w->sj};
        for (int m = 0; m < 4 && st == RP_OK; m++) {
            rp_exp_log(S->p, "stability/small light %g: %s", s, rad[m]);
            sopt sr = {.want = RP_WANT_SURFACES, .budget = 30};
            srun r;
            if ((st = srun_do(S, sc, rad[m], &sr, &r, err)) == RP_OK)
                *dst[m] = (surf_of(sc, &r, "floor") - w->floor_pt) / w->floor_pt;
            srun_free(&r);
        }
        rp_scene_destroy(sc);
        if (st != RP_OK)
            break;
        fprintf(o.f, "%g,", s);
        put(S, o.f, "%.8g,", Le, "small light Le");
        double v[] = {w->floor_pt, w->floor_se, w->ceil_se, w->pix_se_med, w->pix_se_max, w->gs_an, w->gs_hc,
                      w->gs_mc, w->sj};
        for (int c = 0; c < 9; c++)
            put(S, o.f, c < 8 ? "%.6g," : "%.6g\n", v[c], "small light room");
    }
    if ((st = rp_out_close(&o, st == RP_OK, err)) != RP_OK)
        return st;
    const char *body =
        "@PNG\nset output 'small_light_ff.png'\nset logscale xy\nset xlabel 'light side s (power constant)'\n"
        "set ylabel 'relative error of F(receiver -> light)'\n"
        "set title 'Form factor from a unit square to a light of side s at height 0.25'\n"
        "plot 'small_light_ff.csv' skip 1 using 1:4 with linespoints lw 2 pt 7 title 'analytic (default)', "
        "'' skip 1 using 1:5 with linespoints lw 2 pt 7 title 'montecarlo 256 (RMS over seeds)', "
        "'' skip 1 using 1:6 with linespoints lw 2 pt 7 title 'hemicube 64 (vs point factor)', "
        "'' skip 1 using 1:7 with linespoints lw 2 pt 7 title 'hemicube 256 (vs point factor)', "
        "'' skip 1 using 1:8 with linespoints lw 2 pt 7 title 'hemicube 1024 (vs point factor)', "
        "'' skip 1 using 1:9 with linespoints lw 2 pt 5 dt 2 title 'hemicube 256 (vs area factor)'\n"
        "@SVG\nset output 'small_light_ff.svg'\nreplot\nunset output\n"
        "@PNG\nset output 'small_light_pt.png'\nset ylabel 'relative standard error'\n"
        "set title 'Path tracer in a room lit by a light of side s (constant power)'\n"
        "plot 'small_light_room.csv' skip 1 using 1:4 with linespoints lw 2 pt 7 title 'floor average', "
        "'' skip 1 using 1:5 with linespoints lw 2 pt 7 title 'ceiling average (indirect only)', "
        "'' skip 1 using 1:7 with linespoints lw 2 pt 7 title 'worst pixel stderr / image mean'\n"
        "@SVG\nset output 'small_light_pt.svg'\nreplot\nunset output\n";
    if ((st = stab_plot(S, "small_light", body, err)) != RP_OK)
        return st;

    FILE *f = S->md;
    fprintf(f, "## 2. A shrinking light at constant power\n\n"
               "**Form factors.** From a unit receiver square (one element) to a square light of side s at "
               "height 0.25, centred over (0.513, 0.507) (off the hemicube's pixel grid). Exact: Howell C-13 "
               "(parallel rectangles, superposition); the hemicube looks from the receiver's centre, so it is "
               "also compared with the exact point-to-rectangle factor there (B-3). Analytic and Monte Carlo "
               "errors are against the area factor, the hemicube's against the point factor (its aliasing) and, "
               "last column, against the area factor (its point approximation). Monte Carlo: RMS over %u seeds "
               "of 256 point pairs.\n\n![form factors](small_light_ff.png)\n\n"
               "| light side | exact F (area) | analytic | montecarlo | hemicube 64 vs point | hemicube 256 vs point | "
               "hemicube 1024 vs point | hemicube 256 vs area |\n|---|---|---|---|---|---|---|---|\n",
            mc_seeds);
    for (size_t k = 0; k < nsz; k++) {
        fprintf(f, "| %g | ", tab[k][0]);
        put(S, f, "%.4g | ", tab[k][1], "small light exact");
        for (int c = 0; c < 6; c++)
            put(S, f, c < 5 ? "%.3g | " : "%.3g |\n", tab[k][2 + c], "small light ff");
    }
    fprintf(f, "\n**The room.** A closed unit room (reflectance 0.5) lit by a ceiling light of side s with "
               "Le = 1/(pi s^2) (power 1). Path tracer: %lu probe points per surface and %u samples per pixel "
               "(64 x 64, the camera sees the light); radiosity (150 elements) floor averages against the path "
               "tracer's.\n\n![path tracer](small_light_pt.png)\n\n"
               "| light side | PT floor L | floor rel. stderr | ceiling rel. stderr | median pixel rel. stderr | "
               "worst pixel stderr / mean | GS analytic | GS hemicube 64 | GS montecarlo 64 | stochastic Jacobi "
               "|\n|---|---|---|---|---|---|---|---|---|---|\n",
            samples, spp);
    for (size_t k = 0; k < nsz; k++) {
        const lrow *w = &lr[k];
        fprintf(f, "| %g | ", w->s);
        double v[] = {w->floor_pt, w->floor_se, w->ceil_se, w->pix_se_med, w->pix_se_max, w->gs_an, w->gs_hc,
                      w->gs_mc, w->sj};
        for (int c = 0; c < 9; c++)
            put(S, f, c < 8 ? "%.3g | " : "%.3g |\n", v[c], "small light room");
    }
    fprintf(f, "\nNot run on the room: jacobi, southwell and direct solve the same system with the same form "
               "factors as gauss-seidel (their floor would match its column to the tolerance); hierarchical "
               "links with its own analytic factors and refines where B F is large, which is the analytic "
               "column's behaviour.\n");
    fprintf(f, "\nRadiosity columns: (floor average - path tracer's) / path tracer's. Renders: "
               "![largest light](small_light_pt_%g.png) ![smallest light](small_light_pt_%g.png)\n\n",
            sizes[0], sizes[nsz - 1]);
    fprintf(f, "**Failure signature.** Once the light covers less than a hemicube pixel its form factor is "
               "quantised (0 or a whole pixel's delta form factor): the hemicube error against the point "
               "factor grows without bound as s shrinks, and so does the hemicube radiosity floor's error, "
               "while the analytic factor stays exact (the hemicube's error against the *area* factor, last column, "
               "is its point approximation: the receiver is large and close). Monte Carlo's error does not "
               "depend on s (the light is sampled by area). Next-event estimation with MIS keeps the path "
               "tracer's surface averages and their standard errors steady, but the pixels that see the light "
               "carry a standard error growing like 1/s (Le ~ 1/s^2 over a coverage ~ s^2), until the light "
               "falls between the pixel samples and vanishes from the image (the smallest light): the path "
               "tracer's own aliasing.\n\n");
    return RP_OK;
}

/* ---------------------------------------------- 3. corners and contact */

/* One element per square: floor square A facing +z and B either a wall
 * at x = 0 (gap g between them; g = 0 shares an edge) or a parallel
 * square at height c. */
static rp_status corner_scene(stab *S, int perpendicular, double d, double max_edge, rp_scene **sc,
                              rp_mesh **mesh, rp_error *err)
{
    char text[512], name[64];
    if (perpendicular) {
        snprintf(text, sizeof text,
                 "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
                 "quad a w %.17g 0 0  %.17g 0 0  %.17g 1 0  %.17g 1 0\nquad b l 0 0 0  0 1 0  0 1 1  0 0 1\n",
                 d, 1 + d, 1 + d, d);
        snprintf(name, sizeof name, "corner-perpendicular-gap-%g", d);
    } else {
        snprintf(text, sizeof text,
                 "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
                 "quad a w 0 0 0  1 0 0  1 1 0  0 1 0\nquad b l 0 0 %.17g  0 1 %.17g  1 1 %.17g  1 0 %.17g\n",
                 d, d, d, d);
        snprintf(name, sizeof name, "corner-parallel-%g", d);
    }
    rp_status st = stab_scene(S, name, text, sc, err);
    rp_mesh_params mp = {.size = sizeof mp, .max_edge = max_edge};
    if (st == RP_OK)
        st = rp_mesh_create(*sc, &mp, mesh, err);
    return st;
}

/* F from surface a to surface b, summed over their elements; RMS relative
 * error over seeds; seconds for the whole computation. */
static rp_status corner_ff(const rp_experiment_params *p, const rp_scene *sc, const rp_mesh *mesh,
                           const rp_ff_params *base, unsigned seeds, double exact, double *rel_rms, double *mean,
                           double *secs, rp_error *err)
{
    uint32_t a0, na, b0, nbel;
    rp_mesh_surface_elements(mesh, rp_scene_find_surface(sc, "a"), &a0, &na);
    rp_mesh_surface_elements(mesh, rp_scene_find_surface(sc, "b"), &b0, &nbel);
    const rp_element *el = rp_mesh_elements(mesh);
    size_t n = rp_mesh_nelements(mesh);
    /* recorded in the study's journal (the mesh named by its scene and its
     * elements on a and b) */
    char hash[17], key[300];
    rp_scene_hash(sc, hash);
    snprintf(key, sizeof key, "stability form factor scene %s elements %zu a %u b %u %s samples %u resolution %u "
             "tolerance %.17g seeds %u exact %.17g", hash, n, (unsigned)na, (unsigned)nbel,
             rp_ff_method_name(base->method), base->samples, base->resolution, base->tolerance, seeds, exact);
    double rec[3];
    if (rp_exp_unit(p, key, rec, 3)) { /* recorded, or another rank's */
        *rel_rms = rec[0];
        *mean = rec[1];
        *secs = rec[2];
        return RP_OK;
    }
    if (rp_cancelled(p->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted");
    float *row = malloc(n * sizeof *row);
    if (!row)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    double sq = 0, sum = 0, t = 0;
    rp_status st = RP_OK;
    for (unsigned k = 0; k < seeds && st == RP_OK; k++) {
        rp_ff_params fp = *base;
        fp.seed = 1 + k;
        rp_ff_context *ctx = NULL;
        rp_ff_scratch *scr = NULL;
        double t0 = rp_clock();
        st = rp_ff_context_create(sc, mesh, NULL, &fp, &ctx, err);
        if (st == RP_OK)
            st = rp_ff_scratch_create(ctx, &scr, err);
        double F = 0, A = 0;
        for (uint32_t i = a0; st == RP_OK && i < a0 + na; i++) {
            rp_ff_row(ctx, scr, i, row, NULL);
            double r = 0;
            for (uint32_t j = b0; j < b0 + nbel; j++)
                r += row[j];
            F += el[i].area * r;
            A += el[i].area;
        }
        t += rp_clock() - t0;
        rp_ff_scratch_destroy(scr);
        rp_ff_context_destroy(ctx);
        F /= A;
        double e = (F - exact) / exact;
        sq += e * e;
        sum += F;
    }
    free(row);
    *rel_rms = sqrt(sq / seeds);
    *mean = sum / seeds;
    *secs = t / seeds;
    if (st == RP_OK) {
        double v[3] = {*rel_rms, *mean, *secs};
        st = rp_journal_put_doubles(p->journal, key, v, 3, err);
    }
    return st;
}

static rp_status sec_corner(stab *S, rp_error *err)
{
    static const double gaps_full[] = {0.1, 0.01, 0.001, 0};
    static const double gaps_quick[] = {0.1, 0.001, 0};
    static const double dist_full[] = {0.1, 0.01, 0.001};
    static const double dist_quick[] = {0.1, 0.01};
    const double *gaps = S->quick ? gaps_quick : gaps_full, *dist = S->quick ? dist_quick : dist_full;
    const size_t ng = S->quick ? 3 : 4, nd = S->quick ? 2 : 3;
    const unsigned seeds = S->quick ? 8 : 16;
    typedef struct mcfg {
        const char *key, *label;
        rp_ff_method m;
        double tol;
        unsigned samples, res;
    } mcfg;
    static const mcfg methods[] = {{"analytic-1e-3", "analytic 1e-3", RP_FF_ANALYTIC, 1e-3, 0, 0},
                                   {"analytic-1e-5", "analytic 1e-5 (default)", RP_FF_ANALYTIC, 1e-5, 0, 0},
                                   {"analytic-1e-8", "analytic 1e-8", RP_FF_ANALYTIC, 1e-8, 0, 0},
                                   {"montecarlo-256", "montecarlo 256 (default)", RP_FF_MONTECARLO, 0, 256, 0},
                                   {"montecarlo-16384", "montecarlo 16384", RP_FF_MONTECARLO, 0, 16384, 0},
                                   {"hemicube-256", "hemicube 256 (default)", RP_FF_HEMICUBE, 0, 0, 256},
                                   {"hemicube-1024", "hemicube 1024", RP_FF_HEMICUBE, 0, 0, 1024}};
    const size_t nmeth = sizeof methods / sizeof methods[0];
    char path[1200];
    rp_out o;
    rp_status st = rp_out_open(&o, out_path(S, path, sizeof path, "corner.csv"), err);
    if (st != RP_OK)
        return st;
    fputs("table,configuration,distance,elements_per_square,method_key,method,exact,form_factor,rel_error,seconds,"
          "seeds\n",
          o.f);
    FILE *f = S->md;
    fprintf(f, "## 3. Corners and nearly touching surfaces\n\n"
               "Unit squares, one element each unless stated: a floor square and a wall with a gap g between "
               "them (g = 0: sharing an edge, Howell C-14; g > 0: C-14 by superposition, "
               "(1 + g) F(1 + g) - g F(g)), and parallel squares at distance c (C-11). The kernel "
               "cos cos / (pi r^2) is unbounded where the squares meet: Monte Carlo area sampling has infinite "
               "variance at the shared edge, the hemicube sees the surfaces from the element's centre only, and "
               "the analytic contour integral works harder (seconds per pair). Monte Carlo errors are RMS over "
               "%u seeds.\n\n![corner](corner.png)\n\n",
            seeds);
    fprintf(f, "| configuration | exact F |");
    for (size_t m = 0; m < nmeth; m++)
        fprintf(f, " %s |", methods[m].label);
    fprintf(f, "\n|---|---|");
    for (size_t m = 0; m < nmeth; m++)
        fputs("---|", f);
    fputs("\n", f);
    char secs_line[4096] = "";
    size_t sl = 0;
    double perr[4][8]; /* perpendicular, single element: [gap][method] */
    for (int cfg = 0; cfg < 2 && st == RP_OK; cfg++) {
        size_t nconf = cfg == 0 ? ng : nd;
        for (size_t c = 0; c < nconf && st == RP_OK; c++) {
            double d = cfg == 0 ? gaps[c] : dist[c];
            double exact = cfg == 0 ? ff_perpendicular_gap(d) : howell_parallel(1, 1, d);
            rp_scene *sc = NULL;
            rp_mesh *mesh = NULL;
            if ((st = corner_scene(S, cfg == 0, d, 10, &sc, &mesh, err)) != RP_OK) {
                rp_scene_destroy(sc);
                break;
            }
            rp_exp_log(S->p, "stability/corner: %s %g", cfg == 0 ? "perpendicular gap" : "parallel", d);
            fprintf(f, "| %s %g | ", cfg == 0 ? "perpendicular, gap" : "parallel, distance", d);
            put(S, f, "%.8f |", exact, "corner exact");
            if (sl < sizeof secs_line)
                sl += (size_t)snprintf(secs_line + sl, sizeof secs_line - sl, "| %s %g |",
                                       cfg == 0 ? "perpendicular, gap" : "parallel, distance", d);
            for (size_t m = 0; m < nmeth && st == RP_OK; m++) {
                rp_ff_params fp = {.size = sizeof fp, .method = methods[m].m, .tolerance = methods[m].tol,
                                   .samples = methods[m].samples, .resolution = methods[m].res};
                unsigned ns = methods[m].m == RP_FF_MONTECARLO ? seeds : 1;
                double e, F, secs;
                if ((st = corner_ff(S->p, sc, mesh, &fp, ns, exact, &e, &F, &secs, err)) != RP_OK)
                    break;
                put(S, f, " %.3g |", e, "corner error");
                if (cfg == 0)
                    perr[c][m] = e;
                if (sl < sizeof secs_line)
                    sl += (size_t)snprintf(secs_line + sl, sizeof secs_line - sl, " %.2g |", secs);
                fprintf(o.f, "single,%s,%g,1,%s,%s,", cfg == 0 ? "perpendicular" : "parallel", d, methods[m].key,
                        methods[m].label);
                put(S, o.f, "%.12g,", exact, "corner exact");
                put(S, o.f, "%.12g,", F, "corner F");
                put(S, o.f, "%.6g,", e, "corner error");
                put(S, o.f, "%.6g,", secs, "corner seconds");
                fprintf(o.f, "%u\n", ns);
            }
            fputs("\n", f);
            if (sl < sizeof secs_line)
                sl += (size_t)snprintf(secs_line + sl, sizeof secs_line - sl, "\n");
            rp_mesh_destroy(mesh);
            rp_scene_destroy(sc);
        }
    }
    if (st == RP_OK) {
        fprintf(f, "\nSeconds per surface pair (one element each, for the same columns):\n\n| configuration |");
        for (size_t m = 0; m < nmeth; m++)
            fprintf(f, " %s |", methods[m].label);
        fprintf(f, "\n|---|");
        for (size_t m = 0; m < nmeth; m++)
            fputs("---|", f);
        fprintf(f, "\n%s", secs_line);
    }
    /* subdivision: the surface-to-surface factor summed over n x n
     * elements per square, at the defaults */
    static const unsigned subs_full[] = {1, 2, 4, 8};
    static const unsigned subs_quick[] = {1, 2, 4};
    const unsigned *subs = S->quick ? subs_quick : subs_full;
    const size_t nsub = S->quick ? 3 : 4;
    static const size_t defaults[3] = {1, 3, 5};
    if (st == RP_OK) {
        fprintf(f, "\nSubdividing both squares into n x n elements (default settings; F summed over element "
                   "pairs): the hemicube's point-sampling error shrinks with the elements, the kernel's "
                   "singularity stays at the shared edge.\n\n| configuration | n x n |");
        for (size_t m = 0; m < 3; m++)
            fprintf(f, " %s |", methods[defaults[m]].label);
        fprintf(f, "\n|---|---|---|---|---|\n");
    }
    for (int cfg = 0; cfg < 2 && st == RP_OK; cfg++) {
        double d = cfg == 0 ? 0 : 0.01;
        double exact = cfg == 0 ? ff_perpendicular_gap(0) : howell_parallel(1, 1, d);
        for (size_t k = 0; k < nsub && st == RP_OK; k++) {
            rp_scene *sc = NULL;
            rp_mesh *mesh = NULL;
            if ((st = corner_scene(S, cfg == 0, d, 1.0 / subs[k] + 1e-9, &sc, &mesh, err)) != RP_OK) {
                rp_scene_destroy(sc);
                break;
            }
            fprintf(f, "| %s | %u x %u |", cfg == 0 ? "perpendicular, shared edge" : "parallel, distance 0.01",
                    subs[k], subs[k]);
            for (size_t m = 0; m < 3 && st == RP_OK; m++) {
                const mcfg *mc = &methods[defaults[m]];
                rp_ff_params fp = {.size = sizeof fp, .method = mc->m, .tolerance = mc->tol, .samples = mc->samples,
                                   .resolution = mc->res};
                unsigned ns = mc->m == RP_FF_MONTECARLO ? seeds : 1;
                double e, F, secs;
                if ((st = corner_ff(S->p, sc, mesh, &fp, ns, exact, &e, &F, &secs, err)) != RP_OK)
                    break;
                put(S, f, " %.3g |", e, "corner subdivision error");
                fprintf(o.f, "subdivision,%s,%g,%u,%s,%s,", cfg == 0 ? "perpendicular" : "parallel", d,
                        subs[k] * subs[k], mc->key, mc->label);
                put(S, o.f, "%.12g,", exact, "corner exact");
                put(S, o.f, "%.12g,", F, "corner F");
                put(S, o.f, "%.6g,", e, "corner error");
                put(S, o.f, "%.6g,", secs, "corner seconds");
                fprintf(o.f, "%u\n", ns);
            }
            fputs("\n", f);
            rp_mesh_destroy(mesh);
            rp_scene_destroy(sc);
        }
    }
    if ((st = rp_out_close(&o, st == RP_OK, err)) != RP_OK)
        return st;
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "corner.dat"), err)) != RP_OK)
        return st;
    for (size_t m = 0; m < nmeth; m++) {
        fprintf(o.f, "# %s: gap (0 as 1e-4), relative error\n", methods[m].label);
        for (size_t c = 0; c < ng; c++)
            if (isfinite(perr[c][m]))
                fprintf(o.f, "%g,%.6g\n", gaps[c] > 0 ? gaps[c] : 1e-4, perr[c][m] > 1e-16 ? perr[c][m] : 1e-16);
        fputs("\n\n", o.f);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    const char *body =
        "@PNG\nset output 'corner.png'\nset logscale xy\nset xlabel 'gap g between the floor square and the wall'\n"
        "set ylabel 'relative error of F'\n"
        "set title 'Perpendicular unit squares with a gap (g = 1e-4 plotted for g = 0)'\n"
        "plot for [i=0:6] 'corner.dat' index i using 1:2 with linespoints lw 2 pt 7 "
        "title word('analytic-1e-3 analytic-1e-5 analytic-1e-8 montecarlo-256 montecarlo-16384 hemicube-256 "
        "hemicube-1024', i + 1)\n"
        "@SVG\nset output 'corner.svg'\nreplot\nunset output\n";
    if ((st = stab_plot(S, "corner", body, err)) != RP_OK)
        return st;
    fprintf(f, "\nThe solvers are not run here: every radiosity method consumes these form factors (jacobi, "
               "gauss-seidel, southwell and direct through `--ff`; hierarchical through its own analytic links), "
               "so their error at a corner is the form factor's; the path tracer has no form factors (its "
               "corner behaviour is the furnace of section 1 and the contact of section 4).\n");
    fprintf(f, "\n**Failure signature.** As the gap closes the Monte Carlo error stops falling as N^-1/2 "
               "(16384 pairs gain far less than the 8x they gain on a smooth kernel) because the kernel's "
               "variance diverges at the shared edge; the hemicube's error stays at that of a point-to-area "
               "factor at the element's centre whatever its resolution, falling only as the elements shrink; "
               "the analytic integral stays accurate but costs more per pair as the surfaces approach.\n\n");
    return RP_OK;
}

/* ------------------------------------- top-down views (sections 4, 5) */

/* The camera of sections 4 and 5: 3 above the floor's centre, looking
 * down, x to the right; fov 19.5 degrees spans the unit floor. */
#define TOP_H 3.0
#define TOP_FOV 19.5

static double top_col_x(uint32_t px, uint32_t W)
{
    return 0.5 + (2.0 * (px + 0.5) / W - 1.0) * tan(0.5 * TOP_FOV * RP_PI / 180.0) * TOP_H;
}

/* Column means over the rows whose floor z lies in [z0, z1] (rows map to
 * z as columns to x, mirrored: only bands symmetric about 0.5 are asked
 * for). */
static void top_profile(const float *img, uint32_t W, uint32_t H, double z0, double z1, double *out)
{
    for (uint32_t x = 0; x < W; x++) {
        double s = 0;
        size_t n = 0;
        for (uint32_t y = 0; y < H; y++) {
            double z = top_col_x(y, H); /* rows map to z the same way (square image) */
            if (z < z0 || z > z1)
                continue;
            s += img[(size_t)y * W + x];
            n++;
        }
        out[x] = n ? s / (double)n : 0;
    }
}

/* Mean of a profile over columns with x in [x0, x1]. */
static double strip_mean(const double *prof, uint32_t W, double x0, double x1)
{
    double s = 0;
    size_t n = 0;
    for (uint32_t x = 0; x < W; x++) {
        double cx = top_col_x(x, W);
        if (cx >= x0 && cx <= x1) {
            s += prof[x];
            n++;
        }
    }
    return n ? s / (double)n : NAN;
}

/* RMS difference of two profiles over columns with x in [x0, x1]. */
static double strip_rmse(const double *a, const double *b, uint32_t W, double x0, double x1)
{
    double s = 0;
    size_t n = 0;
    for (uint32_t x = 0; x < W; x++) {
        double cx = top_col_x(x, W);
        if (cx >= x0 && cx <= x1) {
            s += (a[x] - b[x]) * (a[x] - b[x]);
            n++;
        }
    }
    return n ? sqrt(s / (double)n) : NAN;
}

/* ----------------------------------------------- 4. block on a floor */

static void block_floor(char *buf, size_t n, int conforming)
{
    if (!conforming) {
        snprintf(buf, n, "quad floor floor 0 0 0  0 0 1  1 0 1  1 0 0\n");
        return;
    }
    /* the floor cut along the block's footprint (x 0.47, 0.53; z 0.2,
     * 0.8): element edges then run along the contact lines */
    static const double xs[4] = {0, 0.47, 0.53, 1}, zs[4] = {0, 0.2, 0.8, 1};
    size_t used = 0;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            used += (size_t)snprintf(buf + used, n - used,
                                     "quad floor%d%d floor %g 0 %g  %g 0 %g  %g 0 %g  %g 0 %g\n", i, k, xs[i], zs[k],
                                     xs[i], zs[k + 1], xs[i + 1], zs[k + 1], xs[i + 1], zs[k]);
}

static rp_status sec_block(stab *S, rp_error *err)
{
    const uint32_t W = S->quick ? 64 : 128;
    const unsigned long ref_spp = S->quick ? 64 : 512;
    char floors[2][1024];
    block_floor(floors[0], sizeof floors[0], 0);
    block_floor(floors[1], sizeof floors[1], 1);
    rp_scene *sc[2] = {NULL, NULL};
    rp_status st = RP_OK;
    for (int c = 0; c < 2 && st == RP_OK; c++) {
        char text[4096];
        snprintf(text, sizeof text,
                 "# a block standing on a floor, lit from the upper left; the floor is %s\n"
                 "bands grey\ncamera eye 0.5 %g 0.5 look 0.5 0 0.5 up 0 0 -1 fov %g size %u %u\n"
                 "material floor reflect 0.6\nmaterial wall reflect 0.6\nmaterial block reflect 0.6\n"
                 "material lamp reflect 0 emit 10\n%s"
                 "quad wallx0 wall 0 0 0  0 1 0  0 1 1  0 0 1\nquad wallx1 wall 1 0 0  1 0 1  1 1 1  1 1 0\n"
                 "quad wallz1 wall 0 0 1  0 1 1  1 1 1  1 0 1\n"
                 "box block block 0.47 0 0.2  0.53 0.5 0.8 outward\n"
                 "quad lamp lamp 0.1 1 0.35  0.3 1 0.35  0.3 1 0.65  0.1 1 0.65\n",
                 c ? "cut along the block's footprint (conforming)" : "one quad (non-conforming)", TOP_H, TOP_FOV, W,
                 W, floors[c]);
        st = stab_scene(S, c ? "block-conforming" : "block-nonconforming", text, &sc[c], err);
    }
    typedef struct brun {
        char label[64];
        int scene;
        char spec[160];
    } brun;
    brun runs[] = {
        {"reference: pathtrace", 0, ""},
        {"pathtrace 16 spp", 0, "pathtrace:spp=16"},
        {"GS flat non-conforming h=0.15", 0, "gauss-seidel:max-edge=0.15"},
        {"GS gouraud non-conforming h=0.15", 0, "gauss-seidel:max-edge=0.15:reconstruct=gouraud"},
        {"GS flat non-conforming h=0.05", 0, ""},
        {"GS flat conforming h=0.15", 1, "gauss-seidel:max-edge=0.15"},
        {"GS gouraud conforming h=0.15", 1, "gauss-seidel:max-edge=0.15:reconstruct=gouraud"},
        {"stochastic-jacobi flat non-conforming h=0.15", 0, ""},
        {"stochastic-jacobi flat conforming h=0.15", 1, ""},
        {"hierarchical non-conforming", 0, ""},
        {"hierarchical conforming", 1, ""},
    };
    for (int k = 9; k < 11; k++)
        snprintf(runs[k].spec, sizeof runs[k].spec, "hierarchical:bf-epsilon=%s",
                 S->quick ? "2e-2:min-area=1e-3" : "1e-2:min-area=1e-4");
    snprintf(runs[0].spec, sizeof runs[0].spec, "pathtrace:spp=%lu", ref_spp);
    if (S->quick)
        snprintf(runs[4].label, sizeof runs[4].label, "GS flat non-conforming h=0.075");
    snprintf(runs[4].spec, sizeof runs[4].spec, "gauss-seidel:max-edge=%g", S->quick ? 0.075 : 0.05);
    snprintf(runs[7].spec, sizeof runs[7].spec, "stochastic-jacobi:max-edge=0.15:rays=%d", S->quick ? 30000 : 100000);
    snprintf(runs[8].spec, sizeof runs[8].spec, "stochastic-jacobi:max-edge=0.15:rays=%d", S->quick ? 30000 : 100000);
    const size_t nr = sizeof runs / sizeof runs[0];
    double *prof = calloc(nr * W, sizeof *prof);
    double left[16], right[16], rmse[16], secs[16];
    if (!prof && st == RP_OK)
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    float *refimg = NULL;
    for (size_t k = 0; k < nr && st == RP_OK; k++) {
        rp_exp_log(S->p, "stability/block: %s", runs[k].label);
        sopt so = {.want = RP_WANT_IMAGE, .budget = 60};
        srun r;
        if ((st = srun_do(S, sc[runs[k].scene], runs[k].spec, &so, &r, err)) != RP_OK)
            break;
        top_profile(r.img, W, W, 0.4, 0.6, prof + k * W);
        secs[k] = r.seconds;
        left[k] = strip_mean(prof + k * W, W, 0.40, 0.46);
        right[k] = strip_mean(prof + k * W, W, 0.54, 0.60);
        if (k == 0) {
            refimg = r.img;
            r.img = NULL;
        }
        rmse[k] = 0;
        for (size_t i = 0; i < r.npix && refimg; i++) {
            double d = (k ? r.img[i] : refimg[i]) - refimg[i];
            rmse[k] += d * d;
        }
        rmse[k] = sqrt(rmse[k] / (double)(r.npix ? r.npix : 1));
        if (k == 0 || k == 2 || k == 5) {
            static const char *const names[] = {"block_reference.png", "", "block_gs_nonconforming.png", "", "",
                                                "block_gs_conforming.png"};
            st = stab_png(S, names[k], k ? r.img : refimg, W, W, 2 * strip_mean(prof, W, 0.2, 0.4), err);
        }
        srun_free(&r);
    }
    free(refimg);
    rp_scene_destroy(sc[0]);
    rp_scene_destroy(sc[1]);
    char path[1200];
    rp_out o;
    if (st == RP_OK && (st = rp_out_open(&o, out_path(S, path, sizeof path, "block_profile.csv"), err)) == RP_OK) {
        fputs("x", o.f);
        for (size_t k = 0; k < nr; k++)
            fprintf(o.f, ",%s", runs[k].label);
        fputs("\n", o.f);
        for (uint32_t x = 0; x < W; x++) {
            put(S, o.f, "%.5f", top_col_x(x, W), "block x");
            for (size_t k = 0; k < nr; k++)
                put(S, o.f, ",%.6g", prof[k * W + x], "block profile");
            fputs("\n", o.f);
        }
        st = rp_out_close(&o, 1, err);
    }
    if (st == RP_OK && (st = rp_out_open(&o, out_path(S, path, sizeof path, "block.csv"), err)) == RP_OK) {
        fputs("method,spec,left_strip_mean,left_rel_dev,right_strip_mean,right_rel_dev,image_rmse,seconds\n", o.f);
        for (size_t k = 0; k < nr; k++) {
            fprintf(o.f, "%s,%s,", runs[k].label, runs[k].spec);
            put(S, o.f, "%.6g,", left[k], "block left");
            put(S, o.f, "%.6g,", (left[k] - left[0]) / left[0], "block left dev");
            put(S, o.f, "%.6g,", right[k], "block right");
            put(S, o.f, "%.6g,", (right[k] - right[0]) / right[0], "block right dev");
            put(S, o.f, "%.6g,", rmse[k], "block rmse");
            put(S, o.f, "%.4g\n", secs[k], "block seconds");
        }
        st = rp_out_close(&o, 1, err);
    }
    if (st == RP_OK) {
        const char *body =
            "@PNG\nset output 'block_profile.png'\nset xlabel 'x on the floor (block between 0.47 and 0.53)'\n"
            "set ylabel 'radiance, mean over z in [0.4, 0.6]'\nset xrange [0.2:0.8]\n"
            "set title 'Floor radiance across the block: leaks of a non-conforming mesh'\n"
            "set arrow from 0.47, graph 0 to 0.47, graph 1 nohead dt 3\n"
            "set arrow from 0.53, graph 0 to 0.53, graph 1 nohead dt 3\nset key autotitle columnheader\n"
            "plot 'block_profile.csv' using 1:2 with lines lw 3 lc rgb 'black', '' using 1:4 with lines lw 2, "
            "'' using 1:6 with lines lw 2, '' using 1:7 with lines lw 2, '' using 1:11 with lines lw 2, "
            "'' using 1:12 with lines lw 2\n"
            "@SVG\nset output 'block_profile.svg'\nreplot\nunset output\n";
        st = stab_plot(S, "block", body, err);
    }
    free(prof);
    if (st != RP_OK)
        return st;
    FILE *f = S->md;
    fprintf(f, "## 4. A block on a floor: light and shadow leaks\n\n"
               "A block (x 0.47 to 0.53, z 0.2 to 0.8, height 0.5) stands on a unit floor with three walls, lit "
               "by a ceiling light on its left; the camera looks straight down. Non-conforming: the floor is one "
               "quad, so with max-edge 0.15 one 1/7-wide element spans the block from x = 0.43 to 0.57, "
               "straddling lit floor, contact and umbra. Conforming: the floor is cut along the block's "
               "footprint (nine quads). Strips (mean over z in [0.4, 0.6]): left x in [0.40, 0.46] (lit, next to "
               "the block) and right x in [0.54, 0.60] (umbra). Reference: path tracer, %lu spp, %u x %u. "
               "Deviation = (method - reference) / reference.\n\n"
               "![profile](block_profile.png)\n\n"
               "Images: ![reference](block_reference.png) ![non-conforming](block_gs_nonconforming.png) "
               "![conforming](block_gs_conforming.png)\n\n"
               "| method | left strip (lit) | deviation | right strip (umbra) | deviation | image RMSE | seconds "
               "|\n|---|---|---|---|---|---|---|\n",
            ref_spp, W, W);
    for (size_t k = 0; k < nr; k++) {
        fprintf(f, "| %s | ", runs[k].label);
        put(S, f, "%.4g | ", left[k], "block left");
        put(S, f, "%+.3f | ", (left[k] - left[0]) / left[0], "block left dev");
        put(S, f, "%.4g | ", right[k], "block right");
        put(S, f, "%+.3f | ", (right[k] - right[0]) / right[0], "block right dev");
        put(S, f, "%.4g | ", rmse[k], "block rmse");
        put(S, f, "%.3g |\n", secs[k], "block seconds");
    }
    fprintf(f, "\nNot run: jacobi, southwell and direct solve the same system on the same mesh as "
               "gauss-seidel, so they leak identically (their difference is the solver tolerance).\n");
    fprintf(f, "\n**Failure signature.** An element that straddles the block averages lit floor, hidden "
               "contact and umbra: drawn flat, its visible part in the umbra is too bright (light leak: "
               "positive right-strip deviation) and its lit part too dark (shadow leak: negative left-strip "
               "deviation); Gouraud interpolation spreads the same error over the neighbours. A finer "
               "non-conforming mesh narrows the leak, conforming meshing removes it at the coarse size. The "
               "path tracer has no mesh and shows noise only.\n\n");
    return RP_OK;
}

/* ----------------------------------------------- 5. a sharp shadow */

static rp_status sec_shadow(stab *S, rp_error *err)
{
    static const double h_full[] = {0.2, 0.1, 0.05, 0.025};
    static const double h_quick[] = {0.2, 0.1, 0.05};
    const double *hs = S->quick ? h_quick : h_full;
    const size_t nh = S->quick ? 3 : 4;
    const uint32_t W = S->quick ? 96 : 128;
    const unsigned long ref_spp = S->quick ? 64 : 512;
    /* lamp 0.04 wide centred at x = 0.2, height 1; plate x 0.3..0.45 at
     * height 0.3: shadow edge on the floor at x = 0.2 + 0.25 / 0.7 =
     * 0.557, penumbra 0.04 x 0.3 / 0.7 = 0.017 wide */
    const double edge = 0.2 + 0.25 / 0.7;
    char text[2048];
    snprintf(text, sizeof text,
             "# a small lamp, a plate and the sharp shadow it casts on the floor (edge at x = %.4f)\n"
             "bands grey\ncamera eye 0.5 %g 0.5 look 0.5 0 0.5 up 0 0 -1 fov %g size %u %u\n"
             "material floor reflect 0.6\nmaterial plate reflect 0.6\nmaterial lamp reflect 0 emit 200\n"
             "quad floor floor 0 0 0  0 0 1  1 0 1  1 0 0\n"
             "quad plate plate 0.3 0.3 0.3  0.3 0.3 0.7  0.45 0.3 0.7  0.45 0.3 0.3\n"
             "quad lamp lamp 0.18 1 0.48  0.22 1 0.48  0.22 1 0.52  0.18 1 0.52\n",
             edge, TOP_H, TOP_FOV, W, W);
    rp_scene *sc = NULL;
    rp_status st = stab_scene(S, "sharp-shadow", text, &sc, err);
    if (st != RP_OK)
        return st;
    double *ref = calloc(W, sizeof *ref), *prof = calloc(W, sizeof *prof);
    if (!ref || !prof) {
        free(ref);
        free(prof);
        rp_scene_destroy(sc);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    typedef struct shrow {
        char label[96];
        double h, elements, band, far, secs;
    } shrow;
    shrow rows[16];
    size_t nrows = 0;
    char spec[160];
    snprintf(spec, sizeof spec, "pathtrace:spp=%lu", ref_spp);
    sopt so = {.want = RP_WANT_IMAGE, .budget = 120};
    srun r;
    rp_exp_log(S->p, "stability/shadow: reference");
    if ((st = srun_do(S, sc, spec, &so, &r, err)) == RP_OK) {
        top_profile(r.img, W, W, 0.4, 0.6, ref);
        st = stab_png(S, "shadow_reference.png", r.img, W, W, 2 * strip_mean(ref, W, 0.7, 0.9), err);
        srun_free(&r);
    }
    const double b0 = edge - 0.06, b1 = edge + 0.06, f0 = 0.7, f1 = 0.95;
    rp_out o;
    char path[1200];
    if (st != RP_OK || (st = rp_out_open(&o, out_path(S, path, sizeof path, "shadow_profile.csv"), err)) != RP_OK) {
        free(ref);
        free(prof);
        rp_scene_destroy(sc);
        return st;
    }
    double *profiles = calloc((2 * nh + 3) * W, sizeof *profiles);
    size_t nprof = 0;
    for (int g = 0; g < 2 && st == RP_OK; g++)
        for (size_t k = 0; k < nh && st == RP_OK; k++) {
            snprintf(spec, sizeof spec, "gauss-seidel:max-edge=%g%s", hs[k], g ? ":reconstruct=gouraud" : "");
            rp_exp_log(S->p, "stability/shadow: %s", spec);
            sopt sr = {.want = RP_WANT_IMAGE, .budget = 120};
            if ((st = srun_do(S, sc, spec, &sr, &r, err)) != RP_OK)
                break;
            top_profile(r.img, W, W, 0.4, 0.6, prof);
            if (profiles)
                memcpy(profiles + nprof++ * W, prof, W * sizeof *prof);
            shrow *w = &rows[nrows++];
            snprintf(w->label, sizeof w->label, "gauss-seidel %s", g ? "gouraud" : "flat");
            w->h = hs[k];
            rp_mesh *mesh = NULL;
            rp_mesh_params mp = {.size = sizeof mp, .max_edge = hs[k]};
            if ((st = rp_mesh_create(sc, &mp, &mesh, err)) == RP_OK)
                w->elements = (double)rp_mesh_nelements(mesh);
            rp_mesh_destroy(mesh);
            w->band = strip_rmse(prof, ref, W, b0, b1);
            w->far = strip_rmse(prof, ref, W, f0, f1);
            w->secs = r.seconds;
            if (g == 0 && k == nh - 1)
                st = stab_png(S, "shadow_gs_flat_finest.png", r.img, W, W, 2 * strip_mean(ref, W, 0.7, 0.9), err);
            srun_free(&r);
        }
    static const char *const others[3][2] = {{"hierarchical (default)", "hierarchical"},
                                             {"hierarchical bf-epsilon 5e-4", "hierarchical:bf-epsilon=5e-4"},
                                             {"pathtrace 16 spp", "pathtrace:spp=16"}};
    for (int k = 0; k < 3 && st == RP_OK; k++) {
        rp_exp_log(S->p, "stability/shadow: %s", others[k][0]);
        sopt sr = {.want = RP_WANT_IMAGE, .budget = 120, .seed = 7};
        if ((st = srun_do(S, sc, others[k][1], &sr, &r, err)) != RP_OK)
            break;
        top_profile(r.img, W, W, 0.4, 0.6, prof);
        if (profiles)
            memcpy(profiles + nprof++ * W, prof, W * sizeof *prof);
        shrow *w = &rows[nrows++];
        snprintf(w->label, sizeof w->label, "%s", others[k][0]);
        w->h = NAN;
        w->elements = NAN;
        w->band = strip_rmse(prof, ref, W, b0, b1);
        w->far = strip_rmse(prof, ref, W, f0, f1);
        w->secs = r.seconds;
        srun_free(&r);
    }
    if (st == RP_OK) {
        fputs("x,reference", o.f);
        for (size_t k = 0; k < nrows; k++) {
            if (isfinite(rows[k].h))
                fprintf(o.f, ",%s h=%g", rows[k].label, rows[k].h);
            else
                fprintf(o.f, ",%s", rows[k].label);
        }
        fputs("\n", o.f);
        for (uint32_t x = 0; x < W; x++) {
            put(S, o.f, "%.5f,", top_col_x(x, W), "shadow x");
            put(S, o.f, "%.6g", ref[x], "shadow ref");
            for (size_t k = 0; k < nprof && profiles; k++)
                put(S, o.f, ",%.6g", profiles[k * W + x], "shadow profile");
            fputs("\n", o.f);
        }
    }
    free(profiles);
    st = rp_out_close(&o, st == RP_OK, err) == RP_OK ? st : RP_ERR_RUNTIME;
    rp_scene_destroy(sc);
    free(ref);
    free(prof);
    if (st != RP_OK)
        return st;
    rp_fit fits[2][2];
    for (int g = 0; g < 2; g++) {
        double x[8], yb[8], yf[8];
        for (size_t k = 0; k < nh; k++) {
            x[k] = rows[g * nh + k].h;
            yb[k] = rows[g * nh + k].band;
            yf[k] = rows[g * nh + k].far;
        }
        rp_fit_loglog(x, yb, nh, 0.95, &fits[g][0]);
        rp_fit_loglog(x, yf, nh, 0.95, &fits[g][1]);
    }
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "shadow.csv"), err)) != RP_OK)
        return st;
    fputs("method,max_edge,elements,rmse_boundary_band,rmse_far_lit,seconds\n", o.f);
    for (size_t k = 0; k < nrows; k++) {
        fprintf(o.f, "%s,", rows[k].label);
        if (isfinite(rows[k].h))
            fprintf(o.f, "%g,%.0f,", rows[k].h, rows[k].elements);
        else
            fputs(",,", o.f);
        put(S, o.f, "%.6g,", rows[k].band, "shadow band");
        put(S, o.f, "%.6g,", rows[k].far, "shadow far");
        put(S, o.f, "%.4g\n", rows[k].secs, "shadow seconds");
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    char body[2048];
    snprintf(body, sizeof body,
             "@PNG\nset output 'shadow_error.png'\nset logscale xy\nset xlabel 'max-edge h'\n"
             "set ylabel 'image RMSE against the reference'\n"
             "set title 'Sharp shadow: error at the boundary and far from it'\n"
             "plot 'shadow.csv' skip 1 every ::0::%zu using 2:4 with linespoints lw 2 pt 7 title 'flat, boundary band', "
             "'' skip 1 every ::0::%zu using 2:5 with linespoints lw 2 pt 7 title 'flat, far lit', "
             "'' skip 1 every ::%zu::%zu using 2:4 with linespoints lw 2 pt 5 title 'gouraud, boundary band', "
             "'' skip 1 every ::%zu::%zu using 2:5 with linespoints lw 2 pt 5 title 'gouraud, far lit'\n"
             "@SVG\nset output 'shadow_error.svg'\nreplot\nunset output\n"
             "@PNG\nset output 'shadow_profile.png'\nunset logscale\nset xrange [0.45:0.7]\n"
             "set xlabel 'x on the floor'\nset ylabel 'radiance, mean over z in [0.4, 0.6]'\n"
             "set title 'Profile across the shadow edge (x = %.3f)'\n"
             "plot 'shadow_profile.csv' using 1:2 with lines lw 3 lc rgb 'black' title columnheader(2), "
             "for [i=3:%zu] '' using 1:i with lines lw 1.5 title columnheader(i)\n"
             "@SVG\nset output 'shadow_profile.svg'\nreplot\nunset output\n",
             nh - 1, nh - 1, nh, 2 * nh - 1, nh, 2 * nh - 1, edge, 2 + 2 * nh);
    if ((st = stab_plot(S, "shadow", body, err)) != RP_OK)
        return st;
    FILE *f = S->md;
    fprintf(f, "## 5. A sharp shadow: error against element size\n\n"
               "A lamp 0.04 wide at height 1 and a plate at height 0.3 cast a shadow whose edge crosses the floor "
               "at x = %.3f with a penumbra 0.017 wide. Gauss-Seidel (analytic form factors) at max-edge h, "
               "against a path-traced reference (%lu spp, %u x %u, top-down): image RMSE over the columns within "
               "0.06 of the edge (boundary band) and over x in [0.7, 0.95] (far lit floor), rows with z in "
               "[0.4, 0.6].\n\n![error](shadow_error.png)\n\n![profile](shadow_profile.png)\n\n"
               "Images: ![reference](shadow_reference.png) ![flat, finest](shadow_gs_flat_finest.png)\n\n"
               "| method | h | elements | RMSE boundary band | RMSE far lit | seconds |\n|---|---|---|---|---|---|\n",
            edge, ref_spp, W, W);
    for (size_t k = 0; k < nrows; k++) {
        fprintf(f, "| %s | ", rows[k].label);
        if (isfinite(rows[k].h))
            fprintf(f, "%g | %.0f | ", rows[k].h, rows[k].elements);
        else
            fputs("adaptive | | ", f);
        put(S, f, "%.4g | ", rows[k].band, "shadow band");
        put(S, f, "%.4g | ", rows[k].far, "shadow far");
        put(S, f, "%.3g |\n", rows[k].secs, "shadow seconds");
    }
    fprintf(f, "\nObserved order (slope of log RMSE against log h, 95%% interval):\n\n| reconstruction | boundary "
               "band | far lit |\n|---|---|---|\n");
    for (int g = 0; g < 2; g++) {
        fprintf(f, "| %s |", g ? "gouraud" : "flat");
        for (int b = 0; b < 2; b++) {
            if (fits[g][b].ok)
                fprintf(f, " %.2f [%.2f, %.2f] |", fits[g][b].slope, fits[g][b].lo, fits[g][b].hi);
            else
                fputs(" n/a |", f);
        }
        fputs("\n", f);
    }
    fprintf(f, "\nNot run: jacobi, southwell and direct (the same system and mesh as gauss-seidel), "
               "stochastic Jacobi (the same piecewise-constant elements, plus noise).\n");
    fprintf(f, "\n**Failure signature.** Where the shadow edge cuts through elements the piecewise-constant "
               "answer is wrong by O(1) over a band one element wide, so the boundary error falls only like "
               "h^(1/2) (RMSE over a fixed band: the fitted boundary slopes above sit near 1/2, with wide "
               "intervals, against about 1 (flat) and 2 to 3 (Gouraud) far from the edge); hierarchical "
               "refinement spends its elements at the edge instead and beats every uniform mesh there.\n\n");
    return RP_OK;
}

/* --------------------------------------- 6. thin and coincident geometry */

/* The rotation every point of the acne scene goes through: about z by
 * 0.5 rad, then about x by 0.3 rad, then a shift, so no face is aligned
 * with the axes and surface points do not round onto their planes. */
static void acne_xf(double x, double y, double z, double out[3])
{
    double c = cos(0.5), s = sin(0.5), cb = cos(0.3), sb = sin(0.3);
    double x1 = c * x - s * y, y1 = s * x + c * y;
    double y2 = cb * y1 - sb * z, z2 = sb * y1 + cb * z;
    out[0] = x1 + 0.123;
    out[1] = y2 + 0.456;
    out[2] = z2 + 0.789;
}

static size_t acne_quad(char *buf, size_t n, const char *name, const double v[4][3])
{
    size_t used = (size_t)snprintf(buf, n, "quad %s w", name);
    for (int i = 0; i < 4 && used < n; i++) {
        double p[3];
        acne_xf(v[i][0], v[i][1], v[i][2], p);
        used += (size_t)snprintf(buf + used, n - used, "  %.17g %.17g %.17g", p[0], p[1], p[2]);
    }
    if (used < n)
        used += (size_t)snprintf(buf + used, n - used, "\n");
    return used;
}

/* An axis box [lo, hi] as six named quads, facing out (sign +1) or in. */
static size_t acne_box(char *buf, size_t n, const char *prefix, const double lo[3], const double hi[3], int out)
{
    size_t used = 0;
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            int u = (axis + 1) % 3, w = (axis + 2) % 3;
            double v[4][3];
            double a = side ? hi[axis] : lo[axis];
            /* corners in (u, w); counter-clockwise about +axis */
            double cu[4] = {lo[u], hi[u], hi[u], lo[u]}, cw[4] = {lo[w], lo[w], hi[w], hi[w]};
            int facing_plus = (side == 1) == (out != 0);
            for (int i = 0; i < 4; i++) {
                int j = facing_plus ? i : 3 - i;
                v[i][axis] = a;
                v[i][u] = cu[j];
                v[i][w] = cw[j];
            }
            char name[64];
            snprintf(name, sizeof name, "%s_%c%s", prefix, "xyz"[axis], side ? "hi" : "lo");
            used += acne_quad(buf + used, n - used, name, v);
        }
    return used;
}

static rp_status sec_acne(stab *S, rp_error *err)
{
    static const double offs_full[] = {0, 1e-9, 1e-7, 1e-5, 1e-4, 1e-3, 1e-2};
    static const double offs_quick[] = {0, 1e-7, 1e-5, 1e-3, 1e-2};
    const double *offs = S->quick ? offs_quick : offs_full;
    const size_t no = S->quick ? 5 : 7;
    const double gap = 1e-3, thick = 5e-3;
    char *text = malloc(16384);
    if (!text)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    size_t used = (size_t)snprintf(text, 16384,
                                   "# a furnace (every surface reflects 0.5 and emits 1, so L = 2 everywhere), "
                                   "rotated off the axes: a room, a slab %g thick hovering %g above the floor, and "
                                   "a zero-thickness two-sided panel (two coincident quads facing opposite ways)\n"
                                   "bands grey\nmaterial w reflect 0.5 emit 1\n",
                                   thick, gap);
    double eye[3], look[3], up0[3], up[3];
    acne_xf(0.5, 0.55, 0.03, eye);
    acne_xf(0.5, 0.05, 0.75, look);
    acne_xf(0.5, 1.55, 0.03, up0);
    for (int i = 0; i < 3; i++)
        up[i] = up0[i] - eye[i];
    used += (size_t)snprintf(text + used, 16384 - used,
                             "camera eye %.17g %.17g %.17g look %.17g %.17g %.17g up %.17g %.17g %.17g fov 75 size %d %d\n",
                             eye[0], eye[1], eye[2], look[0], look[1], look[2], up[0], up[1], up[2],
                             S->quick ? 64 : 96, S->quick ? 64 : 96);
    const double rlo[3] = {0, 0, 0}, rhi[3] = {1, 1, 1};
    used += acne_box(text + used, 16384 - used, "room", rlo, rhi, 0);
    const double slo[3] = {0.2, gap, 0.2}, shi[3] = {0.8, gap + thick, 0.8};
    used += acne_box(text + used, 16384 - used, "slab", slo, shi, 1);
    /* the panel: two coincident quads; the variant gives it a thickness
     * (a closed box 0.002 thick), which is what removes the coincidence */
    const size_t panel_at = used;
    const double pa[4][3] = {{0.2, 0.3, 0.5}, {0.8, 0.3, 0.5}, {0.8, 0.8, 0.5}, {0.2, 0.8, 0.5}};
    const double pb[4][3] = {{0.2, 0.3, 0.5}, {0.2, 0.8, 0.5}, {0.8, 0.8, 0.5}, {0.8, 0.3, 0.5}};
    used += acne_quad(text + used, 16384 - used, "panel_front", pa);
    acne_quad(text + used, 16384 - used, "panel_back", pb);
    rp_scene *sc = NULL, *sc_thick = NULL;
    rp_status st = stab_scene(S, "thin-coincident", text, &sc, err);
    if (st == RP_OK) {
        const double plo[3] = {0.2, 0.3, 0.499}, phi[3] = {0.8, 0.8, 0.501};
        acne_box(text + panel_at, 16384 - panel_at, "panel", plo, phi, 1);
        st = stab_scene(S, "thin-separated", text, &sc_thick, err);
    }
    free(text);
    if (st != RP_OK) {
        rp_scene_destroy(sc);
        return st;
    }
    /* Every face of the furnace is lit, so the ray caster's centre c is the
     * centre of the scene's box, and the largest offset any ray gets,
     * offset x |p - c|_inf, is offset x hmax, half the box's longest side. */
    rp_vec3 blo, bhi;
    rp_scene_bounds(sc, &blo, &bhi);
    const double L = 2, hmax = 0.5 * fmax(bhi.x - blo.x, fmax(bhi.y - blo.y, bhi.z - blo.z));
    char pts[96], gss[96], sjs[96];
    snprintf(pts, sizeof pts, "pathtrace:samples=%d:batch=%d", S->quick ? 256 : 1024, S->quick ? 256 : 1024);
    snprintf(gss, sizeof gss, "gauss-seidel:elements=%d", S->quick ? 150 : 300);
    snprintf(sjs, sizeof sjs, "stochastic-jacobi:elements=%d:rays=%d", S->quick ? 150 : 300, S->quick ? 10000 : 100000);
    struct {
        const char *label, *spec;
    } M[] = {{"pathtrace", pts},
             {"gauss-seidel", gss},
             {"stochastic-jacobi", sjs},
             {"hierarchical", "hierarchical:bf-epsilon=2e-2:min-area=1e-3"}};
    const size_t nm = sizeof M / sizeof M[0];
    typedef struct arow {
        double off;
        double mean_err[4], worst_err[4], max_err[4], max_se[4];
        char worst_name[4][32];
        int failed[4];
        char msg[4][400];
    } arow;
    arow rows[9];
    /* rows[no]: the panel given a thickness, default offset */
    for (size_t k = 0; k <= no && st == RP_OK; k++) {
        const rp_scene *scene = k < no ? sc : sc_thick;
        const rp_surface *surfs = rp_scene_surfaces(scene);
        double area = rp_scene_total_area(scene);
        rows[k].off = k < no ? offs[k] : RP_RAYCAST_DEFAULT_OFFSET;
        for (size_t m = 0; m < nm && st == RP_OK; m++) {
            char spec[200];
            if (k < no)
                snprintf(spec, sizeof spec, "%s:ray-offset=%g", M[m].spec, offs[k]);
            else
                snprintf(spec, sizeof spec, "%s", M[m].spec);
            rp_exp_log(S->p, "stability/acne: %s", spec);
            sopt so = {.want = RP_WANT_SURFACES, .budget = 60};
            srun r;
            rp_error rerr;
            rows[k].failed[m] = 0;
            if ((st = srun_do(S, scene, spec, &so, &r, &rerr)) != RP_OK) {
                if (st == RP_ERR_NOMEM || st == RP_ERR_INTERRUPTED) {
                    rp_error_set(err, st, "%s", rerr.message);
                    break;
                }
                /* a refusal is a signature, not a failure of the atlas */
                rows[k].failed[m] = 1;
                snprintf(rows[k].msg[m], sizeof rows[k].msg[m], "%.380s", rerr.message);
                rp_exp_log(S->p, "  refused: %s", rerr.message);
                st = RP_OK;
                continue;
            }
            double mean = 0, worst = -1;
            size_t wi = 0;
            size_t gi = 0;
            for (size_t i = 0; i < r.ns; i++) {
                double e = (r.surf[i] - L) / L;
                mean += surfs[i].area * e;
                if (e > (r.surf[gi] - L) / L)
                    gi = i;
                if (fabs(e) > worst) {
                    worst = fabs(e);
                    wi = i;
                }
            }
            rows[k].mean_err[m] = mean / area;
            rows[k].worst_err[m] = (r.surf[wi] - L) / L;
            rows[k].max_err[m] = (r.surf[gi] - L) / L;
            rows[k].max_se[m] = r.se ? r.se[gi] / L : 0;
            snprintf(rows[k].worst_name[m], sizeof rows[k].worst_name[m], "%s", surfs[wi].name);
            srun_free(&r);
        }
    }
    /* renders: the path tracer's acne and leaks */
    static const double shots[3] = {0, 1e-5, 1e-2};
    for (int k = 0; k < 3 && st == RP_OK; k++) {
        char spec[128], png[64];
        snprintf(spec, sizeof spec, "pathtrace:spp=%d:ray-offset=%g", S->quick ? 8 : 32, shots[k]);
        snprintf(png, sizeof png, "acne_pt_offset_%g.png", shots[k]);
        sopt so = {.want = RP_WANT_IMAGE, .budget = 60};
        srun r;
        if ((st = srun_do(S, sc, spec, &so, &r, err)) == RP_OK)
            st = stab_png(S, png, r.img, r.w, r.h, 2 * L, err);
        srun_free(&r);
    }
    rp_scene_destroy(sc);
    rp_scene_destroy(sc_thick);
    if (st != RP_OK)
        return st;
    char path[1200];
    rp_out o;
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "acne.csv"), err)) != RP_OK)
        return st;
    fputs("scene,ray_offset_rel,ray_offset_max,method,refused,mean_signed_error,worst_signed_error,worst_surface,"
          "max_signed_error,max_standard_error\n",
          o.f);
    for (size_t k = 0; k <= no; k++)
        for (size_t m = 0; m < nm; m++) {
            fprintf(o.f, "%s,%g,%g,%s,%d,", k < no ? "thin-coincident" : "thin-separated", rows[k].off,
                    rows[k].off * hmax, M[m].label, rows[k].failed[m]);
            if (rows[k].failed[m]) {
                fputs(",,,,\n", o.f);
                continue;
            }
            put(S, o.f, "%.6g,", rows[k].mean_err[m], "acne mean");
            put(S, o.f, "%.6g,", rows[k].worst_err[m], "acne worst");
            fprintf(o.f, "%s,", rows[k].worst_name[m]);
            put(S, o.f, "%.6g,", rows[k].max_err[m], "acne gain");
            put(S, o.f, "%.6g\n", rows[k].max_se[m], "acne gain's standard error");
        }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    if ((st = rp_out_open(&o, out_path(S, path, sizeof path, "acne.dat"), err)) != RP_OK)
        return st;
    for (size_t m = 0; m < nm; m++) {
        fprintf(o.f, "# %s: offset (0 as 1e-11), worst |relative error|\n", M[m].label);
        for (size_t k = 0; k < no; k++)
            if (!rows[k].failed[m] && isfinite(rows[k].worst_err[m]))
                fprintf(o.f, "%g,%.6g\n", rows[k].off > 0 ? rows[k].off : 1e-11,
                        fabs(rows[k].worst_err[m]) > 1e-6 ? fabs(rows[k].worst_err[m]) : 1e-6);
        fputs("\n\n", o.f);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    const char *body =
        "@PNG\nset output 'acne.png'\nset logscale xy\nset xlabel 'ray offset, relative to the point |p - c|_inf (0 plotted at 1e-11)'\n"
        "set ylabel 'worst |relative error| of a surface average'\n"
        "set title 'Furnace with thin and coincident geometry: error against the ray offset'\n"
        "plot for [i=0:3] 'acne.dat' index i using 1:2 with linespoints lw 2 pt 7 "
        "title word('pathtrace gauss-seidel stochastic-jacobi hierarchical', i + 1)\n"
        "@SVG\nset output 'acne.svg'\nreplot\nunset output\n";
    if ((st = stab_plot(S, "acne", body, err)) != RP_OK)
        return st;
    FILE *f = S->md;
    fprintf(f, "## 6. Thin and coincident geometry: acne, leaks and the ray offset\n\n"
               "A furnace rotated off the axes (every surface reflects 0.5 and emits 1: L = 2 exactly, whatever "
               "the geometry inside): a closed room, a slab %g thick hovering %g above the floor, and a "
               "zero-thickness two-sided panel (two coincident quads facing opposite ways). Every method runs "
               "with `--ray-offset` (a ray leaving point p starts offset x |p - c|_inf off the surface, c the "
               "centre of the lit faces' box, so at most offset x %.4g here; default 1e-5; hits on faces whose "
               "plane holds p are rejected at every offset). Errors are relative, signed (negative = light lost); "
               "worst = the surface with the largest "
               "|error| (acne.csv also gives each run's largest gain, max_signed_error, with that surface's relative standard error, 0 for the deterministic methods). The hemicube form factors cast no visibility rays (they rasterise with their own "
               "near-plane epsilon), so `--ray-offset` does not apply to them. jacobi, southwell and "
               "direct share gauss-seidel's raycaster and form factors (solvers/radiosity/system.c), so their "
               "visibility, and their leaks, are the same.\n\n![acne](acne.png)\n\n"
               "Path-traced renders at offsets 0, 1e-5 and 1e-2: ![0](acne_pt_offset_0.png) "
               "![1e-5](acne_pt_offset_1e-05.png) ![1e-2](acne_pt_offset_0.01.png)\n\n"
               "| offset (rel.) | largest offset (abs.) |",
            thick, gap, hmax);
    for (size_t m = 0; m < nm; m++)
        fprintf(f, " %s mean | %s worst (surface) |", M[m].label, M[m].label);
    fprintf(f, "\n|---|---|");
    for (size_t m = 0; m < nm; m++)
        fputs("---|---|", f);
    fputs("\n", f);
    for (size_t k = 0; k <= no; k++) {
        if (k < no)
            fprintf(f, "| %g | %.3g |", rows[k].off, rows[k].off * hmax);
        else
            fprintf(f, "| %g, **panel 0.002 thick** | %.3g |", rows[k].off, rows[k].off * hmax);
        for (size_t m = 0; m < nm; m++) {
            if (rows[k].failed[m]) {
                fputs(" **refused** (see below) | |", f);
                continue;
            }
            put(S, f, " %+.4f |", rows[k].mean_err[m], "acne mean");
            put(S, f, " %+.4f", rows[k].worst_err[m], "acne worst");
            fprintf(f, " (%s) |", rows[k].worst_name[m]);
        }
        fputs("\n", f);
    }
    int any = 0;
    for (size_t k = 0; k <= no; k++)
        for (size_t m = 0; m < nm; m++)
            if (rows[k].failed[m]) {
                if (!any++)
                    fputs("\nRuns the method refused (its own checks caught the damage):\n\n", f);
                fprintf(f, "* offset %g, %s: `%s`\n", rows[k].off, M[m].label, rows[k].msg[m]);
            }
    fprintf(f, "\n**Failure signature.** No acne at any offset: a ray leaving a surface may start on it (offset "
               "0), because a hit on a face whose plane holds the ray's origin, which no real hit can be, is "
               "rejected in double precision (geometry/raycast.c, rule 2; before, rays started on their own "
               "face re-hit it or its coincident twin about half the time and every method lost light "
               "everywhere). Offsets from 0 up to well below the gap (%g) give the same answer to the "
               "methods' noise; once the offset exceeds the gap between slab and floor (offset x |p - c|_inf "
               "> %g under the slab), rays leaving the floor there start inside the slab and those leaving "
               "the slab's underside start below the floor: light leaks and the surfaces there go dark. The "
               "coincident panel is a separate artefact no offset removes: a ray *arriving* at it meets two "
               "faces at the same distance, and Embree reports the back-facing one about half the time, so "
               "light sent to the panel is lost (the Monte Carlo methods' worst surfaces at every offset: the "
               "panel itself, or the wall facing it). Giving the panel a thickness (last row: a closed box "
               "0.002 thick, default offset) removes it.\n\n",
            gap, gap);
    return RP_OK;
}

/* ---------------------------------------------- 7. non-physical input */

static rp_status sec_nonphysical(stab *S, rp_error *err)
{
    static const char *const cases[][3] = {
        {"reflect-one", "reflectance exactly 1", "bands grey\nmaterial w reflect 1 emit 1\nbox room w 0 0 0 1 1 1 inward\n"},
        {"reflect-above-one", "reflectance 1.5",
         "bands grey\nmaterial w reflect 0.5\nmaterial bad reflect 1.5\nmaterial l reflect 0 emit 1\n"
         "box room w 0 0 0 1 1 1 inward\nquad lamp l 0.4 0.99 0.4  0.6 0.99 0.4  0.6 0.99 0.6  0.4 0.99 0.6\n"
         "quad hot bad 0.2 0.01 0.2  0.2 0.01 0.4  0.4 0.01 0.4  0.4 0.01 0.2\n"},
        {"reflect-one-rgb", "reflectance 1 in one band of three",
         "bands rgb\nmaterial w reflect 0.5 1 0.5 emit 1\nbox room w 0 0 0 1 1 1 inward\n"},
        {"reflect-spectrum-above-one", "a reflectance spectrum reaching 1.2",
         "bands 450 550 650\nmaterial w reflect spectrum 400:0.5 700:1.2 emit 1\nbox room w 0 0 0 1 1 1 inward\n"},
        {"reflect-negative", "reflectance -0.1",
         "bands grey\nmaterial w reflect -0.1 emit 1\nbox room w 0 0 0 1 1 1 inward\n"},
        {"emit-negative", "emission -1",
         "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit -1\nbox room w 0 0 0 1 1 1 inward\n"
         "quad lamp l 0.4 0.99 0.4  0.6 0.99 0.4  0.6 0.99 0.6  0.4 0.99 0.6\n"},
        {"emit-nan", "emission NaN", "bands grey\nmaterial w reflect 0.5 emit nan\nbox room w 0 0 0 1 1 1 inward\n"},
        {"emit-inf", "emission infinite", "bands grey\nmaterial w reflect 0.5 emit inf\nbox room w 0 0 0 1 1 1 inward\n"},
        {"reflect-nan", "reflectance NaN", "bands grey\nmaterial w reflect nan emit 1\nbox room w 0 0 0 1 1 1 inward\n"},
        {"obj-kd-above-one", "OBJ + MTL with Kd 1.2 (scene file `obj-kd-above-one.obj`)", NULL},
    };
    const size_t nc = sizeof cases / sizeof cases[0];
    char dir[1024];
    rp_status st = rp_mkdirs(out_path(S, dir, sizeof dir, "scenes"), err);
    if (st != RP_OK)
        return st;
    char path[1400], file[256];
    rp_out o;
    /* the OBJ case: a box of two triangles per face is not needed; one
     * emitting triangle facing a reflecting one */
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "obj-kd-above-one.mtl"), err)) != RP_OK)
        return st;
    fputs("newmtl hot\nKd 1.2 1.2 1.2\nnewmtl lamp\nKd 0 0 0\nKe 1 1 1\n", o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "obj-kd-above-one.obj"), err)) != RP_OK)
        return st;
    fputs("mtllib obj-kd-above-one.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nv 0 1 0\nv 0 1 1\nv 1 1 0\n"
          "usemtl hot\nf 1 3 2\nusemtl lamp\nf 4 6 5\n",
          o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    FILE *f = S->md;
    fprintf(f, "## 7. Non-physical input\n\n"
               "Each scene below is written to `scenes/` in this directory and loaded with the scene parser "
               "(the same call `radpt info`, `render` and `probe` make first); the exit status is the one the "
               "command line gives for that status (`rp_status_exit_code`: 2 = bad input). Nothing is solved: "
               "refusal happens before any solver runs, so no NaN can reach an output and nothing can hang.\n\n"
               "| case | file | refused | exit status | seconds | message |\n|---|---|---|---|---|---|\n");
    rp_out csv;
    if ((st = rp_out_open(&csv, out_path(S, path, sizeof path, "nonphysical.csv"), err)) != RP_OK)
        return st;
    fputs("case,file,refused,exit_status,seconds,message\n", csv.f);
    size_t refused = 0;
    for (size_t k = 0; k < nc && st == RP_OK; k++) {
        if (cases[k][2]) {
            snprintf(file, sizeof file, "nonphysical-%s.scene", cases[k][0]);
            if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, file), err)) != RP_OK)
                break;
            fputs(cases[k][2], o.f);
            if ((st = rp_out_close(&o, 1, err)) != RP_OK)
                break;
        } else {
            snprintf(file, sizeof file, "%s.obj", cases[k][0]);
            rp_path_join(path, sizeof path, dir, file);
        }
        rp_scene *sc = NULL;
        rp_error perr;
        rp_error_clear(&perr);
        double t0 = rp_clock();
        rp_status ps = rp_scene_load(path, &sc, &perr);
        double secs = rp_clock() - t0;
        rp_scene_destroy(sc);
        int code = rp_status_exit_code(ps);
        refused += ps != RP_OK;
        /* the message names the file by its path in DIR: keep it from
         * "scenes/" on so the report does not depend on DIR */
        const char *msg = ps == RP_OK ? "(accepted)" : perr.message;
        const char *rel = strstr(msg, "scenes/");
        if (rel)
            msg = rel;
        /* markdown: escape the table separator; CSV: quote */
        char clean[1024], quoted[1100];
        size_t j = 0, q = 0;
        quoted[q++] = '"';
        for (const char *c = msg; *c && j + 2 < sizeof clean && q + 3 < sizeof quoted; c++) {
            if (*c == '|')
                clean[j++] = '\\';
            clean[j++] = *c == '\n' ? ' ' : *c;
            if (*c == '"')
                quoted[q++] = '"';
            quoted[q++] = *c == '\n' ? ' ' : *c;
        }
        clean[j] = '\0';
        quoted[q++] = '"';
        quoted[q] = '\0';
        fprintf(f, "| %s | `scenes/%s` | %s | %d | ", cases[k][1], file, ps != RP_OK ? "yes" : "**no**", code);
        put(S, f, "%.2g | ", secs, "nonphysical seconds");
        fprintf(f, "`%s` |\n", clean);
        fprintf(csv.f, "%s,scenes/%s,%d,%d,", cases[k][0], file, ps != RP_OK, code);
        put(S, csv.f, "%.3g,", secs, "nonphysical seconds");
        fprintf(csv.f, "%s\n", quoted);
        rp_exp_log(S->p, "stability/nonphysical %s: %s", cases[k][0], clean);
    }
    rp_status st2 = rp_out_close(&csv, st == RP_OK, err);
    if (st == RP_OK)
        st = st2;
    if (st != RP_OK)
        return st;
    fprintf(f, "\n%zu of %zu refused. **Failure signature:** none: each is refused with the file, line and "
               "value named and exit status 2 (a reflectance of 1 would make the furnace answer infinite and "
               "the iterations never converge; a negative emission has no physical meaning).\n\n",
            refused, nc);
    if (refused != nc)
        return rp_error_set(err, RP_ERR_RUNTIME, "experiment stability: %zu non-physical scenes were accepted",
                            nc - refused);
    return RP_OK;
}

/* ------------------------------------------------------------- the atlas */

rp_status rp_exp_stability(const rp_experiment_params *p, rp_error *err)
{
    stab S = {.p = p, .quick = p->quick};
    rp_status st = rp_mkdirs(p->out_dir, err);
    if (st != RP_OK)
        return st;
    S.md = open_memstream(&S.mdbuf, &S.mdlen);
    if (!S.md)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    double t0 = rp_clock();
    struct {
        const char *name;
        rp_status (*run)(stab *, rp_error *);
        double seconds;
    } sections[] = {{"reflectance", sec_reflectance, 0}, {"small light", sec_small_light, 0},
                    {"corner", sec_corner, 0},           {"block", sec_block, 0},
                    {"shadow", sec_shadow, 0},           {"acne", sec_acne, 0},
                    {"non-physical", sec_nonphysical, 0}};
    const size_t ns = sizeof sections / sizeof sections[0];
    for (size_t i = 0; i < ns && st == RP_OK; i++) {
        double t1 = rp_clock();
        st = sections[i].run(&S, err);
        sections[i].seconds = rp_clock() - t1;
        rp_exp_log(S.p, "stability: %s took %.1f s", sections[i].name, sections[i].seconds);
    }
    double total = rp_clock() - t0;
    fclose(S.md);
    if (st == RP_OK) {
        char path[1200];
        rp_out o;
        if ((st = rp_out_open(&o, out_path(&S, path, sizeof path, "report.md"), err)) == RP_OK) {
            FILE *f = o.f;
            fprintf(f, "# Experiment stability: the stability atlas%s\n\n"
                       "Scenes built to push each method past its comfort zone, each run by every method that "
                       "applies, with the failure signature it demonstrates. Every number below is also in a CSV "
                       "next to this file; every number written was checked to be finite (%s). Scenes are in "
                       "`scenes/`.\n\n",
                    p->quick ? " (quick)" : "",
                    S.nonfinite ? "**some were not: see the end**" : "none was NaN or infinite");
            if (p->command)
                fprintf(f, "Command: `%s`\n\n", p->command);
            fprintf(f, "Runtime: %.1f s (", total);
            for (size_t i = 0; i < ns; i++)
                fprintf(f, "%s%s %.1f s", i ? ", " : "", sections[i].name, sections[i].seconds);
            fprintf(f, "); threads: %d.\n\n", p->threads > 0 ? p->threads : omp_get_max_threads());
            if (S.gp_note[0])
                fprintf(f, "**Note:** %s\n\n", S.gp_note);
            fwrite(S.mdbuf, 1, S.mdlen, f);
            if (S.nonfinite)
                fprintf(f, "## Non-finite numbers\n\n%zu numbers were not finite; the first: %s.\n", S.nonfinite,
                        S.first_bad);
            st = rp_out_close(&o, 1, err);
        }
    }
    free(S.mdbuf);
    if (st == RP_OK && S.nonfinite)
        st = rp_error_set(err, RP_ERR_RUNTIME, "experiment stability: %zu non-finite numbers (first: %s)",
                          S.nonfinite, S.first_bad);
    return st;
}
