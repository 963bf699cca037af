/* Hierarchical radiosity: answers in the common space (solver.h) from the
 * leaves of the quadtrees; the camera loop is the uniform solvers'
 * (rp_recon_camera), with the shading below.
 *
 * Surface averages are the area-weighted leaf radiosities over pi, the
 * enclosed part of a leaf (hier_open.c) counting its emission only.
 *
 * Images are filtered as the path tracer's and the uniform solvers': spp
 * camera rays per pixel through the shared pinhole camera (camera.h), box
 * filter, stratified jitter that is a pure function of (seed, pixel,
 * sample).  A ray hitting the front of a face sees L = B / pi, with B
 *
 *   flat     the leaf's own value (--basis linear: its linear function
 *            at the point);
 *   gouraud  interpolated from values at the leaves' corners (Cohen &
 *            Wallace 1993, sec. 9.2): at an ordinary vertex the radiosity
 *            at that point, gathered through the links of the leaves around
 *            it with point-to-polygon form factors (vtx_point_values below;
 *            the mean of leaf values would smear every gradient by half a
 *            leaf and every link's irradiance into a constant); at a
 *            T-vertex (one lying inside an edge of a coarser neighbouring
 *            leaf) the value is anchored, i.e. interpolated along that
 *            coarser edge (Baum, Mann, Smith & Winget 1991), so both sides
 *            of the edge interpolate the same line and the image has no
 *            shading cracks (--basis linear: the area-weighted mean of
 *            the leaves' linear functions at an ordinary vertex);
 *   gather   one bounce of final gathering (Reichert 1992; the uniform
 *            solvers' rp_recon_final_gather): L = Le + rho/pi E(x), the
 *            irradiance from the area lights sampled directly and from
 *            cosine-distributed rays that see the flat value of the leaf
 *            they hit.
 *
 * The backs of faces and misses are black. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"
#include "reconstruct.h"

void hier_surfaces(const hier_state *s, double *out)
{
    const size_t nb = s->nb, ns = rp_scene_nsurfaces(s->scene);
    double *area = calloc(ns ? ns : 1, sizeof *area);
    memset(out, 0, ns * nb * sizeof *out);
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE)
            continue;
        uint32_t sf = s->faces[nd->face].surface;
        if (area)
            area[sf] += nd->area;
        /* B is the radiosity of the leaf's open part (hier_open.c): its
         * enclosed part only emits. */
        const double f = hier_open_fraction(s, (uint32_t)i);
        for (size_t b = 0; b < nb; b++) {
            double e = RP_PI * s->faces[nd->face].Le[b];
            out[sf * nb + b] += nd->area * (e + f * (s->B[i * nb + b] - e));
        }
    }
    const rp_surface *surf = rp_scene_surfaces(s->scene);
    for (size_t k = 0; k < ns; k++) {
        /* Leaf areas add up to the surface's (up to rounding). */
        double a = area ? area[k] : surf[k].area;
        for (size_t b = 0; b < nb; b++)
            out[k * nb + b] = a > 0 ? out[k * nb + b] / (a * RP_PI) : 0;
    }
    free(area);
}

/* ---- vertices of the leaves, shared ones found by exact look-up ---- */

typedef struct vtx_table {
    size_t nb;
    size_t n, cap;       /* vertices */
    rp_vec3 *p;
    uint32_t *surface;
    rp_vec3 *nrm;        /* unit normal of the first face that has it */
    double *acc;         /* n x nb: sum over the leaves with this corner of
                            A x (radiosity there through that leaf's links) */
    double *area;
    uint32_t *ta, *tb;   /* anchor edge of a T-vertex, RP_NONE otherwise */
    double *tlen;        /* squared length of that edge */
    double *val;         /* n x nb: resolved radiosity */
    unsigned char *state; /* 0 unresolved, 1 in progress, 2 done */
    uint32_t *slot;      /* open addressing, hmask + 1 entries */
    size_t hmask;
} vtx_table;

static uint64_t vtx_hash(uint32_t surface, rp_vec3 p)
{
    uint64_t w[3];
    memcpy(&w[0], &p.x, 8);
    memcpy(&w[1], &p.y, 8);
    memcpy(&w[2], &p.z, 8);
    uint64_t h = hier_mix(surface + UINT64_C(0x9e3779b97f4a7c15));
    for (int k = 0; k < 3; k++)
        h = hier_mix(h ^ w[k]);
    return h;
}

/* Faces of one surface share a vertex where their normals are within 30
 * degrees of the first face's at it (a smoothing group, RP_RECON_SMOOTH_COS
 * as for the uniform meshes' Gouraud images). */
static int vtx_same(const vtx_table *t, uint32_t id, uint32_t surface, rp_vec3 p, rp_vec3 n)
{
    return t->surface[id] == surface && t->p[id].x == p.x && t->p[id].y == p.y && t->p[id].z == p.z &&
           rp_v3_dot(t->nrm[id], n) >= RP_RECON_SMOOTH_COS;
}

static uint32_t vtx_find(const vtx_table *t, uint32_t surface, rp_vec3 p, rp_vec3 n)
{
    size_t h = (size_t)vtx_hash(surface, p) & t->hmask;
    while (t->slot[h] != RP_NONE) {
        if (vtx_same(t, t->slot[h], surface, p, n))
            return t->slot[h];
        h = (h + 1) & t->hmask;
    }
    return RP_NONE;
}

/* The table is sized for every corner up front, so it never fills. */
static uint32_t vtx_insert(vtx_table *t, uint32_t surface, rp_vec3 p, rp_vec3 n)
{
    size_t h = (size_t)vtx_hash(surface, p) & t->hmask;
    while (t->slot[h] != RP_NONE) {
        if (vtx_same(t, t->slot[h], surface, p, n))
            return t->slot[h];
        h = (h + 1) & t->hmask;
    }
    uint32_t id = (uint32_t)t->n++;
    t->slot[h] = id;
    t->p[id] = p;
    t->nrm[id] = n;
    t->surface[id] = surface;
    t->ta[id] = t->tb[id] = RP_NONE;
    t->tlen[id] = 0;
    t->area[id] = 0;
    t->state[id] = 0;
    for (size_t b = 0; b < t->nb; b++)
        t->acc[(size_t)id * t->nb + b] = 0;
    return id;
}

static void vtx_free(vtx_table *t)
{
    free(t->p);
    free(t->surface);
    free(t->nrm);
    free(t->acc);
    free(t->area);
    free(t->ta);
    free(t->tb);
    free(t->tlen);
    free(t->val);
    free(t->state);
    free(t->slot);
}

static int vtx_alloc(vtx_table *t, size_t cap, size_t nb)
{
    memset(t, 0, sizeof *t);
    t->nb = nb;
    t->cap = cap;
    size_t hs = 16;
    while (hs < 2 * cap)
        hs *= 2;
    t->hmask = hs - 1;
    t->p = malloc(cap * sizeof *t->p);
    t->surface = malloc(cap * sizeof *t->surface);
    t->nrm = malloc(cap * sizeof *t->nrm);
    t->acc = malloc(cap * nb * sizeof *t->acc);
    t->area = malloc(cap * sizeof *t->area);
    t->ta = malloc(cap * sizeof *t->ta);
    t->tb = malloc(cap * sizeof *t->tb);
    t->tlen = malloc(cap * sizeof *t->tlen);
    t->val = malloc(cap * nb * sizeof *t->val);
    t->state = malloc(cap);
    t->slot = malloc(hs * sizeof *t->slot);
    if (!t->p || !t->surface || !t->nrm || !t->acc || !t->area || !t->ta || !t->tb || !t->tlen || !t->val ||
        !t->state || !t->slot)
        return 0;
    for (size_t k = 0; k < hs; k++)
        t->slot[k] = RP_NONE;
    return 1;
}

/* Walks the dyadic points inside edge (a, b) of a leaf: each one that is a
 * vertex of some finer leaf is a T-vertex, anchored to the longest leaf
 * edge it lies inside.  Its value is the mean of the edge's two ends, which
 * applied recursively is linear interpolation along the coarse edge. */
static void vtx_probe(vtx_table *t, uint32_t surface, rp_vec3 n, uint32_t a, uint32_t b, double len2, int depth)
{
    if (depth > 48)
        return;
    rp_vec3 m = rp_v3_scale(rp_v3_add(t->p[a], t->p[b]), 0.5); /* as hier_tree.c's mid() */
    uint32_t id = vtx_find(t, surface, m, n);
    if (id == RP_NONE)
        return; /* no finer leaf meets this edge here (nor, then, nearer the ends) */
    if (id == a || id == b)
        return;
    if (t->ta[id] == RP_NONE || len2 > t->tlen[id]) {
        t->ta[id] = a;
        t->tb[id] = b;
        t->tlen[id] = len2;
    }
    vtx_probe(t, surface, n, a, id, 0.25 * len2, depth + 1);
    vtx_probe(t, surface, n, id, b, 0.25 * len2, depth + 1);
}

static const double *vtx_value(vtx_table *t, uint32_t id)
{
    const size_t nb = t->nb;
    double *v = t->val + (size_t)id * nb;
    if (t->state[id] == 2)
        return v;
    if (t->state[id] == 1 || t->ta[id] == RP_NONE) {
        /* Ordinary vertex (or a cycle, which the anchoring by the longest
         * edge rules out): the area-weighted mean of its leaves' values
         * (vtx_point_values). */
        for (size_t b = 0; b < nb; b++)
            v[b] = t->area[id] > 0 ? t->acc[(size_t)id * nb + b] / t->area[id] : 0;
        t->state[id] = 2;
        return v;
    }
    t->state[id] = 1;
    const double *va = vtx_value(t, t->ta[id]);
    const double *vb = vtx_value(t, t->tb[id]);
    for (size_t b = 0; b < nb; b++)
        v[b] = 0.5 * (va[b] + vb[b]);
    t->state[id] = 2;
    return v;
}

struct hier_vertices {
    vtx_table t;
    uint32_t *leafpos; /* nnodes: the leaf's number, RP_NONE for inner nodes */
    uint32_t *lv;      /* leaves x 4: vertex of each corner */
    size_t tcount;     /* T-vertices */
    double rays;       /* visibility rays cast for the vertex values */
};

/* Vertex values take the disk approximation for sources more than 10
 * times their size away (the solver's links at 30 times): on the Cornell
 * box the image RMSE is the same to three digits at bf-epsilon 0.05 and
 * 0.02, and the vertex values take 10% less time. */
#define VERTEX_DISK_RATIO 100.0

/* The source's radiosity as the gather saw it (hierarchical.c,
 * source_radiosity): the kernel-weighted children where the shares are
 * known, else the node's own mean. */
static void link_source(const hier_state *s, const hier_link *l, double *out) { hier_source_mean(s, l, s->B, out); }

/* The visible fraction of source p seen from x (normal n): m x m jittered
 * strata on p, each weighted by the kernel cos cos / r^2, as hier_link.c
 * weighs a link's rays.  Points of p behind x's tangent plane (or seeing
 * x from behind) carry no kernel: further uniform points replace them, up
 * to 8 m^2 tries, so that a source the plane cuts through (the floor seen
 * from the foot of a box) is not taken as hidden; with no valid point at
 * all, what x sees of p is negligible and it counts as visible. */
static double point_visibility(const hier_state *s, rp_vec3 x, rp_vec3 n, const hier_node *p,
                               uint64_t key, double *rays)
{
    const rp_vec3 np = s->faces[p->face].n;
    /* An emitter is not split for its shadows (hier_link.c decide): one
     * source stands for the pieces a reflector would be split into, so it
     * gets as many rays as a link (--vis-rays) where --vertex-rays is
     * fewer. */
    const unsigned nr = s->faces[p->face].reflects || s->vertex_rays > s->vis_rays ? s->vertex_rays : s->vis_rays;
    const unsigned m = (unsigned)floor(sqrt((double)nr) + 0.5), N = m * m;
    double wsum = 0, wopen = 0;
    unsigned valid = 0;
    for (unsigned k = 0; k < 8 * N && valid < N; k++) {
        double u1 = hier_u01(key, 2 * (uint64_t)k), u2 = hier_u01(key, 2 * (uint64_t)k + 1);
        if (k < N) {
            u1 = ((k % m) + u1) / m;
            u2 = ((k / m) + u2) / m;
        }
        rp_vec3 b = hier_node_point(p, u1, u2), d = rp_v3_sub(b, x);
        double r2 = rp_v3_dot(d, d);
        double w = hier_max(rp_v3_dot(d, n), 0) * hier_max(-rp_v3_dot(d, np), 0) / (r2 * r2);
        if (!(w > 0))
            continue;
        valid++;
        wsum += w;
        *rays += 1;
        if (!rp_ray_occluded(s->rc, x, n, b, np))
            wopen += w;
    }
    return wsum > 0 ? wopen / wsum : 1;
}

/* Radiosity at a point x of a leaf (Wallace, Elmquist & Haines 1989:
 * vertex radiosities from point-to-area form factors).  The leaf's own
 * value has each link's form factor as estimated for its receiver (the
 * leaf or an ancestor, at that node's centre) and, pushed down, is
 * constant over the leaf:
 *
 *     B_i = pi Le + s_i (rho sum_links F_l B_l + C),
 *
 * C what clusters above hand down, s_i the leaf's row scale (hier_row_scale:
 * an enclosure's row-sum normalisation or the open fractions' cap).  At x
 * each link's form factor is replaced by the exact point-to-polygon one,
 * F_l(x) (times the visible fraction seen from x, point_visibility, for
 * links whose rays were partly blocked), and s by
 * 1 / (sum F_l(x) + the rest of the leaf's row sum), so the light keeps
 * the shape of the kernel (the ramp of direct light under the ceiling, the
 * fall into a corner) below the size of the links.  node_changes sums one
 * node's part of the change, leaf_value applies it.
 *
 * node_changes: the changes node a's links make at x (normal n), dF +=
 * sum (F_l(x) - F_l) and dg += sum (F_l(x) - F_l) B_l. */
static void node_changes(const hier_state *s, uint32_t a, rp_vec3 x, rp_vec3 n, uint64_t key, double *rays,
                         double *dF, double *dg)
{
    const size_t nb = s->nb;
    double Bp[HIER_MAX_BANDS];
    for (uint32_t k = s->link_start[a]; k < s->link_start[a + 1]; k++) {
        const hier_link *l = &s->links[k];
        const hier_node *p = &s->nodes[hier_link_src(l)];
        double F = hier_point_to_node(s, x, n, p, VERTEX_DISK_RATIO);
        if (l->flags & HIER_LINK_PARTIAL)
            F *= point_visibility(s, x, n, p, hier_key(key, k, 0), rays);
        link_source(s, l, Bp);
        /* the form factor the sweep gathered through: F_l over a's open
         * fraction (hier_open.c) */
        const double Fg = hier_link_F(l) / hier_open_divisor(s, a);
        *dF += F - Fg;
        for (size_t b = 0; b < nb; b++)
            dg[b] += (F - Fg) * Bp[b];
    }
}

/* Leaf i's radiosity at a point where its chain of links changes the row
 * sum by dF and the gathered sum by dg (node_changes): B_i = E + s_i G
 * with G = rho sum F_l B_l + C, so there E + s_x (G + rho dg), s_x the
 * enclosure's row-sum scale 1 / (1 / s_i + dF) (elsewhere s_i itself: the
 * open fractions' cap, 1 for an uncapped leaf, is kept as it is). */
static void leaf_value(const hier_state *s, uint32_t i, double dF, const double *dg, double *out)
{
    const hier_face *f = &s->faces[s->nodes[i].face];
    const double scale = hier_row_scale(s, i);
    double sx = scale;
    if (s->enclosure)
        sx = 1.0 / scale + dF > 0 ? 1.0 / (1.0 / scale + dF) : scale;
    for (size_t b = 0; b < s->nb; b++) {
        double E = RP_PI * f->Le[b];
        double G = (s->B[(size_t)i * s->nb + b] - E) / scale;
        out[b] = hier_max(0.0, E + sx * (G + f->rho[b] * dg[b]));
    }
}

/* Per-thread memory of the nodes whose changes at the current vertex are
 * known: the leaves around a vertex share most of their ancestors, so each
 * node's links are evaluated once per vertex. */
typedef struct vtx_memo {
    size_t n, cap, nb;
    uint32_t *node;
    double *dF, *dg; /* cap, cap x nb */
} vtx_memo;

static int memo_find_or_add(vtx_memo *m, uint32_t a, size_t *at)
{
    for (size_t k = 0; k < m->n; k++)
        if (m->node[k] == a) {
            *at = k;
            return 1;
        }
    if (m->n == m->cap) {
        size_t c = m->cap ? 2 * m->cap : 64;
        uint32_t *nn = realloc(m->node, c * sizeof *nn);
        if (nn)
            m->node = nn;
        double *f = realloc(m->dF, c * sizeof *f);
        if (f)
            m->dF = f;
        double *g = realloc(m->dg, c * m->nb * sizeof *g);
        if (g)
            m->dg = g;
        if (!nn || !f || !g)
            return -1;
        m->cap = c;
    }
    *at = m->n++;
    m->node[*at] = a;
    m->dF[*at] = 0;
    for (size_t b = 0; b < m->nb; b++)
        m->dg[*at * m->nb + b] = 0;
    return 0;
}

/* Values at ordinary vertices (Wallace, Elmquist & Haines 1989: vertex
 * radiosities from point-to-area form factors): the area-weighted mean,
 * over the leaves around the vertex, of each leaf's radiosity there with
 * every link of its chain (its own and its ancestors') re-evaluated at the
 * vertex, moved a thousandth of the way towards the centre of the first
 * leaf of its face (off the edges, where the contour integral is
 * singular).  T-vertices then interpolate their anchors. */
static int vtx_point_values(const hier_state *s, hier_vertices *hv, size_t nleaves)
{
    vtx_table *t = &hv->t;
    const size_t nb = t->nb, nv = t->n;
    /* Leaves around each ordinary vertex, in leaf order (CSR). */
    uint32_t *start = calloc(nv + 1, sizeof *start);
    uint32_t *inc = malloc((nleaves ? nleaves : 1) * 4 * sizeof *inc);
    uint32_t *leaf = malloc((nleaves ? nleaves : 1) * sizeof *leaf);
    if (!start || !inc || !leaf) {
        free(start);
        free(inc);
        free(leaf);
        return 0;
    }
    for (size_t i = 0; i < s->nnodes; i++)
        if (hv->leafpos[i] != RP_NONE)
            leaf[hv->leafpos[i]] = (uint32_t)i;
    for (size_t j = 0; j < nleaves; j++)
        for (int k = 0; k < s->nodes[leaf[j]].nverts; k++)
            if (t->ta[hv->lv[j * 4 + k]] == RP_NONE)
                start[hv->lv[j * 4 + k] + 1]++;
    for (size_t v = 0; v < nv; v++)
        start[v + 1] += start[v];
    for (size_t j = 0; j < nleaves; j++)
        for (int k = 0; k < s->nodes[leaf[j]].nverts; k++) {
            uint32_t v = hv->lv[j * 4 + k];
            if (t->ta[v] == RP_NONE)
                inc[start[v]++] = leaf[j];
        }
    for (size_t v = nv; v > 0; v--)
        start[v] = start[v - 1];
    start[0] = 0;

    double nrays = 0;
    int ok = 1;
#pragma omp parallel num_threads(s->threads) reduction(+ : nrays)
    {
        vtx_memo m = {.nb = nb};
        double dg[HIER_MAX_BANDS], val[HIER_MAX_BANDS];
        uint32_t xface[32];
        rp_vec3 xs[32];
#pragma omp for schedule(dynamic, 64)
        for (long v = 0; v < (long)nv; v++) {
            double *acc = t->acc + (size_t)v * nb;
            for (size_t b = 0; b < nb; b++)
                acc[b] = 0;
            m.n = 0;
            int nx = 0;
            const uint64_t key = hier_key(s->seed ^ UINT64_C(0x7674), (uint64_t)v, 0);
            for (uint32_t e = start[v]; e < start[v + 1]; e++) {
                const uint32_t i = inc[e];
                const hier_node *lf = &s->nodes[i];
                /* The evaluation point for this leaf's face. */
                int xi = 0;
                while (xi < nx && xface[xi] != lf->face)
                    xi++;
                if (xi == nx) {
                    xi = nx < 32 ? nx++ : 31; /* (a vertex of more than 32 faces re-uses the last) */
                    xface[xi] = lf->face;
                    xs[xi] = rp_v3_madd(t->p[v], rp_v3_sub(hier_node_c(lf), t->p[v]), 1e-3);
                }
                if (s->linear) {
                    /* --basis linear: the leaf's own linear function
                     * there; the vertex takes the area-weighted mean of
                     * its leaves' (the point gather below corrects
                     * constant leaves, and counted the slopes twice) */
                    hier_linear_eval(s, i, xs[xi], val);
                    for (size_t b = 0; b < nb; b++)
                        acc[b] += lf->area * val[b];
                    continue;
                }
                double dF = 0;
                for (size_t b = 0; b < nb; b++)
                    dg[b] = 0;
                for (uint32_t a = i; a != RP_NONE; a = s->nodes[a].parent) {
                    size_t at;
                    int found = memo_find_or_add(&m, a, &at);
                    if (found < 0) {
#pragma omp atomic write
                        ok = 0;
                        break;
                    }
                    if (!found)
                        node_changes(s, a, xs[xi], s->faces[lf->face].n, key, &nrays, &m.dF[at],
                                     m.dg + at * nb);
                    dF += m.dF[at];
                    for (size_t b = 0; b < nb; b++)
                        dg[b] += m.dg[at * nb + b];
                }
                leaf_value(s, i, dF, dg, val);
                for (size_t b = 0; b < nb; b++)
                    acc[b] += lf->area * val[b];
            }
        }
        free(m.node);
        free(m.dF);
        free(m.dg);
    }
    free(start);
    free(inc);
    free(leaf);
    if (!ok)
        return 0;
    for (size_t v = 0; v < nv; v++)
        vtx_value(t, (uint32_t)v);
    hv->rays = nrays;
    return 1;
}

void hier_vertices_destroy(hier_vertices *v)
{
    if (!v)
        return;
    vtx_free(&v->t);
    free(v->leafpos);
    free(v->lv);
    free(v);
}

rp_status hier_vertices_create(const hier_state *s, hier_vertices **out, rp_error *err)
{
    const size_t nb = s->nb;
    *out = NULL;
    hier_vertices *hv = calloc(1, sizeof *hv);
    if (!hv)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for image vertices");
    vtx_table *t = &hv->t;
    hv->leafpos = malloc((s->nnodes ? s->nnodes : 1) * sizeof *hv->leafpos);
    size_t nleaves = 0;
    if (hv->leafpos)
        for (size_t i = 0; i < s->nnodes; i++)
            hv->leafpos[i] = s->nodes[i].child == RP_NONE ? (uint32_t)nleaves++ : RP_NONE;
    hv->lv = malloc((nleaves ? nleaves : 1) * 4 * sizeof *hv->lv);
    if (!hv->leafpos || !hv->lv || !vtx_alloc(t, 4 * nleaves + 4, nb)) {
        hier_vertices_destroy(hv);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for image vertices");
    }
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (hv->leafpos[i] == RP_NONE)
            continue;
        uint32_t sf = s->faces[nd->face].surface;
        uint32_t *c = hv->lv + (size_t)hv->leafpos[i] * 4;
        c[3] = RP_NONE;
        for (int k = 0; k < nd->nverts; k++) {
            c[k] = vtx_insert(t, sf, nd->v[k], s->faces[nd->face].n);
            t->area[c[k]] += nd->area;
        }
    }
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (hv->leafpos[i] == RP_NONE)
            continue;
        uint32_t sf = s->faces[nd->face].surface;
        const uint32_t *c = hv->lv + (size_t)hv->leafpos[i] * 4;
        for (int k = 0; k < nd->nverts; k++) {
            uint32_t a = c[k], b = c[(k + 1) % nd->nverts];
            rp_vec3 d = rp_v3_sub(t->p[b], t->p[a]);
            vtx_probe(t, sf, s->faces[nd->face].n, a, b, rp_v3_dot(d, d), 0);
        }
    }
    for (size_t v = 0; v < t->n; v++)
        hv->tcount += t->ta[v] != RP_NONE;
    if (!vtx_point_values(s, hv, nleaves)) {
        hier_vertices_destroy(hv);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for image vertices");
    }
    *out = hv;
    return RP_OK;
}

size_t hier_vertices_tcount(const hier_vertices *v) { return v->tcount; }

size_t hier_vertices_count(const hier_vertices *v) { return v->t.n; }

void hier_vertices_eval(const hier_state *s, const hier_vertices *v, uint32_t face, rp_vec3 p, double *B)
{
    const size_t nb = s->nb;
    double w[4];
    uint32_t leaf = hier_locate(s, face, p, w);
    const hier_node *nd = &s->nodes[leaf];
    const uint32_t *c = v->lv + (size_t)v->leafpos[leaf] * 4;
    for (size_t b = 0; b < nb; b++)
        B[b] = 0;
    for (int k = 0; k < nd->nverts; k++)
        for (size_t b = 0; b < nb; b++)
            B[b] += w[k] * v->t.val[(size_t)c[k] * nb + b];
}

/* ---- the image ---- */

typedef struct img_job {
    const hier_state *s;
    const hier_vertices *hv;
    rp_recon_gather gather; /* (gather) */
    double *vtx;            /* --simplify: the solution at the full mesh's vertices */
} img_job;

/* B at point p of solution face `face`: the leaf's own value (with
 * --basis linear its linear function at p). */
static void eval_flat(const void *ctx, uint32_t face, rp_vec3 p, double *B)
{
    rp_hierarchical_radiosity_at(((const img_job *)ctx)->s, face, p, B);
}

/* B there interpolated from the leaves' corners. */
static void eval_gouraud(const void *ctx, uint32_t face, rp_vec3 p, double *B)
{
    const img_job *j = ctx;
    hier_vertices_eval(j->s, j->hv, face, p, B);
}

static void shade(const void *ctx, const rp_hit *h, uint64_t key, double *xyg, uint32_t *perm, double *L,
                  unsigned long long *rays)
{
    const img_job *j = ctx;
    const hier_state *s = j->s;
    const size_t nb = s->nb;
    for (size_t b = 0; b < nb; b++)
        L[b] = 0;
    if (!h->front)
        return; /* the back of a face is black */
    if (s->recon == HIER_RECON_GATHER) {
        rp_recon_final_gather(&j->gather, h, key, xyg, perm, L, rays);
        return;
    }
    const rp_solution_eval_fn eval = s->recon == HIER_RECON_FLAT ? eval_flat : eval_gouraud;
    if (s->view.sol) /* h is on the full scene */
        rp_solution_eval(s->view.sol, nb, eval, j, j->vtx, h->face, h->p, L);
    else
        eval(j, h->face, h->p, L);
    for (size_t b = 0; b < nb; b++)
        L[b] /= RP_PI;
}

/* The solution at a gather ray's hit: the leaf's radiosity (with
 * --simplify, interpolated from the leaves under the full mesh's vertices). */
static void leaf_radiosity(const void *ctx, const rp_hit *g, double *B)
{
    const img_job *j = ctx;
    if (j->s->view.sol)
        rp_solution_eval(j->s->view.sol, j->s->nb, eval_flat, j, j->vtx, g->face, g->p, B);
    else
        eval_flat(j, g->face, g->p, B);
}

rp_status hier_image(const hier_state *s, float *out, float *variance, double *rays, rp_error *err)
{
    if (!rp_scene_camera(s->view.scene))
        return rp_error_set(err, RP_ERR_INPUT, "the scene has no camera to render from");
    rp_status st = rp_recon_view_check(&s->view, err);
    if (st != RP_OK)
        return st;
    const size_t nb = s->nb;
    img_job job = {.s = s};
    hier_vertices *hv = NULL;
    if (s->recon == HIER_RECON_GOURAUD) {
        if ((st = hier_vertices_create(s, &hv, err)) != RP_OK)
            return st;
        job.hv = hv;
        *rays += hv->rays;
    }
    if (s->view.sol) {
        const size_t nv = rp_scene_nvertices(s->view.scene);
        if (!(job.vtx = calloc(nv ? nv * nb : 1, sizeof *job.vtx))) {
            hier_vertices_destroy(hv);
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory");
        }
        rp_solution_vertex_values(s->view.sol, nb, s->recon == HIER_RECON_GOURAUD ? eval_gouraud : eval_flat, &job,
                                  job.vtx);
    }
    rp_area_sampler *lights = NULL;
    if (s->recon == HIER_RECON_GATHER) {
        if ((st = rp_recon_lights(s->view.scene, &lights, err)) != RP_OK) {
            free(job.vtx);
            return st;
        }
        job.gather = (rp_recon_gather){.scene = s->view.scene, .rc = s->view.rc, .lights = lights,
                                       .rays = s->gather_rays, .nb = nb, .radiosity = leaf_radiosity, .ctx = &job};
    }
    const rp_recon_shader shader = {shade, &job, s->recon == HIER_RECON_GATHER ? s->gather_rays : 1};
    st = rp_recon_camera(s->view.scene, s->view.rc, s->spp, s->seed, s->threads, nb, &shader, out, variance, rays,
                         err);
    hier_vertices_destroy(hv);
    rp_area_sampler_destroy(lights);
    free(job.vtx);
    return st;
}
