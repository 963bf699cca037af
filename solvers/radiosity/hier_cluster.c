/* Hierarchical radiosity with clustering (Smits, Arvo & Greenberg 1994,
 * "A clustering algorithm for radiosity in complex environments"; Sillion
 * 1995, "A unified hierarchical algorithm for global illumination with
 * scattering volumes and object clusters").
 *
 * Without clustering every pair of faces is linked first, O(faces^2).
 * Here the face roots are the leaves of a binary bounding-volume hierarchy
 * (median split of the face centroids along the longest axis), and
 * linking starts from ONE self-link at the root cluster.  A link with a
 * cluster at either end (an item pair R <- S; items are clusters or
 * quadtree nodes) is judged by
 *
 *     rho_max(R) x B_S x F_bound x min(1, A_R / cl_area),
 *     F_bound = min(1, A_S c_R c_S / (pi d^2)),   d = gap between the boxes,
 *
 * (Smits et al. 1994, sec. 4: the largest point-to-cluster form factor,
 * and below --cluster-area the error in power rather than radiosity, so
 * that 75k small triangles do not each need every wall refined for them;
 * the face-level oracle in hier_link.c takes the same factor when
 * clustering is on), where c_R, c_S bound the cosines from the normal
 * cones (axis and half-angle of the faces' normals) and the cone of
 * directions between the two bounding spheres.  A pair that cannot
 * exchange anything (cones turned away, or one end planar with the other
 * on or behind its plane) is dropped; boxes that touch (and every
 * self-link) are always split.  The larger end is split: a cluster into
 * its two children, a quadtree node (while it stays above --min-area)
 * into its four; a pair of nodes becomes an ordinary face-level link
 * (hier_link.c), refined from then on exactly as without clustering.
 * Like BF refinement the cluster links are judged again at every pass
 * with the current radiosities.
 *
 * Transfer (the isotropic approximation, Sillion 1995, sec. 3.2, in the
 * form Smits et al. 1994 use for clusters whose members are known):
 *
 *   - a cluster source radiates its area-mean radiosity B_S from all its
 *     faces;
 *   - the link's form factor is the area average over the receiver of the
 *     point-to-source form factor,
 *         F_RS = A_S E[ cos_r+ cos_s+ V / (pi r^2) ],
 *     estimated by N stratified pairs of area-uniform points on the faces
 *     of R and of S (N = --cluster-rays), one visibility ray per pair with
 *     a non-zero kernel.  It is unbiased for the area-mean transfer;
 *   - a cluster receiver hands the gathered F B_S to the faces below it,
 *     each scaled by its own reflectance and by a share linear in its
 *     normal whose area mean over the receiver is 1 (orient, below).
 *     This is the approximation: the energy into the cluster is right on
 *     average, but how it is spread among faces of different orientation
 *     is only roughly right, which shows in Gouraud images as
 *     cluster-sized blotches (--reconstruct gather hides them).  The
 *     oracle keeps such links only where their transfer is below
 *     bf_epsilon (in power below cl_area).
 *
 * Push-pull through clusters: gathered radiosity is pushed down through
 * the clusters to the face roots (cl_push, added to what hierarchical.c's
 * push hands the root's quadtree), cluster links received by quadtree
 * nodes add to the nodes' gathered radiosity, and cluster radiosities are
 * pulled up as area-weighted means of the face roots.  In an enclosure the
 * cluster links' form factors (with the same shares) join the row sums of
 * the leaves below them, so the furnace stays exact.
 *
 * Determinism: node and link order come from serial loops in a fixed
 * order; the parallel parts (judging, form factors) write only their own
 * slots, and random numbers are keyed by the seed and the two items. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"

#define CL_SEED UINT64_C(0x6c75737465723031)

/* ---- items ---- */

/* An item is a quadtree node (a face root or a piece of one) or, with
 * HIER_CL_BIT set, a cluster. */
static int is_node(uint32_t it) { return !(it & HIER_CL_BIT); }
static const hier_cluster *cl_of(const hier_state *s, uint32_t it) { return &s->cl[it & ~HIER_CL_BIT]; }

static void item_box(const hier_state *s, uint32_t it, rp_vec3 *lo, rp_vec3 *hi)
{
    if (is_node(it)) {
        const hier_node *nd = &s->nodes[it];
        *lo = *hi = nd->v[0];
        for (int i = 1; i < nd->nverts; i++) {
            *lo = rp_v3(hier_min(lo->x, nd->v[i].x), hier_min(lo->y, nd->v[i].y), hier_min(lo->z, nd->v[i].z));
            *hi = rp_v3(hier_max(hi->x, nd->v[i].x), hier_max(hi->y, nd->v[i].y), hier_max(hi->z, nd->v[i].z));
        }
        return;
    }
    *lo = cl_of(s, it)->lo;
    *hi = cl_of(s, it)->hi;
}

static double item_area(const hier_state *s, uint32_t it)
{
    return is_node(it) ? s->nodes[it].area : cl_of(s, it)->area;
}

static const double *item_rho(const hier_state *s, uint32_t it)
{
    return is_node(it) ? s->faces[s->nodes[it].face].rho : s->cl_rho + (size_t)(it & ~HIER_CL_BIT) * s->nb;
}

static const double *item_B(const hier_state *s, uint32_t it)
{
    return is_node(it) ? s->B + (size_t)it * s->nb : s->cl_B + (size_t)(it & ~HIER_CL_BIT) * s->nb;
}

static void item_cone(const hier_state *s, uint32_t it, rp_vec3 *axis, double *cs, double *sn)
{
    if (is_node(it)) {
        *axis = s->faces[s->nodes[it].face].n;
        *cs = 1;
        *sn = 0;
        return;
    }
    *axis = cl_of(s, it)->axis;
    *cs = cl_of(s, it)->cone_cos;
    *sn = cl_of(s, it)->cone_sin;
}

/* The item of a child of the cluster hierarchy (face roots are nodes). */
static uint32_t child_item(const hier_state *s, uint32_t ch)
{
    return ch < s->nfaces ? ch : (uint32_t)((ch - s->nfaces) | HIER_CL_BIT);
}

/* ---- the hierarchy ---- */

typedef struct sort_key {
    double key;
    uint32_t f;
} sort_key;

static int key_cmp(const void *a, const void *b)
{
    const sort_key *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return x->f < y->f ? -1 : (x->f > y->f);
}

/* Builds the cluster over idx[lo, hi) (in place), returns its item id. */
static uint32_t build(hier_state *s, uint32_t *idx, sort_key *tmp, uint32_t lo, uint32_t hi, uint32_t parent)
{
    if (hi - lo == 1) {
        s->face_cl[idx[lo]] = parent;
        return idx[lo];
    }
    uint32_t c = (uint32_t)s->ncl++;
    hier_cluster *k = &s->cl[c];
    k->parent = parent;
    k->first = lo;
    k->count = hi - lo;
    rp_vec3 clo = s->nodes[idx[lo]].c, chi = clo;
    for (uint32_t i = lo; i < hi; i++) {
        rp_vec3 p = s->nodes[idx[i]].c;
        clo = rp_v3(hier_min(clo.x, p.x), hier_min(clo.y, p.y), hier_min(clo.z, p.z));
        chi = rp_v3(hier_max(chi.x, p.x), hier_max(chi.y, p.y), hier_max(chi.z, p.z));
    }
    rp_vec3 ext = rp_v3_sub(chi, clo);
    int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    for (uint32_t i = lo; i < hi; i++) {
        rp_vec3 p = s->nodes[idx[i]].c;
        tmp[i].key = axis == 0 ? p.x : (axis == 1 ? p.y : p.z);
        tmp[i].f = idx[i];
    }
    qsort(tmp + lo, hi - lo, sizeof *tmp, key_cmp);
    for (uint32_t i = lo; i < hi; i++)
        idx[i] = tmp[i].f;
    uint32_t mid = lo + (hi - lo) / 2;
    uint32_t a = build(s, idx, tmp, lo, mid, c);
    uint32_t b = build(s, idx, tmp, mid, hi, c);
    k = &s->cl[c]; /* (no reallocation, but keep it obvious) */
    k->child[0] = a;
    k->child[1] = b;
    /* Box, area, reflectance bound and normal cone over the faces. */
    const size_t nb = s->nb;
    double *rho = s->cl_rho + (size_t)c * nb;
    rp_vec3 n = rp_v3(0, 0, 0);
    k->lo = s->faces[idx[lo]].lo;
    k->hi = s->faces[idx[lo]].hi;
    k->area = 0;
    for (size_t bb = 0; bb < nb; bb++)
        rho[bb] = 0;
    for (uint32_t i = lo; i < hi; i++) {
        const hier_face *f = &s->faces[idx[i]];
        k->lo = rp_v3(hier_min(k->lo.x, f->lo.x), hier_min(k->lo.y, f->lo.y), hier_min(k->lo.z, f->lo.z));
        k->hi = rp_v3(hier_max(k->hi.x, f->hi.x), hier_max(k->hi.y, f->hi.y), hier_max(k->hi.z, f->hi.z));
        double A = s->nodes[idx[i]].area;
        k->area += A;
        n = rp_v3_madd(n, f->n, A);
        for (size_t bb = 0; bb < nb; bb++)
            rho[bb] = hier_max(rho[bb], f->rho[bb]);
    }
    k->nbar = rp_v3_scale(n, 1.0 / k->area);
    k->c = rp_v3_scale(rp_v3_add(k->lo, k->hi), 0.5);
    k->r = 0.5 * rp_v3_length(rp_v3_sub(k->hi, k->lo));
    double nl = rp_v3_length(n);
    k->cone_cos = -1;
    k->axis = rp_v3(0, 0, 1);
    if (nl > 1e-9 * k->area) {
        k->axis = rp_v3_scale(n, 1.0 / nl);
        double mc = 1;
        for (uint32_t i = lo; i < hi; i++)
            mc = hier_min(mc, rp_v3_dot(k->axis, s->faces[idx[i]].n));
        /* A little slack for rounding. */
        k->cone_cos = hier_max(-1.0, mc - 1e-9);
    }
    k->cone_sin = sqrt(hier_max(0.0, 1 - k->cone_cos * k->cone_cos));
    /* Planar: one normal and one plane (a wall cut into pieces). */
    const hier_face *f0 = &s->faces[idx[lo]];
    k->planar = 1;
    k->pd = f0->d;
    for (uint32_t i = lo + 1; i < hi && k->planar; i++) {
        const hier_face *f = &s->faces[idx[i]];
        k->planar = rp_v3_dot(f->n, f0->n) >= 1 - 1e-12 && fabs(f->d - f0->d) <= f->tol + f0->tol;
    }
    if (k->planar)
        k->axis = f0->n;
    return s->nfaces + c;
}

rp_status hier_cluster_init(hier_state *s, rp_error *err)
{
    const size_t n = s->nfaces, nb = s->nb;
    if (n < 2) {
        s->clustering = 0;
        return RP_OK;
    }
    s->cl = calloc(n - 1, sizeof *s->cl);
    s->cl_faces = malloc(n * sizeof *s->cl_faces);
    s->cl_cum = malloc((n + 1) * sizeof *s->cl_cum);
    s->face_pos = malloc(n * sizeof *s->face_pos);
    s->face_cl = malloc(n * sizeof *s->face_cl);
    s->cl_rho = calloc((n - 1) * nb, sizeof *s->cl_rho);
    s->cl_B = calloc((n - 1) * nb, sizeof *s->cl_B);
    s->cl_G = calloc((n - 1) * nb * 4, sizeof *s->cl_G);
    s->cl_acc = calloc((n - 1) * nb * 4, sizeof *s->cl_acc);
    s->cl_push = calloc(n * nb, sizeof *s->cl_push);
    s->cl_ff = calloc(n, sizeof *s->cl_ff);
    s->cl_ffacc = calloc((n - 1) * 4, sizeof *s->cl_ffacc);

    sort_key *tmp = malloc(n * sizeof *tmp);
    if (!s->cl || !s->cl_faces || !s->cl_cum || !s->face_pos || !s->face_cl || !s->cl_rho || !s->cl_B ||
        !s->cl_G || !s->cl_acc || !s->cl_push || !s->cl_ff || !s->cl_ffacc || !tmp) {
        free(tmp);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu clusters", n - 1);
    }
    for (size_t f = 0; f < n; f++)
        s->cl_faces[f] = (uint32_t)f;
    s->ncl = 0;
    build(s, s->cl_faces, tmp, 0, (uint32_t)n, RP_NONE);
    free(tmp);
    s->cl_cum[0] = 0;
    for (size_t i = 0; i < n; i++) {
        s->face_pos[s->cl_faces[i]] = (uint32_t)i;
        s->cl_cum[i + 1] = s->cl_cum[i] + s->nodes[s->cl_faces[i]].area;
    }
    return RP_OK;
}

void hier_cluster_free(hier_state *s)
{
    free(s->cl);
    free(s->cl_faces);
    free(s->cl_cum);
    free(s->face_pos);
    free(s->face_cl);
    free(s->cl_rho);
    free(s->cl_B);
    free(s->cl_G);
    free(s->cl_acc);
    free(s->cl_push);
    free(s->cl_ff);
    free(s->cl_ffacc);
    free(s->cl_nff);
    free(s->cl_nreach);
    free(s->clinks);
}

/* Cluster radiosities: area means of the face roots below (pull). */
static void cluster_pull(hier_state *s)
{
    const size_t nb = s->nb;
    for (size_t c = s->ncl; c-- > 0;) {
        const hier_cluster *k = &s->cl[c];
        double *B = s->cl_B + c * nb;
        for (size_t b = 0; b < nb; b++)
            B[b] = 0;
        for (int j = 0; j < 2; j++) {
            uint32_t it = child_item(s, k->child[j]);
            const double *Bc = item_B(s, it);
            double w = item_area(s, it) / k->area;
            for (size_t b = 0; b < nb; b++)
                B[b] += w * Bc[b];
        }
    }
}

/* ---- judging a pair ---- */

/* Cosine bound between a cone of normals (axis a, cos ca, sin sa) and the
 * directions within half-angle (cb, sb) of unit u: cos(max(0, theta -
 * alpha - beta)), theta the angle between a and u. */
static double cone_cos_bound(rp_vec3 a, double ca, double sa, rp_vec3 u, double cb, double sb)
{
    if (ca <= -1)
        return 1;
    /* cos and sin of alpha + beta */
    double cab = ca * cb - sa * sb, sab = sa * cb + ca * sb;
    if (sab < 0 || cab <= -1)
        return 1;
    double ct = rp_v3_dot(a, u);
    ct = hier_max(-1.0, hier_min(1.0, ct));
    double st = sqrt(hier_max(0.0, 1 - ct * ct));
    /* alpha + beta >= pi, or theta <= alpha + beta: bound 1. */
    if (sab <= 0 && cab < 0)
        return 1;
    if (ct >= cab)
        return 1;
    /* cos(theta - (alpha + beta)) */
    return hier_max(0.0, ct * cab + st * sab);
}

/* 1 if item it is planar and the box [lo, hi] lies on or behind its plane. */
static int item_behind(const hier_state *s, uint32_t it, rp_vec3 lo, rp_vec3 hi)
{
    rp_vec3 n;
    double d, tol;
    if (is_node(it)) {
        const hier_face *f = &s->faces[s->nodes[it].face];
        n = f->n;
        d = f->d;
        tol = f->tol;
    } else {
        const hier_cluster *k = cl_of(s, it);
        if (!k->planar)
            return 0;
        n = k->axis;
        d = k->pd;
        tol = hier_box_tol(k->lo, k->hi);
    }
    /* The box corner farthest in front of the plane. */
    rp_vec3 c = rp_v3(n.x > 0 ? hi.x : lo.x, n.y > 0 ? hi.y : lo.y, n.z > 0 ? hi.z : lo.z);
    return rp_v3_dot(n, c) - d <= tol + hier_box_tol(lo, hi);
}

/* -1: nothing can pass (drop); 0: the spheres overlap (split); 1: apart,
 * with the form-factor bound in *Fb. */
static int judge(const hier_state *s, uint32_t r, uint32_t src, double *Fb)
{
    const double *rho = item_rho(s, r);
    int reflects = 0;
    for (size_t b = 0; b < s->nb; b++)
        reflects |= rho[b] > 0;
    if (!reflects)
        return -1;
    if (r == src)
        return 0;
    /* The gap between the two bounding boxes (spheres would make every
     * element of a large wall "overlap" everything near it). */
    rp_vec3 lr, hr, ls, hs;
    item_box(s, r, &lr, &hr);
    item_box(s, src, &ls, &hs);
    /* A planar end (a node, or a cluster of coplanar faces) sees nothing
     * whose box lies on or behind its plane, and is seen by nothing there. */
    if (item_behind(s, r, ls, hs) || item_behind(s, src, lr, hr))
        return -1;
    double gx = hier_max(0.0, hier_max(lr.x - hs.x, ls.x - hr.x));
    double gy = hier_max(0.0, hier_max(lr.y - hs.y, ls.y - hr.y));
    double gz = hier_max(0.0, hier_max(lr.z - hs.z, ls.z - hr.z));
    double gap = sqrt(gx * gx + gy * gy + gz * gz);
    if (!(gap > 0))
        return 0;
    rp_vec3 cr = rp_v3_scale(rp_v3_add(lr, hr), 0.5), cs = rp_v3_scale(rp_v3_add(ls, hs), 0.5);
    double rr = 0.5 * rp_v3_length(rp_v3_sub(hr, lr)), rs = 0.5 * rp_v3_length(rp_v3_sub(hs, ls));
    rp_vec3 d = rp_v3_sub(cs, cr);
    double dist = rp_v3_length(d);
    rp_vec3 u = dist > 0 ? rp_v3_scale(d, 1.0 / dist) : rp_v3(0, 0, 1);
    /* Directions between the two spheres; all of them when they meet. */
    double sb = dist > rr + rs ? (rr + rs) / dist : 1, cb = sqrt(hier_max(0.0, 1 - sb * sb));
    if (!(dist > rr + rs))
        cb = -1, sb = 0;
    rp_vec3 ar, as;
    double car, sar, cas, sas;
    item_cone(s, r, &ar, &car, &sar);
    item_cone(s, src, &as, &cas, &sas);
    double kr = cone_cos_bound(ar, car, sar, u, cb, sb);
    double ks = cone_cos_bound(as, cas, sas, rp_v3_scale(u, -1), cb, sb);
    if (!(kr > 0) || !(ks > 0))
        return -1;
    *Fb = hier_min(1.0, item_area(s, src) * kr * ks / (RP_PI * gap * gap));
    return 1;
}

/* 1 if a node may be split (its children stay above the area floor). */
static int node_can_split(const hier_state *s, uint32_t it)
{
    return is_node(it) && 0.25 * s->nodes[it].area >= s->min_area;
}

/* 0 keep, 1 split the receiver, 2 the source, 3 both, 4 drop. */
static int cl_decide(const hier_state *s, const hier_clink *l)
{
    double Fb = 0;
    int j = judge(s, l->recv, l->src, &Fb);
    if (j < 0)
        return 4;
    if (j == 1) {
        const double *rho = item_rho(s, l->recv), *B = item_B(s, l->src);
        double e = 0;
        for (size_t b = 0; b < s->nb; b++)
            e = hier_max(e, rho[b] * B[b]);
        if (!(e * Fb * hier_min(1.0, item_area(s, l->recv) / s->cl_area) > s->bf_eps))
            return 0;
    }
    if (l->recv == l->src)
        return 3;
    /* The larger end is split; a quadtree node (at least one end is a
     * cluster) only while it may be, else the cluster at the other end. */
    double ar = item_area(s, l->recv), as = item_area(s, l->src);
    if (is_node(l->recv))
        return ar > as && node_can_split(s, l->recv) ? 1 : 2;
    if (is_node(l->src))
        return as > ar && node_can_split(s, l->src) ? 2 : 1;
    return ar >= as ? 1 : 2;
}

/* A point uniform in area on the faces of item it, from u in [0, 1) (the
 * face, for a cluster) and (u2, u3) (the point); *face gets the face. */
static rp_vec3 item_point(const hier_state *s, uint32_t it, double u, double u2, double u3, uint32_t *face)
{
    if (is_node(it)) {
        *face = s->nodes[it].face;
        return hier_node_point(&s->nodes[it], u2, u3);
    }
    const hier_cluster *k = cl_of(s, it);
    uint32_t first = k->first, count = k->count;
    const double *cum = s->cl_cum;
    double t = cum[first] + u * (cum[first + count] - cum[first]);
    uint32_t lo = first, hi = first + count; /* cum[lo] <= t < cum[hi] */
    while (hi - lo > 1) {
        uint32_t m = lo + (hi - lo) / 2;
        if (cum[m] <= t)
            lo = m;
        else
            hi = m;
    }
    *face = s->cl_faces[lo];
    return hier_node_point(&s->nodes[*face], u2, u3);
}

/* F_RS = A_S E[cos_r+ cos_s+ V / (pi r^2)] over area-uniform point pairs
 * (stratified in the choice of face on both ends). */
static double clink_eval(const hier_state *s, uint32_t r, uint32_t src, double *rays)
{
    const unsigned N = s->cluster_rays;
    uint64_t key = hier_key(s->seed ^ CL_SEED, r, src);
    uint32_t perm[256];
    hier_shuffle(perm, N, key, 6 * (uint64_t)N);
    double sum = 0;
    for (unsigned k = 0; k < N; k++) {
        uint32_t fa, fb;
        rp_vec3 a = item_point(s, r, (k + hier_u01(key, 6 * (uint64_t)k)) / N, hier_u01(key, 6 * (uint64_t)k + 1),
                               hier_u01(key, 6 * (uint64_t)k + 2), &fa);
        rp_vec3 b = item_point(s, src, (perm[k] + hier_u01(key, 6 * (uint64_t)k + 3)) / N,
                               hier_u01(key, 6 * (uint64_t)k + 4), hier_u01(key, 6 * (uint64_t)k + 5), &fb);
        if (fa == fb)
            continue;
        rp_vec3 na = s->faces[fa].n, nbv = s->faces[fb].n;
        rp_vec3 ab = rp_v3_sub(b, a);
        double r2 = rp_v3_dot(ab, ab);
        double w = hier_max(rp_v3_dot(ab, na), 0) * hier_max(-rp_v3_dot(ab, nbv), 0) / (r2 * r2);
        if (!(w > 0))
            continue;
        *rays += 1;
        if (!rp_ray_occluded(s->rc, a, na, b, nbv))
            sum += w;
    }
    return item_area(s, src) * sum / (RP_PI * N);
}

/* How a cluster receiver shares a link's transfer among its faces.  The
 * isotropic approximation gives every face the same share, so faces
 * turned away from a light got as much as those facing it (blotches
 * cluster-sized in images).  Instead face f gets w0 (1 + n_f . u), u the
 * unit direction from the receiver's box centre to the source's: a
 * clamped-free "half cosine" that is linear in the normal, so what a
 * cluster gathers pushes down as a constant and a vector per band, and
 * with w0 = 1 / (1 + nbar . u), nbar the area-mean normal, its area
 * average over the receiver is 1: the energy into the cluster, and the
 * area-averaged answers, are those of the isotropic estimate.  Receivers
 * whose faces nearly all face away (1 + nbar . u < 0.1) share evenly. */
static void orient(const hier_state *s, hier_clink *l)
{
    rp_vec3 lr, hr, ls, hs;
    item_box(s, l->recv, &lr, &hr);
    item_box(s, l->src, &ls, &hs);
    rp_vec3 d = rp_v3_sub(rp_v3_add(ls, hs), rp_v3_add(lr, hr));
    double dl = rp_v3_length(d);
    if (!(dl > 0))
        return;
    rp_vec3 u = rp_v3_scale(d, 1.0 / dl);
    double c = 1 + rp_v3_dot(cl_of(s, l->recv)->nbar, u);
    if (!(c >= 0.1))
        return;
    l->u[0] = (float)u.x;
    l->u[1] = (float)u.y;
    l->u[2] = (float)u.z;
    l->w0 = (float)(1.0 / c);
}

/* ---- refinement ---- */

/* Cluster-link form-factor sums: per node, of the links it receives
 * (cl_nff), and per face root, of those its clusters receive (cl_ff);
 * and which nodes some cluster link reaches. */
static rp_status cluster_sums(hier_state *s, rp_error *err)
{
    const size_t n = s->nfaces, nn = s->nnodes;
    if (s->cl_nn < nn) {
        double *f = realloc(s->cl_nff, s->cap_nodes * sizeof *f);
        if (f)
            s->cl_nff = f;
        unsigned char *r = realloc(s->cl_nreach, s->cap_nodes);
        if (r)
            s->cl_nreach = r;
        if (!f || !r)
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for cluster sums");
    }
    s->cl_nn = nn;
    memset(s->cl_nff, 0, nn * sizeof *s->cl_nff);
    memset(s->cl_nreach, 0, nn);
    double *own = s->cl_G; /* scratch: four doubles per cluster */
    memset(own, 0, s->ncl * 4 * sizeof *own);
    unsigned char *chit = calloc(s->ncl ? s->ncl : 1, 1);
    if (!chit)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for cluster sums");
    for (size_t k = 0; k < s->nclinks; k++) {
        uint32_t r = s->clinks[k].recv;
        if (is_node(r)) {
            s->cl_nff[r] += s->clinks[k].F;
            s->cl_nreach[r] = 1;
        } else {
            const hier_clink *l = &s->clinks[k];
            double *o = own + (size_t)(r & ~HIER_CL_BIT) * 4;
            o[0] += l->F * l->w0;
            for (int j = 0; j < 3; j++)
                o[1 + j] += l->F * l->w0 * l->u[j];
            chit[r & ~HIER_CL_BIT] = 1;
        }
    }
    for (size_t c = 0; c < s->ncl; c++) {
        uint32_t p = s->cl[c].parent;
        for (int j = 0; j < 4; j++)
            s->cl_ffacc[c * 4 + j] = own[c * 4 + j] + (p == RP_NONE ? 0 : s->cl_ffacc[(size_t)p * 4 + j]);
        if (p != RP_NONE)
            chit[c] |= chit[p];
    }
    for (size_t f = 0; f < n; f++) {
        const double *a = s->cl_ffacc + (size_t)s->face_cl[f] * 4;
        rp_vec3 nf = s->faces[f].n;
        s->cl_ff[f] = a[0] + nf.x * a[1] + nf.y * a[2] + nf.z * a[3];
        s->cl_nreach[f] |= chit[s->face_cl[f]];
    }
    free(chit);
    return RP_OK;
}

rp_status hier_cluster_refine(hier_state *s, size_t *refined, rp_error *err)
{
    *refined = 0;
    if (!s->clustering)
        return RP_OK;
    cluster_pull(s);
    rp_status st = RP_OK;
    hier_clink *work = NULL, *kept = NULL, *cand = NULL;
    hier_link *flinks = NULL, *fcand = NULL;
    unsigned char *act = NULL, *code = NULL;
    uint32_t *pairs = NULL;
    size_t capw = 0, capk = 0, capc = 0, capfl = 0, capfc = 0, capa = 0, capcode = 0, capp = 0;
    size_t nw = 0, nk = 0, nfl = 0;
    int first = s->nclinks == 0 && !s->linked;
    if (first) {
        if (!hier_grow((void **)&work, &capw, 1, sizeof *work))
            goto nomem;
        work[0].recv = work[0].src = HIER_CL_BIT; /* the root cluster */
        work[0].F = 0;
        work[0].u[0] = work[0].u[1] = work[0].u[2] = 0;
        work[0].w0 = 1;
        nw = 1;
    } else {
        /* The stored links are judged again, with the current radiosities. */
        work = s->clinks;
        capw = s->cap_clinks;
        nw = s->nclinks;
        s->clinks = NULL;
        s->cap_clinks = 0;
        s->nclinks = 0;
    }
    int changed = first;
    while (nw) {
        if (!hier_grow((void **)&act, &capa, nw, 1))
            goto nomem;
#pragma omp parallel for num_threads(s->threads) schedule(static) if (nw > 8192)
        for (long k = 0; k < (long)nw; k++)
            act[k] = (unsigned char)cl_decide(s, &work[k]);
        /* Children pairs, in link order; quadtree nodes are split here,
         * serially, so node numbers do not depend on threads. */
        size_t np = 0;
        for (size_t k = 0; k < nw; k++) {
            const hier_clink l = work[k];
            if (act[k] == 0) {
                if (!hier_grow((void **)&kept, &capk, nk + 1, sizeof *kept))
                    goto nomem;
                kept[nk++] = l;
                continue;
            }
            changed = 1;
            if (act[k] == 4) {
                s->clinks_culled++;
                continue;
            }
            (*refined)++;
            s->clinks_refined++;
            uint32_t rs[4] = {l.recv}, ss[4] = {l.src};
            int nr = 1, nsrc = 1;
            for (int end = 0; end < 2; end++) {
                if (!(act[k] & (1 << end)))
                    continue;
                uint32_t it = end == 0 ? l.recv : l.src;
                uint32_t *out = end == 0 ? rs : ss;
                int m;
                if (is_node(it)) {
                    if ((st = hier_subdivide(s, it, err)) != RP_OK)
                        goto done;
                    for (m = 0; m < 4; m++)
                        out[m] = s->nodes[it].child + (uint32_t)m;
                } else {
                    const hier_cluster *c = cl_of(s, it);
                    out[0] = child_item(s, c->child[0]);
                    out[1] = child_item(s, c->child[1]);
                    m = 2;
                }
                if (end == 0)
                    nr = m;
                else
                    nsrc = m;
            }
            if (!hier_grow((void **)&pairs, &capp, 2 * (np + 16), sizeof *pairs))
                goto nomem;
            for (int i = 0; i < nr; i++)
                for (int j = 0; j < nsrc; j++) {
                    if (rs[i] == ss[j] && is_node(rs[i]))
                        continue; /* a face does not see itself */
                    pairs[2 * np] = rs[i];
                    pairs[2 * np + 1] = ss[j];
                    np++;
                }
        }
        /* Form factors of the new links, in parallel, into their slots:
         * code 0 none, 1 face link, 2 face link with every ray blocked,
         * 3 cluster link. */
        if (!hier_grow((void **)&cand, &capc, np ? np : 1, sizeof *cand) ||
            !hier_grow((void **)&fcand, &capfc, np ? np : 1, sizeof *fcand) ||
            !hier_grow((void **)&code, &capcode, np ? np : 1, 1))
            goto nomem;
        double rays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 64) reduction(+ : rays) if (np > 256)
        for (long t = 0; t < (long)np; t++) {
            uint32_t r = pairs[2 * t], src = pairs[2 * t + 1];
            if (is_node(r) && is_node(src)) {
                code[t] = (unsigned char)hier_link_eval(s, r, src, &fcand[t], &rays);
                continue;
            }
            double Fb;
            int j = judge(s, r, src, &Fb);
            cand[t].recv = r;
            cand[t].src = src;
            cand[t].F = 0;
            cand[t].u[0] = cand[t].u[1] = cand[t].u[2] = 0;
            cand[t].w0 = 1;
            if (j == 1 && !is_node(r))
                orient(s, &cand[t]);
            if (j < 0) {
                code[t] = 0;
                continue;
            }
            if (j == 1)
                cand[t].F = clink_eval(s, r, src, &rays);
            code[t] = 3;
        }
        s->rays += rays;
        size_t nn = 0;
        for (size_t t = 0; t < np; t++) {
            if (code[t] == 0) {
                if (!(is_node(pairs[2 * t]) && is_node(pairs[2 * t + 1])))
                    s->clinks_culled++;
                continue;
            }
            s->form_factors++;
            if (code[t] == 3) {
                cand[nn++] = cand[t];
                continue;
            }
            if (!hier_grow((void **)&flinks, &capfl, nfl + 1, sizeof *flinks))
                goto nomem;
            flinks[nfl++] = fcand[t];
        }
        /* The new cluster links are judged in the next round. */
        hier_clink *t = work;
        size_t tc = capw;
        work = cand;
        capw = capc;
        cand = t;
        capc = tc;
        nw = nn;
    }
    s->clinks = kept;
    s->cap_clinks = capk;
    s->nclinks = nk;
    kept = NULL;
    if (nfl && (st = hier_links_add(s, flinks, nfl, err)) != RP_OK)
        goto done;
    if (first) {
        s->clinks_initial = s->nclinks;
        s->links_initial = s->nlinks;
    }
    if (changed || s->cl_nn < s->nnodes)
        st = cluster_sums(s, err);
    goto done;
nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory refining cluster links");
done:
    free(work);
    free(kept);
    free(cand);
    free(flinks);
    free(fcand);
    free(act);
    free(code);
    free(pairs);
    return st;
}

/* ---- gathering ---- */

void hier_cluster_gather(hier_state *s)
{
    if (!s->clustering)
        return;
    const size_t nb = s->nb, n = s->nfaces;
    cluster_pull(s);
    double *G = s->cl_G;
    memset(G, 0, s->ncl * nb * 4 * sizeof *G);
    for (size_t k = 0; k < s->nclinks; k++) {
        const hier_clink *l = &s->clinks[k];
        if (is_node(l->recv))
            continue; /* hier_cluster_gather_nodes */
        const double *Bs = item_B(s, l->src);
        double *g = G + (size_t)(l->recv & ~HIER_CL_BIT) * nb * 4;
        for (size_t b = 0; b < nb; b++) {
            double t = l->F * l->w0 * Bs[b];
            g[4 * b] += t;
            for (int j = 0; j < 3; j++)
                g[4 * b + 1 + j] += t * l->u[j];
        }
    }
    for (size_t c = 0; c < s->ncl; c++) {
        uint32_t p = s->cl[c].parent;
        double *acc = s->cl_acc + c * nb * 4;
        const double *g = G + c * nb * 4;
        for (size_t b = 0; b < 4 * nb; b++)
            acc[b] = g[b] + (p == RP_NONE ? 0 : s->cl_acc[(size_t)p * nb * 4 + b]);
    }
    for (size_t f = 0; f < n; f++) {
        const double *rho = s->faces[f].rho, *acc = s->cl_acc + (size_t)s->face_cl[f] * nb * 4;
        rp_vec3 nf = s->faces[f].n;
        for (size_t b = 0; b < nb; b++) {
            const double *a = acc + 4 * b;
            s->cl_push[f * nb + b] = rho[b] * (a[0] + nf.x * a[1] + nf.y * a[2] + nf.z * a[3]);
        }
    }
}

void hier_cluster_gather_nodes(hier_state *s, double *Bg)
{
    if (!s->clustering)
        return;
    const size_t nb = s->nb;
    for (size_t k = 0; k < s->nclinks; k++) {
        const hier_clink *l = &s->clinks[k];
        if (!is_node(l->recv))
            continue;
        const double *Bs = item_B(s, l->src), *rho = item_rho(s, l->recv);
        double *g = Bg + (size_t)l->recv * nb;
        for (size_t b = 0; b < nb; b++)
            g[b] += rho[b] * l->F * Bs[b];
    }
}
