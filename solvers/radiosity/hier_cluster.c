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
 * Transfer.  The isotropic approximation (Sillion 1995, sec. 3.2) lets a
 * cluster source radiate its area-mean radiosity from all its faces and a
 * cluster receiver hand what it gathers to all the faces below it.  Both
 * halves carry light between surfaces that cannot see each other: the
 * faces lining the inside of a closed shell, clustered with its outside,
 * were handed a share of the light falling on the outside (a sealed
 * cavity read 0.10 instead of 0), and a receiver that sees only the dark
 * side of a source cluster gathered its mean.  Here a link's transfer is
 * sampled per receiving element with that element's own orientation and
 * visibility, as Smits et al. 1994 compute each member's transfer, and
 * kept as entries (e, leaf, F): e gathers rho_e F B_leaf, the leaf (when
 * drawn) under a source point that an open ray from e reached.
 *
 *   - A link received by a quadtree node: --cluster-rays stratified point
 *     pairs, one ray each (node_entries).  F_qS B_S = A_S E[k V B(y)] / pi
 *     with the kernel k = cos_q+ cos_s+ / r^2; unbiased.
 *   - The links received by a cluster share the samples of its faces:
 *     each face draws --cluster-face-rays samples (a face larger than
 *     --cluster-area also its share by area of --cluster-rays per link,
 *     face_samples), each a link chosen by a mixture of its unoccluded
 *     form factor, that times its source's radiosity, and a uniform part,
 *     then a point on the face, a point on the link's source and one ray
 *     (face_entries).  With the weight 1 / P(link) the estimate of the
 *     face's own sum over links of F B is unbiased, and so is each link's
 *     part of it (its entries alone), whatever the other links: a cluster
 *     that lost links drops their entries, and one that gained links
 *     draws samples for the new links only, over their own mixture, each
 *     face as many as a draw over all its links would give them (at least
 *     one); the old links keep their entries.  Drawn again over all the
 *     links, every face of a cluster that gained one link took new values
 *     for all of them, so each pass shook the radiosities the oracle
 *     judges by, and a few links crossing the threshold at each pass kept
 *     runs going: McGuire's teapot took 27 to 133 passes over 40 seeds
 *     (median 42), the bunny scene 35 to 58 over 20; this way 27 to 122
 *     (median 33) and 38 to 52, with a quarter fewer rays (stop 43,
 *     docs/design.md).  Candidate
 *     links are judged before anything is sampled for them: only the
 *     links the oracle keeps cost rays.
 *
 * So a face turned away from every source of its clusters' links, or that
 * no open segment joins to one, gathers exactly nothing through them, and
 * a closed cavity stays dark for any clustering.  The price is noise: the
 * face-level values carry the sampling error of a few rays per face and
 * cluster level (their area means over many faces do not).  The oracle
 * keeps cluster links only where their transfer is below bf_epsilon (in
 * power below cl_area).
 *
 * Push-pull: entries add to their receiving node's gathered radiosity
 * (hier_cluster_gather_nodes), which the quadtree push hands to the
 * leaves; cluster radiosities, which only the oracle uses, are the
 * area-weighted means of the face roots.  In an enclosure the entries'
 * form factors join the row sums of the leaves below them, so the furnace
 * stays exact.
 *
 * Determinism: node and link order come from serial loops in a fixed
 * order; the parallel parts (judging, form factors, entries) write only their own
 * slots, and random numbers are keyed by the seed and the two items. */
#include <math.h>
#include <stddef.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"

#define CL_SEED UINT64_C(0x6c75737465723031)
#define CE_SEED UINT64_C(0x636c656e74727931)
#define FOLLOW_SEED UINT64_C(0x666f6c6c6f773031)

/* ---- items ---- */

/* An item is a quadtree node (a face root or a piece of one) or, with
 * HIER_CL_BIT set, a cluster. */
static int is_node(uint32_t it) { return !(it & HIER_CL_BIT); }
static const hier_cluster *cl_of(const hier_state *s, uint32_t it) { return &s->cl[it & ~HIER_CL_BIT]; }

static void item_box(const hier_state *s, uint32_t it, rp_vec3 *lo, rp_vec3 *hi)
{
    if (is_node(it)) {
        rp_vec3 box[2];
        hier_node_box(&s->nodes[it], box);
        *lo = box[0];
        *hi = box[1];
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
    rp_vec3 clo = hier_node_c(&s->nodes[idx[lo]]), chi = clo;
    for (uint32_t i = lo; i < hi; i++) {
        rp_vec3 p = hier_node_c(&s->nodes[idx[i]]);
        clo = rp_v3(hier_min(clo.x, p.x), hier_min(clo.y, p.y), hier_min(clo.z, p.z));
        chi = rp_v3(hier_max(chi.x, p.x), hier_max(chi.y, p.y), hier_max(chi.z, p.z));
    }
    rp_vec3 ext = rp_v3_sub(chi, clo);
    int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    for (uint32_t i = lo; i < hi; i++) {
        rp_vec3 p = hier_node_c(&s->nodes[idx[i]]);
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
    s->cl_efirst = calloc(n - 1, sizeof *s->cl_efirst);
    s->cl_ecount = calloc(n - 1, sizeof *s->cl_ecount);

    sort_key *tmp = malloc(n * sizeof *tmp);
    if (!s->cl || !s->cl_faces || !s->cl_cum || !s->face_pos || !s->face_cl || !s->cl_rho || !s->cl_B ||
        !s->cl_efirst || !s->cl_ecount || !tmp) {
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
    free(s->cl_efirst);
    free(s->cl_ecount);
    free(s->cl_nent);
    free(s->cl_cent);
    free(s->cl_cvia);
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

double hier_cluster_bound(const hier_state *s, uint32_t recv, uint32_t src)
{
    double Fb = 0;
    int j = judge(s, recv, src, &Fb);
    return j < 0 ? -1 : j == 0 ? 0 : Fb;
}

/* 1 if a node may be split (its children stay above the area floor). */
static int node_can_split(const hier_state *s, uint32_t it)
{
    return is_node(it) && 0.25 * s->nodes[it].area >= s->min_area;
}

/* 0 keep, 1 split the receiver, 2 the source, 3 both, 4 drop.  A link's
 * bound depends on the geometry alone: judged when the link was made and
 * kept in it (l->Fb), it is not judged again at every pass (stored cluster
 * links were 90% of the calls to judge). */
static int cl_decide(const hier_state *s, const hier_clink *l)
{
    double Fb = 0;
    int j = l->Fb ? 1 : judge(s, l->recv, l->src, &Fb);
    if (l->Fb)
        Fb = hier_bound_unpack(l->Fb);
    else if (j == 1)
        Fb = hier_bound_unpack(hier_bound_pack(Fb)); /* as it will be read at the next pass */
    if (j < 0)
        return 4;
    if (j == 1) {
        /* Not weighted by importance, which weighs quadtree links only
         * (hier_link.c decide): weighted here too, cluster links stayed
         * coarser where the importance was low, and closed meshes came out
         * dark, the same in every band and at any --bf-epsilon (stop 26,
         * against the path tracer: the bunny scene's bunny -0.73% with
         * --importance surfaces, -0.75% camera, 0.0% without importance;
         * CGAL's elephant in the Cornell box -0.6% and -0.9% against
         * -0.1%).  Judged without it, the bunny reads -0.1% and -0.2%.
         * Why cluster links left coarser than BF asks come out dark is
         * not known. */
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

/* A point uniform in area on the faces of item it, from u in [0, 1)
 * (stratified: the face of a cluster, the first coordinate of a node) and
 * (u2, u3); *face gets the face. */
static rp_vec3 item_point(const hier_state *s, uint32_t it, double u, double u2, double u3, uint32_t *face)
{
    if (is_node(it)) {
        *face = s->nodes[it].face;
        return hier_node_point(&s->nodes[it], u, u3);
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

/* ---- transfer: sampled entries ---- */

/* The point-pair kernel cos_x+ cos_y+ / r^2 (times 1/r^2 for the
 * normalisation of d): the integrand of the form factor, without pi. */
static double pair_kernel(rp_vec3 x, rp_vec3 nx, rp_vec3 y, rp_vec3 ny)
{
    rp_vec3 d = rp_v3_sub(y, x);
    double r2 = rp_v3_dot(d, d);
    double w = hier_max(rp_v3_dot(d, nx), 0) * hier_max(-rp_v3_dot(d, ny), 0) / (r2 * r2);
    return w > 0 && isfinite(w) ? w : 0;
}

/* An entry as drawn, with the source item of its link (via); the pools
 * keep hier_centry, and via only for the entries clusters share. */
typedef struct cl_draw {
    hier_centry e;
    uint32_t via;
} cl_draw;

/* Adds F to the entry (recv, src, via) among the last 16 of out[0..*n)
 * (a receiving element's samples often land on one source leaf), or
 * appends it. */
static void entry_add(cl_draw *out, unsigned *n, uint32_t recv, uint32_t src, uint32_t via, double F)
{
    for (unsigned k = *n > 16 ? *n - 16 : 0; k < *n; k++)
        if (out[k].e.src == src && out[k].e.recv == recv && out[k].via == via) {
            out[k].e.F = (float)(out[k].e.F + F);
            return;
        }
    out[*n].e.recv = recv;
    out[*n].e.src = src;
    out[*n].e.F = (float)F;
    out[*n].via = via;
    (*n)++;
}

/* The leaf (now) under point y of face f: the source end of an entry, so a
 * receiver gathers the radiosity of the part of the source its ray
 * reached, not the mean of a cluster it sees only a part of. */
static uint32_t leaf_at(const hier_state *s, uint32_t f, rp_vec3 y)
{
    double w[4];
    return hier_locate(s, f, y, w);
}

/* Unoccluded form-factor estimate of link r <- src from N area-uniform
 * point pairs, kernel only (no rays): how a cluster receiver shares its
 * samples among its links. */
static double link_unoccluded(const hier_state *s, uint32_t r, uint32_t src)
{
    /* A rough estimate is enough to share samples: a few pairs. */
    const unsigned N = s->cluster_rays < 4 ? s->cluster_rays : 4;
    uint64_t key = hier_key(s->seed ^ CL_SEED, r, src);
    double sum = 0;
    for (unsigned k = 0; k < N; k++) {
        uint32_t fa, fb;
        rp_vec3 a = item_point(s, r, (k + hier_u01(key, 6 * (uint64_t)k)) / N, hier_u01(key, 6 * (uint64_t)k + 1),
                               hier_u01(key, 6 * (uint64_t)k + 2), &fa);
        rp_vec3 b = item_point(s, src, hier_u01(key, 6 * (uint64_t)k + 3), hier_u01(key, 6 * (uint64_t)k + 4),
                               hier_u01(key, 6 * (uint64_t)k + 5), &fb);
        sum += pair_kernel(a, s->faces[fa].n, b, s->faces[fb].n);
    }
    return item_area(s, src) * sum / (RP_PI * N);
}

/* A link received by a quadtree node q from cluster src: N stratified
 * pairs (x on q, y on the source's faces), one ray each where the kernel
 * is positive; every open pair is an entry (q, leaf under y,
 * A_S k / (pi N)), so F_qS B_S = A_S E[k V B(y)] / pi, unbiased, and a
 * node that no open segment joins to a lit part of the source gathers
 * exactly nothing.  Returns the entries written to out (room for N). */
static unsigned node_entries(const hier_state *s, uint32_t q, uint32_t src, cl_draw *out, double *rays)
{
    const unsigned N = s->cluster_rays;
    const hier_node *nd = &s->nodes[q];
    rp_vec3 nq = s->faces[nd->face].n;
    uint64_t key = hier_key(s->seed ^ CL_SEED, q, src);
    uint32_t perm[256];
    hier_shuffle(perm, N, key, 6 * (uint64_t)N);
    const double AS = item_area(s, src);
    unsigned n = 0;
    for (unsigned k = 0; k < N; k++) {
        uint32_t fb;
        rp_vec3 a = hier_node_point(nd, (k + hier_u01(key, 6 * (uint64_t)k)) / N, hier_u01(key, 6 * (uint64_t)k + 1));
        rp_vec3 b = item_point(s, src, (perm[k] + hier_u01(key, 6 * (uint64_t)k + 3)) / N,
                               hier_u01(key, 6 * (uint64_t)k + 4), hier_u01(key, 6 * (uint64_t)k + 5), &fb);
        rp_vec3 nbv = s->faces[fb].n;
        double w = pair_kernel(a, nq, b, nbv);
        if (!(w > 0))
            continue;
        *rays += 1;
        if (rp_ray_occluded(s->rc, a, nq, b, nbv))
            continue;
        entry_add(out, &n, q, leaf_at(s, fb, b), src, AS * w / (RP_PI * N));
    }
    return n;
}

/* An entry points at the leaf its sample point fell on when it was
 * drawn, and the old links of a cluster keep their entries (evaluate),
 * so that leaf may be split later; the entry would then gather the mean
 * of its children, and the covariance of kernel and radiosity across it,
 * which hier_source_mean restores for links, would be lost (stop 38 drew
 * for new links only and found 7.4% of the turbine's entry mass on split
 * leaves; 9.3% of the bunny scene's at the end of a run now, 0.09% when
 * every gain drew all links again).  An entry on a split leaf moves down
 * to one child, drawn with probability w_k / sum w, w_k the point form
 * factor from the receiving element's centre to child k (source_value's
 * weights), until it reaches a leaf: in expectation it gathers sum w_k B_k
 * / sum w, the leaf's radiosity weighted by the kernel as a link's shares
 * weigh it.  The draw is keyed by the seed and the entry's receiver,
 * source and link, so it does not depend on threads or on where the
 * entry sits in the pool. */
void hier_cluster_follow_splits(hier_state *s)
{
    if (!s->clustering || s->cl_follow_nn == s->nnodes)
        return;
    s->cl_follow_nn = s->nnodes;
    const long n = (long)s->ncl_cent;
#pragma omp parallel for num_threads(s->threads) schedule(static) if (n > 65536)
    for (long j = 0; j < n; j++) {
        hier_centry *e = &s->cl_cent[j];
        if (e->F == 0 || s->nodes[e->src].child == RP_NONE)
            continue;
        const hier_node *q = &s->nodes[e->recv];
        const rp_vec3 qc = hier_node_c(q), nq = s->faces[q->face].n;
        const uint64_t key = hier_key(s->seed ^ FOLLOW_SEED, e->recv, e->src) ^ s->cl_cvia[j];
        for (uint64_t depth = 0; s->nodes[e->src].child != RP_NONE; depth++) {
            const hier_node *p = &s->nodes[e->src];
            double w[4];
            hier_child_shares(s, qc, nq, p, w);
            double u = hier_u01(key, depth);
            int k = 0;
            while (k < 3 && u >= w[k])
                u -= w[k++];
            e->src = p->child + (uint32_t)k;
        }
    }
}

/* Most samples one face of a receiving cluster draws at one level. */
#define FACE_MAX_SAMPLES 4096

/* Samples face f of cluster receiver c draws for the cluster's nl links:
 * --cluster-face-rays, plus, for a face larger than --cluster-area, its
 * share by area of --cluster-rays per link, as a quadtree node receiving
 * those links would draw.  A wall in a cluster of small faces is then
 * sampled as finely as a node, while the small faces, whose radiosity
 * the oracle already judges by power (sec. 4 of Smits et al. 1994), each
 * keep a few samples. */
static unsigned face_samples(const hier_state *s, const hier_cluster *c, uint32_t f, unsigned nl)
{
    double a = s->nodes[f].area;
    double big = s->cl_area > 0 ? hier_min(1.0, a / s->cl_area) : 1.0;
    double extra = floor((double)s->cluster_rays * nl * (a / c->area) * big);
    return s->cluster_face_rays + (unsigned)hier_min(extra, (double)FACE_MAX_SAMPLES);
}

/* The entries of face f of cluster receiver c from K samples of the links
 * links[0..nl) (all the cluster's links, or those new in this pass when
 * it kept nold others) with sampling probabilities pdf (and cdf,
 * cumulative).
 *
 * What face f gathers through them is sum_L F_fL B_L, F_fL its own form
 * factor to the source of L, with its own orientation and visibility.
 * K samples estimate it: a link L drawn with probability P(L)
 * (stratified over the cdf), a point x on f (stratified), a point y
 * uniform on L's source, and one ray; an open pair with a positive kernel
 * gives the entry (f, leaf under y, A_S k / (pi K P(L))).  This is
 * unbiased for any P > 0, and exact where it matters most: a face turned
 * away from every source, or that no open segment joins to one (inside a
 * sealed shell), gets nothing, and a face gathers only the radiosity of
 * the parts of a source its rays reach.  The isotropic push it replaces
 * handed every face below the cluster a share of the cluster's energy
 * whatever its visibility (Sillion 1995, sec. 3.2; Smits, Arvo & Greenberg
 * 1994 compute each member's own transfer, which this samples). */
static unsigned face_entries(const hier_state *s, uint32_t c, uint32_t f, const hier_clink *links, const double *pdf,
                             const double *cdf, unsigned nl, unsigned K, uint32_t nold, cl_draw *out, double *rays)
{
    const hier_node *nd = &s->nodes[f];
    rp_vec3 nf = s->faces[f].n;
    uint64_t key = hier_key(s->seed ^ CE_SEED, c, f);
    if (nold) /* a later draw beside nold kept links: its own numbers */
        key = hier_key(key, nold, UINT32_MAX);
    /* The points on the face follow a golden-ratio sequence in their
     * first coordinate (well spread for any K, and not in step with the
     * strata of the link choice). */
    const double x0 = hier_u01(key, 8 * (uint64_t)K);
    unsigned n = 0;
    for (unsigned j = 0; j < K; j++) {
        double u = (j + hier_u01(key, 8 * (uint64_t)j)) / K;
        unsigned lo = 0, hi = nl - 1; /* first link with cdf > u */
        while (lo < hi) {
            unsigned m = (lo + hi) / 2;
            if (cdf[m] > u)
                hi = m;
            else
                lo = m + 1;
        }
        if (!(pdf[lo] > 0))
            continue;
        uint32_t src = links[lo].src, fb;
        double ux = x0 + 0.6180339887498949 * j;
        rp_vec3 x = hier_node_point(nd, ux - floor(ux), hier_u01(key, 8 * (uint64_t)j + 2));
        rp_vec3 y = item_point(s, src, hier_u01(key, 8 * (uint64_t)j + 3), hier_u01(key, 8 * (uint64_t)j + 4),
                               hier_u01(key, 8 * (uint64_t)j + 5), &fb);
        rp_vec3 ny = s->faces[fb].n;
        double w = pair_kernel(x, nf, y, ny);
        if (!(w > 0))
            continue;
        *rays += 1;
        if (rp_ray_occluded(s->rc, x, nf, y, ny))
            continue;
        entry_add(out, &n, f, leaf_at(s, fb, y), src, item_area(s, src) * w / (RP_PI * K * pdf[lo]));
    }
    return n;
}

/* Sampling probabilities of cluster c's links (links[0..nl)): a mixture
 * of their unoccluded form factors, the same times the sources' current
 * radiosity (the light arrives through few links) and a uniform part, so
 * that every link keeps a probability > 0 when the radiosities change. */
static void link_pdf(const hier_state *s, const hier_clink *links, unsigned nl, double *pdf, double *cdf)
{
    double sf = 0, sfb = 0;
    for (unsigned k = 0; k < nl; k++) {
        const double *B = item_B(s, links[k].src);
        double bm = 0;
        for (size_t b = 0; b < s->nb; b++)
            bm = hier_max(bm, B[b]);
        pdf[k] = hier_max(0.0, links[k].Fu);
        cdf[k] = pdf[k] * bm; /* scratch */
        sf += pdf[k];
        sfb += cdf[k];
    }
    double wf = sf > 0 ? 0.4 : 0, wfb = sfb > 0 ? 0.4 : 0, wu = 1 - wf - wfb;
    double acc = 0;
    for (unsigned k = 0; k < nl; k++) {
        double p = wu / nl + (wf > 0 ? wf * pdf[k] / sf : 0) + (wfb > 0 ? wfb * cdf[k] / sfb : 0);
        pdf[k] = p;
        acc += p;
        cdf[k] = acc;
    }
    cdf[nl - 1] = 1.0 + 1e-12; /* every u in [0, 1) finds a link */
}

/* ---- refinement ---- */

static int u64_cmp(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : (x > y);
}

/* Cluster-link form-factor sums per node (cl_nff: the entries it
 * receives) and which nodes some cluster link reaches (cl_nreach). */
static rp_status cluster_sums(hier_state *s, rp_error *err)
{
    const size_t nn = s->nnodes;
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
    for (size_t k = 0; k < s->nclinks; k++) {
        const hier_clink *l = &s->clinks[k];
        if (!is_node(l->recv))
            continue;
        for (uint32_t j = 0; j < l->count; j++)
            if (s->cl_nent[l->first + j].F != 0) {
                s->cl_nff[l->recv] += s->cl_nent[l->first + j].F;
                s->cl_nreach[l->recv] = 1;
            }
    }
    for (size_t k = 0; k < s->ncl_cent; k++)
        if (s->cl_cent[k].F != 0) {
            s->cl_nff[s->cl_cent[k].recv] += s->cl_cent[k].F;
            s->cl_nreach[s->cl_cent[k].recv] = 1;
        }
    return RP_OK;
}

/* Cluster c lost links and gained none: the entries drawn for the links
 * it lost, rm[0..nrm) (cluster << 32 | source, sorted), die (F = 0, left
 * for compact_pools).  What is left is still unbiased for the links that
 * stay: each link's entries estimate its own transfer. */
static void prune_entries(hier_state *s, size_t c, const uint64_t *rm, size_t nrm)
{
    hier_centry *e = s->cl_cent + s->cl_efirst[c];
    const uint32_t *via = s->cl_cvia + s->cl_efirst[c];
    size_t n = s->cl_ecount[c];
    size_t lo = 0, hi = nrm;
    while (lo < hi) {
        size_t m = (lo + hi) / 2;
        if ((rm[m] >> 32) < c)
            lo = m + 1;
        else
            hi = m;
    }
    for (hi = lo; hi < nrm && (rm[hi] >> 32) == c; hi++)
        ;
    for (size_t k = 0; k < n; k++) {
        if (e[k].F == 0)
            continue;
        uint64_t want = ((uint64_t)c << 32) | via[k];
        size_t x = lo, y = hi;
        while (x < y) {
            size_t m = (x + y) / 2;
            if (rm[m] < want)
                x = m + 1;
            else
                y = m;
        }
        if (x < hi && rm[x] == want) {
            e[k].F = 0;
            s->ncl_cdead++;
        }
    }
}

/* Kills n entries of size bytes from base, their form factor a float at
 * offset off (set to 0); returns how many were alive.  For both pools:
 * the entries a cluster drew before drawing again, and those of a link a
 * node received when the link goes. */
static size_t kill_entries(void *base, size_t size, size_t off, size_t n)
{
    size_t d = 0;
    for (size_t k = 0; k < n; k++) {
        float *F = (float *)((char *)base + k * size + off);
        if (*F != 0) {
            *F = 0;
            d++;
        }
    }
    return d;
}

/* Appends the n drawn entries d to a pool (*pool, *np used, *cap) and,
 * when via is given (the pool clusters share), their links' sources to
 * *via (capacity *capv, kept in step with the pool's). */
static int pool_append(hier_centry **pool, size_t *np, size_t *cap, uint32_t **via, size_t *capv, const cl_draw *d,
                       size_t n)
{
    if (*np + n > UINT32_MAX || !hier_grow((void **)pool, cap, *np + n + 1, sizeof **pool) ||
        (via && !hier_grow((void **)via, capv, *np + n + 1, sizeof **via)))
        return 0;
    for (size_t k = 0; k < n; k++) {
        (*pool)[*np + k] = d[k].e;
        if (via)
            (*via)[*np + k] = d[k].via;
    }
    *np += n;
    return 1;
}

/* Shrinks array *a (capacity *cap, items of size bytes) to want items if
 * it holds more; left as it is if realloc fails. */
static void trim_to(void **a, size_t *cap, size_t want, size_t size)
{
    if (*cap <= want)
        return;
    void *p = realloc(*a, want * size);
    if (p) {
        *a = p;
        *cap = want;
    }
}

/* Gives a pool's unused storage back beyond a quarter of what it holds
 * (and its via array's, if it has one). */
static void pool_trim(void **pool, size_t size, size_t n, size_t *cap, uint32_t **via, size_t *capv)
{
    size_t want = n + n / 4 + 1024;
    trim_to(pool, cap, want, size);
    if (via)
        trim_to((void **)via, capv, want, sizeof **via);
}

/* Pools hold dead entries (F = 0) where links went or clusters drew
 * again; once they are an eighth of a pool (with all, once there are
 * any), it is compacted in place (in link order for the node pool, start
 * order for the cluster pool: the order the live entries already have,
 * so when it happens changes no sum) and its storage trimmed.  Compacting
 * costs a pass over the pool (0.6% of the bunny scene's solve at an
 * eighth); at a quarter the bunny scene peaked 1.4 MB higher. */
#define POOL_DEAD_SHARE 8

/* The node pool, its links links[0..nl) (those not evaluated yet, count
 * HIER_CL_NONE, have no entries). */
static void compact_node_pool(hier_state *s, hier_clink *links, size_t nl, int all)
{
    if (all ? s->ncl_ndead > 0 : POOL_DEAD_SHARE * s->ncl_ndead > s->ncl_nent) {
        size_t at = 0;
        for (size_t k = 0; k < nl; k++) {
            hier_clink *l = &links[k];
            if (!is_node(l->recv) || l->count == HIER_CL_NONE)
                continue;
            uint32_t f = l->first, c = l->count, n = 0;
            for (uint32_t j = 0; j < c; j++)
                if (s->cl_nent[f + j].F != 0)
                    s->cl_nent[at + n++] = s->cl_nent[f + j];
            l->first = (uint32_t)at;
            l->count = (uint16_t)n;
            at += n;
        }
        s->ncl_nent = at;
        s->ncl_ndead = 0;
        pool_trim((void **)&s->cl_nent, sizeof *s->cl_nent, s->ncl_nent, &s->cap_cl_nent, NULL, NULL);
    }
}

static void compact_cluster_pool(hier_state *s, int all)
{
    if (all ? s->ncl_cdead > 0 : POOL_DEAD_SHARE * s->ncl_cdead > s->ncl_cent) {
        /* Clusters' ranges are not in pool order once some drew again:
         * order them by their start (sorting the clusters, not marking
         * the pool: a pool-sized array was 3.3 MB of the bunny scene's
         * peak), then move down. */
        size_t at = 0;
        uint64_t *ord = malloc((s->ncl ? s->ncl : 1) * sizeof *ord);
        if (!ord)
            return; /* compacted another time */
        size_t no = 0;
        for (size_t c = 0; c < s->ncl; c++)
            if (s->cl_ecount[c])
                ord[no++] = (uint64_t)s->cl_efirst[c] << 32 | c;
        qsort(ord, no, sizeof *ord, u64_cmp);
        for (size_t i = 0; i < no; i++) {
            uint32_t c = (uint32_t)ord[i];
            uint32_t f = s->cl_efirst[c], n = s->cl_ecount[c], m = 0;
            for (uint32_t j = 0; j < n; j++)
                if (s->cl_cent[f + j].F != 0) {
                    s->cl_cvia[at + m] = s->cl_cvia[f + j];
                    s->cl_cent[at + m++] = s->cl_cent[f + j];
                }
            s->cl_efirst[c] = (uint32_t)at;
            s->cl_ecount[c] = m;
            at += m;
        }
        free(ord);
        s->ncl_cent = at;
        s->ncl_cdead = 0;
        pool_trim((void **)&s->cl_cent, sizeof *s->cl_cent, s->ncl_cent, &s->cap_cl_cent, &s->cl_cvia, &s->cap_cl_cvia);
    }
}

static void compact_pools(hier_state *s, hier_clink *links, size_t nl, int all)
{
    compact_node_pool(s, links, nl, all);
    compact_cluster_pool(s, all);
}

/* Scratch is bounded: new work is done in chunks of about this many
 * receiving elements (links received by nodes, or faces).  2048 faces
 * draw about 34k samples (0.5 MB); 32768 took 8.8 MB, the bunny scene's
 * peak 121 MiB against 109 MiB, and 8192 2.2 MB, in no less time. */
#define EVAL_CHUNK 2048

/* Evaluates the links refinement kept: the new ones get their unoccluded
 * estimate, those received by nodes their entries, and the faces of every
 * cluster that gained links draw entries for the new links (the old
 * links' entries stay); a cluster loses the entries of the links it lost.
 * New entries are computed in parallel a chunk at a time and appended to
 * the pools, each cluster's old entries moved next to its new ones. */
static rp_status evaluate(hier_state *s, hier_clink *links, size_t nl, unsigned char *dirty, const uint64_t *rm,
                          size_t nrm, rp_error *err)
{
    rp_status st = RP_OK;
    const unsigned N = s->cluster_rays;
    cl_draw *tmp = NULL;
    size_t captmp = 0;
    uint32_t *cnt = NULL, *lstart = NULL, *tasks = NULL, *fill = NULL, *idx = NULL;
    size_t capcnt = 0, captask = 0, capidx = 0;
    size_t *toff = NULL;
    size_t captoff = 0;
    hier_clink *byc = NULL;
    double *pdf = NULL, *cdf = NULL;
    uint32_t *order = NULL;
    size_t capbyc = 0, cappdf = 0, capcdf = 0;
    uint32_t *nnew = NULL, *ktask = NULL; /* new links per cluster; samples per task */
    size_t capk = 0;
    double rays = 0;
    /* New links received by clusters: their unoccluded estimates. */
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256) if (nl > 1024)
    for (long k = 0; k < (long)nl; k++)
        if (!is_node(links[k].recv) && links[k].Fu < 0)
            links[k].Fu = (float)link_unoccluded(s, links[k].recv, links[k].src);
    /* The entries of the links that went die first. */
    compact_node_pool(s, links, nl, 0);
    /* New links received by nodes: entries, a chunk at a time. */
    for (size_t k0 = 0; k0 < nl;) {
        size_t nnew = 0, k1 = k0;
        for (; k1 < nl && nnew < EVAL_CHUNK; k1++)
            if (links[k1].count == HIER_CL_NONE && is_node(links[k1].recv)) {
                if (!hier_grow((void **)&idx, &capidx, nnew + 1, sizeof *idx))
                    goto nomem;
                idx[nnew++] = (uint32_t)k1;
            }
        if (nnew == 0)
            break;
        if (!hier_grow((void **)&tmp, &captmp, nnew * N + 1, sizeof *tmp) ||
            !hier_grow((void **)&cnt, &capcnt, nnew + 1, sizeof *cnt))
            goto nomem;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 16) reduction(+ : rays) if (nnew > 64)
        for (long i = 0; i < (long)nnew; i++) {
            const hier_clink *l = &links[idx[i]];
            cnt[i] = node_entries(s, l->recv, l->src, tmp + (size_t)i * N, &rays);
        }
        s->form_factors += (double)nnew;
        for (size_t i = 0; i < nnew; i++) {
            hier_clink *l = &links[idx[i]];
            l->first = (uint32_t)s->ncl_nent;
            l->count = (uint16_t)cnt[i];
            if (s->ncl_nent + cnt[i] > UINT32_MAX ||
                !hier_grow((void **)&s->cl_nent, &s->cap_cl_nent, s->ncl_nent + cnt[i] + 1, sizeof *s->cl_nent))
                goto nomem;
            for (uint32_t j = 0; j < cnt[i]; j++) {
                s->cl_nent[s->ncl_nent + j].src = tmp[i * N + j].e.src;
                s->cl_nent[s->ncl_nent + j].F = tmp[i * N + j].e.F;
            }
            s->ncl_nent += cnt[i];
        }
        k0 = k1;
    }
    for (size_t k = 0; k < nl; k++)
        if (links[k].count == HIER_CL_NONE) { /* received by a cluster */
            dirty[links[k].recv & ~HIER_CL_BIT] |= 2;
            links[k].count = 1; /* new in this pass (0 again at the end) */
        }
    /* Clusters that only lost links lose their entries. */
    size_t ngain = 0;
    for (size_t c = 0; c < s->ncl; c++) {
        if (dirty[c] & 1)
            prune_entries(s, c, rm, nrm);
        ngain += (dirty[c] & 2) != 0;
    }
    if (ngain == 0)
        goto done;
    /* Links by receiving cluster (CSR, in link order): their indices; a
     * chunk's clusters get a copy of their links with the links' pdf and
     * cdf (32 bytes a link: for every link at once, 12 MB of the bunny
     * scene's peak). */
    lstart = calloc(s->ncl + 1, sizeof *lstart);
    fill = malloc((s->ncl ? s->ncl : 1) * sizeof *fill);
    nnew = calloc(s->ncl ? s->ncl : 1, sizeof *nnew);
    if (!lstart || !fill || !nnew)
        goto nomem;
    size_t ncl_links = 0;
    for (size_t k = 0; k < nl; k++)
        if (!is_node(links[k].recv)) {
            lstart[(links[k].recv & ~HIER_CL_BIT) + 1]++;
            ncl_links++;
        }
    for (size_t c = 0; c < s->ncl; c++)
        lstart[c + 1] += lstart[c];
    order = malloc((ncl_links ? ncl_links : 1) * sizeof *order);
    if (!order)
        goto nomem;
    memcpy(fill, lstart, s->ncl * sizeof *fill);
    for (size_t k = 0; k < nl; k++)
        if (!is_node(links[k].recv))
            order[fill[links[k].recv & ~HIER_CL_BIT]++] = (uint32_t)k;
    /* from here fill[c] is where cluster c's links start in byc */
    for (size_t c0 = 0; c0 < s->ncl;) {
        /* Clusters [c0, c1) and the tasks (cluster, face) of those that
         * gained links, each task with a slot of face_samples entries; the
         * links of those clusters are byc[fill[c] ...], one after another. */
        size_t c1 = c0, ntask = 0, slots = 0, a = 0;
        while (c1 < s->ncl && ntask < EVAL_CHUNK) {
            size_t c = c1++;
            unsigned n = lstart[c + 1] - lstart[c];
            if (!(dirty[c] & 2))
                continue;
            if (n == 0)
                continue;
            if (!hier_grow((void **)&byc, &capbyc, a + n, sizeof *byc) ||
                !hier_grow((void **)&pdf, &cappdf, a + n, sizeof *pdf) ||
                !hier_grow((void **)&cdf, &capcdf, a + n, sizeof *cdf))
                goto nomem;
            fill[c] = (uint32_t)a;
            for (unsigned i = 0; i < n; i++)
                byc[a + i] = links[order[lstart[c] + i]];
            /* Only the new links draw: their share of the samples a full
             * draw would give them, over their own mixture. */
            link_pdf(s, byc + a, n, pdf + a, cdf + a);
            double share = 0;
            unsigned m = 0;
            for (unsigned i = 0; i < n; i++)
                if (byc[a + i].count == 1) {
                    share += pdf[a + i];
                    byc[a + m++] = byc[a + i];
                }
            nnew[c] = m;
            share = hier_min(1.0, share);
            if (m == 0)
                continue;
            link_pdf(s, byc + a, m, pdf + a, cdf + a);
            a += m;
            const hier_cluster *k = &s->cl[c];
            if (!hier_grow((void **)&tasks, &captask, 2 * (ntask + k->count), sizeof *tasks) ||
                !hier_grow((void **)&toff, &captoff, ntask + k->count + 1, sizeof *toff))
                goto nomem;
            for (uint32_t i = k->first; i < k->first + k->count; i++) {
                tasks[2 * ntask] = (uint32_t)c;
                tasks[2 * ntask + 1] = s->cl_faces[i];
                toff[ntask] = slots;
                unsigned K = face_samples(s, k, s->cl_faces[i], n);
                if (m < n)
                    K = (unsigned)hier_max(1.0, ceil(K * share));
                if (!hier_grow((void **)&ktask, &capk, ntask + 1, sizeof *ktask))
                    goto nomem;
                ktask[ntask] = K;
                slots += K;
                ntask++;
            }
        }
        if (!hier_grow((void **)&tmp, &captmp, slots + 1, sizeof *tmp) ||
            !hier_grow((void **)&cnt, &capcnt, ntask + 1, sizeof *cnt))
            goto nomem;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256) reduction(+ : rays) if (ntask > 256)
        for (long t = 0; t < (long)ntask; t++) {
            uint32_t c = tasks[2 * t], f = tasks[2 * t + 1];
            uint32_t a = fill[c], n = lstart[c + 1] - lstart[c];
            cnt[t] = face_entries(s, c, f, byc + a, pdf + a, cdf + a, nnew[c], ktask[t], n - nnew[c], tmp + toff[t],
                                  &rays);
        }
        s->form_factors += (double)ntask;
        size_t t = 0;
        for (size_t c = c0; c < c1; c++) {
            if (!(dirty[c] & 2) || nnew[c] == 0)
                continue;
            /* The old links' entries stay (moved next to the new ones). */
            const size_t of = s->cl_efirst[c], on = s->cl_ecount[c];
            const size_t first = s->ncl_cent;
            for (size_t j = of; j < of + on; j++) {
                if (s->cl_cent[j].F == 0)
                    continue;
                cl_draw d = {.e = s->cl_cent[j], .via = s->cl_cvia[j]};
                if (!pool_append(&s->cl_cent, &s->ncl_cent, &s->cap_cl_cent, &s->cl_cvia, &s->cap_cl_cvia, &d, 1))
                    goto nomem;
                s->cl_cent[j].F = 0;
                s->ncl_cdead++;
            }
            s->cl_efirst[c] = (uint32_t)first;
            for (; t < ntask && tasks[2 * t] == c; t++)
                if (!pool_append(&s->cl_cent, &s->ncl_cent, &s->cap_cl_cent, &s->cl_cvia, &s->cap_cl_cvia,
                                 tmp + toff[t], cnt[t]))
                    goto nomem;
            s->cl_ecount[c] = (uint32_t)(s->ncl_cent - s->cl_efirst[c]);
        }
        /* The draws replace entries that die: compacting as they go keeps
         * the pool near its live size (compacted at the end of the pass
         * alone, it held the old draws and the new ones together). */
        compact_cluster_pool(s, 0);
        c0 = c1;
    }
    goto done;
nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for cluster-link entries");
done:
    for (size_t k = 0; k < nl; k++)
        if (!is_node(links[k].recv) && links[k].count == 1)
            links[k].count = 0;
    if (st == RP_OK)
        compact_pools(s, links, nl, 0);
    s->rays += rays;
    free(tmp);
    free(cnt);
    free(idx);
    free(lstart);
    free(fill);
    free(tasks);
    free(toff);
    free(byc);
    free(pdf);
    free(cdf);
    free(order);
    free(nnew);
    free(ktask);
    return st;
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
    uint32_t *flinks_r = NULL; /* the face-level links' receivers */
    size_t capflr = 0;
    unsigned char *act = NULL, *code = NULL, *dirty = NULL;
    uint32_t *pairs = NULL;
    uint64_t *rm = NULL; /* (cluster << 32 | source) of stored links that go */
    size_t nrm = 0, caprm = 0;
    size_t capw = 0, capk = 0, capc = 0, capfl = 0, capfc = 0, capa = 0, capcode = 0, capp = 0;
    size_t nw = 0, nk = 0, nfl = 0;
    dirty = calloc(s->ncl ? s->ncl : 1, 1);
    if (!dirty)
        goto nomem;
    int first = s->nclinks == 0 && !s->linked;
    if (first) {
        if (!hier_grow((void **)&work, &capw, 1, sizeof *work))
            goto nomem;
        work[0].recv = work[0].src = HIER_CL_BIT; /* the root cluster */
        work[0].Fu = -1;
        work[0].count = HIER_CL_NONE;
        work[0].Fb = 0;
        nw = 1;
    } else {
        /* The stored links are judged again, with the current radiosities
         * (their form-factor bound is kept in them, cl_decide). */
        work = s->clinks;
        capw = s->cap_clinks;
        nw = s->nclinks;
        s->clinks = NULL;
        s->cap_clinks = 0;
        s->nclinks = 0;
    }
    int changed = first;
    /* The first round judges the stored links: those it keeps are
     * compacted in place (kept takes their array), so the list is not
     * held twice. */
    int in_place = !first;
    while (nw) {
        if (!hier_grow((void **)&act, &capa, nw, 1))
            goto nomem;
#pragma omp parallel for num_threads(s->threads) schedule(static) if (nw > 8192)
        for (long k = 0; k < (long)nw; k++)
            act[k] = (unsigned char)cl_decide(s, &work[k]);
        const hier_clink *round = work;
        if (in_place) {
            kept = work;
            capk = capw;
            work = NULL;
            capw = 0;
            in_place = 0;
        }
        /* Children pairs, in link order; quadtree nodes are split here,
         * serially, so node numbers do not depend on threads. */
        size_t np = 0;
        for (size_t k = 0; k < nw; k++) {
            const hier_clink l = round[k];
            if (act[k] == 0) {
                /* In the in-place round nk <= k < capk: this never moves
                 * kept, which round still points into. */
                if (!hier_grow((void **)&kept, &capk, nk + 1, sizeof *kept))
                    goto nomem;
                kept[nk++] = l;
                continue;
            }
            changed = 1;
            if (l.count != HIER_CL_NONE) {
                /* A stored link goes: its receiver's entries go with it. */
                if (is_node(l.recv))
                    s->ncl_ndead += kill_entries(s->cl_nent + l.first, sizeof(hier_nentry), offsetof(hier_nentry, F), l.count);
                else {
                    dirty[l.recv & ~HIER_CL_BIT] |= 1;
                    if (!hier_grow((void **)&rm, &caprm, nrm + 1, sizeof *rm))
                        goto nomem;
                    rm[nrm++] = ((uint64_t)(l.recv & ~HIER_CL_BIT) << 32) | l.src;
                }
            }
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
        /* New pairs, in parallel into their slots: code 0 none, 1 face
         * link, 2 face link with every ray blocked, 3 cluster link (judged
         * in the next round, evaluated only if it is kept). */
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
            double Fb = 0;
            cand[t].recv = r;
            cand[t].src = src;
            cand[t].Fu = -1;
            cand[t].count = HIER_CL_NONE;
            int j = judge(s, r, src, &Fb);
            cand[t].Fb = j == 1 ? hier_bound_pack(Fb) : 0;
            code[t] = j < 0 ? 0 : 3;
        }
        s->rays += rays;
        size_t nn = 0;
        for (size_t t = 0; t < np; t++) {
            if (code[t] == 0) {
                if (!(is_node(pairs[2 * t]) && is_node(pairs[2 * t + 1])))
                    s->clinks_culled++;
                continue;
            }
            if (code[t] == 3) {
                cand[nn++] = cand[t];
                continue;
            }
            s->form_factors++;
            if (!hier_grow((void **)&flinks, &capfl, nfl + 1, sizeof *flinks) ||
                !hier_grow((void **)&flinks_r, &capflr, nfl + 1, sizeof *flinks_r))
                goto nomem;
            flinks_r[nfl] = pairs[2 * t];
            flinks[nfl++] = fcand[t];
        }
        hier_clink *t = work;
        size_t tc = capw;
        work = cand;
        capw = capc;
        cand = t;
        capc = tc;
        nw = nn;
    }
    if (nrm)
        qsort(rm, nrm, sizeof *rm, u64_cmp);
    if (changed && (st = evaluate(s, kept, nk, dirty, rm, nrm, err)) != RP_OK)
        goto done;
    s->clinks = kept;
    s->cap_clinks = capk;
    s->nclinks = nk;
    kept = NULL;
    if (!changed) {
        /* An idle pass (the usual one near convergence): the dead entries
         * go (compacting keeps the live ones' order, so gathering sums in
         * the same order), and the links' and the entry pools' room
         * beyond what they hold is given back (growth by half leaves up
         * to a third empty: 16 MiB of the bunny scene's 90). */
        compact_pools(s, s->clinks, s->nclinks, 1);
        trim_to((void **)&s->clinks, &s->cap_clinks, nk ? nk : 1, sizeof *s->clinks);
        trim_to((void **)&s->cl_nent, &s->cap_cl_nent, s->ncl_nent + 1, sizeof *s->cl_nent);
        trim_to((void **)&s->cl_cent, &s->cap_cl_cent, s->ncl_cent + 1, sizeof *s->cl_cent);
        trim_to((void **)&s->cl_cvia, &s->cap_cl_cvia, s->ncl_cent + 1, sizeof *s->cl_cvia);
    }
    /* Also with nfl 0: the nodes this pass split for cluster links need
     * their (empty) runs of face-level links (hier_link.c). */
    if ((st = hier_links_add(s, flinks, flinks_r, nfl, err)) != RP_OK)
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
    free(flinks_r);
    free(fcand);
    free(act);
    free(code);
    free(pairs);
    free(dirty);
    free(rm);
    return st;
}

/* ---- gathering ---- */

/* out[recv] += rho F X[src] over every entry of the cluster links, rho the
 * receiver's reflectance (radiosity) or, for the adjoint, the source's
 * (importance: y_q += F rho_p y_p, hier_importance.c). */
static void gather_entries(const hier_state *s, const double *X, int rho_of_src, double *out)
{
    if (!s->clustering)
        return;
    const size_t nb = s->nb;
    /* Node-received links in their order, which is the order of their
     * entries in cl_nent (compact_pools, evaluate), then the clusters'. */
    for (size_t k = 0; k < s->nclinks; k++) {
        const hier_clink *l = &s->clinks[k];
        if (!is_node(l->recv))
            continue;
        double *g = out + (size_t)l->recv * nb;
        for (uint32_t j = 0; j < l->count; j++) {
            const hier_nentry *e = &s->cl_nent[l->first + j];
            if (e->F == 0)
                continue;
            const double *Xs = X + (size_t)e->src * nb;
            const double *rho = s->faces[s->nodes[rho_of_src ? e->src : l->recv].face].rho;
            for (size_t b = 0; b < nb; b++)
                g[b] += rho[b] * e->F * Xs[b];
        }
    }
    for (size_t k = 0; k < s->ncl_cent; k++) {
        const hier_centry *e = &s->cl_cent[k];
        if (e->F == 0)
            continue;
        const double *Xs = X + (size_t)e->src * nb;
        const double *rho = s->faces[s->nodes[rho_of_src ? e->src : e->recv].face].rho;
        double *g = out + (size_t)e->recv * nb;
        for (size_t b = 0; b < nb; b++)
            g[b] += rho[b] * e->F * Xs[b];
    }
}

void hier_cluster_gather_nodes(hier_state *s, double *Bg) { gather_entries(s, s->B, 0, Bg); }

void hier_cluster_gather_importance(hier_state *s, double *Yg) { gather_entries(s, s->Y, 1, Yg); }
