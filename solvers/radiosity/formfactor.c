/* Element-to-element form factors (formfactor.h): analytic and Monte Carlo
 * here, the hemicube in hemicube.c.
 *
 * Analytic.  F_ij = 1/A_i int_Ai F(x -> A_j) V_ij dA_i, where the inner
 * integral F(x -> A_j) is Lambert's contour formula (Baum, Rushmeier &
 * Winget 1989, eq. 2), exact for a polygon in front of x's tangent plane.
 * Every x on element i shares one tangent plane (i's), so A_j is clipped
 * against it once per pair, and i is clipped against j's plane (the points
 * of i behind j see its black back: zero).  Only the outer integral over the
 * receiver needs care, and only where the pair is close: the integrand has
 * a weak (s log s) singularity along a shared edge and a kink where j's
 * plane cuts i.
 *
 * Error goal.  The tolerance tau bounds each pair's error relative to
 * S_ij = max(F_ij, min(1, A_j / (pi d^2))), d the distance between
 * centroids: the form factor itself, or, for pairs that see each other at
 * grazing angles and have a tiny F_ij, about the form factor they would
 * have face on.  Summed over a row, S_ij covers the sphere of directions a
 * few times at most, so row sums are good to a few tau whatever the mesh.
 *
 * The outer integral by the receiver's size relative to the gap between
 * the two elements' bounding spheres, rho = r_i / (d - r_i - r_j):
 *
 *   1a. rho^4 C_A <= tau (quads) or rho^3 C_A' <= tau (triangles): the 2x2
 *       Gauss rule on the receiver's bilinear map, or Strang & Fix's
 *       3-point degree-2 rule on triangles;
 *   1b. rho^6 C_B <= tau: 3x3 Gauss, or Radon's 7-point degree-5 rule
 *       (Stroud 1971, T2:5-1);
 *   2.  otherwise, and whenever a polygon was clipped, globally adaptive
 *       cubature (Genz & Malik 1980; the strategy of Berntsen, Espelid &
 *       Genz 1991): the domain (i clipped, as one bilinear quad or a fan of
 *       triangles, each mapped from the unit square, triangles by the Duffy
 *       map so that every edge is a side of the square) starts as one
 *       region per map, each with the 17-point degree-7 Genz-Malik
 *       estimate; the region with the largest error is bisected along the
 *       axis with the larger fourth difference until the summed error is
 *       below tau S_ij A_i / 4.  A region's error is the larger of Genz &
 *       Malik's |Q7 - Q5| and half the change its parent saw on splitting
 *       (no region stands unsplit).  Bisection along one axis lets regions
 *       grade towards a shared edge as thin strips: O(log 1/tau) regions.
 *
 * The constants C_A = 0.5, C_A' = 0.15, C_B = 0.1 are four times the
 * largest error / (S rho^k) measured against stage 2 at tau = 1e-12 on
 * random element pairs of the Cornell box (300 to 20,000 elements), a
 * closed box, a box with a block and tilted triangles, and the bunny scene.
 * A row's far-pair rules share their points (those of the receiver), so
 * each edge of the mesh is evaluated once per row and its term used, with
 * opposite signs, by the two elements on either side of it.
 *
 * Pairs.  Of F_ij and F_ji only one is computed, from the smaller
 * element's side (the smaller bounding radius; ties: the lower index): the
 * integral over the receiver is then the cheaper and the more accurate
 * one, and the other follows from A_i F_ij = A_j F_ji (rp_ff_primary).
 *
 * Visibility (analytic) is a weighted fraction of unoccluded rays from
 * jittered stratified points x_s of the receiver (k x k strata, k = 2, 3
 * or 4 as the pair gets closer relative to its size; params.visibility_rays
 * overrides) to points of the source, each ray weighted by the exact
 * unoccluded form factor from x_s to the part of the source it stands for,
 * the source being split where that part is large (ff_visibility).  No ray
 * is cast when no face of the scene can block the pair: a face k can block
 * a segment between i and j only if (a) part of it lies in front of both
 * planes, (b) i and j are not both on one side of k's plane, and (c) its
 * bounding box meets theirs.  These tests run per pair of scene faces once
 * (the context), and per pair of elements against the short list of
 * candidate blockers.  The pair's visibility is stored in a table shared
 * by the threads (meshes up to 8192 elements), so a pair is cast once
 * however often its rows or columns are computed.
 *
 * Monte Carlo: point pairs uniform in area on i and j; the estimator
 * A_j cos cos V / (pi r^2) has mean F_ij; its sample standard deviation
 * over sqrt(N) is the standard error.  For elements sharing an edge the
 * estimator's variance is infinite (the kernel ~ 1/r^2 near the edge), so
 * the standard error there is not to be trusted.
 *
 * Random numbers are a counter-based hash of (seed, i, j, sample), so a row
 * does not depend on the thread that computes it. */
#include "ff_internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define RP_FF_DEFAULT_SAMPLES 256
#define RP_FF_DEFAULT_RESOLUTION 256
/* Absolute floor of the analytic error goal (form-factor units). */
#define RP_FF_TOL_ABS 1e-14
/* A priori error constants of the far-pair rules (see the header). */
#define RP_FF_C_A_QUAD 0.5
#define RP_FF_C_A_TRI 0.15
#define RP_FF_C_B 0.1
/* The adaptive stage aims this far below the tolerance: its error
 * estimate, though conservative on average, was measured up to 2x short on
 * adjacent rectangles (tests/test_formfactor.c). */
#define RP_FF_ADAPT_MARGIN 0.25
/* Regions the adaptive cubature may hold; beyond it the estimate stands. */
#define RP_FF_MAX_REGIONS 4000
/* Scene faces above which the per-face-pair blocker table is not built. */
#define RP_FF_MAX_BLK_FACES 256
/* Longest blocker list tested per element pair. */
#define RP_FF_MAX_BLK_LIST 48
/* Largest mesh with a shared visibility cache (2 bytes per pair). */
#define RP_FF_MAX_VCACHE 8192
/* Visibility (ff_visibility): a source cell is split while the form
 * factor from a receiver point to it exceeds this times the number of
 * receiver points; at most RP_FF_VIS_MAX_RAYS rays per pair and cells
 * RP_FF_VIS_DEPTH bisections deep.  RP_FF_VIS_COUNTER: where the cells'
 * random numbers start in the pair's stream. */
#define RP_FF_VIS_CELL 5e-4
#define RP_FF_VIS_MAX_RAYS 1024
/* Cells smaller than this times their distance are weighted by the
 * differential form factor (ff_point_cell). */
#define RP_FF_VIS_FAR_CELL 0.15
/* Segments a pair can cast: the cells, or one per receiver point when
 * --ff-rays asks for more points than that (at most 4096). */
#define RP_FF_VIS_SEGMENTS (RP_FF_VIS_MAX_RAYS + 4096)
#define RP_FF_VIS_DEPTH 24
#define RP_FF_VIS_COUNTER (UINT64_C(1) << 24)
/* Plane-side tolerance relative to a polygon's own size (rp_ff_tol). */
#define RP_FF_EPS_REL 1e-9

/* ---- random numbers ----------------------------------------------------- */

/* SplitMix64's output function (Steele, Lea & Flood 2014). */
static inline uint64_t ff_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static inline uint64_t ff_key(uint64_t seed, uint32_t i, uint32_t j)
{
    return ff_mix(ff_mix(seed + UINT64_C(0x9e3779b97f4a7c15)) ^ (((uint64_t)i << 32) | j));
}

/* Uniform in [0, 1), 53 bits. */
static inline double ff_u01(uint64_t key, uint64_t k)
{
    return (double)(ff_mix(key + (k + 1) * UINT64_C(0x9e3779b97f4a7c15)) >> 11) * 0x1.0p-53;
}

/* ---- names -------------------------------------------------------------- */

rp_status rp_ff_method_parse(const char *name, rp_ff_method *out, rp_error *err)
{
    static const struct {
        const char *name;
        rp_ff_method m;
    } table[] = {{"analytic", RP_FF_ANALYTIC}, {"montecarlo", RP_FF_MONTECARLO},
                 {"hemicube", RP_FF_HEMICUBE}};
    for (size_t k = 0; name && k < sizeof table / sizeof table[0]; k++)
        if (strcmp(name, table[k].name) == 0) {
            *out = table[k].m;
            return RP_OK;
        }
    return rp_error_set(err, RP_ERR_INPUT,
                        "unknown form-factor method '%s' (analytic, montecarlo or hemicube)",
                        name ? name : "(null)");
}

const char *rp_ff_method_name(rp_ff_method m)
{
    switch (m) {
    case RP_FF_ANALYTIC: return "analytic";
    case RP_FF_MONTECARLO: return "montecarlo";
    case RP_FF_HEMICUBE: return "hemicube";
    }
    return "?";
}

/* ---- geometry helpers --------------------------------------------------- */

/* atan2(y, x) for y >= 0, (x, y) != (0, 0): the contour sum's edge angle,
 * about a third of the analytic method's time with libm's atan2.  The
 * argument t = min/max of |x|, y in [0, 1] is reduced to |u| <= tan(pi/32)
 * by atan t = k pi/16 + atan u, u = (t - c_k)/(1 + t c_k), c_k =
 * tan(k pi/16) the nearest of five; then eight terms of atan's Taylor
 * series leave a truncation error below 1e-17 (|u|^17 / 17); measured
 * against libm over 2e7 arguments, 4.4e-16 at most. */
static const double ff_tan16[5] = {0.0, 0.19891236737965800691, 0.41421356237309504880,
                                   0.66817863791929891999, 1.0};
static const double ff_tan32[4] = {0.09849140335716425307, 0.30334668360734239167,
                                   0.53451113595079158137, 0.82067879082866033421};

static inline double ff_atan2_pos(double y, double x)
{
    double ax = fabs(x);
    int swap = y > ax;
    double a = swap ? ax : y, b = swap ? y : ax;
    int k = (a > ff_tan32[0] * b) + (a > ff_tan32[1] * b) + (a > ff_tan32[2] * b) +
            (a > ff_tan32[3] * b);
    double c = ff_tan16[k];
    double u = (a - c * b) / (b + c * a);
    double s = u * u;
    double p = 1.0 / 17;
    p = p * s - 1.0 / 15;
    p = p * s + 1.0 / 13;
    p = p * s - 1.0 / 11;
    p = p * s + 1.0 / 9;
    p = p * s - 1.0 / 7;
    p = p * s + 1.0 / 5;
    p = p * s - 1.0 / 3;
    double r = k * (RP_PI / 16) + (u + u * s * p);
    if (swap)
        r = RP_PI / 2 - r;
    return x < 0 ? RP_PI - r : r;
}

/* One edge's term of Lambert's contour sum seen from x with normal n, for
 * the edge a -> b of a polygon counter-clockwise seen from its front (the
 * side x is on): gamma n . (R_b x R_a) / |R_b x R_a| (the ground-truth
 * formula's R_a x R_b, negated for this orientation). */
static inline double ff_edge_term(rp_vec3 x, rp_vec3 n, rp_vec3 a, rp_vec3 b)
{
    rp_vec3 ra = rp_v3_sub(a, x), rb = rp_v3_sub(b, x);
    rp_vec3 c = rp_v3_cross(rb, ra);
    double cl = rp_v3_length(c);
    return cl > 0 ? ff_atan2_pos(cl, rp_v3_dot(ra, rb)) * rp_v3_dot(n, c) / cl : 0.0;
}

double rp_ff_point_polygon(rp_vec3 p, rp_vec3 n, const rp_vec3 *v, uint32_t nv)
{
    double sum = 0;
    for (uint32_t k = 0; k < nv; k++)
        sum += ff_edge_term(p, n, v[k], v[k + 1 == nv ? 0 : k + 1]);
    return sum / (2.0 * RP_PI);
}

uint32_t rp_ff_clip(const rp_vec3 *in, uint32_t nin, rp_vec3 m, double e, rp_vec3 *out)
{
    uint32_t k = 0;
    for (uint32_t a = 0; a < nin; a++) {
        uint32_t b = a + 1 == nin ? 0 : a + 1;
        double da = rp_v3_dot(m, in[a]) - e, db = rp_v3_dot(m, in[b]) - e;
        if (da >= 0)
            out[k++] = in[a];
        if ((da >= 0) != (db >= 0)) {
            double t = da / (da - db);
            out[k++] = rp_v3_madd(in[a], rp_v3_sub(in[b], in[a]), t);
        }
    }
    return k;
}

/* Range of signed distances of a polygon's corners from the plane n.x = d. */
static void ff_side(const rp_vec3 *v, uint32_t nv, rp_vec3 n, double d, double *lo, double *hi)
{
    double a = INFINITY, b = -INFINITY;
    for (uint32_t k = 0; k < nv; k++) {
        double s = rp_v3_dot(n, v[k]) - d;
        a = s < a ? s : a;
        b = s > b ? s : b;
    }
    *lo = a;
    *hi = b;
}

static int ff_boxes_meet(rp_vec3 alo, rp_vec3 ahi, rp_vec3 blo, rp_vec3 bhi, double eps)
{
    return alo.x <= bhi.x + eps && blo.x <= ahi.x + eps && alo.y <= bhi.y + eps &&
           blo.y <= ahi.y + eps && alo.z <= bhi.z + eps && blo.z <= ahi.z + eps;
}

static rp_vec3 ff_vmin(rp_vec3 a, rp_vec3 b)
{
    return rp_v3(fmin(a.x, b.x), fmin(a.y, b.y), fmin(a.z, b.z));
}
static rp_vec3 ff_vmax(rp_vec3 a, rp_vec3 b)
{
    return rp_v3(fmax(a.x, b.x), fmax(a.y, b.y), fmax(a.z, b.z));
}

/* The plane-side tolerance of a polygon with bounding box lo..hi whose
 * corners lie up to twist off its plane: 1e-9 of its own size plus the
 * double rounding of its coordinates' magnitudes, never the scene's size. */
static double ff_tol(rp_vec3 lo, rp_vec3 hi, double twist)
{
    double m = fmax(fmax(fmax(fabs(lo.x), fabs(hi.x)), fmax(fabs(lo.y), fabs(hi.y))),
                    fmax(fabs(lo.z), fabs(hi.z)));
    return RP_FF_EPS_REL * rp_v3_length(rp_v3_sub(hi, lo)) + 64 * DBL_EPSILON * m + twist;
}

/* How far the corners of scene face f lie off its plane (quads are planar
 * only to 1e-6 of their diagonal, scene.c). */
static double ff_face_twist(const rp_scene *scene, uint32_t f)
{
    const rp_face *fc = &rp_scene_faces(scene)[f];
    const rp_vec3 *V = rp_scene_vertices(scene);
    double d = rp_v3_dot(fc->normal, V[fc->v[0]]), t = 0;
    for (uint32_t k = 1; k < fc->nverts; k++)
        t = fmax(t, fabs(rp_v3_dot(fc->normal, V[fc->v[k]]) - d));
    return t;
}

/* Could polygon K (plane nk.x = dk, box klo..khi) block a segment from
 * polygon A to polygon B (each with its plane)?  Conservative: 1 unless one
 * of the separating tests in the header comment proves it cannot. */
static int ff_can_block(const rp_vec3 *kv, uint32_t kn, rp_vec3 nk, double dk, rp_vec3 klo,
                        rp_vec3 khi, const rp_vec3 *av, uint32_t an, rp_vec3 na, double da,
                        const rp_vec3 *bv, uint32_t bn, rp_vec3 nb, double db, rp_vec3 lo,
                        rp_vec3 hi, double eps)
{
    if (!ff_boxes_meet(klo, khi, lo, hi, eps))
        return 0;
    double l1, h1, l2, h2;
    ff_side(kv, kn, na, da, &l1, &h1);
    if (h1 <= eps) /* K entirely behind (or on) A's plane */
        return 0;
    ff_side(kv, kn, nb, db, &l1, &h1);
    if (h1 <= eps)
        return 0;
    ff_side(av, an, nk, dk, &l1, &h1);
    ff_side(bv, bn, nk, dk, &l2, &h2);
    if ((l1 >= -eps && l2 >= -eps) || (h1 <= eps && h2 <= eps))
        return 0; /* A and B on one side of K's plane */
    return 1;
}

/* ---- context ------------------------------------------------------------ */

void rp_ff_context_destroy(rp_ff_context *ctx)
{
    if (!ctx)
        return;
    free(ctx->el);
    free(ctx->eid);
    free(ctx->erev);
    free(ctx->ea);
    free(ctx->eb);
    free((void *)ctx->vcache);
    free(ctx->blk_start);
    free(ctx->blk_count);
    free(ctx->blk);
    free(ctx->face_lo);
    free(ctx->face_hi);
    free(ctx->face_tol);
    free(ctx->dff_top);
    free(ctx->dff_side);
    free(ctx);
}

/* Face corners (3 or 4) of scene face f. */
static uint32_t ff_face_verts(const rp_scene *scene, uint32_t f, rp_vec3 *out)
{
    const rp_face *fc = &rp_scene_faces(scene)[f];
    const rp_vec3 *V = rp_scene_vertices(scene);
    for (uint32_t k = 0; k < fc->nverts; k++)
        out[k] = V[fc->v[k]];
    return fc->nverts;
}

/* The per-face-pair candidate blockers (see the header comment). */
static rp_status ff_build_blockers(rp_ff_context *ctx, rp_error *err)
{
    const rp_scene *scene = ctx->scene;
    size_t nf = rp_scene_nfaces(scene);
    ctx->nfaces = nf;
    if (!ctx->rc || nf > RP_FF_MAX_BLK_FACES)
        return RP_OK;
    const rp_face *faces = rp_scene_faces(scene);
    ctx->face_lo = malloc(nf * sizeof *ctx->face_lo);
    ctx->face_hi = malloc(nf * sizeof *ctx->face_hi);
    ctx->face_tol = malloc(nf * sizeof *ctx->face_tol);
    double *fd = malloc(nf * sizeof *fd);
    rp_vec3 *fv = malloc(nf * 4 * sizeof *fv);
    ctx->blk_start = malloc(nf * nf * sizeof *ctx->blk_start);
    ctx->blk_count = malloc(nf * nf * sizeof *ctx->blk_count);
    if (!ctx->face_lo || !ctx->face_hi || !ctx->face_tol || !fd || !fv || !ctx->blk_start || !ctx->blk_count) {
        free(fd);
        free(fv);
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for %zu faces", nf);
    }
    for (size_t f = 0; f < nf; f++) {
        uint32_t m = ff_face_verts(scene, (uint32_t)f, &fv[4 * f]);
        rp_vec3 lo = fv[4 * f], hi = fv[4 * f];
        for (uint32_t k = 1; k < m; k++) {
            lo = ff_vmin(lo, fv[4 * f + k]);
            hi = ff_vmax(hi, fv[4 * f + k]);
        }
        ctx->face_lo[f] = lo;
        ctx->face_hi[f] = hi;
        ctx->face_tol[f] = ff_tol(lo, hi, ff_face_twist(scene, (uint32_t)f));
        fd[f] = rp_v3_dot(faces[f].normal, fv[4 * f]);
    }
    /* Two passes: count, then fill. */
    size_t total = 0;
    for (int pass = 0; pass < 2; pass++) {
        size_t at = 0;
        for (size_t a = 0; a < nf; a++) {
            for (size_t b = 0; b < nf; b++) {
                size_t ab = a * nf + b;
                if (b < a) { /* symmetric */
                    if (pass == 0)
                        ctx->blk_count[ab] = ctx->blk_count[b * nf + a];
                    ctx->blk_start[ab] = ctx->blk_start[b * nf + a];
                    continue;
                }
                rp_vec3 lo = ff_vmin(ctx->face_lo[a], ctx->face_lo[b]);
                rp_vec3 hi = ff_vmax(ctx->face_hi[a], ctx->face_hi[b]);
                uint32_t cnt = 0;
                if (pass == 1)
                    ctx->blk_start[ab] = (uint32_t)at;
                for (size_t k = 0; k < nf && a != b; k++) {
                    if (k == a || k == b)
                        continue;
                    if (!ff_can_block(&fv[4 * k], faces[k].nverts, faces[k].normal, fd[k],
                                      ctx->face_lo[k], ctx->face_hi[k], &fv[4 * a], faces[a].nverts,
                                      faces[a].normal, fd[a], &fv[4 * b], faces[b].nverts,
                                      faces[b].normal, fd[b], lo, hi,
                                      ctx->face_tol[a] + ctx->face_tol[b] + ctx->face_tol[k]))
                        continue;
                    if (pass == 1 && ctx->blk_count[ab] != RP_FF_BLK_ALL)
                        ctx->blk[at + cnt] = (uint32_t)k;
                    cnt++;
                }
                if (pass == 0) {
                    ctx->blk_count[ab] = cnt > RP_FF_MAX_BLK_LIST ? RP_FF_BLK_ALL : cnt;
                    total += ctx->blk_count[ab] == RP_FF_BLK_ALL ? 0 : cnt;
                } else if (ctx->blk_count[ab] != RP_FF_BLK_ALL) {
                    at += cnt;
                }
            }
        }
        if (pass == 0) {
            ctx->blk = malloc((total ? total : 1) * sizeof *ctx->blk);
            if (!ctx->blk) {
                free(fd);
                free(fv);
                return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for blockers");
            }
        }
    }
    free(fd);
    free(fv);
    return RP_OK;
}

typedef struct ff_edge_key {
    uint32_t lo, hi, slot;
} ff_edge_key;

static int ff_edge_cmp(const void *pa, const void *pb)
{
    const ff_edge_key *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return a->slot < b->slot ? -1 : a->slot > b->slot;
}

/* Numbers the edges of the mesh: two element edges are one edge when they
 * join the same two mesh vertices. */
static rp_status ff_build_edges(rp_ff_context *ctx, rp_error *err)
{
    const rp_element *E = rp_mesh_elements(ctx->mesh);
    const rp_vec3 *V = rp_mesh_vertices(ctx->mesh);
    size_t n = ctx->n, m = 0;
    ff_edge_key *keys = malloc((4 * n + 1) * sizeof *keys);
    ctx->eid = malloc((4 * n + 1) * sizeof *ctx->eid);
    ctx->erev = calloc(4 * n + 1, 1);
    if (!keys || !ctx->eid || !ctx->erev) {
        free(keys);
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for %zu elements", n);
    }
    for (size_t e = 0; e < n; e++)
        for (uint32_t k = 0; k < E[e].nverts; k++) {
            uint32_t a = E[e].v[k], b = E[e].v[k + 1 == E[e].nverts ? 0 : k + 1];
            keys[m++] = (ff_edge_key){a < b ? a : b, a < b ? b : a, (uint32_t)(4 * e + k)};
            ctx->erev[4 * e + k] = a > b;
        }
    qsort(keys, m, sizeof *keys, ff_edge_cmp);
    size_t ne = 0;
    for (size_t t = 0; t < m; t++) {
        if (t > 0 && (keys[t].lo != keys[t - 1].lo || keys[t].hi != keys[t - 1].hi))
            ne++;
        ctx->eid[keys[t].slot] = (uint32_t)ne;
    }
    ne += m > 0;
    ctx->nedges = ne;
    ctx->ea = malloc((ne + 1) * sizeof *ctx->ea);
    ctx->eb = malloc((ne + 1) * sizeof *ctx->eb);
    if (!ctx->ea || !ctx->eb) {
        free(keys);
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for %zu edges", ne);
    }
    for (size_t t = 0; t < m; t++) {
        ctx->ea[ctx->eid[keys[t].slot]] = V[keys[t].lo];
        ctx->eb[ctx->eid[keys[t].slot]] = V[keys[t].hi];
    }
    free(keys);
    return RP_OK;
}

rp_status rp_ff_context_create(const rp_scene *scene, const rp_mesh *mesh, const rp_raycast *rc,
                               const rp_ff_params *params, rp_ff_context **out, rp_error *err)
{
    *out = NULL;
    if (!scene || !mesh)
        return rp_error_set(err, RP_ERR_INPUT, "formfactor: no scene or mesh");
    rp_ff_params p = {.size = sizeof p, .method = RP_FF_ANALYTIC};
    if (params) {
        if (params->size < offsetof(rp_ff_params, seed) + sizeof params->seed)
            return rp_error_set(err, RP_ERR_INPUT, "formfactor: params.size %zu too small",
                                params->size);
        /* An older caller's shorter struct leaves the newer fields 0. */
        memcpy(&p, params, params->size < sizeof p ? params->size : sizeof p);
        p.size = sizeof p;
    }
    if (p.method != RP_FF_ANALYTIC && p.method != RP_FF_MONTECARLO && p.method != RP_FF_HEMICUBE)
        return rp_error_set(err, RP_ERR_INPUT, "formfactor: unknown method %d", (int)p.method);
    if (p.samples == 0)
        p.samples = RP_FF_DEFAULT_SAMPLES;
    if (p.resolution == 0)
        p.resolution = RP_FF_DEFAULT_RESOLUTION;
    if (p.method == RP_FF_HEMICUBE && (p.resolution < 2 || p.resolution % 2 || p.resolution > 16384))
        return rp_error_set(err, RP_ERR_INPUT,
                            "formfactor: hemicube resolution %u must be even, in [2, 16384]",
                            p.resolution);
    if (p.tolerance == 0)
        p.tolerance = RP_FF_DEFAULT_TOLERANCE;
    if (!(p.tolerance >= 1e-14 && p.tolerance <= 0.1))
        return rp_error_set(err, RP_ERR_INPUT, "formfactor: tolerance %g outside [1e-14, 0.1]",
                            p.tolerance);
    if (p.visibility_rays > 4096)
        return rp_error_set(err, RP_ERR_INPUT, "formfactor: %u visibility rays is more than 4096",
                            p.visibility_rays);

    rp_ff_context *ctx = calloc(1, sizeof *ctx);
    if (!ctx)
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory");
    ctx->scene = scene;
    ctx->mesh = mesh;
    ctx->rc = rc;
    ctx->p = p;
    ctx->tol_rel = p.tolerance;
    ctx->tol_abs = RP_FF_TOL_ABS;

    ctx->n = rp_mesh_nelements(mesh);
    ctx->el = malloc((ctx->n ? ctx->n : 1) * sizeof *ctx->el);
    if (!ctx->el) {
        rp_ff_context_destroy(ctx);
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for %zu elements",
                            ctx->n);
    }
    const rp_element *E = rp_mesh_elements(mesh);
    const rp_vec3 *V = rp_mesh_vertices(mesh);
    for (size_t e = 0; e < ctx->n; e++) {
        rp_ff_elem *el = &ctx->el[e];
        el->nv = E[e].nverts;
        el->face = E[e].face;
        el->n = E[e].normal;
        el->c = E[e].centroid;
        el->area = E[e].area;
        el->radius = 0;
        for (uint32_t k = 0; k < el->nv; k++) {
            el->v[k] = V[E[e].v[k]];
            double r = rp_v3_length(rp_v3_sub(el->v[k], el->c));
            el->radius = r > el->radius ? r : el->radius;
            el->lo = k ? ff_vmin(el->lo, el->v[k]) : el->v[k];
            el->hi = k ? ff_vmax(el->hi, el->v[k]) : el->v[k];
        }
        el->d = rp_v3_dot(el->n, el->c);
        el->tol = ff_tol(el->lo, el->hi, ff_face_twist(scene, el->face));
    }

    rp_status st = ff_build_edges(ctx, err);
    if (st == RP_OK)
        st = ff_build_blockers(ctx, err);
    if (st == RP_OK && rc && ctx->n >= 2 && ctx->n <= RP_FF_MAX_VCACHE) {
        ctx->vcache = calloc(ctx->n * (ctx->n - 1) / 2, sizeof *ctx->vcache);
        if (!ctx->vcache)
            st = rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory for %zu elements",
                              ctx->n);
    }
    if (st == RP_OK && p.method == RP_FF_HEMICUBE)
        st = rp_ff_hemicube_init(ctx, err);
    if (st != RP_OK) {
        rp_ff_context_destroy(ctx);
        return st;
    }
    *out = ctx;
    return RP_OK;
}

void rp_ff_context_params(const rp_ff_context *ctx, rp_ff_params *out)
{
    *out = ctx->p;
}

/* ---- scratch ------------------------------------------------------------ */

void rp_ff_scratch_destroy(rp_ff_scratch *s)
{
    if (!s)
        return;
    free(s->heap);
    free(s->vis_heap);
    free(s->vis_x);
    free(s->vis_y);
    free(s->vis_w);
    free(s->vis_blocked);
    free(s->eterm);
    free(s->estamp_a);
    free(s->estamp_b);
    free(s->zbuf);
    free(s->ibuf);
    free(s->hrow);
    free(s->poly);
    free(s);
}

rp_status rp_ff_scratch_create(const rp_ff_context *ctx, rp_ff_scratch **out, rp_error *err)
{
    *out = NULL;
    rp_ff_scratch *s = calloc(1, sizeof *s);
    if (!s)
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory");
    s->hrow_i = RP_NONE;
    s->heap_cap = RP_FF_MAX_REGIONS + 8;
    s->heap = malloc(s->heap_cap * sizeof *s->heap);
    s->vis_heap = malloc((RP_FF_VIS_MAX_RAYS + 2) * sizeof *s->vis_heap);
    s->vis_x = malloc(RP_FF_VIS_SEGMENTS * sizeof *s->vis_x);
    s->vis_y = malloc(RP_FF_VIS_SEGMENTS * sizeof *s->vis_y);
    s->vis_w = malloc(RP_FF_VIS_SEGMENTS * sizeof *s->vis_w);
    s->vis_blocked = malloc(RP_FF_VIS_SEGMENTS);
    s->far_i = RP_NONE;
    s->eterm = malloc((ctx->nedges + 1) * RP_FF_FARPTS * sizeof *s->eterm);
    s->estamp_a = calloc(ctx->nedges + 1, sizeof *s->estamp_a);
    s->estamp_b = calloc(ctx->nedges + 1, sizeof *s->estamp_b);
    if (!s->heap || !s->vis_heap || !s->vis_x || !s->vis_y || !s->vis_w || !s->vis_blocked || !s->eterm || !s->estamp_a || !s->estamp_b) {
        rp_ff_scratch_destroy(s);
        return rp_error_set(err, RP_ERR_NOMEM, "formfactor: out of memory");
    }
    if (ctx->p.method == RP_FF_HEMICUBE) {
        rp_status st = rp_ff_hemicube_scratch(ctx, s, err);
        if (st != RP_OK) {
            rp_ff_scratch_destroy(s);
            return st;
        }
    }
    *out = s;
    return RP_OK;
}

/* ---- analytic: the outer integral --------------------------------------- */

/* A map from the unit square onto part of the receiver: a bilinear quad
 * p(u,v) = (1-u)(1-v) a + u(1-v) b + uv c + (1-u)v d, or (tri) the Duffy
 * map of triangle abc, p(u,v) = a + u [(b - a) + v (c - b)], Jacobian
 * u |(b - a) x (c - b)|, which sends each edge of the triangle to a side of
 * the square. */
typedef struct ff_map {
    int tri;
    rp_vec3 a, b, c, d;
} ff_map;

/* What the integrand needs: the receiver's normal and the clipped source. */
typedef struct ff_kernel {
    rp_vec3 n;
    const rp_vec3 *src;
    uint32_t nsrc;
    const ff_map *maps;
} ff_kernel;

/* The point of map m at (u, v); returns the Jacobian there. */
static inline double ff_map_point(const ff_map *m, double u, double v, rp_vec3 *p)
{
    rp_vec3 pu, pv;
    if (m->tri) {
        rp_vec3 e = rp_v3_madd(rp_v3_sub(m->b, m->a), rp_v3_sub(m->c, m->b), v);
        *p = rp_v3_madd(m->a, e, u);
        pu = e;
        pv = rp_v3_scale(rp_v3_sub(m->c, m->b), u);
    } else {
        double u1 = 1 - u, v1 = 1 - v;
        *p = rp_v3_add(rp_v3_add(rp_v3_scale(m->a, u1 * v1), rp_v3_scale(m->b, u * v1)),
                       rp_v3_add(rp_v3_scale(m->c, u * v), rp_v3_scale(m->d, u1 * v)));
        pu = rp_v3_add(rp_v3_scale(rp_v3_sub(m->b, m->a), v1), rp_v3_scale(rp_v3_sub(m->c, m->d), v));
        pv = rp_v3_add(rp_v3_scale(rp_v3_sub(m->d, m->a), u1), rp_v3_scale(rp_v3_sub(m->c, m->b), u));
    }
    return rp_v3_length(rp_v3_cross(pu, pv));
}

static inline double ff_integrand(const ff_kernel *k, const ff_map *m, double u, double v)
{
    rp_vec3 p;
    double J = ff_map_point(m, u, v, &p);
    return J * rp_ff_point_polygon(p, k->n, k->src, k->nsrc);
}

/* Genz & Malik (1980) degree-7 rule, n = 2, with its embedded degree-5
 * rule; generators lambda2 = sqrt(9/70), lambda3 = lambda4 = sqrt(9/10),
 * lambda5 = sqrt(9/19); weights for the unit-volume cube. */
#define GM_L2 0.35856858280031809199 /* sqrt(9/70) */
#define GM_L4 0.94868329805051379960 /* sqrt(9/10) */
#define GM_L5 0.68824720161168529772 /* sqrt(9/19) */
static const double GM_W[5] = {-3816.0 / 19683, 980.0 / 6561, 1020.0 / 19683, 200.0 / 19683,
                               6859.0 / 19683 / 4};
static const double GM_E[4] = {-971.0 / 729, 245.0 / 486, 65.0 / 1458, 25.0 / 729};

static void ff_gm(const ff_kernel *k, rp_ff_region *r)
{
    const ff_map *m = &k->maps[r->map];
    double uc = 0.5 * (r->u0 + r->u1), vc = 0.5 * (r->v0 + r->v1);
    double hu = 0.5 * (r->u1 - r->u0), hv = 0.5 * (r->v1 - r->v0);
    double f0 = ff_integrand(k, m, uc, vc);
    double a2u = ff_integrand(k, m, uc - GM_L2 * hu, vc) + ff_integrand(k, m, uc + GM_L2 * hu, vc);
    double a2v = ff_integrand(k, m, uc, vc - GM_L2 * hv) + ff_integrand(k, m, uc, vc + GM_L2 * hv);
    double a3u = ff_integrand(k, m, uc - GM_L4 * hu, vc) + ff_integrand(k, m, uc + GM_L4 * hu, vc);
    double a3v = ff_integrand(k, m, uc, vc - GM_L4 * hv) + ff_integrand(k, m, uc, vc + GM_L4 * hv);
    double s4 = 0, s5 = 0;
    for (int su = -1; su <= 1; su += 2)
        for (int sv = -1; sv <= 1; sv += 2) {
            s4 += ff_integrand(k, m, uc + su * GM_L4 * hu, vc + sv * GM_L4 * hv);
            s5 += ff_integrand(k, m, uc + su * GM_L5 * hu, vc + sv * GM_L5 * hv);
        }
    double vol = 4 * hu * hv;
    double s2 = a2u + a2v, s3 = a3u + a3v;
    double q7 = vol * (GM_W[0] * f0 + GM_W[1] * s2 + GM_W[2] * s3 + GM_W[3] * s4 + GM_W[4] * s5);
    double q5 = vol * (GM_E[0] * f0 + GM_E[1] * s2 + GM_E[2] * s3 + GM_E[3] * s4);
    r->q = q7;
    r->err = fabs(q7 - q5);
    /* Fourth divided differences pick the axis to split (Genz & Malik). */
    double ratio = (GM_L2 * GM_L2) / (GM_L4 * GM_L4);
    double du = fabs(a2u - 2 * f0 - ratio * (a3u - 2 * f0));
    double dv = fabs(a2v - 2 * f0 - ratio * (a3v - 2 * f0));
    r->axis = dv > du;
}

/* Max-heap on err. */
static void ff_heap_push(rp_ff_region *h, size_t *n, rp_ff_region r)
{
    size_t c = (*n)++;
    while (c > 0) {
        size_t p = (c - 1) / 2;
        if (h[p].err >= r.err)
            break;
        h[c] = h[p];
        c = p;
    }
    h[c] = r;
}

static rp_ff_region ff_heap_pop(rp_ff_region *h, size_t *n)
{
    rp_ff_region top = h[0], last = h[--(*n)];
    size_t c = 0;
    for (;;) {
        size_t l = 2 * c + 1, big = c;
        if (l >= *n)
            break;
        big = l + 1 < *n && h[l + 1].err > h[l].err ? l + 1 : l;
        if (h[big].err <= last.err)
            break;
        h[c] = h[big];
        c = big;
    }
    if (*n > 0)
        h[c] = last;
    return top;
}

/* Adaptive integral of F(x -> src) over the maps; returns the integral
 * (area times form factor).  scale: tau S_ij A_i / tau, the error goal's
 * natural size. */
static double ff_adaptive(const rp_ff_context *ctx, rp_ff_scratch *s, const ff_kernel *k, int nmaps,
                          double area_i, double scale)
{
    size_t n = 0;
    double q = 0, e = 0; /* e: the finite errors; ninf regions not yet split */
    size_t ninf = 0;
    for (int m = 0; m < nmaps; m++) {
        rp_ff_region r = {0, 1, 0, 1, 0, 0, m, 0};
        ff_gm(k, &r);
        /* No region is accepted on its own rule's word before it has been
         * split once (see the error rule below). */
        r.err = INFINITY;
        ninf++;
        q += r.q;
        ff_heap_push(s->heap, &n, r);
    }
    while ((ninf || e > RP_FF_ADAPT_MARGIN * fmax(ctx->tol_rel * fmax(fabs(q), scale),
                                                  ctx->tol_abs * area_i)) &&
           n + 2 <= RP_FF_MAX_REGIONS) {
        rp_ff_region r = ff_heap_pop(s->heap, &n);
        rp_ff_region a = r, b = r;
        if (r.axis == 0)
            a.u1 = b.u0 = 0.5 * (r.u0 + r.u1);
        else
            a.v1 = b.v0 = 0.5 * (r.v0 + r.v1);
        ff_gm(k, &a);
        ff_gm(k, &b);
        /* Genz & Malik's |Q7 - Q5| misjudges regions touching the shared
         * edge of adjacent elements by up to 80x (measured against Howell
         * C-14): the s log s singularity fools both rules alike.  The
         * change from the parent's estimate to its children's does not
         * (the brief's "subdivided agrees with coarse"), so each child
         * carries at least half of it. */
        double split = 0.5 * fabs(a.q + b.q - r.q);
        a.err = fmax(a.err, split);
        b.err = fmax(b.err, split);
        q += a.q + b.q - r.q;
        if (isinf(r.err))
            ninf--;
        else
            e -= r.err;
        e += a.err + b.err;
        ff_heap_push(s->heap, &n, a);
        ff_heap_push(s->heap, &n, b);
    }
    /* Re-add from scratch: the running sums drift. */
    q = 0;
    for (size_t r = 0; r < n; r++)
        q += s->heap[r].q;
    return q;
}

/* 2x2 Gauss-Legendre nodes on [0, 1]. */
#define GL2_A 0.21132486540518711775 /* (1 - 1/sqrt 3) / 2 */
#define GL2_B 0.78867513459481288225

/* The far-pair points of receiver i, weights including the Jacobian.
 * Quads: stage 1a's 2x2 Gauss points, then stage 1b's 3x3.  Triangles:
 * Strang & Fix's 3 points (barycentric (2/3, 1/6, 1/6)), then Radon's 7
 * (the centroid and two orbits of three).  Starting a new receiver
 * invalidates the cached edge terms. */
static void ff_far_setup(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i)
{
    const rp_ff_elem *ei = &ctx->el[i];
    s->far_i = i;
    if (++s->stamp == 0) {
        memset(s->estamp_a, 0, (ctx->nedges + 1) * sizeof *s->estamp_a);
        memset(s->estamp_b, 0, (ctx->nedges + 1) * sizeof *s->estamp_b);
        s->stamp = 1;
    }
    int q = 0;
    if (ei->nv == 4) {
        static const double g2[2] = {GL2_A, GL2_B};
        static const double g3[3] = {0.11270166537925831148, 0.5, 0.88729833462074168852};
        static const double w3[3] = {5.0 / 18, 8.0 / 18, 5.0 / 18};
        ff_map m = {0, ei->v[0], ei->v[1], ei->v[2], ei->v[3]};
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 2; b++, q++)
                s->far_w[q] = 0.25 * ff_map_point(&m, g2[a], g2[b], &s->far_x[q]);
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++, q++)
                s->far_w[q] = w3[a] * w3[b] * ff_map_point(&m, g3[a], g3[b], &s->far_x[q]);
        s->nfar_a = 4;
        s->nfar_b = 9;
    } else {
        const rp_vec3 *v = ei->v;
        double A = ei->area;
        static const double al[3] = {1.0 / 6, 0.10128650732345633880, 0.47014206410511508977};
        static const double wt[3] = {1.0 / 3, 0.12593918054482715260, 0.13239415278850618074};
        for (int t = 0; t < 3; t++) {
            if (t == 1) {
                s->far_x[q] = ei->c;
                s->far_w[q++] = 0.225 * A;
            }
            for (int r = 0; r < 3; r++, q++) {
                double a = al[t];
                s->far_x[q] = rp_v3_add(rp_v3_scale(v[r], 1 - 2 * a),
                                        rp_v3_scale(rp_v3_add(v[(r + 1) % 3], v[(r + 2) % 3]), a));
                s->far_w[q] = wt[t] * A;
            }
        }
        s->nfar_a = 3;
        s->nfar_b = 7;
    }
}

/* F(x_q -> A_j) at far points q0 <= q < q1 into g, from per-edge terms
 * cached across the row: an edge shared by two elements of a surface is
 * evaluated once, its term entering the two with opposite signs. */
static void ff_far_eval(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t j, uint32_t q0,
                        uint32_t q1, uint32_t *stamps, double *g)
{
    const rp_ff_elem *ei = &ctx->el[s->far_i], *ej = &ctx->el[j];
    for (uint32_t q = q0; q < q1; q++)
        g[q] = 0;
    for (uint32_t k = 0; k < ej->nv; k++) {
        uint32_t e = ctx->eid[4 * (size_t)j + k];
        double *t = &s->eterm[(size_t)e * RP_FF_FARPTS];
        if (stamps[e] != s->stamp) {
            for (uint32_t q = q0; q < q1; q++)
                t[q] = ff_edge_term(s->far_x[q], ei->n, ctx->ea[e], ctx->eb[e]);
            stamps[e] = s->stamp;
        }
        if (ctx->erev[4 * (size_t)j + k])
            for (uint32_t q = q0; q < q1; q++)
                g[q] -= t[q];
        else
            for (uint32_t q = q0; q < q1; q++)
                g[q] += t[q];
    }
    for (uint32_t q = q0; q < q1; q++)
        g[q] *= 1.0 / (2.0 * RP_PI);
}

/* The analytic F_ij without visibility. */
static double ff_analytic_unoccluded(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i,
                                     uint32_t j)
{
    const rp_ff_elem *ei = &ctx->el[i], *ej = &ctx->el[j];
    double eps = ei->tol + ej->tol;
    double lo, hi;
    rp_vec3 src[RP_FF_MAXV], dom[RP_FF_MAXV];
    uint32_t nsrc = ej->nv, ndom = ei->nv;
    int clipped = 0;

    /* Source against the receiver's tangent plane. */
    ff_side(ej->v, ej->nv, ei->n, ei->d, &lo, &hi);
    if (hi <= eps)
        return 0;
    if (lo < -eps) {
        nsrc = rp_ff_clip(ej->v, ej->nv, ei->n, ei->d, src);
        clipped = 1;
    } else {
        memcpy(src, ej->v, ej->nv * sizeof *src);
    }
    /* Receiver against the source's plane: behind it, j shows its back. */
    ff_side(ei->v, ei->nv, ej->n, ej->d, &lo, &hi);
    if (hi <= eps)
        return 0;
    if (lo < -eps) {
        ndom = rp_ff_clip(ei->v, ei->nv, ej->n, ej->d, dom);
        clipped = 1;
    } else {
        memcpy(dom, ei->v, ei->nv * sizeof *dom);
    }
    if (nsrc < 3 || ndom < 3)
        return 0;

    ff_map maps[RP_FF_MAXV];
    ff_kernel k = {ei->n, src, nsrc, maps};
    int nmaps;
    if (ndom == 4 && !clipped) {
        maps[0] = (ff_map){0, dom[0], dom[1], dom[2], dom[3]};
        nmaps = 1;
    } else {
        nmaps = (int)ndom - 2;
        for (int t = 0; t < nmaps; t++)
            maps[t] = (ff_map){1, dom[0], dom[t + 1], dom[t + 2], dom[0]};
    }

    double d = rp_v3_length(rp_v3_sub(ei->c, ej->c));
    /* The error goal in integral units (tau S_ij A_i, see the header). */
    double scale = fmin(ej->area / (RP_PI * d * d), 1.0) * ei->area;
    double gap = d - ei->radius - ej->radius;
    double rho = gap > 0 ? ei->radius / gap : INFINITY;
    double r3 = rho * rho * rho, r6 = r3 * r3;
    int tri_a = RP_FF_C_A_TRI * r3 <= ctx->tol_rel, rule_b = RP_FF_C_B * r6 <= ctx->tol_rel;
    if (!clipped) {
        int stage_a = ei->nv == 4 ? RP_FF_C_A_QUAD * r3 * rho <= ctx->tol_rel : tri_a;
        if (stage_a || rule_b) {
            if (s->far_i != i)
                ff_far_setup(ctx, s, i);
            double g[RP_FF_FARPTS] = {0}, q = 0;
            uint32_t q0 = stage_a ? 0 : s->nfar_a, q1 = stage_a ? s->nfar_a : s->nfar_a + s->nfar_b;
            ff_far_eval(ctx, s, j, q0, q1, stage_a ? s->estamp_a : s->estamp_b, g);
            for (uint32_t t = q0; t < q1; t++)
                q += s->far_w[t] * g[t];
            return q / ei->area;
        }
    } else if (tri_a || rule_b) {
        /* A far pair cut by a plane: the integrand is as smooth on the
         * clipped receiver as on the whole one (it falls to zero linearly
         * at j's plane), so the same rules apply to each triangle of the
         * clipped receiver's fan, whose sizes r_i bounds. */
        static const double al[3] = {1.0 / 6, 0.10128650732345633880, 0.47014206410511508977};
        static const double wt[3] = {1.0 / 3, 0.12593918054482715260, 0.13239415278850618074};
        double q = 0;
        for (int t = 0; t < nmaps; t++) {
            rp_vec3 v[3] = {maps[t].a, maps[t].b, maps[t].c};
            double A = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(v[1], v[0]), rp_v3_sub(v[2], v[0])));
            double qt = 0;
            if (!tri_a) {
                rp_vec3 c = rp_v3_scale(rp_v3_add(v[0], rp_v3_add(v[1], v[2])), 1.0 / 3);
                qt = 0.225 * rp_ff_point_polygon(c, ei->n, src, nsrc);
            }
            for (int o = tri_a ? 0 : 1; o < (tri_a ? 1 : 3); o++)
                for (int r = 0; r < 3; r++) {
                    rp_vec3 x = rp_v3_add(rp_v3_scale(v[r], 1 - 2 * al[o]),
                                          rp_v3_scale(rp_v3_add(v[(r + 1) % 3], v[(r + 2) % 3]), al[o]));
                    qt += wt[o] * rp_ff_point_polygon(x, ei->n, src, nsrc);
                }
            q += A * qt;
        }
        return q / ei->area;
    }
    return ff_adaptive(ctx, s, &k, nmaps, ei->area, scale) / ei->area;
}

/* ---- visibility --------------------------------------------------------- */

/* 1 if some face of the scene could block a segment between i and j. */
static int ff_needs_rays(const rp_ff_context *ctx, uint32_t i, uint32_t j)
{
    if (!ctx->rc)
        return 0;
    if (!ctx->blk_count)
        return 1;
    const rp_ff_elem *ei = &ctx->el[i], *ej = &ctx->el[j];
    size_t ab = (size_t)ei->face * ctx->nfaces + ej->face;
    uint32_t cnt = ctx->blk_count[ab];
    if (cnt == RP_FF_BLK_ALL)
        return 1;
    if (cnt == 0)
        return 0;
    const rp_face *faces = rp_scene_faces(ctx->scene);
    rp_vec3 lo = ff_vmin(ei->lo, ej->lo), hi = ff_vmax(ei->hi, ej->hi);
    const uint32_t *list = &ctx->blk[ctx->blk_start[ab]];
    for (uint32_t t = 0; t < cnt; t++) {
        uint32_t f = list[t];
        const double tol = ctx->face_tol[f] + ei->tol + ej->tol;
        if (!ff_boxes_meet(ctx->face_lo[f], ctx->face_hi[f], lo, hi, tol))
            continue;
        rp_vec3 fv[4];
        uint32_t m = ff_face_verts(ctx->scene, f, fv);
        if (ff_can_block(fv, m, faces[f].normal, rp_v3_dot(faces[f].normal, fv[0]), ctx->face_lo[f],
                         ctx->face_hi[f], ei->v, ei->nv, ei->n, ei->d, ej->v, ej->nv, ej->n, ej->d,
                         lo, hi, tol))
            return 1;
    }
    return 0;
}

/* A point of element e from (u, v) in the unit square: bilinear on quads,
 * uniform-in-area on triangles. */
static rp_vec3 ff_elem_point(const rp_ff_elem *e, double u, double v)
{
    if (e->nv == 3) {
        double su = sqrt(u);
        return rp_v3_add(rp_v3_scale(e->v[0], 1 - su),
                         rp_v3_add(rp_v3_scale(e->v[1], su * (1 - v)), rp_v3_scale(e->v[2], su * v)));
    }
    return rp_v3_add(rp_v3_add(rp_v3_scale(e->v[0], (1 - u) * (1 - v)), rp_v3_scale(e->v[1], u * (1 - v))),
                     rp_v3_add(rp_v3_scale(e->v[2], u * v), rp_v3_scale(e->v[3], (1 - u) * v)));
}

/* The unoccluded form factor from point x (normal nx) to the cell
 * [u0,u1] x [v0,v1] of element e's parameter square (ff_elem_point; a
 * cell's sides are straight, so it is the quadrilateral of its corners),
 * clipped to x's tangent plane; 0 when nothing of it is in front of x.
 * *inside gets a point of the clipped cell (the mean of its corners). */
static double ff_point_cell(rp_vec3 x, rp_vec3 nx, const rp_ff_elem *e, double u0, double u1,
                            double v0, double v1, rp_vec3 *inside)
{
    rp_vec3 cell[4] = {ff_elem_point(e, u0, v0), ff_elem_point(e, u1, v0), ff_elem_point(e, u1, v1),
                       ff_elem_point(e, u0, v1)};
    /* A cell small against its distance: the differential form factor
     * A cos cos / (pi r^2) from its centre, within about (size / r)^2
     * (2% at RP_FF_VIS_FAR_CELL) of the contour integral. */
    rp_vec3 c = rp_v3_scale(rp_v3_add(rp_v3_add(cell[0], cell[1]), rp_v3_add(cell[2], cell[3])), 0.25);
    rp_vec3 d = rp_v3_sub(c, x);
    double r2 = rp_v3_dot(d, d), s2 = 0;
    for (int k = 0; k < 4; k++) {
        rp_vec3 t = rp_v3_sub(cell[k], c);
        double tt = rp_v3_dot(t, t);
        s2 = tt > s2 ? tt : s2;
    }
    if (s2 < RP_FF_VIS_FAR_CELL * RP_FF_VIS_FAR_CELL * r2) {
        double cx = rp_v3_dot(nx, d), cq = -rp_v3_dot(e->n, d);
        *inside = c;
        if (cx <= 0 || cq <= 0)
            return 0;
        double a = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(cell[2], cell[0]), rp_v3_sub(cell[3], cell[1])));
        return a * cx * cq / (RP_PI * r2 * r2);
    }
    rp_vec3 cut[RP_FF_MAXV];
    uint32_t nc = rp_ff_clip(cell, 4, nx, rp_v3_dot(nx, x), cut);
    if (nc < 3)
        return 0;
    rp_vec3 m = cut[0];
    for (uint32_t k = 1; k < nc; k++)
        m = rp_v3_add(m, cut[k]);
    *inside = rp_v3_scale(m, 1.0 / nc);
    double f = rp_ff_point_polygon(x, nx, cut, nc);
    return f > 0 ? f : 0;
}

/* Max-heap of cells on f. */
static void ff_cell_push(rp_ff_cell *h, size_t *n, rp_ff_cell c)
{
    size_t k = (*n)++;
    while (k > 0) {
        size_t p = (k - 1) / 2;
        if (h[p].f >= c.f)
            break;
        h[k] = h[p];
        k = p;
    }
    h[k] = c;
}

static rp_ff_cell ff_cell_pop(rp_ff_cell *h, size_t *n)
{
    rp_ff_cell top = h[0], last = h[--(*n)];
    size_t k = 0;
    for (;;) {
        size_t l = 2 * k + 1;
        if (l >= *n)
            break;
        size_t big = l + 1 < *n && h[l + 1].f > h[l].f ? l + 1 : l;
        if (h[big].f <= last.f)
            break;
        h[k] = h[big];
        k = big;
    }
    if (*n > 0)
        h[k] = last;
    return top;
}

/* The visible fraction V_rq of the analytic F_rq, receiver r, source q
 * (the roles rp_ff_pair gives the pair), estimated by rays from points x_s
 * of r (k x k jittered strata) to points of q, each ray weighted by the
 * exact unoccluded form factor from x_s to the part of q it stands for:
 *
 *   V_rq = sum_s sum_c F(x_s -> c) v(x_s, y_c) / sum_s F(x_s -> q),
 *
 * c the cells of a partition of q and y_c a random point of cell c (source
 * subdivision for visibility, as Wallace, Elmquist & Haines 1989 sample a
 * source in parts, with Lambert's contour integral as each part's
 * weight).  The partition starts from q itself, ray to a point of q's
 * stratum pi(s) (pi a random permutation, as far pairs always had), and is
 * bisected along the longer side while a cell's F(x_s -> c) exceeds
 * RP_FF_VIS_CELL k^2: the number of rays grows with F_rq (about
 * F_rq / RP_FF_VIS_CELL), so a big element seen at close range (an
 * elephant's foot above a floor that is one element) is sampled where it
 * matters, not uniformly in area.  Weights in area (the old estimate, the
 * fraction of open segments between uniform points) overestimated such
 * pairs up to 1.7x and pushed row sums to 1.4; weights in the point-pair
 * kernel cos cos / r^2 are unbiased but their variance is unbounded near
 * contacts.  Here every weight is at most F(x_s -> c) <= 1 and the
 * estimate is exact (1) where nothing blocks.  The result is kept for the
 * unordered pair (vcache), so V_qr = V_rq and reciprocity holds. */
static double ff_visibility(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t r, uint32_t q,
                            double *rays)
{
    if (!ff_needs_rays(ctx, r, q))
        return 1;
    /* Shared across threads: whichever computes a pair first stores it, and
     * every reader, that one included, uses the stored (quantised) value,
     * so rows do not depend on the schedule. */
    uint32_t lo = r < q ? r : q, hi = r < q ? q : r;
    _Atomic uint16_t *slot = ctx->vcache ? &ctx->vcache[(size_t)hi * (hi - 1) / 2 + lo] : NULL;
    if (slot) {
        uint16_t code = atomic_load_explicit(slot, memory_order_relaxed);
        if (code)
            return (code - 1) / 65520.0;
    }
    const rp_ff_elem *er = &ctx->el[r], *eq = &ctx->el[q];
    unsigned kk;
    if (ctx->p.visibility_rays) {
        kk = (unsigned)ceil(sqrt((double)ctx->p.visibility_rays) - 1e-9);
    } else {
        /* Receiver points by the receiver's size against the distance
         * (visibility varies across it); the source is covered by the
         * cells.  For elements of one size the same as the old rule on
         * (r_r + r_q) / d, 4, 9 or 16 up to 1. */
        double rho = er->radius / rp_v3_length(rp_v3_sub(er->c, eq->c));
        kk = rho < 0.125 ? 2 : rho < 0.3 ? 3 : rho < 0.5 ? 4 : rho < 1 ? 6 : 8;
    }
    unsigned m = ctx->p.visibility_rays ? ctx->p.visibility_rays : kk * kk;
    uint64_t key = ff_key(ctx->p.seed, r, q);
    /* Strata of q in a random order (Fisher-Yates), paired with r's. */
    uint16_t perm[4096];
    unsigned ns = kk * kk;
    for (unsigned t = 0; t < ns; t++)
        perm[t] = (uint16_t)t;
    for (unsigned t = ns; t > 1; t--) {
        unsigned u = (unsigned)(ff_u01(key, 4096 + t) * t);
        uint16_t tmp = perm[t - 1];
        perm[t - 1] = perm[u];
        perm[u] = tmp;
    }
    const double split = RP_FF_VIS_CELL * m;
    const size_t max_leaves = RP_FF_VIS_MAX_RAYS / m > 1 ? RP_FF_VIS_MAX_RAYS / m : 1;
    /* F(x -> q) <= A_q / (pi gap^2): a pair too far apart for any cell to
     * be split needs no weights, all being about equal (1 each: the
     * fraction of open segments). */
    double gap = rp_v3_length(rp_v3_sub(er->c, eq->c)) - er->radius - eq->radius;
    int far = gap > 0 && eq->area <= split * RP_PI * gap * gap;
    double inv = 1.0 / kk, wsum = 0, wopen = 0;
    size_t cast = 0;
    uint64_t counter = 0;
    for (unsigned t = 0; t < m; t++) {
        unsigned si = t % ns, sj = perm[t % ns];
        rp_vec3 x = ff_elem_point(er, ((si % kk) + ff_u01(key, 4 * t)) * inv,
                                  ((si / kk) + ff_u01(key, 4 * t + 1)) * inv);
        /* x behind q's plane sees its black back: no energy. */
        if (rp_v3_dot(eq->n, x) - eq->d <= 0)
            continue;
        /* Best-first: the cell with the largest share is split next, so
         * a pair that reaches the cap has its rays spread evenly. */
        rp_ff_cell *heap = s->vis_heap;
        size_t nh = 0;
        rp_ff_cell root = {0, 1, 0, 1, 1, {0, 0, 0}, 0};
        if (!far) {
            root.f = ff_point_cell(x, er->n, eq, 0, 1, 0, 1, &root.inside);
            if (!(root.f > 0))
                continue;
        }
        ff_cell_push(heap, &nh, root);
        while (!far && nh < max_leaves && heap[0].f > split && heap[0].depth < RP_FF_VIS_DEPTH) {
            rp_ff_cell c = ff_cell_pop(heap, &nh);
            /* Bisect along the longer side (in the scene, not in (u, v)). */
            double um = 0.5 * (c.u0 + c.u1), vm = 0.5 * (c.v0 + c.v1);
            double lu = rp_v3_length(rp_v3_sub(ff_elem_point(eq, c.u1, vm), ff_elem_point(eq, c.u0, vm)));
            double lv = rp_v3_length(rp_v3_sub(ff_elem_point(eq, um, c.v1), ff_elem_point(eq, um, c.v0)));
            rp_ff_cell a = c, b = c;
            if (lu >= lv)
                a.u1 = b.u0 = um;
            else
                a.v1 = b.v0 = vm;
            a.depth = b.depth = c.depth + 1;
            a.f = ff_point_cell(x, er->n, eq, a.u0, a.u1, a.v0, a.v1, &a.inside);
            b.f = ff_point_cell(x, er->n, eq, b.u0, b.u1, b.v0, b.v1, &b.inside);
            if (a.f > 0)
                ff_cell_push(heap, &nh, a);
            if (b.f > 0)
                ff_cell_push(heap, &nh, b);
            if (nh == 0)
                break;
        }
        /* The leaves in the heap's (deterministic) order. */
        for (size_t h = 0; h < nh; h++) {
            rp_ff_cell c = heap[h];
            /* A leaf: one ray, to q's stratum pi(s) when q was not split,
             * else to a random point of the cell. */
            rp_vec3 y;
            if (c.depth == 0)
                y = ff_elem_point(eq, ((sj % kk) + ff_u01(key, 4 * t + 2)) * inv,
                                  ((sj / kk) + ff_u01(key, 4 * t + 3)) * inv);
            else {
                uint64_t k2 = RP_FF_VIS_COUNTER + 2 * counter++;
                y = ff_elem_point(eq, c.u0 + (c.u1 - c.u0) * ff_u01(key, k2),
                                  c.v0 + (c.v1 - c.v0) * ff_u01(key, k2 + 1));
            }
            rp_vec3 d = rp_v3_sub(y, x);
            /* Only segments that leave both fronts carry energy; a point
             * of the cell's part behind x's plane is replaced by one of
             * the part in front. */
            if (rp_v3_dot(d, er->n) <= 0 || rp_v3_dot(d, eq->n) >= 0) {
                if (far)
                    continue;
                y = c.inside;
                d = rp_v3_sub(y, x);
                if (rp_v3_dot(d, er->n) <= 0 || rp_v3_dot(d, eq->n) >= 0)
                    continue;
            }
            s->vis_x[cast] = x;
            s->vis_y[cast] = y;
            s->vis_w[cast] = c.f;
            cast++;
        }
    }
    /* The pair's segments share their end normals: one coherent stream
     * (rtcOccluded1M; the same answers as ray by ray). */
    rp_ray_occluded_n(ctx->rc, cast, s->vis_x, er->n, s->vis_y, eq->n, s->vis_blocked);
    for (size_t t = 0; t < cast; t++) {
        wsum += s->vis_w[t];
        if (!s->vis_blocked[t])
            wopen += s->vis_w[t];
    }
    if (rays)
        *rays += (double)cast;
    double v = wsum > 0 ? wopen / wsum : 1.0;
    if (slot) {
        uint16_t code = (uint16_t)(1 + lround(v * 65520));
        atomic_store_explicit(slot, code, memory_order_relaxed);
        v = (code - 1) / 65520.0;
    }
    return v;
}

/* ---- Monte Carlo -------------------------------------------------------- */

/* A point uniform in area on element e from three uniforms. */
static rp_vec3 ff_uniform_point(const rp_ff_elem *e, double u0, double u1, double u2)
{
    rp_vec3 a = e->v[0], b = e->v[1], c = e->v[2];
    if (e->nv == 4) {
        /* Choose triangle (v0 v1 v2) or (v0 v2 v3) by area. */
        double a1 = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
        if (u0 * e->area >= a1) {
            b = c;
            c = e->v[3];
        }
    }
    double su = sqrt(u1);
    return rp_v3_add(rp_v3_scale(a, 1 - su),
                     rp_v3_add(rp_v3_scale(b, su * (1 - u2)), rp_v3_scale(c, su * u2)));
}

static double ff_montecarlo(const rp_ff_context *ctx, uint32_t i, uint32_t j, double *se,
                            double *rays)
{
    const rp_ff_elem *ei = &ctx->el[i], *ej = &ctx->el[j];
    if (se)
        *se = 0;
    double lo, hi;
    ff_side(ej->v, ej->nv, ei->n, ei->d, &lo, &hi);
    if (hi <= ei->tol + ej->tol)
        return 0;
    ff_side(ei->v, ei->nv, ej->n, ej->d, &lo, &hi);
    if (hi <= ei->tol + ej->tol)
        return 0;
    int vis = ff_needs_rays(ctx, i, j);
    /* Samples keyed on the unordered pair, x always on the lower-numbered
     * element: the estimates of F_ij and F_ji then obey reciprocity
     * exactly. */
    int swap = i > j;
    const rp_ff_elem *ea = swap ? ej : ei, *eb = swap ? ei : ej;
    uint64_t key = swap ? ff_key(ctx->p.seed, j, i) : ff_key(ctx->p.seed, i, j);
    unsigned N = ctx->p.samples;
    double mean = 0, m2 = 0, cast = 0;
    for (unsigned t = 0; t < N; t++) {
        rp_vec3 a = ff_uniform_point(ea, ff_u01(key, 6 * (uint64_t)t), ff_u01(key, 6 * (uint64_t)t + 1),
                                     ff_u01(key, 6 * (uint64_t)t + 2));
        rp_vec3 b = ff_uniform_point(eb, ff_u01(key, 6 * (uint64_t)t + 3),
                                     ff_u01(key, 6 * (uint64_t)t + 4), ff_u01(key, 6 * (uint64_t)t + 5));
        rp_vec3 x = swap ? b : a, y = swap ? a : b;
        rp_vec3 d = rp_v3_sub(y, x);
        double r2 = rp_v3_dot(d, d);
        double ci = rp_v3_dot(ei->n, d), cj = -rp_v3_dot(ej->n, d);
        double f = 0;
        if (ci > 0 && cj > 0 && r2 > 0) {
            f = ej->area * ci * cj / (RP_PI * r2 * r2);
            if (vis) {
                cast++;
                if (rp_ray_occluded(ctx->rc, x, ei->n, y, ej->n))
                    f = 0;
            }
        }
        /* Welford's running mean and variance. */
        double delta = f - mean;
        mean += delta / (t + 1);
        m2 += delta * (f - mean);
    }
    if (se)
        *se = N > 1 ? sqrt(m2 / (N - 1) / N) : 0;
    if (rays)
        *rays += cast;
    return mean;
}

/* ---- the public calls --------------------------------------------------- */

int rp_ff_reciprocal(const rp_ff_context *ctx)
{
    return ctx->p.method != RP_FF_HEMICUBE;
}

int rp_ff_primary(const rp_ff_context *ctx, uint32_t i, uint32_t j)
{
    if (ctx->p.method == RP_FF_ANALYTIC) {
        double ri = ctx->el[i].radius, rj = ctx->el[j].radius;
        return ri < rj || (ri == rj && i < j);
    }
    return ctx->p.method == RP_FF_HEMICUBE || i < j;
}

/* F_ji from F_ij: A_i F_ij = A_j F_ji (Cohen & Wallace 1993, eq. 4.4). */
double rp_ff_mirror(const rp_ff_context *ctx, uint32_t i, uint32_t j, double fij)
{
    return fij * ctx->el[i].area / ctx->el[j].area;
}



/* The primary F_ij (rp_ff_primary(i, j) holds). */
static double ff_primary_pair(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, uint32_t j,
                              double *se, double *rays)
{
    if (se)
        *se = 0;
    if (ctx->p.method == RP_FF_MONTECARLO)
        return ff_montecarlo(ctx, i, j, se, rays);
    double f = ff_analytic_unoccluded(ctx, s, i, j);
    if (f <= 0)
        return 0;
    return f * ff_visibility(ctx, s, i, j, rays);
}

void rp_ff_pair_both(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, uint32_t j,
                     double *fij, double *fji, double *rays)
{
    if (i == j || !rp_ff_reciprocal(ctx)) {
        *fij = rp_ff_pair(ctx, s, i, j, NULL, rays);
        *fji = rp_ff_pair(ctx, s, j, i, NULL, rays);
        return;
    }
    if (rp_ff_primary(ctx, i, j)) {
        *fij = ff_primary_pair(ctx, s, i, j, NULL, rays);
        *fji = rp_ff_mirror(ctx, i, j, *fij);
    } else {
        *fji = ff_primary_pair(ctx, s, j, i, NULL, rays);
        *fij = rp_ff_mirror(ctx, j, i, *fji);
    }
}

void rp_ff_row(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, float *row, double *rays)
{
    if (ctx->p.method == RP_FF_HEMICUBE) {
        if (s->hrow_i != i)
            rp_ff_hemicube_row(ctx, s, i);
        for (size_t j = 0; j < ctx->n; j++)
            row[j] = (float)s->hrow[j];
        return;
    }
    /* The pairs computed from i's side first, then the others (from
     * theirs): the far-pair rules' per-row edge terms (ff_far_eval) stay
     * valid through the first pass.  The order changes no value. */
    memset(row, 0, ctx->n * sizeof *row);
    for (int pass = 0; pass < 2; pass++)
        for (size_t j = 0; j < ctx->n; j++) {
            if (j == i || rp_ff_primary(ctx, i, (uint32_t)j) != (pass == 0))
                continue;
            if (j % 64 == 0 && ctx->p.cancel && atomic_load_explicit(ctx->p.cancel, memory_order_relaxed))
                return;
            double f = pass == 0 ? ff_primary_pair(ctx, s, i, (uint32_t)j, NULL, rays)
                                 : rp_ff_mirror(ctx, (uint32_t)j, i,
                                             ff_primary_pair(ctx, s, (uint32_t)j, i, NULL, rays));
            row[j] = (float)f;
        }
}

double rp_ff_pair(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i, uint32_t j,
                  double *stderr_out, double *rays)
{
    if (stderr_out)
        *stderr_out = 0;
    if (i == j)
        return 0;
    if (ctx->p.method == RP_FF_HEMICUBE) {
        if (s->hrow_i != i)
            rp_ff_hemicube_row(ctx, s, i);
        return s->hrow[j];
    }
    if (rp_ff_primary(ctx, i, j))
        return ff_primary_pair(ctx, s, i, j, stderr_out, rays);
    double se = 0, f = ff_primary_pair(ctx, s, j, i, stderr_out ? &se : NULL, rays);
    if (stderr_out)
        *stderr_out = rp_ff_mirror(ctx, j, i, se);
    return rp_ff_mirror(ctx, j, i, f);
}
