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
 * rank computes and stores only its rows of F and updates only their
 * elements, and the new B is summed over the ranks (one contributor per
 * element: exact).  Jacobi is then the same iteration to the last bit
 * for any rank count.  Gauss-Seidel becomes block Jacobi across ranks:
 * a rank sweeps its own rows in order with their new values and the
 * other ranks' values from the previous sweep (Gauss-Seidel within a
 * rank); it converges to the same solution, in a few more sweeps, and
 * stops by the same residual, computed from the whole F B. */
#include <limits.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "system.h"

typedef struct it_state {
    rp_rad_system sys;
    int have_FB; /* sys.G holds F B for the current B (Jacobi) */
    double *old; /* split Gauss-Seidel: a block's previous values (GS_BLOCK x nb) */
} it_state;

/* Rows per block of a Gauss-Seidel sweep over the stored matrix (see
 * gs_sweep_dense). */
#define GS_BLOCK 256

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
    rp_status st = rp_rad_system_init(&s->sys, &cfg, scene, o, err);
    if (st == RP_OK && rp_rad_split(&s->sys)) {
        s->old = malloc(GS_BLOCK * s->sys.nb * sizeof *s->old);
        if (!s->old)
            return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", name);
    }
    return st;
}

static rp_status jacobi_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    return it_init_common(state, scene, o, "jacobi", err);
}

static rp_status gs_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    return it_init_common(state, scene, o, "gauss-seidel", err);
}

static void it_fini(void *state)
{
    it_state *s = state;
    rp_rad_system_fini(&s->sys);
    free(s->old);
    s->old = NULL;
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

/* gs_sweep_dense under a split: this rank's rows in order, in blocks of
 * GS_BLOCK local rows (round robin, so a block's columns are not
 * contiguous): F B for the block's rows with the current B in parallel
 * (new values of this rank's earlier rows, old ones of the rest), then
 * the rows in order, each corrected for the block's rows already updated:
 * B_i = E_i + rho_i (P_i + sum_{j in block, before i} F_ij (B_j' - B_j)). */
static void gs_sweep_dense_split(it_state *s)
{
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, nb = sys->nb, nloc = sys->nloc;
    const float *F = sys->F;
    double *B = sys->B, *P = sys->G, *old = s->old;
    for (size_t l0 = 0; l0 < nloc; l0 += GS_BLOCK) {
        size_t l1 = l0 + GS_BLOCK < nloc ? l0 + GS_BLOCK : nloc;
#pragma omp parallel for num_threads(sys->threads) schedule(static)
        for (long l = (long)l0; l < (long)l1; l++)
            rp_rad_dot(F + (size_t)l * n, B, n, nb, P + rp_rad_global_row(sys, (size_t)l) * nb);
        for (size_t l = l0; l < l1; l++)
            memcpy(old + (l - l0) * nb, B + rp_rad_global_row(sys, l) * nb, nb * sizeof *old);
        for (size_t l = l0; l < l1; l++) {
            const size_t i = rp_rad_global_row(sys, l);
            const float *row = F + l * n;
            double acc[RP_RAD_MAX_BANDS];
            for (size_t b = 0; b < nb; b++)
                acc[b] = P[i * nb + b];
            for (size_t q = l0; q < l; q++) {
                const size_t j = rp_rad_global_row(sys, q);
                double f = row[j];
                for (size_t b = 0; b < nb; b++)
                    acc[b] += f * (B[j * nb + b] - old[(q - l0) * nb + b]);
            }
            for (size_t b = 0; b < nb; b++)
                B[i * nb + b] = sys->E[i * nb + b] + sys->rho[i * nb + b] * acc[b];
        }
    }
}

/* Under a split, after a sweep: every rank's new values of its rows to
 * every rank (through G, which the residual's product overwrites next). */
static void gs_combine(rp_rad_system *sys)
{
    const size_t n = sys->n, nb = sys->nb;
    for (size_t i = 0; i < n; i++)
        for (size_t b = 0; b < nb; b++)
            sys->G[i * nb + b] = rp_rad_owns(sys, i) ? sys->B[i * nb + b] : 0;
    rp_comm_sum(sys->comm, sys->G, n * nb);
    memcpy(sys->B, sys->G, n * nb * sizeof *sys->B);
}

static rp_status gs_step(void *state, rp_step_info *info, rp_error *err)
{
    it_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n;
    const int split = rp_rad_split(sys);
    rp_status st;
    if (sys->dense) {
        if ((st = rp_rad_system_matrix(sys, info, err)) != RP_OK)
            return st;
        if (split)
            gs_sweep_dense_split(s);
        else
            gs_sweep_dense(sys);
    } else {
        /* Rows do not depend on B: compute a block of them in parallel,
         * then update in element order.  Local rows l (split: this rank's
         * rows in order; alone l is the row). */
        const size_t R = sys->rowbuf_rows, nloc = sys->nloc;
        int stopped = 0;
        long failed = LONG_MAX; /* split: the first bad row found here */
        rp_status fst = RP_OK;
        for (size_t i0 = 0; i0 < nloc && !stopped && failed == LONG_MAX; i0 += R) {
            size_t i1 = i0 + R < nloc ? i0 + R : nloc;
            double rays = 0, ff = 0, max_sum = sys->max_row_sum;
            long bad = -1;
            int stop = 0;
#pragma omp parallel for num_threads(sys->threads) schedule(dynamic, 1) reduction(+ : rays, ff) \
    reduction(max : max_sum, bad, stop)
            for (long l = (long)i0; l < (long)i1; l++) {
                const long i = (long)rp_rad_global_row(sys, (size_t)l);
                if (rp_cancelled(sys->cancel)) {
                    stop = 1;
                    continue;
                }
                float *buf = sys->rowbuf + (size_t)(l - (long)i0) * n;
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
            if (stop) {
                if (!split)
                    return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted in sweep %lu", sys->name,
                                        sys->iterations + 1);
                stopped = 1;
                break;
            }
            for (size_t l = i0; l < i1; l++) {
                const size_t i = rp_rad_global_row(sys, l);
                const float *row = sys->rowbuf + (l - i0) * n;
                double sum;
                /* Checked in order so the error names the first bad row. */
                if (bad >= 0 && (st = rp_rad_check_row(sys, (uint32_t)i, row, &sum, err)) != RP_OK) {
                    if (!split)
                        return st;
                    failed = (long)i;
                    fst = st;
                    break;
                }
                gs_update(sys, i, row);
            }
        }
        if (split) {
            rp_rad_agree(sys, &stopped, &failed);
            if (stopped)
                return rp_error_set(err, RP_ERR_INTERRUPTED, "%s: interrupted in sweep %lu", sys->name,
                                    sys->iterations + 1);
            if (failed != LONG_MAX)
                return rp_rad_share_error(sys, rp_rad_owns(sys, (size_t)failed) ? fst : RP_ERR_RUNTIME, err,
                                          (int)((size_t)failed % (size_t)rp_comm_size(sys->comm)));
        }
        rp_rad_report_scaled(sys);
    }
    if (split)
        gs_combine(sys);
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
