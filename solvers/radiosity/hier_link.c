/* Hierarchical radiosity: links, their form-factor estimates and their
 * refinement (Hanrahan, Salzman & Aupperle 1991, sec. 4 and 5).
 *
 * A link is one-way: receiver q gathers rho_q F_qp B_p from source p.  Its
 * form factor is estimated at q's centroid by Lambert's contour integral
 * over p (the disk approximation F = A cos cos / (pi r^2 + A) when p is far
 * away), times the fraction of a few jittered ray pairs between q and p
 * that are not blocked (Embree, rp_ray_occluded).  Shaft culling (Haines &
 * Wallace 1994) skips the rays when no face can lie between the two: for
 * every pair of faces the faces that might block a segment between them
 * are listed once (a face can only if its box meets the pair's box, it
 * reaches in front of both planes, and its own plane separates corners of
 * the pair: the walls of a convex room never block), and a link tests only
 * those, with the same box and plane tests on its two elements.
 *
 * BF refinement (sec. 5): a link whose error estimate
 *     rho_q * B_p * F_err   (the worst band)
 * exceeds bf_epsilon is replaced by four links to the children of the
 * larger of its two elements, as long as their area stays above min_area.
 * F_err is the estimate itself for a fully visible link; for a partially
 * visible link (a shadow boundary crosses it) or one whose elements cross
 * each other's planes it is the unoccluded estimate times partial_weight,
 * so those are refined first.
 *
 * Refinement runs breadth first: the decisions and the new links' form
 * factors are computed in parallel, and nodes are created in link order in
 * between, so node numbers, link order and every random number (keyed by
 * the seed and the two node numbers) are the same for any thread count. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"

/* ---- shaft culling ---- */

static int box_overlap(rp_vec3 alo, rp_vec3 ahi, rp_vec3 blo, rp_vec3 bhi, double eps)
{
    return alo.x <= bhi.x + eps && blo.x <= ahi.x + eps && alo.y <= bhi.y + eps &&
           blo.y <= ahi.y + eps && alo.z <= bhi.z + eps && blo.z <= ahi.z + eps;
}

static rp_vec3 vmin(rp_vec3 a, rp_vec3 b) { return rp_v3(fmin(a.x, b.x), fmin(a.y, b.y), fmin(a.z, b.z)); }
static rp_vec3 vmax(rp_vec3 a, rp_vec3 b) { return rp_v3(fmax(a.x, b.x), fmax(a.y, b.y), fmax(a.z, b.z)); }

/* 1 if some corner of node nd lies strictly on side `side` (+1 front, -1
 * behind) of face f's plane. */
static int face_side(const hier_state *s, const hier_node *nd, uint32_t f, int side)
{
    const hier_face *hf = &s->faces[f];
    for (int i = 0; i < nd->nverts; i++)
        if (side * (rp_v3_dot(hf->n, nd->v[i]) - hf->d) > s->eps)
            return 1;
    return 0;
}

rp_status hier_cull_init(hier_state *s, rp_error *err)
{
    const size_t n = s->nfaces;
    s->cull = n <= HIER_CULL_MAX_FACES;
    if (!s->cull)
        return RP_OK; /* every link casts its rays */
    s->pair_off = calloc(n * n, sizeof *s->pair_off);
    s->pair_cnt = calloc(n * n, sizeof *s->pair_cnt);
    size_t cap = 1024;
    s->cand = malloc(cap * sizeof *s->cand);
    if (!s->pair_off || !s->pair_cnt || !s->cand)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
    /* front[k n + f]: face k has a corner strictly in front of f's plane;
     * behind[k n + f]: strictly behind it. */
    unsigned char *front = malloc(n * n), *behind = malloc(n * n);
    if (!front || !behind) {
        free(front);
        free(behind);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for occluder lists");
    }
    for (size_t k = 0; k < n; k++)
        for (size_t f = 0; f < n; f++) {
            front[k * n + f] = (unsigned char)face_side(s, &s->nodes[k], (uint32_t)f, 1);
            behind[k * n + f] = (unsigned char)face_side(s, &s->nodes[k], (uint32_t)f, -1);
        }
    s->ncand = 0;
    for (size_t i = 0; i < n; i++)
        for (size_t j = i + 1; j < n; j++) {
            rp_vec3 lo = vmin(s->faces[i].lo, s->faces[j].lo), hi = vmax(s->faces[i].hi, s->faces[j].hi);
            size_t off = s->ncand;
            for (size_t k = 0; k < n; k++) {
                if (k == i || k == j || !front[k * n + i] || !front[k * n + j] ||
                    !box_overlap(s->faces[k].lo, s->faces[k].hi, lo, hi, s->eps) ||
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

/* 1 if some listed face may block a segment between nodes q and p. */
static int shaft_blocked(const hier_state *s, const hier_node *q, const hier_node *p)
{
    if (!s->cull)
        return 1;
    size_t at = (size_t)q->face * s->nfaces + p->face;
    uint32_t cnt = s->pair_cnt[at];
    if (cnt == 0)
        return 0;
    rp_vec3 lo = q->v[0], hi = q->v[0];
    for (int i = 1; i < q->nverts; i++) {
        lo = vmin(lo, q->v[i]);
        hi = vmax(hi, q->v[i]);
    }
    for (int i = 0; i < p->nverts; i++) {
        lo = vmin(lo, p->v[i]);
        hi = vmax(hi, p->v[i]);
    }
    const uint32_t *c = s->cand + s->pair_off[at];
    for (uint32_t k = 0; k < cnt; k++) {
        if (!box_overlap(s->faces[c[k]].lo, s->faces[c[k]].hi, lo, hi, s->eps))
            continue;
        /* Both elements on one side of the candidate's plane: the segments
         * between them cannot cross it. */
        if (!(face_side(s, q, c[k], 1) || face_side(s, p, c[k], 1)) ||
            !(face_side(s, q, c[k], -1) || face_side(s, p, c[k], -1)))
            continue;
        return 1;
    }
    return 0;
}

/* ---- form-factor estimates ---- */

/* Point x (normal n) on the receiver to source node p: 0 if x is not in
 * front of p; the disk approximation far away; else the contour integral. */
static double point_to_node(const hier_state *s, rp_vec3 x, rp_vec3 n, const hier_node *p, int far_ok)
{
    const hier_face *fp = &s->faces[p->face];
    if (rp_v3_dot(fp->n, x) - fp->d <= 0)
        return 0; /* x sees the back of p (which is black and one-sided) */
    rp_vec3 d = rp_v3_sub(p->c, x);
    double r2 = rp_v3_dot(d, d);
    if (far_ok && r2 > HIER_DISK_RATIO * p->area) {
        /* A disk of p's area facing along its normal (Wallace, Elmquist &
         * Haines 1989, eq. 6): F = A cos_q cos_p / (pi r^2 + A). */
        double r = sqrt(r2);
        double cq = rp_v3_dot(n, d) / r, cp = -rp_v3_dot(fp->n, d) / r;
        if (cq > 0 && cp > 0)
            return p->area * cq * cp / (RP_PI * r2 + p->area);
    }
    return hier_point_polygon(x, n, p->v, p->nverts);
}

/* Evaluates link q <- p into *out.  Returns 0 if there is no link (the two
 * do not face each other, or no part of q sees p), 1 for a link, 2 for a
 * link every visibility ray found blocked (not stored). */
static int link_eval(const hier_state *s, uint32_t qi, uint32_t pi, hier_link *out, double *rays)
{
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[pi];
    if (q->face == p->face)
        return 0; /* planar: F_ii = 0 */
    const hier_face *fq = &s->faces[q->face], *fp = &s->faces[p->face];
    double pmax = -INFINITY, pmin = INFINITY, qmax = -INFINITY, qmin = INFINITY;
    for (int i = 0; i < p->nverts; i++) {
        double d = rp_v3_dot(fq->n, p->v[i]) - fq->d;
        pmax = fmax(pmax, d);
        pmin = fmin(pmin, d);
    }
    for (int i = 0; i < q->nverts; i++) {
        double d = rp_v3_dot(fp->n, q->v[i]) - fp->d;
        qmax = fmax(qmax, d);
        qmin = fmin(qmin, d);
    }
    /* Faces facing away: no link. */
    if (pmax <= s->eps || qmax <= s->eps)
        return 0;
    int straddle = pmin < -s->eps || qmin < -s->eps;
    double F, Fmax;
    rp_vec3 dc = rp_v3_sub(p->c, q->c);
    if (!straddle && rp_v3_dot(dc, dc) > HIER_NEAR_RATIO * q->area) {
        F = Fmax = point_to_node(s, q->c, fq->n, p, 1);
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
        for (int k = 0; k < 4; k++) {
            double f = point_to_node(s, cc[k], fq->n, p, 0);
            F += ca[k] / q->area * f;
            Fmax = fmax(Fmax, f);
        }
    }
    if (!(F > 0) && !(Fmax > 0))
        return 0;
    double vis = 1;
    uint32_t flags = straddle ? HIER_LINK_STRADDLE : 0;
    if (shaft_blocked(s, q, p)) {
        /* m x m jittered strata on q paired with a random permutation of
         * m x m strata on p; pairs that face away from each other (possible
         * when one crosses the other's plane) carry no energy and do not
         * count. */
        flags |= HIER_LINK_TESTED;
        unsigned m = (unsigned)floor(sqrt((double)s->vis_rays) + 0.5), N = m * m;
        uint64_t key = hier_key(s->seed, qi, pi);
        uint32_t perm[64];
        for (unsigned k = 0; k < N; k++)
            perm[k] = k;
        for (unsigned k = N; k > 1; k--) {
            unsigned j = (unsigned)(hier_u01(key, 4 * (uint64_t)N + k) * k);
            j = j < k ? j : k - 1;
            uint32_t t = perm[k - 1];
            perm[k - 1] = perm[j];
            perm[j] = t;
        }
        unsigned valid = 0, open = 0;
        for (unsigned k = 0; k < N; k++) {
            double u1 = ((k % m) + hier_u01(key, 4 * (uint64_t)k)) / m;
            double u2 = ((k / m) + hier_u01(key, 4 * (uint64_t)k + 1)) / m;
            double w1 = ((perm[k] % m) + hier_u01(key, 4 * (uint64_t)k + 2)) / m;
            double w2 = ((perm[k] / m) + hier_u01(key, 4 * (uint64_t)k + 3)) / m;
            rp_vec3 a = hier_node_point(q, u1, u2), b = hier_node_point(p, w1, w2);
            rp_vec3 ab = rp_v3_sub(b, a);
            if (straddle && (rp_v3_dot(ab, fq->n) <= 0 || rp_v3_dot(ab, fp->n) >= 0))
                continue;
            valid++;
            *rays += 1;
            if (!rp_ray_occluded(s->rc, a, fq->n, b, fp->n))
                open++;
        }
        vis = valid ? (double)open / valid : 1.0;
        if (open < valid)
            flags |= HIER_LINK_PARTIAL;
    }
    out->recv = qi;
    out->src = pi;
    out->F = F * vis;
    out->F_err = (float)((flags & (HIER_LINK_PARTIAL | HIER_LINK_STRADDLE)) ? s->partial_weight * Fmax : Fmax);
    out->flags = flags;
    return vis > 0 ? 1 : 2;
}

/* ---- link storage ---- */

static rp_status reserve_links(hier_link **a, size_t *cap, size_t need, rp_error *err)
{
    if (need <= *cap)
        return RP_OK;
    size_t c = *cap ? *cap : 1024;
    while (c < need)
        c *= 2;
    hier_link *l = realloc(*a, c * sizeof *l);
    if (!l)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu links", c);
    *a = l;
    *cap = c;
    return RP_OK;
}

/* Sorts links by receiver (a stable counting sort, so the order within a
 * receiver is the order of creation) and builds link_start. */
static rp_status links_adopt(hier_state *s, hier_link *links, size_t n, size_t cap, rp_error *err)
{
    size_t nn = s->nnodes;
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
    if (n > UINT32_MAX)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: more than 2^32 links");
    hier_link *sorted = malloc((cap ? cap : 1) * sizeof *sorted);
    if (!sorted)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu links", n);
    uint32_t *start = s->link_start;
    memset(start, 0, (nn + 1) * sizeof *start);
    for (size_t k = 0; k < n; k++)
        start[links[k].recv + 1]++;
    for (size_t i = 0; i < nn; i++)
        start[i + 1] += start[i];
    for (size_t k = 0; k < n; k++)
        sorted[start[links[k].recv]++] = links[k];
    /* start[i] now holds the end of receiver i's run: shift back. */
    for (size_t i = nn; i > 0; i--)
        start[i] = start[i - 1];
    start[0] = 0;
    free(links);
    free(s->links);
    s->links = sorted;
    s->nlinks = n;
    s->cap_links = cap;
    size_t full = 0, partial = 0;
    for (size_t k = 0; k < n; k++) {
        if (sorted[k].flags & HIER_LINK_PARTIAL)
            partial++;
        else
            full++;
    }
    s->links_full = full;
    s->links_partial = partial;
    return RP_OK;
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
    size_t nl = 0, cap = 0;
    rp_status st = RP_OK;
    if (!buf || !code) {
        st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for the initial links");
        goto done;
    }
    for (size_t i0 = 0; i0 < n; i0 += R) {
        size_t i1 = i0 + R < n ? i0 + R : n;
        double rays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 1) reduction(+ : rays) collapse(2)
        for (long i = (long)i0; i < (long)i1; i++)
            for (long j = 0; j < (long)n; j++) {
                size_t at = (size_t)(i - (long)i0) * n + (size_t)j;
                code[at] = i == j ? 0 : (unsigned char)link_eval(s, (uint32_t)i, (uint32_t)j, &buf[at], &rays);
            }
        s->rays += rays;
        for (size_t k = 0; k < (i1 - i0) * n; k++) {
            if (code[k] == 0)
                continue;
            s->form_factors++;
            if (code[k] == 2) {
                s->links_invisible++;
                continue;
            }
            if ((st = reserve_links(&links, &cap, nl + 1, err)) != RP_OK)
                goto done;
            links[nl++] = buf[k];
        }
    }
    st = links_adopt(s, links, nl, cap, err);
    links = NULL;
done:
    free(buf);
    free(code);
    free(links);
    return st;
}

/* The refinement decision for one link: 0 keep, 1 split the receiver,
 * 2 split the source. */
static int decide(const hier_state *s, const hier_link *l)
{
    const size_t nb = s->nb;
    const hier_node *q = &s->nodes[l->recv], *p = &s->nodes[l->src];
    const double *rho = s->faces[q->face].rho;
    const double *Bp = s->B + (size_t)l->src * nb;
    double e = 0;
    for (size_t b = 0; b < nb; b++)
        e = fmax(e, rho[b] * Bp[b]);
    if (!(e * l->F_err > s->bf_eps))
        return 0;
    int can_q = 0.25 * q->area >= s->min_area, can_p = 0.25 * p->area >= s->min_area;
    /* Split the larger element (Hanrahan et al. 1991, fig. 3: the one with
     * the larger form factor to the other). */
    if (can_q && (q->area >= p->area || !can_p))
        return 1;
    if (can_p)
        return 2;
    return 0;
}

rp_status hier_refine(hier_state *s, size_t *refined, rp_error *err)
{
    *refined = 0;
    rp_status st = RP_OK;
    hier_link *out = NULL, *work = s->links;
    size_t nout = 0, capout = 0, nwork = s->nlinks;
    unsigned char *act = NULL, *code = NULL;
    size_t capact = 0;
    int own_work = 0; /* work is s->links until the first round is done */
    if ((st = reserve_links(&out, &capout, s->nlinks + 16, err)) != RP_OK)
        goto done;
    while (nwork > 0) {
        if (nwork > capact) {
            unsigned char *a = realloc(act, nwork);
            if (!a) {
                st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory refining links");
                goto done;
            }
            act = a;
            capact = nwork;
        }
        size_t nsplit = 0;
#pragma omp parallel for num_threads(s->threads) schedule(static) reduction(+ : nsplit)
        for (long k = 0; k < (long)nwork; k++) {
            act[k] = (unsigned char)decide(s, &work[k]);
            nsplit += act[k] != 0;
        }
        /* Keep what stays; create the children the splits need, in link
         * order (node numbers must not depend on threads). */
        if ((st = reserve_links(&out, &capout, nout + nwork - nsplit, err)) != RP_OK)
            goto done;
        uint32_t *split = malloc((nsplit ? nsplit : 1) * 2 * sizeof *split);
        if (!split) {
            st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory refining links");
            goto done;
        }
        size_t ns = 0;
        for (size_t k = 0; k < nwork; k++) {
            if (!act[k]) {
                out[nout++] = work[k];
                continue;
            }
            uint32_t node = act[k] == 1 ? work[k].recv : work[k].src;
            if ((st = hier_subdivide(s, node, err)) != RP_OK) {
                free(split);
                goto done;
            }
            split[2 * ns] = (uint32_t)k;
            split[2 * ns + 1] = act[k];
            ns++;
        }
        *refined += ns;
        s->links_refined += ns;
        hier_link *cand = malloc((ns ? ns : 1) * 4 * sizeof *cand);
        unsigned char *cc = realloc(code, (ns ? ns : 1) * 4);
        if (!cand || !cc) {
            free(cand);
            free(split);
            if (cc)
                code = cc;
            st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory refining links");
            goto done;
        }
        code = cc;
        double rays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 16) reduction(+ : rays)
        for (long t = 0; t < (long)ns * 4; t++) {
            const hier_link *l = &work[split[2 * (t / 4)]];
            uint32_t c = (uint32_t)(t % 4);
            uint32_t qi = l->recv, pi = l->src;
            if (split[2 * (t / 4) + 1] == 1)
                qi = s->nodes[qi].child + c;
            else
                pi = s->nodes[pi].child + c;
            code[t] = (unsigned char)link_eval(s, qi, pi, &cand[t], &rays);
        }
        s->rays += rays;
        free(split);
        size_t nn = 0;
        for (size_t t = 0; t < ns * 4; t++) {
            if (code[t] == 0)
                continue;
            s->form_factors++;
            if (code[t] == 2) {
                s->links_invisible++;
                continue;
            }
            cand[nn++] = cand[t];
        }
        if (own_work)
            free(work);
        work = cand;
        own_work = 1;
        nwork = nn;
    }
    if (own_work)
        free(work);
    own_work = 0;
    work = NULL;
    s->refine_passes++;
    st = links_adopt(s, out, nout, capout, err);
    out = NULL;
done:
    if (own_work)
        free(work);
    free(out);
    free(act);
    free(code);
    return st;
}
