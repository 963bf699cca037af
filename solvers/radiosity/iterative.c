/* Gathering iterations on the radiosity system B = E + rho F B (Cohen &
 * Wallace 1993, sec. 5.2), registered as "jacobi" and "gauss-seidel".
 *
 * Both start from B = E; a step is one sweep over all elements.  Jacobi
 * updates every element from the previous iterate, B' = E + rho F B, so its
 * error shrinks by rho per sweep in a closed scene with uniform rho;
 * Gauss-Seidel uses each new value as soon as it has it, in element order,
 * and is never slower for this M-matrix (Stein-Rosenberg theorem).
 *
 * After every sweep the residual of the new iterate is computed exactly,
 *     r = max_b sum_i A_i |E + rho F B - B|_ib / sum_i A_i E_ib
 * (the power norm, worst band), from one product F B.  Jacobi's next sweep
 * is that same product (B'' = E + rho F B'), so it costs one product per
 * sweep; Gauss-Seidel pays a second one.  Both are cheap beside the form
 * factors with a stored matrix; with rows on the fly (--matrix rows) every
 * product recomputes all n rows.
 *
 * Split over MPI ranks (solvers/comm.h, rows round robin: system.h), each
 * rank computes and stores only its rows of F and the products F B are
 * summed over the ranks (one contributor per element: exact), so Jacobi
 * is the same iteration to the last bit for any rank count.  So is
 * Gauss-Seidel (gs_sweep_dense_split, gs_sweep_rows_split): each block
 * of rows is updated in element order as alone, the rows' sums over the
 * columns outside the block computed by the rows' owners in parallel and
 * the block's own columns gathered to every rank, which then all update
 * the block's elements the same way; only a block's rows travel, never
 * the matrix. */
#include <limits.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "system.h"

typedef struct it_state {
    rp_rad_system sys;
    int have_FB; /* sys.G holds F B for the current B (Jacobi) */
    double *xbuf; /* split Gauss-Seidel: a block's rows being summed */
    size_t xbuf_size;
} it_state;

/* Rows per block of a Gauss-Seidel sweep over the stored matrix (see
 * gs_sweep_dense). */
#define GS_BLOCK 256
/* Rows per block of a split sweep with rows on the fly: a constant, not
 * the thread count, so that every rank runs the same collectives (the
 * system's row buffer holds at least min(n, 64) rows). */
#define GS_ROWS_SPLIT 64

static const rp_option_spec it_options[] = {
    RP_RAD_MESH_OPTIONS,
    {"matrix", "auto|dense|rows",
     "form-factor storage: dense float n x n matrix (auto: below 512 MiB) or rows recomputed every sweep",
     "auto"},
    RP_RAD_RECIPROCITY_OPTION,
    RP_RAD_SOLVE_OPTIONS,
    {"max-iterations", "N", "stop after N sweeps", "1000"},
    RP_RAD_IMAGE_OPTIONS,
    {NULL, NULL, NULL, NULL}
};

static rp_status it_init_common(void *state, const rp_scene *scene, const rp_options *o, const char *name,
                                rp_error *err)
{
    it_state *s = state;
    rp_rad_config cfg = {.name = name, .storage_option = 1, .reciprocity_option = 1,
                         .storage = RP_RAD_STORAGE_AUTO,
                         .default_max_iterations = 1000};
    return rp_rad_system_init(&s->sys, &cfg, scene, o, err);
}

static rp_status jacobi_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    return rp_rad_init_agree(rp_rad_options_comm(o), it_init_common(state, scene, o, "jacobi", err), err);
}

static rp_status gs_init_local(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    it_state *s = state;
    rp_status st = it_init_common(state, scene, o, "gauss-seidel", err);
    rp_rad_system *sys = &s->sys;
    if (st != RP_OK || !rp_rad_split(sys))
        return st;
    /* dense: a block's square of F and its outer sums; rows on the fly:
     * a block of whole rows, and two flags */
    s->xbuf_size = sys->dense ? (size_t)GS_BLOCK * GS_BLOCK + GS_BLOCK * sys->nb
                              : (sys->n < GS_ROWS_SPLIT ? sys->n : GS_ROWS_SPLIT) * sys->n + 2;
    s->xbuf = malloc(s->xbuf_size * sizeof *s->xbuf);
    if (!s->xbuf)
        return rp_error_set(err, RP_ERR_NOMEM, "gauss-seidel: out of memory");
    sys->bytes += s->xbuf_size * sizeof *s->xbuf;
    return RP_OK;
}

static rp_status gs_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    return rp_rad_init_agree(rp_rad_options_comm(o), gs_init_local(state, scene, o, err), err);
}

static void it_fini(void *state)
{
    it_state *s = state;
    rp_rad_system_fini(&s->sys);
    free(s->xbuf);
    s->xbuf = NULL;
}

static rp_status jacobi_step(void *state, rp_step_info *info, rp_error *err)
{
    it_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t nn = sys->n * sys->nb;
    rp_status st;
    if (!s->have_FB) {
        if ((st = rp_rad_matvec(sys, sys->B, sys->G, info, err)) != RP_OK)
            return st;
        s->have_FB = 1;
    }
    /* B' = E + rho F B, with F B from the previous residual. */
    for (size_t k = 0; k < nn; k++)
        sys->B[k] = sys->E[k] + sys->rho[k] * sys->G[k];
    s->have_FB = 0;
    if ((st = rp_rad_matvec(sys, sys->B, sys->G, info, err)) != RP_OK)
        return st;
    s->have_FB = 1;
    rp_rad_step_done(sys, rp_rad_residual(sys, sys->B, sys->G), info);
    return RP_OK;
}

/* One Gauss-Seidel update of element i from its row. */
static inline void gs_update(rp_rad_system *sys, size_t i, const float *row)
{
    const size_t n = sys->n, nb = sys->nb;
    double acc[RP_RAD_MAX_BANDS];
    rp_rad_dot(row, sys->B, n, nb, acc);
    for (size_t b = 0; b < nb; b++)
        sys->B[i * nb + b] = sys->E[i * nb + b] + sys->rho[i * nb + b] * acc[b];
}

/* A Gauss-Seidel sweep over the stored matrix, in blocks of GS_BLOCK rows
 * (a constant, so the sums, hence the iterates, are the same for any
 * thread count): for the rows of a block, the part of F B over the columns
 * outside the block (new values before it, old ones after) is computed in
 * parallel, then the rows are updated in order with the block's own
 * columns.  The same iteration as row-by-row Gauss-Seidel, the sums only
 * grouped differently, and all but GS_BLOCK / n of the work parallel. */

static void gs_sweep_dense(rp_rad_system *sys)
{
    const size_t n = sys->n, nb = sys->nb;
    const float *F = sys->F;
    double *B = sys->B, *P = sys->G; /* G: scratch until the residual's F B */
    for (size_t i0 = 0; i0 < n; i0 += GS_BLOCK) {
        size_t i1 = i0 + GS_BLOCK < n ? i0 + GS_BLOCK : n;
#pragma omp parallel for num_threads(sys->threads) schedule(static)
        for (long i = (long)i0; i < (long)i1; i++) {
            const float *row = F + (size_t)i * n;
            double a[RP_RAD_MAX_BANDS], c[RP_RAD_MAX_BANDS];
            rp_rad_dot(row, B, i0, nb, a);
            rp_rad_dot(row + i1, B + i1 * nb, n - i1, nb, c);
            for (size_t b = 0; b < nb; b++)
                P[(size_t)i * nb + b] = a[b] + c[b];
        }
        for (size_t i = i0; i < i1; i++) {
            double acc[RP_RAD_MAX_BANDS];
            rp_rad_dot(F + i * n + i0, B + i0 * nb, i1 - i0, nb, acc);
            for (size_t b = 0; b < nb; b++)
                B[i * nb + b] = sys->E[i * nb + b] + sys->rho[i * nb + b] * (P[i * nb + b] + acc[b]);
        }
    }
}

/* gs_sweep_dense under a split, the same sums to the last bit: for each
 * block of GS_BLOCK rows, the owners compute their rows' sums over the
 * columns outside the block (a with the new values before it, c with the
 * old ones after, exactly as alone), and the block's square of F and those
 * sums are summed over the ranks (each entry from one owner: exact); then
 * every rank updates the block's elements in order, as alone, so B stays
 * the same on every rank.  Collective. */
static void gs_sweep_dense_split(it_state *s)
{
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, nb = sys->nb;
    double *B = sys->B, *x = s->xbuf;
    float sub[GS_BLOCK];
    for (size_t i0 = 0; i0 < n; i0 += GS_BLOCK) {
        const size_t i1 = i0 + GS_BLOCK < n ? i0 + GS_BLOCK : n, m = i1 - i0;
        double *P = x + m * m; /* m x nb outer sums */
        memset(x, 0, (m * m + m * nb) * sizeof *x);
#pragma omp parallel for num_threads(sys->threads) schedule(static)
        for (long i = (long)i0; i < (long)i1; i++) {
            if (!rp_rad_owns(sys, (size_t)i))
                continue;
            const float *row = rp_rad_local_row(sys, (size_t)i);
            double a[RP_RAD_MAX_BANDS], c[RP_RAD_MAX_BANDS];
            rp_rad_dot(row, B, i0, nb, a);
            rp_rad_dot(row + i1, B + i1 * nb, n - i1, nb, c);
            for (size_t b = 0; b < nb; b++)
                P[((size_t)i - i0) * nb + b] = a[b] + c[b];
            for (size_t j = 0; j < m; j++)
                x[((size_t)i - i0) * m + j] = row[i0 + j];
        }
        rp_comm_sum(sys->comm, x, m * m + m * nb);
        for (size_t i = i0; i < i1; i++) {
            double acc[RP_RAD_MAX_BANDS];
            for (size_t j = 0; j < m; j++)
                sub[j] = (float)x[(i - i0) * m + j];
            rp_rad_dot(sub, B + i0 * nb, m, nb, acc);
            for (size_t b = 0; b < nb; b++)
                B[i * nb + b] = sys->E[i * nb + b] + sys->rho[i * nb + b] * (P[(i - i0) * nb + b] + acc[b]);
        }
    }
}

/* A sweep with rows on the fly under a split, the same as alone: each
 * block of rows is computed by the rows' owners in parallel, summed over
 * the ranks (exact) with a cancel flag and a bad-row flag, and every rank
 * then checks (if flagged) and applies the rows in element order as
 * alone.  Collective; every rank returns the same status and message. */
static rp_status gs_sweep_rows_split(it_state *s, rp_step_info *info, rp_error *err)
{
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, R = n < GS_ROWS_SPLIT ? n : GS_ROWS_SPLIT;
    double *x = s->xbuf;
    rp_status st;
    for (size_t i0 = 0; i0 < n; i0 += R) {
        const size_t i1 = i0 + R < n ? i0 + R : n, m = (i1 - i0) * n;
        double rays = 0, ff = 0, max_sum = sys->max_row_sum;
        int stop = 0, bad = 0;
#pragma omp parallel for num_threads(sys->threads) schedule(dynamic, 1) reduction(+ : rays, ff) \
    reduction(max : max_sum, bad, stop)
        for (long i = (long)i0; i < (long)i1; i++) {
            float *buf = sys->rowbuf + (size_t)(i - (long)i0) * n;
            if (!rp_rad_owns(sys, (size_t)i)) {
                memset(buf, 0, n * sizeof *buf);
                continue;
            }
            if (rp_cancelled(sys->cancel)) {
                stop = 1;
                continue;
            }
            rp_rad_row(sys, (uint32_t)i, sys->scratch[omp_get_thread_num()], buf, &ff, &rays);
            double sum;
            if (rp_rad_check_row(sys, (uint32_t)i, buf, &sum, NULL) != RP_OK)
                bad = 1;
            if (sys->row_sum[i] > max_sum)
                max_sum = sys->row_sum[i];
        }
        info->rays += rays;
        info->form_factors += ff;
        sys->max_row_sum = max_sum;
        for (size_t k = 0; k < m; k++)
            x[k] = sys->rowbuf[k];
        x[m] = stop;
        x[m + 1] = bad;
        rp_comm_sum(sys->comm, x, m + 2);
        if (x[m] > 0)
            return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted in sweep %lu", sys->name,
                                sys->iterations + 1);
        for (size_t k = 0; k < m; k++)
            sys->rowbuf[k] = (float)x[k];
        for (size_t i = i0; i < i1; i++) {
            const float *row = sys->rowbuf + (i - i0) * n;
            double sum;
            /* Checked in order so the error names the first bad row. */
            if (x[m + 1] > 0 && (st = rp_rad_check_row(sys, (uint32_t)i, row, &sum, err)) != RP_OK)
                return st;
            gs_update(sys, i, row);
        }
    }
    rp_rad_report_scaled(sys);
    return RP_OK;
}

/* gs_step under a split: the same sweep as alone, then the residual. */
static rp_status gs_step_split(it_state *s, rp_step_info *info, rp_error *err)
{
    rp_rad_system *sys = &s->sys;
    rp_status st;
    if (sys->dense) {
        if ((st = rp_rad_system_matrix(sys, info, err)) != RP_OK)
            return st;
        gs_sweep_dense_split(s);
    } else if ((st = gs_sweep_rows_split(s, info, err)) != RP_OK) {
        return st;
    }
    if ((st = rp_rad_matvec(sys, sys->B, sys->G, info, err)) != RP_OK)
        return st;
    rp_rad_step_done(sys, rp_rad_residual(sys, sys->B, sys->G), info);
    return RP_OK;
}

static rp_status gs_step(void *state, rp_step_info *info, rp_error *err)
{
    it_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n;
    rp_status st;
    if (rp_rad_split(sys))
        return gs_step_split(s, info, err);
    if (sys->dense) {
        if ((st = rp_rad_system_matrix(sys, info, err)) != RP_OK)
            return st;
        gs_sweep_dense(sys);
    } else {
        /* Rows do not depend on B: compute a block of them in parallel,
         * then update in element order. */
        const size_t R = sys->rowbuf_rows;
        for (size_t i0 = 0; i0 < n; i0 += R) {
            size_t i1 = i0 + R < n ? i0 + R : n;
            double rays = 0, ff = 0, max_sum = sys->max_row_sum;
            long bad = -1;
            int stop = 0;
#pragma omp parallel for num_threads(sys->threads) schedule(dynamic, 1) reduction(+ : rays, ff) \
    reduction(max : max_sum, bad, stop)
            for (long i = (long)i0; i < (long)i1; i++) {
                if (rp_cancelled(sys->cancel)) {
                    stop = 1;
                    continue;
                }
                float *buf = sys->rowbuf + (size_t)(i - (long)i0) * n;
                rp_rad_row(sys, (uint32_t)i, sys->scratch[omp_get_thread_num()], buf, &ff, &rays);
                double sum;
                if (rp_rad_check_row(sys, (uint32_t)i, buf, &sum, NULL) != RP_OK)
                    bad = bad < 0 || i < bad ? i : bad;
                if (sys->row_sum[i] > max_sum)
                    max_sum = sys->row_sum[i];
            }
            info->rays += rays;
            info->form_factors += ff;
            sys->max_row_sum = max_sum;
            if (stop)
                return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted in sweep %lu", sys->name,
                                    sys->iterations + 1);
            for (size_t i = i0; i < i1; i++) {
                const float *row = sys->rowbuf + (i - i0) * n;
                double sum;
                /* Checked in order so the error names the first bad row. */
                if (bad >= 0 && (st = rp_rad_check_row(sys, (uint32_t)i, row, &sum, err)) != RP_OK)
                    return st;
                gs_update(sys, i, row);
            }
        }
        rp_rad_report_scaled(sys);
    }
    if ((st = rp_rad_matvec(sys, sys->B, sys->G, info, err)) != RP_OK)
        return st;
    rp_rad_step_done(sys, rp_rad_residual(sys, sys->B, sys->G), info);
    return RP_OK;
}

static rp_status it_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const it_state *s = state;
    return rp_rad_estimate(&s->sys, s->sys.B, e, err);
}

const rp_solver_type rp_solver_jacobi = {
    .name = "jacobi",
    .summary = "finite-element radiosity, Jacobi iteration (gathering sweeps from B = E)",
    .options = it_options,
    .state_size = sizeof(it_state),
    .init = jacobi_init,
    .step = jacobi_step,
    .estimate = it_estimate,
    .fini = it_fini,
    .iteration_name = "sweeps",
    .distributed = 1,
};

const rp_solver_type rp_solver_gauss_seidel = {
    .name = "gauss-seidel",
    .summary = "finite-element radiosity, Gauss-Seidel iteration (in-place gathering sweeps)",
    .options = it_options,
    .state_size = sizeof(it_state),
    .init = gs_init,
    .step = gs_step,
    .estimate = it_estimate,
    .fini = it_fini,
    .iteration_name = "sweeps",
    .distributed = 1,
};
