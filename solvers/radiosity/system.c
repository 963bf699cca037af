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

#include "../../geometry/log.h"

/* Rows computed together by one parallel block when F is not stored. */
#define RAD_ROW_BLOCK 64
#define MIB(x) ((double)(x) / (1024.0 * 1024.0))

void rp_rad_agree(const rp_rad_system *s, int *stop, long *bad)
{
    if (!rp_rad_split(s))
        return;
    /* max of n - bad picks the lowest failing row */
    double v[2] = {*stop ? 1 : 0, *bad == LONG_MAX ? 0 : (double)s->n - (double)*bad};
    rp_comm_max(s->comm, v, 2);
    *stop = v[0] > 0;
    *bad = v[1] > 0 ? (long)((double)s->n - v[1]) : LONG_MAX;
}

/* Status and message of rank root to every rank of c (size > 1). */
static rp_status rad_bcast_error(const rp_comm *c, rp_status st, rp_error *err, int root)
{
    struct {
        int status;
        char message[sizeof err->message];
    } why;
    memset(&why, 0, sizeof why);
    why.status = (int)st;
    if (err && rp_comm_rank(c) == root)
        memcpy(why.message, err->message, sizeof why.message);
    rp_comm_bcast(c, &why, sizeof why, root);
    why.message[sizeof why.message - 1] = '\0';
    if (err)
        memcpy(err->message, why.message, sizeof why.message);
    return (rp_status)why.status;
}

rp_status rp_rad_share_error(const rp_rad_system *s, rp_status st, rp_error *err, int root)
{
    return rp_rad_split(s) ? rad_bcast_error(s->comm, st, err, root) : st;
}

const rp_comm *rp_rad_options_comm(const rp_options *o)
{
    return o && o->size >= offsetof(rp_options, comm) + sizeof o->comm ? o->comm : NULL;
}

rp_status rp_rad_init_agree(const rp_comm *c, rp_status st, rp_error *err)
{
    if (rp_comm_size(c) <= 1)
        return st;
    /* max of size - rank picks the lowest failing rank */
    double v[1] = {st != RP_OK ? (double)(c->size - c->rank) : 0};
    rp_comm_max(c, v, 1);
    if (v[0] <= 0)
        return RP_OK;
    return rad_bcast_error(c, st, err, c->size - (int)v[0]);
}

int rp_rad_threads(const rp_rad_system *s)
{
    return s->threads > 0 ? s->threads : omp_get_max_threads();
}

void rp_rad_log(const rp_rad_system *s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    rp_vlogf(s->log, s->log_ctx, fmt, ap);
    va_end(ap);
}

void rp_rad_system_fini(rp_rad_system *s)
{
    rp_recon_view_fini(&s->recon.view);
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
    const char *mode = rp_options_word(o, "mesh");
    if (!mode || strcmp(mode, "uniform") == 0)
        mp->mode = RP_MESH_UNIFORM;
    else if (strcmp(mode, "discontinuity") == 0)
        mp->mode = RP_MESH_DISCONTINUITY;
    else
        return rp_error_set(err, RP_ERR_INPUT, "%s: --mesh: '%s' is not uniform or discontinuity", method, mode);
    unsigned long segs;
    if ((st = rp_rad_mesh_segments(method, o, mp->mode == RP_MESH_DISCONTINUITY, &segs, err)) != RP_OK)
        return st;
    mp->max_segments = segs;
    return RP_OK;
}

rp_status rp_rad_mesh_segments(const char *method, const rp_options *o, int disc, unsigned long *segs,
                               rp_error *err)
{
    *segs = RP_DISC_DEFAULT_MAX_PER_FACE;
    rp_status st = rp_options_uint(o, "mesh-segments", 1, 1u << 20, segs, err);
    if (st != RP_OK)
        return st;
    /* Given without --mesh discontinuity (a script that spells out every
     * default): it has nothing to act on, and the run says so. */
    if (rp_options_get(o, "mesh-segments") && !disc)
        rp_logf(o->log, o->log_ctx, "warning: %s: --mesh-segments %s ignored: it applies to --mesh discontinuity only",
                method, rp_options_get(o, "mesh-segments"));
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
    /* --simplify first: everything below reads the scene solved on. */
    if ((st = rp_recon_view_init(&s->recon.view, o, scene, &scene, err)) != RP_OK)
        return st;
    s->scene = scene;
    s->nb = rp_scene_nbands(scene);
    s->want = o ? o->want : RP_WANT_IMAGE;
    s->open_ended = o ? o->open_ended : 0;
    s->log = o ? o->log : NULL;
    s->log_ctx = o ? o->log_ctx : NULL;
    s->cancel = o && o->size >= offsetof(rp_options, cancel) + sizeof o->cancel ? o->cancel : NULL;
    s->comm = rp_rad_options_comm(o);
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
    if (rp_mesh_disc_truncated(s->mesh))
        rp_rad_log(s, "warning: %s: the discontinuity mesh traced its cap of %lu (wedge, receiving face) pairs and "
                   "stopped: the shadow boundaries (D1) of the remaining lights and occluders are not in the mesh",
                   cfg->name, RP_DISC_MAX_PAIRS);
    if (rp_cancelled(s->cancel))
        return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted while meshing", cfg->name);
    s->n = rp_mesh_nelements(s->mesh);
    const size_t n = s->n, nb = s->nb;
    if (n == 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no elements", cfg->name);
    {
        /* round robin: rows rank, rank + K, ... (rp_comm_owns) */
        size_t K = (size_t)rp_comm_size(s->comm), r = (size_t)rp_comm_rank(s->comm);
        s->nloc = n > r ? (n - r + K - 1) / K : 0;
    }
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
    if ((st = rp_recon_view_rays(&s->recon.view, o, s->rc, err)) != RP_OK)
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

    /* this rank's rows (all of them alone) */
    size_t dense_bytes = s->nloc * n * sizeof(float);
    if (s->nloc && s->nloc > SIZE_MAX / sizeof(float) / n)
        dense_bytes = SIZE_MAX;
    /* auto: judged on the largest share (rank 0's), so that every rank
     * makes the same choice */
    const size_t nmax = (n + (size_t)rp_comm_size(s->comm) - 1) / (size_t)rp_comm_size(s->comm);
    if (storage == RP_RAD_STORAGE_AUTO)
        s->dense = nmax <= SIZE_MAX / sizeof(float) / n && nmax * n * sizeof(float) < RP_RAD_DENSE_CAP;
    else
        s->dense = storage == RP_RAD_STORAGE_DENSE;
    if (s->reciprocity && !s->dense)
        return rp_error_set(err, RP_ERR_INPUT, "%s: --reciprocity applies to a dense matrix only "
                            "(%zu elements would need %.1f MiB; see --matrix)", cfg->name, n, MIB(dense_bytes));
    if (s->dense) {
        if (dense_bytes == SIZE_MAX)
            return rp_error_set(err, RP_ERR_NOMEM, "%s: a dense matrix of %zu elements does not fit in memory",
                                cfg->name, n);
        s->F = malloc(dense_bytes ? dense_bytes : 1);
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
    if (rp_rad_split(s))
        rp_rad_log(s, "%s: %zu elements, %zu bands, %s form factors, %s, rows split over %d ranks "
                   "(%.1f MiB of solver memory on rank %d, which owns %zu rows)", cfg->name, n, nb,
                   rp_ff_method_name(s->ffp.method),
                   s->dense ? "dense single-precision matrix" : "form factors computed on the fly",
                   rp_comm_size(s->comm), MIB(s->bytes), rp_comm_rank(s->comm), s->nloc);
    else
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

static void rad_report_scaled(rp_rad_system *s, int gather);

/* Under a split: every rank's row sums and scaled flags to every rank
 * (each row from its owner, so the sums are exact), and the largest row
 * sum over all.  Collective.  Without memory for the buffer the stats
 * stay this rank's (they only feed a message). */
static void rad_gather_row_stats(rp_rad_system *s)
{
    const size_t n = s->n;
    double *v = malloc((2 * n + 1) * sizeof *v);
    double mx[1] = {s->max_row_sum};
    rp_comm_max(s->comm, mx, 1);
    s->max_row_sum = mx[0];
    /* the same on every rank: a failed malloc here makes them disagree
     * on the collective, so a rank without the buffer sends a flag
     * first */
    double ok[1] = {v ? 0 : 1};
    rp_comm_max(s->comm, ok, 1);
    if (ok[0] > 0) {
        free(v);
        return;
    }
    for (size_t i = 0; i < n; i++) {
        int own = rp_rad_owns(s, i);
        v[i] = own ? s->row_sum[i] : 0;
        v[n + i] = own ? s->row_scaled[i] : 0;
    }
    rp_comm_sum(s->comm, v, 2 * n);
    for (size_t i = 0; i < n; i++) {
        s->row_sum[i] = v[i];
        s->row_scaled[i] = v[n + i] > 0;
    }
    free(v);
}

void rp_rad_report_scaled(rp_rad_system *s)
{
    rad_report_scaled(s, 1);
}

/* gather: under a split, collect every rank's row stats first */
static void rad_report_scaled(rp_rad_system *s, int gather)
{
    if (s->rows_reported)
        return;
    s->rows_reported = 1;
    if (gather && rp_rad_split(s))
        rad_gather_row_stats(s);
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
        return rp_rad_local_row(s, i);
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

/* Exchange buffer per chunk of rows (doubles). */
#define RAD_XCHG_BYTES ((size_t)32 << 20)

/* The dense matrix split over ranks: this rank's rows, each pair computed
 * once over all ranks, by the owner of its primary side (rp_ff_primary),
 * as rad_fill_pairs does alone: row i computes the pairs it is primary
 * for and writes F_ij and F_ji, the latter into this rank's row j or, when
 * another rank owns row j, into the exchange buffer.  (Computing a pair
 * from the other side would cost more: the far-pair rules keep terms per
 * receiver, formfactor.c.)  Round robin spreads the rows, hence the
 * primary pairs, evenly.  The columns j go by chunks, each chunk's sends
 * through one rp_comm_sum of a chunk x n buffer where each entry has one
 * sender (exact), so the receiver stores the float the sender computed.
 * A pair's value depends only on (seed, pair) (formfactor.h), so every
 * row is bit for bit the row a single process computes.  Collective:
 * every rank runs the same chunks, and a cancel on any rank stops all
 * after the chunk.  Returns the agreed stop flag, or -1 out of memory
 * (agreed too). */
static int rad_fill_split(rp_rad_system *s, double *rays_out, double *ff_out)
{
    const size_t n = s->n, K = (size_t)rp_comm_size(s->comm);
    const int me = rp_comm_rank(s->comm);
    const int reciprocal = rp_ff_reciprocal(s->ff);
    size_t C = RAD_XCHG_BYTES / sizeof(double) / n;
    C = C < 1 ? 1 : (C > n ? n : C);
    double *buf = reciprocal ? malloc((C * n + 1) * sizeof *buf) : NULL;
    double oom[1] = {reciprocal && !buf};
    rp_comm_max(s->comm, oom, 1);
    if (oom[0] > 0) {
        free(buf);
        return -1;
    }
    double rays = 0, ff = 0;
    int stop = 0;
    if (!reciprocal) {
        /* Whole rows (hemicube): each rank its own. */
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(max : stop)
        for (long l = 0; l < (long)s->nloc; l++) {
            if (rp_cancelled(s->cancel)) {
                stop = 1;
                continue;
            }
            rp_ff_row(s->ff, s->scratch[omp_get_thread_num()], (uint32_t)rp_rad_global_row(s, (size_t)l),
                      s->F + (size_t)l * n, &rays);
            ff += (double)n;
        }
        long none = LONG_MAX;
        rp_rad_agree(s, &stop, &none);
        *rays_out += rays;
        *ff_out += ff;
        return stop;
    }
    for (size_t l = 0; l < s->nloc; l++) {
        size_t i = rp_rad_global_row(s, l);
        s->F[l * n + i] = 0;
    }
    for (size_t j0 = 0; j0 < n; j0 += C) {
        const size_t j1 = j0 + C < n ? j0 + C : n, m = (j1 - j0) * n;
        memset(buf, 0, (m + 1) * sizeof *buf);
        if (!stop) {
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(max : stop)
            for (long l = 0; l < (long)s->nloc; l++) {
                if (rp_cancelled(s->cancel)) {
                    stop = 1;
                    continue;
                }
                rp_ff_scratch *scr = s->scratch[omp_get_thread_num()];
                const size_t i = rp_rad_global_row(s, (size_t)l);
                float *row = s->F + (size_t)l * n;
                for (size_t j = j0; j < j1; j++) {
                    if (j == i || !rp_ff_primary(s->ff, (uint32_t)i, (uint32_t)j))
                        continue;
                    double fij, fji;
                    rp_ff_pair_both(s->ff, scr, (uint32_t)i, (uint32_t)j, &fij, &fji, &rays);
                    row[j] = (float)fij;
                    if (rp_rad_owns(s, j))
                        rp_rad_local_row(s, j)[i] = (float)fji;
                    else
                        buf[(j - j0) * n + i] = (float)fji;
                    ff += 1;
                }
            }
        }
        buf[m] = stop;
        rp_comm_sum(s->comm, buf, m + 1);
        if (buf[m] > 0) {
            stop = 1;
            break;
        }
        /* the entries of this rank's rows in the chunk that other ranks
         * computed: pairs whose primary side is another rank's row */
        for (size_t j = j0 + ((size_t)me + K - j0 % K) % K; j < j1; j += K) {
            float *row = rp_rad_local_row(s, j);
            const double *in = buf + (j - j0) * n;
            for (size_t i = 0; i < n; i++)
                if (i != j && !rp_rad_owns(s, i) && rp_ff_primary(s->ff, (uint32_t)i, (uint32_t)j))
                    row[i] = (float)in[i];
        }
    }
    free(buf);
    *rays_out += rays;
    *ff_out += ff;
    return stop;
}

/* rp_rad_system_matrix under a split: collective. */
static rp_status rad_matrix_split(rp_rad_system *s, rp_step_info *info, rp_error *err)
{
    const size_t n = s->n, nloc = s->nloc;
    double rays = 0, ff = 0;
    int stop = rad_fill_split(s, &rays, &ff);
    info->rays += rays;
    info->form_factors += ff;
    if (stop < 0)
        return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory for the form-factor exchange buffer", s->name);
    if (stop)
        return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted while computing form factors", s->name);
    long bad = LONG_MAX;
    double max_sum = 0;
#pragma omp parallel for num_threads(s->threads) schedule(static) reduction(min : bad) reduction(max : max_sum)
    for (long l = 0; l < (long)nloc; l++) {
        const size_t i = rp_rad_global_row(s, (size_t)l);
        float *row = s->F + (size_t)l * n;
        double sum;
        rp_rad_scale_row(s, (uint32_t)i, row);
        if (rp_rad_check_row(s, (uint32_t)i, row, &sum, NULL) != RP_OK && (long)i < bad)
            bad = (long)i;
        if (s->row_sum[i] > max_sum)
            max_sum = s->row_sum[i];
    }
    s->max_row_sum = max_sum;
    rp_rad_agree(s, &stop, &bad);
    if (bad != LONG_MAX) {
        int owner = (int)((size_t)bad % (size_t)rp_comm_size(s->comm));
        rp_status st = RP_ERR_RUNTIME;
        if (rp_rad_owns(s, (size_t)bad))
            st = rad_first_bad_row(s, rp_rad_local_row(s, (size_t)bad), (uint32_t)bad, err);
        return rp_rad_share_error(s, st, err, owner);
    }
    s->matrix_ready = 1;
    rad_gather_row_stats(s); /* every rank's rows, for the messages */
    rp_rad_log(s, "%s: %zu x %zu form factors computed (%.1f MiB on this rank, %zu rows of %d ranks), "
               "largest row sum %.9g", s->name, n, n, MIB(nloc * n * sizeof(float)), nloc,
               rp_comm_size(s->comm), s->max_row_sum);
    rad_report_scaled(s, 0);
    return RP_OK;
}

rp_status rp_rad_system_matrix(rp_rad_system *s, rp_step_info *info, rp_error *err)
{
    if (!s->dense || s->matrix_ready)
        return RP_OK;
    if (rp_rad_split(s))
        return rad_matrix_split(s, info, err);
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
    /* Split: this rank's rows (local row l is row rp_rad_global_row(l),
     * which is l alone), the others' rows of Y 0 until the sum. */
    if (rp_rad_split(s))
        memset(Y, 0, n * nb * sizeof *Y);
    if (s->dense) {
        rp_status st = rp_rad_system_matrix(s, info, err);
        if (st != RP_OK)
            return st;
        const float *F = s->F;
#pragma omp parallel for num_threads(s->threads) schedule(static)
        for (long l = 0; l < (long)s->nloc; l++)
            rp_rad_dot(F + (size_t)l * n, X, n, nb, Y + rp_rad_global_row(s, (size_t)l) * nb);
        rp_comm_sum(s->comm, Y, n * nb);
        return RP_OK;
    }
    /* Rows on the fly: every row is computed (and checked) again. */
    double rays = 0, ff = 0, max_sum = s->max_row_sum;
    long bad = LONG_MAX;
    int stop = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : rays, ff) \
    reduction(min : bad) reduction(max : max_sum, stop)
    for (long l = 0; l < (long)s->nloc; l++) {
        const long i = (long)rp_rad_global_row(s, (size_t)l);
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
    rp_rad_agree(s, &stop, &bad);
    if (stop)
        return rad_interrupted(s, "computing form factors", err);
    if (bad != LONG_MAX) {
        rp_status st = RP_ERR_RUNTIME;
        if (rp_rad_owns(s, (size_t)bad)) {
            float *buf = s->rowbuf;
            double dff = 0, drays = 0;
            rp_rad_row(s, (uint32_t)bad, s->scratch[0], buf, &dff, &drays);
            st = rad_first_bad_row(s, buf, (uint32_t)bad, err);
        }
        return rp_rad_share_error(s, st, err, (int)((size_t)bad % (size_t)rp_comm_size(s->comm)));
    }
    rp_comm_sum(s->comm, Y, n * nb);
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
