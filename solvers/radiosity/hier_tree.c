/* Hierarchical radiosity: the quadtrees over the scene's faces, and the
 * geometry they need (Hanrahan, Salzman & Aupperle 1991, sec. 3).
 *
 * Each face is the root of a quadtree.  A triangle splits into four at its
 * edge midpoints; a quad (planar, convex) splits into four along its
 * bilinear iso-parameter lines u = 1/2 and v = 1/2, which are straight, so
 * the children are quads again (parallelograms stay parallelograms).
 *
 * Every point on an edge of a child is computed as the midpoint (a + b) / 2
 * of the two points that bound it on the coarser level, and IEEE addition is
 * commutative, so two leaves that meet along an edge (in one face or across
 * faces that share the edge) produce bit-identical vertices: the image code
 * finds shared vertices and T-vertices by exact look-up (hier_image.c). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ff_internal.h"
#include "hier_internal.h"

static inline rp_vec3 mid(rp_vec3 a, rp_vec3 b) { return rp_v3_scale(rp_v3_add(a, b), 0.5); }

/* Area of a node from its corners (a convex quad is two triangles; its
 * centroid, hier_node_c, weighs the two by these areas). */
static void node_measure(hier_node *nd)
{
    hier_polygon_c(nd->v, nd->nverts, &nd->area);
}

/* Every per-node array to room for cap nodes.  Returns 0 if a realloc
 * failed (that array keeps its old room). */
static int resize_nodes(hier_state *s, size_t cap)
{
    int ok = 1;
    hier_node *nd = realloc(s->nodes, cap * sizeof *nd);
    ok &= nd != NULL;
    if (nd)
        s->nodes = nd;
    double **arrs[3] = {&s->B, &s->Bg, s->Y ? &s->Y : NULL};
    for (int k = 0; k < 3; k++) {
        if (!arrs[k])
            continue;
        double *a = realloc(*arrs[k], cap * s->nb * sizeof *a);
        ok &= a != NULL;
        if (a)
            *arrs[k] = a;
    }
    if (s->linear) {
        hier_basis *bs = realloc(s->basis, cap * sizeof *bs);
        ok &= bs != NULL;
        if (bs)
            s->basis = bs;
        double **lin[3] = {&s->B1, &s->Bg1, &s->Bd1};
        for (int k = 0; k < 3; k++) {
            double *a = realloc(*lin[k], cap * s->nb * 2 * sizeof *a);
            ok &= a != NULL;
            if (a)
                *lin[k] = a;
        }
    }
    double *w = realloc(s->W, cap * sizeof *w);
    ok &= w != NULL;
    if (w)
        s->W = w;
    return ok;
}

static rp_status grow_nodes(hier_state *s, size_t need, rp_error *err)
{
    if (need <= s->cap_nodes)
        return RP_OK;
    /* Half as much again (a face root each for a scene of 75k faces
     * must not hold room for 260k nodes, 189 bytes each with their
     * radiosities). */
    size_t cap = s->cap_nodes ? s->cap_nodes + s->cap_nodes / 2 : 1024;
    if (cap < need)
        cap = need;
    if (!resize_nodes(s, cap))
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu nodes", cap);
    s->cap_nodes = cap;
    return RP_OK;
}

void hier_nodes_trim(hier_state *s)
{
    if (s->nnodes == 0 || s->cap_nodes <= s->nnodes)
        return;
    /* A shrinking realloc that fails leaves the old, larger block: every
     * array still has room for nnodes. */
    resize_nodes(s, s->nnodes);
    s->cap_nodes = s->nnodes;
}

rp_status hier_nodes_init(hier_state *s, rp_error *err)
{
    const rp_face *faces = rp_scene_faces(s->scene);
    const rp_vec3 *vs = rp_scene_vertices(s->scene);
    rp_status st = grow_nodes(s, s->nfaces + s->nfaces / 8 + 16, err);
    if (st != RP_OK)
        return st;
    for (size_t f = 0; f < s->nfaces; f++) {
        hier_node *nd = &s->nodes[f];
        memset(nd, 0, sizeof *nd);
        nd->nverts = (uint16_t)faces[f].nverts;
        for (uint32_t k = 0; k < faces[f].nverts; k++)
            nd->v[k] = vs[faces[f].v[k]];
        if (nd->nverts == 3)
            nd->v[3] = nd->v[2];
        node_measure(nd);
        nd->face = (uint32_t)f;
        nd->parent = RP_NONE;
        nd->child = RP_NONE;
        const double *Le = s->faces[f].Le;
        for (size_t b = 0; b < s->nb; b++) {
            /* B starts at E = pi Le (Cohen & Wallace 1993, eq. 2.4). */
            s->B[f * s->nb + b] = RP_PI * Le[b];
            s->Bg[f * s->nb + b] = 0;
        }
        if (s->linear) {
            hier_basis_of(nd, s->faces[f].n, &s->basis[f]);
            memset(s->B1 + f * s->nb * 2, 0, s->nb * 2 * sizeof *s->B1);
            memset(s->Bg1 + f * s->nb * 2, 0, s->nb * 2 * sizeof *s->Bg1);
            memset(s->Bd1 + f * s->nb * 2, 0, s->nb * 2 * sizeof *s->Bd1);
        }
    }
    s->nnodes = s->nfaces;
    return RP_OK;
}

/* The corners of a node's four children. */
static void child_corners(const hier_node *p, rp_vec3 cv[4][4])
{
    if (p->nverts == 3) {
        rp_vec3 a = p->v[0], b = p->v[1], c = p->v[2];
        rp_vec3 mab = mid(a, b), mbc = mid(b, c), mca = mid(c, a);
        /* Corners keep the parent's orientation; the middle child's
         * barycentrics are 1 - 2 lambda (hier_locate). */
        rp_vec3 t[4][3] = {{a, mab, mca}, {mab, b, mbc}, {mca, mbc, c}, {mbc, mca, mab}};
        for (int k = 0; k < 4; k++) {
            cv[k][0] = t[k][0];
            cv[k][1] = t[k][1];
            cv[k][2] = t[k][2];
            cv[k][3] = t[k][2];
        }
        return;
    }
    rp_vec3 c0 = p->v[0], c1 = p->v[1], c2 = p->v[2], c3 = p->v[3];
    rp_vec3 m01 = mid(c0, c1), m12 = mid(c1, c2), m23 = mid(c2, c3), m30 = mid(c3, c0);
    rp_vec3 ctr = mid(m01, m23); /* the bilinear patch at (1/2, 1/2) */
    /* Child k covers u in [u0, u0 + 1/2], v in [v0, v0 + 1/2] with
     * (u0, v0) = (0,0), (1/2,0), (1/2,1/2), (0,1/2). */
    rp_vec3 q[4][4] = {{c0, m01, ctr, m30}, {m01, c1, m12, ctr}, {ctr, m12, c2, m23}, {m30, ctr, m23, c3}};
    memcpy(cv, q, sizeof q);
}

void hier_child_shapes(const hier_node *nd, hier_node out[4])
{
    rp_vec3 cv[4][4];
    child_corners(nd, cv);
    for (int k = 0; k < 4; k++) {
        memcpy(out[k].v, cv[k], sizeof out[k].v);
        out[k].nverts = nd->nverts;
        out[k].face = nd->face;
        node_measure(&out[k]);
    }
}

void hier_child_centroids(const hier_node *nd, rp_vec3 c[4], double area[4])
{
    rp_vec3 cv[4][4];
    child_corners(nd, cv);
    for (int k = 0; k < 4; k++) {
        c[k] = hier_polygon_c(cv[k], nd->nverts, &area[k]);
    }
}

rp_status hier_subdivide(hier_state *s, uint32_t i, rp_error *err)
{
    if (s->nodes[i].child != RP_NONE)
        return RP_OK;
    if (s->nnodes + 4 > UINT32_MAX - 1)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: more than 2^32 nodes");
    rp_status st = grow_nodes(s, s->nnodes + 4, err);
    if (st != RP_OK)
        return st;
    hier_node *p = &s->nodes[i];
    uint32_t first = (uint32_t)s->nnodes;
    hier_node *ch = &s->nodes[first];
    rp_vec3 cv[4][4];
    child_corners(p, cv);
    const size_t nb = s->nb;
    for (int k = 0; k < 4; k++) {
        hier_node *c = &ch[k];
        memset(c, 0, sizeof *c);
        memcpy(c->v, cv[k], sizeof c->v);
        c->nverts = p->nverts;
        c->face = p->face;
        c->parent = i;
        c->child = RP_NONE;
        c->depth = (uint16_t)(p->depth + 1);
        node_measure(c);
        size_t ci = (size_t)first + (size_t)k;
        for (size_t b = 0; b < nb; b++) {
            s->B[ci * nb + b] = s->B[(size_t)i * nb + b];
            s->Bg[ci * nb + b] = 0;
        }
        if (s->Y)
            for (size_t b = 0; b < nb; b++)
                s->Y[ci * nb + b] = s->Y[(size_t)i * nb + b];
    }
    p->child = first;
    s->nnodes += 4;
    if (s->linear)
        /* The parent's linear function restricted to each child. */
        for (uint32_t c = first; c < first + 4; c++) {
            hier_basis_of(&s->nodes[c], s->faces[s->nodes[c].face].n, &s->basis[c]);
            double a[2], A[2][2];
            hier_linear_relation(s, i, c, a, A);
            for (size_t b = 0; b < nb; b++) {
                s->B[(size_t)c * nb + b] +=
                    hier_linear_restrict(a, A, s->B1 + ((size_t)i * nb + b) * 2, s->B1 + ((size_t)c * nb + b) * 2);
                s->Bg1[((size_t)c * nb + b) * 2] = s->Bg1[((size_t)c * nb + b) * 2 + 1] = 0;
                s->Bd1[((size_t)c * nb + b) * 2] = s->Bd1[((size_t)c * nb + b) * 2 + 1] = 0;
            }
        }
    return RP_OK;
}

rp_vec3 hier_node_point(const hier_node *nd, double u1, double u2)
{
    if (nd->nverts == 3) {
        /* Uniform on a triangle (Shirley's square-to-triangle map keeps
         * strata). */
        double r = sqrt(u1);
        rp_vec3 p = rp_v3_scale(nd->v[0], 1.0 - r);
        p = rp_v3_madd(p, nd->v[1], r * (1.0 - u2));
        return rp_v3_madd(p, nd->v[2], r * u2);
    }
    rp_vec3 p = rp_v3_scale(nd->v[0], (1 - u1) * (1 - u2));
    p = rp_v3_madd(p, nd->v[1], u1 * (1 - u2));
    p = rp_v3_madd(p, nd->v[2], u1 * u2);
    return rp_v3_madd(p, nd->v[3], (1 - u1) * u2);
}

int hier_polygon_prepare(const rp_vec3 *poly, int m, double *cum)
{
    cum[0] = 0;
    for (int k = 1; k + 1 < m; k++)
        cum[k] = cum[k - 1] + hier_tri_area(poly[0], poly[k], poly[k + 1]);
    return m >= 3 && cum[m - 2] > 0;
}

rp_vec3 hier_polygon_point(const rp_vec3 *poly, int m, const double *cum, double u1, double u2)
{
    /* The fan triangle whose share of the area holds u1, then u1 rescaled
     * within it (so strata in u1 stay strata), then Shirley's map. */
    double t = u1 * cum[m - 2];
    int k = 1;
    while (k + 2 < m && cum[k] <= t)
        k++;
    double a = cum[k] - cum[k - 1];
    double v = a > 0 ? (t - cum[k - 1]) / a : 0.5;
    v = v < 0 ? 0 : (v > 1 ? 1 : v);
    double r = sqrt(v);
    rp_vec3 p = rp_v3_scale(poly[0], 1.0 - r);
    p = rp_v3_madd(p, poly[k], r * (1.0 - u2));
    return rp_v3_madd(p, poly[k + 1], r * u2);
}

double hier_point_polygon(rp_vec3 x, rp_vec3 n, const rp_vec3 *poly, int m)
{
    /* The contour formula holds only for the part of the polygon above x's
     * tangent plane: clipped to dot(n, y - x) >= 0 first (formfactor.c's
     * Sutherland-Hodgman clip and contour sum, with its fast atan2). */
    rp_vec3 r[10];
    uint32_t k = rp_ff_clip(poly, (uint32_t)m, n, rp_v3_dot(n, x), r);
    if (k < 3)
        return 0;
    return fabs(rp_ff_point_polygon(x, n, r, k));
}

/* Inverse of the bilinear map P(u, v) of a planar quad, in the face's own
 * 2-d frame: p - v0 = u e + v f + u v g with e = v1 - v0, f = v3 - v0,
 * g = v0 - v1 + v2 - v3.  Crossing with (e + v g) eliminates u and leaves
 * k2 v^2 + k1 v + k0 = 0. */
static void inverse_bilinear(const hier_node *nd, rp_vec3 n, rp_vec3 p, double *uo, double *vo)
{
    rp_vec3 t, bt;
    rp_v3_basis(n, &t, &bt);
    rp_vec3 E = rp_v3_sub(nd->v[1], nd->v[0]), Fv = rp_v3_sub(nd->v[3], nd->v[0]);
    rp_vec3 G = rp_v3_add(rp_v3_sub(nd->v[0], nd->v[1]), rp_v3_sub(nd->v[2], nd->v[3]));
    rp_vec3 H = rp_v3_sub(p, nd->v[0]);
    double e[2] = {rp_v3_dot(E, t), rp_v3_dot(E, bt)};
    double f[2] = {rp_v3_dot(Fv, t), rp_v3_dot(Fv, bt)};
    double g[2] = {rp_v3_dot(G, t), rp_v3_dot(G, bt)};
    double h[2] = {rp_v3_dot(H, t), rp_v3_dot(H, bt)};
#define CROSS2(a, b) ((a)[0] * (b)[1] - (a)[1] * (b)[0])
    double k2 = CROSS2(g, f), k1 = CROSS2(e, f) + CROSS2(h, g), k0 = CROSS2(h, e);
#undef CROSS2
    double v;
    if (fabs(k2) <= 1e-12 * fabs(k1)) {
        v = k1 != 0 ? -k0 / k1 : 0;
    } else {
        double w = k1 * k1 - 4 * k0 * k2;
        w = w > 0 ? sqrt(w) : 0;
        /* The two roots in a cancellation-free form; take the one in
         * [0, 1] (the other lies outside a convex quad). */
        double q = -0.5 * (k1 + copysign(w, k1));
        double r1 = q / k2, r2 = q != 0 ? k0 / q : r1;
        double d1 = r1 < 0 ? -r1 : (r1 > 1 ? r1 - 1 : 0);
        double d2 = r2 < 0 ? -r2 : (r2 > 1 ? r2 - 1 : 0);
        v = d1 <= d2 ? r1 : r2;
    }
    double den0 = e[0] + v * g[0], den1 = e[1] + v * g[1];
    double u = fabs(den0) >= fabs(den1) ? (h[0] - v * f[0]) / den0 : (h[1] - v * f[1]) / den1;
    if (!isfinite(u))
        u = 0.5;
    if (!isfinite(v))
        v = 0.5;
    *uo = u < 0 ? 0 : (u > 1 ? 1 : u);
    *vo = v < 0 ? 0 : (v > 1 ? 1 : v);
}

uint32_t hier_locate(const hier_state *s, uint32_t f, rp_vec3 p, double w[4])
{
    const hier_node *nodes = s->nodes;
    uint32_t i = f;
    const hier_node *nd = &nodes[i];
    rp_vec3 n = s->faces[f].n;
    if (nd->nverts == 3) {
        /* Barycentrics from signed areas in the face's plane. */
        rp_vec3 a = nd->v[0], b = nd->v[1], c = nd->v[2];
        double den = rp_v3_dot(n, rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
        double l1 = rp_v3_dot(n, rp_v3_cross(rp_v3_sub(p, a), rp_v3_sub(c, a))) / den;
        double l2 = rp_v3_dot(n, rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(p, a))) / den;
        if (!isfinite(l1) || !isfinite(l2))
            l1 = l2 = 1.0 / 3.0;
        l1 = l1 < 0 ? 0 : l1;
        l2 = l2 < 0 ? 0 : l2;
        if (l1 + l2 > 1) {
            double sc = 1.0 / (l1 + l2);
            l1 *= sc;
            l2 *= sc;
        }
        double l[3] = {1 - l1 - l2, l1, l2};
        while (nd->child != RP_NONE) {
            /* Corner child k where lambda_k > 1/2, else the middle one
             * (hier_subdivide's child order). */
            int k;
            if (l[0] > 0.5) {
                k = 0;
                l[1] *= 2;
                l[2] *= 2;
                l[0] = 1 - l[1] - l[2];
            } else if (l[1] > 0.5) {
                k = 1;
                l[0] *= 2;
                l[2] *= 2;
                l[1] = 1 - l[0] - l[2];
            } else if (l[2] > 0.5) {
                k = 2;
                l[0] *= 2;
                l[1] *= 2;
                l[2] = 1 - l[0] - l[1];
            } else {
                k = 3;
                for (int j = 0; j < 3; j++)
                    l[j] = 1 - 2 * l[j];
            }
            for (int j = 0; j < 3; j++)
                l[j] = l[j] < 0 ? 0 : l[j];
            i = nd->child + (uint32_t)k;
            nd = &nodes[i];
        }
        double sum = l[0] + l[1] + l[2];
        w[0] = l[0] / sum;
        w[1] = l[1] / sum;
        w[2] = l[2] / sum;
        w[3] = 0;
        return i;
    }
    double u, v;
    inverse_bilinear(nd, n, p, &u, &v);
    while (nd->child != RP_NONE) {
        int hu = u >= 0.5, hv = v >= 0.5;
        static const int child_of[2][2] = {{0, 3}, {1, 2}}; /* [hu][hv] */
        u = hu ? 2 * u - 1 : 2 * u;
        v = hv ? 2 * v - 1 : 2 * v;
        i = nd->child + (uint32_t)child_of[hu][hv];
        nd = &nodes[i];
    }
    w[0] = (1 - u) * (1 - v);
    w[1] = u * (1 - v);
    w[2] = u * v;
    w[3] = (1 - u) * v;
    return i;
}

size_t hier_bytes(const hier_state *s)
{
    size_t b = s->cap_nodes * (sizeof(hier_node) + ((s->Y ? 3 : 2) * s->nb + 1) * sizeof(double));
    if (s->Y)
        b += s->cap_Y0 * sizeof(double) + s->nimp_hits * sizeof(hier_imp_hit);
    b += s->cap_links * sizeof(hier_link) + s->cap_start * sizeof(uint32_t);
    b += s->nfaces * sizeof(hier_face) + s->cap_open * sizeof *s->open;
    b += s->ff_scale ? s->cap_scale * sizeof(double) : 0; /* row sums (update_scale) */
    if (s->linear)
        b += s->cap_nodes * (sizeof(hier_basis) + 6 * s->nb * sizeof(double)) + s->cap_lin_K * 8 * sizeof(float) +
             (s->ff_lin ? 2 * s->cap_scale * sizeof(double) : 0);
    if (s->clustering)
        b += s->ncl * (sizeof(hier_cluster) + 2 * s->nb * sizeof(double) + 2 * sizeof(uint32_t)) +
             s->nfaces * (3 * sizeof(uint32_t) + sizeof(double)) + s->cl_nn * (sizeof(double) + 1) +
             s->cap_clinks * sizeof(hier_clink) + s->cap_cl_cent * sizeof(hier_centry) + s->cap_cl_nent * sizeof(hier_nentry) + s->cap_cl_cvia * sizeof(uint32_t);
    if (s->cull)
        b += s->nunits * s->nunits * (sizeof(uint32_t) + sizeof(uint16_t)) + s->ncand * sizeof(uint32_t) +
             s->nfaces * sizeof(uint32_t) + s->nunits * (sizeof(uint32_t) + 2 * sizeof(rp_vec3));
    return b;
}

/* The root's id is its face's index; a child's mixes its parent's with its
 * number among the four.  Computed by walking to the root rather than held
 * (8 bytes a node; the walk is a few nanoseconds a level, once per set of
 * a link's visibility rays). */
uint64_t hier_node_id(const hier_state *s, const hier_node *nd)
{
    if (nd->parent == RP_NONE)
        return nd->face;
    const hier_node *p = &s->nodes[nd->parent];
    const uint64_t k = (uint64_t)(nd - s->nodes) - p->child;
    return hier_mix(hier_node_id(s, p) + (k + 1) * UINT64_C(0x9e3779b97f4a7c15));
}
