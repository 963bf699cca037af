/* Importance-driven hierarchical radiosity (Smits, Arvo & Salesin 1992,
 * "An importance-driven radiosity algorithm", SIGGRAPH 92), --importance.
 *
 * Radiosity solves B = E + K B with K_ij = rho_i F_ij.  What a run is
 * asked for is a linear functional of B, <R, B> = sum_i R_i B_i: a pixel is
 * the mean of B / pi over what it sees, so the image's R_i is the share of
 * the image element i covers; a surface average is sum_i (A_i / A_s) B_i.
 * The importance Y solves the adjoint (transposed) system
 *
 *     Y = R + K^T Y,   Y_i = R_i + sum_j rho_j F_ji Y_j
 *
 * (the importance equation of Smits et al. 1992: the adjoint of B = E + K B;
 * section numbers are not cited here, the paper was not at hand), and then
 * <R, B> = <Y, E>: Y_i is what a unit of radiosity on i adds to the
 * answer, directly (R_i) or through every element j that gathers from i,
 * whose radiosity grows by rho_j F_ji (the power A_i F_ij = A_j F_ji that
 * leaves i towards j, reflected and spread over A_j) and counts Y_j.  So
 * importance travels along the links against the light, and it is the
 * reflectance of the light's receiver j that multiplies it.
 *
 * The hierarchy stores densities (area means) and links carry F_qp from
 * receiver q's point of view, so Y is held as the density y_i = Y_i / A_i.
 * Dividing the equation by A_i and using A_i F_ij = A_j F_ji:
 *
 *     y_q = r_q + sum_p F_qp rho_p y_p,   r_q = R_q / A_q,
 *
 * the radiosity equation with the reflectance moved from the receiver q to
 * the source p.  So importance is gathered over the very links light is
 * (same form factors, same push-pull, same row-sum normalisation in an
 * enclosure: hierarchical.c, importance_sweep), one Jacobi sweep before
 * every radiosity sweep, the two solved alternately as in the paper.
 *
 * Direct importance r:
 *   camera    one ray through the centre of every pixel (the image's own
 *             camera, camera.h); each front hit on a face adds 1 / pixels,
 *             spread as a density over the smallest element around it
 *             that holds enough hits to measure one (a cut of the
 *             quadtree, hier_importance_direct);
 *   surfaces  the radiosity of every face, by area: r = 1 on every face
 *             that reflects (R_i = A_i, each element's area share up to
 *             a constant).  (r = 1 / A_s, every surface's average alike,
 *             was tried: the small strips of the Cornell ceiling then
 *             dominate ybar below, the larger surfaces are refined less
 *             than without importance, and the elephant in the box came
 *             out 3.3% dark against the path tracer, 0.9% without.)
 * Faces that do not reflect get no direct importance: their radiosity is
 * their emission, exact whatever the links.
 *
 * The oracle for quadtree links (hier_link.c decide) weighs a link's
 * transfer by importance, as Smits et al. 1992 refine: a link q <- p is
 * refined while
 *
 *     F_err max(rho_q B_p y_q, rho_p y_p B_q) / ybar  >  bf_epsilon
 *
 * (worst band).  The first term is the error the link puts into the answer
 * through the light it carries, the second (the symmetric term: the same
 * links carry importance) the error through the importance it carries,
 * weighed by the radiosity it then meets.  ybar, the importance-weighted mean of y over the leaves of
 * the faces that reflect (sum A y^2 / sum A y, hier_importance_finish), keeps the
 * units and the meaning of --bf-epsilon: with a uniform y the first term
 * is the BF oracle's rho_q B_p F_err, and where y is typical of what is
 * seen, close to it.  (The larger of the two terms rather than their sum:
 * a link from a pure emitter, rho_p = 0, is then judged exactly as
 * without importance at uniform y.)  A face-level link whose visibility
 * rays were all blocked is judged without importance (hier_link.c): the
 * oracle's "keep" drops it for good.  Cluster links are judged without
 * importance too (hier_cluster.c cl_decide, where the measurements are).
 *
 * Determinism: the camera rays are one per pixel, written to their own
 * slots; every sum here runs in node or hit order. */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "../../geometry/camera.h"
#include "hier_internal.h"

/* Camera hits a node of the density cut holds at least (hier_importance_direct). */
#define HIER_IMP_HITS 16

rp_status hier_importance_init(hier_state *s, rp_error *err)
{
    if (s->importance == HIER_IMP_CAMERA) {
        const rp_camera *cam = rp_scene_camera(s->scene);
        if (!cam)
            return rp_error_set(err, RP_ERR_INPUT, "--importance camera: the scene has no camera");
        rp_camera_frame fr;
        rp_camera_frame_init(&fr, cam);
        const size_t w = fr.width, h = fr.height, n = w * h;
        hier_imp_hit *hits = malloc((n ? n : 1) * sizeof *hits);
        if (!hits)
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for importance rays");
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 16)
        for (long y = 0; y < (long)h; y++)
            for (size_t x = 0; x < w; x++) {
                hier_imp_hit *o = &hits[(size_t)y * w + x];
                o->face = RP_NONE;
                rp_vec3 d = rp_camera_direction(&fr, (double)x + 0.5, (double)y + 0.5);
                rp_hit hit;
                if (rp_ray_closest(s->rc, fr.eye, d, INFINITY, &hit) && hit.front && hit.face < s->nfaces) {
                    o->face = hit.face;
                    o->p = hit.p;
                }
            }
        s->rays += (double)n;
        /* Keep the hits on faces that reflect: the radiosity of one that
         * does not is its emission (0 for a black face) whatever the
         * links. */
        size_t m = 0;
        for (size_t k = 0; k < n; k++)
            if (hits[k].face != RP_NONE && s->faces[hits[k].face].reflects)
                hits[m++] = hits[k];
        s->imp_hits = hits;
        s->nimp_hits = m;
        s->imp_pixels = (double)n;
    }
    const size_t nb = s->nb;
    s->Y = malloc(s->cap_nodes * nb * sizeof *s->Y);
    if (!s->Y)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for importance");
    rp_status st = hier_importance_direct(s, err);
    if (st != RP_OK)
        return st;
    /* Y starts at its direct term, as B at E. */
    for (size_t i = 0; i < s->nnodes; i++)
        for (size_t b = 0; b < nb; b++)
            s->Y[i * nb + b] = s->Y0[i];
    hier_importance_finish(s);
    return RP_OK;
}

rp_status hier_importance_direct(hier_state *s, rp_error *err)
{
    if (!hier_grow((void **)&s->Y0, &s->cap_Y0, s->nnodes, sizeof *s->Y0))
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for importance");
    double *r = s->Y0;
    const size_t nn = s->nnodes;
    if (s->importance == HIER_IMP_CAMERA) {
        /* Hits per node (a leaf's count in it and all its ancestors). */
        uint32_t *cnt = calloc(nn ? nn : 1, sizeof *cnt);
        unsigned char *cut = malloc(nn ? nn : 1);
        if (!cnt || !cut) {
            free(cnt);
            free(cut);
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for importance");
        }
        for (size_t k = 0; k < s->nimp_hits; k++) {
            double w[4];
            for (uint32_t i = hier_locate(s, s->imp_hits[k].face, s->imp_hits[k].p, w); i != RP_NONE;
                 i = s->nodes[i].parent)
                cnt[i]++;
        }
        /* Hit densities on a cut of each quadtree: a node is split only
         * while each of its children holds HIER_IMP_HITS hits, and every
         * leaf below a node of the cut gets its density, hits / (pixels x
         * area).  One hit per leaf would make the direct importance of
         * leaves smaller than a pixel's footprint 0 or a spike (the
         * oracle would refine them at random); on a cut the densities
         * still add up, area-weighted, to the share of the image each
         * face covers.  Parents come before children in node order. */
        const double wpix = 1.0 / s->imp_pixels;
        for (size_t i = 0; i < nn; i++) {
            const hier_node *nd = &s->nodes[i];
            if (nd->parent != RP_NONE && cut[nd->parent]) {
                r[i] = r[nd->parent];
                cut[i] = 1;
                continue;
            }
            int split = nd->child != RP_NONE;
            for (uint32_t c = 0; split && c < 4; c++)
                split = cnt[nd->child + c] >= HIER_IMP_HITS;
            cut[i] = (unsigned char)!split;
            r[i] = !split && nd->area > 0 ? cnt[i] * wpix / nd->area : 0;
        }
        free(cnt);
        free(cut);
    } else {
        /* Uniform on every face that reflects (the radiosity of one that
         * does not is its emission, with no error to weigh). */
        for (size_t i = 0; i < nn; i++)
            r[i] = s->faces[s->nodes[i].face].reflects ? 1.0 : 0.0;
    }
    return RP_OK;
}

void hier_importance_finish(hier_state *s)
{
    const size_t nb = s->nb;
    /* ybar, the importance-weighted mean of y (sum A y^2 / sum A y over
     * the leaves of the faces that reflect, worst band): the importance where the
     * answer is.  The area mean would make ybar 1/6 of a wall's y when
     * only that wall is seen in a cube, and refine it 6 times finer than
     * without importance; this way what matters is refined as without
     * importance, and what does not, less. */
    double ay = 0, a = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE || !s->faces[nd->face].reflects)
            continue;
        double y = 0;
        for (size_t b = 0; b < nb; b++)
            y = hier_max(y, s->Y[i * nb + b]);
        ay += nd->area * y * y;
        a += nd->area * y;
    }
    s->y_scale = ay > 0 ? a / ay : 0;
}

double hier_importance_error(const hier_state *s, const double *rho_q, const double *Bq, const double *Yq,
                             const double *rho_p, const double *Bp, const double *Yp)
{
    double e = 0;
    for (size_t b = 0; b < s->nb; b++)
        e = hier_max(e, hier_max(rho_q[b] * Bp[b] * Yq[b], rho_p[b] * Yp[b] * Bq[b]));
    return e * s->y_scale;
}

void hier_importance_free(hier_state *s)
{
    free(s->Y);
    free(s->Y0);
    free(s->imp_hits);
    s->Y = s->Y0 = NULL;
    s->imp_hits = NULL;
}
