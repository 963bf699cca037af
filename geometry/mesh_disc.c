/* Discontinuity meshes (mesh.h, RP_MESH_DISCONTINUITY).
 *
 * Heckbert 1992 ("Discontinuity meshing for radiosity") and Lischinski,
 * Tampieri & Greenberg 1992 ("Discontinuity meshing for accurate
 * radiosity"): elements whose edges follow the lines where radiosity or
 * its derivatives jump, so that no element straddles a shadow boundary or
 * a contact line and a piecewise constant (or linear) basis fits the
 * smooth pieces.  The segments come from discontinuity.c; each face is
 * triangulated in its own plane by CGAL's constrained Delaunay
 * triangulation (cgal/cdt.h) with:
 *
 *   - its boundary: the welded corners, points every h along each edge
 *     (as in the uniform mesh, from the unique edge, so faces of one
 *     surface that share an edge share its points) and the points where
 *     segments of any face of the surface end on that edge;
 *   - every segment, cut into pieces no longer than h, as constraints;
 *   - Steiner points on an equilateral lattice of spacing h, left out
 *     within 0.45 h of the boundary and of every segment.
 *
 * With a target count, h starts from the lattice's element area
 * (sqrt(3)/4 h^2 per triangle) and is rescaled by sqrt(count / target) up
 * to DISC_CALIBRATIONS times.  Faces black in every band get their corners
 * only (one or two triangles), as they get one element in the uniform mesh.
 * The mesh stays conforming inside each surface: no segment endpoint or
 * Steiner point lies on a shared edge unless it is one of that edge's
 * points, which both faces use. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cgal/cdt.h"
#include "discontinuity.h"
#include "mesh_internal.h"

#define DISC_CALIBRATIONS 4
/* Stop calibrating within this fraction of the target. */
#define DISC_COUNT_SLACK 0.03
/* Steiner points keep this many h away from the boundary and segments. */
#define DISC_CLEARANCE 0.45

typedef struct darr {
    void *p;
    size_t n, cap, elsize;
} darr;

static void *darr_push(darr *a)
{
    if (a->n == a->cap) {
        size_t cap = a->cap ? 2 * a->cap : 64;
        void *p = realloc(a->p, cap * a->elsize);
        if (!p)
            return NULL;
        a->p = p;
        a->cap = cap;
    }
    return (char *)a->p + a->elsize * a->n++;
}

/* An endpoint of a segment on a face: inside, at a corner, or on an edge
 * at parameter s (from corner e to corner e + 1). */
typedef struct endpt {
    double x, y;
    int where;  /* 0 inside, 1 corner e, 2 edge e */
    int e;
    double s;
} endpt;

typedef struct fseg {
    endpt a, b;
} fseg;

typedef struct snap {
    uint32_t ue;
    double t; /* along the unique edge, ue_a -> ue_b */
} snap;

static int snap_cmp(const void *pa, const void *pb)
{
    const snap *a = pa, *b = pb;
    if (a->ue != b->ue)
        return a->ue < b->ue ? -1 : 1;
    return a->t < b->t ? -1 : (a->t > b->t);
}

typedef struct dface {
    rp_vec3 o, ax, ay;
    double xy[8];
    int nv;
    double orient;
    int black;
    size_t seg0, nseg; /* into the fseg array */
} dface;

static void p2(const dface *d, rp_vec3 p, double *x, double *y)
{
    rp_vec3 q = rp_v3_sub(p, d->o);
    *x = rp_v3_dot(q, d->ax);
    *y = rp_v3_dot(q, d->ay);
}

static rp_vec3 p3(const dface *d, double x, double y)
{
    return rp_v3_add(d->o, rp_v3_add(rp_v3_scale(d->ax, x), rp_v3_scale(d->ay, y)));
}

/* Distance of (x, y) from segment (ax, ay)-(bx, by). */
static double seg_dist(double x, double y, double ax, double ay, double bx, double by)
{
    double dx = bx - ax, dy = by - ay, l2 = dx * dx + dy * dy;
    double t = l2 > 0 ? ((x - ax) * dx + (y - ay) * dy) / l2 : 0;
    t = t < 0 ? 0 : (t > 1 ? 1 : t);
    return hypot(x - ax - t * dx, y - ay - t * dy);
}

/* Snaps an endpoint to the face's boundary when within tol of it. */
static void classify(const dface *d, double tol, endpt *p)
{
    p->where = 0;
    for (int i = 0; i < d->nv; i++) {
        int j = (i + 1) % d->nv;
        double ex = d->xy[2 * j] - d->xy[2 * i], ey = d->xy[2 * j + 1] - d->xy[2 * i + 1];
        double l = hypot(ex, ey);
        double s = ((p->x - d->xy[2 * i]) * ex + (p->y - d->xy[2 * i + 1]) * ey) / (l * l);
        double dist = fabs(ex * (p->y - d->xy[2 * i + 1]) - ey * (p->x - d->xy[2 * i])) / l;
        if (dist > tol || s * l < -tol || (1 - s) * l < -tol)
            continue;
        if (s * l <= tol) {
            p->where = 1;
            p->e = i;
        } else if ((1 - s) * l <= tol) {
            p->where = 1;
            p->e = j;
        } else {
            p->where = 2;
            p->e = i;
            p->s = s;
        }
        return;
    }
}

typedef struct built {
    rp_element *el;
    size_t nel;
    rp_vec3 *v;
    size_t nv;
    uint32_t *first, *count; /* per face */
} built;

static void built_free(built *b)
{
    free(b->el);
    free(b->v);
    free(b->first);
    free(b->count);
    memset(b, 0, sizeof *b);
}

typedef struct ctx {
    const rp_scene *scene;
    const rp_mesh_weld *w;
    const face_grid *fg;
    size_t nfaces;
    dface *df;
    fseg *segs;
    snap *snaps;
    size_t nsnaps;
    unsigned char *ue_black;
    double tol;
} ctx;

/* A segment end that lies on another segment (within tol, away from its
 * ends) splits it there: traces meeting at the image of one occluder
 * vertex then share that point exactly, instead of CGAL constructing
 * crossings a rounding error apart (coincident vertices, slivers).  The
 * face's segments are the last d->nseg of c->segs[0, *ns). */
static int split_t_junctions(ctx *c, dface *d, size_t *ns, size_t *cap)
{
    int changed = 1;
    for (int round = 0; changed && round < 8; round++) {
        changed = 0;
        for (size_t i = d->seg0; i < *ns; i++)
            for (int k = 0; k < 2; k++) {
                const endpt p = k ? c->segs[i].b : c->segs[i].a;
                for (size_t j = d->seg0; j < *ns; j++) {
                    if (j == i)
                        continue;
                    fseg *g = &c->segs[j];
                    double dx = g->b.x - g->a.x, dy = g->b.y - g->a.y, l = hypot(dx, dy);
                    if (!(l > 2 * c->tol))
                        continue;
                    double t = ((p.x - g->a.x) * dx + (p.y - g->a.y) * dy) / (l * l);
                    if (t * l <= c->tol || (1 - t) * l <= c->tol)
                        continue;
                    if (fabs(dx * (p.y - g->a.y) - dy * (p.x - g->a.x)) / l > c->tol)
                        continue;
                    if (*ns == *cap) {
                        fseg *ng = realloc(c->segs, 2 * *cap * sizeof *ng);
                        if (!ng)
                            return -1;
                        c->segs = ng;
                        *cap *= 2;
                        g = &c->segs[j];
                    }
                    fseg tail = {p, g->b};
                    g->b = p;
                    c->segs[(*ns)++] = tail;
                    changed = 1;
                }
            }
    }
    d->nseg = *ns - d->seg0;
    return 0;
}

/* One mesh for spacing h. */
static rp_status build(const ctx *c, double h, built *out, rp_error *err)
{
    rp_status st = RP_OK;
    const rp_mesh_weld *w = c->w;
    const rp_face *sf = rp_scene_faces(c->scene);
    darr V = {.elsize = sizeof(rp_vec3)}, E = {.elsize = sizeof(rp_element)};
    darr pts = {.elsize = 2 * sizeof(double)}, cons = {.elsize = 2 * sizeof(uint32_t)};
    darr loopv = {.elsize = sizeof(uint32_t)}, loope = {.elsize = sizeof(double) * 2};
    size_t *ue_start = calloc(w->nue + 1, sizeof *ue_start);
    darr uep = {.elsize = sizeof(double)}, uev = {.elsize = sizeof(uint32_t)};
    int64_t *newid = NULL;
    size_t newid_cap = 0;
    rp_cdt_output co = {0};
    memset(out, 0, sizeof *out);
    out->first = calloc(c->nfaces + 1, sizeof *out->first);
    out->count = calloc(c->nfaces + 1, sizeof *out->count);
    if (!ue_start || !out->first || !out->count)
        goto nomem;
    for (size_t i = 0; i < w->nweld; i++) {
        rp_vec3 *p = darr_push(&V);
        if (!p)
            goto nomem;
        *p = w->wpos[i];
    }
    /* Points of each unique edge: every h, and where segments end. */
    size_t si = 0;
    for (size_t u = 0; u < w->nue; u++) {
        ue_start[u] = uep.n;
        rp_vec3 a = w->wpos[w->ue_a[u]], b = w->wpos[w->ue_b[u]];
        double len = rp_v3_length(rp_v3_sub(b, a));
        double cnt = c->ue_black[u] ? 1 : ceil(len / h * (1 - 1e-12));
        if (cnt < 1)
            cnt = 1;
        if (cnt > 1e7) {
            st = rp_error_set(err, RP_ERR_INPUT, "mesh: discontinuity spacing %g cuts an edge %.0f times", h, cnt);
            goto fail;
        }
        size_t s0 = si;
        while (si < c->nsnaps && c->snaps[si].ue == u)
            si++;
        double tolp = c->tol / len;
        /* Merge the edge's own points with the snapped ones, ascending. */
        size_t k = s0;
        double last = 0;
        for (uint32_t s = 1; s <= (uint32_t)cnt; s++) {
            double t = s / cnt;
            while (k < si && c->snaps[k].t <= t + 1e-15) {
                double ts = c->snaps[k++].t;
                if (ts - last > tolp && ts < 1 - tolp) {
                    double *q = darr_push(&uep);
                    if (!q)
                        goto nomem;
                    *q = last = ts;
                }
            }
            if (s == (uint32_t)cnt)
                break;
            /* A grid point near a snapped one gives way to it. */
            int near = 0;
            for (size_t m = s0; m < si; m++)
                if (fabs(c->snaps[m].t - t) < 0.3 / cnt)
                    near = 1;
            if (!near && t - last > tolp) {
                double *q = darr_push(&uep);
                if (!q)
                    goto nomem;
                *q = last = t;
            }
        }
        for (size_t m = ue_start[u]; m < uep.n; m++) {
            double t = ((double *)uep.p)[m];
            rp_vec3 *p = darr_push(&V);
            uint32_t *id = darr_push(&uev);
            if (!p || !id)
                goto nomem;
            *id = (uint32_t)(V.n - 1);
            *p = rp_v3_add(rp_v3_scale(a, 1 - t), rp_v3_scale(b, t));
        }
    }
    ue_start[w->nue] = uep.n;

    for (size_t f = 0; f < c->nfaces; f++) {
        const dface *d = &c->df[f];
        out->first[f] = (uint32_t)E.n;
        pts.n = cons.n = loopv.n = loope.n = 0;
        /* The boundary loop: corner, then the edge's points in the face's
         * direction; loope holds (edge, s) of each loop point. */
        size_t corner_at[4];
        for (int i = 0; i < d->nv; i++) {
            uint32_t u = w->edge_of[4 * f + i];
            int fwd = w->wid[4 * f + i] == w->ue_a[u];
            corner_at[i] = loopv.n;
            uint32_t *id = darr_push(&loopv);
            double *le = darr_push(&loope);
            if (!id || !le)
                goto nomem;
            *id = w->wid[4 * f + i];
            le[0] = i;
            le[1] = 0;
            size_t n = ue_start[u + 1] - ue_start[u];
            for (size_t k = 0; k < n; k++) {
                size_t m = fwd ? ue_start[u] + k : ue_start[u + 1] - 1 - k;
                double t = ((double *)uep.p)[m];
                id = darr_push(&loopv);
                le = darr_push(&loope);
                if (!id || !le)
                    goto nomem;
                *id = ((uint32_t *)uev.p)[m];
                le[0] = i;
                le[1] = fwd ? t : 1 - t;
            }
        }
        const size_t nb = loopv.n;
        for (size_t k = 0; k < nb; k++) {
            double *q = darr_push(&pts);
            if (!q)
                goto nomem;
            p2(d, ((rp_vec3 *)V.p)[((uint32_t *)loopv.p)[k]], &q[0], &q[1]);
        }
        /* Segments: endpoints (loop points or interior points), then
         * pieces of at most h. */
        for (size_t s = 0; s < d->nseg; s++) {
            const fseg *g = &c->segs[d->seg0 + s];
            uint32_t ends[2];
            for (int k = 0; k < 2; k++) {
                const endpt *e = k ? &g->b : &g->a;
                if (e->where == 1) {
                    ends[k] = (uint32_t)corner_at[e->e];
                } else if (e->where == 2) {
                    size_t best = 0;
                    double bd = INFINITY;
                    for (size_t m = 0; m < nb; m++) {
                        const double *le = (double *)loope.p + 2 * m;
                        if ((int)le[0] == e->e && fabs(le[1] - e->s) < bd) {
                            bd = fabs(le[1] - e->s);
                            best = m;
                        }
                    }
                    ends[k] = (uint32_t)best;
                } else {
                    size_t m;
                    for (m = nb; m < pts.n; m++) {
                        const double *q = (double *)pts.p + 2 * m;
                        if (hypot(q[0] - e->x, q[1] - e->y) <= c->tol)
                            break;
                    }
                    if (m == pts.n) {
                        double *q = darr_push(&pts);
                        if (!q)
                            goto nomem;
                        q[0] = e->x;
                        q[1] = e->y;
                    }
                    ends[k] = (uint32_t)m;
                }
            }
            if (ends[0] == ends[1])
                continue;
            double ax = ((double *)pts.p)[2 * ends[0]], ay = ((double *)pts.p)[2 * ends[0] + 1];
            double bx = ((double *)pts.p)[2 * ends[1]], by = ((double *)pts.p)[2 * ends[1] + 1];
            double n = ceil(hypot(bx - ax, by - ay) / h);
            if (n < 1)
                n = 1;
            if (n > 1e6)
                n = 1e6;
            uint32_t prev = ends[0];
            for (uint32_t k = 1; k <= (uint32_t)n; k++) {
                uint32_t cur = ends[1];
                if (k < (uint32_t)n) {
                    double *q = darr_push(&pts);
                    if (!q)
                        goto nomem;
                    q[0] = ax + (bx - ax) * k / n;
                    q[1] = ay + (by - ay) * k / n;
                    cur = (uint32_t)(pts.n - 1);
                }
                uint32_t *cc = darr_push(&cons);
                if (!cc)
                    goto nomem;
                cc[0] = prev;
                cc[1] = cur;
                prev = cur;
            }
        }
        /* Steiner points on an equilateral lattice. */
        if (!d->black) {
            double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
            for (int i = 0; i < d->nv; i++) {
                xmin = fmin(xmin, d->xy[2 * i]);
                xmax = fmax(xmax, d->xy[2 * i]);
                ymin = fmin(ymin, d->xy[2 * i + 1]);
                ymax = fmax(ymax, d->xy[2 * i + 1]);
            }
            const double dy = h * sqrt(3.0) / 2, clr = DISC_CLEARANCE * h;
            double rows = ceil((ymax - ymin) / dy), cols = ceil((xmax - xmin) / h) + 1;
            if (rows * cols > 4.0 * RP_MESH_MAX_ELEMENTS) {
                st = rp_error_set(err, RP_ERR_INPUT, "mesh: discontinuity spacing %g gives %.0f points on face %zu",
                                  h, rows * cols, f);
                goto fail;
            }
            for (double j = 0; j <= rows; j++) {
                double y = ymin + j * dy;
                double off = fmod(j, 2.0) * 0.5 * h;
                for (double i = 0; i <= cols; i++) {
                    double x = xmin + off + i * h;
                    int ok = 1;
                    for (int k = 0; k < d->nv && ok; k++) {
                        int l = (k + 1) % d->nv;
                        double ex = d->xy[2 * l] - d->xy[2 * k], ey = d->xy[2 * l + 1] - d->xy[2 * k + 1];
                        double in = d->orient * (ex * (y - d->xy[2 * k + 1]) - ey * (x - d->xy[2 * k])) /
                                    hypot(ex, ey);
                        ok = in >= clr;
                    }
                    for (size_t s = 0; s < cons.n && ok; s++) {
                        const uint32_t *cc = (uint32_t *)cons.p + 2 * s;
                        const double *qa = (double *)pts.p + 2 * cc[0], *qb = (double *)pts.p + 2 * cc[1];
                        ok = seg_dist(x, y, qa[0], qa[1], qb[0], qb[1]) >= clr;
                    }
                    if (!ok)
                        continue;
                    double *q = darr_push(&pts);
                    if (!q)
                        goto nomem;
                    q[0] = x;
                    q[1] = y;
                }
            }
        }
        rp_cdt_input ci = {pts.p, pts.n, nb, cons.p, cons.n};
        char msg[256];
        if (rp_cgal_cdt(&ci, &co, msg, sizeof msg)) {
            st = rp_error_set(err, RP_ERR_RUNTIME, "mesh: face %zu: %s", f, msg);
            goto fail;
        }
        if (pts.n > newid_cap) {
            free(newid);
            newid_cap = pts.n;
            if (!(newid = malloc(newid_cap * sizeof *newid)))
                goto nomem;
        }
        for (size_t k = 0; k < pts.n; k++)
            newid[k] = -1;
        uint32_t *vmap = malloc((co.nvertices ? co.nvertices : 1) * sizeof *vmap);
        if (!vmap)
            goto nomem;
        for (size_t k = 0; k < co.nvertices; k++) {
            int64_t in = co.input[k];
            if (in >= 0 && (size_t)in < nb) {
                vmap[k] = ((uint32_t *)loopv.p)[in];
                continue;
            }
            if (in >= 0 && newid[in] >= 0) {
                vmap[k] = (uint32_t)newid[in];
                continue;
            }
            rp_vec3 *p = darr_push(&V);
            if (!p) {
                free(vmap);
                goto nomem;
            }
            *p = p3(d, co.xy[2 * k], co.xy[2 * k + 1]);
            vmap[k] = (uint32_t)(V.n - 1);
            if (in >= 0)
                newid[in] = vmap[k];
        }
        const rp_vec3 *VV = V.p;
        for (size_t t = 0; t < co.ntriangles; t++) {
            uint32_t a = vmap[co.tri[3 * t]], b = vmap[co.tri[3 * t + 1]], cc = vmap[co.tri[3 * t + 2]];
            VV = V.p;
            rp_vec3 nrm = rp_v3_cross(rp_v3_sub(VV[b], VV[a]), rp_v3_sub(VV[cc], VV[a]));
            double s = rp_v3_dot(nrm, c->fg[f].normal);
            if (!(s != 0))
                continue; /* a degenerate triangle (collinear crossing points) */
            if (s < 0) {
                uint32_t tmp = b;
                b = cc;
                cc = tmp;
            }
            rp_element *el = darr_push(&E);
            if (!el) {
                free(vmap);
                goto nomem;
            }
            el->v[0] = a;
            el->v[1] = b;
            el->v[2] = cc;
            el->v[3] = RP_NONE;
            el->nverts = 3;
            el->face = (uint32_t)f;
            el->surface = sf[f].surface;
            el->normal = c->fg[f].normal;
            el->area = 0.5 * fabs(s);
            el->centroid = rp_v3_scale(rp_v3_add(rp_v3_add(VV[a], VV[b]), VV[cc]), 1.0 / 3.0);
        }
        free(vmap);
        rp_cdt_output_free(&co);
        out->count[f] = (uint32_t)(E.n - out->first[f]);
        if (E.n > RP_MESH_MAX_ELEMENTS || V.n > UINT32_MAX - 1) {
            st = rp_error_set(err, RP_ERR_INPUT,
                              "mesh: discontinuity spacing %g gives more than %zu elements (memory)", h,
                              (size_t)RP_MESH_MAX_ELEMENTS);
            goto fail;
        }
    }
    out->el = E.p;
    out->nel = E.n;
    out->v = V.p;
    out->nv = V.n;
    E.p = V.p = NULL;
    goto done;
nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
fail:
    built_free(out);
done:
    rp_cdt_output_free(&co);
    free(E.p);
    free(V.p);
    free(pts.p);
    free(cons.p);
    free(loopv.p);
    free(loope.p);
    free(uep.p);
    free(uev.p);
    free(ue_start);
    free(newid);
    return st;
}

/* Buckets [a0, a1] x [b0, b1] met by element e's bounding box. */
static void element_buckets(const rp_mesh *mesh, const face_grid *fg, uint32_t e, uint32_t r[4])
{
    const rp_element *el = &mesh->elements[e];
    double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    for (int k = 0; k < 3; k++) {
        rp_vec3 q = rp_v3_sub(mesh->vertices[el->v[k]], fg->c[0]);
        double x = rp_v3_dot(q, fg->ax), y = rp_v3_dot(q, fg->ay);
        x0 = fmin(x0, x);
        x1 = fmax(x1, x);
        y0 = fmin(y0, y);
        y1 = fmax(y1, y);
    }
    double v[4] = {floor((x0 - fg->x0) / fg->cell), floor((x1 - fg->x0) / fg->cell),
                   floor((y0 - fg->y0) / fg->cell), floor((y1 - fg->y0) / fg->cell)};
    for (int k = 0; k < 4; k++) {
        uint32_t n = k < 2 ? fg->gx : fg->gy;
        r[k] = !(v[k] > 0) ? 0 : (v[k] >= n ? n - 1 : (uint32_t)v[k]);
    }
}

/* Bucket grid of one triangulated face for rp_mesh_locate: about one
 * bucket per element over the face's bounding box. */
static int face_buckets(rp_mesh *mesh, face_grid *fg)
{
    double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
    for (uint32_t i = 0; i < fg->nverts; i++) {
        rp_vec3 q = rp_v3_sub(fg->c[i], fg->c[0]);
        double x = rp_v3_dot(q, fg->ax), y = rp_v3_dot(q, fg->ay);
        xmin = fmin(xmin, x);
        xmax = fmax(xmax, x);
        ymin = fmin(ymin, y);
        ymax = fmax(ymax, y);
    }
    double wdt = xmax - xmin, hgt = ymax - ymin;
    double cell = sqrt(wdt * hgt / (fg->count ? fg->count : 1));
    if (!(cell > 0))
        cell = fmax(wdt, hgt) > 0 ? fmax(wdt, hgt) : 1;
    double gx = ceil(wdt / cell), gy = ceil(hgt / cell);
    gx = gx < 1 ? 1 : (gx > 2048 ? 2048 : gx);
    gy = gy < 1 ? 1 : (gy > 2048 ? 2048 : gy);
    fg->gx = (uint32_t)gx;
    fg->gy = (uint32_t)gy;
    fg->cell = fmax(wdt / gx, hgt / gy);
    if (!(fg->cell > 0))
        fg->cell = 1;
    fg->x0 = xmin;
    fg->y0 = ymin;
    const size_t nc = (size_t)fg->gx * fg->gy;
    fg->bstart = calloc(nc + 1, sizeof *fg->bstart);
    if (!fg->bstart)
        return -1;
    uint32_t r[4];
    for (uint32_t e = fg->first; e < fg->first + fg->count; e++) {
        element_buckets(mesh, fg, e, r);
        for (uint32_t j = r[2]; j <= r[3]; j++)
            for (uint32_t i = r[0]; i <= r[1]; i++)
                fg->bstart[(size_t)j * fg->gx + i + 1]++;
    }
    for (size_t k = 0; k < nc; k++)
        fg->bstart[k + 1] += fg->bstart[k];
    fg->belems = malloc((fg->bstart[nc] ? fg->bstart[nc] : 1) * sizeof *fg->belems);
    uint32_t *cur = malloc((nc ? nc : 1) * sizeof *cur);
    if (!fg->belems || !cur) {
        free(cur);
        return -1;
    }
    memcpy(cur, fg->bstart, nc * sizeof *cur);
    for (uint32_t e = fg->first; e < fg->first + fg->count; e++) {
        element_buckets(mesh, fg, e, r);
        for (uint32_t j = r[2]; j <= r[3]; j++)
            for (uint32_t i = r[0]; i <= r[1]; i++)
                fg->belems[cur[(size_t)j * fg->gx + i]++] = e;
    }
    free(cur);
    return 0;
}

/* Smallest barycentric coordinate of (x, y) in element e (2-D frame of fg). */
static double min_bary(const rp_mesh *mesh, const face_grid *fg, uint32_t e, double x, double y)
{
    const rp_element *el = &mesh->elements[e];
    double px[3], py[3];
    for (int k = 0; k < 3; k++) {
        rp_vec3 q = rp_v3_sub(mesh->vertices[el->v[k]], fg->c[0]);
        px[k] = rp_v3_dot(q, fg->ax);
        py[k] = rp_v3_dot(q, fg->ay);
    }
    double det = (px[1] - px[0]) * (py[2] - py[0]) - (px[2] - px[0]) * (py[1] - py[0]);
    if (det == 0)
        return -INFINITY;
    double l1 = ((x - px[0]) * (py[2] - py[0]) - (px[2] - px[0]) * (y - py[0])) / det;
    double l2 = ((px[1] - px[0]) * (y - py[0]) - (x - px[0]) * (py[1] - py[0])) / det;
    return fmin(1 - l1 - l2, fmin(l1, l2));
}

uint32_t rp_mesh_locate_disc(const rp_mesh *mesh, const face_grid *fg, rp_vec3 p)
{
    if (fg->count == 0)
        return RP_NONE;
    rp_vec3 q = rp_v3_sub(p, fg->c[0]);
    double x = rp_v3_dot(q, fg->ax), y = rp_v3_dot(q, fg->ay);
    double fi = floor((x - fg->x0) / fg->cell), fj = floor((y - fg->y0) / fg->cell);
    uint32_t i = !(fi > 0) ? 0 : (fi >= fg->gx ? fg->gx - 1 : (uint32_t)fi);
    uint32_t j = !(fj > 0) ? 0 : (fj >= fg->gy ? fg->gy - 1 : (uint32_t)fj);
    size_t cidx = (size_t)j * fg->gx + i;
    uint32_t best = RP_NONE;
    double bb = -INFINITY;
    for (uint32_t k = fg->bstart[cidx]; k < fg->bstart[cidx + 1]; k++) {
        double b = min_bary(mesh, fg, fg->belems[k], x, y);
        if (b > bb) {
            bb = b;
            best = fg->belems[k];
        }
    }
    if (best != RP_NONE && bb >= -1e-9)
        return best;
    /* Outside every bucketed element (a point just off the face): the
     * nearest of all the face's elements. */
    for (uint32_t e = fg->first; e < fg->first + fg->count; e++) {
        double b = min_bary(mesh, fg, e, x, y);
        if (b > bb) {
            bb = b;
            best = e;
        }
    }
    return best;
}

rp_status rp_mesh_build_disc(rp_mesh *mesh, const rp_scene *scene, const rp_mesh_weld *w, double max_edge,
                             size_t target, size_t max_per_face, rp_error *err)
{
    const size_t nf = mesh->nfaces;
    const rp_face *sf = rp_scene_faces(scene);
    const size_t nbands = rp_scene_nbands(scene);
    rp_status st;
    rp_disc_segment *ds = NULL;
    size_t nds = 0;
    ctx c = {scene, w, mesh->faces, nf, NULL, NULL, NULL, 0, NULL, RP_DISC_REL_TOL * rp_disc_scale(scene)};
    built best = {0}, cur = {0};
    rp_disc_params dp = {.size = sizeof dp, .max_per_face = max_per_face, .truncated = &mesh->disc_truncated};
    if ((st = rp_disc_find(scene, &dp, &ds, &nds, err)) != RP_OK)
        return st;
    c.df = calloc(nf + 1, sizeof *c.df);
    size_t segcap = nds + 1;
    c.segs = malloc(segcap * sizeof *c.segs);
    c.snaps = malloc((2 * nds + 1) * sizeof *c.snaps);
    c.ue_black = calloc(w->nue + 1, 1);
    if (!c.df || !c.segs || !c.snaps || !c.ue_black) {
        st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
        goto done;
    }
    double lit_area = 0;
    size_t black_elements = 0;
    for (size_t f = 0; f < nf; f++) {
        dface *d = &c.df[f];
        face_grid *fg = &mesh->faces[f];
        d->o = fg->c[0];
        rp_v3_basis(fg->normal, &d->ax, &d->ay);
        fg->ax = d->ax;
        fg->ay = d->ay;
        fg->triangulated = 1;
        d->nv = (int)fg->nverts;
        double a2 = 0;
        for (int i = 0; i < d->nv; i++)
            p2(d, fg->c[i], &d->xy[2 * i], &d->xy[2 * i + 1]);
        for (int i = 0; i < d->nv; i++) {
            int j = (i + 1) % d->nv;
            a2 += d->xy[2 * i] * d->xy[2 * j + 1] - d->xy[2 * j] * d->xy[2 * i + 1];
        }
        d->orient = a2 >= 0 ? 1 : -1;
        const rp_material *m = rp_scene_face_material(scene, (uint32_t)f);
        int lit = 0;
        for (size_t b = 0; b < nbands; b++)
            lit |= m->rho[b] > 0 || m->Le[b] > 0;
        d->black = !lit;
        for (int i = 0; i < d->nv; i++)
            if (d->black)
                c.ue_black[w->edge_of[4 * f + i]] = 1;
        if (d->black)
            black_elements += d->nv == 4 ? 2 : 1;
        else
            lit_area += sf[f].area;
    }
    /* Segments per face, endpoints snapped to the boundary. */
    size_t ns = 0;
    for (size_t k = 0; k < nds;) {
        uint32_t f = ds[k].face;
        dface *d = &c.df[f];
        d->seg0 = ns;
        for (; k < nds && ds[k].face == f; k++) {
            if (d->black)
                continue;
            fseg g;
            p2(d, ds[k].a, &g.a.x, &g.a.y);
            p2(d, ds[k].b, &g.b.x, &g.b.y);
            classify(d, c.tol, &g.a);
            classify(d, c.tol, &g.b);
            /* Both ends on one edge (or its corners): the boundary already. */
            int ea = g.a.where == 2 ? g.a.e : -1, eb = g.b.where == 2 ? g.b.e : -1;
            if (g.a.where && g.b.where) {
                int same = 0;
                for (int i = 0; i < d->nv; i++) {
                    int j = (i + 1) % d->nv;
                    int ona = (g.a.where == 2 && g.a.e == i) || (g.a.where == 1 && (g.a.e == i || g.a.e == j));
                    int onb = (g.b.where == 2 && g.b.e == i) || (g.b.where == 1 && (g.b.e == i || g.b.e == j));
                    same |= ona && onb;
                }
                if (same)
                    continue;
            }
            for (int e2 = 0; e2 < 2; e2++) {
                int e = e2 ? eb : ea;
                if (e < 0)
                    continue;
                double s = e2 ? g.b.s : g.a.s;
                uint32_t u = w->edge_of[4 * f + e];
                c.snaps[c.nsnaps].ue = u;
                c.snaps[c.nsnaps].t = w->wid[4 * f + e] == w->ue_a[u] ? s : 1 - s;
                c.nsnaps++;
            }
            /* split_t_junctions may have used the room the faces before
             * this one left */
            if (ns == segcap) {
                fseg *ng = realloc(c.segs, 2 * segcap * sizeof *ng);
                if (!ng) {
                    st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
                    goto done;
                }
                c.segs = ng;
                segcap *= 2;
            }
            c.segs[ns++] = g;
        }
        d->nseg = ns - d->seg0;
        if (split_t_junctions(&c, d, &ns, &segcap)) {
            st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
            goto done;
        }
    }
    qsort(c.snaps, c.nsnaps, sizeof *c.snaps, snap_cmp);

    const double lattice = sqrt(3.0) / 4.0; /* element area / h^2 */
    double h = max_edge;
    if (!(h > 0)) {
        double lit_target = target > black_elements + 1 ? (double)(target - black_elements) : 1.0;
        h = lit_area > 0 ? sqrt(lit_area / (lattice * lit_target)) : 1.0;
        double best_err = INFINITY;
        for (int it = 0; it < DISC_CALIBRATIONS; it++) {
            if ((st = build(&c, h, &cur, err)) != RP_OK)
                goto done;
            double nlit = (double)cur.nel - (double)black_elements;
            double e = fabs(nlit - lit_target) / lit_target;
            if (e < best_err) {
                built_free(&best);
                best = cur;
                best_err = e;
                mesh->max_edge = h;
            } else {
                built_free(&cur);
            }
            memset(&cur, 0, sizeof cur);
            if (e <= DISC_COUNT_SLACK || !(nlit > 0))
                break;
            h *= sqrt(nlit / lit_target);
        }
    } else {
        if (lit_area / (lattice * h * h) > (double)RP_MESH_MAX_ELEMENTS) {
            st = rp_error_set(err, RP_ERR_INPUT, "mesh: max_edge %g gives about %.0f elements (the cap is %zu: memory)",
                              h, lit_area / (lattice * h * h), (size_t)RP_MESH_MAX_ELEMENTS);
            goto done;
        }
        if ((st = build(&c, h, &best, err)) != RP_OK)
            goto done;
        mesh->max_edge = h;
    }
    mesh->elements = best.el;
    mesh->nelements = best.nel;
    mesh->vertices = best.v;
    mesh->nvertices = best.nv;
    mesh->nconstraints = ns;
    for (size_t f = 0; f < nf; f++) {
        mesh->faces[f].first = best.first[f];
        mesh->faces[f].count = best.count[f];
        mesh->faces[f].n = mesh->faces[f].m = 0;
    }
    best.el = NULL;
    best.v = NULL;
    for (size_t f = 0; f < nf; f++)
        if (face_buckets(mesh, &mesh->faces[f])) {
            st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
            goto done;
        }
    st = RP_OK;
done:
    built_free(&best);
    built_free(&cur);
    free(ds);
    free(c.df);
    free(c.segs);
    free(c.snaps);
    free(c.ue_black);
    return st;
}
