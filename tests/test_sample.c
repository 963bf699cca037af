/* Tests of area sampling (geometry/sample.h).
 *
 * The alias choice is checked three ways: draw for draw against GSL's own
 * gsl_ran_discrete fed the same uniform numbers, by a chi-square test of the
 * frequencies against the weights (gsl_cdf_chisq_Q), and with stratified
 * u0 (what a quasi-random sampler feeds it).  Points are checked to lie on
 * their face, their mean against the area centroid (hand-computed: the
 * vertex mean for a triangle, area-weighted triangle centroids for a quad)
 * within 4 standard errors, and the pdf against its closed form. */
#include <criterion/criterion.h>

#include <gsl/gsl_cdf.h>
#include <gsl/gsl_randist.h>
#include <gsl/gsl_rng.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "geometry/sample.h"
#include "geometry/scene.h"

static rp_scene *parse(const char *text)
{
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_parse(text, "sample.scene", NULL, &s, &err);
    cr_assert_eq(st, RP_OK, "scene: %s", err.message);
    return s;
}

static rp_area_sampler *make_sampler(const rp_scene *s, uint32_t surface, rp_area_weight w)
{
    rp_area_sampler *a = NULL;
    rp_error err = {""};
    cr_assert_eq(rp_area_sampler_create(s, surface, w, &a, &err), RP_OK, "%s", err.message);
    return a;
}

/* Twelve unit-wide rectangles of areas 1..12 (so weights differ), the first
 * eight emitting with Le 1..8 in band 0 and 1 in band 1, except rectangle 3
 * which does not emit, plus a triangle and a box that do not emit. */
static rp_scene *weights_scene(void)
{
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    fputs("bands 500 600\nmaterial w reflect 0.5\n", f);
    for (int i = 0; i < 12; i++) {
        if (i < 8 && i != 3)
            fprintf(f, "material e%d reflect 0 emit %d 1\n", i, i + 1);
        double x = 2.0 * i, h = i + 1;
        char mat[16] = "w";
        if (i < 8 && i != 3)
            snprintf(mat, sizeof mat, "e%d", i);
        fprintf(f, "quad r%d %s %g 0 0  %g 0 0  %g %g 0  %g %g 0\n", i, mat, x, x + 1, x + 1, h, x, h);
    }
    fputs("triangle tri w 0 0 5  3 0 5  0 4 5\n", f);
    fputs("box b w 0 0 10  1 2 13 outward\n", f);
    fclose(f);
    rp_scene *s = parse(buf);
    free(buf);
    return s;
}

Test(sample, alias_lookup_is_gsl_lookup)
{
    rp_scene *s = weights_scene();
    rp_area_sampler *a = make_sampler(s, RP_NONE, RP_WEIGHT_AREA);
    size_t nf = rp_scene_nfaces(s);
    const rp_face *faces = rp_scene_faces(s);
    cr_assert_eq(rp_area_sampler_count(a), nf);
    double *w = malloc(nf * sizeof *w);
    for (size_t i = 0; i < nf; i++)
        w[i] = faces[i].area;
    gsl_ran_discrete_t *g = gsl_ran_discrete_preproc(nf, w);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 7);
    for (int i = 0; i < 100000; i++) {
        /* gsl_ran_discrete consumes exactly one gsl_rng_uniform. */
        gsl_rng *c = gsl_rng_clone(r);
        double u = gsl_rng_uniform(c);
        gsl_rng_free(c);
        size_t k = gsl_ran_discrete(r, g);
        rp_area_sample smp;
        rp_area_sampler_sample(a, u, 0.5, 0.5, &smp);
        cr_assert_eq(smp.face, (uint32_t)k, "draw %d: u = %.17g", i, u);
    }
    gsl_rng_free(r);
    gsl_ran_discrete_free(g);
    free(w);
    rp_area_sampler_destroy(a);
    rp_scene_destroy(s);
}

static double band_mean_Le(const rp_scene *s, uint32_t f)
{
    const rp_material *m = rp_scene_face_material(s, f);
    size_t nb = rp_scene_nbands(s);
    double sum = 0;
    for (size_t b = 0; b < nb; b++)
        sum += m->Le[b];
    return sum / (double)nb;
}

static void check_frequencies(rp_area_weight weight)
{
    rp_scene *s = weights_scene();
    rp_area_sampler *a = make_sampler(s, RP_NONE, weight);
    size_t nf = rp_scene_nfaces(s);
    const rp_face *faces = rp_scene_faces(s);
    double *p = calloc(nf, sizeof *p);
    double total = 0;
    size_t nonzero = 0;
    for (uint32_t f = 0; f < nf; f++) {
        p[f] = faces[f].area * (weight == RP_WEIGHT_POWER ? band_mean_Le(s, f) : 1.0);
        total += p[f];
        nonzero += p[f] > 0;
    }
    cr_assert_eq(rp_area_sampler_count(a), nonzero);
    if (weight == RP_WEIGHT_POWER)
        cr_assert_eq(nonzero, 7); /* rectangles 0-7 but 3 */
    for (uint32_t f = 0; f < nf; f++)
        p[f] /= total;

    /* Pseudo-random u0: chi-square over the faces with non-zero weight. */
    const long N = 1000000;
    long *count = calloc(nf, sizeof *count);
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 2718);
    for (long i = 0; i < N; i++) {
        rp_area_sample smp;
        rp_area_sampler_sample(a, gsl_rng_uniform(r), gsl_rng_uniform(r), gsl_rng_uniform(r), &smp);
        cr_assert_lt(smp.face, nf);
        cr_assert(p[smp.face] > 0, "face %u has zero weight but was sampled", smp.face);
        count[smp.face]++;
    }
    double chi2 = 0;
    for (uint32_t f = 0; f < nf; f++)
        if (p[f] > 0) {
            double e = N * p[f];
            chi2 += (count[f] - e) * (count[f] - e) / e;
        }
    double q = gsl_cdf_chisq_Q(chi2, (double)(nonzero - 1));
    cr_assert_gt(q, 1e-3, "chi2 = %g with %zu dof, p = %g", chi2, nonzero - 1, q);

    /* Stratified u0 = (i + 1/2) / M: the alias table maps each face to at
     * most 1 + (number of columns aliasing to it) <= nonzero intervals of u0,
     * so each count is within nonzero + 1 of M p. */
    const long M = 100000;
    for (uint32_t f = 0; f < nf; f++)
        count[f] = 0;
    for (long i = 0; i < M; i++) {
        rp_area_sample smp;
        rp_area_sampler_sample(a, (i + 0.5) / M, 0.5, 0.5, &smp);
        count[smp.face]++;
    }
    for (uint32_t f = 0; f < nf; f++)
        cr_assert(fabs(count[f] - M * p[f]) <= (double)nonzero + 1, "face %u: %ld draws, expected %g",
                  f, count[f], M * p[f]);

    gsl_rng_free(r);
    free(count);
    free(p);
    rp_area_sampler_destroy(a);
    rp_scene_destroy(s);
}

Test(sample, frequencies_by_area) { check_frequencies(RP_WEIGHT_AREA); }
Test(sample, frequencies_by_power) { check_frequencies(RP_WEIGHT_POWER); }

Test(sample, pdf_closed_form_and_normalised)
{
    rp_scene *s = weights_scene();
    size_t nf = rp_scene_nfaces(s);
    const rp_face *faces = rp_scene_faces(s);
    /* Area: 1 + ... + 12 = 78 for the rectangles, 6 for the triangle, and
     * 2 (1*2 + 1*3 + 2*3) = 22 for the 1 x 2 x 3 box. */
    double A = 78 + 6 + 22;
    cr_assert_float_eq(rp_scene_total_area(s), A, 1e-12);
    rp_area_sampler *a = make_sampler(s, RP_NONE, RP_WEIGHT_AREA);
    double sum = 0;
    for (uint32_t f = 0; f < nf; f++) {
        cr_assert_float_eq(rp_area_sampler_pdf(a, f), 1.0 / A, 1e-15);
        sum += rp_area_sampler_pdf(a, f) * faces[f].area;
    }
    cr_assert_float_eq(sum, 1.0, 1e-12);
    cr_assert_eq(rp_area_sampler_pdf(a, (uint32_t)nf), 0.0);
    rp_area_sampler_destroy(a);

    /* Power: rectangle i (i < 8, i != 3) has area i + 1 and band-mean Le
     * (i + 2) / 2, so weight (i + 1)(i + 2) / 2; the total is
     * (2 + 6 + 12 + 30 + 42 + 56 + 72) / 2 = 110, and the pdf
     * weight / (W area) = (i + 2) / 220. */
    a = make_sampler(s, RP_NONE, RP_WEIGHT_POWER);
    sum = 0;
    for (uint32_t f = 0; f < nf; f++) {
        uint32_t surf = faces[f].surface;
        double expect = 0;
        if (surf < 8 && surf != 3)
            expect = (surf + 2) / 220.0;
        cr_assert_float_eq(rp_area_sampler_pdf(a, f), expect, 1e-15, "face %u", f);
        sum += rp_area_sampler_pdf(a, f) * faces[f].area;
    }
    cr_assert_float_eq(sum, 1.0, 1e-12);
    /* Samples carry the pdf of their face. */
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 1);
    for (int i = 0; i < 1000; i++) {
        rp_area_sample smp;
        rp_area_sampler_sample(a, gsl_rng_uniform(r), gsl_rng_uniform(r), gsl_rng_uniform(r), &smp);
        cr_assert_eq(smp.pdf_area, rp_area_sampler_pdf(a, smp.face));
        cr_assert_eq(smp.surface, faces[smp.face].surface);
        cr_assert_eq(smp.n.x, faces[smp.face].normal.x);
        cr_assert_eq(smp.n.y, faces[smp.face].normal.y);
        cr_assert_eq(smp.n.z, faces[smp.face].normal.z);
    }
    gsl_rng_free(r);
    rp_area_sampler_destroy(a);
    rp_scene_destroy(s);
}

Test(sample, one_surface)
{
    rp_scene *s = weights_scene();
    uint32_t box = rp_scene_find_surface(s, "b");
    cr_assert_neq(box, RP_NONE);
    const rp_surface *sf = &rp_scene_surfaces(s)[box];
    rp_area_sampler *a = make_sampler(s, box, RP_WEIGHT_AREA);
    cr_assert_eq(rp_area_sampler_count(a), sf->nfaces);
    cr_assert_eq(sf->nfaces, 6);
    double sum = 0;
    for (uint32_t f = 0; f < rp_scene_nfaces(s); f++) {
        int inside = f >= sf->first_face && f < sf->first_face + sf->nfaces;
        double pdf = rp_area_sampler_pdf(a, f);
        cr_assert_float_eq(pdf, inside ? 1.0 / 22.0 : 0.0, 1e-15, "face %u", f);
        sum += pdf * rp_scene_faces(s)[f].area;
    }
    cr_assert_float_eq(sum, 1.0, 1e-12);
    for (int i = 0; i < 1000; i++) {
        rp_area_sample smp;
        rp_area_sampler_sample(a, (i + 0.5) / 1000, 0.3, 0.7, &smp);
        cr_assert_eq(smp.surface, box);
    }
    rp_area_sampler_destroy(a);
    /* The box emits nothing: a power sampler over it has nothing to sample. */
    a = make_sampler(s, box, RP_WEIGHT_POWER);
    cr_assert_eq(rp_area_sampler_count(a), 0);
    rp_area_sampler_destroy(a);
    /* A surface that does not exist is refused. */
    rp_error err = {""};
    a = NULL;
    cr_assert_eq(rp_area_sampler_create(s, 1000, RP_WEIGHT_AREA, &a, &err), RP_ERR_INPUT);
    cr_assert_null(a);
    rp_scene_destroy(s);
}

/* ---- points on faces ---------------------------------------------------- */

/* A tilted triangle and a tilted trapezoid (not a parallelogram, so the area
 * centroid differs from the vertex mean). */
static const char *shapes_text =
    "bands grey\n"
    "material lamp reflect 0 emit 1\n"
    "triangle tri lamp  1 2 3  4 2.5 3.5  2 5 2\n"
    /* trapezoid in the plane x + y = 0, parallel sides v0v1 and v3v2 along (1, -1, 0) */
    "quad trap lamp  0 0 1  4 -4 1  2.75 -2.75 -1  1.25 -1.25 -1\n";

static void sample_moments(const rp_scene *s, uint32_t face, rp_vec3 centroid)
{
    const rp_face *fc = &rp_scene_faces(s)[face];
    const rp_vec3 *v = rp_scene_vertices(s);
    rp_vec3 v0 = v[fc->v[0]];
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 424242 + face);
    const int N = 200000;
    double m[3] = {0, 0, 0}, m2[3] = {0, 0, 0};
    double scale = sqrt(fc->area);
    for (int i = 0; i < N; i++) {
        rp_vec3 p = rp_face_sample_uniform(s, face, gsl_rng_uniform(r), gsl_rng_uniform(r));
        /* On the plane ... */
        cr_assert(fabs(rp_v3_dot(rp_v3_sub(p, v0), fc->normal)) < 1e-12 * scale, "point %d off plane", i);
        /* ... and inside every edge (convex, counter-clockwise about n). */
        for (uint32_t k = 0; k < fc->nverts; k++) {
            rp_vec3 a = v[fc->v[k]], b = v[fc->v[(k + 1) % fc->nverts]];
            double side = rp_v3_dot(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(p, a)), fc->normal);
            cr_assert_geq(side, -1e-12 * scale * scale, "point %d outside edge %u", i, k);
        }
        double c[3] = {p.x, p.y, p.z};
        for (int k = 0; k < 3; k++) {
            m[k] += c[k];
            m2[k] += c[k] * c[k];
        }
    }
    double cc[3] = {centroid.x, centroid.y, centroid.z};
    for (int k = 0; k < 3; k++) {
        double mean = m[k] / N;
        double var = m2[k] / N - mean * mean;
        double se = sqrt(var / N);
        cr_assert_gt(se, 0);
        cr_assert(fabs(mean - cc[k]) < 4 * se, "face %u axis %d: mean %.6f, centroid %.6f, se %.2g",
                  face, k, mean, cc[k], se);
    }
    /* The corners are reached: u1 -> 1 and u2 in {0, 1} give vertices. */
    rp_vec3 p = rp_face_sample_uniform(s, face, 0.0, 0.0);
    cr_assert(rp_v3_isfinite(p));
    gsl_rng_free(r);
}

Test(sample, uniform_points_on_triangle)
{
    rp_scene *s = parse(shapes_text);
    uint32_t f = rp_scene_surfaces(s)[rp_scene_find_surface(s, "tri")].first_face;
    /* Centroid: vertex mean ((1+4+2)/3, (2+2.5+5)/3, (3+3.5+2)/3). */
    sample_moments(s, f, rp_v3(7.0 / 3, 9.5 / 3, 8.5 / 3));
    rp_scene_destroy(s);
}

Test(sample, uniform_points_on_quad)
{
    rp_scene *s = parse(shapes_text);
    uint32_t f = rp_scene_surfaces(s)[rp_scene_find_surface(s, "trap")].first_face;
    /* Trapezoid, parallel sides a = |v1 - v0| = 4 sqrt 2 and b = |v2 - v3| =
     * 1.5 sqrt 2.  Split along v0 v2: triangle (v0, v1, v2) has area
     * proportional to a, (v0, v2, v3) to b (same height), so the centroid is
     * (a c1 + b c2) / (a + b) with c1, c2 the triangles' vertex means:
     * c1 = (6.75, -6.75, 1) / 3, c2 = (4, -4, -1) / 3,
     * centroid = (4 c1 + 1.5 c2) / 5.5. */
    rp_vec3 c1 = rp_v3(6.75 / 3, -6.75 / 3, 1.0 / 3), c2 = rp_v3(4.0 / 3, -4.0 / 3, -1.0 / 3);
    rp_vec3 c = rp_v3_scale(rp_v3_add(rp_v3_scale(c1, 4.0), rp_v3_scale(c2, 1.5)), 1.0 / 5.5);
    sample_moments(s, f, c);
    rp_scene_destroy(s);
}
