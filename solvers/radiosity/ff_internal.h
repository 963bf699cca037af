/* Private to the form-factor module (formfactor.c, hemicube.c): the context
 * and scratch layouts and the helpers both files use. */
#ifndef RP_FF_INTERNAL_H
#define RP_FF_INTERNAL_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "formfactor.h"

/* Most vertices a convex polygon can have after a plane clips a quad. */
#define RP_FF_MAXV 6

/* Points of the far-pair rules on the receiver: stage 1a's (up to 4), then
 * stage 1b's (up to 9); see formfactor.c. */
#define RP_FF_FARPTS 13

/* An element as the form-factor code sees it: its polygon and plane. */
typedef struct rp_ff_elem {
    rp_vec3 v[4];     /* corners, counter-clockwise seen from the front */
    uint32_t nv;      /* 3 or 4 */
    uint32_t face;
    rp_vec3 n;        /* unit front normal */
    double d;         /* plane offset: n . x = d on the element */
    rp_vec3 c;        /* centroid */
    double area;
    double radius;    /* largest distance from c to a corner */
    rp_vec3 lo, hi;   /* bounding box */
    double tol;       /* plane-side tolerance (rp_ff_tol); a pair is judged
                         with the sum of its two */
} rp_ff_elem;

/* One adaptive-quadrature region: a rectangle [u0,u1] x [v0,v1] of the unit
 * square of map `map` (see formfactor.c), its estimate and error. */
typedef struct rp_ff_region {
    double u0, u1, v0, v1;
    double q, err;
    int map;
    int axis;         /* axis to split along next (0: u, 1: v) */
} rp_ff_region;

/* A cell [u0,u1] x [v0,v1] of a source element's parameter square in the
 * visibility estimate (formfactor.c, ff_visibility): f is the unoccluded
 * form factor to it from the current receiver point, inside a point of
 * its part in front of that point. */
typedef struct rp_ff_cell {
    double u0, u1, v0, v1, f;
    rp_vec3 inside;
    int depth;
} rp_ff_cell;

struct rp_ff_context {
    const rp_scene *scene;
    const rp_mesh *mesh;
    const rp_raycast *rc;
    rp_ff_params p;          /* with defaults filled in */
    size_t n;                /* elements */
    rp_ff_elem *el;
    /* Element edges: edge k of element e (v[k] -> v[k+1]) is mesh edge
     * eid[4e + k], run backwards from its canonical direction when
     * erev[4e + k]; elements of a surface share their common edges. */
    uint32_t *eid;
    unsigned char *erev;
    rp_vec3 *ea, *eb;        /* canonical ends of each edge */
    size_t nedges;
    /* Visibility of unordered pairs, shared by the threads: 0 unknown,
     * else 1 + V * 65520 (NULL when the mesh is too large to keep it);
     * 65520 = 2^4 3^2 5 7 13 keeps k/4, k/9 and k/16 exact. */
    _Atomic uint16_t *vcache;
    double tol_rel, tol_abs; /* analytic: error goal per pair */
    /* Visibility culling per pair of scene faces (NULL: not computed, every
     * pair casts rays): blk[blk_start[ab] .. + blk_count[ab]], ab =
     * fa * nfaces + fb, are the faces that could block a segment between
     * faces fa and fb; an empty list means no ray is needed, and
     * RP_FF_BLK_ALL in blk_count "too many to test: cast rays". */
    size_t nfaces;
    uint32_t *blk_start;
    uint32_t *blk_count;
    uint32_t *blk;
    rp_vec3 *face_lo, *face_hi;  /* face bounding boxes */
    double *face_tol;            /* face plane-side tolerances (rp_ff_tol) */
    /* Hemicube: exact delta form factors of the top face (res x res) and of
     * one side face (res x res/2, row 0 at the horizon). */
    unsigned res;
    double *dff_top, *dff_side;
};

#define RP_FF_BLK_ALL UINT32_MAX

struct rp_ff_scratch {
    /* adaptive quadrature heap */
    rp_ff_region *heap;
    size_t heap_cap;
    /* visibility: cells of the source still to split or to cast to, and
     * the pair's segments (ends, weights, answers) cast together */
    rp_ff_cell *vis_heap;
    rp_vec3 *vis_x, *vis_y;
    double *vis_w;
    unsigned char *vis_blocked;
    /* Far-pair rules on the current receiver: points, weights (Jacobian
     * included) and the per-edge contour terms at those points, valid for
     * edges whose stamp equals `stamp`. */
    uint32_t far_i;
    uint32_t nfar_a, nfar_b;     /* points of stage 1a and 1b */
    rp_vec3 far_x[RP_FF_FARPTS];
    double far_w[RP_FF_FARPTS];  /* weights, Jacobian included */
    double *eterm;               /* RP_FF_FARPTS per edge */
    uint32_t *estamp_a, *estamp_b;
    uint32_t stamp;
    /* hemicube */
    float *zbuf;             /* 1/depth per pixel, top then four sides */
    uint32_t *ibuf;          /* element per pixel, RP_NONE for none */
    double *hrow;            /* last hemicube row */
    uint32_t hrow_i;         /* its element, RP_NONE if none */
    rp_vec3 *poly;           /* clipping workspace */
};

/* The differential form factor from a point p with unit normal n to the
 * convex polygon v[0..nv) (Lambert's contour integral; Baum, Rushmeier &
 * Winget 1989, eq. 2).  The polygon must lie in front of p's tangent plane
 * and be counter-clockwise seen from p's side of its plane. */
double rp_ff_point_polygon(rp_vec3 p, rp_vec3 n, const rp_vec3 *v, uint32_t nv);

/* Clips polygon in[0..nin) to the half-space dot(m, x) >= e (Sutherland &
 * Hodgman 1974); returns the vertex count written to out (room for
 * nin + 1). */
uint32_t rp_ff_clip(const rp_vec3 *in, uint32_t nin, rp_vec3 m, double e, rp_vec3 *out);

/* Hemicube row (hemicube.c); s->hrow gets the row and s->hrow_i = i. */
void rp_ff_hemicube_row(const rp_ff_context *ctx, rp_ff_scratch *s, uint32_t i);
/* Allocates the hemicube's delta form factors (context) and buffers (scratch). */
rp_status rp_ff_hemicube_init(rp_ff_context *ctx, rp_error *err);
rp_status rp_ff_hemicube_scratch(const rp_ff_context *ctx, rp_ff_scratch *s, rp_error *err);

#endif
