/* Hierarchical radiosity with a linear basis (--basis linear): Galerkin
 * radiosity with piecewise-linear elements on the quadtrees (Zatz 1993,
 * "Galerkin radiosity: a higher order solution method for global
 * illumination"; Gortler, Schroeder, Cohen & Hanrahan 1993, "Wavelet
 * radiosity", sec. 4, whose multiwavelet bases of order 2 are these
 * functions; RenderPark's hierarchical Galerkin solver offers the same).
 *
 * Each node carries, besides its area mean B (the constant coefficient,
 * which surface averages, clusters, importance and the oracle keep
 * reading), the coefficients B1 of two linear functions phi_0, phi_1,
 * orthonormal over the node with the constant (hier_basis_of):
 *
 *     B(x) = B + B1_0 phi_0(x) + B1_1 phi_1(x)   on the node.
 *
 * A link q <- p carries the 3 x 3 coupling coefficients (index 0 the
 * constant, 1 and 2 the linear functions; Zatz 1993, eq. 9, with the
 * receiver's basis orthonormal so its mass matrix is the identity)
 *
 *     K_ij = (1 / A_q) int_q int_p psi_i(x) psi_j(y) G(x, y) V(x, y) dy dx,
 *     G = cos_x cos_y / (pi r^2),
 *
 * so that q gathers rho sum_j K_ij B_p,j into its coefficient i.  K_00 is
 * the link's form factor F (hier_link.c: the constant basis's refinement
 * and visibility, and for links that do not cross each other's planes the
 * unoccluded part by this rule over x, hier_linear_rule_mean).  The rest
 * are integrated without visibility and scaled by F over their own K_00
 * (a link's visibility taken as uniform over the pair, as the constant
 * basis takes it): over x by a rule exact for quadratics (3 points on a
 * triangle, Strang & Fix 1973; the 2 x 2 Gauss points on a
 * parallelogram, weighted by the area element on other quads), over y from
 * the source's quarters, each one's point-to-polygon form factor (the disk
 * approximation when far, LIN_DISK_RATIO) times the source function at its
 * centroid,
 * corrected by the inverse of the centroids' moments so that a kernel
 * linear across the source is integrated exactly (link_coefficients).
 *
 * Push-pull uses the two-scale relation of a child c of p (exact, since a
 * linear function on p is linear on c): phi^p_i = a_i + sum_k A_ik phi^c_k
 * on c (hier_linear_relation).  Pushing down, c's constant gains a . L and
 * its linear coefficients become A^T L; pulling up, p's linear
 * coefficient i is the mean over its children of a_i (B_c - B_p) +
 * A_i . B1_c, weighted as p's mean is (by area, or by the area some link
 * reaches, hierarchical.c, hier_sweep): with area weights the L2
 * projection of the children's functions on p's basis. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"

/* Second moments of polygon v[0..m-1] about point c in the plane frame
 * (t1, t2), divided by the polygon's area: M = [m11 m12; m12 m22].  A fan
 * of triangles from v[0], each contributing its area times its own
 * moments, (1/12) sum over its corners of d d^T about its centroid, plus
 * d d^T of its centroid (parallel axes). */
static void polygon_moments(const rp_vec3 *v, int m, rp_vec3 c, rp_vec3 t1, rp_vec3 t2, double M[3])
{
    double area = 0;
    M[0] = M[1] = M[2] = 0;
    for (int k = 1; k + 1 < m; k++) {
        rp_vec3 tri[3] = {v[0], v[k], v[k + 1]};
        double a = 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(tri[1], tri[0]), rp_v3_sub(tri[2], tri[0])));
        rp_vec3 ct = rp_v3_scale(rp_v3_add(rp_v3_add(tri[0], tri[1]), tri[2]), 1.0 / 3.0);
        double s = 0, st = 0, t = 0;
        for (int j = 0; j < 3; j++) {
            rp_vec3 d = rp_v3_sub(tri[j], ct);
            double u = rp_v3_dot(d, t1), w = rp_v3_dot(d, t2);
            s += u * u;
            st += u * w;
            t += w * w;
        }
        rp_vec3 dc = rp_v3_sub(ct, c);
        double uc = rp_v3_dot(dc, t1), wc = rp_v3_dot(dc, t2);
        M[0] += a * (s / 12 + uc * uc);
        M[1] += a * (st / 12 + uc * wc);
        M[2] += a * (t / 12 + wc * wc);
        area += a;
    }
    for (int k = 0; k < 3; k++)
        M[k] = area > 0 ? M[k] / area : 0;
}

void hier_basis_of(const hier_node *nd, rp_vec3 n, hier_basis *out)
{
    rp_vec3 t1, t2;
    rp_v3_basis(n, &t1, &t2);
    double M[3];
    polygon_moments(nd->v, nd->nverts, hier_node_c(nd), t1, t2, M);
    memset(out, 0, sizeof *out);
    out->c = hier_node_c(nd);
    /* M = L L^T (Cholesky); phi = L^-1 (t1 . d, t2 . d) has the identity
     * as its second moments, and d = t1 (L phi)_0 + t2 (L phi)_1. */
    double l11 = M[0] > 0 ? sqrt(M[0]) : 0;
    if (!(l11 > 0))
        return;
    double l21 = M[1] / l11, r = M[2] - l21 * l21;
    /* A sliver whose second direction is lost to rounding keeps its
     * linear function along the first only. */
    double l22 = r > 1e-12 * M[0] ? sqrt(r) : 0;
    out->g[0] = rp_v3_scale(t1, 1.0 / l11);
    out->h[0] = rp_v3_add(rp_v3_scale(t1, l11), rp_v3_scale(t2, l21));
    if (l22 > 0) {
        out->g[1] = rp_v3_add(rp_v3_scale(t1, -l21 / (l11 * l22)), rp_v3_scale(t2, 1.0 / l22));
        out->h[1] = rp_v3_scale(t2, l22);
    }
}

static inline double phi(const hier_basis *b, int k, rp_vec3 x) { return rp_v3_dot(b->g[k], rp_v3_sub(x, b->c)); }

void hier_linear_relation(const hier_state *s, uint32_t p, uint32_t c, double a[2], double A[2][2])
{
    const hier_basis *bp = &s->basis[p], *bc = &s->basis[c];
    for (int i = 0; i < 2; i++) {
        a[i] = phi(bp, i, bc->c);
        for (int k = 0; k < 2; k++)
            A[i][k] = rp_v3_dot(bp->g[i], bc->h[k]);
    }
}

void hier_linear_eval(const hier_state *s, uint32_t i, rp_vec3 x, double *out)
{
    const size_t nb = s->nb;
    const hier_basis *b = &s->basis[i];
    double f0 = phi(b, 0, x), f1 = phi(b, 1, x);
    for (size_t k = 0; k < nb; k++) {
        const double *c = s->B1 + ((size_t)i * nb + k) * 2;
        /* A steep linear function can dip below zero in a corner: light
         * cannot. */
        out[k] = hier_max(0.0, s->B[(size_t)i * nb + k] + c[0] * f0 + c[1] * f1);
    }
}

/* The source's quarters take the disk approximation beyond about 5.5
 * times their size (r^2 > 30 x their size^2; a link's own form factor
 * beyond about 30 times, HIER_DISK_RATIO).  The contour integrals were
 * most of the linear basis's cost: on the Cornell box from the
 * discontinuity mesh at the defaults, one thread, 8.05 s with the links'
 * threshold, 6.75 s with this one, the surface averages the same to
 * 0.01% (RMS against the path tracer 0.233% and 0.232%). */
#define LIN_DISK_RATIO 30.0

/* Quadrature exact for quadratics over node q: *n points x[] with weights
 * w[] adding up to 1. */
static int receiver_rule(const hier_node *q, rp_vec3 x[4], double w[4])
{
    if (q->nverts == 3) {
        /* Strang & Fix's 3-point rule: barycentrics (2/3, 1/6, 1/6). */
        for (int k = 0; k < 3; k++) {
            x[k] = rp_v3_add(rp_v3_scale(q->v[k], 2.0 / 3.0),
                             rp_v3_scale(rp_v3_add(q->v[(k + 1) % 3], q->v[(k + 2) % 3]), 1.0 / 6.0));
            w[k] = 1.0 / 3.0;
        }
        return 3;
    }
    /* 2 x 2 Gauss points of the bilinear patch, each weighted by the
     * patch's area element |dx/ds x dx/dt| there (linear in s and t for a
     * planar quad), so that the rule stays exact for quadratics in x on
     * any convex quad, not only on parallelograms (where the weights are
     * all 1/4). */
    const double g = 0.5 / sqrt(3.0), u[2] = {0.5 - g, 0.5 + g};
    double sum = 0;
    for (int k = 0; k < 4; k++) {
        double s = u[k & 1], t = u[k >> 1];
        x[k] = rp_v3_add(rp_v3_add(rp_v3_scale(q->v[0], (1 - s) * (1 - t)), rp_v3_scale(q->v[1], s * (1 - t))),
                         rp_v3_add(rp_v3_scale(q->v[2], s * t), rp_v3_scale(q->v[3], (1 - s) * t)));
        rp_vec3 ds = rp_v3_add(rp_v3_scale(rp_v3_sub(q->v[1], q->v[0]), 1 - t), rp_v3_scale(rp_v3_sub(q->v[2], q->v[3]), t));
        rp_vec3 dt = rp_v3_add(rp_v3_scale(rp_v3_sub(q->v[3], q->v[0]), 1 - s), rp_v3_scale(rp_v3_sub(q->v[2], q->v[1]), s));
        w[k] = rp_v3_length(rp_v3_cross(ds, dt));
        sum += w[k];
    }
    for (int k = 0; k < 4; k++)
        w[k] = sum > 0 ? w[k] / sum : 0.25;
    return 4;
}

/* The coupling coefficients of link qi <- l's source (K[0][0] = F), see the
 * top. */
static void link_coefficients(const hier_state *s, uint32_t qi, const hier_link *l, float out[8])
{
    const uint32_t pi = hier_link_src(l);
    const hier_node *q = &s->nodes[qi], *p = &s->nodes[pi];
    const hier_basis *bq = &s->basis[qi], *bp = &s->basis[pi];
    const rp_vec3 nq = s->faces[q->face].n;
    const int src_linear = s->faces[p->face].reflects; /* a pure emitter is uniform */
    hier_node quarter[4];
    double psi_p[4][3];
    if (src_linear) {
        hier_child_shapes(p, quarter);
        for (int c = 0; c < 4; c++) {
            psi_p[c][0] = quarter[c].area / p->area; /* (the weights of the mean) */
            psi_p[c][1] = phi(bp, 0, hier_node_c(&quarter[c]));
            psi_p[c][2] = phi(bp, 1, hier_node_c(&quarter[c]));
        }
    }
    rp_vec3 x[4];
    double w[4];
    int nx = receiver_rule(q, x, w);
    double K[3][3] = {{0}};
    for (int k = 0; k < nx; k++) {
        double psi_q[3] = {1, phi(bq, 0, x[k]), phi(bq, 1, x[k])};
        double col[3] = {0, 0, 0}; /* int_p psi_j G dy at x_k */
        if (src_linear)
            for (int c = 0; c < 4; c++) {
                double f = hier_point_to_node(s, x[k], nq, &quarter[c], LIN_DISK_RATIO);
                col[0] += f;
                col[1] += f * psi_p[c][1];
                col[2] += f * psi_p[c][2];
            }
        else
            col[0] = hier_point_to_node(s, x[k], nq, p, HIER_DISK_RATIO);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                K[i][j] += w[k] * psi_q[i] * col[j];
    }
    if (src_linear) {
        /* The quarters' sums give sum_c psi_j(c_c) int_c G = A_p (M g)_j
         * for a kernel linear across p, g its coefficients, M_jk = sum_c
         * (A_c / A_p) psi_j(c_c) psi_k(c_c) the quarters' centroids'
         * moments (3/4 of the identity for a parallelogram or triangle:
         * the centroids spread less than the points), whereas int_p psi_j G
         * is A_p g_j: M^-1 takes the one to the other, exact for a linear
         * kernel. */
        double M[2][2] = {{0, 0}, {0, 0}};
        for (int c = 0; c < 4; c++)
            for (int j = 0; j < 2; j++)
                for (int k = 0; k < 2; k++)
                    M[j][k] += psi_p[c][0] * psi_p[c][1 + j] * psi_p[c][1 + k];
        double det = M[0][0] * M[1][1] - M[0][1] * M[1][0];
        if (det > 1e-12) {
            double Mi[2][2] = {{M[1][1] / det, -M[0][1] / det}, {-M[1][0] / det, M[0][0] / det}};
            for (int i = 0; i < 3; i++) {
                double a = K[i][1], b = K[i][2];
                K[i][1] = Mi[0][0] * a + Mi[0][1] * b;
                K[i][2] = Mi[1][0] * a + Mi[1][1] * b;
            }
        } else if (M[0][0] > 1e-12)
            /* a sliver with one linear function (hier_basis_of) */
            for (int i = 0; i < 3; i++)
                K[i][1] /= M[0][0];
    }
    /* The visibility (and the estimate) of the constant basis's F. */
    double v = K[0][0] > 0 ? (double)hier_link_F(l) / K[0][0] : 0;
    for (int m = 1; m < 9; m++)
        out[m - 1] = (float)(v * K[m / 3][m % 3]);
}

void hier_linear_coef(const hier_state *s, const hier_link *l, double K[3][3])
{
    const float *c = s->lin_K + (size_t)hier_link_slot(l) * 8;
    K[0][0] = hier_link_F(l);
    for (int m = 1; m < 9; m++)
        K[m / 3][m % 3] = c[m - 1];
}

rp_status hier_linear_links(hier_state *s, rp_error *err)
{
    const size_t nl = s->nlinks;
    size_t fresh = 0;
    for (size_t k = 0; k < nl; k++)
        fresh += !(s->links[k].flags & HIER_LINK_COEF);
    if (fresh == 0)
        return RP_OK;
    uint32_t *todo = malloc(2 * fresh * sizeof *todo), *todo_r = todo + fresh; /* links, their receivers */
    if (!todo)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu linear links", nl);
    /* Slots of links since replaced are dead: when they would be more than
     * a fifth of the pool, the live ones are copied into a new pool, in link
     * order. */
    if (s->nlin_K + fresh > nl + nl / 4 + 1024) {
        float *pool = malloc((nl ? nl : 1) * 8 * sizeof *pool); /* the live ones and the new */
        if (!pool) {
            free(todo);
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu linear links", nl);
        }
        uint32_t m = 0;
        for (size_t k = 0; k < nl; k++) {
            hier_link *l = &s->links[k];
            if (!(l->flags & HIER_LINK_COEF))
                continue;
            memcpy(pool + (size_t)m * 8, s->lin_K + (size_t)hier_link_slot(l) * 8, 8 * sizeof *pool);
            hier_link_set_slot(l, m++);
        }
        free(s->lin_K);
        s->lin_K = pool;
        s->cap_lin_K = nl ? nl : 1;
        s->nlin_K = m;
    }
    if (s->nlin_K + fresh > UINT32_MAX || !hier_grow((void **)&s->lin_K, &s->cap_lin_K, s->nlin_K + fresh,
                                                      8 * sizeof *s->lin_K)) {
        free(todo);
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for %zu linear links", nl);
    }
    size_t n = 0;
    for (uint32_t i = 0; i < s->nnodes; i++)
        for (uint32_t k = s->link_start[i]; k < s->link_start[i + 1]; k++)
            if (!(s->links[k].flags & HIER_LINK_COEF)) {
                todo[n] = k;
                todo_r[n++] = i;
                hier_link_set_slot(&s->links[k], (uint32_t)s->nlin_K++);
            }
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 64)
    for (long t = 0; t < (long)n; t++) {
        const hier_link *l = &s->links[todo[t]];
        link_coefficients(s, todo_r[t], l, s->lin_K + (size_t)hier_link_slot(l) * 8);
    }
    free(todo);
    return RP_OK;
}

void hier_linear_free(hier_state *s)
{
    free(s->basis);
    free(s->B1);
    free(s->Bg1);
    free(s->Bd1);
    free(s->lin_K);
}

void hier_linear_gather(const hier_state *s, uint32_t q, double *acc, double *acc1)
{
    const size_t nb = s->nb;
    for (size_t b = 0; b < nb; b++)
        acc[b] = acc1[2 * b] = acc1[2 * b + 1] = 0;
    for (uint32_t k = s->link_start[q]; k < s->link_start[q + 1]; k++) {
        const hier_link *l = &s->links[k];
        /* K_01 K_02 K_10 K_11 K_12 K_20 K_21 K_22 (hier_linear_coef) */
        const float *K = s->lin_K + (size_t)hier_link_slot(l) * 8;
        const double F = hier_link_F(l);
        const size_t pi = hier_link_src(l);
        const double *Bp = s->B + pi * nb, *B1p = s->B1 + pi * nb * 2;
        for (size_t b = 0; b < nb; b++) {
            double c0 = Bp[b], c1 = B1p[2 * b], c2 = B1p[2 * b + 1];
            acc[b] += F * c0 + K[0] * c1 + K[1] * c2;
            acc1[2 * b] += K[2] * c0 + K[3] * c1 + K[4] * c2;
            acc1[2 * b + 1] += K[5] * c0 + K[6] * c1 + K[7] * c2;
        }
    }
}

void hier_linear_push(hier_state *s, uint32_t i)
{
    const size_t nb = s->nb;
    const hier_node *nd = &s->nodes[i];
    for (uint32_t c = nd->child; c < nd->child + 4; c++) {
        double a[2], A[2][2];
        hier_linear_relation(s, i, c, a, A);
        for (size_t b = 0; b < nb; b++) {
            const size_t at = ((size_t)i * nb + b) * 2, ct = ((size_t)c * nb + b) * 2;
            const double L[2] = {s->Bd1[at] + s->Bg1[at], s->Bd1[at + 1] + s->Bg1[at + 1]};
            const double down = s->Bg[(size_t)i * nb + b] + hier_linear_restrict(a, A, L, s->Bd1 + ct);
            s->Bg[(size_t)c * nb + b] += down;
        }
    }
}

void hier_linear_pull(hier_state *s, uint32_t i, const double w[4])
{
    const size_t nb = s->nb;
    const hier_node *nd = &s->nodes[i];
    for (size_t b = 0; b < nb; b++)
        s->B1[((size_t)i * nb + b) * 2] = s->B1[((size_t)i * nb + b) * 2 + 1] = 0;
    for (uint32_t c = nd->child; c < nd->child + 4; c++) {
        const double wc = w[c - nd->child];
        double ar[2], A[2][2];
        hier_linear_relation(s, i, c, ar, A);
        for (size_t b = 0; b < nb; b++) {
            const size_t at = ((size_t)i * nb + b) * 2, ct = ((size_t)c * nb + b) * 2;
            double dB = s->B[(size_t)c * nb + b] - s->B[(size_t)i * nb + b];
            for (int k = 0; k < 2; k++)
                s->B1[at + k] += wc * (ar[k] * dB + A[k][0] * s->B1[ct] + A[k][1] * s->B1[ct + 1]);
        }
    }
}

void hier_linear_chain_sums(const hier_state *s, double *S0, double *S1)
{
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        double own0 = 0, own1[2] = {0, 0};
        for (uint32_t k = s->link_start[i]; k < s->link_start[i + 1]; k++) {
            double K[3][3];
            hier_linear_coef(s, &s->links[k], K);
            own0 += K[0][0];
            own1[0] += K[1][0];
            own1[1] += K[2][0];
        }
        if (s->cl_nff && i < s->cl_nn)
            own0 += s->cl_nff[i];
        S0[i] = own0;
        S1[2 * i] = own1[0];
        S1[2 * i + 1] = own1[1];
        if (nd->parent == RP_NONE)
            continue;
        /* The parent's sum, a linear function on it, restricted to i. */
        double a[2], A[2][2], r[2];
        hier_linear_relation(s, nd->parent, (uint32_t)i, a, A);
        S0[i] += S0[nd->parent] + hier_linear_restrict(a, A, S1 + 2 * (size_t)nd->parent, r);
        S1[2 * i] += r[0];
        S1[2 * i + 1] += r[1];
    }
}

double hier_linear_rule_mean(const hier_state *s, const hier_node *q, const hier_node *p)
{
    rp_vec3 x[4];
    double w[4], m = 0;
    int nx = receiver_rule(q, x, w);
    for (int k = 0; k < nx; k++)
        m += w[k] * hier_point_to_node(s, x[k], s->faces[q->face].n, p, HIER_DISK_RATIO);
    return m;
}
