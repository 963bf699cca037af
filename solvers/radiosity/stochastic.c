/* Stochastic Jacobi radiosity, registered as "stochastic-jacobi" (Neumann
 * 1995, "Monte Carlo radiosity", Computing 55; Bekaert 1999, "Hierarchical
 * and stochastic algorithms for radiosity", PhD thesis, KU Leuven;
 * Dutre, Bala & Bekaert, "Advanced Global Illumination" (AGI), 2nd ed.,
 * ch. 6, stochastic relaxation radiosity).
 *
 * In power form the radiosity system reads, per band,
 *
 *     P_j = Phi_j + rho_j sum_i P_i F_ij,     P = A B, Phi = A E = pi Le A,
 *
 * and a Jacobi iteration P' = Phi + rho F^T P is estimated with random
 * lines: a ray leaves element i with probability p_i proportional to the
 * power being shot, from a uniform point, in a cosine-distributed
 * direction, so it lands on element j with probability F_ij given i; the
 * element it lands on (front face only: backs are black) receives
 * rho_j P_i / (N p_i).  Its expectation is rho_j sum_i P_i F_ij exactly
 * whatever the p_i (> 0 where P_i > 0), so no form factor is ever
 * computed.
 *
 * Two phases (Bekaert's "incremental + regular" scheme, AGI ch. 6):
 *   incremental  shoot the unshot power dP of the last iteration,
 *                P += dP' = rho F^T dP, until sum dP falls below --unshot
 *                times the emitted power: a stochastic Neumann series,
 *                unbiased for its partial sum;
 *   regular      from that P, iterate P' = Phi + rho F^T P, shooting the
 *                total power, and average the iterates: each is an
 *                estimate of the same fixed point, so the average's
 *                variance falls as 1 / (iterations) (successive iterates
 *                are correlated over about 1 / (1 - rho) iterations).
 *                Started from a converged enough P the average is unbiased
 *                up to the incremental phase's truncation; started from
 *                P = Phi (--unshot 1) it keeps the start-up transient:
 *                the error P* - Phi shrinks by about rho per iteration, so
 *                the average of N iterates is low by about
 *                rho (P* - Phi) / ((1 - rho) N).
 *
 * Standard errors come from independent replicas (--batches K): the rays of
 * an iteration are split into K groups, each driving its own complete
 * solution with its own random numbers.  The answer is the mean of the K
 * solutions and its standard error the replicas' standard deviation over
 * sqrt(K); unlike per-ray variances this includes the noise each iteration
 * inherits from the previous ones, and covariances between elements when
 * surfaces are averaged.  Estimating from K replicas of N/K rays costs the
 * same rays as one solution from N.
 *
 * Determinism: every ray's sample vector is a pure function of (seed,
 * replica, iteration, ray index) (pathtrace/sampler.h, random or
 * Owen-scrambled Sobol'); the rays record (source, hit) per ray in parallel
 * and the contributions are added in ray order, one replica per thread, so
 * the result is bit-identical for any thread count.
 *
 * Split over MPI ranks (solvers/comm.h), the rays are traced by blocks of
 * SJ_RAY_BLOCK by global index, round robin (rp_comm_owns), and every
 * rank's (source, hit) records are summed over the ranks (one tracer per
 * ray: exact), so every rank adds up the same records in the same order
 * as a single process: bit-identical for any rank count too. */
#include <gsl/gsl_interp.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../geometry/discontinuity.h"
#include "../../geometry/mesh.h"
#include "../../geometry/raycast.h"
#include "../../geometry/scene.h"
#include "../pathtrace/sampler.h"
#include "system.h"
#include "../solver.h"
#include "reconstruct.h"

#define SJ_MAX_BANDS 256
/* Rays per work item of the parallel ray loop. */
#define SJ_RAY_BLOCK 256

/* Dimensions of one ray's sample vector: the pairs the stratified sampler
 * jitters together (0-1, 2-3) are the point and the direction. */
enum {
    DIM_POINT = 0,     /* 0, 1: uniform point on the source element */
    DIM_DIRECTION = 2, /* 2, 3: cosine-distributed direction */
    DIM_SOURCE = 4     /* which element shoots (inverse CDF over power) */
};

typedef struct sj_state {
    const rp_scene *scene;
    size_t n, nb, nv;
    size_t K;                  /* replicas (--batches) */
    size_t M;                  /* rays per replica per iteration */
    int threads;
    unsigned want;

    rp_mesh *mesh;
    rp_raycast *rc;
    const rp_element *el;
    const rp_vec3 *verts;
    double *area;              /* n */
    double *split;             /* n: area fraction of triangle (v0, v1, v2) of a quad */
    double *rho;               /* n x nb */
    double *phi;               /* n x nb: emitted power pi Le A */
    double phi_total;          /* sum over elements and bands */

    /* Per replica k, arrays of n x nb at offset k n nb. */
    double *P;                 /* current power: running sum (incremental), iterate (regular) */
    double *dP;                /* unshot power (incremental); the sum of the
                                  iterates once regular (the unshot power is
                                  no longer needed then) */
    double *acc;               /* this iteration's received power */
    double *cdf;               /* per replica n + 1: cumulative source weight */
    double *shot;              /* per replica: total source weight this iteration */
    uint32_t *src, *hit;       /* per ray of an iteration (K M): RP_NONE for none */
    const rp_comm *comm;       /* ranks the rays are split over (NULL: alone) */
    double *xchg;              /* split: 2 K M, the records being summed */

    rp_sampler sampler;
    double unshot_eps;
    unsigned long regular_target;  /* ULONG_MAX: none (open-ended) */
    unsigned long max_iterations;  /* ULONG_MAX: none */
    unsigned long iterations, regular_done;
    int regular;               /* in the regular phase */
    double unshot;             /* after the last incremental iteration */
    double bytes;

    rp_recon_params recon;
} sj_state;

static const rp_option_spec sj_options[] = {
    {"elements", "N",
     "target element count for the whole scene: one per face black in every band, the rest spread over the "
     "faces that reflect or emit (exclusive with --max-edge)",
     "the faces + 1000"},
    {"max-edge", "L", "target longest element edge in scene units (exclusive with --elements)", NULL},
    RP_RAD_MESH_MODE_OPTIONS,
    {"rays", "N", "rays per iteration, all batches together (rounded down to a multiple of --batches)",
     "100000"},
    {"batches", "K",
     "independent replicas the rays are split into; the answer is their mean, its standard error "
     "their spread (K >= 2)",
     "16"},
    {"unshot", "EPS",
     "shoot unshot power (incremental iterations) until it is below EPS times the emitted power; "
     "1: regular iterations from P = emission (their average then keeps the start-up transient)",
     "1e-3"},
    {"regular", "N",
     "regular iterations (shooting the total power) averaged after that; 0: stop at the unshot rule",
     "10"},
    {"iterations", "N", "stop after N iterations in all (both phases)", NULL},
    {"sampler", "random|stratified|sobol",
     "ray parameters: independent, jittered pairs, or Owen-scrambled Sobol' (per replica and iteration)",
     "random"},
    {"reconstruct", "flat|gouraud|gather",
     "image: element value, vertex-interpolated values, or a one-bounce final gather", "flat"},
    {"spp", "N", "image: camera rays per pixel (stratified, box filter)", "16"},
    {"gather-rays", "N", "image with --reconstruct gather: cosine-distributed rays per camera ray", "16"},
    RP_RAY_OFFSET_OPTION,
    {NULL, NULL, NULL, NULL}
};

static void sj_fini(void *state)
{
    sj_state *s = state;
    rp_recon_view_fini(&s->recon.view);
    rp_raycast_destroy(s->rc);
    rp_mesh_destroy(s->mesh);
    free(s->area);
    free(s->split);
    free(s->rho);
    free(s->phi);
    free(s->P);
    free(s->dP);
    free(s->acc);
    free(s->cdf);
    free(s->shot);
    free(s->src);
    free(s->hit);
    free(s->xchg);
    memset(s, 0, sizeof *s);
}

static double tri_area(rp_vec3 a, rp_vec3 b, rp_vec3 c)
{
    return 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
}

static rp_status sj_parse(sj_state *s, const rp_options *o, rp_mesh_params *mp, unsigned long *rays,
                          rp_error *err)
{
    rp_status st;
    const char *v;
    if ((st = rp_rad_mesh_params("stochastic-jacobi", o, mp, err)) != RP_OK)
        return st;

    unsigned long K = 0; /* defaults: the option specs' fallbacks (rp_options_uint) */
    *rays = 0;
    if ((st = rp_options_uint(o, "rays", 1, (unsigned long)UINT32_MAX, rays, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "batches", 2, 65536, &K, err)) != RP_OK)
        return st;
    if (*rays < K)
        return rp_error_set(err, RP_ERR_INPUT,
                            "stochastic-jacobi: --rays %lu is fewer than --batches %lu (each replica needs rays)",
                            *rays, K);
    s->K = K;
    s->M = *rays / K;

    int open_ended = o ? o->open_ended : 0;
    if ((st = rp_options_double(o, "unshot", 0, 1, &s->unshot_eps, err)) != RP_OK)
        return st;
    unsigned long regular = 0;
    if ((st = rp_options_uint(o, "regular", 0, ULONG_MAX - 1, &regular, err)) != RP_OK)
        return st;
    /* Under the harness's own budget a rule stops the run only when its
     * option was given (solver.h, rp_options.open_ended). */
    s->regular_target = open_ended && !rp_options_get(o, "regular") ? ULONG_MAX : regular;
    s->max_iterations = ULONG_MAX;
    if ((st = rp_options_uint(o, "iterations", 1, ULONG_MAX - 1, &s->max_iterations, err)) != RP_OK)
        return st;
    if (!open_ended && s->regular_target == 0 && s->unshot_eps == 0 && s->max_iterations == ULONG_MAX)
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: --unshot 0 with --regular 0 never stops; "
                            "give --iterations");

    rp_sampler_kind kind = RP_SAMPLER_RANDOM;
    if ((v = rp_options_word(o, "sampler")) && (st = rp_sampler_parse(v, &kind, err)) != RP_OK)
        return st;
    /* Stratified: one grid of strata per replica and iteration. */
    rp_sampler_init(&s->sampler, kind, o ? o->seed : 0, s->M);

    s->recon.spp = 16;
    s->recon.gather_rays = 16;
    s->recon.seed = o ? o->seed : 0;
    s->recon.threads = s->threads;
    if ((v = rp_options_word(o, "reconstruct")) && (st = rp_recon_mode_parse(v, &s->recon.mode, err)) != RP_OK)
        return st;
    unsigned long u = s->recon.spp;
    if ((st = rp_options_uint(o, "spp", 1, 1u << 20, &u, err)) != RP_OK)
        return st;
    s->recon.spp = (unsigned)u;
    u = s->recon.gather_rays;
    if ((st = rp_options_uint(o, "gather-rays", 1, 1u << 20, &u, err)) != RP_OK)
        return st;
    s->recon.gather_rays = (unsigned)u;
    return RP_OK;
}

static rp_status sj_init_local(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    sj_state *s = state;
    rp_status st;
    if ((st = rp_recon_view_init(&s->recon.view, o, scene, &scene, err)) != RP_OK)
        return st;
    s->scene = scene;
    s->nb = rp_scene_nbands(scene);
    s->want = o ? o->want : RP_WANT_IMAGE;
    if (o && o->threads < 0)
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: %d threads", o->threads);
    s->threads = o && o->threads > 0 ? o->threads : omp_get_max_threads();
    if (s->nb == 0 || s->nb > SJ_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "stochastic-jacobi: %zu bands (at most %d)", s->nb,
                            SJ_MAX_BANDS);
    if (!(s->want & (RP_WANT_IMAGE | RP_WANT_SURFACES)))
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: asked for neither an image nor surfaces");
    rp_mesh_params mp;
    unsigned long rays;
    if ((st = sj_parse(s, o, &mp, &rays, err)) != RP_OK)
        return st;
    if ((s->want & RP_WANT_IMAGE) && !rp_scene_camera(scene))
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: the scene has no camera to render from");

    if ((st = rp_mesh_create(scene, &mp, &s->mesh, err)) != RP_OK)
        return st;
    if (rp_mesh_disc_truncated(s->mesh) && o && o->log) {
        char msg[320];
        snprintf(msg, sizeof msg,
                 "warning: stochastic-jacobi: the discontinuity mesh traced its cap of %lu (wedge, receiving face) "
                 "pairs and stopped: the shadow boundaries (D1) of the remaining lights and occluders are not in "
                 "the mesh",
                 RP_DISC_MAX_PAIRS);
        o->log(o->log_ctx, msg);
    }
    s->n = rp_mesh_nelements(s->mesh);
    s->nv = rp_mesh_nvertices(s->mesh);
    if (s->n == 0)
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: the scene has no elements");
    if (s->n >= RP_NONE)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "stochastic-jacobi: %zu elements is too many", s->n);
    if ((st = rp_raycast_create(scene, s->mesh, &s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_options_ray_offset(o, s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_recon_view_rays(&s->recon.view, o, s->rc, err)) != RP_OK)
        return st;
    s->el = rp_mesh_elements(s->mesh);
    s->verts = rp_mesh_vertices(s->mesh);

    const size_t n = s->n, nb = s->nb, K = s->K, R = K * s->M;
    s->area = malloc(n * sizeof *s->area);
    s->split = malloc(n * sizeof *s->split);
    s->rho = malloc(n * nb * sizeof *s->rho);
    s->phi = malloc(n * nb * sizeof *s->phi);
    s->P = malloc(K * n * nb * sizeof *s->P);
    s->dP = malloc(K * n * nb * sizeof *s->dP);
    s->acc = malloc(K * n * nb * sizeof *s->acc);
    s->cdf = malloc(K * (n + 1) * sizeof *s->cdf);
    s->shot = calloc(K, sizeof *s->shot);
    s->src = malloc(R * sizeof *s->src);
    s->hit = malloc(R * sizeof *s->hit);
    s->comm = rp_rad_options_comm(o);
    if (rp_comm_size(s->comm) > 1)
        s->xchg = malloc(2 * R * sizeof *s->xchg);
    if (!s->area || !s->split || !s->rho || !s->phi || !s->P || !s->dP || !s->acc || !s->cdf ||
        !s->shot || !s->src || !s->hit || (rp_comm_size(s->comm) > 1 && !s->xchg))
        return rp_error_set(err, RP_ERR_NOMEM, "stochastic-jacobi: out of memory for %zu elements x %zu replicas",
                            n, K);
    s->bytes = (double)(n * (2 + 2 * nb) * sizeof(double) + K * n * nb * 3 * sizeof(double) +
                        K * (n + 2) * sizeof(double) + R * 2 * sizeof(uint32_t) +
                        (s->xchg ? 2 * R * sizeof *s->xchg : 0));

    const rp_material *mats = rp_scene_materials(scene);
    const rp_surface *surfs = rp_scene_surfaces(scene);
    s->phi_total = 0;
    for (size_t i = 0; i < n; i++) {
        const rp_element *e = &s->el[i];
        const rp_material *m = &mats[surfs[e->surface].material];
        s->area[i] = e->area;
        s->split[i] = 1;
        if (e->nverts == 4) {
            double a1 = tri_area(s->verts[e->v[0]], s->verts[e->v[1]], s->verts[e->v[2]]);
            double a2 = tri_area(s->verts[e->v[0]], s->verts[e->v[2]], s->verts[e->v[3]]);
            s->split[i] = a1 + a2 > 0 ? a1 / (a1 + a2) : 1;
        }
        for (size_t b = 0; b < nb; b++) {
            s->rho[i * nb + b] = m->rho[b];
            s->phi[i * nb + b] = RP_PI * m->Le[b] * e->area;
            s->phi_total += s->phi[i * nb + b];
        }
    }
    if (!(s->phi_total > 0))
        return rp_error_set(err, RP_ERR_INPUT, "stochastic-jacobi: the scene emits no power");
    for (size_t k = 0; k < K; k++) {
        memcpy(s->P + k * n * nb, s->phi, n * nb * sizeof *s->P);
        memcpy(s->dP + k * n * nb, s->phi, n * nb * sizeof *s->dP);
    }
    s->unshot = 1;
    /* --unshot 1: regular iterations from P = Phi at once. */
    if (s->unshot_eps >= 1 && s->regular_target > 0) {
        s->regular = 1;
        memset(s->dP, 0, K * n * nb * sizeof *s->dP);
    }
    return RP_OK;
}

/* Under a split every rank returns the lowest failing rank's status. */
static rp_status sj_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    return rp_rad_init_agree(rp_rad_options_comm(o), sj_init_local(state, scene, o, err), err);
}

/* A uniform point on element i from (u1, u2): a quad is split into the
 * triangles (v0, v1, v2) and (v0, v2, v3), chosen by area with u1 (then
 * rescaled), and a triangle sampled by the square-root map (Shirley & Chiu
 * 1997), which keeps stratification of (u1, u2). */
static rp_vec3 sj_point(const sj_state *s, uint32_t i, double u1, double u2)
{
    const rp_element *e = &s->el[i];
    rp_vec3 a = s->verts[e->v[0]], b = s->verts[e->v[1]], c = s->verts[e->v[2]];
    if (e->nverts == 4) {
        double f = s->split[i];
        if (u1 < f) {
            u1 /= f;
        } else {
            u1 = (u1 - f) / (1 - f);
            b = c;
            c = s->verts[e->v[3]];
        }
        if (u1 >= 1)
            u1 = 0x1.fffffffffffffp-1;
    }
    double r = sqrt(u1);
    return rp_v3_add(rp_v3_add(rp_v3_scale(a, 1 - r), rp_v3_scale(b, r * (1 - u2))), rp_v3_scale(c, r * u2));
}

/* One ray of replica k: its source element (RP_NONE if the replica has
 * nothing to shoot) and the element whose front it lands on (RP_NONE for
 * a miss or a back face, which absorbs). */
static void sj_ray(const sj_state *s, size_t k, uint32_t index, uint32_t *src, uint32_t *hit)
{
    const size_t n = s->n;
    const double *cdf = s->cdf + k * (n + 1);
    const double T = s->shot[k];
    *src = *hit = RP_NONE;
    if (!(T > 0))
        return;
    rp_sample_point sp;
    rp_sampler_start(&s->sampler, (uint64_t)s->iterations * s->K + k, index, &sp);
    /* Inverse CDF rather than an alias table: it maps the coordinate
     * monotonically onto the elements, so a low-discrepancy coordinate
     * stays evenly spread over the sources (an alias table folds it). */
    double x = rp_sampler_get(&sp, DIM_SOURCE) * T;
    if (x >= T)
        x = nextafter(T, 0);
    uint32_t i = (uint32_t)gsl_interp_bsearch(cdf, x, 0, n);
    rp_vec3 p = sj_point(s, i, rp_sampler_get(&sp, DIM_POINT), rp_sampler_get(&sp, DIM_POINT + 1));
    /* Cosine-distributed direction (pdf cos / pi): the ray then lands on j
     * with probability F_ij. */
    double u3 = rp_sampler_get(&sp, DIM_DIRECTION), u4 = rp_sampler_get(&sp, DIM_DIRECTION + 1);
    double r = sqrt(u3), phi = 2.0 * RP_PI * u4;
    rp_vec3 nrm = s->el[i].normal, t, bt;
    rp_v3_basis(nrm, &t, &bt);
    rp_vec3 d = rp_v3_add(rp_v3_add(rp_v3_scale(t, r * cos(phi)), rp_v3_scale(bt, r * sin(phi))),
                          rp_v3_scale(nrm, sqrt(1 - u3)));
    *src = i;
    rp_hit h;
    if (rp_ray_closest_from(s->rc, p, nrm, d, &h) && h.front && h.element != RP_NONE)
        *hit = h.element;
}

static rp_status sj_step(void *state, rp_step_info *info, rp_error *err)
{
    sj_state *s = state;
    const size_t n = s->n, nb = s->nb, K = s->K, M = s->M;
    (void)err;

    /* Source weights: the band sum of the power being shot. */
#pragma omp parallel for num_threads(s->threads) schedule(static)
    for (long k = 0; k < (long)K; k++) {
        const double *w = (s->regular ? s->P : s->dP) + (size_t)k * n * nb;
        double *cdf = s->cdf + (size_t)k * (n + 1);
        double c = 0;
        cdf[0] = 0;
        for (size_t i = 0; i < n; i++) {
            double wi = 0;
            for (size_t b = 0; b < nb; b++)
                wi += w[i * nb + b];
            c += wi;
            cdf[i + 1] = c;
        }
        s->shot[k] = c;
    }

    const size_t R = K * M;
    const long nblocks = (long)((R + SJ_RAY_BLOCK - 1) / SJ_RAY_BLOCK);
    unsigned long long traced = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 4) reduction(+ : traced)
    for (long blk = 0; blk < nblocks; blk++) {
        size_t r0 = (size_t)blk * SJ_RAY_BLOCK, r1 = r0 + SJ_RAY_BLOCK < R ? r0 + SJ_RAY_BLOCK : R;
        if (!rp_comm_owns(s->comm, (size_t)blk)) {
            for (size_t r = r0; r < r1; r++)
                s->src[r] = s->hit[r] = 0; /* another rank's: 0 in the sum */
            continue;
        }
        for (size_t r = r0; r < r1; r++)
            sj_ray(s, r / M, (uint32_t)(r % M), &s->src[r], &s->hit[r]);
        traced += r1 - r0;
    }
    if (s->xchg) {
        /* element indices and RP_NONE are exact in a double */
        for (size_t r = 0; r < R; r++) {
            s->xchg[2 * r] = s->src[r];
            s->xchg[2 * r + 1] = s->hit[r];
        }
        rp_comm_sum(s->comm, s->xchg, 2 * R);
        for (size_t r = 0; r < R; r++) {
            s->src[r] = (uint32_t)s->xchg[2 * r];
            s->hit[r] = (uint32_t)s->xchg[2 * r + 1];
        }
    }

    /* Contributions in ray order within each replica: a ray from i landing
     * on j brings rho_j P_i / (M p_i), p_i = w_i / T. */
#pragma omp parallel for num_threads(s->threads) schedule(static)
    for (long k = 0; k < (long)K; k++) {
        const size_t off = (size_t)k * n * nb;
        const double *w = (s->regular ? s->P : s->dP) + off;
        const double *cdf = s->cdf + (size_t)k * (n + 1);
        double *acc = s->acc + off;
        memset(acc, 0, n * nb * sizeof *acc);
        const double T = s->shot[k];
        for (size_t r = (size_t)k * M; r < (size_t)(k + 1) * M; r++) {
            uint32_t i = s->src[r], j = s->hit[r];
            if (i == RP_NONE || j == RP_NONE)
                continue;
            /* p_i from the length of i's interval of the CDF, not from
             * w_i: that is the probability with which i is picked, to the
             * last bit (an element whose weight is lost in the rounding
             * of the running sum is never picked, and shoots nothing). */
            double scale = T / ((cdf[i + 1] - cdf[i]) * (double)M);
            for (size_t b = 0; b < nb; b++)
                acc[j * nb + b] += s->rho[j * nb + b] * (w[i * nb + b] * scale);
        }
        double *P = s->P + off;
        if (s->regular) {
            double *sum = s->dP + off;
            for (size_t q = 0; q < n * nb; q++) {
                P[q] = s->phi[q] + acc[q];
                sum[q] += P[q];
            }
        } else {
            double *dP = s->dP + off;
            for (size_t q = 0; q < n * nb; q++) {
                P[q] += acc[q];
                dP[q] = acc[q];
            }
        }
    }

    s->iterations++;
    info->rays += (double)traced; /* this rank's: the driver sums the ranks */
    info->iterations += 1;
    info->memory = s->bytes;
    double p;
    if (s->regular) {
        s->regular_done++;
        info->unshot = -1;
        p = s->regular_target == ULONG_MAX ? 0.5
                                           : 0.5 + 0.5 * (double)s->regular_done / (double)s->regular_target;
    } else {
        double u = 0;
        for (size_t q = 0; q < K * n * nb; q++)
            u += s->dP[q];
        s->unshot = u / ((double)K * s->phi_total);
        info->unshot = s->unshot;
        if (s->unshot <= s->unshot_eps)
            p = 1;
        else
            p = s->unshot_eps > 0 ? log(s->unshot) / log(s->unshot_eps) : 0;
        if (s->regular_target > 0)
            p *= 0.5;
        if (s->unshot <= s->unshot_eps && s->regular_target > 0) {
            s->regular = 1; /* the next step starts the regular phase */
            memset(s->dP, 0, K * n * nb * sizeof *s->dP);
        }
    }
    int done = (!s->regular && s->regular_target == 0 && s->unshot <= s->unshot_eps) ||
               (s->regular && s->regular_target != ULONG_MAX && s->regular_done >= s->regular_target);
    if (s->max_iterations != ULONG_MAX) {
        double pi = (double)s->iterations / (double)s->max_iterations;
        if (pi > p)
            p = pi;
        if (s->iterations >= s->max_iterations)
            done = 1;
    }
    info->progress = p < 0 ? 0 : (p > 1 ? 1 : p);
    info->converged = done;
    return RP_OK;
}

/* Replica k's radiosity solution (n x nb) into B: the average of its
 * regular iterates, or its incremental sum before any. */
static void sj_replica_B(const sj_state *s, size_t k, double *B)
{
    const size_t n = s->n, nb = s->nb, off = k * n * nb;
    const double *src = s->regular_done ? s->dP + off : s->P + off;
    double scale = s->regular_done ? 1.0 / (double)s->regular_done : 1.0;
    for (size_t i = 0; i < n; i++)
        for (size_t b = 0; b < nb; b++)
            B[i * nb + b] = src[i * nb + b] * scale / s->area[i];
}

/* Welford's running mean and sum of squared deviations, after sample k
 * (from 0) of x. */
static void welford(double *mean, double *m2, const double *x, size_t m, size_t k)
{
    for (size_t q = 0; q < m; q++) {
        double d = x[q] - mean[q];
        mean[q] += d / (double)(k + 1);
        m2[q] += d * (x[q] - mean[q]);
    }
}

static rp_status sj_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const sj_state *s = state;
    const size_t n = s->n, nb = s->nb, K = s->K, ns = rp_scene_nsurfaces(s->scene);
    e->samples = (double)s->iterations;
    if ((e->surface_radiance || e->surface_stderr) && !(s->want & RP_WANT_SURFACES))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "stochastic-jacobi: no surface averages were asked for at init");
    if ((e->radiance || e->variance) && !(s->want & RP_WANT_IMAGE))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "stochastic-jacobi: no image was asked for at init");

    double *Bk = malloc(n * nb * sizeof *Bk);
    double *B = calloc(n * nb, sizeof *B);
    double *Sk = malloc((ns ? ns : 1) * nb * sizeof *Sk);
    double *Smean = calloc((ns ? ns : 1) * nb, sizeof *Smean);
    double *Sm2 = calloc((ns ? ns : 1) * nb, sizeof *Sm2);
    if (!Bk || !B || !Sk || !Smean || !Sm2) {
        free(Bk), free(B), free(Sk), free(Smean), free(Sm2);
        return rp_error_set(err, RP_ERR_NOMEM, "stochastic-jacobi: out of memory");
    }
    /* Surface averages per replica, then their mean and standard error
     * (covariances between a surface's elements included), accumulated
     * with Welford's update: no cancellation when the spread is tiny
     * beside the mean (the furnace's total is exact). */
    for (size_t k = 0; k < K; k++) {
        sj_replica_B(s, k, Bk);
        for (size_t q = 0; q < n * nb; q++)
            B[q] += Bk[q];
        rp_recon_surfaces(s->scene, s->mesh, nb, Bk, Sk);
        welford(Smean, Sm2, Sk, ns * nb, k);
    }
    for (size_t q = 0; q < n * nb; q++)
        B[q] /= (double)K;
    for (size_t q = 0; q < ns * nb; q++) {
        if (e->surface_radiance)
            e->surface_radiance[q] = Smean[q];
        if (e->surface_stderr)
            e->surface_stderr[q] = sqrt(Sm2[q] / (double)(K - 1) / (double)K);
    }
    free(Sk), free(Smean), free(Sm2);

    rp_status st = RP_OK;
    if (e->radiance || e->variance) {
        const rp_camera *cam = rp_scene_camera(s->scene);
        size_t npix = (size_t)cam->width * cam->height, m = npix * nb;
        float *img = e->radiance ? e->radiance : malloc(m * sizeof *img);
        float *tmp = e->variance ? malloc(m * sizeof *tmp) : NULL;
        double *x = e->variance ? malloc(m * sizeof *x) : NULL;
        double *mean = e->variance ? calloc(m, sizeof *mean) : NULL;
        double *sq = e->variance ? calloc(m, sizeof *sq) : NULL;
        if (!img || (e->variance && (!tmp || !x || !mean || !sq)))
            st = rp_error_set(err, RP_ERR_NOMEM, "stochastic-jacobi: out of memory for the image");
        if (st == RP_OK)
            st = rp_recon_image(s->scene, s->mesh, s->rc, &s->recon, nb, B, img, e->variance, NULL, err);
        /* The image is linear in B, so the radiosity noise in a pixel is
         * the spread of the replicas' images over sqrt(K); every replica
         * image uses the same camera rays (same seed), so only B differs.
         * The camera-sampling variance from the mean image adds to it. */
        for (size_t k = 0; st == RP_OK && e->variance && k < K; k++) {
            sj_replica_B(s, k, Bk);
            st = rp_recon_image(s->scene, s->mesh, s->rc, &s->recon, nb, Bk, tmp, NULL, NULL, err);
            if (st != RP_OK)
                break;
            for (size_t q = 0; q < m; q++)
                x[q] = tmp[q];
            welford(mean, sq, x, m, k);
        }
        if (st == RP_OK && e->variance)
            for (size_t q = 0; q < m; q++)
                e->variance[q] += (float)(sq[q] / (double)(K - 1) / (double)K);
        if (!e->radiance)
            free(img);
        free(tmp);
        free(x);
        free(mean);
        free(sq);
    }
    free(Bk);
    free(B);
    return st;
}

const rp_solver_type rp_solver_stochastic_jacobi = {
    .name = "stochastic-jacobi",
    .summary = "Monte Carlo radiosity: stochastic Jacobi power shooting along random lines "
               "(incremental, then averaged regular iterations), standard errors from replicas",
    .options = sj_options,
    .state_size = sizeof(sj_state),
    .init = sj_init,
    .step = sj_step,
    .estimate = sj_estimate,
    .fini = sj_fini,
    .monte_carlo = 1,
    .distributed = 1,
};
