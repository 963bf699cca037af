/* Tests of the classic radiosity solvers (jacobi, gauss-seidel, southwell,
 * direct) and of the answers built from their solutions.
 *
 * Check values come from closed forms, not from radpt:
 *   - furnace (closed box, rho 0.5, Le 1): L = Le / (1 - rho) = 2 for every
 *     element, every solver and every image reconstruction (1e-6; with
 *     --ff-tolerance 1e-9 the analytic form factors close each row to
 *     about 2e-8, which moves L by about 2 * 2e-8);
 *   - Jacobi's residual shrinks by rho per sweep in a closed uniform-rho
 *     scene: sweeps to eps = ln(eps) / ln(rho) (+-2), Gauss-Seidel fewer;
 *   - energy invariant (closed, uniform rho, one emitting face): area-mean
 *     L = mean(Le) / (1 - rho) = 1/3 for cube-ceiling (1e-6), and for
 *     progressive refinement with the ambient term after any number of
 *     shots (Cohen et al. 1988: the ambient term restores exactly the
 *     unshot power's eventual contribution when rho is uniform);
 *   - the six-patch cube (one element per face): the 3 x 3 system built
 *     from Howell's closed-form factors C-11 and C-14, solved with GSL;
 *   - the solvers agree with each other on the Cornell box (1e-6);
 *   - mesh refinement of cube-ceiling: surface averages approach a fine
 *     solution monotonically (observed order logged);
 *   - a system made divergent by bad (1-sample Monte Carlo) form factors
 *     is not refused: the rows the form-factor module alone shows summing
 *     past 1 + RP_RAD_ROW_SUM_TOL are scaled to 1, counted in one warning,
 *     and every solver converges.
 *
 * White box where needed: every classic solver's state starts with an
 * rp_rad_system (system.h), which the tests read for element values. */
#include <criterion/criterion.h>

#include <gsl/gsl_errno.h>
#include <gsl/gsl_linalg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/sample.h"
#include "geometry/scene.h"
#include "closed_form.h"
#include "scene_util.h"
#include "solvers/radiosity/formfactor.h"
#include "solvers/radiosity/reconstruct.h"
#include "solvers/radiosity/system.h"
#include "solvers/solver.h"

#define PI 3.14159265358979323846

extern const rp_solver_type rp_solver_jacobi, rp_solver_gauss_seidel, rp_solver_southwell,
    rp_solver_direct;

static const rp_solver_type *const all_types[] = {&rp_solver_jacobi, &rp_solver_gauss_seidel,
                                                  &rp_solver_southwell, &rp_solver_direct};

static void setup(void) { gsl_set_error_handler_off(); }

/* ---- scenes ------------------------------------------------------------ */



/* ---- running a solver through its type table --------------------------- */

#define MAX_OPTS 16

typedef struct rad_run {
    const rp_solver_type *type;
    void *state;
    rp_rad_system *sys;
    char buf[512];
    const char *keys[MAX_OPTS], *values[MAX_OPTS];
    rp_options o;
    unsigned long steps;
    rp_step_info last;
    double form_factors;
} rad_run;

/* opts: "key=value key flag ..." (a bare key is a flag, value "1"). */
static rp_status rad_open(rad_run *r, const rp_solver_type *t, const rp_scene *sc, unsigned want,
                          int threads, const char *opts, rp_error *err)
{
    memset(r, 0, sizeof *r);
    r->type = t;
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
    r->o = (rp_options){.size = sizeof r->o, .want = want, .seed = 7, .threads = threads,
                        .keys = r->keys, .values = r->values, .count = n};
    rp_status st = rp_options_check(&r->o, t, err);
    if (st != RP_OK)
        return st;
    r->state = calloc(1, t->state_size);
    cr_assert(r->state);
    r->sys = r->state;
    r->o.specs = t->options; /* as rp_solver_create hands them to init */
    st = t->init(r->state, sc, &r->o, err);
    if (st != RP_OK) {
        t->fini(r->state);
        free(r->state);
        r->state = NULL;
    }
    return st;
}

static rp_status rad_step(rad_run *r, rp_error *err)
{
    memset(&r->last, 0, sizeof r->last);
    r->last.residual = r->last.unshot = -1;
    rp_status st = r->type->step(r->state, &r->last, err);
    if (st == RP_OK) {
        r->steps++;
        r->form_factors += r->last.form_factors;
    }
    return st;
}

static rp_status rad_solve(rad_run *r, unsigned long max_steps, rp_error *err)
{
    while (r->steps < max_steps) {
        rp_status st = rad_step(r, err);
        if (st != RP_OK)
            return st;
        cr_assert(isfinite(r->last.residual) && r->last.residual >= 0);
        if (r->last.converged)
            return RP_OK;
    }
    cr_assert_fail("%s: not converged after %lu steps (residual %g)", r->type->name, max_steps, r->last.residual);
    return RP_ERR_RUNTIME;
}

static void rad_close(rad_run *r)
{
    if (r->state) {
        r->type->fini(r->state);
        free(r->state);
    }
    r->state = NULL;
}

/* Opens and solves, asserting success. */
static void rad_run_ok(rad_run *r, const rp_solver_type *t, const rp_scene *sc, unsigned want, int threads,
                       const char *opts)
{
    rp_error err = {""};
    rp_status st = rad_open(r, t, sc, want, threads, opts, &err);
    cr_assert_eq(st, RP_OK, "%s init: %s", t->name, err.message);
    st = rad_solve(r, 1000000, &err);
    cr_assert_eq(st, RP_OK, "%s step: %s", t->name, err.message);
}

/* Options of an iterative method asked to converge hard (direct has no
 * tolerance). */
static const char *tight(const rp_solver_type *t, const char *rest, char *buf, size_t n)
{
    snprintf(buf, n, "%s%s", t == &rp_solver_direct ? "" : "tolerance=1e-11 ", rest);
    return buf;
}

/* Area-weighted mean radiance over every surface, from surface averages. */
static double area_mean(const rp_scene *sc, const double *L, size_t nb, size_t band)
{
    const rp_surface *s = rp_scene_surfaces(sc);
    double a = 0, m = 0;
    for (size_t i = 0; i < rp_scene_nsurfaces(sc); i++) {
        a += s[i].area;
        m += s[i].area * L[i * nb + band];
    }
    return m / a;
}

/* ---- furnace ----------------------------------------------------------- */

Test(radiosity, furnace_every_solver, .init = setup, .timeout = 120)
{
    /* Le / (1 - rho) = 1 / 0.5 = 2 on every element. */
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    for (size_t k = 0; k < 4; k++) {
        rad_run r;
        char o[128];
        rad_run_ok(&r, all_types[k], sc, RP_WANT_SURFACES, 0, tight(all_types[k], "elements=96 ff-tolerance=1e-9", o, sizeof o));
        const rp_rad_system *sys = r.sys;
        cr_assert_eq(sys->n, 96);
        for (size_t i = 0; i < sys->n; i++)
            cr_assert_float_eq(sys->B[i] / PI, 2.0, 1e-6, "%s: element %zu: %.9g", all_types[k]->name, i,
                               sys->B[i] / PI);
        if (all_types[k] != &rp_solver_direct)
            cr_assert_leq(r.last.residual, 1e-11);
        double L, se = -1;
        rp_estimate e = {.surface_radiance = &L, .surface_stderr = &se};
        rp_error err = {""};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        cr_assert_float_eq(L, 2.0, 1e-6);
        cr_assert_eq(se, 0.0); /* deterministic */
        cr_assert_eq(e.samples, (double)r.steps);
        cr_assert_gt(r.last.memory, 0);
        rad_close(&r);
    }
    rp_scene_destroy(sc);
}

Test(radiosity, furnace_images, .init = setup, .timeout = 120)
{
    /* Flat and Gouraud show B / pi = 2; the final gather Le + rho/pi E with
     * every gather ray seeing B = 2 pi gives 1 + 0.5 * 2 = 2 as well. */
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    const rp_camera *cam = rp_scene_camera(sc);
    size_t npix = (size_t)cam->width * cam->height;
    float *img = malloc(npix * sizeof *img), *var = malloc(npix * sizeof *var);
    const char *modes[] = {"flat", "gouraud", "gather"};
    for (int m = 0; m < 3; m++) {
        rad_run r;
        char opts[128];
        snprintf(opts, sizeof opts, "elements=96 ff-tolerance=1e-9 tolerance=1e-11 spp=4 gather-rays=4 reconstruct=%s", modes[m]);
        rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_IMAGE, 0, opts);
        rp_estimate e = {.radiance = img, .variance = var};
        rp_error err = {""};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        for (size_t p = 0; p < npix; p++) {
            cr_assert_float_eq(img[p], 2.0, 1e-6, "%s: pixel %zu: %.9g", modes[m], p, img[p]);
            cr_assert_float_eq(var[p], 0.0, 1e-11, "%s: pixel %zu variance %g", modes[m], p, var[p]);
        }
        rad_close(&r);
    }
    free(img);
    free(var);
    rp_scene_destroy(sc);
}

/* ---- convergence rates --------------------------------------------------- */

static void sweeps_case(const char *scene_text, double rho)
{
    rp_scene *sc = rp_test_parse(scene_text);
    const double eps = 1e-6;
    rad_run j, g;
    rad_run_ok(&j, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=96 tolerance=1e-6");
    rad_run_ok(&g, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "elements=96 tolerance=1e-6");
    double expect = log(eps) / log(rho);
    cr_log_info("rho %.2f: Jacobi %lu sweeps, Gauss-Seidel %lu, ln(eps)/ln(rho) = %.2f", rho, j.steps, g.steps,
                expect);
    cr_assert_leq(fabs((double)j.steps - expect), 2.0, "Jacobi: %lu sweeps, expected %.2f", j.steps, expect);
    cr_assert_lt(g.steps, j.steps, "Gauss-Seidel %lu sweeps, Jacobi %lu", g.steps, j.steps);
    cr_assert_leq(j.last.residual, eps);
    cr_assert_leq(g.last.residual, eps);
    rad_close(&j);
    rad_close(&g);
    rp_scene_destroy(sc);
}

Test(radiosity, jacobi_sweeps_follow_rho, .init = setup, .timeout = 120)
{
    sweeps_case("bands grey\nmaterial m reflect 0.5 emit 1\nbox b m 0 0 0 1 1 1 inward\n", 0.5);
    sweeps_case("bands grey\nmaterial m reflect 0.8 emit 1\nbox b m 0 0 0 1 1 1 inward\n", 0.8);
}

Test(radiosity, jacobi_residual_ratio_is_rho, .init = setup, .timeout = 120)
{
    /* Non-uniform emission, uniform rho 0.5: the error's slowest mode is
     * the uniform one, which rho F shrinks by exactly rho. */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    rad_run r;
    rp_error err = {""};
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=54 tolerance=0", &err), RP_OK,
                 "%s", err.message);
    double prev = -1;
    for (int k = 0; k < 16; k++) {
        cr_assert_eq(rad_step(&r, &err), RP_OK, "%s", err.message);
        if (k == 15)
            cr_assert_float_eq(r.last.residual / prev, 0.5, 5e-3, "ratio %.6f", r.last.residual / prev);
        prev = r.last.residual;
    }
    rad_close(&r);
    rp_scene_destroy(sc);
}

/* ---- closed forms -------------------------------------------------------- */

Test(radiosity, six_patch_cube_closed_form, .init = setup)
{
    double Fo = rp_cf_howell_parallel(1, 1, 1), Fa = rp_cf_howell_perpendicular(1, 1, 1);
    cr_assert_float_eq(Fo, 0.1998248957, 1e-9);
    cr_assert_float_eq(Fa, 0.2000437761, 1e-9);
    /* Unknowns L_ceiling, L_floor, L_wall (four walls alike), rho 0.5,
     * Le 1 on the ceiling:  L = Le + rho sum_j F_ij L_j. */
    const double r = 0.5;
    double a[9] = {1, -r * Fo, -r * 4 * Fa,
                   -r * Fo, 1, -r * 4 * Fa,
                   -r * Fa, -r * Fa, 1 - r * (Fo + 2 * Fa)};
    double rhs[3] = {1, 0, 0}, x[3];
    gsl_matrix_view A = gsl_matrix_view_array(a, 3, 3);
    gsl_vector_view b = gsl_vector_view_array(rhs, 3), xv = gsl_vector_view_array(x, 3);
    gsl_permutation *p = gsl_permutation_alloc(3);
    int sgn;
    cr_assert_eq(gsl_linalg_LU_decomp(&A.matrix, p, &sgn), 0);
    cr_assert_eq(gsl_linalg_LU_solve(&A.matrix, p, &b.vector, &xv.vector), 0);
    gsl_permutation_free(p);

    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    uint32_t ceil = rp_scene_find_surface(sc, "ceiling"), floor = rp_scene_find_surface(sc, "floor");
    for (size_t k = 0; k < 4; k++) {
        rad_run run;
        char o[128];
        rad_run_ok(&run, all_types[k], sc, RP_WANT_SURFACES, 0, tight(all_types[k], "elements=6 ff-tolerance=1e-10", o, sizeof o));
        cr_assert_eq(run.sys->n, 6);
        double L[6];
        rp_estimate e = {.surface_radiance = L};
        rp_error err = {""};
        cr_assert_eq(run.type->estimate(run.state, &e, &err), RP_OK);
        for (uint32_t s = 0; s < 6; s++) {
            double want = s == ceil ? x[0] : s == floor ? x[1] : x[2];
            cr_assert_float_eq(L[s], want, 1e-6 * want, "%s: surface %u: %.10g, closed form %.10g",
                               all_types[k]->name, s, L[s], want);
        }
        rad_close(&run);
    }
    rp_scene_destroy(sc);
}

Test(radiosity, energy_invariant_and_ambient, .init = setup, .timeout = 120)
{
    /* Closed cube, rho 0.5 everywhere, Le 1 on one face of six:
     * area-mean L = mean(Le) / (1 - rho) = (1/6) / 0.5 = 1/3. */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    double L[6];
    rp_error err = {""};
    rad_run r;
    rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "elements=96 ff-tolerance=1e-9 tolerance=1e-10");
    rp_estimate e = {.surface_radiance = L};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
    cr_assert_float_eq(area_mean(sc, L, 1, 0), 1.0 / 3.0, 1e-6, "%.10g", area_mean(sc, L, 1, 0));
    rad_close(&r);

    /* Progressive refinement after a few shots: with the ambient term the
     * invariant holds at once (sum A B + rho/(1-rho) sum A dB is conserved
     * by every shot); without it the mean is still far below. */
    for (int amb = 0; amb < 2; amb++) {
        cr_assert_eq(rad_open(&r, &rp_solver_southwell, sc, RP_WANT_SURFACES, 0,
                              amb ? "elements=96 ff-tolerance=1e-9 ambient" : "elements=96 ff-tolerance=1e-9", &err),
                     RP_OK, "%s", err.message);
        for (int k = 0; k < 30; k++)
            cr_assert_eq(rad_step(&r, &err), RP_OK, "%s", err.message);
        cr_assert_gt(r.last.unshot, 1e-2);
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
        double m = area_mean(sc, L, 1, 0);
        if (amb)
            cr_assert_float_eq(m, 1.0 / 3.0, 1e-6, "ambient: %.10g", m);
        else
            cr_assert_lt(m, 1.0 / 3.0 - 1e-2, "no ambient: %.10g", m);
        rad_close(&r);
    }
    rp_scene_destroy(sc);
}

/* ---- the solvers against each other ------------------------------------ */

Test(radiosity, solvers_agree_on_cornell, .init = setup, .timeout = 300)
{
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    const size_t nb = 3;
    rad_run ref;
    rad_run_ok(&ref, &rp_solver_direct, sc, RP_WANT_SURFACES, 0, "elements=250");
    const rp_rad_system *d = ref.sys;
    cr_assert_lt(ref.last.residual, 1e-12);
    const char *variants[] = {"", "overshoot=1.5"};
    for (size_t k = 0; k < 4; k++) {
        for (int v = 0; v < (all_types[k] == &rp_solver_southwell ? 2 : 1); v++) {
            if (all_types[k] == &rp_solver_direct)
                continue;
            rad_run r;
            char o[128], rest[64];
            snprintf(rest, sizeof rest, "elements=250 %s", variants[v]);
            rad_run_ok(&r, all_types[k], sc, RP_WANT_SURFACES, 0, tight(all_types[k], rest, o, sizeof o));
            cr_assert_eq(r.sys->n, d->n);
            for (size_t i = 0; i < d->n * nb; i++)
                cr_assert_float_eq(r.sys->B[i], d->B[i], 1e-6 * fabs(d->B[i]) + 1e-300,
                                   "%s %s: element %zu band %zu: %.12g, direct %.12g", all_types[k]->name,
                                   variants[v], i / nb, i % nb, r.sys->B[i], d->B[i]);
            rad_close(&r);
        }
    }
    /* The light reflects nothing: it shows exactly its Le. */
    size_t ns = rp_scene_nsurfaces(sc);
    double *L = malloc(ns * nb * sizeof *L);
    rp_estimate e = {.surface_radiance = L};
    rp_error err = {""};
    cr_assert_eq(ref.type->estimate(ref.state, &e, &err), RP_OK);
    uint32_t light = rp_scene_find_surface(sc, "light");
    cr_assert_neq(light, RP_NONE);
    cr_assert_float_eq(L[light * nb + 0], 17.0, 1e-12);
    cr_assert_float_eq(L[light * nb + 1], 12.0, 1e-12);
    cr_assert_float_eq(L[light * nb + 2], 4.0, 1e-12);
    free(L);
    rad_close(&ref);
    rp_scene_destroy(sc);
}

Test(radiosity, rows_on_the_fly_equal_dense, .init = setup, .timeout = 120)
{
    /* The same rows in the same order: bit-identical iterates; the row
     * buffer is smaller than the matrix and every sweep recomputes rows. */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    rad_run a, b;
    rad_run_ok(&a, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=96 matrix=dense tolerance=1e-9");
    rad_run_ok(&b, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=96 matrix=rows tolerance=1e-9");
    cr_assert_eq(a.steps, b.steps);
    cr_assert_eq(memcmp(a.sys->B, b.sys->B, a.sys->n * sizeof(double)), 0);
    cr_assert(a.sys->dense && !b.sys->dense);
    cr_assert_lt(b.last.memory, a.last.memory);
    /* Dense: each pair once, n (n - 1) / 2.  Rows: n^2 per product, one
     * per sweep plus one. */
    double n2 = (double)a.sys->n * a.sys->n;
    cr_assert_eq(a.form_factors, 0.5 * (double)a.sys->n * (double)(a.sys->n - 1));
    cr_assert_eq(b.form_factors, n2 * (double)(b.steps + 1));
    rad_close(&a);
    rad_close(&b);
    rp_scene_destroy(sc);
}

/* ---- mesh refinement ----------------------------------------------------- */

Test(radiosity, cube_ceiling_refinement, .init = setup, .timeout = 300)
{
    /* k x k elements per face, k = 2, 3, 4, 6, against k = 16 (three
     * refinements, four meshes). */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    enum { NK = 4 };
    const int ks[NK] = {2, 3, 4, 6}, kfine = 16;
    double Lf[6], L[6], errs[NK];
    rp_error err = {""};
    char o[96];
    rad_run r;
    snprintf(o, sizeof o, "elements=%d tolerance=1e-10", 6 * kfine * kfine);
    rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, o);
    cr_assert_eq(r.sys->n, (size_t)(6 * kfine * kfine));
    rp_estimate e = {.surface_radiance = Lf};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
    rad_close(&r);
    for (int t = 0; t < NK; t++) {
        snprintf(o, sizeof o, "elements=%d tolerance=1e-10", 6 * ks[t] * ks[t]);
        rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, o);
        cr_assert_eq(r.sys->n, (size_t)(6 * ks[t] * ks[t]));
        e.surface_radiance = L;
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
        rad_close(&r);
        errs[t] = 0;
        for (int s = 0; s < 6; s++)
            errs[t] = fmax(errs[t], fabs(L[s] - Lf[s]) / Lf[s]);
        cr_log_info("cube-ceiling %dx%d per face: max relative surface error %.3e against %dx%d", ks[t], ks[t],
                    errs[t], kfine, kfine);
    }
    for (int t = 1; t < NK; t++) {
        cr_log_info("observed order %dx%d -> %dx%d: %.2f", ks[t - 1], ks[t - 1], ks[t], ks[t],
                    log(errs[t - 1] / errs[t]) / log((double)ks[t] / ks[t - 1]));
        cr_assert_gt(errs[t - 1], errs[t], "error grew from %dx%d to %dx%d", ks[t - 1], ks[t - 1], ks[t], ks[t]);
    }
    /* Surface averages of piecewise-constant radiosity converge faster
     * than the O(h) pointwise error (docs/ground-truth.md: about h^1.6 to h^2). */
    cr_assert_gt(log(errs[0] / errs[NK - 1]) / log((double)ks[NK - 1] / ks[0]), 1.0);
    rp_scene_destroy(sc);
}

Test(radiosity, reciprocity_halves_the_work, .init = setup, .timeout = 120)
{
    /* --reciprocity: pairs i < j only, mirrored; the matrix then meets
     * A_i F_ij = A_j F_ji to float rounding, and the furnace still holds. */
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    rad_run r;
    rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0,
               "elements=96 ff-tolerance=1e-9 tolerance=1e-11 reciprocity");
    const rp_rad_system *sys = r.sys;
    size_t n = sys->n;
    cr_assert_eq(r.form_factors, 0.5 * n * (n - 1));
    for (size_t i = 0; i < n; i++) {
        cr_assert_float_eq(sys->B[i] / PI, 2.0, 1e-6, "element %zu: %.9g", i, sys->B[i] / PI);
        for (size_t j = 0; j < n; j++) {
            double a = sys->area[i] * sys->F[i * n + j], b = sys->area[j] * sys->F[j * n + i];
            cr_assert_float_eq(a, b, 3e-7 * fabs(a), "pair %zu %zu", i, j);
        }
    }
    rad_close(&r);
    rp_scene_destroy(sc);
}

Test(radiosity, hemicube_form_factors, .init = setup, .timeout = 120)
{
    /* Hemicube rows (southwell turns them into columns by reciprocity):
     * within 2% of the analytic solution on cube-ceiling, and the two
     * hemicube solvers within 1e-2 of each other (their systems differ by
     * the hemicube's departure from reciprocity). */
    rp_scene *sc = rp_test_load("scenes/cube-ceiling.scene");
    double La[6], Lg[6], Ls[6];
    rp_error err = {""};
    rad_run r;
    rp_estimate e = {.surface_radiance = La};
    rad_run_ok(&r, &rp_solver_direct, sc, RP_WANT_SURFACES, 0, "elements=54");
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
    rad_close(&r);
    rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "elements=54 ff=hemicube tolerance=1e-9");
    e.surface_radiance = Lg;
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
    rad_close(&r);
    rad_run_ok(&r, &rp_solver_southwell, sc, RP_WANT_SURFACES, 0, "elements=54 ff=hemicube tolerance=1e-9");
    e.surface_radiance = Ls;
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK);
    rad_close(&r);
    for (int s = 0; s < 6; s++) {
        cr_assert_float_eq(Lg[s], La[s], 2e-2 * La[s], "surface %d: hemicube %.6g, analytic %.6g", s, Lg[s], La[s]);
        cr_assert_float_eq(Ls[s], Lg[s], 1e-2 * Lg[s], "surface %d: southwell %.6g, gauss-seidel %.6g", s, Ls[s],
                           Lg[s]);
    }
    /* --reciprocity needs pairs */
    cr_assert_eq(rad_open(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "ff=hemicube reciprocity", &err),
                 RP_ERR_INPUT);
    rp_scene_destroy(sc);
}

/* ---- refusals ------------------------------------------------------------ */

/* Log messages of a run, kept for the test to read. */
typedef struct log_buf {
    char text[8192];
    int count;
} log_buf;

static void log_keep(void *ctx, const char *message)
{
    log_buf *b = ctx;
    size_t used = strlen(b->text);
    snprintf(b->text + used, sizeof b->text - used, "%s\n", message);
    b->count++;
}

/* The warnings in a log (lines containing "warning:"). */
static int log_warnings(const log_buf *b)
{
    int k = 0;
    for (const char *p = b->text; (p = strstr(p, "warning:")) != NULL; p++)
        k++;
    return k;
}

Test(radiosity, bad_rows_scaled_not_refused, .init = setup, .timeout = 120)
{
    /* rho 0.95 is legal, but one-sample Monte Carlo form factors sum well
     * past 1 / 0.95 on some rows.  Such rows are form-factor error: every
     * solver scales each row whose sum exceeds 1 + RP_RAD_ROW_SUM_TOL (or
     * breaks the contraction, rho sum F >= 1, which here is the same rule
     * with 1 / 0.95) to sum 1, says so in one warning naming how many rows
     * and the worst, and converges.  The count and the worst sum are
     * computed here from the form-factor module alone. */
    const char *text = "bands grey\nmaterial m reflect 0.95 emit 1\nbox b m 0 0 0 1 1 1 inward\n";
    rp_scene *sc = rp_test_parse(text);
    rp_error err = {""};
    rp_mesh *mesh;
    rp_mesh_params mp = {.size = sizeof mp, .target_count = 150};
    cr_assert_eq(rp_mesh_create(sc, &mp, &mesh, &err), RP_OK);
    rp_raycast *rc;
    cr_assert_eq(rp_raycast_create(sc, mesh, &rc, &err), RP_OK);
    rp_ff_params fp = {.size = sizeof fp, .method = RP_FF_MONTECARLO, .samples = 1, .seed = 7};
    rp_ff_context *ctx;
    rp_ff_scratch *scr;
    cr_assert_eq(rp_ff_context_create(sc, mesh, rc, &fp, &ctx, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_ff_scratch_create(ctx, &scr, &err), RP_OK);
    size_t n = rp_mesh_nelements(mesh);
    float *row = malloc(n * sizeof *row);
    double worst = 0;
    size_t over = 0;
    for (size_t i = 0; i < n; i++) {
        rp_ff_row(ctx, scr, (uint32_t)i, row, NULL);
        double sum = 0;
        for (size_t j = 0; j < n; j++)
            sum += row[j];
        if (sum > 1 + RP_RAD_ROW_SUM_TOL || 0.95 * sum >= 1) {
            over++;
            worst = fmax(worst, sum);
        }
    }
    cr_assert_geq(0.95 * worst, 1.0, "the constructed case is not divergent: max rho sum F = %g", 0.95 * worst);
    free(row);
    rp_ff_scratch_destroy(scr);
    rp_ff_context_destroy(ctx);
    rp_raycast_destroy(rc);
    rp_mesh_destroy(mesh);
    char want[64], worst_text[64];
    snprintf(want, sizeof want, "%zu of %zu rows", over, n);
    snprintf(worst_text, sizeof worst_text, "summed to %.6g", worst);

    const char *variants[5] = {"", "", "", "", "matrix=rows"};
    const rp_solver_type *types[5] = {&rp_solver_jacobi, &rp_solver_gauss_seidel, &rp_solver_southwell,
                                      &rp_solver_direct, &rp_solver_jacobi};
    for (size_t k = 0; k < 5; k++) {
        rad_run r;
        char o[128];
        snprintf(o, sizeof o, "elements=150 ff=montecarlo ff-samples=1 %s", variants[k]);
        log_buf lb = {"", 0};
        rp_status st = rad_open(&r, types[k], sc, RP_WANT_SURFACES, 0, o, &err);
        cr_assert_eq(st, RP_OK, "%s: %s", types[k]->name, err.message);
        /* rad_open set the options; the log goes to lb from here on */
        r.o.log = log_keep;
        r.o.log_ctx = &lb;
        r.sys->log = log_keep;
        r.sys->log_ctx = &lb;
        while (st == RP_OK && r.steps < 100000 && !r.last.converged)
            st = rad_step(&r, &err);
        cr_assert_eq(st, RP_OK, "%s %s: %s", types[k]->name, variants[k], err.message);
        cr_assert(r.last.converged, "%s: not converged", types[k]->name);
        for (size_t i = 0; i < r.sys->n; i++)
            cr_assert(isfinite(r.sys->B[i]) && r.sys->B[i] > 0);
        cr_assert_eq(log_warnings(&lb), 1, "%s %s: %d warnings in\n%s", types[k]->name, variants[k],
                     log_warnings(&lb), lb.text);
        cr_assert(strstr(lb.text, want) && strstr(lb.text, worst_text), "%s %s: want '%s' and '%s' in\n%s",
                  types[k]->name, variants[k], want, worst_text, lb.text);
        cr_assert_eq(r.sys->rows_scaled, over);
        rad_close(&r);
    }
    /* The same scene with accurate form factors: a furnace at 1/(1 - 0.95) = 20
     * (row sums within ~2e-8 of 1, amplified by about rho/(1-rho)^2 = 380),
     * and no row scaled. */
    rad_run r;
    rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "elements=150 ff-tolerance=1e-9 tolerance=1e-10");
    for (size_t i = 0; i < r.sys->n; i++)
        cr_assert_float_eq(r.sys->B[i] / PI, 20.0, 1e-4);
    cr_assert_eq(r.sys->rows_scaled, 0);
    rad_close(&r);
    rp_scene_destroy(sc);
}

Test(radiosity, check_row_by_hand, .init = setup)
{
    /* Rows built by hand against the rule: rho_i sum_j F_ij < 1 and
     * sum_j rho_j F_ij < 1 (furnace, rho 0.5 everywhere). */
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    rad_run r;
    rp_error err = {""};
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=24", &err), RP_OK);
    size_t n = r.sys->n;
    float *row = calloc(n, sizeof *row);
    double sum;
    for (size_t j = 1; j < n; j++)
        row[j] = (float)(1.99 / (n - 1)); /* rho * sum = 0.995 */
    cr_assert_eq(rp_rad_check_row(r.sys, 0, row, &sum, &err), RP_OK);
    cr_assert_float_eq(sum, 1.99, 1e-6);
    for (size_t j = 1; j < n; j++)
        row[j] = (float)(2.01 / (n - 1)); /* rho * sum = 1.005 */
    cr_assert_eq(rp_rad_check_row(r.sys, 0, row, &sum, &err), RP_ERR_INPUT);
    row[3] = NAN;
    cr_assert_eq(rp_rad_check_row(r.sys, 0, row, &sum, &err), RP_ERR_RUNTIME);
    row[3] = -0.01f;
    cr_assert_eq(rp_rad_check_row(r.sys, 0, row, &sum, &err), RP_ERR_RUNTIME);
    free(row);
    rad_close(&r);
    rp_scene_destroy(sc);
}

Test(radiosity, options_refused, .init = setup)
{
    rp_scene *sc = rp_test_load("scenes/furnace.scene");
    rp_error err = {""};
    rad_run r;
    /* direct refuses big systems before computing anything */
    cr_assert_eq(rad_open(&r, &rp_solver_direct, sc, RP_WANT_SURFACES, 0, "elements=6000", &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "direct"), "%s", err.message);
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "elements=100 max-edge=0.1", &err),
                 RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_IMAGE, 0, "reconstruct=phong", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "matrix=sparse", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_SURFACES, 0, "ff=radiant", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_southwell, sc, RP_WANT_SURFACES, 0, "overshoot=2", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_southwell, sc, RP_WANT_SURFACES, 0, "matrix=sparse", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_direct, sc, RP_WANT_SURFACES, 0, "tolerance=1e-3", &err), RP_ERR_INPUT);
    cr_assert_eq(rad_open(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, 0, "tolerance=-1", &err),
                 RP_ERR_INPUT);
    rp_scene_destroy(sc);
    /* An image needs a camera. */
    sc = rp_test_parse("bands grey\nmaterial m reflect 0.5 emit 1\nbox b m 0 0 0 1 1 1 inward\n");
    cr_assert_eq(rad_open(&r, &rp_solver_jacobi, sc, RP_WANT_IMAGE, 0, "elements=24", &err), RP_ERR_INPUT);
    rp_scene_destroy(sc);
}

/* ---- determinism --------------------------------------------------------- */

Test(radiosity, same_answers_for_any_thread_count, .init = setup, .timeout = 300)
{
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    const rp_camera *cam = rp_scene_camera(sc);
    size_t nv = (size_t)cam->width * cam->height * 3;
    float *img[3];
    double *B[3];
    size_t n = 0;
    const char *opts[3] = {"elements=120 reconstruct=gather spp=1 gather-rays=2 tolerance=1e-8",
                           "elements=120 reconstruct=gather spp=1 gather-rays=2 tolerance=1e-8",
                           "elements=120 reconstruct=gather spp=1 gather-rays=2 tolerance=1e-8 ff-rays=16"};
    int threads[3] = {1, 2, 2};
    for (int t = 0; t < 3; t++) {
        rad_run r;
        rad_run_ok(&r, &rp_solver_southwell, sc, RP_WANT_IMAGE, threads[t], opts[t]);
        n = r.sys->n;
        img[t] = malloc(nv * sizeof(float));
        B[t] = malloc(n * 3 * sizeof(double));
        memcpy(B[t], r.sys->B, n * 3 * sizeof(double));
        rp_estimate e = {.radiance = img[t]};
        rp_error err = {""};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        rad_close(&r);
    }
    cr_assert_eq(memcmp(B[0], B[1], n * 3 * sizeof(double)), 0, "solution depends on the thread count");
    cr_assert_eq(memcmp(img[0], img[1], nv * sizeof(float)), 0, "image depends on the thread count");
    /* ...and the comparison can fail: other visibility rays, another B. */
    cr_assert_neq(memcmp(B[0], B[2], n * 3 * sizeof(double)), 0);
    /* Nor do columns computed on the fly through a small cache instead of
     * the stored matrix change anything, only the work. */
    rad_run r;
    rad_run_ok(&r, &rp_solver_southwell, sc, RP_WANT_SURFACES, 2, "elements=120 tolerance=1e-8 matrix=rows row-cache=0");
    cr_assert_eq(memcmp(B[0], r.sys->B, n * 3 * sizeof(double)), 0, "solution depends on the cache size");
    cr_assert_gt(r.form_factors, 2.0 * n * n);
    rad_close(&r);
    for (int t = 0; t < 3; t++) {
        free(img[t]);
        free(B[t]);
    }
    rp_scene_destroy(sc);
}

/* Gouraud corners follow smoothing groups (reconstruct.h): a `box` room is
 * one surface of six faces meeting at right angles, so no corner value mixes
 * two faces.  With B = the element's face number, every corner of every
 * element must read its own face's number, also along the room's edges
 * where the mesh shares vertices between faces. */
Test(radiosity, gouraud_corners_keep_creases)
{
    rp_scene *sc = rp_test_parse("bands grey\n"
                                 "material w reflect 0.5\n"
                                 "material l reflect 0 emit 1\n"
                                 "box room w  0 0 0  1 1 1  inward\n"
                                 "quad lamp l  0.4 0.99 0.4  0.6 0.99 0.4  0.6 0.99 0.6  0.4 0.99 0.6\n");
    rp_mesh *mesh = NULL;
    rp_error err = {""};
    rp_mesh_params mp = {.size = sizeof mp, .target_count = 96};
    cr_assert_eq(rp_mesh_create(sc, &mp, &mesh, &err), RP_OK, "%s", err.message);
    const size_t n = rp_mesh_nelements(mesh);
    const rp_element *el = rp_mesh_elements(mesh);
    double *B = malloc(n * sizeof *B), *C = malloc(n * 4 * sizeof *C);
    cr_assert(B && C);
    for (size_t e = 0; e < n; e++)
        B[e] = el[e].face;
    cr_assert(rp_recon_corners(mesh, 1, B, C));
    size_t shared = 0;
    for (size_t e = 0; e < n; e++)
        for (uint32_t k = 0; k < el[e].nverts; k++) {
            if (el[e].surface != el[0].surface)
                continue; /* the lamp */
            cr_assert_eq(C[e * 4 + k], B[e], "element %zu corner %u: %g, face %g", e, k, C[e * 4 + k], B[e]);
            size_t cnt;
            const uint32_t *inc = rp_mesh_vertex_elements(mesh, el[e].v[k], &cnt);
            for (size_t j = 0; j < cnt; j++)
                shared += el[inc[j]].face != el[e].face;
        }
    cr_assert_gt(shared, 0, "no vertex is shared between faces: the test would prove nothing");
    free(B);
    free(C);
    rp_mesh_destroy(mesh);
    rp_scene_destroy(sc);
}

/* The final gather samples pure emitters directly (reconstruct.h).  A
 * receiver (rho 1/2) under a parallel unit-square lamp (Le 3, reflecting
 * nothing) at height 1, and a solution that is dark everywhere: at a point
 * p of the receiver the gather must give L = rho Le F(p), F the point-to-
 * rectangle form factor by superposition of Howell's B-3 corner
 * rectangles.  64 independent keys of 64 light samples: the mean within 4
 * standard errors, the standard error under 1% (so the test can fail). */
static void dark_solution(const void *ctx, const rp_hit *g, double *B)
{
    (void)ctx;
    (void)g;
    B[0] = 0;
}

Test(radiosity, final_gather_samples_the_lamp)
{
    rp_scene *sc = rp_test_parse("bands grey\n"
                                 "material floor reflect 0.5\n"
                                 "material lamp reflect 0 emit 3\n"
                                 "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                 "quad emitter lamp  0 0 1  0 1 1  1 1 1  1 0 1\n");
    rp_error err = {""};
    rp_raycast *rc = NULL;
    rp_area_sampler *lights = NULL;
    cr_assert_eq(rp_raycast_create(sc, NULL, &rc, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_recon_lights(sc, &lights, &err), RP_OK, "%s", err.message);
    cr_assert(lights);
    enum { G = 64, KEYS = 64 };
    rp_recon_gather g = {.scene = sc, .rc = rc, .lights = lights, .rays = G, .nb = 1,
                         .radiosity = dark_solution, .ctx = NULL};
    rp_hit h = {.p = rp_v3(0.3, 0.6, 0), .n = rp_v3(0, 0, 1), .face = 0, .surface = 0, .element = RP_NONE,
                .front = 1};
    double xy[2 * G], sum = 0, sum2 = 0;
    uint32_t perm[G];
    unsigned long long rays = 0;
    for (int k = 0; k < KEYS; k++) {
        double L;
        rp_recon_final_gather(&g, &h, 1000 + (uint64_t)k, xy, perm, &L, &rays);
        sum += L;
        sum2 += L * L;
    }
    double mean = sum / KEYS, se = sqrt((sum2 / KEYS - mean * mean) / (KEYS - 1));
    double F = rp_cf_corner_rect(0.3, 0.6, 1) + rp_cf_corner_rect(0.7, 0.6, 1) + rp_cf_corner_rect(0.3, 0.4, 1) +
               rp_cf_corner_rect(0.7, 0.4, 1);
    double want = 0.5 * 3 * F;
    cr_log_info("final gather under the lamp: L %.6f +- %.6f, closed form %.6f (%llu rays)", mean, se, want, rays);
    cr_assert_lt(se, 0.01 * want);
    cr_assert_lt(fabs(mean - want), 4 * se + 1e-12, "%.6f vs %.6f +- %.6f", mean, want, se);
    rp_area_sampler_destroy(lights);
    rp_raycast_destroy(rc);
    rp_scene_destroy(sc);
}

/* A lamp that emits and reflects (an MTL light: Kd 0.78, Ke 17 12 4) is
 * sampled as a light like a pure emitter (reconstruct.h): its emitted part
 * by shadow rays and cosine rays under MIS, its reflected part B - pi Le
 * by the cosine rays.  The receiver (rho 1/2) under the unit-square lamp
 * (Le 3, reflect 1/2) at height 1, with a solution that gives the lamp
 * B = pi (Le + c) and the receiver 0: at p the gather must give
 * L = rho (Le + c) F(p), F Howell's B-3 by superposition.  c = 0 (nothing
 * lights the lamp) must be exactly as noisy as the pure emitter of the same
 * Le (with only cosine rays, as before, the standard error was 3 times
 * that of the pure emitter); c = 1/2 checks that the reflected part is
 * counted once.  64 independent keys of 64 rays: within 4 standard
 * errors. */
typedef struct lamp_solution {
    uint32_t lamp; /* the lamp's surface */
    double B;      /* its radiosity */
} lamp_solution;

static void lamp_radiosity(const void *ctx, const rp_hit *g, double *B)
{
    const lamp_solution *s = ctx;
    B[0] = g->surface == s->lamp ? s->B : 0;
}

static void gather_under_lamp(const char *lamp, double c, double *mean, double *se, double *want)
{
    char text[512];
    snprintf(text, sizeof text,
             "bands grey\n"
             "material floor reflect 0.5\n"
             "material lamp %s\n"
             "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
             "quad emitter lamp  0 0 1  0 1 1  1 1 1  1 0 1\n",
             lamp);
    rp_scene *sc = rp_test_parse(text);
    rp_error err = {""};
    rp_raycast *rc = NULL;
    rp_area_sampler *lights = NULL;
    cr_assert_eq(rp_raycast_create(sc, NULL, &rc, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_recon_lights(sc, &lights, &err), RP_OK, "%s", err.message);
    cr_assert(lights, "%s: not sampled as a light", lamp);
    const double Le = 3;
    lamp_solution sol = {.lamp = 1, .B = PI * (Le + c)};
    enum { G = 64, KEYS = 64 };
    rp_recon_gather g = {.scene = sc, .rc = rc, .lights = lights, .rays = G, .nb = 1,
                         .radiosity = lamp_radiosity, .ctx = &sol};
    rp_hit h = {.p = rp_v3(0.3, 0.6, 0), .n = rp_v3(0, 0, 1), .face = 0, .surface = 0, .element = RP_NONE,
                .front = 1};
    double xy[2 * G], sum = 0, sum2 = 0;
    uint32_t perm[G];
    unsigned long long rays = 0;
    for (int k = 0; k < KEYS; k++) {
        double L;
        rp_recon_final_gather(&g, &h, 1000 + (uint64_t)k, xy, perm, &L, &rays);
        sum += L;
        sum2 += L * L;
    }
    *mean = sum / KEYS;
    *se = sqrt((sum2 / KEYS - *mean * *mean) / (KEYS - 1));
    *want = 0.5 * (Le + c) * rp_cf_point_rect(0.3, 0.6, 1, 1, 1);
    cr_log_info("gather under '%s', lamp B = pi (Le + %g): L %.6f +- %.6f, closed form %.6f", lamp, c, *mean, *se,
                *want);
    cr_assert_lt(fabs(*mean - *want), 4 * *se + 1e-12, "%s, c %g: %.6f vs %.6f +- %.6f", lamp, c, *mean, *want,
                 *se);
    rp_area_sampler_destroy(lights);
    rp_raycast_destroy(rc);
    rp_scene_destroy(sc);
}

Test(radiosity, final_gather_samples_an_emitting_reflector)
{
    double mp, sp, wp, m0, s0, w0, m1, s1, w1;
    gather_under_lamp("reflect 0 emit 3", 0, &mp, &sp, &wp);
    gather_under_lamp("reflect 0.5 emit 3", 0, &m0, &s0, &w0);
    gather_under_lamp("reflect 0.5 emit 3", 0.5, &m1, &s1, &w1);
    cr_assert_lt(sp, 0.01 * wp);
    cr_assert_leq(s0, sp * (1 + 1e-9), "emitting reflector: standard error %.3g, pure emitter %.3g", s0, sp);
    cr_assert_lt(s1, 0.02 * w1);
}

/* A furnace (one Le on every face) has no light to sample: the gather
 * keeps to its cosine rays there, which are exact (furnace_images); any
 * other scene with an emitter gets its light sampler. */
Test(radiosity, final_gather_lights)
{
    const char *scenes[] = {"scenes/furnace.scene", "scenes/cube-ceiling.scene", "scenes/cornell.scene"};
    for (int i = 0; i < 3; i++) {
        rp_scene *sc = rp_test_load(scenes[i]);
        rp_area_sampler *lights = NULL;
        rp_error err = {""};
        cr_assert_eq(rp_recon_lights(sc, &lights, &err), RP_OK, "%s", err.message);
        cr_assert_eq(lights != NULL, i > 0, "%s", scenes[i]);
        rp_area_sampler_destroy(lights);
        rp_scene_destroy(sc);
    }
}

/* The gather image (rp_recon_image, as every finite-element method makes
 * it) of the receiver under the emitting-and-reflecting lamp: a 4 x 4
 * camera at height 0.5 looking straight down at (0.3, 0.6), so each pixel
 * sees a square of the receiver (uniformly: the image plane is parallel to
 * it) and its mean is rho (Le + c) times the mean of B-3 over that square
 * (Gauss-Legendre).  The lamp's elements hold B = pi (Le + c), c = 1/2.
 * Every pixel within 4 of its standard errors (from its 16 camera samples,
 * an overestimate under stratification), each under 1.5%. */
Test(radiosity, final_gather_image_under_emitting_reflector, .init = setup)
{
    const double Le = 3, c = 0.5, rho = 0.5, h = 0.5, fov = 8, cx = 0.3, cy = 0.6;
    char text[640];
    snprintf(text, sizeof text,
             "bands grey\n"
             "material floor reflect %g\n"
             "material lamp reflect 0.5 emit %g\n"
             "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
             "quad emitter lamp  0 0 1  0 1 1  1 1 1  1 0 1\n"
             "camera eye %g %g %g  look %g %g 0  up 0 1 0  fov %g  size 4 4\n",
             rho, Le, cx, cy, h, cx, cy, fov);
    rp_scene *sc = rp_test_parse(text);
    rp_error err = {""};
    rp_mesh *mesh = NULL;
    rp_raycast *rc = NULL;
    rp_mesh_params mp = {.size = sizeof mp, .target_count = 32};
    cr_assert_eq(rp_mesh_create(sc, &mp, &mesh, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_raycast_create(sc, mesh, &rc, &err), RP_OK, "%s", err.message);
    const size_t n = rp_mesh_nelements(mesh);
    const rp_element *el = rp_mesh_elements(mesh);
    double *B = malloc(n * sizeof *B);
    cr_assert(B);
    for (size_t e = 0; e < n; e++)
        B[e] = el[e].surface == 1 ? PI * (Le + c) : 0;
    rp_recon_params p = {.mode = RP_RECON_GATHER, .spp = 16, .gather_rays = 64, .seed = 5, .threads = 2};
    float img[16], var[16];
    cr_assert_eq(rp_recon_image(sc, mesh, rc, &p, 1, B, img, var, NULL, &err), RP_OK, "%s", err.message);
    /* pixel (i, j) sees x in eye.x + h tan(fov/2) (2i/4 - 1 .. 2(i+1)/4 - 1),
     * y in eye.y + h tan(fov/2) (1 - 2(j+1)/4 .. 1 - 2j/4) (camera.c) */
    const double s = h * tan(0.5 * fov * PI / 180);
    double worst = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double F = rp_cf_point_rect_mean(cx + s * (i / 2.0 - 1), cx + s * ((i + 1) / 2.0 - 1),
                                             cy + s * (1 - (j + 1) / 2.0), cy + s * (1 - j / 2.0), 1, 1, 1);
            double want = rho * (Le + c) * F, got = img[j * 4 + i], se = sqrt(var[j * 4 + i]);
            cr_assert_lt(se, 0.015 * want, "pixel (%d, %d): standard error %.3g of %.4f", i, j, se, want);
            cr_assert_lt(fabs(got - want), 4 * se, "pixel (%d, %d): %.6f, closed form %.6f +- %.2g", i, j, got,
                         want, se);
            worst = fmax(worst, fabs(got - want) / se);
        }
    cr_log_info("gather image under the emitting reflector: largest deviation %.2f standard errors", worst);
    free(B);
    rp_raycast_destroy(rc);
    rp_mesh_destroy(mesh);
    rp_scene_destroy(sc);
}

/* Gauss-Seidel's sweep runs in blocks of rows (iterative.c, GS_BLOCK 256):
 * with more elements than a block, the iterates are the same bit for bit
 * for 1, 2 and 3 threads, and the solution is direct's (LU) to 1e-6. */
Test(radiosity, gauss_seidel_blocks_any_thread_count, .init = setup, .timeout = 300)
{
    rp_scene *sc = rp_test_load("scenes/cornell.scene");
    rad_run d;
    rad_run_ok(&d, &rp_solver_direct, sc, RP_WANT_SURFACES, 0, "elements=600");
    const size_t n = d.sys->n, nb = 3;
    cr_assert_gt(n, 512, "%zu elements: not several blocks", n);
    double *B1 = NULL;
    const int threads[3] = {1, 2, 3};
    for (int t = 0; t < 3; t++) {
        rad_run r;
        rad_run_ok(&r, &rp_solver_gauss_seidel, sc, RP_WANT_SURFACES, threads[t], "elements=600 tolerance=1e-11");
        cr_assert_eq(r.sys->n, n);
        if (!B1) {
            B1 = malloc(n * nb * sizeof *B1);
            memcpy(B1, r.sys->B, n * nb * sizeof *B1);
            for (size_t i = 0; i < n * nb; i++)
                cr_assert_float_eq(B1[i], d.sys->B[i], 1e-6 * fabs(d.sys->B[i]) + 1e-300,
                                   "element %zu band %zu: %.12g, direct %.12g", i / nb, i % nb, B1[i], d.sys->B[i]);
        } else {
            cr_assert_eq(memcmp(B1, r.sys->B, n * nb * sizeof *B1), 0, "%d threads: another solution", threads[t]);
        }
        rad_close(&r);
    }
    free(B1);
    rad_close(&d);
    rp_scene_destroy(sc);
}
