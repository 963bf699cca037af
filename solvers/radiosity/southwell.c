/* Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988),
 * registered as "southwell": a step is one shot.  The element i with the
 * most unshot power A_i |dB_i| shoots it to every element j,
 *
 *     dB_j += rho_j F_ji w dB_i,
 *
 * which needs only column i of F.  This is Southwell relaxation of
 * B = E + rho F B (Gortler, Cohen & Slusallek 1994), the residual kept as
 * the unshot radiosity dB.
 *
 * The columns (--matrix).  When the n x n float matrix fits (auto: below
 * 512 MiB, as for the gathering solvers) the first shot computes it as
 * jacobi and gauss-seidel do (each pair once, rows scaled as theirs:
 * system.h) and transposes it, so southwell solves exactly their system
 * and a shot costs O(n): on CGAL's elephant in the Cornell box (5,568
 * elements) the 24,730 shots to a 1e-6 residual recomputed 2.6 n^2 form
 * factors through the column cache, minutes, against n^2 / 2 once.
 * Otherwise (--matrix rows) columns are computed when shot, no matrix is
 * stored: analytic and Monte Carlo form factors give F_ji pair by pair
 * (rp_ff_pair, the same value as row j of the gathering solvers), so the
 * column is computed directly, in parallel over j.  The hemicube gives
 * whole rows from i only, so there the column comes from reciprocity,
 * F_ji = F_ij A_i / A_j, as in the 1988 paper; reciprocity holds for the
 * hemicube only to its aliasing error, so there the system differs
 * slightly.  A column computed on the fly whose closure exceeds
 * 1 + RP_RAD_ROW_SUM_TOL is scaled to 1 (sw_check_column), the shooting
 * analogue of the gathering solvers' row scaling.
 *
 * Options:
 *   --ambient      answers show B + rho * ambient, the unshot power spread
 *                  uniformly and interreflected with the area-mean
 *                  reflectance: ambient = R sum_j A_j dB_j / sum_j A_j,
 *                  R = 1 / (1 - rho_avg) (Cohen et al. 1988, sec. 4).
 *                  The iteration itself is unchanged.
 *   --overshoot W  shoots W times the unshot radiosity, leaving (1 - W) dB_i
 *                  unshot (negative for W > 1): over-relaxed Southwell
 *                  (overshooting, Feda & Purgathofer 1992; relaxation
 *                  factors analysed by Gortler et al. 1994).  W = 1 is the
 *                  classic method.
 *
 * Residual.  The current B satisfies E + rho F B - B = rho F dB exactly, so
 * in the power norm ||r||_b <= sum_i A_i |dB_ib| k_ib with
 * k_ib = sum_j A_j rho_jb F_ji / A_i, known exactly once column i has been
 * computed, and bounded by rho_max_b C before (C = max(1, largest
 * sum_j A_j F_ji / A_i seen), about 1 by reciprocity and closure).  The
 * reported residual is this bound over the emitted power (worst band): an
 * upper bound on the relative residual the gathering solvers report
 * exactly, at no extra form factors.
 *
 * Split over MPI ranks (solvers/comm.h; rows round robin, system.h), the
 * rank that owns row j computes (or, dense, stores) F_ji for its j, and
 * the column is summed over the ranks (one contributor per entry: exact),
 * so every rank holds the same whole column and shoots it as a single
 * process does: the shots, hence the answers, are bit-identical for any
 * rank count, and the dense matrix is never held whole by one rank.
 *
 * On the fly, columns are kept in a cache of bounded size (--row-cache)
 * that evicts the column of the element with the least unshot power.  The shooting order never depends on the cache or the
 * thread count, so results are the same for any of them. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "system.h"

typedef struct sw_state {
    rp_rad_system sys;
    double *U;          /* n x nb unshot radiosity */
    double *power;      /* n: A_i sum_b |U_ib| */
    int ambient;
    double overshoot;
    double rho_avg[RP_RAD_MAX_BANDS];
    double total_area;
    double closure;     /* max over computed columns of sum_j A_j F_ji / A_i */
    double *reflect;    /* n x nb: sum_j A_j rho_jb F_ji / A_i once column i was
                           computed, -1 before */
    int by_rows;        /* columns from rows by reciprocity (hemicube) */
    int transposed;     /* dense: sys.F holds F transposed (column i at F + i n) */
    unsigned char *col_scaled; /* on the fly: columns scaled (sw_check_column) */
    size_t ncol_scaled;

    /* Column cache over sys.rowbuf. */
    size_t nslots;
    int32_t *slot_of;   /* n: slot holding column i, or -1 */
    uint32_t *col_in;   /* nslots: column held, or RP_NONE */
    uint64_t *used;     /* nslots: last use, for LRU */
    uint64_t clock;
    size_t batch_max;   /* columns computed together on a miss */
    uint32_t *batch;    /* batch_max: columns computed together */
    int32_t *batch_slot;

    /* Split over ranks: the columns being summed (batch_max x n, or one
     * column when dense, + 1 for the cancel flag) and, dense, the
     * current column. */
    double *gather;
    float *col;
} sw_state;

static const rp_option_spec sw_options[] = {
    RP_RAD_MESH_OPTIONS,
    {"matrix", "auto|dense|rows",
     "form-factor storage: dense float n x n matrix computed at the first shot (auto: below 512 MiB), "
     "or columns computed when shot, in a cache (--row-cache)",
     "auto"},
    RP_RAD_SOLVE_OPTIONS,
    {"max-iterations", "N", "stop after N shots", "100 x the element count"},
    {"ambient", NULL, "show the ambient term (unshot power spread uniformly) in the answers", NULL},
    {"overshoot", "W", "shoot W times the unshot radiosity, W in [1, 2); 1 is classic shooting", "1"},
    {"row-cache", "MIB", "memory for cached form-factor columns (at least one per thread)", "16"},
    RP_RAD_IMAGE_OPTIONS,
    {NULL, NULL, NULL, NULL}
};

static void sw_fini(void *state)
{
    sw_state *s = state;
    rp_rad_system_fini(&s->sys);
    free(s->U);
    free(s->power);
    free(s->reflect);
    free(s->slot_of);
    free(s->col_in);
    free(s->used);
    free(s->batch);
    free(s->batch_slot);
    free(s->col_scaled);
    free(s->gather);
    free(s->col);
    memset(s, 0, sizeof *s);
}

static rp_status sw_init_local(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    sw_state *s = state;
    rp_status st;
    double cache_mib = 0; /* defaults: the option specs' fallbacks (rp_options_double) */
    if ((st = rp_options_double(o, "row-cache", 0, 1 << 20, &cache_mib, err)) != RP_OK)
        return st;
    if ((st = rp_options_double(o, "overshoot", 1, 2, &s->overshoot, err)) != RP_OK)
        return st;
    if (!(s->overshoot < 2))
        return rp_error_set(err, RP_ERR_INPUT, "--overshoot: %g is not below 2", s->overshoot);
    s->ambient = rp_options_get(o, "ambient") != NULL;
    rp_rad_config cfg = {.name = "southwell", .storage_option = 1, .storage = RP_RAD_STORAGE_AUTO,
                         .default_max_iterations = 0,
                         /* 0 MiB still keeps one column per thread */
                         .row_bytes = cache_mib > 0 ? (size_t)(cache_mib * 1024 * 1024) : 1};
    rp_rad_system *sys = &s->sys;
    if ((st = rp_rad_system_init(sys, &cfg, scene, o, err)) != RP_OK)
        return st;
    const size_t n = sys->n, nb = sys->nb;
    s->by_rows = sys->ffp.method == RP_FF_HEMICUBE;
    /* dense: no cache (one unused slot keeps the arrays non-empty) */
    s->nslots = sys->dense ? 1 : sys->rowbuf_rows;
    s->col_scaled = calloc(n, 1);
    s->U = malloc(n * nb * sizeof *s->U);
    s->power = malloc(n * sizeof *s->power);
    s->reflect = malloc(n * nb * sizeof *s->reflect);
    s->slot_of = malloc(n * sizeof *s->slot_of);
    s->col_in = malloc(s->nslots * sizeof *s->col_in);
    s->used = calloc(s->nslots, sizeof *s->used);
    /* A few columns per thread per miss, at most half the cache. */
    s->batch_max = 4 * (size_t)sys->threads;
    if (s->batch_max > s->nslots / 2)
        s->batch_max = s->nslots / 2 > 0 ? s->nslots / 2 : 1;
    s->batch = malloc(s->batch_max * sizeof *s->batch);
    s->batch_slot = malloc(s->batch_max * sizeof *s->batch_slot);
    if (!s->U || !s->power || !s->reflect || !s->slot_of || !s->col_in || !s->used || !s->batch ||
        !s->batch_slot || !s->col_scaled)
        return rp_error_set(err, RP_ERR_NOMEM, "southwell: out of memory");
    sys->bytes += 2 * n * nb * sizeof *s->U + n * (sizeof *s->power + sizeof *s->slot_of) +
                  s->nslots * (sizeof *s->col_in + sizeof *s->used);
    if (rp_rad_split(sys)) {
        size_t cols = sys->dense ? 1 : s->batch_max;
        s->gather = malloc((cols * n + 1) * sizeof *s->gather);
        s->col = sys->dense ? malloc(n * sizeof *s->col) : NULL;
        if (!s->gather || (sys->dense && !s->col))
            return rp_error_set(err, RP_ERR_NOMEM, "southwell: out of memory");
        sys->bytes += (cols * n + 1) * sizeof *s->gather + (sys->dense ? n * sizeof *s->col : 0);
    }
    for (size_t i = 0; i < n; i++)
        s->slot_of[i] = -1;
    for (size_t k = 0; k < n * nb; k++)
        s->reflect[k] = -1;
    for (size_t k = 0; k < s->nslots; k++)
        s->col_in[k] = RP_NONE;
    /* Everything emitted is unshot at first. */
    memcpy(s->U, sys->E, n * nb * sizeof *s->U);
    s->total_area = 0;
    for (size_t b = 0; b < nb; b++)
        s->rho_avg[b] = 0;
    for (size_t i = 0; i < n; i++) {
        double p = 0;
        for (size_t b = 0; b < nb; b++) {
            p += fabs(s->U[i * nb + b]);
            s->rho_avg[b] += sys->area[i] * sys->rho[i * nb + b];
        }
        s->power[i] = sys->area[i] * p;
        s->total_area += sys->area[i];
    }
    for (size_t b = 0; b < nb; b++)
        s->rho_avg[b] /= s->total_area;
    return RP_OK;
}

/* The slot to reuse, among those not taken by the first `taken` entries
 * of the current batch: the one whose element has the least unshot power
 * (the shooting order reaches it last, so this approximates evicting the
 * column needed furthest in the future; plain LRU thrashes once shooting
 * cycles through more elements than the cache holds), least recently used
 * among equals.  Empty slots first. */
static int32_t sw_victim(const sw_state *s, size_t taken)
{
    int32_t best = -1;
    double best_power = 0;
    for (size_t k = 0; k < s->nslots; k++) {
        int busy = 0;
        for (size_t t = 0; t < taken; t++)
            if (s->batch_slot[t] == (int32_t)k)
                busy = 1;
        if (busy)
            continue;
        double p = s->col_in[k] == RP_NONE ? -1 : s->power[s->col_in[k]];
        if (best < 0 || p < best_power || (p == best_power && s->used[k] < s->used[best])) {
            best = (int32_t)k;
            best_power = p;
        }
    }
    return best;
}

/* Puts column i (and, batched with it, others) into cache slots. */
static void sw_assign(sw_state *s, size_t m)
{
    for (size_t t = 0; t < m; t++) {
        int32_t k = sw_victim(s, t);
        s->batch_slot[t] = k;
        if (s->col_in[k] != RP_NONE)
            s->slot_of[s->col_in[k]] = -1;
        s->col_in[k] = s->batch[t];
        s->slot_of[s->batch[t]] = k;
        s->used[k] = ++s->clock;
    }
}

/* Transposes the n x n matrix F in place, in square blocks. */
static void sw_transpose(float *F, size_t n, int threads)
{
    const size_t B = 64;
    const long nblk = (long)((n + B - 1) / B);
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
    for (long bi = 0; bi < nblk; bi++) {
        size_t i0 = (size_t)bi * B, i1 = i0 + B < n ? i0 + B : n;
        for (size_t j0 = i0; j0 < n; j0 += B) {
            size_t j1 = j0 + B < n ? j0 + B : n;
            for (size_t i = i0; i < i1; i++)
                for (size_t j = j0 > i + 1 ? j0 : i + 1; j < j1; j++) {
                    float t = F[i * n + j];
                    F[i * n + j] = F[j * n + i];
                    F[j * n + i] = t;
                }
        }
    }
}

/* Column i of F (F_ji for every j) into *out.  Dense: the first call
 * computes the gathering solvers' matrix (rp_rad_system_matrix, rows
 * scaled as theirs) and transposes it, so southwell solves exactly their
 * system.  On the fly: from the cache or computed; a miss computes i's
 * column together with those of the next largest uncached shooters (they
 * are about to be needed): one parallel region per batch rather than per
 * column keeps the threads busy on a loaded machine. */
static rp_status sw_column(sw_state *s, uint32_t i, rp_step_info *info, const float **out, rp_error *err)
{
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n;
    const int split = rp_rad_split(sys);
    if (sys->dense && split) {
        /* F_ji from the owners of rows j, summed: collective */
        rp_status st = rp_rad_system_matrix(sys, info, err);
        if (st != RP_OK)
            return st;
        for (size_t j = 0; j < n; j++)
            s->gather[j] = rp_rad_owns(sys, j) ? rp_rad_local_row(sys, j)[i] : 0;
        rp_comm_sum(sys->comm, s->gather, n);
        for (size_t j = 0; j < n; j++)
            s->col[j] = (float)s->gather[j];
        *out = s->col;
        return RP_OK;
    }
    if (sys->dense) {
        if (!s->transposed) {
            rp_status st = rp_rad_system_matrix(sys, info, err);
            if (st != RP_OK)
                return st;
            sw_transpose(sys->F, n, sys->threads);
            s->transposed = 1;
        }
        *out = sys->F + (size_t)i * n;
        return RP_OK;
    }
    if (s->slot_of[i] < 0) {
        size_t K = s->batch_max < s->nslots ? s->batch_max : s->nslots;
        size_t m = 0;
        s->batch[m++] = i;
        while (m < K) {
            uint32_t best = RP_NONE;
            for (size_t j = 0; j < n; j++) {
                if (s->slot_of[j] >= 0 || !(s->power[j] > 0))
                    continue;
                int in = 0;
                for (size_t t = 0; t < m; t++)
                    in |= s->batch[t] == j;
                if (!in && (best == RP_NONE || s->power[j] > s->power[best]))
                    best = (uint32_t)j;
            }
            if (best == RP_NONE)
                break;
            s->batch[m++] = best;
        }
        sw_assign(s, m);
        double rays = 0, ff = 0;
        int stop = 0;
        if (!s->by_rows) {
            /* F_ji pair by pair: the same values as row j (split: this
             * rank's rows j, the others' entries 0 until the sum). */
            const long total = (long)(m * n);
#pragma omp parallel for num_threads(sys->threads) schedule(dynamic, 64) reduction(+ : rays, ff) \
    reduction(max : stop)
            for (long q = 0; q < total; q++) {
                size_t t = (size_t)q / n, j = (size_t)q % n;
                float *col = sys->rowbuf + (size_t)s->batch_slot[t] * n;
                if (!rp_rad_owns(sys, j)) {
                    col[j] = 0;
                    continue;
                }
                if (rp_cancelled(sys->cancel)) {
                    stop = 1;
                    continue;
                }
                col[j] = (float)rp_ff_pair(sys->ff, sys->scratch[omp_get_thread_num()], (uint32_t)j,
                                           s->batch[t], NULL, &rays);
                ff += 1;
            }
        } else {
            /* Whole rows only (hemicube): F_ji = F_ij A_i / A_j. */
#pragma omp parallel for num_threads(sys->threads) schedule(dynamic, 1) reduction(+ : rays, ff) \
    reduction(max : stop)
            for (long t = 0; t < (long)m; t++) {
                if (rp_cancelled(sys->cancel)) {
                    stop = 1;
                    continue;
                }
                uint32_t r = s->batch[t];
                float *buf = sys->rowbuf + (size_t)s->batch_slot[t] * n;
                if (!rp_rad_owns(sys, r)) {
                    /* split: row r's owner computes the column */
                    memset(buf, 0, n * sizeof *buf);
                    continue;
                }
                rp_rad_row(sys, r, sys->scratch[omp_get_thread_num()], buf, &ff, &rays);
                for (size_t j = 0; j < n; j++)
                    buf[j] = (float)((double)buf[j] * sys->area[r] / sys->area[j]);
            }
        }
        info->rays += rays;
        info->form_factors += ff;
        if (split) {
            /* every rank's entries of the batch's columns to every rank */
            for (size_t t = 0; t < m; t++) {
                const float *col = sys->rowbuf + (size_t)s->batch_slot[t] * n;
                for (size_t j = 0; j < n; j++)
                    s->gather[t * n + j] = col[j];
            }
            s->gather[m * n] = stop;
            rp_comm_sum(sys->comm, s->gather, m * n + 1);
            stop = s->gather[m * n] > 0;
            for (size_t t = 0; t < m; t++) {
                float *col = sys->rowbuf + (size_t)s->batch_slot[t] * n;
                for (size_t j = 0; j < n; j++)
                    col[j] = (float)s->gather[t * n + j];
            }
        }
        if (stop) {
            /* The batch's columns are incomplete: out of the cache. */
            for (size_t t = 0; t < m; t++) {
                s->slot_of[s->batch[t]] = -1;
                s->col_in[s->batch_slot[t]] = RP_NONE;
            }
            return rp_error_set(err, RP_ERR_INTERRUPTED, "southwell: interrupted computing form factors "
                                "(shot %lu)", sys->iterations + 1);
        }
    }
    int32_t k = s->slot_of[i];
    s->used[k] = ++s->clock;
    *out = sys->rowbuf + (size_t)k * n;
    return RP_OK;
}

/* Checks column i and records its closure sum_j A_j F_ji / A_i (*closure)
 * and reflectance-weighted closure (for the residual bound).  Negative or
 * non-finite entries are bugs.  On the fly, a column that would make
 * shooting diverge (the power i sends out, reflected, must be less than it
 * had: sum_j A_j rho_jb F_ji < A_i, Cohen & Wallace 1993, sec. 5.3) or
 * whose closure exceeds 1 + RP_RAD_ROW_SUM_TOL is form-factor error: it is
 * scaled to closure 1 (the shooting analogue of rp_rad_scale_row; the
 * first one is logged).  Dense columns come from the gathering solvers'
 * matrix, whose rows are scaled already and contract, so the iteration
 * converges and nothing is scaled here. */
static rp_status sw_check_column(sw_state *s, uint32_t i, float *col, double *closure, rp_error *err)
{
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, nb = sys->nb;
    double sum = 0, shot[RP_RAD_MAX_BANDS];
    for (size_t b = 0; b < nb; b++)
        shot[b] = 0;
    int bad = 0;
    for (size_t j = 0; j < n; j++) {
        double f = col[j];
        if (!(f >= 0) || !isfinite(f))
            bad = 1;
        double w = sys->area[j] * f;
        sum += w;
        for (size_t b = 0; b < nb; b++)
            shot[b] += sys->rho[j * nb + b] * w;
    }
    if (bad)
        return rp_error_set(err, RP_ERR_RUNTIME, "southwell: form factors to element %u are negative or not finite",
                            i);
    const double Ai = sys->area[i];
    int scale = !sys->dense && sum > (1 + RP_RAD_ROW_SUM_TOL) * Ai;
    for (size_t b = 0; b < nb; b++)
        scale |= !sys->dense && shot[b] >= Ai;
    if (scale && sum > 0) {
        double c = Ai / sum;
        for (size_t j = 0; j < n; j++)
            col[j] = (float)(col[j] * c);
        if (!s->col_scaled[i]) {
            s->col_scaled[i] = 1;
            if (s->ncol_scaled++ == 0) {
                const rp_element *el = rp_mesh_elements(sys->mesh);
                rp_rad_log(sys, "warning: southwell: the form factors to element %u of surface '%s' close to %.6g "
                           "(more than 1 + %g, or shooting would not converge): scaled to 1, as is every such "
                           "column computed on the fly (form-factor error: try more elements where small and "
                           "large elements meet)",
                           i, rp_scene_surfaces(sys->scene)[el[i].surface].name, sum / Ai, RP_RAD_ROW_SUM_TOL);
            }
        }
        sum *= c;
        for (size_t b = 0; b < nb; b++)
            shot[b] *= c;
    }
    *closure = sum / Ai;
    for (size_t b = 0; b < nb; b++)
        s->reflect[(size_t)i * nb + b] = shot[b] / Ai;
    return RP_OK;
}

static rp_status sw_step(void *state, rp_step_info *info, rp_error *err)
{
    sw_state *s = state;
    rp_rad_system *sys = &s->sys;
    const size_t n = sys->n, nb = sys->nb;
    rp_status st;

    uint32_t i = 0;
    for (size_t j = 1; j < n; j++)
        if (s->power[j] > s->power[i])
            i = (uint32_t)j;
    if (!(s->power[i] > 0)) {
        /* Nothing left to shoot: the solution is exact.  A step then does
         * no work and counts no shot; the method says it has converged
         * whatever its rules, since more steps cannot change anything. */
        info->residual = 0;
        info->tolerance = sys->tolerance;
        info->unshot = 0;
        info->progress = 1;
        info->converged = 1;
        info->memory = (double)sys->bytes;
        return RP_OK;
    }
    {
        const float *ccol = NULL;
        if ((st = sw_column(s, i, info, &ccol, err)) != RP_OK)
            return st;
        float *col = (float *)ccol;
        double closure = 0;
        if ((st = sw_check_column(s, i, col, &closure, err)) != RP_OK)
            return st;
        if (closure > s->closure)
            s->closure = closure;
        double d[RP_RAD_MAX_BANDS];
        for (size_t b = 0; b < nb; b++)
            d[b] = s->overshoot * s->U[(size_t)i * nb + b];
        for (size_t j = 0; j < n; j++) {
            double f = col[j];
            if (f == 0)
                continue;
            double p = 0;
            for (size_t b = 0; b < nb; b++) {
                double delta = sys->rho[j * nb + b] * f * d[b];
                sys->B[j * nb + b] += delta;
                s->U[j * nb + b] += delta;
                p += fabs(s->U[j * nb + b]);
            }
            s->power[j] = sys->area[j] * p;
        }
        double p = 0;
        for (size_t b = 0; b < nb; b++) {
            double *u = &s->U[(size_t)i * nb + b];
            *u = s->overshoot == 1 ? 0 : *u - d[b];
            p += fabs(*u);
        }
        s->power[i] = sys->area[i] * p;
    }

    /* Unshot power per band and the residual bound (see the top). */
    double unshot = 0, residual = 0;
    double C = s->closure > 1 ? s->closure : 1;
    for (size_t b = 0; b < nb; b++) {
        double u = 0, r = 0;
        for (size_t j = 0; j < n; j++) {
            double a = sys->area[j] * fabs(s->U[j * nb + b]);
            double k = s->reflect[j * nb + b];
            u += a;
            r += a * (k >= 0 ? k : sys->rho_max[b] * C);
        }
        if (sys->e_norm[b] > 0) {
            u /= sys->e_norm[b];
            r /= sys->e_norm[b];
            if (u > unshot)
                unshot = u;
            if (r > residual)
                residual = r;
        }
    }
    rp_rad_step_done(sys, residual, info);
    info->unshot = unshot;
    return RP_OK;
}

static rp_status sw_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const sw_state *s = state;
    const rp_rad_system *sys = &s->sys;
    if (!s->ambient)
        return rp_rad_estimate(sys, sys->B, e, err);
    const size_t n = sys->n, nb = sys->nb;
    double *Bd = malloc(n * nb * sizeof *Bd);
    if (!Bd)
        return rp_error_set(err, RP_ERR_NOMEM, "southwell: out of memory");
    double ambient[RP_RAD_MAX_BANDS];
    for (size_t b = 0; b < nb; b++) {
        double u = 0;
        for (size_t j = 0; j < n; j++)
            u += sys->area[j] * s->U[j * nb + b];
        /* Cohen et al. 1988, sec. 4: the area-mean unshot radiosity times
         * the interreflection factor 1 / (1 - rho_avg). */
        ambient[b] = u / s->total_area / (1 - s->rho_avg[b]);
    }
    for (size_t j = 0; j < n; j++)
        for (size_t b = 0; b < nb; b++)
            Bd[j * nb + b] = sys->B[j * nb + b] + sys->rho[j * nb + b] * ambient[b];
    rp_status st = rp_rad_estimate(sys, Bd, e, err);
    free(Bd);
    return st;
}

static rp_status sw_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    sw_state *s = state;
    rp_status st = rp_rad_init_agree(rp_rad_options_comm(o), sw_init_local(state, scene, o, err), err);
    if (st == RP_OK && rp_rad_split(&s->sys)) {
        /* The cache decides when columns are computed, hence the
         * collectives: every rank takes the smallest cache and batch of
         * all (their sizes follow the thread count, which may differ;
         * each rank's arrays hold its own, at least as large). */
        double v[2] = {-(double)s->nslots, -(double)s->batch_max};
        rp_comm_max(s->sys.comm, v, 2);
        s->nslots = (size_t)-v[0];
        s->batch_max = (size_t)-v[1];
    }
    return st;
}

const rp_solver_type rp_solver_southwell = {
    .name = "southwell",
    .summary = "finite-element radiosity, progressive refinement (shooting unshot power; "
               "the stored matrix when it fits, columns on the fly otherwise)",
    .options = sw_options,
    .state_size = sizeof(sw_state),
    .init = sw_init,
    .step = sw_step,
    .estimate = sw_estimate,
    .fini = sw_fini,
    .iteration_name = "shots",
    .distributed = 1,
};
