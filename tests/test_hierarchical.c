/* Tests of hierarchical radiosity (solvers/radiosity/hierarchical.c).
 *
 * Check values come from closed forms or from another method, not from the
 * code under test:
 *   - the contour kernel against the closed form for a differential area
 *     below a parallel rectangle (Howell's catalog, B-3 by superposition),
 *     and its clipping against a hand-cut polygon;
 *   - furnace (closed box, rho 0.5, Le 1): L = Le / (1 - rho) = 2.  Without
 *     refinement every element is a face and the point-to-polygon form
 *     factors from its centre to the five others close to 1 exactly, so
 *     every leaf is within 1e-6 of 2.  With refinement a leaf also
 *     gathers through its ancestors' links, whose form factors were
 *     estimated at the ancestors' centres: the raw sums reaching a leaf
 *     are 1 only on average (0.90 to 1.15 with the defaults), and the
 *     enclosure's row-sum normalisation must still put every leaf within
 *     1e-6 of 2 at the defaults, and within 1e-9 at tolerance 1e-12;
 *   - cube-ceiling: surface averages against the path tracer through the
 *     solver interface (262144 probe points per surface, within 1% + 3
 *     standard errors), and the energy invariant of a closed uniform-rho
 *     scene, area-mean L = mean(Le) / (1 - rho) = 1/3 (1%);
 *   - links grow as bf-epsilon shrinks (counts and the slope of log links
 *     against log leaves are logged), and the counts add up: stored links
 *     are the fully plus the partially visible ones, and the equivalent
 *     uniform mesh is lit area / smallest leaf (recomputed here from the
 *     leaves);
 *   - Gouraud images have no cracks: on the Cornell box (whose blocks force
 *     T-vertices) the interpolated radiosity on both sides of every leaf
 *     edge inside a face agrees;
 *   - the same answers, bit for bit, with one thread and with two (with
 *     importance too: camera through auto, surfaces with clustering; with
 *     the linear basis);
 *   - a refinement pass that refines nothing leaves the links untouched;
 *   - clustering (Smits, Arvo & Greenberg 1994): the furnace cut into 3072
 *     triangles, every leaf within 2e-6 of L = 2 (row-sum normalisation
 *     makes the uniform answer a fixed point; the bound is the Jacobi
 *     stopping rule's) with initial links under 5% of faces^2; cube-ceiling
 *     cut into 216 quads, per-wall means with clustering on and off within
 *     1% of each other and 2% + 3 standard errors of the path tracer; the
 *     same answer for one and two threads with clustering on;
 *   - no light leaks: a closed shell in a lit room lined inside by an
 *     inward surface (a box, 19 and 607 faces; a sphere in a sphere, 247
 *     and 727 faces), with clustering on and off: the inside reads exactly
 *     0 (no light can reach it), the room and the outside of the shell
 *     within 2% + 4 standard errors of the path tracer; CGAL's elephant in
 *     the Cornell box, clustered: every surface of 2% of the area or more
 *     within 3% of the path tracer;
 *   - importance (Smits, Arvo & Salesin 1992): --importance none is the
 *     default, and gives the same Cornell box whether an image is wanted
 *     or not;
 *     the importance of two parallel plates, camera and surfaces, against
 *     the closed-form solution of the 2 x 2 adjoint system; the camera's
 *     direct importance adds up to the share of the image a wall covers;
 *     a camera seeing one wall of a lit cube leaves the wall behind it
 *     coarser and the image as close to a finer solution;
 *   - a floor under a lamp and a blocker: its mean radiance against the
 *     one-bounce closed form (B-3 over the lamp), on four seeds, each
 *     within 0.1% and their mean within 0.04% (shadow_mean_is_unbiased);
 *   - --mesh discontinuity: no floor leaf crosses the outline of a box
 *     standing on it (from the faces as given, some do), and the option is
 *     refused, naming --simplify off, when a mesh was simplified;
 *   - --basis linear (Galerkin, linear elements): a plate under a lamp and
 *     a wall lit only by that plate, both against closed forms integrated
 *     by GSL's Gauss-Legendre, within 1% and 0.5% of the best any linear
 *     function on the same 4 x 4 elements reaches, and several times
 *     better than constant elements; the furnace exact at every leaf
 *     corner (1e-9); the same answer for one and two threads; the basis
 *     orthonormal on a triangle, a sliver and a trapezoid; on the Cornell
 *     box the two-scale relation exact at every child's corners, every
 *     parent's mean and slopes the projection of its children's functions
 *     (quadrature), and every link's coefficient slot its own. */
#include <criterion/criterion.h>

#include <gsl/gsl_errno.h>
#include <gsl/gsl_fit.h>
#include <gsl/gsl_integration.h>
#include <gsl/gsl_linalg.h>
#include <gsl/gsl_rng.h>
#include <gsl/gsl_statistics.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "geometry/scene.h"
#include "solvers/radiosity/hier_internal.h"
#include "solvers/radiosity/hierarchical.h"
#include "solvers/solver.h"
#include "closed_form.h"
#include "scene_util.h"

extern const rp_solver_type rp_solver_pathtrace;

static void hsetup(void) { gsl_set_error_handler_off(); }

/* The last message a solver logged. */
static char last_log[1024];
static void capture_log(void *ctx, const char *msg)
{
    (void)ctx;
    snprintf(last_log, sizeof last_log, "%s", msg);
}

typedef struct hrun {
    const rp_solver_type *type;
    void *state;
} hrun;

/* The seed hrun_start hands the solver. */
static uint64_t hrun_seed = 7;

/* Options as "key", "value" pairs, NULL-terminated. */
static rp_status hrun_start(hrun *r, const rp_solver_type *type, const rp_scene *scene, unsigned want,
                            int threads, const char *const *kv, rp_error *err)
{
    static const char *keys[16], *vals[16];
    size_t n = 0;
    for (; kv && kv[2 * n]; n++) {
        keys[n] = kv[2 * n];
        vals[n] = kv[2 * n + 1];
    }
    rp_options o = {.size = sizeof o, .want = want, .seed = hrun_seed, .threads = threads,
                    .keys = keys, .values = vals, .count = n, .log = capture_log,
                    .specs = type->options}; /* as rp_solver_create hands them to init */
    r->type = type;
    r->state = calloc(1, type->state_size);
    cr_assert(r->state);
    rp_status st = rp_options_check(&o, type, err);
    if (st == RP_OK)
        st = type->init(r->state, scene, &o, err);
    return st;
}

static void hrun_solve(hrun *r)
{
    rp_error err = {""};
    for (int k = 0; k < 100000; k++) {
        rp_step_info info;
        memset(&info, 0, sizeof info);
        rp_status st = r->type->step(r->state, &info, &err);
        cr_assert_eq(st, RP_OK, "%s", err.message);
        if (info.converged)
            return;
    }
    cr_assert_fail("%s did not converge", r->type->name);
}

static void hrun_end(hrun *r)
{
    r->type->fini(r->state);
    free(r->state);
}

static void solve_hier(hrun *r, const rp_scene *scene, unsigned want, int threads, const char *const *kv)
{
    rp_error err = {""};
    rp_status st = hrun_start(r, &rp_solver_hierarchical, scene, want, threads, kv, &err);
    cr_assert_eq(st, RP_OK, "%s", err.message);
    hrun_solve(r);
}

/* The path tracer's surface averages and their standard errors, from
 * `samples` probe points a surface (the independent reference of the
 * tests that compare against it). */
static void probe_pathtrace(const rp_scene *scene, const char *samples, double *L, double *se)
{
    hrun p;
    rp_error err = {""};
    const char *kv[] = {"samples", samples, "batch", "16384", NULL};
    cr_assert_eq(hrun_start(&p, &rp_solver_pathtrace, scene, RP_WANT_SURFACES, 0, kv, &err), RP_OK, "%s",
                 err.message);
    hrun_solve(&p);
    rp_estimate pe = {.surface_radiance = L, .surface_stderr = se};
    cr_assert_eq(p.type->estimate(p.state, &pe, &err), RP_OK, "%s", err.message);
    hrun_end(&p);
}

/* ---- the contour kernel ------------------------------------------------ */

Test(hier, contour_kernel, .init = hsetup)
{
    /* Unit square centred 0.7 above the point: four corner rectangles. */
    rp_vec3 sq[4] = {{-0.5, -0.5, 0.7}, {-0.5, 0.5, 0.7}, {0.5, 0.5, 0.7}, {0.5, -0.5, 0.7}};
    double F = hier_point_polygon(rp_v3(0, 0, 0), rp_v3(0, 0, 1), sq, 4);
    cr_assert_float_eq(F, 4 * rp_cf_corner_rect(0.5, 0.5, 0.7), 1e-13, "%.15g", F);
    /* Off-centre: the rectangle [0.2, 1.4] x [0.1, 0.6] at height 0.5 from
     * the origin, by superposition of corner rectangles. */
    rp_vec3 r[4] = {{0.2, 0.1, 0.5}, {1.4, 0.1, 0.5}, {1.4, 0.6, 0.5}, {0.2, 0.6, 0.5}};
    double want = rp_cf_corner_rect(1.4, 0.6, 0.5) - rp_cf_corner_rect(0.2, 0.6, 0.5) -
                  rp_cf_corner_rect(1.4, 0.1, 0.5) + rp_cf_corner_rect(0.2, 0.1, 0.5);
    F = hier_point_polygon(rp_v3(0, 0, 0), rp_v3(0, 0, 1), r, 4);
    cr_assert_float_eq(F, want, 1e-13, "%.15g vs %.15g", F, want);
    /* Clipping: a square in the plane x = 1 from z = -1 to z = 1 is seen
     * only above the tangent plane z = 0: its form factor is that of the
     * hand-cut upper half. */
    rp_vec3 t[4] = {{1, -0.5, -1}, {1, 0.5, -1}, {1, 0.5, 1}, {1, -0.5, 1}};
    rp_vec3 h[4] = {{1, -0.5, 0}, {1, 0.5, 0}, {1, 0.5, 1}, {1, -0.5, 1}};
    double Ft = hier_point_polygon(rp_v3(0, 0, 0), rp_v3(0, 0, 1), t, 4);
    double Fh = hier_point_polygon(rp_v3(0, 0, 0), rp_v3(0, 0, 1), h, 4);
    cr_assert(Fh > 0.01);
    cr_assert_float_eq(Ft, Fh, 1e-14, "%.15g vs %.15g", Ft, Fh);
}

/* ---- the furnace ------------------------------------------------------- */

Test(hier, furnace_unrefined, .init = hsetup)
{
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    hrun r;
    /* No link is ever worth refining: every leaf is a face. */
    const char *kv[] = {"bf-epsilon", "1e6", "tolerance", "1e-12", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    double area[16], B[16], sums[16];
    size_t n = rp_hierarchical_leaves(r.state, area, NULL, B, 16);
    cr_assert_eq(n, 6);
    cr_assert_eq(rp_hierarchical_leaf_form_factor_sums(r.state, sums, 16), 6);
    for (size_t i = 0; i < n; i++) {
        /* five links of about 0.2, each kept to 2^-16 of itself (hier_link) */
        cr_assert_float_eq(sums[i], 1.0, 0x1p-16, "leaf %zu: form factors sum to %.15g", i, sums[i]);
        cr_assert_float_eq(B[i] / RP_PI, 2.0, 1e-6, "leaf %zu: L = %.12g", i, B[i] / RP_PI);
    }
    /* The counts SPLASH-2 reports reach the log at convergence. */
    cr_assert(strstr(last_log, "6 leaves") && strstr(last_log, "30 (30 fully visible, 0 partial"),
              "log: %s", last_log);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* The furnace with refinement: every leaf's L against the closed form
 * Le / (1 - rho) = 2.  The raw form-factor sums reaching the leaves scatter
 * (their ancestors' links are estimated at the ancestors' centres); the
 * row-sum normalisation of an enclosure must make every leaf exact all the
 * same, to the solver's tolerance (1e-6 relative energy change per sweep at
 * the defaults, which bounds a leaf's error by about 1e-6 here: the error
 * of Jacobi on the furnace shrinks by rho = 1/2 per sweep, so it is at most
 * the last change). */
static void furnace_check(const char *const *kv, double tol, size_t min_leaves)
{
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    hrun r;
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    cr_assert_eq(rp_hierarchical_enclosure(r.state), 1, "the furnace is an enclosure");
    size_t n = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
    double *area = malloc(n * sizeof *area), *B = malloc(n * sizeof *B), *S = malloc(n * sizeof *S);
    cr_assert(area && B && S);
    rp_hierarchical_leaves(r.state, area, NULL, B, n);
    rp_hierarchical_leaf_form_factor_sums(r.state, S, n);
    double at = 0, aL = 0, emax = 0, smin = INFINITY, smax = 0;
    for (size_t i = 0; i < n; i++) {
        double L = B[i] / RP_PI;
        at += area[i];
        aL += area[i] * L;
        emax = fmax(emax, fabs(L - 2));
        smin = fmin(smin, S[i]);
        smax = fmax(smax, S[i]);
    }
    cr_log_info("furnace, %s %s: %zu leaves; raw form-factor sums %.4f to %.4f; area-mean L %.12f; "
                "largest |L - 2| %.3g",
                kv ? kv[0] : "defaults", kv ? kv[1] : "", n, smin, smax, aL / at, emax);
    cr_assert_geq(n, min_leaves, "refinement is on: %zu leaves", n);
    cr_assert(smax - smin > 0.01, "the raw sums scatter (%.4f to %.4f): the test would prove nothing", smin, smax);
    for (size_t i = 0; i < n; i++)
        cr_assert_float_eq(B[i] / RP_PI, 2.0, tol, "leaf %zu: L = %.12g", i, B[i] / RP_PI);
    free(area);
    free(B);
    free(S);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

Test(hier, furnace_refined, .init = hsetup, .timeout = 120)
{
    /* The defaults refine the furnace into thousands of leaves. */
    furnace_check(NULL, 1e-6, 1000);
}

Test(hier, furnace_refined_exact, .init = hsetup, .timeout = 120)
{
    /* A coarser oracle (still refined) and a tight tolerance: exact to
     * 1e-9 (the iteration stops once a sweep changes less than 1e-12). */
    const char *kv[] = {"bf-epsilon", "0.05", "tolerance", "1e-12", NULL};
    furnace_check(kv, 1e-9, 50);
}

Test(hier, enclosure_detection, .init = hsetup)
{
    /* The normalisation applies to enclosures seen from inside only: the
     * closed cube is one, the Cornell box (open at the front) is not. */
    static const char *scenes[] = {"scenes/cube-ceiling.scene", "scenes/furnace.scene", "scenes/cornell.scene"};
    static const int want[] = {1, 1, 0};
    for (int k = 0; k < 3; k++) {
        rp_scene *scene = rp_test_load(scenes[k]);
        hrun r;
        rp_error err = {""};
        cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_SURFACES, 0, NULL, &err), RP_OK, "%s",
                     err.message);
        cr_assert_eq(rp_hierarchical_enclosure(r.state), want[k], "%s", scenes[k]);
        hrun_end(&r);
        rp_scene_destroy(scene);
    }
}

/* ---- cube-ceiling ------------------------------------------------------ */

Test(hier, cube_against_pathtrace_and_uniform, .init = hsetup, .timeout = 600)
{
    rp_scene *scene = rp_test_load("scenes/cube-ceiling.scene");
    const size_t ns = rp_scene_nsurfaces(scene);
    cr_assert_eq(rp_scene_nbands(scene), 1);
    double h[8], pt[8], se[8];
    hrun r;
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, NULL);
    rp_estimate e = {.surface_radiance = h};
    rp_error err = {""};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
    rp_hier_stats st;
    rp_hierarchical_stats(r.state, &st);
    hrun_end(&r);

    probe_pathtrace(scene, "262144", pt, se);

    /* And the fine uniform solution (Gauss-Seidel on 4800 elements, 800
     * a face): within 1%. */
    double g[8];
    hrun u;
    const char *gk[] = {"elements", "4800", NULL};
    cr_assert_eq(hrun_start(&u, rp_solver_lookup("gauss-seidel"), scene, RP_WANT_SURFACES, 0, gk, &err), RP_OK, "%s",
                 err.message);
    hrun_solve(&u);
    rp_estimate ge = {.surface_radiance = g};
    cr_assert_eq(u.type->estimate(u.state, &ge, &err), RP_OK, "%s", err.message);
    hrun_end(&u);

    const rp_surface *surf = rp_scene_surfaces(scene);
    double aL = 0, at = 0, worst = 0;
    for (size_t s = 0; s < ns; s++) {
        cr_log_info("%-8s hierarchical %.6f  gauss-seidel 4800 %.6f  (%+.3f%%)", surf[s].name, h[s], g[s],
                    100 * (h[s] - g[s]) / g[s]);
        cr_expect_leq(fabs(h[s] - g[s]), 0.01 * g[s], "%s: %.6f vs uniform %.6f", surf[s].name, h[s], g[s]);
        double tol = 0.01 * pt[s] + 3 * se[s];
        cr_log_info("%-8s hierarchical %.6f  pathtrace %.6f +- %.6f  (%+.3f%%)", surf[s].name, h[s], pt[s], se[s],
                    100 * (h[s] - pt[s]) / pt[s]);
        worst = fmax(worst, fabs(h[s] - pt[s]) / pt[s]);
        cr_expect_leq(fabs(h[s] - pt[s]), tol, "%s: %.6f vs %.6f +- %.6f", surf[s].name, h[s], pt[s], se[s]);
        aL += surf[s].area * h[s];
        at += surf[s].area;
    }
    cr_log_info("cube-ceiling: %zu leaves, %zu links; worst surface %.3f%%", st.leaves, st.links, 100 * worst);
    /* Energy invariant: one face of six emits Le = 1, rho = 0.5. */
    cr_assert_float_eq(aL / at, 1.0 / 3.0, 0.01 / 3.0, "area-mean L %.6f", aL / at);
    rp_scene_destroy(scene);
}

Test(hier, links_grow_as_epsilon_shrinks, .init = hsetup, .timeout = 600)
{
    rp_scene *scene = rp_test_load("scenes/cube-ceiling.scene");
    /* bf-epsilon and min-area shrink together, so the leaves are not held
     * back by the area floor. */
    static const char *eps[] = {"0.3", "0.1", "0.03", "0.01"};
    static const char *amin[] = {"3e-4", "1e-4", "3e-5", "1e-5"};
    double lx[4], ly[4];
    size_t prev_links = 0, prev_leaves = 0;
    for (int k = 0; k < 4; k++) {
        hrun r;
        const char *kv[] = {"bf-epsilon", eps[k], "min-area", amin[k], NULL};
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        rp_hier_stats st;
        rp_hierarchical_stats(r.state, &st);
        size_t n = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
        double *area = malloc(n * sizeof *area);
        rp_hierarchical_leaves(r.state, area, NULL, NULL, n);
        double amin_leaf = INFINITY;
        for (size_t i = 0; i < n; i++)
            amin_leaf = fmin(amin_leaf, area[i]);
        free(area);
        cr_log_info("bf-epsilon %s, min-area %s: %zu leaves, %zu links (%zu full, %zu partial, %zu invisible), "
                    "equivalent uniform mesh %.0f",
                    eps[k], amin[k], st.leaves, st.links, st.links_full, st.links_partial, st.links_invisible,
                    st.uniform_equivalent);
        cr_assert_eq(st.leaves, n);
        cr_assert_eq(st.links, st.links_full + st.links_partial);
        /* every face of cube-ceiling reflects or emits: lit area = total area */
        cr_assert_float_eq(st.uniform_equivalent, rp_scene_total_area(scene) / amin_leaf, 1e-9 * st.uniform_equivalent);
        cr_assert_gt(st.links, prev_links);
        cr_assert_gt(st.leaves, prev_leaves);
        prev_links = st.links;
        prev_leaves = st.leaves;
        lx[k] = log((double)st.leaves);
        ly[k] = log((double)st.links);
        hrun_end(&r);
    }
    double c0, c1, cov00, cov01, cov11, sumsq;
    gsl_fit_linear(lx, 1, ly, 1, 4, &c0, &c1, &cov00, &cov01, &cov11, &sumsq);
    cr_log_info("slope of log links against log leaves: %.3f", c1);
    rp_scene_destroy(scene);
}

/* ---- images ------------------------------------------------------------ */

/* Solves, then builds the Gouraud vertex values (hier_image.c). */
static hier_vertices *solve_vertices(hrun *r, const rp_scene *scene, const char *const *kv)
{
    solve_hier(r, scene, RP_WANT_IMAGE, 0, kv);
    rp_error err = {""};
    hier_vertices *hv = NULL;
    cr_assert_eq(hier_vertices_create(r->state, &hv, &err), RP_OK, "%s", err.message);
    return hv;
}

Test(hier, gouraud_is_crack_free, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0.1", NULL};
    hier_vertices *hv = solve_vertices(&r, scene, kv);
    const hier_state *s = r.state;
    size_t tcount = hier_vertices_tcount(hv);
    cr_assert_gt(tcount, 0, "no T-vertex: the test would prove nothing");
    const size_t nb = s->nb;
    double Bp[HIER_MAX_BANDS], Bm[HIER_MAX_BANDS], worst = 0, Bmax = 0;
    size_t checked = 0;
    for (size_t i = 0; i < s->nnodes * nb; i++)
        Bmax = fmax(Bmax, s->B[i]);
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE)
            continue;
        const hier_face *f = &s->faces[nd->face];
        const hier_node *root = &s->nodes[nd->face];
        for (int k = 0; k < nd->nverts; k++) {
            rp_vec3 a = nd->v[k], b = nd->v[(k + 1) % nd->nverts];
            rp_vec3 e = rp_v3_sub(b, a);
            double len = rp_v3_length(e);
            /* In-plane normal of the edge, and a point 37% along it. */
            rp_vec3 m = rp_v3_normalize(rp_v3_cross(f->n, e));
            rp_vec3 x = rp_v3_madd(a, e, 0.37);
            double d = 1e-9 * len;
            rp_vec3 xp = rp_v3_madd(x, m, d), xm = rp_v3_madd(x, m, -d);
            /* Only edges inside the face: both points within the root. */
            int inside = 1;
            for (int j = 0; j < root->nverts && inside; j++) {
                rp_vec3 ra = root->v[j], rb = root->v[(j + 1) % root->nverts];
                rp_vec3 c = rp_v3_cross(rp_v3_sub(rb, ra), f->n);
                double lim = 1e-6 * rp_v3_length(rp_v3_sub(rb, ra)) * len;
                if (rp_v3_dot(rp_v3_sub(xp, ra), c) > -lim || rp_v3_dot(rp_v3_sub(xm, ra), c) > -lim)
                    inside = 0;
            }
            if (!inside)
                continue;
            hier_vertices_eval(s, hv, nd->face, xp, Bp);
            hier_vertices_eval(s, hv, nd->face, xm, Bm);
            /* Relative, down to 1e-4 of the brightest leaf: on the floor
             * under a box, which no light reaches, vertex values are 0 to
             * rounding, and the points 1e-9 of an edge away from the edge
             * pick up 1e-9 of the lit corners across their leaves. */
            double scale = 1e-4 * Bmax;
            for (size_t bnd = 0; bnd < nb; bnd++) {
                scale = fmax(scale, fabs(Bp[bnd]) + fabs(Bm[bnd]));
                worst = fmax(worst, fabs(Bp[bnd] - Bm[bnd]) / scale);

            }
            checked++;
        }
    }
    cr_log_info("Cornell box, bf-epsilon 0.1: %zu T-vertices, %zu leaf edges checked, largest relative jump %.3g",
                tcount, checked, worst);
    cr_assert_gt(checked, 100);
    cr_assert_lt(worst, 1e-6, "a crack: radiosity jumps by %.3g across a leaf edge", worst);
    hier_vertices_destroy(hv);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* Gouraud vertex values are the radiosity at the vertex, not the mean of
 * the leaves around it.  A unit-square receiver (rho 1/2) under a parallel
 * unit-square emitter at height 1, never refined (one leaf, four corner
 * vertices): its radiosity at a point p is rho pi Le F(p), with F the
 * point-to-rectangle form factor by superposition of Howell's B-3 corner
 * rectangles.  The vertex is evaluated a thousandth of the way towards the
 * leaf's centre (hier_image.c), so the closed form is taken there too.  A
 * leaf-mean value would be off by 30% at the corners. */
Test(hier, gouraud_vertices_are_point_values, .init = hsetup)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material floor reflect 0.5\n"
                                    "material lamp reflect 0 emit 3\n"
                                    "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad emitter lamp  0 0 1  0 1 1  1 1 1  1 0 1\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "1e6", NULL};
    hier_vertices *hv = solve_vertices(&r, scene, kv);
    const hier_state *s = r.state;
    cr_assert_eq(s->nodes[0].child, RP_NONE, "the receiver was refined");
    double leaf = s->B[0];
    const double corner[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (int k = 0; k < 4; k++) {
        /* By symmetry each corner sees the emitter as (0, 0) does. */
        double e = 0.5e-3, f = 1 - e;
        double F = rp_cf_corner_rect(f, f, 1) + 2 * rp_cf_corner_rect(e, f, 1) + rp_cf_corner_rect(e, e, 1);
        double want = 0.5 * RP_PI * 3 * F;
        rp_vec3 x = rp_v3(corner[k][0] + (corner[k][0] > 0 ? -e : e), corner[k][1] + (corner[k][1] > 0 ? -e : e), 0);
        double B;
        hier_vertices_eval(s, hv, 0, x, &B);
        cr_log_info("receiver corner %d: vertex B %.9f, closed form %.9f, leaf mean %.6f", k, B, want, leaf);
        cr_assert_float_eq(B, want, 1e-9 * want, "corner %d: %.12g vs %.12g", k, B, want);
        cr_assert_gt(fabs(leaf - want), 0.2 * want, "the leaf mean is close: the test would prove nothing");
    }
    hier_vertices_destroy(hv);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* The unit-square lamp (Le 3) at height c over the receiver given by
 * `receiver` (scene lines, material floor: rho 1/2), solved with
 * bf-epsilon 0 down to min_area in basis `basis`; `leaves` leaves expected. */
static rp_scene *plate_under_lamp(hrun *r, const char *receiver, double c, const char *min_area, const char *basis,
                                  size_t leaves)
{
    char text[512];
    snprintf(text, sizeof text,
             "bands grey\nmaterial floor reflect 0.5\nmaterial lamp reflect 0 emit 3\n%s"
             "quad emitter lamp  0 0 %g  0 1 %g  1 1 %g  1 0 %g\n",
             receiver, c, c, c, c);
    rp_scene *scene = rp_test_parse(text);
    const char *kv[] = {"bf-epsilon", "0", "min-area", min_area, "basis", basis, NULL};
    solve_hier(r, scene, RP_WANT_SURFACES, 0, kv);
    cr_assert_eq(rp_hierarchical_leaves(r->state, NULL, NULL, NULL, 0), leaves, "leaves: receiver's and the lamp");
    return scene;
}

/* --basis linear against the closed form.  A unit-square receiver (rho
 * 1/2) under a parallel unit-square emitter (Le 3) at height 0.4, refined
 * to 4 x 4 leaves (bf-epsilon 0, min-area 0.02 of the two squares' area):
 * one bounce is the whole answer, B(x) = rho pi Le F(x), F the point-to-
 * rectangle form factor (Howell's B-3 by superposition).  On every leaf
 * the best any linear function can do is the L2 projection of B onto the
 * leaf's linear functions, computed here by 8 x 8-point Gauss-Legendre
 * (GSL); the best constant, B's mean there.  The linear solution must come
 * within 1% of the best linear error (measured: 0.2%) and be several times
 * better than the constant basis's solution on the same leaves. */
static void linear_plate_errors(const char *basis, double *err, double *best_const, double *best_lin)
{
    const double c = 0.4, rho = 0.5, Le = 3;
    hrun r;
    rp_scene *scene = plate_under_lamp(&r, "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n", c, "0.02", basis, 17);
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(8);
    cr_assert(t);
    double e2 = 0, bc2 = 0, bl2 = 0;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            const double x0 = i / 4.0, y0 = j / 4.0, h = 0.25;
            /* moments of B over the leaf: mean, and against the leaf's
             * orthonormal linear functions sqrt(3) (2u - 1), sqrt(3) (2v - 1) */
            double m = 0, m2 = 0, cu = 0, cv = 0, se = 0;
            for (size_t a = 0; a < t->n; a++)
                for (size_t b = 0; b < t->n; b++) {
                    double x, wx, y, wy;
                    gsl_integration_glfixed_point(x0, x0 + h, a, &x, &wx, t);
                    gsl_integration_glfixed_point(y0, y0 + h, b, &y, &wy, t);
                    double w = wx * wy / (h * h);
                    double B = rho * RP_PI * Le * rp_cf_point_rect(x, y, 1, 1, c);
                    double got;
                    rp_hierarchical_radiosity_at(r.state, 0, rp_v3(x, y, 0), &got);
                    m += w * B;
                    m2 += w * B * B;
                    cu += w * B * sqrt(3.0) * (2 * (x - x0) / h - 1);
                    cv += w * B * sqrt(3.0) * (2 * (y - y0) / h - 1);
                    se += w * (got - B) * (got - B);
                }
            e2 += se / 16;
            bc2 += (m2 - m * m) / 16;
            bl2 += (m2 - m * m - cu * cu - cv * cv) / 16;
        }
    gsl_integration_glfixed_table_free(t);
    *err = sqrt(e2);
    *best_const = sqrt(bc2);
    *best_lin = sqrt(fmax(bl2, 0));
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* Solves with both bases (errors: RMS error, best constant's, best
 * linear's) and requires the linear solution within a factor `near` of
 * the best linear error and below 0.2 of the constant basis's. */
typedef void linear_errors_fn(const char *basis, double *err, double *best_const, double *best_lin);

static void expect_linear_near_best(const char *what, linear_errors_fn *errors, double near)
{
    double ec, el, bc, bl;
    errors("constant", &ec, &bc, &bl);
    errors("linear", &el, &bc, &bl);
    cr_log_info("%s, RMS error of B: constant basis %.5f (best constant %.5f), linear basis %.5f (best linear %.5f)",
                what, ec, bc, el, bl);
    cr_assert_lt(bl, 0.5 * bc, "B is nearly constant over a leaf: the test would prove nothing");
    cr_assert_lt(el, near * bl, "linear: %.5f against the best linear %.5f", el, bl);
    cr_assert_lt(el, 0.2 * ec, "linear %.5f, constant %.5f", el, ec);
}

Test(hier, linear_basis_against_closed_form, .init = hsetup)
{
    /* measured: 0.2% above the best linear, 0.13 of the constant's error */
    expect_linear_near_best("plate under a lamp, 4 x 4 leaves", linear_plate_errors, 1.01);
}

/* --basis linear on triangles, which the discontinuity mesh is made of
 * (the plate above has quads only).  The same lamp and receiver as above,
 * the receiver given as the two triangles (0,0)-(1,0)-(1,1) and
 * (0,0)-(1,1)-(0,1), each refined to 16 leaves (bf-epsilon 0, min-area
 * 0.01 of the lit area: a triangle is split at its edge midpoints, so 1/32
 * of the square each); B(x) = rho pi Le F(x) as above.  On every leaf the
 * best linear function is B's L2 projection onto {1, x, y}, taken here from
 * the 3 x 3 Gram matrix by GSL's Cholesky, every integral by 8 x 8-point
 * Gauss-Legendre on the square mapped onto the triangle (Duffy: x = a + u
 * (b - a) + u v (c - b), Jacobian 2 A u).  The leaves are made here by the
 * same midpoint rule, not read from the solver.  The linear solution must
 * come within 2% of the best linear error and below 0.2 of the constant
 * basis's. */
typedef struct tri2 {
    double p[3][2];
} tri2;

static int tri_leaves(const tri2 *t, int levels, tri2 *out)
{
    if (levels == 0) {
        *out = *t;
        return 1;
    }
    double m[3][2];
    for (int k = 0; k < 3; k++)
        for (int d = 0; d < 2; d++)
            m[k][d] = 0.5 * (t->p[k][d] + t->p[(k + 1) % 3][d]);
    tri2 ch[4] = {{{{t->p[0][0], t->p[0][1]}, {m[0][0], m[0][1]}, {m[2][0], m[2][1]}}},
                  {{{m[0][0], m[0][1]}, {t->p[1][0], t->p[1][1]}, {m[1][0], m[1][1]}}},
                  {{{m[2][0], m[2][1]}, {m[1][0], m[1][1]}, {t->p[2][0], t->p[2][1]}}},
                  {{{m[0][0], m[0][1]}, {m[1][0], m[1][1]}, {m[2][0], m[2][1]}}}};
    int n = 0;
    for (int k = 0; k < 4; k++)
        n += tri_leaves(&ch[k], levels - 1, out + n);
    return n;
}

static void linear_triangle_errors(const char *basis, double *err, double *best_const, double *best_lin)
{
    const double c = 0.4, rho = 0.5, Le = 3;
    hrun r;
    rp_scene *scene = plate_under_lamp(&r,
                                       "triangle lower floor  0 0 0  1 0 0  1 1 0\n"
                                       "triangle upper floor  0 0 0  1 1 0  0 1 0\n",
                                       c, "0.01", basis, 33); /* 16 leaves per triangle */
    const tri2 roots[2] = {{{{0, 0}, {1, 0}, {1, 1}}}, {{{0, 0}, {1, 1}, {0, 1}}}};
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(8);
    cr_assert(t);
    double e2 = 0, bc2 = 0, bl2 = 0;
    int nleaves = 0;
    for (uint32_t face = 0; face < 2; face++) {
        tri2 leaf[16];
        cr_assert_eq(tri_leaves(&roots[face], 2, leaf), 16);
        for (int l = 0; l < 16; l++, nleaves++) {
            const double *a = leaf[l].p[0], *b = leaf[l].p[1], *cc = leaf[l].p[2];
            double area = 0.5 * fabs((b[0] - a[0]) * (cc[1] - a[1]) - (b[1] - a[1]) * (cc[0] - a[0]));
            cr_assert_float_eq(area, 1.0 / 32, 1e-15);
            /* means over the leaf: of B, B^2, B phi_i and phi_i phi_j, phi = (1, x, y) */
            double m = 0, m2 = 0, bphi[3] = {0, 0, 0}, gram[9] = {0}, se = 0;
            for (size_t i = 0; i < t->n; i++)
                for (size_t j = 0; j < t->n; j++) {
                    double u, wu, v, wv;
                    gsl_integration_glfixed_point(0, 1, i, &u, &wu, t);
                    gsl_integration_glfixed_point(0, 1, j, &v, &wv, t);
                    double x = a[0] + u * (b[0] - a[0]) + u * v * (cc[0] - b[0]);
                    double y = a[1] + u * (b[1] - a[1]) + u * v * (cc[1] - b[1]);
                    double w = wu * wv * 2 * u; /* 2 A u / A */
                    double B = rho * RP_PI * Le * rp_cf_point_rect(x, y, 1, 1, c), got;
                    rp_hierarchical_radiosity_at(r.state, face, rp_v3(x, y, 0), &got);
                    const double phi[3] = {1, x, y};
                    m += w * B;
                    m2 += w * B * B;
                    for (int p = 0; p < 3; p++) {
                        bphi[p] += w * B * phi[p];
                        for (int q = 0; q < 3; q++)
                            gram[3 * p + q] += w * phi[p] * phi[q];
                    }
                    se += w * (got - B) * (got - B);
                }
            /* best linear: m2 - bphi^T G^-1 bphi */
            gsl_matrix_view G = gsl_matrix_view_array(gram, 3, 3);
            double sol[3];
            gsl_vector_view rhs = gsl_vector_view_array(bphi, 3), xs = gsl_vector_view_array(sol, 3);
            cr_assert_eq(gsl_linalg_cholesky_decomp1(&G.matrix), 0);
            cr_assert_eq(gsl_linalg_cholesky_solve(&G.matrix, &rhs.vector, &xs.vector), 0);
            double proj = sol[0] * bphi[0] + sol[1] * bphi[1] + sol[2] * bphi[2];
            e2 += se / 32;
            bc2 += (m2 - m * m) / 32;
            bl2 += fmax(m2 - proj, 0) / 32;
        }
    }
    cr_assert_eq(nleaves, 32);
    gsl_integration_glfixed_table_free(t);
    *err = sqrt(e2);
    *best_const = sqrt(bc2);
    *best_lin = sqrt(bl2);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

Test(hier, linear_basis_on_triangles_against_closed_form, .init = hsetup)
{
    /* measured: 0.8% above the best linear (the quads above: 0.2%; the
     * receiver rule on a triangle is exact for quadratics, on a quad for
     * cubics), 0.13 of the constant basis's error */
    expect_linear_near_best("plate of two triangles under a lamp, 32 leaves", linear_triangle_errors, 1.02);
}

/* --open-fraction against the closed form (hier_open.c).  The plate and
 * lamp of the linear-basis tests (unit squares, lamp Le 3 at height 0.4,
 * plate rho 1/2), with a black tile 1e-3 thick lying across the plate over
 * 0.375 <= x <= 0.625 (a box without light of its own: it only encloses
 * the plate under it).  Refined to 4 x 4 leaves, the columns 0.25..0.5
 * and 0.5..0.75 are each half under the tile.  One bounce is the whole
 * answer: on the open part B(x) = rho pi Le F(x), F the point-to-rectangle
 * form factor (Howell's B-3; the tile's 1e-3 sides shade the plate by
 * well under 0.1%), and the value of a half-enclosed leaf must be the mean
 * of B over its open half (8 x 8-point Gauss-Legendre, GSL).  Its
 * visibility is sampled (256 rays from an emitter since stop 46, 16
 * before; half of them blocked), so the test
 * takes the mean signed error over the 8 half-enclosed leaves and holds it
 * within 3 standard errors (from their spread) plus 0.5%, the open
 * leaves' own error (measured: mean +0.6%, spread 0.5%, open leaves
 * 0.55%; before stop 46 gave an emitter's links more rays, -0.8%, 2.0%).
 * Without it (--open-fraction off) a half-enclosed leaf shows the mean
 * over its whole area, half of that (measured: 50% low).  The plate's
 * surface average counts the enclosed part as dark either way.  The
 * Gouraud vertex where an open and a half-enclosed column meet is a point
 * value in the open, within 0.5% of the closed form (measured: 0.01%; 25%
 * bright when the vertex gather subtracted the links' undivided F). */
static void tile_errors(const char *open, const char *basis, double *worst_open, double *mean, double *sd,
                        double *avg_err, double *vertex_err)
{
    const double c = 0.4, rho = 0.5, Le = 3, x0 = 0.375, x1 = 0.625;
    rp_scene *scene = rp_test_parse("bands grey\nmaterial floor reflect 0.5\nmaterial lamp reflect 0 emit 3\n"
                                    "material black reflect 0\n"
                                    "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "box tile black  0.375 -0.1 0  0.625 1.1 0.001  outward\n"
                                    "quad emitter lamp  0 0 0.4  0 1 0.4  1 1 0.4  1 0 0.4\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0", "min-area", "0.02", "open-fraction", open, "basis", basis, NULL};
    hier_vertices *hv = solve_vertices(&r, scene, kv);
    double half[8], total = 0;
    int nh = 0;
    *worst_open = 0;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            /* the leaf's open part: [a, b] x [j / 4, (j + 1) / 4] */
            double a = i / 4.0, b = (i + 1) / 4.0;
            if (i == 1)
                b = x0;
            if (i == 2)
                a = x1;
            double m = rho * RP_PI * Le * rp_cf_point_rect_mean(a, b, j / 4.0, (j + 1) / 4.0, 1, 1, c);
            total += m * (b - a) * 0.25;
            double got;
            rp_hierarchical_radiosity_at(r.state, 0, rp_v3(0.5 * (a + b), (j + 0.5) / 4, 0), &got);
            if (i == 1 || i == 2)
                half[nh++] = got / m - 1;
            else
                *worst_open = fmax(*worst_open, fabs(got / m - 1));
        }
    *mean = gsl_stats_mean(half, 1, 8);
    *sd = gsl_stats_sd(half, 1, 8);
    double L[3];
    rp_estimate est = {.surface_radiance = L};
    rp_error err = {""};
    cr_assert_eq(r.type->estimate(r.state, &est, &err), RP_OK, "%s", err.message);
    *avg_err = fabs(L[0] / (total / RP_PI) - 1); /* the plate's area is 1 */
    /* The Gouraud vertex where an open and a half-enclosed column meet:
     * every leaf around it is evaluated a thousandth of the way towards its
     * centre, all in the open, where the radiosity is the closed form's. */
    double Bv, want = rho * RP_PI * Le * rp_cf_point_rect(0.25, 0.5, 1, 1, c);
    hier_vertices_eval(r.state, hv, 0, rp_v3(0.25, 0.5, 0), &Bv);
    *vertex_err = fabs(Bv / want - 1);
    hier_vertices_destroy(hv);
    cr_log_info("--open-fraction %s --basis %s: open leaves %.4f at worst; half-enclosed mean %+.4f, spread %.4f; "
                "plate average %.4f; vertex %.4f",
                open, basis, *worst_open, *mean, *sd, *avg_err, *vertex_err);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* The radiosity of the penumbra plate below (x, y on the unit plate):
 * rho pi Le F to the part of the lamp [0.4, 0.6]^2 at height 4 that the
 * shield leaves visible, lx < 1 - x (Howell's B-3 by superposition; the
 * corner form is odd in its sides, so the point may lie outside). */
static double penumbra_B(double x, double y)
{
    const double rho = 0.5, Le = 3, c = 4, l0 = 0.4, l1 = 0.6;
    const double hi = fmin(l1, 1 - x);
    if (hi <= l0)
        return 0;
    return rho * RP_PI * Le * rp_cf_point_rect(x - l0, y - l0, hi - l0, l1 - l0, c);
}

/* penumbra_B's mean over [x0, x1] x [y0, y1], by 8 x 8-point
 * Gauss-Legendre (GSL) on each piece between its kinks at x = 0.4, 0.6. */
static double penumbra_mean(double x0, double x1, double y0, double y1)
{
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(8);
    cr_assert(t);
    const double cuts[] = {x0, fmin(fmax(0.4, x0), x1), fmin(fmax(0.6, x0), x1), x1};
    double sum = 0;
    for (int k = 0; k < 3; k++)
        for (size_t i = 0; cuts[k + 1] > cuts[k] && i < t->n; i++)
            for (size_t j = 0; j < t->n; j++) {
                double x, wx, y, wy;
                gsl_integration_glfixed_point(cuts[k], cuts[k + 1], i, &x, &wx, t);
                gsl_integration_glfixed_point(y0, y1, j, &y, &wy, t);
                sum += wx * wy * penumbra_B(x, y);
            }
    gsl_integration_glfixed_table_free(t);
    return sum / ((x1 - x0) * (y1 - y0));
}

/* A far emitter seen in part (issue 16's square light over an occluder's
 * edge): the lamp 0.2 x 0.2 (Le 3) at height 4 over the unit plate (rho
 * 1/2), a black shield at height 2 over x >= 0.5.  The segment from plate
 * point (x, y) to lamp point (lx, ly) crosses z = 2 at (x + lx) / 2, so the
 * plate sees the lamp's part lx < 1 - x: umbra beyond x = 0.6, penumbra
 * from 0.4, and one bounce is the whole answer (penumbra_B).  Refined to
 * 16 x 16 leaves (bf-epsilon 0), the lamp, 20 of its sizes away, must stay
 * one element (hier_link.c decide: a partly visible emitter is split only
 * where the kernel varies across it; before stop 46 it went down to
 * --min-area with the leaves), so the penumbra leaves' values come from
 * their links' own rays: their mean signed error against the leaf means
 * must be within 3 standard errors (from their spread) plus 0.5%, their
 * sum within 0.5%, every other leaf within 0.5%, and the plate's average
 * within 0.5% (measured: -0.72%, spread 8.9%; the sum +0.32%; the
 * others 0.01%; the average +0.09%.  With the lamp split, 21 nodes:
 * spread 6.7%, the sum -0.09%, the average -0.02%). */
Test(hier, far_emitter_penumbra_against_closed_form, .init = hsetup)
{
    rp_scene *scene = rp_test_parse("bands grey\nmaterial floor reflect 0.5\nmaterial lamp reflect 0 emit 3\n"
                                    "material black reflect 0\n"
                                    "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad shield black  0.5 -1 2  0.5 2 2  2 2 2  2 -1 2\n"
                                    "quad emitter lamp  0.4 0.4 4  0.4 0.6 4  0.6 0.6 4  0.6 0.4 4\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0", "min-area", "0.001", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    const hier_state *s = r.state;
    size_t lamp_nodes = 0;
    for (size_t i = 0; i < s->nnodes; i++)
        lamp_nodes += s->nodes[i].face == 2;
    cr_expect_eq(lamp_nodes, 1, "the far lamp was split into %zu nodes", lamp_nodes);
    const int n = 16;
    double pen[4 * 16], worst = 0, total = 0, pen_got = 0, pen_want = 0;
    int np = 0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            const double x0 = (double)i / n, x1 = (double)(i + 1) / n, y0 = (double)j / n, y1 = (double)(j + 1) / n;
            const double m = penumbra_mean(x0, x1, y0, y1);
            total += m / (n * n);
            double got;
            rp_hierarchical_radiosity_at(s, 0, rp_v3(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0), &got);
            if (x1 > 0.4 && x0 < 0.6) {
                pen[np++] = got / m - 1;
                pen_got += got;
                pen_want += m;
            } else
                worst = fmax(worst, m > 0 ? fabs(got / m - 1) : fabs(got));
        }
    cr_assert_eq(np, 4 * n);
    const double mean = gsl_stats_mean(pen, 1, (size_t)np), sd = gsl_stats_sd(pen, 1, (size_t)np);
    double L[3]; /* receiver, shield, lamp; one band */
    cr_assert_eq(rp_scene_nsurfaces(scene) * rp_scene_nbands(scene), 3);
    rp_estimate est = {.surface_radiance = L};
    rp_error err = {""};
    cr_assert_eq(r.type->estimate(r.state, &est, &err), RP_OK, "%s", err.message);
    const double avg = L[0] / (total / RP_PI) - 1; /* the plate's area is 1 */
    cr_log_info("far lamp: penumbra leaves %+.4f (spread %.4f), their sum %+.4f; other leaves %.4f at worst; "
                "plate average %+.4f",
                mean, sd, pen_got / pen_want - 1, worst, avg);
    cr_expect(fabs(mean) < 3 * sd / sqrt((double)np) + 0.005,
              "penumbra leaves %+.4f off their means (3 standard errors %.4f)", mean, 3 * sd / sqrt((double)np));
    cr_expect(fabs(pen_got / pen_want - 1) < 0.005, "penumbra leaves' sum %+.4f off", pen_got / pen_want - 1);
    cr_expect(worst < 0.005, "lit and umbra leaves %.4f off", worst);
    cr_expect(fabs(avg) < 0.005, "plate average %+.4f off", avg);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* The tile's checks for one basis: with --open-fraction the half-enclosed
 * leaves within 3 standard errors (from their spread) plus 0.5% of their
 * open part's mean, the open leaves within 1%, the plate's average and
 * the Gouraud vertex within the bounds given; without it the half-enclosed
 * leaves at about half (below -40%), the average as bounded. */
static void expect_tile(const char *basis, double avg_bound, double vertex_bound)
{
    double wo, mean, sd, avg, vx;
    tile_errors("on", basis, &wo, &mean, &sd, &avg, &vx);
    cr_expect(fabs(mean) < 3 * sd / sqrt(8.0) + 0.005,
              "--basis %s: half-enclosed leaves %+.4f off their open part's mean (3 standard errors %.4f)", basis,
              mean, 3 * sd / sqrt(8.0));
    cr_expect(sd < 0.05, "--basis %s: half-enclosed leaves spread %.4f", basis, sd);
    cr_expect(wo < 0.01, "--basis %s: open leaves %.4f off", basis, wo);
    cr_expect(vx < vertex_bound, "--basis %s: Gouraud vertex %.4f off", basis, vx);
    tile_errors("off", basis, &wo, &mean, &sd, &avg, &vx);
    cr_expect(mean < -0.4, "--basis %s --open-fraction off: half-enclosed leaves only %+.4f off", basis, mean);
    /* The plate's average carries the noise of the half-enclosed leaves'
     * rays (the constant basis, seeds 7 to 15: +0.35 to +0.54%, mean
     * +0.44%, the open leaves' midpoint rule; -0.0 to +0.8% before stop
     * 46 gave an emitter's links more rays), so it is judged by its mean
     * over four seeds (+0.47%), with and without the open fractions. */
    const uint64_t seed0 = hrun_seed;
    for (int off = 0; off < 2; off++) {
        double avg_mean = 0;
        for (uint64_t k = 0; k < 4; k++) {
            hrun_seed = seed0 + k;
            tile_errors(off ? "off" : "on", basis, &wo, &mean, &sd, &avg, &vx);
            avg_mean += avg / 4;
        }
        cr_expect(avg_mean < avg_bound, "--basis %s --open-fraction %s: plate average %.4f off (mean of four seeds)",
                  basis, off ? "off" : "on", avg_mean);
    }
    hrun_seed = seed0;
}

Test(hier, open_fraction_of_a_plate_under_a_tile_against_closed_form, .init = hsetup)
{
    expect_tile("constant", 0.005, 0.005);
}

/* The same with --basis linear, whose half-enclosed leaves gather the
 * coupling of the whole leaf with visibility taken as uniform over it
 * (hier_linear.c): divided by the open fraction, the leaf's function is
 * that of its open part, so at the open part's centre it must match the
 * closed form's mean there as the constant basis does (measured: mean
 * -0.7%, spread 1.9%; the open leaves 0.05%; the plate's average 0.54%
 * off with and without the division, held under 1%).  Without the
 * division it showed half of it (-50%), which put the Cornell box's sides
 * standing on the floor 1.2 to 1.9% dark.  The Gouraud vertex is the mean
 * of the leaves' linear functions at the corner, not a point gather:
 * measured 4.3% off (22% without the division), held under 10%. */
Test(hier, open_fraction_linear_basis_tile_against_closed_form, .init = hsetup)
{
    expect_tile("linear", 0.01, 0.1);
}

/* An overhang is not an enclosure: a one-sided black shelf 0.05 above the
 * plate over 0.375 <= x <= 0.625 (facing up, so the plate under it sees
 * its back).  Every point under it sees past its edges at grazing angles,
 * so every node of the plate must be measured fully open (the ring 1.4
 * radians off the normal: with the 1-radian ring alone the points within
 * 0.05 of the shelf's middle line came out enclosed). */
Test(hier, open_fraction_an_overhang_is_open, .init = hsetup)
{
    rp_scene *scene = rp_test_parse("bands grey\nmaterial floor reflect 0.5\nmaterial lamp reflect 0 emit 3\n"
                                    "material black reflect 0\n"
                                    "quad receiver floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad shelf black  0.375 -0.1 0.05  0.625 -0.1 0.05  "
                                    "0.625 1.1 0.05  0.375 1.1 0.05\n"
                                    "quad emitter lamp  0 0 0.4  0 1 0.4  1 1 0.4  1 0 0.4\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0", "min-area", "0.005", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    const hier_state *s = r.state;
    cr_assert(s->open_on, "--open-fraction applies to this open scene");
    size_t n = 0;
    for (size_t i = 0; i < s->nnodes; i++)
        if (s->nodes[i].face == 0) {
            cr_expect_eq(hier_open_fraction(s, (uint32_t)i), 1.0, "plate node %zu: open fraction %g", i,
                         hier_open_fraction(s, (uint32_t)i));
            n++;
        }
    cr_expect_gt(n, 64, "%zu plate nodes", n);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* --basis linear through a reflecting source: a lamp (0.5 x 0.5, Le 3,
 * facing down at height 1, off-centre) lights a floor A (unit square,
 * rho 1/2), whose light falls off across it; a wall W above the lamp's
 * plane (x = 1.3, z from 1.05 to 2.05, facing -x, rho 0.01, so that what
 * it sends back changes A by under 1e-3) sees the lamp's black back and
 * gathers A's light alone:
 *
 *     B_W(x) = rho_W int_A G(x, y) B_A(y) dy,   B_A(y) = rho_A pi Le F_lamp(y),
 *
 * F_lamp by Howell's B-3 with signs, the integral over A by 4 x 4
 * cells of 6 x 6-point Gauss-Legendre (GSL).  (No segment from A to W
 * passes the lamp: they cross its plane at x > 0.63.)  Everything refined
 * to 4 x 4 leaves: W's error under the linear basis must be within 0.5%
 * of the best linear one (measured: 0.03%), which needs A's linear
 * functions, the source side of the coupling, carried right: with the
 * midpoint rule over A's quarters uncorrected (3/4 of each source slope,
 * hier_linear.c) it was 1.3% above the best, and with the constant
 * basis's estimate of the links' F (biased high on these leaves) 67%. */
/* The form factor from point (x, y) of the plane z = 0 (normal +z) to the
 * parallel rectangle [x0, x1] x [y0, y1] at height h, wherever the point's
 * projection falls: Howell's B-3 corner rectangles with signs. */
static double point_rect_anywhere(double x, double y, double x0, double x1, double y0, double y1, double h)
{
    double u[2] = {x0 - x, x1 - x}, v[2] = {y0 - y, y1 - y}, F = 0;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            double su = u[i] < 0 ? -1 : 1, sv = v[j] < 0 ? -1 : 1;
            double c = fabs(u[i]) > 0 && fabs(v[j]) > 0 ? rp_cf_corner_rect(fabs(u[i]), fabs(v[j]), h) : 0;
            F += (i == j ? 1 : -1) * su * sv * c;
        }
    return F;
}

static double wall_exact(double y, double z)
{
    const double rhoA = 0.5, rhoW = 0.01, Le = 3, lx0 = 0, lx1 = 0.5, ly0 = 0.25, ly1 = 0.75, h = 1;
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(6);
    double sum = 0;
    for (int ci = 0; ci < 4; ci++)
        for (int cj = 0; cj < 4; cj++)
            for (size_t i = 0; i < t->n; i++)
                for (size_t j = 0; j < t->n; j++) {
                    double ux, wx, uy, wy;
                    gsl_integration_glfixed_point(ci / 4.0, (ci + 1) / 4.0, i, &ux, &wx, t);
                    gsl_integration_glfixed_point(cj / 4.0, (cj + 1) / 4.0, j, &uy, &wy, t);
                    /* B_A at (ux, uy), the lamp [0, 0.5] x [0.25, 0.75] */
                    double F = point_rect_anywhere(ux, uy, lx0, lx1, ly0, ly1, h);
                    double BA = rhoA * RP_PI * Le * F;
                    double dx = 1.3 - ux, dy = y - uy, dz = z, r2 = dx * dx + dy * dy + dz * dz;
                    double G = (dz * dx) / (RP_PI * r2 * r2); /* cos_A = dz / r, cos_W = dx / r */
                    sum += wx * wy * G * BA;
                }
    gsl_integration_glfixed_table_free(t);
    return rhoW * sum;
}

static void linear_wall_errors(const char *basis, double *err, double *best_lin)
{
    rp_scene *scene = rp_test_parse("bands grey\nmaterial floor reflect 0.5\nmaterial wall reflect 0.01\n"
                                    "material lamp reflect 0 emit 3\n"
                                    "quad floor floor  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad wall wall  1.3 0 1.05  1.3 0 2.05  1.3 1 2.05  1.3 1 1.05\n"
                                    "quad lamp lamp  0 0.25 1  0 0.75 1  0.5 0.75 1  0.5 0.25 1\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0", "min-area", "0.02", "basis", basis, NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    cr_assert_eq(rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0), 33, "4 x 4 leaves on the floor and the wall");
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(4);
    double e2 = 0, bl2 = 0;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            const double y0 = i / 4.0, z0 = 1.05 + j / 4.0, hh = 0.25;
            double m = 0, m2 = 0, cu = 0, cv = 0, se = 0;
            for (size_t a = 0; a < t->n; a++)
                for (size_t b = 0; b < t->n; b++) {
                    double y, wy, z, wz;
                    gsl_integration_glfixed_point(y0, y0 + hh, a, &y, &wy, t);
                    gsl_integration_glfixed_point(z0, z0 + hh, b, &z, &wz, t);
                    double w = wy * wz / (hh * hh), B = wall_exact(y, z), got;
                    rp_hierarchical_radiosity_at(r.state, 1, rp_v3(1.3, y, z), &got);
                    m += w * B;
                    m2 += w * B * B;
                    cu += w * B * sqrt(3.0) * (2 * (y - y0) / hh - 1);
                    cv += w * B * sqrt(3.0) * (2 * (z - z0) / hh - 1);
                    se += w * (got - B) * (got - B);
                }
            e2 += se / 16;
            bl2 += (m2 - m * m - cu * cu - cv * cv) / 16;
        }
    gsl_integration_glfixed_table_free(t);
    *err = sqrt(e2);
    *best_lin = sqrt(fmax(bl2, 0));
    hrun_end(&r);
    rp_scene_destroy(scene);
}

Test(hier, linear_basis_reflecting_source, .init = hsetup, .timeout = 120)
{
    double ec, el, bl;
    linear_wall_errors("constant", &ec, &bl);
    linear_wall_errors("linear", &el, &bl);
    cr_log_info("wall lit by a floor under a lamp, 4 x 4 leaves, RMS error of B: constant basis %.4g, linear basis "
                "%.4g (best linear %.4g)",
                ec, el, bl);
    cr_assert_lt(el, 1.005 * bl, "linear: %.4g against the best linear %.4g", el, bl);
    cr_assert_lt(el, 0.2 * ec, "linear %.4g, constant %.4g", el, ec); /* measured 0.065 */
}

/* The linear basis of a node (hier_basis_of) is orthonormal with the
 * constant over the node's area: on a right triangle, a sliver and a
 * trapezoid (not a parallelogram), the means of phi_k and of phi_j phi_k,
 * by the centroid rule over 4^6 sub-triangles of each fan triangle,
 * are 0 and delta_jk to 1e-3. */
static void moments_over(const rp_vec3 a, const rp_vec3 b, const rp_vec3 c, int depth, const hier_basis *B,
                         double *acc)
{
    if (depth == 0) {
        double ar = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
        rp_vec3 m = rp_v3_scale(rp_v3_add(rp_v3_add(a, b), c), 1.0 / 3.0);
        double f0 = rp_v3_dot(B->g[0], rp_v3_sub(m, B->c)), f1 = rp_v3_dot(B->g[1], rp_v3_sub(m, B->c));
        acc[0] += ar;
        acc[1] += ar * f0;
        acc[2] += ar * f1;
        acc[3] += ar * f0 * f0;
        acc[4] += ar * f0 * f1;
        acc[5] += ar * f1 * f1;
        return;
    }
    rp_vec3 ab = rp_v3_scale(rp_v3_add(a, b), 0.5), bc = rp_v3_scale(rp_v3_add(b, c), 0.5),
            ca = rp_v3_scale(rp_v3_add(c, a), 0.5);
    moments_over(a, ab, ca, depth - 1, B, acc);
    moments_over(ab, b, bc, depth - 1, B, acc);
    moments_over(ca, bc, c, depth - 1, B, acc);
    moments_over(bc, ca, ab, depth - 1, B, acc);
}

Test(hier, linear_basis_is_orthonormal, .init = hsetup)
{
    const rp_vec3 shapes[3][4] = {{{0, 0, 0}, {2, 0, 0}, {0, 1, 0}, {0, 1, 0}},
                                  {{0, 0, 0}, {10, 0, 0}, {10, 0.05, 0}, {10, 0.05, 0}},
                                  {{0, 0, 0}, {3, 0, 0}, {2, 1, 0}, {0.5, 1, 0}}};
    const int nv[3] = {3, 3, 4};
    for (int k = 0; k < 3; k++) {
        hier_node nd;
        memset(&nd, 0, sizeof nd);
        memcpy(nd.v, shapes[k], sizeof nd.v);
        nd.nverts = (uint16_t)nv[k];
        /* the area, as hier_tree.c measures it (the centroid, hier_node_c,
         * follows from it and the corners) */
        double at = 0;
        for (int t = 1; t + 1 < nv[k]; t++)
            at += 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(nd.v[t], nd.v[0]), rp_v3_sub(nd.v[t + 1], nd.v[0])));
        nd.area = at;
        hier_basis B;
        hier_basis_of(&nd, rp_v3(0, 0, 1), &B);
        double acc[6] = {0};
        for (int t = 1; t + 1 < nv[k]; t++)
            moments_over(nd.v[0], nd.v[t], nd.v[t + 1], 6, &B, acc);
        double want[5] = {0, 0, 1, 0, 1};
        for (int m = 0; m < 5; m++)
            cr_assert_float_eq(acc[m + 1] / acc[0], want[m], 1e-3, "shape %d, moment %d: %.6g", k, m,
                               acc[m + 1] / acc[0]);
    }
}

/* The linear basis's bookkeeping on the Cornell box (bf-epsilon 0.05,
 * links at every level, the coefficient pool compacted as links are
 * replaced): every stored link has a slot of its own inside the pool,
 * which holds at most a quarter more slots than links (plus 1024); at
 * every corner of every child, its parent's linear functions equal the
 * two-scale relation's a + A phi_child (hier_linear_relation, which push,
 * pull and the row sums use); and every parent's mean and slopes are
 * the projection of its children's linear functions on its own (the pull),
 * by the centroid rule over 4^5 sub-triangles of each child (3e-4 of the
 * mean measured, the rule's own error: 1.3e-3 with 4^4). */
Test(hier, linear_basis_two_scale_and_pool, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0.05", "basis", "linear", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    const hier_state *s = r.state;
    const size_t nb = s->nb;
    unsigned char *used = calloc(s->nlin_K ? s->nlin_K : 1, 1);
    cr_assert(used);
    for (size_t k = 0; k < s->nlinks; k++) {
        const hier_link *l = &s->links[k];
        cr_assert(l->flags & HIER_LINK_COEF, "link %zu has no coefficients", k);
        uint32_t slot = hier_link_slot(l);
        cr_assert_lt(slot, s->nlin_K, "link %zu: slot %u of %zu", k, slot, s->nlin_K);
        cr_assert_eq(used[slot], 0, "slot %u shared", slot);
        used[slot] = 1;
    }
    free(used);
    cr_log_info("Cornell box, --basis linear, bf-epsilon 0.05: %zu links in a pool of %zu slots (%.0f links made)",
                s->nlinks, s->nlin_K, s->form_factors);
    /* dead slots are kept below a fifth of the pool (hier_linear_links) */
    cr_assert_leq((double)s->nlin_K, 1.25 * (double)s->nlinks + 1024, "the pool holds %zu slots", s->nlin_K);
    double worst_rel = 0, worst_pull = 0;
    size_t parents = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *p = &s->nodes[i];
        if (p->child == RP_NONE)
            continue;
        const hier_basis *bp = &s->basis[i];
        /* pull check: only where every child is reached (area weights) */
        int all = 1;
        double m[HIER_MAX_BANDS][3];
        memset(m, 0, sizeof m);
        for (uint32_t c = p->child; c < p->child + 4; c++) {
            const hier_basis *bc = &s->basis[c];
            double a[2], A[2][2];
            hier_linear_relation(s, (uint32_t)i, c, a, A);
            const hier_node *cn = &s->nodes[c];
            for (int v = 0; v < cn->nverts; v++) {
                rp_vec3 x = cn->v[v];
                double fc[2] = {rp_v3_dot(bc->g[0], rp_v3_sub(x, bc->c)), rp_v3_dot(bc->g[1], rp_v3_sub(x, bc->c))};
                for (int k = 0; k < 2; k++) {
                    double fp = rp_v3_dot(bp->g[k], rp_v3_sub(x, bp->c));
                    worst_rel = fmax(worst_rel, fabs(fp - (a[k] + A[k][0] * fc[0] + A[k][1] * fc[1])));
                }
            }
            all &= fabs(s->W[c] - cn->area) <= 1e-9 * cn->area; /* every leaf below reached: area weights */
            /* E_p[psi_j B] over child c by the centroid rule */
            for (int t = 1; t + 1 < cn->nverts; t++) {
                rp_vec3 tri[3] = {cn->v[0], cn->v[t], cn->v[t + 1]};
                /* 4^4 sub-triangles */
                static rp_vec3 stack[1024][3], next[1024][3];
                int n = 1;
                memcpy(stack[0], tri, sizeof tri);
                for (int d = 0; d < 5; d++) {
                    int n2 = 0;

                    for (int q = 0; q < n; q++) {
                        rp_vec3 *T = stack[q];
                        rp_vec3 ab = rp_v3_scale(rp_v3_add(T[0], T[1]), 0.5), bc2 = rp_v3_scale(rp_v3_add(T[1], T[2]), 0.5),
                                ca = rp_v3_scale(rp_v3_add(T[2], T[0]), 0.5);
                        rp_vec3 sub[4][3] = {{T[0], ab, ca}, {ab, T[1], bc2}, {ca, bc2, T[2]}, {bc2, ca, ab}};
                        memcpy(next + n2, sub, sizeof sub);
                        n2 += 4;
                    }
                    memcpy(stack, next, (size_t)n2 * sizeof next[0]);
                    n = n2;
                }
                for (int q = 0; q < n; q++) {
                    rp_vec3 *T = stack[q];
                    double ar = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(T[1], T[0]), rp_v3_sub(T[2], T[0])));
                    rp_vec3 x = rp_v3_scale(rp_v3_add(rp_v3_add(T[0], T[1]), T[2]), 1.0 / 3.0);
                    double Bx[HIER_MAX_BANDS]; /* the child's linear function, unclamped */
                    double f0 = rp_v3_dot(bc->g[0], rp_v3_sub(x, bc->c)), f1 = rp_v3_dot(bc->g[1], rp_v3_sub(x, bc->c));
                    for (size_t b = 0; b < nb; b++)
                        Bx[b] = s->B[c * nb + b] + s->B1[(c * nb + b) * 2] * f0 + s->B1[(c * nb + b) * 2 + 1] * f1;
                    double psi[3] = {1, rp_v3_dot(bp->g[0], rp_v3_sub(x, bp->c)), rp_v3_dot(bp->g[1], rp_v3_sub(x, bp->c))};
                    for (size_t b = 0; b < nb; b++)
                        for (int j = 0; j < 3; j++)
                            m[b][j] += ar * psi[j] * Bx[b] / p->area;
                }
            }
        }
        if (!all)
            continue;
        parents++;
        for (size_t b = 0; b < nb; b++) {
            double scale = fmax(fabs(s->B[i * nb + b]), 1e-12);
            worst_pull = fmax(worst_pull, fabs(m[b][0] - s->B[i * nb + b]) / scale);
            worst_pull = fmax(worst_pull, fabs(m[b][1] - s->B1[(i * nb + b) * 2]) / scale);
            worst_pull = fmax(worst_pull, fabs(m[b][2] - s->B1[(i * nb + b) * 2 + 1]) / scale);
        }
    }
    cr_log_info("two-scale relation: largest error %.3g; pull against quadrature over %zu parents: largest %.3g "
                "(relative to the mean)",
                worst_rel, parents, worst_pull);
    cr_assert_gt(parents, 100);
    cr_assert_lt(worst_rel, 1e-9);
    cr_assert_lt(worst_pull, 1e-3);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* The furnace with --basis linear: every leaf's mean is still
 * Le / (1 - rho) = 2, and the linear functions on it carry nothing (the
 * radiosity is uniform): at every leaf corner |L - 2| is small. */
Test(hier, linear_basis_furnace, .init = hsetup, .timeout = 120)
{
    const char *kv[] = {"bf-epsilon", "0.05", "tolerance", "1e-12", "basis", "linear", NULL};
    furnace_check(kv, 1e-6, 50);
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    hrun r;
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    const hier_state *s = r.state;
    double worst = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE)
            continue;
        for (int k = 0; k < nd->nverts; k++) {
            double B[HIER_MAX_BANDS];
            rp_vec3 x = rp_v3_madd(nd->v[k], rp_v3_sub(hier_node_c(nd), nd->v[k]), 1e-6);
            rp_hierarchical_radiosity_at(s, nd->face, x, B);
            worst = fmax(worst, fabs(B[0] / RP_PI - 2));
        }
    }
    cr_log_info("furnace, --basis linear: largest |L - 2| at a leaf corner %.3g", worst);
    cr_assert_lt(worst, 1e-9); /* measured 9.1e-13 */
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* In the refined furnace every vertex value is Le / (1 - rho) = 2 too: the
 * point form factors are renormalised as the leaves' rows are. */
Test(hier, gouraud_furnace, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0.05", "tolerance", "1e-12", NULL};
    hier_vertices *hv = solve_vertices(&r, scene, kv);
    const hier_state *s = r.state;
    double worst = 0;
    size_t n = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE)
            continue;
        for (int k = 0; k < nd->nverts; k++) {
            /* Just inside the leaf, next to each corner. */
            rp_vec3 x = rp_v3_madd(nd->v[k], rp_v3_sub(hier_node_c(nd), nd->v[k]), 1e-6);
            double B[HIER_MAX_BANDS];
            hier_vertices_eval(s, hv, nd->face, x, B);
            for (size_t b = 0; b < s->nb; b++)
                worst = fmax(worst, fabs(B[b] / RP_PI - 2));
            n++;
        }
    }
    cr_log_info("furnace, bf-epsilon 0.05: %zu leaf corners, largest |L - 2| %.3g", n, worst);
    cr_assert_gt(n, 100);
    cr_assert_lt(worst, 1e-6);
    hier_vertices_destroy(hv);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* Faces of one surface share Gouraud vertices only within 30 degrees of
 * each other.  One mesh surface, never refined: two coplanar triangles and
 * one folded 20 degrees along their shared edge's far side share corners;
 * a fourth folded 90 degrees keeps its own; a lamp above.  Corners: the
 * flat square's 4, one more for the 20-degree flap, and 3 of the upright
 * flap's own, plus the lamp's 4. */
Test(hier, vertices_shared_within_smoothing_groups, .init = hsetup)
{
    char dir[64], path[96];
    snprintf(dir, sizeof dir, "/tmp/rp-smooth-%d", (int)getpid());
    cr_assert_eq(mkdir(dir, 0700), 0);
    snprintf(path, sizeof path, "%s/fold.obj", dir);
    FILE *f = fopen(path, "w");
    cr_assert(f);
    double c = cos(20 * RP_PI / 180), sn = sin(20 * RP_PI / 180);
    fprintf(f, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv %.17g 0.5 %.17g\nv 0 1 1\nv 0 0 1\n", 1 + c, sn);
    /* Flat square (two triangles), the 20-degree flap on edge 2-3... */
    fprintf(f, "f 1 2 3\nf 1 3 4\nf 2 5 3\n");
    /* ...and an upright flap on edge 4-1 (x = 0), facing +x. */
    fprintf(f, "f 1 4 6\nf 1 6 7\n");
    fclose(f);
    rp_scene *scene = rp_test_parse_in("bands grey\n"
                                       "material w reflect 0.5\n"
                                       "material l reflect 0 emit 1\n"
                                       "mesh fold w fold.obj\n"
                                       "quad lamp l  0.2 0.2 2  0.2 0.8 2  0.8 0.8 2  0.8 0.2 2\n",
                                       dir);
    cr_assert(scene);
    hrun r;
    const char *kv[] = {"bf-epsilon", "1e6", NULL};
    hier_vertices *hv = solve_vertices(&r, scene, kv);
    /* Flat square and 20-degree flap: 1 2 3 4 5; upright flap: its own
     * copies of 1 and 4, and 6 7; lamp 4. */
    cr_assert_eq(hier_vertices_count(hv), 5 + 4 + 4, "%zu vertices", hier_vertices_count(hv));
    hier_vertices_destroy(hv);
    hrun_end(&r);
    rp_scene_destroy(scene);
    remove(path);
    rmdir(dir);
}

/* With the constant basis and with the linear one (whose leaves' slopes,
 * kept beside the means, shape the Gouraud image). */
Test(hier, same_answer_for_any_thread_count, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    const rp_camera *cam = rp_scene_camera(scene);
    const size_t nb = rp_scene_nbands(scene), npix = (size_t)cam->width * cam->height;
    static const char *const basis[2] = {"constant", "linear"};
    for (int m = 0; m < 2; m++) {
        float *img[2];
        double *B[2];
        size_t n[2];
        for (int t = 0; t < 2; t++) {
            hrun r;
            const char *kv[] = {"bf-epsilon", "0.1", "spp", "4", "reconstruct", "gouraud", "basis", basis[m], NULL};
            solve_hier(&r, scene, RP_WANT_IMAGE, t + 1, kv);
            n[t] = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
            B[t] = malloc(n[t] * nb * sizeof *B[t]);
            rp_hierarchical_leaves(r.state, NULL, NULL, B[t], n[t]);
            img[t] = malloc(npix * nb * sizeof *img[t]);
            rp_estimate e = {.radiance = img[t]};
            rp_error err = {""};
            cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
            hrun_end(&r);
        }
        cr_assert_eq(n[0], n[1], "%s", basis[m]);
        cr_assert_eq(memcmp(B[0], B[1], n[0] * nb * sizeof *B[0]), 0, "%s: leaf radiosities differ", basis[m]);
        cr_assert_eq(memcmp(img[0], img[1], npix * nb * sizeof *img[0]), 0, "%s: images differ", basis[m]);
        for (int t = 0; t < 2; t++) {
            free(B[t]);
            free(img[t]);
        }
    }
    rp_scene_destroy(scene);
}

/* A refinement pass that splits nothing must leave the links where they
 * are (no copy, no re-sort): after convergence one more pass refines
 * nothing and the link array, its order and the offsets are unchanged. */
Test(hier, idle_refinement_keeps_links, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_load("scenes/cube-ceiling.scene");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0.1", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    hier_state *s = r.state;
    const hier_link *before = s->links;
    size_t n = s->nlinks, nn = s->nnodes;
    hier_link *copy = malloc(n * sizeof *copy);
    uint32_t *start = malloc((nn + 1) * sizeof *start);
    cr_assert(copy && start);
    memcpy(copy, s->links, n * sizeof *copy);
    memcpy(start, s->link_start, (nn + 1) * sizeof *start);
    size_t refined = 99;
    rp_error err = {""};
    cr_assert_eq(hier_refine(s, &refined, &err), RP_OK, "%s", err.message);
    cr_assert_eq(refined, 0);
    cr_assert_eq(s->links, before, "the link array was replaced");
    cr_assert_eq(s->nlinks, n);
    cr_assert_eq(s->nnodes, nn);
    cr_assert_eq(memcmp(copy, s->links, n * sizeof *copy), 0, "links changed");
    /* a link's receiver is the node whose run holds it */
    cr_assert_eq(memcmp(start, s->link_start, (nn + 1) * sizeof *start), 0, "link offsets changed");
    free(copy);
    free(start);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* 1 if face f crosses another face's plane or another face crosses f's. */
static int crosses_a_plane(const hier_state *s, uint32_t f)
{
    for (uint32_t g = 0; g < s->nfaces; g++) {
        if (g == f)
            continue;
        for (int k = 0; k < 2; k++) {
            const hier_node *a = &s->nodes[k ? f : g];
            const hier_face *b = &s->faces[k ? g : f];
            double lo = INFINITY, hi = -INFINITY;
            for (int v = 0; v < a->nverts; v++) {
                double d = rp_v3_dot(b->n, a->v[v]) - b->d;
                lo = fmin(lo, d);
                hi = fmax(hi, d);
            }
            /* the pair's plane tolerance, as hier_link.c judges it */
            double tol = s->faces[f].tol + s->faces[g].tol;
            if (lo < -tol && hi > tol)
                return 1;
        }
    }
    return 0;
}

/* --contact-levels: only pairs in which one element crosses the other's
 * plane (the floor and the sides of the boxes standing on it, the lamp and
 * the planes of the boxes' sides) go below --min-area, by 4 per level, and
 * no further. */
Test(hier, contact_levels, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    const double total = rp_scene_total_area(scene), amin = 1e-4 * total;
    const rp_surface *surf = rp_scene_surfaces(scene);
    for (int levels = 0; levels <= 2; levels++) {
        char lv[8];
        snprintf(lv, sizeof lv, "%d", levels);
        hrun r;
        const char *kv[] = {"bf-epsilon", "0.05", "min-area", "1e-4", "contact-levels", lv, NULL};
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        size_t n = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
        double *area = malloc(n * sizeof *area);
        uint32_t *sf = malloc(n * sizeof *sf);
        cr_assert(area && sf);
        rp_hierarchical_leaves(r.state, area, sf, NULL, n);
        double smallest = INFINITY;
        size_t below = 0;
        for (size_t i = 0; i < n; i++) {
            smallest = fmin(smallest, area[i]);
            if (area[i] < amin * (1 - 1e-9)) {
                below++;
                cr_assert(crosses_a_plane(r.state, surf[sf[i]].first_face), "a leaf of %s below --min-area",
                          surf[sf[i]].name);
            }
        }
        cr_log_info("contact-levels %d: %zu leaves, %zu below min-area, smallest %.3g x min-area", levels, n,
                    below, smallest / amin);
        cr_assert_geq(smallest, ldexp(amin, -2 * levels) * (1 - 1e-9));
        if (levels == 0)
            cr_assert_eq(below, 0);
        else
            cr_assert_lt(smallest, ldexp(amin, -2 * levels + 2) * (1 - 1e-9), "level %d not reached", levels);
        free(area);
        free(sf);
        hrun_end(&r);
    }
    rp_scene_destroy(scene);
}

Test(hier, refuses_bad_options, .init = hsetup)
{
    rp_scene *scene = rp_test_load("scenes/cube-ceiling.scene");
    rp_error err = {""};
    hrun r;
    const char *bad[] = {"reconstruct", "phong", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, bad, &err), RP_ERR_INPUT);
    hrun_end(&r);
    const char *deep[] = {"contact-levels", "9", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, deep, &err), RP_ERR_INPUT);
    hrun_end(&r);
    const char *few[] = {"max-faces", "5", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, few, &err), RP_ERR_UNSUPPORTED);
    cr_assert(strstr(err.message, "6 faces"), "%s", err.message);
    hrun_end(&r);
    const char *rule[] = {"ff-rule", "simpson", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, rule, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "--ff-rule") && strstr(err.message, "simpson"), "%s", err.message);
    hrun_end(&r);
    const char *mesh[] = {"mesh", "uniform", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, mesh, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "--mesh") && strstr(err.message, "uniform"), "%s", err.message);
    hrun_end(&r);
    /* --mesh-segments alone has nothing to act on: a warning, not a refusal
     * (the CLI's text: test_mesh.c, discontinuity::cli_mesh_option) */
    const char *segs[] = {"mesh-segments", "8", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_IMAGE, 0, segs, &err), RP_OK, "%s",
                 err.message);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* --ff-rule: the form factor one unrefined link integrates over its
 * receiver, against Howell's closed forms, for unit squares at a right
 * angle sharing an edge (C-14) and facing each other 1 and 6 apart (C-11;
 * 1 apart is a near pair, 6 a far one, hier_link.c link_eval).  The
 * midpoint rule's errors are those of the kernel at the centre or the
 * quarters' centres (computed apart: -1.0%, +4.0%, +0.91%); the Gauss
 * rule's, -0.73% at 1 apart where the kernel curves most, +0.18% where
 * it is not smooth (the shared edge) and 2e-5 far.  The bounds sit
 * between the two rules' errors, so the test fails if the option stops
 * choosing the rule, and the default stays the midpoint rule. */
Test(hier, ff_rule_against_closed_forms, .init = hsetup)
{
    static const char *const scenes[3] = {
        "quad a m  0 0 0  0 0 1  1 0 1  1 0 0\nquad b m  0 0 0  0 1 0  0 1 1  0 0 1\n",
        "quad a m  0 0 0  0 0 1  1 0 1  1 0 0\nquad b m  0 1 0  1 1 0  1 1 1  0 1 1\n",
        "quad a m  0 0 0  0 0 1  1 0 1  1 0 0\nquad b m  0 6 0  1 6 0  1 6 1  0 6 1\n"};
    const double exact[3] = {rp_cf_howell_perpendicular(1, 1, 1), rp_cf_howell_parallel(1, 1, 1),
                             rp_cf_howell_parallel(1, 1, 6)};
    /* |relative error| of the Gauss rule below gauss_max, the midpoint rule's above mid_min */
    const double gauss_max[3] = {0.003, 0.008, 0.001}, mid_min[3] = {0.008, 0.03, 0.008};
    const char *rules[3] = {NULL, "midpoint", "gauss"};
    for (int c = 0; c < 3; c++)
        for (int k = 0; k < 3; k++) {
            char text[512];
            snprintf(text, sizeof text,
                     "bands grey\nmaterial m reflect 0.5 emit 1\n%scamera eye 0.5 0.5 3  look 0.5 0.5 0  up 0 1 0  "
                     "fov 40  size 8 8\n",
                     scenes[c]);
            rp_scene *scene = rp_test_parse(text);
            const char *kv[] = {"ff-rule", rules[k], NULL};
            hrun r;
            rp_error err = {""};
            cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_SURFACES, 1, k ? kv : NULL, &err), RP_OK,
                         "%s", err.message);
            const hier_state *s = r.state;
            hier_link e;
            double rays = 0;
            cr_assert_eq(hier_link_eval(s, 0, 1, &e, &rays), 1);
            cr_assert_eq(rays, 0, "two squares alone cast no visibility rays");
            const double rel = hier_link_F(&e) / exact[c] - 1;
            cr_log_info("case %d, rule %s: F %.7f, closed form %.7f (%+.3f%%)", c, rules[k] ? rules[k] : "default",
                        hier_link_F(&e), exact[c], 100 * rel);
            if (k == 2)
                cr_expect_lt(fabs(rel), gauss_max[c], "case %d: gauss %+.4f%%", c, 100 * rel);
            else
                cr_expect_gt(fabs(rel), mid_min[c], "case %d: %s %+.4f%%", c, rules[k] ? rules[k] : "default",
                             100 * rel);
            hrun_end(&r);
            rp_scene_destroy(scene);
        }
}

/* --cluster-area auto follows what the run is asked for (hierarchical.c
 * hier_init): 3e-3 of the lit area for surface averages alone, 1e-3 for an
 * image or for both; a number given is kept, and a word that is neither is
 * refused with an error that names auto. */
Test(hier, cluster_area_follows_the_question, .init = hsetup)
{
    rp_scene *scene = rp_test_load("scenes/cube-ceiling.scene");
    static const struct {
        unsigned want;
        const char *value;
        double rel;
    } cases[] = {
        {RP_WANT_SURFACES, NULL, 3e-3},
        {RP_WANT_SURFACES, "auto", 3e-3},
        {RP_WANT_IMAGE, NULL, 1e-3},
        {RP_WANT_IMAGE | RP_WANT_SURFACES, NULL, 1e-3},
        {RP_WANT_SURFACES, "2e-3", 2e-3},
        {RP_WANT_IMAGE, "0", 0},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        rp_error err = {""};
        hrun r;
        const char *kv[] = {"cluster", "on", cases[k].value ? "cluster-area" : NULL, cases[k].value, NULL};
        cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, cases[k].want, 1, kv, &err), RP_OK, "%s",
                     err.message);
        const hier_state *s = r.state;
        cr_assert_eq(s->cl_area_rel, cases[k].rel, "case %zu: %g, not %g", k, s->cl_area_rel, cases[k].rel);
        cr_assert_float_eq(s->cl_area, cases[k].rel * s->lit_area, 1e-15 * s->lit_area, "case %zu", k);
        hrun_end(&r);
    }
    rp_error err = {""};
    hrun r;
    const char *bad[] = {"cluster", "on", "cluster-area", "some", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_SURFACES, 1, bad, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "--cluster-area") && strstr(err.message, "'some'") && strstr(err.message, "auto"),
              "%s", err.message);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* ---- clustering (Smits, Arvo & Greenberg 1994) ------------------------- */

/* The unit box seen from inside with every wall cut into an n x n grid of
 * cells (two triangles each when tris, else one quad), one surface per
 * face, walls in the order floor, ceiling, x0, x1, z0, z1 (n^2 or 2 n^2
 * surfaces each).  Every face of wall w gets material mat[w]; the
 * materials are declared by head. */
static char *grid_box(int n, int tris, const char *head, const char *const mat[6])
{
    /* Origin and two edge axes per wall, a x b pointing into the box. */
    static const double o[6][3] = {{0, 0, 0}, {0, 1, 0}, {0, 0, 0}, {1, 0, 0}, {0, 0, 0}, {0, 0, 1}};
    static const double a[6][3] = {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 0}, {0, 1, 0}};
    static const double b[6][3] = {{1, 0, 0}, {0, 0, 1}, {0, 0, 1}, {0, 1, 0}, {0, 1, 0}, {1, 0, 0}};
    size_t cap = strlen(head) + (size_t)6 * n * n * 2 * 160 + 64, len = 0;
    char *t = malloc(cap);
    cr_assert(t);
    len += (size_t)snprintf(t + len, cap - len, "%s", head);
    for (int w = 0; w < 6; w++)
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double p[4][3];
                static const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
                for (int k = 0; k < 4; k++)
                    for (int c = 0; c < 3; c++)
                        p[k][c] = o[w][c] + a[w][c] * (double)(i + di[k]) / n + b[w][c] * (double)(j + dj[k]) / n;
#define P(k) p[k][0], p[k][1], p[k][2]
                if (tris) {
                    len += (size_t)snprintf(t + len, cap - len, "triangle w%d-%d-%d-a %s %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
                                            w, i, j, mat[w], P(0), P(1), P(2));
                    len += (size_t)snprintf(t + len, cap - len, "triangle w%d-%d-%d-b %s %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
                                            w, i, j, mat[w], P(0), P(2), P(3));
                } else
                    len += (size_t)snprintf(t + len, cap - len,
                                            "quad w%d-%d-%d %s %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
                                            w, i, j, mat[w], P(0), P(1), P(2), P(3));
#undef P
                cr_assert(len < cap);
            }
    return t;
}

/* The furnace (rho 0.5, Le 1, exact L = 2 everywhere) as 3072 triangles,
 * solved with clustering.  The box is an enclosure, so each leaf's
 * gathered radiosity is divided by the form factors reaching it through
 * its own links, its ancestors' and its clusters' (row-sum normalisation):
 * gathering is then rho times a weighted mean of the sources' radiosities
 * with weights summing to 1 however rough the isotropic cluster estimates
 * are, and a uniform answer is a fixed point.  What is left is the
 * Jacobi iteration's: the sweeps stop when the energy changes by less
 * than --tolerance 1e-9 of the emitted power, and each sweep shrinks the
 * error by rho = 1/2, so the distance to the fixed point is below
 * 1e-9 x rho / (1 - rho) relative (on the worst leaf at most the area
 * ratio more, total area over smallest leaf, 6 / (1/512 / 6)): 1e-6 x 2
 * holds with a wide margin.  The initial linking must also stay far below
 * the faces^2 = 9.4e6 pairs of the method without clustering. */
Test(hier, cluster_furnace, .init = hsetup, .timeout = 120)
{
    static const char *const mat[6] = {"hot", "hot", "hot", "hot", "hot", "hot"};
    char *text = grid_box(16, 1, "bands grey\nmaterial hot reflect 0.5 emit 1\n", mat);
    rp_scene *scene = rp_test_parse(text);
    free(text);
    const size_t nf = rp_scene_nfaces(scene);
    cr_assert_eq(nf, 3072);
    hrun r;
    const char *kv[] = {"cluster", "on", "tolerance", "1e-9", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    cr_assert_eq(rp_hierarchical_enclosure(r.state), 1);
    rp_hier_stats st;
    rp_hierarchical_stats(r.state, &st);
    size_t n = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
    double *B = malloc(n * sizeof *B);
    rp_hierarchical_leaves(r.state, NULL, NULL, B, n);
    double worst = 0;
    for (size_t i = 0; i < n; i++)
        worst = fmax(worst, fabs(B[i] / RP_PI - 2.0));
    cr_log_info("cluster furnace: %zu faces, %zu clusters, %zu initial links (%.3g%% of faces^2), %zu links + %zu "
                "cluster links at the end, %zu leaves; worst |L - 2| = %.3g",
                nf, st.clusters, st.initial_links, 100.0 * st.initial_links / ((double)nf * nf), st.links,
                st.cluster_links, n, worst);
    cr_assert_eq(st.clusters, nf - 1);
    cr_assert_gt(st.cluster_links, 0);
    cr_assert_lt((double)st.initial_links, 0.05 * (double)nf * (double)nf, "%zu initial links", st.initial_links);
    cr_assert_leq(worst, 2e-6, "worst leaf off by %.3g", worst);
    free(B);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* cube-ceiling with every wall cut into 6 x 6 quads (216 faces): per-wall
 * area means with clustering on, off, and from the path tracer (8192
 * probe points per face, 294912 per wall).  Clustering changes only how
 * far pairs of faces exchange energy (the isotropic cluster estimate,
 * whose error the oracle bounds by bf_epsilon per link), so on and off
 * must agree within 1%, and each must be within 2% + 3 standard errors of
 * the path tracer (the unclustered method's own error against it on the
 * undivided scene is under 1%, cube_against_pathtrace; 2% leaves room for
 * the cluster links' 16-ray estimates). */
Test(hier, cluster_on_off_pathtrace, .init = hsetup, .timeout = 300)
{
    static const char *const mat[6] = {"wall", "lamp", "wall", "wall", "wall", "wall"};
    char *text = grid_box(6, 0, "bands grey\nmaterial lamp reflect 0.5 emit 1\nmaterial wall reflect 0.5\n", mat);
    rp_scene *scene = rp_test_parse(text);
    free(text);
    const size_t ns = rp_scene_nsurfaces(scene);
    cr_assert_eq(ns, 216);
    const rp_surface *surf = rp_scene_surfaces(scene);
    double *v[3], *se = calloc(ns, sizeof *se);
    rp_hier_stats st[2];
    for (int m = 0; m < 3; m++) {
        v[m] = calloc(ns, sizeof *v[m]);
        hrun r;
        rp_error err = {""};
        if (m < 2) {
            const char *kv[] = {"cluster", m == 0 ? "off" : "on", NULL};
            solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
            rp_hierarchical_stats(r.state, &st[m]);
        } else {
            const char *kv[] = {"samples", "8192", "batch", "4096", NULL};
            cr_assert_eq(hrun_start(&r, &rp_solver_pathtrace, scene, RP_WANT_SURFACES, 0, kv, &err), RP_OK, "%s",
                         err.message);
            hrun_solve(&r);
        }
        rp_estimate e = {.surface_radiance = v[m], .surface_stderr = m == 2 ? se : NULL};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
    }
    cr_assert_eq(st[0].clusters, 0);
    cr_assert_eq(st[1].clusters, 215);
    cr_log_info("subdivided cube: off %zu initial links, %zu links; on %zu initial (%zu face + cluster), %zu links + "
                "%zu cluster links",
                st[0].initial_links, st[0].links, st[1].initial_links, st[1].initial_links, st[1].links,
                st[1].cluster_links);
    static const char *names[6] = {"floor", "ceiling", "wall-x0", "wall-x1", "wall-z0", "wall-z1"};
    for (int w = 0; w < 6; w++) {
        double a = 0, m[3] = {0, 0, 0}, var = 0;
        for (size_t s = (size_t)w * 36; s < (size_t)(w + 1) * 36; s++) {
            a += surf[s].area;
            for (int k = 0; k < 3; k++)
                m[k] += surf[s].area * v[k][s];
            var += surf[s].area * surf[s].area * se[s] * se[s];
        }
        for (int k = 0; k < 3; k++)
            m[k] /= a;
        double sew = sqrt(var) / a;
        cr_log_info("%-8s off %.6f  on %.6f (%+.3f%%)  pathtrace %.6f +- %.6f (off %+.3f%%, on %+.3f%%)", names[w], m[0],
                    m[1], 100 * (m[1] - m[0]) / m[0], m[2], sew, 100 * (m[0] - m[2]) / m[2],
                    100 * (m[1] - m[2]) / m[2]);
        cr_expect_leq(fabs(m[1] - m[0]), 0.01 * m[0], "%s: on %.6f off %.6f", names[w], m[1], m[0]);
        for (int k = 0; k < 2; k++)
            cr_expect_leq(fabs(m[k] - m[2]), 0.02 * m[2] + 3 * sew, "%s: %.6f vs pathtrace %.6f +- %.6f", names[w],
                          m[k], m[2], sew);
    }
    for (int m = 0; m < 3; m++)
        free(v[m]);
    free(se);
    rp_scene_destroy(scene);
}

/* Clustering keeps the answer independent of the thread count. */
Test(hier, cluster_same_answer_for_any_thread_count, .init = hsetup, .timeout = 120)
{
    static const char *const mat[6] = {"wall", "lamp", "wall", "wall", "wall", "wall"};
    char *text = grid_box(6, 1, "bands grey\nmaterial lamp reflect 0.5 emit 1\nmaterial wall reflect 0.5\n", mat);
    rp_scene *scene = rp_test_parse(text);
    free(text);
    /* without importance and with it (the importance sweeps and the
     * cluster oracle's importance) */
    static const char *const imp[2] = {"none", "surfaces"};
    for (int m = 0; m < 2; m++) {
        double *B[2];
        size_t n[2], links[2], cl[2];
        for (int t = 0; t < 2; t++) {
            hrun r;
            const char *kv[] = {"cluster", "on", "bf-epsilon", "0.02", "importance", imp[m], NULL};
            solve_hier(&r, scene, RP_WANT_SURFACES, t + 1, kv);
            rp_hier_stats st;
            rp_hierarchical_stats(r.state, &st);
            links[t] = st.links;
            cl[t] = st.cluster_links;
            n[t] = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
            B[t] = malloc(n[t] * sizeof *B[t]);
            rp_hierarchical_leaves(r.state, NULL, NULL, B[t], n[t]);
            hrun_end(&r);
        }
        cr_assert_gt(cl[0], 0);
        cr_assert_eq(links[0], links[1]);
        cr_assert_eq(cl[0], cl[1]);
        cr_assert_eq(n[0], n[1]);
        cr_assert_eq(memcmp(B[0], B[1], n[0] * sizeof *B[0]), 0, "leaf radiosities differ (importance %s)", imp[m]);
        for (int t = 0; t < 2; t++)
            free(B[t]);
    }
    rp_scene_destroy(scene);
}

/* ---- sealed cavities and closed meshes (no light leaks) ---------------- */

/* A closed surface written as an OFF file: a UV sphere of radius r about
 * (0, c, 0) with nlat rings (2 nlat segments), or the box [lo, hi] with
 * every side cut into n x n quads (the importer splits them in two);
 * fronts outward, or inward when `inward`.  Returns the face count. */
static size_t off_sphere(const char *path, int nlat, double r, double c, int inward)
{
    FILE *f = fopen(path, "w");
    cr_assert(f, "%s", path);
    const int nlon = 2 * nlat;
    const int nv = 2 + (nlat - 1) * nlon, nf = 2 * nlon * (nlat - 1);
    fprintf(f, "OFF\n%d %d 0\n0 %.17g 0\n", nv, nf, c + r);
    for (int i = 1; i < nlat; i++)
        for (int j = 0; j < nlon; j++) {
            double th = RP_PI * i / nlat, ph = 2 * RP_PI * j / nlon;
            fprintf(f, "%.17g %.17g %.17g\n", r * sin(th) * cos(ph), c + r * cos(th), r * sin(th) * sin(ph));
        }
    fprintf(f, "0 %.17g 0\n", c - r);
#define V(i, j) (1 + ((i) - 1) * nlon + ((j) % nlon))
#define TRI(a, b, cc) fprintf(f, "3 %d %d %d\n", (a), inward ? (cc) : (b), inward ? (b) : (cc))
    for (int j = 0; j < nlon; j++)
        TRI(0, V(1, j + 1), V(1, j));
    for (int i = 1; i < nlat - 1; i++)
        for (int j = 0; j < nlon; j++) {
            TRI(V(i, j), V(i, j + 1), V(i + 1, j + 1));
            TRI(V(i, j), V(i + 1, j + 1), V(i + 1, j));
        }
    for (int j = 0; j < nlon; j++)
        TRI(nv - 1, V(nlat - 1, j), V(nlat - 1, j + 1));
#undef TRI
#undef V
    fclose(f);
    return (size_t)nf;
}

static size_t off_box(const char *path, const double lo[3], const double hi[3], int n, int inward)
{
    FILE *f = fopen(path, "w");
    cr_assert(f, "%s", path);
    /* Each side its own (n + 1)^2 vertices: sides share no vertex, which
     * the importer accepts (closedness is not required of a mesh). */
    const int nv = 6 * (n + 1) * (n + 1), nf = 6 * n * n;
    fprintf(f, "OFF\n%d %d 0\n", nv, nf);
    for (int side = 0; side < 6; side++) {
        int ax = side / 2, u = (ax + 1) % 3, w = (ax + 2) % 3;
        for (int i = 0; i <= n; i++)
            for (int j = 0; j <= n; j++) {
                double p[3];
                p[ax] = side % 2 ? hi[ax] : lo[ax];
                p[u] = lo[u] + (hi[u] - lo[u]) * i / n;
                p[w] = lo[w] + (hi[w] - lo[w]) * j / n;
                fprintf(f, "%.17g %.17g %.17g\n", p[0], p[1], p[2]);
            }
    }
    for (int side = 0; side < 6; side++)
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                int b = side * (n + 1) * (n + 1);
                int q[4] = {b + i * (n + 1) + j, b + (i + 1) * (n + 1) + j, b + (i + 1) * (n + 1) + j + 1,
                            b + i * (n + 1) + j + 1};
                /* (e_u x e_w) = +e_ax: outward on the high side. */
                int flip = (side % 2 == 0) != (inward != 0);
                if (flip)
                    fprintf(f, "4 %d %d %d %d\n", q[3], q[2], q[1], q[0]);
                else
                    fprintf(f, "4 %d %d %d %d\n", q[0], q[1], q[2], q[3]);
            }
    fclose(f);
    return (size_t)nf;
}

/* A lit room (3 x 2 x 3, rho 0.7, a 0.8 x 0.8 panel of Le 8 under the
 * ceiling) around `body` (statements naming surfaces "outer" and
 * "inner", material "ball", rho 0.6). */
static char *lit_room(const char *body)
{
    static const char head[] = "bands grey\n"
                               "material wall reflect 0.7\n"
                               "material ball reflect 0.6\n"
                               "material panel reflect 0 emit 8\n"
                               "box room wall -1.5 0 -1.5 1.5 2 1.5 inward\n"
                               "quad light panel -0.4 1.99 -0.4  0.4 1.99 -0.4  0.4 1.99 0.4  -0.4 1.99 0.4\n";
    size_t n = strlen(head) + strlen(body) + 1;
    char *t = malloc(n);
    cr_assert(t);
    snprintf(t, n, "%s%s", head, body);
    return t;
}

static size_t surface_index(const rp_scene *scene, const char *name)
{
    const rp_surface *surf = rp_scene_surfaces(scene);
    for (size_t i = 0; i < rp_scene_nsurfaces(scene); i++)
        if (strcmp(surf[i].name, name) == 0)
            return i;
    cr_assert_fail("no surface %s", name);
    return 0;
}

/* The sealed-cavity check.  The surface "inner" lines a closed shell
 * ("outer", fronts out) from inside, facing in, with no emitter inside:
 * no light can reach it, so its radiance is exactly 0 (not small: any
 * path that hands it energy is a leak).  For each --cluster mode in
 * modes, hierarchical radiosity (bf-epsilon 0.1, min-area 1e-3, fast)
 * must give exactly 0 inside, cluster the faces when want_clusters[k]
 * says so (the 512-face threshold of --cluster auto is crossed as
 * intended), and agree on the room and the outside of the shell with the
 * path tracer (65536 probe points per surface, fixed seed) within 2% + 4
 * standard errors: a leak also takes its light from somewhere (the
 * isotropic push that leaked 0.09 into the coarse sphere's inside left
 * the outside 9% dark). */
static void sealed_check(const rp_scene *scene, const char *const *modes, const int *want_clusters, int nmodes)
{
    const size_t ns = rp_scene_nsurfaces(scene);
    const size_t in = surface_index(scene, "inner"), out = surface_index(scene, "outer"),
                 room = surface_index(scene, "room");
    double *pt = calloc(ns, sizeof *pt), *se = calloc(ns, sizeof *se), *h = calloc(ns, sizeof *h);
    cr_assert(pt && se && h);
    rp_error err = {""};
    probe_pathtrace(scene, "65536", pt, se);
    cr_assert_eq(pt[in], 0.0, "the path tracer sees light inside: %g (the scene is not sealed)", pt[in]);
    for (int m = 0; m < nmodes; m++) {
        hrun r;
        const char *kv[] = {"cluster", modes[m], "bf-epsilon", "0.1", "min-area", "1e-3", NULL};
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        rp_hier_stats st;
        rp_hierarchical_stats(r.state, &st);
        rp_estimate e = {.surface_radiance = h};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
        cr_log_info("%zu faces, --cluster %s (%zu clusters): inside %g; outside %.6f vs path tracer %.6f +- %.6f "
                    "(%+.2f%%); room %.6f vs %.6f +- %.6f (%+.2f%%)",
                    rp_scene_nfaces(scene), modes[m], st.clusters, h[in], h[out], pt[out], se[out],
                    100 * (h[out] - pt[out]) / pt[out], h[room], pt[room], se[room],
                    100 * (h[room] - pt[room]) / pt[room]);
        cr_expect_eq(st.clusters > 0, want_clusters[m] != 0, "--cluster %s: %zu clusters", modes[m], st.clusters);
        cr_expect_eq(h[in], 0.0, "--cluster %s: light inside the sealed shell: L = %g", modes[m], h[in]);
        for (int k = 0; k < 2; k++) {
            size_t i = k ? room : out;
            cr_expect_leq(fabs(h[i] - pt[i]), 0.02 * pt[i] + 4 * se[i], "--cluster %s, %s: %.6f vs %.6f +- %.6f",
                          modes[m], k ? "room" : "outer", h[i], pt[i], se[i]);
        }
    }
    free(pt);
    free(se);
    free(h);
}

/* Shaft culling with a mesh as one occluder unit (hier_link.c
 * cull_units): a 0.8 x 0.8 lamp 1 above a floor of the same size, and
 * between them a black slab (a box mesh 2 x 0.1 x 2 of 1,200 triangles,
 * one unit) that hides the lamp from every point of the floor.  The
 * lamp-floor links are between two one-face units, so culling judges
 * them: the floor must stay exactly black, with the mesh solved whole
 * (one unit) and simplified (a few faces, each its own unit), and be lit
 * without the slab (so the check can fail). */
Test(hier, mesh_occluder_unit_blocks_links_between_faces, .init = hsetup, .timeout = 300)
{
    char dir[] = "/tmp/rp-cull-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char path[64];
    snprintf(path, sizeof path, "%s/slab.off", dir);
    static const double lo[3] = {-1, 0.45, -1}, hi[3] = {1, 0.55, 1};
    cr_assert_eq(off_box(path, lo, hi, 10, 0), 600);
    static const char head[] = "bands grey\n"
                               "material lamp reflect 0 emit 1\n"
                               "material white reflect 0.5\n"
                               "material black reflect 0\n"
                               "quad lamp lamp  -0.4 1 -0.4  0.4 1 -0.4  0.4 1 0.4  -0.4 1 0.4\n"
                               "quad floor white  -0.4 0 -0.4  -0.4 0 0.4  0.4 0 0.4  0.4 0 -0.4\n";
    for (int k = 0; k < 3; k++) {
        char text[512];
        snprintf(text, sizeof text, "%s%s", head, k < 2 ? "mesh slab black slab.off\n" : "");
        rp_scene *scene = rp_test_parse_in(text, dir);
        const char *kv[] = {"simplify", k == 0 ? "off" : "auto", NULL};
        hrun r;
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        const hier_state *hs = r.state;
        cr_assert(hs->cull, "culling is on");
        if (k == 0)
            cr_assert(hs->nunits == 3 && hs->nfaces == 1202, "%zu units for %zu faces", hs->nunits, hs->nfaces);
        double h[3] = {0}; /* one band, at most three surfaces */
        rp_error err = {""};
        rp_estimate e = {.surface_radiance = h};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        double floor = h[surface_index(scene, "floor")];
        cr_log_info("slab %s: %zu faces, %zu units, floor %.6g", k == 2 ? "absent" : kv[1], hs->nfaces, hs->nunits,
                    floor);
        if (k < 2)
            cr_expect_eq(floor, 0.0, "simplify %s: floor %.6g behind the slab", kv[1], floor);
        else
            cr_expect_gt(floor, 0.01, "no slab: floor %.6g", floor);
        hrun_end(&r);
        rp_scene_destroy(scene);
    }
    remove(path);
    rmdir(dir);
}

/* The shaft of a link (hier_link.c hier_outside_hull; Haines & Wallace
 * 1994) is the convex hull of its two elements' boxes.  A box at a corner
 * of the union box that no segment between the two reaches is outside it;
 * one on the segment between their centres is not.  And over random boxes
 * (some flat, as elements are), every box the test puts outside is missed
 * by each of 1,024 segments between the two boxes (their corners and
 * random points), checked by slab clipping here, independently: the test
 * must never skip the rays of a segment an occluder may cut.  It must also
 * skip some: a test that kept every box in the union would pass the first
 * check alone. */
static int segment_meets_box(const double p[3], const double q[3], const double lo[3], const double hi[3])
{
    double t0 = 0, t1 = 1;
    for (int i = 0; i < 3; i++) {
        double d = q[i] - p[i];
        if (d == 0) {
            if (p[i] < lo[i] || p[i] > hi[i])
                return 0;
            continue;
        }
        double a = (lo[i] - p[i]) / d, b = (hi[i] - p[i]) / d;
        if (a > b) {
            double t = a;
            a = b;
            b = t;
        }
        t0 = a > t0 ? a : t0;
        t1 = b < t1 ? b : t1;
        if (t0 > t1)
            return 0;
    }
    return 1;
}

static void random_box(gsl_rng *g, double lo[3], double hi[3])
{
    int flat = (int)gsl_rng_uniform_int(g, 4) - 1; /* -1: solid, else that axis flat */
    for (int i = 0; i < 3; i++) {
        double c = 10 * gsl_rng_uniform(g), h = i == flat ? 0 : 2 * gsl_rng_uniform(g);
        lo[i] = c - h;
        hi[i] = c + h;
    }
}

static rp_vec3 v3a(const double x[3]) { return rp_v3(x[0], x[1], x[2]); }

Test(hier, shaft_hull_skips_only_boxes_no_segment_meets)
{
    const rp_vec3 a[2] = {rp_v3(0, 0, 0), rp_v3(1, 1, 1)}, b[2] = {rp_v3(4, 4, 0), rp_v3(5, 5, 1)};
    const rp_vec3 corner[2] = {rp_v3(0, 4, 0), rp_v3(1, 5, 1)}, middle[2] = {rp_v3(2, 2, 0), rp_v3(3, 3, 1)};
    /* The shaft's side there is the line y = x + 1 through (0, 1) and (4, 5);
     * the box's nearest corner (1, 4), grown by e on each axis, is
     * (1 + e, 4 - e): on the line at e = 1. */
    cr_expect(hier_outside_hull(a, b, corner, 0), "the union box's corner is outside the shaft");
    cr_expect(hier_outside_hull(a, b, corner, 0.9), "grown by 0.9 it is still outside");
    cr_expect(!hier_outside_hull(a, b, corner, 1.1), "grown by 1.1 it reaches the shaft");
    cr_expect(!hier_outside_hull(a, b, middle, 0), "a box on the centres' segment is inside");

    gsl_rng *g = gsl_rng_alloc(gsl_rng_mt19937);
    gsl_rng_set(g, 44);
    int overlapping = 0, skipped = 0, wrong = 0;
    for (int t = 0; t < 20000; t++) {
        double alo[3], ahi[3], blo[3], bhi[3], olo[3], ohi[3];
        random_box(g, alo, ahi);
        random_box(g, blo, bhi);
        random_box(g, olo, ohi);
        int meets_union = 1;
        for (int i = 0; i < 3; i++)
            meets_union &= olo[i] <= fmax(ahi[i], bhi[i]) && ohi[i] >= fmin(alo[i], blo[i]);
        if (!meets_union)
            continue;
        overlapping++;
        const rp_vec3 A[2] = {v3a(alo), v3a(ahi)}, B[2] = {v3a(blo), v3a(bhi)}, O[2] = {v3a(olo), v3a(ohi)};
        if (!hier_outside_hull(A, B, O, 0))
            continue;
        skipped++;
        for (int k = 0; k < 1024 && !wrong; k++) {
            double p[3], q[3];
            for (int i = 0; i < 3; i++) {
                /* the first 64: corner to corner */
                double u = k < 64 ? (double)((k >> i) & 1) : gsl_rng_uniform(g);
                double w = k < 64 ? (double)((k >> (i + 3)) & 1) : gsl_rng_uniform(g);
                p[i] = alo[i] + u * (ahi[i] - alo[i]);
                q[i] = blo[i] + w * (bhi[i] - blo[i]);
            }
            wrong += segment_meets_box(p, q, olo, ohi);
        }
    }
    gsl_rng_free(g);
    cr_log_info("shaft: %d of %d boxes in the union box skipped", skipped, overlapping);
    cr_expect_eq(wrong, 0, "%d skipped boxes are met by a segment", wrong);
    cr_expect_gt(skipped, overlapping / 10, "only %d of %d boxes in the union box skipped", skipped, overlapping);
}

/* A closed box in a lit room whose inside is a separate surface: an
 * outward box with an inward box 1 cm inside it.  As two `box` statements
 * (19 faces in the scene, clustering only when asked), and as meshes with
 * every side cut into 5 x 5 quads (607 faces: clustered by --cluster auto). */
Test(hier, sealed_box_stays_dark, .init = hsetup, .timeout = 300)
{
    char *text = lit_room("box outer ball -0.5 0.3 -0.5 0.5 1.3 0.5 outward\n"
                          "box inner ball -0.49 0.31 -0.49 0.49 1.29 0.49 inward\n");
    rp_scene *scene = rp_test_parse(text);
    free(text);
    static const char *const m1[] = {"on", "off"};
    static const int w1[] = {1, 0};
    sealed_check(scene, m1, w1, 2);
    rp_scene_destroy(scene);

    char dir[] = "/tmp/rp-sealed-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char po[64], pi[64];
    snprintf(po, sizeof po, "%s/outer.off", dir);
    snprintf(pi, sizeof pi, "%s/inner.off", dir);
    static const double lo[3] = {-0.5, 0.3, -0.5}, hi[3] = {0.5, 1.3, 0.5};
    static const double lo2[3] = {-0.49, 0.31, -0.49}, hi2[3] = {0.49, 1.29, 0.49};
    off_box(po, lo, hi, 5, 0);
    off_box(pi, lo2, hi2, 5, 1);
    text = lit_room("mesh outer ball outer.off\nmesh inner ball inner.off\n");
    scene = rp_test_parse_in(text, dir);
    free(text);
    cr_assert_gt(rp_scene_nfaces(scene), HIER_CLUSTER_AUTO_FACES);
    static const char *const m2[] = {"auto", "off"};
    static const int w2[] = {1, 0};
    sealed_check(scene, m2, w2, 2);
    rp_scene_destroy(scene);
    remove(po);
    remove(pi);
    rmdir(dir);
}

/* Sphere in a sphere: a triangulated sphere (radius 0.5) in a lit room,
 * an inward-facing sphere (radius 0.49) just inside it.  Coarse (6 rings:
 * 247 faces in the scene, below the 512 of --cluster auto) and fine (10
 * rings: 727 faces, above), each with and without clustering. */
Test(hier, sealed_sphere_stays_dark, .init = hsetup, .timeout = 300)
{
    char dir[] = "/tmp/rp-sealed-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char po[64], pi[64];
    snprintf(po, sizeof po, "%s/outer.off", dir);
    snprintf(pi, sizeof pi, "%s/inner.off", dir);
    static const int rings[2] = {6, 10};
    static const char *const modes[2][2] = {{"auto", "on"}, {"auto", "off"}};
    static const int want[2][2] = {{0, 1}, {1, 0}};
    for (int k = 0; k < 2; k++) {
        off_sphere(po, rings[k], 0.5, 0.8, 0);
        off_sphere(pi, rings[k], 0.49, 0.8, 1);
        char *text = lit_room("mesh outer ball outer.off\nmesh inner ball inner.off\n");
        rp_scene *scene = rp_test_parse_in(text, dir);
        free(text);
        cr_assert_eq(rp_scene_nfaces(scene) > HIER_CLUSTER_AUTO_FACES, k == 1, "%zu faces", rp_scene_nfaces(scene));
        sealed_check(scene, modes[k], want[k], 2);
        rp_scene_destroy(scene);
    }
    remove(po);
    remove(pi);
    rmdir(dir);
}

/* A closed mesh in a lit room: CGAL's elephant (5558 triangles, scaled to
 * 300 mm, resting 0.1 mm above the floor) in the Cornell box without its
 * blocks, clustered (--cluster auto), against the path tracer (262144
 * probe points per surface: standard errors below 0.5%, checked, so 3%
 * is more than 6 of them).  Every surface holding 2% of the area or more
 * must be within 3%; the isotropic push was 3.3% off on the front ceiling
 * at these options (0.9% now), and 2.5% at the defaults. */
Test(hier, cluster_elephant_against_pathtrace, .init = hsetup, .timeout = 600)
{
    rp_scene *scene = rp_test_parse_in(
        "bands rgb\n"
        "material white  reflect 0.725 0.71 0.68\n"
        "material red    reflect 0.63 0.065 0.05\n"
        "material green  reflect 0.14 0.45 0.091\n"
        "material light  reflect 0  emit 17 12 4\n"
        "camera eye 278 273 -800  look 278 273 0  up 0 1 0  fov 39.3077  size 64 64\n"
        "quad floor        white  552.8 0 0  0 0 0  0 0 559.2  549.6 0 559.2\n"
        "quad light        light  343.0 548.8 227.0  343.0 548.8 332.0  213.0 548.8 332.0  213.0 548.8 227.0\n"
        "quad ceiling-front white 556.0 548.8 0  556.0 548.8 227.0  0 548.8 227.0  0 548.8 0\n"
        "quad ceiling-back white  556.0 548.8 332.0  556.0 548.8 559.2  0 548.8 559.2  0 548.8 332.0\n"
        "quad ceiling-left white  556.0 548.8 227.0  556.0 548.8 332.0  343.0 548.8 332.0  343.0 548.8 227.0\n"
        "quad ceiling-right white 213.0 548.8 227.0  213.0 548.8 332.0  0 548.8 332.0  0 548.8 227.0\n"
        "quad back         white  549.6 0 559.2  0 0 559.2  0 548.8 559.2  556.0 548.8 559.2\n"
        "quad right-green  green  0 0 559.2  0 0 0  0 548.8 0  0 548.8 559.2\n"
        "triangle left-red-low  red  552.8 0 0  549.6 0 559.2  556.0 548.8 559.2\n"
        "triangle left-red-high red  552.8 0 0  556.0 548.8 559.2  556.0 548.8 0\n"
        "mesh elephant white data/elephant.off scale 300 translate 278 150.1 280\n",
        RP_SOURCE_DIR "/scenes");
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    double *h = calloc(ns * nb, sizeof *h), *pt = calloc(ns * nb, sizeof *pt), *se = calloc(ns * nb, sizeof *se);
    cr_assert(h && pt && se);
    hrun r;
    /* On the elephant as given (--simplify off): this checks clustering,
     * which it predates; simplification has its own tests (test_simplify.c).
     * With stop 37's auto (5,290 of the 5,558 faces kept) the front ceiling
     * read -3.6% in band 2 here; at these options its value spreads over
     * -4 to +6% across seeds 1-4 with stop 36's simplification and this
     * one's alike (radpt probe), so one seed of it judges neither. */
    const char *kv[] = {"bf-epsilon", "0.05", "min-area", "1e-4", "simplify", "off", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
    rp_hier_stats st;
    rp_hierarchical_stats(r.state, &st);
    rp_error err = {""};
    rp_estimate e = {.surface_radiance = h};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
    hrun_end(&r);
    cr_assert_gt(st.clusters, 0);
    probe_pathtrace(scene, "262144", pt, se);
    const double total = rp_scene_total_area(scene);
    size_t checked = 0;
    for (size_t s = 0; s < ns; s++) {
        if (surf[s].area < 0.02 * total)
            continue;
        for (size_t b = 0; b < nb; b++) {
            size_t i = s * nb + b;
            if (pt[i] == 0 && h[i] == 0)
                continue;
            cr_log_info("%-14s band %zu: hierarchical %.6f  path tracer %.6f +- %.6f  (%+.2f%%)", surf[s].name, b,
                        h[i], pt[i], se[i], 100 * (h[i] - pt[i]) / pt[i]);
            if (rp_scene_materials(scene)[surf[s].material].Le[b] > 0)
                continue; /* the light: its own emission */
            cr_assert_lt(se[i], 0.005 * pt[i], "%s: the path tracer's error is too large to judge", surf[s].name);
            cr_expect_leq(fabs(h[i] - pt[i]), 0.03 * pt[i], "%s band %zu: %.6f vs %.6f +- %.6f",
                          surf[s].name, b, h[i], pt[i], se[i]);
            checked++;
        }
    }
    cr_assert_geq(checked, 8 * nb, "%zu values checked", checked);
    /* Importance weighs quadtree links only (hier_cluster.c cl_decide).
     * At the defaults with --importance camera the elephant's mean over
     * seeds 1-4 must be within 0.5% of the path tracer in every band, at
     * least twice the path tracer's standard error (0.18 to 0.22% here;
     * below 0.25%, checked), and each seed within 1%.  One seed varies
     * too much to judge 0.5%: against a 1M-sample probe, seeds 1-8 read
     * -0.76 to +0.33% (stop 43, band by band; -0.53% against this test's
     * probe at seed 7 once clusters drew samples for their new links
     * only), and their mean -0.11%.  When cluster links were weighted
     * too, the elephant read -0.94, -0.89, -0.99% (without importance
     * -0.11%; stop 26), which the mean rejects. */
    const char *ki[] = {"importance", "camera", NULL};
    size_t el = ns;
    for (size_t s = 0; s < ns; s++)
        if (strcmp(surf[s].name, "elephant") == 0)
            el = s;
    cr_assert_lt(el, ns);
    double mean[8] = {0};
    cr_assert_leq(nb, 8);
    const uint64_t seed0 = hrun_seed;
    for (int seed = 1; seed <= 4; seed++) {
        hrun_seed = (uint64_t)seed;
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, ki);
        e = (rp_estimate){.surface_radiance = h};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
        for (size_t b = 0; b < nb; b++) {
            size_t i = el * nb + b;
            cr_log_info("elephant band %zu, --importance camera, seed %d: %.6f, path tracer %.6f +- %.6f (%+.2f%%)", b,
                        seed, h[i], pt[i], se[i], 100 * (h[i] - pt[i]) / pt[i]);
            cr_expect_leq(fabs(h[i] - pt[i]), 0.01 * pt[i], "elephant band %zu with importance, seed %d: %.6f vs %.6f",
                          b, seed, h[i], pt[i]);
            mean[b] += h[i] / 4;
        }
    }
    hrun_seed = seed0;
    for (size_t b = 0; b < nb; b++) {
        size_t i = el * nb + b;
        cr_assert_lt(se[i], 0.0025 * pt[i], "the path tracer's error is too large to judge 0.5%%");
        cr_expect_leq(fabs(mean[b] - pt[i]), 0.005 * pt[i],
                      "elephant band %zu with importance, mean of seeds 1-4: %.6f vs %.6f +- %.6f", b, mean[b], pt[i],
                      se[i]);
    }
    free(h);
    free(pt);
    free(se);
    rp_scene_destroy(scene);
}

/* ---- a cluster link against a closed form ------------------------------ */

/* Lambert's point-to-polygon form factor (Cohen & Wallace 1993, eq. 4.21;
 * written out here, not radpt's): from a differential area at p with unit
 * normal n to the triangle (a, b, c), F = 1 / (2 pi) |sum_i theta_i
 * n . unit(R_i x R_i+1)|, R_i the vectors from p to the vertices and
 * theta_i the angles between them; the triangle must lie wholly above p's
 * tangent plane (true here). */
static double lambert_triangle(const double *p, const double *n, const double *a, const double *b, const double *c)
{
    const double *v[3] = {a, b, c};
    double s = 0;
    for (int i = 0; i < 3; i++) {
        const double *u = v[i], *w = v[(i + 1) % 3];
        double r0[3] = {u[0] - p[0], u[1] - p[1], u[2] - p[2]}, r1[3] = {w[0] - p[0], w[1] - p[1], w[2] - p[2]};
        double x[3] = {r0[1] * r1[2] - r0[2] * r1[1], r0[2] * r1[0] - r0[0] * r1[2], r0[0] * r1[1] - r0[1] * r1[0]};
        double lx = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
        double th = atan2(lx, r0[0] * r1[0] + r0[1] * r1[1] + r0[2] * r1[2]);
        if (lx > 0)
            s += th * (n[0] * x[0] + n[1] * x[1] + n[2] * x[2]) / lx;
    }
    return fabs(s) / (2 * M_PI);
}

/* A unit UV sphere (slices x stacks, fronts outward) written as ball.off
 * in a new temporary directory; scenes name it by its full path. */
typedef struct temp_ball {
    char dir[32], path[64];
} temp_ball;

static void temp_ball_write(temp_ball *b, int slices, int stacks)
{
    snprintf(b->dir, sizeof b->dir, "/tmp/radpt-ball-XXXXXX");
    cr_assert(mkdtemp(b->dir));
    snprintf(b->path, sizeof b->path, "%s/ball.off", b->dir);
    rp_test_mesh m = rp_test_uv_sphere(slices, stacks, 0, stacks, 0);
    rp_test_write_off(b->path, &m);
    rp_test_mesh_free(&m);
}

static void temp_ball_remove(const temp_ball *b)
{
    unlink(b->path);
    rmdir(b->dir);
}

/* A ball of 720 faces (radius 0.1, emitting Le = 1) far above a small patch
 * (side 0.02, reflectance 0.5, facing it at distance 2), clustered, with an
 * oracle so loose that no cluster link is refined: the patch's radiance is
 * rho Le F, F the form factor from the patch's centre to the ball's faces
 * (the sum of Lambert's closed form over the faces turned towards it: the
 * faceted ball is convex, so they do not hide one another), and for every
 * cluster of the ball the oracle's bound on the form factor from the
 * patch to that cluster is at least the exact one. */
Test(hier, cluster_link_bound_and_transfer_closed_form, .init = hsetup, .timeout = 120)
{
    temp_ball ball;
    temp_ball_write(&ball, 24, 16);
    const double R = 0.1, D = 2;
    char text[1024];
    snprintf(text, sizeof text,
             "bands grey\nmaterial lamp reflect 0 emit 1\nmaterial grey reflect 0.5\n"
             "mesh ball lamp %s scale %g translate 0 0 %g\n"
             "quad patch grey -0.01 -0.01 0  0.01 -0.01 0  0.01 0.01 0  -0.01 0.01 0\n",
             ball.path, R, D);
    rp_scene *scene = rp_test_parse(text);
    const size_t nf = rp_scene_nfaces(scene);
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    const uint32_t patch = rp_scene_find_surface(scene, "patch");
    const uint32_t pf = rp_scene_surfaces(scene)[patch].first_face;
    const double P[3] = {0, 0, 0}, N[3] = {0, 0, 1};
    /* F from the patch's centre to face f of the ball (0 if turned away) */
    double *Ff = calloc(nf, sizeof *Ff), Fexact = 0;
    for (size_t f = 0; f < nf; f++) {
        if (faces[f].surface == patch)
            continue;
        rp_vec3 a = V[faces[f].v[0]], b = V[faces[f].v[1]], c = V[faces[f].v[2]];
        if (rp_v3_dot(faces[f].normal, rp_v3_sub(rp_v3(0, 0, 0), a)) <= 0)
            continue;
        const double A[3] = {a.x, a.y, a.z}, B[3] = {b.x, b.y, b.z}, C[3] = {c.x, c.y, c.z};
        Ff[f] = lambert_triangle(P, N, A, B, C);
        Fexact += Ff[f];
    }
    /* the faceted ball is a little smaller than the sphere: (R/D)^2 less
     * a few percent */
    cr_assert(Fexact < R * R / (D * D) && Fexact > 0.95 * R * R / (D * D), "F %g, sphere %g", Fexact, R * R / (D * D));

    hrun r;
    const char *kv[] = {"cluster", "on", "bf-epsilon", "1e6", "cluster-rays", "256", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 2, kv);
    const hier_state *s = r.state;
    cr_assert(s->ncl > 0);
    size_t checked = 0;
    for (size_t i = 0; i < s->ncl; i++) {
        const hier_cluster *c = &s->cl[i];
        double Fc = 0;
        int only_ball = 1;
        for (uint32_t k = 0; k < c->count; k++) {
            uint32_t f = s->cl_faces[c->first + k];
            only_ball &= faces[f].surface != patch;
            Fc += Ff[f];
        }
        if (!only_ball)
            continue;
        double Fb = hier_cluster_bound(s, pf, (uint32_t)i | HIER_CL_BIT);
        if (Fb < 0) { /* dropped: nothing may pass, and nothing does */
            cr_expect(Fc == 0, "cluster %zu dropped with F %g", i, Fc);
            continue;
        }
        if (Fb == 0)
            continue; /* touching: always split */
        cr_expect(Fc <= Fb, "cluster %zu (%u faces): exact F %g above the bound %g", i, c->count, Fc, Fb);
        checked++;
    }
    cr_expect(checked > 10, "%zu clusters checked", checked);
    /* The transfer: sampled with 256 stratified point pairs per link and
     * ray (hier_cluster.c node_entries): within 3% of the closed form. */
    double surf[3];
    rp_estimate e = {.surface_radiance = surf};
    rp_error err = {""};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
    const double L = 0.5 * 1 * Fexact;
    cr_expect(fabs(surf[patch] / L - 1) < 0.03, "patch radiance %g, closed form %g", surf[patch], L);
    hrun_end(&r);
    free(Ff);
    rp_scene_destroy(scene);
    temp_ball_remove(&ball);
}

/* The ball of *ball (radius 0.3, reflectance 0.5) half a unit over a
 * floor of side 8, under a square lamp (Le 5) of side 1 at height 2. */
static rp_scene *ball_over_floor(const temp_ball *ball)
{
    char text[1024];
    snprintf(text, sizeof text,
             "bands grey\nmaterial lamp reflect 0 emit 5\nmaterial grey reflect 0.5\n"
             "mesh ball grey %s scale 0.3 translate 0 0 0.5\n"
             "quad floor grey -4 -4 0  4 -4 0  4 4 0  -4 4 0\n"
             "quad lamp lamp -0.5 -0.5 2  -0.5 0.5 2  0.5 0.5 2  0.5 -0.5 2\n",
             ball->path);
    return rp_test_parse(text);
}

/* A cluster keeps its old links' entries when it gains links, and an
 * entry points at the leaf its sample fell on, so that leaf may be split
 * later; the entry must then move down to a leaf (hier_cluster.c,
 * hier_cluster_follow_splits), or it would gather the children's mean.  A
 * ball of 720 faces over a floor under a lamp, clustered and solved; then
 * the leaf that holds the most entries is split by hand: its entries sit
 * on a split leaf until they follow, and afterwards every live entry sits
 * on a leaf, each of those on a child of the split one, with the form
 * factors untouched. */
Test(hier, cluster_entries_follow_split_leaves, .init = hsetup, .timeout = 120)
{
    temp_ball ball;
    temp_ball_write(&ball, 24, 16);
    rp_scene *scene = ball_over_floor(&ball);
    hrun r;
    const char *kv[] = {"cluster", "on", NULL};
    solve_hier(&r, scene, RP_WANT_SURFACES, 2, kv);
    hier_state *s = r.state;
    /* After the solve no live entry sits on a split leaf. */
    size_t live = 0;
    double Fsum = 0;
    for (size_t j = 0; j < s->ncl_cent; j++)
        if (s->cl_cent[j].F != 0) {
            live++;
            Fsum += s->cl_cent[j].F;
            cr_assert_eq(s->nodes[s->cl_cent[j].src].child, RP_NONE, "entry %zu on split node %u", j,
                         s->cl_cent[j].src);
        }
    cr_assert_gt(live, 1000, "%zu live entries: the test would prove little", live);
    /* The leaf most entries point at. */
    uint32_t *count = calloc(s->nnodes, sizeof *count);
    cr_assert(count);
    uint32_t best = 0;
    for (size_t j = 0; j < s->ncl_cent; j++)
        if (s->cl_cent[j].F != 0 && ++count[s->cl_cent[j].src] > count[best])
            best = s->cl_cent[j].src;
    const uint32_t n0 = count[best];
    free(count);
    cr_assert_geq(n0, 8, "the busiest leaf holds %u entries", n0);
    rp_error err = {""};
    cr_assert_eq(hier_subdivide(s, best, &err), RP_OK, "%s", err.message);
    const uint32_t child = s->nodes[best].child;
    cr_assert_neq(child, RP_NONE);
    size_t on_split = 0;
    for (size_t j = 0; j < s->ncl_cent; j++)
        on_split += s->cl_cent[j].F != 0 && s->cl_cent[j].src == best;
    cr_assert_eq(on_split, n0);
    hier_cluster_follow_splits(s);
    size_t moved = 0;
    double Fafter = 0;
    for (size_t j = 0; j < s->ncl_cent; j++) {
        const hier_centry *e = &s->cl_cent[j];
        if (e->F == 0)
            continue;
        Fafter += e->F;
        cr_assert_eq(s->nodes[e->src].child, RP_NONE, "entry %zu still on split node %u", j, e->src);
        moved += e->src >= child && e->src < child + 4;
    }
    cr_expect_eq(moved, n0, "%zu of the %u entries of the split leaf moved to its children", moved, n0);
    cr_expect_eq(Fafter, Fsum, "form factors %.17g after, %.17g before", Fafter, Fsum);
    hrun_end(&r);
    rp_scene_destroy(scene);
    temp_ball_remove(&ball);
}

/* A link is 14 bytes: the oracle's bound in 16 bits, the form factor in
 * 24 and three shares of 10 bits (or a 32-bit slot) in four bytes.  The
 * bound must stay a bound, at most 2^-7 above the value over the whole
 * range a bound takes (the closed form of rounding up to 8 bits of
 * mantissa); the form factor must come back within 2^-16 of itself
 * (rounding to 15 bits of mantissa, after the float's own 2^-24), 0 as
 * 0; the shares must be whole steps of 1/1023 adding up to exactly 1023
 * of them, each within one step of what was stored (they are rounded
 * through their running sum); a source and a slot must come back whole,
 * their top bits included. */
Test(hier, link_packing_keeps_bounds_shares_and_slots, .init = hsetup)
{
    cr_assert_eq(sizeof(hier_link), 14);
    cr_assert_eq(hier_bound_unpack(hier_bound_pack(0)) > 0, 1, "0 must pack as judged");
    for (double b = 1e-35; b < 1e6; b *= 1.0007) {
        double u = hier_bound_unpack(hier_bound_pack(b));
        cr_assert(u >= b && u <= b * (1 + 0x1p-7), "bound %.17g packs as %.17g", b, u);
    }
    for (double F = 1e-30; F < 2; F *= 1.0003) {
        hier_link l = {.flags = HIER_LINK_PARTIAL};
        hier_link_set_F(&l, F);
        double u = hier_link_F(&l);
        cr_assert(fabs(u - F) <= F * (0x1p-16 + 0x1p-24), "form factor %.17g packs as %.17g", F, u);
        cr_assert_eq(l.flags, HIER_LINK_PARTIAL);
    }
    hier_link z = {.flags = 0};
    hier_link_set_F(&z, 0);
    cr_assert_eq(hier_link_F(&z), 0.0f);
    const uint32_t nodes[] = {0, 1, 65535, 65536, 0x7fffffffu, 0xffffffffu};
    for (size_t k = 0; k < sizeof nodes / sizeof *nodes; k++) {
        hier_link_set_src(&z, nodes[k]);
        cr_assert_eq(hier_link_src(&z), nodes[k]);
    }
    for (int t = 0; t < 100000; t++) {
        double w[4], sum = 0;
        for (int k = 0; k < 4; k++) {
            /* uniform shares, one of them 0 in every seventh set */
            w[k] = t % 7 == 0 && k == t % 4 ? 0 : hier_u01(hier_key(12345, (uint64_t)t, 0), (uint64_t)k);
            sum += w[k];
        }
        for (int k = 0; k < 4; k++)
            w[k] /= sum;
        hier_link l = {.flags = HIER_LINK_PARTIAL};
        hier_link_set_shares(&l, w);
        cr_assert_eq(l.flags, HIER_LINK_PARTIAL | HIER_LINK_SHARES);
        double r[4], steps = 0;
        hier_link_shares(&l, r);
        for (int k = 0; k < 4; k++) {
            cr_assert(fabs(r[k] - w[k]) <= 1.0 / HIER_SHARE_ONE, "share %d: %.9f stored as %.9f", k, w[k], r[k]);
            double n = r[k] * HIER_SHARE_ONE;
            cr_assert(fabs(n - nearbyint(n)) < 1e-9, "share %d is not a whole number of steps: %.17g", k, n);
            steps += nearbyint(n);
        }
        cr_assert_eq(steps, (double)HIER_SHARE_ONE, "shares add up to %g steps", steps);
    }
    const uint32_t slots[] = {0, 1, 8191, 65536, 0x7fffffffu, 0xffffffffu};
    for (size_t k = 0; k < sizeof slots / sizeof *slots; k++) {
        hier_link l = {.flags = HIER_LINK_STRADDLE};
        hier_link_set_slot(&l, slots[k]);
        cr_assert_eq(hier_link_slot(&l), slots[k]);
        cr_assert_eq(l.flags, HIER_LINK_STRADDLE | HIER_LINK_COEF);
    }
}

/* After every step the receiver offsets of the face-level links cover
 * every node, and a node's run holds exactly the links it receives: the
 * gather sweep walks link_start over all nodes.  Nodes made by splitting
 * a cluster link's quadtree end, in a pass that added no face-level link
 * and refined none, were once left with the offsets realloc gave them
 * (hier_link.c hier_links_cover).  A ball over a large floor under a
 * lamp, clustered, at several refinements. */
Test(hier, link_offsets_cover_every_node, .init = hsetup, .timeout = 120)
{
    temp_ball ball;
    temp_ball_write(&ball, 16, 10);
    rp_scene *scene = ball_over_floor(&ball);
    const char *eps[] = {"0.2", "0.05", "0.01"};
    size_t steps = 0, filled = 0;
    for (int e = 0; e < 3; e++) {
        hrun r;
        rp_error err = {""};
        const char *kv[] = {"cluster", "on", "bf-epsilon", eps[e], "cluster-rays", "4", NULL};
        cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_SURFACES, 2, kv, &err), RP_OK, "%s",
                     err.message);
        for (int k = 0; k < 200; k++, steps++) {
            rp_step_info info;
            memset(&info, 0, sizeof info);
            const hier_state *s = r.state;
            const size_t nn0 = s->nnodes, nl0 = s->nlinks, ref0 = s->links_refined, inv0 = s->links_invisible;
            cr_assert_eq(r.type->step(r.state, &info, &err), RP_OK, "%s", err.message);
            /* New nodes while no face-level link was added, refined or
             * dropped: only hier_links_cover can have given them offsets
             * (the list's address says nothing since idle passes trim it) */
            filled += s->nnodes > nn0 && s->nlinks == nl0 && s->links_refined == ref0 && s->links_invisible == inv0;
            cr_assert_eq(s->start_nn, s->nnodes, "bf-epsilon %s, step %d (from 0): offsets for %zu of %zu nodes", eps[e], k,
                         s->start_nn, s->nnodes);
            cr_assert_eq(s->link_start[0], 0);
            for (size_t i = 0; i < s->nnodes; i++) {
                cr_assert_leq(s->link_start[i], s->link_start[i + 1], "node %zu", i);
                for (uint32_t l = s->link_start[i]; l < s->link_start[i + 1]; l++) {
                    /* Links do not store their receiver (the run they are
                     * in is it): the oracle's bound, a function of the
                     * pair, says whose link this is. */
                    hier_link e;
                    double rays = 0;
                    cr_assert(hier_link_eval(s, (uint32_t)i, hier_link_src(&s->links[l]), &e, &rays) != 0 &&
                                  e.F_err == s->links[l].F_err,
                              "link %lu in node %zu's run is not node %zu's", (unsigned long)l, i, i);
                }
            }
            cr_assert_eq(s->link_start[s->nnodes], s->nlinks);
            if (info.converged)
                break;
        }
        hrun_end(&r);
    }
    cr_log_info("%zu steps checked, %zu of them made nodes for cluster links only", steps, filled);
    cr_assert_gt(filled, 0, "no step made nodes without face-level links: the case is not exercised");
    rp_scene_destroy(scene);
    temp_ball_remove(&ball);
}

/* ---- importance (Smits, Arvo & Salesin 1992), --importance ------------ */

/* --importance none is the solver as it was before the option: the
 * Cornell box's surface averages at --bf-epsilon 0.05, seed 7, as the
 * release before it (commit e986708) printed them with `radpt probe
 * --surface-averages --json` (10 significant digits, so 2e-9 relative),
 * and bit for bit what auto gives when both an image and surface averages
 * are wanted (auto is none then, and for surface averages alone; camera
 * for an image alone). */
Test(hier, importance_none_is_the_default, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    cr_assert_eq(nb, 3);
    double *h[2];
    size_t n[2];
    double *B[2];
    for (int k = 0; k < 2; k++) {
        hrun r;
        /* (--variation-weight follows the question too: pinned) */
        const char *none[] = {"bf-epsilon", "0.05", "importance", "none", "variation-weight", "0", NULL};
        const char *dflt[] = {"bf-epsilon", "0.05", "variation-weight", "0", NULL};
        solve_hier(&r, scene, k == 0 ? RP_WANT_SURFACES : RP_WANT_SURFACES | RP_WANT_IMAGE, 0, k == 0 ? none : dflt);
        cr_assert_eq(((hier_state *)r.state)->importance, HIER_IMP_NONE);
        h[k] = calloc(ns * nb, sizeof *h[k]);
        rp_estimate e = {.surface_radiance = h[k]};
        rp_error err = {""};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        n[k] = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
        B[k] = malloc(n[k] * nb * sizeof *B[k]);
        rp_hierarchical_leaves(r.state, NULL, NULL, B[k], n[k]);
        hrun_end(&r);
    }
    cr_assert_eq(memcmp(h[0], h[1], ns * nb * sizeof *h[0]), 0, "none and the default differ");
    cr_assert_eq(n[0], n[1]);
    cr_assert_eq(memcmp(B[0], B[1], n[0] * nb * sizeof *B[0]), 0, "none and auto (image and surfaces) differ");
    /* auto: camera for an image alone, none for surface averages alone;
     * the default (no option): none for either */
    const unsigned wants[2] = {RP_WANT_IMAGE, RP_WANT_SURFACES};
    const int imps[2] = {HIER_IMP_CAMERA, HIER_IMP_NONE};
    const char *autokv[] = {"importance", "auto", NULL};
    for (int k = 0; k < 4; k++) {
        hrun r;
        rp_error err = {""};
        cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, wants[k % 2], 0, k < 2 ? autokv : NULL, &err),
                     RP_OK, "%s", err.message);
        cr_assert_eq((int)((hier_state *)r.state)->importance, k < 2 ? imps[k] : HIER_IMP_NONE);
        hrun_end(&r);
    }
    for (int k = 0; k < 2; k++) {
        free(h[k]);
        free(B[k]);
    }
    rp_scene_destroy(scene);
}

/* The importance solve against its closed form.  Two parallel unit squares
 * one apart, facing each other, never refined (--bf-epsilon 1e6): one
 * link each way, whose form factor is the midpoint rule over the
 * receiver's four quarters (the pair is near, hier_link.c), i.e. the
 * point-to-rectangle form factor at a quarter's centre, which by symmetry
 * is the same for all four and both ways: F = rp_cf_point_rect(1/4, 1/4,
 * 1, 1, 1) (Howell B-3 by superposition).  With the camera inside the gap
 * seeing plate 1 only, r = (1 / A_1, 0), and the importance equation
 * y_q = r_q + F rho_p y_p (reflectance of the OTHER plate, the one the
 * light lands on) gives
 *     y_1 = 1 / (1 - F^2 rho_1 rho_2),   y_2 = F rho_1 y_1.
 * rho_1 = 0.3 and rho_2 = 0.9 tell the right reflectance from the wrong
 * one (F rho_2 y_1 would be 3 times larger).  With --importance surfaces
 * r = (1, 1): y_1 = (1 + F rho_2) / (1 - F^2 rho_1 rho_2) and
 * y_2 = (1 + F rho_1) / (1 - F^2 rho_1 rho_2).  Both plates emit a little,
 * so that the radiosity sweeps, which the importance sweeps follow, do not
 * stop at the first. */
Test(hier, importance_two_plates_closed_form, .init = hsetup)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material one reflect 0.3 emit 1\n"
                                    "material two reflect 0.9 emit 0.5\n"
                                    "quad plate1 one  0 0 0  0 0 1  1 0 1  1 0 0\n"
                                    "quad plate2 two  0 1 0  1 1 0  1 1 1  0 1 1\n"
                                    "camera eye 0.5 0.9 0.5  look 0.5 0 0.5  up 0 0 1  fov 30  size 32 32\n");
    const double F = rp_cf_point_rect(0.25, 0.25, 1, 1, 1);
    const double r1 = 0.3, r2 = 0.9, den = 1 - F * F * r1 * r2;
    const double want[2][2] = {{1 / den, F * r1 / den}, {(1 + F * r2) / den, (1 + F * r1) / den}};
    const char *mode[2] = {"camera", "surfaces"};
    for (int m = 0; m < 2; m++) {
        hrun r;
        const char *kv[] = {"bf-epsilon", "1e6", "tolerance", "1e-14", "importance", mode[m], NULL};
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        const hier_state *s = r.state;
        cr_assert_eq(s->nnodes, 2, "refined");
        cr_assert_eq(s->nlinks, 2);
        cr_assert_eq(s->nimp_hits, m == 0 ? 32 * 32 : 0, "the camera sees plate 1 only");
        for (int k = 0; k < 2; k++) {
            cr_log_info("%s: y_%d %.12f, closed form %.12f", mode[m], k + 1, s->Y[k], want[m][k]);
            /* 3e-5: a link keeps its form factor to 2^-16 = 1.5e-5
             * relative (hier_link), which moves y_k by less than twice
             * that; the rest is solved to 1e-14 */
            cr_assert_float_eq(s->Y[k], want[m][k], 3e-5 * want[m][k], "%s: y_%d %.12g vs %.12g", mode[m], k + 1,
                               s->Y[k], want[m][k]);
        }
        hrun_end(&r);
    }
    rp_scene_destroy(scene);
}

/* Importance from the camera where it is known: in a unit cube the camera
 * sees the far wall (z = 1) whole and nothing else, so that wall's leaves
 * share all the direct importance, 1 / A = 1 per unit area on the wall.
 * The leaves' direct importance (Y0) must add up, area-weighted, to the
 * fraction of pixels that see the wall, 1, and be 0 on the five other
 * faces. */
Test(hier, importance_camera_direct_term, .init = hsetup, .timeout = 120)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material lamp reflect 0.5 emit 1\n"
                                    "material wall reflect 0.5\n"
                                    "quad floor    wall  0 0 0  0 0 1  1 0 1  1 0 0\n"
                                    "quad ceiling  lamp  0 1 0  1 1 0  1 1 1  0 1 1\n"
                                    "quad wall-x0  wall  0 0 0  0 1 0  0 1 1  0 0 1\n"
                                    "quad wall-x1  wall  1 0 0  1 0 1  1 1 1  1 1 0\n"
                                    "quad wall-z0  wall  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad wall-z1  wall  0 0 1  0 1 1  1 1 1  1 0 1\n"
                                    "camera eye 0.5 0.5 0.3  look 0.5 0.5 1  up 0 1 0  fov 60  size 64 64\n");
    hrun r;
    const char *kv[] = {"bf-epsilon", "0.05", "importance", "camera", NULL};
    solve_hier(&r, scene, RP_WANT_IMAGE, 0, kv);
    const hier_state *s = r.state;
    double on = 0, off = 0;
    for (size_t i = 0; i < s->nnodes; i++)
        if (s->nodes[i].child == RP_NONE)
            *(s->nodes[i].face == 5 ? &on : &off) += s->nodes[i].area * s->Y0[i];
    cr_log_info("direct importance: %.15f on the far wall, %.3g elsewhere", on, off);
    cr_assert_float_eq(on, 1.0, 1e-12);
    cr_assert_eq(off, 0);
    hrun_end(&r);
    rp_scene_destroy(scene);
}

/* Leaves per surface (nsurf entries) and the camera image of a solve. */
static void solve_leaves_image(const rp_scene *scene, const char *const *kv, size_t *leaves, float *img,
                               rp_hier_stats *st)
{
    hrun r;
    solve_hier(&r, scene, RP_WANT_IMAGE, 0, kv);
    size_t n = rp_hierarchical_leaves(r.state, NULL, NULL, NULL, 0);
    uint32_t *sf = malloc(n * sizeof *sf);
    cr_assert(sf);
    rp_hierarchical_leaves(r.state, NULL, sf, NULL, n);
    memset(leaves, 0, rp_scene_nsurfaces(scene) * sizeof *leaves);
    for (size_t i = 0; i < n; i++)
        leaves[sf[i]]++;
    free(sf);
    rp_hierarchical_stats(r.state, st);
    rp_estimate e = {.radiance = img};
    rp_error err = {""};
    cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
    hrun_end(&r);
}

/* A camera that sees one wall of the lit cube (cube-ceiling.scene: lamp
 * ceiling, walls of reflectance 1/2) from inside.  With --importance camera
 * the wall behind the camera (z0), which the image shows only through
 * interreflection, gets under 60% of the leaves it gets without importance
 * (measured 1000 against 1816) and the wall in view at least 90% (1936),
 * while the image stays as close to a finer solution without importance
 * (--bf-epsilon 3e-3; 20k leaves, 9 s) as the image without importance
 * at the same --bf-epsilon 0.01: RMSE within 1.25 times that one's, and
 * under 0.5% of the mean pixel.  (Measured: camera 9.1e-5, none 1.44e-4,
 * and against a still finer 1e-3 solution 2.2e-4 and 2.9e-4; the finer
 * reference is not a test's work, 1.7 GB.) */
Test(hier, importance_camera_coarsens_unseen, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material lamp reflect 0.5 emit 1\n"
                                    "material wall reflect 0.5\n"
                                    "quad floor    wall  0 0 0  0 0 1  1 0 1  1 0 0\n"
                                    "quad ceiling  lamp  0 1 0  1 1 0  1 1 1  0 1 1\n"
                                    "quad wall-x0  wall  0 0 0  0 1 0  0 1 1  0 0 1\n"
                                    "quad wall-x1  wall  1 0 0  1 0 1  1 1 1  1 1 0\n"
                                    "quad wall-z0  wall  0 0 0  1 0 0  1 1 0  0 1 0\n"
                                    "quad wall-z1  wall  0 0 1  0 1 1  1 1 1  1 0 1\n"
                                    "camera eye 0.5 0.5 0.3  look 0.5 0.5 1  up 0 1 0  fov 60  size 64 64\n");
    const size_t ns = rp_scene_nsurfaces(scene), npix = 64 * 64;
    size_t leaves[3][8];
    float *img[3];
    rp_hier_stats st[3];
    const char *kv[3][5] = {{"bf-epsilon", "3e-3", "importance", "none", NULL},
                            {"bf-epsilon", "0.01", "importance", "none", NULL},
                            {"bf-epsilon", "0.01", "importance", "camera", NULL}};
    for (int k = 0; k < 3; k++) {
        img[k] = malloc(npix * sizeof *img[k]);
        cr_assert(img[k]);
        solve_leaves_image(scene, kv[k], leaves[k], img[k], &st[k]);
    }
    double mean = 0, e[2] = {0, 0};
    for (size_t i = 0; i < npix; i++) {
        mean += img[0][i] / (double)npix;
        for (int k = 0; k < 2; k++)
            e[k] += (img[k + 1][i] - (double)img[0][i]) * (img[k + 1][i] - (double)img[0][i]) / (double)npix;
    }
    e[0] = sqrt(e[0]);
    e[1] = sqrt(e[1]);
    const rp_surface *surf = rp_scene_surfaces(scene);
    for (size_t s = 0; s < ns; s++)
        cr_log_info("%-8s leaves: none %zu, camera %zu (fine none %zu)", surf[s].name, leaves[1][s], leaves[2][s],
                    leaves[0][s]);
    cr_log_info("leaves %zu / %zu, links %zu / %zu; image RMSE against the finer solution: none %.3g, camera %.3g "
                "(mean pixel %.4f)",
                st[1].leaves, st[2].leaves, st[1].links, st[2].links, e[0], e[1], mean);
    cr_assert_lt(leaves[2][4], 0.6 * leaves[1][4], "the wall behind the camera is not coarser: %zu vs %zu",
                 leaves[2][4], leaves[1][4]);
    cr_assert_geq(leaves[2][5], 0.9 * leaves[1][5], "the wall in view is coarser: %zu vs %zu", leaves[2][5],
                  leaves[1][5]);
    cr_assert_lt(st[2].leaves, st[1].leaves);
    cr_assert_leq(e[1], 1.25 * e[0], "camera image RMSE %.3g against none's %.3g", e[1], e[0]);
    cr_assert_lt(e[1], 0.005 * mean);
    for (int k = 0; k < 3; k++)
        free(img[k]);
    rp_scene_destroy(scene);
}

/* ---- visibility estimates are unbiased ------------------------------------ */

/* A 0.5 m lamp 1 m above the centre of a 4 m floor (rho 0.5), a black
 * 0.3 m blocker half way up, off centre.  Nothing but the floor reflects
 * and the floor cannot see itself, so its mean radiance is one bounce:
 *     L = rho Le (A_lamp / A_floor) (F_lamp,floor - F_lamp,blocker),
 * every ray from the lamp to the blocker having been bound for the floor.
 * Both form factors are B-3 (Howell) averaged over the lamp by
 * Gauss-Legendre (tests/closed_form.c), 8 x 8 sub-squares.
 *
 * Two failures this catches.  (1) The floor's first link, centred under
 * the lamp, has four quarters that agree (0.009) and a centre that does
 * not (0.08): judged by the quarters alone it was never refined, and the
 * floor came out 22% dark.  (2) When one set of 16 rays both decides
 * whether a link is refined and measures its visibility, a link whose
 * rays all missed the blocker's shadow keeps visibility 1 while one whose
 * rays found it is refined and re-measured: the shadow comes out too light
 * on average (measured: +0.08% to +0.12% on each of six seeds, mean
 * +0.10%).  With a second, independent set for the value the seeds
 * scatter around the closed form (-0.04% to +0.01%, mean -0.008%). */
Test(hier, shadow_mean_is_unbiased, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material floor reflect 0.5\n"
                                    "material black reflect 0\n"
                                    "material lamp reflect 0 emit 1\n"
                                    "quad floor floor  -2 0 -2  -2 0 2  2 0 2  2 0 -2\n"
                                    "quad lamp lamp  -0.25 1 -0.25  0.25 1 -0.25  0.25 1 0.25  -0.25 1 0.25\n"
                                    "quad blocker black  -0.05 0.5 -0.15  0.25 0.5 -0.15  0.25 0.5 0.15  "
                                    "-0.05 0.5 0.15\n");
    const int n = 8;
    const double h = 0.5 / n;
    double f_floor = 0, f_block = 0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            /* lamp point (x, z), looking down; rectangles in its frame */
            double x0 = -0.25 + i * h, z0 = -0.25 + j * h;
            f_floor += rp_cf_point_rect_mean(x0 + 2, x0 + h + 2, z0 + 2, z0 + h + 2, 4, 4, 1) / (n * n);
            f_block += rp_cf_point_rect_mean(x0 + 0.05, x0 + h + 0.05, z0 + 0.15, z0 + h + 0.15, 0.3, 0.3, 0.5) / (n * n);
        }
    const double want = 0.5 * 1.0 * (0.25 / 16.0) * (f_floor - f_block);
    const int nseeds = 4;
    double mean = 0;
    for (int k = 0; k < nseeds; k++) {
        const char *kv[] = {"min-area", "1e-4", NULL};
        hrun r;
        rp_error err = {""};
        hrun_seed = (uint64_t)(k + 1);
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        hrun_seed = 7;
        double L[3];
        rp_estimate e = {.surface_radiance = L};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
        double rel = L[0] / want - 1;
        cr_log_info("seed %d: floor %.8f, closed form %.8f (%+.3f%%)", k + 1, L[0], want, 100 * rel);
        cr_assert_lt(fabs(rel), 1e-3, "seed %d: floor %.8g, closed form %.8g", k + 1, L[0], want);
        mean += rel / nseeds;
    }
    cr_log_info("mean %+.4f%% (closed form %.8f, F_lamp,floor %.8f, F_lamp,blocker %.8f)", 100 * mean, want,
                f_floor, f_block);
    cr_assert_lt(fabs(mean), 4e-4, "the seeds' mean is %+.3f%% off the closed form", 100 * mean);
    rp_scene_destroy(scene);
}

/* ---- --variation-weight: a dim source whose radiosity varies ------------ */

/* The Cornell box's floor, light and short box, everything but the floor
 * and the box's front black: the front (which the light does not reach)
 * is lit by the floor alone, and the floor at its foot lies in the box's
 * shadow.  BF refinement keeps the front's links to that dim floor
 * coarse, and an element reaching from the shadow into the light gave
 * the front its brighter mean.  Against a 4M-sample path-traced probe
 * (radpt probe, standard error 0.18%), seeds 1-7 read +0.98 to +1.88%
 * without the variation test and +0.24 to +1.13% with it (the floor's
 * shadow is sampled by 16 rays a link, which moves this small face by a
 * few tenths of a percent from seed to seed), 0.72 to 0.78% less at
 * every seed.  Here: at each of seeds 1-4 the test moves the front down
 * by at least 0.5% of its value (deterministic, no path-tracing noise
 * enters), and the four seeds' mean is within 0.75% of the path tracer
 * (+0.55% with the test, +1.32% without; seed 7 for the path tracer). */
Test(hier, variation_weight_floor_seen_by_a_box_side, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_parse(
        "bands rgb\n"
        "material white  reflect 0.725 0.71 0.68\n"
        "material black  reflect 0\n"
        "material light  reflect 0  emit 17 12 4\n"
        "quad floor        white  552.8 0 0  0 0 0  0 0 559.2  549.6 0 559.2\n"
        "quad light        light  343.0 548.8 227.0  343.0 548.8 332.0  213.0 548.8 332.0  213.0 548.8 227.0\n"
        "quad short-top    black  130 165 65  82 165 225  240 165 272  290 165 114\n"
        "quad short-left   black  290 0 114  290 165 114  240 165 272  240 0 272\n"
        "quad short-front  white  130 0 65  130 165 65  290 165 114  290 0 114\n"
        "quad short-right  black  82 0 225  82 165 225  130 165 65  130 0 65\n"
        "quad short-back   black  240 0 272  240 165 272  82 165 225  82 0 225\n");
    const size_t ns = rp_scene_nsurfaces(scene), nb = rp_scene_nbands(scene);
    const size_t front = surface_index(scene, "short-front");
    double *on = calloc(ns * nb, sizeof *on), *off = calloc(ns * nb, sizeof *off);
    double *pt = calloc(ns * nb, sizeof *pt), *se = calloc(ns * nb, sizeof *se);
    double mean_on[3] = {0}, mean_off[3] = {0};
    cr_assert(on && off && pt && se && nb == 3);
    rp_error err = {""};
    probe_pathtrace(scene, "4194304", pt, se);
    const int nseeds = 4;
    for (int k = 1; k <= nseeds; k++) {
        hrun r;
        hrun_seed = (uint64_t)k;
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, NULL);
        rp_estimate e = {.surface_radiance = on};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
        const char *kv[] = {"variation-weight", "0", NULL};
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        e = (rp_estimate){.surface_radiance = off};
        cr_assert_eq(r.type->estimate(r.state, &e, &err), RP_OK, "%s", err.message);
        hrun_end(&r);
        hrun_seed = 7;
        for (size_t b = 0; b < nb; b++) {
            const size_t i = front * nb + b;
            cr_log_info("seed %d band %zu: path tracer %.6f +- %.6f; variation test on %.6f (%+.2f%%), off %.6f "
                        "(%+.2f%%)",
                        k, b, pt[i], se[i], on[i], 100 * (on[i] / pt[i] - 1), off[i], 100 * (off[i] / pt[i] - 1));
            cr_expect_geq(off[i] - on[i], 0.005 * pt[i], "seed %d band %zu: the variation test moved the front by "
                          "%.6f only", k, b, off[i] - on[i]);
            mean_on[b] += on[i] / nseeds;
            mean_off[b] += off[i] / nseeds;
        }
    }
    for (size_t b = 0; b < nb; b++) {
        const size_t i = front * nb + b;
        cr_log_info("band %zu: mean of %d seeds %+.2f%% with the variation test, %+.2f%% without", b, nseeds,
                    100 * (mean_on[b] / pt[i] - 1), 100 * (mean_off[b] / pt[i] - 1));
        cr_assert_lt(se[i], 0.002 * pt[i], "band %zu: the path tracer's error is too large to judge", b);
        cr_expect_leq(fabs(mean_on[b] - pt[i]), 0.0075 * pt[i], "band %zu: %.6f vs %.6f +- %.6f", b, mean_on[b],
                      pt[i], se[i]);
    }
    free(on);
    free(off);
    free(pt);
    free(se);
    rp_scene_destroy(scene);
}

/* --variation-weight auto: 10 for surface averages alone (probe), 0 when
 * an image is wanted; a number is taken as given. */
Test(hier, variation_weight_follows_the_question, .init = hsetup)
{
    rp_scene *scene = rp_test_load("scenes/cornell.scene");
    const unsigned wants[3] = {RP_WANT_SURFACES, RP_WANT_IMAGE, RP_WANT_SURFACES | RP_WANT_IMAGE};
    const double want_w[3] = {10, 0, 0};
    const char *autokv[] = {"variation-weight", "auto", NULL}, *three[] = {"variation-weight", "3", NULL};
    for (int k = 0; k < 9; k++) {
        hrun r;
        rp_error err = {""};
        const char *const *kv = k < 3 ? NULL : k < 6 ? autokv : three;
        cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, wants[k % 3], 0, kv, &err), RP_OK, "%s",
                     err.message);
        cr_expect_eq(((hier_state *)r.state)->variation_weight, k < 6 ? want_w[k % 3] : 3.0, "case %d", k);
        hrun_end(&r);
    }
    rp_scene_destroy(scene);
}

/* ---- --mesh discontinuity: the quadtrees start conforming ----------------- */

/* A box standing on a floor under a lamp.  With --mesh discontinuity the
 * floor is cut along the box's outline (a D0 line) before refinement, so
 * no floor leaf has a corner inside the footprint and another outside it;
 * starting from the faces as given, refinement stops at --min-area with
 * leaves across the outline (the check's own control).  The footprint is
 * [-0.3, 0.3] x [-0.2, 0.4]. */
static size_t floor_leaves_across(const hier_state *s, uint32_t floor_surface)
{
    const double x0 = -0.3, x1 = 0.3, z0 = -0.2, z1 = 0.4, tol = 1e-9;
    size_t across = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE || s->faces[nd->face].surface != floor_surface)
            continue;
        int in = 0, out = 0;
        for (int k = 0; k < nd->nverts; k++) {
            rp_vec3 v = nd->v[k];
            if (v.x > x0 + tol && v.x < x1 - tol && v.z > z0 + tol && v.z < z1 - tol)
                in = 1;
            else if (v.x < x0 - tol || v.x > x1 + tol || v.z < z0 - tol || v.z > z1 + tol)
                out = 1;
        }
        across += in && out;
    }
    return across;
}

Test(hier, discontinuity_start_mesh_conforms, .init = hsetup, .timeout = 300)
{
    rp_scene *scene = rp_test_parse("bands grey\n"
                                    "material floor reflect 0.5\n"
                                    "material white reflect 0.7\n"
                                    "material lamp reflect 0 emit 1\n"
                                    "quad floor floor  -2 0 -2  -2 0 2  2 0 2  2 0 -2\n"
                                    "box block white  -0.3 0 -0.2  0.3 0.5 0.4  outward\n"
                                    "quad lamp lamp  -0.5 2 -0.5  0.5 2 -0.5  0.5 2 0.5  -0.5 2 0.5\n");
    const uint32_t floor_surface = (uint32_t)surface_index(scene, "floor");
    size_t across[2], leaves[2];
    for (int m = 0; m < 2; m++) {
        const char *kv[] = {"mesh", m ? "discontinuity" : "faces", NULL};
        hrun r;
        solve_hier(&r, scene, RP_WANT_SURFACES, 0, kv);
        const hier_state *s = r.state;
        across[m] = floor_leaves_across(s, floor_surface);
        leaves[m] = rp_hierarchical_leaves(s, NULL, NULL, NULL, 0);
        cr_log_info("--mesh %s: %zu faces, %zu leaves, %zu floor leaves across the box's outline",
                    m ? "discontinuity" : "faces", s->nfaces, leaves[m], across[m]);
        hrun_end(&r);
    }
    cr_assert_gt(across[0], 0, "the faces as given: some floor leaf should cross the outline");
    cr_assert_eq(across[1], 0, "--mesh discontinuity: %zu floor leaves cross the box's outline", across[1]);
    rp_scene_destroy(scene);
}

/* --mesh discontinuity cuts the faces as given: refused, naming the way
 * out, when --simplify has simplified a mesh of the scene (a 2208-triangle
 * sphere at --simplify 0.5). */
Test(hier, discontinuity_start_mesh_refuses_a_simplified_mesh, .init = hsetup, .timeout = 120)
{
    char off[] = "/tmp/rp_hier_meshXXXXXX.off";
    int fd = mkstemps(off, 4);
    cr_assert(fd >= 0);
    close(fd);
    cr_assert_geq(off_sphere(off, 24, 0.3, 1.0, 0), RP_SIMPLIFY_MIN_FACES);
    char text[1024];
    snprintf(text, sizeof text,
             "bands grey\nmaterial w reflect 0.5\nmaterial l reflect 0 emit 1\n"
             "box room w -2 -2 -2 2 2 2 inward\nmesh ball w %s\n"
             "quad lamp l -0.5 1.9 -0.5 0.5 1.9 -0.5 0.5 1.9 0.5 -0.5 1.9 0.5\n",
             off);
    rp_scene *scene = rp_test_parse(text);
    rp_error err = {""};
    hrun r;
    const char *both[] = {"mesh", "discontinuity", "simplify", "0.5", NULL};
    cr_assert_eq(hrun_start(&r, &rp_solver_hierarchical, scene, RP_WANT_SURFACES, 0, both, &err), RP_ERR_UNSUPPORTED);
    cr_assert(strstr(err.message, "--simplify off"), "%s", err.message);
    hrun_end(&r);
    rp_scene_destroy(scene);
    unlink(off);
}
