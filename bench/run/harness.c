/* The benchmark harness (harness.h). */
#include "bench/run/harness.h"

#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "geometry/log.h"
#include "bench/run/mpi.h"

/* ------------------------------------------------------------- specs */

/* 1 if v is a number the placeholder arg (N: a count; any other
 * capitals, as FRAC, EPS, W: a real) takes. */
static int number_fits(const char *arg, size_t len, const char *v)
{
    char *end;
    double x = strtod(v, &end);
    if (end == v || *end || !isfinite(x))
        return 0;
    return !(len == 1 && arg[0] == 'N') || (x >= 0 && x == floor(x));
}

/* An alternative of an option's arg in capitals is a placeholder for a
 * number ("auto|FRAC" takes auto or a number); the others are words. */
static int placeholder(const char *w, size_t len)
{
    for (size_t i = 0; i < len; i++)
        if (w[i] < 'A' || w[i] > 'Z')
            return 0;
    return len > 0;
}

/* The form of an option's value, checked before any run so that a bench
 * fails at once rather than after its other methods: one of the words of
 * an "a|b|c" argument, or a number where the argument (or one of its
 * alternatives, as in "auto|FRAC") is a placeholder in capitals (a whole
 * one >= 0 for "N"); ranges are the method's own check at init. */
static int value_fits(const rp_option_spec *spec, const char *v)
{
    const size_t n = strlen(v);
    for (const char *w = spec->arg; *w;) {
        size_t len = strcspn(w, "|");
        if (placeholder(w, len) ? number_fits(w, len, v) : (len == n && strncmp(w, v, n) == 0))
            return 1;
        w += len + (w[len] == '|');
    }
    return 0;
}

rp_status rp_method_spec_parse(const char *text, rp_method_spec *m, rp_error *err)
{
    memset(m, 0, sizeof *m);
    size_t len = strlen(text);
    if (len == 0)
        return rp_error_set(err, RP_ERR_INPUT, "empty method spec");
    if (len >= sizeof m->text)
        return rp_error_set(err, RP_ERR_INPUT, "method spec '%.40s...' is too long", text);
    memcpy(m->text, text, len + 1);
    memcpy(m->buf, text, len + 1);
    char *p = m->buf, *colon = strchr(p, ':');
    if (colon)
        *colon = '\0';
    if (strlen(p) >= sizeof m->name || !*p)
        return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': bad method name", text);
    strcpy(m->name, p);
    m->type = rp_solver_lookup(m->name);
    if (!m->type) {
        char known[512] = "";
        size_t used = 0;
        for (const rp_solver_type *const *t = rp_solver_types(); *t && used < sizeof known; t++)
            used += (size_t)snprintf(known + used, sizeof known - used, " %s", (*t)->name);
        return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': unknown method '%s'; known methods:%s", text,
                            m->name, known);
    }
    while (colon) {
        p = colon + 1;
        colon = strchr(p, ':');
        if (colon)
            *colon = '\0';
        if (!*p)
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': empty option", text);
        if (m->count == RP_SPEC_MAX_OPTIONS)
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': too many options", text);
        char *eq = strchr(p, '=');
        const rp_option_spec *spec = NULL;
        if (eq)
            *eq = '\0';
        for (const rp_option_spec *o = m->type->options; o && o->name; o++)
            if (strcmp(o->name, p) == 0)
                spec = o;
        if (!spec)
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': method %s has no option '%s' (see radpt help %s)",
                                text, m->name, p, m->name);
        if (!eq && spec->arg)
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': option '%s' needs a value (%s=%s)", text, p, p,
                                spec->arg);
        if (eq && !spec->arg)
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': option '%s' is a flag and takes no value", text,
                                p);
        if (eq && !value_fits(spec, eq + 1))
            return rp_error_set(err, RP_ERR_INPUT, "method spec '%s': %s=%s: expected %s%s", text, p, eq + 1,
                                strchr(spec->arg, '|') ? "one of " : "a value for ", spec->arg);
        m->keys[m->count] = spec->name;
        m->values[m->count++] = eq ? eq + 1 : "1";
    }
    return RP_OK;
}

rp_status rp_method_list_parse(const char *list, rp_method_spec **out, size_t *n, rp_error *err)
{
    *out = NULL;
    *n = 0;
    size_t cap = 1;
    for (const char *c = list; *c; c++)
        cap += *c == ',';
    rp_method_spec *m = calloc(cap, sizeof *m);
    char *copy = strdup(list);
    if (!m || !copy) {
        free(m);
        free(copy);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    size_t k = 0;
    rp_status st = RP_OK;
    char *save = NULL;
    for (char *tok = strtok_r(copy, ",", &save); tok && st == RP_OK; tok = strtok_r(NULL, ",", &save)) {
        while (*tok == ' ')
            tok++;
        st = rp_method_spec_parse(tok, &m[k], err);
        k += st == RP_OK;
    }
    free(copy);
    if (st == RP_OK && k == 0)
        st = rp_error_set(err, RP_ERR_INPUT, "no methods in '%s'", list);
    if (st != RP_OK) {
        free(m);
        return st;
    }
    *out = m;
    *n = k;
    return RP_OK;
}

const char *rp_method_spec_get(const rp_method_spec *m, const char *key)
{
    const char *v = NULL;
    for (size_t i = 0; i < m->count; i++)
        if (strcmp(m->keys[i], key) == 0)
            v = m->values[i];
    return v;
}

int rp_method_is_monte_carlo(const rp_method_spec *m)
{
    return m->type && m->type->monte_carlo;
}

/* A spec copied by value keeps pointers into the original's buffer;
 * re-point them at the copy's own. */
static void spec_copy(rp_method_spec *dst, const rp_method_spec *src)
{
    *dst = *src;
    for (size_t i = 0; i < src->count; i++) {
        if (src->values[i] >= src->buf && src->values[i] < src->buf + sizeof src->buf)
            dst->values[i] = dst->buf + (src->values[i] - src->buf);
    }
}

/* ------------------------------------------------------------ clocks */



/* --------------------------------------------------------------- run */

void rp_trial_free(rp_trial *run)
{
    if (!run)
        return;
    free(run->cp);
    free(run->image);
    free(run->surfaces);
    run->cp = NULL;
    run->image = NULL;
    run->surfaces = NULL;
    run->ncp = 0;
}

typedef struct run_ctx {
    const rp_scene *scene;
    const rp_reference *ref;
    rp_solver *solver;
    unsigned want;
    float *image;
    double *surf, *surf_se;
    size_t npix, nb, ns;
} run_ctx;

static rp_status measure(run_ctx *c, rp_checkpoint *cp, rp_error *err)
{
    double t0 = rp_clock();
    rp_estimate e = {.radiance = (c->want & RP_WANT_IMAGE) ? c->image : NULL,
                     .surface_radiance = (c->want & RP_WANT_SURFACES) ? c->surf : NULL,
                     .surface_stderr = (c->want & RP_WANT_SURFACES) ? c->surf_se : NULL};
    rp_status st = rp_solver_estimate(c->solver, &e, err);
    if (st != RP_OK)
        return st;
    cp->samples = e.samples;
    cp->rmse = cp->relmse = cp->mae = cp->surface_err = cp->rmse_debiased = NAN;
    const rp_reference *r = c->ref;
    if (e.radiance && r->radiance) {
        for (size_t i = 0; i < c->npix * c->nb; i++)
            if (!isfinite(c->image[i]))
                return rp_error_set(err, RP_ERR_RUNTIME, "non-finite radiance at pixel %zu", i / c->nb);
        rp_image_metrics im;
        rp_metrics_image(c->image, r->radiance, r->mask, c->npix, c->nb, &im);
        cp->rmse = im.rmse;
        cp->relmse = im.relmse;
        cp->mae = im.mae;
        /* below the reference's own noise the error is not resolved: no
         * value (an empty field, "n/a"), not a misleading 0 */
        rp_debiased_mse dm;
        rp_metrics_debiased_image(c->image, r->radiance, r->variance, r->mask, c->npix, c->nb, &dm);
        cp->rmse_debiased = isfinite(dm.mse) && dm.mse > 0 ? sqrt(dm.mse) : NAN;
        cp->ref_flag = dm.count && !rp_metrics_resolved(&dm);
    }
    if (e.surface_radiance) {
        cp->surface_err = rp_metrics_surface_error(c->surf, r->surface_radiance, r->surface_mask, c->ns, c->nb, NULL);
        rp_debiased_mse ds;
        rp_metrics_debiased_surfaces(c->surf, r->surface_radiance, r->surface_stderr, r->surface_mask, c->ns, c->nb,
                                     &ds);
        if (ds.count && !rp_metrics_resolved(&ds))
            cp->ref_flag = 1;
    }
    /* ref_flag: the reference does not resolve the error measured
     * (metrics.h: the debiased MSE and its standard error). */
    cp->measure_s = rp_clock() - t0;
    return RP_OK;
}

/* The harness's checkpoints: checkpoint k at the first step boundary where
 * the clock (solver seconds, or iterations) >= budget * 2^-k, k = levels -
 * 1 .. 0; when one step passes several thresholds only the last of them is
 * recorded; the run's last step (its rule or its budget) is recorded as the
 * next k. */
typedef struct checkpointing {
    run_ctx *c;
    rp_trial *run;
    const rp_harness_params *hp;
    double budget;
    int k;
} checkpointing;

static int checkpoint_after_step(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    (void)s;
    checkpointing *ck = ctx;
    const int done = t->stop != RP_STOP_NONE;
    const double clock = ck->hp->schedule == RP_SCHEDULE_ITERATIONS ? t->sum.iterations : t->wall_s;
    if (!(clock >= ldexp(ck->budget, -ck->k)) && !done)
        return 0;
    while (ck->k > 0 && clock >= ldexp(ck->budget, -(ck->k - 1)))
        ck->k--;
    rp_checkpoint *cp = &ck->run->cp[ck->run->ncp];
    cp->index = ck->k;
    cp->target = ldexp(ck->budget, -ck->k);
    cp->wall_s = t->wall_s;
    cp->cpu_s = t->cpu_s;
    cp->steps = t->steps;
    cp->rays = t->sum.rays;
    cp->paths = t->sum.paths;
    cp->iterations = t->sum.iterations;
    cp->form_factors = t->sum.form_factors;
    cp->residual = t->last.residual;
    cp->unshot = t->last.unshot;
    /* the method's own rule: its tolerance met (reported even when the
     * harness's budget, not the rule, ends the run), or it says so */
    cp->converged = t->last.converged ||
                    (t->last.tolerance >= 0 && t->last.residual >= 0 && t->last.residual <= t->last.tolerance);
    cp->peak_rss_mb = rp_peak_rss_mb();
    cp->solver_mb = t->last.memory / (1024.0 * 1024.0);
    if ((*st = measure(ck->c, cp, err)) != RP_OK)
        return 1;
    ck->run->ncp++;
    ck->k--;
    /* the last checkpoint taken: the run ends here */
    return ck->k < 0;
}

rp_status rp_harness_run(const rp_scene *scene, const rp_reference *ref, const rp_method_spec *m,
                         uint64_t seed, const rp_harness_params *hp, rp_trial *run, rp_error *err)
{
    memset(run, 0, sizeof *run);
    run->seed = seed;
    const unsigned levels = hp->levels ? hp->levels : 9;
    run_ctx c = {.scene = scene, .ref = ref, .nb = rp_scene_nbands(scene), .ns = rp_scene_nsurfaces(scene)};
    const rp_camera *cam = rp_scene_camera(scene);
    c.npix = cam && ref->radiance ? (size_t)cam->width * cam->height : 0;
    const int costly = m->type->surfaces_cost;
    c.want = (c.npix ? RP_WANT_IMAGE : 0) | (!costly || hp->surfaces_for_mc || !c.npix ? RP_WANT_SURFACES : 0);
    run->cp = calloc(levels + 1, sizeof *run->cp);
    c.image = c.npix ? malloc(c.npix * c.nb * sizeof *c.image) : NULL;
    c.surf = calloc(c.ns * c.nb + 1, sizeof *c.surf);
    c.surf_se = calloc(c.ns * c.nb + 1, sizeof *c.surf_se);
    if (!run->cp || (c.npix && !c.image) || !c.surf || !c.surf_se) {
        free(c.image);
        free(c.surf);
        free(c.surf_se);
        rp_trial_free(run);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }

    rp_options o = {.size = sizeof o, .want = c.want, .seed = seed, .threads = hp->threads,
                    .keys = m->keys, .values = m->values, .count = m->count, .open_ended = 1,
                    .cancel = hp->cancel};
    rp_error rerr;
    rp_error_clear(&rerr);
    rp_peak_rss_reset();
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    run->rank = rp_mpi_rank();
    run->threads = hp->threads ? hp->threads : omp_get_max_threads();
    rp_status st = rp_drive_create(m->type, scene, &o, &c.solver, &tot, &rerr);
    checkpointing ck = {.c = &c, .run = run, .hp = hp, .budget = hp->budget, .k = (int)levels - 1};
    char label[200];
    snprintf(label, sizeof label, "%.80s seed %llu", m->text, (unsigned long long)seed);
    rp_drive_params dp = {.size = sizeof dp, .budget = hp->budget, .schedule = hp->schedule,
                          .budget_base = tot.wall_s, .stop_at_rule = hp->stop_when_converged,
                          .cancel = hp->cancel, .after_step = checkpoint_after_step, .ctx = &ck,
                          .progress = hp->progress, .progress_ctx = hp->progress_ctx, .label = label};
    if (st == RP_OK)
        st = rp_drive(c.solver, &dp, &tot, &rerr);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(&rerr, RP_ERR_INTERRUPTED, "interrupted");
    if (run->ncp)
        run->cp[run->ncp - 1].final = 1;
    if (st == RP_OK && hp->keep_image && c.image) {
        run->image = c.image;
        c.image = NULL;
    }
    if (st == RP_OK && (c.want & RP_WANT_SURFACES)) {
        run->surfaces = c.surf;
        c.surf = NULL;
    }
    run->status = st;
    if (st != RP_OK)
        snprintf(run->error, sizeof run->error, "%s", rerr.message[0] ? rerr.message : rp_status_string(st));
    rp_solver_destroy(c.solver);
    free(c.image);
    free(c.surf);
    free(c.surf_se);
    return RP_OK;
}

/* ------------------------------------------------------------- bench */

void rp_bench_destroy(rp_bench *b)
{
    if (!b)
        return;
    for (size_t i = 0; i < b->nruns; i++)
        rp_trial_free(&b->runs[i]);
    for (size_t i = 0; b->summary && i < b->nmethods; i++)
        free(b->summary[i].pts);
    free(b->summary);
    free(b->runs);
    free(b->methods);
    free(b);
}

static void agg_rows(const rp_checkpoint *const *rows, size_t n, rp_agg *a)
{
    memset(a, 0, sizeof *a);
    a->n = n;
    double *v = calloc(n ? n : 1, sizeof *v);
    if (!v)
        return;
#define AGG(field, mean, sd)                                                                       \
    do {                                                                                           \
        double sd_;                                                                                \
        for (size_t i = 0; i < n; i++)                                                             \
            v[i] = rows[i]->field;                                                                 \
        rp_metrics_mean_sd(v, n, &a->mean, &sd_, NULL);                                            \
        sd;                                                                                        \
    } while (0)
    AGG(wall_s, wall_s, a->wall_sd = sd_);
    AGG(cpu_s, cpu_s, (void)sd_);
    AGG(samples, samples, (void)sd_);
    AGG(iterations, iterations, (void)sd_);
    AGG(rays, rays, (void)sd_);
    AGG(form_factors, form_factors, (void)sd_);
    AGG(peak_rss_mb, peak_rss_mb, (void)sd_);
    AGG(rmse, rmse, a->rmse_sd = sd_);
    AGG(relmse, relmse, a->relmse_sd = sd_);
    AGG(mae, mae, a->mae_sd = sd_);
    AGG(surface_err, surface_err, a->surface_err_sd = sd_);
    AGG(rmse_debiased, rmse_debiased, a->rmse_debiased_sd = sd_);
#undef AGG
    a->work = a->rays + a->form_factors;
    for (size_t i = 0; i < n; i++)
        a->ref_flag |= rows[i]->ref_flag;
    a->index = n ? rows[0]->index : 0;
    free(v);
}

void rp_bench_summarise(rp_bench *b)
{
    size_t levels = b->params.run.levels ? b->params.run.levels : 9;
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        rp_method_summary *s = &b->summary[mi];
        free(s->pts);
        memset(s, 0, sizeof *s);
        size_t total = 0;
        for (size_t r = 0; r < b->nruns; r++)
            if (b->runs[r].method == mi) {
                s->runs++;
                s->runs_ok += b->runs[r].status == RP_OK;
                total += b->runs[r].ncp;
            }
        const rp_checkpoint **rows = malloc((total + 1) * sizeof *rows);
        double *x = malloc((total + 1) * sizeof *x), *xw = malloc((total + 1) * sizeof *xw),
               *xs = malloc((total + 1) * sizeof *xs), *y = malloc((total + 1) * sizeof *y);
        s->pts = calloc(levels + 1, sizeof *s->pts);
        if (!rows || !x || !xw || !xs || !y || !s->pts) {
            free(rows);
            free(x);
            free(xw);
            free(xs);
            free(y);
            continue;
        }
        /* every row, for the fits */
        size_t n = 0;
        for (size_t r = 0; r < b->nruns; r++)
            if (b->runs[r].method == mi)
                for (size_t i = 0; i < b->runs[r].ncp; i++) {
                    const rp_checkpoint *cp = &b->runs[r].cp[i];
                    x[n] = cp->wall_s;
                    xw[n] = cp->rays + cp->form_factors;
                    xs[n] = cp->samples;
                    y[n++] = cp->rmse;
                }
        rp_fit_loglog(x, y, n, 0.95, &s->fit_time);
        rp_fit_loglog(xw, y, n, 0.95, &s->fit_work);
        rp_fit_loglog(xs, y, n, 0.95, &s->fit_samples);
        /* per checkpoint index, by increasing time */
        for (int k = (int)levels - 1; k >= 0; k--) {
            size_t m = 0;
            for (size_t r = 0; r < b->nruns; r++)
                if (b->runs[r].method == mi)
                    for (size_t i = 0; i < b->runs[r].ncp; i++)
                        if (b->runs[r].cp[i].index == k)
                            rows[m++] = &b->runs[r].cp[i];
            if (m)
                agg_rows(rows, m, &s->pts[s->npts++]);
        }
        size_t m = 0;
        for (size_t r = 0; r < b->nruns; r++)
            if (b->runs[r].method == mi && b->runs[r].ncp)
                rows[m++] = &b->runs[r].cp[b->runs[r].ncp - 1];
        agg_rows(rows, m, &s->final);
        free(rows);
        free(x);
        free(xw);
        free(xs);
        free(y);
    }
    /* The target RMSE: given, or the geometric mean of the best and the
     * worst final RMSE (twice the final RMSE with one method), so that some
     * methods reach it and some do not. */
    double lo = INFINITY, hi = 0;
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        double e = b->summary[mi].final.rmse;
        if (isfinite(e) && e > 0) {
            lo = e < lo ? e : lo;
            hi = e > hi ? e : hi;
        }
    }
    b->target_auto = !(b->params.target > 0);
    b->target = !b->target_auto ? b->params.target : (hi > 0 ? (lo < hi ? sqrt(lo * hi) : 2 * hi) : NAN);
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        rp_method_summary *s = &b->summary[mi];
        double *t = malloc((s->npts + 1) * sizeof *t), *e = malloc((s->npts + 1) * sizeof *e);
        s->time_to_target = NAN;
        if (t && e && isfinite(b->target)) {
            for (size_t i = 0; i < s->npts; i++) {
                t[i] = s->pts[i].wall_s;
                e[i] = s->pts[i].rmse;
            }
            s->time_to_target = rp_metrics_time_to_error(t, e, s->npts, b->target, &s->target_before);
        }
        free(t);
        free(e);
    }
}

/* ------------------------------------------------- journal records */

#define bench_log(b, ...) rp_logf((b)->params.log, (b)->params.log_ctx, __VA_ARGS__)

/* A finished run as journal numbers: status, rows, surface values, then
 * each row's fields; the error text under KEY#error, a kept image in
 * IMAGE_DIR/runs/ under the FNV hash of KEY (binary floats). */
#define CP_FIELDS 23

static void cp_to(const rp_checkpoint *c, double *v)
{
    double x[CP_FIELDS] = {c->index, c->target, c->wall_s, c->cpu_s, c->steps, c->rays, c->paths, c->iterations,
                           c->form_factors, c->samples, c->residual, c->unshot, c->peak_rss_mb, c->solver_mb,
                           c->rmse, c->relmse, c->mae, c->surface_err, c->rmse_debiased, c->measure_s, c->ref_flag,
                           c->converged, c->final};
    memcpy(v, x, sizeof x);
}

static void cp_from(const double *v, rp_checkpoint *c)
{
    c->index = (int)v[0];
    c->target = v[1];
    c->wall_s = v[2];
    c->cpu_s = v[3];
    c->steps = v[4];
    c->rays = v[5];
    c->paths = v[6];
    c->iterations = v[7];
    c->form_factors = v[8];
    c->samples = v[9];
    c->residual = v[10];
    c->unshot = v[11];
    c->peak_rss_mb = v[12];
    c->solver_mb = v[13];
    c->rmse = v[14];
    c->relmse = v[15];
    c->mae = v[16];
    c->surface_err = v[17];
    c->rmse_debiased = v[18];
    c->measure_s = v[19];
    c->ref_flag = (int)v[20];
    c->converged = (int)v[21];
    c->final = (int)v[22];
}

static size_t image_values(const rp_bench *b)
{
    const rp_camera *cam = rp_scene_camera(b->scene);
    return cam && b->ref->radiance ? (size_t)cam->width * cam->height * rp_scene_nbands(b->scene) : 0;
}

static void image_path(const rp_bench *b, const char *key, char *out, size_t n)
{
    char h[17], name[64];
    rp_hash_text(key, h);
    snprintf(name, sizeof name, "runs/%s.f32", h);
    rp_path_join(out, n, b->params.image_dir ? b->params.image_dir : ".", name);
}

/* A run's numbers (malloc'd, *n of them): status, rows, surface values,
 * whether an image is kept, then the surface values, each row's fields,
 * and the rank and threads it ran on (absent from records of radpt
 * 0.15.0 and earlier). */
static double *trial_pack(const rp_bench *b, const rp_trial *run, size_t *n)
{
    size_t ns = run->surfaces ? rp_scene_nsurfaces(b->scene) * rp_scene_nbands(b->scene) : 0;
    *n = 4 + ns + CP_FIELDS * run->ncp + 2;
    double *v = malloc(*n * sizeof *v);
    if (!v)
        return NULL;
    v[0] = run->status;
    v[1] = (double)run->ncp;
    v[2] = (double)ns;
    v[3] = run->image != NULL;
    for (size_t i = 0; i < ns; i++)
        v[4 + i] = run->surfaces[i];
    for (size_t i = 0; i < run->ncp; i++)
        cp_to(&run->cp[i], v + 4 + ns + CP_FIELDS * i);
    v[*n - 2] = run->rank;
    v[*n - 1] = run->threads;
    return v;
}

/* The inverse of trial_pack (run->image stays NULL; *has_image says
 * whether there was one); 0 when v is malformed. */
static int trial_unpack(const rp_bench *b, const double *v, size_t n, rp_trial *run, int *has_image)
{
    if (n < 4)
        return 0;
    size_t ncp = (size_t)v[1], ns = (size_t)v[2], base = 4 + ns + CP_FIELDS * ncp;
    if (!(v[1] >= 1 && v[2] >= 0 && (n == base || n == base + 2) &&
          (ns == 0 || ns == rp_scene_nsurfaces(b->scene) * rp_scene_nbands(b->scene))))
        return 0;
    run->status = (rp_status)v[0];
    run->cp = calloc(ncp, sizeof *run->cp);
    run->surfaces = ns ? malloc(ns * sizeof *run->surfaces) : NULL;
    if (!run->cp || (ns && !run->surfaces)) {
        rp_trial_free(run);
        return 0;
    }
    run->ncp = ncp;
    for (size_t i = 0; i < ns; i++)
        run->surfaces[i] = v[4 + i];
    for (size_t i = 0; i < ncp; i++)
        cp_from(v + 4 + ns + CP_FIELDS * i, &run->cp[i]);
    run->rank = n == base + 2 ? (int)v[base] : 0;
    run->threads = n == base + 2 ? (int)v[base + 1] : b->threads;
    *has_image = v[3] != 0;
    return 1;
}

static rp_status trial_put(const rp_bench *b, const char *key, const rp_trial *run, rp_error *err)
{
    rp_journal *j = b->params.journal;
    if (!j)
        return RP_OK;
    size_t n;
    double *v = trial_pack(b, run, &n);
    if (!v)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_status st = RP_OK;
    if (run->image) {
        /* the image first: a record that exists always has its image */
        char path[1200], dir[1100];
        rp_path_join(dir, sizeof dir, b->params.image_dir ? b->params.image_dir : ".", "runs");
        st = rp_mkdirs(dir, err);
        image_path(b, key, path, sizeof path);
        rp_out o;
        if (st == RP_OK && (st = rp_out_open(&o, path, err)) == RP_OK) {
            size_t nv = image_values(b);
            int ok = fwrite(run->image, sizeof *run->image, nv, o.f) == nv;
            st = rp_out_close(&o, ok, err);
            if (st == RP_OK && !ok)
                st = rp_error_set(err, RP_ERR_RUNTIME, "%s: write failed", path);
        }
    }
    if (st == RP_OK && run->status != RP_OK) {
        char ekey[640], text[1024];
        snprintf(ekey, sizeof ekey, "%s#error", key);
        snprintf(text, sizeof text, "%s", run->error);
        for (char *c = text; *c; c++)
            if (*c == '\n')
                *c = ' ';
        st = rp_journal_put(j, ekey, text, err);
    }
    if (st == RP_OK)
        st = rp_journal_put_doubles(j, key, v, n, err);
    free(v);
    return st;
}

/* Reads a recorded run back into run (run->cp stays NULL when key is not
 * recorded). */
static rp_status trial_get(const rp_bench *b, const char *key, uint64_t seed, int keep_image, rp_trial *run,
                           rp_error *err)
{
    memset(run, 0, sizeof *run);
    run->seed = seed;
    const char *text = rp_journal_get(b->params.journal, key);
    if (!text)
        return RP_OK;
    size_t n = 1;
    for (const char *c = text; *c; c++)
        n += *c == ' ';
    double *v = malloc((n + 1) * sizeof *v);
    if (!v)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    int has_image = 0;
    int ok = n >= 4 && rp_journal_get_doubles(b->params.journal, key, v, n) &&
             trial_unpack(b, v, n, run, &has_image);
    free(v);
    if (!ok)
        return rp_error_set(err, RP_ERR_INPUT, "%s: the record of '%s' is malformed (or out of memory)",
                            rp_journal_path(b->params.journal), key);
    if (run->status != RP_OK) {
        char ekey[640];
        snprintf(ekey, sizeof ekey, "%s#error", key);
        const char *e = rp_journal_get(b->params.journal, ekey);
        snprintf(run->error, sizeof run->error, "%s", e ? e : rp_status_string(run->status));
    }
    if (has_image && keep_image) {
        char path[1200];
        image_path(b, key, path, sizeof path);
        size_t nv = image_values(b);
        FILE *f = fopen(path, "rb");
        run->image = malloc((nv ? nv : 1) * sizeof *run->image);
        int got = f && run->image && fread(run->image, sizeof *run->image, nv, f) == nv && fgetc(f) == EOF;
        if (f)
            fclose(f);
        if (!got) {
            rp_trial_free(run);
            return rp_error_set(err, RP_ERR_INPUT, "%s: missing or short (the image of recorded run '%s')", path,
                                key);
        }
    }
    return RP_OK;
}

/* ------------------------------------------- runs handed out to ranks
 *
 * Under mpirun (docs/design.md, "MPI as a layer") the bench's runs are
 * independent: run k of the study goes to rank k mod K, which runs it
 * alone (its solver sees no communicator: its timings are its own rank's,
 * with the threads it was given).  Then, in the study's order, each run's
 * record (trial_pack: the journal's numbers, the error text, the kept
 * image) goes from the rank that holds it to every rank, and rank 0
 * journals and logs it.  Every rank ends with the same runs, so reports
 * (written by rank 0) and anything an experiment decides from them are the
 * same as alone; runs recorded by an earlier, interrupted study are read
 * back by rank 0 and handed out the same way. */

typedef struct bench_slot {
    size_t method;
    uint64_t seed;
    int keep_image;
    char key[600];
} bench_slot;

/* Sends slot k's outcome from `holder` to every rank: head {state, count
 * of numbers, image floats, status}, state 1 a finished run, 0 none
 * (not run: interrupted), -1 the harness failed (its message follows). */
static rp_status spread_run(rp_bench *b, const rp_comm *comm, int holder, rp_trial *run, int state,
                            rp_status hst, const rp_error *herr, rp_error *err)
{
    double head[4] = {0};
    double *v = NULL;
    size_t n = 0;
    if (comm->rank == holder) {
        if (state == 1 && !(v = trial_pack(b, run, &n)))
            state = -1, hst = RP_ERR_NOMEM;
        head[0] = state;
        head[1] = (double)n;
        head[2] = state == 1 && run->image ? (double)image_values(b) : 0;
        head[3] = hst;
    }
    rp_comm_bcast(comm, head, sizeof head, holder);
    state = (int)head[0];
    if (state == 0) {
        free(v);
        return RP_OK;
    }
    if (state == -1) {
        rp_error e;
        if (comm->rank == holder)
            memcpy(e.message, herr->message, sizeof e.message);
        rp_comm_bcast(comm, e.message, sizeof e.message, holder);
        e.message[sizeof e.message - 1] = '\0';
        free(v);
        return rp_error_set(err, (rp_status)head[3], "%s", e.message);
    }
    n = (size_t)head[1];
    size_t nimage = (size_t)head[2];
    if (comm->rank != holder) {
        v = malloc((n ? n : 1) * sizeof *v);
        memset(run, 0, sizeof *run);
        run->image = nimage ? malloc(nimage * sizeof *run->image) : NULL;
    }
    /* every rank takes part in every broadcast, even out of memory */
    double short_of_memory = !(v && (!nimage || run->image));
    rp_comm_max(comm, &short_of_memory, 1);
    if (short_of_memory) {
        free(v);
        if (comm->rank != holder)
            rp_trial_free(run);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory (handing out the runs)");
    }
    rp_comm_bcast(comm, v, n * sizeof *v, holder);
    rp_comm_bcast(comm, run->error, sizeof run->error, holder);
    if (nimage)
        rp_comm_bcast(comm, run->image, nimage * sizeof *run->image, holder);
    if (comm->rank != holder) {
        float *image = run->image;
        char error[sizeof run->error];
        memcpy(error, run->error, sizeof error);
        int has_image = 0;
        run->image = NULL;
        if (!trial_unpack(b, v, n, run, &has_image)) {
            free(v);
            free(image);
            return rp_error_set(err, RP_ERR_RUNTIME, "a run's record came malformed from rank %d", holder);
        }
        run->image = image;
        memcpy(run->error, error, sizeof error);
    }
    free(v);
    return RP_OK;
}

static void bench_log_result(rp_bench *b, const rp_trial *run)
{
    const rp_method_spec *m = &b->methods[run->method];
    if (run->status != RP_OK) {
        bench_log(b, "%s seed %llu failed: %s", m->text, (unsigned long long)run->seed, run->error);
    } else if (run->ncp) {
        const rp_checkpoint *cp = &run->cp[run->ncp - 1];
        char rmse[32] = "n/a", surf[32] = "n/a";
        if (isfinite(cp->rmse))
            snprintf(rmse, sizeof rmse, "%.4g", cp->rmse);
        if (isfinite(cp->surface_err))
            snprintf(surf, sizeof surf, "%.4g", cp->surface_err);
        char where[64] = ""; /* under mpirun: the rank it ran on */
        if (rp_mpi_world())
            snprintf(where, sizeof where, " (rank %d, %d threads)", run->rank, run->threads);
        bench_log(b, "  %s seed %llu: %.3g s, RMSE %s, surface error %s%s", m->text, (unsigned long long)run->seed,
                  cp->wall_s, rmse, surf, where);
    }
}

static rp_status bench_spread(rp_bench *b, const rp_comm *comm, bench_slot *slots, size_t nslots, rp_error *err)
{
    rp_trial *done = calloc(nslots ? nslots : 1, sizeof *done);
    double *state = calloc(nslots ? nslots : 1, sizeof *state); /* 1 recorded, 0 to run */
    rp_status st = RP_OK;
    double short_of_memory = !(done && state);
    rp_comm_max(comm, &short_of_memory, 1);
    if (short_of_memory) {
        free(done);
        free(state);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    /* what an earlier study recorded: read by rank 0 */
    rp_error rerr;
    rp_error_clear(&rerr);
    rp_status rst = RP_OK;
    if (comm->rank == 0)
        for (size_t k = 0; k < nslots && rst == RP_OK; k++) {
            rst = trial_get(b, slots[k].key, slots[k].seed, slots[k].keep_image, &done[k], &rerr);
            state[k] = rst == RP_OK && done[k].cp;
        }
    double bad = rst != RP_OK;
    rp_comm_max(comm, &bad, 1);
    if (bad) {
        st = spread_run(b, comm, 0, NULL, -1, rst, &rerr, err);
        goto out;
    }
    rp_comm_bcast(comm, state, nslots * sizeof *state, 0);
    size_t todo = 0;
    for (size_t k = 0; k < nslots; k++)
        todo += state[k] == 0;
    bench_log(b, "%zu runs handed out to %d ranks (run k to rank k mod %d); rank 0 shows its own runs' progress",
              todo, comm->size, comm->size);

    /* this rank's runs; slot k's rank is k mod K */
    rp_status hst = RP_OK;
    rp_error herr;
    rp_error_clear(&herr);
    int interrupted = 0;
    for (size_t k = 0; k < nslots && hst == RP_OK && !interrupted; k++) {
        if (state[k] != 0 || !rp_comm_owns(comm, k))
            continue;
        if (rp_cancelled(b->params.run.cancel)) {
            interrupted = 1;
            break;
        }
        const rp_method_spec *m = &b->methods[slots[k].method];
        rp_harness_params hp = b->params.run;
        hp.keep_image = slots[k].keep_image;
        bench_log(b, "run %zu of %zu: %s, seed %llu, budget %g %s (rank %d)", k + 1, nslots, m->text,
                  (unsigned long long)slots[k].seed, hp.budget,
                  hp.schedule == RP_SCHEDULE_ITERATIONS ? "iterations" : "s", comm->rank);
        hst = rp_harness_run(b->scene, b->ref, m, slots[k].seed, &hp, &done[k], &herr);
        if (hst == RP_OK && done[k].status == RP_ERR_INTERRUPTED) {
            rp_trial_free(&done[k]);
            interrupted = 1;
        } else if (hst == RP_OK) {
            state[k] = 2; /* finished here */
            /* recorded at once by the rank that ran it (its image too):
             * mpirun may kill the ranks before the hand-back below */
            rp_files_own(1);
            hst = trial_put(b, slots[k].key, &done[k], &herr);
            rp_files_own(0);
        }
    }

    /* every run's record to every rank, in the study's order */
    for (size_t k = 0; k < nslots && st == RP_OK; k++) {
        int holder = state[k] == 1 ? 0 : (int)(k % (size_t)comm->size);
        int mine = comm->rank == holder;
        int what = !mine ? 0 : state[k] == 1 || state[k] == 2 ? 1 : hst != RP_OK ? -1 : 0;
        rp_trial *run = &b->runs[b->nruns];
        if (mine) {
            *run = done[k];
            memset(&done[k], 0, sizeof done[k]);
        }
        st = spread_run(b, comm, holder, run, what, hst, &herr, err);
        if (st != RP_OK)
            break;
        if (!run->cp) /* not run: interrupted */
            continue;
        run->method = slots[k].method;
        run->seed = slots[k].seed;
        if (state[k] == 1) {
            b->resumed++;
            bench_log(b, "run %zu of %zu: %s seed %llu: recorded, read back from %s", k + 1, nslots,
                      b->methods[run->method].text, (unsigned long long)run->seed,
                      rp_journal_path(b->params.journal));
        } else if (!mine && (st = trial_put(b, slots[k].key, run, err)) != RP_OK)
            break; /* the holder recorded it when it finished */
        b->nruns++;
        if (run->status != RP_OK)
            b->failures++;
        if (state[k] != 1)
            bench_log_result(b, run);
        if (b->params.on_run)
            b->params.on_run(b->params.on_run_ctx, b);
    }
    double any = interrupted;
    rp_comm_max(comm, &any, 1);
    b->interrupted = any != 0 || b->nruns < nslots;
out:
    for (size_t k = 0; k < nslots; k++)
        rp_trial_free(&done[k]);
    free(done);
    free(state);
    return st;
}

rp_status rp_bench_run(const rp_scene *scene, const char *scene_name, const rp_reference *ref,
                       const rp_method_spec *methods, size_t nmethods, const rp_bench_params *params,
                       rp_bench **out, rp_error *err)
{
    *out = NULL;
    rp_bench *b = calloc(1, sizeof *b);
    if (!b)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    b->params = *params;
    if (!b->params.nseeds)
        b->params.nseeds = 3;
    if (!b->params.seed)
        b->params.seed = 1;
    if (!b->params.run.levels)
        b->params.run.levels = 9;
    b->scene = scene;
    b->scene_name = scene_name;
    rp_scene_hash(scene, b->scene_hash);
    b->ref = ref;
    b->nmethods = nmethods;
    b->methods = calloc(nmethods ? nmethods : 1, sizeof *b->methods);
    b->summary = calloc(nmethods ? nmethods : 1, sizeof *b->summary);
    size_t nruns = 0;
    for (size_t i = 0; i < nmethods; i++)
        nruns += rp_method_is_monte_carlo(&methods[i]) ? b->params.nseeds : 1;
    b->runs = calloc(nruns ? nruns : 1, sizeof *b->runs);
    if (!b->methods || !b->summary || !b->runs) {
        rp_bench_destroy(b);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    for (size_t i = 0; i < nmethods; i++)
        spec_copy(&b->methods[i], &methods[i]);
    b->planned = nruns;
    b->threads = b->params.run.threads ? b->params.run.threads : omp_get_max_threads();
    /* the study's runs in order: methods, then seeds */
    bench_slot *slots = calloc(nruns ? nruns : 1, sizeof *slots);
    if (!slots) {
        rp_bench_destroy(b);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    for (size_t i = 0, k = 0; i < nmethods; i++) {
        unsigned ns = rp_method_is_monte_carlo(&b->methods[i]) ? b->params.nseeds : 1;
        for (unsigned s = 0; s < ns; s++, k++) {
            slots[k].method = i;
            slots[k].seed = b->params.seed + s;
            slots[k].keep_image = b->params.run.keep_image && s == 0; /* the sheet shows the first seed */
            snprintf(slots[k].key, sizeof slots[k].key, "%s%s seed %llu",
                     b->params.journal_prefix ? b->params.journal_prefix : "", b->methods[i].text,
                     (unsigned long long)slots[k].seed);
        }
    }
    const rp_comm *comm = rp_mpi_world();
    rp_status st = comm ? bench_spread(b, comm, slots, nruns, err) : RP_OK;
    for (size_t k = 0; !comm && k < nruns && !b->interrupted; k++) {
        const bench_slot *sl = &slots[k];
        const rp_method_spec *m = &b->methods[sl->method];
        rp_trial *run = &b->runs[b->nruns];
        rp_harness_params hp = b->params.run;
        hp.keep_image = sl->keep_image;
        st = trial_get(b, sl->key, sl->seed, hp.keep_image, run, err);
        if (st == RP_OK && run->cp) {
            b->resumed++;
            bench_log(b, "run %zu of %zu: %s seed %llu: recorded, read back from %s", k + 1, nruns, m->text,
                      (unsigned long long)sl->seed, rp_journal_path(b->params.journal));
        } else if (st == RP_OK) {
            if (rp_cancelled(hp.cancel)) {
                b->interrupted = 1;
                break;
            }
            double eta = (double)(nruns - k) * b->params.run.budget;
            const char *unit = b->params.run.schedule == RP_SCHEDULE_ITERATIONS ? "iterations" : "s";
            bench_log(b, "run %zu of %zu: %s, seed %llu, budget %g %s (ETA: at most %.3g %s for this and the rest)",
                      k + 1, nruns, m->text, (unsigned long long)sl->seed, b->params.run.budget, unit, eta, unit);
            st = rp_harness_run(scene, ref, m, sl->seed, &hp, run, err);
            if (st == RP_OK && run->status == RP_ERR_INTERRUPTED) {
                /* not finished: not recorded, not counted */
                rp_trial_free(run);
                b->interrupted = 1;
                break;
            }
            if (st == RP_OK)
                st = trial_put(b, sl->key, run, err);
        }
        if (st != RP_OK)
            break;
        run->method = sl->method;
        b->nruns++;
        if (run->status != RP_OK)
            b->failures++;
        bench_log_result(b, run);
        if (b->params.on_run)
            b->params.on_run(b->params.on_run_ctx, b);
    }
    free(slots);
    if (st != RP_OK) {
        rp_bench_destroy(b);
        return st;
    }
    rp_bench_summarise(b);
    *out = b;
    return RP_OK;
}
