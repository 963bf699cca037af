/* Hierarchical radiosity's private state, shared by hierarchical.c (the
 * solver), hier_tree.c (quadtrees and geometry), hier_link.c (form-factor
 * estimates and link refinement) and hier_image.c (answers).  Not a public
 * module. */
#ifndef RP_HIER_INTERNAL_H
#define RP_HIER_INTERNAL_H

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../../geometry/raycast.h"
#include "../../geometry/scene.h"
#include "../../geometry/simplify.h"
#include "reconstruct.h"
#include "../solver.h"
#include "hierarchical.h"

/* Per-band arrays on the stack. */
#define HIER_MAX_BANDS 256
/* Without clustering, scenes with more faces are refused by default (the
 * initial linking is O(n^2)). */
#define HIER_DEFAULT_MAX_FACES 4096
/* Root-pair occluder lists (shaft culling) up to this many occluder
 * units.  Up to this many faces a unit is a face; above, the faces of a
 * surface of more than HIER_CULL_GROUP_FACES faces (a mesh) are one unit,
 * their box (hier_link.c cull_units). */
#define HIER_CULL_MAX_FACES 512
#define HIER_CULL_GROUP_FACES 64
/* A point far from a source (r^2 > ratio x source area) uses the disk
 * approximation instead of the contour integral. */
#define HIER_DISK_RATIO 1000.0
/* Receivers closer than sqrt(ratio x area) to the source's centroid
 * integrate the kernel over their four quarters, and take such links down
 * with them when they are split. */
#define HIER_NEAR_RATIO 16.0
/* Visibility rays per set at most: --vis-rays, and the value set of a
 * partly visible emitter's link (hier_link.c value_rays; a link casts
 * them from arrays on the stack). */
#define HIER_MAX_VIS_RAYS 64
#define HIER_MAX_SET_RAYS 256

/* A quadtree node: a root face or a piece of one.  Children are four
 * consecutive nodes with larger indices than their parent. */
typedef struct hier_node {
    rp_vec3 v[4];      /* corners, counter-clockwise from the front (3 for triangles) */
    double area;       /* (its centroid is computed: hier_node_c) */
    uint32_t face;     /* the scene face this node is part of (= its root's index) */
    uint32_t parent;   /* RP_NONE for roots */
    uint32_t child;    /* first of four children, RP_NONE for a leaf */
    uint16_t nverts;   /* 3 or 4 */
    uint16_t depth;    /* 0 for roots */
} hier_node;

static inline double hier_tri_area(rp_vec3 a, rp_vec3 b, rp_vec3 c)
{
    return 0.5 * rp_v3_length(rp_v3_cross(rp_v3_sub(b, a), rp_v3_sub(c, a)));
}

/* The area (into *area) and area centroid of the polygon of a node's
 * corners v (nverts 3 or 4; a convex quad is two triangles). */
static inline rp_vec3 hier_polygon_c(const rp_vec3 *v, int nverts, double *area)
{
    rp_vec3 c1 = rp_v3_scale(rp_v3_add(rp_v3_add(v[0], v[1]), v[2]), 1.0 / 3.0);
    double a1 = hier_tri_area(v[0], v[1], v[2]);
    if (nverts == 3) {
        *area = a1;
        return c1;
    }
    double a2 = hier_tri_area(v[0], v[2], v[3]);
    rp_vec3 c2 = rp_v3_scale(rp_v3_add(rp_v3_add(v[0], v[2]), v[3]), 1.0 / 3.0);
    *area = a1 + a2;
    return *area > 0 ? rp_v3_scale(rp_v3_add(rp_v3_scale(c1, a1), rp_v3_scale(c2, a2)), 1.0 / *area) : c1;
}

/* A node's area centroid, computed from its corners as it was when nodes
 * held it (24 bytes a node): the same operations, so the same bits. */
static inline rp_vec3 hier_node_c(const hier_node *nd)
{
    if (nd->nverts == 3)
        return rp_v3_scale(rp_v3_add(rp_v3_add(nd->v[0], nd->v[1]), nd->v[2]), 1.0 / 3.0);
    double area;
    return hier_polygon_c(nd->v, nd->nverts, &area);
}

enum {
    HIER_LINK_PARTIAL = 1u << 0,  /* some visibility rays blocked */
    HIER_LINK_STRADDLE = 1u << 1, /* one element crosses the other's plane */
    HIER_LINK_TESTED = 1u << 2,   /* visibility was sampled by rays */
    HIER_LINK_INVISIBLE = 1u << 3, /* every deciding ray blocked: kept only
                                     until the oracle decides not to refine
                                     it, unless the value's rays found it
                                     visible (link_value, hier_link.c) */
    HIER_LINK_SHARES = 1u << 4,   /* share[] holds the source's children's
                                     shares (hierarchical.c, source_value) */
    HIER_LINK_COEF = 1u << 5,     /* --basis linear: share[0], share[1] hold
                                     the link's slot in lin_K (hier_linear.c) */
    HIER_LINK_PENDING = 1u << 6,  /* F is not set yet: the value's rays wait
                                     for the oracle (hier_refine), which
                                     does not read F */
    HIER_LINK_GONE = 1u << 7      /* within a refinement pass: the stored
                                     link leaves the list (split or dropped) */
};

/* A link's shares of its source's four children are kept in 10 bits each
 * as multiples of 1/HIER_SHARE_ONE; the fourth is what the first three
 * leave, so they add up to exactly one (hier_link_set_shares). */
#define HIER_SHARE_ONE 1023u
#define HIER_SHARE_BITS 10

/* A one-way link: the receiver gathers rho F B_src through it.  14 bytes:
 * links are most of the method's memory (the bunny scene: 0.5M links,
 * 0.4M cluster links, 1M cluster entries; the Cornell box at 10^6 leaves
 * 107M links), and a link's form factor needs no more than the upper 24
 * bits of a float (15 bits of mantissa, rounded: 1.5e-5 relative, far
 * below its visibility rays' noise), the oracle's bound 8 bits of
 * mantissa (rounded up, so it stays a bound) and a share of a source's
 * child 10 bits (their sums are taken in double).  The receiver is not
 * stored: the list is sorted by it (link_start), and links not yet in the
 * list carry theirs beside them.  Every member is a byte or two, so the
 * struct needs no padding; read and write src and F through
 * hier_link_src, hier_link_F and their setters. */
typedef struct hier_link {
    uint16_t src_[2]; /* the source node (hier_link_src) */
    uint16_t F_err;   /* the oracle's form-factor bound (unoccluded estimate
                         for partial or straddling links), packed by
                         hier_bound_pack: read it with hier_link_ferr */
    uint8_t F_[3];    /* form-factor estimate times visibility: the upper 24
                         bits of a float (hier_link_F) */
    uint8_t flags;
    uint8_t share[4]; /* three 10-bit shares of the source's children 0-2
                         in the kernel seen from the receiver's centre, when
                         flags has HIER_LINK_SHARES (child 3 has the rest);
                         or, with HIER_LINK_COEF, a 32-bit slot */
} hier_link;

static inline uint32_t hier_link_src(const hier_link *l) { return (uint32_t)l->src_[0] | (uint32_t)l->src_[1] << 16; }

static inline void hier_link_set_src(hier_link *l, uint32_t src)
{
    l->src_[0] = (uint16_t)(src & 0xffffu);
    l->src_[1] = (uint16_t)(src >> 16);
}

static inline float hier_link_F(const hier_link *l)
{
    uint32_t u = (uint32_t)l->F_[0] << 8 | (uint32_t)l->F_[1] << 16 | (uint32_t)l->F_[2] << 24;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* F rounded to the nearest 24-bit value (a carry out of the mantissa steps
 * the exponent, as it should). */
static inline void hier_link_set_F(hier_link *l, double F)
{
    float f = (float)F;
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    if ((u & 0x7f800000u) != 0x7f800000u) /* not inf or NaN */
        u += 0x80u;
    l->F_[0] = (uint8_t)(u >> 8);
    l->F_[1] = (uint8_t)(u >> 16);
    l->F_[2] = (uint8_t)(u >> 24);
}

/* --basis linear (hier_linear.c): a node's linear basis functions
 * phi_k(x) = dot(g[k], x - c), k = 0, 1, orthonormal with the constant
 * over the node (the mean of phi_j phi_k over its area is delta_jk, that
 * of phi_k zero), and their dual vectors in the face's plane
 * (dot(g[j], h[k]) = delta_jk, so x - c = sum_k phi_k(x) h[k]). */
typedef struct hier_basis {
    rp_vec3 c;
    rp_vec3 g[2], h[2];
} hier_basis;

/* What is fixed per scene face. */
typedef struct hier_face {
    rp_vec3 n;          /* unit front normal */
    double d;           /* plane: dot(n, x) = d */
    rp_vec3 lo, hi;     /* bounding box */
    const double *rho;  /* per band */
    const double *Le;
    uint32_t surface;
    int reflects;       /* some band of rho is > 0 */
    int lit;            /* reflects, or emits in some band */
    double tol;         /* plane tolerance: hier_box_tol of its box plus its
                           non-planarity; a pair of faces is judged with
                           the sum of their two */
} hier_face;

/* A cluster (Smits, Arvo & Greenberg 1994): a node of a binary bounding-
 * volume hierarchy over the face roots (hier_cluster.c).  Items are face
 * roots (ids below nfaces) and clusters (nfaces + cluster index); clusters
 * are numbered in preorder, so a parent comes before its children. */
typedef struct hier_cluster {
    rp_vec3 lo, hi;      /* bounding box of its faces */
    rp_vec3 c;           /* box centre */
    double r;            /* half the box diagonal */
    double area;         /* sum of its faces' areas */
    rp_vec3 axis;        /* normal cone: unit axis and half-angle cosine */
    double cone_cos;     /* (-1 when the normals span more than a hemisphere) */
    double cone_sin;
    rp_vec3 nbar;        /* area-weighted mean normal (not unit) */
    int planar;          /* every face in the plane dot(axis, x) = pd */
    double pd;
    uint32_t child[2];   /* items */
    uint32_t parent;     /* cluster index, RP_NONE for the root */
    uint32_t first, count; /* range in cl_faces */
} hier_cluster;

/* A link with a cluster at one end or both (hier_cluster.c).  The energy
 * it carries is held as entries: a link received by a quadtree node owns
 * its entries (first, count in cl_nent), the links received by a cluster
 * share the entries drawn for its faces (cl_efirst, cl_ecount). */
typedef struct hier_clink {
    uint32_t recv, src; /* items */
    union {
        float Fu;       /* cluster receivers: unoccluded form-factor
                           estimate (kernel only), -1 until evaluated */
        uint32_t first; /* node receivers: their entries in cl_nent */
    };
    uint16_t count;     /* node receivers: how many entries (at most
                           --cluster-rays, 256); HIER_CL_NONE until the link
                           is evaluated (any receiver), then 0 for a
                           cluster receiver (1 while the pass that made it
                           draws its entries, hier_cluster.c evaluate) */
    uint16_t Fb;        /* the oracle's form-factor bound (geometry only,
                           so judged once), rounded up to 8 bits of
                           mantissa (hier_bound_pack); 0 when not
                           yet judged */
} hier_clink;

/* hier_clink.count of a link not yet evaluated. */
#define HIER_CL_NONE 0xffffu

/* One sampled piece of cluster-link transfer: node recv (a quadtree node,
 * or the root of a face below a receiving cluster) gathers rho F B[src],
 * src the leaf (when drawn) under a point of the source that an open ray
 * from recv reached. */
typedef struct hier_centry {
    uint32_t recv, src;
    float F;
} hier_centry;

/* An entry of a link received by a quadtree node: its receiver is the
 * link's, so it is not stored (8 bytes, not 12: the bunny scene holds
 * 1.3M of them). */
typedef struct hier_nentry {
    uint32_t src;
    float F;
} hier_nentry;

/* Items at or above this id are clusters, below it quadtree nodes. */
#define HIER_CL_BIT 0x80000000u
/* Clustering is on above this many faces with --cluster auto. */
#define HIER_CLUSTER_AUTO_FACES 512

typedef enum hier_recon {
    HIER_RECON_FLAT,
    HIER_RECON_GOURAUD,
    HIER_RECON_GATHER
} hier_recon;

/* --importance (Smits, Arvo & Salesin 1992): what the oracle weighs links
 * by, see hier_importance.c. */
typedef enum hier_importance {
    HIER_IMP_NONE,
    HIER_IMP_CAMERA,
    HIER_IMP_SURFACES
} hier_importance;

/* A camera ray's first hit on the front of a face (--importance camera). */
typedef struct hier_imp_hit {
    rp_vec3 p;
    uint32_t face;
} hier_imp_hit;

typedef struct hier_state {
    const rp_scene *scene;
    /* --simplify (reconstruct.h): scene is view.sol's, a coarser copy of
     * view.scene, which camera rays and final gathers see through view.rc;
     * the solution reaches their points through rp_solution_eval. */
    rp_recon_view view;
    /* --mesh discontinuity: the scene's faces cut into triangles that
     * conform to its D0 and D1 lines (owned; scene and view.scene are it) */
    rp_scene *disc;
    size_t nb, nfaces;
    int threads;
    unsigned want;
    int open_ended;
    rp_log_fn log;
    void *log_ctx;
    const atomic_int *cancel; /* rp_options.cancel, polled by the long loops */
    uint64_t seed;
    rp_raycast *rc;

    hier_face *faces;    /* nfaces */
    double e_norm[HIER_MAX_BANDS]; /* sum over faces of A E per band */
    double lit_area;     /* area of the faces that reflect or emit in some
                            band: the scale of --min-area, --cluster-area and
                            the oracle (black faces, however large, change
                            none of them) */

    hier_node *nodes;
    size_t nnodes, cap_nodes;
    double *B;           /* nnodes x nb: radiosity (area mean over the node) */
    double *Bg;          /* nnodes x nb: rho x radiosity gathered by the node's links;
                            the push then adds what its ancestors gathered
                            (hier_sweep), so no array for that part */
    /* --open-fraction (hier_open.c): per node, the fraction of its area
     * not enclosed by other geometry, held as the count of open points on
     * hier_open.c's fine grid (a byte, not a double: read it with
     * hier_open_fraction); open_n nodes measured so far. */
    int open_on;
    uint8_t *open;
    size_t open_n, cap_open;
    double *W;           /* nnodes: weight in the pull, the open area
                            (hier_open.c) of the leaves below that some
                            link reaches (see hier_sweep) */
    /* Row-sum normalisation in an enclosure (hierarchical.c, hier_sweep):
     * enclosure is 1 when every ray leaving a front lands on a front, so
     * the exact form factors of any element sum to 1; ff_scale[i] is then
     * 1 / (the form factors reaching leaf i through its own and its
     * ancestors' links).  With open fractions (open_on) it caps that sum,
     * each node's own part divided by its divisor, at 1 or at the undivided
     * sum if larger (hierarchical.c open_row_caps); otherwise it is not
     * allocated (hier_row_scale). */
    int enclosure;
    double *ff_scale;
    double *ff_lin;      /* --basis linear: nnodes x 2, the linear part of
                            each node's row sum times ff_scale (update_scale) */
    size_t cap_scale;

    hier_link *links;    /* sorted by receiver after every refinement pass,
                            which is where each one's receiver is known from */
    size_t nlinks, cap_links;
    uint32_t *link_start; /* nnodes + 1 offsets into links (CSR by receiver) */
    size_t cap_start;
    size_t start_nn;     /* the node count link_start covers: every pass that
                            makes nodes ends in links_merge or
                            hier_links_cover, before anything reads it */

    /* Shaft culling (Haines & Wallace 1994): for each pair of occluder
     * units, the units that may block a segment between them.  A unit is
     * a face, or the faces of a large mesh together (its box). */
    int cull;
    size_t nunits;
    uint32_t *face_unit; /* nfaces: each face's unit */
    uint32_t *unit_face; /* nunits: the face of a one-face unit, RP_NONE for a mesh */
    rp_vec3 *unit_lo, *unit_hi;
    uint32_t *pair_off;  /* nunits x nunits */
    uint16_t *pair_cnt;
    uint32_t *cand;
    size_t ncand;

    /* Clustering (hier_cluster.c); all NULL / 0 when it is off. */
    int clustering;
    size_t ncl;
    hier_cluster *cl;
    uint32_t *cl_faces;  /* faces in hierarchy order */
    double *cl_cum;      /* nfaces + 1 cumulative areas in that order */
    uint32_t *face_pos;  /* nfaces: position of each face in cl_faces */
    uint32_t *face_cl;   /* nfaces: the cluster a face root is a child of */
    double *cl_rho;      /* ncl x nb: largest reflectance below */
    double *cl_B;        /* ncl x nb: area-mean radiosity */
    uint32_t *cl_efirst, *cl_ecount; /* ncl: each cluster's entries in cl_cent */
    hier_centry *cl_cent; /* entries of the links clusters receive, by cluster */
    size_t ncl_cent, cap_cl_cent, ncl_cdead;
    uint32_t *cl_cvia;    /* for each of cl_cent: the source item of the link
                             it was drawn for (prune_entries; the entries of
                             a link a node receives need none) */
    size_t cap_cl_cvia;
    size_t cl_follow_nn;  /* nodes when cl_cent last followed the splits */
    hier_nentry *cl_nent; /* entries of the links quadtree nodes receive, each
                             link's in its range (first, count), the ranges
                             in the order of the links in clinks */
    size_t ncl_nent, cap_cl_nent, ncl_ndead; /* (dead entries have F = 0) */
    double *cl_nff;      /* per node (cl_nn of them): form factors of the
                            cluster-link entries it receives */
    unsigned char *cl_nreach; /* per node: some cluster-link entry reaches it */
    size_t cl_nn;
    hier_clink *clinks;
    size_t nclinks, cap_clinks;
    size_t clinks_refined, clinks_culled;
    size_t clinks_initial, links_initial;
    unsigned cluster_rays;
    unsigned cluster_face_rays; /* samples per face of a receiving cluster */
    double cl_area_rel, cl_area; /* power-error area scale (relative, absolute) */

    /* --ff-rule gauss: a link's form factor by hier_linear_rule_mean (the
     * receiver's Gauss points) for every pair that does not straddle. */
    int ff_gauss;

    /* --basis linear (hier_linear.c); all NULL / 0 with the constant basis.
     * B and Bg above keep the constant coefficients (the area means),
     * so surface averages, clusters, importance and the oracle read them
     * unchanged; the linear ones are kept beside them. */
    int linear;
    hier_basis *basis;   /* nnodes */
    double *B1, *Bg1, *Bd1; /* nnodes x nb x 2: the coefficients of phi_0, phi_1 */
    float *lin_K;        /* 8 per slot: a link's coupling coefficients but
                            the constant-to-constant one, which is F */
    size_t nlin_K, cap_lin_K;

    /* Importance (hier_importance.c); all NULL / 0 with --importance none. */
    hier_importance importance;
    double *Y;           /* nnodes x nb: importance density (area mean over the
                            node, like B), grown with the nodes */
    double *Y0;          /* nnodes: direct importance density (leaves) */
    size_t cap_Y0;
    hier_imp_hit *imp_hits; /* camera: the pixel-centre rays' hits */
    size_t nimp_hits;
    double imp_pixels;   /* camera: pixels in the image (hits weigh 1 / it) */
    double y_scale;      /* 1 / the importance-weighted mean importance of the
                            reflecting leaves (worst band): uniform importance weighs 1 */
    unsigned long imp_sweeps;
    size_t imp_nn;       /* nnodes when Y0 was last filled */

    /* Parameters. */
    double bf_rel, min_area_rel;   /* as given: relative */
    double bf_eps, min_area;       /* absolute */
    unsigned contact_levels;
    double min_area_contact;       /* min_area / 4^contact_levels */
    double partial_weight;
    double invisible_weight;
    double variation_weight;       /* --variation-weight (hier_link.c source_varies) */
    double tolerance;
    int tolerance_given;
    unsigned long max_iterations;
    int max_iterations_given;
    unsigned vis_rays;
    unsigned long max_faces;
    hier_recon recon;
    unsigned spp, gather_rays, vertex_rays;

    /* Progress. */
    int linked;
    unsigned long iterations, refine_passes;
    double residual;
    size_t links_full, links_partial, links_invisible, links_refined;
    double rays;         /* visibility rays cast so far */
    double form_factors; /* link form factors estimated so far */
    size_t bytes;
} hier_state;

/* ---- hier_tree.c ---- */

/* One root node per scene face (node i is face i). */
rp_status hier_nodes_init(hier_state *s, rp_error *err);
/* Gives node i four children (no-op if it has them); their radiosity
 * starts at the parent's. */
rp_status hier_subdivide(hier_state *s, uint32_t i, rp_error *err);
/* Gives back the per-node arrays' room beyond the nodes (an idle pass). */
void hier_nodes_trim(hier_state *s);
/* A point on a node from (u1, u2) in [0, 1)^2, uniform in area for
 * triangles and parallelograms. */
rp_vec3 hier_node_point(const hier_node *nd, double u1, double u2);
/* Area sampling of a convex polygon poly[0..m-1] (m <= 8): prepare fills
 * cum[0..m-2] with the cumulative areas of its fan from poly[0] and
 * returns 0 if the polygon has no area; point maps (u1, u2) in [0, 1)^2 to
 * a point uniform in area. */
int hier_polygon_prepare(const rp_vec3 *poly, int m, double *cum);
rp_vec3 hier_polygon_point(const rp_vec3 *poly, int m, const double *cum, double u1, double u2);
/* Lambert's contour integral (docs/ground-truth.md): the form factor from a
 * differential area at x with unit normal n to polygon poly[0..m-1],
 * clipped to the half-space in front of x's tangent plane. */
double hier_point_polygon(rp_vec3 x, rp_vec3 n, const rp_vec3 *poly, int m);
/* The leaf of face f that contains p (a point on the face), and the
 * interpolation weights of its corners at p (w[3] = 0 for triangles). */
uint32_t hier_locate(const hier_state *s, uint32_t f, rp_vec3 p, double w[4]);
/* Centroids and areas of the four children node i would get, without
 * creating them. */
void hier_child_centroids(const hier_node *nd, rp_vec3 c[4], double area[4]);
/* The corners, centroids, areas and face of the four children node nd
 * would get (the rest of out is not set), without creating them. */
void hier_child_shapes(const hier_node *nd, hier_node out[4]);
/* Memory the nodes, radiosities and links hold. */
size_t hier_bytes(const hier_state *s);

/* ---- hier_link.c ---- */

/* The form factor from a point x (unit normal n) on a receiver to source
 * node p: 0 if x is not in front of p; the disk approximation where the
 * squared distance exceeds far_ratio x p's area (never for 0); else the
 * contour integral. */
double hier_point_to_node(const hier_state *s, rp_vec3 x, rp_vec3 n, const hier_node *p, double far_ratio);

rp_status hier_cull_init(hier_state *s, rp_error *err);
/* 1 if a side of the convex hull of boxes a and b (their shaft, Haines &
 * Wallace 1994) other than a face of their union box has box o = (lo, hi),
 * grown by eps, wholly outside: then no segment from a point of a to a
 * point of b meets it.  The union box is the caller's test. */
int hier_outside_hull(const rp_vec3 a[2], const rp_vec3 b[2], const rp_vec3 o[2], double eps);
/* Links every pair of faces that can see each other. */
rp_status hier_link_initial(hier_state *s, rp_error *err);
/* One refinement pass with the current radiosities (Hanrahan et al. 1991,
 * sec. 5, "BF refinement"); *refined gets the links replaced. */
rp_status hier_refine(hier_state *s, size_t *refined, rp_error *err);

/* Measures the open fraction of the nodes made since the last call
 * (--open-fraction, hier_open.c). */
rp_status hier_open_update(hier_state *s, rp_error *err);
/* Node i's open fraction (1 when --open-fraction is off or does not apply). */
double hier_open_fraction(const hier_state *s, uint32_t i);
/* What node i's gathered radiosity is divided by: its open fraction, but
 * not less than the resolution of a link's rays (hier_open.c). */
double hier_open_divisor(const hier_state *s, uint32_t i);

/* The factor leaf i's gathered radiosity is multiplied by: the row-sum
 * normalisation of an enclosure or the cap of open fractions
 * (hierarchical.c update_scale), 1 where neither applies. */
static inline double hier_row_scale(const hier_state *s, size_t i)
{
    return s->enclosure || s->open_on ? s->ff_scale[i] : 1.0;
}

/* The direction theta radians off unit normal n, at azimuth phi about it
 * in the frame (t, b) of rp_v3_basis(n): the rings of fixed rays that
 * probe what surrounds a point (scene_is_enclosure, hier_open.c). */
static inline rp_vec3 hier_ring_dir(rp_vec3 n, rp_vec3 t, rp_vec3 b, double theta, double phi)
{
    rp_vec3 d = rp_v3_scale(n, cos(theta));
    d = rp_v3_madd(d, t, sin(theta) * cos(phi));
    return rp_v3_madd(d, b, sin(theta) * sin(phi));
}

/* Evaluates face-level link q <- p (0: none, 1: link, 2: every ray blocked). */
int hier_link_eval(const hier_state *s, uint32_t qi, uint32_t pi, hier_link *out, double *rays);
/* Appends n face-level links add[k] received by recv[k] and re-sorts the
 * list by receiver. */
rp_status hier_links_add(hier_state *s, const hier_link *add, const uint32_t *recv, size_t n, rp_error *err);

/* ---- hier_cluster.c ---- */

/* Builds the cluster hierarchy over the face roots. */
rp_status hier_cluster_init(hier_state *s, rp_error *err);
/* One refinement pass over the cluster links (the first one starts from
 * the root's self-link); face pairs become face-level links. */
rp_status hier_cluster_refine(hier_state *s, size_t *refined, rp_error *err);
/* Moves every entry of the clusters' pool whose source leaf has been split
 * since it was drawn down to one of that leaf's descendants (hier_step,
 * after a pass's refinement). */
void hier_cluster_follow_splits(hier_state *s);
/* Adds rho F B_src of every cluster-link entry to the receiving node's
 * gathered radiosity Bg (hier_sweep, between its gather and its push). */
void hier_cluster_gather_nodes(hier_state *s, double *Bg);
/* The same for importance: F rho_src Y_src into Yg (hier_importance.c). */
void hier_cluster_gather_importance(hier_state *s, double *Yg);
void hier_cluster_free(hier_state *s);
/* The oracle's bound on the form factor from any point of item recv to
 * item src (items: quadtree nodes, or clusters with HIER_CL_BIT):
 * min(1, A_src c_recv c_src / (pi d^2)), hier_cluster.c; 0 when the two
 * touch (always split), -1 when nothing can pass between them.  For the
 * tests. */
double hier_cluster_bound(const hier_state *s, uint32_t recv, uint32_t src);

/* ---- hier_linear.c ---- */

/* The basis of a node (its corners, centroid, area and face normal n set). */
void hier_basis_of(const hier_node *nd, rp_vec3 n, hier_basis *out);
/* Gives every link without one its coupling coefficients (after each
 * refinement pass), compacting lin_K when dead slots would be more than a
 * fifth of it. */
rp_status hier_linear_links(hier_state *s, rp_error *err);
/* Link k's coefficients K[i][j] (i receiver, j source; 0 the constant,
 * 1-2 phi_0, phi_1), K[0][0] = its F. */
void hier_linear_coef(const hier_state *s, const hier_link *l, double K[3][3]);
/* The two-scale relation of child node c with its parent p: on c,
 * phi^p_i = a[i] + sum_k A[i][k] phi^c_k. */
void hier_linear_relation(const hier_state *s, uint32_t p, uint32_t c, double a[2], double A[2][2]);
/* Receiver q's gathered sums over its links, before rho: acc[b] for the
 * constant, acc1[2 b + k] for phi_k. */
void hier_linear_gather(const hier_state *s, uint32_t q, double *acc, double *acc1);
/* Push: node i's children's Bd1 from i's Bd1 + Bg1, and their Bg gains
 * i's Bg (by then what i and its ancestors gathered) plus i's linear
 * function's mean over each child. */
void hier_linear_push(hier_state *s, uint32_t i);
/* Pull: node i's B1 from its children's, weighted as its B was (w, the
 * weights of hierarchical.c's pull_children); i's B must be set. */
void hier_linear_pull(hier_state *s, uint32_t i, const double w[4]);
/* The form factors reaching each node through its own links and its
 * ancestors' as a linear function on it, S0[i] + S1[2 i .. 2 i + 1] . phi
 * (chain_sums of hierarchical.c with the ancestors' linear parts pushed
 * down; exactly 1 everywhere in an enclosure). */
void hier_linear_chain_sums(const hier_state *s, double *S0, double *S1);
/* --basis linear: the unoccluded form factor of link q <- p by the rule
 * over q of the coupling coefficients (exact where the kernel is quadratic
 * across q), so that a link's F and its linear coefficients are one
 * integral's. */
double hier_linear_rule_mean(const hier_state *s, const hier_node *q, const hier_node *p);
/* Radiosity at point x of leaf i: B + B1 . phi(x) (nb bands). */
void hier_linear_eval(const hier_state *s, uint32_t i, rp_vec3 x, double *out);
void hier_linear_free(hier_state *s);

/* ---- hier_importance.c ---- */

/* Sets up s->importance's direct term (camera: casts one ray through each
 * pixel centre) and the roots' importance Y = Y0. */
rp_status hier_importance_init(hier_state *s, rp_error *err);
/* Fills s->Y0 for the current leaves (density: importance per unit area). */
rp_status hier_importance_direct(hier_state *s, rp_error *err);
/* After an importance sweep: y_scale (1 / ybar). */
void hier_importance_finish(hier_state *s);
/* The oracle's weight of the transfer q <- p through F (max over bands of
 * F (rho_q B_p Y_q + ...) y_scale), for quadtree links (hier_link.c;
 * cluster links are judged without importance, hier_cluster.c). */
double hier_importance_error(const hier_state *s, const double *rho_q, const double *Bq, const double *Yq,
                             const double *rho_p, const double *Bp, const double *Yp);
void hier_importance_free(hier_state *s);

/* ---- hier_image.c ---- */

/* Area-weighted mean of B / pi over each surface's leaves: out[s * nb + b]. */
void hier_surfaces(const hier_state *s, double *out);
/* The camera image (width x height x nb radiance) and optional per-pixel
 * variance of the mean; *rays gets the rays cast added. */
rp_status hier_image(const hier_state *s, float *out, float *variance, double *rays,
                     rp_error *err);

/* Crack-free vertex radiosities for Gouraud interpolation (hier_image.c),
 * built from the current leaves. */
typedef struct hier_vertices hier_vertices;
rp_status hier_vertices_create(const hier_state *s, hier_vertices **out, rp_error *err);
void hier_vertices_destroy(hier_vertices *v);
/* Interpolated radiosity (nb bands) at point p of face `face`. */
void hier_vertices_eval(const hier_state *s, const hier_vertices *v, uint32_t face, rp_vec3 p, double *B);
/* How many vertices were anchored as T-vertices, and how many there are. */
size_t hier_vertices_tcount(const hier_vertices *v);
size_t hier_vertices_count(const hier_vertices *v);

/* ---- shared helpers ---- */

/* fmax and fmin without the library call (no NaNs reach them). */
static inline double hier_max(double a, double b) { return a > b ? a : b; }
static inline double hier_min(double a, double b) { return a < b ? a : b; }

/* A plane-side tolerance for geometry within the box [lo, hi]: 1e-9 of the
 * box's own diagonal plus the double rounding of its coordinates'
 * magnitudes, never the scene's size. */
static inline double hier_box_tol(rp_vec3 lo, rp_vec3 hi)
{
    double m = hier_max(hier_max(fabs(lo.x), fabs(hi.x)), hier_max(hier_max(fabs(lo.y), fabs(hi.y)),
                                                                  hier_max(fabs(lo.z), fabs(hi.z))));
    return 1e-9 * rp_v3_length(rp_v3_sub(hi, lo)) + 64 * DBL_EPSILON * m;
}

/* A node's bounding box, box[0] its low corner and box[1] its high one. */
static inline void hier_node_box(const hier_node *nd, rp_vec3 box[2])
{
    box[0] = box[1] = nd->v[0];
    for (int i = 1; i < nd->nverts; i++) {
        box[0] = rp_v3(hier_min(box[0].x, nd->v[i].x), hier_min(box[0].y, nd->v[i].y), hier_min(box[0].z, nd->v[i].z));
        box[1] = rp_v3(hier_max(box[1].x, nd->v[i].x), hier_max(box[1].y, nd->v[i].y), hier_max(box[1].z, nd->v[i].z));
    }
}

/* A node's size for the near and far tests: its area, or a quarter of its
 * squared diameter when that is larger.  The two agree for squares, right
 * and equilateral triangles; for the slivers of a discontinuity mesh
 * (--mesh discontinuity) the area alone would call a long thin element
 * far from a neighbour along it, and its kernel constant across it. */
static inline double hier_extent2(const hier_node *nd)
{
    double d2 = 0;
    for (int i = 0; i < nd->nverts; i++)
        for (int j = i + 1; j < nd->nverts; j++) {
            rp_vec3 e = rp_v3_sub(nd->v[i], nd->v[j]);
            double l2 = rp_v3_dot(e, e);
            d2 = l2 > d2 ? l2 : d2;
        }
    return 0.25 * d2 > nd->area ? 0.25 * d2 : nd->area;
}

/* A nonnegative bound in 16 bits: the upper half of its float, rounded
 * up, so that it stays a bound, at most 2^-7 above (8 bits of mantissa,
 * the full exponent range); 0 packs as the smallest denormal, so that 0
 * can mean "not judged" (hier_clink.Fb). */
static inline uint16_t hier_bound_pack(double b)
{
    float f = (float)b;
    if ((double)f < b)
        f = nextafterf(f, INFINITY);
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    u = (u >> 16) + ((u & 0xffffu) != 0);
    return (uint16_t)(u ? u : 1);
}

static inline double hier_bound_unpack(uint16_t b)
{
    uint32_t u = (uint32_t)b << 16;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static inline double hier_link_ferr(const hier_link *l) { return hier_bound_unpack(l->F_err); }

/* The 32 bits of l->share as one number, and back. */
static inline uint32_t hier_link_share_bits(const hier_link *l)
{
    uint32_t v = 0;
    for (int k = 3; k >= 0; k--)
        v = v << 8 | l->share[k];
    return v;
}

static inline void hier_link_set_share_bits(hier_link *l, uint32_t v)
{
    for (int k = 0; k < 4; k++, v >>= 8)
        l->share[k] = (uint8_t)(v & 0xffu);
}

/* Stores shares w[0..3] (>= 0, adding up to one) in l: each is rounded
 * through the running sum, so none is negative and they add up to
 * HIER_SHARE_ONE exactly. */
static inline void hier_link_set_shares(hier_link *l, const double w[4])
{
    double run = 0;
    uint32_t prev = 0;
    uint32_t v = 0;
    for (int k = 0; k < 3; k++) {
        run += w[k];
        double c = floor(run * HIER_SHARE_ONE + 0.5);
        uint32_t ck = c <= prev ? prev : (c >= HIER_SHARE_ONE ? HIER_SHARE_ONE : (uint32_t)c);
        v |= (ck - prev) << (HIER_SHARE_BITS * k);
        prev = ck;
    }
    hier_link_set_share_bits(l, v);
    l->flags |= HIER_LINK_SHARES;
}

/* --basis linear: link l's slot in lin_K, kept in share[0..3]. */
static inline void hier_link_set_slot(hier_link *l, uint32_t slot)
{
    hier_link_set_share_bits(l, slot);
    l->flags |= HIER_LINK_COEF;
}

static inline uint32_t hier_link_slot(const hier_link *l) { return (uint32_t)hier_link_share_bits(l); }

/* --basis linear: a linear function with coefficients L on a node,
 * restricted to its child (two-scale relation a, A: hier_linear_relation):
 * returns what it adds to the child's constant, a . L, and writes its
 * coefficients on the child, A^T L, to out (push, subdivision, row sums). */
static inline double hier_linear_restrict(const double a[2], const double A[2][2], const double L[2], double out[2])
{
    out[0] = A[0][0] * L[0] + A[1][0] * L[1];
    out[1] = A[0][1] * L[0] + A[1][1] * L[1];
    return a[0] * L[0] + a[1] * L[1];
}

/* The four shares of l as fractions (adding up to one). */
static inline void hier_link_shares(const hier_link *l, double w[4])
{
    uint32_t rest = HIER_SHARE_ONE;
    uint32_t v = hier_link_share_bits(l);
    for (int k = 0; k < 3; k++, v >>= HIER_SHARE_BITS) {
        uint32_t sk = (uint32_t)(v & HIER_SHARE_ONE);
        w[k] = (double)sk / HIER_SHARE_ONE;
        rest -= sk;
    }
    w[3] = (double)rest / HIER_SHARE_ONE;
}

/* Counter-based random numbers (a pure function of the key and the
 * dimension), so results do not depend on the thread schedule:
 * splitmix64's finaliser (Steele, Lea & Flood 2014) as the mixer. */
static inline uint64_t hier_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

/* A node's name by its face and place in the tree, not its index (which
 * shifts when a face is added anywhere): the key of its random draws, so
 * a black ground plane added to a scene changes none (hier_tree.c). */
uint64_t hier_node_id(const hier_state *s, const hier_node *nd);

static inline uint64_t hier_key(uint64_t seed, uint64_t a, uint64_t b)
{
    return hier_mix(hier_mix(hier_mix(seed ^ UINT64_C(0x41e7a2c4b5d3f901)) ^ a) + b);
}

static inline double hier_u01(uint64_t key, uint64_t d)
{
    return (double)(hier_mix(key + (d + 1) * UINT64_C(0x9e3779b97f4a7c15)) >> 11) * 0x1.0p-53;
}

/* A random permutation of 0..n-1 (Fisher-Yates), drawing dimensions
 * dim0 + 2 .. dim0 + n of key: it pairs the strata on two elements. */
static inline void hier_shuffle(uint32_t *perm, unsigned n, uint64_t key, uint64_t dim0)
{
    for (unsigned k = 0; k < n; k++)
        perm[k] = k;
    for (unsigned k = n; k > 1; k--) {
        unsigned j = (unsigned)(hier_u01(key, dim0 + k) * k);
        j = j < k ? j : k - 1;
        uint32_t t = perm[k - 1];
        perm[k - 1] = perm[j];
        perm[j] = t;
    }
}

/* Growable scratch arrays: room for need items of size bytes in *a
 * (capacity *cap, from 1024 growing by half); 0 when out of memory. */
int hier_grow(void **a, size_t *cap, size_t need, size_t size);

/* X (nb values per node) of link l's source as the link sees it: its
 * children weighted by the link's shares once they are known
 * (HIER_LINK_SHARES), else the source's own value (hierarchical.c). */
void hier_source_mean(const hier_state *s, const hier_link *l, const double *X, double *out);
/* The shares of source node p's four children in what a receiver at qc
 * (normal n) gathers from p: their point form factors from qc, summing to
 * 1 (by area where all are 0); a link's shares (source_value). */
void hier_child_shares(const hier_state *s, rp_vec3 qc, rp_vec3 n, const hier_node *p, double w[4]);

#endif
