/* Tests of the path tracer (solvers/pathtrace/) against values it did not
 * produce.
 *
 * Reference values:
 *  - the furnace, L = Le / (1 - rho) (docs/ground-truth.md);
 *  - Howell's closed-form form factors C-11 (parallel opposed squares) and
 *    C-14 (perpendicular squares sharing an edge), implemented here and
 *    checked against the catalogue values 0.1998248957 and 0.2000437761;
 *    one-bounce radiance rho F Le is exact for area averages;
 *  - the energy invariant of a closed enclosure with uniform rho:
 *    area mean of L = area mean of Le / (1 - rho);
 *  - an independent brute-force random walk in the unit cube written here
 *    (analytic ray-cube exits, GSL's Mersenne Twister, no Embree, no NEE,
 *    no MIS) for the cube-ceiling surface averages at full depth;
 *  - the Sobol' net property and hand-computed first points.
 * Monte Carlo tolerances are multiples of estimated standard errors with
 * fixed seeds; each multiple is justified where it is used. */
#include <criterion/criterion.h>

#include <gsl/gsl_cdf.h>
#include <gsl/gsl_errno.h>
#include <gsl/gsl_fit.h>
#include <gsl/gsl_rng.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "closed_form.h"
#include "geometry/scene.h"
#include "scene_util.h"
#include "solvers/pathtrace/sampler.h"
#include "solvers/solver.h"

#ifndef RP_SOURCE_DIR
#define RP_SOURCE_DIR "."
#endif

/* ---------------------------------------------------------------- helpers */



/* Options as a NULL-terminated list "key", "value", ... */
typedef struct opts {
    const char *keys[16], *values[16];
    size_t n;
} opts;

static void opts_from(opts *o, va_list ap)
{
    o->n = 0;
    const char *k;
    while ((k = va_arg(ap, const char *)) != NULL) {
        cr_assert_lt(o->n, 16u);
        o->keys[o->n] = k;
        o->values[o->n++] = va_arg(ap, const char *);
    }
}

static rp_status try_create(const rp_scene *sc, unsigned want, uint64_t seed, int threads,
                            rp_solver **out, rp_error *err, ...)
{
    opts kv;
    va_list ap;
    va_start(ap, err);
    opts_from(&kv, ap);
    va_end(ap);
    rp_options o = {sizeof o, want, seed, threads, kv.keys, kv.values, kv.n, 0, NULL, NULL, NULL, NULL, NULL};
    return rp_solver_create(rp_solver_lookup("pathtrace"), sc, &o, out, err);
}

static rp_solver *vcreate(const rp_scene *sc, unsigned want, uint64_t seed, int threads, int open_ended,
                          va_list ap)
{
    opts kv;
    opts_from(&kv, ap);
    rp_options o = {sizeof o, want, seed, threads, kv.keys, kv.values, kv.n, open_ended, NULL, NULL, NULL, NULL, NULL};
    rp_solver *s = NULL;
    rp_error err = {""};
    cr_assert_eq(rp_solver_create(rp_solver_lookup("pathtrace"), sc, &o, &s, &err), RP_OK, "%s",
                 err.message);
    return s;
}

static rp_solver *create(const rp_scene *sc, unsigned want, uint64_t seed, int threads, ...)
{
    va_list ap;
    va_start(ap, threads);
    rp_solver *s = vcreate(sc, want, seed, threads, 0, ap);
    va_end(ap);
    return s;
}

/* Steps until the solver's own rule says converged; returns the work. */
static rp_step_info run(rp_solver *s)
{
    rp_step_info total = {0};
    rp_error err = {""};
    for (int k = 0; k < 1000000; k++) {
        rp_step_info info;
        cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK, "%s", err.message);
        total.rays += info.rays;
        total.paths += info.paths;
        total.iterations += info.iterations;
        if (info.converged)
            return total;
    }
    cr_assert_fail("never converged");
    return total;
}

typedef struct image {
    size_t npix, nbands;
    float *radiance, *variance;
    double samples;
} image;

static image render(const rp_scene *sc, uint64_t seed, int threads, ...)
{
    va_list ap;
    va_start(ap, threads);
    rp_solver *s = vcreate(sc, RP_WANT_IMAGE, seed, threads, 0, ap);
    va_end(ap);
    run(s);
    const rp_camera *cam = rp_scene_camera(sc);
    image im = {(size_t)cam->width * cam->height, rp_scene_nbands(sc), NULL, NULL, 0};
    im.radiance = malloc(im.npix * im.nbands * sizeof(float));
    im.variance = malloc(im.npix * im.nbands * sizeof(float));
    cr_assert(im.radiance && im.variance);
    rp_estimate e = {im.radiance, im.variance, NULL, NULL, 0};
    rp_error err = {""};
    cr_assert_eq(rp_solver_estimate(s, &e, &err), RP_OK, "%s", err.message);
    im.samples = e.samples;
    rp_solver_destroy(s);
    return im;
}

static void image_free(image *im)
{
    free(im->radiance);
    free(im->variance);
}

/* Surface averages (band 0) and their standard errors. */
typedef struct probe {
    size_t n;
    double L[16], se[16];
    rp_step_info work;
} probe;

static probe probe_surfaces(const rp_scene *sc, uint64_t seed, int threads, ...)
{
    va_list ap;
    va_start(ap, threads);
    rp_solver *s = vcreate(sc, RP_WANT_SURFACES, seed, threads, 0, ap);
    va_end(ap);
    probe p = {0};
    p.work = run(s);
    p.n = rp_scene_nsurfaces(sc);
    size_t nb = rp_scene_nbands(sc);
    cr_assert_leq(p.n * nb, 16u);
    double L[16], se[16];
    rp_estimate e = {NULL, NULL, L, se, 0};
    rp_error err = {""};
    cr_assert_eq(rp_solver_estimate(s, &e, &err), RP_OK, "%s", err.message);
    for (size_t i = 0; i < p.n; i++) {
        p.L[i] = L[i * nb];
        p.se[i] = se[i * nb];
    }
    rp_solver_destroy(s);
    return p;
}

static uint32_t surface(const rp_scene *sc, const char *name)
{
    uint32_t i = rp_scene_find_surface(sc, name);
    cr_assert_neq(i, RP_NONE, "no surface %s", name);
    return i;
}

/* ------------------------------------------------ Howell's form factors */

Test(pathtrace, howell_formulas_match_catalogue)
{
    /* The implementations above against docs/ground-truth.md's values, and the
     * closure of the unit cube. */
    cr_assert_float_eq(rp_cf_howell_parallel(1, 1, 1), 0.1998248957, 1e-10);
    cr_assert_float_eq(rp_cf_howell_perpendicular(1, 1, 1), 0.2000437761, 1e-10);
    cr_assert_float_eq(rp_cf_howell_parallel(1, 1, 1) + 4 * rp_cf_howell_perpendicular(1, 1, 1), 1.0, 1e-9);
}

/* ------------------------------------------------------------- samplers */

static rp_sampler make_sampler(rp_sampler_kind kind, uint64_t seed, uint64_t budget)
{
    rp_sampler s;
    rp_sampler_init(&s, kind, seed, budget);
    return s;
}

Test(pathtrace, sobol_first_points)
{
    /* By hand from the direction numbers (fractions v_k = m_k 2^-k):
     * dimension 0 is van der Corput: 1/2, 1/4, 3/4, 1/8.  Dimension 1
     * (x + 1, m_1 = 1): v_1 = 1/2 and v_k = v_(k-1) ^ v_(k-1)/2, so v_2 =
     * 3/4, v_3 = 5/8; index 3 = v_1 ^ v_2 = 1/4.  Dimension 2 (x^2 + x + 1,
     * m = 1, 3): v_1 = 1/2, v_2 = 3/4, v_3 = v_1 ^ v_1/4 ^ v_2 = 3/8. */
    rp_sampler s = make_sampler(RP_SAMPLER_SOBOL, 0, 16);
    const double d0[] = {0, 0.5, 0.25, 0.75, 0.125};
    const double d1[] = {0, 0.5, 0.75, 0.25, 0.625};
    const double d2[] = {0, 0.5, 0.75, 0.25, 0.375};
    for (uint32_t i = 0; i < 5; i++) {
        cr_assert_float_eq(rp_sobol_raw(&s, i, 0) * 0x1p-32, d0[i], 0, "dim 0 index %u", i);
        cr_assert_float_eq(rp_sobol_raw(&s, i, 1) * 0x1p-32, d1[i], 0, "dim 1 index %u", i);
        cr_assert_float_eq(rp_sobol_raw(&s, i, 2) * 0x1p-32, d2[i], 0, "dim 2 index %u", i);
    }
}

/* 1 if the first 2^m values of (dims a, b) of stream `stream` put exactly
 * one point in each elementary interval of shape 2^-k x 2^-(m-k), every k
 * (a (0, m, 2)-net); with a == b the 1-D version. */
static int is_net(const rp_sampler *s, uint64_t stream, unsigned a, unsigned b, unsigned m, int raw)
{
    uint32_t n = 1u << m;
    unsigned char *count = calloc(n, 1);
    int ok = 1;
    for (unsigned k = (a == b ? m : 0); k <= m && ok; k++) {
        memset(count, 0, n);
        for (uint32_t i = 0; i < n; i++) {
            double x, y;
            if (raw) {
                x = rp_sobol_raw(s, i, a) * 0x1p-32;
                y = rp_sobol_raw(s, i, b) * 0x1p-32;
            } else {
                rp_sample_point p;
                rp_sampler_start(s, stream, i, &p);
                x = rp_sampler_get(&p, a);
                y = rp_sampler_get(&p, b);
                if (!(x >= 0 && x < 1 && y >= 0 && y < 1))
                    ok = 0;
            }
            uint32_t cx = (uint32_t)(x * (double)(1u << k));
            uint32_t cy = a == b ? 0 : (uint32_t)(y * (double)(1u << (m - k)));
            uint32_t cell = (cy << k) | cx;
            if (count[cell]++)
                ok = 0;
        }
    }
    free(count);
    return ok;
}

Test(pathtrace, sobol_nets_survive_scrambling)
{
    /* Owen scrambling must keep the net structure: dimensions (0, 1) of
     * Sobol' form a (0, m, 2)-net for every m, and each dimension alone a
     * (0, m, 1)-net, scrambled (several pixels' streams) or not. */
    rp_sampler s = make_sampler(RP_SAMPLER_SOBOL, 42, 4096);
    for (unsigned m = 1; m <= 12; m++) {
        cr_assert(is_net(&s, 0, 0, 1, m, 1), "raw m = %u", m);
        for (uint64_t stream = 0; stream < 3; stream++)
            cr_assert(is_net(&s, stream * 977, 0, 1, m, 0), "scrambled m = %u", m);
    }
    for (unsigned d = 0; d < RP_SOBOL_DIMS; d++)
        for (unsigned m = 1; m <= 10; m++) {
            cr_assert(is_net(&s, 0, d, d, m, 1), "raw dim %u m %u", d, m);
            cr_assert(is_net(&s, 5, d, d, m, 0), "scrambled dim %u m %u", d, m);
        }
}

Test(pathtrace, stratified_fills_each_stratum_once)
{
    /* budget 60: grid ceil(sqrt 60) = 8, 64 strata; every round of 64
     * samples puts one in each 1/8 x 1/8 cell, for the pixel pair and for
     * padded pairs (4, 5) and (10, 11). */
    rp_sampler s = make_sampler(RP_SAMPLER_STRATIFIED, 7, 60);
    cr_assert_eq(s.grid, 8u);
    const unsigned pairs[] = {0, 4, 10};
    for (unsigned round = 0; round < 2; round++)
        for (size_t q = 0; q < 3; q++) {
            int count[64] = {0};
            for (uint32_t i = 64 * round; i < 64 * (round + 1); i++) {
                rp_sample_point p;
                rp_sampler_start(&s, 123, i, &p);
                double x = rp_sampler_get(&p, pairs[q]), y = rp_sampler_get(&p, pairs[q] + 1);
                cr_assert(x >= 0 && x < 1 && y >= 0 && y < 1);
                count[(int)(y * 8) * 8 + (int)(x * 8)]++;
            }
            for (int c = 0; c < 64; c++)
                cr_assert_eq(count[c], 1, "round %u pair %u cell %d: %d", round, pairs[q], c, count[c]);
        }
}

Test(pathtrace, samplers_are_uniform)
{
    /* Chi-square of 64 equal bins over 2^16 draws of one dimension across
     * streams (what an image pass sees), for every sampler and a few
     * dimensions inside and past the Sobol' table; the bound is GSL's
     * chi-square quantile at p = 1e-6 (63 degrees of freedom). */
    double bound = gsl_cdf_chisq_Qinv(1e-6, 63);
    const rp_sampler_kind kinds[] = {RP_SAMPLER_RANDOM, RP_SAMPLER_STRATIFIED, RP_SAMPLER_SOBOL};
    const unsigned dims[] = {0, 1, 5, 21, 22, 40};
    for (size_t k = 0; k < 3; k++) {
        rp_sampler s = make_sampler(kinds[k], 99, 16);
        for (size_t d = 0; d < 6; d++)
            for (uint32_t index = 0; index < 3; index++) {
                double count[64] = {0};
                const uint32_t n = 1u << 16;
                for (uint32_t st = 0; st < n; st++) {
                    rp_sample_point p;
                    rp_sampler_start(&s, st, index, &p);
                    double u = rp_sampler_get(&p, dims[d]);
                    cr_assert(u >= 0 && u < 1);
                    count[(int)(u * 64)]++;
                }
                double chi2 = 0, e = n / 64.0;
                for (int b = 0; b < 64; b++)
                    chi2 += (count[b] - e) * (count[b] - e) / e;
                cr_assert_lt(chi2, bound, "%s dim %u index %u: chi2 %g", rp_sampler_name(kinds[k]), dims[d],
                             index, chi2);
            }
    }
}

/* ---------------------------------------------------------------- furnace */

/* The furnace (Le 1, rho 0.5 everywhere): L = 2 at every pixel.  Each
 * pixel's mean must lie within z* standard errors of 2, with z* the
 * Bonferroni bound for all 16384 pixels at a 1% family-wise level
 * (gsl_cdf_ugaussian_Qinv(0.005 / npix) = 5.0): with this many pixels a
 * 3-sigma bound would be exceeded by about 44 pixels of a perfect
 * estimator.  The image mean (all samples) must lie within 0.1% of 2 and
 * within 3 of its standard errors. */
static void furnace_check(const char *sampler, const char *spp)
{
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    image im = render(sc, 2024, 0, "sampler", sampler, "spp", spp, NULL);
    cr_assert_eq(im.nbands, 1u);
    cr_assert_float_eq(im.samples, atof(spp), 0);
    double zmax_allowed = gsl_cdf_ugaussian_Qinv(0.005 / (double)im.npix);
    double sum = 0, var = 0, zmax = 0;
    size_t beyond3 = 0;
    for (size_t i = 0; i < im.npix; i++) {
        double se = sqrt(im.variance[i]);
        cr_assert(se > 0, "pixel %zu: no variance", i);
        double z = fabs(im.radiance[i] - 2.0) / se;
        cr_assert_leq(z, zmax_allowed, "%s pixel %zu: %g, %g standard errors from 2", sampler, i,
                      im.radiance[i], z);
        zmax = z > zmax ? z : zmax;
        beyond3 += z > 3;
        sum += im.radiance[i];
        var += im.variance[i];
    }
    double mean = sum / im.npix, se = sqrt(var) / im.npix;
    cr_assert_lt(fabs(mean - 2.0), 0.002, "%s: image mean %.6f", sampler, mean);
    cr_assert_lt(fabs(mean - 2.0), 3 * se, "%s: image mean %.6f +- %.2e", sampler, mean, se);
    /* For the random sampler the z-scores should be roughly normal: the
     * fraction beyond 3 standard errors (0.27% for a normal) stays below
     * 1% unless the variance estimate is wrong. */
    if (strcmp(sampler, "random") == 0)
        cr_assert_lt((double)beyond3 / im.npix, 0.01, "%zu pixels beyond 3 standard errors", beyond3);
    image_free(&im);
    rp_scene_destroy(sc);
}

Test(pathtrace, furnace_random) { furnace_check("random", "128"); }
Test(pathtrace, furnace_stratified) { furnace_check("stratified", "128"); }
Test(pathtrace, furnace_sobol) { furnace_check("sobol", "128"); }

Test(pathtrace, furnace_spectral_bands)
{
    /* Five bands with different rho and Le: each band is its own furnace,
     * L_b = Le_b / (1 - rho_b); the image mean per band within 3 standard
     * errors and 0.5%.  Also checks that nothing assumes three bands. */
    rp_scene *sc = rp_test_parse("bands 400 450 500 550 600\n"
                         "material m reflect 0.1 0.3 0.5 0.7 0.8 emit 1 2 0.5 0 3\n"
                         "box room m 0 0 0 2 1 1.5 inward\n"
                         "camera eye 0.4 0.5 0.3 look 2 0 1.5 up 0 1 0 fov 80 size 48 32\n");
    const double rho[] = {0.1, 0.3, 0.5, 0.7, 0.8}, Le[] = {1, 2, 0.5, 0, 3};
    image im = render(sc, 5, 0, "spp", "64", "sampler", "random", NULL);
    cr_assert_eq(im.nbands, 5u);
    for (size_t b = 0; b < 5; b++) {
        double sum = 0, var = 0;
        for (size_t i = 0; i < im.npix; i++) {
            sum += im.radiance[i * 5 + b];
            var += im.variance[i * 5 + b];
        }
        double mean = sum / im.npix, se = sqrt(var) / im.npix, want = Le[b] / (1 - rho[b]);
        if (want == 0) {
            cr_assert_eq(mean, 0.0, "band %zu: %g", b, mean);
            continue;
        }
        cr_assert_lt(fabs(mean - want), 3 * se, "band %zu: %.5f +- %.2e, want %.5f", b, mean, se, want);
        cr_assert_lt(fabs(mean - want), 0.005 * want, "band %zu: %.5f want %.5f", b, mean, want);
    }
    image_free(&im);
    rp_scene_destroy(sc);
}

/* ---------------------------------------------------------------- plates */

static void plates_check(const char *scene, double F)
{
    char rel[256];
    snprintf(rel, sizeof rel, "scenes/%s", scene);
    rp_scene *sc = rp_test_load(rel);
    uint32_t em = surface(sc, "emitter"), rc = surface(sc, "receiver");
    double want = 0.5 * F * 1.0; /* rho_receiver F(receiver -> emitter) Le */
    const char *depths[] = {"unlimited", "1"};
    const char *samplers[] = {"random", "sobol"};
    for (int d = 0; d < 2; d++)
        for (int k = 0; k < 2; k++) {
            probe p = probe_surfaces(sc, 11, 0, "samples", "65536", "batch", "8192", "max-depth", depths[d],
                                     "sampler", samplers[k], NULL);
            /* The emitter reflects nothing: its average is Le exactly. */
            cr_assert_eq(p.L[em], 1.0, "%s emitter %g", scene, p.L[em]);
            cr_assert_eq(p.se[em], 0.0);
            cr_assert_gt(p.se[rc], 0.0);
            cr_assert_lt(fabs(p.L[rc] - want), 3 * p.se[rc], "%s depth %s %s: receiver %.6f +- %.2e, want %.6f",
                         scene, depths[d], samplers[k], p.L[rc], p.se[rc], want);
            /* The standard error is below 1% of the value (0.5% for the
             * perpendicular pair, whose kernel is singular at the shared
             * edge), so the comparison above has teeth. */
            cr_assert_lt(p.se[rc], 0.01 * want);
        }
    /* Direct lighting only (max-depth 1): each receiver path casts exactly
     * one shadow ray and one continuation ray, the emitter's none. */
    probe p = probe_surfaces(sc, 3, 0, "samples", "1000", "max-depth", "1", NULL);
    cr_assert_eq(p.work.rays, 2000.0);
    cr_assert_eq(p.work.paths, 2000.0);
    /* Emission only (max-depth 0): the receiver is black, no ray is cast. */
    p = probe_surfaces(sc, 3, 0, "samples", "1000", "max-depth", "0", NULL);
    cr_assert_eq(p.L[rc], 0.0);
    cr_assert_eq(p.L[em], 1.0);
    cr_assert_eq(p.work.rays, 0.0);
    rp_scene_destroy(sc);
}

Test(pathtrace, plates_parallel) { plates_check("plates-parallel.scene", rp_cf_howell_parallel(1, 1, 1)); }

/* --target-error: the probe stops at the first batch after which every
 * surface's standard error is at most that fraction of its average (the
 * batch before, some surface's was not), well before --samples, and the
 * receiver's average there agrees with Howell's closed form (parallel unit
 * plates at distance 1) within 4 standard errors; a target never reached
 * leaves --samples as the cap. */
Test(pathtrace, target_error_stops_at_the_first_batch_within_it)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    uint32_t rc = surface(sc, "receiver");
    const size_t ns = rp_scene_nsurfaces(sc);
    double want = 0.5 * rp_cf_howell_parallel(1, 1, 1);
    rp_solver *s = create(sc, RP_WANT_SURFACES, 5, 0, "target-error", "0.005", "samples", "1048576", "batch", "512",
                          NULL);
    rp_error err = {""};
    double L[8], se[8], worst_before = INFINITY;
    int steps = 0;
    for (;;) {
        rp_step_info info;
        cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK, "%s", err.message);
        steps++;
        rp_estimate e = {NULL, NULL, L, se, 0};
        cr_assert_eq(rp_solver_estimate(s, &e, &err), RP_OK);
        double worst = 0;
        for (size_t i = 0; i < ns; i++)
            worst = fmax(worst, L[i] > 0 ? se[i] / L[i] : 0);
        if (info.converged) {
            cr_expect_leq(worst, 0.005, "stopped at a largest relative error of %g", worst);
            cr_expect_gt(worst_before, 0.005, "the batch before was already within: %g", worst_before);
            cr_expect_lt(e.samples, 1048576, "ran to the cap");
            cr_expect_eq(e.samples, 512.0 * steps);
            cr_expect_gt(steps, 4, "within 0.5%% after %d batches: the target asks too little to test", steps);
            break;
        }
        cr_assert_lt(info.progress, 1.0);
        worst_before = worst;
        cr_assert_lt(steps, 2048, "never within 0.5%%");
    }
    cr_expect_lt(fabs(L[rc] - want), 4 * se[rc], "receiver %.6f +- %.2e, Howell %.6f", L[rc], se[rc], want);
    cr_log_info("--target-error 0.005: %d batches of 512, receiver %.6f +- %.2e (Howell %.6f)", steps, L[rc], se[rc],
                want);
    rp_solver_destroy(s);
    s = create(sc, RP_WANT_SURFACES, 5, 0, "target-error", "1e-6", "samples", "2048", "batch", "512", NULL);
    rp_step_info total = run(s);
    cr_expect_eq(total.iterations, 4.0, "the cap of 2048 samples in batches of 512");
    rp_solver_destroy(s);
    /* out of range */
    const char *k[] = {"target-error"}, *v[] = {"-0.1"};
    rp_options o = {sizeof o, RP_WANT_SURFACES, 1, 0, k, v, 1, 0, NULL, NULL, NULL, NULL, NULL};
    cr_expect_neq(rp_solver_create(rp_solver_lookup("pathtrace"), sc, &o, &s, &err), RP_OK);
    rp_scene_destroy(sc);
}
Test(pathtrace, plates_perpendicular)
{
    plates_check("plates-perpendicular.scene", rp_cf_howell_perpendicular(1, 1, 1));
}

/* Slope of log(y) against log(N) by least squares (gsl_fit_linear). */
static double loglog_slope(const double *N, const double *y, size_t n)
{
    double lx[16], ly[16], c0, c1, cov00, cov01, cov11, sumsq;
    for (size_t i = 0; i < n; i++) {
        lx[i] = log(N[i]);
        ly[i] = log(y[i]);
    }
    gsl_fit_linear(lx, 1, ly, 1, n, &c0, &c1, &cov00, &cov01, &cov11, &sumsq);
    return c1;
}

Test(pathtrace, error_falls_as_inverse_sqrt_n)
{
    /* Parallel plates, receiver, N = 256 .. 65536 (2.4 decades), one run
     * per N and seed (independent points).  (a) The reported standard
     * error, random sampler: fitted slope -0.5 +- 0.05.  (b) The actual
     * error against the closed form, RMS over 32 seeds, random sampler:
     * slope -0.5 +- 0.1 (an RMS of 32 errors is itself uncertain by about
     * 1/sqrt(64) = 12%, which moves the fitted slope by about 0.03).  (c)
     * Owen-scrambled Sobol' on the same integrand converges faster than
     * N^-1/2: slope below -0.6. */
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    uint32_t rc = surface(sc, "receiver");
    double want = 0.5 * rp_cf_howell_parallel(1, 1, 1);
    enum { NPTS = 5, SEEDS = 32 };
    double N[NPTS], se[NPTS] = {0}, ms[2][NPTS] = {{0}};
    const char *samplers[2] = {"random", "sobol"};
    for (int i = 0; i < NPTS; i++) {
        N[i] = 256.0 * pow(4.0, i);
        char n[32];
        snprintf(n, sizeof n, "%.0f", N[i]);
        for (int k = 0; k < 2; k++)
            for (int seed = 0; seed < SEEDS; seed++) {
                probe p = probe_surfaces(sc, 1000 + 37 * i + seed, 0, "samples", n, "batch", n, "sampler",
                                         samplers[k], NULL);
                cr_assert_eq(p.work.iterations, 1.0);
                double d = p.L[rc] - want;
                ms[k][i] += d * d / SEEDS;
                if (k == 0 && seed == 0)
                    se[i] = p.se[rc];
            }
    }
    double rms_random[NPTS], rms_sobol[NPTS];
    for (int i = 0; i < NPTS; i++) {
        rms_random[i] = sqrt(ms[0][i]);
        rms_sobol[i] = sqrt(ms[1][i]);
    }
    double a = loglog_slope(N, se, NPTS), b = loglog_slope(N, rms_random, NPTS),
           c = loglog_slope(N, rms_sobol, NPTS);
    cr_assert_lt(fabs(a + 0.5), 0.05, "standard error slope %g", a);
    cr_assert_lt(fabs(b + 0.5), 0.1, "random RMS error slope %g", b);
    cr_assert_lt(c, -0.6, "sobol RMS error slope %g", c);
    rp_scene_destroy(sc);
}

/* ---------------------------------------------------------- cube-ceiling */

/* Independent brute force for the unit cube lit by its ceiling (Le 1, rho
 * 0.5 everywhere): the area average of L over face f is estimated by
 * walks from uniform points on f with cosine-sampled directions, exits
 * found analytically, scoring sum_k rho^k Le(x_k) (expected-value
 * weighting, no roulette) up to k = 60 (truncation 0.5^60).  Faces:
 * 0 x=0, 1 x=1, 2 y=0 (floor), 3 y=1 (ceiling), 4 z=0, 5 z=1. */
static void brute_cube(gsl_rng *r, int face, size_t n, double *mean, double *se)
{
    double s = 0, s2 = 0;
    for (size_t i = 0; i < n; i++) {
        double p[3], nrm[3] = {0, 0, 0};
        int axis = face / 2, side = face % 2;
        p[axis] = side;
        p[(axis + 1) % 3] = gsl_rng_uniform(r);
        p[(axis + 2) % 3] = gsl_rng_uniform(r);
        nrm[axis] = side ? -1 : 1;
        int f = face;
        double score = f == 3 ? 1.0 : 0.0, w = 1.0;
        for (int k = 1; k <= 60; k++) {
            /* Cosine-weighted direction about the inward normal. */
            double u1 = gsl_rng_uniform(r), u2 = gsl_rng_uniform(r);
            double rr = sqrt(u1), phi = 2 * M_PI * u2, ct = sqrt(1 - u1);
            double d[3];
            d[axis] = nrm[axis] * ct;
            d[(axis + 1) % 3] = rr * cos(phi);
            d[(axis + 2) % 3] = rr * sin(phi);
            double tmin = INFINITY;
            int exit = -1;
            for (int a = 0; a < 3; a++) {
                if (d[a] > 0 && (1 - p[a]) / d[a] < tmin) {
                    tmin = (1 - p[a]) / d[a];
                    exit = 2 * a + 1;
                } else if (d[a] < 0 && -p[a] / d[a] < tmin) {
                    tmin = -p[a] / d[a];
                    exit = 2 * a;
                }
            }
            for (int a = 0; a < 3; a++)
                p[a] += tmin * d[a];
            f = exit;
            axis = f / 2;
            side = f % 2;
            p[axis] = side;
            nrm[0] = nrm[1] = nrm[2] = 0;
            nrm[axis] = side ? -1 : 1;
            w *= 0.5;
            if (f == 3)
                score += w;
        }
        s += score;
        s2 += score * score;
    }
    *mean = s / n;
    *se = sqrt((s2 - s * s / n) / (n - 1) / n);
}

Test(pathtrace, cube_ceiling_direct_is_closed_form)
{
    /* max-depth 1: floor L = rho F(floor -> ceiling) Le with the C-11
     * factor, each wall rho F(wall -> ceiling) Le with C-14, the ceiling
     * its own Le (it cannot see itself).  Exact for area averages; within
     * 3 standard errors (the standard error is below 0.3% of the value). */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    probe p = probe_surfaces(sc, 8, 0, "samples", "65536", "batch", "16384", "max-depth", "1", "sampler",
                             "random", NULL);
    const char *walls[] = {"wall-x0", "wall-x1", "wall-z0", "wall-z1"};
    double Ff = rp_cf_howell_parallel(1, 1, 1), Fw = rp_cf_howell_perpendicular(1, 1, 1);
    uint32_t fl = surface(sc, "floor"), ce = surface(sc, "ceiling");
    cr_assert_lt(fabs(p.L[fl] - 0.5 * Ff), 3 * p.se[fl], "floor %.6f +- %.2e want %.6f", p.L[fl], p.se[fl],
                 0.5 * Ff);
    cr_assert_lt(p.se[fl], 0.003 * 0.5 * Ff);
    for (int i = 0; i < 4; i++) {
        uint32_t w = surface(sc, walls[i]);
        cr_assert_lt(fabs(p.L[w] - 0.5 * Fw), 3 * p.se[w], "%s %.6f +- %.2e want %.6f", walls[i], p.L[w],
                     p.se[w], 0.5 * Fw);
    }
    cr_assert_float_eq(p.L[ce], 1.0, 1e-12);
    rp_scene_destroy(sc);
}

Test(pathtrace, cube_ceiling_full_depth)
{
    /* Full depth.  The six-patch system B = E + rho F B with exact
     * form factors is only the piecewise-constant approximation (radiosity
     * is not uniform over a face), so it is not used as a reference.
     * Asserted instead, each within 3 standard errors:
     *  (a) the energy invariant of a closed enclosure with uniform rho:
     *      area mean of L = mean Le / (1 - rho) = (1/6) / 0.5 = 1/3, exact;
     *  (b) the four walls agree (symmetry);
     *  (c) floor, ceiling and walls against the brute-force walk above
     *      (errors combined in quadrature). */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    probe p = probe_surfaces(sc, 21, 0, "samples", "65536", "batch", "16384", "sampler", "random", NULL);
    const char *names[6] = {"wall-x0", "wall-x1", "floor", "ceiling", "wall-z0", "wall-z1"};
    uint32_t id[6];
    double mean = 0, var = 0;
    for (int f = 0; f < 6; f++) {
        id[f] = surface(sc, names[f]);
        mean += p.L[id[f]] / 6;
        var += p.se[id[f]] * p.se[id[f]] / 36;
    }
    cr_assert_lt(fabs(mean - 1.0 / 3.0), 3 * sqrt(var), "area mean %.6f +- %.2e", mean, sqrt(var));
    const int wall[4] = {0, 1, 4, 5};
    for (int i = 1; i < 4; i++) {
        double a = p.L[id[wall[0]]], b = p.L[id[wall[i]]];
        double s = hypot(p.se[id[wall[0]]], p.se[id[wall[i]]]);
        cr_assert_lt(fabs(a - b), 3 * s, "%s %.6f vs %s %.6f", names[wall[0]], a, names[wall[i]], b);
    }
    gsl_rng *r = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(r, 12345);
    const int faces[3] = {2, 3, 0};
    for (int i = 0; i < 3; i++) {
        double m, se;
        brute_cube(r, faces[i], 200000, &m, &se);
        uint32_t s = id[faces[i]];
        double tol = 3 * hypot(se, p.se[s]);
        cr_assert_lt(fabs(p.L[s] - m), tol, "%s: path tracer %.6f +- %.2e, brute force %.6f +- %.2e",
                     names[faces[i]], p.L[s], p.se[s], m, se);
    }
    gsl_rng_free(r);
    rp_scene_destroy(sc);
}

/* ------------------------------------------------------------ determinism */

Test(pathtrace, deterministic_for_any_thread_count)
{
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    const char *samplers[] = {"random", "stratified", "sobol"};
    for (int k = 0; k < 3; k++) {
        image a = render(sc, 77, 1, "spp", "2", "sampler", samplers[k], NULL);
        image b = render(sc, 77, 2, "spp", "2", "sampler", samplers[k], NULL);
        image c = render(sc, 77, 2, "spp", "2", "sampler", samplers[k], NULL);
        size_t bytes = a.npix * a.nbands * sizeof(float);
        cr_assert_eq(memcmp(a.radiance, b.radiance, bytes), 0, "%s: 1 vs 2 threads", samplers[k]);
        cr_assert_eq(memcmp(a.variance, b.variance, bytes), 0);
        cr_assert_eq(memcmp(b.radiance, c.radiance, bytes), 0, "%s: run to run", samplers[k]);
        cr_assert_eq(memcmp(b.variance, c.variance, bytes), 0);
        /* A different seed gives a different image. */
        image d = render(sc, 78, 2, "spp", "2", "sampler", samplers[k], NULL);
        cr_assert_neq(memcmp(a.radiance, d.radiance, bytes), 0);
        image_free(&a);
        image_free(&b);
        image_free(&c);
        image_free(&d);
    }
    rp_scene_destroy(sc);
    sc = rp_test_load("scenes/cube-ceiling.scene");
    probe p1 = probe_surfaces(sc, 5, 1, "samples", "3000", "batch", "700", NULL);
    probe p2 = probe_surfaces(sc, 5, 2, "samples", "3000", "batch", "700", NULL);
    cr_assert_eq(memcmp(p1.L, p2.L, sizeof p1.L), 0);
    cr_assert_eq(memcmp(p1.se, p2.se, sizeof p1.se), 0);
    cr_assert_eq(p1.work.rays, p2.work.rays);
    rp_scene_destroy(sc);
}

/* ----------------------------------------------------------------- camera */

Test(pathtrace, cornell_camera_orientation)
{
    /* The red wall (x ~ 550) is on the image's left, the green one on its
     * right (the photographs' view); the light is at the top: pixels wholly
     * on it read Le = (17, 12, 4) exactly (its reflectance is 0), and no
     * pixel of the bottom quarter does. */
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    const rp_camera *cam = rp_scene_camera(sc);
    uint32_t W = cam->width, H = cam->height;
    image im = render(sc, 1, 0, "spp", "4", NULL);
    double left[3] = {0}, right[3] = {0}, top_max = 0, top_var = -1, bottom_max = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            const float *px = im.radiance + ((size_t)y * W + x) * 3;
            /* Side strips, middle rows only (the walls, not floor or ceiling). */
            for (int b = 0; b < 3 && y >= 3 * H / 8 && y < 5 * H / 8; b++) {
                if (x < W / 8)
                    left[b] += px[b];
                if (x >= W - W / 8)
                    right[b] += px[b];
            }
            if (y < H / 4 && px[0] > top_max) {
                top_max = px[0];
                top_var = im.variance[((size_t)y * W + x) * 3];
            }
            if (y >= H - H / 4 && px[0] > bottom_max)
                bottom_max = px[0];
        }
    cr_assert_gt(left[0], 3 * left[1], "left strip should be red: %g %g %g", left[0], left[1], left[2]);
    cr_assert_gt(right[1], 2 * right[0], "right strip should be green: %g %g %g", right[0], right[1], right[2]);
    cr_assert_float_eq(top_max, 17.0, 1e-5);
    /* Every sample of such a pixel is 17: its variance is exactly 0. */
    cr_assert_eq(top_var, 0.0f);
    cr_assert_lt(bottom_max, 17.0 * 0.9);
    image_free(&im);
    rp_scene_destroy(sc);
}

/* --------------------------------------------------------------- interface */

Test(pathtrace, refuses_bad_options)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    rp_solver *s = NULL;
    rp_error err = {""};
    const char *bad[][2] = {{"sampler", "halton"}, {"spp", "0"},        {"spp", "-3"},
                            {"spp", "ten"},        {"samples", "0"},    {"batch", "0"},
                            {"max-depth", "-1"},   {"max-depth", "x"},  {"rr-depth", "0"},
                            {"no-such-option", "1"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        rp_status st = try_create(sc, RP_WANT_SURFACES, 1, 0, &s, &err, bad[i][0], bad[i][1], NULL);
        cr_assert_eq(st, RP_ERR_INPUT, "--%s %s accepted", bad[i][0], bad[i][1]);
        cr_assert_null(s);
        cr_assert_gt(strlen(err.message), 0u);
    }
    rp_scene_destroy(sc);
}

Test(pathtrace, no_camera_no_image)
{
    /* A scene without a camera: render is refused as bad input, surface
     * averages still work (and equal Le on the lone emitter). */
    rp_scene *sc = rp_test_parse("bands grey\nmaterial e reflect 0 emit 2\nquad lamp e 0 0 0 1 0 0 1 1 0 0 1 0\n");
    rp_solver *s = NULL;
    rp_error err = {""};
    cr_assert_eq(try_create(sc, RP_WANT_IMAGE, 1, 0, &s, &err, NULL), RP_ERR_INPUT);
    cr_assert_null(s);
    probe p = probe_surfaces(sc, 1, 0, "samples", "100", NULL);
    cr_assert_eq(p.L[0], 2.0);
    rp_scene_destroy(sc);
}

Test(pathtrace, progressive_counts_and_open_ended)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    const rp_camera *cam = rp_scene_camera(sc);
    double npix = (double)cam->width * cam->height;
    rp_error err = {""};
    /* spp 3: converged after exactly three steps, one path per pixel each. */
    rp_solver *s = create(sc, RP_WANT_IMAGE, 1, 0, "spp", "3", NULL);
    for (int k = 1; k <= 3; k++) {
        rp_step_info info;
        cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK);
        cr_assert_eq(info.paths, npix);
        cr_assert_geq(info.rays, npix);
        cr_assert_eq(info.converged, k == 3);
        cr_assert_float_eq(info.progress, k / 3.0, 1e-12);
    }
    rp_solver_destroy(s);
    /* Under an open-ended budget the default spp does not stop the run... */
    rp_options o = {sizeof o, RP_WANT_IMAGE, 1, 0, NULL, NULL, 0, 1, NULL, NULL, NULL, NULL, NULL};
    cr_assert_eq(rp_solver_create(rp_solver_lookup("pathtrace"), sc, &o, &s, &err), RP_OK);
    for (int k = 0; k < 20; k++) {
        rp_step_info info;
        cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK);
        cr_assert_eq(info.converged, 0);
    }
    rp_estimate e = {NULL, NULL, NULL, NULL, 0};
    cr_assert_eq(rp_solver_estimate(s, &e, &err), RP_OK);
    cr_assert_eq(e.samples, 20.0);
    /* ...and surfaces were not asked for. */
    double L[2], S[2];
    rp_estimate es = {NULL, NULL, L, S, 0};
    cr_assert_eq(rp_solver_estimate(s, &es, &err), RP_ERR_UNSUPPORTED);
    rp_solver_destroy(s);
    /* ...but an explicit one does. */
    const char *k[] = {"spp"}, *v[] = {"2"};
    rp_options o2 = {sizeof o2, RP_WANT_IMAGE, 1, 0, k, v, 1, 1, NULL, NULL, NULL, NULL, NULL};
    cr_assert_eq(rp_solver_create(rp_solver_lookup("pathtrace"), sc, &o2, &s, &err), RP_OK);
    rp_step_info info;
    cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK);
    cr_assert_eq(info.converged, 0);
    cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK);
    cr_assert_eq(info.converged, 1);
    rp_solver_destroy(s);
    rp_scene_destroy(sc);
}

/* ------------------------------------------------- emitting reflectors */

/* A lamp that emits and reflects (an MTL light: Kd 0.78, Ke 17 12 4) is a
 * light for next-event estimation and MIS like a pure emitter.  The unit
 * receiver (rho 1/2) under the unit-square lamp (Le 3) at height 1, seen
 * by a 4 x 4 camera at height 0.5 looking straight down at (0.3, 0.6):
 * with --max-depth 1 (emission and direct light only) each pixel's mean is
 * rho Le times the mean over its footprint on the receiver (a square, the
 * image plane being parallel) of Howell's B-3 by superposition (Gauss-
 * Legendre, closed_form.c).  Every pixel within 4 standard errors, each
 * under 1%; and the lamp that also reflects 1/2 is exactly as noisy as the
 * pure one (the same estimator: if NEE left it out, MIS would weigh its
 * hits down and the mean would fall short). */
static void direct_under_lamp(const char *lamp, double *se_sum)
{
    const double Le = 3, rho = 0.5, h = 0.5, fov = 8, cx = 0.3, cy = 0.6;
    char text[640];
    snprintf(text, sizeof text,
             "bands grey\n"
             "material floor reflect %g\n"
             "material lamp %s emit %g\n"
             "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
             "quad emitter lamp  0 0 1  0 1 1  1 1 1  1 0 1\n"
             "camera eye %g %g %g  look %g %g 0  up 0 1 0  fov %g  size 4 4\n",
             rho, lamp, Le, cx, cy, h, cx, cy, fov);
    rp_scene *sc = rp_test_parse(text);
    image im = render(sc, 11, 1, "sampler", "random", "spp", "1024", "max-depth", "1", NULL);
    const double s = h * tan(0.5 * fov * M_PI / 180);
    double worst = 0;
    *se_sum = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double F = rp_cf_point_rect_mean(cx + s * (i / 2.0 - 1), cx + s * ((i + 1) / 2.0 - 1),
                                             cy + s * (1 - (j + 1) / 2.0), cy + s * (1 - j / 2.0), 1, 1, 1);
            double want = rho * Le * F, got = im.radiance[j * 4 + i], se = sqrt(im.variance[j * 4 + i]);
            cr_assert_lt(se, 0.01 * want, "%s: pixel (%d, %d): standard error %.3g of %.4f", lamp, i, j, se, want);
            cr_assert_lt(fabs(got - want), 4 * se, "%s: pixel (%d, %d): %.6f, closed form %.6f +- %.2g", lamp, i,
                         j, got, want, se);
            worst = fmax(worst, fabs(got - want) / se);
            *se_sum += se;
        }
    cr_log_info("direct light under '%s': largest deviation %.2f standard errors, mean standard error %.3g", lamp,
                worst, *se_sum / 16);
    image_free(&im);
    rp_scene_destroy(sc);
}

Test(pathtrace, emitting_reflector_is_a_light)
{
    double se_pure, se_refl;
    direct_under_lamp("reflect 0", &se_pure);
    direct_under_lamp("reflect 0.5", &se_refl);
    cr_assert_leq(se_refl, se_pure * (1 + 1e-9), "standard errors: %.4g reflecting, %.4g pure", se_refl / 16,
                  se_pure / 16);
}
