/* Discontinuity segments (discontinuity.h).
 *
 * D0 (Heckbert 1992, sec. 3; Lischinski, Tampieri & Greenberg 1992, sec. 3):
 * for a receiving face R and another face O, O's vertices' signed distances
 * to R's plane say where O meets that plane: vertices on it and edges that
 * cross it give at most two distinct points (O is convex), the segment
 * between them is where O touches or pierces R's plane, clipped to R.
 *
 * D1 (Heckbert 1992, sec. 4, "EV and VE events"; Lischinski et al. 1992,
 * sec. 4): the critical surfaces of an area light L and a polygonal
 * occluder are wedges spanned by a vertex and an edge, one of them the
 * light's.  Traced on R's plane, a wedge is a central projection:
 *   EV, light vertex v, occluder edge p0 p1:  x = v + t (p - v), p on p0 p1;
 *   VE, occluder vertex p, light edge q0 q1:  x = q + t (p - q), q on q0 q1;
 * with t = d_s / (d_s - d_p) >= 1 where d_s, d_p are the signed distances
 * of the source (v or q) and of the occluder point to R's plane; the trace
 * of a segment is the segment between its endpoints' images as long as every
 * point of it lies strictly between the source's level and the plane.  Only
 * silhouette edges (their two faces face the source differently, or the
 * edge bounds a single face) span wedges, and VE wedges only through
 * endpoints of silhouette edges. */
#include "discontinuity.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh_internal.h"
#include "raycast.h"

/* Pieces of a trace tested for visibility (discontinuity.h). */
#define DISC_PIECES 16
/* A wedge's trace is cut where t passes this (the occluder point near the
 * source's level projects to infinity). */
#define DISC_MAX_T 1e4

typedef struct frame2 {
    rp_vec3 o, t, b, n;
    double xy[8];   /* the face's corners in (t, b) */
    int nv;
    double orient;  /* +1 if the corners run counter-clockwise in (t, b) */
} frame2;

typedef struct seg_list {
    rp_disc_segment *s;
    size_t n, cap;
} seg_list;

static int seg_push(seg_list *l, uint32_t face, uint32_t kind, uint32_t source, rp_vec3 a, rp_vec3 b)
{
    if (l->n == l->cap) {
        size_t cap = l->cap ? 2 * l->cap : 256;
        rp_disc_segment *s = realloc(l->s, cap * sizeof *s);
        if (!s)
            return -1;
        l->s = s;
        l->cap = cap;
    }
    l->s[l->n++] = (rp_disc_segment){face, kind, source, a, b};
    return 0;
}

static void frame_make(const rp_scene *scene, uint32_t f, frame2 *fr)
{
    const rp_face *F = &rp_scene_faces(scene)[f];
    const rp_vec3 *V = rp_scene_vertices(scene);
    fr->n = F->normal;
    fr->o = V[F->v[0]];
    rp_v3_basis(F->normal, &fr->t, &fr->b);
    fr->nv = (int)F->nverts;
    double area2 = 0;
    for (int i = 0; i < fr->nv; i++) {
        rp_vec3 d = rp_v3_sub(V[F->v[i]], fr->o);
        fr->xy[2 * i] = rp_v3_dot(d, fr->t);
        fr->xy[2 * i + 1] = rp_v3_dot(d, fr->b);
    }
    for (int i = 0; i < fr->nv; i++) {
        int j = (i + 1) % fr->nv;
        area2 += fr->xy[2 * i] * fr->xy[2 * j + 1] - fr->xy[2 * j] * fr->xy[2 * i + 1];
    }
    fr->orient = area2 >= 0 ? 1.0 : -1.0;
}

static void to2(const frame2 *fr, rp_vec3 p, double *x, double *y)
{
    rp_vec3 d = rp_v3_sub(p, fr->o);
    *x = rp_v3_dot(d, fr->t);
    *y = rp_v3_dot(d, fr->b);
}

static rp_vec3 to3(const frame2 *fr, double x, double y)
{
    return rp_v3_add(fr->o, rp_v3_add(rp_v3_scale(fr->t, x), rp_v3_scale(fr->b, y)));
}

/* Clips segment a b (in the face's plane) to the convex face (Cyrus-Beck);
 * 1 and the clipped ends when something of length > tol remains, 0
 * otherwise.  Also 0 when what remains runs along one of the face's
 * edges (within tol): the face boundary is an element edge already. */
static int clip_to_face(const frame2 *fr, rp_vec3 a, rp_vec3 b, double tol, rp_vec3 *ca, rp_vec3 *cb)
{
    double ax, ay, bx, by;
    to2(fr, a, &ax, &ay);
    to2(fr, b, &bx, &by);
    double dx = bx - ax, dy = by - ay;
    double t0 = 0, t1 = 1;
    for (int i = 0; i < fr->nv; i++) {
        int j = (i + 1) % fr->nv;
        double ex = fr->xy[2 * j] - fr->xy[2 * i], ey = fr->xy[2 * j + 1] - fr->xy[2 * i + 1];
        double el = hypot(ex, ey);
        /* Inward distance of a point: orient * cross(e, p - ci) / |e|. */
        double da = fr->orient * (ex * (ay - fr->xy[2 * i + 1]) - ey * (ax - fr->xy[2 * i])) / el;
        double dd = fr->orient * (ex * dy - ey * dx) / el;
        if (fabs(dd) < 1e-300) {
            if (da < -tol)
                return 0;
            continue;
        }
        /* da + t dd >= 0 */
        double t = -da / dd;
        if (dd > 0)
            t0 = fmax(t0, t);
        else
            t1 = fmin(t1, t);
    }
    if (!(t1 > t0))
        return 0;
    double x0 = ax + t0 * dx, y0 = ay + t0 * dy, x1 = ax + t1 * dx, y1 = ay + t1 * dy;
    if (hypot(x1 - x0, y1 - y0) <= tol)
        return 0;
    for (int i = 0; i < fr->nv; i++) {
        int j = (i + 1) % fr->nv;
        double ex = fr->xy[2 * j] - fr->xy[2 * i], ey = fr->xy[2 * j + 1] - fr->xy[2 * i + 1];
        double el = hypot(ex, ey);
        double d0 = fabs(ex * (y0 - fr->xy[2 * i + 1]) - ey * (x0 - fr->xy[2 * i])) / el;
        double d1 = fabs(ex * (y1 - fr->xy[2 * i + 1]) - ey * (x1 - fr->xy[2 * i])) / el;
        if (d0 <= tol && d1 <= tol)
            return 0;
    }
    *ca = to3(fr, x0, y0);
    *cb = to3(fr, x1, y1);
    return 1;
}

/* 1 if face f reflects in some band (a receiver: a black face needs no
 * elements). */
static int face_reflects(const rp_scene *scene, uint32_t f)
{
    const rp_material *m = rp_scene_face_material(scene, f);
    const size_t nb = rp_scene_nbands(scene);
    for (size_t k = 0; k < nb; k++)
        if (m->rho[k] > 0)
            return 1;
    return 0;
}

/* ---- D0 ------------------------------------------------------------- */

static int find_d0(const rp_scene *scene, const frame2 *frames, double tol, seg_list *out)
{
    const size_t nf = rp_scene_nfaces(scene);
    const rp_face *F = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    for (size_t r = 0; r < nf; r++) {
        const frame2 *fr = &frames[r];
        for (size_t o = 0; o < nf; o++) {
            if (o == r || F[o].surface == F[r].surface)
                continue;
            double d[4];
            rp_vec3 p[4];
            int on = 0;
            for (uint32_t i = 0; i < F[o].nverts; i++) {
                p[i] = V[F[o].v[i]];
                d[i] = rp_v3_dot(fr->n, rp_v3_sub(p[i], fr->o));
                on += fabs(d[i]) <= tol;
            }
            if (on == (int)F[o].nverts)
                continue; /* coplanar: no line */
            rp_vec3 pts[8];
            int np = 0;
            for (uint32_t i = 0; i < F[o].nverts; i++) {
                uint32_t j = (i + 1) % F[o].nverts;
                if (fabs(d[i]) <= tol)
                    pts[np++] = p[i];
                else if (fabs(d[j]) > tol && (d[i] > 0) != (d[j] > 0))
                    pts[np++] = rp_v3_add(p[i], rp_v3_scale(rp_v3_sub(p[j], p[i]), d[i] / (d[i] - d[j])));
            }
            if (np < 2)
                continue;
            /* The two points farthest apart. */
            int bi = 0, bj = 1;
            double best = -1;
            for (int i = 0; i < np; i++)
                for (int j = i + 1; j < np; j++) {
                    double l = rp_v3_length(rp_v3_sub(pts[i], pts[j]));
                    if (l > best) {
                        best = l;
                        bi = i;
                        bj = j;
                    }
                }
            if (best <= tol)
                continue;
            rp_vec3 a, b;
            if (clip_to_face(fr, pts[bi], pts[bj], tol, &a, &b) &&
                seg_push(out, (uint32_t)r, RP_DISC_D0, (uint32_t)o, a, b))
                return -1;
        }
    }
    return 0;
}

/* ---- GAP outlines ------------------------------------------------------ */

/* For each receiving face r that reflects (face_reflects), every face o of
 * another surface lying wholly in front of r (beyond tol) and no farther
 * than RP_DISC_GAP_RATIO x sqrt(area of o), which also keeps o within a
 * few degrees of parallel to r: o's edges projected along r's normal onto
 * r's plane and clipped to r (discontinuity.h). */
static int find_gap(const rp_scene *scene, const frame2 *frames, double tol, seg_list *out)
{
    const size_t nf = rp_scene_nfaces(scene);
    const rp_face *F = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    for (size_t r = 0; r < nf; r++) {
        const frame2 *fr = &frames[r];
        if (!face_reflects(scene, (uint32_t)r))
            continue;
        for (size_t o = 0; o < nf; o++) {
            if (o == r || F[o].surface == F[r].surface)
                continue;
            const double reach = RP_DISC_GAP_RATIO * sqrt(F[o].area);
            rp_vec3 p[4];
            int near = 1;
            for (uint32_t i = 0; i < F[o].nverts && near; i++) {
                rp_vec3 v = V[F[o].v[i]];
                double d = rp_v3_dot(fr->n, rp_v3_sub(v, fr->o));
                near = d > tol && d <= reach;
                p[i] = rp_v3_sub(v, rp_v3_scale(fr->n, d));
            }
            if (!near)
                continue;
            for (uint32_t i = 0; i < F[o].nverts; i++) {
                rp_vec3 a, b;
                if (clip_to_face(fr, p[i], p[(i + 1) % F[o].nverts], tol, &a, &b) &&
                    seg_push(out, (uint32_t)r, RP_DISC_GAP, (uint32_t)o, a, b))
                    return -1;
            }
        }
    }
    return 0;
}

/* ---- D1 ------------------------------------------------------------- */

typedef struct edge_info {
    uint32_t a, b;     /* welded vertices (scene vertex indices of their
                          representatives), a < b */
    uint32_t f0, f1;   /* the faces using it (f1 RP_NONE: a boundary edge) */
} edge_info;

typedef struct key_rec {
    uint64_t key;
    uint32_t face;
} key_rec;

static int key_cmp(const void *pa, const void *pb)
{
    const key_rec *a = pa, *b = pb;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return a->face < b->face ? -1 : (a->face > b->face);
}

/* 1 if edge e bounds the region of its surface seen from point q (the two
 * faces face q differently, or it is a boundary edge). */
static int silhouette(const rp_scene *scene, const edge_info *e, rp_vec3 q)
{
    if (e->f1 == RP_NONE)
        return 1;
    const rp_face *F = rp_scene_faces(scene);
    rp_vec3 p = rp_scene_vertices(scene)[e->a];
    double s0 = rp_v3_dot(F[e->f0].normal, rp_v3_sub(q, p));
    double s1 = rp_v3_dot(F[e->f1].normal, rp_v3_sub(q, p));
    return (s0 > 0) != (s1 > 0);
}

/* Closest point to line (c, d) on line (p, q). */
static rp_vec3 closest_on_line(rp_vec3 p, rp_vec3 q, rp_vec3 c, rp_vec3 d)
{
    rp_vec3 u = rp_v3_sub(q, p), v = rp_v3_sub(d, c), w = rp_v3_sub(p, c);
    double a = rp_v3_dot(u, u), b = rp_v3_dot(u, v), cc = rp_v3_dot(v, v);
    double dd = rp_v3_dot(u, w), e = rp_v3_dot(v, w);
    double den = a * cc - b * b;
    double s = den > 1e-300 * a * cc ? (b * e - cc * dd) / den : 0;
    s = s < 0 ? 0 : (s > 1 ? 1 : s);
    return rp_v3_add(p, rp_v3_scale(u, s));
}

typedef struct wedge {
    int ev;              /* 1: EV (source v = s0, edge e0 e1); 0: VE (vertex e0, light edge s0 s1) */
    rp_vec3 s0, s1, e0, e1;
    rp_vec3 nl;          /* the light's front normal */
    uint32_t light;
    /* VE: the front normals of the faces around the vertex, when it is a
     * corner of a closed fan (3 or more faces). */
    const rp_vec3 *vn;
    size_t nvn;
} wedge;

/* VE: the line from light point q through vertex e grazes the solid at e
 * (Heckbert 1992, sec. 4: only such lines bound a shadow).  Around a
 * convex corner the solid is the cone n_f . d <= 0 over the faces f at the
 * vertex; the line enters it after e when d = e - q points into the cone,
 * or leaves it there when -d does. */
static int grazes(const wedge *w, rp_vec3 q, rp_vec3 e)
{
    if (w->nvn < 3)
        return 1; /* an open corner (a sheet): lines through it only touch it */
    rp_vec3 d = rp_v3_normalize(rp_v3_sub(e, q));
    int into = 1, outof = 1;
    for (size_t k = 0; k < w->nvn; k++) {
        double c = rp_v3_dot(w->vn[k], d);
        into &= c < -1e-9;
        outof &= c > 1e-9;
    }
    return !into && !outof;
}

/* The segment from o to x is unblocked (ends excluded by eta). */
static int clear(const rp_raycast *rc, rp_vec3 from, rp_vec3 to, double eta)
{
    rp_vec3 d = rp_v3_sub(to, from);
    double len = rp_v3_length(d);
    if (!(len > 3 * eta))
        return 1;
    d = rp_v3_scale(d, 1.0 / len);
    rp_hit hit;
    return !rp_ray_closest(rc, rp_v3_madd(from, d, eta), d, len - 2 * eta, &hit);
}

/* The piece of the trace at x is a real boundary: the wedge's occluder
 * point and light point that line up with x see each other and x. */
static int wedge_visible(const rp_raycast *rc, const wedge *w, rp_vec3 x, rp_vec3 nr, double eta)
{
    rp_vec3 e, q;
    if (w->ev) {
        q = w->s0;
        e = closest_on_line(w->e0, w->e1, q, x);
    } else {
        e = w->e0;
        q = closest_on_line(w->s0, w->s1, x, e);
    }
    if (!(rp_v3_dot(w->nl, rp_v3_sub(e, q)) > 0) || !(rp_v3_dot(nr, rp_v3_sub(q, x)) > 0))
        return 0;
    if (!w->ev && !grazes(w, q, e))
        return 0;
    return clear(rc, e, x, eta) && clear(rc, e, q, eta);
}

/* Traces wedge w on receiver r: the central projection of the segment
 * (p0, p1) from source s, or of the source segment (p0, p1) through the
 * point c (VE); clips, filters and keeps the visible pieces. */
static int trace_wedge(const rp_scene *scene, const rp_raycast *rc, const frame2 *fr, uint32_t r,
                       const wedge *w, double tol, double eta, seg_list *out)
{
    /* Endpoints of the trace: image of each end of the moving segment. */
    rp_vec3 img[2];
    int on[2];
    for (int k = 0; k < 2; k++) {
        rp_vec3 src = w->ev ? w->s0 : (k ? w->s1 : w->s0);
        rp_vec3 thr = w->ev ? (k ? w->e1 : w->e0) : w->e0;
        double ds = rp_v3_dot(fr->n, rp_v3_sub(src, fr->o));
        double dp = rp_v3_dot(fr->n, rp_v3_sub(thr, fr->o));
        if (!(ds > tol) || dp < -tol || !(dp < ds))
            return 0;
        on[k] = dp <= tol;
        double t = ds / (ds - dp);
        if (!(t <= DISC_MAX_T))
            return 0;
        img[k] = rp_v3_add(src, rp_v3_scale(rp_v3_sub(thr, src), t));
    }
    if (on[0] && on[1])
        return 0; /* an edge lying on the receiver: D0, not a shadow */
    rp_vec3 a, b;
    if (!clip_to_face(fr, img[0], img[1], tol, &a, &b))
        return 0;
    (void)scene;
    /* Visible pieces, merged into runs. */
    int run = -1;
    for (int i = 0; i <= DISC_PIECES; i++) {
        int vis = 0;
        if (i < DISC_PIECES) {
            double t = (i + 0.5) / DISC_PIECES;
            vis = wedge_visible(rc, w, rp_v3_add(a, rp_v3_scale(rp_v3_sub(b, a), t)), fr->n, eta);
        }
        if (vis && run < 0)
            run = i;
        if (!vis && run >= 0) {
            rp_vec3 ra = rp_v3_add(a, rp_v3_scale(rp_v3_sub(b, a), (double)run / DISC_PIECES));
            rp_vec3 rb = rp_v3_add(a, rp_v3_scale(rp_v3_sub(b, a), (double)i / DISC_PIECES));
            if (seg_push(out, r, w->ev ? RP_DISC_EV : RP_DISC_VE, w->light, ra, rb))
                return -1;
            run = -1;
        }
    }
    return 0;
}

typedef struct xkey {
    double x;
    uint32_t i;
} xkey;

static int by_x(const void *pa, const void *pb)
{
    const xkey *a = pa, *b = pb;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    return a->i < b->i ? -1 : (a->i > b->i);
}

static int find_d1(const rp_scene *scene, const frame2 *frames, double tol, double eta, seg_list *out,
                   unsigned long max_pairs, int *truncated, rp_error *err)
{
    const size_t nf = rp_scene_nfaces(scene);
    const rp_face *F = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    int ret = -1;
    rp_raycast *rc = NULL;
    key_rec *keys = malloc((4 * nf + 1) * sizeof *keys);
    edge_info *edges = malloc((4 * nf + 1) * sizeof *edges);
    unsigned char *cand = NULL;
    uint32_t *wid = NULL;
    xkey *order = NULL;
    size_t *vstart = NULL;
    rp_vec3 *vnorm = NULL;
    unsigned char *recv = calloc(nf + 1, 1);
    if (!keys || !edges || !recv)
        goto done;
    /* Receivers: faces that reflect in some band. */
    for (size_t f = 0; f < nf; f++)
        recv[f] = (unsigned char)face_reflects(scene, (uint32_t)f);
    /* Weld vertices closer than tol, across surfaces (the Cornell box's
     * blocks are five quads each, with their own vertices): edges and
     * corners are found by position. */
    const size_t nvs = rp_scene_nvertices(scene);
    wid = malloc((nvs + 1) * sizeof *wid);
    order = malloc((nvs + 1) * sizeof *order);
    vstart = calloc(nvs + 2, sizeof *vstart);
    vnorm = malloc((4 * nf + 1) * sizeof *vnorm);
    if (!wid || !order || !vstart || !vnorm)
        goto done;
    for (size_t i = 0; i < nvs; i++) {
        wid[i] = (uint32_t)i;
        order[i] = (xkey){V[i].x, (uint32_t)i};
    }
    qsort(order, nvs, sizeof *order, by_x);
    for (size_t i = 0; i < nvs; i++)
        for (size_t j = i + 1; j < nvs && order[j].x - order[i].x <= tol; j++)
            if (rp_v3_length(rp_v3_sub(V[order[i].i], V[order[j].i])) <= tol)
                rp_uf_union(wid, order[i].i, order[j].i);
    for (size_t i = 0; i < nvs; i++)
        wid[i] = rp_uf_find(wid, (uint32_t)i);
    /* The front normals of the faces around each welded vertex. */
    for (size_t f = 0; f < nf; f++)
        for (uint32_t i = 0; i < F[f].nverts; i++)
            vstart[wid[F[f].v[i]] + 2]++;
    for (size_t i = 0; i < nvs; i++)
        vstart[i + 2] += vstart[i + 1];
    for (size_t f = 0; f < nf; f++)
        for (uint32_t i = 0; i < F[f].nverts; i++)
            vnorm[vstart[wid[F[f].v[i]] + 1]++] = F[f].normal;

    size_t nk = 0;
    for (size_t f = 0; f < nf; f++)
        for (uint32_t i = 0; i < F[f].nverts; i++) {
            uint32_t a = wid[F[f].v[i]], b = wid[F[f].v[(i + 1) % F[f].nverts]];
            keys[nk].key = a < b ? ((uint64_t)a << 32) | b : ((uint64_t)b << 32) | a;
            keys[nk].face = (uint32_t)f;
            nk++;
        }
    qsort(keys, nk, sizeof *keys, key_cmp);
    size_t ne = 0;
    for (size_t i = 0; i < nk;) {
        size_t j = i + 1;
        while (j < nk && keys[j].key == keys[i].key)
            j++;
        edges[ne].a = (uint32_t)(keys[i].key >> 32);
        edges[ne].b = (uint32_t)(keys[i].key & 0xffffffffu);
        edges[ne].f0 = keys[i].face;
        /* Exactly two faces: a manifold edge; more (a seam), or one: a
         * boundary edge for the silhouette test. */
        edges[ne].f1 = j - i == 2 ? keys[i + 1].face : RP_NONE;
        ne++;
        i = j;
    }
    if (rp_raycast_create(scene, NULL, &rc, err) != RP_OK) {
        ret = -2;
        goto done;
    }
    cand = malloc(rp_scene_nvertices(scene) + 1);
    if (!cand)
        goto done;

    unsigned long pairs = 0;
    for (size_t l = 0; l < nf; l++) {
        const rp_material *lm = rp_scene_face_material(scene, (uint32_t)l);
        if (!lm->emitter)
            continue;
        const rp_face *L = &F[l];
        rp_vec3 ln = L->normal, lo = V[L->v[0]];
        memset(cand, 0, rp_scene_nvertices(scene) + 1);
        /* EV: light vertex x silhouette edge. */
        for (uint32_t k = 0; k < L->nverts; k++) {
            rp_vec3 v = V[L->v[k]];
            for (size_t e = 0; e < ne; e++) {
                const edge_info *E = &edges[e];
                rp_vec3 p0 = V[E->a], p1 = V[E->b];
                if (fabs(rp_v3_dot(ln, rp_v3_sub(p0, lo))) <= tol && fabs(rp_v3_dot(ln, rp_v3_sub(p1, lo))) <= tol)
                    continue; /* in the light's plane: blocks nothing */
                if (!(rp_v3_dot(ln, rp_v3_sub(p0, lo)) > 0 || rp_v3_dot(ln, rp_v3_sub(p1, lo)) > 0))
                    continue; /* behind the light */
                if (!silhouette(scene, E, v))
                    continue;
                cand[E->a] = cand[E->b] = 1;
                wedge w = {1, v, v, p0, p1, ln, (uint32_t)l, NULL, 0};
                for (size_t r = 0; r < nf; r++) {
                    if (!recv[r] || r == l || r == E->f0 || r == E->f1)
                        continue;
                    if (++pairs > max_pairs) {
                        *truncated = 1;
                        goto out_of_budget;
                    }
                    if (trace_wedge(scene, rc, &frames[r], (uint32_t)r, &w, tol, eta, out))
                        goto done;
                }
            }
        }
        /* VE: silhouette vertex x light edge. */
        for (uint32_t k = 0; k < L->nverts; k++) {
            rp_vec3 q0 = V[L->v[k]], q1 = V[L->v[(k + 1) % L->nverts]];
            for (size_t pv = 0; pv < rp_scene_nvertices(scene); pv++) {
                if (!cand[pv])
                    continue;
                rp_vec3 p = V[pv];
                wedge w = {0, q0, q1, p, p, ln, (uint32_t)l, vnorm + vstart[pv], vstart[pv + 1] - vstart[pv]};
                for (size_t r = 0; r < nf; r++) {
                    if (!recv[r] || r == l)
                        continue;
                    if (fabs(rp_v3_dot(frames[r].n, rp_v3_sub(p, frames[r].o))) <= tol)
                        continue; /* the vertex lies on the receiver */
                    if (++pairs > max_pairs) {
                        *truncated = 1;
                        goto out_of_budget;
                    }
                    if (trace_wedge(scene, rc, &frames[r], (uint32_t)r, &w, tol, eta, out))
                        goto done;
                }
            }
        }
    }
out_of_budget: /* also the end of the loops */
    ret = 0;
done:
    if (ret == -1)
        rp_error_set(err, RP_ERR_NOMEM, "discontinuity: out of memory");
    rp_raycast_destroy(rc);
    free(keys);
    free(edges);
    free(cand);
    free(recv);
    free(wid);
    free(order);
    free(vstart);
    free(vnorm);
    return ret;
}

/* ---- merging and capping ------------------------------------------- */

static double seg_len(const rp_disc_segment *s) { return rp_v3_length(rp_v3_sub(s->b, s->a)); }

/* Distance of p from the line through s. */
static double line_dist(const rp_disc_segment *s, rp_vec3 p)
{
    rp_vec3 d = rp_v3_sub(s->b, s->a);
    double l = rp_v3_length(d);
    return rp_v3_length(rp_v3_cross(d, rp_v3_sub(p, s->a))) / l;
}

static int by_face(const void *pa, const void *pb)
{
    const rp_disc_segment *a = pa, *b = pb;
    if (a->face != b->face)
        return a->face < b->face ? -1 : 1;
    if ((a->kind == RP_DISC_D0) != (b->kind == RP_DISC_D0))
        return a->kind == RP_DISC_D0 ? -1 : 1;
    double la = seg_len(a), lb = seg_len(b);
    return la > lb ? -1 : (la < lb);
}

/* Within one face's run [s, s + n): merges collinear overlapping segments
 * (a D0 segment absorbs a D1 one, whose kind is then lost); returns the
 * new count. */
static size_t merge_run(rp_disc_segment *s, size_t n, double tol)
{
    int changed = 1;
    while (changed) {
        changed = 0;
        for (size_t i = 0; i < n; i++)
            for (size_t j = i + 1; j < n; j++) {
                if (line_dist(&s[i], s[j].a) > tol || line_dist(&s[i], s[j].b) > tol)
                    continue;
                rp_vec3 d = rp_v3_sub(s[i].b, s[i].a);
                double l2 = rp_v3_dot(d, d);
                double ta = rp_v3_dot(rp_v3_sub(s[j].a, s[i].a), d) / l2;
                double tb = rp_v3_dot(rp_v3_sub(s[j].b, s[i].a), d) / l2;
                double lo = fmin(ta, tb), hi = fmax(ta, tb);
                double slack = tol / sqrt(l2);
                if (lo > 1 + slack || hi < -slack)
                    continue; /* collinear but apart */
                if (s[j].kind == RP_DISC_D0)
                    s[i].kind = RP_DISC_D0;
                rp_vec3 a0 = s[i].a;
                if (lo < 0)
                    s[i].a = rp_v3_add(a0, rp_v3_scale(d, lo));
                if (hi > 1)
                    s[i].b = rp_v3_add(a0, rp_v3_scale(d, hi));
                s[j] = s[--n];
                j--;
                changed = 1;
            }
    }
    return n;
}

double rp_disc_scale(const rp_scene *scene)
{
    const size_t nf = rp_scene_nfaces(scene), nb = rp_scene_nbands(scene);
    const rp_face *F = rp_scene_faces(scene);
    const rp_vec3 *V = rp_scene_vertices(scene);
    rp_vec3 lo = rp_v3(INFINITY, INFINITY, INFINITY), hi = rp_v3(-INFINITY, -INFINITY, -INFINITY);
    for (size_t f = 0; f < nf; f++) {
        const rp_material *m = rp_scene_face_material(scene, (uint32_t)f);
        int lit = 0;
        for (size_t k = 0; k < nb; k++)
            lit |= m->rho[k] > 0 || m->Le[k] > 0;
        if (!lit)
            continue;
        for (uint32_t i = 0; i < F[f].nverts; i++) {
            rp_vec3 p = V[F[f].v[i]];
            lo = rp_v3(fmin(lo.x, p.x), fmin(lo.y, p.y), fmin(lo.z, p.z));
            hi = rp_v3(fmax(hi.x, p.x), fmax(hi.y, p.y), fmax(hi.z, p.z));
        }
    }
    double d = lo.x <= hi.x ? rp_v3_length(rp_v3_sub(hi, lo)) : 0;
    return d > 0 ? d : rp_scene_diagonal(scene);
}

rp_status rp_disc_find(const rp_scene *scene, const rp_disc_params *params, rp_disc_segment **out,
                       size_t *count, rp_error *err)
{
    if (!scene || !out || !count)
        return rp_error_set(err, RP_ERR_INPUT, "discontinuity: no scene or no output");
    *out = NULL;
    *count = 0;
    rp_disc_params p = {.size = sizeof p, .max_per_face = RP_DISC_DEFAULT_MAX_PER_FACE};
    if (params) {
        if (params->size != sizeof *params)
            return rp_error_set(err, RP_ERR_INPUT, "discontinuity: params.size %zu is not %zu", params->size,
                                sizeof *params);
        p = *params;
        if (p.max_per_face == 0)
            p.max_per_face = RP_DISC_DEFAULT_MAX_PER_FACE;
    }
    if (p.truncated)
        *p.truncated = 0;
    const size_t nf = rp_scene_nfaces(scene);
    const double diag = rp_disc_scale(scene);
    const double tol = RP_DISC_REL_TOL * diag;
    /* Rays start and stop this far from the wedge's points. */
    const double eta = 1e-6 * diag;
    frame2 *frames = malloc((nf + 1) * sizeof *frames);
    seg_list l = {0};
    if (!frames)
        return rp_error_set(err, RP_ERR_NOMEM, "discontinuity: out of memory");
    for (size_t f = 0; f < nf; f++)
        frame_make(scene, (uint32_t)f, &frames[f]);
    if (!p.no_d0 && (find_d0(scene, frames, tol, &l) || find_gap(scene, frames, tol, &l))) {
        free(frames);
        free(l.s);
        return rp_error_set(err, RP_ERR_NOMEM, "discontinuity: out of memory");
    }
    if (!p.no_d1) {
        int truncated = 0;
        int r = find_d1(scene, frames, tol, eta, &l, p.max_pairs ? p.max_pairs : RP_DISC_MAX_PAIRS, &truncated,
                        err);
        if (p.truncated)
            *p.truncated = truncated;
        if (r) {
            free(frames);
            free(l.s);
            return r == -2 ? RP_ERR_RUNTIME : RP_ERR_NOMEM;
        }
    }
    free(frames);
    /* Per face: merge, then keep the D0 and GAP segments and the longest D1
     * ones. */
    if (l.n) /* (l.s is NULL when nothing was found) */
        qsort(l.s, l.n, sizeof *l.s, by_face);
    size_t w = 0;
    for (size_t i = 0; i < l.n;) {
        size_t j = i;
        while (j < l.n && l.s[j].face == l.s[i].face)
            j++;
        size_t n = merge_run(l.s + i, j - i, tol);
        qsort(l.s + i, n, sizeof *l.s, by_face);
        size_t d1 = 0;
        for (size_t k = i; k < i + n; k++) {
            if (l.s[k].kind != RP_DISC_D0 && l.s[k].kind != RP_DISC_GAP && d1++ >= p.max_per_face)
                continue;
            l.s[w++] = l.s[k];
        }
        i = j;
    }
    l.n = w;
    *out = l.s;
    *count = l.n;
    return RP_OK;
}
