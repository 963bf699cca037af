/* Tests of stochastic Jacobi radiosity ("stochastic-jacobi").
 *
 * Check values come from closed forms or from another method, not from
 * this one:
 *   - furnace (closed box, rho 0.5, Le 1): L = Le / (1 - rho) = 2.  Every
 *     ray from a closed uniform-rho box lands on a front face, so the total
 *     power, and the furnace's single surface average, has (almost) zero
 *     variance: the tolerance is 3 standard errors plus the truncation of
 *     the Neumann series (unshot power below 1e-12 of the emitted: at most
 *     2e-12 in L) and rounding (1e-9);
 *   - energy invariant (closed cube of 54 patches, uniform rho 0.5, uneven
 *     emission): area-mean L = mean(Le) / (1 - rho), to 3 conservative
 *     standard errors (sum of the surfaces' standard errors, weighted by
 *     area: the bound for perfectly correlated errors) plus truncation;
 *   - parallel plates (Howell C-11, computed here): receiver L = rho F Le,
 *     within 3 standard errors, random and Sobol' samplers;
 *   - error ~ N^-1/2: log(standard error) against log(rays) over 2.1
 *     decades, slope -0.5 +- 0.05 (gsl_fit_linear), and the errors against
 *     the closed form agree with the standard errors (mean z^2);
 *   - agreement with gauss-seidel on the same mesh (the 54-patch cube with
 *     mixed rho, one element per patch, analytic form factors without
 *     occluders), patch by patch: every |z| < 4, at most 2 beyond 3, mean
 *     z^2 in [0.4, 2];
 *   - the standard errors are honest per element: the same z test against
 *     the analytic 2 in the 54-patch furnace;
 *   - images: furnace pixels are 2 to within their variance estimate,
 *     emitters show Le, backs and misses are black;
 *   - determinism: bit-identical answers for 1 and 2 threads. */
#include <criterion/criterion.h>

#include <gsl/gsl_errno.h>
#include <gsl/gsl_fit.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/scene.h"
#include "scene_util.h"
#include "solvers/solver.h"
#include "closed_form.h"

#define PI 3.14159265358979323846

static void setup(void) { gsl_set_error_handler_off(); }

/* ---- scenes ------------------------------------------------------------ */



/* A closed unit cube seen from inside, each face cut into 3 x 3 square
 * patches, every patch its own surface and material (54 surfaces).  With
 * mixed == 0 every rho is 0.5; otherwise rho runs over 0.2 .. 0.8.  The
 * emission is uneven either way: Le 1 on alternate ceiling patches, 3 on
 * one floor patch.  *mean_le gets the area mean of Le. */
static rp_scene *cube_patches(int mixed, double *mean_le)
{
    /* Origin o and edges a, b of each face, with a x b pointing inwards. */
    static const double face[6][3][3] = {
        {{0, 0, 0}, {0, 0, 1}, {1, 0, 0}}, /* y = 0, floor */
        {{0, 1, 0}, {1, 0, 0}, {0, 0, 1}}, /* y = 1, ceiling */
        {{0, 0, 0}, {0, 1, 0}, {0, 0, 1}}, /* x = 0 */
        {{1, 0, 0}, {0, 0, 1}, {0, 1, 0}}, /* x = 1 */
        {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, /* z = 0 */
        {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}}, /* z = 1 */
    };
    const int g = 3;
    size_t cap = 64 * 1024, len = 0;
    char *buf = malloc(cap);
    cr_assert(buf);
    len += (size_t)snprintf(buf + len, cap - len, "bands grey\n"
                            "camera eye 0.5 0.5 0.1  look 0.5 0.5 1  up 0 1 0  fov 80  size 32 32\n");
    double le_sum = 0;
    for (int f = 0; f < 6; f++)
        for (int i = 0; i < g; i++)
            for (int j = 0; j < g; j++) {
                int id = (f * g + i) * g + j;
                double rho = mixed ? 0.2 + 0.1 * (id % 7) : 0.5;
                double le = 0;
                if (f == 1 && (i + j) % 2 == 0)
                    le = 1;
                if (f == 0 && i == 1 && j == 2)
                    le = 3;
                le_sum += le;
                len += (size_t)snprintf(buf + len, cap - len, "material m%d reflect %g emit %g\n", id, rho, le);
                double v[4][3];
                const double ui[4] = {(double)i / g, (double)(i + 1) / g, (double)(i + 1) / g, (double)i / g};
                const double vj[4] = {(double)j / g, (double)j / g, (double)(j + 1) / g, (double)(j + 1) / g};
                for (int k = 0; k < 4; k++)
                    for (int c = 0; c < 3; c++)
                        v[k][c] = face[f][0][c] + ui[k] * face[f][1][c] + vj[k] * face[f][2][c];
                len += (size_t)snprintf(buf + len, cap - len, "quad p%d m%d", id, id);
                for (int k = 0; k < 4; k++)
                    len += (size_t)snprintf(buf + len, cap - len, "  %.17g %.17g %.17g", v[k][0], v[k][1], v[k][2]);
                len += (size_t)snprintf(buf + len, cap - len, "\n");
                cr_assert(len < cap);
            }
    *mean_le = le_sum / (6.0 * g * g);
    rp_scene *s = rp_test_parse(buf);
    free(buf);
    return s;
}

/* Howell's catalog C-11: directly opposed parallel a x b rectangles at
 * distance c (docs/ground-truth.md). */
/* ---- running a method -------------------------------------------------- */

#define MAX_OPTS 16

typedef struct run {
    const rp_scene *scene;
    rp_solver *solver;
    char buf[512];
    const char *keys[MAX_OPTS], *values[MAX_OPTS];
    rp_options o;
    rp_step_info sum, last;
    unsigned long steps;
    size_t ns, nb;
    double *L, *se;    /* surface averages and standard errors */
} run;

/* opts: "key=value ..." */
static rp_status run_open(run *r, const char *method, const rp_scene *sc, unsigned want, int threads,
                          uint64_t seed, const char *opts, rp_error *err)
{
    memset(r, 0, sizeof *r);
    r->scene = sc;
    snprintf(r->buf, sizeof r->buf, "%s", opts ? opts : "");
    size_t n = 0;
    for (char *tok = strtok(r->buf, " "); tok; tok = strtok(NULL, " ")) {
        cr_assert(n < MAX_OPTS);
        char *eq = strchr(tok, '=');
        if (eq)
            *eq = '\0';
        r->keys[n] = tok;
        r->values[n++] = eq ? eq + 1 : "1";
    }
    r->o = (rp_options){.size = sizeof r->o, .want = want, .seed = seed, .threads = threads,
                        .keys = r->keys, .values = r->values, .count = n};
    const rp_solver_type *t = rp_solver_lookup(method);
    cr_assert(t, "method %s is not registered", method);
    return rp_solver_create(t, sc, &r->o, &r->solver, err);
}

/* Steps until the method's own rule says converged (at most max_steps). */
static void run_solve(run *r, unsigned long max_steps)
{
    rp_error err = {""};
    for (r->steps = 0; r->steps < max_steps;) {
        rp_step_info info;
        rp_status st = rp_solver_step(r->solver, &info, &err);
        cr_assert_eq(st, RP_OK, "step %lu: %s", r->steps, err.message);
        r->steps++;
        r->sum.rays += info.rays;
        r->sum.iterations += info.iterations;
        r->last = info;
        if (info.converged)
            return;
    }
    cr_assert_fail("not converged after %lu steps", max_steps);
}

static void run_surfaces(run *r)
{
    r->ns = rp_scene_nsurfaces(r->scene);
    r->nb = rp_scene_nbands(r->scene);
    r->L = calloc(r->ns * r->nb, sizeof *r->L);
    r->se = calloc(r->ns * r->nb, sizeof *r->se);
    cr_assert(r->L && r->se);
    rp_estimate e = {.surface_radiance = r->L, .surface_stderr = r->se};
    rp_error err = {""};
    cr_assert_eq(rp_solver_estimate(r->solver, &e, &err), RP_OK, "%s", err.message);
}

static void run_close(run *r)
{
    rp_solver_destroy(r->solver);
    free(r->L);
    free(r->se);
    r->solver = NULL;
    r->L = r->se = NULL;
}

/* Solves and returns the surface averages (caller closes). */
static void solve(run *r, const char *method, const rp_scene *sc, int threads, uint64_t seed, const char *opts)
{
    rp_error err = {""};
    rp_status st = run_open(r, method, sc, RP_WANT_SURFACES, threads, seed, opts, &err);
    cr_assert_eq(st, RP_OK, "%s %s: %s", method, opts, err.message);
    run_solve(r, 100000);
    run_surfaces(r);
}

/* ---- closed forms -------------------------------------------------------- */

Test(stochastic, furnace, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    run r;
    solve(&r, "stochastic-jacobi", sc, 0, 11, "elements=600 rays=40000 unshot=1e-12 regular=10");
    double L = r.L[0], se = r.se[0];
    /* Neumann series truncated with unshot <= 1e-12 of the emitted power:
     * the missing L is at most 1e-12 * Le / (1 - rho) = 2e-12. */
    cr_assert(r.last.unshot == -1, "ended in the regular phase");
    double tol = 3 * se + 2e-12 + 1e-9;
    cr_log_info("furnace: L = %.15g +- %.3g (exact 2), %lu iterations, %.0f rays", L, se, r.steps, r.sum.rays);
    cr_expect(fabs(L - 2.0) <= tol, "furnace L = %.15g, expected 2 within %.3g", L, tol);
    run_close(&r);

    /* With the default stopping rule (unshot 1e-3, 10 regular iterations)
     * the truncation shows: about 2 * rho^11 / 10 ~ 1e-4 below 2, never
     * above. */
    solve(&r, "stochastic-jacobi", sc, 0, 11, "elements=600 rays=20000");
    cr_log_info("furnace, default rule: L = %.10g", r.L[0]);
    cr_expect(r.L[0] <= 2.0 + 1e-9 && r.L[0] > 2.0 - 2e-3, "furnace default rule: L = %.10g", r.L[0]);
    run_close(&r);
    rp_scene_destroy(sc);
}

Test(stochastic, energy_invariant, .init = setup)
{
    double mean_le;
    rp_scene *sc = cube_patches(0, &mean_le);
    run r;
    solve(&r, "stochastic-jacobi", sc, 0, 5, "max-edge=0.34 rays=50000 unshot=1e-12 regular=10");
    const rp_surface *surf = rp_scene_surfaces(sc);
    double A = 0, AL = 0, Ase = 0;
    for (size_t s = 0; s < r.ns; s++) {
        A += surf[s].area;
        AL += surf[s].area * r.L[s];
        Ase += surf[s].area * r.se[s];
    }
    double expect = mean_le / (1 - 0.5), got = AL / A, se = Ase / A;
    cr_log_info("energy invariant: area-mean L = %.15g, expected %.15g, conservative se %.3g", got, expect, se);
    cr_expect(fabs(got - expect) <= 3 * se + 2e-12 * expect + 1e-9, "area-mean L %.15g, expected %.15g (se %.3g)",
              got, expect, se);
    /* Closed, uniform rho: every ray lands on a front face, so each
     * iteration passes on exactly rho times the power it shoots, and the
     * sum is exact up to rounding; one ray leaking through an edge of the
     * box would move it by about 1e-4. */
    cr_expect(fabs(got - expect) <= 1e-9 * expect, "area-mean L %.15g, expected %.15g: power leaks", got, expect);
    /* The patches' own standard errors are not zero: the invariant is
     * exact only for the sum. */
    cr_expect(se > 1e-4 * expect, "per-patch standard errors %.3g", se);
    run_close(&r);
    rp_scene_destroy(sc);
}

/* z statistics of estimates against reference values. */
typedef struct zstats {
    double max_abs, mean_sq;
    int beyond3;
} zstats;

static zstats z_against(const double *L, const double *se, const double *ref, size_t n)
{
    zstats z = {0, 0, 0};
    for (size_t i = 0; i < n; i++) {
        cr_assert(se[i] > 0, "surface %zu has standard error %g", i, se[i]);
        double v = (L[i] - ref[i]) / se[i];
        if (fabs(v) > z.max_abs)
            z.max_abs = fabs(v);
        if (fabs(v) > 3)
            z.beyond3++;
        z.mean_sq += v * v / (double)n;
    }
    return z;
}

/* Honest standard errors, patch by patch: the 54-patch furnace (uniform
 * rho 0.5 and Le 1 on every patch), each patch one element, against the
 * analytic 2.  For K = 16 replicas z follows Student's t with 15 degrees
 * of freedom: P(|z| > 3) = 0.9%, P(|z| > 4) = 0.1%, E[z^2] = 15/13. */
Test(stochastic, stderr_per_element, .init = setup)
{
    static char text[64 * 1024];
    size_t len = (size_t)snprintf(text, sizeof text, "bands grey\nmaterial hot reflect 0.5 emit 1\n");
    /* The same 3 x 3 patches as cube_patches, all one material. */
    static const double face[6][3][3] = {
        {{0, 0, 0}, {0, 0, 1}, {1, 0, 0}}, {{0, 1, 0}, {1, 0, 0}, {0, 0, 1}},
        {{0, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 0, 1}, {0, 1, 0}},
        {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}},
    };
    for (int f = 0, id = 0; f < 6; f++)
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++, id++) {
                len += (size_t)snprintf(text + len, sizeof text - len, "quad p%d hot", id);
                const double ui[4] = {i / 3.0, (i + 1) / 3.0, (i + 1) / 3.0, i / 3.0};
                const double vj[4] = {j / 3.0, j / 3.0, (j + 1) / 3.0, (j + 1) / 3.0};
                for (int k = 0; k < 4; k++)
                    for (int c = 0; c < 3; c++)
                        len += (size_t)snprintf(text + len, sizeof text - len, " %.17g",
                                                face[f][0][c] + ui[k] * face[f][1][c] + vj[k] * face[f][2][c]);
                len += (size_t)snprintf(text + len, sizeof text - len, "\n");
            }
    rp_scene *sc = rp_test_parse(text);
    run r;
    solve(&r, "stochastic-jacobi", sc, 0, 3, "max-edge=0.34 rays=20000 unshot=1e-12 regular=10");
    cr_assert_eq(r.ns, 54);
    double ref[54];
    for (int s = 0; s < 54; s++)
        ref[s] = 2.0;
    zstats z = z_against(r.L, r.se, ref, 54);
    cr_log_info("54-patch furnace: max |z| %.2f, %d beyond 3, mean z^2 %.3f (se of patch 0: %.3g)", z.max_abs,
                z.beyond3, z.mean_sq, r.se[0]);
    cr_expect(z.max_abs < 4, "max |z| = %.2f", z.max_abs);
    cr_expect(z.beyond3 <= 2, "%d patches beyond 3 standard errors", z.beyond3);
    cr_expect(z.mean_sq > 0.4 && z.mean_sq < 2.0, "mean z^2 = %.3f", z.mean_sq);
    run_close(&r);
    rp_scene_destroy(sc);
}

Test(stochastic, parallel_plates, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    double F = rp_cf_howell_parallel(1, 1, 1);
    cr_assert(fabs(F - 0.1998248957) < 1e-9, "Howell C-11 = %.10f", F);
    const double expect = 0.5 * F * 1.0; /* rho2 F21 Le1 */
    uint32_t recv = rp_scene_find_surface(sc, "receiver"), emit = rp_scene_find_surface(sc, "emitter");
    const char *samplers[] = {"random", "stratified", "sobol"};
    for (int k = 0; k < 3; k++) {
        char opts[128];
        snprintf(opts, sizeof opts, "rays=100000 sampler=%s", samplers[k]);
        run r;
        solve(&r, "stochastic-jacobi", sc, 0, 21, opts);
        double L = r.L[recv], se = r.se[recv];
        cr_log_info("plates, %s: receiver L = %.8g +- %.3g, expected %.10g (z = %.2f)", samplers[k], L, se, expect,
                    (L - expect) / se);
        cr_expect(se > 0 && fabs(L - expect) <= 3 * se, "%s: receiver L = %.8g +- %.3g, expected %.10g",
                  samplers[k], L, se, expect);
        /* The emitter reflects nothing: its radiance is Le exactly. */
        cr_expect(fabs(r.L[emit] - 1.0) < 1e-12 && r.se[emit] == 0, "emitter L = %.15g +- %g", r.L[emit],
                  r.se[emit]);
        run_close(&r);
    }
    rp_scene_destroy(sc);
}

/* Error ~ N^-1/2: 15 runs from 2^13 to 2^20 rays per iteration (2.1
 * decades; the iteration count is the same for all, 2 incremental + 1
 * regular), 128 replicas so each standard error is itself known to about
 * 6% (and every replica has at least 64 rays per iteration: with fewer,
 * the noise of the source weights adds a visible 1/N^2 term).  The slope
 * of log(se) against log(rays) then scatters by about 0.013 from seed to
 * seed, so +-0.05 is over 3 of those. */
Test(stochastic, convergence_rate, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    const double expect = 0.5 * rp_cf_howell_parallel(1, 1, 1);
    uint32_t recv = rp_scene_find_surface(sc, "receiver");
    enum { NRUNS = 15 };
    double x[NRUNS], y[NRUNS], zsq = 0;
    double iters = -1;
    for (int k = 0; k < NRUNS; k++) {
        unsigned long rays = (unsigned long)floor(8192.0 * pow(2.0, k / 2.0) + 0.5);
        rays -= rays % 128;
        char opts[128];
        snprintf(opts, sizeof opts, "rays=%lu batches=128 regular=1 elements=100", rays);
        run r;
        solve(&r, "stochastic-jacobi", sc, 0, 100 + (uint64_t)k, opts);
        if (iters < 0)
            iters = r.sum.iterations;
        cr_assert_eq(r.sum.iterations, iters, "same iteration count for every run");
        double z = (r.L[recv] - expect) / r.se[recv];
        zsq += z * z / NRUNS;
        x[k] = log(r.sum.rays);
        y[k] = log(r.se[recv]);
        cr_log_info("rays %.0f: L = %.8g +- %.3g, z = %.2f", r.sum.rays, r.L[recv], r.se[recv], z);
        run_close(&r);
    }
    double c0, c1, cov00, cov01, cov11, sumsq;
    cr_assert_eq(gsl_fit_linear(x, 1, y, 1, NRUNS, &c0, &c1, &cov00, &cov01, &cov11, &sumsq), GSL_SUCCESS);
    cr_log_info("slope of log(se) against log(rays): %.4f +- %.4f; mean z^2 %.3f", c1, sqrt(cov11), zsq);
    cr_expect(fabs(c1 + 0.5) <= 0.05, "slope %.4f, expected -0.5 +- 0.05", c1);
    /* The errors themselves follow the standard errors: mean z^2 over 15
     * runs is chi^2_15 / 15 (times 128/126), 99.9% within [0.24, 2.5]. */
    cr_expect(zsq > 0.24 && zsq < 2.5, "mean z^2 = %.3f", zsq);
    rp_scene_destroy(sc);
}

/* Scrambled Sobol' points beat independent ones on the plates (the
 * receiver's power is a 5-dimensional integral with a visibility-free,
 * piecewise smooth integrand): smaller standard error at the same rays. */
Test(stochastic, sobol_beats_random, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    uint32_t recv = rp_scene_find_surface(sc, "receiver");
    run r;
    solve(&r, "stochastic-jacobi", sc, 0, 9, "rays=131072 batches=32 sampler=random");
    double se_random = r.se[recv];
    run_close(&r);
    solve(&r, "stochastic-jacobi", sc, 0, 9, "rays=131072 batches=32 sampler=sobol");
    double se_sobol = r.se[recv];
    run_close(&r);
    cr_log_info("plates, 131072 rays per iteration: se random %.3g, sobol %.3g", se_random, se_sobol);
    cr_expect(se_sobol < 0.7 * se_random, "sobol se %.3g, random se %.3g", se_sobol, se_random);
    rp_scene_destroy(sc);
}

/* ---- against the deterministic solver --------------------------------- */

Test(stochastic, agrees_with_gauss_seidel, .init = setup)
{
    double mean_le;
    rp_scene *sc = cube_patches(1, &mean_le);
    run gs, sj;
    /* One element per patch (edges 1/3 < 0.34) for both; no occluders, so
     * the analytic form factors are exact to their tolerance. */
    solve(&gs, "gauss-seidel", sc, 0, 1, "max-edge=0.34 tolerance=1e-10 ff-tolerance=1e-8");
    solve(&sj, "stochastic-jacobi", sc, 0, 2, "max-edge=0.34 rays=100000 regular=20");
    cr_assert_eq(sj.ns, 54);
    zstats z = z_against(sj.L, sj.se, gs.L, sj.ns);
    cr_log_info("54 patches, mixed rho: max |z| %.2f, %d beyond 3, mean z^2 %.3f", z.max_abs, z.beyond3, z.mean_sq);
    cr_expect(z.max_abs < 4, "max |z| = %.2f", z.max_abs);
    cr_expect(z.beyond3 <= 2, "%d patches beyond 3 standard errors", z.beyond3);
    cr_expect(z.mean_sq > 0.4 && z.mean_sq < 2.0, "mean z^2 = %.3f", z.mean_sq);
    run_close(&gs);
    run_close(&sj);
    rp_scene_destroy(sc);
}

/* ---- images ------------------------------------------------------------- */

static float *render(const rp_scene *sc, const char *opts, int threads, float **variance)
{
    run r;
    rp_error err = {""};
    rp_status st = run_open(&r, "stochastic-jacobi", sc, RP_WANT_IMAGE, threads, 17, opts, &err);
    cr_assert_eq(st, RP_OK, "%s: %s", opts, err.message);
    run_solve(&r, 100000);
    const rp_camera *cam = rp_scene_camera(sc);
    size_t m = (size_t)cam->width * cam->height * rp_scene_nbands(sc);
    float *img = malloc(m * sizeof *img);
    cr_assert(img);
    rp_estimate e = {.radiance = img};
    if (variance) {
        *variance = malloc(m * sizeof **variance);
        cr_assert(*variance);
        e.variance = *variance;
    }
    cr_assert_eq(rp_solver_estimate(r.solver, &e, &err), RP_OK, "%s", err.message);
    run_close(&r);
    return img;
}

/* Furnace pixels: 2 up to the radiosity noise of the elements they see
 * (and the camera jitter across element edges); the variance estimate
 * covers that noise: few pixels beyond 3 standard deviations (with 32
 * replicas, P(|t_31| > 3) = 0.5%; pixels come in clumps, one per element,
 * so the bound is 2%; a variance image missing the radiosity noise fails
 * in nearly every pixel, one at half the truth in about 4%). */
Test(stochastic, furnace_image, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    const rp_camera *cam = rp_scene_camera(sc);
    size_t npix = (size_t)cam->width * cam->height;
    const char *modes[] = {"flat", "gouraud"};
    for (int k = 0; k < 2; k++) {
        char opts[160];
        snprintf(opts, sizeof opts, "elements=600 rays=64000 batches=32 unshot=1e-6 regular=5 spp=4 reconstruct=%s",
                 modes[k]);
        float *var;
        float *img = render(sc, opts, 0, &var);
        size_t beyond = 0;
        double mean = 0;
        for (size_t i = 0; i < npix; i++) {
            mean += img[i] / (double)npix;
            /* 1e-4: the Neumann series' tail past unshot 1e-6, with room. */
            if (fabs(img[i] - 2.0) > 3 * sqrt(var[i]) + 1e-4)
                beyond++;
        }
        cr_log_info("furnace image, %s: mean %.6f, %zu of %zu pixels beyond 3 sd", modes[k], mean, beyond, npix);
        cr_expect(fabs(mean - 2.0) < 0.01, "%s: mean pixel %.6f", modes[k], mean);
        cr_expect(beyond < npix / 50, "%s: %zu pixels beyond 3 sd", modes[k], beyond);
        free(img);
        free(var);
    }
    rp_scene_destroy(sc);
}

/* A pure emitter seen from the front shows Le; a reflector seen from the
 * back and empty space are black. */
Test(stochastic, image_emitter_back_miss, .init = setup)
{
    rp_scene *sc = rp_test_parse("bands rgb\n"
                         "material lamp reflect 0 emit 1 2 3\n"
                         "material white reflect 0.7\n"
                         /* left half of the view, facing the camera (+z) */
                         "quad lamp lamp  -1 -1 0  0 -1 0  0 1 0  -1 1 0\n"
                         /* right half, facing away from the camera (-z) */
                         "quad wall white  0 -1 0  0 1 0  1 1 0  1 -1 0\n"
                         "camera eye 0 0 3  look 0 0 0  up 0 1 0  fov 60  size 32 32\n");
    float *img = render(sc, "elements=50 rays=10000 spp=4", 0, NULL);
    const float *lamp = img + (16 * 32 + 8) * 3, *wall = img + (16 * 32 + 24) * 3, *sky = img + (1 * 32 + 16) * 3;
    for (int b = 0; b < 3; b++) {
        cr_expect(fabs(lamp[b] - (b + 1.0)) < 1e-6, "lamp band %d: %g", b, lamp[b]);
        cr_expect(wall[b] == 0, "back of the wall, band %d: %g", b, wall[b]);
        cr_expect(sky[b] == 0, "miss, band %d: %g", b, sky[b]);
    }
    free(img);
    rp_scene_destroy(sc);
}

/* ---- determinism and options ------------------------------------------- */

Test(stochastic, deterministic_across_threads, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    const char *opts[] = {"rays=20000 batches=4 regular=2 spp=2", "rays=20000 batches=4 regular=2 spp=2 sampler=sobol"};
    for (int k = 0; k < 2; k++) {
        run a, b, c;
        rp_error err = {""};
        double *out[3][2];
        run *rs[3] = {&a, &b, &c};
        const int threads[3] = {1, 2, 2};
        const uint64_t seeds[3] = {5, 5, 6};
        for (int q = 0; q < 3; q++) {
            cr_assert_eq(run_open(rs[q], "stochastic-jacobi", sc, RP_WANT_SURFACES, threads[q], seeds[q], opts[k], &err),
                         RP_OK, "%s", err.message);
            run_solve(rs[q], 1000);
            run_surfaces(rs[q]);
            out[q][0] = rs[q]->L;
            out[q][1] = rs[q]->se;
        }
        size_t m = a.ns * a.nb * sizeof(double);
        cr_expect(memcmp(out[0][0], out[1][0], m) == 0, "%s: surface averages differ between 1 and 2 threads", opts[k]);
        cr_expect(memcmp(out[0][1], out[1][1], m) == 0, "%s: standard errors differ between 1 and 2 threads", opts[k]);
        cr_expect(memcmp(out[0][0], out[2][0], m) != 0, "%s: another seed gives the same answer", opts[k]);
        for (int q = 0; q < 3; q++)
            run_close(rs[q]);
    }
    /* Images too (the variance image is built from the replicas). */
    float *v1, *v2;
    float *i1 = render(sc, "rays=20000 batches=4 regular=2 spp=1", 1, &v1);
    float *i2 = render(sc, "rays=20000 batches=4 regular=2 spp=1", 2, &v2);
    const rp_camera *cam = rp_scene_camera(sc);
    size_t m = (size_t)cam->width * cam->height * 3 * sizeof(float);
    cr_expect(memcmp(i1, i2, m) == 0, "images differ between 1 and 2 threads");
    cr_expect(memcmp(v1, v2, m) == 0, "variance images differ between 1 and 2 threads");
    free(i1), free(i2), free(v1), free(v2);
    rp_scene_destroy(sc);
}

Test(stochastic, bad_options, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/plates-parallel.scene");
    const char *bad[] = {"sampler=halton", "rays=8 batches=16", "batches=1", "elements=100 max-edge=0.1",
                         "unshot=2", "reconstruct=smooth", "unshot=0 regular=0", "colour=red"};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        run r;
        rp_error err = {""};
        rp_status st = run_open(&r, "stochastic-jacobi", sc, RP_WANT_SURFACES, 0, 1, bad[k], &err);
        cr_expect_eq(st, RP_ERR_INPUT, "'%s' accepted", bad[k]);
        cr_expect(err.message[0] != '\0', "'%s': no message", bad[k]);
        cr_log_info("'%s': %s", bad[k], err.message);
        run_close(&r);
    }
    rp_scene_destroy(sc);
}
