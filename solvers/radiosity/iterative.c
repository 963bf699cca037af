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
 * product recomputes all n rows. */
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "system.h"

typedef struct it_state {
    rp_rad_system sys;
    int have_FB; /* sys.G holds F B for the current B (Jacobi) */
} it_state;

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
#define GS_BLOCK 256

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

static rp_status gs_step(void *state, rp_step_info *info, rp_error *err)
{
    it_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n;
    rp_status st;
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
};
