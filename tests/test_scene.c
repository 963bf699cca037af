/* The scene reader (geometry/scene.c) against hand computation: areas by the
 * shoelace formula and Heron's formula (not the cross products scene.c
 * uses), normals worked out by hand, spectra integrated by hand, and every
 * malformed scene in tests/bad/ refused with "FILE:LINE: ...". */
#include <criterion/criterion.h>

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/default_camera.h"
#include "geometry/scene.h"

#ifndef RP_SOURCE_DIR
#define RP_SOURCE_DIR "."
#endif

#define PI 3.14159265358979323846

static rp_scene *parse_ok(const char *text)
{
    rp_scene *s = NULL;
    rp_error err = {{0}};
    rp_status st = rp_scene_parse(text, "test.scene", NULL, &s, &err);
    cr_assert_eq(st, RP_OK, "parse failed: %s", err.message);
    cr_assert_not_null(s);
    return s;
}

static rp_scene *load_ok(const char *rel)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", RP_SOURCE_DIR, rel);
    rp_scene *s = NULL;
    rp_error err = {{0}};
    rp_status st = rp_scene_load(path, &s, &err);
    cr_assert_eq(st, RP_OK, "load %s failed: %s", rel, err.message);
    cr_assert_not_null(s);
    return s;
}

/* Parses text expecting RP_ERR_INPUT and a message starting with prefix. */
static void parse_bad(const char *text, const char *prefix)
{
    rp_scene *s = (rp_scene *)1;
    rp_error err = {{0}};
    rp_status st = rp_scene_parse(text, "test.scene", NULL, &s, &err);
    cr_assert_eq(st, RP_ERR_INPUT, "expected a refusal, got %d (%s)", st, err.message);
    cr_assert_null(s);
    cr_assert(strncmp(err.message, prefix, strlen(prefix)) == 0, "message '%s' does not start with '%s'",
              err.message, prefix);
}

static const rp_surface *surface(const rp_scene *s, const char *name)
{
    uint32_t i = rp_scene_find_surface(s, name);
    cr_assert_neq(i, RP_NONE, "no surface '%s'", name);
    return &rp_scene_surfaces(s)[i];
}

static const rp_face *first_face(const rp_scene *s, const char *name)
{
    return &rp_scene_faces(s)[surface(s, name)->first_face];
}

static void assert_rel(double got, double want, double tol, const char *what)
{
    cr_assert(fabs(got - want) <= tol * fabs(want), "%s: got %.15g, want %.15g (rel tol %g)", what, got, want, tol);
}

/* Shoelace area of a polygon given as (a, b) pairs in its own plane. */
static double shoelace(const double *ab, int n)
{
    double sum = 0;
    for (int i = 0; i < n; i++) {
        int j = (i + 1) % n;
        sum += ab[2 * i] * ab[2 * j + 1] - ab[2 * j] * ab[2 * i + 1];
    }
    return 0.5 * fabs(sum);
}

/* Heron's formula from the three side lengths. */
static double heron(const double *p, const double *q, const double *r)
{
    double a = hypot(hypot(p[0] - q[0], p[1] - q[1]), p[2] - q[2]);
    double b = hypot(hypot(q[0] - r[0], q[1] - r[1]), q[2] - r[2]);
    double c = hypot(hypot(r[0] - p[0], r[1] - p[1]), r[2] - p[2]);
    double s = 0.5 * (a + b + c);
    return sqrt(s * (s - a) * (s - b) * (s - c));
}

/* ------------------------------------------------------------ parsing */

Test(scene, minimal_rgb)
{
    rp_scene *s = parse_ok("bands rgb\n"
                           "material lamp reflect 0 emit 1 2 3\n"
                           "material white reflect 0.25 0.5 0.75  # per band\n"
                           "# a comment line\n"
                           "\n"
                           "quad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\n"
                           "triangle t white  0 0 0  0 0 2  3 0 0\n");
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_RGB);
    cr_assert_eq(rp_scene_nbands(s), 3);
    cr_assert_null(rp_scene_wavelengths(s));
    cr_assert_eq(rp_scene_nmaterials(s), 2);
    cr_assert_eq(rp_scene_nsurfaces(s), 2);
    cr_assert_eq(rp_scene_nfaces(s), 2);
    cr_assert_eq(rp_scene_nvertices(s), 7);
    cr_assert_null(rp_scene_camera(s));
    const rp_material *m = rp_scene_materials(s);
    cr_assert_str_eq(m[1].name, "white");
    cr_assert_eq(m[1].rho[0], 0.25);
    cr_assert_eq(m[1].rho[2], 0.75);
    cr_assert_eq(m[0].Le[1], 2.0);
    cr_assert(m[0].emitter && !m[1].emitter);
    /* Light: (v1 - v0) x (v3 - v0) = (1,0,0) x (0,0,1) = (0,-1,0), area 1. */
    const rp_face *f = first_face(s, "light");
    cr_assert_eq(f->nverts, 4);
    cr_assert_float_eq(f->normal.y, -1.0, 1e-15);
    cr_assert_float_eq(f->area, 1.0, 1e-15);
    /* Triangle: (0,0,2) x (3,0,0) = (0, 6, 0): normal +y, area 3. */
    f = first_face(s, "t");
    cr_assert_eq(f->nverts, 3);
    cr_assert_eq(f->v[3], RP_NONE);
    cr_assert_float_eq(f->normal.y, 1.0, 1e-15);
    cr_assert_float_eq(f->area, 3.0, 1e-15);
    cr_assert_float_eq(rp_scene_total_area(s), 4.0, 1e-14);
    cr_assert_eq(rp_scene_face_material(s, 1), &m[1]);
    cr_assert_eq(surface(s, "t")->line, 7);
    cr_assert_str_eq(surface(s, "t")->file, "test.scene");
    /* Bounds (0,0,0)-(3,1,2), diagonal sqrt(14). */
    rp_vec3 lo, hi;
    rp_scene_bounds(s, &lo, &hi);
    cr_assert(lo.x == 0 && lo.y == 0 && lo.z == 0 && hi.x == 3 && hi.y == 1 && hi.z == 2);
    cr_assert_float_eq(rp_scene_diagonal(s), sqrt(14.0), 1e-15);
    cr_assert_eq(rp_scene_find_surface(s, "nope"), RP_NONE);
    rp_scene_destroy(s);
    rp_scene_destroy(NULL);
}

Test(scene, grey_default_and_numbers)
{
    /* No bands statement: grey.  Numbers in every strtod spelling radpt
     * accepts: signs, exponents, leading dots. */
    rp_scene *s = parse_ok("material lamp emit 1e0\n"
                           "quad light lamp  +0 .1e1 0  1 1 0  1.0 1 1E0  -0.0 1 1\n");
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_GREY);
    cr_assert_eq(rp_scene_nbands(s), 1);
    cr_assert_eq(rp_scene_materials(s)[0].rho[0], 0.0);
    cr_assert_float_eq(rp_scene_faces(s)[0].area, 1.0, 1e-15);
    rp_scene_destroy(s);
}

Test(scene, camera)
{
    rp_scene *s = load_ok("scenes/cornell.scene");
    const rp_camera *c = rp_scene_camera(s);
    cr_assert_not_null(c);
    cr_assert(c->eye.x == 278 && c->eye.y == 273 && c->eye.z == -800);
    cr_assert(c->look.x == 278 && c->look.y == 273 && c->look.z == 0);
    cr_assert(c->up.x == 0 && c->up.y == 1 && c->up.z == 0);
    /* 35 mm lens, 25 mm film: 2 atan(12.5 / 35) = 39.30776 degrees; the
     * file rounds to 4 decimals. */
    cr_assert_float_eq(c->fov_deg, 2 * atan(12.5 / 35) * 180 / PI, 1e-4);
    cr_assert(c->width == 256 && c->height == 256);
    rp_scene_destroy(s);

    /* Keywords in any order. */
    s = parse_ok("material lamp emit 1\nquad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\n"
                 "camera size 64 32 fov 45 up 0 0 1 look 1 2 3 eye 0 0 0\n");
    c = rp_scene_camera(s);
    cr_assert(c->width == 64 && c->height == 32 && c->fov_deg == 45 && c->up.z == 1 && c->look.z == 3);
    rp_scene_destroy(s);
}

/* ------------------------------------------------------------ Cornell */

/* Areas of every Cornell surface from the measured coordinates
 * (docs/ground-truth.md), by formulas independent of scene.c's. */
Test(scene, cornell_areas)
{
    rp_scene *s = load_ok("scenes/cornell.scene");
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_RGB);
    cr_assert_eq(rp_scene_nsurfaces(s), 20);

    /* Floor in (x, z): (552.8,0) (0,0) (0,559.2) (549.6,559.2); by hand
     * the shoelace sum is 0 + 0 - 307336.32 - 309125.76, area 308231.04. */
    double floor_xz[] = {552.8, 0, 0, 0, 0, 559.2, 549.6, 559.2};
    assert_rel(shoelace(floor_xz, 4), 308231.04, 1e-14, "hand shoelace");
    assert_rel(surface(s, "floor")->area, 308231.04, 1e-12, "floor");

    /* Back wall in (x, y): (549.6,0) (0,0) (0,548.8) (556,548.8): 303376.64. */
    double back_xy[] = {549.6, 0, 0, 0, 0, 548.8, 556, 548.8};
    assert_rel(shoelace(back_xy, 4), 303376.64, 1e-14, "hand shoelace");
    assert_rel(surface(s, "back")->area, 303376.64, 1e-12, "back");

    /* Green wall: a 559.2 x 548.8 rectangle. */
    assert_rel(surface(s, "right-green")->area, 559.2 * 548.8, 1e-12, "right-green");

    /* Light 130 x 105; the four ceiling pieces around it sum to the whole
     * ceiling (556 x 559.2) less the light. */
    assert_rel(surface(s, "light")->area, 130.0 * 105.0, 1e-12, "light");
    assert_rel(surface(s, "ceiling-front")->area, 556.0 * 227.0, 1e-12, "ceiling-front");
    assert_rel(surface(s, "ceiling-back")->area, 556.0 * (559.2 - 332.0), 1e-12, "ceiling-back");
    assert_rel(surface(s, "ceiling-left")->area, (556.0 - 343.0) * 105.0, 1e-12, "ceiling-left");
    assert_rel(surface(s, "ceiling-right")->area, 213.0 * 105.0, 1e-12, "ceiling-right");
    double ceiling = surface(s, "ceiling-front")->area + surface(s, "ceiling-back")->area +
                     surface(s, "ceiling-left")->area + surface(s, "ceiling-right")->area;
    assert_rel(ceiling, 556.0 * 559.2 - 130.0 * 105.0, 1e-12, "ceiling");

    /* Red wall: two triangles split along (552.8,0,0)-(556,548.8,559.2). */
    double r0[] = {552.8, 0, 0}, r1[] = {549.6, 0, 559.2}, r2[] = {556, 548.8, 559.2}, r3[] = {556, 548.8, 0};
    assert_rel(surface(s, "left-red-low")->area, heron(r0, r1, r2), 1e-10, "left-red-low");
    assert_rel(surface(s, "left-red-high")->area, heron(r0, r2, r3), 1e-10, "left-red-high");

    /* Block tops in (x, z).  By hand: short top shoelace sum
     * 23920 - 31696 - 51520 + 4030 = -55266, area 27633; tall top
     * 59753 + 27896 - 87748 - 55154 = -55253, area 27626.5. */
    double short_top[] = {130, 65, 82, 225, 240, 272, 290, 114};
    double tall_top[] = {423, 247, 265, 296, 314, 456, 472, 406};
    assert_rel(shoelace(short_top, 4), 27633.0, 1e-14, "hand shoelace");
    assert_rel(shoelace(tall_top, 4), 27626.5, 1e-14, "hand shoelace");
    assert_rel(surface(s, "short-top")->area, 27633.0, 1e-12, "short-top");
    assert_rel(surface(s, "tall-top")->area, 27626.5, 1e-12, "tall-top");

    /* Block sides: rectangles, horizontal edge length x height. */
    struct {
        const char *name;
        double x0, z0, x1, z1, h;
    } sides[] = {
        {"short-left", 290, 114, 240, 272, 165},  {"short-front", 130, 65, 290, 114, 165},
        {"short-right", 82, 225, 130, 65, 165},   {"short-back", 240, 272, 82, 225, 165},
        {"tall-left", 423, 247, 472, 406, 330},   {"tall-back", 472, 406, 314, 456, 330},
        {"tall-right", 314, 456, 265, 296, 330},  {"tall-front", 265, 296, 423, 247, 330},
    };
    for (size_t i = 0; i < sizeof sides / sizeof sides[0]; i++)
        assert_rel(surface(s, sides[i].name)->area, hypot(sides[i].x1 - sides[i].x0, sides[i].z1 - sides[i].z0) * sides[i].h,
                   1e-12, sides[i].name);

    double total = 0;
    for (size_t i = 0; i < rp_scene_nsurfaces(s); i++)
        total += rp_scene_surfaces(s)[i].area;
    assert_rel(rp_scene_total_area(s), total, 1e-14, "total area");

    /* Emitted power of the light: pi Le A per band. */
    double power[3];
    rp_scene_surface_power(s, rp_scene_find_surface(s, "light"), power);
    assert_rel(power[0], PI * 17 * 13650, 1e-12, "power R");
    assert_rel(power[1], PI * 12 * 13650, 1e-12, "power G");
    assert_rel(power[2], PI * 4 * 13650, 1e-12, "power B");
    rp_scene_surface_power(s, rp_scene_find_surface(s, "floor"), power);
    cr_assert(power[0] == 0 && power[1] == 0 && power[2] == 0);
    rp_scene_destroy(s);
}

Test(scene, cornell_normals)
{
    rp_scene *s = load_ok("scenes/cornell.scene");
    struct {
        const char *name;
        double x, y, z;
    } axis[] = {
        {"floor", 0, 1, 0},         {"light", 0, -1, 0},         {"ceiling-front", 0, -1, 0},
        {"ceiling-back", 0, -1, 0}, {"ceiling-left", 0, -1, 0},  {"ceiling-right", 0, -1, 0},
        {"back", 0, 0, -1},         {"right-green", 1, 0, 0},    {"short-top", 0, 1, 0},
        {"tall-top", 0, 1, 0},
    };
    for (size_t i = 0; i < sizeof axis / sizeof axis[0]; i++) {
        rp_vec3 n = first_face(s, axis[i].name)->normal;
        cr_assert(fabs(n.x - axis[i].x) < 1e-12 && fabs(n.y - axis[i].y) < 1e-12 && fabs(n.z - axis[i].z) < 1e-12,
                  "%s normal (%g, %g, %g)", axis[i].name, n.x, n.y, n.z);
    }
    /* Red wall, lower triangle: by hand (v1 - v0) x (v2 - v0) =
     * (-3.2, 0, 559.2) x (3.2, 548.8, 559.2) = (-306888.96, 3578.88, -1756.16). */
    double hx = -306888.96, hy = 3578.88, hz = -1756.16, hl = sqrt(hx * hx + hy * hy + hz * hz);
    rp_vec3 n = first_face(s, "left-red-low")->normal;
    cr_assert(fabs(n.x - hx / hl) < 1e-12 && fabs(n.y - hy / hl) < 1e-12 && fabs(n.z - hz / hl) < 1e-12);
    n = first_face(s, "left-red-high")->normal;
    cr_assert_gt(-n.x, 0.9999, "left-red-high faces into the room (-x): %g", n.x);

    /* Block sides face out of their block: away from the block's axis. */
    const char *shorts[] = {"short-left", "short-front", "short-right", "short-back"};
    const char *talls[] = {"tall-left", "tall-back", "tall-right", "tall-front"};
    double sc[2] = {(130 + 82 + 240 + 290) / 4.0, (65 + 225 + 272 + 114) / 4.0};
    double tc[2] = {(423 + 265 + 314 + 472) / 4.0, (247 + 296 + 456 + 406) / 4.0};
    for (int b = 0; b < 2; b++)
        for (int i = 0; i < 4; i++) {
            const char *name = b ? talls[i] : shorts[i];
            const double *c = b ? tc : sc;
            const rp_face *f = first_face(s, name);
            rp_vec3 m = rp_scene_face_point(s, (uint32_t)(f - rp_scene_faces(s)), 0.5, 0.5);
            double out = f->normal.x * (m.x - c[0]) + f->normal.z * (m.z - c[1]);
            cr_assert_gt(out, 0, "%s faces into its block", name);
            cr_assert_float_eq(f->normal.y, 0, 1e-15);
        }
    /* Image convention: right = forward x up = (0,0,1) x (0,1,0) = (-1,0,0),
     * so the red wall (x ~ 550) is on the image's left. */
    const rp_camera *c = rp_scene_camera(s);
    rp_vec3 right = rp_v3_cross(rp_v3_sub(c->look, c->eye), c->up);
    cr_assert_lt(right.x, 0);
    rp_scene_destroy(s);
}

Test(scene, face_point)
{
    rp_scene *s = load_ok("scenes/cornell.scene");
    uint32_t f = surface(s, "floor")->first_face;
    /* Bilinear centre of the floor: the mean of its four vertices. */
    rp_vec3 p = rp_scene_face_point(s, f, 0.5, 0.5);
    cr_assert_float_eq(p.x, (552.8 + 549.6) / 4, 1e-12);
    cr_assert_float_eq(p.y, 0, 1e-12);
    cr_assert_float_eq(p.z, 2 * 559.2 / 4, 1e-12);
    /* Corners: (1, 1) is v2, (0, 1) is v3. */
    p = rp_scene_face_point(s, f, 1, 1);
    cr_assert(p.x == 0 && p.y == 0 && p.z == 559.2);
    p = rp_scene_face_point(s, f, 0, 1);
    cr_assert(p.x == 549.6 && p.y == 0 && p.z == 559.2);
    /* Triangle: v0 + 0.25 (v1 - v0) + 0.5 (v2 - v0). */
    f = surface(s, "left-red-low")->first_face;
    p = rp_scene_face_point(s, f, 0.25, 0.5);
    cr_assert_float_eq(p.x, 552.8 + 0.25 * -3.2 + 0.5 * 3.2, 1e-12);
    cr_assert_float_eq(p.y, 0.5 * 548.8, 1e-12);
    cr_assert_float_eq(p.z, 0.75 * 559.2, 1e-12);
    rp_scene_destroy(s);
}

/* ------------------------------------------------------------ spectra */

Test(scene, spectrum_resampling)
{
    /* Spectrum 450:0.1 650:0.9: constant outside, slope 0.004 per nm.
     * Grey, mean over 400-700: (0.1*50 + 0.5*200 + 0.9*50) / 300 = 0.5.
     * RGB: B = (0.1*50 + 0.2*50)/100 = 0.15, G = mean(0.3, 0.7) = 0.5,
     *      R = (0.8*50 + 0.9*50)/100 = 0.85.
     * Spectral at 400 450 550 600 700: 0.1 0.1 0.5 0.7 0.9. */
    const char *geometry = "quad light m  0 1 0  1 1 0  1 1 1  0 1 1\n";
    char text[512];
    snprintf(text, sizeof text, "bands grey\nmaterial m reflect spectrum 450:0.1 650:0.9 emit 1\n%s", geometry);
    rp_scene *s = parse_ok(text);
    cr_assert_float_eq(rp_scene_materials(s)[0].rho[0], 0.5, 1e-14);
    rp_scene_destroy(s);

    snprintf(text, sizeof text, "bands rgb\nmaterial m emit 1 reflect spectrum 450:0.1 650:0.9\n%s", geometry);
    s = parse_ok(text);
    const double *rho = rp_scene_materials(s)[0].rho;
    cr_assert_float_eq(rho[0], 0.85, 1e-14);
    cr_assert_float_eq(rho[1], 0.5, 1e-14);
    cr_assert_float_eq(rho[2], 0.15, 1e-14);
    rp_scene_destroy(s);

    snprintf(text, sizeof text, "bands 400 450 550 600 700\nmaterial m emit 1 reflect spectrum 450:0.1 650:0.9\n%s",
             geometry);
    s = parse_ok(text);
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_SPECTRAL);
    cr_assert_eq(rp_scene_nbands(s), 5);
    cr_assert_eq(rp_scene_wavelengths(s)[2], 550.0);
    rho = rp_scene_materials(s)[0].rho;
    double want[] = {0.1, 0.1, 0.5, 0.7, 0.9};
    for (int i = 0; i < 5; i++)
        cr_assert_float_eq(rho[i], want[i], 1e-14, "band %d: %g", i, rho[i]);
    /* One emit value fills every band. */
    for (int i = 0; i < 5; i++)
        cr_assert_eq(rp_scene_materials(s)[0].Le[i], 1.0);
    rp_scene_destroy(s);

    /* A single point is a constant spectrum. */
    snprintf(text, sizeof text, "bands rgb\nmaterial m emit spectrum 555:2\n%s", geometry);
    s = parse_ok(text);
    for (int i = 0; i < 3; i++)
        cr_assert_float_eq(rp_scene_materials(s)[0].Le[i], 2.0, 1e-15);
    rp_scene_destroy(s);
}

Test(scene, cornell_light_spectrum)
{
    /* 400:0 500:8 600:15.6 700:18.4: box means by hand B = 4, G = 11.8,
     * R = 17, the RGB light of cornell.scene to within 0.2 in G. */
    rp_scene *s = parse_ok("bands rgb\nmaterial light emit spectrum 400:0 500:8 600:15.6 700:18.4\n"
                           "quad light light  0 1 0  1 1 0  1 1 1  0 1 1\n");
    const double *Le = rp_scene_materials(s)[0].Le;
    cr_assert_float_eq(Le[0], 17.0, 1e-13);
    cr_assert_float_eq(Le[1], 11.8, 1e-13);
    cr_assert_float_eq(Le[2], 4.0, 1e-13);
    rp_scene_destroy(s);
}

Test(scene, cornell_spectral)
{
    rp_scene *s = load_ok("scenes/cornell-spectral.scene");
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_SPECTRAL);
    cr_assert_eq(rp_scene_nbands(s), 16);
    for (int i = 0; i < 16; i++)
        cr_assert_eq(rp_scene_wavelengths(s)[i], 400.0 + 20 * i);
    const rp_material *m = rp_scene_materials(s);
    /* Measured white at 400 and 420 nm (docs/ground-truth.md, values 1 and 6):
     * .343, .687; red at 700 nm (value 76): .642; light at 520 nm:
     * 8 + 0.2 * 7.6 = 9.52. */
    cr_assert_str_eq(m[0].name, "white");
    cr_assert_float_eq(m[0].rho[0], 0.343, 1e-15);
    cr_assert_float_eq(m[0].rho[1], 0.687, 1e-15);
    cr_assert_str_eq(m[1].name, "red");
    cr_assert_float_eq(m[1].rho[15], 0.642, 1e-15);
    cr_assert_str_eq(m[3].name, "light");
    cr_assert_float_eq(m[3].Le[6], 9.52, 1e-13);
    cr_assert_float_eq(m[3].Le[0], 0.0, 1e-15);
    /* Same geometry as the RGB scene. */
    rp_scene *rgb = load_ok("scenes/cornell.scene");
    cr_assert_eq(rp_scene_nfaces(s), rp_scene_nfaces(rgb));
    assert_rel(rp_scene_total_area(s), rp_scene_total_area(rgb), 1e-15, "total area");
    rp_scene_destroy(rgb);
    rp_scene_destroy(s);
}

/* -------------------------------------------------------------- boxes */

Test(scene, box)
{
    for (int inward = 0; inward < 2; inward++) {
        char text[256];
        snprintf(text, sizeof text, "material m reflect 0.5 emit 1\nbox b m  1 2 3  3 5 7  %s\n",
                 inward ? "inward" : "outward");
        rp_scene *s = parse_ok(text);
        cr_assert_eq(rp_scene_nsurfaces(s), 1);
        cr_assert_eq(rp_scene_surfaces(s)[0].kind, RP_SURFACE_BOX);
        cr_assert_eq(rp_scene_nfaces(s), 6);
        cr_assert_eq(rp_scene_nvertices(s), 8);
        /* 2 x 3 x 4 box: 2 (6 + 12 + 8) = 52. */
        cr_assert_float_eq(rp_scene_surfaces(s)[0].area, 52.0, 1e-13);
        for (uint32_t f = 0; f < 6; f++) {
            const rp_face *face = &rp_scene_faces(s)[f];
            rp_vec3 c = rp_scene_face_point(s, f, 0.5, 0.5);
            rp_vec3 to_centre = rp_v3_sub(rp_v3(2, 3.5, 5), c);
            double d = rp_v3_dot(face->normal, to_centre);
            cr_assert(inward ? d > 0 : d < 0, "face %u points %s", f, inward ? "outward" : "inward");
            cr_assert_float_eq(rp_v3_length(face->normal), 1.0, 1e-15);
        }
        cr_assert_eq(rp_scene_is_closed(s), 1);
        rp_scene_destroy(s);
    }
}

/* ------------------------------------------------------------ includes */

Test(scene, include)
{
    rp_scene *s = load_ok("tests/data/include-main.scene");
    cr_assert_eq(rp_scene_nsurfaces(s), 3);
    const rp_surface *wall = surface(s, "wall"), *fl = surface(s, "floor"), *light = surface(s, "light");
    const char *suffix[] = {"tests/data/parts/walls.inc", "tests/data/parts/floor.inc", "tests/data/include-main.scene"};
    const rp_surface *surf[] = {wall, fl, light};
    int lines[] = {2, 1, 8};
    for (int i = 0; i < 3; i++) {
        size_t n = strlen(surf[i]->file), k = strlen(suffix[i]);
        cr_assert(n >= k && !strcmp(surf[i]->file + n - k, suffix[i]), "%s declared in %s", surf[i]->name,
                  surf[i]->file);
        cr_assert_eq(surf[i]->line, lines[i], "%s at line %d", surf[i]->name, surf[i]->line);
    }
    cr_assert_eq(rp_scene_materials(s)[0].Le[2], 3.0);
    rp_scene_destroy(s);

    /* rp_scene_parse resolves includes against the directory it is given. */
    rp_scene *t = NULL;
    rp_error err;
    rp_status st = rp_scene_parse("material lamp emit 1\nmaterial white reflect 0.5\n"
                                  "quad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\ninclude parts/walls.inc\n",
                                  "inline", RP_SOURCE_DIR "/tests/data", &t, &err);
    cr_assert_eq(st, RP_OK, "%s", err.message);
    cr_assert_eq(rp_scene_nsurfaces(t), 3);
    rp_scene_destroy(t);
}

/* ------------------------------------------------------------- hashing */

Test(scene, hash)
{
    const char *a = "bands rgb\nmaterial lamp emit 1 2 3\nquad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\n";
    const char *b = "# same content, other spelling\nbands   rgb\n\nmaterial lamp emit 1.0 2e0 3 # c\n"
                    "quad light lamp 0 1 0 1 1 0 1 1 1 0.0 1 1\n";
    const char *c = "bands rgb\nmaterial lamp emit 1 2 3\nquad light lamp  0 1 0  1 1 0  1 1 1  0 1 1.5\n";
    const char *d = "bands rgb\nmaterial lamp emit 1 2 3.5\nquad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\n";
    char ha[17], hb[17], hc[17], hd[17];
    rp_scene *s = parse_ok(a);
    rp_scene_hash(s, ha);
    rp_scene_destroy(s);
    s = parse_ok(b);
    rp_scene_hash(s, hb);
    rp_scene_destroy(s);
    s = parse_ok(c);
    rp_scene_hash(s, hc);
    rp_scene_destroy(s);
    s = parse_ok(d);
    rp_scene_hash(s, hd);
    rp_scene_destroy(s);
    cr_assert_eq(strlen(ha), 16);
    for (int i = 0; i < 16; i++)
        cr_assert(strchr("0123456789abcdef", ha[i]));
    cr_assert_str_eq(ha, hb, "comments and spelling changed the hash");
    cr_assert_str_neq(ha, hc, "a moved vertex left the hash unchanged");
    cr_assert_str_neq(ha, hd, "a changed emission left the hash unchanged");
}

/* --------------------------------------------------- built-in scenes */

Test(scene, builtin_scenes)
{
    rp_scene *s = load_ok("scenes/furnace.scene");
    cr_assert_eq(rp_scene_nfaces(s), 6);
    cr_assert_float_eq(rp_scene_total_area(s), 6.0, 1e-14);
    cr_assert_eq(rp_scene_materials(s)[0].rho[0], 0.5);
    cr_assert_eq(rp_scene_materials(s)[0].Le[0], 1.0);
    cr_assert_not_null(rp_scene_camera(s));
    rp_scene_destroy(s);

    s = load_ok("scenes/cube-ceiling.scene");
    cr_assert_eq(rp_scene_nsurfaces(s), 6);
    const char *walls[] = {"floor", "ceiling", "wall-x0", "wall-x1", "wall-z0", "wall-z1"};
    for (int i = 0; i < 6; i++) {
        const rp_surface *w = surface(s, walls[i]);
        cr_assert_float_eq(w->area, 1.0, 1e-15);
        cr_assert_eq(rp_scene_materials(s)[w->material].rho[0], 0.5);
        cr_assert_eq(rp_scene_materials(s)[w->material].emitter, i == 1);
        /* Normals into the cube. */
        rp_vec3 c = rp_scene_face_point(s, w->first_face, 0.5, 0.5);
        cr_assert_gt(rp_v3_dot(rp_scene_faces(s)[w->first_face].normal, rp_v3_sub(rp_v3(0.5, 0.5, 0.5), c)), 0.49);
    }
    rp_scene_destroy(s);

    /* Parallel plates: opposed, one unit apart; perpendicular plates:
     * sharing the edge y = z = 0 and facing each other. */
    s = load_ok("scenes/plates-parallel.scene");
    const rp_face *e = first_face(s, "emitter"), *r = first_face(s, "receiver");
    cr_assert(e->normal.y == -1 && r->normal.y == 1);
    cr_assert(rp_scene_vertices(s)[e->v[0]].y - rp_scene_vertices(s)[r->v[0]].y == 1);
    rp_scene_destroy(s);
    s = load_ok("scenes/plates-perpendicular.scene");
    e = first_face(s, "emitter");
    r = first_face(s, "receiver");
    cr_assert(e->normal.z == 1 && r->normal.y == 1);
    cr_assert_float_eq(rp_scene_total_area(s), 2.0, 1e-15);
    rp_scene_destroy(s);
}

/* Needs the CGAL shim (rp_cgal_is_closed). */
Test(scene, closedness)
{
    rp_scene *s = load_ok("scenes/cornell.scene");
    cr_assert_eq(rp_scene_is_closed(s), 0, "the Cornell box is open at z = 0");
    rp_scene_destroy(s);
    s = load_ok("scenes/furnace.scene");
    cr_assert_eq(rp_scene_is_closed(s), 1);
    rp_scene_destroy(s);
    /* Six quads with their own vertices: closed only after welding. */
    s = load_ok("scenes/cube-ceiling.scene");
    cr_assert_eq(rp_scene_nvertices(s), 24);
    cr_assert_eq(rp_scene_is_closed(s), 1);
    rp_scene_destroy(s);
    s = load_ok("scenes/plates-parallel.scene");
    cr_assert_eq(rp_scene_is_closed(s), 0);
    rp_scene_destroy(s);
}

/* Needs the CGAL shim (rp_cgal_read_mesh). */
Test(scene, mesh)
{
    rp_scene *s = load_ok("tests/data/mesh-tetra.scene");
    const rp_surface *t = surface(s, "tetra");
    cr_assert_eq(t->kind, RP_SURFACE_MESH);
    cr_assert_eq(t->nfaces, 4);
    /* Unit tetrahedron scaled by 2: three right triangles of legs 2 (area 2
     * each) and an equilateral triangle of side 2 sqrt 2 (area 2 sqrt 3). */
    cr_assert_float_eq(t->area, 6 + 2 * sqrt(3.0), 1e-13);
    /* Vertices moved to 2 p + (1, 2, 3): bounds (1,2,3)-(3,4,5) with the
     * light quad at y = 5 from (0,5,0) to (1,5,1). */
    rp_vec3 lo, hi;
    rp_scene_bounds(s, &lo, &hi);
    cr_assert(lo.x == 0 && lo.y == 2 && lo.z == 0 && hi.x == 3 && hi.y == 5 && hi.z == 5);
    /* Faces point out of the tetrahedron, whose centroid is (1.5, 2.5, 3.5). */
    for (uint32_t f = t->first_face; f < t->first_face + t->nfaces; f++) {
        rp_vec3 c = rp_scene_face_point(s, f, 1.0 / 3, 1.0 / 3);
        cr_assert_gt(rp_v3_dot(rp_scene_faces(s)[f].normal, rp_v3_sub(c, rp_v3(1.5, 2.5, 3.5))), 0);
    }
    rp_scene_destroy(s);
}

/* Needs the CGAL shim (rp_obj_read_scene). */
Test(scene, obj_scene)
{
    rp_scene *s = load_ok("tests/data/two-groups.obj");
    cr_assert_eq(rp_scene_band_kind(s), RP_BANDS_RGB);
    cr_assert_null(rp_scene_camera(s));
    cr_assert_eq(rp_scene_nsurfaces(s), 3);
    const rp_surface *w = surface(s, "box.white"), *r = surface(s, "box.red"), *l = surface(s, "light");
    const rp_material *m = rp_scene_materials(s);
    cr_assert_str_eq(m[w->material].name, "white");
    cr_assert_str_eq(m[r->material].name, "red");
    cr_assert_float_eq(m[r->material].rho[0], 0.6, 1e-15);
    cr_assert_float_eq(m[l->material].Le[0], 4.0, 1e-15);
    cr_assert_float_eq(m[l->material].Le[2], 2.0, 1e-15);
    cr_assert(m[l->material].emitter && !m[w->material].emitter);
    for (int i = 0; i < 3; i++) {
        const rp_surface *x = i == 0 ? w : i == 1 ? r : l;
        cr_assert_float_eq(x->area, 1.0, 1e-14, "%s area %g", x->name, x->area);
    }
    cr_assert_float_eq(rp_scene_faces(s)[l->first_face].normal.y, -1.0, 1e-15);
    cr_assert_float_eq(rp_scene_faces(s)[w->first_face].normal.y, 1.0, 1e-15);
    rp_scene_destroy(s);
}

/* Needs the CGAL shim (rp_obj_read_scene). */
Test(scene, obj_refused)
{
    rp_scene *s = (rp_scene *)1;
    rp_error err = {{0}};
    const char *path = RP_SOURCE_DIR "/tests/data/obj-no-material.obj";
    cr_assert_eq(rp_scene_load(path, &s, &err), RP_ERR_INPUT);
    cr_assert_null(s);
    cr_assert(strncmp(err.message, path, strlen(path)) == 0 && err.message[strlen(path)] == ':', "%s", err.message);
    cr_assert_not_null(strstr(err.message, "no material"), "%s", err.message);
}

Test(scene, bunny)
{
    /* make meshes extracts scenes/data/bunny00.off from CGAL's data. */
    rp_scene *s = load_ok("scenes/bunny.scene");
    const rp_surface *b = surface(s, "bunny");
    cr_assert_eq(b->nfaces, 75408);
    const rp_vec3 *v = rp_scene_vertices(s);
    uint32_t lowest = rp_scene_faces(s)[b->first_face].v[0];
    for (uint32_t f = b->first_face; f < b->first_face + b->nfaces; f++)
        for (int k = 0; k < 3; k++)
            if (v[rp_scene_faces(s)[f].v[k]].y < v[lowest].y)
                lowest = rp_scene_faces(s)[f].v[k];
    /* -0.493434 + 0.4935: resting on the floor, not through it. */
    cr_assert_float_eq(v[lowest].y, 0.000066, 1e-9);
    rp_scene_destroy(s);
}

/* ------------------------------------------------------------ refusals */

Test(scene, refusals_from_text)
{
    const char *light = "material lamp emit 1\nquad light lamp  0 1 0  1 1 0  1 1 1  0 1 1\n";
    char text[512];
    snprintf(text, sizeof text, "%smaterial m reflect 1.2\n", light);
    parse_bad(text, "test.scene:3: reflect 1.2 outside [0, 1]");
    snprintf(text, sizeof text, "%s\n\nquad q nope  0 0 0  1 0 0  1 0 1  0 0 1\n", light);
    parse_bad(text, "test.scene:5: unknown material 'nope'");
    snprintf(text, sizeof text, "%striangle t lamp 0 0 0 1 0 0 0 0 1abc\n", light);
    parse_bad(text, "test.scene:3: '1abc' is not a number");
    parse_bad("material white reflect 0.5\nquad q white  0 0 0  0 0 1  1 0 1  1 0 0\n", "test.scene:2: ");
    /* No error object: refused all the same, nothing written. */
    rp_scene *s = (rp_scene *)1;
    cr_assert_eq(rp_scene_parse("bogus\n", "x", NULL, &s, NULL), RP_ERR_INPUT);
    cr_assert_null(s);
    /* Missing top-level file. */
    rp_error err;
    cr_assert_eq(rp_scene_load(RP_SOURCE_DIR "/tests/data/no-such.scene", &s, &err), RP_ERR_INPUT);
    cr_assert(strstr(err.message, "no-such.scene: ") == err.message + strlen(RP_SOURCE_DIR "/tests/data/"));
}

/* The line marked "<-- bad" in path, or 0. */
static int marked_line(const char *path)
{
    FILE *f = fopen(path, "r");
    cr_assert_not_null(f, "cannot open %s", path);
    char buf[4096];
    int line = 0, found = 0;
    while (fgets(buf, sizeof buf, f)) {
        line++;
        if (strstr(buf, "<-- bad"))
            found = line;
    }
    fclose(f);
    return found;
}

/* The file named by a "# error-in: NAME" line, if any. */
static int error_in(const char *path, char *name, size_t len)
{
    FILE *f = fopen(path, "r");
    cr_assert_not_null(f);
    char buf[4096];
    int found = 0;
    while (fgets(buf, sizeof buf, f))
        if (sscanf(buf, "# error-in: %255s", name) == 1 && strlen(name) < len) {
            found = 1;
            break;
        }
    fclose(f);
    return found;
}

/* Every .scene file in tests/bad is refused as bad input, with a one-line message
 * starting "FILE:LINE: " where FILE:LINE is the line marked "<-- bad" (in
 * the scene, or in the include its "# error-in:" line names). */
Test(scene, bad_scenes)
{
    const char *dir = RP_SOURCE_DIR "/tests/bad";
    DIR *d = opendir(dir);
    cr_assert_not_null(d);
    struct dirent *e;
    int count = 0;
    while ((e = readdir(d))) {
        size_t n = strlen(e->d_name);
        if (n < 7 || strcmp(e->d_name + n - 6, ".scene"))
            continue;
        char path[1024], where[1024], inc[256];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (error_in(path, inc, sizeof inc))
            snprintf(where, sizeof where, "%s/%s", dir, inc);
        else
            snprintf(where, sizeof where, "%s", path);
        int line = marked_line(where);
        cr_assert_gt(line, 0, "%s has no line marked '<-- bad'", where);
        char prefix[1100];
        snprintf(prefix, sizeof prefix, "%s:%d: ", where, line);

        rp_scene *s = (rp_scene *)1;
        rp_error err = {{0}};
        rp_status st = rp_scene_load(path, &s, &err);
        cr_expect_eq(st, RP_ERR_INPUT, "%s: status %d (%s)", e->d_name, st, err.message);
        cr_expect_null(s, "%s: scene returned on failure", e->d_name);
        cr_expect(strncmp(err.message, prefix, strlen(prefix)) == 0 && strlen(err.message) > strlen(prefix),
                  "%s: message '%s' should start '%s'", e->d_name, err.message, prefix);
        cr_expect_null(strchr(err.message, '\n'), "%s: message spans lines", e->d_name);
        if (st == RP_OK)
            rp_scene_destroy(s);
        count++;
    }
    closedir(d);
    cr_assert_geq(count, 25, "only %d bad scenes", count);
}

/* ------------------------------------------------- OBJ scenes, cameras */

#define DATA_DIR RP_SOURCE_DIR "/tests/data"

/* The first line of a tests/data file containing needle (from the file
 * itself, not from the reader). */
static int data_line(const char *file, const char *needle)
{
    char path[1024], buf[1024];
    snprintf(path, sizeof path, DATA_DIR "/%s", file);
    FILE *f = fopen(path, "r");
    cr_assert_not_null(f, "cannot open %s", path);
    int n = 0, found = 0;
    while (!found && fgets(buf, sizeof buf, f)) {
        n++;
        if (strstr(buf, needle))
            found = n;
    }
    fclose(f);
    cr_assert_gt(found, 0, "%s has no line with '%s'", file, needle);
    return found;
}

/* The number of warnings of s containing needle. */
static int warnings_with(const rp_scene *s, const char *needle)
{
    int n = 0;
    for (size_t i = 0; i < rp_scene_nwarnings(s); i++)
        n += strstr(rp_scene_warning(s, i), needle) != NULL;
    return n;
}

static const rp_material *surface_material(const rp_scene *s, const char *name)
{
    return &rp_scene_materials(s)[surface(s, name)->material];
}

/* McGuire's CornellBox-Original.obj/.mtl: its eight groups are the eight
 * surfaces; the light (Kd 0.78, Ke 17 12 4) emits and reflects. */
Test(scene, obj_mcguire_cornell_box)
{
    rp_scene *s = load_ok("tests/data/CornellBox-Original.obj");
    const char *names[8] = {"floor", "ceiling", "backWall", "rightWall", "leftWall", "shortBox", "tallBox", "light"};
    cr_assert_eq(rp_scene_nsurfaces(s), 8);
    for (int i = 0; i < 8; i++)
        surface(s, names[i]);
    const rp_material *light = surface_material(s, "light");
    cr_assert(light->emitter);
    cr_assert(!rp_material_pure_emitter(light, 3));
    const double le[3] = {17, 12, 4};
    for (int b = 0; b < 3; b++) {
        cr_assert_eq(light->rho[b], 0.78);
        cr_assert_eq(light->Le[b], le[b]);
        cr_assert_eq(surface_material(s, "shortBox")->rho[b], 0.0, "Kd 0 0 0 (its Ks is not read)");
    }
    cr_assert_float_eq(rp_scene_materials(s)[surface(s, "leftWall")->material].rho[1], 0.065, 1e-17);
    /* Floor (y = 0) from the file's vertices, in the xz plane. */
    const double floor_xz[8] = {-1.01, 0.99, 1.00, 0.99, 1.00, -1.04, -0.99, -1.04};
    assert_rel(surface(s, "floor")->area, shoelace(floor_xz, 4), 1e-14, "floor area");
    assert_rel(surface(s, "light")->area, 0.47 * 0.38, 1e-13, "light area");
    /* The light faces down, into the room. */
    cr_assert_float_eq(first_face(s, "light")->normal.y, -1.0, 1e-15);
    cr_assert_eq(rp_scene_nwarnings(s), 2);
    rp_scene_destroy(s);
}

/* The copy of the same box in chellmuth/pathed repeats two faces exactly
 * (same vertices, same order), which radpt used to refuse as
 * "inconsistently oriented": now they are dropped, with one warning naming
 * the first one's line and the count. */
Test(scene, obj_duplicate_faces_dropped_not_refused)
{
    rp_scene *s = load_ok("tests/data/CornellBox-Original-dup.obj");
    cr_assert_eq(rp_scene_nsurfaces(s), 7, "no back wall in this copy");
    char where[128];
    snprintf(where, sizeof where, "CornellBox-Original-dup.obj:%d: 2 exact duplicate faces dropped",
             data_line("CornellBox-Original-dup.obj", "f -12 -11 -10 -9"));
    cr_assert_eq(warnings_with(s, where), 1, "no warning '%s'", where);
    cr_assert_eq(warnings_with(s, "inconsistently"), 0);
    /* The short box has five quads left (ten triangles). */
    cr_assert_eq(surface(s, "leftWall.shortBox")->nfaces, 10);
    rp_scene_destroy(s);
}

Test(scene, obj_orientation_conflict_is_a_warning)
{
    rp_scene *s = load_ok("tests/data/conflict.obj");
    char where[96];
    snprintf(where, sizeof where, "conflict.obj:%d: faces wound inconsistently: 1 edge",
             data_line("conflict.obj", "f 1 2 5 6"));
    cr_assert_eq(warnings_with(s, where), 1, "no warning '%s'", where);
    /* each keeps its own winding: floor (1,0,0) x (1,0,1) = -y, wall +z */
    cr_assert_float_eq(first_face(s, "floor")->normal.y, -1.0, 1e-15);
    cr_assert_float_eq(first_face(s, "wall")->normal.z, 1.0, 1e-15);
    rp_scene_destroy(s);
}

Test(scene, obj_surface_names_unique)
{
    rp_scene *s = load_ok("tests/data/names.obj");
    cr_assert_eq(rp_scene_nsurfaces(s), 4);
    cr_assert_str_eq(rp_scene_materials(s)[surface(s, "left wall")->material].name, "white");
    cr_assert_str_eq(surface_material(s, "a.white")->name, "white");
    cr_assert_str_eq(surface_material(s, "a.light")->name, "light");
    /* the group literally called a.white, after a's white part took it */
    const rp_surface *again = surface(s, "a.white~2");
    cr_assert_float_eq(rp_scene_faces(s)[again->first_face].normal.z, 1.0, 1e-15);
    cr_assert_eq(again->line, data_line("names.obj", "f 1 2 6 5"));
    rp_scene_destroy(s);
}

/* mesh-mtl.scene places scene.obj (a unit floor quad at y = 0 and a lamp
 * quad at y = 1, scene.mtl) scaled by 2 and moved up by 3. */
Test(scene, mesh_mtl_places_the_obj_materials)
{
    rp_scene *s = load_ok("tests/data/mesh-mtl.scene");
    cr_assert_eq(rp_scene_nsurfaces(s), 3);
    cr_assert_eq(rp_scene_nmaterials(s), 3);
    const rp_material *own = surface_material(s, "ground"), *white = surface_material(s, "lamp/floor"),
                      *light = surface_material(s, "lamp/lamp");
    cr_assert_str_eq(own->name, "white");
    cr_assert_str_eq(white->name, "lamp/white");
    cr_assert_str_eq(light->name, "lamp/light");
    const double kd_white[3] = {0.725, 0.71, 0.68}, kd_light[3] = {0.1, 0.2, 0.3}, le[3] = {17, 12, 4};
    for (int b = 0; b < 3; b++) {
        cr_assert_eq(own->rho[b], 0.5);
        cr_assert_eq(white->rho[b], kd_white[b]);
        cr_assert_eq(light->rho[b], kd_light[b]);
        cr_assert_eq(light->Le[b], le[b]);
    }
    cr_assert(light->emitter && !white->emitter);
    /* Unit squares scaled by 2: area 4; the lamp at y = 2 * 1 + 3 = 5,
     * facing down; the floor at y = 3. */
    cr_assert_float_eq(surface(s, "lamp/floor")->area, 4.0, 1e-14);
    cr_assert_float_eq(surface(s, "lamp/lamp")->area, 4.0, 1e-14);
    rp_vec3 lo, hi;
    rp_scene_bounds(s, &lo, &hi);
    cr_assert(lo.y == 0 && hi.y == 5, "y from %g to %g", lo.y, hi.y);
    cr_assert_float_eq(rp_scene_face_point(s, first_face(s, "lamp/floor") - rp_scene_faces(s), 0.3, 0.3).y, 3.0,
                       1e-15);
    cr_assert_float_eq(first_face(s, "lamp/lamp")->normal.y, -1.0, 1e-15);
    rp_scene_destroy(s);
}

static rp_scene *parse_in_data(const char *text, rp_error *err)
{
    rp_scene *s = NULL;
    rp_scene_parse(text, "test.scene", DATA_DIR, &s, err);
    return s;
}

/* A grey scene takes an MTL colour as its Rec. 709 luminance
 * Y = 0.2126 R + 0.7152 G + 0.0722 B (ITU-R BT.709); a spectral scene
 * refuses RGB at the mesh statement's line. */
Test(scene, mesh_mtl_grey_luminance_spectral_refused)
{
    rp_error err = {{0}};
    rp_scene *s = parse_in_data("bands grey\nmaterial w reflect 0.5\n\nmesh lamp mtl scene.obj\n", &err);
    cr_assert_not_null(s, "%s", err.message);
    cr_assert_float_eq(surface_material(s, "lamp/floor")->rho[0], 0.2126 * 0.725 + 0.7152 * 0.71 + 0.0722 * 0.68,
                       1e-15);
    cr_assert_float_eq(surface_material(s, "lamp/lamp")->Le[0], 0.2126 * 17 + 0.7152 * 12 + 0.0722 * 4, 1e-13);
    rp_scene_destroy(s);
    s = parse_in_data("bands 450 550 650\nmaterial w reflect 0.5\n\nmesh lamp mtl scene.obj\n", &err);
    cr_assert_null(s);
    cr_assert(strncmp(err.message, "test.scene:4: ", 14) == 0 && strstr(err.message, "spectral"), "%s",
              err.message);
    /* 'mtl' is the keyword, never a material name; a material of the scene
     * named like a placed one is refused where it would clash */
    s = parse_in_data("material mtl reflect 0.5\n", &err);
    cr_assert_null(s);
    cr_assert(strncmp(err.message, "test.scene:1: ", 14) == 0, "%s", err.message);
    s = parse_in_data("material lamp/white reflect 0.5\nmesh lamp mtl scene.obj\n", &err);
    cr_assert_null(s);
    const char *clash = "test.scene:2: material 'lamp/white'";
    cr_assert(strncmp(err.message, clash, strlen(clash)) == 0, "%s", err.message);
}

/* One-material meshes: zero-area faces dropped with a warning (the OFF
 * file's line), inconsistent orientation refused at the statement's line,
 * naming the mesh file's line of the conflict. */
Test(scene, mesh_one_material_drops_and_orientation)
{
    rp_error err = {{0}};
    rp_scene *s = parse_in_data("material w reflect 0.5 emit 1\nmesh t w degenerate-tetra.off\n", &err);
    cr_assert_not_null(s, "%s", err.message);
    cr_assert_eq(surface(s, "t")->nfaces, 4);
    char where[96];
    snprintf(where, sizeof where, "degenerate-tetra.off:%d: 1 zero-area face dropped",
             data_line("degenerate-tetra.off", "3 0 1 4"));
    cr_assert_eq(warnings_with(s, where), 1, "no warning '%s'", where);
    rp_scene_destroy(s);
    s = parse_in_data("material w reflect 0.5 emit 1\n\nmesh c w conflict.obj\n", &err);
    cr_assert_null(s);
    snprintf(where, sizeof where, "conflict.obj:%d)", data_line("conflict.obj", "f 1 2 5 6"));
    cr_assert(strncmp(err.message, "test.scene:3: ", 14) == 0 && strstr(err.message, where), "%s", err.message);
}

/* reflect 1, a perfect reflector (MTL's Kd 1), is accepted as Kd 1 is. */
Test(scene, reflect_one_accepted)
{
    rp_scene *s = parse_ok("material m reflect 1 emit 1\nquad q m  0 0 0  1 0 0  1 0 1  0 0 1\n");
    cr_assert_eq(rp_scene_materials(s)[0].rho[0], 1.0);
    rp_scene_destroy(s);
}

Test(scene, camera_words)
{
    rp_camera c;
    rp_error err = {{0}};
    cr_assert_eq(rp_camera_parse("fov 30 eye 1 2 3  look 1 2 4 up 0 1 0 size 64 32", "--camera", &c, &err), RP_OK,
                 "%s", err.message);
    cr_assert(c.eye.x == 1 && c.eye.y == 2 && c.eye.z == 3 && c.look.z == 4 && c.up.y == 1);
    cr_assert(c.fov_deg == 30 && c.width == 64 && c.height == 32);
    /* a scene file's whole statement, keyword and all */
    rp_camera d;
    cr_assert_eq(rp_camera_parse("camera eye 1 2 3 look 1 2 4 up 0 1 0 fov 30 size 64 32", NULL, &d, &err), RP_OK);
    cr_assert_eq(memcmp(&c, &d, sizeof c), 0);
    const char *bad[][2] = {
        {"", "--camera: no camera words"},
        {"eye 1 2 look 0 0 0 up 0 1 0 fov 40 size 8 8", "--camera: camera 'eye' takes 3 numbers"},
        {"eye 0 0 0 look 0 0 1 up 0 1 0 size 8 8", "--camera: camera lacks 'fov'"},
        {"eye 0 0 0 look 0 0 0 up 0 1 0 fov 40 size 8 8", "--camera: camera eye and look are the same point"},
        {"eye 0 0 0 look 0 0 1 up 0 0 2 fov 40 size 8 8", "--camera: camera up is zero or parallel"},
        {"eye 0 0 0 look 0 0 1 up 0 1 0 fov 180 size 8 8", "--camera: camera fov 180 degrees outside (0, 180)"},
        {"eye 0 0 0 look 0 0 1 up 0 1 0 fov 40 size 8 0.5", "--camera: camera size 0.5"},
        {"eye 0 0 nan look 0 0 1 up 0 1 0 fov 40 size 8 8", "--camera: 'nan' is not a finite number"},
        {"eye 0 0 0 look 0 0 1 up 0 1 0 fov 40 size 8 8 zoom 2", "--camera: unknown camera keyword 'zoom'"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        cr_expect_eq(rp_camera_parse(bad[i][0], "--camera", &d, &err), RP_ERR_INPUT, "'%s' accepted", bad[i][0]);
        cr_expect(strncmp(err.message, bad[i][1], strlen(bad[i][1])) == 0, "'%s': %s", bad[i][0], err.message);
    }
    /* Setting a camera changes the hash (references are cached by it). */
    rp_scene *s = load_ok("scenes/cornell.scene");
    char before[17], after[17];
    rp_scene_hash(s, before);
    cr_assert_eq(rp_scene_set_camera(s, &c, &err), RP_OK);
    rp_scene_hash(s, after);
    cr_assert_str_neq(before, after);
    cr_assert_eq(memcmp(rp_scene_camera(s), &c, sizeof c), 0);
    c.fov_deg = 0;
    cr_assert_eq(rp_scene_set_camera(s, &c, &err), RP_ERR_INPUT);
    rp_scene_destroy(s);
}

/* Where a point shows in a camera's image: 1 if inside the frame. */
static int in_frame(const rp_camera *c, rp_vec3 p)
{
    rp_vec3 f = rp_v3_normalize(rp_v3_sub(c->look, c->eye));
    rp_vec3 r = rp_v3_normalize(rp_v3_cross(f, c->up)), u = rp_v3_cross(r, f);
    rp_vec3 d = rp_v3_sub(p, c->eye);
    double z = rp_v3_dot(d, f), t = tan(0.5 * c->fov_deg * PI / 180);
    return z > 0 && fabs(rp_v3_dot(d, u)) <= t * z &&
           fabs(rp_v3_dot(d, r)) <= t * z * c->width / (double)c->height;
}

/* The default camera: McGuire's open box is framed from outside along -z
 * (every corner of its bounding box in the frame); the furnace cube, a
 * closed room, is seen from inside (from outside only the backs of its
 * walls show).  Its printed words give it back exactly. */
Test(scene, default_camera)
{
    rp_error err = {{0}};
    rp_camera c, back;
    char words[512];
    rp_scene *s = load_ok("tests/data/CornellBox-Original.obj");
    cr_assert_eq(rp_scene_default_camera(s, &c, &err), RP_OK, "%s", err.message);
    rp_vec3 lo, hi;
    rp_scene_bounds(s, &lo, &hi);
    cr_assert_gt(c.eye.z, hi.z);
    cr_assert(c.look.x == c.eye.x && c.look.y == c.eye.y && c.look.z < c.eye.z, "looks along -z");
    cr_assert(c.up.x == 0 && c.up.y == 1 && c.up.z == 0);
    cr_assert(c.fov_deg == RP_DEFAULT_CAMERA_FOV && c.width == 256 && c.height == 256);
    for (int k = 0; k < 8; k++) {
        rp_vec3 p = rp_v3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
        cr_assert(in_frame(&c, p), "corner %d (%g, %g, %g) out of frame", k, p.x, p.y, p.z);
    }
    rp_camera_format(&c, words, sizeof words);
    cr_assert_eq(rp_camera_parse(words, "words", &back, &err), RP_OK, "%s: %s", words, err.message);
    cr_assert_eq(memcmp(&c, &back, sizeof c), 0, "%s does not give the camera back", words);
    rp_scene_destroy(s);

    s = load_ok("tests/data/furnace-cube.obj");
    cr_assert_eq(rp_scene_default_camera(s, &c, &err), RP_OK, "%s", err.message);
    cr_assert(c.eye.x > 0 && c.eye.x < 1 && c.eye.y > 0 && c.eye.y < 1 && c.eye.z > 0 && c.eye.z < 1,
              "eye (%g, %g, %g) outside the closed room", c.eye.x, c.eye.y, c.eye.z);
    /* the far wall (z = 0) fills the view: its corners at the frame's edge or beyond */
    cr_assert(in_frame(&c, rp_v3(0.5, 0.5, 0)));
    rp_camera_format(&c, words, sizeof words);
    cr_assert_eq(rp_camera_parse(words, "words", &back, &err), RP_OK);
    cr_assert_eq(memcmp(&c, &back, sizeof c), 0, "%s does not give the camera back", words);
    rp_scene_destroy(s);
}
