/* A solution mesh separate from the ray mesh: see simplify.h. */
#include "simplify.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cgal/simplify.h"
#include "log.h"

static double seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

struct rp_solution {
    const rp_scene *full;
    rp_scene *scene;          /* solved on (owned) */
    uint32_t *face_map;       /* per full face: its copy, RP_NONE on a simplified surface */
    uint32_t *vtx_face;       /* per full vertex: solution face of its image, RP_NONE if none */
    double *vtx_w;            /* 3 per full vertex: barycentric weights there */
    size_t nsimplified;
    double max_distance;
};

void rp_solution_destroy(rp_solution *sol)
{
    if (!sol)
        return;
    rp_scene_destroy(sol->scene);
    rp_solution_drop_maps(sol);
    free(sol);
}

/* One dense surface's triangles in local vertex numbering. */
typedef struct local_mesh {
    double *xyz;
    uint32_t *tri;
    uint32_t *global;   /* local vertex -> full scene vertex */
    size_t nv, nt;
} local_mesh;

static void local_free(local_mesh *m)
{
    free(m->xyz);
    free(m->tri);
    free(m->global);
    memset(m, 0, sizeof *m);
}

/* 1 if the surface is made of triangles only and has enough of them. */
static int dense_triangles(const rp_scene *scene, const rp_surface *sf)
{
    if (sf->kind != RP_SURFACE_MESH || sf->nfaces < RP_SIMPLIFY_MIN_FACES)
        return 0;
    const rp_face *faces = rp_scene_faces(scene);
    for (uint32_t j = 0; j < sf->nfaces; j++)
        if (faces[sf->first_face + j].nverts != 3)
            return 0;
    return 1;
}

static int local_build(const rp_scene *scene, const rp_surface *sf, uint32_t *slot, local_mesh *m)
{
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    m->nt = sf->nfaces;
    m->tri = malloc(3 * m->nt * sizeof *m->tri);
    m->xyz = malloc(9 * m->nt * sizeof *m->xyz);
    m->global = malloc(3 * m->nt * sizeof *m->global);
    if (!m->tri || !m->xyz || !m->global)
        return 0;
    m->nv = 0;
    for (uint32_t j = 0; j < sf->nfaces; j++)
        for (int k = 0; k < 3; k++) {
            uint32_t v = faces[sf->first_face + j].v[k];
            if (slot[v] == RP_NONE) {
                slot[v] = (uint32_t)m->nv;
                m->global[m->nv] = v;
                m->xyz[3 * m->nv] = V[v].x;
                m->xyz[3 * m->nv + 1] = V[v].y;
                m->xyz[3 * m->nv + 2] = V[v].z;
                m->nv++;
            }
            m->tri[3 * j + k] = slot[v];
        }
    for (size_t i = 0; i < m->nv; i++)
        slot[m->global[i]] = RP_NONE; /* ready for the next surface */
    return 1;
}

rp_status rp_solution_create(const rp_scene *full, double ratio, double tolerance_rel, int threads, rp_solution **out,
                             void (*log)(void *ctx, const char *message), void *log_ctx, rp_error *err)
{
    *out = NULL;
    if (!(ratio >= 0 && ratio < 1))
        return rp_error_set(err, RP_ERR_INPUT, "simplify: ratio %g is not in [0, 1)", ratio);
    const size_t ns = rp_scene_nsurfaces(full), nv = rp_scene_nvertices(full), nf = rp_scene_nfaces(full);
    const rp_surface *surf = rp_scene_surfaces(full);
    const double diag = rp_scene_diagonal(full);
    const double tol_rel = tolerance_rel > 0 ? tolerance_rel : ratio > 0 ? 0 : RP_SIMPLIFY_AUTO_TOLERANCE;
    rp_solution *sol = calloc(1, sizeof *sol);
    rp_simplified *simp = calloc(ns ? ns : 1, sizeof *simp);
    local_mesh *loc = calloc(ns ? ns : 1, sizeof *loc);
    rp_surface_triangles *tris = calloc(ns ? ns : 1, sizeof *tris);
    const rp_surface_triangles **replace = calloc(ns ? ns : 1, sizeof *replace);
    uint32_t *slot = malloc((nv ? nv : 1) * sizeof *slot);
    rp_status st = RP_OK;
    if (!sol || !simp || !loc || !tris || !replace || !slot) {
        st = rp_error_set(err, RP_ERR_NOMEM, "simplify: out of memory");
        goto done;
    }
    sol->full = full;
    for (size_t i = 0; i < nv; i++)
        slot[i] = RP_NONE;
    const rp_simplify_params params = {.ratio = ratio > 0 ? ratio : 1, .tolerance = tol_rel * diag, .threads = threads};
    for (size_t k = 0; k < ns; k++) {
        if (!dense_triangles(full, &surf[k]))
            continue;
        if (!local_build(full, &surf[k], slot, &loc[k])) {
            st = rp_error_set(err, RP_ERR_NOMEM, "simplify: out of memory");
            goto done;
        }
        const double t0 = seconds();
        char msg[256] = "";
        int r = rp_cgal_simplify(loc[k].xyz, loc[k].nv, loc[k].tri, loc[k].nt, &params, &simp[k], msg, sizeof msg);
        if (r < 0) {
            st = rp_error_set(err, RP_ERR_RUNTIME, "simplify: surface '%s' (%s:%d): %s", surf[k].name,
                              surf[k].file ? surf[k].file : "?", surf[k].line, msg);
            goto done;
        }
        if (r > 0) {
            rp_logf(log, log_ctx, "simplify: surface '%s' (%s:%d) kept as it is (%u triangles): %s", surf[k].name,
                    surf[k].file ? surf[k].file : "?", surf[k].line, surf[k].nfaces, msg);
            continue;
        }
        tris[k] = (rp_surface_triangles){simp[k].xyz, simp[k].nvertices, simp[k].tri, simp[k].ntriangles};
        replace[k] = &tris[k];
        sol->nsimplified++;
        double d = fmax(simp[k].max_distance_in, simp[k].max_distance_out);
        sol->max_distance = fmax(sol->max_distance, d);
        char cut[160] = "";
        if (simp[k].cut_points)
            snprintf(cut, sizeof cut, "; not a 2-manifold: cut into one at %zu duplicated points", simp[k].cut_points);
        if (simp[k].degenerate)
            snprintf(cut + strlen(cut), sizeof cut - strlen(cut),
                     "; %zu triangles with two corners at one position left out", simp[k].degenerate);
        rp_logf(log, log_ctx,
                "simplify: surface '%s' %u -> %zu triangles; largest distance between the two at their vertices "
                "%.3g (%.2g%% of the scene's diagonal)%s%s; %.2f s",
                surf[k].name, surf[k].nfaces, simp[k].ntriangles, d, diag > 0 ? 100 * d / diag : 0,
                simp[k].border_edges ? "; border edges kept" : "", cut, seconds() - t0);
    }
    size_t dropped = 0;
    if ((st = rp_scene_with_surfaces(full, replace, &sol->scene, &dropped, err)) != RP_OK)
        goto done;
    if (dropped) {
        st = rp_error_set(err, RP_ERR_RUNTIME, "simplify: %zu simplified triangles have no area", dropped);
        goto done;
    }

    /* The maps back. */
    const rp_surface *ss = rp_scene_surfaces(sol->scene);
    sol->face_map = malloc((nf ? nf : 1) * sizeof *sol->face_map);
    sol->vtx_face = malloc((nv ? nv : 1) * sizeof *sol->vtx_face);
    sol->vtx_w = calloc(nv ? 3 * nv : 1, sizeof *sol->vtx_w);
    if (!sol->face_map || !sol->vtx_face || !sol->vtx_w) {
        st = rp_error_set(err, RP_ERR_NOMEM, "simplify: out of memory");
        goto done;
    }
    for (size_t i = 0; i < nv; i++)
        sol->vtx_face[i] = RP_NONE;
    for (size_t k = 0; k < ns; k++)
        for (uint32_t j = 0; j < surf[k].nfaces; j++)
            sol->face_map[surf[k].first_face + j] = replace[k] ? RP_NONE : ss[k].first_face + j;
    for (size_t k = 0; k < ns; k++) {
        if (!replace[k])
            continue;
        for (size_t i = 0; i < loc[k].nv; i++) {
            uint32_t g = loc[k].global[i];
            sol->vtx_face[g] = ss[k].first_face + simp[k].vertex_tri[i];
            memcpy(sol->vtx_w + 3 * (size_t)g, simp[k].vertex_bary + 3 * i, 3 * sizeof *sol->vtx_w);
        }
    }

done:
    for (size_t k = 0; simp && loc && k < ns; k++) {
        rp_simplified_free(&simp[k]);
        local_free(&loc[k]);
    }
    free(simp);
    free(loc);
    free(tris);
    free(replace);
    free(slot);
    if (st != RP_OK) {
        rp_solution_destroy(sol);
        return st;
    }
    *out = sol;
    return RP_OK;
}

void rp_solution_drop_maps(rp_solution *sol)
{
    free(sol->face_map);
    free(sol->vtx_face);
    free(sol->vtx_w);
    sol->face_map = sol->vtx_face = NULL;
    sol->vtx_w = NULL;
}

const rp_scene *rp_solution_scene(const rp_solution *sol) { return sol->scene; }
size_t rp_solution_nsimplified(const rp_solution *sol) { return sol->nsimplified; }
double rp_solution_max_distance(const rp_solution *sol) { return sol->max_distance; }

/* The point of solution face f with barycentric weights w. */
static rp_vec3 face_point(const rp_scene *scene, uint32_t f, const double *w)
{
    const rp_face *fc = &rp_scene_faces(scene)[f];
    const rp_vec3 *V = rp_scene_vertices(scene);
    rp_vec3 p = rp_v3_scale(V[fc->v[0]], w[0]);
    p = rp_v3_madd(p, V[fc->v[1]], w[1]);
    return rp_v3_madd(p, V[fc->v[2]], w[2]);
}

void rp_solution_vertex_values(const rp_solution *sol, size_t nb, rp_solution_eval_fn eval, const void *ctx,
                               double *values)
{
    const size_t nv = rp_scene_nvertices(sol->full);
    for (size_t i = 0; i < nv; i++) {
        uint32_t f = sol->vtx_face[i];
        if (f != RP_NONE)
            eval(ctx, f, face_point(sol->scene, f, sol->vtx_w + 3 * i), values + i * nb);
    }
}

void rp_solution_eval(const rp_solution *sol, size_t nb, rp_solution_eval_fn eval, const void *ctx,
                      const double *values, uint32_t face, rp_vec3 p, double *out)
{
    uint32_t g = sol->face_map[face];
    if (g != RP_NONE) {
        eval(ctx, g, p, out);
        return;
    }
    /* Linear interpolation over the full triangle (barycentric weights of p). */
    const rp_face *fc = &rp_scene_faces(sol->full)[face];
    const rp_vec3 *V = rp_scene_vertices(sol->full);
    rp_vec3 a = V[fc->v[0]], e1 = rp_v3_sub(V[fc->v[1]], a), e2 = rp_v3_sub(V[fc->v[2]], a), d = rp_v3_sub(p, a);
    double d00 = rp_v3_dot(e1, e1), d01 = rp_v3_dot(e1, e2), d11 = rp_v3_dot(e2, e2);
    double d20 = rp_v3_dot(d, e1), d21 = rp_v3_dot(d, e2), den = d00 * d11 - d01 * d01;
    double v = den > 0 ? (d11 * d20 - d01 * d21) / den : 0, w = den > 0 ? (d00 * d21 - d01 * d20) / den : 0;
    v = fmin(fmax(v, 0), 1);
    w = fmin(fmax(w, 0), 1 - v);
    const double u = 1 - v - w;
    const double *b0 = values + (size_t)fc->v[0] * nb, *b1 = values + (size_t)fc->v[1] * nb,
                 *b2 = values + (size_t)fc->v[2] * nb;
    for (size_t b = 0; b < nb; b++)
        out[b] = u * b0[b] + v * b1[b] + w * b2[b];
}

/* ---- the opposite way: the same surface at four times the triangles ---- */

int rp_triangles_subdivide(const double *xyz, size_t nv, const uint32_t *tri, size_t nt, double **oxyz, size_t *onv,
                           uint32_t **otri, size_t *ont)
{
    /* one new vertex per edge, found through a hash of (min, max) */
    size_t cap = 1;
    while (cap < 6 * nt)
        cap <<= 1;
    uint64_t *key = malloc(cap * sizeof *key);
    uint32_t *val = malloc(cap * sizeof *val);
    double *x = malloc(3 * (nv + 3 * nt) * sizeof *x);
    uint32_t *t = malloc(12 * nt * sizeof *t);
    if (!key || !val || !x || !t) {
        free(key), free(val), free(x), free(t);
        return 0;
    }
    for (size_t i = 0; i < cap; i++)
        key[i] = UINT64_MAX;
    memcpy(x, xyz, 3 * nv * sizeof *x);
    size_t n = nv;
    for (size_t f = 0; f < nt; f++) {
        uint32_t c[3], m[3];
        for (int k = 0; k < 3; k++)
            c[k] = tri[3 * f + k];
        for (int k = 0; k < 3; k++) {
            uint32_t a = c[k], b = c[(k + 1) % 3];
            uint64_t kk = a < b ? ((uint64_t)a << 32 | b) : ((uint64_t)b << 32 | a);
            size_t h = (size_t)((kk * 0x9E3779B97F4A7C15ull) >> 20) & (cap - 1);
            while (key[h] != UINT64_MAX && key[h] != kk)
                h = (h + 1) & (cap - 1);
            if (key[h] == UINT64_MAX) {
                key[h] = kk;
                val[h] = (uint32_t)n;
                for (int d = 0; d < 3; d++)
                    x[3 * n + d] = 0.5 * (xyz[3 * a + d] + xyz[3 * b + d]);
                n++;
            }
            m[k] = val[h];
        }
        const uint32_t q[12] = {c[0], m[0], m[2], m[0], c[1], m[1], m[2], m[1], c[2], m[0], m[1], m[2]};
        memcpy(t + 12 * f, q, sizeof q);
    }
    free(key);
    free(val);
    *oxyz = x;
    *onv = n;
    *otri = t;
    *ont = 4 * nt;
    return 1;
}
