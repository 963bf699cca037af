/* References and their cache (reference.h). */
#include "bench/run/reference.h"

#include "geometry/hash.h"
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "geometry/camera.h"
#include "geometry/raycast.h"
#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "bench/report/image.h"
#include "bench/run/metrics.h"
#include "bench/report/plot.h"
#include "bench/run/driver.h"
#include "bench/run/mpi.h"
#include "bench/run/resume.h"

/* Sub-pixel rays per side for the pixel mask. */
#define MASK_SUB 4

void rp_hash_text(const char *text, char out[17])
{
    snprintf(out, 17, "%016" PRIx64, rp_fnv1a64(RP_FNV1A64_INIT, text, strlen(text)));
}

/* ------------------------------------------------------------- furnace */

/* Signed volume enclosed by the faces with their front normals taken as
 * outward (divergence theorem): negative when the fronts face inward. */
static double signed_volume(const rp_scene *scene)
{
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *v = rp_scene_vertices(scene);
    double vol = 0;
    for (size_t f = 0; f < rp_scene_nfaces(scene); f++) {
        const rp_face *F = &faces[f];
        rp_vec3 a = v[F->v[0]];
        for (uint32_t k = 1; k + 1 < F->nverts; k++)
            vol += rp_v3_dot(a, rp_v3_cross(v[F->v[k]], v[F->v[k + 1]])) / 6.0;
    }
    return vol;
}

/* Every ray leaving the front of a face must land on a front face for the
 * scene to be an enclosure seen from inside; a few deterministic rays per
 * face check that (closedness and orientation are necessary, not
 * sufficient, e.g. for nested shells). */
static int rays_stay_inside(const rp_scene *scene, const rp_raycast *rc)
{
    static const double tri[4][2] = {{0.25, 0.25}, {0.5, 0.25}, {0.25, 0.5}, {0.3, 0.3}};
    static const double quad[4][2] = {{0.25, 0.25}, {0.75, 0.25}, {0.25, 0.75}, {0.6, 0.6}};
    const rp_face *faces = rp_scene_faces(scene);
    for (size_t f = 0; f < rp_scene_nfaces(scene); f++) {
        rp_vec3 n = faces[f].normal, t, b;
        rp_v3_basis(n, &t, &b);
        const double(*uv)[2] = faces[f].nverts == 4 ? quad : tri;
        for (int k = 0; k < 4; k++) {
            rp_vec3 p = rp_scene_face_point(scene, (uint32_t)f, uv[k][0], uv[k][1]);
            for (int d = 0; d < 9; d++) {
                rp_vec3 dir = n;
                if (d > 0) {
                    double phi = 2 * RP_PI * (d - 1) / 8.0 + 0.3 * k, s = sin(1.2);
                    dir = rp_v3_add(rp_v3_scale(n, cos(1.2)),
                                    rp_v3_add(rp_v3_scale(t, s * cos(phi)), rp_v3_scale(b, s * sin(phi))));
                }
                rp_hit hit;
                if (!rp_ray_closest_from(rc, p, n, dir, &hit) || !hit.front)
                    return 0;
            }
        }
    }
    return 1;
}

int rp_reference_furnace(const rp_scene *scene, double *L, rp_error *err)
{
    size_t nb = rp_scene_nbands(scene), ns = rp_scene_nsurfaces(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_material *mat = rp_scene_materials(scene);
    if (ns == 0)
        return 0;
    /* one reflectance and one emission shared by every surface */
    const rp_material *m0 = &mat[surf[0].material];
    for (size_t s = 1; s < ns; s++) {
        const rp_material *m = &mat[surf[s].material];
        for (size_t b = 0; b < nb; b++)
            if (m->rho[b] != m0->rho[b] || m->Le[b] != m0->Le[b])
                return 0;
    }
    if (!m0->emitter || rp_scene_is_closed(scene) != 1 || !(signed_volume(scene) < 0))
        return 0;
    rp_raycast *rc = NULL;
    if (rp_raycast_create(scene, NULL, &rc, err) != RP_OK)
        return -1;
    int inside = rays_stay_inside(scene, rc);
    rp_raycast_destroy(rc);
    if (!inside)
        return 0;
    /* rho = 1 (allowed: a perfect reflector) has no finite, unique furnace
     * radiance: nothing leaves the enclosure. */
    for (size_t b = 0; b < nb; b++)
        if (!(m0->rho[b] < 1)) {
            rp_error_set(err, RP_ERR_INPUT,
                         "a closed enclosure that reflects everything (reflect 1 in band %zu) has no finite "
                         "radiance (furnace: L = Le / (1 - rho))", b);
            return -2;
        }
    for (size_t b = 0; b < nb; b++)
        L[b] = m0->Le[b] / (1.0 - m0->rho[b]);
    return 1;
}

/* ---------------------------------------------------------------- mask */

/* Pixel coverage by 4 x 4 sub-pixel rays at the sub-cell centres: *front
 * counts front hits on reflecting surfaces, *bad anything else (miss, back
 * face, pure emitter). */
static rp_status cast_mask(const rp_scene *scene, unsigned char *mask, unsigned char *front_count,
                           size_t *count, rp_error *err)
{
    const rp_camera *cam = rp_scene_camera(scene);
    if (!cam)
        return rp_error_set(err, RP_ERR_INPUT, "the scene has no camera");
    rp_raycast *rc = NULL;
    rp_status st = rp_raycast_create(scene, NULL, &rc, err);
    if (st != RP_OK)
        return st;
    rp_camera_frame fr;
    rp_camera_frame_init(&fr, cam);
    const size_t nb = rp_scene_nbands(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_material *mat = rp_scene_materials(scene);
    const long npix = (long)cam->width * cam->height;
    size_t total = 0;
#pragma omp parallel for schedule(dynamic, 64) reduction(+ : total)
    for (long i = 0; i < npix; i++) {
        uint32_t x = (uint32_t)(i % cam->width), y = (uint32_t)(i / cam->width);
        int good = 0;
        for (int sy = 0; sy < MASK_SUB; sy++)
            for (int sx = 0; sx < MASK_SUB; sx++) {
                rp_vec3 d = rp_camera_direction(&fr, x + (sx + 0.5) / MASK_SUB, y + (sy + 0.5) / MASK_SUB);
                rp_hit hit;
                if (rp_ray_closest(rc, fr.eye, d, INFINITY, &hit) && hit.front &&
                    !rp_material_pure_emitter(&mat[surf[hit.surface].material], nb))
                    good++;
            }
        mask[i] = good == MASK_SUB * MASK_SUB;
        if (front_count)
            front_count[i] = (unsigned char)good;
        total += mask[i];
    }
    rp_raycast_destroy(rc);
    *count = total;
    return RP_OK;
}

rp_status rp_reference_pixel_mask(const rp_scene *scene, unsigned char *mask, size_t *count,
                                  rp_error *err)
{
    return cast_mask(scene, mask, NULL, count, err);
}

/* ----------------------------------------------------------------- key */

static void resolve(const rp_reference_params *p, unsigned long *spp, unsigned long *samples,
                    unsigned long *batch, uint64_t *seed)
{
    *spp = p && p->spp ? p->spp : RP_REFERENCE_DEFAULT_SPP;
    /* 256 probe points per surface for each sample per pixel: on the
     * Cornell box about 8% of the image's paths, and surface averages to
     * 0.5% at 256 spp, 0.2% at 2048 */
    *samples = p && p->samples ? p->samples : 256 * *spp;
    /* probe batches sized so surfaces finish with the image */
    *batch = (*samples + *spp - 1) / *spp;
    *seed = p && p->seed ? p->seed : RP_REFERENCE_SEED;
}

rp_status rp_reference_key(const rp_scene *scene, const rp_reference_params *params, char *key,
                           size_t keylen, char options_hash[17], rp_error *err)
{
    double L[64];
    size_t nb = rp_scene_nbands(scene);
    int exact = nb <= 64 ? rp_reference_furnace(scene, L, err) : 0;
    if (exact < 0)
        return exact == -2 ? RP_ERR_INPUT : RP_ERR_RUNTIME;
    if (exact)
        snprintf(key, keylen, "radpt-reference 1; exact furnace L = Le / (1 - rho)");
    else {
        unsigned long spp, samples, batch;
        uint64_t seed;
        resolve(params, &spp, &samples, &batch, &seed);
        snprintf(key, keylen,
                 "radpt-reference 1; pathtrace; sampler " RP_REFERENCE_SAMPLER "; spp %lu; samples %lu; batch %lu; "
                 "seed %" PRIu64 "; max-depth unlimited",
                 spp, samples, batch, seed);
    }
    rp_hash_text(key, options_hash);
    return RP_OK;
}

/* ------------------------------------------------------------ helpers */

void rp_reference_destroy(rp_reference *r)
{
    if (!r)
        return;
    free(r->radiance);
    free(r->variance);
    free(r->mask);
    free(r->surface_radiance);
    free(r->surface_stderr);
    free(r->surface_mask);
    free(r);
}

static void band_name(const rp_scene *scene, size_t b, char *buf, size_t n)
{
    static const char *rgb[3] = {"R", "G", "B"};
    switch (rp_scene_band_kind(scene)) {
    case RP_BANDS_GREY: snprintf(buf, n, "Y"); break;
    case RP_BANDS_RGB: snprintf(buf, n, "%s", rgb[b]); break;
    default: snprintf(buf, n, "L%g", rp_scene_wavelengths(scene)[b]); break;
    }
}

static char *join_values(const double *v, size_t n)
{
    char *s = malloc(n * 26 + 2);
    if (!s)
        return NULL;
    size_t used = 0;
    s[0] = '\0';
    for (size_t i = 0; i < n; i++)
        used += (size_t)sprintf(s + used, "%s%.17g", i ? " " : "", v[i]);
    return s;
}

static int parse_values(const char *s, double *v, size_t n)
{
    if (!s)
        return -1;
    const char *p = s;
    for (size_t i = 0; i < n; i++) {
        char *end;
        errno = 0;
        v[i] = strtod(p, &end);
        if (end == p || errno)
            return -1;
        p = end;
    }
    while (*p == ' ')
        p++;
    return *p ? -1 : 0;
}

static void finish_stats(rp_reference *r)
{
    size_t npix = (size_t)r->width * r->height;
    r->rmse_se = r->radiance ? rp_metrics_reference_rmse_se(r->variance, r->mask, npix, r->nbands) : NAN;
    double s = 0;
    size_t m = 0;
    for (size_t i = 0; i < r->nsurfaces; i++) {
        if (!r->surface_mask[i])
            continue;
        for (size_t b = 0; b < r->nbands; b++) {
            double v = r->surface_radiance[i * r->nbands + b], e = r->surface_stderr[i * r->nbands + b];
            if (v > 0) {
                s += (e / v) * (e / v);
                m++;
            }
        }
    }
    r->surface_rel_se = m ? sqrt(s / (double)m) : NAN;
}

static rp_reference *ref_alloc(const rp_scene *scene, rp_error *err)
{
    rp_reference *r = calloc(1, sizeof *r);
    if (!r) {
        rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        return NULL;
    }
    const rp_camera *cam = rp_scene_camera(scene);
    r->nbands = rp_scene_nbands(scene);
    r->nsurfaces = rp_scene_nsurfaces(scene);
    size_t ns = r->nsurfaces ? r->nsurfaces : 1;
    r->surface_radiance = calloc(ns * r->nbands, sizeof(double));
    r->surface_stderr = calloc(ns * r->nbands, sizeof(double));
    r->surface_mask = calloc(ns, 1);
    int ok = r->surface_radiance && r->surface_stderr && r->surface_mask;
    if (cam) {
        r->width = cam->width;
        r->height = cam->height;
        size_t npix = (size_t)cam->width * cam->height;
        r->radiance = calloc(npix * r->nbands, sizeof(float));
        r->mask = calloc(npix, 1);
        ok = ok && r->radiance && r->mask;
    }
    if (!ok) {
        rp_reference_destroy(r);
        rp_error_set(err, RP_ERR_NOMEM, "out of memory for the reference");
        return NULL;
    }
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_material *mat = rp_scene_materials(scene);
    for (size_t s = 0; s < r->nsurfaces; s++)
        r->surface_mask[s] = !rp_material_pure_emitter(&mat[surf[s].material], r->nbands);
    return r;
}

/* ---------------------------------------------------------- computing */

static rp_status make_exact(const rp_scene *scene, const double *L, rp_reference *r, rp_error *err)
{
    r->kind = RP_REFERENCE_EXACT;
    for (size_t s = 0; s < r->nsurfaces; s++)
        for (size_t b = 0; b < r->nbands; b++)
            r->surface_radiance[s * r->nbands + b] = L[b];
    if (!r->radiance)
        return RP_OK;
    size_t npix = (size_t)r->width * r->height;
    unsigned char *front = malloc(npix);
    if (!front)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_status st = cast_mask(scene, r->mask, front, &r->mask_count, err);
    /* Fully covered pixels are exact; partly covered ones (left out of the
     * mask) get the covered fraction of L. */
    for (size_t i = 0; st == RP_OK && i < npix; i++)
        for (size_t b = 0; b < r->nbands; b++)
            r->radiance[i * r->nbands + b] = (float)(L[b] * front[i] / (MASK_SUB * MASK_SUB));
    free(front);
    return st;
}

/* A field of rp_reference_params that the caller's struct has (it can grow). */
#define PARAM(p, field, fallback)                                                                   \
    ((p) && (p)->size >= offsetof(rp_reference_params, field) + sizeof(p)->field ? (p)->field : (fallback))

/* A reference render's state saving and stop flag, after each step of
 * the driver: the state goes to the checkpoint file every `every` seconds
 * (the totals: the resumed run's plus this run's). */
typedef struct ref_saving {
    const char *ckpt;
    double every, prior, last_ckpt;
    volatile sig_atomic_t *stop;
    rp_resume_info *id;
    rp_resume_info base; /* the totals the run resumed with */
    int based, interrupted;
} ref_saving;

static void ref_totals(ref_saving *sv, const rp_drive_totals *t)
{
    if (!sv->based) {
        sv->base = *sv->id;
        sv->based = 1;
    }
    sv->id->steps = sv->base.steps + t->steps;
    sv->id->iterations = sv->base.iterations + t->sum.iterations;
    sv->id->rays = sv->base.rays + t->sum.rays;
    sv->id->paths = sv->base.paths + t->sum.paths;
    sv->id->seconds = sv->prior + t->wall_s;
}

static int ref_after_step(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    ref_saving *sv = ctx;
    if (t->stop != RP_STOP_NONE)
        return 0;
    if (sv->stop && *sv->stop) {
        sv->interrupted = 1;
        return 1;
    }
    /* solver seconds, which all MPI ranks share (the driver's), so that
     * they save (collectively) together */
    if (sv->ckpt && t->wall_s - sv->last_ckpt >= sv->every) {
        ref_totals(sv, t);
        *st = rp_resume_save(sv->ckpt, sv->id, s, err);
        sv->last_ckpt = t->wall_s;
    }
    return 0;
}

static rp_status make_pathtraced(const rp_scene *scene, const char *scene_name, const rp_reference_params *p,
                                 rp_reference *r, rp_error *err)
{
    unsigned long spp, samples, batch;
    uint64_t seed;
    resolve(p, &spp, &samples, &batch, &seed);
    r->kind = RP_REFERENCE_PATHTRACE;
    r->spp = spp;
    r->samples = samples;
    r->seed = seed;
    char spp_s[32], samples_s[32], batch_s[32];
    snprintf(spp_s, sizeof spp_s, "%lu", spp);
    snprintf(samples_s, sizeof samples_s, "%lu", samples);
    snprintf(batch_s, sizeof batch_s, "%lu", batch);
    const char *keys[] = {"sampler", "spp", "samples", "batch"};
    const char *values[] = {RP_REFERENCE_SAMPLER, spp_s, samples_s, batch_s};
    rp_options o = {.size = sizeof o,
                    .want = RP_WANT_SURFACES | (r->radiance ? RP_WANT_IMAGE : 0),
                    .seed = seed, .threads = p ? p->threads : 0,
                    .keys = keys, .values = values, .count = 4, .cancel = PARAM(p, cancel, NULL),
                    .comm = rp_mpi_world()};
    rp_solver *solver = NULL;
    rp_status st = rp_solver_create(rp_solver_lookup("pathtrace"), scene, &o, &solver, err);
    if (st != RP_OK)
        return st;

    /* Checkpoint and resume (resume.h): the state is identified by the
     * scene hash, seed and image, and by the key as the options text. */
    const char *ckpt = PARAM(p, checkpoint, NULL), *resume = PARAM(p, resume, NULL);
    double every = PARAM(p, checkpoint_every, 60.0);
    volatile sig_atomic_t *stop = PARAM(p, stop, NULL);
    rp_resume_info id;
    memset(&id, 0, sizeof id);
    snprintf(id.scene_hash, sizeof id.scene_hash, "%s", r->scene_hash);
    snprintf(id.method, sizeof id.method, "pathtrace");
    id.seed = seed;
    id.width = r->radiance ? r->width : 0;
    id.height = r->radiance ? r->height : 0;
    id.nbands = r->nbands;
    snprintf(id.scene, sizeof id.scene, "%s", scene_name);
    snprintf(id.options, sizeof id.options, "%s", r->key);
    double prior = 0;
    int done = 0, interrupted = 0;
    if (resume) {
        rp_resume_info got;
        rp_step_info last_info;
        if ((st = rp_resume_load(resume, &id, &got, solver, &last_info, err)) != RP_OK) {
            rp_solver_destroy(solver);
            return st;
        }
        prior = got.seconds;
        id.steps = got.steps;
        id.iterations = got.iterations;
        id.rays = got.rays;
        id.paths = got.paths;
        done = last_info.converged;
    }
    ref_saving sv = {.ckpt = ckpt, .every = every, .stop = stop, .id = &id, .prior = prior};
    char label[96];
    snprintf(label, sizeof label, "reference, %lu spp", spp);
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_drive_params dp = {.size = sizeof dp, .stop_at_rule = 1, .cancel = o.cancel, .after_step = ref_after_step,
                          .ctx = &sv, .progress = p ? p->progress : NULL, .progress_ctx = p ? p->progress_ctx : NULL,
                          .label = label};
    if (!done)
        st = rp_drive(solver, &dp, &tot, err);
    if (st == RP_OK && tot.stop == RP_STOP_SIGNAL)
        st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted while rendering the reference");
    interrupted = sv.interrupted;
    ref_totals(&sv, &tot);
    r->seconds = prior + tot.wall_s;
    if (st == RP_OK && ckpt) {
        id.seconds = r->seconds;
        st = rp_resume_save(ckpt, &id, solver, err);
    }
    if (st == RP_OK && interrupted)
        st = ckpt ? rp_error_set(err, RP_ERR_RUNTIME, "interrupted; the reference render's state is in %s "
                                 "(continue it with --resume %s)", ckpt, ckpt)
                  : rp_error_set(err, RP_ERR_RUNTIME, "interrupted");
    size_t npix = (size_t)r->width * r->height;
    if (st == RP_OK && r->radiance && !(r->variance = malloc(npix * r->nbands * sizeof(float))))
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory for the reference");
    if (st == RP_OK) {
        rp_estimate e = {.radiance = r->radiance, .variance = r->variance,
                         .surface_radiance = r->surface_radiance, .surface_stderr = r->surface_stderr};
        st = rp_solver_estimate(solver, &e, err);
    }
    rp_solver_destroy(solver);
    if (st == RP_OK && r->radiance)
        st = rp_reference_pixel_mask(scene, r->mask, &r->mask_count, err);
    return st;
}

/* --------------------------------------------------------------- files */

static rp_status write_json(const rp_scene *scene, const char *scene_name, const rp_reference *r,
                            rp_error *err)
{
    rp_out o;
    rp_status st = rp_out_open(&o, r->json_path, err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    const rp_surface *surf = rp_scene_surfaces(scene);
    fprintf(f, "{\n  \"scene\": ");
    rp_json_string(f, scene_name);
    fprintf(f, ",\n  \"scene_hash\": \"%s\",\n  \"options_hash\": \"%s\",\n  \"key\": ", r->scene_hash,
            r->options_hash);
    rp_json_string(f, r->key);
    fprintf(f, ",\n  \"kind\": \"%s\",\n  \"image\": ", r->kind == RP_REFERENCE_EXACT ? "exact" : "pathtrace");
    rp_json_string(f, r->exr_path);
    if (r->kind == RP_REFERENCE_PATHTRACE)
        fprintf(f, ",\n  \"method\": \"pathtrace\", \"sampler\": \"" RP_REFERENCE_SAMPLER "\", \"spp\": %lu, \"samples\": %lu, "
                   "\"seed\": %" PRIu64 ", \"seconds\": %.3f",
                r->spp, r->samples, r->seed, r->seconds);
    fprintf(f, ",\n  \"width\": %u, \"height\": %u, \"measured_pixels\": %zu", r->width, r->height, r->mask_count);
    fprintf(f, ",\n  \"rmse_stderr\": ");
    if (isfinite(r->rmse_se))
        fprintf(f, "%.6g", r->rmse_se);
    else
        fputs("null", f);
    fprintf(f, ", \"surface_relative_stderr\": ");
    if (isfinite(r->surface_rel_se))
        fprintf(f, "%.6g", r->surface_rel_se);
    else
        fputs("null", f);
    fprintf(f, ",\n  \"bands\": [");
    for (size_t b = 0; b < r->nbands; b++) {
        char name[32];
        band_name(scene, b, name, sizeof name);
        fprintf(f, "%s\"%s\"", b ? ", " : "", name);
    }
    fprintf(f, "],\n  \"surfaces\": [");
    for (size_t s = 0; s < r->nsurfaces; s++) {
        fprintf(f, "%s\n    {\"name\": ", s ? "," : "");
        rp_json_string(f, surf[s].name);
        fprintf(f, ", \"area\": %.10g, \"measured\": %s, \"radiance\": [", surf[s].area,
                r->surface_mask[s] ? "true" : "false");
        for (size_t b = 0; b < r->nbands; b++)
            fprintf(f, "%s%.10g", b ? ", " : "", r->surface_radiance[s * r->nbands + b]);
        fprintf(f, "], \"stderr\": [");
        for (size_t b = 0; b < r->nbands; b++)
            fprintf(f, "%s%.4g", b ? ", " : "", r->surface_stderr[s * r->nbands + b]);
        fprintf(f, "]}");
    }
    fprintf(f, "\n  ]\n}\n");
    return rp_out_close(&o, 1, err);
}

static rp_status write_exr(const rp_scene *scene, const char *scene_name, const rp_reference *r,
                           rp_error *err)
{
    const size_t nb = r->nbands;
    int has_image = r->radiance != NULL;
    uint32_t w = has_image ? r->width : 1, h = has_image ? r->height : 1;
    size_t npix = (size_t)w * h;
    size_t nch = has_image ? (r->variance ? 2 * nb : nb) : 1;
    char(*names)[48] = calloc(nch, sizeof *names);
    float **planes = calloc(nch, sizeof *planes);
    const char **name_ptrs = calloc(nch, sizeof *name_ptrs);
    char *sr = join_values(r->surface_radiance, r->nsurfaces * nb);
    char *se = join_values(r->surface_stderr, r->nsurfaces * nb);
    rp_status st = RP_OK;
    if (!names || !planes || !name_ptrs || !sr || !se)
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    for (size_t c = 0; st == RP_OK && c < nch; c++) {
        if (!(planes[c] = calloc(npix, sizeof(float)))) {
            st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
            break;
        }
        name_ptrs[c] = names[c];
        if (!has_image) {
            snprintf(names[c], sizeof names[c], "none");
            continue;
        }
        size_t b = c % nb;
        char bn[32];
        band_name(scene, b, bn, sizeof bn);
        snprintf(names[c], sizeof names[c], c < nb ? "%s" : "variance.%s", bn);
        const float *src = c < nb ? r->radiance : r->variance;
        for (size_t i = 0; i < npix; i++)
            planes[c][i] = src[i * nb + b];
    }
    if (st == RP_OK) {
        char spp[32], samples[32], seed[32], secs[32];
        snprintf(spp, sizeof spp, "%lu", r->spp);
        snprintf(samples, sizeof samples, "%lu", r->samples);
        snprintf(seed, sizeof seed, "%" PRIu64, r->seed);
        snprintf(secs, sizeof secs, "%.6f", r->seconds);
        rp_image_attr attrs[] = {
            {"radpt:scene", scene_name},
            {"radpt:scene_hash", r->scene_hash},
            {"radpt:reference_key", r->key},
            {"radpt:kind", r->kind == RP_REFERENCE_EXACT ? "exact" : "pathtrace"},
            {"radpt:method", r->kind == RP_REFERENCE_EXACT ? "exact" : "pathtrace"},
            {"radpt:has_image", has_image ? "yes" : "no"},
            {"radpt:spp", spp},
            {"radpt:samples", samples},
            {"radpt:seed", seed},
            {"radpt:seconds", secs},
            {"radpt:surface_radiance", sr},
            {"radpt:surface_stderr", se},
        };
        rp_image img = {.width = w, .height = h, .nchannels = nch, .channel_names = name_ptrs,
                        .planes = (const float *const *)planes, .attrs = attrs,
                        .nattrs = sizeof attrs / sizeof attrs[0]};
        st = rp_image_write_exr(r->exr_path, &img, err);
    }
    for (size_t c = 0; planes && c < nch; c++)
        free(planes[c]);
    free(planes);
    free(names);
    free(name_ptrs);
    free(sr);
    free(se);
    return st;
}

static void free_planes(size_t n, char **names, float **planes)
{
    for (size_t c = 0; c < n; c++) {
        free(names ? names[c] : NULL);
        free(planes ? planes[c] : NULL);
    }
    free(names);
    free(planes);
}

/* Reads a cached reference; returns 0 on success, -1 when the file is not
 * usable (missing, another key, unreadable: then it is recomputed). */
static int read_cached(const rp_scene *scene, rp_reference *r)
{
    struct stat sb;
    if (stat(r->exr_path, &sb) != 0)
        return -1;
    char *key = rp_image_read_exr_attr(r->exr_path, "radpt:reference_key");
    char *hash = rp_image_read_exr_attr(r->exr_path, "radpt:scene_hash");
    int match = key && hash && strcmp(key, r->key) == 0 && strcmp(hash, r->scene_hash) == 0;
    free(key);
    free(hash);
    if (!match)
        return -1;
    char *kind = rp_image_read_exr_attr(r->exr_path, "radpt:kind");
    char *sr = rp_image_read_exr_attr(r->exr_path, "radpt:surface_radiance");
    char *se = rp_image_read_exr_attr(r->exr_path, "radpt:surface_stderr");
    char *spp = rp_image_read_exr_attr(r->exr_path, "radpt:spp");
    char *samples = rp_image_read_exr_attr(r->exr_path, "radpt:samples");
    char *seed = rp_image_read_exr_attr(r->exr_path, "radpt:seed");
    char *secs = rp_image_read_exr_attr(r->exr_path, "radpt:seconds");
    int ok = kind && sr && se && spp && samples && seed && secs;
    size_t nv = r->nsurfaces * r->nbands;
    if (ok) {
        r->kind = strcmp(kind, "exact") == 0 ? RP_REFERENCE_EXACT : RP_REFERENCE_PATHTRACE;
        r->spp = strtoul(spp, NULL, 10);
        r->samples = strtoul(samples, NULL, 10);
        r->seed = strtoull(seed, NULL, 10);
        r->seconds = strtod(secs, NULL);
        ok = parse_values(sr, r->surface_radiance, nv) == 0 && parse_values(se, r->surface_stderr, nv) == 0;
    }
    free(kind);
    free(sr);
    free(se);
    free(spp);
    free(samples);
    free(seed);
    free(secs);
    if (!ok)
        return -1;
    if (!r->radiance)
        return 0;
    uint32_t w, h;
    size_t nch;
    char **names = NULL;
    float **planes = NULL;
    rp_error e2;
    if (rp_image_read_exr(r->exr_path, &w, &h, &nch, &names, &planes, &e2) != RP_OK)
        return -1;
    ok = w == r->width && h == r->height;
    size_t npix = (size_t)w * h;
    int have_var = r->kind == RP_REFERENCE_PATHTRACE;
    if (ok && have_var && !(r->variance = malloc(npix * r->nbands * sizeof(float))))
        ok = 0;
    for (size_t b = 0; ok && b < r->nbands; b++) {
        char bn[32], vn[48];
        band_name(scene, b, bn, sizeof bn);
        snprintf(vn, sizeof vn, "variance.%s", bn);
        int found = 0, found_var = !have_var;
        for (size_t c = 0; c < nch; c++) {
            if (strcmp(names[c], bn) == 0) {
                for (size_t i = 0; i < npix; i++)
                    r->radiance[i * r->nbands + b] = planes[c][i];
                found = 1;
            } else if (have_var && strcmp(names[c], vn) == 0) {
                for (size_t i = 0; i < npix; i++)
                    r->variance[i * r->nbands + b] = planes[c][i];
                found_var = 1;
            }
        }
        ok = found && found_var;
    }
    free_planes(nch, names, planes);
    if (!ok) {
        free(r->variance);
        r->variance = NULL;
        return -1;
    }
    return 0;
}

rp_status rp_reference_get(const rp_scene *scene, const char *scene_name,
                           const rp_reference_params *params, rp_reference **out, rp_error *err)
{
    *out = NULL;
    rp_reference *r = ref_alloc(scene, err);
    if (!r)
        return RP_ERR_NOMEM;
    rp_scene_hash(scene, r->scene_hash);
    rp_status st = rp_reference_key(scene, params, r->key, sizeof r->key, r->options_hash, err);
    if (st != RP_OK) {
        rp_reference_destroy(r);
        if (st == RP_ERR_INPUT && err && scene_name) {
            char msg[sizeof err->message];
            snprintf(msg, sizeof msg, "%s", err->message);
            rp_error_set(err, st, "%s: %s", scene_name, msg);
        }
        return st;
    }
    const char *dir = params && params->cache_dir ? params->cache_dir : "refs";
    char base[64];
    snprintf(base, sizeof base, "%s-%s.exr", r->scene_hash, r->options_hash);
    rp_path_join(r->exr_path, sizeof r->exr_path, dir, base);
    snprintf(base, sizeof base, "%s-%s.json", r->scene_hash, r->options_hash);
    rp_path_join(r->json_path, sizeof r->json_path, dir, base);

    double L[64];
    int exact = r->nbands <= 64 ? rp_reference_furnace(scene, L, err) : 0;
    if (exact < 0) {
        rp_reference_destroy(r);
        return exact == -2 ? RP_ERR_INPUT : RP_ERR_RUNTIME;
    }
    if (exact)
        for (size_t b = 0; b < r->nbands; b++)
            r->exact_L[b] = L[b];

    if (!(params && params->force) && read_cached(scene, r) == 0) {
        r->cached = 1;
        if (r->radiance)
            st = rp_reference_pixel_mask(scene, r->mask, &r->mask_count, err);
        if (st == RP_OK) {
            finish_stats(r);
            if (params && params->log) {
                char msg[1400];
                if (r->kind == RP_REFERENCE_EXACT)
                    snprintf(msg, sizeof msg, "using cached reference %s (exact, furnace closed form)", r->exr_path);
                else
                    snprintf(msg, sizeof msg,
                             "using cached reference %s (pathtrace, " RP_REFERENCE_SAMPLER ", %lu spp, %lu samples per surface, "
                             "seed %" PRIu64 ", made in %.1f s)",
                             r->exr_path, r->spp, r->samples, r->seed, r->seconds);
                params->log(params->log_ctx, msg);
            }
            *out = r;
            return RP_OK;
        }
        rp_reference_destroy(r);
        return st;
    }

    if (params && params->log) {
        char msg[1400];
        if (exact)
            snprintf(msg, sizeof msg, "computing the exact reference (furnace: L = Le / (1 - rho) = %g in band 0) -> %s",
                     L[0], r->exr_path);
        else {
            unsigned long spp, samples, batch;
            uint64_t seed;
            resolve(params, &spp, &samples, &batch, &seed);
            snprintf(msg, sizeof msg, "computing a reference: pathtrace, " RP_REFERENCE_SAMPLER ", %lu spp, %lu samples per surface -> %s",
                     spp, samples, r->exr_path);
        }
        params->log(params->log_ctx, msg);
    }
    st = exact ? make_exact(scene, L, r, err) : make_pathtraced(scene, scene_name, params, r, err);
    if (st == RP_OK) {
        finish_stats(r);
        st = rp_mkdirs(dir, err);
    }
    if (st == RP_OK)
        st = write_exr(scene, scene_name, r, err);
    if (st == RP_OK)
        st = write_json(scene, scene_name, r, err);
    if (st != RP_OK) {
        rp_reference_destroy(r);
        return st;
    }
    *out = r;
    return RP_OK;
}
