/* Elements for finite-element radiosity (mesh.h).
 *
 * Every face becomes a regular grid in its own parameter space: a quad the
 * bilinear patch p(u, v) = (1-u)(1-v) v0 + u(1-v) v1 + uv v2 + (1-u)v v3
 * cut into n x m cells (n along v0v1 and v3v2, m along v1v2 and v0v3), a
 * triangle p = v0 + u (v1 - v0) + v (v2 - v0) cut into k^2 triangles.
 *
 * Conformity (no T-vertices inside a surface) is a constraint on edge
 * subdivision counts: the two opposite sides of a quad carry the same count,
 * so do the three sides of a triangle, and so does an edge shared by two
 * faces of one surface.  Those equalities partition the edges into classes
 * (union-find); a class takes the largest count any of its edges asks for,
 * ceil(length / max_edge).  Faces of a surface then share the grid vertices
 * of their common edges, laid out along the edge's canonical direction (from
 * the smaller welded corner index to the larger) so that two faces that run
 * the edge in opposite directions agree.
 *
 * Element quality ("aspect"): the area of the regular polygon (equilateral
 * triangle, square) whose side is the element's longest edge, divided by the
 * element's area.  It is 1 for an equilateral triangle and for a square and
 * grows without bound as an element degenerates; for a triangle it equals
 * (sqrt 3 / 2) * longest edge / shortest altitude. */
#include "mesh.h"
#include "mesh_internal.h"

#include <float.h>
#include <stddef.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Corners of one surface closer than this fraction of the surface's own
 * bounding-box diagonal, plus WELD_ULPS double ulps of its largest
 * coordinate, are one vertex.  Scene files repeat coordinates verbatim, so
 * this only has to absorb rounding in generated geometry (box expansion,
 * mesh import); it never depends on the rest of the scene. */
#define WELD_REL_TOL 1e-10
#define WELD_ULPS 64.0
/* Side of the cells corners are sorted into, in units of the tolerance. */
#define WELD_CELL 1024.0

/* ceil(L / h) is taken of L / h shrunk by this much, so that an edge whose
 * length is an exact multiple of max_edge up to rounding (1 / 0.1) is not
 * cut once more than asked. */
#define COUNT_SLACK 1e-12

/* ---- union-find ------------------------------------------------------ */

uint32_t rp_uf_find(uint32_t *parent, uint32_t x)
{
    while (parent[x] != x) {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    return x;
}

void rp_uf_union(uint32_t *parent, uint32_t a, uint32_t b)
{
    a = rp_uf_find(parent, a);
    b = rp_uf_find(parent, b);
    /* The smaller index becomes the root: the result does not depend on
     * the order of the unions. */
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

/* ---- welding --------------------------------------------------------- */

typedef struct weld_key {
    uint32_t surface;
    int64_t ix, iy, iz;
    uint32_t slot;
} weld_key;

static int weld_cmp_cell(const weld_key *a, const weld_key *b)
{
    if (a->surface != b->surface)
        return a->surface < b->surface ? -1 : 1;
    if (a->ix != b->ix)
        return a->ix < b->ix ? -1 : 1;
    if (a->iy != b->iy)
        return a->iy < b->iy ? -1 : 1;
    if (a->iz != b->iz)
        return a->iz < b->iz ? -1 : 1;
    return 0;
}

static int weld_cmp(const void *pa, const void *pb)
{
    const weld_key *a = pa, *b = pb;
    int c = weld_cmp_cell(a, b);
    if (c)
        return c;
    return a->slot < b->slot ? -1 : (a->slot > b->slot);
}

/* First key whose cell is not below the cell of *k. */
static size_t weld_lower_bound(const weld_key *keys, size_t n, const weld_key *k)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (weld_cmp_cell(&keys[mid], k) < 0)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* ---- edges ----------------------------------------------------------- */

typedef struct edge_rec {
    uint64_t key;   /* (smaller vertex << 32) | larger vertex */
    uint32_t id;    /* face slot 4 f + e, or element slot 4 e + i */
} edge_rec;

static int edge_cmp(const void *pa, const void *pb)
{
    const edge_rec *a = pa, *b = pb;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return a->id < b->id ? -1 : (a->id > b->id);
}

static uint64_t edge_key(uint32_t a, uint32_t b)
{
    return a < b ? ((uint64_t)a << 32) | b : ((uint64_t)b << 32) | a;
}

/* ---- subdivision counts ---------------------------------------------- */

static double class_count(double length, double h)
{
    double c = ceil(length / h * (1.0 - COUNT_SLACK));
    return c < 1.0 ? 1.0 : c;
}

/* Total element count for longest edge h; face f's classes are fc[2f] (u)
 * and fc[2f + 1] (v, quads only).  Classes of black surfaces (black[c]) are
 * never cut. */
static double total_count(const double *class_len, const unsigned char *black, size_t nclass,
                          const uint32_t *fc, const face_grid *faces, size_t nfaces, double h, double *cc)
{
    for (size_t c = 0; c < nclass; c++)
        cc[c] = black[c] ? 1.0 : class_count(class_len[c], h);
    double total = 0;
    for (size_t f = 0; f < nfaces; f++) {
        double a = cc[fc[2 * f]];
        total += faces[f].nverts == 4 ? a * cc[fc[2 * f + 1]] : a * a;
    }
    return total;
}

/* The longest edge giving the element count closest to target: the count
 * is a non-increasing step function of h, so bisect (in log h) for the step
 * where it crosses target and keep the closer side. */
static double find_max_edge(const double *class_len, const unsigned char *black, size_t nclass,
                            const uint32_t *fc, const face_grid *faces, size_t nfaces, size_t target, double *cc)
{
    double hmax = 0;
    for (size_t c = 0; c < nclass; c++)
        if (!black[c] && class_len[c] > hmax)
            hmax = class_len[c];
    if (!(hmax > 0))
        return 1.0; /* every class is black: nothing to cut */
    double t = (double)target;
    /* One element per face is as coarse as it gets. */
    double hi = hmax;
    double nhi = total_count(class_len, black, nclass, fc, faces, nfaces, hi, cc);
    if (nhi >= t)
        return hi;
    double lo = hi, nlo = nhi;
    for (int it = 0; it < 2100 && nlo < t && lo > 0; it++) {
        hi = lo;
        nhi = nlo;
        lo *= 0.5;
        nlo = total_count(class_len, black, nclass, fc, faces, nfaces, lo, cc);
    }
    if (!(lo > 0))
        return 0;
    /* Invariant: count(lo) >= target > count(hi). */
    for (int it = 0; it < 200 && hi > lo * (1 + 1e-15); it++) {
        double mid = sqrt(lo * hi);
        if (!(mid > lo && mid < hi))
            break;
        double nmid = total_count(class_len, black, nclass, fc, faces, nfaces, mid, cc);
        if (nmid >= t) {
            lo = mid;
            nlo = nmid;
        } else {
            hi = mid;
            nhi = nmid;
        }
    }
    return (nlo - t <= t - nhi) ? lo : hi;
}

/* ---- parameter-space inversion --------------------------------------- */

static double cross2(double ax, double ay, double bx, double by) { return ax * by - ay * bx; }

/* Distance of (u, v) outside the unit square (0 inside). */
static double outside(double u, double v)
{
    double du = u < 0 ? -u : (u > 1 ? u - 1 : 0);
    double dv = v < 0 ? -v : (v > 1 ? v - 1 : 0);
    return du + dv;
}

/* Inverts the bilinear patch of planar quad p0 p1 p2 p3 with unit normal n
 * at p (projected onto the plane): closed form, then Newton polish.
 * With h = p - p0, e = p1 - p0, f = p3 - p0, g = p0 - p1 + p2 - p3 the patch
 * is h = u e + v f + u v g; crossing with (e + v g) eliminates u and leaves
 * (g x f) v^2 + (h x g + e x f) v + h x e = 0 (2-D cross products). */
static void quad_inverse(const rp_vec3 q[4], rp_vec3 n, rp_vec3 p, double *uo, double *vo)
{
    rp_vec3 t, b;
    rp_v3_basis(n, &t, &b);
    rp_vec3 d = rp_v3_sub(p, q[0]), e3 = rp_v3_sub(q[1], q[0]), f3 = rp_v3_sub(q[3], q[0]);
    rp_vec3 g3 = rp_v3_add(rp_v3_sub(q[0], q[1]), rp_v3_sub(q[2], q[3]));
    double hx = rp_v3_dot(d, t), hy = rp_v3_dot(d, b);
    double ex = rp_v3_dot(e3, t), ey = rp_v3_dot(e3, b);
    double fx = rp_v3_dot(f3, t), fy = rp_v3_dot(f3, b);
    double gx = rp_v3_dot(g3, t), gy = rp_v3_dot(g3, b);

    double k2 = cross2(gx, gy, fx, fy);
    double k1 = cross2(hx, hy, gx, gy) + cross2(ex, ey, fx, fy);
    double k0 = cross2(hx, hy, ex, ey);
    double disc = k1 * k1 - 4 * k2 * k0;
    if (disc < 0)
        disc = 0;
    /* Numerically stable roots: q / k2 and k0 / q (Press et al., Numerical
     * Recipes, sec. 5.6); k0 / q is the linear root when k2 = 0. */
    double qq = -0.5 * (k1 + copysign(sqrt(disc), k1));
    double cand[2];
    int nc = 0;
    if (qq != 0)
        cand[nc++] = k0 / qq;
    if (k2 != 0)
        cand[nc++] = qq / k2;
    if (nc == 0)
        cand[nc++] = 0;
    double best_u = 0, best_v = 0, best_out = INFINITY;
    for (int i = 0; i < nc; i++) {
        double v = cand[i];
        double dx = ex + v * gx, dy = ey + v * gy;
        double dd = dx * dx + dy * dy;
        double u = dd > 0 ? ((hx - v * fx) * dx + (hy - v * fy) * dy) / dd : 0;
        double o = outside(u, v);
        if (isfinite(u) && isfinite(v) && o < best_out) {
            best_out = o;
            best_u = u;
            best_v = v;
        }
    }
    double u = best_u, v = best_v;
    /* Two Newton steps on r(u, v) = u e + v f + u v g - h remove the
     * rounding the closed form leaves near degenerate coefficients. */
    for (int it = 0; it < 2; it++) {
        double rx = u * ex + v * fx + u * v * gx - hx;
        double ry = u * ey + v * fy + u * v * gy - hy;
        double j11 = ex + v * gx, j21 = ey + v * gy; /* d r / d u */
        double j12 = fx + u * gx, j22 = fy + u * gy; /* d r / d v */
        double det = j11 * j22 - j12 * j21;
        if (!(fabs(det) > 0))
            break;
        double du = (-rx * j22 + ry * j12) / det;
        double dv = (-ry * j11 + rx * j21) / det;
        double nu = u + du, nv = v + dv;
        double nrx = nu * ex + nv * fx + nu * nv * gx - hx;
        double nry = nu * ey + nv * fy + nu * nv * gy - hy;
        if (!(nrx * nrx + nry * nry < rx * rx + ry * ry))
            break;
        u = nu;
        v = nv;
    }
    *uo = u;
    *vo = v;
}

/* Barycentric (u, v) of p's projection onto the plane of triangle
 * p0 p1 p2: p = p0 + u (p1 - p0) + v (p2 - p0), least squares. */
static void tri_inverse(rp_vec3 p0, rp_vec3 p1, rp_vec3 p2, rp_vec3 p, double *u, double *v)
{
    rp_vec3 e1 = rp_v3_sub(p1, p0), e2 = rp_v3_sub(p2, p0), h = rp_v3_sub(p, p0);
    double d11 = rp_v3_dot(e1, e1), d12 = rp_v3_dot(e1, e2), d22 = rp_v3_dot(e2, e2);
    double h1 = rp_v3_dot(h, e1), h2 = rp_v3_dot(h, e2);
    double den = d11 * d22 - d12 * d12;
    if (!(den > 0)) {
        *u = *v = 0;
        return;
    }
    *u = (d22 * h1 - d12 * h2) / den;
    *v = (d11 * h2 - d12 * h1) / den;
}

static double clamp01(double x) { return x < 0 ? 0 : (x > 1 ? 1 : x); }

/* ---- element geometry ------------------------------------------------ */

static void element_geometry(rp_element *el, const rp_vec3 *V)
{
    rp_vec3 a = V[el->v[0]], b = V[el->v[1]], c = V[el->v[2]];
    if (el->nverts == 3) {
        el->area = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
        el->centroid = rp_v3_scale(rp_v3_add(rp_v3_add(a, b), c), 1.0 / 3.0);
        return;
    }
    rp_vec3 d = V[el->v[3]];
    /* Planar quad: half the cross product of the diagonals. */
    el->area = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(c, a), rp_v3_sub(d, b)));
    /* Area centroid: the two triangles' centroids weighted by area. */
    double a1 = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
    double a2 = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(c, a), rp_v3_sub(d, a)));
    rp_vec3 c1 = rp_v3_scale(rp_v3_add(rp_v3_add(a, b), c), 1.0 / 3.0);
    rp_vec3 c2 = rp_v3_scale(rp_v3_add(rp_v3_add(a, c), d), 1.0 / 3.0);
    double s = a1 + a2;
    el->centroid = s > 0 ? rp_v3_add(rp_v3_scale(c1, a1 / s), rp_v3_scale(c2, a2 / s))
                         : rp_v3_scale(rp_v3_add(c1, c2), 0.5);
}

/* ---- construction ---------------------------------------------------- */

typedef struct build {
    const rp_face *sf;          /* scene faces */
    const uint32_t *wid;        /* welded vertex of corner slot 4 f + c */
    const uint32_t *edge_of;    /* unique edge of face-edge slot 4 f + e */
    const uint32_t *edge_first; /* first interior vertex of a unique edge */
} build;

/* Mesh vertex at step s (0..c) along edge e of face f, from corner e to
 * corner e + 1.  Interior edge vertices are stored along the canonical
 * direction (smaller welded index first). */
static uint32_t edge_vertex(const build *bd, uint32_t f, uint32_t e, uint32_t s, uint32_t c)
{
    uint32_t nv = bd->sf[f].nverts;
    uint32_t a = bd->wid[4 * f + e], b = bd->wid[4 * f + (e + 1) % nv];
    if (s == 0)
        return a;
    if (s == c)
        return b;
    uint32_t step = a < b ? s : c - s;
    return bd->edge_first[bd->edge_of[4 * f + e]] + step - 1;
}

/* Per-surface element ranges, adjacency and vertex -> element lists,
 * from the elements and vertices alone (both mesh modes). */
static rp_status mesh_topology(rp_mesh *mesh, const rp_surface *surf, size_t nsurf, rp_error *err)
{
    const size_t nel = mesh->nelements, nvert = mesh->nvertices, nfaces = mesh->nfaces;
    edge_rec *elrec = NULL;
    size_t *vfill = NULL;
    if (!mesh->neighbors && !(mesh->neighbors = malloc((nel ? 4 * nel : 1) * sizeof *mesh->neighbors)))
        goto nomem;
    for (size_t s = 0; s < nsurf; s++) {
        if (surf[s].nfaces == 0 || surf[s].first_face >= nfaces)
            continue;
        uint32_t f0 = surf[s].first_face, f1 = f0 + surf[s].nfaces - 1;
        mesh->surf_first[s] = mesh->faces[f0].first;
        mesh->surf_count[s] = mesh->faces[f1].first + mesh->faces[f1].count - mesh->faces[f0].first;
    }

    /* Adjacency: element edges with the same two vertices (vertices are
     * shared only inside a surface).  An edge met by more than two elements
     * (a non-manifold seam) gets no neighbour. */
    size_t nel_edges = 0;
    elrec = malloc((nel ? 4 * nel : 1) * sizeof *elrec);
    if (!elrec)
        goto nomem;
    for (size_t e = 0; e < nel; e++) {
        const rp_element *el = &mesh->elements[e];
        for (uint32_t i = 0; i < 4; i++)
            mesh->neighbors[4 * e + i] = RP_NONE;
        for (uint32_t i = 0; i < el->nverts; i++) {
            elrec[nel_edges].key = edge_key(el->v[i], el->v[(i + 1) % el->nverts]);
            elrec[nel_edges].id = (uint32_t)(4 * e + i);
            nel_edges++;
        }
    }
    qsort(elrec, nel_edges, sizeof *elrec, edge_cmp);
    for (size_t i = 0; i < nel_edges;) {
        size_t j = i + 1;
        while (j < nel_edges && elrec[j].key == elrec[i].key)
            j++;
        if (j - i == 2) {
            mesh->neighbors[elrec[i].id] = elrec[i + 1].id / 4;
            mesh->neighbors[elrec[i + 1].id] = elrec[i].id / 4;
        }
        i = j;
    }
    free(elrec);
    elrec = NULL;

    /* Vertex -> incident elements (compressed rows, elements ascending). */
    mesh->vstart = calloc(nvert + 1, sizeof *mesh->vstart);
    vfill = malloc((nvert ? nvert : 1) * sizeof *vfill);
    size_t nref = 0;
    for (size_t e = 0; e < nel; e++)
        nref += mesh->elements[e].nverts;
    mesh->velems = malloc((nref ? nref : 1) * sizeof *mesh->velems);
    if (!mesh->vstart || !vfill || !mesh->velems)
        goto nomem;
    for (size_t e = 0; e < nel; e++)
        for (uint32_t i = 0; i < mesh->elements[e].nverts; i++)
            mesh->vstart[mesh->elements[e].v[i] + 1]++;
    for (size_t v = 0; v < nvert; v++) {
        mesh->vstart[v + 1] += mesh->vstart[v];
        vfill[v] = mesh->vstart[v];
    }
    for (size_t e = 0; e < nel; e++)
        for (uint32_t i = 0; i < mesh->elements[e].nverts; i++)
            mesh->velems[vfill[mesh->elements[e].v[i]]++] = (uint32_t)e;

    free(vfill);
    return RP_OK;

nomem:
    free(elrec);
    free(vfill);
    return rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
}

rp_status rp_mesh_create(const rp_scene *scene, const rp_mesh_params *params, rp_mesh **out,
                         rp_error *err)
{
    if (!scene || !out)
        return rp_error_set(err, RP_ERR_INPUT, "mesh: no scene or no output");
    *out = NULL;

    double max_edge = 0;
    size_t target = 0, max_segments = 0;
    int mode = RP_MESH_UNIFORM;
    if (params) {
        /* Callers built before the mode existed pass the old size. */
        const size_t old_size = offsetof(rp_mesh_params, mode);
        if (params->size != 0 && params->size < old_size)
            return rp_error_set(err, RP_ERR_INPUT, "mesh: params.size %zu is too small (%zu)",
                                params->size, old_size);
        max_edge = params->max_edge;
        target = params->target_count;
        if (params->size == 0 || params->size >= offsetof(rp_mesh_params, mode) + sizeof params->mode)
            mode = params->mode;
        if (params->size == 0 || params->size >= offsetof(rp_mesh_params, max_segments) + sizeof params->max_segments)
            max_segments = params->max_segments;
        if (mode != RP_MESH_UNIFORM && mode != RP_MESH_DISCONTINUITY)
            return rp_error_set(err, RP_ERR_INPUT, "mesh: unknown mode %d (uniform 0, discontinuity 1)", mode);
        if (isnan(max_edge) || max_edge < 0 || isinf(max_edge))
            return rp_error_set(err, RP_ERR_INPUT,
                                "mesh: max_edge must be a positive finite length (got %g)", max_edge);
        if (max_edge > 0 && target > 0)
            return rp_error_set(err, RP_ERR_INPUT,
                                "mesh: set max_edge or target_count, not both (%g and %zu)", max_edge,
                                target);
    }
    /* The default: every face one element, and RP_MESH_DEFAULT_COUNT more
     * spread by area, so a finely tessellated object (a scanned mesh, a
     * tessellated sphere) does not take the walls' elements (McGuire's
     * CornellBox-Sphere: 2,188 faces left the ceiling one element and
     * Gauss-Seidel 8.6% dark; with this default, 1.0%). */
    if (max_edge == 0 && target == 0)
        target = RP_MESH_DEFAULT_COUNT + rp_scene_nfaces(scene);
    if (target > RP_MESH_MAX_ELEMENTS)
        return rp_error_set(err, RP_ERR_INPUT, "mesh: %zu elements asked for; the cap is %zu (memory)",
                            target, RP_MESH_MAX_ELEMENTS);

    const size_t nfaces = rp_scene_nfaces(scene);
    const size_t nsurf = rp_scene_nsurfaces(scene);
    const rp_face *sf = rp_scene_faces(scene);
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_vec3 *sv = rp_scene_vertices(scene);
    if (nfaces > (UINT32_MAX - 1) / 4)
        return rp_error_set(err, RP_ERR_INPUT, "mesh: too many faces (%zu)", nfaces);

    rp_status st = RP_OK;
    rp_mesh *mesh = calloc(1, sizeof *mesh);
    const size_t nslots = 4 * nfaces;
    uint32_t *parent = malloc((nslots ? nslots : 1) * sizeof *parent);
    uint32_t *wid = malloc((nslots ? nslots : 1) * sizeof *wid);
    uint32_t *edge_of = malloc((nslots ? nslots : 1) * sizeof *edge_of);
    weld_key *keys = malloc((nslots ? nslots : 1) * sizeof *keys);
    edge_rec *erec = malloc((nslots ? nslots : 1) * sizeof *erec);
    uint32_t *fc = calloc(2 * nfaces + 1, sizeof *fc);
    rp_vec3 *wpos = NULL;
    uint32_t *ue_a = NULL, *ue_b = NULL, *eparent = NULL, *ue_class = NULL, *edge_first = NULL;
    uint32_t *class_of_root = NULL, *grid = NULL;
    double *class_len = NULL, *cc = NULL, *stol = NULL;
    rp_vec3 *slo = NULL, *shi = NULL;
    unsigned char *black = NULL;
    if (!mesh || !parent || !wid || !edge_of || !keys || !erec || !fc) {
        st = RP_ERR_NOMEM;
        goto nomem;
    }
    mesh->nfaces = nfaces;
    mesh->nsurfaces = nsurf;
    mesh->faces = calloc(nfaces ? nfaces : 1, sizeof *mesh->faces);
    mesh->surf_first = calloc(nsurf ? nsurf : 1, sizeof *mesh->surf_first);
    mesh->surf_count = calloc(nsurf ? nsurf : 1, sizeof *mesh->surf_count);
    if (!mesh->faces || !mesh->surf_first || !mesh->surf_count)
        goto nomem;

    /* Face corners and, per surface, the box and magnitude its weld
     * tolerance is relative to. */
    slo = malloc((nsurf ? nsurf : 1) * sizeof *slo);
    shi = malloc((nsurf ? nsurf : 1) * sizeof *shi);
    stol = malloc((nsurf ? nsurf : 1) * sizeof *stol);
    if (!slo || !shi || !stol)
        goto nomem;
    for (size_t s = 0; s < nsurf; s++) {
        slo[s] = rp_v3(INFINITY, INFINITY, INFINITY);
        shi[s] = rp_v3(-INFINITY, -INFINITY, -INFINITY);
        stol[s] = -INFINITY; /* the largest coordinate first */
    }
    for (size_t f = 0; f < nfaces; f++) {
        face_grid *fg = &mesh->faces[f];
        fg->nverts = sf[f].nverts;
        fg->normal = sf[f].normal;
        if (fg->nverts != 3 && fg->nverts != 4) {
            st = rp_error_set(err, RP_ERR_INPUT, "mesh: face %zu has %u vertices", f, fg->nverts);
            goto fail;
        }
        const uint32_t s = sf[f].surface;
        for (uint32_t c = 0; c < fg->nverts; c++) {
            rp_vec3 p = sv[sf[f].v[c]];
            fg->c[c] = p;
            slo[s] = rp_v3(fmin(slo[s].x, p.x), fmin(slo[s].y, p.y), fmin(slo[s].z, p.z));
            shi[s] = rp_v3(fmax(shi[s].x, p.x), fmax(shi[s].y, p.y), fmax(shi[s].z, p.z));
            stol[s] = fmax(stol[s], fmax(fabs(p.x), fmax(fabs(p.y), fabs(p.z))));
        }
    }
    for (size_t s = 0; s < nsurf; s++)
        stol[s] = slo[s].x <= shi[s].x
                      ? WELD_REL_TOL * rp_v3_length(rp_v3_sub(shi[s], slo[s])) + WELD_ULPS * DBL_EPSILON * stol[s]
                      : 0;

    /* Weld corners within each surface.  Corners are sorted by cell of a
     * grid of side WELD_CELL * tol (the surface's tol, from its own box);
     * two corners closer than tol share a cell or sit within tol of a
     * common cell face, so only a corner that near a face of its cell needs
     * to look in the neighbouring cells. */
    size_t nkeys = 0;
    for (size_t f = 0; f < nfaces; f++)
        for (uint32_t c = 0; c < 4; c++) {
            uint32_t s = (uint32_t)(4 * f + c);
            parent[s] = s;
            wid[s] = RP_NONE;
            if (c >= sf[f].nverts)
                continue;
            rp_vec3 p = mesh->faces[f].c[c], lo = slo[sf[f].surface];
            const double cell = WELD_CELL * stol[sf[f].surface];
            weld_key *k = &keys[nkeys++];
            k->surface = sf[f].surface;
            k->ix = cell > 0 ? (int64_t)floor((p.x - lo.x) / cell) : 0;
            k->iy = cell > 0 ? (int64_t)floor((p.y - lo.y) / cell) : 0;
            k->iz = cell > 0 ? (int64_t)floor((p.z - lo.z) / cell) : 0;
            k->slot = s;
        }
    qsort(keys, nkeys, sizeof *keys, weld_cmp);
    for (size_t i = 0; i < nkeys; i++) {
        const weld_key *ki = &keys[i];
        rp_vec3 pi = mesh->faces[ki->slot / 4].c[ki->slot % 4], lo = slo[ki->surface];
        const double tol = stol[ki->surface], cell = WELD_CELL * tol;
        /* Own cell: the run after i (pairs before i were seen from them). */
        for (size_t j = i + 1; j < nkeys && weld_cmp_cell(&keys[j], ki) == 0; j++) {
            rp_vec3 pj = mesh->faces[keys[j].slot / 4].c[keys[j].slot % 4];
            if (rp_v3_length(rp_v3_sub(pi, pj)) <= tol)
                rp_uf_union(parent, ki->slot, keys[j].slot);
        }
        if (!(cell > 0))
            continue;
        /* Neighbouring cells, only across faces within 2 tol (rounding in
         * the cell index). */
        double fr[3] = {(pi.x - lo.x) / cell - (double)ki->ix, (pi.y - lo.y) / cell - (double)ki->iy,
                        (pi.z - lo.z) / cell - (double)ki->iz};
        int dlo[3], dhi[3];
        for (int a = 0; a < 3; a++) {
            dlo[a] = fr[a] * WELD_CELL <= 2 ? -1 : 0;
            dhi[a] = (1 - fr[a]) * WELD_CELL <= 2 ? 1 : 0;
        }
        for (int dx = dlo[0]; dx <= dhi[0]; dx++)
            for (int dy = dlo[1]; dy <= dhi[1]; dy++)
                for (int dz = dlo[2]; dz <= dhi[2]; dz++) {
                    if (dx == 0 && dy == 0 && dz == 0)
                        continue;
                    weld_key probe = {ki->surface, ki->ix + dx, ki->iy + dy, ki->iz + dz, 0};
                    for (size_t j = weld_lower_bound(keys, nkeys, &probe);
                         j < nkeys && weld_cmp_cell(&keys[j], &probe) == 0; j++) {
                        rp_vec3 pj = mesh->faces[keys[j].slot / 4].c[keys[j].slot % 4];
                        if (rp_v3_length(rp_v3_sub(pi, pj)) <= tol)
                            rp_uf_union(parent, ki->slot, keys[j].slot);
                    }
                }
    }
    free(keys);
    keys = NULL;

    /* Welded vertices numbered in order of first appearance; they are the
     * first mesh vertices. */
    size_t nweld = 0;
    wpos = malloc((nslots ? nslots : 1) * sizeof *wpos);
    if (!wpos)
        goto nomem;
    for (size_t f = 0; f < nfaces; f++)
        for (uint32_t c = 0; c < sf[f].nverts; c++) {
            uint32_t s = (uint32_t)(4 * f + c), r = rp_uf_find(parent, s);
            if (wid[r] == RP_NONE) {
                wid[r] = (uint32_t)nweld;
                wpos[nweld++] = mesh->faces[f].c[c];
            }
            wid[s] = wid[r];
        }
    for (size_t f = 0; f < nfaces; f++)
        for (uint32_t c = 0; c < sf[f].nverts; c++)
            for (uint32_t c2 = c + 1; c2 < sf[f].nverts; c2++)
                if (wid[4 * f + c] == wid[4 * f + c2]) {
                    st = rp_error_set(err, RP_ERR_INPUT,
                                      "mesh: face %zu of surface '%s' has corners %u and %u closer than %g",
                                      f, surf[sf[f].surface].name, c, c2, stol[sf[f].surface]);
                    goto fail;
                }

    /* Unique edges of each surface (welded ids are per surface, so equal
     * keys never join two surfaces). */
    size_t nrec = 0;
    for (size_t f = 0; f < nfaces; f++)
        for (uint32_t e = 0; e < sf[f].nverts; e++) {
            erec[nrec].key = edge_key(wid[4 * f + e], wid[4 * f + (e + 1) % sf[f].nverts]);
            erec[nrec].id = (uint32_t)(4 * f + e);
            nrec++;
        }
    qsort(erec, nrec, sizeof *erec, edge_cmp);
    size_t nue = 0;
    ue_a = malloc((nrec ? nrec : 1) * sizeof *ue_a);
    ue_b = malloc((nrec ? nrec : 1) * sizeof *ue_b);
    if (!ue_a || !ue_b)
        goto nomem;
    for (size_t i = 0; i < nrec; i++) {
        if (i == 0 || erec[i].key != erec[i - 1].key) {
            ue_a[nue] = (uint32_t)(erec[i].key >> 32);
            ue_b[nue] = (uint32_t)(erec[i].key & 0xffffffffu);
            nue++;
        }
        edge_of[erec[i].id] = (uint32_t)(nue - 1);
    }
    free(erec);
    erec = NULL;

    /* Classes of edges that must carry the same count. */
    eparent = malloc((nue ? nue : 1) * sizeof *eparent);
    ue_class = malloc((nue ? nue : 1) * sizeof *ue_class);
    class_of_root = malloc((nue ? nue : 1) * sizeof *class_of_root);
    class_len = calloc(nue ? nue : 1, sizeof *class_len);
    cc = calloc(nue ? nue : 1, sizeof *cc);
    if (!eparent || !ue_class || !class_of_root || !class_len || !cc)
        goto nomem;
    for (size_t i = 0; i < nue; i++) {
        eparent[i] = (uint32_t)i;
        class_of_root[i] = RP_NONE;
    }
    for (size_t f = 0; f < nfaces; f++) {
        const uint32_t *eo = &edge_of[4 * f];
        if (sf[f].nverts == 4) {
            rp_uf_union(eparent, eo[0], eo[2]); /* v0v1 ~ v3v2: n */
            rp_uf_union(eparent, eo[1], eo[3]); /* v1v2 ~ v0v3: m */
        } else {
            rp_uf_union(eparent, eo[0], eo[1]);
            rp_uf_union(eparent, eo[1], eo[2]);
        }
    }
    size_t nclass = 0;
    for (size_t i = 0; i < nue; i++) {
        uint32_t r = rp_uf_find(eparent, (uint32_t)i);
        if (class_of_root[r] == RP_NONE)
            class_of_root[r] = (uint32_t)nclass++;
        ue_class[i] = class_of_root[r];
        double len = rp_v3_length(rp_v3_sub(wpos[ue_b[i]], wpos[ue_a[i]]));
        if (len > class_len[ue_class[i]])
            class_len[ue_class[i]] = len;
    }
    /* A surface black in every band (neither reflects nor emits: a ground
     * plane that only blocks light) has radiosity 0 everywhere, so its
     * faces are never cut, and a target count is spread over the others
     * alone: adding a black plane, however large, leaves the rest of the
     * mesh as it was.  Classes never join two surfaces. */
    black = calloc(nclass ? nclass : 1, 1);
    if (!black)
        goto nomem;
    const size_t nb = rp_scene_nbands(scene);
    for (size_t f = 0; f < nfaces; f++) {
        fc[2 * f] = ue_class[edge_of[4 * f]];
        fc[2 * f + 1] = ue_class[edge_of[4 * f + 1]];
        const rp_material *mat = rp_scene_face_material(scene, (uint32_t)f);
        int lit = 0;
        for (size_t b = 0; b < nb; b++)
            lit |= mat->rho[b] > 0 || mat->Le[b] > 0;
        black[fc[2 * f]] = black[fc[2 * f + 1]] = (unsigned char)!lit;
    }

    if (mode == RP_MESH_DISCONTINUITY) {
        rp_mesh_weld mw = {wid, edge_of, ue_a, ue_b, nue, nweld, wpos};
        if ((st = rp_mesh_build_disc(mesh, scene, &mw, max_edge, target, max_segments, err)) != RP_OK)
            goto fail;
        goto topology;
    }

    /* The longest element edge. */
    if (max_edge == 0) {
        max_edge = find_max_edge(class_len, black, nclass, fc, mesh->faces, nfaces, target, cc);
        if (!(max_edge > 0) && nfaces > 0) {
            st = rp_error_set(err, RP_ERR_INPUT, "mesh: no subdivision reaches %zu elements", target);
            goto fail;
        }
    }
    mesh->max_edge = max_edge;
    double ntotal = total_count(class_len, black, nclass, fc, mesh->faces, nfaces, max_edge, cc);

    /* Vertex count: welded corners, edge interiors, face interiors. */
    double nvert_d = (double)nweld;
    for (size_t i = 0; i < nue; i++)
        nvert_d += cc[ue_class[i]] - 1;
    for (size_t f = 0; f < nfaces; f++) {
        double n = cc[fc[2 * f]];
        nvert_d += sf[f].nverts == 4 ? (n - 1) * (cc[fc[2 * f + 1]] - 1) : (n - 1) * (n - 2) / 2;
    }
    if (ntotal > (double)RP_MESH_MAX_ELEMENTS || nvert_d > (double)(UINT32_MAX - 1)) {
        st = rp_error_set(err, RP_ERR_INPUT,
                          "mesh: max_edge %g gives %.0f elements and %.0f vertices (the cap is "
                          "16777216 elements: memory)",
                          max_edge, ntotal, nvert_d);
        goto fail;
    }
    const size_t nel = (size_t)ntotal, nvert = (size_t)nvert_d;
    mesh->nelements = nel;
    mesh->nvertices = nvert;
    mesh->elements = malloc((nel ? nel : 1) * sizeof *mesh->elements);
    mesh->vertices = malloc((nvert ? nvert : 1) * sizeof *mesh->vertices);
    mesh->neighbors = malloc((nel ? 4 * nel : 1) * sizeof *mesh->neighbors);
    edge_first = malloc((nue ? nue : 1) * sizeof *edge_first);
    if (!mesh->elements || !mesh->vertices || !mesh->neighbors || !edge_first)
        goto nomem;

    /* Corner and edge vertices. */
    size_t nv = 0;
    for (size_t i = 0; i < nweld; i++)
        mesh->vertices[nv++] = wpos[i];
    for (size_t i = 0; i < nue; i++) {
        uint32_t c = (uint32_t)cc[ue_class[i]];
        edge_first[i] = (uint32_t)nv;
        rp_vec3 a = wpos[ue_a[i]], b = wpos[ue_b[i]];
        for (uint32_t s = 1; s < c; s++) {
            double t = (double)s / c;
            mesh->vertices[nv++] = rp_v3_add(rp_v3_scale(a, 1 - t), rp_v3_scale(b, t));
        }
    }

    /* Face grids: vertices then elements. */
    build bd = {sf, wid, edge_of, edge_first};
    size_t grid_cap = 0, ne = 0;
    for (size_t f = 0; f < nfaces; f++) {
        face_grid *fg = &mesh->faces[f];
        const uint32_t F = (uint32_t)f;
        fg->first = (uint32_t)ne;
        const rp_vec3 *q = fg->c;
        if (fg->nverts == 4) {
            uint32_t n = (uint32_t)cc[fc[2 * f]], m = (uint32_t)cc[fc[2 * f + 1]];
            fg->n = n;
            fg->m = m;
            fg->count = n * m;
            size_t need = (size_t)(n + 1) * (m + 1);
            if (need > grid_cap) {
                free(grid);
                grid_cap = need;
                grid = malloc(grid_cap * sizeof *grid);
                if (!grid)
                    goto nomem;
            }
            for (uint32_t j = 0; j <= m; j++)
                for (uint32_t i = 0; i <= n; i++) {
                    uint32_t id;
                    if (j == 0)
                        id = edge_vertex(&bd, F, 0, i, n);
                    else if (i == n)
                        id = edge_vertex(&bd, F, 1, j, m);
                    else if (j == m)
                        id = edge_vertex(&bd, F, 2, n - i, n);
                    else if (i == 0)
                        id = edge_vertex(&bd, F, 3, m - j, m);
                    else {
                        double u = (double)i / n, v = (double)j / m;
                        rp_vec3 bot = rp_v3_add(rp_v3_scale(q[0], 1 - u), rp_v3_scale(q[1], u));
                        rp_vec3 top = rp_v3_add(rp_v3_scale(q[3], 1 - u), rp_v3_scale(q[2], u));
                        id = (uint32_t)nv;
                        mesh->vertices[nv++] = rp_v3_add(rp_v3_scale(bot, 1 - v), rp_v3_scale(top, v));
                    }
                    grid[(size_t)j * (n + 1) + i] = id;
                }
            for (uint32_t j = 0; j < m; j++)
                for (uint32_t i = 0; i < n; i++) {
                    rp_element *el = &mesh->elements[ne++];
                    size_t g = (size_t)j * (n + 1) + i;
                    el->v[0] = grid[g];
                    el->v[1] = grid[g + 1];
                    el->v[2] = grid[g + n + 2];
                    el->v[3] = grid[g + n + 1];
                    el->nverts = 4;
                }
        } else {
            uint32_t k = (uint32_t)cc[fc[2 * f]];
            fg->n = fg->m = k;
            fg->count = k * k;
            size_t need = (size_t)(k + 1) * (k + 2) / 2;
            if (need > grid_cap) {
                free(grid);
                grid_cap = need;
                grid = malloc(grid_cap * sizeof *grid);
                if (!grid)
                    goto nomem;
            }
            /* Row j holds the k + 1 - j points (i, j), i + j <= k. */
#define TRI(i, j) ((size_t)(j) * (k + 1) - (size_t)(j) * ((j) - 1) / 2 + (i))
            for (uint32_t j = 0; j <= k; j++)
                for (uint32_t i = 0; i + j <= k; i++) {
                    uint32_t id;
                    if (j == 0)
                        id = edge_vertex(&bd, F, 0, i, k);
                    else if (i + j == k)
                        id = edge_vertex(&bd, F, 1, j, k);
                    else if (i == 0)
                        id = edge_vertex(&bd, F, 2, k - j, k);
                    else {
                        double u = (double)i / k, v = (double)j / k;
                        id = (uint32_t)nv;
                        mesh->vertices[nv++] = rp_v3_add(
                            q[0], rp_v3_add(rp_v3_scale(rp_v3_sub(q[1], q[0]), u),
                                            rp_v3_scale(rp_v3_sub(q[2], q[0]), v)));
                    }
                    grid[TRI(i, j)] = id;
                }
            /* Row j: lower triangles at 2i, upper ones at 2i + 1; the row
             * starts at j (2k - j) (see rp_mesh_locate). */
            for (uint32_t j = 0; j < k; j++)
                for (uint32_t i = 0; i + j < k; i++) {
                    rp_element *el = &mesh->elements[ne++];
                    el->v[0] = grid[TRI(i, j)];
                    el->v[1] = grid[TRI(i + 1, j)];
                    el->v[2] = grid[TRI(i, j + 1)];
                    el->v[3] = RP_NONE;
                    el->nverts = 3;
                    if (i + j + 1 < k) {
                        el = &mesh->elements[ne++];
                        el->v[0] = grid[TRI(i + 1, j)];
                        el->v[1] = grid[TRI(i + 1, j + 1)];
                        el->v[2] = grid[TRI(i, j + 1)];
                        el->v[3] = RP_NONE;
                        el->nverts = 3;
                    }
                }
#undef TRI
        }
        for (size_t e = fg->first; e < ne; e++) {
            rp_element *el = &mesh->elements[e];
            el->face = F;
            el->surface = sf[f].surface;
            el->normal = fg->normal;
            element_geometry(el, mesh->vertices);
        }
    }
    free(grid);
    grid = NULL;

topology:
    if ((st = mesh_topology(mesh, surf, nsurf, err)) != RP_OK)
        goto fail;

    free(parent);
    free(wid);
    free(edge_of);
    free(fc);
    free(wpos);
    free(ue_a);
    free(ue_b);
    free(eparent);
    free(ue_class);
    free(class_of_root);
    free(class_len);
    free(cc);
    free(edge_first);
    free(slo);
    free(shi);
    free(stol);
    free(black);
    *out = mesh;
    return RP_OK;

nomem:
    st = rp_error_set(err, RP_ERR_NOMEM, "mesh: out of memory");
fail:
    free(grid);
    free(parent);
    free(wid);
    free(edge_of);
    free(keys);
    free(erec);
    free(fc);
    free(wpos);
    free(ue_a);
    free(ue_b);
    free(eparent);
    free(ue_class);
    free(class_of_root);
    free(class_len);
    free(cc);
    free(edge_first);
    free(slo);
    free(shi);
    free(stol);
    free(black);
    rp_mesh_destroy(mesh);
    return st;
}

void rp_mesh_destroy(rp_mesh *mesh)
{
    if (!mesh)
        return;
    for (size_t f = 0; mesh->faces && f < mesh->nfaces; f++) {
        free(mesh->faces[f].bstart);
        free(mesh->faces[f].belems);
    }
    free(mesh->elements);
    free(mesh->vertices);
    free(mesh->neighbors);
    free(mesh->vstart);
    free(mesh->velems);
    free(mesh->faces);
    free(mesh->surf_first);
    free(mesh->surf_count);
    free(mesh);
}

size_t rp_mesh_nelements(const rp_mesh *mesh) { return mesh->nelements; }
int rp_mesh_disc_truncated(const rp_mesh *mesh) { return mesh->disc_truncated; }
const rp_element *rp_mesh_elements(const rp_mesh *mesh) { return mesh->elements; }
size_t rp_mesh_nvertices(const rp_mesh *mesh) { return mesh->nvertices; }
const rp_vec3 *rp_mesh_vertices(const rp_mesh *mesh) { return mesh->vertices; }

void rp_mesh_face_elements(const rp_mesh *mesh, uint32_t face, uint32_t *first, uint32_t *count)
{
    if (face >= mesh->nfaces) {
        *first = 0;
        *count = 0;
        return;
    }
    *first = mesh->faces[face].first;
    *count = mesh->faces[face].count;
}

void rp_mesh_surface_elements(const rp_mesh *mesh, uint32_t surface, uint32_t *first, uint32_t *count)
{
    if (surface >= mesh->nsurfaces) {
        *first = 0;
        *count = 0;
        return;
    }
    *first = mesh->surf_first[surface];
    *count = mesh->surf_count[surface];
}

void rp_mesh_neighbors(const rp_mesh *mesh, uint32_t e, uint32_t out[4])
{
    for (int i = 0; i < 4; i++)
        out[i] = e < mesh->nelements ? mesh->neighbors[4 * (size_t)e + i] : RP_NONE;
}

const uint32_t *rp_mesh_vertex_elements(const rp_mesh *mesh, uint32_t v, size_t *count)
{
    if (v >= mesh->nvertices) {
        *count = 0;
        return NULL;
    }
    *count = mesh->vstart[v + 1] - mesh->vstart[v];
    return mesh->velems + mesh->vstart[v];
}

uint32_t rp_mesh_locate(const rp_mesh *mesh, uint32_t face, rp_vec3 p)
{
    if (face >= mesh->nfaces)
        return RP_NONE;
    const face_grid *fg = &mesh->faces[face];
    if (fg->triangulated)
        return rp_mesh_locate_disc(mesh, fg, p);
    if (fg->nverts == 4) {
        double u, v;
        quad_inverse(fg->c, fg->normal, p, &u, &v);
        double su = floor(clamp01(u) * fg->n), sv = floor(clamp01(v) * fg->m);
        uint32_t i = su >= fg->n ? fg->n - 1 : (uint32_t)su;
        uint32_t j = sv >= fg->m ? fg->m - 1 : (uint32_t)sv;
        return fg->first + j * fg->n + i;
    }
    double u, v;
    tri_inverse(fg->c[0], fg->c[1], fg->c[2], p, &u, &v);
    /* Clamp to the triangle first, so grid indices stay in range. */
    u = u < 0 ? 0 : u;
    v = v < 0 ? 0 : v;
    if (u + v > 1) {
        double s = u + v;
        u /= s;
        v /= s;
    }
    const uint32_t k = fg->n;
    double U = u * k, V = v * k;
    double fj = floor(V);
    uint32_t j = fj >= k ? k - 1 : (uint32_t)fj;
    double fi = floor(U);
    uint32_t i = fi >= k - j ? k - 1 - j : (uint32_t)fi;
    /* In cell (i, j) the upper triangle is where the local coordinates sum
     * past 1; the last cell of a row has none. */
    uint32_t upper = (i + j + 1 < k && (U - i) + (V - j) > 1) ? 1 : 0;
    return fg->first + j * (2 * k - j) + 2 * i + upper;
}

void rp_mesh_element_weights(const rp_mesh *mesh, uint32_t e, rp_vec3 p, double w[4])
{
    w[0] = w[1] = w[2] = w[3] = 0;
    if (e >= mesh->nelements)
        return;
    const rp_element *el = &mesh->elements[e];
    const rp_vec3 *V = mesh->vertices;
    if (el->nverts == 4) {
        rp_vec3 q[4] = {V[el->v[0]], V[el->v[1]], V[el->v[2]], V[el->v[3]]};
        double s, t;
        quad_inverse(q, el->normal, p, &s, &t);
        /* A point just outside the element (rounding in a ray hit) is
         * pulled onto it, so interpolation never extrapolates. */
        s = clamp01(s);
        t = clamp01(t);
        w[0] = (1 - s) * (1 - t);
        w[1] = s * (1 - t);
        w[2] = s * t;
        w[3] = (1 - s) * t;
        return;
    }
    double u, v;
    tri_inverse(V[el->v[0]], V[el->v[1]], V[el->v[2]], p, &u, &v);
    double b0 = 1 - u - v;
    if (u < 0 || v < 0 || b0 < 0) {
        u = u < 0 ? 0 : u;
        v = v < 0 ? 0 : v;
        b0 = b0 < 0 ? 0 : b0;
        double s = u + v + b0;
        u /= s;
        v /= s;
        b0 /= s;
    }
    w[0] = b0;
    w[1] = u;
    w[2] = v;
}

void rp_mesh_quality_get(const rp_mesh *mesh, rp_mesh_quality *q)
{
    memset(q, 0, sizeof *q);
    if (mesh->nelements == 0)
        return;
    q->min_aspect = q->min_area = INFINITY;
    double sum = 0;
    for (size_t e = 0; e < mesh->nelements; e++) {
        const rp_element *el = &mesh->elements[e];
        double l2 = 0;
        for (uint32_t i = 0; i < el->nverts; i++) {
            rp_vec3 d = rp_v3_sub(mesh->vertices[el->v[(i + 1) % el->nverts]], mesh->vertices[el->v[i]]);
            double d2 = rp_v3_dot(d, d);
            if (d2 > l2)
                l2 = d2;
        }
        /* Area of the regular polygon with the longest edge as side
         * (sqrt(3)/4 L^2 or L^2) over the element's area. */
        double reg = el->nverts == 3 ? sqrt(3.0) / 4.0 * l2 : l2;
        double aspect = el->area > 0 ? reg / el->area : INFINITY;
        sum += aspect;
        q->min_aspect = fmin(q->min_aspect, aspect);
        q->max_aspect = fmax(q->max_aspect, aspect);
        q->min_area = fmin(q->min_area, el->area);
        q->max_area = fmax(q->max_area, el->area);
    }
    q->mean_aspect = sum / (double)mesh->nelements;
}
