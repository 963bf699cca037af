/* Scale independence (issue 13): no tolerance, offset or element budget may
 * depend on the scene's overall size or units.  The Cornell box
 * (scenes/cornell.scene, millimetres) is solved alone and with a black
 * ground plane (reflect 0, no emission, facing up, 1 mm below the floor,
 * centred under the box) 1 km (1e6 mm) and 100 km (1e8 mm) wide.  Black,
 * the plane cannot change what the box's surfaces see, so the check values
 * are the plain box's own answers, from the same method:
 *   - path tracer (4096 probe points per surface): every surface and band
 *     within 4 combined standard errors, sqrt(se_a^2 + se_b^2);
 *   - hierarchical radiosity (bf-epsilon 0.05, min-area 1e-4, the fast
 *     benchmark's settings) and Gauss-Seidel at its default budget (1000
 *     elements): within 1%.
 * Before the change the plane moved the path tracer by 8 (1 km) and 480
 * (100 km) standard errors, hierarchical radiosity by +93% and -99.8%,
 * and Gauss-Seidel by +56% (1 km; at 100 km it refused the scene). */
#include <criterion/criterion.h>

#include <gsl/gsl_errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/scene.h"
#include "solvers/solver.h"
#include "scene_util.h"

static void ssetup(void) { gsl_set_error_handler_off(); }

/* The Cornell box, with a black plane `width` wide when width > 0. */
static rp_scene *cornell_with_plane(double width)
{
    char text[1024];
    int n = snprintf(text, sizeof text, "include cornell.scene\n");
    if (width > 0) {
        const double h = 0.5 * width, cx = 278, cz = 280;
        snprintf(text + n, sizeof text - n,
                 "material black reflect 0\n"
                 "quad ground black %.17g -1 %.17g  %.17g -1 %.17g  %.17g -1 %.17g  %.17g -1 %.17g\n",
                 cx - h, cz - h, cx - h, cz + h, cx + h, cz + h, cx + h, cz - h);
    }
    return rp_test_parse_in(text, RP_SOURCE_DIR "/scenes");
}

/* Surface averages (and standard errors) of one method, run to its own
 * stopping rule.  Options as "key", "value" pairs, NULL-terminated. */
static void solve(const rp_scene *scene, const char *method, const char *const *kv, double *L, double *se)
{
    const char *keys[8], *vals[8];
    size_t n = 0;
    for (; kv && kv[2 * n]; n++) {
        keys[n] = kv[2 * n];
        vals[n] = kv[2 * n + 1];
    }
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .seed = 3, .keys = keys, .values = vals, .count = n};
    const rp_solver_type *type = rp_solver_lookup(method);
    cr_assert_not_null(type, "%s", method);
    rp_solver *s = NULL;
    rp_error err = {""};
    cr_assert_eq(rp_solver_create(type, scene, &o, &s, &err), RP_OK, "%s: %s", method, err.message);
    for (int k = 0;; k++) {
        rp_step_info info;
        memset(&info, 0, sizeof info);
        cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK, "%s: %s", method, err.message);
        if (info.converged)
            break;
        cr_assert_lt(k, 100000, "%s did not converge", method);
    }
    rp_estimate e = {.surface_radiance = L, .surface_stderr = se};
    cr_assert_eq(rp_solver_estimate(s, &e, &err), RP_OK, "%s: %s", method, err.message);
    rp_solver_destroy(s);
}

/* The box's surfaces, alone and beside planes 1e6 and 1e8 wide: every
 * value within tol_rel relative, or (se != 0) within 4 combined standard
 * errors. */
static void check(const char *method, const char *const *kv, double tol_rel, int monte_carlo)
{
    rp_scene *plain = cornell_with_plane(0);
    const size_t ns = rp_scene_nsurfaces(plain), nb = rp_scene_nbands(plain);
    const rp_surface *surf = rp_scene_surfaces(plain);
    double *L0 = calloc((ns + 1) * nb, sizeof *L0), *s0 = calloc((ns + 1) * nb, sizeof *s0);
    double *L1 = calloc((ns + 1) * nb, sizeof *L1), *s1 = calloc((ns + 1) * nb, sizeof *s1);
    cr_assert(L0 && s0 && L1 && s1);
    solve(plain, method, kv, L0, s0);
    static const double widths[2] = {1e6, 1e8};
    for (int w = 0; w < 2; w++) {
        rp_scene *scene = cornell_with_plane(widths[w]);
        cr_assert_eq(rp_scene_nsurfaces(scene), ns + 1);
        solve(scene, method, kv, L1, s1);
        double worst = 0;
        for (size_t i = 0; i < ns; i++) {
            cr_assert_str_eq(rp_scene_surfaces(scene)[i].name, surf[i].name);
            for (size_t b = 0; b < nb; b++) {
                double a = L0[i * nb + b], c = L1[i * nb + b];
                cr_assert(isfinite(c), "%s, plane %g: %s band %zu is %g", method, widths[w], surf[i].name, b, c);
                if (monte_carlo) {
                    double se = sqrt(s0[i * nb + b] * s0[i * nb + b] + s1[i * nb + b] * s1[i * nb + b]);
                    cr_expect_leq(fabs(c - a), 4 * se, "%s, plane %g: %s band %zu: %.6g vs %.6g (combined SE %.3g)",
                                  method, widths[w], surf[i].name, b, c, a, se);
                    if (se > 0)
                        worst = fmax(worst, fabs(c - a) / se);
                } else {
                    cr_expect_leq(fabs(c - a), tol_rel * fabs(a), "%s, plane %g: %s band %zu: %.6g vs %.6g", method,
                                  widths[w], surf[i].name, b, c, a);
                    if (a != 0)
                        worst = fmax(worst, fabs(c - a) / fabs(a));
                }
            }
        }
        cr_log_info("%s, black plane %g wide: worst deviation %g %s", method, widths[w], worst,
                    monte_carlo ? "combined SE" : "relative");
        rp_scene_destroy(scene);
    }
    free(L0);
    free(s0);
    free(L1);
    free(s1);
    rp_scene_destroy(plain);
}

Test(scale, black_plane_pathtrace, .init = ssetup, .timeout = 120)
{
    const char *kv[] = {"samples", "4096", "batch", "4096", NULL};
    check("pathtrace", kv, 0, 1);
}

Test(scale, black_plane_hierarchical, .init = ssetup, .timeout = 300)
{
    const char *kv[] = {"bf-epsilon", "0.05", "min-area", "1e-4", NULL};
    check("hierarchical", kv, 0.01, 0);
}

Test(scale, black_plane_gauss_seidel_default_budget, .init = ssetup, .timeout = 300)
{
    check("gauss-seidel", NULL, 0.01, 0);
}
