/* lighttrace: particle tracing from the emitters (light tracing), a radpt
 * method written as a plugin against the installed headers only.
 *
 * Method: Arvo & Kirk, "Particle transport and image synthesis" (SIGGRAPH
 * 1990); Dutré, Bala & Bekaert, "Advanced Global Illumination" (2nd ed.,
 * 2006), ch. 5 (particle tracing, light tracing); Veach's thesis (1997),
 * ch. 10 (light subpaths joined to the eye, bidirectional path tracing's
 * t = 1 strategies) for the splat to a pinhole camera.  Surfaces are one-sided
 * Lambertian reflectors, BRDF rho/pi; the back of a face absorbs.
 *
 * A particle starts at a point x0 on an emitting face, picked by emitted
 * power with area density p_A(x0) (rp_area_sampler, RP_WEIGHT_POWER), and
 * leaves in a cosine-distributed direction (density cos/pi), carrying per
 * band the flux
 *
 *     Phi_0,b = Le_b(x0) cos / (p_A(x0) cos / pi) = pi Le_b(x0) / p_A(x0).
 *
 * At its k-th hit x_k (on the front of a face) it carries the flux Phi_k,b
 * that arrives there; it then reflects by cosine sampling, Phi_k+1,b =
 * Phi_k,b rho_b (the BRDF times cos over the density is rho), with Russian
 * roulette on reflectance from reflection rr-depth + 1 on: it survives with
 * probability q = min(0.95, max_b rho_b) and then carries Phi rho_b / q
 * (Arvo & Kirk 1990), which keeps every estimate unbiased.
 *
 * Vertices x_k with k > max-depth are not counted (k = 0 is emission).
 *
 * Surface averages.  For N particles, Phi_in,s = (1/N) sum_i X_i,s with
 * X_i,s = sum of Phi_k over the hits of particle i on surface s is an
 * unbiased estimate of the flux incident on the front of s, so
 *
 *     L_s = Le_s + rho_s Phi_in,s / (pi A_s)          (per band)
 *
 * is an unbiased estimate of the area-averaged outgoing radiance of s, and
 * its standard error is rho_s / (pi A_s) sqrt(var(X_s) / N), var the sample
 * variance over particles (sums of X and X^2 per surface); a surface that
 * reflects nothing (a pure emitter) gets Le exactly, standard error 0.
 *
 * Image.  Every vertex (the emitter's x0 included) is connected to the eye
 * by a visibility ray.  Pixel j's value is the mean radiance over its
 * image-plane area (the box filter of the path tracer's camera rays), i.e.
 * the measurement I_j = int_A W_j(x) L(x -> eye) G(x, eye) dA with, for a
 * pinhole at unit image distance, W_j G = cos_x / (r^2 A_pix cos_c^3),
 * A_pix = 4 tan(fov/2)^2 aspect / (W H) and cos_c the cosine of the angle
 * to the camera axis (geometry/camera.h: the importance W H / (4 tan^2 aspect cos_c^4)
 * times cos_c).  So a vertex splats into the pixel it projects to
 *
 *     Y_b = Phi_k,b f_b cos_x / (r^2 A_pix cos_c^3),
 *     f_b = 1/pi at x0 (emission, Phi_0 = pi Le / p_A), rho_b/pi at a hit,
 *
 * and I_j = (1/N) sum_i Y_i,j (Y_i,j: particle i's splats into j, summed)
 * is unbiased; the variance of that mean comes from the sums of Y and Y^2.
 *
 * Determinism.  Particle i of a run (counted over all steps) draws its
 * numbers from a splitmix64 stream keyed by (seed, i); chunks of LT_CHUNK
 * particles keep their own partial sums and splat lists, added in chunk
 * order, so the answer is bit-identical for any thread count.
 *
 * Build against an installed radpt (make install), see the Makefile:
 *     PKG_CONFIG_PATH=PREFIX/lib/pkgconfig make
 * and run it:
 *     radpt render scenes/cornell.scene --plugin ./lighttrace.so --method lighttrace -o lt.exr
 *     radpt probe scenes/cornell.scene --plugin ./lighttrace.so --method lighttrace --surface-averages */
#include <radpt/radpt.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

RP_PLUGIN_DECLARE_ABI;

#define LT_MAX_BANDS 256
/* Particles per work item: partial sums per chunk, added in chunk order. */
#define LT_CHUNK 1024
/* Chunks traced in parallel before their sums are added: bounds the
 * memory of partial sums and splat lists whatever --particles is. */
#define LT_WAVE 64
/* Russian roulette survival is capped so that a particle in a white
 * closed room still ends (its flux then grows by 1/0.95 per reflection). */
#define LT_RR_MAX 0.95
#define LT_UNLIMITED UINT32_MAX

/* One chunk's splats: pixel index and nb values each, one entry per
 * particle and pixel (a particle's splats into one pixel are summed). */
typedef struct lt_splats {
    size_t n, cap;
    uint32_t *pixel;
    double *value;
} lt_splats;

typedef struct lt_state {
    const rp_scene *scene;
    size_t nbands, nsurfaces;
    unsigned want;
    int threads;
    uint64_t key;             /* the seed, hashed */
    rp_options poll;          /* the caller's cancel flag, for rp_options_cancelled */
    unsigned long particles;  /* per step */
    unsigned long batches;    /* steps after which the run has converged */
    int batches_rule;         /* batches stops the run (solver.h, open_ended) */
    unsigned max_depth, rr_depth;

    rp_raycast *rc;
    rp_area_sampler *lights;  /* NULL when nothing emits */
    const rp_material *mats;
    const rp_surface *surfs;
    uint32_t *face_mat;
    unsigned char *mat_reflects;

    /* Camera: frame, and W H / (4 tan^2 aspect) = 1 / A_pix. */
    rp_camera_frame cam;
    double inv_pixel_area;

    /* Surfaces: per surface and band, sums of X and X^2 over particles,
     * and per chunk the same (2 nsurfaces nb each). */
    double *ssum, *ssumsq, *partial;
    /* Image: per pixel and band, sums of Y and Y^2; per chunk, splats. */
    double *isum, *isumsq;
    lt_splats *splats;
    size_t nchunks;           /* entries of partial and splats: one wave's chunks */

    uint64_t done;            /* particles traced */
    unsigned long steps;
} lt_state;

static const rp_option_spec lt_options[] = {
    {"particles", "N", "particles traced from the emitters per step", "65536"},
    {"batches", "N",
     "steps after which the run has converged (N x particles in all); under a time budget only "
     "when given",
     "16"},
    {"max-depth", "D",
     "reflections light may make before it is counted: 0 emission only, 1 direct lighting, "
     "'unlimited' ends particles by Russian roulette only",
     "unlimited"},
    {"rr-depth", "N",
     "reflections before Russian roulette starts (survival min(0.95, max band reflectance))", "0"},
    RP_RAY_OFFSET_OPTION,
    {NULL, NULL, NULL, NULL}
};

/* ------------------------------------------------------------ random numbers
 * splitmix64 (Steele, Lea & Flood 2014): the finaliser hashes a particle's
 * index and the seed into a start state, and the stream goes on from there
 * by the Weyl increment. */
static inline uint64_t lt_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

typedef struct lt_rng {
    uint64_t s;
} lt_rng;

static inline void lt_rng_start(lt_rng *r, uint64_t key, uint64_t index)
{
    r->s = lt_mix(key ^ lt_mix(index + UINT64_C(0x9e3779b97f4a7c15)));
}

/* Uniform in [0, 1), 53 bits. */
static inline double lt_uniform(lt_rng *r)
{
    r->s += UINT64_C(0x9e3779b97f4a7c15);
    return (double)(lt_mix(r->s) >> 11) * (1.0 / 9007199254740992.0);
}

/* A cosine-distributed direction around unit n (Malley's method). */
static rp_vec3 lt_cosine_direction(rp_vec3 n, double u1, double u2)
{
    double r = sqrt(u1), cos_t = sqrt(1.0 - u1), phi = 2.0 * RP_PI * u2;
    rp_vec3 t, b;
    rp_v3_basis(n, &t, &b);
    return rp_v3_madd(rp_v3_madd(rp_v3_scale(n, cos_t), t, r * cos(phi)), b, r * sin(phi));
}

/* ------------------------------------------------------------- set up */
static void lt_fini(void *state)
{
    lt_state *s = state;
    rp_raycast_destroy(s->rc);
    rp_area_sampler_destroy(s->lights);
    free(s->face_mat);
    free(s->mat_reflects);
    free(s->ssum);
    free(s->ssumsq);
    free(s->partial);
    free(s->isum);
    free(s->isumsq);
    if (s->splats)
        for (size_t c = 0; c < s->nchunks; c++) {
            free(s->splats[c].pixel);
            free(s->splats[c].value);
        }
    free(s->splats);
    memset(s, 0, sizeof *s);
}

static rp_status lt_parse_options(lt_state *s, const rp_options *o, rp_error *err)
{
    rp_status st;
    unsigned long rr = 0;
    if ((st = rp_options_uint(o, "particles", 1, UINT32_MAX, &s->particles, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "batches", 1, UINT32_MAX, &s->batches, err)) != RP_OK)
        return st;
    if ((st = rp_options_uint(o, "rr-depth", 0, 1000000, &rr, err)) != RP_OK)
        return st;
    s->rr_depth = (unsigned)rr;
    s->max_depth = LT_UNLIMITED;
    const char *v = rp_options_get(o, "max-depth");
    if (v && strcmp(v, "unlimited") != 0) {
        unsigned long d = 0;
        if ((st = rp_options_uint(o, "max-depth", 0, 1000000, &d, err)) != RP_OK)
            return st;
        s->max_depth = (unsigned)d;
    }
    int open_ended = o->size >= offsetof(rp_options, open_ended) + sizeof o->open_ended ? o->open_ended : 0;
    s->batches_rule = !open_ended || rp_options_get(o, "batches");
    return RP_OK;
}

static rp_status lt_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    lt_state *s = state;
    rp_status st;
    if (!o)
        return rp_error_set(err, RP_ERR_INPUT, "lighttrace: no options");
    s->scene = scene;
    s->nbands = rp_scene_nbands(scene);
    s->nsurfaces = rp_scene_nsurfaces(scene);
    s->want = o->want;
    s->threads = o->threads;
    s->key = lt_mix(o->seed ^ UINT64_C(0x6c69676874747263)); /* "lighttrc" */
    s->poll.size = sizeof s->poll;
    s->poll.cancel = o->cancel;
    if (s->nbands == 0 || s->nbands > LT_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "lighttrace: %zu bands (at most %d)", s->nbands,
                            LT_MAX_BANDS);
    if (s->threads < 0)
        return rp_error_set(err, RP_ERR_INPUT, "lighttrace: %d threads", s->threads);
    if (!(s->want & (RP_WANT_IMAGE | RP_WANT_SURFACES)))
        return rp_error_set(err, RP_ERR_INPUT, "lighttrace: asked for neither an image nor surfaces");
    if ((st = lt_parse_options(s, o, err)) != RP_OK)
        return st;

    if ((st = rp_raycast_create(scene, NULL, &s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_options_ray_offset(o, s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_area_sampler_create(scene, RP_NONE, RP_WEIGHT_POWER, &s->lights, err)) != RP_OK)
        return st;
    if (rp_area_sampler_count(s->lights) == 0) {
        rp_area_sampler_destroy(s->lights);
        s->lights = NULL; /* a dark scene: every answer is 0 */
    }

    s->mats = rp_scene_materials(scene);
    s->surfs = rp_scene_surfaces(scene);
    size_t nfaces = rp_scene_nfaces(scene), nmat = rp_scene_nmaterials(scene);
    const rp_face *faces = rp_scene_faces(scene);
    s->face_mat = malloc((nfaces ? nfaces : 1) * sizeof *s->face_mat);
    s->mat_reflects = calloc(nmat ? nmat : 1, 1);
    if (!s->face_mat || !s->mat_reflects)
        return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory");
    for (size_t f = 0; f < nfaces; f++)
        s->face_mat[f] = s->surfs[faces[f].surface].material;
    for (size_t m = 0; m < nmat; m++)
        for (size_t b = 0; b < s->nbands; b++)
            if (s->mats[m].rho[b] > 0)
                s->mat_reflects[m] = 1;

    if (s->want & RP_WANT_IMAGE) {
        const rp_camera *cam = rp_scene_camera(scene);
        if (!cam)
            return rp_error_set(err, RP_ERR_INPUT, "lighttrace: the scene has no camera to render from");
        rp_camera_frame_init(&s->cam, cam);
        s->inv_pixel_area = (double)cam->width * cam->height / (4.0 * s->cam.tan_half * s->cam.tan_half * s->cam.aspect);
        size_t n = (size_t)cam->width * cam->height * s->nbands;
        s->isum = calloc(n, sizeof *s->isum);
        s->isumsq = calloc(n, sizeof *s->isumsq);
        if (!s->isum || !s->isumsq)
            return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory (image of %ux%u)", cam->width,
                                cam->height);
    }
    if (s->want & RP_WANT_SURFACES) {
        size_t n = s->nsurfaces * s->nbands;
        s->ssum = calloc(n ? n : 1, sizeof *s->ssum);
        s->ssumsq = calloc(n ? n : 1, sizeof *s->ssumsq);
        if (!s->ssum || !s->ssumsq)
            return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory");
    }
    s->nchunks = (s->particles + LT_CHUNK - 1) / LT_CHUNK;
    s->nchunks = s->nchunks < LT_WAVE ? s->nchunks : LT_WAVE;
    s->splats = calloc(s->nchunks, sizeof *s->splats);
    if (!s->splats)
        return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory");
    if (s->want & RP_WANT_SURFACES) {
        s->partial = malloc((s->nchunks * 2 * s->nsurfaces * s->nbands + 1) * sizeof *s->partial);
        if (!s->partial)
            return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory");
    }
    return RP_OK;
}

/* ------------------------------------------------------------- tracing */

/* Per work item scratch: one particle's flux per surface (X), and which
 * surfaces it touched, so only those are added and cleared. */
typedef struct lt_scratch {
    double *X;
    uint32_t *touched;
    unsigned char *mark;
    size_t ntouched;
} lt_scratch;

static int lt_splats_reserve(lt_splats *sp, size_t nb)
{
    if (sp->n < sp->cap)
        return 1;
    size_t cap = sp->cap ? 2 * sp->cap : 256;
    uint32_t *p = realloc(sp->pixel, cap * sizeof *p);
    if (!p)
        return 0;
    sp->pixel = p;
    double *v = realloc(sp->value, cap * nb * sizeof *v);
    if (!v)
        return 0;
    sp->value = v;
    sp->cap = cap;
    return 1;
}

/* Splats vertex x (normal n, flux Phi, f_b = scale * (rho_b or 1)) to the
 * camera; returns 0 when out of memory.  *rays counts visibility rays. */
static int lt_splat(const lt_state *s, lt_splats *sp, rp_vec3 x, rp_vec3 n, const double *Phi, const double *rho,
                    unsigned long long *rays)
{
    const size_t nb = s->nbands;
    double px, py, cos_c;
    if (!rp_camera_project(&s->cam, x, &px, &py, &cos_c))
        return 1;
    rp_vec3 to_eye = rp_v3_sub(s->cam.eye, x);
    double r2 = rp_v3_dot(to_eye, to_eye);
    if (!(r2 > 0))
        return 1;
    double r = sqrt(r2);
    double cos_x = rp_v3_dot(n, to_eye) / r;
    if (!(cos_x > 0))
        return 1; /* the eye sees the back of the face: black */
    (*rays)++;
    if (rp_ray_occluded(s->rc, x, n, s->cam.eye, rp_v3_scale(to_eye, -1.0 / r)))
        return 1;
    if (!lt_splats_reserve(sp, nb))
        return 0;
    /* Y_b = Phi_b f_b cos_x / (r^2 A_pix cos_c^3), f_b = rho_b / pi */
    double g = cos_x * s->inv_pixel_area / (r2 * cos_c * cos_c * cos_c * RP_PI);
    uint32_t x0 = (uint32_t)px, y0 = (uint32_t)py;
    sp->pixel[sp->n] = y0 * s->cam.width + x0;
    double *v = sp->value + sp->n * nb;
    for (size_t b = 0; b < nb; b++)
        v[b] = Phi[b] * (rho ? rho[b] : 1.0) * g;
    sp->n++;
    return 1;
}

/* A particle's splats [first, sp->n): sorted by pixel (insertion sort:
 * a handful), those into one pixel summed, so each entry is one Y_i,j. */
static void lt_splats_merge(lt_splats *sp, size_t first, size_t nb)
{
    double tmp[LT_MAX_BANDS];
    for (size_t i = first + 1; i < sp->n; i++) {
        uint32_t p = sp->pixel[i];
        memcpy(tmp, sp->value + i * nb, nb * sizeof *tmp);
        size_t j = i;
        while (j > first && sp->pixel[j - 1] > p) {
            sp->pixel[j] = sp->pixel[j - 1];
            memcpy(sp->value + j * nb, sp->value + (j - 1) * nb, nb * sizeof *tmp);
            j--;
        }
        sp->pixel[j] = p;
        memcpy(sp->value + j * nb, tmp, nb * sizeof *tmp);
    }
    size_t out = first;
    for (size_t i = first; i < sp->n; i++) {
        if (out > first && sp->pixel[out - 1] == sp->pixel[i]) {
            for (size_t b = 0; b < nb; b++)
                sp->value[(out - 1) * nb + b] += sp->value[i * nb + b];
            continue;
        }
        if (out != i) {
            sp->pixel[out] = sp->pixel[i];
            memmove(sp->value + out * nb, sp->value + i * nb, nb * sizeof *tmp);
        }
        out++;
    }
    sp->n = out;
}

/* Traces particle `index`; its hits go to sc (surfaces) and its splats to
 * sp (image).  Returns 0 when out of memory. */
static int lt_particle(const lt_state *s, uint64_t index, lt_scratch *sc, lt_splats *sp, unsigned long long *rays)
{
    const size_t nb = s->nbands;
    lt_rng rng;
    lt_rng_start(&rng, s->key, index);
    double u0 = lt_uniform(&rng), u1 = lt_uniform(&rng), u2 = lt_uniform(&rng);
    rp_area_sample a;
    rp_area_sampler_sample(s->lights, u0, u1, u2, &a);
    if (!(a.pdf_area > 0))
        return 1;
    const double *Le = s->mats[s->face_mat[a.face]].Le;
    double Phi[LT_MAX_BANDS];
    for (size_t b = 0; b < nb; b++)
        Phi[b] = RP_PI * Le[b] / a.pdf_area;
    if (sp && !lt_splat(s, sp, a.p, a.n, Phi, NULL, rays))
        return 0;

    rp_vec3 p = a.p, n = a.n;
    for (unsigned depth = 1; depth <= s->max_depth; depth++) {
        double v1 = lt_uniform(&rng), v2 = lt_uniform(&rng);
        rp_vec3 d = lt_cosine_direction(n, v1, v2);
        rp_hit hit;
        (*rays)++;
        if (!rp_ray_closest_from(s->rc, p, n, d, &hit) || !hit.front)
            break; /* gone, or absorbed by the back of a face */
        uint32_t m = s->face_mat[hit.face];
        if (!s->mat_reflects[m])
            break; /* a black face or a pure emitter: nothing to count */
        const double *rho = s->mats[m].rho;
        if (sc) {
            uint32_t su = hit.surface;
            if (!sc->mark[su]) {
                sc->mark[su] = 1;
                sc->touched[sc->ntouched++] = su;
                for (size_t b = 0; b < nb; b++)
                    sc->X[su * nb + b] = 0;
            }
            for (size_t b = 0; b < nb; b++)
                sc->X[su * nb + b] += Phi[b];
        }
        if (sp && !lt_splat(s, sp, hit.p, hit.n, Phi, rho, rays))
            return 0;
        if (depth == s->max_depth)
            break;
        /* Reflection `depth`: cosine sampling has weight rho; Russian
         * roulette on reflectance past rr-depth. */
        double rmax = 0;
        for (size_t b = 0; b < nb; b++)
            rmax = rho[b] > rmax ? rho[b] : rmax;
        double q = 1;
        if (depth > s->rr_depth) {
            q = rmax < LT_RR_MAX ? rmax : LT_RR_MAX;
            if (lt_uniform(&rng) >= q)
                break;
        }
        for (size_t b = 0; b < nb; b++)
            Phi[b] *= rho[b] / q;
        p = hit.p;
        n = hit.n;
    }
    return 1;
}

#ifdef _OPENMP
static inline int lt_nthreads(const lt_state *s)
{
    return s->threads > 0 ? s->threads : omp_get_max_threads();
}
#endif

/* Particles [first, first + count) of the run: chunks of LT_CHUNK in
 * parallel, then their sums in chunk order.  Returns 0 when out of memory;
 * *cancelled is set when the caller asked to stop. */
static int lt_wave(lt_state *s, uint64_t first, uint64_t count, unsigned long long *rays_out, int *cancelled)
{
    const size_t nb = s->nbands, ns = s->nsurfaces;
    const int surfaces = (s->want & RP_WANT_SURFACES) != 0, image = (s->want & RP_WANT_IMAGE) != 0;
    const long nchunks = (long)((count + LT_CHUNK - 1) / LT_CHUNK);
    unsigned long long rays = 0;
    int nomem = 0;

#ifdef _OPENMP
#pragma omp parallel for num_threads(lt_nthreads(s)) schedule(dynamic, 1) reduction(+ : rays)
#endif
    for (long c = 0; c < nchunks; c++) {
        double *psum = surfaces ? s->partial + (size_t)c * 2 * ns * nb : NULL;
        double *psq = psum ? psum + ns * nb : NULL;
        lt_splats *sp = image ? &s->splats[c] : NULL;
        if (sp)
            sp->n = 0;
        if (psum)
            memset(psum, 0, 2 * ns * nb * sizeof *psum);
        lt_scratch sc = {0};
        if (surfaces) {
            sc.X = malloc((ns * nb + 1) * sizeof *sc.X);
            sc.touched = malloc((ns + 1) * sizeof *sc.touched);
            sc.mark = calloc(ns + 1, 1);
        }
        int ok = !surfaces || (sc.X && sc.touched && sc.mark);
        uint64_t k0 = (uint64_t)c * LT_CHUNK, k1 = k0 + LT_CHUNK < count ? k0 + LT_CHUNK : count;
        for (uint64_t k = k0; ok && k < k1; k++) {
            size_t mark = sp ? sp->n : 0;
            if (!lt_particle(s, first + k, surfaces ? &sc : NULL, sp, &rays)) {
                ok = 0;
                break;
            }
            if (sp)
                lt_splats_merge(sp, mark, nb);
            for (size_t t = 0; t < sc.ntouched; t++) {
                uint32_t su = sc.touched[t];
                for (size_t b = 0; b < nb; b++) {
                    double x = sc.X[su * nb + b];
                    psum[su * nb + b] += x;
                    psq[su * nb + b] += x * x;
                }
                sc.mark[su] = 0;
            }
            sc.ntouched = 0;
        }
        if (!ok) {
#ifdef _OPENMP
#pragma omp atomic write
#endif
            nomem = 1;
        }
        free(sc.X);
        free(sc.touched);
        free(sc.mark);
    }
    *rays_out += rays;
    if (nomem)
        return 0;
    if (rp_options_cancelled(&s->poll)) {
        *cancelled = 1;
        return 1;
    }
    /* Chunk order: the same sums for any thread count. */
    for (size_t c = 0; c < (size_t)nchunks; c++) {
        if (surfaces) {
            const double *psum = s->partial + c * 2 * ns * nb, *psq = psum + ns * nb;
            for (size_t i = 0; i < ns * nb; i++) {
                s->ssum[i] += psum[i];
                s->ssumsq[i] += psq[i];
            }
        }
        if (image) {
            const lt_splats *sp = &s->splats[c];
            for (size_t i = 0; i < sp->n; i++) {
                double *sum = s->isum + (size_t)sp->pixel[i] * nb, *sq = s->isumsq + (size_t)sp->pixel[i] * nb;
                const double *v = sp->value + i * nb;
                for (size_t b = 0; b < nb; b++) {
                    sum[b] += v[b];
                    sq[b] += v[b] * v[b];
                }
            }
        }
    }
    return 1;
}

/* One step: `particles` particles, in waves of at most LT_WAVE chunks (the
 * memory for partial sums and splats is the wave's), polling for
 * cancellation between waves (a cancelled state is only good for fini). */
static rp_status lt_step(void *state, rp_step_info *info, rp_error *err)
{
    lt_state *s = state;
    const size_t nb = s->nbands, ns = s->nsurfaces;
    unsigned long long rays = 0;
    int cancelled = 0;
    const uint64_t wave = (uint64_t)LT_WAVE * LT_CHUNK;
    if (s->lights)
        for (uint64_t k = 0; k < s->particles && !cancelled; k += wave) {
            uint64_t count = s->particles - k < wave ? s->particles - k : wave;
            if (!lt_wave(s, s->done + k, count, &rays, &cancelled))
                return rp_error_set(err, RP_ERR_NOMEM, "lighttrace: out of memory (splats)");
        }
    if (cancelled)
        return rp_error_set(err, RP_ERR_INTERRUPTED, "lighttrace: interrupted");
    s->done += s->particles;
    s->steps++;
    info->rays += (double)rays;
    info->paths += (double)s->particles;
    info->iterations += 1;
    info->converged = s->batches_rule && s->steps >= s->batches;
    info->progress = s->steps >= s->batches ? 1.0 : (double)s->steps / (double)s->batches;
    double mem = (double)(s->nchunks * sizeof *s->splats);
    for (size_t c = 0; c < s->nchunks; c++)
        mem += (double)s->splats[c].cap * (sizeof(uint32_t) + nb * sizeof(double));
    if (s->want & RP_WANT_IMAGE)
        mem += 2.0 * s->cam.width * s->cam.height * nb * sizeof(double);
    if (s->want & RP_WANT_SURFACES)
        mem += (2.0 + 2.0 * (double)s->nchunks) * ns * nb * sizeof(double);
    info->memory = mem;
    return RP_OK;
}

/* Mean and variance of the mean of n samples from their sum and sum of
 * squares (the unbiased sample variance over n; infinite below 2). */
static void lt_moments(double sum, double sumsq, double n, double *mean, double *var)
{
    *mean = n > 0 ? sum / n : 0;
    if (n < 2) {
        *var = INFINITY;
        return;
    }
    double v = (sumsq - sum * sum / n) / (n - 1);
    *var = v > 0 ? v / n : 0;
}

static rp_status lt_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const lt_state *s = state;
    const size_t nb = s->nbands;
    const double n = (double)s->done;
    if ((e->radiance || e->variance) && !(s->want & RP_WANT_IMAGE))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "lighttrace: no image was asked for at init");
    if ((e->surface_radiance || e->surface_stderr) && !(s->want & RP_WANT_SURFACES))
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "lighttrace: no surface averages were asked for at init");
    if (s->want & RP_WANT_IMAGE) {
        size_t np = (size_t)s->cam.width * s->cam.height * nb;
        for (size_t i = 0; i < np; i++) {
            double m, v;
            lt_moments(s->isum[i], s->isumsq[i], n, &m, &v);
            if (e->radiance)
                e->radiance[i] = (float)m;
            if (e->variance)
                e->variance[i] = (float)v;
        }
    }
    if (s->want & RP_WANT_SURFACES)
        for (size_t i = 0; i < s->nsurfaces; i++) {
            const rp_material *m = &s->mats[s->surfs[i].material];
            double A = s->surfs[i].area;
            for (size_t b = 0; b < nb; b++) {
                /* L_s = Le_s + rho_s Phi_in,s / (pi A_s) */
                double c = A > 0 ? m->rho[b] / (RP_PI * A) : 0, mean, var;
                lt_moments(s->ssum[i * nb + b], s->ssumsq[i * nb + b], n, &mean, &var);
                if (e->surface_radiance)
                    e->surface_radiance[i * nb + b] = m->Le[b] + c * mean;
                if (e->surface_stderr)
                    e->surface_stderr[i * nb + b] = c > 0 ? c * sqrt(var) : 0;
            }
        }
    e->samples = n;
    return RP_OK;
}

static const rp_solver_type lt_type = {
    .name = "lighttrace",
    .summary = "light tracing: particles from the emitters, surface flux tallies and splats to the camera, "
               "Russian roulette on reflectance (Arvo & Kirk 1990; unbiased; a plugin)",
    .options = lt_options,
    .state_size = sizeof(lt_state),
    .init = lt_init,
    .step = lt_step,
    .estimate = lt_estimate,
    .fini = lt_fini,
    .iteration_name = "batches",
    .monte_carlo = 1,
    .samples_name = "particles",
};

rp_status rp_plugin_init(const rp_plugin_host *host, int abi, rp_error *err)
{
    (void)abi; /* equal to RP_PLUGIN_ABI: radpt checked rp_plugin_abi */
    return host->register_type(host, &lt_type, err);
}
