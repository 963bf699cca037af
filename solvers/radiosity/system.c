/* The radiosity system shared by the classic solvers (system.h). */
#include "system.h"

#include <limits.h>
#include <stddef.h>
#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Rows computed together by one parallel block when F is not stored. */
#define RAD_ROW_BLOCK 64
#define MIB(x) ((double)(x) / (1024.0 * 1024.0))

int rp_rad_threads(const rp_rad_system *s)
{
    return s->threads > 0 ? s->threads : omp_get_max_threads();
}

void rp_rad_log(const rp_rad_system *s, const char *fmt, ...)
{
    if (!s->log)
        return;
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    s->log(s->log_ctx, msg);
}

void rp_rad_system_fini(rp_rad_system *s)
{
    if (s->scratch)
        for (int t = 0; t < s->threads; t++)
            rp_ff_scratch_destroy(s->scratch[t]);
    free(s->scratch);
    rp_ff_context_destroy(s->ff);
    rp_raycast_destroy(s->rc);
    rp_mesh_destroy(s->mesh);
    free(s->rowbuf);
    free(s->F);
    free(s->area);
    free(s->rho);
    free(s->E);
    free(s->B);
    free(s->G);
    free(s->row_sum);
    free(s->row_scaled);
    memset(s, 0, sizeof *s);
}

rp_status rp_rad_mesh_params(const char *method, const rp_options *o, rp_mesh_params *mp,
                             rp_error *err)
{
    rp_status st;
    memset(mp, 0, sizeof *mp);
    mp->size = sizeof *mp;
    unsigned long elements = 0;
    double max_edge = 0;
    if ((st = rp_options_uint(o, "elements", 1, RP_MESH_MAX_ELEMENTS, &elements, err)) != RP_OK)
        return st;
    if ((st = rp_options_double(o, "max-edge", 0, INFINITY, &max_edge, err)) != RP_OK)
        return st;
    if (rp_options_get(o, "elements") && rp_options_get(o, "max-edge"))
        return rp_error_set(err, RP_ERR_INPUT, "%s: give --elements or --max-edge, not both", method);
    if (rp_options_get(o, "max-edge") && !(max_edge > 0))
        return rp_error_set(err, RP_ERR_INPUT, "%s: --max-edge must be positive", method);
    mp->target_count = elements;
    mp->max_edge = max_edge;
    return RP_OK;
}

static rp_status rad_parse_options(rp_rad_system *s, const rp_rad_config *cfg, const rp_options *o,
                                   rp_mesh_params *mp, rp_rad_storage *storage, rp_error *err)
{
    rp_status st;
    const char *name = cfg->name;
    if ((st = rp_rad_mesh_params(name, o, mp, err)) != RP_OK)
        return st;

    memset(&s->ffp, 0, sizeof s->ffp);
    s->ffp.size = sizeof s->ffp;
    s->ffp.method = RP_FF_ANALYTIC;
    /* 0: the form-factor module's defaults (formfactor.c). */
    s->ffp.samples = 0;
    s->ffp.resolution = 0;
    s->ffp.visibility_rays = 0;
    s->ffp.seed = o ? o->seed : 0;
    s->ffp.cancel = s->cancel;
    const char *v = rp_options_word(o, "ff"); /* defaults: the specs' */
    if (v && (st = rp_ff_method_parse(v, &s->ffp.method, err)) != RP_OK)
        return st;
    unsigned long u = s->ffp.samples;
    if ((st = rp_options_uint(o, "ff-samples", 1, UINT32_MAX, &u, err)) != RP_OK)
        return st;
    s->ffp.samples = (unsigned)u;
    u = s->ffp.visibility_rays;
    if ((st = rp_options_uint(o, "ff-rays", 1, 4096, &u, err)) != RP_OK)
        return st;
    s->ffp.visibility_rays = (unsigned)u;
    u = s->ffp.resolution;
    if ((st = rp_options_uint(o, "hemicube-resolution", 2, 16384, &u, err)) != RP_OK)
        return st;
    s->ffp.resolution = (unsigned)u;
    if ((st = rp_options_double(o, "ff-tolerance", 1e-14, 0.1, &s->ffp.tolerance, err)) != RP_OK)
        return st;

    /* defaults: the option specs' fallbacks (rp_options_double) */
    if ((st = rp_options_double(o, "tolerance", 0, 1, &s->tolerance, err)) != RP_OK)
        return st;
    s->tolerance_given = rp_options_get(o, "tolerance") != NULL;
    s->max_iterations = cfg->default_max_iterations;
    if ((st = rp_options_uint(o, "max-iterations", 1, ULONG_MAX, &s->max_iterations, err)) != RP_OK)
        return st;
    s->max_iterations_given = rp_options_get(o, "max-iterations") != NULL;

    *storage = cfg->storage;
    if (cfg->storage_option && (v = rp_options_get(o, "matrix"))) {
        if (strcmp(v, "auto") == 0)
            *storage = RP_RAD_STORAGE_AUTO;
        else if (strcmp(v, "dense") == 0)
            *storage = RP_RAD_STORAGE_DENSE;
        else if (strcmp(v, "rows") == 0)
            *storage = RP_RAD_STORAGE_ROWS;
        else
            return rp_error_set(err, RP_ERR_INPUT, "--matrix: '%s' is not auto, dense or rows", v);
    }

    s->reciprocity = cfg->reciprocity_option && rp_options_get(o, "reciprocity") != NULL;
    if (s->reciprocity && s->ffp.method == RP_FF_HEMICUBE)
        return rp_error_set(err, RP_ERR_INPUT, "%s: --reciprocity needs pairwise form factors "
                            "(--ff analytic or montecarlo); the hemicube gives whole rows", name);

    s->recon.spp = 16;
    s->recon.gather_rays = 16;
    s->recon.seed = o ? o->seed : 0;
    if ((v = rp_options_word(o, "reconstruct")) && (st = rp_recon_mode_parse(v, &s->recon.mode, err)) != RP_OK)
        return st;
    u = s->recon.spp;
    if ((st = rp_options_uint(o, "spp", 1, 1u << 20, &u, err)) != RP_OK)
        return st;
    s->recon.spp = (unsigned)u;
    u = s->recon.gather_rays;
    if ((st = rp_options_uint(o, "gather-rays", 1, 1u << 20, &u, err)) != RP_OK)
        return st;
    s->recon.gather_rays = (unsigned)u;
    return RP_OK;
}

rp_status rp_rad_system_init(rp_rad_system *s, const rp_rad_config *cfg, const rp_scene *scene,
                             const rp_options *o, rp_error *err)
{
    rp_status st;
    s->name = cfg->name;
    s->scene = scene;
    s->nb = rp_scene_nbands(scene);
    s->want = o ? o->want : RP_WANT_IMAGE;
    s->open_ended = o ? o->open_ended : 0;
    s->log = o ? o->log : NULL;
    s->log_ctx = o ? o->log_ctx : NULL;
    s->cancel = o && o->size >= offsetof(rp_options, cancel) + sizeof o->cancel ? o->cancel : NULL;
    s->residual = -1;
    if (o && o->threads < 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: %d threads", cfg->name, o->threads);
    s->threads = o && o->threads > 0 ? o->threads : omp_get_max_threads();
    s->recon.threads = s->threads;
    if (s->nb == 0 || s->nb > RP_RAD_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "%s: %zu bands (at most %d)", cfg->name, s->nb,
                            RP_RAD_MAX_BANDS);
    rp_mesh_params mp;
    rp_rad_storage storage = cfg->storage;
    if ((st = rad_parse_options(s, cfg, o, &mp, &storage, err)) != RP_OK)
        return st;
    if ((s->want & RP_WANT_IMAGE) && !rp_scene_camera(scene))
        return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no camera to render from", cfg->name);

    if ((st = rp_mesh_create(scene, &mp, &s->mesh, err)) != RP_OK)
        return st;
    if (rp_cancelled(s->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted while meshing", cfg->name);
    s->n = rp_mesh_nelements(s->mesh);
    const size_t n = s->n, nb = s->nb;
    if (n == 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no elements", cfg->name);
    if (cfg->max_elements && n > cfg->max_elements)
        return rp_error_set(err, RP_ERR_INPUT, "%s: %zu elements is more than the %zu it allows (%s); "
                            "ask for fewer with --elements or --max-edge", cfg->name, n, cfg->max_elements,
                            cfg->max_elements_why ? cfg->max_elements_why : "size cap");
    if (cfg->default_max_iterations == 0 && !s->max_iterations_given)
        s->max_iterations = 100 * (unsigned long)n;
    if ((st = rp_raycast_create(scene, s->mesh, &s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_options_ray_offset(o, s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_ff_context_create(scene, s->mesh, s->rc, &s->ffp, &s->ff, err)) != RP_OK)
        return st;
    if (rp_cancelled(s->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted while setting up form factors",
                            cfg->name);
    s->scratch = calloc((size_t)s->threads, sizeof *s->scratch);
    if (!s->scratch)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    for (int t = 0; t < s->threads; t++)
        if ((st = rp_ff_scratch_create(s->ff, &s->scratch[t], err)) != RP_OK)
            return st;

    s->area = malloc(n * sizeof *s->area);
    s->rho = malloc(n * nb * sizeof *s->rho);
    s->E = malloc(n * nb * sizeof *s->E);
    s->B = malloc(n * nb * sizeof *s->B);
    s->G = calloc(n * nb, sizeof *s->G);
    s->row_sum = calloc(n, sizeof *s->row_sum);
    s->row_scaled = calloc(n, 1);
    if (!s->area || !s->rho || !s->E || !s->B || !s->G || !s->row_sum || !s->row_scaled)
        return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory for %zu elements", cfg->name, n);
    s->bytes = n * (sizeof *s->area + sizeof *s->row_sum + 1) + 4 * n * nb * sizeof(double);
    const rp_element *el = rp_mesh_elements(s->mesh);
    const rp_material *mats = rp_scene_materials(scene);
    const rp_surface *surfs = rp_scene_surfaces(scene);
    for (size_t b = 0; b < nb; b++)
        s->e_norm[b] = s->rho_max[b] = 0;
    for (size_t i = 0; i < n; i++) {
        const rp_material *m = &mats[surfs[el[i].surface].material];
        s->area[i] = el[i].area;
        for (size_t b = 0; b < nb; b++) {
            s->rho[i * nb + b] = m->rho[b];
            /* Emitted radiosity of a Lambertian emitter: E = pi Le. */
            s->E[i * nb + b] = RP_PI * m->Le[b];
            s->B[i * nb + b] = s->E[i * nb + b];
            s->e_norm[b] += el[i].area * s->E[i * nb + b];
            if (m->rho[b] > s->rho_max[b])
                s->rho_max[b] = m->rho[b];
        }
    }

    size_t dense_bytes = n * n * sizeof(float);
    if (n > SIZE_MAX / sizeof(float) / n)
        dense_bytes = SIZE_MAX;
    if (storage == RP_RAD_STORAGE_AUTO)
        s->dense = dense_bytes < RP_RAD_DENSE_CAP;
    else
        s->dense = storage == RP_RAD_STORAGE_DENSE;
    if (s->reciprocity && !s->dense)
        return rp_error_set(err, RP_ERR_INPUT, "%s: --reciprocity applies to a dense matrix only "
                            "(%zu elements would need %.1f MiB; see --matrix)", cfg->name, n, MIB(dense_bytes));
    if (s->dense) {
        if (dense_bytes == SIZE_MAX)
            return rp_error_set(err, RP_ERR_NOMEM, "%s: a dense matrix of %zu elements does not fit in memory",
                                cfg->name, n);
        s->F = malloc(dense_bytes);
        if (!s->F)
            return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory for a dense %zu x %zu form-factor matrix "
                                "(%.1f MiB); try --matrix rows", cfg->name, n, n, MIB(dense_bytes));
        s->bytes += dense_bytes;
    } else {
        size_t rows = cfg->row_bytes ? cfg->row_bytes / (n * sizeof(float)) : RAD_ROW_BLOCK;
        if (rows > n)
            rows = n;
        s->rowbuf_rows = rows > (size_t)s->threads ? rows : (size_t)s->threads;
        s->rowbuf = malloc(s->rowbuf_rows * n * sizeof *s->rowbuf);
        if (!s->rowbuf)
            return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory for form-factor rows", cfg->name);
        s->bytes += s->rowbuf_rows * n * sizeof *s->rowbuf;
    }
    rp_rad_log(s, "%s: %zu elements, %zu bands, %s form factors, %s (%.1f MiB of solver memory)", cfg->name,
               n, nb, rp_ff_method_name(s->ffp.method),
               s->dense ? "dense single-precision matrix" : "form factors computed on the fly",
               MIB(s->bytes));
    return RP_OK;
}

rp_status rp_rad_check_row(const rp_rad_system *s, uint32_t i, const float *row, double *row_sum,
                           rp_error *err)
{
    const size_t n = s->n, nb = s->nb;
    double sum = 0, shoot[RP_RAD_MAX_BANDS];
    for (size_t b = 0; b < nb; b++)
        shoot[b] = 0;
    int bad = 0;
    for (size_t j = 0; j < n; j++) {
        double f = row[j];
        if (!(f >= 0) || !isfinite(f))
            bad = 1;
        sum += f;
        for (size_t b = 0; b < nb; b++)
            shoot[b] += s->rho[j * nb + b] * f;
    }
    *row_sum = sum;
    if (bad)
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: form factors from element %u are negative or not finite",
                            s->name, i);
    const rp_element *el = rp_mesh_elements(s->mesh);
    const char *surf = rp_scene_surfaces(s->scene)[el[i].surface].name;
    for (size_t b = 0; b < nb; b++) {
        /* Either sum exceeding 1 breaks the contraction the iterations rely
         * on: rho_i sum_j F_ij for gathering (max norm), sum_j rho_j F_ij
         * for shooting (power norm, Cohen & Wallace 1993, sec. 5.3). */
        double gather = s->rho[(size_t)i * nb + b] * sum;
        if (gather >= 1 || shoot[b] >= 1)
            return rp_error_set(err, RP_ERR_INPUT,
                                "%s: element %u of surface '%s', band %zu: reflectance times form factors "
                                "sums to %.9g >= 1 (form factors sum to %.9g): the radiosity system would be "
                                "singular or divergent; use more accurate form factors (--ff)",
                                s->name, i, surf, b, gather > shoot[b] ? gather : shoot[b], sum);
    }
    return RP_OK;
}

/* 1 if element i neither reflects nor emits in any band: its radiosity is
 * 0 whatever it sees, and what others see of it adds nothing. */
static int rad_black(const rp_rad_system *s, size_t i)
{
    for (size_t b = 0; b < s->nb; b++)
        if (s->rho[i * s->nb + b] != 0 || s->E[i * s->nb + b] != 0)
            return 0;
    return 1;
}

void rp_rad_scale_row(const rp_rad_system *s, uint32_t i, float *row)
{
    const size_t n = s->n, nb = s->nb;
    /* Form factors to and from black elements are dropped before the row
     * is judged: they carry no light (B_j = 0 for a black j, and a black
     * row is never gathered), so a huge black ground plane, whose form
     * factors are the hardest to estimate, cannot scale the rows of the
     * scene it lies under (issue 13: nothing may change when one is
     * added). */
    const int black_row = rad_black(s, i);
    for (size_t j = 0; j < n; j++)
        if (row[j] != 0 && (black_row || rad_black(s, j)))
            row[j] = 0;
    double sum = 0, shoot[RP_RAD_MAX_BANDS];
    for (size_t b = 0; b < nb; b++)
        shoot[b] = 0;
    for (size_t j = 0; j < n; j++) {
        double f = row[j];
        sum += f;
        for (size_t b = 0; b < nb; b++)
            shoot[b] += s->rho[j * nb + b] * f;
    }
    int scale = sum > 1 + RP_RAD_ROW_SUM_TOL;
    for (size_t b = 0; b < nb; b++)
        scale |= s->rho[(size_t)i * nb + b] * sum >= 1 || shoot[b] >= 1;
    s->row_sum[i] = sum;
    s->row_scaled[i] = 0;
    /* Not a finite positive sum: left for rp_rad_check_row to refuse. */
    if (!scale || !(sum > 0) || !isfinite(sum))
        return;
    for (size_t j = 0; j < n; j++)
        row[j] = (float)(row[j] / sum);
    s->row_scaled[i] = 1;
}

void rp_rad_report_scaled(rp_rad_system *s)
{
    if (s->rows_reported)
        return;
    s->rows_reported = 1;
    size_t count = 0, worst = 0;
    for (size_t i = 0; i < s->n; i++)
        if (s->row_scaled[i]) {
            if (!count || s->row_sum[i] > s->row_sum[worst])
                worst = i;
            count++;
        }
    s->rows_scaled = count;
    if (!count)
        return;
    const rp_element *el = rp_mesh_elements(s->mesh);
    rp_rad_log(s, "warning: %s: %zu of %zu rows of form factors summed to more than 1 + %g (or broke "
               "rho sum F < 1) and were scaled to sum 1; the worst, element %zu of surface '%s', summed "
               "to %.6g (form-factor error: try more elements where small and large elements meet)",
               s->name, count, s->n, RP_RAD_ROW_SUM_TOL, worst,
               rp_scene_surfaces(s->scene)[el[worst].surface].name, s->row_sum[worst]);
}

const float *rp_rad_row(const rp_rad_system *s, uint32_t i, rp_ff_scratch *scratch, float *buf,
                        double *ff, double *rays)
{
    if (s->F && s->matrix_ready)
        return s->F + (size_t)i * s->n;
    rp_ff_row(s->ff, scratch, i, buf, rays);
    *ff += (double)s->n;
    rp_rad_scale_row(s, i, buf);
    return buf;
}

/* The first failing row of a parallel loop, reported in index order so the
 * message does not depend on the schedule. */
static rp_status rad_first_bad_row(const rp_rad_system *s, const float *row, uint32_t i, rp_error *err)
{
    double sum;
    return rp_rad_check_row(s, i, row, &sum, err);
}

static rp_status rad_interrupted(const rp_rad_system *s, const char *what, rp_error *err)
{
    return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted while %s", s->name, what);
}

/* F by pairs (analytic and Monte Carlo form factors): row i computes the
 * pairs whose primary side is i (rp_ff_primary) and writes both F_ij and,
 * in column i, F_ji = F_ij A_i / A_j (Cohen & Wallace 1993, eq. 4.4),
 * exactly as rp_ff_row would give them: half the work of computing every
 * row, and A_i F_ij = A_j F_ji to float rounding.  No two rows write the
 * same entry; each primary depends only on (seed, pair), so F is the same
 * for any thread count. */
static int rad_fill_pairs(rp_rad_system *s, double *rays_out, double *ff_out)
{
    const size_t n = s->n;
    float *F = s->F;
    double rays = 0, ff = 0;
    int stop = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(max : stop)
    for (long i = 0; i < (long)n; i++) {
        if (rp_cancelled(s->cancel)) {
            stop = 1;
            continue;
        }
        rp_ff_scratch *scr = s->scratch[omp_get_thread_num()];
        F[(size_t)i * n + (size_t)i] = 0;
        for (size_t j = 0; j < n; j++)
            if (j != (size_t)i && rp_ff_primary(s->ff, (uint32_t)i, (uint32_t)j)) {
                double fij, fji;
                rp_ff_pair_both(s->ff, scr, (uint32_t)i, (uint32_t)j, &fij, &fji, &rays);
                F[(size_t)i * n + j] = (float)fij;
                F[j * n + (size_t)i] = (float)fji;
                ff += 1;
            }
    }
    *rays_out += rays;
    *ff_out += ff;
    return stop;
}

rp_status rp_rad_system_matrix(rp_rad_system *s, rp_step_info *info, rp_error *err)
{
    if (!s->dense || s->matrix_ready)
        return RP_OK;
    const size_t n = s->n;
    double rays = 0, ff = 0;
    float *F = s->F;
    int stop = 0;
    if (rp_ff_reciprocal(s->ff)) {
        stop = rad_fill_pairs(s, &rays, &ff);
    } else {
        /* Whole rows (hemicube). */
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(max : stop)
        for (long i = 0; i < (long)n; i++) {
            if (rp_cancelled(s->cancel)) {
                stop = 1;
                continue;
            }
            rp_ff_row(s->ff, s->scratch[omp_get_thread_num()], (uint32_t)i, F + (size_t)i * n, &rays);
            ff += (double)n;
        }
    }
    info->rays += rays;
    info->form_factors += ff;
    if (stop)
        return rad_interrupted(s, "computing form factors", err);

    long bad = LONG_MAX;
#pragma omp parallel for num_threads(s->threads) schedule(static) reduction(min : bad)
    for (long i = 0; i < (long)n; i++) {
        double sum;
        rp_rad_scale_row(s, (uint32_t)i, F + (size_t)i * n);
        if (rp_rad_check_row(s, (uint32_t)i, F + (size_t)i * n, &sum, NULL) != RP_OK && i < bad)
            bad = i;
    }
    if (bad != LONG_MAX)
        return rad_first_bad_row(s, F + (size_t)bad * n, (uint32_t)bad, err);
    double max_sum = 0;
    for (size_t i = 0; i < n; i++)
        max_sum = s->row_sum[i] > max_sum ? s->row_sum[i] : max_sum;
    s->max_row_sum = max_sum;
    s->matrix_ready = 1;
    rp_rad_log(s, "%s: %zu x %zu form factors computed (%.1f MiB), largest row sum %.9g", s->name, n, n,
               MIB(n * n * sizeof(float)), max_sum);
    rp_rad_report_scaled(s);
    return RP_OK;
}

rp_status rp_rad_matvec(rp_rad_system *s, const double *X, double *Y, rp_step_info *info, rp_error *err)
{
    const size_t n = s->n, nb = s->nb;
    if (s->dense) {
        rp_status st = rp_rad_system_matrix(s, info, err);
        if (st != RP_OK)
            return st;
        const float *F = s->F;
#pragma omp parallel for num_threads(s->threads) schedule(static)
        for (long i = 0; i < (long)n; i++)
            rp_rad_dot(F + (size_t)i * n, X, n, nb, Y + (size_t)i * nb);
        return RP_OK;
    }
    /* Rows on the fly: every row is computed (and checked) again. */
    double rays = 0, ff = 0, max_sum = s->max_row_sum;
    long bad = LONG_MAX;
    int stop = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(min : bad) reduction(max : max_sum, stop)
    for (long i = 0; i < (long)n; i++) {
        if (rp_cancelled(s->cancel)) {
            stop = 1;
            continue;
        }
        int t = omp_get_thread_num();
        float *buf = s->rowbuf + (size_t)t * n;
        const float *row = rp_rad_row(s, (uint32_t)i, s->scratch[t], buf, &ff, &rays);
        double sum;
        if (s->row_sum[i] > max_sum)
            max_sum = s->row_sum[i];
        if (rp_rad_check_row(s, (uint32_t)i, row, &sum, NULL) != RP_OK) {
            if (i < bad)
                bad = i;
            continue;
        }
        rp_rad_dot(row, X, n, nb, Y + (size_t)i * nb);
    }
    info->rays += rays;
    info->form_factors += ff;
    s->max_row_sum = max_sum;
    if (stop)
        return rad_interrupted(s, "computing form factors", err);
    if (bad != LONG_MAX) {
        float *buf = s->rowbuf;
        double dff = 0, drays = 0;
        rp_rad_row(s, (uint32_t)bad, s->scratch[0], buf, &dff, &drays);
        return rad_first_bad_row(s, buf, (uint32_t)bad, err);
    }
    rp_rad_report_scaled(s);
    return RP_OK;
}

double rp_rad_residual(const rp_rad_system *s, const double *X, const double *FX)
{
    const size_t n = s->n, nb = s->nb;
    double worst = 0;
    for (size_t b = 0; b < nb; b++) {
        double r = 0;
        for (size_t i = 0; i < n; i++) {
            size_t k = i * nb + b;
            r += s->area[i] * fabs(s->E[k] + s->rho[k] * FX[k] - X[k]);
        }
        double rel = s->e_norm[b] > 0 ? r / s->e_norm[b] : (r > 0 ? INFINITY : 0);
        if (rel > worst)
            worst = rel;
    }
    return worst;
}

void rp_rad_step_done(rp_rad_system *s, double residual, rp_step_info *info)
{
    s->iterations++;
    s->residual = residual;
    info->iterations += 1;
    info->residual = residual;
    info->tolerance = s->tolerance;
    info->memory = (double)s->bytes;
    /* With the harness's own budget (open_ended) a rule stops the run only
     * when its option was given. */
    int tol_rule = s->tolerance_given || !s->open_ended;
    int iter_rule = s->max_iterations_given || !s->open_ended;
    double p = 0;
    if (residual <= 0 || residual <= s->tolerance)
        p = 1;
    else if (residual < 1 && s->tolerance > 0 && s->tolerance < 1)
        p = log(residual) / log(s->tolerance);
    double pi = (double)s->iterations / (double)s->max_iterations;
    if (pi > p)
        p = pi;
    info->progress = p < 0 ? 0 : (p > 1 ? 1 : p);
    info->converged = (tol_rule && residual <= s->tolerance) ||
                      (iter_rule && s->iterations >= s->max_iterations);
}

rp_status rp_rad_estimate(const rp_rad_system *s, const double *Bd, rp_estimate *e, rp_error *err)
{
    const size_t nb = s->nb;
    e->samples = (double)s->iterations;
    if (e->surface_radiance)
        rp_recon_surfaces(s->scene, s->mesh, nb, Bd, e->surface_radiance);
    if (e->surface_stderr)
        memset(e->surface_stderr, 0, rp_scene_nsurfaces(s->scene) * nb * sizeof *e->surface_stderr);
    if (e->radiance || e->variance) {
        const rp_camera *cam = rp_scene_camera(s->scene);
        if (!cam)
            return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no camera to render from", s->name);
        size_t npix = (size_t)cam->width * cam->height;
        float *out = e->radiance;
        if (!out && !(out = malloc(npix * nb * sizeof *out)))
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the image");
        rp_status st = rp_recon_image(s->scene, s->mesh, s->rc, &s->recon, nb, Bd, out, e->variance, NULL, err);
        if (out != e->radiance)
            free(out);
        if (st != RP_OK)
            return st;
    }
    return RP_OK;
}
