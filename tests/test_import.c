/* Tests of the CGAL shim (geometry/cgal/import.h): mesh readers, the OBJ+MTL
 * scene reader and the closedness test.  Expected values come from the
 * hand-written meshes in tests/data (a unit cube has 6 quads = 12 triangles
 * and area 6, an L of three unit squares has area 3) and from the header of
 * CGAL's bunny00.off ("37706 75408 0"). */
#include <criterion/criterion.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/cgal/import.h"

#define DATA RP_SOURCE_DIR "/tests/data/"

static void tri_normal(const rp_tri_mesh *m, size_t t, double n[3])
{
    const double *a = m->xyz + 3 * m->tri[3 * t];
    const double *b = m->xyz + 3 * m->tri[3 * t + 1];
    const double *c = m->xyz + 3 * m->tri[3 * t + 2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
}

/* Sum of unsigned triangle areas: a triangulation that overlaps itself or
 * leaves the polygon shows up here even when signed areas would cancel. */
static double total_area(const rp_tri_mesh *m)
{
    double s = 0;
    for (size_t t = 0; t < m->ntriangles; t++) {
        double n[3];
        tri_normal(m, t, n);
        s += 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    }
    return s;
}

static void check_unit_cube(const char *path)
{
    rp_tri_mesh m;
    char msg[512];
    int rc = rp_cgal_read_mesh(path, 1, &m, msg, sizeof msg);
    cr_assert_eq(rc, 0, "%s: %s", path, msg);
    cr_expect_eq(m.nvertices, 8);
    cr_expect_eq(m.ntriangles, 12, "6 quads -> 12 triangles, got %zu", m.ntriangles);
    /* 12 triangles of area 1/2 each, coordinates exact in binary. */
    cr_expect_float_eq(total_area(&m), 6.0, 1e-12);
    cr_expect_eq(m.degenerate_faces, 0);
    cr_expect_eq(m.orientation_conflicts, 0);
    /* Triangulating must keep each quad's winding: every normal points out
     * of the cube, away from its centre (0.5, 0.5, 0.5). */
    for (size_t t = 0; t < m.ntriangles; t++) {
        double n[3], c[3] = {0, 0, 0};
        tri_normal(&m, t, n);
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++)
                c[j] += m.xyz[3 * m.tri[3 * t + k] + j] / 3.0;
        double out = n[0] * (c[0] - 0.5) + n[1] * (c[1] - 0.5) + n[2] * (c[2] - 0.5);
        cr_expect_gt(out, 0.0, "%s: triangle %zu faces inward", path, t);
    }
    cr_expect_null(m.tri_group);
    cr_expect_null(m.tri_material);
    cr_expect_eq(m.ngroups, 0);
    cr_expect_eq(m.nmaterials, 0);
    rp_tri_mesh_free(&m);
    cr_expect_null(m.xyz);
    cr_expect_null(m.tri);
    cr_expect_eq(m.ntriangles, 0);
}

Test(import, cube_obj) { check_unit_cube(DATA "cube.obj"); }
Test(import, cube_off) { check_unit_cube(DATA "cube.off"); }
Test(import, cube_ply) { check_unit_cube(DATA "cube.ply"); }

Test(import, nonconvex_polygon)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "lshape.obj", 1, &m, msg, sizeof msg), 0, "%s", msg);
    /* A simple hexagon triangulates into 6 - 2 = 4 triangles covering
     * exactly its area 3; a fan from the first vertex would cover 4. */
    cr_expect_eq(m.ntriangles, 4);
    cr_expect_float_eq(total_area(&m), 3.0, 1e-12);
    for (size_t t = 0; t < m.ntriangles; t++) {
        double n[3];
        tri_normal(&m, t, n);
        cr_expect_gt(n[2], 0.0, "triangle %zu lost the polygon's +z winding", t);
    }
    rp_tri_mesh_free(&m);
}

Test(import, degenerate_face_dropped_or_rejected)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "degenerate.obj", 0, &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.degenerate_faces, 1);
    cr_expect_eq(m.ntriangles, 12);
    cr_expect_float_eq(total_area(&m), 6.0, 1e-12);
    rp_tri_mesh_free(&m);

    int rc = rp_cgal_read_mesh(DATA "degenerate.obj", 1, &m, msg, sizeof msg);
    cr_expect_neq(rc, 0);
    /* "f 1 9 2" is on line 18 of the file. */
    cr_expect(strstr(msg, "degenerate.obj:18:") != NULL, "msg: %s", msg);
    cr_expect(strstr(msg, "degenerate") != NULL, "msg: %s", msg);
    cr_expect_null(m.xyz);
}

Test(import, flipped_face_counted)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "flipped.obj", 0, &m, msg, sizeof msg), 0, "%s", msg);
    /* The reversed top quad runs each of its 4 edges the same way as the
     * neighbouring side quad; its diagonal is internal and consistent. */
    cr_expect_eq(m.orientation_conflicts, 4);
    cr_expect_eq(m.ntriangles, 12);
    rp_tri_mesh_free(&m);
}

Test(import, closed_and_open)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "cube.obj", 0, &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(rp_cgal_is_closed(m.xyz, m.nvertices, m.tri, m.ntriangles, 0.0), 1);
    cr_expect_eq(rp_cgal_is_closed(m.xyz, m.nvertices, m.tri, m.ntriangles, 1e-6), 1);

    /* Open box: drop the two triangles of the top face z = 1. */
    uint32_t open[36];
    size_t nopen = 0;
    for (size_t t = 0; t < m.ntriangles; t++) {
        int top = 1;
        for (int k = 0; k < 3; k++)
            top = top && m.xyz[3 * m.tri[3 * t + k] + 2] == 1.0;
        if (!top) {
            memcpy(open + 3 * nopen, m.tri + 3 * t, 3 * sizeof(uint32_t));
            nopen++;
        }
    }
    cr_assert_eq(nopen, 10);
    cr_expect_eq(rp_cgal_is_closed(m.xyz, m.nvertices, open, nopen, 1e-6), 0);

    /* Bad input: an index past the last vertex. */
    uint32_t bad[3] = {0, 1, 8};
    cr_expect_eq(rp_cgal_is_closed(m.xyz, m.nvertices, bad, 1, 1e-6), -1);
    rp_tri_mesh_free(&m);
}

Test(import, soup_welded_closed)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "cube.obj", 0, &m, msg, sizeof msg), 0, "%s", msg);
    cr_assert_eq(m.ntriangles, 12);
    /* Every triangle gets its own three vertices, each copy moved by
     * (i+1) 1e-9 along every axis: copies of one corner differ by at most
     * 35e-9 sqrt(3) = 6.1e-8, and by at least 1e-9 sqrt(3) = 1.7e-9. */
    double xyz[36 * 3];
    uint32_t tri[36];
    for (size_t i = 0; i < 36; i++) {
        for (int c = 0; c < 3; c++)
            xyz[3 * i + c] = m.xyz[3 * m.tri[i] + c] + 1e-9 * (double)(i + 1);
        tri[i] = (uint32_t)i;
    }
    cr_expect_eq(rp_cgal_is_closed(xyz, 36, tri, 12, 1e-6), 1, "welded within 1e-6: closed");
    cr_expect_eq(rp_cgal_is_closed(xyz, 36, tri, 12, 1e-12), 0, "nothing welds at 1e-12");
    rp_tri_mesh_free(&m);
}

Test(import, edge_shared_by_four_is_not_closed)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "cube.obj", 0, &m, msg, sizeof msg), 0, "%s", msg);
    /* A second cube translated by (1, 1, 0) meets the first along the edge
     * x = y = 1: that edge has four triangles (an even count, but not a
     * 2-manifold), every other edge two. */
    double xyz[16 * 3];
    uint32_t tri[24 * 3];
    for (size_t i = 0; i < 8; i++)
        for (int c = 0; c < 3; c++) {
            xyz[3 * i + c] = m.xyz[3 * i + c];
            xyz[3 * (i + 8) + c] = m.xyz[3 * i + c] + (c < 2 ? 1.0 : 0.0);
        }
    for (size_t j = 0; j < 36; j++) {
        tri[j] = m.tri[j];
        tri[36 + j] = m.tri[j] + 8;
    }
    cr_expect_eq(rp_cgal_is_closed(xyz, 16, tri, 24, 1e-9), 0);
    /* Each cube alone is closed. */
    cr_expect_eq(rp_cgal_is_closed(xyz, 16, tri + 36, 12, 1e-9), 1);
    rp_tri_mesh_free(&m);
}

static size_t find_name(char **names, size_t n, const char *name)
{
    for (size_t i = 0; i < n; i++)
        if (strcmp(names[i], name) == 0)
            return i;
    return SIZE_MAX;
}

Test(import, obj_scene_groups_and_materials)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "scene.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.nvertices, 8);
    cr_assert_eq(m.ntriangles, 4);
    cr_assert_eq(m.ngroups, 2);
    cr_assert_eq(m.nmaterials, 2);
    size_t floor = find_name(m.group_names, m.ngroups, "floor");
    size_t lamp = find_name(m.group_names, m.ngroups, "lamp");
    size_t white = find_name(m.material_names, m.nmaterials, "white");
    size_t light = find_name(m.material_names, m.nmaterials, "light");
    cr_assert(floor != SIZE_MAX && lamp != SIZE_MAX, "groups %s, %s", m.group_names[0],
              m.group_names[1]);
    cr_assert(white != SIZE_MAX && light != SIZE_MAX);

    /* Values as written in scene.mtl; Ke absent means zero. */
    const double kd_white[3] = {0.725, 0.71, 0.68}, kd_light[3] = {0.1, 0.2, 0.3};
    const double ke_light[3] = {17, 12, 4};
    for (int c = 0; c < 3; c++) {
        cr_expect_float_eq(m.material_kd[3 * white + c], kd_white[c], 1e-15);
        cr_expect_float_eq(m.material_ke[3 * white + c], 0.0, 1e-15);
        cr_expect_float_eq(m.material_kd[3 * light + c], kd_light[c], 1e-15);
        cr_expect_float_eq(m.material_ke[3 * light + c], ke_light[c], 1e-15);
    }

    /* Floor: y = 0, facing +y, white; lamp: y = 1, facing -y, light; each a
     * unit square split in two. */
    double area[2] = {0, 0};
    for (size_t t = 0; t < m.ntriangles; t++) {
        double n[3];
        tri_normal(&m, t, n);
        int is_lamp = m.tri_group[t] == lamp;
        cr_expect(m.tri_group[t] == floor || is_lamp);
        cr_expect_eq(m.tri_material[t], is_lamp ? light : white);
        for (int k = 0; k < 3; k++)
            cr_expect_eq(m.xyz[3 * m.tri[3 * t + k] + 1], is_lamp ? 1.0 : 0.0);
        cr_expect_float_eq(n[1], is_lamp ? -1.0 : 1.0, 1e-15);
        area[is_lamp] += 0.5 * fabs(n[1]);
    }
    cr_expect_float_eq(area[0], 1.0, 1e-15);
    cr_expect_float_eq(area[1], 1.0, 1e-15);
    cr_expect_eq(m.degenerate_faces, 0);
    cr_expect_eq(m.orientation_conflicts, 0);
    rp_tri_mesh_free(&m);
    cr_expect_null(m.group_names);
    cr_expect_eq(m.nmaterials, 0);
}

Test(import, obj_scene_nonconvex_without_material)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "lshape.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.ntriangles, 4);
    cr_expect_float_eq(total_area(&m), 3.0, 1e-12);
    cr_expect_eq(m.ngroups, 1, "faces before any o/g form one unnamed group");
    cr_expect_eq(m.nmaterials, 0);
    for (size_t t = 0; t < m.ntriangles; t++) {
        double n[3];
        tri_normal(&m, t, n);
        cr_expect_gt(n[2], 0.0);
        cr_expect_eq(m.tri_group[t], 0);
        cr_expect_eq(m.tri_material[t], UINT32_MAX);
    }
    rp_tri_mesh_free(&m);
}

static void expect_error(int scene, const char *path, const char *needle)
{
    rp_tri_mesh m;
    char msg[512];
    int rc = scene ? rp_obj_read_scene(path, &m, msg, sizeof msg)
                   : rp_cgal_read_mesh(path, 0, &m, msg, sizeof msg);
    cr_expect_neq(rc, 0, "%s read without error", path);
    cr_expect(strstr(msg, needle) != NULL, "%s: message '%s' lacks '%s'", path, msg, needle);
    cr_expect_null(m.xyz);
    cr_expect_null(m.tri);
    rp_tri_mesh_free(&m);
}

Test(import, errors_name_file_and_line)
{
    expect_error(0, DATA "no_such_file.obj", "no_such_file.obj: cannot open");
    expect_error(0, DATA "cube.stl", "cube.stl: unknown mesh extension");
    expect_error(0, DATA "scene.mtl", "scene.mtl: unknown mesh extension");
    expect_error(0, DATA "garbage.obj", "garbage.obj: not a valid OBJ");
    expect_error(0, DATA "garbage.ply", "garbage.ply: not a valid PLY");
    expect_error(0, DATA "empty.off", "empty.off: no vertices");
    expect_error(0, DATA "nan.obj", "nan.obj:4:");
    expect_error(0, DATA "badindex.obj", "badindex.obj:6:");
    expect_error(0, DATA "badindex.off", "badindex.off:7:");
    expect_error(1, DATA "no_such_file.obj", "cannot open");
    expect_error(1, DATA "cube.off", "cube.off:");
    expect_error(1, DATA "garbage.obj", "garbage.obj: no vertices");
    expect_error(1, DATA "nan.obj", "nan.obj:4:");
    expect_error(1, DATA "badindex.obj", "badindex.obj:6:");
    expect_error(1, DATA "scene_nomtl.obj", "no_such_library.mtl");
    expect_error(1, DATA "scene_badmtl.obj", "chrome");
}

Test(import, bunny)
{
    rp_tri_mesh m;
    char msg[512];
    const char *path = RP_SOURCE_DIR "/scenes/data/bunny00.off";
    int rc = rp_cgal_read_mesh(path, 0, &m, msg, sizeof msg);
    cr_assert_eq(rc, 0, "%s (run `make scenes/data/bunny00.off`)", msg);
    /* Header line of the file: 37706 vertices, 75408 triangles. */
    cr_expect_eq(m.nvertices, 37706);
    cr_expect_eq(m.ntriangles + m.degenerate_faces, 75408);
    for (size_t i = 0; i < 3 * m.ntriangles; i++)
        cr_assert_lt(m.tri[i], m.nvertices);
    rp_tri_mesh_free(&m);
}

/* ------------------------------------------------ OBJ + MTL, as specified */

/* The number of the first line of a tests/data file containing needle:
 * where the file itself says a statement is, found without the reader. */
static size_t line_of(const char *file, const char *needle)
{
    char path[1024], buf[1024];
    snprintf(path, sizeof path, DATA "%s", file);
    FILE *f = fopen(path, "r");
    cr_assert_not_null(f, "cannot open %s", path);
    size_t n = 0, found = 0;
    while (!found && fgets(buf, sizeof buf, f)) {
        n++;
        if (strstr(buf, needle))
            found = n;
    }
    fclose(f);
    cr_assert_gt(found, 0, "%s has no line with '%s'", file, needle);
    return found;
}

/* The first warning of m containing needle, or NULL. */
static const char *warning_with(const rp_tri_mesh *m, const char *needle)
{
    for (size_t i = 0; i < m->nwarnings; i++)
        if (strstr(m->warnings[i], needle))
            return m->warnings[i];
    return NULL;
}

/* MTL (Wavefront, appendix B2): "Kd r g b ... g and b are optional; if
 * only r is specified, then g and b are assumed to be equal to r".  Kd 1
 * is a perfect reflector, inside the range [0, 1]. */
Test(import, mtl_one_value_is_grey_and_kd_1_accepted)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "mtl-values.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_assert_eq(m.nmaterials, 3);
    size_t grey = find_name(m.material_names, 3, "grey"), mirror = find_name(m.material_names, 3, "mirror"),
           lamp = find_name(m.material_names, 3, "lamp");
    cr_assert(grey != SIZE_MAX && mirror != SIZE_MAX && lamp != SIZE_MAX);
    for (int c = 0; c < 3; c++) {
        cr_expect_eq(m.material_kd[3 * grey + c], 0.7, "Kd 0.7 band %d: %g", c, m.material_kd[3 * grey + c]);
        cr_expect_eq(m.material_ke[3 * grey + c], 0.0);
        cr_expect_eq(m.material_kd[3 * mirror + c], 1.0);
        cr_expect_eq(m.material_kd[3 * lamp + c], 0.78);
        cr_expect_eq(m.material_ke[3 * lamp + c], 5.0, "Ke 5 band %d: %g", c, m.material_ke[3 * lamp + c]);
    }
    /* Ka is not read: listed, with its line and its count. */
    char where[64];
    snprintf(where, sizeof where, "mtl-values.mtl:%zu:", line_of("mtl-values.mtl", "Ka"));
    const char *w = warning_with(&m, where);
    cr_expect_not_null(w, "no warning at %s", where);
    cr_expect(w && strstr(w, "ignored: Ka (1 material)"), "%s", w ? w : "");
    rp_tri_mesh_free(&m);
}

Test(import, mtl_errors_name_the_mtl_file_and_line)
{
    char want[128];
    snprintf(want, sizeof want, "mtl-kd-high.mtl:%zu: Kd 1.2 outside [0, 1]", line_of("mtl-kd-high.mtl", "Kd 0.5 1.2"));
    expect_error(1, DATA "mtl-kd-high.obj", want);
    snprintf(want, sizeof want, "mtl-kd-word.mtl:%zu: Kd: 'half' is not a number", line_of("mtl-kd-word.mtl", "Kd 0.5 half"));
    expect_error(1, DATA "mtl-kd-word.obj", want);
    snprintf(want, sizeof want, "scene_nomtl.obj:%zu: material library", line_of("scene_nomtl.obj", "mtllib"));
    expect_error(1, DATA "scene_nomtl.obj", want);
    snprintf(want, sizeof want, "scene_badmtl.obj:%zu: usemtl 'chrome'", line_of("scene_badmtl.obj", "usemtl"));
    expect_error(1, DATA "scene_badmtl.obj", want);
}

/* drops.obj says in its comments what it holds: a floor quad, two exact
 * copies of it (one rotated), its reverse (kept), two zero-area faces, a
 * lamp, and vt / vn / s statements. */
Test(import, duplicates_and_zero_area_faces_dropped_with_lines)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "drops.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.duplicate_faces, 2);
    cr_expect_eq(m.duplicate_line, line_of("drops.obj", "f 1/1/1"));
    cr_expect_eq(m.degenerate_faces, 2);
    cr_expect_eq(m.degenerate_line, line_of("drops.obj", "f 1 2 5"));
    /* floor, its reverse and the lamp: three unit squares, two triangles each */
    cr_expect_eq(m.ntriangles, 6);
    cr_expect_float_eq(total_area(&m), 3.0, 1e-15);
    /* the reverse copy runs the floor's edges the other way: no conflict */
    cr_expect_eq(m.orientation_conflicts, 0);
    char where[64];
    snprintf(where, sizeof where, "drops.obj:%zu:", line_of("drops.obj", "vt 0 0"));
    const char *w = warning_with(&m, where);
    cr_expect_not_null(w, "no warning at %s", where);
    cr_expect(w && strstr(w, "ignored: vt (2 lines), vn (1), s (1)"), "%s", w ? w : "");
    for (size_t t = 0; t < m.ntriangles; t++)
        cr_expect_gt(m.tri_line[t], 0);
    rp_tri_mesh_free(&m);
}

Test(import, orientation_conflict_counted_with_line)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "conflict.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.orientation_conflicts, 1);
    cr_expect_eq(m.orientation_line, line_of("conflict.obj", "f 1 2 5 6"));
    rp_tri_mesh_free(&m);
}

/* McGuire's CornellBox-Original (public domain, tests/data): eight groups,
 * eight materials as its .mtl writes them, and one warning per kind of
 * thing radpt does not read. */
Test(import, mcguire_cornell_box)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_obj_read_scene(DATA "CornellBox-Original.obj", &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.ngroups, 8);
    cr_expect_eq(m.nmaterials, 8);
    cr_expect_eq(m.duplicate_faces, 0);
    cr_expect_eq(m.degenerate_faces, 0);
    size_t light = find_name(m.material_names, m.nmaterials, "light");
    cr_assert_neq(light, SIZE_MAX);
    const double ke[3] = {17, 12, 4};
    for (int c = 0; c < 3; c++) {
        cr_expect_eq(m.material_kd[3 * light + c], 0.78);
        cr_expect_eq(m.material_ke[3 * light + c], ke[c]);
    }
    char where[64];
    snprintf(where, sizeof where, "CornellBox-Original.mtl:%zu:", line_of("CornellBox-Original.mtl", "Ns"));
    const char *w = warning_with(&m, where);
    cr_expect(w && strstr(w, "ignored: Ns (8 materials), Ni (8), illum (8), Ka (8), Ks (8)"), "%s", w ? w : where);
    snprintf(where, sizeof where, "CornellBox-Original.mtl:%zu:", line_of("CornellBox-Original.mtl", "Ks 0.725"));
    w = warning_with(&m, where);
    cr_expect(w && strstr(w, "shortBox, tallBox have Kd 0 but a non-zero Ks"), "%s", w ? w : where);
    cr_expect_eq(m.nwarnings, 2);
    rp_tri_mesh_free(&m);
}

/* A one-material mesh drops zero-area faces too (OFF: located by line). */
Test(import, mesh_zero_area_face_dropped_with_line)
{
    rp_tri_mesh m;
    char msg[512];
    cr_assert_eq(rp_cgal_read_mesh(DATA "degenerate-tetra.off", 0, &m, msg, sizeof msg), 0, "%s", msg);
    cr_expect_eq(m.degenerate_faces, 1);
    cr_expect_eq(m.degenerate_line, line_of("degenerate-tetra.off", "3 0 1 4"));
    cr_expect_eq(m.ntriangles, 4);
    cr_expect_eq(m.orientation_conflicts, 0, "the dropped face's edge 0-1 is not counted");
    rp_tri_mesh_free(&m);
}

/* Header counts a file cannot hold are refused with FILE:LINE and the
 * count, before any reader reserves room for them (the fuzz target found
 * an OFF header of absurd counts that made CGAL's reader try a huge
 * allocation).  The bound is the file's own size: no fixed limit. */
Test(import, absurd_header_counts_are_refused_before_allocation)
{
    static const struct {
        const char *file, *where, *what;
    } cases[] = {
        {"huge-vertices.off", "huge-vertices.off:2:", "vertex count 4000000000 is more than the file's"},
        {"huge-faces.off", "huge-faces.off:2:", "face count 99999999999999 is more than"},
        {"negative-count.off", "negative-count.off:2:", "'-1' is not a face count"},
        {"garbage-count.off", "garbage-count.off:2:", "'3x' is not a vertex count"},
        {"huge-vertices.ply", "huge-vertices.ply:3:", "vertex count 3000000000 is more than"},
        {"huge-faces-binary.ply", "huge-faces-binary.ply:7:", "face count 99999999999 is more than"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char path[512], msg[1024];
        snprintf(path, sizeof path, DATA "bad-mesh/%s", cases[i].file);
        rp_tri_mesh m;
        memset(&m, 0, sizeof m);
        cr_expect_neq(rp_cgal_read_mesh(path, 1, &m, msg, sizeof msg), 0, "%s was accepted", cases[i].file);
        cr_expect(strstr(msg, cases[i].where) && strstr(msg, cases[i].what), "%s: %s", cases[i].file, msg);
        rp_tri_mesh_free(&m);
    }
}
