/* Tests of the element form factors (solvers/radiosity/formfactor.h) and of
 * `radpt formfactor`.
 *
 * References the code did not produce: Howell's closed forms C-11 (directly
 * opposed parallel rectangles) and C-14 (perpendicular rectangles sharing
 * an edge), written here from docs/ground-truth.md; the differential area
 * to a parallel rectangle by superposing the corner form of Howell's
 * catalogue (normal through a corner; Hamilton & Morgan 1952), for the
 * hemicube's point values; the unoccluded Cornell-box form factors quoted
 * in docs/ground-truth.md; closure (row sums of 1) and reciprocity in a closed
 * box.  Rectangle sizes are odd on purpose (0.37, 1.9, 0.61, ...), so a
 * formula that only works for unit squares cannot pass.
 *
 * Tolerances: the analytic method at its default tolerance (1e-5 relative
 * per pair) must match the closed forms to 1e-5 relative, and at 1e-9 to
 * 1e-8; Monte Carlo within 3 standard errors for fixed seeds, and its
 * standard error honest (mean squared z-score over 20 seeds near 1, bounds
 * at the chi-square(20) 0.1% and 99.9% points); the hemicube's error
 * against the exact point value at each element centroid must fall from
 * resolution 64 to 512 and stay below a few pixel rows' worth of form
 * factor; exact pixel delta form factors make its rows in a closed box sum
 * to 1. */
#include <criterion/criterion.h>
#include <criterion/logging.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli_util.h"
#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/radiosity/formfactor.h"
#include "closed_form.h"

/* ---- closed forms (docs/ground-truth.md) -------------------------------- */

/* A differential area parallel to an x by y rectangle at distance c,
 * its normal through a corner; signed in x and y so that rectangles not
 * containing the foot of the normal follow by inclusion-exclusion. */
static double corner(double x, double y, double c)
{
    double X = fabs(x) / c, Y = fabs(y) / c;
    double sx = sqrt(1 + X * X), sy = sqrt(1 + Y * Y);
    double f = (X / sx * atan(Y / sx) + Y / sy * atan(X / sy)) / (2 * M_PI);
    return (x < 0) != (y < 0) ? -f : f;
}

/* From a point at height c below the rectangle [x0,x1] x [y0,y1] (in the
 * rectangle's own axes, the point's foot at the origin). */
static double point_rect(double x0, double x1, double y0, double y1, double c)
{
    return corner(x1, y1, c) - corner(x0, y1, c) - corner(x1, y0, c) + corner(x0, y0, c);
}

/* ---- set-up ------------------------------------------------------------- */

typedef struct fixture {
    rp_scene *scene;
    rp_mesh *mesh;
    rp_raycast *rc;
    rp_ff_context *ctx;
    rp_ff_scratch *scratch;
} fixture;

static void setup(fixture *f, const char *text, double max_edge, int rays, rp_ff_params p)
{
    rp_error err = {""};
    memset(f, 0, sizeof *f);
    cr_assert_eq(rp_scene_parse(text, "ff.scene", NULL, &f->scene, &err), RP_OK, "%s", err.message);
    rp_mesh_params mp = {.size = sizeof mp, .max_edge = max_edge};
    cr_assert_eq(rp_mesh_create(f->scene, &mp, &f->mesh, &err), RP_OK, "%s", err.message);
    if (rays)
        cr_assert_eq(rp_raycast_create(f->scene, f->mesh, &f->rc, &err), RP_OK, "%s", err.message);
    p.size = sizeof p;
    cr_assert_eq(rp_ff_context_create(f->scene, f->mesh, f->rc, &p, &f->ctx, &err), RP_OK, "%s",
                 err.message);
    cr_assert_eq(rp_ff_scratch_create(f->ctx, &f->scratch, &err), RP_OK, "%s", err.message);
}

static void teardown(fixture *f)
{
    rp_ff_scratch_destroy(f->scratch);
    rp_ff_context_destroy(f->ctx);
    rp_raycast_destroy(f->rc);
    rp_mesh_destroy(f->mesh);
    rp_scene_destroy(f->scene);
}

static uint32_t surface(const fixture *f, const char *name)
{
    uint32_t s = rp_scene_find_surface(f->scene, name);
    cr_assert_neq(s, RP_NONE, "no surface %s", name);
    return s;
}

/* F from the union of surfaces `from` (NULL-terminated) to the union `to`:
 * sum_i sum_j A_i F_ij / sum_i A_i, with the combined standard error. */
static double group_ff(fixture *f, const char *const *from, const char *const *to, double *se,
                       double *rays)
{
    const rp_element *E = rp_mesh_elements(f->mesh);
    double num = 0, den = 0, var = 0;
    for (const char *const *a = from; *a; a++) {
        uint32_t a0, na;
        rp_mesh_surface_elements(f->mesh, surface(f, *a), &a0, &na);
        for (uint32_t i = a0; i < a0 + na; i++) {
            den += E[i].area;
            for (const char *const *b = to; *b; b++) {
                uint32_t b0, nb;
                rp_mesh_surface_elements(f->mesh, surface(f, *b), &b0, &nb);
                for (uint32_t j = b0; j < b0 + nb; j++) {
                    double s = 0;
                    num += E[i].area * rp_ff_pair(f->ctx, f->scratch, i, j, &s, rays);
                    var += E[i].area * E[i].area * s * s;
                }
            }
        }
    }
    if (se)
        *se = sqrt(var) / den;
    return num / den;
}

static double surf_ff(fixture *f, const char *a, const char *b, double *se, double *rays)
{
    const char *from[] = {a, NULL}, *to[] = {b, NULL};
    return group_ff(f, from, to, se, rays);
}

#define HEAD "bands grey\nmaterial e reflect 0 emit 1\nmaterial w reflect 0.5\n"

/* Directly opposed a x b rectangles: A at y = 0 facing up, B at y = c
 * facing down. */
static void parallel_scene(char *buf, size_t n, double a, double b, double c)
{
    snprintf(buf, n,
             HEAD "quad A e 0 0 0  0 0 %.17g  %.17g 0 %.17g  %.17g 0 0\n"
                  "quad B w 0 %.17g 0  %.17g %.17g 0  %.17g %.17g %.17g  0 %.17g %.17g\n",
             b, a, b, a, c, a, c, a, c, b, c, b);
}

/* A: the floor y = 0, w deep (z) by l (x); B: the wall z = 0, h high; they
 * share the edge from the origin to (l, 0, 0). */
static void perpendicular_scene(char *buf, size_t n, double w, double h, double l)
{
    snprintf(buf, n,
             HEAD "quad A e 0 0 0  0 0 %.17g  %.17g 0 %.17g  %.17g 0 0\n"
                  "quad B w 0 0 0  %.17g 0 0  %.17g %.17g 0  0 %.17g 0\n",
             w, l, w, l, l, l, h, h);
}

static const double PARALLEL[][3] = {{0.37, 1.9, 0.61}, {1.3, 0.45, 2.2}, {0.083, 0.29, 0.051},
                                     {3.7, 2.9, 0.43}};
static const double PERPENDICULAR[][3] = {{0.37, 1.9, 0.61}, {1.9, 0.37, 0.61}, {0.7, 0.3, 2.3},
                                          {0.13, 2.6, 0.9}, {3.1, 2.7, 0.23}};

/* ---- analytic ----------------------------------------------------------- */

static void check_pair_rectangles(double tolerance, double bound)
{
    char buf[1024];
    for (size_t t = 0; t < sizeof PARALLEL / sizeof PARALLEL[0]; t++) {
        double a = PARALLEL[t][0], b = PARALLEL[t][1], c = PARALLEL[t][2];
        fixture f;
        parallel_scene(buf, sizeof buf, a, b, c);
        setup(&f, buf, 100, 0, (rp_ff_params){.method = RP_FF_ANALYTIC, .tolerance = tolerance});
        double ref = rp_cf_howell_parallel(a, b, c);
        double fab = surf_ff(&f, "A", "B", NULL, NULL), fba = surf_ff(&f, "B", "A", NULL, NULL);
        cr_expect(fabs(fab / ref - 1) < bound, "C-11 %g %g %g: F_AB %.12g vs %.12g (%.2e)", a, b, c,
                  fab, ref, fab / ref - 1);
        cr_expect(fabs(fba / ref - 1) < bound, "C-11 %g %g %g: F_BA %.12g vs %.12g", a, b, c, fba, ref);
        teardown(&f);
    }
    for (size_t t = 0; t < sizeof PERPENDICULAR / sizeof PERPENDICULAR[0]; t++) {
        double w = PERPENDICULAR[t][0], h = PERPENDICULAR[t][1], l = PERPENDICULAR[t][2];
        fixture f;
        perpendicular_scene(buf, sizeof buf, w, h, l);
        setup(&f, buf, 100, 0, (rp_ff_params){.method = RP_FF_ANALYTIC, .tolerance = tolerance});
        double fab = surf_ff(&f, "A", "B", NULL, NULL), fba = surf_ff(&f, "B", "A", NULL, NULL);
        double rab = rp_cf_howell_perpendicular(w, h, l), rba = rp_cf_howell_perpendicular(h, w, l);
        cr_expect(fabs(fab / rab - 1) < bound, "C-14 %g %g %g: F_AB %.12g vs %.12g (%.2e)", w, h, l,
                  fab, rab, fab / rab - 1);
        cr_expect(fabs(fba / rba - 1) < bound, "C-14 %g %g %g: F_BA %.12g vs %.12g (%.2e)", w, h, l,
                  fba, rba, fba / rba - 1);
        teardown(&f);
    }
}

Test(formfactor, closed_forms_are_right)
{
    /* The values docs/ground-truth.md quotes for its own check. */
    cr_assert(fabs(rp_cf_howell_parallel(1, 1, 1) - 0.1998248957) < 1e-10);
    cr_assert(fabs(rp_cf_howell_perpendicular(1, 1, 1) - 0.2000437761) < 1e-10);
    /* point_rect over a whole rectangle seen from below its centre
     * against the unit-square limit of C-11's integrand: as c grows the
     * point value tends to A / (pi c^2). */
    double c = 1e3;
    cr_assert(fabs(point_rect(-0.5, 0.5, -0.5, 0.5, c) * M_PI * c * c - 1) < 1e-5);
}

Test(formfactor, analytic_rectangles_match_howell_at_default_tolerance)
{
    check_pair_rectangles(0, 1e-5);
}

Test(formfactor, analytic_rectangles_converge_at_tight_tolerance)
{
    check_pair_rectangles(1e-9, 1e-8);
}

/* The same rectangles meshed into elements: adjacent and corner-touching
 * element pairs along the shared edge are the near-singular cases. */
Test(formfactor, analytic_meshed_rectangles_match_howell)
{
    char buf[1024];
    fixture f;
    perpendicular_scene(buf, sizeof buf, 0.37, 1.9, 0.61);
    setup(&f, buf, 0.17, 0, (rp_ff_params){.method = RP_FF_ANALYTIC});
    cr_assert_gt(rp_mesh_nelements(f.mesh), 20);
    double fab = surf_ff(&f, "A", "B", NULL, NULL), fba = surf_ff(&f, "B", "A", NULL, NULL);
    cr_expect(fabs(fab / rp_cf_howell_perpendicular(0.37, 1.9, 0.61) - 1) < 1e-5, "F_AB %.10g", fab);
    cr_expect(fabs(fba / rp_cf_howell_perpendicular(1.9, 0.37, 0.61) - 1) < 1e-5, "F_BA %.10g", fba);
    teardown(&f);

    parallel_scene(buf, sizeof buf, 0.37, 1.9, 0.61);
    setup(&f, buf, 0.13, 0, (rp_ff_params){.method = RP_FF_ANALYTIC});
    fab = surf_ff(&f, "A", "B", NULL, NULL);
    cr_expect(fabs(fab / rp_cf_howell_parallel(0.37, 1.9, 0.61) - 1) < 1e-5, "F_AB %.10g", fab);
    teardown(&f);
}

/* Triangles take other paths (Duffy-mapped cubature, Strang-Fix and Radon
 * rules): each rectangle given as two triangles, one pair meeting only at a
 * vertex. */
Test(formfactor, analytic_triangles_sum_to_howell)
{
    const double w = 0.37, h = 1.9, l = 0.61;
    char buf[1024];
    snprintf(buf, sizeof buf,
             HEAD "triangle A1 e 0 0 0  0 0 %.17g  %.17g 0 %.17g\n"
                  "triangle A2 e 0 0 0  %.17g 0 %.17g  %.17g 0 0\n"
                  "triangle B1 w 0 0 0  %.17g 0 0  %.17g %.17g 0\n"
                  "triangle B2 w 0 0 0  %.17g %.17g 0  0 %.17g 0\n",
             w, l, w, l, w, l, l, l, h, l, h, h);
    fixture f;
    setup(&f, buf, 100, 0, (rp_ff_params){.method = RP_FF_ANALYTIC});
    const char *A[] = {"A1", "A2", NULL}, *B[] = {"B1", "B2", NULL};
    double fab = group_ff(&f, A, B, NULL, NULL), fba = group_ff(&f, B, A, NULL, NULL);
    cr_expect(fabs(fab / rp_cf_howell_perpendicular(w, h, l) - 1) < 1e-5, "F_AB %.10g vs %.10g", fab, rp_cf_howell_perpendicular(w, h, l));
    cr_expect(fabs(fba / rp_cf_howell_perpendicular(h, w, l) - 1) < 1e-5, "F_BA %.10g vs %.10g", fba, rp_cf_howell_perpendicular(h, w, l));
    teardown(&f);
}

/* Elements cut by the other's plane: a floor strip A (z in [g, g + w])
 * and a wall B at z = 0 that reaches below the floor (y in [-0.23, h]);
 * the part of B below y = 0 is behind A and the rows of wall elements
 * straddle the floor's plane.  Howell's algebra with C-14:
 * A_A F_AB = A_(A+G) F_(A+G)B - A_G F_GB, G the floor strip between. */
Test(formfactor, analytic_clipped_pairs_match_howell_algebra)
{
    const double w = 0.37, l = 0.61, h = 1.9, g = 0.29, below = 0.23;
    char buf[1024];
    snprintf(buf, sizeof buf,
             HEAD "quad A e 0 0 %.17g  0 0 %.17g  %.17g 0 %.17g  %.17g 0 %.17g\n"
                  "quad B w 0 %.17g 0  %.17g %.17g 0  %.17g %.17g 0  0 %.17g 0\n",
             g, g + w, l, g + w, l, g, -below, l, -below, l, h, h);
    const double fab = ((w + g) * rp_cf_howell_perpendicular(w + g, h, l) - g * rp_cf_howell_perpendicular(g, h, l)) / w;
    const double fba = w * l * fab / ((h + below) * l);
    const double edges[2] = {100, 0.1};
    for (int m = 0; m < 2; m++) {
        fixture f;
        setup(&f, buf, edges[m], 0, (rp_ff_params){.method = RP_FF_ANALYTIC});
        double ab = surf_ff(&f, "A", "B", NULL, NULL), ba = surf_ff(&f, "B", "A", NULL, NULL);
        cr_expect(fabs(ab / fab - 1) < 1e-5, "max edge %g: F_AB %.10g vs %.10g (%.2e)", edges[m], ab,
                  fab, ab / fab - 1);
        cr_expect(fabs(ba / fba - 1) < 1e-5, "max edge %g: F_BA %.10g vs %.10g (%.2e)", edges[m], ba,
                  fba, ba / fba - 1);
        teardown(&f);
    }
}

/* A closed box of odd proportions meshed into 136 elements: every row sums
 * to 1 and A_i F_ij = A_j F_ji.  Edge-adjacent pairs across the box's edges
 * dominate both errors. */
static void check_box(double tolerance, double closure, double reciprocity)
{
    fixture f;
    setup(&f, HEAD "box room e 0 0 0  0.37 1.9 0.61 inward\n", 0.2, 0,
          (rp_ff_params){.method = RP_FF_ANALYTIC, .tolerance = tolerance});
    size_t n = rp_mesh_nelements(f.mesh);
    cr_assert_eq(n, 136);
    const rp_element *E = rp_mesh_elements(f.mesh);
    float *F = malloc(n * n * sizeof *F);
    double rays = 0, worst_sum = 0, worst_rec = 0;
    for (size_t i = 0; i < n; i++) {
        rp_ff_row(f.ctx, f.scratch, (uint32_t)i, F + i * n, &rays);
        double s = 0;
        for (size_t j = 0; j < n; j++)
            s += F[i * n + j];
        worst_sum = fmax(worst_sum, fabs(s - 1));
    }
    /* Rows are float: about 6e-8 relative rounding per entry. */
    for (size_t i = 0; i < n; i++)
        for (size_t j = i + 1; j < n; j++) {
            double a = E[i].area * F[i * n + j], b = E[j].area * F[j * n + i];
            if (a > 0 || b > 0)
                worst_rec = fmax(worst_rec, fabs(a - b) / fmax(a, b));
        }
    cr_log_info("box, tolerance %g: worst |row sum - 1| %.3g, worst reciprocity %.3g", tolerance,
                worst_sum, worst_rec);
    cr_expect(worst_sum < closure, "row sums off by %.3g", worst_sum);
    cr_expect(worst_rec < reciprocity, "reciprocity off by %.3g", worst_rec);
    cr_expect_eq(rays, 0, "no visibility rays without a ray caster");
    free(F);
    teardown(&f);
}

Test(formfactor, analytic_closed_box_default_tolerance)
{
    /* Per-pair errors of at most 1e-5 relative add up to at most 1e-5. */
    check_box(0, 1e-5, 2e-5);
}

Test(formfactor, analytic_closed_box_closure_and_reciprocity)
{
    check_box(1e-7, 1e-6, 1e-6);
}

/* docs/ground-truth.md: the Cornell box's light to the walls, ignoring the
 * blocks (no ray caster), one element per face. */
Test(formfactor, cornell_light_unoccluded)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/scenes/cornell.scene", RP_SOURCE_DIR);
    fixture f;
    memset(&f, 0, sizeof f);
    rp_error err = {""};
    cr_assert_eq(rp_scene_load(path, &f.scene, &err), RP_OK, "%s", err.message);
    rp_mesh_params mp = {.size = sizeof mp, .max_edge = rp_scene_diagonal(f.scene)};
    cr_assert_eq(rp_mesh_create(f.scene, &mp, &f.mesh, &err), RP_OK, "%s", err.message);
    rp_ff_params p = {.size = sizeof p, .method = RP_FF_ANALYTIC, .tolerance = 1e-9};
    cr_assert_eq(rp_ff_context_create(f.scene, f.mesh, NULL, &p, &f.ctx, &err), RP_OK);
    cr_assert_eq(rp_ff_scratch_create(f.ctx, &f.scratch, &err), RP_OK);
    const char *light[] = {"light", NULL}, *floor_[] = {"floor", NULL}, *back[] = {"back", NULL};
    const char *red[] = {"left-red-low", "left-red-high", NULL}, *green[] = {"right-green", NULL};
    /* Quoted to 6 digits: half a unit in the last is < 3e-6 relative. */
    double got[4] = {group_ff(&f, light, floor_, NULL, NULL), group_ff(&f, light, back, NULL, NULL),
                     group_ff(&f, light, red, NULL, NULL), group_ff(&f, light, green, NULL, NULL)};
    const double want[4] = {0.241536, 0.187096, 0.193177, 0.190639};
    for (int k = 0; k < 4; k++)
        cr_expect(fabs(got[k] / want[k] - 1) < 3e-6, "light -> wall %d: %.8f vs %.6f", k, got[k],
                  want[k]);
    teardown(&f);
}

/* ---- visibility --------------------------------------------------------- */

Test(formfactor, visibility_blocker_and_bystander)
{
    const double a = 0.37, b = 1.9, c = 0.61;
    char buf[2048];
    /* A plate between A and B, wider than both: nothing gets through. */
    snprintf(buf, sizeof buf,
             HEAD "quad A e 0 0 0  0 0 %.17g  %.17g 0 %.17g  %.17g 0 0\n"
                  "quad B w 0 %.17g 0  %.17g %.17g 0  %.17g %.17g %.17g  0 %.17g %.17g\n"
                  "quad M w -1 0.3 -1  3 0.3 -1  3 0.3 4  -1 0.3 4\n",
             b, a, b, a, c, a, c, a, c, b, c, b);
    for (int m = 0; m < 2; m++) {
        fixture f;
        setup(&f, buf, 100, 1,
              (rp_ff_params){.method = m ? RP_FF_MONTECARLO : RP_FF_ANALYTIC, .samples = 1000, .seed = 3});
        double rays = 0;
        cr_expect_eq(surf_ff(&f, "A", "B", NULL, &rays), 0.0, "%s through a wall",
                     rp_ff_method_name((rp_ff_method)m));
        cr_expect_gt(rays, 0);
        teardown(&f);
    }
    /* A bystander beside the pair (outside the hull of A and B) cannot
     * block: no ray is cast and the answer is Howell's. */
    snprintf(buf, sizeof buf,
             HEAD "quad A e 0 0 0  0 0 %.17g  %.17g 0 %.17g  %.17g 0 0\n"
                  "quad B w 0 %.17g 0  %.17g %.17g 0  %.17g %.17g %.17g  0 %.17g %.17g\n"
                  "quad M w 2 0.1 0  2 0.1 1  2 0.5 1  2 0.5 0\n",
             b, a, b, a, c, a, c, a, c, b, c, b);
    fixture f;
    setup(&f, buf, 100, 1, (rp_ff_params){.method = RP_FF_ANALYTIC});
    double rays = 0;
    double fab = surf_ff(&f, "A", "B", NULL, &rays);
    cr_expect_eq(rays, 0, "%g rays cast for an unblockable pair", rays);
    cr_expect(fabs(fab / rp_cf_howell_parallel(a, b, c) - 1) < 1e-5, "F_AB %.10g", fab);
    teardown(&f);
}

/* A partly occluded scene meshed into elements: a row is the same whether
 * computed first or after every other row (the visibility cache is shared
 * between rows), and visibility obeys reciprocity exactly. */
Test(formfactor, rows_do_not_depend_on_order)
{
    const char *scene = HEAD "box room e 0 0 0  1 1 1 inward\n"
                             "box block w 0.3 0 0.3  0.6 0.45 0.7 outward\n";
    fixture f, g;
    rp_ff_params p = {.method = RP_FF_ANALYTIC, .seed = 11};
    setup(&f, scene, 0.25, 1, p);
    setup(&g, scene, 0.25, 1, p);
    size_t n = rp_mesh_nelements(f.mesh);
    float *r1 = malloc(n * sizeof *r1), *r2 = malloc(n * sizeof *r2);
    const uint32_t probe = (uint32_t)(n / 3);
    double rays = 0;
    rp_ff_row(f.ctx, f.scratch, probe, r1, &rays);
    cr_expect_gt(rays, 0, "the block should cost rays");
    for (size_t i = n; i-- > 0;)
        rp_ff_row(g.ctx, g.scratch, (uint32_t)i, r2, NULL);
    rp_ff_row(g.ctx, g.scratch, probe, r2, NULL);
    cr_expect_eq(memcmp(r1, r2, n * sizeof *r1), 0, "row %u differs with the order of rows", probe);
    const rp_element *E = rp_mesh_elements(f.mesh);
    for (uint32_t j = 0; j < n; j++) {
        double a = E[probe].area * rp_ff_pair(f.ctx, f.scratch, probe, j, NULL, NULL);
        double b = E[j].area * rp_ff_pair(f.ctx, f.scratch, j, probe, NULL, NULL);
        cr_expect(fabs(a - b) <= 2e-5 * fmax(a, b), "reciprocity %u %u: %g vs %g", probe, j, a, b);
    }
    free(r1);
    free(r2);
    teardown(&f);
    teardown(&g);
}

/* ---- Monte Carlo -------------------------------------------------------- */

Test(formfactor, montecarlo_within_three_standard_errors)
{
    char buf[1024];
    for (size_t t = 0; t < sizeof PARALLEL / sizeof PARALLEL[0]; t++) {
        double a = PARALLEL[t][0], b = PARALLEL[t][1], c = PARALLEL[t][2];
        fixture f;
        parallel_scene(buf, sizeof buf, a, b, c);
        setup(&f, buf, 100, 1, (rp_ff_params){.method = RP_FF_MONTECARLO, .samples = 100000, .seed = 5});
        double se = 0, fab = surf_ff(&f, "A", "B", &se, NULL), ref = rp_cf_howell_parallel(a, b, c);
        cr_expect(se > 0 && se < 0.05 * ref, "standard error %g", se);
        cr_expect(fabs(fab - ref) < 3 * se, "C-11 %g %g %g: %.6f +- %.2g vs %.6f", a, b, c, fab, se, ref);
        teardown(&f);
    }
}

Test(formfactor, montecarlo_standard_error_is_honest)
{
    /* z = (F - exact) / se over 20 seeds: sum z^2 ~ chi-square(20), whose
     * 0.1% and 99.9% points are 6.0 and 45.3. */
    char buf[1024];
    parallel_scene(buf, sizeof buf, 0.37, 1.9, 0.61);
    const double ref = rp_cf_howell_parallel(0.37, 1.9, 0.61);
    double chi2 = 0;
    for (int seed = 0; seed < 20; seed++) {
        fixture f;
        setup(&f, buf, 100, 0, (rp_ff_params){.method = RP_FF_MONTECARLO, .samples = 2000, .seed = seed});
        double se = 0, F = surf_ff(&f, "A", "B", &se, NULL);
        chi2 += (F - ref) * (F - ref) / (se * se);
        teardown(&f);
    }
    cr_expect(chi2 > 6.0 && chi2 < 45.3, "sum of z^2 over 20 seeds %.2f", chi2);
}

Test(formfactor, montecarlo_reciprocity_is_exact)
{
    char buf[1024];
    perpendicular_scene(buf, sizeof buf, 0.37, 1.9, 0.61);
    fixture f;
    setup(&f, buf, 0.3, 0, (rp_ff_params){.method = RP_FF_MONTECARLO, .samples = 500, .seed = 9});
    const rp_element *E = rp_mesh_elements(f.mesh);
    size_t n = rp_mesh_nelements(f.mesh);
    for (uint32_t i = 0; i < n; i++)
        for (uint32_t j = 0; j < n; j++) {
            double a = E[i].area * rp_ff_pair(f.ctx, f.scratch, i, j, NULL, NULL);
            double b = E[j].area * rp_ff_pair(f.ctx, f.scratch, j, i, NULL, NULL);
            cr_expect(fabs(a - b) <= 1e-12 * fmax(a, b), "%u %u: %g vs %g", i, j, a, b);
        }
    teardown(&f);
}

/* ---- hemicube ----------------------------------------------------------- */

Test(formfactor, hemicube_closed_box_rows_sum_to_one)
{
    fixture f;
    setup(&f, HEAD "box room e 0 0 0  0.37 1.9 0.61 inward\n", 0.2, 0,
          (rp_ff_params){.method = RP_FF_HEMICUBE, .resolution = 64});
    size_t n = rp_mesh_nelements(f.mesh);
    float *row = malloc(n * sizeof *row);
    double worst = 0;
    for (size_t i = 0; i < n; i++) {
        rp_ff_row(f.ctx, f.scratch, (uint32_t)i, row, NULL);
        double s = 0;
        for (size_t j = 0; j < n; j++)
            s += row[j];
        worst = fmax(worst, fabs(s - 1));
        cr_expect_eq(row[i], 0.0f);
    }
    /* Exact pixel delta form factors sum to 1; every pixel sees a wall. */
    cr_expect(worst < 1e-6, "hemicube row sums off by %.3g", worst);
    free(row);
    teardown(&f);
}

/* The hemicube's own error: at each receiver element's centroid it should
 * give the point-to-rectangle form factor (point_rect); B is turned
 * 0.3 rad in its plane so its edges cross the pixel grid at an angle. */
static double hemicube_point_error(unsigned res)
{
    const double a = 0.8, b = 0.5, c = 0.45, th = 0.3, x0 = 0.2, z0 = 0.25;
    const double ca = cos(th), sa = sin(th);
    /* B's corners: x0 + R(th) (u, v), in its plane y = c, facing down. */
    double P[4][2] = {{0, 0}, {a, 0}, {a, b}, {0, b}};
    char buf[2048];
    int k = snprintf(buf, sizeof buf, HEAD "quad A e 0 0 0  0 0 1  1 0 1  1 0 0\nquad B w");
    for (int q = 0; q < 4; q++)
        k += snprintf(buf + k, sizeof buf - (size_t)k, "  %.17g %.17g %.17g",
                      x0 + ca * P[q][0] - sa * P[q][1], c, z0 + sa * P[q][0] + ca * P[q][1]);
    snprintf(buf + k, sizeof buf - (size_t)k, "\n");
    fixture f;
    setup(&f, buf, 0.2, 0, (rp_ff_params){.method = RP_FF_HEMICUBE, .resolution = res});
    const rp_element *E = rp_mesh_elements(f.mesh);
    uint32_t a0, na, b0, nb;
    rp_mesh_surface_elements(f.mesh, surface(&f, "A"), &a0, &na);
    rp_mesh_surface_elements(f.mesh, surface(&f, "B"), &b0, &nb);
    double worst = 0;
    for (uint32_t i = a0; i < a0 + na; i++) {
        double hc = 0;
        for (uint32_t j = b0; j < b0 + nb; j++)
            hc += rp_ff_pair(f.ctx, f.scratch, i, j, NULL, NULL);
        /* The centroid in B's axes. */
        double dx = E[i].centroid.x - x0, dz = E[i].centroid.z - z0;
        double u = ca * dx + sa * dz, v = -sa * dx + ca * dz;
        double exact = point_rect(-u, a - u, -v, b - v, c);
        worst = fmax(worst, fabs(hc - exact));
    }
    teardown(&f);
    return worst;
}

Test(formfactor, hemicube_error_falls_with_resolution)
{
    double e64 = hemicube_point_error(64), e512 = hemicube_point_error(512);
    cr_log_info("hemicube worst error at element centroids: %.3g at 64, %.3g at 512", e64, e512);
    cr_expect(e512 < e64, "error %.3g at 512 is not below %.3g at 64", e512, e64);
    /* A pixel row of the top face near the zenith holds about 4/(pi R) of
     * the hemisphere: bounds of a few such rows along the footprint. */
    cr_expect(e64 < 2e-3, "error at 64: %.3g", e64);
    cr_expect(e512 < 2e-4, "error at 512: %.3g", e512);

    /* Against Howell: the receiver meshed (the centroid rule's error adds
     * to aliasing). */
    char buf[1024];
    parallel_scene(buf, sizeof buf, 0.37, 1.9, 0.61);
    const double ref = rp_cf_howell_parallel(0.37, 1.9, 0.61);
    double err[2];
    const unsigned res[2] = {64, 512};
    for (int r = 0; r < 2; r++) {
        fixture f;
        setup(&f, buf, 0.1, 0, (rp_ff_params){.method = RP_FF_HEMICUBE, .resolution = res[r]});
        err[r] = surf_ff(&f, "A", "B", NULL, NULL) / ref - 1;
        teardown(&f);
    }
    cr_log_info("hemicube vs C-11 (receiver meshed at 0.1): %.3g at 64, %.3g at 512", err[0], err[1]);
    cr_expect(fabs(err[0]) < 2e-2 && fabs(err[1]) < 5e-3, "hemicube vs C-11: %.3g, %.3g", err[0], err[1]);
}

/* ---- parameters --------------------------------------------------------- */

Test(formfactor, bad_parameters_are_refused)
{
    rp_ff_method m;
    rp_error err = {""};
    cr_expect_eq(rp_ff_method_parse("hemicube", &m, &err), RP_OK);
    cr_expect_eq(m, RP_FF_HEMICUBE);
    cr_expect_eq(rp_ff_method_parse("radiosity", &m, &err), RP_ERR_INPUT);
    cr_expect(strstr(err.message, "radiosity") != NULL, "%s", err.message);

    rp_scene *s = NULL;
    cr_assert_eq(rp_scene_parse(HEAD "quad A e 0 0 0  0 0 1  1 0 1  1 0 0\n", "p", NULL, &s, &err), RP_OK);
    rp_mesh *mesh = NULL;
    rp_mesh_params mp = {.size = sizeof mp};
    cr_assert_eq(rp_mesh_create(s, &mp, &mesh, &err), RP_OK);
    rp_ff_context *ctx = NULL;
    rp_ff_params p = {.size = sizeof p, .method = RP_FF_HEMICUBE, .resolution = 63};
    cr_expect_eq(rp_ff_context_create(s, mesh, NULL, &p, &ctx, &err), RP_ERR_INPUT);
    cr_expect_null(ctx);
    p = (rp_ff_params){.size = sizeof p, .method = RP_FF_ANALYTIC, .tolerance = 0.5};
    cr_expect_eq(rp_ff_context_create(s, mesh, NULL, &p, &ctx, &err), RP_ERR_INPUT);
    p = (rp_ff_params){.size = sizeof p, .method = RP_FF_ANALYTIC};
    cr_expect_eq(rp_ff_context_create(s, mesh, NULL, &p, &ctx, &err), RP_OK);
    rp_ff_params used;
    rp_ff_context_params(ctx, &used);
    cr_expect_eq(used.tolerance, RP_FF_DEFAULT_TOLERANCE);
    rp_ff_context_destroy(ctx);
    rp_ff_context_destroy(NULL);
    rp_ff_scratch_destroy(NULL);
    rp_mesh_destroy(mesh);
    rp_scene_destroy(s);
}

/* ---- radpt formfactor --------------------------------------------------- */

Test(formfactor, command_json_and_errors)
{
    rp_run r = rp_run_radpt("formfactor scenes/plates-parallel.scene --from emitter --to receiver --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    double F = rp_json_number_after(r.out, "{", "form_factor");
    cr_expect(fabs(F / 0.1998248957 - 1) < 1e-5, "F %.10g\n%s", F, r.out);
    cr_expect_eq(rp_json_number_after(r.out, "{", "elements_from"), 1);
    cr_expect_eq(rp_count_lines(r.out), 1);
    rp_run_free(&r);

    r = rp_run_radpt("formfactor scenes/plates-perpendicular.scene --from receiver --to emitter "
                     "--method montecarlo --samples 40000 --seed 4 --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    F = rp_json_number_after(r.out, "{", "form_factor");
    double se = rp_json_number_after(r.out, "{", "stderr");
    cr_expect(se > 0 && se < 0.01, "stderr %g", se);
    /* Adjacent squares: the estimator's variance is infinite, so only a
     * loose check. */
    cr_expect(fabs(F - 0.2000437761) < 0.02, "F %g", F);
    rp_run_free(&r);

    r = rp_run_radpt("formfactor scenes/plates-parallel.scene --from emitter --to receivr");
    cr_expect_eq(r.status, 2);
    cr_expect(strstr(r.err, "receivr") != NULL, "stderr: %s", r.err);
    rp_run_free(&r);

    r = rp_run_radpt("formfactor scenes/plates-parallel.scene --from emitter --to receiver "
                     "--method hemicube --resolution 63");
    cr_expect_eq(r.status, 2, "stderr: %s", r.err);
    rp_run_free(&r);

    r = rp_run_radpt("formfactor scenes/plates-parallel.scene --from emitter --to receiver --method foo");
    cr_expect_eq(r.status, 2, "stderr: %s", r.err);
    rp_run_free(&r);
}

/* ---- near contacts (issue 13, part 4) ----------------------------------- */

/* Directly opposed plates 1e-3 apart, meshed: element pairs face each other
 * at a gap of 1% of their size, where a point or centre rule is unbounded.
 * The plates' form factor against C-11 (1e-5 relative, the default goal),
 * and no row above 1 by more than the goal (no ray caster: nothing to
 * block). */
Test(formfactor, nearly_touching_plates_match_howell)
{
    const double a = 0.37, b = 1.9, c = 1e-3;
    char buf[1024];
    parallel_scene(buf, sizeof buf, a, b, c);
    fixture f;
    setup(&f, buf, 0.12, 0, (rp_ff_params){.method = RP_FF_ANALYTIC});
    size_t n = rp_mesh_nelements(f.mesh);
    cr_assert_gt(n, 100);
    double fab = surf_ff(&f, "A", "B", NULL, NULL), ref = rp_cf_howell_parallel(a, b, c);
    cr_expect(fabs(fab / ref - 1) < 1e-5, "F_AB %.10g vs C-11 %.10g (%.2e)", fab, ref, fab / ref - 1);
    float *row = malloc(n * sizeof *row);
    double worst = 0;
    for (size_t i = 0; i < n; i++) {
        rp_ff_row(f.ctx, f.scratch, (uint32_t)i, row, NULL);
        double s = 0;
        for (size_t j = 0; j < n; j++)
            s += row[j];
        worst = fmax(worst, s);
    }
    cr_expect(worst < 1 + 1e-5, "a row sums to %.9g", worst);
    free(row);
    teardown(&f);
}

/* Visibility near a contact, with elements of very unequal sizes: a closed
 * room whose walls are one element each (or 2 x 2) around a 0.3 cube
 * standing 1e-3 above the floor (tests/data/cube.off).  Every pair seen
 * past the cube is partly occluded and the room's elements are large
 * against their distances, where the old estimate (the fraction of open
 * rays between uniform points, times the unoccluded F) put rows at up to
 * 1.13 (mean |sum - 1| 0.019).  The room is closed: each row must sum to 1.
 * Bounds: every row within RP_RAD_ROW_SUM_TOL (0.02; none would be
 * scaled), the mean within 0.004, for four seeds (measured: worst 0.012,
 * mean 0.003 at most). */
Test(formfactor, visibility_closes_rows_near_a_contact)
{
    char buf[1024];
    snprintf(buf, sizeof buf,
             HEAD "box room e 0 0 0  1 1 1 inward\n"
                  "mesh cube w %s/tests/data/cube.off scale 0.3 translate 0.35 0.001 0.35\n",
             RP_SOURCE_DIR);
    const double edges[2] = {10, 0.5};
    for (int m = 0; m < 2; m++)
        for (uint64_t seed = 1; seed <= 4; seed++) {
            fixture f;
            setup(&f, buf, edges[m], 1, (rp_ff_params){.method = RP_FF_ANALYTIC, .seed = seed});
            size_t n = rp_mesh_nelements(f.mesh);
            float *row = malloc(n * sizeof *row);
            double worst = 0, mean = 0, rays = 0;
            for (size_t i = 0; i < n; i++) {
                rp_ff_row(f.ctx, f.scratch, (uint32_t)i, row, &rays);
                double s = 0;
                for (size_t j = 0; j < n; j++)
                    s += row[j];
                worst = fmax(worst, fabs(s - 1));
                mean += fabs(s - 1) / (double)n;
            }
            cr_log_info("closed room, max edge %g, seed %llu: %zu elements, %.0f rays, mean |sum - 1| %.3g, worst %.3g",
                        edges[m], (unsigned long long)seed, n, rays, mean, worst);
            cr_expect(worst < 0.02, "max edge %g seed %llu: a row off by %.3g", edges[m], (unsigned long long)seed,
                      worst);
            cr_expect(mean < 0.004, "max edge %g seed %llu: mean |sum - 1| %.3g", edges[m],
                      (unsigned long long)seed, mean);
            free(row);
            teardown(&f);
        }
}
