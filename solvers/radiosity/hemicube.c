/* The hemicube (Cohen & Greenberg 1985), rasterised on the CPU.
 *
 * A half cube of side 2 stands on element i's centroid c, oriented by i's
 * normal: a top face of res x res pixels at height 1 and four side faces of
 * res x res/2 pixels.  Every element in front of i's plane is transformed
 * into the cube's frame and, for each of the five faces, clipped against
 * that face's viewing pyramid (Sutherland-Hodgman, the near plane at the
 * scene's epsilon) and scan-converted: the pixel centres inside the
 * projected polygon are z-buffered on 1/depth, which is affine in screen
 * space for a planar polygon.  Each pixel then adds its delta form factor
 * to the element it sees.  Elements seen from behind occupy the z-buffer
 * (they occlude) but add nothing: the back of a surface is black.
 *
 * Delta form factors are the exact form factors from c to each pixel
 * square (Lambert's contour integral, the same routine as the analytic
 * method) rather than Cohen & Greenberg's midpoint values
 * dA / (pi (x^2 + y^2 + 1)^2): they sum to 1 to rounding, so what remains is
 * the hemicube's own error: the point (centroid) approximation of the outer
 * integral and aliasing, which falls with the resolution. */
#include "ff_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Bit marking a pixel's element as seen from behind. */
#define RP_HC_BACK 0x80000000u
/* A quad clipped by the five planes of a face's pyramid: at most 9 corners. */
#define RP_HC_MAXV 12

rp_status rp_ff_hemicube_init(rp_ff_context *ctx, rp_error *err)
{
    unsigned R = ctx->p.resolution, H = R / 2;
    ctx->res = R;
    ctx->dff_top = malloc((size_t)R * R * sizeof *ctx->dff_top);
    ctx->dff_side = malloc((size_t)R * H * sizeof *ctx->dff_side);
    if (!ctx->dff_top || !ctx->dff_side)
        return rp_error_set(err, RP_ERR_NOMEM, "hemicube: out of memory for resolution %u", R);
    double h = 2.0 / R;
    rp_vec3 o = rp_v3(0, 0, 0), z = rp_v3(0, 0, 1);
    for (unsigned py = 0; py < R; py++)
        for (unsigned px = 0; px < R; px++) {
            double x0 = -1 + px * h, y0 = -1 + py * h;
            rp_vec3 q[4] = {rp_v3(x0, y0, 1), rp_v3(x0 + h, y0, 1), rp_v3(x0 + h, y0 + h, 1),
                            rp_v3(x0, y0 + h, 1)};
            ctx->dff_top[(size_t)py * R + px] = fabs(rp_ff_point_polygon(o, z, q, 4));
        }
    /* Side face at x = 1: screen a along y, b (row) along z up from the
     * horizon. */
    for (unsigned pb = 0; pb < H; pb++)
        for (unsigned pa = 0; pa < R; pa++) {
            double a0 = -1 + pa * h, b0 = pb * h;
            rp_vec3 q[4] = {rp_v3(1, a0, b0), rp_v3(1, a0 + h, b0), rp_v3(1, a0 + h, b0 + h),
                            rp_v3(1, a0, b0 + h)};
            ctx->dff_side[(size_t)pb * R + pa] = fabs(rp_ff_point_polygon(o, z, q, 4));
        }
    return RP_OK;
}

rp_status rp_ff_hemicube_scratch(const rp_ff_context *ctx, rp_ff_scratch *s, rp_error *err)
{
    size_t R = ctx->res, npix = 3 * R * R;
    s->zbuf = malloc(npix * sizeof *s->zbuf);
    s->ibuf = malloc(npix * sizeof *s->ibuf);
    s->hrow = malloc((ctx->n ? ctx->n : 1) * sizeof *s->hrow);
    s->poly = malloc(4 * RP_HC_MAXV * sizeof *s->poly);
    if (!s->zbuf || !s->ibuf || !s->hrow || !s->poly)
        return rp_error_set(err, RP_ERR_NOMEM, "hemicube: out of memory for resolution %zu", R);
    return RP_OK;
}

/* Scan-converts the convex polygon P (face coordinates (a, b, w), w > 0)
 * into one face's buffers: rows x R pixels, screen x in [-1, 1], screen y
 * from y0.  nl, dl: the polygon's plane nl . X = dl in face coordinates. */
static void hc_raster(const rp_vec3 *P, uint32_t np, rp_vec3 nl, double dl, unsigned R,
                      unsigned rows, double y0, float *zb, uint32_t *ib, uint32_t id)
{
    double sx[RP_HC_MAXV], sy[RP_HC_MAXV];
    double ylo = INFINITY, yhi = -INFINITY;
    for (uint32_t k = 0; k < np; k++) {
        sx[k] = P[k].x / P[k].z;
        sy[k] = P[k].y / P[k].z;
        ylo = fmin(ylo, sy[k]);
        yhi = fmax(yhi, sy[k]);
    }
    double h = 2.0 / R;
    /* Rows whose centres y0 + (r + 0.5) h lie in [ylo, yhi]. */
    double rlo = ceil((ylo - y0) / h - 0.5), rhi = floor((yhi - y0) / h - 0.5);
    if (rlo < 0)
        rlo = 0;
    if (rhi > rows - 1.0)
        rhi = rows - 1.0;
    /* 1/w = (nl . (sx, sy, 1)) / dl: affine in screen space. */
    double A = nl.x / dl, B = nl.y / dl, C = nl.z / dl;
    for (long r = (long)rlo; r <= (long)rhi; r++) {
        double y = y0 + (r + 0.5) * h;
        double xl = INFINITY, xr = -INFINITY;
        for (uint32_t k = 0; k < np; k++) {
            uint32_t k1 = k + 1 == np ? 0 : k + 1;
            double ya = sy[k], yb = sy[k1];
            if ((y < ya && y < yb) || (y > ya && y > yb))
                continue;
            double x;
            if (ya == yb) { /* horizontal edge on this row: both ends */
                xl = fmin(xl, fmin(sx[k], sx[k1]));
                xr = fmax(xr, fmax(sx[k], sx[k1]));
                continue;
            }
            x = sx[k] + (y - ya) / (yb - ya) * (sx[k1] - sx[k]);
            xl = fmin(xl, x);
            xr = fmax(xr, x);
        }
        if (!(xl <= xr))
            continue;
        double clo = ceil((xl + 1) / h - 0.5), chi = floor((xr + 1) / h - 0.5);
        if (clo < 0)
            clo = 0;
        if (chi > R - 1.0)
            chi = R - 1.0;
        size_t row = (size_t)r * R;
        for (long c = (long)clo; c <= (long)chi; c++) {
            double x = -1 + (c + 0.5) * h;
            float iw = (float)(A * x + B * y + C);
            if (iw > zb[row + c]) {
                zb[row + c] = iw;
                ib[row + c] = id;
            }
        }
    }
}

void rp_ff_hemicube_row(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i)
{
    unsigned R = ctx->res, H = R / 2;
    size_t top = (size_t)R * R, side = (size_t)R * H, npix = top + 4 * side;
    for (size_t p = 0; p < npix; p++) {
        s->zbuf[p] = 0.0f;
        s->ibuf[p] = RP_NONE;
    }
    const rp_ff_elem *ei = &ctx->el[i];
    rp_vec3 t, b, n = ei->n, c = ei->c;
    rp_v3_basis(n, &t, &b);
    rp_vec3 *L = s->poly, *Q = s->poly + RP_HC_MAXV, *T1 = s->poly + 2 * RP_HC_MAXV,
            *T2 = s->poly + 3 * RP_HC_MAXV;

    for (size_t j = 0; j < ctx->n; j++) {
        if (j == i)
            continue;
        const rp_ff_elem *ej = &ctx->el[j];
        const double eps = ei->tol + ej->tol; /* plane-side tolerance of the pair */
        double hi = -INFINITY;
        for (uint32_t k = 0; k < ej->nv; k++)
            hi = fmax(hi, rp_v3_dot(n, ej->v[k]) - ei->d);
        if (hi <= eps) /* behind or in i's plane: below the horizon */
            continue;
        for (uint32_t k = 0; k < ej->nv; k++) {
            rp_vec3 d = rp_v3_sub(ej->v[k], c);
            L[k] = rp_v3(rp_v3_dot(t, d), rp_v3_dot(b, d), rp_v3_dot(n, d));
        }
        rp_vec3 nl = rp_v3(rp_v3_dot(t, ej->n), rp_v3_dot(b, ej->n), rp_v3_dot(n, ej->n));
        double dl = rp_v3_dot(nl, L[0]);
        if (fabs(dl) <= eps) /* the plane passes through c: seen edge-on */
            continue;
        /* c behind j's plane (dl > 0 means c on the back side). */
        uint32_t id = (uint32_t)j | (dl > 0 ? RP_HC_BACK : 0);

        for (int f = 0; f < 5; f++) {
            /* Face coordinates (a, b, w): screen (a/w, b/w), depth w. */
            for (uint32_t k = 0; k < ej->nv; k++) {
                rp_vec3 p = L[k];
                switch (f) {
                case 0: Q[k] = p; break;
                case 1: Q[k] = rp_v3(p.y, p.z, p.x); break;
                case 2: Q[k] = rp_v3(p.y, p.z, -p.x); break;
                case 3: Q[k] = rp_v3(p.x, p.z, p.y); break;
                default: Q[k] = rp_v3(p.x, p.z, -p.y); break;
                }
            }
            rp_vec3 nf;
            switch (f) {
            case 0: nf = nl; break;
            case 1: nf = rp_v3(nl.y, nl.z, nl.x); break;
            case 2: nf = rp_v3(nl.y, nl.z, -nl.x); break;
            case 3: nf = rp_v3(nl.x, nl.z, nl.y); break;
            default: nf = rp_v3(nl.x, nl.z, -nl.y); break;
            }
            /* Outcodes (Cohen & Sutherland): skip faces the polygon lies
             * wholly outside of one plane of, and clip only when needed. */
            unsigned all = 0x1f, any = 0;
            for (uint32_t k = 0; k < ej->nv; k++) {
                rp_vec3 p = Q[k];
                unsigned code = (p.z < eps) | (p.x + p.z < 0) << 1 | (p.z - p.x < 0) << 2 |
                                ((f == 0 ? p.y + p.z : p.y) < 0) << 3 | (p.z - p.y < 0) << 4;
                all &= code;
                any |= code;
            }
            if (all)
                continue;
            if (!any) {
                hc_raster(Q, ej->nv, nf, dl, R, f == 0 ? R : H, f == 0 ? -1.0 : 0.0,
                          s->zbuf + (f == 0 ? 0 : top + (size_t)(f - 1) * side),
                          s->ibuf + (f == 0 ? 0 : top + (size_t)(f - 1) * side), id);
                continue;
            }
            /* The face's viewing pyramid: w >= eps, |a| <= w, and
             * |b| <= w (top) or 0 <= b <= w (sides, above the horizon). */
            uint32_t m = rp_ff_clip(Q, ej->nv, rp_v3(0, 0, 1), eps, T1);
            m = m >= 3 ? rp_ff_clip(T1, m, rp_v3(1, 0, 1), 0, T2) : 0;
            m = m >= 3 ? rp_ff_clip(T2, m, rp_v3(-1, 0, 1), 0, T1) : 0;
            m = m >= 3 ? rp_ff_clip(T1, m, f == 0 ? rp_v3(0, 1, 1) : rp_v3(0, 1, 0), 0, T2) : 0;
            m = m >= 3 ? rp_ff_clip(T2, m, rp_v3(0, -1, 1), 0, T1) : 0;
            if (m < 3)
                continue;
            if (f == 0)
                hc_raster(T1, m, nf, dl, R, R, -1.0, s->zbuf, s->ibuf, id);
            else
                hc_raster(T1, m, nf, dl, R, H, 0.0, s->zbuf + top + (size_t)(f - 1) * side,
                          s->ibuf + top + (size_t)(f - 1) * side, id);
        }
    }

    memset(s->hrow, 0, ctx->n * sizeof *s->hrow);
    for (size_t p = 0; p < npix; p++) {
        uint32_t id = s->ibuf[p];
        if (id == RP_NONE || (id & RP_HC_BACK))
            continue;
        s->hrow[id] += p < top ? ctx->dff_top[p] : ctx->dff_side[(p - top) % side];
    }
    s->hrow_i = i;
}
