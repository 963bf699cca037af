/* Hierarchical radiosity: links, their form-factor estimates and their
 * refinement (Hanrahan, Salzman & Aupperle 1991, sec. 4 and 5).
 *
 * A link is one-way: receiver q gathers rho_q F_qp B_p from source p.  Its
 * form factor is Lambert's contour integral over p at q's centroid (the
 * disk approximation F = A cos cos / (pi r^2 + A) when p is far away), or
 * for near pairs the midpoint rule over q's four quarters, times the
 * visibility of a few jittered ray pairs between q and p (Embree,
 * rp_ray_occluded), each pair weighted by its kernel: two independent
 * sets, one deciding the link's refinement and one measuring the
 * visibility it keeps (link_rays_cast), so that shadows are unbiased.  The
 * second set waits until the oracle has judged a new link: one split in
 * the round that made it never casts it (its children replace it; 6 to
 * 12% of the rays on the scenes measured, answers bit for bit the same,
 * since each set is keyed by the seed and the two nodes).  Shaft culling
 * (Haines & Wallace 1994) skips the rays when no face can lie between the
 * two: for every pair of faces the faces that might block a segment
 * between them are listed once (a face can only if its box meets the
 * pair's box, it reaches in front of both planes, and its own plane
 * separates corners of the pair: the walls of a convex room never block),
 * and a link tests only those, with the same plane tests on its two
 * elements and the box test against their shaft, the convex hull of their
 * two boxes (since stop 44; the union box before: 10.6% fewer rays on
 * the bunny scene, 6.4% on the Cornell box, with the Cornell box's answers
 * bit for bit the same and the bunny scene's within 1e-8: two links
 * between opposite walls had one ray of 16 blocked, though neither the
 * lamp nor the bunny's box meets their shaft, and are now fully visible;
 * the hit was not traced further).
 *
 * BF refinement (sec. 5): a link whose error estimate
 *     rho_q * B_p * F_err   (the worst band)
 * exceeds bf_epsilon is replaced by four links to the children of the
 * larger of its two elements, as long as their area stays above min_area.
 * F_err is the largest point estimate over q for a fully visible link;
 * partial_weight times that for a partially visible link or one whose
 * elements cross each other's planes, so shadow boundaries and contacts
 * are refined first; and for a fully visible link from a pure emitter
 * (uniform, with the contour integral exact over it) the kernel's
 * variation across q, with only q split.  A link whose rays were all
 * blocked is refined with invisible_weight times its unoccluded form
 * factor (16 blocked rays between large elements can miss a penumbra, but
 * only a small part of one) and dropped once the oracle lets it be.
 * A link the test keeps still splits its source where the source's
 * radiosity varies under a kernel that varies across it (source_varies,
 * --variation-weight): B x F misses that where the source is dim.
 * When a receiver is split its near links go down with it, re-evaluated
 * at the children: a near source's kernel varies across the receiver, and
 * an estimate at the parent's centre pushed down unchanged would give the
 * children next to the source too little and the others too much.
 *
 * Refinement runs breadth first: the decisions and the new links' form
 * factors are computed in parallel, and nodes are created serially in a
 * fixed order in between (the order of the links split), so node numbers,
 * link order and every random number (keyed by the seed and the two node
 * numbers) are the same for any thread count.  Only new links are judged
 * again within a pass, and a pass that splits nothing leaves the stored
 * links untouched (each step runs one pass, most of them idle near
 * convergence). */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "ff_internal.h"
#include "hier_internal.h"

/* Mixed into the seed for a link's second set of visibility rays. */
#define HIER_VALUE_KEY UINT64_C(0x6a09e667f3bcc909)

/* ---- shaft culling ---- */

static int box_overlap(rp_vec3 alo, rp_vec3 ahi, rp_vec3 blo, rp_vec3 bhi, double eps)
{
    return alo.x <= bhi.x + eps && blo.x <= ahi.x + eps && alo.y <= bhi.y + eps &&
           blo.y <= ahi.y + eps && alo.z <= bhi.z + eps && blo.z <= ahi.z + eps;
}

static rp_vec3 vmin(rp_vec3 a, rp_vec3 b) { return rp_v3(hier_min(a.x, b.x), hier_min(a.y, b.y), hier_min(a.z, b.z)); }
static rp_vec3 vmax(rp_vec3 a, rp_vec3 b) { return rp_v3(hier_max(a.x, b.x), hier_max(a.y, b.y), hier_max(a.z, b.z)); }

/* 1 if some corner of node nd lies strictly on side `side` (+1 front, -1
 * behind) of face f's plane (beyond the two faces' tolerances). */
static int face_side(const hier_state *s, const hier_node *nd, uint32_t f, int side)
{
    const hier_face *hf = &s->faces[f];
    const double tol = hf->tol + s->faces[nd->face].tol;
    for (int i = 0; i < nd->nverts; i++)
        if (side * (rp_v3_dot(hf->n, nd->v[i]) - hf->d) > tol)
            return 1;
    return 0;
}

/* 1 if some corner of box [lo, hi] lies strictly in front of face f's
 * plane (beyond its tolerance and tol). */
static int box_in_front(const hier_state *s, rp_vec3 lo, rp_vec3 hi, uint32_t f, double tol)
{
    const hier_face *hf = &s->faces[f];
    rp_vec3 c = rp_v3(hf->n.x > 0 ? hi.x : lo.x, hf->n.y > 0 ? hi.y : lo.y, hf->n.z > 0 ? hi.z : lo.z);
    return rp_v3_dot(hf->n, c) - hf->d > hf->tol + tol;
}

/* The occluder units.  Up to HIER_CULL_MAX_FACES faces each face is its
 * own unit.  Above, a face of a surface of at most HIER_CULL_GROUP_FACES
 * faces is its own unit and a larger surface (a mesh) one unit, its box.
 * Links between two one-face units test the listed units; a link with an
 * end on a mesh casts its rays (the mesh may block itself).  So a room
 * with a scanned mesh in it keeps its walls' culling: a link between two
 * walls casts rays only when its shaft meets the mesh's box or a face that
 * may block it (before, culling was off above 512 faces: the bunny scene
 * cast 29.2M rays, now 20.4M with the same answers).  Grouping a mesh of
 * fewer faces would only coarsen its faces' own plane tests (CGAL's blade,
 * 246 faces in the room: 57M rays instead of 68M as faces).  s->cull is
 * 0 when there are more units than HIER_CULL_MAX_FACES. */
static rp_status cull_units(hier_state *s, rp_error *err)
{
    const size_t n = s->nfaces;
    uint32_t nsurf = 0;
    for (size_t f = 0; f < n; f++)
        nsurf = s->faces[f].surface + 1 > nsurf ? s->faces[f].surface + 1 : nsurf;
    uint32_t *count = calloc(nsurf ? nsurf : 1, sizeof *count), *unit = malloc((nsurf ? nsurf : 1) * sizeof *unit);
    rp_status st = RP_OK;
    if (!count || !unit)
        goto nomem;
    for (size_t f = 0; f < n; f++)
        count[s->faces[f].surface]++;
    const uint32_t group = n <= HIER_CULL_MAX_FACES ? UINT32_MAX : HIER_CULL_GROUP_FACES;
    size_t nu = 0;
    for (uint32_t k = 0; k < nsurf; k++)
        nu += count[k] > group ? 1 : count[k];
    s->cull = nu <= HIER_CULL_MAX_FACES;
    if (!s->cull)
        goto done;
    s->face_unit = malloc((n ? n : 1) * sizeof *s->face_unit);
    s->unit_face = malloc((nu ? nu : 1) * sizeof *s->unit_face);
    s->unit_lo = malloc((nu ? nu : 1) * sizeof *s->unit_lo);
    s->unit_hi = malloc((nu ? nu : 1) * sizeof *s->unit_hi);
    if (!s->face_unit || !s->unit_face || !s->unit_lo || !s->unit_hi)
        goto nomem;
    /* Units in face order: a mesh's at its first face. */
    for (uint32_t k = 0; k < nsurf; k++)
        unit[k] = RP_NONE;
    s->nunits = 0;
    for (size_t f = 0; f < n; f++) {
        uint32_t k = s->faces[f].surface, u;
        if (count[k] <= group || unit[k] == RP_NONE) {
            u = (uint32_t)s->nunits++;
            s->unit_face[u] = count[k] <= group ? (uint32_t)f : RP_NONE;
            s->unit_lo[u] = s->faces[f].lo;
            s->unit_hi[u] = s->faces[f].hi;
            if (count[k] > group)
                unit[k] = u;
        } else {
            u = unit[k];
            s->unit_lo[u] = vmin(s->unit_lo[u], s->faces[f].lo);
            s->unit_hi[u] = vmax(s->unit_hi[u], s->faces[f].hi);
        }
        s->face_unit[f] = u;
    }
    goto done;
nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
done:
    free(count);
    free(unit);
    return st;
}

rp_status hier_cull_init(hier_state *s, rp_error *err)
{
    rp_status st = cull_units(s, err);
    if (st != RP_OK || !s->cull)
        return st; /* without culling every link casts its rays */
    const size_t n = s->nunits;
    s->pair_off = calloc(n * n, sizeof *s->pair_off);
    s->pair_cnt = calloc(n * n, sizeof *s->pair_cnt);
    size_t cap = 1024;
    s->cand = malloc(cap * sizeof *s->cand);
    if (!s->pair_off || !s->pair_cnt || !s->cand)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
    /* Between one-face units: front[k n + f]: unit k has a corner strictly
     * in front of face f's plane; behind[k n + f]: strictly behind it. */
    unsigned char *front = calloc(n * n, 1), *behind = calloc(n * n, 1);
    if (!front || !behind) {
        free(front);
        free(behind);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
    }
    for (size_t k = 0; k < n; k++)
        for (size_t f = 0; f < n; f++) {
            uint32_t fk = s->unit_face[k], ff = s->unit_face[f];
            if (ff == RP_NONE)
                continue;
            if (fk != RP_NONE) {
                front[k * n + f] = (unsigned char)face_side(s, &s->nodes[fk], ff, 1);
                behind[k * n + f] = (unsigned char)face_side(s, &s->nodes[fk], ff, -1);
            } else
                front[k * n + f] = (unsigned char)box_in_front(s, s->unit_lo[k], s->unit_hi[k], ff,
                                                               hier_box_tol(s->unit_lo[k], s->unit_hi[k]));
        }
    s->ncand = 0;
    for (size_t i = 0; i < n; i++)
        for (size_t j = i + 1; j < n; j++) {
            uint32_t fi = s->unit_face[i], fj = s->unit_face[j];
            if (fi == RP_NONE || fj == RP_NONE)
                continue; /* a link with an end on a mesh casts its rays */
            rp_vec3 lo = vmin(s->faces[fi].lo, s->faces[fj].lo), hi = vmax(s->faces[fi].hi, s->faces[fj].hi);
            size_t off = s->ncand;
            for (size_t k = 0; k < n; k++) {
                uint32_t fk = s->unit_face[k];
                if (k == i || k == j || !front[k * n + i] || !front[k * n + j])
                    continue;
                if (fk == RP_NONE) {
                    /* A mesh: its box meets the pair's, in front of both. */
                    if (!box_overlap(s->unit_lo[k], s->unit_hi[k], lo, hi,
                                     hier_box_tol(s->unit_lo[k], s->unit_hi[k]) + s->faces[fi].tol + s->faces[fj].tol))
                        continue;
                } else if (!box_overlap(s->faces[fk].lo, s->faces[fk].hi, lo, hi,
                                        s->faces[fk].tol + s->faces[fi].tol + s->faces[fj].tol) ||
                           !(front[i * n + k] || front[j * n + k]) || !(behind[i * n + k] || behind[j * n + k]))
                    continue;
                if (s->ncand == cap) {
                    cap *= 2;
                    uint32_t *c = realloc(s->cand, cap * sizeof *c);
                    if (!c) {
                        free(front);
                        free(behind);
                        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
                    }
                    s->cand = c;
                }
                s->cand[s->ncand++] = (uint32_t)k;
            }
            s->pair_off[i * n + j] = s->pair_off[j * n + i] = (uint32_t)off;
            s->pair_cnt[i * n + j] = s->pair_cnt[j * n + i] = (uint16_t)(s->ncand - off);
        }
    free(front);
    free(behind);
    return RP_OK;
}

/* Coordinate i (0 x, 1 y, 2 z) of v. */
static double vat(rp_vec3 v, int i) { return i == 0 ? v.x : (i == 1 ? v.y : v.z); }

/* The convex hull of two boxes (Haines & Wallace 1994, "Shaft culling for
 * efficient ray-cast radiosity") is their union box cut by one plane for
 * each edge of it where one box bounds the union on one of the edge's two
 * faces and the other box on the other: the plane holds the two boxes'
 * matching edges (parallel to the third axis), so it cuts that corner of
 * the union box off.  Only those planes are tested here; the callers have
 * tested the union box. */
int hier_outside_hull(const rp_vec3 a[2], const rp_vec3 b[2], const rp_vec3 o[2], double eps)
{
    for (int i = 0; i < 3; i++)
        for (int j = i + 1; j < 3; j++)
            for (int si = 0; si < 2; si++)
                for (int sj = 0; sj < 2; sj++) {
                    const double gi = si ? 1.0 : -1.0, gj = sj ? 1.0 : -1.0;
                    const double ai = vat(a[si], i), bi = vat(b[si], i);
                    const double aj = vat(a[sj], j), bj = vat(b[sj], j);
                    /* a bounds the union on face (i, si) and b on (j, sj), or
                     * the other way round */
                    if (!((gi * ai > gi * bi && gj * bj > gj * aj) || (gi * bi > gi * ai && gj * aj > gj * bj)))
                        continue;
                    /* the line through (ai, aj) and (bi, bj) in the (i, j)
                     * plane, its normal towards the union's corner c */
                    double ni = aj - bj, nj = bi - ai;
                    const double ci = gi > 0 ? hier_max(ai, bi) : hier_min(ai, bi);
                    const double cj = gj > 0 ? hier_max(aj, bj) : hier_min(aj, bj);
                    const double side = ni * (ci - ai) + nj * (cj - aj);
                    if (side == 0)
                        continue;
                    if (side < 0) {
                        ni = -ni;
                        nj = -nj;
                    }
                    /* o's corner least far along n, pulled back by eps */
                    const double m = ni * vat(o[ni > 0 ? 0 : 1], i) + nj * vat(o[nj > 0 ? 0 : 1], j);
                    if (m - eps * (fabs(ni) + fabs(nj)) > ni * ai + nj * aj)
                        return 1;
                }
    return 0;
}

/* 1 if some listed unit may block a segment between nodes q and p: its
 * box meets the convex hull of the two elements' boxes (the shaft), and for
 * a face, its plane separates corners of the two. */
static int shaft_blocked(const hier_state *s, const hier_node *q, const hier_node *p)
{
    if (!s->cull)
        return 1;
    uint32_t uq = s->face_unit[q->face], up = s->face_unit[p->face];
    if (s->unit_face[uq] == RP_NONE || s->unit_face[up] == RP_NONE)
        return 1;
    size_t at = (size_t)uq * s->nunits + up;
    uint32_t cnt = s->pair_cnt[at];
    if (cnt == 0)
        return 0;
    rp_vec3 qb[2], pb[2];
    hier_node_box(q, qb);
    hier_node_box(p, pb);
    const rp_vec3 lo = vmin(qb[0], pb[0]), hi = vmax(qb[1], pb[1]);
    const uint32_t *c = s->cand + s->pair_off[at];
    const double tol = s->faces[q->face].tol + s->faces[p->face].tol;
    for (uint32_t k = 0; k < cnt; k++) {
        uint32_t fk = s->unit_face[c[k]];
        const rp_vec3 ob[2] = {fk == RP_NONE ? s->unit_lo[c[k]] : s->faces[fk].lo,
                               fk == RP_NONE ? s->unit_hi[c[k]] : s->faces[fk].hi};
        const double eps = tol + (fk == RP_NONE ? hier_box_tol(ob[0], ob[1]) : s->faces[fk].tol);
        if (!box_overlap(ob[0], ob[1], lo, hi, eps))
            continue;
        /* A face with both elements on one side of its plane: the segments
         * between them cannot cross it.  (A mesh may block with any box
         * in the shaft.) */
        if (fk != RP_NONE && (!(face_side(s, q, fk, 1) || face_side(s, p, fk, 1)) ||
                              !(face_side(s, q, fk, -1) || face_side(s, p, fk, -1))))
            continue;
        if (hier_outside_hull(qb, pb, ob, eps))
            continue;
        return 1;
    }
    return 0;
}

/* ---- form-factor estimates ---- */

/* hier_point_to_node with p's centroid pc, when the caller has it. */
static double point_to_node(const hier_state *s, rp_vec3 x, rp_vec3 n, const hier_node *p, const rp_vec3 *pc,
                            double far_ratio)
{
    const hier_face *fp = &s->faces[p->face];
    if (rp_v3_dot(fp->n, x) - fp->d <= 0)
        return 0; /* x sees the back of p (which is black and one-sided) */
    if (far_ratio > 0) {
        rp_vec3 d = rp_v3_sub(pc ? *pc : hier_node_c(p), x);
        double r2 = rp_v3_dot(d, d);
        if (r2 > far_ratio * hier_extent2(p)) {
            /* A disk of p's area facing along its normal (Wallace,
             * Elmquist & Haines 1989, eq. 6): F = A cos_q cos_p / (pi r^2
             * + A). */
            double r = sqrt(r2);
            double cq = rp_v3_dot(n, d) / r, cp = -rp_v3_dot(fp->n, d) / r;
            if (cq > 0 && cp > 0)
                return p->area * cq * cp / (RP_PI * r2 + p->area);
        }
    }
    return hier_point_polygon(x, n, p->v, p->nverts);
}

double hier_point_to_node(const hier_state *s, rp_vec3 x, rp_vec3 n, const hier_node *p, double far_ratio)
{
    return point_to_node(s, x, n, p, NULL, far_ratio);
}

/* The visibility rays of a link: m x m jittered strata on q paired with
 * a random permutation of m x m strata on p.  When one crosses the
 * other's plane only the part of each in front of the other can exchange
 * light: the strata are laid on those two clipped polygons, so every pair
 * faces the other way round and the rays measure the visibility of the
 * part that carries the energy.  (Drawn over the whole elements, all
 * pairs of a sliver pair could face away; with no ray cast the link used
 * to be taken as fully visible, which let the room's walls shine into a
 * sealed shell through its inside surface.) */
typedef struct {
    const hier_node *q, *p;
    const hier_face *fq, *fp;
    int straddle, nq, np;
    rp_vec3 qc[8], pc[8];
    double qcum[8], pcum[8];
} link_rays;

/* 0 when no part of either element faces the other. */
static int link_rays_prepare(link_rays *r, const hier_node *q, const hier_node *p, const hier_face *fq,
                             const hier_face *fp, int straddle)
{
    r->q = q;
    r->p = p;
    r->fq = fq;
    r->fp = fp;
    r->straddle = straddle;
    r->nq = r->np = 0;
    if (!straddle)
        return 1;
    r->nq = (int)rp_ff_clip(q->v, q->nverts, fp->n, fp->d, r->qc);
    r->np = (int)rp_ff_clip(p->v, p->nverts, fq->n, fq->d, r->pc);
    return hier_polygon_prepare(r->qc, r->nq, r->qcum) && hier_polygon_prepare(r->pc, r->np, r->pcum);
}

/* Casts one set of rays drawn with key; *open of *valid pairs that can
 * carry light were unblocked.  Returns the visible fraction, each pair
 * weighted by its kernel cos cos / r^2 (where the visible part of p is the
 * nearer one, or the one seen more squarely, a plain fraction of open rays
 * would understate the energy it passes); 0 when no pair can carry light. */
static double link_rays_cast(const hier_state *s, const link_rays *r, unsigned n, uint64_t key, unsigned *open,
                             unsigned *valid, double *rays)
{
    unsigned m = (unsigned)floor(sqrt((double)n) + 0.5), N = m * m;
    uint32_t perm[HIER_MAX_SET_RAYS];
    hier_shuffle(perm, N, key, 4 * (uint64_t)N);
    double wsum = 0, wopen = 0, w[HIER_MAX_SET_RAYS];
    rp_vec3 a[HIER_MAX_SET_RAYS], b[HIER_MAX_SET_RAYS];
    unsigned char blocked[HIER_MAX_SET_RAYS];
    *valid = *open = 0;
    for (unsigned k = 0; k < N; k++) {
        double u1 = ((k % m) + hier_u01(key, 4 * (uint64_t)k)) / m;
        double u2 = ((k / m) + hier_u01(key, 4 * (uint64_t)k + 1)) / m;
        double w1 = ((perm[k] % m) + hier_u01(key, 4 * (uint64_t)k + 2)) / m;
        double w2 = ((perm[k] / m) + hier_u01(key, 4 * (uint64_t)k + 3)) / m;
        rp_vec3 x = r->straddle ? hier_polygon_point(r->qc, r->nq, r->qcum, u1, u2) : hier_node_point(r->q, u1, u2);
        rp_vec3 y = r->straddle ? hier_polygon_point(r->pc, r->np, r->pcum, w1, w2) : hier_node_point(r->p, w1, w2);
        rp_vec3 xy = rp_v3_sub(y, x);
        if (r->straddle && (rp_v3_dot(xy, r->fq->n) <= 0 || rp_v3_dot(xy, r->fp->n) >= 0))
            continue;
        double r2 = rp_v3_dot(xy, xy);
        w[*valid] = hier_max(rp_v3_dot(xy, r->fq->n), 0) * hier_max(-rp_v3_dot(xy, r->fp->n), 0) / (r2 * r2);
        a[*valid] = x;
        b[*valid] = y;
        (*valid)++;
    }
    /* The segments leave one small element for another: one coherent
     * stream. */
    rp_ray_occluded_n(s->rc, *valid, a, r->fq->n, b, r->fp->n, blocked);
    *rays += *valid;
    for (unsigned k = 0; k < *valid; k++) {
        wsum += w[k];
        if (!blocked[k]) {
            (*open)++;
            wopen += w[k];
        }
    }
    return *valid ? (wsum > 0 ? wopen / wsum : (double)*open / *valid) : 0.0;
}

/* --vis-rays times k, at most HIER_MAX_SET_RAYS: the rays of a set for a
 * link from an emitter, which stands for the children a reflector would
 * be split into (decide).  The deciding set casts four times --vis-rays
 * for it: the floor at the foot of the Cornell box's short box, in its
 * shadow, then finds the penumbra's edge as the light's children found
 * it, and the box's front, lit by that floor alone (the test
 * hier/variation_weight_floor_seen_by_a_box_side), reads +0.65% against
 * the path tracer where it read +0.81% with --vis-rays and +0.55% with
 * the light split. */
static unsigned set_rays(const hier_state *s, unsigned k)
{
    return k * s->vis_rays < HIER_MAX_SET_RAYS ? k * s->vis_rays : HIER_MAX_SET_RAYS;
}

/* The visible fraction from the second, independent set of rays of the
 * link q <- p prepared in *set: the value's (see link_eval). */
static double value_rays(const hier_state *s, const link_rays *set, const hier_node *q, const hier_node *p,
                         unsigned flags, double *rays)
{
    /* A far, partly visible emitter is not split (decide): its one link
     * measures with sixteen times the rays what two levels of children
     * would.  (A near one, which is split, gets them too: not measured
     * apart.)  On the Cornell box the short box's front (green, seeds 1-8)
     * varied by 0.45% from seed to seed with the rays of one child, 0.16%
     * with four times them, 0.12% with these and 0.11% when the emitter
     * was split. */
    const unsigned n = (flags & HIER_LINK_PARTIAL) && !s->faces[p->face].reflects ? set_rays(s, 16) : s->vis_rays;
    unsigned open = 0, valid = 0;
    const uint64_t key = hier_key(s->seed ^ HIER_VALUE_KEY, hier_node_id(s, q), hier_node_id(s, p));
    return link_rays_cast(s, set, n, key, &open, &valid, rays);
}

/* Completes a link qi <- its source link_eval left pending, whose unoccluded
 * form factor is F: its form factor becomes F x the value's visible
 * fraction. */
static void link_value(const hier_state *s, uint32_t qi, hier_link *l, double F, double *rays)
{
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[hier_link_src(l)];
    link_rays set;
    link_rays_prepare(&set, q, p, &s->faces[q->face], &s->faces[p->face], (l->flags & HIER_LINK_STRADDLE) != 0);
    hier_link_set_F(l, F * value_rays(s, &set, q, p, l->flags, rays));
    l->flags = (uint8_t)(l->flags & ~HIER_LINK_PENDING);
}

/* Evaluates link q <- p into *out.  Returns 0 if there is no link (the two
 * do not face each other, or no part of q sees p), 1 for a link, 2 for a
 * link every visibility ray of both sets found blocked (dropped once the
 * oracle would not refine it, hier_refine).  With defer, a
 * link that casts rays casts only the deciding set: it is marked
 * HIER_LINK_PENDING, *Fu gets its unoccluded form factor, and link_value
 * completes it once the oracle keeps it (returning 1 for it). */
static int link_eval(const hier_state *s, uint32_t qi, uint32_t pi, hier_link *out, double *Fu, double *rays,
                     int defer)
{
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[pi];
    if (q->face == p->face)
        return 0; /* planar: F_ii = 0 */
    const hier_face *fq = &s->faces[q->face], *fp = &s->faces[p->face];
    if (!fq->reflects)
        return 0; /* a black receiver (a pure emitter) gathers nothing */
    if (!fp->lit)
        return 0; /* a black source (a ground plane) gives nothing: a link
                     from it would only mark its receiver as seen (the
                     pull's weights, hierarchical.c) */
    double pmax = -INFINITY, pmin = INFINITY, qmax = -INFINITY, qmin = INFINITY;
    for (int i = 0; i < p->nverts; i++) {
        double d = rp_v3_dot(fq->n, p->v[i]) - fq->d;
        pmax = hier_max(pmax, d);
        pmin = hier_min(pmin, d);
    }
    for (int i = 0; i < q->nverts; i++) {
        double d = rp_v3_dot(fp->n, q->v[i]) - fp->d;
        qmax = hier_max(qmax, d);
        qmin = hier_min(qmin, d);
    }
    /* Faces facing away: no link. */
    const double tol = fq->tol + fp->tol;
    if (pmax <= tol || qmax <= tol)
        return 0;
    int straddle = pmin < -tol || qmin < -tol;
    double F, Fmax, Fvar = 0;
    const int emitter = !fp->reflects;
    const rp_vec3 qc = hier_node_c(q), pc = hier_node_c(p);
    rp_vec3 dc = rp_v3_sub(pc, qc);
    if (!straddle && rp_v3_dot(dc, dc) > HIER_NEAR_RATIO * hier_extent2(q)) {
        F = Fmax = point_to_node(s, qc, fq->n, p, &pc, HIER_DISK_RATIO);
        if (emitter) {
            /* How much the kernel varies across q, from its four quarters. */
            rp_vec3 cc[4];
            double ca[4];
            hier_child_centroids(q, cc, ca);
            for (int k = 0; k < 4; k++)
                Fvar = hier_max(Fvar, fabs(point_to_node(s, cc[k], fq->n, p, &pc, HIER_DISK_RATIO) - F));
        }
    } else {
        /* Near pairs (the kernel varies across q: point estimates at the
         * centroid put too much energy into pairs that meet at an edge),
         * and pairs where part of one lies behind the other (the centroid
         * alone may see nothing): the midpoint rule over q's four children
         * instead, and the largest of the four as the bound for straddling
         * pairs. */
        rp_vec3 cc[4];
        double ca[4];
        hier_child_centroids(q, cc, ca);
        F = 0;
        Fmax = 0;
        double fk[4], flo = INFINITY;
        for (int k = 0; k < 4; k++) {
            fk[k] = hier_point_to_node(s, cc[k], fq->n, p, 0);
            F += ca[k] / q->area * fk[k];
            Fmax = hier_max(Fmax, fk[k]);
            flo = hier_min(flo, fk[k]);
        }
        Fvar = hier_max(Fmax - F, F - flo);
        if (emitter) {
            /* The four quarters of a receiver centred under a source agree
             * with each other and not with the centre (a floor under its
             * lamp: 0.009 at the quarters, 0.08 at the centre), so the
             * variation also counts the centroid; without it such a link
             * was never refined and kept the midpoint rule's 4 points. */
            double fc = hier_point_to_node(s, qc, fq->n, p, 0);
            Fvar = hier_max(Fvar, fabs(fc - F));
        }
        if (straddle)
            /* All four centres may lie behind p while a corner of q sees
             * it (the floor beside a box): the corners, pulled 1% towards
             * the centroid, join the bound, so such a pair is refined
             * rather than lost. */
            for (int k = 0; k < q->nverts; k++) {
                rp_vec3 x = rp_v3_madd(q->v[k], rp_v3_sub(qc, q->v[k]), 0.01);
                Fmax = hier_max(Fmax, hier_point_to_node(s, x, fq->n, p, 0));
            }
    }
    if ((s->linear || s->ff_gauss) && !straddle)
        /* --basis linear: F is the coupling coefficients' constant entry,
         * integrated by their rule (hier_linear.c).  The estimates above,
         * the kernel at q's centre or the midpoint rule over its quarters,
         * are biased where the kernel curves across q: high by 1.0 to 1.6%
         * on a plate's 4 x 4 leaves a lamp's width below it
         * (hier/linear_basis_reflecting_source), which the linear basis
         * would carry into the slopes; they remain the oracle's.  With
         * --ff-rule gauss the constant basis takes the same rule: an error
         * of order h^4 where the kernel is smooth across q, against h^2
         * for the midpoint rule (unit squares 6 apart: -0.002% against
         * +0.91% at the centre; sharing an edge, where the kernel is not
         * smooth: +0.18% against -1.0% over the quarters;
         * hier/ff_rule_against_closed_forms). */
        F = hier_linear_rule_mean(s, q, p);
    if (!(F > 0) && !(Fmax > 0))
        return 0;
    double vis = 1;
    uint32_t flags = straddle ? HIER_LINK_STRADDLE : 0;
    *Fu = F;
    hier_link_set_src(out, pi);
    if (shaft_blocked(s, q, p)) {
        flags |= HIER_LINK_TESTED;
        link_rays set;
        if (!link_rays_prepare(&set, q, p, fq, fp, straddle)) {
            vis = 0; /* no part of either faces the other */
            flags |= HIER_LINK_INVISIBLE;
        } else {
            /* Two independent sets of rays (Monte Carlo visibility in
             * hierarchical radiosity is biased when one set both decides
             * and measures: a link whose few rays all missed a shadow
             * keeps visibility 1 while one whose rays found it is refined
             * and re-measured, so shadows come out too light on average).
             * The first set decides (partial, invisible: the oracle's
             * flags), the second, drawn with another key, gives the value
             * kept: independent of the decision, it is unbiased whatever
             * the oracle does with the link. */
            unsigned open = 0, valid = 0;
            link_rays_cast(s, &set, fp->reflects ? s->vis_rays : set_rays(s, 4),
                           hier_key(s->seed, hier_node_id(s, q), hier_node_id(s, p)), &open, &valid, rays);
            if (open < valid)
                flags |= HIER_LINK_PARTIAL;
            if (open == 0)
                flags |= HIER_LINK_INVISIBLE;
            if (defer)
                flags |= HIER_LINK_PENDING;
            else
                vis = value_rays(s, &set, q, p, flags, rays);
        }
    }
    hier_link_set_share_bits(out, 0);
    hier_link_set_F(out, flags & HIER_LINK_PENDING ? 0.0 : F * vis);
    double F_err = Fmax;
    if (flags & (HIER_LINK_PARTIAL | HIER_LINK_STRADDLE))
        F_err = s->partial_weight * Fmax;
    else if (emitter)
        /* A pure emitter is uniform and the contour integral exact over it:
         * the estimate's error is the kernel's variation across q. */
        F_err = Fvar;
    if (flags & HIER_LINK_INVISIBLE)
        /* Refined towards a penumbra it may hide, but with the weight
         * --invisible-weight (default 1/4 = 1/sqrt(16)): N stratified rays
         * that were all blocked leave a visible fraction of about
         * 1/sqrt(N) undetected at most, not the whole unoccluded form
         * factor. */
        F_err = s->invisible_weight * Fmax;
    out->F_err = hier_bound_pack(F_err);
    out->flags = (uint8_t)flags;
    return (flags & HIER_LINK_INVISIBLE) && !(vis > 0) && !(flags & HIER_LINK_PENDING) ? 2 : 1;
}

int hier_link_eval(const hier_state *s, uint32_t qi, uint32_t pi, hier_link *out, double *rays)
{
    double Fu;
    return link_eval(s, qi, pi, out, &Fu, rays, 0);
}

/* ---- link storage ---- */

static rp_status reserve_links(hier_link **a, size_t *cap, size_t need, rp_error *err)
{
    if (!hier_grow((void **)a, cap, need, sizeof **a))
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu links", need);
    return RP_OK;
}

/* Room in link_start for nn nodes. */
static rp_status reserve_start(hier_state *s, size_t nn, rp_error *err)
{
    if (s->cap_start < nn + 1) {
        size_t c = s->cap_start ? s->cap_start : 1024;
        while (c < nn + 1)
            c *= 2;
        uint32_t *ls = realloc(s->link_start, c * sizeof *ls);
        if (!ls)
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for link offsets");
        s->link_start = ls;
        s->cap_start = c;
    }
    return RP_OK;
}

/* Room for exactly n links: the list grows by what a pass adds, not by
 * half again (realloc of a block this large moves pages, not bytes). */
static rp_status links_fit(hier_state *s, size_t n, rp_error *err)
{
    if (n <= s->cap_links)
        return RP_OK;
    hier_link *a = realloc(s->links, n * sizeof *a);
    if (!a)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu links", n);
    s->links = a;
    s->cap_links = n;
    return RP_OK;
}

/* The list becomes links[0..m) (sorted by receiver, as the last merge left
 * them; link_start holds their offsets for the first mn nodes, the others
 * have none) and add[0..n) received by recv[0..n) (any order, not in the
 * list's storage), sorted by receiver and stable: each receiver's kept
 * links, then its new ones in the order given.  The new links' order is a
 * counting sort of indices (ord); each receiver's kept links are moved up
 * to their place and its new ones copied after them, from the last
 * receiver down, so the list is never held twice (a second sorted copy of
 * it was 36 MiB of the bunny scene's 135 MiB peak).  Completes
 * link_start. */
static rp_status links_merge(hier_state *s, size_t m, size_t mn, const hier_link *add, const uint32_t *recv, size_t n,
                             rp_error *err)
{
    const size_t nn = s->nnodes;
    rp_status st;
    if (m + n > UINT32_MAX)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: more than 2^32 links");
    if ((st = reserve_start(s, nn, err)) != RP_OK || (st = links_fit(s, m + n ? m + n : 1, err)) != RP_OK)
        return st;
    uint32_t *start = s->link_start;
    hier_link *links = s->links;
    if (mn == 0)
        start[0] = 0;
    for (size_t i = mn + 1; i <= nn; i++)
        start[i] = (uint32_t)m;
    if (n > 0) {
        /* end[r]: counts, then where receiver r's new links start among
         * the new ones, then (once ord is filled through it) where they
         * end, which is where receiver r + 1's start: one array, not a
         * second one to fill through (4 bytes a node, 5 MiB of the
         * Cornell box's peak at 10^6 leaves). */
        uint32_t *ord = malloc(n * sizeof *ord);
        uint32_t *end = calloc(nn + 1, sizeof *end);
        if (!ord || !end) {
            free(ord);
            free(end);
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory sorting %zu links", n);
        }
        for (size_t k = 0; k < n; k++)
            end[recv[k] + 1]++;
        for (size_t i = 0; i < nn; i++)
            end[i + 1] += end[i];
        for (size_t k = 0; k < n; k++)
            ord[end[recv[k]]++] = (uint32_t)k;
        /* From the last receiver down: receiver r's kept links
         * [start[r], start[r + 1]) move up by the new links of the
         * receivers before it (the first end[r - 1]), its own new ones
         * follow them.  Both land at or above where r's kept links were,
         * so nothing not yet moved is overwritten. */
        for (size_t r = nn; r-- > 0;) {
            const size_t first = r ? end[r - 1] : 0;
            const size_t lo = start[r], mc = start[r + 1] - lo, nc = end[r] - first;
            const size_t at = lo + first;
            if (mc && at != lo)
                memmove(links + at, links + lo, mc * sizeof *links);
            for (size_t j = 0; j < nc; j++)
                links[at + mc + j] = add[ord[first + j]];
            start[r + 1] = (uint32_t)(at + mc + nc);
        }
        free(ord);
        free(end);
    }
    n += m;
    s->start_nn = nn;
    s->nlinks = n;
    size_t partial = 0;
    for (size_t k = 0; k < n; k++)
        partial += (links[k].flags & HIER_LINK_PARTIAL) != 0;
    s->links_full = n - partial;
    s->links_partial = partial;
    return RP_OK;
}

/* Makes link_start cover every node (the gather sweep, importance and the
 * image walk it over all of them). */
static rp_status hier_links_cover(hier_state *s, rp_error *err)
{
    const size_t nn = s->nnodes;
    if (s->link_start && s->start_nn == nn)
        return RP_OK;
    if (!s->link_start) /* no merge yet (a clustered scene's first pass, no links) */
        return links_merge(s, s->nlinks, 0, NULL, NULL, 0, err);
    /* Nodes are never removed, so start_nn < nn here.  Nodes made since
     * the last sort (the split end of a cluster link, hier_cluster.c) have
     * no face-level links yet (links change only through links_merge):
     * empty runs at the end of the list.  Until
     * stop 28 their offsets were left unwritten, as realloc gave them or
     * past the end of the array once the nodes outgrew it, and the next
     * sweep read them, when a pass split nodes for cluster links only and
     * added or refined no face-level link (hier/link_offsets_cover_every_node:
     * a ball over a floor at bf-epsilon 0.2, 32 of 650 nodes after the
     * second step). */
    rp_status st = reserve_start(s, nn, err);
    if (st != RP_OK)
        return st;
    for (size_t i = s->start_nn + 1; i <= nn; i++)
        s->link_start[i] = (uint32_t)s->nlinks;
    s->start_nn = nn;
    return RP_OK;
}

rp_status hier_links_add(hier_state *s, const hier_link *add, const uint32_t *recv, size_t n, rp_error *err)
{
    if (n == 0)
        return hier_links_cover(s, err);
    return links_merge(s, s->nlinks, s->link_start ? s->start_nn : 0, add, recv, n, err);
}

rp_status hier_link_initial(hier_state *s, rp_error *err)
{
    const size_t n = s->nfaces;
    /* Rows of R receivers at a time, evaluated in parallel into a buffer
     * and appended in order. */
    const size_t R = 64;
    hier_link *buf = malloc(R * n * sizeof *buf);
    unsigned char *code = malloc(R * n);
    hier_link *links = NULL;
    uint32_t *recv = NULL;
    size_t nl = 0, cap = 0, capr = 0;
    rp_status st = RP_OK;
    if (!buf || !code) {
        st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for the initial links");
        goto done;
    }
    for (size_t i0 = 0; i0 < n; i0 += R) {
        size_t i1 = i0 + R < n ? i0 + R : n;
        double rays = 0;
        if (rp_cancelled(s->cancel) && (st = rp_error_set(err, RP_ERR_INTERRUPTED, "hierarchical: interrupted")))
            goto done;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 1) reduction(+ : rays) collapse(2)
        for (long i = (long)i0; i < (long)i1; i++)
            for (long j = 0; j < (long)n; j++) {
                size_t at = (size_t)(i - (long)i0) * n + (size_t)j;
                code[at] = i == j ? 0 : (unsigned char)hier_link_eval(s, (uint32_t)i, (uint32_t)j, &buf[at], &rays);
            }
        s->rays += rays;
        for (size_t k = 0; k < (i1 - i0) * n; k++) {
            if (code[k] == 0)
                continue;
            s->form_factors++;
            if ((st = reserve_links(&links, &cap, nl + 1, err)) != RP_OK)
                goto done;
            if (!hier_grow((void **)&recv, &capr, nl + 1, sizeof *recv)) {
                st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for the initial links");
                goto done;
            }
            recv[nl] = (uint32_t)(i0 + k / n);
            links[nl++] = buf[k];
        }
    }
    st = links_merge(s, 0, 0, links, recv, nl, err);
done:
    free(buf);
    free(code);
    free(links);
    free(recv);
    return st;
}

/* An invisible link the oracle keeps is dropped (hier_refine): its
 * value's rays were all blocked too. */
static int link_dropped(const hier_link *l) { return (l->flags & HIER_LINK_INVISIBLE) && !(hier_link_F(l) > 0); }

/* Whether receiver q is near enough to source p that the kernel varies
 * across p: within sqrt(HIER_NEAR_RATIO) of p's extent (the test
 * near_pair makes for the receiver, from the source's side). */
static int kernel_varies_across_source(const hier_node *q, const hier_node *p)
{
    rp_vec3 d = rp_v3_sub(hier_node_c(p), hier_node_c(q));
    return rp_v3_dot(d, d) <= HIER_NEAR_RATIO * hier_extent2(p);
}

/* 1 if link q <- p, which the BF test keeps, should split its source p
 * for the variation of p's radiosity under a kernel that varies across
 * p.  A link carries F x (p's mean), or with shares its children's
 * means; what q gathers is the integral of the kernel times B over p,
 * and the two differ by the covariance of the two across p.  Where q is
 * near p (within sqrt(HIER_NEAR_RATIO) of p's extents, as near_pair
 * judges the kernel across q) the kernel varies across p by a factor of
 * order one, and how far p's radiosity varies is judged by how far it
 * differs from its siblings'.  So p is split while
 *     rho_q x max_sibling |B_sibling - B_p| x F_err x scale x W
 * exceeds bf_epsilon (W = --variation-weight).  BF refinement misses
 * this where p is dim: the floor at the foot of a box, in the box's
 * shadow and half enclosed by it, is what the box side sees best, and an
 * element reaching from there into the light beyond gave the side its
 * brighter mean (the Cornell box's short front +1.19%, +0.81% with
 * this).  For the constant basis without importance (a linear element
 * carries its own gradient). */
static int source_varies(const hier_state *s, const hier_node *q, const hier_node *p, const double *rho,
                         const double *Bp, double Fs)
{
    const size_t nb = s->nb;
    if (!(s->variation_weight > 0) || s->linear || s->importance != HIER_IMP_NONE || p->parent == RP_NONE ||
        0.25 * p->area < s->min_area)
        return 0;
    const uint32_t c0 = s->nodes[p->parent].child;
    double dv = 0;
    for (uint32_t c = 0; c < 4; c++) {
        const double *Bc = s->B + (size_t)(c0 + c) * nb;
        for (size_t b = 0; b < nb; b++)
            dv = hier_max(dv, rho[b] * fabs(Bc[b] - Bp[b]));
    }
    if (!(dv * Fs * s->variation_weight > s->bf_eps))
        return 0;
    return kernel_varies_across_source(q, p);
}

/* The refinement decision for link qi <- its source: 0 keep, 1 split the
 * receiver, 2 split the source. */
static int decide(const hier_state *s, uint32_t qi, const hier_link *l)
{
    const size_t nb = s->nb;
    const uint32_t pi = hier_link_src(l);
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[pi];
    const double *rho = s->faces[q->face].rho;
    const double *Bp = s->B + (size_t)pi * nb;
    double e = 0;
    if (s->importance != HIER_IMP_NONE && !(l->flags & HIER_LINK_INVISIBLE))
        /* Weighted by importance (hier_importance.c; Smits, Arvo &
         * Salesin 1992), in the same units.  Not a link whose rays were
         * all blocked: the oracle's "keep" drops it for good, and the
         * light of a penumbra its rays missed with it, so it goes only
         * as deep as without importance. */
        e = hier_importance_error(s, rho, s->B + (size_t)qi * nb, s->Y + (size_t)qi * nb,
                                  s->faces[p->face].rho, Bp, s->Y + (size_t)pi * nb);
    else
        for (size_t b = 0; b < nb; b++)
            e = hier_max(e, rho[b] * Bp[b]);
    /* With clustering, elements smaller than cl_area are judged by the
     * error in the power they receive instead of their radiosity
     * (Smits, Arvo & Greenberg 1994, sec. 4): e x F x A_q / cl_area. */
    double scale = s->clustering ? hier_min(1.0, q->area / s->cl_area) : 1.0;
    if (!(e * hier_link_ferr(l) * scale > s->bf_eps))
        return source_varies(s, q, p, rho, Bp, hier_link_ferr(l) * scale) ? 2 : 0;
    /* Pairs where one element crosses the other's plane meet along a
     * line (a box standing on the floor) or nearly: there the kernel is
     * singular and the light discontinuous (a D0 discontinuity, Heckbert
     * 1992), so they may go --contact-levels deeper. */
    double amin = (l->flags & HIER_LINK_STRADDLE) ? s->min_area_contact : s->min_area;
    int can_q = 0.25 * q->area >= amin, can_p = 0.25 * p->area >= amin;
    if (!s->faces[p->face].reflects && !(l->flags & HIER_LINK_STRADDLE) &&
        (!(l->flags & HIER_LINK_PARTIAL) || !kernel_varies_across_source(q, p)))
        /* A pure emitter's radiosity is uniform and the contour integral
         * is exact over the whole source: splitting it changes nothing, so
         * only the receiver (across which the kernel varies) is split.
         * Partly visible links too, once the receiver is far enough that
         * the kernel hardly varies across the emitter: splitting it then
         * only sharpens the visible fraction, which the link's own rays
         * measure, kernel-weighted, over the whole source (value_rays
         * casts sixteen times --vis-rays for it; the image's vertices cast
         * --vis-rays to it, hier_image.c point_visibility).  Split like a
         * reflector's, the Cornell box's light went down with every
         * penumbra leaf to pieces of the leaf's size: at --min-area 0.8 x
         * --bf-epsilon^2 its partly visible links to leaves at --min-area
         * grew as leaves^2.2, and the links as a whole as leaves^1.19 from
         * 123k to 10^6 leaves; now as leaves^1.03 (docs/design.md, stop
         * 46). */
        return can_q ? 1 : 0;
    /* Split the larger element (Hanrahan et al. 1991, fig. 3: the one with
     * the larger form factor to the other). */
    if (can_q && (q->area >= p->area || !can_p))
        return 1;
    if (can_p)
        return 2;
    return 0;
}

/* A source near enough to the receiver that the kernel varies across it
 * (the same test link_eval uses to integrate over the receiver). */
static int near_pair(const hier_state *s, uint32_t qi, const hier_link *l)
{
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[hier_link_src(l)];
    rp_vec3 d = rp_v3_sub(hier_node_c(p), hier_node_c(q));
    return rp_v3_dot(d, d) <= HIER_NEAR_RATIO * hier_extent2(q);
}

/* Growable arrays (links, cluster links and entries, scratch): room for
 * need items of size bytes in *a, growing by half from 1024 (doubling
 * held up to twice what the bunny scene's million links need: with the
 * 40-byte links of stop 25, 80 MiB of room for 42 MiB); 0 when out of
 * memory. */
int hier_grow(void **a, size_t *cap, size_t need, size_t size)
{
    if (need <= *cap)
        return 1;
    size_t c = *cap ? *cap : 1024;
    while (c < need)
        c += c / 2;
    void *p = realloc(*a, c * size);
    if (!p)
        return 0;
    *a = p;
    *cap = c;
    return 1;
}

/* The pair of split link r <- src's child c: the receiver's child (mode
 * 1) with the source, or the receiver with the source's child. */
static void split_child(const hier_state *s, uint32_t r, uint32_t src, unsigned char mode, uint32_t c,
                        uint32_t *qi, uint32_t *pi)
{
    *qi = mode == 1 ? s->nodes[r].child + c : r;
    *pi = mode == 1 ? src : s->nodes[src].child + c;
}

/* Child links hier_refine evaluates at once (33 bytes of slot each). */
#define HIER_SLOT_BLOCK ((size_t)1 << 16)

/* One refinement pass.  The stored links (sorted by receiver) are judged
 * once, in parallel; those split are replaced by links to the children,
 * which are judged in the next round, and so on until a round splits
 * nothing.  Only the new links are judged and copied in later rounds: the
 * stored ones stay where they are, marked when they go, so a pass that
 * splits nothing costs one parallel sweep over the links and leaves them
 * untouched. */
rp_status hier_refine(hier_state *s, size_t *refined, rp_error *err)
{
    *refined = 0;
    rp_status st = RP_OK;
    /* The stored links' receivers are read from their offsets: those must
     * cover every node (they do after any pass). */
    if ((st = hier_links_cover(s, err)) != RP_OK)
        return st;
    const size_t nn0 = s->nnodes, nl0 = s->nlinks;
    hier_link *orig = s->links;
    const uint32_t *ostart = s->link_start;
    hier_link *fresh = NULL, *kept = NULL, *cand = NULL;
    /* their receivers (the stored links' are known from ostart); a split
     * link is its receiver, its source and its mode alone */
    uint32_t *fresh_r = NULL, *kept_r = NULL, *split_r = NULL, *split_s = NULL;
    size_t capfr = 0, capkr = 0, capsr = 0;
    double *freshF = NULL, *candF = NULL; /* unoccluded form factors of pending links */
    unsigned char *fact = NULL, *kdead = NULL, *mark = NULL, *smode = NULL, *code = NULL;
    size_t capf = 0, capk = 0, caps = 0, capc = 0, capfa = 0, capkd = 0, capm = 0, capsm = 0, capcode = 0;
    size_t capfF = 0, capcF = 0;
    size_t nfresh = 0, nkept = 0;
    int changed = 0;
    /* What the pass uses besides the links it keeps: freed before those
     * are merged into the list (the Cornell box at 10^6 leaves peaked 720
     * MiB above what it held, 216 MiB since, 145 MiB since the stored
     * links' fates are a bit in their flags). */
    void **scratch[] = {(void **)&fresh, (void **)&fresh_r, (void **)&freshF, (void **)&cand,
                        (void **)&candF, (void **)&code, (void **)&fact, (void **)&kdead, (void **)&mark,
                        (void **)&split_s, (void **)&split_r, (void **)&smode};

    /* A stored link that leaves the list (split or dropped) is marked
     * HIER_LINK_GONE in place: a byte per stored link beside the list was
     * 74 MiB of the pass in which the Cornell box at 10^6 leaves peaked.
     * Where round 0 needs the oracle's mode again it asks it again
     * (decide reads nothing this loop changes). */
    size_t nsplit = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256) reduction(+ : nsplit) if (nl0 > 8192)
    for (long i = 0; i < (long)nn0; i++)
        for (uint32_t k = ostart[i]; k < ostart[i + 1]; k++)
            if (decide(s, (uint32_t)i, &orig[k])) {
                orig[k].flags |= HIER_LINK_GONE;
                nsplit++;
            }
    for (size_t k = 0; k < nl0; k++)
        if (!(orig[k].flags & HIER_LINK_GONE) && link_dropped(&orig[k])) {
            /* An invisible link the oracle would not refine is dropped:
             * 16 blocked rays between two large elements may miss a
             * penumbra, so it is dropped only once it is this fine, and
             * only if its second set of rays (the value's) was blocked
             * too: dropped on the first set alone, the penumbrae those
             * rays missed would come out too dark on average. */
            orig[k].flags |= HIER_LINK_GONE;
            s->links_invisible++;
            changed = 1;
        }
    /* Round 0 judged the stored links, later rounds the fresh ones. */
    for (int round = 0;; round++) {
        if (rp_cancelled(s->cancel) && (st = rp_error_set(err, RP_ERR_INTERRUPTED, "hierarchical: interrupted")))
            goto done;
        size_t capm0 = capm;
        if (!hier_grow((void **)&mark, &capm, s->nnodes, 1))
            goto nomem;
        memset(mark + capm0, 0, capm - capm0);
        size_t ns = 0;
        /* Splits, in a fixed order: node numbers and random keys must not
         * depend on threads. */
#define ADD_SPLIT(R, L, MODE)                                                      \
    do {                                                                           \
        if (!hier_grow((void **)&split_s, &caps, ns + 1, sizeof *split_s) ||       \
            !hier_grow((void **)&split_r, &capsr, ns + 1, sizeof *split_r) ||      \
            !hier_grow((void **)&smode, &capsm, ns + 1, 1))                        \
            goto nomem;                                                            \
        split_s[ns] = hier_link_src(&(L));                                         \
        split_r[ns] = (R);                                                         \
        smode[ns] = (unsigned char)(MODE);                                         \
        ns++;                                                                      \
    } while (0)
        if (round == 0) {
            if (nsplit == 0)
                break;
            /* A receiver that is split takes its near links down with it
             * (re-evaluated at the children's centres): pushed down
             * unchanged, the kernel of a near source, which varies across
             * the receiver, would give the children next to the source
             * too little and the others too much. */
            for (uint32_t i = 0; i < nn0; i++)
                for (uint32_t k = ostart[i]; k < ostart[i + 1]; k++)
                    if ((orig[k].flags & HIER_LINK_GONE) && decide(s, i, &orig[k]) == 1)
                        mark[i] = 1;
            /* A near link taken down goes with its receiver (mode 1), though
             * the oracle would keep it; of the links it keeps, the dropped
             * ones are those link_dropped names. */
            for (uint32_t i = 0; i < nn0; i++)
                for (uint32_t k = ostart[i]; k < ostart[i + 1]; k++)
                    if (!(orig[k].flags & HIER_LINK_GONE) && mark[i] && near_pair(s, i, &orig[k]))
                        orig[k].flags |= HIER_LINK_GONE;
            for (uint32_t i = 0; i < nn0; i++)
                for (uint32_t k = ostart[i]; k < ostart[i + 1]; k++)
                    if (orig[k].flags & HIER_LINK_GONE) {
                        int mode = decide(s, i, &orig[k]);
                        if (!mode && link_dropped(&orig[k]))
                            continue; /* dropped, not split */
                        mark[i] = 0;
                        ADD_SPLIT(i, orig[k], mode ? mode : 1);
                    }
        } else {
            if (nfresh == 0)
                break;
            if (!hier_grow((void **)&fact, &capfa, nfresh, 1) || !hier_grow((void **)&kdead, &capkd, nkept + nfresh, 1))
                goto nomem;
            size_t nsp = 0;
#pragma omp parallel for num_threads(s->threads) schedule(static) reduction(+ : nsp) if (nfresh > 8192)
            for (long k = 0; k < (long)nfresh; k++) {
                fact[k] = (unsigned char)decide(s, fresh_r[k], &fresh[k]);
                nsp += fact[k] != 0;
            }
            if (nsp) {
                for (size_t k = 0; k < nfresh; k++)
                    if (fact[k] == 1)
                        mark[fresh_r[k]] = 1;
                for (size_t k = 0; k < nfresh; k++)
                    if (fact[k] == 0 && mark[fresh_r[k]] && near_pair(s, fresh_r[k], &fresh[k]))
                        fact[k] = 1;
            }
            /* The oracle has decided: the links it keeps cast their
             * value's rays now (link_value), and a link split in the round
             * that made it never does (its children replace it). */
            double vrays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 64) reduction(+ : vrays) if (nfresh > 256)
            for (long k = 0; k < (long)nfresh; k++)
                if (!fact[k] && (fresh[k].flags & HIER_LINK_PENDING))
                    link_value(s, fresh_r[k], &fresh[k], freshF[k], &vrays);
            s->rays += vrays;
            for (size_t k = 0; k < nfresh; k++)
                if (fact[k])
                    ADD_SPLIT(fresh_r[k], fresh[k], fact[k]);
            if (nsp) {
                /* Near links of the split receivers that an earlier round
                 * kept, then stored ones (found through link_start). */
                memset(kdead, 0, nkept);
                for (size_t k = 0; k < nkept; k++)
                    if (mark[kept_r[k]] == 1 && near_pair(s, kept_r[k], &kept[k])) {
                        kdead[k] = 1;
                        ADD_SPLIT(kept_r[k], kept[k], 1);
                    }
                for (size_t k = 0; k < nfresh; k++) {
                    uint32_t r = fresh_r[k];
                    if (fact[k] != 1 || mark[r] != 1)
                        continue;
                    mark[r] = 2;
                    if (r >= nn0)
                        continue;
                    for (uint32_t j = ostart[r]; j < ostart[r + 1]; j++)
                        if (!(orig[j].flags & HIER_LINK_GONE) && near_pair(s, r, &orig[j])) {
                            orig[j].flags |= HIER_LINK_GONE;
                            ADD_SPLIT(r, orig[j], 1);
                        }
                }
                for (size_t k = 0; k < nfresh; k++)
                    mark[fresh_r[k]] = 0;
                size_t m = 0;
                for (size_t k = 0; k < nkept; k++)
                    if (!kdead[k]) {
                        kept_r[m] = kept_r[k];
                        kept[m++] = kept[k];
                    }
                nkept = m;
            }
            /* What this round keeps joins the kept list; an invisible link
             * the oracle would not refine is dropped. */
            if (!hier_grow((void **)&kept, &capk, nkept + nfresh, sizeof *kept) ||
                !hier_grow((void **)&kept_r, &capkr, nkept + nfresh, sizeof *kept_r))
                goto nomem;
            for (size_t k = 0; k < nfresh; k++) {
                if (fact[k])
                    continue;
                if (link_dropped(&fresh[k]))
                    s->links_invisible++;
                else {
                    kept_r[nkept] = fresh_r[k];
                    kept[nkept++] = fresh[k];
                }
            }
            nfresh = 0;
            if (ns == 0)
                break;
        }
#undef ADD_SPLIT
        changed = 1;
        for (size_t t = 0; t < ns; t++) {
            uint32_t node = smode[t] == 1 ? split_r[t] : split_s[t];
            if ((st = hier_subdivide(s, node, err)) != RP_OK)
                goto done;
        }
        *refined += ns;
        s->links_refined += ns;
        /* The split links' children, evaluated in parallel into slots a
         * block at a time (all 4 ns at once took the Cornell box at 83k
         * leaves to 279 MiB, not 256), then kept in order. */
        if (!hier_grow((void **)&fresh, &capf, ns * 4, sizeof *fresh) ||
            !hier_grow((void **)&fresh_r, &capfr, ns * 4, sizeof *fresh_r) ||
            !hier_grow((void **)&freshF, &capfF, ns * 4, sizeof *freshF))
            goto nomem;
        for (size_t t0 = 0; t0 < ns * 4; t0 += HIER_SLOT_BLOCK) {
            const size_t nb = ns * 4 - t0 < HIER_SLOT_BLOCK ? ns * 4 - t0 : HIER_SLOT_BLOCK;
            if (!hier_grow((void **)&cand, &capc, nb, sizeof *cand) || !hier_grow((void **)&code, &capcode, nb, 1) ||
                !hier_grow((void **)&candF, &capcF, nb, sizeof *candF))
                goto nomem;
            double rays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 16) reduction(+ : rays) if (nb > 256)
            for (long i = 0; i < (long)nb; i++) {
                const size_t t = t0 + (size_t)i;
                uint32_t qi, pi;
                split_child(s, split_r[t / 4], split_s[t / 4], smode[t / 4], (uint32_t)(t % 4), &qi, &pi);
                code[i] = (unsigned char)link_eval(s, qi, pi, &cand[i], &candF[i], &rays, 1);
            }
            s->rays += rays;
            for (size_t i = 0; i < nb; i++) {
                if (code[i] == 0)
                    continue;
                s->form_factors++;
                const size_t t = t0 + i;
                uint32_t qi, pi;
                split_child(s, split_r[t / 4], split_s[t / 4], smode[t / 4], (uint32_t)(t % 4), &qi, &pi);
                freshF[nfresh] = candF[i];
                fresh_r[nfresh] = qi;
                fresh[nfresh++] = cand[i];
            }
        }
    }
    s->refine_passes++;
    if (changed) {
        /* The stored links that stay (their offsets rewritten in place),
         * then the new ones, sorted by receiver (stable: old links first,
         * new ones in creation order). */
        uint32_t *start = s->link_start;
        size_t m = 0;
        for (size_t i = 0, lo = 0; i < nn0; i++) {
            const size_t hi = start[i + 1];
            start[i] = (uint32_t)m;
            for (size_t k = lo; k < hi; k++)
                if (!(orig[k].flags & HIER_LINK_GONE))
                    orig[m++] = orig[k];
            lo = hi;
        }
        start[nn0] = (uint32_t)m;
        for (size_t k = 0; k < sizeof scratch / sizeof *scratch; k++) {
            free(*scratch[k]);
            *scratch[k] = NULL;
        }
        st = links_merge(s, m, nn0, kept, kept_r, nkept, err);
    } else {
        /* An idle pass (the usual one near convergence): the list's room
         * beyond its links is given back (a pass that dropped links left
         * it), and the nodes' (growth by half). */
        hier_nodes_trim(s);
        if (s->nlinks > 0 && s->cap_links > s->nlinks) {
            hier_link *t = realloc(s->links, s->nlinks * sizeof *t);
            if (t) {
                s->links = t;
                s->cap_links = s->nlinks;
            }
        }
    }
    goto done;
nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory refining links");
done:
    for (size_t k = 0; k < sizeof scratch / sizeof *scratch; k++)
        free(*scratch[k]);
    free(kept);
    free(kept_r);
    return st;
}
