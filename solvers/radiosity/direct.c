/* A direct solve of the radiosity system, registered as "direct": LU
 * decomposition with partial pivoting (GSL, gsl_linalg_LU_decomp /
 * gsl_linalg_LU_solve) of (I - diag(rho_b) F) B_b = E_b, once per band
 * (bands with identical reflectances share one factorisation).
 *
 * O(n^3) time and 8 n^2 bytes beside the float matrix, so it is for small
 * systems and as a check on the iterations; above RP_RAD_DIRECT_MAX
 * elements it refuses.  One step does the whole solve. */
#include <gsl/gsl_errno.h>
#include <gsl/gsl_linalg.h>
#include <gsl/gsl_matrix.h>
#include <gsl/gsl_permutation.h>
#include <gsl/gsl_vector.h>
#include <stdlib.h>
#include <string.h>

#include "system.h"

/* 3000^3 * 2/3 = 1.8e10 flops per band for GSL's LU: some seconds. */
#define RP_RAD_DIRECT_MAX 3000

typedef struct direct_state {
    rp_rad_system sys;
    int solved;
} direct_state;

static const rp_option_spec direct_options[] = {
    RP_RAD_MESH_OPTIONS,
    RP_RAD_RECIPROCITY_OPTION,
    RP_RAD_IMAGE_OPTIONS,
    {NULL, NULL, NULL, NULL}
};

static rp_status direct_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    direct_state *s = state;
    rp_rad_config cfg = {.name = "direct", .storage_option = 0, .reciprocity_option = 1,
                         .storage = RP_RAD_STORAGE_DENSE,
                         .default_max_iterations = 1, .max_elements = RP_RAD_DIRECT_MAX,
                         .max_elements_why = "a dense LU solve takes O(n^3) time and 8 n^2 bytes; "
                                             "iterate instead with gauss-seidel"};
    rp_status st = rp_rad_system_init(&s->sys, &cfg, scene, o, err);
    if (st != RP_OK)
        return st;
    s->sys.bytes += s->sys.n * s->sys.n * sizeof(double);
    return RP_OK;
}

static void direct_fini(void *state)
{
    direct_state *s = state;
    rp_rad_system_fini(&s->sys);
}

/* 1 if band b's reflectances equal band c's for every element. */
static int same_rho(const rp_rad_system *sys, size_t b, size_t c)
{
    for (size_t i = 0; i < sys->n; i++)
        if (sys->rho[i * sys->nb + b] != sys->rho[i * sys->nb + c])
            return 0;
    return 1;
}

static rp_status direct_step(void *state, rp_step_info *info, rp_error *err)
{
    direct_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, nb = sys->nb;
    rp_status st;
    if (!s->solved) {
        if ((st = rp_rad_system_matrix(sys, info, err)) != RP_OK)
            return st;
        gsl_matrix *A = gsl_matrix_alloc(n, n);
        gsl_permutation *perm = gsl_permutation_alloc(n);
        gsl_vector *rhs = gsl_vector_alloc(n), *x = gsl_vector_alloc(n);
        if (!A || !perm || !rhs || !x) {
            gsl_matrix_free(A);
            gsl_permutation_free(perm);
            gsl_vector_free(rhs);
            gsl_vector_free(x);
            return rp_error_set(err, RP_ERR_NOMEM, "direct: out of memory for a %zu x %zu matrix", n, n);
        }
        long factored = -1; /* band whose reflectances A was factored for */
        int status = GSL_SUCCESS;
        for (size_t b = 0; b < nb && status == GSL_SUCCESS; b++) {
            if (factored < 0 || !same_rho(sys, (size_t)factored, b)) {
                /* A = I - diag(rho_b) F */
                for (size_t i = 0; i < n; i++) {
                    double r = sys->rho[i * nb + b];
                    const float *row = sys->F + i * n;
                    double *a = gsl_matrix_ptr(A, i, 0);
                    for (size_t j = 0; j < n; j++)
                        a[j] = -r * row[j];
                    a[i] += 1.0;
                }
                int signum;
                status = gsl_linalg_LU_decomp(A, perm, &signum);
                factored = (long)b;
                /* The row check (rho sum F < 1) makes A strictly diagonally
                 * dominant, hence regular; a zero pivot would still be a
                 * bug, not an answer. */
                for (size_t i = 0; i < n && status == GSL_SUCCESS; i++)
                    if (!(gsl_matrix_get(A, i, i) != 0))
                        status = GSL_ESING;
            }
            if (status != GSL_SUCCESS)
                break;
            for (size_t i = 0; i < n; i++)
                gsl_vector_set(rhs, i, sys->E[i * nb + b]);
            status = gsl_linalg_LU_solve(A, perm, rhs, x);
            for (size_t i = 0; i < n; i++)
                sys->B[i * nb + b] = gsl_vector_get(x, i);
        }
        gsl_matrix_free(A);
        gsl_permutation_free(perm);
        gsl_vector_free(rhs);
        gsl_vector_free(x);
        if (status != GSL_SUCCESS)
            return rp_error_set(err, RP_ERR_RUNTIME, "direct: LU solve failed: %s", gsl_strerror(status));
        s->solved = 1;
    }
    if ((st = rp_rad_matvec(sys, sys->B, sys->G, info, err)) != RP_OK)
        return st;
    rp_rad_step_done(sys, rp_rad_residual(sys, sys->B, sys->G), info);
    /* Nothing is left to do after the solve, whatever the residual. */
    info->converged = 1;
    info->progress = 1;
    return RP_OK;
}

static rp_status direct_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const direct_state *s = state;
    return rp_rad_estimate(&s->sys, s->sys.B, e, err);
}

const rp_solver_type rp_solver_direct = {
    .name = "direct",
    .summary = "finite-element radiosity solved directly by LU decomposition (GSL); small systems only",
    .options = direct_options,
    .state_size = sizeof(direct_state),
    .init = direct_init,
    .step = direct_step,
    .estimate = direct_estimate,
    .fini = direct_fini,
    .iteration_name = "solves",
};
