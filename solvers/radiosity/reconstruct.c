/* Answers from an element radiosity solution: surface averages and images
 * (reconstruct.h). */
#include "reconstruct.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "../../geometry/camera.h"

/* Small per-ray band arrays live on the stack (the solvers refuse more). */
#define RECON_MAX_BANDS 256

rp_status rp_recon_mode_parse(const char *name, rp_recon_mode *out, rp_error *err)
{
    static const char *names[] = {"flat", "gouraud", "gather"};
    for (int m = 0; m < 3; m++)
        if (strcmp(name, names[m]) == 0) {
            *out = (rp_recon_mode)m;
            return RP_OK;
        }
    return rp_error_set(err, RP_ERR_INPUT, "--reconstruct: '%s' is not flat, gouraud or gather", name);
}

const char *rp_recon_mode_name(rp_recon_mode m)
{
    switch (m) {
    case RP_RECON_FLAT: return "flat";
    case RP_RECON_GOURAUD: return "gouraud";
    case RP_RECON_GATHER: return "gather";
    }
    return "?";
}

void rp_recon_surfaces(const rp_scene *scene, const rp_mesh *mesh, size_t nb, const double *B,
                       double *out)
{
    const rp_element *el = rp_mesh_elements(mesh);
    size_t ns = rp_scene_nsurfaces(scene);
    for (size_t s = 0; s < ns; s++) {
        uint32_t first, count;
        rp_mesh_surface_elements(mesh, (uint32_t)s, &first, &count);
        double area = 0;
        double *o = out + s * nb;
        for (size_t b = 0; b < nb; b++)
            o[b] = 0;
        for (uint32_t e = first; e < first + count; e++) {
            area += el[e].area;
            for (size_t b = 0; b < nb; b++)
                o[b] += el[e].area * B[(size_t)e * nb + b];
        }
        /* Outgoing radiance of a Lambertian surface is B / pi. */
        for (size_t b = 0; b < nb; b++)
            o[b] = area > 0 ? o[b] / (area * RP_PI) : 0;
    }
}

int rp_recon_corners(const rp_mesh *mesh, size_t nb, const double *B, double *out)
{
    const rp_element *el = rp_mesh_elements(mesh);
    const size_t nv = rp_mesh_nvertices(mesh);
    size_t maxc = 0;
    for (size_t v = 0; v < nv; v++) {
        size_t cnt;
        rp_mesh_vertex_elements(mesh, (uint32_t)v, &cnt);
        maxc = cnt > maxc ? cnt : maxc;
    }
    uint32_t *group = malloc((maxc ? maxc : 1) * sizeof *group);
    double *sum = malloc((maxc ? maxc : 1) * (nb + 1) * sizeof *sum);
    if (!group || !sum) {
        free(group);
        free(sum);
        return 0;
    }
    for (size_t v = 0; v < nv; v++) {
        size_t cnt;
        const uint32_t *inc = rp_mesh_vertex_elements(mesh, (uint32_t)v, &cnt);
        /* Smoothing groups: each incident element joins the first group
         * whose first element's normal is within RP_RECON_SMOOTH_COS of its
         * own, else starts one; so every element has one group here and
         * two elements of a group interpolate the same value (no cracks). */
        size_t ng = 0;
        for (size_t k = 0; k < cnt; k++) {
            size_t g = 0;
            while (g < ng && rp_v3_dot(el[inc[group[g]]].normal, el[inc[k]].normal) < RP_RECON_SMOOTH_COS)
                g++;
            if (g == ng) {
                group[ng] = (uint32_t)k; /* first member */
                for (size_t b = 0; b <= nb; b++)
                    sum[ng * (nb + 1) + b] = 0;
                ng++;
            }
            const rp_element *e = &el[inc[k]];
            double *sg = sum + g * (nb + 1);
            for (size_t b = 0; b < nb; b++)
                sg[b] += e->area * B[(size_t)inc[k] * nb + b];
            sg[nb] += e->area;
        }
        for (size_t k = 0; k < cnt; k++) {
            size_t g = 0;
            while (rp_v3_dot(el[inc[group[g]]].normal, el[inc[k]].normal) < RP_RECON_SMOOTH_COS)
                g++;
            const rp_element *e = &el[inc[k]];
            uint32_t c = 0;
            while (c < e->nverts && e->v[c] != v)
                c++;
            const double *sg = sum + g * (nb + 1);
            double *o = out + ((size_t)inc[k] * 4 + c) * nb;
            for (size_t b = 0; b < nb; b++)
                o[b] = sg[nb] > 0 ? sg[b] / sg[nb] : 0;
        }
    }
    free(group);
    free(sum);
    return 1;
}

/* Counter-based random numbers: a pure function of (seed, stream, index,
 * dimension), so no pixel's value depends on which thread computed it.
 * splitmix64's output function (Steele, Lea & Flood 2014) as the mixer. */
static inline uint64_t recon_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static inline uint64_t recon_key(uint64_t seed, uint64_t a, uint64_t b)
{
    return recon_mix(recon_mix(recon_mix(seed ^ UINT64_C(0x7ad10517c0ffee)) ^ a) + b);
}

/* A uniform number in [0, 1) for dimension d of a key. */
static inline double recon_u01(uint64_t key, uint64_t d)
{
    return (double)(recon_mix(key + (d + 1) * UINT64_C(0x9e3779b97f4a7c15)) >> 11) * 0x1.0p-53;
}

void rp_recon_strata(uint64_t key, unsigned n, uint32_t *perm, double *xy)
{
    unsigned m = (unsigned)floor(sqrt((double)n) + 0.5);
    if (m * m == n) {
        for (unsigned k = 0; k < n; k++) {
            xy[2 * k] = ((k % m) + recon_u01(key, 2 * (uint64_t)k)) / m;
            xy[2 * k + 1] = ((k / m) + recon_u01(key, 2 * (uint64_t)k + 1)) / m;
        }
        return;
    }
    for (unsigned k = 0; k < n; k++)
        perm[k] = k;
    for (unsigned k = n; k > 1; k--) { /* Fisher-Yates */
        unsigned j = (unsigned)(recon_u01(key, 2 * (uint64_t)n + k) * k);
        if (j >= k)
            j = k - 1;
        uint32_t t = perm[k - 1];
        perm[k - 1] = perm[j];
        perm[j] = t;
    }
    for (unsigned k = 0; k < n; k++) {
        xy[2 * k] = (perm[k] + recon_u01(key, 2 * (uint64_t)k)) / n;
        xy[2 * k + 1] = (k + recon_u01(key, 2 * (uint64_t)k + 1)) / n;
    }
}

/* 1 when every face emits the same Le in every band (a furnace). */
static int uniform_emission(const rp_scene *scene, size_t nb)
{
    const size_t nf = rp_scene_nfaces(scene);
    const rp_material *m0 = nf ? rp_scene_face_material(scene, 0) : NULL;
    for (size_t f = 1; f < nf; f++) {
        const rp_material *m = rp_scene_face_material(scene, (uint32_t)f);
        for (size_t b = 0; b < nb; b++)
            if (m->Le[b] != m0->Le[b])
                return 0;
    }
    return m0 && m0->emitter;
}

rp_status rp_recon_lights(const rp_scene *scene, rp_area_sampler **out, rp_error *err)
{
    *out = NULL;
    if (uniform_emission(scene, rp_scene_nbands(scene)))
        return RP_OK;
    rp_status st = rp_area_sampler_create(scene, RP_NONE, RP_WEIGHT_POWER, out, err);
    if (st == RP_OK && rp_area_sampler_count(*out) == 0) {
        rp_area_sampler_destroy(*out);
        *out = NULL;
    }
    return st;
}

/* Power heuristic (Veach 1997, sec. 9.2.4, beta = 2) for one sample of
 * density p against the other strategy's q, as the path tracer weighs its
 * two (pathtrace.c); the gather draws as many of each. */
static inline double recon_mis(double p, double q)
{
    return p * p / (p * p + q * q);
}

void rp_recon_final_gather(const rp_recon_gather *g, const rp_hit *h, uint64_t key, double *xy, uint32_t *perm,
                           double *L, unsigned long long *rays)
{
    const size_t nb = g->nb;
    const unsigned G = g->rays;
    const rp_material *m = rp_scene_face_material(g->scene, h->face);
    double E[RECON_MAX_BANDS], Bh[RECON_MAX_BANDS]; /* irradiance */
    for (size_t b = 0; b < nb; b++)
        E[b] = 0;
    rp_recon_strata(key, G, perm, xy);
    rp_vec3 t, bt;
    rp_v3_basis(h->n, &t, &bt);
    for (unsigned k = 0; k < G; k++) {
        double u1 = xy[2 * k], u2 = xy[2 * k + 1];
        double r = sqrt(u1), phi = 2.0 * RP_PI * u2, c = sqrt(1.0 - u1);
        rp_vec3 wi = rp_v3_madd(rp_v3_madd(rp_v3_scale(h->n, c), t, r * cos(phi)), bt, r * sin(phi));
        rp_hit hit;
        (*rays)++;
        if (!rp_ray_closest_from(g->rc, h->p, h->n, wi, &hit) || !hit.front)
            continue;
        const rp_material *mh = rp_scene_face_material(g->scene, hit.face);
        if (!g->lights || !mh->emitter) {
            g->radiosity(g->ctx, &hit, Bh);
        } else {
            /* An emitter: B = pi Le + rho H (Cohen & Wallace 1993, eq.
             * 2.8).  Its reflected part rho H = B - pi Le is gathered here
             * in full; its emitted part pi Le is shared with the light
             * samples below by MIS, with this ray's weight.  A pure
             * emitter reflects nothing, whatever the solution says. */
            if (rp_material_pure_emitter(mh, nb))
                for (size_t b = 0; b < nb; b++)
                    Bh[b] = 0;
            else
                g->radiosity(g->ctx, &hit, Bh);
            /* both densities in solid angle at h: cos / pi and
             * pdf_A t^2 / cos_y */
            double pl = rp_area_sampler_pdf(g->lights, hit.face) * hit.t * hit.t / -rp_v3_dot(wi, hit.n);
            double w = recon_mis(c / RP_PI, pl);
            for (size_t b = 0; b < nb; b++) {
                double emitted = RP_PI * mh->Le[b], reflected = Bh[b] - emitted;
                Bh[b] = (reflected > 0 ? reflected : 0) + w * emitted;
            }
        }
        for (size_t b = 0; b < nb; b++)
            E[b] += Bh[b] / G;
    }
    if (g->lights) {
        const uint64_t lkey = recon_mix(key ^ UINT64_C(0x6c69676874730a01));
        rp_recon_strata(lkey, G, perm, xy);
        for (unsigned k = 0; k < G; k++) {
            rp_area_sample ls;
            rp_area_sampler_sample(g->lights, recon_u01(lkey, 4 * (uint64_t)G + k), xy[2 * k], xy[2 * k + 1], &ls);
            if (!(ls.pdf_area > 0))
                continue;
            rp_vec3 d = rp_v3_sub(ls.p, h->p);
            double r2 = rp_v3_dot(d, d), cx = rp_v3_dot(h->n, d), cy = -rp_v3_dot(ls.n, d);
            if (!(cx > 0 && cy > 0 && r2 > 0))
                continue;
            (*rays)++;
            if (rp_ray_occluded(g->rc, h->p, h->n, ls.p, ls.n))
                continue;
            /* Irradiance Le cos_x cos_y / r^2 over the area density, MIS
             * weighted against the cosine rays (densities in solid angle:
             * pdf_A r^2 / cos_y and cos_x / pi). */
            double dist = sqrt(r2);
            double w = cx * cy / (r2 * r2 * ls.pdf_area * G) *
                       recon_mis(ls.pdf_area * r2 * dist / cy, cx / (dist * RP_PI));
            const rp_material *me = rp_scene_face_material(g->scene, ls.face);
            for (size_t b = 0; b < nb; b++)
                E[b] += me->Le[b] * w;
        }
    }
    for (size_t b = 0; b < nb; b++)
        L[b] = m->Le[b] + m->rho[b] / RP_PI * E[b];
}

typedef struct recon_job {
    const rp_scene *scene;
    const rp_mesh *mesh;
    const rp_element *el;
    const rp_raycast *rc;
    const rp_recon_params *p;
    size_t nb;
    const double *B;        /* elements x nb */
    const double *CB;       /* elements x 4 corners x nb (gouraud) */
    rp_recon_gather gather; /* (gather) */
    double *vtx;            /* --simplify: the solution at the full mesh's vertices */
} recon_job;

/* B at point p of face `face` of the mesh's scene: the element's value. */
static void eval_flat(const void *ctx, uint32_t face, rp_vec3 p, double *B)
{
    const recon_job *j = ctx;
    uint32_t e = rp_mesh_locate(j->mesh, face, p);
    for (size_t b = 0; b < j->nb; b++)
        B[b] = e == RP_NONE ? 0 : j->B[(size_t)e * j->nb + b];
}

/* B there interpolated from the element's corners. */
static void eval_gouraud(const void *ctx, uint32_t face, rp_vec3 p, double *B)
{
    const recon_job *j = ctx;
    uint32_t e = rp_mesh_locate(j->mesh, face, p);
    for (size_t b = 0; b < j->nb; b++)
        B[b] = 0;
    if (e == RP_NONE)
        return;
    double w[4];
    rp_mesh_element_weights(j->mesh, e, p, w);
    for (uint32_t k = 0; k < j->el[e].nverts; k++)
        for (size_t b = 0; b < j->nb; b++)
            B[b] += w[k] * j->CB[((size_t)e * 4 + k) * j->nb + b];
}

/* --simplify: radiance leaving the front of a full face hit. */
static void recon_shade_mapped(const void *ctx, const rp_hit *h, uint64_t key, double *xy_gather, uint32_t *perm,
                               double *L, unsigned long long *rays)
{
    const recon_job *j = ctx;
    for (size_t b = 0; b < j->nb; b++)
        L[b] = 0;
    if (!h->front)
        return;
    if (j->p->mode == RP_RECON_GATHER) {
        rp_recon_final_gather(&j->gather, h, key, xy_gather, perm, L, rays);
        return;
    }
    rp_solution_eval(j->p->view.sol, j->nb, j->p->mode == RP_RECON_GOURAUD ? eval_gouraud : eval_flat, j, j->vtx, h->face,
                     h->p, L);
    for (size_t b = 0; b < j->nb; b++)
        L[b] /= RP_PI;
}

/* --simplify: the solution at a gather ray's hit on the full scene. */
static void mapped_radiosity(const void *ctx, const rp_hit *g, double *B)
{
    const recon_job *j = ctx;
    rp_solution_eval(j->p->view.sol, j->nb, eval_flat, j, j->vtx, g->face, g->p, B);
}

/* Radiance leaving the front of the element hit towards the camera. */
static void recon_shade(const void *ctx, const rp_hit *h, uint64_t key, double *xy_gather, uint32_t *perm,
                        double *L, unsigned long long *rays)
{
    const recon_job *j = ctx;
    const size_t nb = j->nb;
    uint32_t e = h->element;
    for (size_t b = 0; b < nb; b++)
        L[b] = 0;
    if (!h->front || e == RP_NONE)
        return; /* the back of a face is black */
    switch (j->p->mode) {
    case RP_RECON_FLAT:
        for (size_t b = 0; b < nb; b++)
            L[b] = j->B[(size_t)e * nb + b] / RP_PI;
        return;
    case RP_RECON_GOURAUD: {
        double w[4];
        rp_mesh_element_weights(j->mesh, e, h->p, w);
        const rp_element *el = &j->el[e];
        for (uint32_t k = 0; k < el->nverts; k++)
            for (size_t b = 0; b < nb; b++)
                L[b] += w[k] * j->CB[((size_t)e * 4 + k) * nb + b];
        for (size_t b = 0; b < nb; b++)
            L[b] /= RP_PI;
        return;
    }
    case RP_RECON_GATHER:
        rp_recon_final_gather(&j->gather, h, key, xy_gather, perm, L, rays);
        return;
    }
}

/* The solution at a gather ray's hit: its element's radiosity. */
static void element_radiosity(const void *ctx, const rp_hit *g, double *B)
{
    const recon_job *j = ctx;
    for (size_t b = 0; b < j->nb; b++)
        B[b] = g->element == RP_NONE ? 0 : j->B[(size_t)g->element * j->nb + b];
}

/* An image needs a camera, and the shaders' per-band arrays room for nb. */
static rp_status recon_check(const rp_scene *scene, size_t nb, rp_error *err)
{
    if (!rp_scene_camera(scene))
        return rp_error_set(err, RP_ERR_INPUT, "the scene has no camera to render from");
    if (nb == 0 || nb > RECON_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "%zu bands (at most %d)", nb, RECON_MAX_BANDS);
    return RP_OK;
}

rp_status rp_recon_camera(const rp_scene *scene, const rp_raycast *rc, unsigned spp, uint64_t seed,
                          int threads, size_t nb, const rp_recon_shader *shader, float *out,
                          float *variance, double *rays, rp_error *err)
{
    rp_status cst = recon_check(scene, nb, err);
    if (cst != RP_OK)
        return cst;
    const rp_camera *cam = rp_scene_camera(scene);
    if (spp == 0 || shader->samples == 0)
        return rp_error_set(err, RP_ERR_INPUT, "no camera or gather rays asked for");
    rp_camera_frame frame;
    rp_camera_frame_init(&frame, cam);
    const uint32_t W = cam->width, H = cam->height;
    const unsigned G = shader->samples;
    const unsigned nperm = spp > G ? spp : G;
    unsigned long long nrays = 0;
    int failed = 0;

#pragma omp parallel num_threads(threads) reduction(+ : nrays)
    {
        double *xy = malloc(2 * (size_t)spp * sizeof *xy);
        double *xyg = malloc(2 * (size_t)G * sizeof *xyg);
        uint32_t *perm = malloc((size_t)nperm * sizeof *perm);
        if (!xy || !xyg || !perm) {
#pragma omp atomic write
            failed = 1;
        }
        /* Every thread takes part in the loop (a worksharing construct
         * must be met by all); one without scratch skips its rows. */
#pragma omp for schedule(dynamic, 1)
        for (long y = 0; y < (long)H; y++) {
            if (!xy || !xyg || !perm)
                continue;
            double L[RECON_MAX_BANDS], sum[RECON_MAX_BANDS], sq[RECON_MAX_BANDS];
            for (uint32_t x = 0; x < W; x++) {
                uint64_t pix = (uint64_t)y * W + x;
                rp_recon_strata(recon_key(seed, pix, 0), spp, perm, xy);
                for (size_t b = 0; b < nb; b++)
                    sum[b] = sq[b] = 0;
                for (unsigned k = 0; k < spp; k++) {
                    rp_vec3 d = rp_camera_direction(&frame, x + xy[2 * k], (double)y + xy[2 * k + 1]);
                    rp_hit h;
                    nrays++;
                    if (!rp_ray_closest(rc, frame.eye, d, INFINITY, &h))
                        continue; /* a miss is black */
                    shader->shade(shader->ctx, &h, recon_key(seed, pix, (uint64_t)k + 1), xyg, perm, L, &nrays);
                    for (size_t b = 0; b < nb; b++) {
                        sum[b] += L[b];
                        sq[b] += L[b] * L[b];
                    }
                }
                float *o = out + pix * nb;
                for (size_t b = 0; b < nb; b++)
                    o[b] = (float)(sum[b] / spp);
                if (variance) {
                    /* Sample variance / spp (stratification makes it an
                     * overestimate); infinite from a single sample. */
                    float *v = variance + pix * nb;
                    for (size_t b = 0; b < nb; b++) {
                        double var = spp > 1 ? (sq[b] - sum[b] * sum[b] / spp) / (spp - 1) / spp : INFINITY;
                        v[b] = (float)(var > 0 ? var : 0);
                    }
                }
            }
        }
        free(xy);
        free(xyg);
        free(perm);
    }
    if (failed)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory for image scratch");
    if (rays)
        *rays += (double)nrays;
    return RP_OK;
}

rp_status rp_recon_image(const rp_scene *scene, const rp_mesh *mesh, const rp_raycast *rc,
                         const rp_recon_params *p, size_t nb, const double *B, float *out,
                         float *variance, double *rays, rp_error *err)
{
    rp_status st = recon_check(scene, nb, err);
    if (st == RP_OK)
        st = rp_recon_view_check(&p->view, err);
    if (st != RP_OK)
        return st;
    if (p->spp == 0 || (p->mode == RP_RECON_GATHER && p->gather_rays == 0))
        return rp_error_set(err, RP_ERR_INPUT, "no camera or gather rays asked for");

    const size_t n = rp_mesh_nelements(mesh);
    recon_job job = {.scene = scene, .mesh = mesh, .el = rp_mesh_elements(mesh), .rc = rc,
                     .p = p, .nb = nb, .B = B};
    double *CB = NULL;
    rp_area_sampler *lights = NULL;
    if (p->mode == RP_RECON_GOURAUD) {
        CB = malloc((n ? n : 1) * 4 * nb * sizeof *CB);
        if (!CB || !rp_recon_corners(mesh, nb, B, CB)) {
            free(CB);
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for vertex radiosities");
        }
        job.CB = CB;
    }
    /* With --simplify the camera and the gather see the full scene. */
    const rp_scene *view = p->view.sol ? p->view.scene : scene;
    const rp_raycast *vrc = p->view.sol ? p->view.rc : rc;
    if (p->view.sol) {
        const size_t nv = rp_scene_nvertices(view);
        if (!(job.vtx = calloc(nv ? nv * nb : 1, sizeof *job.vtx))) {
            free(CB);
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for vertex radiosities");
        }
        rp_solution_vertex_values(p->view.sol, nb, p->mode == RP_RECON_GOURAUD ? eval_gouraud : eval_flat, &job,
                                  job.vtx);
    }
    if (p->mode == RP_RECON_GATHER) {
        if ((st = rp_recon_lights(view, &lights, err)) != RP_OK) {
            free(CB);
            free(job.vtx);
            return st;
        }
        job.gather = (rp_recon_gather){.scene = view, .rc = vrc, .lights = lights, .rays = p->gather_rays,
                                       .nb = nb, .radiosity = p->view.sol ? mapped_radiosity : element_radiosity,
                                       .ctx = &job};
    }
    rp_recon_shader shader = {p->view.sol ? recon_shade_mapped : recon_shade, &job,
                              p->mode == RP_RECON_GATHER ? p->gather_rays : 1};
    st = rp_recon_camera(view, vrc, p->spp, p->seed, p->threads, nb, &shader, out, variance, rays, err);
    free(CB);
    free(job.vtx);
    rp_area_sampler_destroy(lights);
    return st;
}

rp_status rp_recon_view_init(rp_recon_view *v, const rp_options *o, const rp_scene *scene, const rp_scene **solve,
                             rp_error *err)
{
    v->scene = scene;
    v->rc = NULL;
    *solve = scene;
    rp_status st = rp_options_simplify(o, scene, &v->sol, err);
    if (st == RP_OK && v->sol)
        *solve = rp_solution_scene(v->sol);
    return st;
}

rp_status rp_recon_view_rays(rp_recon_view *v, const rp_options *o, rp_raycast *rc, rp_error *err)
{
    if (!v->sol) {
        v->rc = rc;
        return RP_OK;
    }
    /* Only the camera looks at the full scene: a run that asks for surface
     * averages alone (probe) does without its raycaster, whose BVH is most
     * of what the full mesh costs (about 9 MB for the bunny's 75k
     * triangles); rp_recon_view_check refuses an image then. */
    if (rp_options_image_unwanted(o))
        return RP_OK;
    rp_status st = rp_raycast_create(v->scene, NULL, &v->rc, err);
    if (st == RP_OK)
        st = rp_options_ray_offset(o, v->rc, err);
    return st;
}

rp_status rp_recon_view_check(const rp_recon_view *v, rp_error *err)
{
    if (v->sol && !v->rc)
        return rp_error_set(err, RP_ERR_UNSUPPORTED,
                            "an image from a run that asked only for surface averages (options.want)");
    return RP_OK;
}

void rp_recon_view_fini(rp_recon_view *v)
{
    if (v->sol) {
        rp_raycast_destroy(v->rc);
        rp_solution_destroy(v->sol);
    }
    memset(v, 0, sizeof *v);
}
