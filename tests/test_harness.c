/* The benchmark harness (bench/run/harness.h, metrics.h, reference.h; bench/report/plot.h):
 * metrics on hand-made images, log-log fits on synthetic data, the
 * reference cache, the furnace's exact reference, and a tiny benchmark
 * whose runs.csv and summary.json must agree with each other and with the
 * images the runs produced. */
#include <criterion/criterion.h>
#include <gsl/gsl_randist.h>
#include <gsl/gsl_rng.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bench/run/harness.h"
#include "bench/run/metrics.h"
#include "bench/report/plot.h"
#include "bench/run/reference.h"
#include "geometry/scene.h"
#include "scene_util.h"

static char *make_tmpdir(void)
{
    static char buf[64];
    snprintf(buf, sizeof buf, "/tmp/rp_harness_XXXXXX");
    cr_assert_not_null(mkdtemp(buf));
    return buf;
}

static void remove_tree(const char *dir)
{
    char cmd[256];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_expect_eq(system(cmd), 0);
}



/* ------------------------------------------------------------ metrics */

/* 2 x 2 pixels, one band: differences 0, 1, 0, -2 against 1, 2, 3, 4. */
Test(metrics, image_metrics_by_hand)
{
    const float ref[4] = {1, 2, 3, 4}, img[4] = {1, 3, 3, 2};
    rp_image_metrics m;
    rp_metrics_image(img, ref, NULL, 4, 1, &m);
    cr_expect_eq(m.count, 4);
    cr_expect_float_eq(m.rmse, sqrt(5.0 / 4.0), 1e-12);        /* (0 + 1 + 0 + 4) / 4 */
    cr_expect_float_eq(m.mae, 3.0 / 4.0, 1e-12);               /* (0 + 1 + 0 + 2) / 4 */
    double rel = (1.0 / (4 + 0.01) + 4.0 / (16 + 0.01)) / 4;  /* (x-r)^2 / (r^2 + 0.01) */
    cr_expect_float_eq(m.relmse, rel, 1e-12);

    /* the mask drops the last pixel: differences 0, 1, 0 */
    const unsigned char mask[4] = {1, 1, 1, 0};
    rp_metrics_image(img, ref, mask, 4, 1, &m);
    cr_expect_eq(m.count, 3);
    cr_expect_float_eq(m.rmse, sqrt(1.0 / 3.0), 1e-12);
    cr_expect_float_eq(m.mae, 1.0 / 3.0, 1e-12);

    const unsigned char none[4] = {0, 0, 0, 0};
    rp_metrics_image(img, ref, none, 4, 1, &m);
    cr_expect(isnan(m.rmse) && m.count == 0);
}

/* Two pixels, three bands: every band counts. */
Test(metrics, image_metrics_over_bands)
{
    const float ref[6] = {1, 1, 1, 2, 2, 2}, img[6] = {1, 2, 1, 2, 2, 5};
    rp_image_metrics m;
    rp_metrics_image(img, ref, NULL, 2, 3, &m);
    cr_expect_eq(m.count, 6);
    cr_expect_float_eq(m.rmse, sqrt(10.0 / 6.0), 1e-12); /* 1^2 + 3^2 over 6 values */
    cr_expect_float_eq(m.mae, 4.0 / 6.0, 1e-12);
    /* the reference's RMSE standard error: sqrt(mean variance) */
    const float var[6] = {0.01f, 0.04f, 0.01f, 0.04f, 0.01f, 0.04f};
    cr_expect_float_eq(rp_metrics_reference_rmse_se(var, NULL, 2, 3), sqrt(0.025), 1e-7);
}

/* Relative errors 0.1 and -0.2 on two measured surfaces, one excluded,
 * one band with a zero reference (skipped). */
Test(metrics, surface_error_by_hand)
{
    const double ref[6] = {1, 10, 5, 0, 7, 7}, x[6] = {1.1, 8, 99, 3, 7, 7};
    const unsigned char smask[3] = {1, 0, 1};
    size_t m = 0;
    /* surface 0: bands (1 -> 1.1: 0.1), (10 -> 8: -0.2); surface 2 exact */
    double e = rp_metrics_surface_error(x, ref, smask, 3, 2, &m);
    cr_expect_eq(m, 4);
    cr_expect_float_eq(e, sqrt((0.01 + 0.04) / 4), 1e-12);
    /* surface 1 has a zero band: only its first band counts */
    const unsigned char all[3] = {1, 1, 1};
    e = rp_metrics_surface_error(x, ref, all, 3, 2, &m);
    cr_expect_eq(m, 5);
    double r1 = (99.0 - 5) / 5;
    cr_expect_float_eq(e, sqrt((0.01 + 0.04 + r1 * r1) / 5), 1e-12);
}

/* The debiased MSE against a noisy reference (metrics.h) on synthetic
 * data whose truth is known: K values L_k = 1 + k mod 7, an answer with a
 * fixed error e_k = a (1 if k even, -2 if odd) (MSE 2.5 a^2), and a
 * reference r_k that is the mean of n exponential samples of mean L_k
 * (skewed, as path-traced radiance is) with v_k its sample variance / n;
 * n = 64 and a = 0.3 put the reference's noise at 0.4 to 3 times the
 * error, as for accurate radiosity against a quick reference.  For every
 * seed the debiased MSE lies within 4 of its standard errors of the
 * truth, while the plain MSE is off by more than 10 of them; the
 * reference resolves the error at a = 0.3 and not at a = 0. */
static void synthetic(unsigned long seed, double a, size_t K, unsigned n, float *x, float *r, float *v)
{
    gsl_rng *g = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(g, seed);
    for (size_t k = 0; k < K; k++) {
        double L = 1 + (double)(k % 7), s = 0, s2 = 0;
        for (unsigned i = 0; i < n; i++) {
            double y = gsl_ran_exponential(g, L);
            s += y;
            s2 += y * y;
        }
        double m = s / n;
        r[k] = (float)m;
        v[k] = (float)((s2 - n * m * m) / (n - 1) / n);
        x[k] = (float)(L + a * (k % 2 ? -2 : 1));
    }
    gsl_rng_free(g);
}

Test(metrics, debiased_mse_finds_the_error_under_reference_noise)
{
    enum { K = 20000, N = 64 };
    float *x = malloc(K * sizeof *x), *r = malloc(K * sizeof *r), *v = malloc(K * sizeof *v);
    cr_assert(x && r && v);
    const double a = 0.3, truth = 2.5 * a * a;
    for (unsigned long seed = 1; seed <= 10; seed++) {
        synthetic(seed, a, K, N, x, r, v);
        rp_debiased_mse d;
        rp_metrics_debiased_image(x, r, v, NULL, K, 1, &d);
        cr_expect_eq(d.count, K);
        cr_expect(d.se > 0);
        cr_expect(fabs(d.mse - truth) <= 4 * d.se, "seed %lu: %g vs %g, se %g", seed, d.mse, truth, d.se);
        rp_image_metrics m;
        rp_metrics_image(x, r, NULL, K, 1, &m);
        cr_expect(m.rmse * m.rmse - truth > 10 * d.se, "seed %lu: plain MSE %g", seed, m.rmse * m.rmse);
        cr_expect(rp_metrics_resolved(&d), "seed %lu: se %g of %g", seed, d.se, d.mse);
    }
    /* an answer with outliers (fireflies: 5 values 30 too high) is still
     * resolved: the empirical standard error counts their spread, the
     * normal one does not (metrics.h) */
    synthetic(11, a, K, N, x, r, v);
    double truth_ff = 0;
    for (size_t k = 0; k < K; k++) {
        if (k % 4000 == 1)
            x[k] += 30;
        double e = x[k] - (1 + (double)(k % 7));
        truth_ff += e * e / K;
    }
    rp_debiased_mse f;
    rp_metrics_debiased_image(x, r, v, NULL, K, 1, &f);
    cr_expect(fabs(f.mse - truth_ff) <= 4 * f.se, "%g vs %g, se %g", f.mse, truth_ff, f.se);
    cr_expect(rp_metrics_resolved(&f), "se %g of %g", f.se, f.mse);
    /* no error at all: nothing to resolve */
    synthetic(99, 0, K, N, x, r, v);
    rp_debiased_mse d;
    rp_metrics_debiased_image(x, r, v, NULL, K, 1, &d);
    cr_expect(fabs(d.mse) <= 4 * d.se, "%g, se %g", d.mse, d.se);
    cr_expect(!rp_metrics_resolved(&d));
    /* an exact reference resolves any error, none included */
    rp_metrics_debiased_image(x, x, NULL, NULL, K, 1, &d);
    cr_expect(d.mse == 0 && d.se == 0 && rp_metrics_resolved(&d));
    free(x);
    free(r);
    free(v);
}

/* Surfaces: 57 relative errors e_k = 0.01 (1 + k mod 3) against a
 * reference with normal relative errors of standard deviation s_k = 0.004
 * (1 + k mod 5); over 400 seeds the debiased MSE's z-score against the
 * known MSE has about unit spread: |z| < 2 in 95% of them (the interval
 * checked, 0.91 .. 0.99, holds with probability > 0.999 for a correct
 * standard error). */
Test(metrics, debiased_surface_error_has_a_true_standard_error)
{
    enum { NS = 19, NB = 3 };
    double x[NS * NB], ref[NS * NB], se[NS * NB], truth = 0;
    for (size_t k = 0; k < NS * NB; k++) {
        double e = 0.01 * (double)(1 + k % 3);
        truth += e * e / (NS * NB);
    }
    gsl_rng *g = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(g, 7);
    int inside = 0;
    for (int t = 0; t < 400; t++) {
        for (size_t k = 0; k < NS * NB; k++) {
            double L = 0.1 + 0.05 * (double)(k % 4), s = 0.004 * (double)(1 + k % 5);
            ref[k] = L * (1 + gsl_ran_gaussian(g, s));
            se[k] = s * ref[k];
            x[k] = L * (1 + 0.01 * (double)(1 + k % 3));
        }
        rp_debiased_mse d;
        rp_metrics_debiased_surfaces(x, ref, se, NULL, NS, NB, &d);
        cr_assert_eq(d.count, NS * NB);
        inside += fabs(d.mse - truth) < 2 * d.se;
    }
    gsl_rng_free(g);
    cr_expect(inside >= 364 && inside <= 396, "%d of 400 within 2 standard errors", inside);
}

/* An exact power law y = 3 x^-0.5 has slope -0.5 and a zero-width
 * interval. */
Test(metrics, fit_exact_power_law)
{
    double x[6], y[6];
    for (int i = 0; i < 6; i++) {
        x[i] = pow(2, i);
        y[i] = 3 * pow(x[i], -0.5);
    }
    rp_fit f;
    rp_fit_loglog(x, y, 6, 0.95, &f);
    cr_assert(f.ok);
    cr_expect_float_eq(f.slope, -0.5, 1e-12);
    cr_expect_float_eq(f.intercept, log(3.0), 1e-12);
    cr_expect(f.hi - f.lo < 1e-10);
    cr_expect_eq(f.n, 6);
}

/* Noisy data: the slope and its interval against the textbook formulas
 * computed here, with t(0.975, 3) = 3.182446305 from tables. */
Test(metrics, fit_noisy_against_formulas)
{
    const double x[5] = {1, 2, 4, 8, 16};
    const double noise[5] = {0.05, -0.03, 0.04, -0.06, 0.01};
    double y[5], lx[5], ly[5];
    for (int i = 0; i < 5; i++) {
        y[i] = 2 * pow(x[i], -0.75) * exp(noise[i]);
        lx[i] = log(x[i]);
        ly[i] = log(y[i]);
    }
    double mx = 0, my = 0;
    for (int i = 0; i < 5; i++) {
        mx += lx[i] / 5;
        my += ly[i] / 5;
    }
    double sxx = 0, sxy = 0;
    for (int i = 0; i < 5; i++) {
        sxx += (lx[i] - mx) * (lx[i] - mx);
        sxy += (lx[i] - mx) * (ly[i] - my);
    }
    double b = sxy / sxx, a = my - b * mx, ss = 0;
    for (int i = 0; i < 5; i++)
        ss += (ly[i] - a - b * lx[i]) * (ly[i] - a - b * lx[i]);
    double se = sqrt(ss / 3 / sxx);
    rp_fit f;
    rp_fit_loglog(x, y, 5, 0.95, &f);
    cr_assert(f.ok);
    cr_expect_float_eq(f.slope, b, 1e-12);
    cr_expect_float_eq(f.slope_se, se, 1e-12);
    cr_expect_float_eq(f.lo, b - 3.182446305 * se, 1e-8);
    cr_expect_float_eq(f.hi, b + 3.182446305 * se, 1e-8);
    cr_expect(f.lo < -0.75 && -0.75 < f.hi, "[%g, %g]", f.lo, f.hi);
    /* two points are not enough for an interval; non-positive values are skipped */
    const double x2[3] = {1, 2, 4}, y2[3] = {1, -1, 0.5};
    rp_fit_loglog(x2, y2, 3, 0.95, &f);
    cr_expect(!f.ok && f.n == 2);
}

/* Log-log interpolation: y = 1/x between (1, 1) and (4, 0.25) reaches 0.5
 * at x = 2. */
Test(metrics, time_to_error)
{
    const double t[3] = {1, 4, 8}, e[3] = {1, 0.25, 0.2};
    int before;
    cr_expect_float_eq(rp_metrics_time_to_error(t, e, 3, 0.5, &before), 2.0, 1e-12);
    cr_expect_eq(before, 0);
    cr_expect_float_eq(rp_metrics_time_to_error(t, e, 3, 2.0, &before), 1.0, 1e-12);
    cr_expect_eq(before, 1);
    cr_expect(isnan(rp_metrics_time_to_error(t, e, 3, 0.1, &before)));
}

/* -------------------------------------------------------------- specs */

Test(harness, method_specs)
{
    rp_method_spec m;
    rp_error err;
    cr_assert_eq(rp_method_spec_parse("gauss-seidel:elements=1000:reconstruct=gouraud", &m, &err), RP_OK, "%s",
                 err.message);
    cr_expect_str_eq(m.name, "gauss-seidel");
    cr_expect_eq(m.count, 2);
    cr_expect_str_eq(rp_method_spec_get(&m, "elements"), "1000");
    cr_expect_str_eq(rp_method_spec_get(&m, "reconstruct"), "gouraud");
    cr_expect(!rp_method_is_monte_carlo(&m));
    cr_assert_eq(rp_method_spec_parse("southwell:ambient:overshoot=1.5", &m, &err), RP_OK, "%s", err.message);
    cr_expect_str_eq(rp_method_spec_get(&m, "ambient"), "1");
    cr_assert_eq(rp_method_spec_parse("pathtrace:sampler=sobol", &m, &err), RP_OK);
    cr_expect(rp_method_is_monte_carlo(&m));
    cr_expect_eq(rp_method_spec_parse("pathtrace:elements=4", &m, &err), RP_ERR_INPUT);
    cr_expect(strstr(err.message, "elements") != NULL, "%s", err.message);
    cr_expect_eq(rp_method_spec_parse("nosuchmethod", &m, &err), RP_ERR_INPUT);
    cr_expect_eq(rp_method_spec_parse("pathtrace:spp", &m, &err), RP_ERR_INPUT); /* needs a value */
    /* An option taking a word or a number ("auto|FRAC"): both, and
     * nothing else. */
    cr_expect_eq(rp_method_spec_parse("hierarchical:cluster-area=1e-3", &m, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_method_spec_parse("hierarchical:cluster-area=auto", &m, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_method_spec_parse("hierarchical:variation-weight=10", &m, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_method_spec_parse("hierarchical:simplify=0.1", &m, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_method_spec_parse("hierarchical:cluster-area=big", &m, &err), RP_ERR_INPUT);
    cr_expect_eq(rp_method_spec_parse("hierarchical:cluster=maybe", &m, &err), RP_ERR_INPUT);
    cr_expect_eq(rp_method_spec_parse("hierarchical:vis-rays=2.5", &m, &err), RP_ERR_INPUT);
    rp_method_spec *list = NULL;
    size_t n = 0;
    cr_assert_eq(rp_method_list_parse("pathtrace,southwell:elements=40", &list, &n, &err), RP_OK);
    cr_expect_eq(n, 2);
    cr_expect_str_eq(list[1].text, "southwell:elements=40");
    free(list);
}

/* ---------------------------------------------------------- references */

/* docs/ground-truth.md, the furnace: rho 0.5, Le 1 -> L = 1 / (1 - 0.5) = 2
 * at every measured pixel and on every surface, exactly. */
Test(reference, furnace_is_exact)
{
    char *dir = make_tmpdir();
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    double L = 0;
    rp_error err;
    cr_assert_eq(rp_reference_furnace(scene, &L, &err), 1);
    cr_expect_eq(L, 2.0);
    rp_reference_params p = {.size = sizeof p, .cache_dir = dir};
    rp_reference *ref = NULL;
    cr_assert_eq(rp_reference_get(scene, "furnace", &p, &ref, &err), RP_OK, "%s", err.message);
    cr_expect_eq(ref->kind, RP_REFERENCE_EXACT);
    /* the camera is inside the closed box: every pixel is measured */
    size_t npix = (size_t)ref->width * ref->height;
    cr_expect_eq(ref->mask_count, npix);
    for (size_t i = 0; i < npix; i++)
        cr_assert_eq(ref->radiance[i], 2.0f, "pixel %zu: %g", i, ref->radiance[i]);
    for (size_t s = 0; s < ref->nsurfaces; s++)
        cr_expect_eq(ref->surface_radiance[s], 2.0);
    cr_expect_eq(ref->rmse_se, 0.0);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_tree(dir);
}

/* Not furnaces: a uniform box seen from outside (closed, but its faces see
 * nothing), and the Cornell box (several materials, open). */
Test(reference, furnace_detection_is_from_the_scene)
{
    rp_error err;
    double L[3];
    rp_scene *s = rp_test_parse("bands grey\nmaterial m reflect 0.5 emit 1\nbox b m 0 0 0 1 1 1 outward\n");
    cr_expect_eq(rp_reference_furnace(s, L, &err), 0);
    rp_scene_destroy(s);
    /* the same box inward with another reflectance and emission is one */
    s = rp_test_parse("bands grey\nmaterial m reflect 0.25 emit 3\nbox b m 0 0 0 2 1 1 inward\n");
    cr_expect_eq(rp_reference_furnace(s, L, &err), 1);
    cr_expect_float_eq(L[0], 3 / 0.75, 1e-15);
    rp_scene_destroy(s);
    /* inward, but two materials that differ */
    s = rp_test_parse("bands grey\nmaterial m reflect 0.5 emit 1\nmaterial n reflect 0.4 emit 1\n"
              "quad a m 0 0 0  1 0 0  1 1 0  0 1 0\nquad b n 0 0 1  0 1 1  1 1 1  1 0 1\n");
    cr_expect_eq(rp_reference_furnace(s, L, &err), 0);
    rp_scene_destroy(s);
    s = rp_test_load("scenes/cornell.scene");
    cr_expect_eq(rp_reference_furnace(s, L, &err), 0);
    rp_scene_destroy(s);
}

/* Two parallel plates with a 16 x 16 camera: a path-traced reference. */
static const char *plates =
    "bands grey\nmaterial w reflect 0.6\nmaterial l reflect 0.2 emit 1\n"
    "quad a w 0 0 0  1 0 0  1 1 0  0 1 0\nquad b l 0 0 0.5  0 1 0.5  1 1 0.5  1 0 0.5\n"
    "camera eye 0.5 0.5 0.05 look 0.5 0.5 1 up 0 1 0 fov 60 size 16 16\n";

/* The reference's variance estimate is unbiased (reference.h: independent
 * random numbers): two references with different seeds differ, pixel by
 * pixel, by as much as their estimated variances say, E[(A - B)^2] =
 * v_A + v_B.  The mean of (A - B)^2 - v_A - v_B over 32 x 32 pixels lies
 * within 4 of its standard errors of 0 and its relative size is below
 * 15% (scrambled Sobol' points, whose sample variance overestimates their
 * error, give -0.63 (v_A + v_B) on this smooth image: checked). */
Test(reference, variance_estimate_is_unbiased)
{
    char *dir = make_tmpdir();
    char text[512];
    snprintf(text, sizeof text, "%.*s32 32\n", (int)(strlen(plates) - strlen("16 16\n")), plates);
    rp_scene *scene = rp_test_parse(text);
    rp_error err;
    rp_reference *ref[2];
    for (int i = 0; i < 2; i++) {
        rp_reference_params p = {.size = sizeof p, .spp = 32, .samples = 256, .cache_dir = dir,
                                 .seed = 1000 + (uint64_t)i};
        cr_assert_eq(rp_reference_get(scene, "plates", &p, &ref[i], &err), RP_OK, "%s", err.message);
    }
    cr_assert_eq(ref[0]->width, 32);
    size_t n = (size_t)ref[0]->width * ref[0]->height;
    float *zero = calloc(n, sizeof *zero), *vsum = malloc(n * sizeof *vsum);
    cr_assert(zero && vsum);
    double v = 0;
    for (size_t i = 0; i < n; i++) {
        vsum[i] = ref[0]->variance[i] + ref[1]->variance[i];
        v += vsum[i] / (double)n;
    }
    rp_debiased_mse d;
    rp_metrics_debiased_image(ref[0]->radiance, ref[1]->radiance, vsum, NULL, n, 1, &d);
    cr_expect(fabs(d.mse) <= 4 * d.se, "%g, se %g", d.mse, d.se);
    cr_expect(fabs(d.mse) < 0.15 * v, "%g against mean v_A + v_B %g", d.mse, v);
    free(zero);
    free(vsum);
    rp_reference_destroy(ref[0]);
    rp_reference_destroy(ref[1]);
    rp_scene_destroy(scene);
    remove_tree(dir);
}

Test(reference, cache_hit_and_miss)
{
    char *dir = make_tmpdir();
    rp_scene *scene = rp_test_parse(plates);
    rp_error err;
    rp_reference_params p = {.size = sizeof p, .spp = 8, .samples = 256, .cache_dir = dir};
    rp_reference *a = NULL, *b = NULL, *c = NULL;
    cr_assert_eq(rp_reference_get(scene, "plates", &p, &a, &err), RP_OK, "%s", err.message);
    cr_expect_eq(a->kind, RP_REFERENCE_PATHTRACE);
    cr_expect_eq(a->cached, 0);
    struct stat sb;
    cr_expect_eq(stat(a->exr_path, &sb), 0, "%s", a->exr_path);
    cr_expect_eq(stat(a->json_path, &sb), 0, "%s", a->json_path);
    cr_expect(a->rmse_se > 0);
    /* the file name is the scene hash and the options hash */
    char hash[17];
    rp_scene_hash(scene, hash);
    cr_expect(strstr(a->exr_path, hash) != NULL);

    /* the same options: read back, bit for bit */
    cr_assert_eq(rp_reference_get(scene, "plates", &p, &b, &err), RP_OK, "%s", err.message);
    cr_expect_eq(b->cached, 1);
    cr_expect_str_eq(b->exr_path, a->exr_path);
    size_t n = (size_t)a->width * a->height;
    cr_expect_eq(memcmp(a->radiance, b->radiance, n * sizeof(float)), 0);
    cr_expect_eq(memcmp(a->variance, b->variance, n * sizeof(float)), 0);
    for (size_t s = 0; s < a->nsurfaces; s++) {
        cr_expect_eq(a->surface_radiance[s], b->surface_radiance[s]);
        cr_expect_eq(a->surface_stderr[s], b->surface_stderr[s]);
    }
    cr_expect_eq(a->rmse_se, b->rmse_se);
    cr_expect_eq(b->spp, 8);

    /* other options: another key, computed afresh */
    p.spp = 16;
    cr_assert_eq(rp_reference_get(scene, "plates", &p, &c, &err), RP_OK, "%s", err.message);
    cr_expect_eq(c->cached, 0);
    cr_expect_str_neq(c->options_hash, a->options_hash);
    cr_expect_str_neq(c->exr_path, a->exr_path);
    /* twice the samples: the standard error shrinks by about sqrt 2 */
    cr_expect(c->rmse_se < a->rmse_se, "%g vs %g", c->rmse_se, a->rmse_se);

    /* the emitting plate sends out at least its own Le = 1 */
    cr_expect(a->surface_radiance[1] >= 1.0);
    rp_reference_destroy(a);
    rp_reference_destroy(b);
    rp_reference_destroy(c);
    rp_scene_destroy(scene);
    remove_tree(dir);
}

/* ------------------------------------------------------ a tiny bench */

static char *slurp(const char *path)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f, "%s", path);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    cr_assert_eq(fread(s, 1, (size_t)n, f), (size_t)n);
    s[n] = '\0';
    fclose(f);
    return s;
}

/* The value of column col (0-based) in a CSV line without quotes. */
static double csv_col(const char *line, int col)
{
    const char *p = line;
    for (int i = 0; i < col; i++) {
        p = strchr(p, ',');
        cr_assert_not_null(p);
        p++;
    }
    return strtod(p, NULL);
}

static int header_index(const char *header, const char *name)
{
    int col = 0;
    size_t n = strlen(name);
    for (const char *p = header; *p; col++) {
        if (strncmp(p, name, n) == 0 && (p[n] == ',' || p[n] == '\n'))
            return col;
        p = strchr(p, ',');
        if (!p)
            break;
        p++;
    }
    cr_assert_fail("column %s not in runs.csv", name);
    return -1;
}

/* Pathtrace and Jacobi on the furnace for 0.3 s each: runs.csv has a row
 * per checkpoint, its final rows average to summary.json's numbers, and the
 * final RMSE is the RMSE of the final image against 2. */
Test(harness, tiny_bench_files_agree, .timeout = 120)
{
    char *dir = make_tmpdir();
    char cache[128], out[128];
    snprintf(cache, sizeof cache, "%s/refs", dir);
    snprintf(out, sizeof out, "%s/out", dir);
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    rp_error err;
    rp_reference_params rp = {.size = sizeof rp, .cache_dir = cache};
    rp_reference *ref = NULL;
    cr_assert_eq(rp_reference_get(scene, "furnace", &rp, &ref, &err), RP_OK, "%s", err.message);
    rp_method_spec *methods = NULL;
    size_t nm = 0;
    cr_assert_eq(rp_method_list_parse("pathtrace,jacobi:elements=24", &methods, &nm, &err), RP_OK, "%s", err.message);
    rp_bench_params bp = {.size = sizeof bp, .nseeds = 2, .seed = 1};
    bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = 0.3, .levels = 5, .keep_image = 1};
    rp_bench *b = NULL;
    cr_assert_eq(rp_bench_run(scene, "furnace", ref, methods, nm, &bp, &b, &err), RP_OK, "%s", err.message);
    cr_assert_eq(b->nruns, 3); /* two seeds of pathtrace, one Jacobi */
    cr_expect_eq(b->failures, 0);
    char note[256];
    rp_bench_output o = {.size = sizeof o, .sheet = 1};
    cr_assert_eq(rp_bench_write(b, out, &o, note, &err), RP_OK, "%s", err.message);

    /* every run ended at the budget and took its time as solver time */
    for (size_t r = 0; r < b->nruns; r++) {
        const rp_trial *t = &b->runs[r];
        cr_assert(t->ncp >= 1);
        cr_expect(t->cp[t->ncp - 1].final);
        cr_expect(t->cp[t->ncp - 1].wall_s >= 0.3);
        for (size_t i = 1; i < t->ncp; i++)
            cr_expect(t->cp[i].wall_s > t->cp[i - 1].wall_s && t->cp[i].index < t->cp[i - 1].index);
    }
    /* the path tracer's final RMSE, recomputed from its image */
    const rp_trial *pt = &b->runs[0];
    cr_assert_not_null(pt->image);
    size_t npix = (size_t)ref->width * ref->height;
    double se = 0;
    for (size_t i = 0; i < npix; i++)
        se += ((double)pt->image[i] - 2.0) * ((double)pt->image[i] - 2.0);
    double rmse0 = sqrt(se / (double)npix);
    cr_expect_float_eq(pt->cp[pt->ncp - 1].rmse, rmse0, 1e-9 * rmse0);

    char path[256];
    snprintf(path, sizeof path, "%s/runs.csv", out);
    char *csv = slurp(path);
    char *nl = strchr(csv, '\n');
    cr_assert_not_null(nl);
    int c_method = 0, c_seed = header_index(csv, "seed"), c_rmse = header_index(csv, "rmse"),
        c_final = header_index(csv, "final"), c_wall = header_index(csv, "wall_s");
    (void)c_method;
    size_t rows = 0, expect_rows = 0;
    for (size_t r = 0; r < b->nruns; r++)
        expect_rows += b->runs[r].ncp;
    double pt_final_sum = 0, pt_wall_sum = 0, jacobi_final = NAN;
    int pt_finals = 0;
    for (char *line = nl + 1; *line; line = strchr(line, '\n') + 1) {
        rows++;
        if (csv_col(line, c_final) == 1) {
            if (strncmp(line, "pathtrace,", 10) == 0) {
                pt_final_sum += csv_col(line, c_rmse);
                pt_wall_sum += csv_col(line, c_wall);
                pt_finals++;
                cr_expect(csv_col(line, c_seed) == 1 || csv_col(line, c_seed) == 2);
            } else
                jacobi_final = csv_col(line, c_rmse);
        }
        if (!strchr(line, '\n'))
            break;
    }
    cr_expect_eq(rows, expect_rows);
    cr_expect_eq(pt_finals, 2);
    /* runs.csv holds 6 significant digits */
    double pt_mean = pt_final_sum / 2;
    cr_expect_float_eq(pt_mean, b->summary[0].final.rmse, 1e-5 * pt_mean);

    snprintf(path, sizeof path, "%s/summary.json", out);
    char *json = slurp(path);
    /* methods[0].final.rmse in summary.json */
    const char *m0 = strstr(json, "\"spec\": \"pathtrace\"");
    cr_assert_not_null(m0);
    const char *fin = strstr(m0, "\"final\":");
    cr_assert_not_null(fin);
    const char *r = strstr(fin, "\"rmse\": ");
    cr_assert_not_null(r);
    double json_rmse = strtod(r + 8, NULL);
    cr_expect_float_eq(json_rmse, pt_mean, 1e-5 * pt_mean, "json %g csv %g", json_rmse, pt_mean);
    const char *w = strstr(fin, "\"wall_s\": ");
    cr_assert_not_null(w);
    cr_expect_float_eq(strtod(w + 10, NULL), pt_wall_sum / 2, 1e-5 * pt_wall_sum);
    /* Jacobi on a furnace: exact up to the form factors (row sums 1 to
     * about 1e-5), far below the path tracer */
    const char *m1 = strstr(json, "\"spec\": \"jacobi:elements=24\"");
    cr_assert_not_null(m1);
    r = strstr(strstr(m1, "\"final\":"), "\"rmse\": ");
    cr_expect_float_eq(strtod(r + 8, NULL), jacobi_final, 1e-5 * jacobi_final + 1e-12);
    cr_expect(jacobi_final < 1e-3, "jacobi %g", jacobi_final);
    cr_expect(jacobi_final < pt_mean / 10);
    snprintf(path, sizeof path, "%s/report.md", out);
    char *md = slurp(path);
    cr_expect(strstr(md, "| `pathtrace` |") != NULL);
    snprintf(path, sizeof path, "%s/sheet.png", out);
    struct stat sb;
    cr_expect_eq(stat(path, &sb), 0);
    free(md);
    free(json);
    free(csv);
    rp_bench_destroy(b);
    free(methods);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_tree(dir);
}

/* Defaults live once, in the option specs --help shows: an absent option
 * takes its spec's numeric fallback; a given one wins; no specs, no
 * default (the caller's value stays). */
Test(harness, option_defaults_come_from_the_specs)
{
    static const rp_option_spec specs[] = {
        {"tolerance", "EPS", "stop at EPS", "1e-6"},
        {"rays", "N", "rays", "100000"},
        {"mode", "a|b", "a word", "a"},
        {NULL, NULL, NULL, NULL},
    };
    const char *keys[1] = {"rays"}, *values[1] = {"7"};
    rp_options o = {.size = sizeof o, .keys = keys, .values = values, .count = 1, .specs = specs};
    rp_error err;
    double tol = -1;
    unsigned long rays = 0;
    cr_assert_eq(rp_options_double(&o, "tolerance", 0, 1, &tol, &err), RP_OK);
    cr_expect_eq(tol, 1e-6);
    cr_assert_eq(rp_options_uint(&o, "rays", 1, 1000000, &rays, &err), RP_OK);
    cr_expect_eq(rays, 7);
    o.specs = NULL;
    tol = -1;
    cr_assert_eq(rp_options_double(&o, "tolerance", 0, 1, &tol, &err), RP_OK);
    cr_expect_eq(tol, -1);
    /* every registered method: each numeric fallback is within what its own
     * init accepts, so creating it with no options at all must work for a
     * scene it can solve */
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    for (const rp_solver_type *const *t = rp_solver_types(); *t; t++) {
        rp_options none = {.size = sizeof none, .want = RP_WANT_SURFACES, .seed = 1};
        rp_solver *s = NULL;
        cr_expect_eq(rp_solver_create(*t, scene, &none, &s, &err), RP_OK, "%s: %s", (*t)->name, err.message);
        rp_solver_destroy(s);
    }
    rp_scene_destroy(scene);
}

/* Chart colours are fixed per method name, in every report: distinct
 * between methods, the same for a method's variants, which differ by dash
 * type from the plain spec. */
Test(harness, method_chart_styles_are_fixed)
{
    char a[64], b[64];
    snprintf(a, sizeof a, "%s", rp_plot_method_style("pathtrace"));
    snprintf(b, sizeof b, "%s", rp_plot_method_style("pathtrace"));
    cr_expect_str_eq(a, b);
    const char *names[] = {"pathtrace", "gauss-seidel", "jacobi", "southwell", "stochastic-jacobi", "hierarchical"};
    char colours[6][16];
    for (int i = 0; i < 6; i++) {
        const char *s = strstr(rp_plot_method_style(names[i]), "'#");
        cr_assert_not_null(s);
        snprintf(colours[i], sizeof colours[i], "%.9s", s);
        for (int k = 0; k < i; k++)
            cr_expect_str_neq(colours[i], colours[k], "%s and %s share %s", names[i], names[k], colours[i]);
    }
    snprintf(b, sizeof b, "%s", rp_plot_method_style("pathtrace:sampler=random"));
    cr_expect(strstr(b, colours[0]) != NULL, "%s", b);
    cr_expect_str_neq(a, b, "a variant's dash type differs");
}
