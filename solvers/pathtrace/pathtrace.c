/* Unidirectional path tracing of diffuse scenes, registered as "pathtrace".
 *
 * Estimates L(x, w) = Le(x) + rho(x)/pi * int L_i cos(theta) dw_i (Kajiya
 * 1986) by random walks: at each vertex, next-event estimation (one point
 * sampled on the emitters by power, area measure) and a cosine-weighted
 * continuation, combined by multiple importance sampling with the power
 * heuristic (Veach & Guibas 1995; Veach's thesis 1997, sec. 9.2).  Surfaces
 * are one-sided Lambertian: a path that reaches the back of a face ends
 * there with nothing, for emission and reflection alike.
 *
 * Two questions can be asked (solver.h): the camera image, one sample per
 * pixel per step, and the area-averaged outgoing radiance of every surface,
 * a batch of uniformly placed probe points per step.  Both use the same
 * path kernel.  Every random number is a pure function of (seed, pixel or
 * surface, sample index, dimension) (sampler.h) and every sum is formed in
 * a fixed order, so output is bit-identical for any thread count. */
#include <float.h>
#include <limits.h>
#include <math.h>
#include <omp.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "../../geometry/log.h"
#include "../../geometry/raycast.h"
#include "../../geometry/sample.h"
#include "../solver.h"
#include "sampler.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* Small per-path band arrays live on the stack. */
#define PT_MAX_BANDS 256
/* Russian roulette (Arvo & Kirk 1990) from bounce PT_RR_DEPTH on, with
 * survival q = min(0.95, max_b T_b / w): a weight window, in which paths
 * whose throughput T fell below w survive with probability T / w and carry
 * w onwards (the plain rule is w = 1).  Measured at equal CPU time: on the
 * Cornell box (64 x 64, 64 spp) w = 0.25 is as efficient as w = 1 (within
 * the 10% timing noise); in the furnace (rho 0.5) it is 5 times as
 * efficient, and its survivors are lighter, so per-pixel variance
 * estimates from few samples are less skewed (furnace, 96 spp: 3.0% of
 * pixels more than 3 estimated standard errors off with w = 1, 0.47% with
 * w = 0.25, 0.27% for a normal variate). */
#define PT_RR_DEPTH 3
#define PT_RR_WEIGHT 0.25
#define PT_RR_MAX 0.95
#define PT_TILE 16
/* Probe samples per work item: partial sums are kept per chunk and added
 * in chunk order, so the sum does not depend on the schedule. */
#define PT_CHUNK 64
#define PT_UNLIMITED UINT_MAX

/* Dimensions of a path's sample vector.  Pairs that are sampled together
 * start at even dimensions (the stratified sampler stratifies pairs). */
enum {
    DIM_PIXEL = 0,       /* 0, 1: pixel jitter, or the point on a probed face */
    DIM_PROBE_FACE = 2,  /* which face of the probed surface */
    DIM_VERTEX = 4,      /* first vertex's block */
    DIM_PER_VERTEX = 6,
    /* offsets within a vertex's block */
    DIM_LIGHT_POINT = 0, /* 0, 1: point on the chosen emitter face */
    DIM_BSDF = 2,        /* 2, 3: cosine-weighted direction */
    DIM_LIGHT_FACE = 4,  /* emitter face choice */
    DIM_RR = 5           /* Russian roulette */
};

typedef struct pt_state {
    const rp_scene *scene;
    size_t nbands, nfaces, nsurfaces;
    unsigned want;
    int threads;
    /* Ranks the work is split over (NULL: alone): image tiles and probe
     * chunks by global index, so each pixel's and chunk's sums are made
     * by one rank in the same order as alone, and summing the ranks'
     * arrays (where the others hold 0) is exact: the answer is
     * bit-identical for any rank and thread count. */
    const rp_comm *comm;
    unsigned long spp, samples, batch;
    double target_error; /* --target-error: 0 off */
    /* Under an open-ended harness budget, spp and samples stop the run
     * only when given explicitly (solver.h, rp_options.open_ended). */
    int spp_rule, samples_rule;
    unsigned max_depth, rr_depth;
    double rr_weight;

    rp_raycast *rc;
    rp_area_sampler *lights;     /* NULL when nothing emits */
    int many_lights;             /* more than one emitting face to choose from */
    rp_area_sampler **probes;    /* per surface, NULL when not wanted */
    const rp_material *mats;
    uint32_t *face_mat;
    double *light_pdf;           /* per face: the NEE area density, 0 if not an emitter */
    unsigned char *mat_reflects; /* some band of rho > 0 */

    rp_sampler image_sampler, probe_sampler;

    /* Pinhole camera. */
    rp_vec3 eye, forward, right, up;
    double tan_half, aspect;
    uint32_t width, height;

    /* Image: per pixel and band, sum and sum of squares of the samples
     * minus a shift (the pixel's first sample), which keeps the variance
     * free of cancellation and exactly 0 where every sample is the same. */
    double *sum, *sumsq, *shift;
    unsigned long passes;

    /* Surfaces: per surface and band, the same with the surface's Le as
     * the shift (the deterministic part), plus chunk partial sums. */
    double *ssum, *ssumsq, *partial;
    unsigned long probe_done;
} pt_state;

static const rp_option_spec pt_options[] = {
    {"spp", "N",
     "samples per pixel (one per step) after which a render has converged; under a time "
     "budget only when given",
     "16"},
    {"samples", "N",
     "probe points per surface after which surface averages have converged; under a time "
     "budget only when given",
     "4096"},
    {"batch", "N", "probe points per surface added by each step", "1024"},
    {"target-error", "REL",
     "surface averages have converged once every surface's standard error is at most REL times its "
     "average in every band (checked after each batch; --samples stays the cap; 0: off)",
     "0"},
    {"sampler", "random|stratified|sobol",
     "random: hashed uniform numbers; stratified: jittered grid per pair of dimensions; "
     "sobol: Owen-scrambled Sobol' (22 dimensions, random beyond)",
     "sobol"},
    {"max-depth", "D",
     "reflections a path may carry to the eye: 0 emission only, 1 direct lighting, "
     "'unlimited' ends paths by Russian roulette only",
     "unlimited"},
    {"rr-depth", "N", "bounces before Russian roulette starts", "3"},
    {"rr-weight", "W",
     "Russian roulette survival min(0.95, max band throughput / W), in (0, 1]; 1 is the plain rule", "0.25"},
    RP_RAY_OFFSET_OPTION,
    {NULL, NULL, NULL, NULL}
};

static void pt_fini(void *state)
{
    pt_state *s = state;
    rp_raycast_destroy(s->rc);
    rp_area_sampler_destroy(s->lights);
    if (s->probes)
        for (size_t i = 0; i < s->nsurfaces; i++)
            rp_area_sampler_destroy(s->probes[i]);
    free(s->probes);
    free(s->face_mat);
    free(s->light_pdf);
    free(s->mat_reflects);
    free(s->sum);
    free(s->sumsq);
    free(s->shift);
    free(s->ssum);
    free(s->ssumsq);
    free(s->partial);
    memset(s, 0, sizeof *s);
}

static rp_status pt_camera(pt_state *s, const rp_camera *cam, rp_error *err)
{
    rp_vec3 f = rp_v3_sub(cam->look, cam->eye);
    if (!(rp_v3_length(f) > 0))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: camera eye and look coincide");
    f = rp_v3_normalize(f);
    rp_vec3 r = rp_v3_cross(f, cam->up);
    double rl = rp_v3_length(r);
    if (!(rl > 1e-12 * rp_v3_length(cam->up)))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: camera up is parallel to the view direction");
    if (!(cam->fov_deg > 0 && cam->fov_deg < 180))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: camera fov %g is outside (0, 180)", cam->fov_deg);
    if (cam->width == 0 || cam->height == 0)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: camera image is empty");
    s->eye = cam->eye;
    s->forward = f;
    s->right = rp_v3_scale(r, 1.0 / rl);
    s->up = rp_v3_cross(s->right, f);
    s->tan_half = tan(0.5 * cam->fov_deg * M_PI / 180.0);
    s->width = cam->width;
    s->height = cam->height;
    s->aspect = (double)cam->width / (double)cam->height;
    return RP_OK;
}

static rp_status pt_parse_options(pt_state *s, const rp_options *o, rp_sampler_kind *kind, rp_error *err)
{
    rp_status st;
    /* defaults: the option specs' fallbacks (rp_options_uint and
     * rp_options_word read them) */
    s->max_depth = PT_UNLIMITED;
    unsigned long rr = PT_RR_DEPTH;
    if ((st = rp_options_uint(o, "spp", 1, UINT32_MAX, &s->spp, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "samples", 1, UINT32_MAX, &s->samples, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "batch", 1, UINT32_MAX, &s->batch, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "rr-depth", 1, 1000000, &rr, err)) != RP_OK)
        return st;
    s->rr_depth = (unsigned)rr;
    if ((st = rp_options_double(o, "target-error", 0.0, 1.0, &s->target_error, err)) != RP_OK)
        return st;
    if (s->target_error > 0 && !(s->want & RP_WANT_SURFACES) && o)
        rp_logf(o->log, o->log_ctx, "warning: pathtrace: --target-error %g ignored: it applies to surface averages "
                "(probe) only", s->target_error);
    s->rr_weight = PT_RR_WEIGHT;
    if ((st = rp_options_double(o, "rr-weight", 1e-6, 1.0, &s->rr_weight, err)) != RP_OK)
        return st;
    int open_ended = o && o->size >= offsetof(rp_options, open_ended) + sizeof o->open_ended
                     ? o->open_ended : 0;
    s->spp_rule = !open_ended || rp_options_get(o, "spp");
    s->samples_rule = !open_ended || rp_options_get(o, "samples");
    const char *v = rp_options_word(o, "sampler"); /* default: the spec's */
    if (v && (st = rp_sampler_parse(v, kind, err)) != RP_OK)
        return st;
    v = rp_options_get(o, "max-depth");
    if (v && strcmp(v, "unlimited") != 0) {
        unsigned long d = 0;
        if ((st = rp_options_uint(o, "max-depth", 0, 1000000, &d, err)) != RP_OK)
            return st;
        s->max_depth = (unsigned)d;
    }
    return RP_OK;
}

static rp_status pt_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    pt_state *s = state;
    rp_status st;
    s->scene = scene;
    s->nbands = rp_scene_nbands(scene);
    s->nfaces = rp_scene_nfaces(scene);
    s->nsurfaces = rp_scene_nsurfaces(scene);
    s->want = o ? o->want : RP_WANT_IMAGE;
    s->threads = o ? o->threads : 0;
    s->comm = o ? o->comm : NULL;
    uint64_t seed = o ? o->seed : 0;
    if (s->nbands == 0 || s->nbands > PT_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "pathtrace: %zu bands (at most %d)",
                            s->nbands, PT_MAX_BANDS);
    if (s->threads < 0)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: %d threads", s->threads);
    if (!(s->want & (RP_WANT_IMAGE | RP_WANT_SURFACES)))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: asked for neither an image nor surfaces");
    rp_sampler_kind kind;
    if ((st = pt_parse_options(s, o, &kind, err)) != RP_OK)
        return st;
    if (s->want & RP_WANT_IMAGE) {
        const rp_camera *cam = rp_scene_camera(scene);
        if (!cam)
            return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the scene has no camera to render from");
        if ((st = pt_camera(s, cam, err)) != RP_OK)
            return st;
    }

    if ((st = rp_raycast_create(scene, NULL, &s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_options_ray_offset(o, s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_area_sampler_create(scene, RP_NONE, RP_WEIGHT_POWER, &s->lights, err)) != RP_OK)
        return st;
    if (rp_area_sampler_count(s->lights) == 0) {
        rp_area_sampler_destroy(s->lights);
        s->lights = NULL;
    }
    s->many_lights = s->lights && rp_area_sampler_count(s->lights) > 1;

    s->mats = rp_scene_materials(scene);
    size_t nmat = rp_scene_nmaterials(scene);
    const rp_face *faces = rp_scene_faces(scene);
    const rp_surface *surfs = rp_scene_surfaces(scene);
    s->face_mat = malloc((s->nfaces ? s->nfaces : 1) * sizeof *s->face_mat);
    s->light_pdf = calloc(s->nfaces ? s->nfaces : 1, sizeof *s->light_pdf);
    s->mat_reflects = calloc(nmat ? nmat : 1, 1);
    if (!s->face_mat || !s->light_pdf || !s->mat_reflects)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    for (size_t m = 0; m < nmat; m++)
        for (size_t b = 0; b < s->nbands; b++)
            if (s->mats[m].rho[b] > 0)
                s->mat_reflects[m] = 1;
    for (size_t f = 0; f < s->nfaces; f++) {
        uint32_t m = surfs[faces[f].surface].material;
        s->face_mat[f] = m;
        if (s->lights && s->mats[m].emitter)
            s->light_pdf[f] = rp_area_sampler_pdf(s->lights, (uint32_t)f);
    }

    if (s->want & RP_WANT_IMAGE) {
        size_t n = (size_t)s->width * s->height * s->nbands;
        s->sum = calloc(n, sizeof *s->sum);
        s->sumsq = calloc(n, sizeof *s->sumsq);
        s->shift = calloc(n, sizeof *s->shift);
        if (!s->sum || !s->sumsq || !s->shift)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory (image of %ux%u)", s->width, s->height);
        rp_sampler_init(&s->image_sampler, kind, seed, s->spp);
    }
    if (s->want & RP_WANT_SURFACES) {
        size_t n = s->nsurfaces * s->nbands;
        s->probes = calloc(s->nsurfaces ? s->nsurfaces : 1, sizeof *s->probes);
        s->ssum = calloc(n ? n : 1, sizeof *s->ssum);
        s->ssumsq = calloc(n ? n : 1, sizeof *s->ssumsq);
        if (!s->probes || !s->ssum || !s->ssumsq)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        for (size_t i = 0; i < s->nsurfaces; i++)
            if ((st = rp_area_sampler_create(scene, (uint32_t)i, RP_WEIGHT_AREA, &s->probes[i], err)) != RP_OK)
                return st;
        /* A different seed stream from the image's (streams are keyed by
         * surface number, which would collide with pixel numbers). */
        rp_sampler_init(&s->probe_sampler, kind, rp_hash64(seed ^ UINT64_C(0x5eed0f5a11ce5)), s->samples);
    }
    return RP_OK;
}

/* cos and sin of 2 pi u for u in [0, 1), inline (the libm call was 1% of
 * the path tracer's instructions): u picks a quadrant and an angle x in
 * [-pi/4, pi/4) around its middle, where Taylor series to x^11 (sin) and
 * x^12 (cos) are within 1e-11; then the rotation by pi/4 and by the
 * quadrant is exact up to rounding. */
static inline void pt_cos_sin_2pi(double u, double *c, double *s)
{
    double q4 = 4.0 * u;
    int q = (int)q4;
    q = q < 0 ? 0 : (q > 3 ? 3 : q);
    double x = (q4 - q - 0.5) * (0.5 * M_PI), x2 = x * x;
    double sx = x * (1 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 +
                                                                                     x2 * (-1.0 / 39916800))))));
    double cx = 1 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 +
                                                                          x2 * (-1.0 / 3628800 +
                                                                                x2 * (1.0 / 479001600))))));
    const double h = 0.70710678118654752440; /* cos(pi/4) = sin(pi/4) */
    double c0 = h * (cx - sx), s0 = h * (sx + cx);  /* angle pi/4 + x */
    switch (q) {
    case 0: *c = c0; *s = s0; break;
    case 1: *c = -s0; *s = c0; break;
    case 2: *c = -c0; *s = -s0; break;
    default: *c = s0; *s = -c0; break;
    }
}

/* One path's estimate of the radiance leaving vertex hit towards where the
 * path came from (the eye, or nowhere for a probe point: then the outgoing
 * radiance of a Lambertian point).  hit is the first vertex, already found;
 * L (nbands) receives the estimate; *rays counts the rays cast.
 *
 * Vertex k = 0, 1, ... carries light reflected k times at its emission and
 * k + 1 times through its next-event estimate, so with max_depth D the walk
 * stops after vertex D's emission: D = 1 is emission plus direct lighting. */
static inline __attribute__((always_inline)) void
pt_path_n(const pt_state *s, const rp_sample_point *sp, const rp_hit *first, rp_vec3 dir, double *L,
          unsigned long long *rays, const size_t nb)
{
    rp_hit buf[2];
    buf[0] = *first;
    const rp_hit *hit = &buf[0];
    double T[PT_MAX_BANDS];
    for (size_t b = 0; b < nb; b++) {
        T[b] = 1.0;
        L[b] = 0.0;
    }
    double pdf_bsdf_prev = 0; /* solid-angle density of the direction that found hit */
    for (unsigned depth = 0;; depth++) {
        if (!hit->front)
            break; /* the back of a face is black */
        const rp_material *mat = &s->mats[s->face_mat[hit->face]];
        if (mat->emitter) {
            double w = 1.0;
            double pl_area = s->light_pdf[hit->face];
            if (depth > 0 && pl_area > 0) {
                /* The density NEE would have had for this point, in solid
                 * angle at the previous vertex: pdf_A d^2 / cos_light. */
                double cos_l = -rp_v3_dot(dir, hit->n);
                double pl = pl_area * hit->t * hit->t / cos_l;
                double pb2 = pdf_bsdf_prev * pdf_bsdf_prev;
                w = pb2 / (pb2 + pl * pl);
            }
            for (size_t b = 0; b < nb; b++)
                L[b] += T[b] * w * mat->Le[b];
        }
        if (depth >= s->max_depth || !s->mat_reflects[s->face_mat[hit->face]])
            break;
        const double *rho = mat->rho;
        unsigned base = DIM_VERTEX + DIM_PER_VERTEX * depth;

        /* Next-event estimation: rho/pi Le cos_x cos_y / d^2 / pdf_A. */
        if (s->lights) {
            rp_area_sample ls;
            double u0 = s->many_lights ? rp_sampler_get(sp, base + DIM_LIGHT_FACE) : 0.5;
            rp_area_sampler_sample(s->lights, u0,
                                   rp_sampler_get(sp, base + DIM_LIGHT_POINT),
                                   rp_sampler_get(sp, base + DIM_LIGHT_POINT + 1), &ls);
            rp_vec3 dv = rp_v3_sub(ls.p, hit->p);
            double d2 = rp_v3_dot(dv, dv);
            if (d2 > 0) {
                double d = sqrt(d2);
                rp_vec3 wi = rp_v3_scale(dv, 1.0 / d);
                double cos_x = rp_v3_dot(hit->n, wi), cos_y = -rp_v3_dot(ls.n, wi);
                if (cos_x > 0 && cos_y > 0) {
                    (*rays)++;
                    if (!rp_ray_occluded(s->rc, hit->p, hit->n, ls.p, ls.n)) {
                        double pl = ls.pdf_area * d2 / cos_y;
                        double pb = cos_x / M_PI;
                        double w = pl * pl / (pl * pl + pb * pb);
                        double f = w * cos_x / (M_PI * pl);
                        const double *Le = s->mats[s->face_mat[ls.face]].Le;
                        for (size_t b = 0; b < nb; b++)
                            L[b] += T[b] * rho[b] * Le[b] * f;
                    }
                }
            }
        }

        /* Continue by cosine-weighted sampling (Malley's method): the
         * weight f cos / pdf is rho. */
        double u1 = rp_sampler_get(sp, base + DIM_BSDF), u2 = rp_sampler_get(sp, base + DIM_BSDF + 1);
        double r = sqrt(u1), cos_t = sqrt(1.0 - u1);
        double cphi, sphi;
        pt_cos_sin_2pi(u2, &cphi, &sphi);
        rp_vec3 t, bt;
        rp_v3_basis(hit->n, &t, &bt);
        rp_vec3 wi = rp_v3_madd(rp_v3_madd(rp_v3_scale(hit->n, cos_t), t, r * cphi), bt, r * sphi);
        double tmax = 0;
        for (size_t b = 0; b < nb; b++) {
            T[b] *= rho[b];
            if (T[b] > tmax)
                tmax = T[b];
        }
        if (!(cos_t > 0) || !(tmax > 0))
            break;
        if (depth + 1 >= s->rr_depth) {
            double q = tmax / s->rr_weight;
            q = q < PT_RR_MAX ? q : PT_RR_MAX;
            if (rp_sampler_get(sp, base + DIM_RR) >= q)
                break;
            for (size_t b = 0; b < nb; b++)
                T[b] /= q;
        }
        pdf_bsdf_prev = cos_t / M_PI;
        (*rays)++;
        rp_hit *next = hit == &buf[0] ? &buf[1] : &buf[0];
        if (!rp_ray_closest_from(s->rc, hit->p, hit->n, wi, next))
            break;
        hit = next;
        dir = wi;
    }
}

/* pt_path_n compiled for grey and rgb with the band count a constant, so
 * the per-band loops unroll (about 10% of the path tracer's instructions on
 * the Cornell box, measured with callgrind). */
static void pt_path(const pt_state *s, const rp_sample_point *sp, const rp_hit *first, rp_vec3 dir,
                    double *L, unsigned long long *rays)
{
    switch (s->nbands) {
    case 1: pt_path_n(s, sp, first, dir, L, rays, 1); break;
    case 3: pt_path_n(s, sp, first, dir, L, rays, 3); break;
    default: pt_path_n(s, sp, first, dir, L, rays, s->nbands); break;
    }
}

static inline int pt_nthreads(const pt_state *s)
{
    return s->threads > 0 ? s->threads : omp_get_max_threads();
}

/* One sample per pixel over the whole image. */
static void pt_image_pass(pt_state *s, rp_step_info *info)
{
    const uint32_t W = s->width, H = s->height;
    const size_t nb = s->nbands;
    const uint32_t tx = (W + PT_TILE - 1) / PT_TILE, ty = (H + PT_TILE - 1) / PT_TILE;
    const long ntiles = (long)tx * ty;
    const uint32_t index = (uint32_t)s->passes;
    unsigned long long rays = 0, paths = 0;

#pragma omp parallel for num_threads(pt_nthreads(s)) schedule(dynamic, 1) reduction(+ : rays, paths)
    for (long tile = 0; tile < ntiles; tile++) {
        if (!rp_comm_owns(s->comm, (size_t)tile))
            continue;
        double L[PT_MAX_BANDS];
        uint32_t x0 = (uint32_t)(tile % tx) * PT_TILE, y0 = (uint32_t)(tile / tx) * PT_TILE;
        uint32_t x1 = x0 + PT_TILE < W ? x0 + PT_TILE : W, y1 = y0 + PT_TILE < H ? y0 + PT_TILE : H;
        rp_sample_point sp[PT_TILE];
        rp_vec3 d[PT_TILE];
        rp_hit hit[PT_TILE];
        unsigned char found[PT_TILE];
        for (uint32_t y = y0; y < y1; y++) {
            /* The row's camera rays first, as one coherent stream. */
            const uint32_t n = x1 - x0;
            for (uint32_t i = 0; i < n; i++) {
                uint32_t x = x0 + i;
                rp_sampler_start(&s->image_sampler, (size_t)y * W + x, index, &sp[i]);
                /* Box filter: a uniform point in the pixel; the vertical
                 * field of view spans the image height, (0, 0) is the
                 * top-left corner. */
                double jx = rp_sampler_get(&sp[i], DIM_PIXEL), jy = rp_sampler_get(&sp[i], DIM_PIXEL + 1);
                double sx = (2.0 * (x + jx) / W - 1.0) * s->tan_half * s->aspect;
                double sy = (1.0 - 2.0 * (y + jy) / H) * s->tan_half;
                d[i] = rp_v3_normalize(rp_v3_madd(rp_v3_madd(s->forward, s->right, sx), s->up, sy));
            }
            rp_ray_closest_coherent(s->rc, n, s->eye, d, hit, found);
            rays += n;
            paths += n;
            for (uint32_t i = 0; i < n; i++) {
                size_t pix = (size_t)y * W + x0 + i;
                if (found[i])
                    pt_path(s, &sp[i], &hit[i], d[i], L, &rays);
                else
                    for (size_t b = 0; b < nb; b++)
                        L[b] = 0; /* nothing out there */
                double *sum = s->sum + pix * nb, *sq = s->sumsq + pix * nb, *k = s->shift + pix * nb;
                for (size_t b = 0; b < nb; b++) {
                    if (index == 0)
                        k[b] = L[b];
                    double x = L[b] - k[b];
                    sum[b] += x;
                    sq[b] += x * x;
                }
            }
        }
    }
    s->passes++;
    info->rays += (double)rays;
    info->paths += (double)paths;
}

/* The image's sums (sum, sumsq, shift: n each) of all ranks: the state's
 * own arrays when alone, else a malloc'd copy (*copy, to free) summed over
 * the ranks; collective. */
static rp_status pt_image_sums(const pt_state *s, const double **sum, const double **sumsq, const double **shift,
                               double **copy, rp_error *err)
{
    size_t n = (size_t)s->width * s->height * s->nbands;
    *copy = NULL;
    *sum = s->sum;
    *sumsq = s->sumsq;
    *shift = s->shift;
    if (!s->comm)
        return RP_OK;
    double *c = malloc((n ? 3 * n : 1) * sizeof *c);
    if (!c)
        return rp_error_set(err, RP_ERR_NOMEM, "pathtrace: out of memory (gathering the image)");
    memcpy(c, s->sum, n * sizeof *c);
    memcpy(c + n, s->sumsq, n * sizeof *c);
    memcpy(c + 2 * n, s->shift, n * sizeof *c);
    rp_comm_sum(s->comm, c, 3 * n);
    *copy = c;
    *sum = c;
    *sumsq = c + n;
    *shift = c + 2 * n;
    return RP_OK;
}

/* After loading all ranks' sums: keep this rank's tiles only, so the sums
 * over ranks stay exact. */
static void pt_keep_own_tiles(pt_state *s)
{
    if (!s->comm)
        return;
    const uint32_t W = s->width, H = s->height, tx = (W + PT_TILE - 1) / PT_TILE;
    const size_t nb = s->nbands;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            size_t tile = (size_t)(y / PT_TILE) * tx + x / PT_TILE;
            if (rp_comm_owns(s->comm, tile))
                continue;
            size_t i = ((size_t)y * W + x) * nb;
            for (size_t b = 0; b < nb; b++)
                s->sum[i + b] = s->sumsq[i + b] = s->shift[i + b] = 0;
        }
}

/* A batch of probe points on every surface: L = Le + one path's estimate
 * of the reflected radiance, at points uniform over the surface. */
static rp_status pt_probe_batch(pt_state *s, rp_step_info *info, rp_error *err)
{
    const size_t nb = s->nbands, ns = s->nsurfaces;
    unsigned long n = s->batch;
    if (s->probe_done < s->samples && s->samples - s->probe_done < n)
        n = s->samples - s->probe_done; /* land exactly on the budget */
    if (s->probe_done + n > UINT32_MAX)
        return rp_error_set(err, RP_ERR_RUNTIME, "pathtrace: more than 2^32 probe samples per surface");
    const size_t nchunks = (n + PT_CHUNK - 1) / PT_CHUNK;
    const long nitems = (long)(ns * nchunks);
    double *partial = realloc(s->partial, (nitems ? nitems : 1) * 2 * nb * sizeof *partial);
    if (!partial)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    s->partial = partial;
    const rp_surface *surfs = rp_scene_surfaces(s->scene);
    const unsigned long first = s->probe_done;
    unsigned long long rays = 0, paths = 0;

#pragma omp parallel for num_threads(pt_nthreads(s)) schedule(dynamic, 1) reduction(+ : rays, paths)
    for (long item = 0; item < nitems; item++) {
        double L[PT_MAX_BANDS];
        size_t surf = (size_t)item / nchunks, chunk = (size_t)item % nchunks;
        double *psum = partial + (size_t)item * 2 * nb, *psq = psum + nb;
        for (size_t b = 0; b < 2 * nb; b++)
            psum[b] = 0;
        if (!rp_comm_owns(s->comm, (size_t)item))
            continue;
        const rp_area_sampler *as = s->probes[surf];
        if (rp_area_sampler_count(as) == 0)
            continue;
        const double *Le = s->mats[surfs[surf].material].Le;
        unsigned long k0 = chunk * PT_CHUNK, k1 = k0 + PT_CHUNK < n ? k0 + PT_CHUNK : n;
        paths += k1 - k0;
        for (unsigned long k = k0; k < k1; k++) {
            rp_sample_point sp;
            rp_sampler_start(&s->probe_sampler, surf, (uint32_t)(first + k), &sp);
            rp_area_sample a;
            rp_area_sampler_sample(as, rp_sampler_get(&sp, DIM_PROBE_FACE), rp_sampler_get(&sp, DIM_PIXEL),
                                   rp_sampler_get(&sp, DIM_PIXEL + 1), &a);
            rp_hit hit;
            memset(&hit, 0, sizeof hit);
            hit.p = a.p;
            hit.n = a.n;
            hit.face = a.face;
            hit.surface = a.surface;
            hit.element = RP_NONE;
            hit.front = 1;
            /* The path kernel counts the start's emission fully (depth 0),
             * which is the Le term; its direction argument is unused there. */
            pt_path(s, &sp, &hit, rp_v3_scale(a.n, -1.0), L, &rays);
            for (size_t b = 0; b < nb; b++) {
                double x = L[b] - Le[b];
                psum[b] += x;
                psq[b] += x * x;
            }
        }
    }
    /* each chunk's partial sums from the rank that owns it */
    rp_comm_sum(s->comm, partial, (size_t)nitems * 2 * nb);
    for (size_t i = 0; i < (size_t)nitems; i++) {
        size_t surf = i / nchunks;
        const double *psum = partial + i * 2 * nb, *psq = psum + nb;
        for (size_t b = 0; b < nb; b++) {
            s->ssum[surf * nb + b] += psum[b];
            s->ssumsq[surf * nb + b] += psq[b];
        }
    }
    s->probe_done += n;
    info->rays += (double)rays;
    info->paths += (double)paths; /* this rank's: the driver sums the ranks */
    return RP_OK;
}

static int pt_probe_done(const pt_state *s, double *progress);

static rp_status pt_step(void *state, rp_step_info *info, rp_error *err)
{
    pt_state *s = state;
    int done = 1;
    double progress = 1;
    if (s->want & RP_WANT_IMAGE) {
        if (s->passes >= UINT32_MAX)
            return rp_error_set(err, RP_ERR_RUNTIME, "pathtrace: more than 2^32 passes");
        pt_image_pass(s, info);
        done = done && s->spp_rule && s->passes >= s->spp;
        double f = (double)s->passes / (double)s->spp;
        progress = f < progress ? f : progress;
    }
    if (s->want & RP_WANT_SURFACES) {
        rp_status st = pt_probe_batch(s, info, err);
        if (st != RP_OK)
            return st;
        double f;
        done = done && pt_probe_done(s, &f);
        progress = f < progress ? f : progress;
    }
    info->iterations += 1;
    info->converged = done;
    info->progress = progress;
    return RP_OK;
}

/* Mean and variance of the mean from the sum and the sum of squares of n
 * samples minus a shift (unbiased sample variance / n; infinite below two
 * samples). */
static inline void pt_moments(double sum, double sumsq, double shift, double n, double *mean,
                              double *var)
{
    if (n <= 0) {
        *mean = 0;
        *var = INFINITY;
        return;
    }
    *mean = shift + sum / n;
    if (n < 2) {
        *var = INFINITY;
        return;
    }
    double v = (sumsq - sum * sum / n) / (n - 1);
    *var = v > 0 ? v / n : 0;
}

/* Mean and variance of the mean of surface and band i (i = surface x
 * nbands + band): its emission plus the probe's reflected sums. */
static void pt_surface_moments(const pt_state *s, const rp_surface *surfs, size_t i, double *mean, double *var)
{
    const size_t nb = s->nbands;
    pt_moments(s->ssum[i], s->ssumsq[i], s->mats[surfs[i / nb].material].Le[i % nb], (double)s->probe_done, mean,
               var);
}

/* Whether the surface averages have converged: --samples reached (when
 * it rules), or every surface's standard error at most --target-error
 * times its average in every band.  *progress: the larger of the two
 * fractions, the second (target / largest relative error)^2 as the error
 * falls as 1 / sqrt(samples). */
static int pt_probe_done(const pt_state *s, double *progress)
{
    const size_t nb = s->nbands;
    int done = s->samples_rule && s->probe_done >= s->samples;
    double f = (double)s->probe_done / (double)s->samples;
    if (s->target_error > 0) {
        const rp_surface *surfs = rp_scene_surfaces(s->scene);
        double worst = 0; /* largest standard error / average */
        for (size_t i = 0; i < s->nsurfaces * nb; i++) {
            double m, v;
            pt_surface_moments(s, surfs, i, &m, &v);
            double r = v > 0 ? (m > 0 ? sqrt(v) / m : INFINITY) : 0;
            worst = r > worst ? r : worst;
        }
        if (worst <= s->target_error)
            done = 1, f = 1;
        else if (isfinite(worst)) {
            double g = (s->target_error / worst) * (s->target_error / worst);
            f = g > f ? g : f;
        }
    }
    *progress = f < 1 ? f : 1;
    return done;
}

static rp_status pt_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const pt_state *s = state;
    const size_t nb = s->nbands;
    if ((e->radiance || e->variance) && !(s->want & RP_WANT_IMAGE))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "pathtrace: no image was asked for at init");
    if ((e->surface_radiance || e->surface_stderr) && !(s->want & RP_WANT_SURFACES))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "pathtrace: no surface averages were asked for at init");
    if (s->want & RP_WANT_IMAGE) {
        size_t n = (size_t)s->width * s->height * nb;
        const double *sum, *sumsq, *shift;
        double *copy;
        rp_status st = pt_image_sums(s, &sum, &sumsq, &shift, &copy, err);
        if (st != RP_OK)
            return st;
        for (size_t i = 0; i < n; i++) {
            double m, v;
            pt_moments(sum[i], sumsq[i], shift[i], (double)s->passes, &m, &v);
            if (e->radiance)
                e->radiance[i] = (float)m;
            if (e->variance)
                e->variance[i] = (float)v;
        }
        free(copy);
        e->samples = (double)s->passes;
    }
    if (s->want & RP_WANT_SURFACES) {
        const rp_surface *surfs = rp_scene_surfaces(s->scene);
        for (size_t i = 0; i < s->nsurfaces * nb; i++) {
            double m, v;
            pt_surface_moments(s, surfs, i, &m, &v);
            if (e->surface_radiance)
                e->surface_radiance[i] = m;
            if (e->surface_stderr)
                e->surface_stderr[i] = sqrt(v);
        }
        if (!(s->want & RP_WANT_IMAGE))
            e->samples = (double)s->probe_done;
    }
    return RP_OK;
}

/* ------------------------------------------------- checkpoint and resume
 *
 * The state is the running sums (sum, sumsq, shift per pixel and band;
 * ssum, ssumsq per surface and band) and the sample counts.  Since every
 * random number is a pure function of (seed, stream, index, dimension),
 * passes resumed from index `passes` on draw the very numbers an
 * uninterrupted run would, and the sums continue in the same order: the
 * resumed image is bit-identical.  (Surface sums are bit-identical when the
 * checkpoint falls on a whole probe batch, as it does unless --samples was
 * reached with a short last batch.)  Before the sums go the settings that
 * shape them, checked on load. */
#define PT_STATE_VERSION 1

enum {
    PT_F_VERSION, PT_F_NBANDS, PT_F_WIDTH, PT_F_HEIGHT, PT_F_NSURFACES, PT_F_WANT,
    PT_F_SAMPLER, PT_F_SEED, PT_F_GRID, PT_F_PROBE_SEED, PT_F_PROBE_GRID,
    PT_F_MAX_DEPTH, PT_F_RR_DEPTH, PT_F_BATCH, PT_F_SPP, PT_F_SAMPLES,
    PT_F_PASSES, PT_F_PROBE_DONE, PT_F_COUNT
};

static void pt_state_fields(const pt_state *s, uint64_t *f)
{
    f[PT_F_VERSION] = PT_STATE_VERSION;
    f[PT_F_NBANDS] = s->nbands;
    f[PT_F_WIDTH] = s->width;
    f[PT_F_HEIGHT] = s->height;
    f[PT_F_NSURFACES] = s->nsurfaces;
    f[PT_F_WANT] = s->want;
    const rp_sampler *any = s->want & RP_WANT_IMAGE ? &s->image_sampler : &s->probe_sampler;
    f[PT_F_SAMPLER] = (uint64_t)any->kind;
    f[PT_F_SEED] = s->image_sampler.seed;
    f[PT_F_GRID] = s->image_sampler.grid;
    f[PT_F_PROBE_SEED] = s->probe_sampler.seed;
    f[PT_F_PROBE_GRID] = s->probe_sampler.grid;
    f[PT_F_MAX_DEPTH] = s->max_depth;
    f[PT_F_RR_DEPTH] = s->rr_depth;
    f[PT_F_BATCH] = s->batch;
    f[PT_F_SPP] = s->spp;
    f[PT_F_SAMPLES] = s->samples;
    f[PT_F_PASSES] = s->passes;
    f[PT_F_PROBE_DONE] = s->probe_done;
}

static rp_status pt_save(const void *state, FILE *f, rp_error *err)
{
    const pt_state *s = state;
    uint64_t fields[PT_F_COUNT];
    pt_state_fields(s, fields);
    int bad = rp_solver_put_u64(f, fields, PT_F_COUNT) != 0;
    bad = bad || rp_solver_put_f64(f, &s->rr_weight, 1) != 0;
    if (s->want & RP_WANT_IMAGE) {
        /* all ranks' sums, so any rank count can resume (pt_keep_own_tiles) */
        size_t n = (size_t)s->width * s->height * s->nbands;
        const double *sum, *sumsq, *shift;
        double *copy;
        rp_status st = pt_image_sums(s, &sum, &sumsq, &shift, &copy, err);
        if (st != RP_OK)
            return st;
        bad = bad || rp_solver_put_f64(f, sum, n) != 0 || rp_solver_put_f64(f, sumsq, n) != 0 ||
              rp_solver_put_f64(f, shift, n) != 0;
        free(copy);
    }
    if (s->want & RP_WANT_SURFACES) {
        size_t n = s->nsurfaces * s->nbands;
        bad = bad || rp_solver_put_f64(f, s->ssum, n) != 0 || rp_solver_put_f64(f, s->ssumsq, n) != 0;
    }
    return bad ? rp_error_set(err, RP_ERR_RUNTIME, "pathtrace: writing the state failed") : RP_OK;
}

static rp_status pt_load(void *state, FILE *f, rp_step_info *info, rp_error *err)
{
    pt_state *s = state;
    uint64_t got[PT_F_COUNT], want[PT_F_COUNT];
    double rr_weight;
    if (rp_solver_get_u64(f, got, PT_F_COUNT) != 0 || rp_solver_get_f64(f, &rr_weight, 1) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: state truncated (settings)");
    pt_state_fields(s, want);
    if (got[PT_F_VERSION] != PT_STATE_VERSION)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: state format %llu, this radpt reads %d",
                            (unsigned long long)got[PT_F_VERSION], PT_STATE_VERSION);
#define PT_DIFFERS(field, what)                                                                         \
    if (got[field] != want[field])                                                                      \
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint has %s %llu, this run %llu", what, \
                            (unsigned long long)got[field], (unsigned long long)want[field]);
    PT_DIFFERS(PT_F_NBANDS, "bands")
    PT_DIFFERS(PT_F_WIDTH, "image width")
    PT_DIFFERS(PT_F_HEIGHT, "image height")
    PT_DIFFERS(PT_F_NSURFACES, "surfaces")
    if (got[PT_F_WANT] != want[PT_F_WANT]) {
        static const char *const asked[4] = {"nothing", "an image", "surface averages",
                                             "an image and surface averages"};
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint holds %s, this run asks for %s",
                            asked[got[PT_F_WANT] & 3], asked[want[PT_F_WANT] & 3]);
    }
    if (got[PT_F_SAMPLER] != want[PT_F_SAMPLER])
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint has --sampler %s, this run %s",
                            got[PT_F_SAMPLER] <= RP_SAMPLER_SOBOL ? rp_sampler_name((rp_sampler_kind)got[PT_F_SAMPLER]) : "?",
                            rp_sampler_name((rp_sampler_kind)want[PT_F_SAMPLER]));
    PT_DIFFERS(PT_F_SEED, "--seed")
    PT_DIFFERS(PT_F_PROBE_SEED, "probe seed (a hash of --seed)")
    /* The stratified grid is sized by the sample budget (sampler.h). */
    if (want[PT_F_SAMPLER] == RP_SAMPLER_STRATIFIED) {
        if (got[PT_F_GRID] != want[PT_F_GRID])
            return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the stratified sampler's grid follows --spp: the "
                                "checkpoint has --spp %llu, this run %llu (they must be equal)",
                                (unsigned long long)got[PT_F_SPP], (unsigned long long)want[PT_F_SPP]);
        if (got[PT_F_PROBE_GRID] != want[PT_F_PROBE_GRID])
            return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the stratified sampler's grid follows --samples: "
                                "the checkpoint has --samples %llu, this run %llu (they must be equal)",
                                (unsigned long long)got[PT_F_SAMPLES], (unsigned long long)want[PT_F_SAMPLES]);
    }
    PT_DIFFERS(PT_F_MAX_DEPTH, "--max-depth")
    PT_DIFFERS(PT_F_RR_DEPTH, "--rr-depth")
    PT_DIFFERS(PT_F_BATCH, "--batch")
#undef PT_DIFFERS
    if (memcmp(&rr_weight, &s->rr_weight, sizeof rr_weight) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint has --rr-weight %.17g, this run %.17g",
                            rr_weight, s->rr_weight);
    uint64_t passes = got[PT_F_PASSES], probe_done = got[PT_F_PROBE_DONE];
    if ((s->want & RP_WANT_IMAGE) && (passes > UINT32_MAX || (s->spp_rule && passes > s->spp)))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint holds %llu samples per pixel, more "
                            "than --spp %lu", (unsigned long long)passes, s->spp);
    if ((s->want & RP_WANT_SURFACES) && (probe_done > UINT32_MAX || (s->samples_rule && probe_done > s->samples)))
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: the checkpoint holds %llu probe samples per surface, "
                            "more than --samples %lu", (unsigned long long)probe_done, s->samples);
    int bad = 0;
    if (s->want & RP_WANT_IMAGE) {
        size_t n = (size_t)s->width * s->height * s->nbands;
        bad = rp_solver_get_f64(f, s->sum, n) != 0 || rp_solver_get_f64(f, s->sumsq, n) != 0 ||
              rp_solver_get_f64(f, s->shift, n) != 0;
    }
    if (!bad && (s->want & RP_WANT_SURFACES)) {
        size_t n = s->nsurfaces * s->nbands;
        bad = rp_solver_get_f64(f, s->ssum, n) != 0 || rp_solver_get_f64(f, s->ssumsq, n) != 0;
    }
    if (bad)
        return rp_error_set(err, RP_ERR_INPUT, "pathtrace: state truncated (sums)");
    if (s->want & RP_WANT_IMAGE)
        pt_keep_own_tiles(s);
    s->passes = (unsigned long)passes;
    s->probe_done = (unsigned long)probe_done;

    /* What pt_step would have reported after the last step. */
    int done = 1;
    double progress = 1;
    if (s->want & RP_WANT_IMAGE) {
        done = done && s->spp_rule && s->passes >= s->spp;
        double fr = (double)s->passes / (double)s->spp;
        progress = fr < progress ? fr : progress;
        info->iterations = (double)s->passes;
    } else
        info->iterations = ceil((double)s->probe_done / (double)s->batch);
    if (s->want & RP_WANT_SURFACES) {
        double fr;
        done = done && pt_probe_done(s, &fr);
        progress = fr < progress ? fr : progress;
    }
    info->converged = done;
    info->progress = progress;
    return RP_OK;
}

const rp_solver_type rp_solver_pathtrace = {
    .name = "pathtrace",
    .summary = "Monte Carlo path tracing: next-event estimation + cosine sampling with MIS, "
               "Russian roulette (unbiased)",
    .options = pt_options,
    .state_size = sizeof(pt_state),
    .init = pt_init,
    .step = pt_step,
    .estimate = pt_estimate,
    .fini = pt_fini,
    .save = pt_save,
    .load = pt_load,
    .iteration_name = "passes",
    .monte_carlo = 1,
    .samples_name = "samples per pixel",
    .surfaces_cost = 1,
    .distributed = 1,
};
