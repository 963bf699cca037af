/* Tests of the Embree ray caster (geometry/raycast.h).
 *
 * Closest hits are checked against a brute-force double-precision
 * Moller-Trumbore intersection (Moller & Trumbore 1997) over every face,
 * written here and independent of Embree; occlusion against the closed-form
 * midpoint of a segment between two parallel planes; self-intersection with
 * 1e5 grazing rays, and on a face 2e6 wide 3.7e7 from the origin against
 * the double-precision distance to a wall across it; a 1e-4 gap beside a
 * black plane 1e8 wide; element ids against a point-in-polygon search over the
 * face's elements.  Scenes come from rp_scene_parse.  Also a smoke test of
 * the ray-throughput benchmark (bench/run/raybench.h). */
#include <criterion/criterion.h>

#include <float.h>
#include <gsl/gsl_rng.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/run/raybench.h"
#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"

#define PI 3.14159265358979323846

/* ---- scene text ------------------------------------------------------- */

typedef struct text {
    char *buf;
    size_t len;
    FILE *f;
} text;

static void text_begin(text *t)
{
    t->buf = NULL;
    t->len = 0;
    t->f = open_memstream(&t->buf, &t->len);
    cr_assert(t->f);
    fputs("bands grey\nmaterial w reflect 0.5\nmaterial lamp reflect 0 emit 1\n", t->f);
}

static rp_scene *text_parse(text *t)
{
    fclose(t->f);
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_parse(t->buf, "test.scene", NULL, &s, &err);
    cr_assert_eq(st, RP_OK, "scene: %s\n%s", err.message, t->buf);
    free(t->buf);
    return s;
}

static void put_v(FILE *f, rp_vec3 v)
{
    fprintf(f, " %.17g %.17g %.17g", v.x, v.y, v.z);
}

static void put_quad(text *t, const char *name, const char *mat, rp_vec3 a, rp_vec3 b, rp_vec3 c,
                     rp_vec3 d)
{
    fprintf(t->f, "quad %s %s", name, mat);
    put_v(t->f, a);
    put_v(t->f, b);
    put_v(t->f, c);
    put_v(t->f, d);
    fputc('\n', t->f);
}

static void put_tri(text *t, const char *name, const char *mat, rp_vec3 a, rp_vec3 b, rp_vec3 c)
{
    fprintf(t->f, "triangle %s %s", name, mat);
    put_v(t->f, a);
    put_v(t->f, b);
    put_v(t->f, c);
    fputc('\n', t->f);
}

static rp_raycast *make_rc(const rp_scene *s, const rp_mesh *m)
{
    rp_raycast *rc = NULL;
    rp_error err = {""};
    rp_status st = rp_raycast_create(s, m, &rc, &err);
    cr_assert_eq(st, RP_OK, "raycast: %s", err.message);
    return rc;
}

static rp_vec3 rnd_unit(gsl_rng *r)
{
    double z = 2 * gsl_rng_uniform(r) - 1, phi = 2 * PI * gsl_rng_uniform(r);
    double s = sqrt(1 - z * z);
    return rp_v3(s * cos(phi), s * sin(phi), z);
}

static rp_vec3 rnd_box(gsl_rng *r, double lo, double hi)
{
    return rp_v3(lo + (hi - lo) * gsl_rng_uniform(r), lo + (hi - lo) * gsl_rng_uniform(r),
                 lo + (hi - lo) * gsl_rng_uniform(r));
}

/* ---- brute force ------------------------------------------------------ */

/* Moller-Trumbore: t of the hit of o + t d with triangle (a, b, c), or -1. */
static double mt_intersect(rp_vec3 o, rp_vec3 d, rp_vec3 a, rp_vec3 b, rp_vec3 c)
{
    rp_vec3 e1 = rp_v3_sub(b, a), e2 = rp_v3_sub(c, a);
    rp_vec3 pv = rp_v3_cross(d, e2);
    double det = rp_v3_dot(e1, pv);
    if (fabs(det) < 1e-300)
        return -1;
    double inv = 1.0 / det;
    rp_vec3 tv = rp_v3_sub(o, a);
    double u = rp_v3_dot(tv, pv) * inv;
    if (u < 0 || u > 1)
        return -1;
    rp_vec3 qv = rp_v3_cross(tv, e1);
    double v = rp_v3_dot(d, qv) * inv;
    if (v < 0 || u + v > 1)
        return -1;
    double t = rp_v3_dot(e2, qv) * inv;
    return t > 0 ? t : -1;
}

typedef struct bf_face {
    rp_vec3 v[4];
    int nv;
    rp_vec3 n; /* unit, from the vertices */
    double size; /* sqrt(area) */
} bf_face;

static bf_face *bf_faces(const rp_scene *s)
{
    size_t nf = rp_scene_nfaces(s);
    const rp_face *f = rp_scene_faces(s);
    const rp_vec3 *v = rp_scene_vertices(s);
    bf_face *out = calloc(nf, sizeof *out);
    for (size_t i = 0; i < nf; i++) {
        out[i].nv = (int)f[i].nverts;
        for (int k = 0; k < out[i].nv; k++)
            out[i].v[k] = v[f[i].v[k]];
        rp_vec3 c = rp_v3_cross(rp_v3_sub(out[i].v[1], out[i].v[0]),
                                rp_v3_sub(out[i].v[out[i].nv - 1], out[i].v[0]));
        double area = 0.5 * rp_v3_length(c) * (out[i].nv == 4 ? 2 : 1);
        out[i].n = rp_v3_normalize(c);
        out[i].size = sqrt(area);
    }
    return out;
}

static double bf_face_t(const bf_face *f, rp_vec3 o, rp_vec3 d)
{
    double t = mt_intersect(o, d, f->v[0], f->v[1], f->v[2]);
    if (f->nv == 4) {
        double t2 = mt_intersect(o, d, f->v[0], f->v[2], f->v[3]);
        if (t2 > 0 && (t < 0 || t2 < t))
            t = t2;
    }
    return t;
}

/* Smallest distance, relative to the face's size, from where the ray
 * crosses the face's plane to the face's boundary (inside or out); a ray
 * that close to an edge may fall on either side in float. */
static double bf_edge_margin(const bf_face *f, rp_vec3 o, rp_vec3 d)
{
    double dn = rp_v3_dot(d, f->n);
    if (fabs(dn) < 1e-12)
        return 0;
    double t = rp_v3_dot(rp_v3_sub(f->v[0], o), f->n) / dn;
    if (t <= 0)
        return INFINITY;
    rp_vec3 p = rp_v3_madd(o, d, t);
    double m = INFINITY;
    for (int k = 0; k < f->nv; k++) {
        rp_vec3 a = f->v[k], b = f->v[(k + 1) % f->nv];
        rp_vec3 e = rp_v3_sub(b, a);
        double dist = rp_v3_dot(rp_v3_cross(e, rp_v3_sub(p, a)), f->n) / rp_v3_length(e);
        if (fabs(dist) < m)
            m = fabs(dist);
    }
    return m / f->size;
}

/* ---- closest hits against brute force --------------------------------- */

/* A few hundred random triangles and planar convex quads in [-1, 1]^3 (the
 * quads: four points on a circle at angles near 0, 90, 180, 270 degrees). */
static rp_scene *random_scene(gsl_rng *r, int ntri, int nquad)
{
    text t;
    text_begin(&t);
    char name[32];
    for (int i = 0; i < ntri; i++) {
        rp_vec3 c = rnd_box(r, -1, 1);
        rp_vec3 a = rp_v3_madd(c, rnd_unit(r), 0.05 + 0.25 * gsl_rng_uniform(r));
        rp_vec3 b = rp_v3_madd(c, rnd_unit(r), 0.05 + 0.25 * gsl_rng_uniform(r));
        rp_vec3 e = rp_v3_madd(c, rnd_unit(r), 0.05 + 0.25 * gsl_rng_uniform(r));
        snprintf(name, sizeof name, "t%d", i);
        put_tri(&t, name, i == 0 ? "lamp" : "w", a, b, e);
    }
    for (int i = 0; i < nquad; i++) {
        rp_vec3 c = rnd_box(r, -1, 1), n = rnd_unit(r), e1, e2;
        rp_v3_basis(n, &e1, &e2);
        double rad = 0.05 + 0.25 * gsl_rng_uniform(r);
        rp_vec3 p[4];
        for (int k = 0; k < 4; k++) {
            double a = k * PI / 2 + 0.6 * (gsl_rng_uniform(r) - 0.5);
            p[k] = rp_v3_add(c, rp_v3_add(rp_v3_scale(e1, rad * cos(a)), rp_v3_scale(e2, rad * sin(a))));
        }
        snprintf(name, sizeof name, "q%d", i);
        put_quad(&t, name, "w", p[0], p[1], p[2], p[3]);
    }
    return text_parse(&t);
}

/* A generator seeded with seed, a random scene of 100 triangles and 100
 * quads drawn from it, and its ray caster. */
static rp_raycast *random_rc(unsigned long seed, gsl_rng **r, rp_scene **s)
{
    *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(*r, seed);
    *s = random_scene(*r, 100, 100);
    return make_rc(*s, NULL);
}

Test(raycast, closest_hit_matches_brute_force)
{
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 12345);
    rp_scene *s = random_scene(r, 150, 150);
    size_t nf = rp_scene_nfaces(s);
    cr_assert_eq(nf, 300);
    const rp_face *faces = rp_scene_faces(s);
    bf_face *bf = bf_faces(s);
    rp_raycast *rc = make_rc(s, NULL);

    const int nrays = 20000;
    int checked = 0, hits = 0, ambiguous = 0;
    for (int i = 0; i < nrays; i++) {
        rp_vec3 o = rnd_box(r, -1.5, 1.5), d = rnd_unit(r);
        double best = INFINITY, second = INFINITY, margin = INFINITY;
        uint32_t bf_face_id = RP_NONE;
        for (size_t f = 0; f < nf; f++) {
            double t = bf_face_t(&bf[f], o, d);
            double m = bf_edge_margin(&bf[f], o, d);
            if (m < margin)
                margin = m;
            if (t > 0 && t < best) {
                second = best;
                best = t;
                bf_face_id = (uint32_t)f;
            } else if (t > 0 && t < second) {
                second = t;
            }
        }
        /* Near-ties: a ray within 1e-5 of some face's edge (relative to the
         * face), or two faces within 1e-4 relative distance of each other. */
        if (margin < 1e-5 || (isfinite(second) && second - best < 1e-4 * best)) {
            ambiguous++;
            continue;
        }
        checked++;
        rp_hit h;
        int got = rp_ray_closest(rc, o, d, INFINITY, &h);
        cr_assert_eq(got, bf_face_id != RP_NONE, "ray %d: hit %d, brute force %s", i, got,
                     bf_face_id != RP_NONE ? "hit" : "miss");
        if (!got)
            continue;
        hits++;
        cr_assert_eq(h.face, bf_face_id, "ray %d: face %u, brute force %u", i, h.face, bf_face_id);
        cr_assert(fabs(h.t - best) <= 1e-4 * best, "ray %d: t %.9g, brute force %.9g", i, h.t, best);
        cr_assert_eq(h.front, rp_v3_dot(d, bf[bf_face_id].n) < 0, "ray %d: front flag", i);
        cr_assert_eq(h.surface, faces[h.face].surface);
        cr_assert_eq(h.element, RP_NONE);
        rp_vec3 p = rp_v3_madd(o, d, best);
        cr_assert(rp_v3_length(rp_v3_sub(h.p, p)) <= 1e-4 * (1 + best), "ray %d: hit point", i);
        cr_assert(fabs(rp_v3_dot(h.n, bf[bf_face_id].n) - 1) < 1e-9, "ray %d: normal", i);

        /* tmax short of the closest hit: nothing closer exists. */
        rp_hit h2;
        cr_assert_eq(rp_ray_closest(rc, o, d, 0.999 * best, &h2), 0, "ray %d: tmax", i);
        /* d need not be unit: t stays a distance. */
        cr_assert_eq(rp_ray_closest(rc, o, rp_v3_scale(d, 7.5), INFINITY, &h2), 1);
        cr_assert_eq(h2.face, h.face);
        cr_assert(fabs(h2.t - h.t) <= 1e-6 * h.t);
    }
    cr_log_info("%d rays: %d checked, %d hits, %d ambiguous", nrays, checked, hits, ambiguous);
    /* The test must test: most rays unambiguous, a good share of them hits. */
    cr_assert_lt(ambiguous, nrays / 50, "%d of %d rays ambiguous", ambiguous, nrays);
    cr_assert_gt(hits, checked / 10, "%d hits out of %d rays", hits, checked);

    rp_raycast_destroy(rc);
    free(bf);
    rp_scene_destroy(s);
    gsl_rng_free(r);
}

Test(raycast, stream_matches_single_rays)
{
    gsl_rng *r;
    rp_scene *s;
    rp_raycast *rc = random_rc(777, &r, &s);
    enum { N = 1000 }; /* not a multiple of the stream length */
    rp_vec3 *o = malloc(N * sizeof *o), *d = malloc(N * sizeof *d);
    rp_hit *hits = malloc(N * sizeof *hits);
    unsigned char *mask = malloc(N);
    for (int i = 0; i < N; i++) {
        o[i] = rnd_box(r, -1.5, 1.5);
        d[i] = rp_v3_scale(rnd_unit(r), 0.5 + gsl_rng_uniform(r));
    }
    rp_ray_closest_n(rc, N, o, d, 2.0, hits, mask);
    int nhit = 0;
    for (int i = 0; i < N; i++) {
        rp_hit h;
        int got = rp_ray_closest(rc, o[i], d[i], 2.0, &h);
        cr_assert_eq(mask[i], got, "ray %d", i);
        if (got) {
            nhit++;
            cr_assert_eq(hits[i].face, h.face, "ray %d", i);
            cr_assert_float_eq(hits[i].t, h.t, 1e-12 * (1 + h.t), "ray %d", i);
            cr_assert(hits[i].t <= 2.0);
        }
    }
    cr_assert_gt(nhit, N / 10);
    free(o);
    free(d);
    free(hits);
    free(mask);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
    gsl_rng_free(r);
}

/* Camera-like rays from one eye through a grid, traced as a coherent
 * stream: the same faces and distances as one by one. */
Test(raycast, coherent_stream_matches_single_rays)
{
    gsl_rng *r;
    rp_scene *s;
    rp_raycast *rc = random_rc(778, &r, &s);
    enum { N = 37 * 23 }; /* rows of 37: not a multiple of the stream length */
    rp_vec3 eye = rp_v3(0.1, -0.2, -3.0);
    rp_vec3 *d = malloc(N * sizeof *d);
    rp_hit *hits = malloc(N * sizeof *hits);
    unsigned char *mask = malloc(N);
    for (int i = 0; i < N; i++)
        d[i] = rp_v3(-0.6 + 1.2 * (i % 37) / 36.0 + 0.01 * gsl_rng_uniform(r),
                     -0.6 + 1.2 * (i / 37) / 22.0 + 0.01 * gsl_rng_uniform(r), 1.0);
    rp_ray_closest_coherent(rc, N, eye, d, hits, mask);
    int nhit = 0;
    for (int i = 0; i < N; i++) {
        rp_hit h;
        int got = rp_ray_closest(rc, eye, d[i], INFINITY, &h);
        cr_assert_eq(mask[i], got, "ray %d", i);
        if (got) {
            nhit++;
            cr_assert_eq(hits[i].face, h.face, "ray %d", i);
            cr_assert_eq(hits[i].front, h.front, "ray %d", i);
            cr_assert_float_eq(hits[i].t, h.t, 1e-12 * (1 + h.t), "ray %d", i);
        }
    }
    cr_assert_gt(nhit, N / 10);
    free(d);
    free(hits);
    free(mask);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
    gsl_rng_free(r);
}

/* Segments between two parallel planes across a random scene, traced as one
 * coherent occlusion stream: the same answers as rp_ray_occluded one by one
 * (more than one stream block, some blocked and some open). */
Test(raycast, occluded_stream_matches_single_rays)
{
    gsl_rng *r;
    rp_scene *s;
    rp_raycast *rc = random_rc(779, &r, &s);
    enum { N = 150 };
    rp_vec3 a[N], b[N];
    unsigned char blocked[N];
    const rp_vec3 na = rp_v3(0, 0, 1), nb = rp_v3(0, 0, -1);
    for (int i = 0; i < N; i++) {
        a[i] = rp_v3(-1 + 2 * gsl_rng_uniform(r), -1 + 2 * gsl_rng_uniform(r), -3.0);
        b[i] = rp_v3(-1 + 2 * gsl_rng_uniform(r), -1 + 2 * gsl_rng_uniform(r), 3.0);
    }
    rp_ray_occluded_n(rc, N, a, na, b, nb, blocked);
    int nblocked = 0;
    for (int i = 0; i < N; i++) {
        cr_assert_eq(blocked[i], rp_ray_occluded(rc, a[i], na, b[i], nb), "segment %d", i);
        nblocked += blocked[i];
    }
    cr_log_info("%d of %d segments blocked", nblocked, N);
    cr_assert_gt(nblocked, N / 10);
    cr_assert_lt(nblocked, N - N / 10);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
    gsl_rng_free(r);
}

/* ---- front / back ----------------------------------------------------- */

Test(raycast, front_and_back)
{
    text t;
    text_begin(&t);
    /* Unit square in z = 0, front normal +z (counter-clockwise seen from +z). */
    put_quad(&t, "sq", "lamp", rp_v3(0, 0, 0), rp_v3(1, 0, 0), rp_v3(1, 1, 0), rp_v3(0, 1, 0));
    rp_scene *s = text_parse(&t);
    rp_raycast *rc = make_rc(s, NULL);
    rp_hit h;
    cr_assert_eq(rp_ray_closest(rc, rp_v3(0.3, 0.6, 2), rp_v3(0, 0, -1), INFINITY, &h), 1);
    cr_expect_eq(h.front, 1);
    cr_expect_float_eq(h.t, 2.0, 1e-12);
    cr_expect_float_eq(h.n.z, 1.0, 1e-15);
    /* Embree's quad parameterisation: p = v0 + u (v1 - v0) + v (v3 - v0). */
    cr_expect_float_eq(h.u, 0.3, 1e-6);
    cr_expect_float_eq(h.v, 0.6, 1e-6);
    /* The other half of the quad (u + v > 1), from behind. */
    cr_assert_eq(rp_ray_closest(rc, rp_v3(0.8, 0.7, -3), rp_v3(0, 0, 1), INFINITY, &h), 1);
    cr_expect_eq(h.front, 0);
    cr_expect_float_eq(h.t, 3.0, 1e-12);
    cr_expect_float_eq(h.u, 0.8, 1e-6);
    cr_expect_float_eq(h.v, 0.7, 1e-6);
    /* Outside the square, and pointing away from it. */
    cr_expect_eq(rp_ray_closest(rc, rp_v3(1.2, 0.5, 1), rp_v3(0, 0, -1), INFINITY, &h), 0);
    cr_expect_eq(rp_ray_closest(rc, rp_v3(0.5, 0.5, 1), rp_v3(0, 0, 1), INFINITY, &h), 0);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* ---- occlusion -------------------------------------------------------- */

/* Floor y = 0 facing up, ceiling y = 2 facing down, blocker square
 * [0.4, 0.7] x [0.2, 0.5] in y = 1.  A segment from the floor to the
 * ceiling crosses y = 1 at its midpoint. */
static rp_scene *occlusion_scene(int blocker, int blocker_up)
{
    text t;
    text_begin(&t);
    put_quad(&t, "floor", "w", rp_v3(0, 0, 0), rp_v3(0, 0, 1), rp_v3(1, 0, 1), rp_v3(1, 0, 0));
    put_quad(&t, "ceiling", "lamp", rp_v3(0, 2, 0), rp_v3(1, 2, 0), rp_v3(1, 2, 1), rp_v3(0, 2, 1));
    if (blocker && blocker_up)
        put_quad(&t, "blocker", "w", rp_v3(0.4, 1, 0.2), rp_v3(0.4, 1, 0.5), rp_v3(0.7, 1, 0.5),
                 rp_v3(0.7, 1, 0.2));
    else if (blocker)
        put_quad(&t, "blocker", "w", rp_v3(0.4, 1, 0.2), rp_v3(0.7, 1, 0.2), rp_v3(0.7, 1, 0.5),
                 rp_v3(0.4, 1, 0.5));
    return text_parse(&t);
}

static void check_occlusion(int blocker, int blocker_up)
{
    rp_scene *s = occlusion_scene(blocker, blocker_up);
    rp_raycast *rc = make_rc(s, NULL);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 99);
    rp_vec3 up = rp_v3(0, 1, 0), down = rp_v3(0, -1, 0);
    int blocked = 0, n = 0;
    for (int i = 0; i < 20000; i++) {
        rp_vec3 a = rp_v3(gsl_rng_uniform(r), 0, gsl_rng_uniform(r));
        rp_vec3 b = rp_v3(gsl_rng_uniform(r), 2, gsl_rng_uniform(r));
        double mx = 0.5 * (a.x + b.x), mz = 0.5 * (a.z + b.z);
        double edge = fmin(fmin(fabs(mx - 0.4), fabs(mx - 0.7)), fmin(fabs(mz - 0.2), fabs(mz - 0.5)));
        if (blocker && edge < 1e-5)
            continue;
        int expect = blocker && mx > 0.4 && mx < 0.7 && mz > 0.2 && mz < 0.5;
        n++;
        blocked += expect;
        cr_assert_eq(rp_ray_occluded(rc, a, up, b, down), expect, "pair %d, midpoint (%g, %g)", i,
                     mx, mz);
        /* Symmetric in its ends. */
        cr_assert_eq(rp_ray_occluded(rc, b, down, a, up), expect, "pair %d reversed", i);
    }
    /* The blocker's shadow: the midpoint of two uniform points is
     * triangular-distributed, P = F(0.7) - F(0.4) in x, F(0.5) - F(0.2) in
     * z, with F the triangular CDF on [0, 1]: 0.42 * 0.42 = 0.1764... just
     * require it to be well away from 0 so the test exercises blocking. */
    if (blocker)
        cr_assert_gt(blocked, n / 20);
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

Test(raycast, occlusion_without_blocker) { check_occlusion(0, 0); }
Test(raycast, occlusion_blocker_facing_down) { check_occlusion(1, 0); }
Test(raycast, occlusion_blocker_facing_up) { check_occlusion(1, 1); }

/* ---- epsilon and self-intersection ------------------------------------ */

/* The offset follows the point, not the scene: 1e-5 of |p - c|_inf, c the
 * centre of the lit faces' box, which a black plane does not move. */
Test(raycast, offset_follows_the_point)
{
    rp_scene *s = occlusion_scene(1, 1);
    rp_raycast *rc = make_rc(s, NULL);
    /* Lit box [0,1] x [0,2] x [0,1]: c = (0.5, 1, 0.5). */
    cr_expect_float_eq(rp_raycast_offset(rc, rp_v3(0, 0, 0)), 1e-5, 1e-18);
    cr_expect_float_eq(rp_raycast_offset(rc, rp_v3(0.5, 1.25, 0.4)), 1e-5 * 0.25, 1e-18);
    rp_raycast_set_offset(rc, 1e-3);
    cr_expect_float_eq(rp_raycast_offset(rc, rp_v3(1, 2, 1)), 1e-3, 1e-18);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);

    text t;
    text_begin(&t);
    fputs("material black reflect 0\n", t.f);
    put_quad(&t, "floor", "w", rp_v3(0, 0, 0), rp_v3(0, 0, 1), rp_v3(1, 0, 1), rp_v3(1, 0, 0));
    put_quad(&t, "ceiling", "lamp", rp_v3(0, 2, 0), rp_v3(1, 2, 0), rp_v3(1, 2, 1), rp_v3(0, 2, 1));
    put_quad(&t, "ground", "black", rp_v3(-1e8, -1, -1e8), rp_v3(-1e8, -1, 1e8), rp_v3(1e8, -1, 1e8),
             rp_v3(1e8, -1, -1e8));
    s = text_parse(&t);
    rc = make_rc(s, NULL);
    cr_expect_float_eq(rp_raycast_offset(rc, rp_v3(0, 0, 0)), 1e-5, 1e-18);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* Two parallel squares 20 offsets apart: a ray leaving one surface toward
 * the other must still find it (the offset must not jump real gaps). */
Test(raycast, small_gap_is_not_skipped)
{
    const double L = 100.0;
    /* |p - c|_inf <= L / 2 on both squares (c is their centre). */
    double gap = 20 * 1e-5 * 0.5 * L;
    text t;
    text_begin(&t);
    put_quad(&t, "a", "w", rp_v3(0, 0, 0), rp_v3(L, 0, 0), rp_v3(L, L, 0), rp_v3(0, L, 0));
    put_quad(&t, "b", "lamp", rp_v3(0, 0, gap), rp_v3(0, L, gap), rp_v3(L, L, gap), rp_v3(L, 0, gap));
    rp_scene *s = text_parse(&t);
    rp_raycast *rc = make_rc(s, NULL);
    cr_assert_leq(rp_raycast_offset(rc, rp_v3(0, 0, 0)), gap / 20 * (1 + 1e-12));
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 5);
    for (int i = 0; i < 1000; i++) {
        rp_vec3 p = rp_v3(10 + 80 * gsl_rng_uniform(r), 10 + 80 * gsl_rng_uniform(r), 0);
        rp_vec3 d = rp_v3_normalize(rp_v3(gsl_rng_uniform(r) - 0.5, gsl_rng_uniform(r) - 0.5, 1));
        rp_hit h;
        cr_assert_eq(rp_ray_closest_from(rc, p, rp_v3(0, 0, 1), d, &h), 1, "ray %d", i);
        cr_assert_eq(h.surface, 1u, "ray %d hit surface %u", i, h.surface);
        cr_assert_float_eq(h.t, gap / d.z, 1e-9 * L, "ray %d", i);
        cr_assert_eq(h.front, 1);
        /* And back down from b to a. */
        cr_assert_eq(rp_ray_closest_from(rc, h.p, h.n, rp_v3(d.x, d.y, -d.z), &h), 1);
        cr_assert_eq(h.surface, 0u);
        cr_assert_float_eq(h.p.z, 0.0, 1e-12);
    }
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* 1e5 rays leave a tilted parallelogram (far from the origin, so float
 * coordinates are coarse) at grazing angles within 0.01 degree of its plane,
 * on both sides, including exactly in the plane: none may hit its own face.
 * A wall across the parallelogram's far edge, perpendicular to it, catches
 * the rays heading that way, so they must pass over their own face. */
Test(raycast, grazing_rays_miss_their_own_face)
{
    rp_vec3 base = rp_v3(1000.0, -2000.0, 500.0);
    rp_vec3 n = rp_v3_normalize(rp_v3(1, 2, 3)), t1, t2;
    rp_v3_basis(n, &t1, &t2);
    rp_vec3 e1 = rp_v3_scale(t1, 3.0), e2 = rp_v3_scale(t2, 2.0);
    rp_vec3 v0 = base, v1 = rp_v3_add(base, e1), v3 = rp_v3_add(base, e2);
    rp_vec3 v2 = rp_v3_add(v1, e2);
    /* Wall in the plane through v1 + 0.5 t1, normal -t1, spanning
     * [-1, 3] along t2 and [-1, 1] along n. */
    rp_vec3 c = rp_v3_madd(v1, t1, 0.5);
    rp_vec3 w0 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, -1), rp_v3_scale(n, -1)));
    rp_vec3 w1 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, 3), rp_v3_scale(n, -1)));
    rp_vec3 w2 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, 3), rp_v3_scale(n, 1)));
    rp_vec3 w3 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, -1), rp_v3_scale(n, 1)));
    rp_vec3 wn = rp_v3_cross(rp_v3_sub(w1, w0), rp_v3_sub(w3, w0));
    text t;
    text_begin(&t);
    put_quad(&t, "slab", "w", v0, v1, v2, v3);
    if (rp_v3_dot(wn, t1) < 0)
        put_quad(&t, "wall", "lamp", w0, w1, w2, w3);
    else
        put_quad(&t, "wall", "lamp", w0, w3, w2, w1);
    rp_scene *s = text_parse(&t);
    rp_raycast *rc = make_rc(s, NULL);
    uint32_t own = rp_scene_surfaces(s)[0].first_face;
    cr_assert_gt(rp_v3_dot(rp_scene_faces(s)[own].normal, n), 0.999999);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 2024);
    int wall = 0;
    for (int i = 0; i < 100000; i++) {
        double a = gsl_rng_uniform(r), b = gsl_rng_uniform(r);
        rp_vec3 p = rp_v3_add(v0, rp_v3_add(rp_v3_scale(e1, a), rp_v3_scale(e2, b)));
        double phi = 2 * PI * gsl_rng_uniform(r);
        /* elevation in [-0.01, 0.01] degrees; every 16th exactly 0 */
        double el = (i % 16 == 0) ? 0.0 : (2 * gsl_rng_uniform(r) - 1) * 0.01 * PI / 180;
        rp_vec3 tang = rp_v3_add(rp_v3_scale(t1, cos(phi)), rp_v3_scale(t2, sin(phi)));
        rp_vec3 d = rp_v3_add(rp_v3_scale(tang, cos(el)), rp_v3_scale(n, sin(el)));
        rp_hit h;
        if (rp_ray_closest_from(rc, p, n, d, &h)) {
            cr_assert_neq(h.face, own, "ray %d (elevation %g rad) hit its own face at t = %g", i, el, h.t);
            /* The wall, at the distance the double-precision plane gives. */
            double tw = rp_v3_dot(rp_v3_sub(c, p), t1) / rp_v3_dot(d, t1);
            cr_assert_float_eq(h.t, tw, 1e-4 * tw, "ray %d", i);
            cr_assert_eq(h.front, 1);
            wall++;
        }
    }
    /* The wall subtends at least ~1/4 of the directions from every point. */
    cr_assert_gt(wall, 20000, "%d rays reached the wall", wall);
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* Rule 2 of raycast.c: a tilted quad 2e6 wide, centred 3.7e7 from the
 * origin, with points leaving it within 0.4 of its centre.  Its float
 * vertices (relative to the centre, ulp 0.0625) put Embree's plane up to a
 * few hundredths off, far beyond the offset there (4e-6), so only the
 * rejection of hits on the plane holding the origin keeps rays off it.
 * A small lamp wall stands across the quad 0.5 from its centre: grazing
 * rays toward it must reach it at the double-precision distance, and
 * segments to it must be clear both ways.  (An offset relative to the
 * scene's diagonal, 28 here, starts the rays above the wall.) */
Test(raycast, rays_leave_a_huge_face_far_from_the_origin)
{
    rp_vec3 base = rp_v3(3.0e7, -1.0e7, 2.0e7);
    rp_vec3 n = rp_v3_normalize(rp_v3(1, 2, 3)), t1, t2;
    rp_v3_basis(n, &t1, &t2);
    const double H = 1e6;
    rp_vec3 v0 = rp_v3_add(base, rp_v3_add(rp_v3_scale(t1, -H), rp_v3_scale(t2, -H)));
    rp_vec3 v1 = rp_v3_add(base, rp_v3_add(rp_v3_scale(t1, H), rp_v3_scale(t2, -H)));
    rp_vec3 v2 = rp_v3_add(base, rp_v3_add(rp_v3_scale(t1, H), rp_v3_scale(t2, H)));
    rp_vec3 v3 = rp_v3_add(base, rp_v3_add(rp_v3_scale(t1, -H), rp_v3_scale(t2, H)));
    rp_vec3 c = rp_v3_madd(base, t1, 0.5);
    rp_vec3 w0 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, -1), rp_v3_scale(n, -1)));
    rp_vec3 w1 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, 1), rp_v3_scale(n, -1)));
    rp_vec3 w2 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, 1), rp_v3_scale(n, 1)));
    rp_vec3 w3 = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, -1), rp_v3_scale(n, 1)));
    rp_vec3 wn = rp_v3_cross(rp_v3_sub(w1, w0), rp_v3_sub(w3, w0));
    text t;
    text_begin(&t);
    int quad_up = rp_v3_dot(rp_v3_cross(rp_v3_sub(v1, v0), rp_v3_sub(v3, v0)), n) > 0;
    if (quad_up)
        put_quad(&t, "huge", "w", v0, v1, v2, v3);
    else
        put_quad(&t, "huge", "w", v0, v3, v2, v1);
    /* the wall faces -t1, toward the points */
    if (rp_v3_dot(wn, t1) < 0)
        put_quad(&t, "wall", "lamp", w0, w1, w2, w3);
    else
        put_quad(&t, "wall", "lamp", w0, w3, w2, w1);
    rp_scene *s = text_parse(&t);
    rp_raycast *rc = make_rc(s, NULL);
    const rp_face *faces = rp_scene_faces(s);
    uint32_t own = rp_scene_surfaces(s)[0].first_face, wallf = rp_scene_surfaces(s)[1].first_face;
    rp_vec3 fn = faces[own].normal, nw = faces[wallf].normal;
    cr_assert_gt(rp_v3_dot(fn, n), 0.999999);
    cr_assert_lt(rp_v3_dot(nw, t1), -0.999999);
    cr_assert_lt(rp_raycast_offset(rc, base), 1e-3);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 77);
    int wall = 0;
    for (int i = 0; i < 20000; i++) {
        rp_vec3 p = rp_v3_add(base, rp_v3_add(rp_v3_scale(t1, 0.8 * gsl_rng_uniform(r) - 0.4),
                                              rp_v3_scale(t2, 0.8 * gsl_rng_uniform(r) - 0.4)));
        /* p on the quad's plane, as a hit point would be */
        p = rp_v3_madd(p, fn, rp_v3_dot(rp_v3_sub(v0, p), fn));
        double phi = 2 * PI * gsl_rng_uniform(r);
        /* every other ray grazing (within 0.01 degree, every 16th exactly in
         * the plane), the rest cosine-distributed */
        double el = i % 2 ? asin(sqrt(gsl_rng_uniform(r)))
                          : (i % 16 == 0 ? 0.0 : gsl_rng_uniform(r) * 0.01 * PI / 180);
        rp_vec3 tang = rp_v3_add(rp_v3_scale(t1, cos(phi)), rp_v3_scale(t2, sin(phi)));
        rp_vec3 d = rp_v3_add(rp_v3_scale(tang, cos(el)), rp_v3_scale(fn, sin(el)));
        rp_hit h;
        if (rp_ray_closest_from(rc, p, fn, d, &h)) {
            cr_assert_neq(h.face, own, "ray %d (elevation %g rad) hit its own face at t = %g", i, el, h.t);
            double tw = rp_v3_dot(rp_v3_sub(c, p), t1) / rp_v3_dot(d, t1);
            cr_assert_float_eq(h.t, tw, 1e-6 * tw, "ray %d", i);
            cr_assert_eq(h.front, 1);
            wall++;
        }
        /* a segment to a point on the wall's upper half, both ways */
        rp_vec3 y = rp_v3_add(c, rp_v3_add(rp_v3_scale(t2, 1.8 * gsl_rng_uniform(r) - 0.9),
                                           rp_v3_scale(n, 0.9 * gsl_rng_uniform(r) + 1e-3)));
        cr_assert_eq(rp_ray_occluded(rc, p, fn, y, nw), 0, "segment %d", i);
        cr_assert_eq(rp_ray_occluded(rc, y, nw, p, fn), 0, "segment %d reversed", i);
    }
    /* the wall subtends a good share of the grazing directions */
    cr_assert_gt(wall, 1000, "%d rays reached the wall", wall);
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* A gap of 1e-4 between two unit squares, next to a black ground plane
 * 1e8 wide: rays and segments from one square reach the other across the
 * gap (the offset, 1e-5 of the point's distance from the lit faces'
 * centre, is at most 5e-6 there; one relative to the scene's diagonal
 * would be 1.4e3). */
Test(raycast, tiny_gap_beside_a_huge_black_plane)
{
    const double g = 1e-4;
    text t;
    text_begin(&t);
    fputs("material black reflect 0\n", t.f);
    put_quad(&t, "a", "w", rp_v3(0, 0, 0), rp_v3(1, 0, 0), rp_v3(1, 1, 0), rp_v3(0, 1, 0));
    put_quad(&t, "b", "lamp", rp_v3(0, 0, g), rp_v3(0, 1, g), rp_v3(1, 1, g), rp_v3(1, 0, g));
    put_quad(&t, "ground", "black", rp_v3(-5e7, -5e7, -1), rp_v3(5e7, -5e7, -1), rp_v3(5e7, 5e7, -1),
             rp_v3(-5e7, 5e7, -1));
    rp_scene *s = text_parse(&t);
    rp_raycast *rc = make_rc(s, NULL);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 8);
    rp_vec3 up = rp_v3(0, 0, 1), down = rp_v3(0, 0, -1);
    for (int i = 0; i < 5000; i++) {
        rp_vec3 p = rp_v3(0.1 + 0.8 * gsl_rng_uniform(r), 0.1 + 0.8 * gsl_rng_uniform(r), 0);
        rp_vec3 d = rp_v3_normalize(rp_v3(gsl_rng_uniform(r) - 0.5, gsl_rng_uniform(r) - 0.5, 0.05 + gsl_rng_uniform(r)));
        rp_hit h;
        cr_assert_eq(rp_ray_closest_from(rc, p, up, d, &h), 1, "ray %d", i);
        cr_assert_eq(h.surface, 1u, "ray %d hit surface %u", i, h.surface);
        cr_assert_float_eq(h.t, g / d.z, 1e-9, "ray %d", i);
        cr_assert_eq(rp_ray_closest_from(rc, h.p, h.n, rp_v3(d.x, d.y, -d.z), &h), 1);
        cr_assert_eq(h.surface, 0u);
        cr_assert_float_eq(h.p.z, 0.0, 1e-12);
        rp_vec3 q = rp_v3(p.x + 0.1 * (gsl_rng_uniform(r) - 0.5), p.y + 0.1 * (gsl_rng_uniform(r) - 0.5), g);
        cr_assert_eq(rp_ray_occluded(rc, p, up, q, down), 0, "segment %d", i);
    }
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}

/* ---- elements --------------------------------------------------------- */

/* p inside (or on) the convex polygon of element e, in the plane with
 * normal n. */
static int in_element(const rp_mesh *m, uint32_t e, rp_vec3 p, double tol)
{
    const rp_element *el = &rp_mesh_elements(m)[e];
    const rp_vec3 *v = rp_mesh_vertices(m);
    for (uint32_t k = 0; k < el->nverts; k++) {
        rp_vec3 a = v[el->v[k]], b = v[el->v[(k + 1) % el->nverts]];
        if (rp_v3_dot(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(p, a)), el->normal) < -tol)
            return 0;
    }
    return 1;
}

Test(raycast, hits_name_their_element)
{
    text t;
    text_begin(&t);
    put_quad(&t, "floor", "w", rp_v3(0, 0, 0), rp_v3(0, 0, 2), rp_v3(3, 0, 2), rp_v3(3, 0, 0));
    put_tri(&t, "lamp", "lamp", rp_v3(0, 2, 0), rp_v3(3, 2, 0), rp_v3(0, 2, 2));
    rp_scene *s = text_parse(&t);
    rp_mesh_params mp = {.size = sizeof mp, .max_edge = 0.25};
    rp_mesh *m = NULL;
    rp_error err = {""};
    cr_assert_eq(rp_mesh_create(s, &mp, &m, &err), RP_OK, "%s", err.message);
    cr_assert_gt(rp_mesh_nelements(m), 50);
    rp_raycast *rc = make_rc(s, m);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 31);
    for (int i = 0; i < 5000; i++) {
        rp_vec3 o = rp_v3(3 * gsl_rng_uniform(r), 1, 2 * gsl_rng_uniform(r));
        rp_vec3 d = gsl_rng_uniform(r) < 0.5 ? rp_v3(0, -1, 0) : rp_v3(0, 1, 0);
        rp_hit h;
        if (!rp_ray_closest(rc, o, d, INFINITY, &h))
            continue;
        uint32_t first, count;
        rp_mesh_face_elements(m, h.face, &first, &count);
        cr_assert(h.element >= first && h.element < first + count, "ray %d: element %u of face %u",
                  i, h.element, h.face);
        cr_assert(in_element(m, h.element, h.p, 1e-9), "ray %d: point not in element %u", i, h.element);
        /* Unless on an element boundary, no other element contains it. */
        int containing = 0;
        for (uint32_t e = first; e < first + count; e++)
            containing += in_element(m, e, h.p, -1e-9);
        cr_assert_leq(containing, 1);
    }
    gsl_rng_free(r);
    rp_raycast_destroy(rc);
    rp_mesh_destroy(m);
    rp_scene_destroy(s);
}

/* Queries from several OpenMP threads at once give the single-thread
 * answers (the Embree scene is shared read-only). */
Test(raycast, concurrent_queries_agree)
{
    gsl_rng *r;
    rp_scene *s;
    rp_raycast *rc = random_rc(4321, &r, &s);
    enum { N = 20000 };
    rp_vec3 *o = malloc(N * sizeof *o), *d = malloc(N * sizeof *d);
    rp_hit *serial = malloc(N * sizeof *serial), *par = malloc(N * sizeof *par);
    int *got_s = malloc(N * sizeof *got_s), *got_p = malloc(N * sizeof *got_p);
    int *occ_s = malloc(N * sizeof *occ_s), *occ_p = malloc(N * sizeof *occ_p);
    for (int i = 0; i < N; i++) {
        o[i] = rnd_box(r, -1.5, 1.5);
        d[i] = rnd_unit(r);
    }
    rp_vec3 z = rp_v3(0, 0, 1);
    for (int i = 0; i < N; i++) {
        got_s[i] = rp_ray_closest(rc, o[i], d[i], INFINITY, &serial[i]);
        occ_s[i] = rp_ray_occluded(rc, o[i], z, o[(i + 1) % N], z);
    }
#pragma omp parallel for num_threads(4) schedule(dynamic, 64)
    for (int i = 0; i < N; i++) {
        got_p[i] = rp_ray_closest(rc, o[i], d[i], INFINITY, &par[i]);
        occ_p[i] = rp_ray_occluded(rc, o[i], z, o[(i + 1) % N], z);
    }
    int nhit = 0, nocc = 0;
    for (int i = 0; i < N; i++) {
        cr_assert_eq(got_p[i], got_s[i], "ray %d", i);
        cr_assert_eq(occ_p[i], occ_s[i], "segment %d", i);
        if (got_s[i]) {
            cr_assert_eq(par[i].face, serial[i].face, "ray %d", i);
            cr_assert_eq(par[i].t, serial[i].t, "ray %d", i);
        }
        nhit += got_s[i];
        nocc += occ_s[i];
    }
    cr_assert_gt(nhit, N / 10);
    cr_assert_gt(nocc, N / 10);
    cr_assert_lt(nocc, N);
    free(o);
    free(d);
    free(serial);
    free(par);
    free(got_s);
    free(got_p);
    free(occ_s);
    free(occ_p);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
    gsl_rng_free(r);
}

/* The ray-throughput benchmark runs and reports a rate; zero rays is
 * refused. */
Test(raycast, raybench_runs)
{
    rp_scene *s = occlusion_scene(1, 1);
    rp_raycast *rc = make_rc(s, NULL);
    rp_error err = {""};
    double rps = 0;
    cr_assert_eq(rp_raybench_run(s, rc, 20000, 2, 1, &rps, &err), RP_OK, "%s", err.message);
    /* Embree does millions per second; 1e4 only guards against a broken clock. */
    cr_assert(isfinite(rps) && rps > 1e4, "%g rays/s", rps);
    cr_assert_eq(rp_raybench_run(s, rc, 0, 1, 1, &rps, &err), RP_ERR_INPUT);
    rp_raycast_destroy(rc);
    rp_scene_destroy(s);
}
