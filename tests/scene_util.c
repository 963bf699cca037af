/* Scenes for tests (see scene_util.h). */
#include "scene_util.h"

#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

rp_scene *rp_test_load(const char *rel)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", RP_SOURCE_DIR, rel);
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_load(path, &s, &err);
    cr_assert_eq(st, RP_OK, "scene %s: %s", rel, err.message);
    return s;
}

rp_scene *rp_test_parse_in(const char *text, const char *dir)
{
    rp_scene *s = NULL;
    rp_error err = {""};
    rp_status st = rp_scene_parse(text, "test.scene", dir, &s, &err);
    cr_assert_eq(st, RP_OK, "scene: %s", err.message);
    return s;
}

rp_scene *rp_test_parse(const char *text)
{
    return rp_test_parse_in(text, NULL);
}
void rp_test_mesh_free(rp_test_mesh *m)
{
    free(m->xyz);
    free(m->tri);
}

void rp_test_mesh_push(rp_test_mesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    m->tri[3 * m->nt] = a;
    m->tri[3 * m->nt + 1] = b;
    m->tri[3 * m->nt + 2] = c;
    m->nt++;
}

/* A unit sphere of `slices` x `stacks` (poles as fans), triangles wound
 * outward (inward when `inward`).  Rows of latitude first..last only
 * (0..stacks for the whole sphere; rows are stacks+1 rings, the poles being
 * rings of one point). */
rp_test_mesh rp_test_uv_sphere(int slices, int stacks, int first, int last, int inward)
{
    rp_test_mesh m = {0};
    size_t cap = (size_t)(stacks + 1) * (size_t)slices;
    m.xyz = malloc(3 * cap * sizeof *m.xyz);
    m.tri = malloc(6 * cap * sizeof *m.tri);
    cr_assert(m.xyz && m.tri);
    /* ring r (0 = north pole) */
    uint32_t *ring = malloc((size_t)(stacks + 1) * sizeof *ring);
    for (int r = first; r <= last; r++) {
        ring[r] = (uint32_t)m.nv;
        double th = M_PI * r / stacks;
        int n = (r == 0 || r == stacks) ? 1 : slices;
        for (int k = 0; k < n; k++) {
            double ph = 2 * M_PI * k / slices;
            m.xyz[3 * m.nv] = sin(th) * cos(ph);
            m.xyz[3 * m.nv + 1] = cos(th);
            m.xyz[3 * m.nv + 2] = sin(th) * sin(ph);
            m.nv++;
        }
    }
    for (int r = first; r < last; r++)
        for (int k = 0; k < slices; k++) {
            int k1 = (k + 1) % slices;
            uint32_t a = ring[r] + (r == 0 ? 0 : (uint32_t)k), b = ring[r] + (r == 0 ? 0 : (uint32_t)k1);
            uint32_t c = ring[r + 1] + (r + 1 == stacks ? 0 : (uint32_t)k),
                     d = ring[r + 1] + (r + 1 == stacks ? 0 : (uint32_t)k1);
            /* seen from outside, (a, c, d) and (a, d, b) are counter-clockwise
             * when y is up and phi turns from x to z: checked below */
            if (r != 0)
                rp_test_mesh_push(&m, a, d, c), rp_test_mesh_push(&m, a, b, d);
            else
                rp_test_mesh_push(&m, a, d, c);
            if (r == 0 || r + 1 == stacks) {
                if (r + 1 == stacks) {
                    m.nt--;
                    m.nt--;
                    rp_test_mesh_push(&m, a, b, c);
                }
            }
        }
    free(ring);
    /* Orient every triangle by its centroid (the sphere is star-shaped
     * about the origin), outward or inward as asked. */
    for (size_t f = 0; f < m.nt; f++) {
        const double *p0 = m.xyz + 3 * m.tri[3 * f], *p1 = m.xyz + 3 * m.tri[3 * f + 1],
                     *p2 = m.xyz + 3 * m.tri[3 * f + 2];
        double e1[3], e2[3], n[3], c[3];
        for (int i = 0; i < 3; i++) {
            e1[i] = p1[i] - p0[i];
            e2[i] = p2[i] - p0[i];
            c[i] = p0[i] + p1[i] + p2[i];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double out = n[0] * c[0] + n[1] * c[1] + n[2] * c[2];
        if ((out < 0) != (inward != 0)) {
            uint32_t t = m.tri[3 * f + 1];
            m.tri[3 * f + 1] = m.tri[3 * f + 2];
            m.tri[3 * f + 2] = t;
        }
    }
    return m;
}

void rp_test_write_off(const char *path, const rp_test_mesh *m)
{
    FILE *f = fopen(path, "w");
    cr_assert(f, "%s", path);
    fprintf(f, "OFF\n%zu %zu 0\n", m->nv, m->nt);
    for (size_t i = 0; i < m->nv; i++)
        fprintf(f, "%.17g %.17g %.17g\n", m->xyz[3 * i], m->xyz[3 * i + 1], m->xyz[3 * i + 2]);
    for (size_t t = 0; t < m->nt; t++)
        fprintf(f, "3 %u %u %u\n", m->tri[3 * t], m->tri[3 * t + 1], m->tri[3 * t + 2]);
    fclose(f);
}
