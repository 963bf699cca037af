/* The open part of each element (--open-fraction).
 *
 * A constant element stands for the mean radiosity of its area.  Where
 * another object rests on a face (a box standing on the floor) an element
 * that crosses the object's outline is partly enclosed: the part under the
 * box neither gathers light nor is seen.  Its links' visibility rays, drawn
 * over the whole element, find that part blocked, so what the element
 * gathers is its open fraction f times the radiosity of the open part, and
 * the element shows and sends that diluted mean to everything that sees
 * only the open part: on the Cornell box at `--bf-epsilon 0.05 --min-area
 * 1e-4` the box sides came out up to 3.8% dark and the ceiling 2.8% (the D0
 * discontinuities of Heckbert 1992 and Lischinski, Tampieri & Greenberg
 * 1992, which --mesh discontinuity removes by cutting the faces along
 * them; this measures them instead, for any mesh and refinement).
 *
 * Here each node's open fraction f is measured once, in the step that
 * makes the node, after refinement (hier_open_update): a grid of points on
 * it, each enclosed when every one of a few fixed rays from it lands on
 * the back of a face (the inside of the box); a node whose coarse grid is
 * neither all open nor all enclosed is measured again on a fine grid.  The
 * gather divides what a node gathers by its f (not less than OPEN_MIN),
 * so its value is that of its open part (what the camera and other
 * elements see); the pull weighs a leaf by its open area, and a
 * surface's average counts the enclosed part as emission only
 * (hier_surfaces).  With --basis linear the gathered linear coefficients
 * are divided too: a link's coupling takes its visibility as uniform over
 * the pair (hier_linear.c), so what a half-enclosed leaf gathers is f
 * times the function its open part would have, and the leaf keeps that
 * function.  (Not divided, it kept the whole leaf's, half the light on its
 * open half, and the Cornell box's sides came out 1.2 to 1.9% dark.)  In
 * an enclosure the row sums already do this (the leaf's form factors sum
 * to f, update_scale), so it is not used there; nor does the importance
 * sweep, which only weighs the refinement.  Gouraud vertex
 * values replace each link's gathered F / f by the point form factor at
 * the vertex (hier_image.c node_changes).
 *
 * Links that cast no rays (shaft culling) are consistent with this: a
 * link from a partly enclosed floor leaf to the box side standing on it
 * crosses the side's plane, and its form factor and rays cover only the
 * part in front of the side (hier_link.c), the open part; any other source
 * is seen from the enclosed part only through the box's faces, which then
 * lie between the two and are tested.  Measured on the Cornell box with
 * the row-sum cap (hierarchical.c open_row_caps): RMS surface error 0.31%
 * against 0.69% with --open-fraction off at the defaults, 1.41% against
 * 1.81% at --bf-epsilon 0.05 --min-area 1e-4 (image RMSE 0.00208 against
 * 0.00232, image mean -0.43 to -0.63% against -1.0 to -1.25%), for 8% more
 * rays (README.md has the table and its commands). */
#include <math.h>
#include <stdlib.h>

#include "hier_internal.h"

/* Coarse and fine grids of points per side; rays per point: one along
 * the normal and two rings of OPEN_RING, 1 and 1.4 radians off it (the
 * grazing ring lets a point under a one-sided overhang out: only the
 * light beyond 80 degrees, 3% of a cosine-weighted hemisphere, is lost
 * where even that ring is blocked). */
#define OPEN_COARSE 3
#define OPEN_FINE 12
#define OPEN_RING 4
/* A node's fraction is held as its count of open points on the fine grid
 * (a coarse grid all open or all enclosed as all or none of them), one
 * byte; count / OPEN_FINE^2 is the same double as before it was held. */
#define OPEN_POINTS (OPEN_FINE * OPEN_FINE)
_Static_assert(OPEN_POINTS <= UINT8_MAX, "an open count fits a byte");

/* The smallest divisor (one of a link's default 16 ray pairs): below it
 * the few rays of a node's links that reach its open part would be
 * amplified without bound rather than measured. */
#define OPEN_MIN (1.0 / 16)

/* 1 if every ray from point x (on a face with normal n) lands on the back
 * of a face; k turns the rings from point to point. */
static int ray_enclosed(const hier_state *s, rp_vec3 x, rp_vec3 n, rp_vec3 dir, double *rays)
{
    rp_hit hit;
    *rays += 1;
    return rp_ray_closest_from(s->rc, x, n, dir, &hit) && !hit.front;
}

static int point_enclosed(const hier_state *s, rp_vec3 x, rp_vec3 n, int k, double *rays)
{
    static const double theta[2] = {1.0, 1.4};
    rp_vec3 t, b;
    rp_v3_basis(n, &t, &b);
    if (!ray_enclosed(s, x, n, n, rays))
        return 0;
    /* the second ring half a step round from the first */
    for (int r = 0; r < 2; r++)
        for (int j = 0; j < OPEN_RING; j++) {
            double phi = 2 * RP_PI * (j + 0.5 * r) / OPEN_RING + 0.9 * k;
            if (!ray_enclosed(s, x, n, hier_ring_dir(n, t, b, theta[r], phi), rays))
                return 0;
        }
    return 1;
}

/* Open points of node nd on a g x g grid of cell centres. */
static int grid_open(const hier_state *s, const hier_node *nd, int g, double *rays)
{
    rp_vec3 n = s->faces[nd->face].n;
    int open = 0;
    for (int k = 0; k < g * g; k++) {
        rp_vec3 x = hier_node_point(nd, (k % g + 0.5) / g, (k / g + 0.5) / g);
        open += !point_enclosed(s, x, n, k, rays);
    }
    return open;
}

rp_status hier_open_update(hier_state *s, rp_error *err)
{
    if (!s->open_on || s->open_n == s->nnodes)
        return RP_OK;
    if (!hier_grow((void **)&s->open, &s->cap_open, s->nnodes, sizeof *s->open))
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for open fractions");
    double rays = 0;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 64) reduction(+ : rays)
    for (long i = (long)s->open_n; i < (long)s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        int k = OPEN_POINTS; /* a face that does not reflect gathers nothing to divide */
        if (s->faces[nd->face].reflects) {
            k = grid_open(s, nd, OPEN_COARSE, &rays);
            if (k == OPEN_COARSE * OPEN_COARSE)
                k = OPEN_POINTS;
            else if (k > 0)
                k = grid_open(s, nd, OPEN_FINE, &rays);
        }
        s->open[i] = (uint8_t)k;
    }
    s->rays += rays;
    s->open_n = s->nnodes;
    return RP_OK;
}

double hier_open_fraction(const hier_state *s, uint32_t i)
{
    return s->open_on && i < s->open_n ? s->open[i] / (double)OPEN_POINTS : 1.0;
}

double hier_open_divisor(const hier_state *s, uint32_t i)
{
    const double f = hier_open_fraction(s, i);
    return f >= OPEN_MIN ? f : OPEN_MIN;
}
