/* The default camera (default_camera.h).
 *
 * Outside view: eye on the +z side of the bounding box, on its axis,
 * looking along -z with up +y, at the distance where the box's near face
 * (z = zmax, the largest it appears in perspective) fills the vertical
 * field of RP_DEFAULT_CAMERA_FOV with a 10% margin:
 *
 *     d = 1.1 h / tan(fov / 2),   h = max(x extent, y extent) / 2.
 *
 * A closed room (its faces facing inwards) seen from there shows only the
 * backs of its walls, which are black for every solver.  So the view is
 * tested: 7 x 7 rays through the image find the first face each meets;
 * when back faces outnumber front faces, two eyes inside the box are tried
 * (near the +z wall, then the centre), with the field widened so that the
 * -z wall fills 70% of it and the walls around it show (40 to 100
 * degrees), and the first whose rays meet more fronts than backs is used.  If none does, the outside view stays. */
#include "default_camera.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"

#define MARGIN 1.1
#define PROBE_RAYS 7 /* per image side */
#define FOV_MAX 100.0
#define INSIDE_FILL 0.7 /* the far wall's share of the view from inside */
#define ROUND_REL 1e-6 /* printed digits resolve 1e-6 of the scene's extent */

/* Closest hit of the ray o + t d (t > 0) on a triangle (Moller & Trumbore
 * 1997); t or INFINITY. */
static double ray_triangle(rp_vec3 o, rp_vec3 d, rp_vec3 a, rp_vec3 b, rp_vec3 c)
{
    rp_vec3 e1 = rp_v3_sub(b, a), e2 = rp_v3_sub(c, a);
    rp_vec3 pv = rp_v3_cross(d, e2);
    double det = rp_v3_dot(e1, pv);
    if (det == 0 || !isfinite(det))
        return INFINITY;
    double inv = 1.0 / det;
    rp_vec3 tv = rp_v3_sub(o, a);
    double u = rp_v3_dot(tv, pv) * inv;
    if (u < 0 || u > 1)
        return INFINITY;
    rp_vec3 qv = rp_v3_cross(tv, e1);
    double v = rp_v3_dot(d, qv) * inv;
    if (v < 0 || u + v > 1)
        return INFINITY;
    double t = rp_v3_dot(e2, qv) * inv;
    return t > 0 ? t : INFINITY;
}

/* Counts the first hits of the probe rays of cam that meet a face's front
 * and its back. */
static void probe_view(const rp_scene *s, const rp_camera *cam, int *front, int *back)
{
    rp_camera_frame fr;
    rp_camera_frame_init(&fr, cam);
    const rp_face *faces = rp_scene_faces(s);
    const rp_vec3 *V = rp_scene_vertices(s);
    size_t nf = rp_scene_nfaces(s);
    *front = *back = 0;
    for (int j = 0; j < PROBE_RAYS; j++)
        for (int i = 0; i < PROBE_RAYS; i++) {
            double x = (i + 0.5) * cam->width / PROBE_RAYS, y = (j + 0.5) * cam->height / PROBE_RAYS;
            rp_vec3 d = rp_camera_direction(&fr, x, y);
            double best = INFINITY;
            size_t hit = nf;
            for (size_t f = 0; f < nf; f++) {
                const rp_face *fc = &faces[f];
                rp_vec3 a = V[fc->v[0]], b = V[fc->v[1]], c = V[fc->v[2]];
                double t = ray_triangle(cam->eye, d, a, b, c);
                if (fc->nverts == 4) {
                    double t2 = ray_triangle(cam->eye, d, a, c, V[fc->v[3]]);
                    t = t2 < t ? t2 : t;
                }
                if (t < best) {
                    best = t;
                    hit = f;
                }
            }
            if (hit == nf)
                continue;
            if (rp_v3_dot(faces[hit].normal, d) < 0)
                ++*front;
            else
                ++*back;
        }
}

/* The fewest %g digits (at least min_digits) that give v back. */
static int print_number(char *buf, size_t len, double v, int min_digits)
{
    char tmp[64];
    for (int p = min_digits; p < 17; p++) {
        snprintf(tmp, sizeof tmp, "%.*g", p, v);
        if (strtod(tmp, NULL) == v)
            return snprintf(buf, len, "%s", tmp);
    }
    return snprintf(buf, len, "%.17g", v);
}

int rp_camera_format(const rp_camera *c, char *buf, size_t len)
{
    const double v[10] = {c->eye.x,  c->eye.y,  c->eye.z,  c->look.x, c->look.y, c->look.z,
                          c->up.x,   c->up.y,   c->up.z,   c->fov_deg};
    static const char *const lead[10] = {"eye ", " ", " ", " look ", " ", " ", " up ", " ", " ", " fov "};
    char out[512], num[64];
    size_t n = 0;
    out[0] = '\0';
    for (int k = 0; k < 10; k++) {
        print_number(num, sizeof num, v[k] == 0 ? 0.0 : v[k], 6);
        n += (size_t)snprintf(out + n, sizeof out - n, "%s%s", lead[k], num);
    }
    snprintf(out + n, sizeof out - n, " size %u %u", c->width, c->height);
    return snprintf(buf, len, "%s", out);
}

/* v rounded to the digits that resolve quantum q (at least 6). */
static double round_to(double v, double q)
{
    if (v == 0 || !(q > 0))
        return v;
    int digits = (int)floor(log10(fabs(v))) - (int)floor(log10(q)) + 1;
    if (digits < 6)
        digits = 6;
    if (digits > 17)
        return v;
    char tmp[64];
    snprintf(tmp, sizeof tmp, "%.*g", digits, v);
    return strtod(tmp, NULL);
}

static rp_vec3 round_vec(rp_vec3 v, double q)
{
    return rp_v3(round_to(v.x, q), round_to(v.y, q), round_to(v.z, q));
}

/* A camera at eye looking along -z, rounded so that its printed words give
 * it back; fov in degrees. */
static rp_status make_camera(rp_vec3 eye, double dist, double fov, double q, rp_camera *out, rp_error *err)
{
    rp_camera c;
    memset(&c, 0, sizeof c);
    c.eye = round_vec(eye, q);
    c.look = round_vec(rp_v3(eye.x, eye.y, eye.z - dist), q);
    c.up = rp_v3(0, 1, 0);
    c.fov_deg = round_to(fov, 1e-4);
    c.width = c.height = RP_DEFAULT_CAMERA_SIZE;
    char words[512];
    rp_camera_format(&c, words, sizeof words);
    return rp_camera_parse(words, "default camera", out, err);
}

rp_status rp_scene_default_camera(const rp_scene *s, rp_camera *out, rp_error *err)
{
    if (!s || !out || rp_scene_nfaces(s) == 0)
        return rp_error_set(err, RP_ERR_INPUT, "default camera: the scene has no faces");
    rp_vec3 lo, hi;
    rp_scene_bounds(s, &lo, &hi);
    rp_vec3 e = rp_v3_sub(hi, lo), c = rp_v3_scale(rp_v3_add(lo, hi), 0.5);
    double extent = fmax(e.x, fmax(e.y, e.z));
    double h = 0.5 * fmax(e.x, e.y);
    if (!(h > 0))
        h = 0.5 * extent;
    const double q = ROUND_REL * extent;
    const double t = tan(0.5 * RP_DEFAULT_CAMERA_FOV * RP_PI / 180);

    double d = MARGIN * h / t;
    rp_camera outside;
    rp_status st = make_camera(rp_v3(c.x, c.y, hi.z + d), d + 0.5 * e.z, RP_DEFAULT_CAMERA_FOV, q, &outside, err);
    if (st)
        return st;
    int front, back;
    probe_view(s, &outside, &front, &back);
    *out = outside;
    if (back <= front || !(e.z > 0))
        return RP_OK;

    /* Inside: near the +z wall, then at the centre. */
    const double depth[2] = {0.95, 0.5}; /* distance to the -z wall / z extent */
    for (int k = 0; k < 2; k++) {
        double dist = depth[k] * e.z;
        double fov = 2 * atan(h / (INSIDE_FILL * dist)) * 180 / RP_PI;
        fov = fmin(FOV_MAX, fmax(RP_DEFAULT_CAMERA_FOV, fov));
        rp_camera in;
        if ((st = make_camera(rp_v3(c.x, c.y, lo.z + dist), dist, fov, q, &in, err)))
            return st;
        int f2, b2;
        probe_view(s, &in, &f2, &b2);
        if (f2 > b2) {
            *out = in;
            return RP_OK;
        }
    }
    return RP_OK;
}
