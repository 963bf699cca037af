/* Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991), registered as
 * "hierarchical".
 *
 * Every face is the root of a quadtree of elements (hier_tree.c).  Energy
 * moves along links between elements at whatever level the BF oracle
 * chose (hier_link.c), so the work grows with the number of links, O(n)
 * after the O(faces^2) initial linking, instead of O(n^2).  Per band,
 *
 *     B = E + rho * gathered,   E = pi Le,
 *
 * solved by Jacobi sweeps: every node gathers rho F B_src over its own
 * links, then push-pull (sec. 4.2) pushes each node's gathered radiosity
 * down to its leaves, adds E there, and pulls area-weighted means back up,
 * so every node holds the area mean of the leaves below it.  In an
 * enclosure seen from inside each leaf's gathered radiosity is divided by
 * the form factors that reached it (row-sum normalisation, update_scale):
 * the summation relation, sum_j F_ij = 1, then holds leaf by leaf.
 *
 * A step is one refinement pass with the current radiosities (BF
 * refinement starts from B = E and refines the links from brighter sources
 * as their light arrives) followed by one sweep.  The method has converged
 * when a pass refined nothing and the sweep changed the energy by less than
 * --tolerance:
 *     max_b sum_leaves A |B' - B| / sum_faces A E,
 * the same power norm the uniform solvers use for their residual.
 *
 * Clustering (hier_cluster.c; Smits, Arvo & Greenberg 1994): above 512
 * faces (--cluster auto) the face roots are the leaves of a cluster
 * hierarchy and linking starts from one self-link at the root cluster
 * instead of every pair of faces.  Cluster links carry their transfer as
 * sampled entries, each received by a quadtree node (a face root below a
 * receiving cluster) with that element's own orientation and visibility,
 * and added to the node's gathered radiosity.  Elements and clusters smaller than
 * --cluster-area are then refined by their error in power, not radiosity.
 * With clustering off (the default below 512 faces) nothing here changes. */
#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"
#include "../../geometry/discontinuity.h"
#include "../../geometry/log.h"
#include "../../geometry/mesh.h"
#include "../../geometry/simplify.h"
#include "system.h"

/* Defaults, relative to the scene (see the option help).  Chosen on the
 * Cornell box and the cube scenes: surface averages within 1% of a fine
 * reference (tests/test_hierarchical.c, README notes in the report). */
#define HIER_DEFAULT_BF "5e-3"
#define HIER_DEFAULT_MIN_AREA "2e-5"
/* --cluster-area auto: for surface averages alone, and otherwise (see
 * hier_init). */
#define HIER_CLUSTER_AREA_SURFACES "3e-3"
#define HIER_CLUSTER_AREA_IMAGE "1e-3"
/* --variation-weight auto: for surface averages alone, and otherwise. */
#define HIER_VARIATION_SURFACES "10"
#define HIER_VARIATION_IMAGE "0"
#define HIER_STR_(x) #x
#define HIER_STR(x) HIER_STR_(x)

static const rp_option_spec hier_options[] = {
    {"bf-epsilon", "EPS",
     "refine a link while rho_receiver x B_source x F exceeds EPS x the mean emitted radiosity "
     "over the faces that reflect or emit (BF refinement); 0 refines nearly every link down to "
     "--min-area (minutes and gigabytes on the Cornell box at the default --min-area)",
     HIER_DEFAULT_BF},
    {"min-area", "FRAC",
     "smallest element area, as a fraction of the area of the faces that reflect or emit (black "
     "faces, which need no elements, do not count; see also --contact-levels)",
     HIER_DEFAULT_MIN_AREA},
    {"contact-levels", "N",
     "pairs in which one element crosses the other's plane (a box standing on the floor) may be "
     "refined N quadtree levels below --min-area",
     "1"},
    {"partial-weight", "W",
     "partially visible links (and pairs crossing each other's planes) are judged by W x their "
     "unoccluded form factor, so shadow boundaries are refined first",
     "10"},
    {"invisible-weight", "W",
     "links whose visibility rays were all blocked are judged by W x their unoccluded form factor "
     "(refined towards a penumbra they may hide, then dropped)",
     "0.25"},
    {"variation-weight", "auto|W",
     "a link the BF test keeps still splits its source while rho_receiver x F x W x the source's "
     "difference in radiosity from its siblings exceeds --bf-epsilon's threshold, when the receiver "
     "is within 4 of the source's extents (where the kernel varies across the source): the floor "
     "beside a box, dark at its foot, as the box side sees it.  Constant basis, no importance; 0: "
     "off; auto: " HIER_VARIATION_SURFACES " when only surface averages are asked for (probe), else "
     HIER_VARIATION_IMAGE " (on the Cornell box it made surface averages better but not the image)",
     "auto"},
    {"vis-rays", "N",
     "visibility rays per set (rounded to a square, at most 64); a link the oracle keeps casts two "
     "independent sets, one to decide its refinement and one for the visibility it keeps, so that "
     "shadows are unbiased",
     "16"},
    {"tolerance", "EPS",
     "stop when a sweep changes the energy by less than EPS (relative, worst band) and no link "
     "was refined",
     "1e-6"},
    {"max-iterations", "N", "stop after N sweeps", "1000"},
    {"max-faces", "N",
     "without clustering, refuse scenes with more faces (the initial linking is O(faces^2))", "4096"},
    {"cluster", "auto|on|off",
     "cluster the faces (Smits, Arvo & Greenberg 1994) and link from the root cluster instead of "
     "every pair of faces; auto: on above 512 faces",
     "auto"},
    {"cluster-rays", "N",
     "point pairs (and visibility rays) per link from a cluster to a quadtree node", "16"},
    {"cluster-face-rays", "N",
     "visibility rays per face below a receiving cluster, shared among the cluster's links (faces "
     "larger than 1/N of the cluster get more)",
     "16"},
    {"cluster-area", "auto|FRAC",
     "with clustering, links to elements and clusters smaller than FRAC x the area of the faces "
     "that reflect or emit are refined by the error in power (B x F x area) rather than radiosity; "
     "auto: " HIER_CLUSTER_AREA_SURFACES " when only surface averages are asked for (probe: a "
     "surface's average is its power over its area), else " HIER_CLUSTER_AREA_IMAGE,
     "auto"},
    RP_SIMPLIFY_OPTION("auto"),
    {"mesh", "faces|discontinuity",
     "the quadtrees' roots: the faces as given, or the faces cut into triangles whose edges follow "
     "contact lines (D0), the outlines of faces hovering just over a face (GAP: a lamp 1 cm below a "
     "ceiling) and the umbra/penumbra boundaries of area lights (D1), so that no element "
     "straddles them (the --mesh discontinuity of the uniform solvers, with no points inside a face)",
     "faces"},
    {"mesh-segments", "N", "--mesh discontinuity: D1 segments kept per face, the longest first (D0 and GAP all kept)",
     HIER_STR(RP_DISC_DEFAULT_MAX_PER_FACE)},
    {"importance", "camera|surfaces|none|auto",
     "weigh the refinement by importance (Smits, Arvo & Salesin 1992): camera: what the image sees, "
     "surfaces: uniform over the faces that reflect, none: off (the BF oracle alone); auto: camera when "
     "only an image is wanted (render), else none.  It weighs the links between elements, not those of "
     "clusters.  Default none: on the scenes measured it saved no time (docs/design.md)",
     "none"},
    {"open-fraction", "on|off",
     "an element's value (with --basis linear, its function) is that of its part not enclosed by "
     "other geometry (the floor under a box standing on it), measured by rays from a grid of points "
     "on it, rather than the mean over the whole element; open scenes only (in an enclosure the row "
     "sums do this)",
     "on"},
    {"ff-rule", "midpoint|gauss",
     "how a link integrates the point-to-element form factor over its receiver: midpoint, the kernel "
     "at the receiver's centre for pairs over 4 receiver sizes apart and the mean over its four "
     "quarters' centres nearer (0.9% high for unit squares 6 apart, 1% low for two sharing an edge); "
     "gauss, the 2 x 2 Gauss points (3 points on a triangle) for every pair that does not cross the "
     "other's plane, as --basis linear always does (0.002% and 0.2%; 7 to 19% more time).  On the "
     "scenes measured the more accurate rule uncovers negative biases the midpoint rule's had "
     "offset (docs/design.md, stop 45)",
     "midpoint"},
    {"basis", "constant|linear",
     "the functions radiosity is expanded in on each element: its area mean, or a linear function "
     "(Galerkin, Zatz 1993; three coefficients per band, nine coupling coefficients per link)",
     "constant"},
    {"reconstruct", "flat|gouraud|gather",
     "image: leaf value (with --basis linear the leaf's linear function), crack-free vertex interpolation "
     "(with --basis linear of the leaves' functions at the vertices), or a one-bounce final gather",
     "gouraud"},
    {"vertex-rays", "N",
     "image with --reconstruct gouraud: visibility rays from each vertex to each partly visible "
     "source it gathers from (rounded to a square, at most 64; to an emitter, which is not split "
     "for its shadows, at least --vis-rays)",
     "1"},
    {"spp", "N", "image: camera rays per pixel (stratified, box filter)", "16"},
    {"gather-rays", "N", "image with --reconstruct gather: cosine-distributed rays per camera ray",
     "16"},
    RP_RAY_OFFSET_OPTION,
    {NULL, NULL, NULL, NULL}
};

static void hier_log(const hier_state *s, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void hier_log(const hier_state *s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    rp_vlogf(s->log, s->log_ctx, fmt, ap);
    va_end(ap);
}

/* --mesh discontinuity: a copy of scene whose faces are cut into triangles
 * whose edges follow the contact lines (D0) and the umbra and penumbra
 * boundaries of the area lights (D1; geometry/mesh_disc.c, CGAL's
 * constrained Delaunay triangulation), with no Steiner lattice inside a face
 * (its spacing is the scene's diagonal): the coarsest mesh on which no
 * element straddles those lines.  The quadtrees then start from it, and
 * their midpoint subdivisions keep conforming (Heckbert 1992; Lischinski,
 * Tampieri & Greenberg 1992, who also start hierarchical radiosity from a
 * discontinuity mesh).  A floor leaf that crossed the outline of a box
 * standing on it averaged the lit floor with the dark floor under the box. */
static rp_status disc_start_scene(const rp_scene *scene, size_t max_segments, rp_scene **out, rp_error *err)
{
    rp_vec3 lo, hi;
    rp_scene_bounds(scene, &lo, &hi);
    rp_mesh_params mp = {.size = sizeof mp,
                         .max_edge = rp_v3_length(rp_v3_sub(hi, lo)),
                         .mode = RP_MESH_DISCONTINUITY,
                         .max_segments = max_segments};
    rp_mesh *mesh = NULL;
    rp_status st = rp_mesh_create(scene, &mp, &mesh, err);
    if (st != RP_OK)
        return st;
    const size_t ns = rp_scene_nsurfaces(scene), ne = rp_mesh_nelements(mesh), nv = rp_mesh_nvertices(mesh);
    const rp_element *el = rp_mesh_elements(mesh);
    const rp_surface *surf = rp_scene_surfaces(scene);
    const rp_vec3 *mv = rp_mesh_vertices(mesh);
    rp_surface_triangles *tris = calloc(ns, sizeof *tris);
    const rp_surface_triangles **replace = calloc(ns, sizeof *replace);
    uint32_t *tri = malloc(6 * ne * sizeof *tri);
    double *xyz = malloc(3 * nv * sizeof *xyz);
    uint32_t *local = malloc(nv * sizeof *local);
    if (!tris || !replace || !tri || !xyz || !local) {
        st = rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for the discontinuity mesh");
        goto done;
    }
    /* Surface by surface (its faces, then each face's elements, which the
     * mesh keeps contiguous): its vertices renumbered from 0 (shared within
     * the surface, as the mesh shares them), a quad split along its
     * diagonal 0-2.  local[] is reset by the same walk, so the whole costs
     * one pass over the elements, however many surfaces. */
    for (size_t v = 0; v < nv; v++)
        local[v] = RP_NONE;
    size_t ntri = 0, nxyz = 0;
    for (size_t k = 0; k < ns; k++) {
        size_t t0 = ntri, v0 = nxyz;
        const uint32_t f0 = surf[k].first_face, f1 = f0 + surf[k].nfaces;
        for (uint32_t f = f0; f < f1; f++) {
            uint32_t e0, cnt;
            rp_mesh_face_elements(mesh, f, &e0, &cnt);
            for (uint32_t e = e0; e < e0 + cnt; e++) {
                uint32_t w[4];
                for (uint32_t j = 0; j < el[e].nverts; j++) {
                    uint32_t v = el[e].v[j];
                    if (local[v] == RP_NONE) {
                        local[v] = (uint32_t)(nxyz - v0);
                        xyz[3 * nxyz] = mv[v].x;
                        xyz[3 * nxyz + 1] = mv[v].y;
                        xyz[3 * nxyz + 2] = mv[v].z;
                        nxyz++;
                    }
                    w[j] = local[v];
                }
                for (uint32_t j = 1; j + 1 < el[e].nverts; j++) {
                    tri[3 * ntri] = w[0];
                    tri[3 * ntri + 1] = w[j];
                    tri[3 * ntri + 2] = w[j + 1];
                    ntri++;
                }
            }
        }
        /* local[] back to RP_NONE for the next surface: the vertices of
         * this surface's elements. */
        for (uint32_t f = f0; f < f1; f++) {
            uint32_t e0, cnt;
            rp_mesh_face_elements(mesh, f, &e0, &cnt);
            for (uint32_t e = e0; e < e0 + cnt; e++)
                for (uint32_t j = 0; j < el[e].nverts; j++)
                    local[el[e].v[j]] = RP_NONE;
        }
        tris[k] = (rp_surface_triangles){xyz + 3 * v0, nxyz - v0, tri + 3 * t0, ntri - t0};
        replace[k] = &tris[k];
    }
    st = rp_scene_with_surfaces(scene, replace, out, NULL, err);
done:
    free(tris);
    free(replace);
    free(tri);
    free(xyz);
    free(local);
    rp_mesh_destroy(mesh);
    return st;
}

static void hier_fini(void *state)
{
    hier_state *s = state;
    rp_raycast_destroy(s->rc);
    rp_recon_view_fini(&s->view);
    rp_scene_destroy(s->disc);
    free(s->faces);
    free(s->nodes);
    free(s->B);
    free(s->Bg);
    free(s->W);
    free(s->ff_scale);
    free(s->ff_lin);
    free(s->links);
    free(s->link_start);
    free(s->pair_off);
    free(s->pair_cnt);
    free(s->cand);
    free(s->face_unit);
    free(s->unit_face);
    free(s->unit_lo);
    free(s->unit_hi);
    hier_importance_free(s);
    hier_cluster_free(s);
    hier_linear_free(s);
    free(s->open);
    memset(s, 0, sizeof *s);
}

/* Signed volume bounded by the faces, fronts taken as outward (divergence
 * theorem): negative when the fronts face inward. */
static double signed_volume(const rp_scene *scene)
{
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *v = rp_scene_vertices(scene);
    double vol = 0;
    for (size_t f = 0; f < rp_scene_nfaces(scene); f++)
        for (uint32_t k = 1; k + 1 < faces[f].nverts; k++)
            vol += rp_v3_dot(v[faces[f].v[0]], rp_v3_cross(v[faces[f].v[k]], v[faces[f].v[k + 1]])) / 6.0;
    return vol;
}

/* 1 if the scene is an enclosure seen from inside: closed (every edge
 * shared by two faces), fronts inward, and a few fixed rays from the front
 * of every face all land on fronts (closedness and orientation alone admit
 * nested shells whose backs are in view).  Only then is the summation
 * relation sum_j F_ij = 1 exact for every element (Siegel & Howell,
 * Thermal Radiation Heat Transfer, "summation relation" for an enclosure). */
static int scene_is_enclosure(const hier_state *s)
{
    if (s->nfaces == 0 || rp_scene_is_closed(s->scene) != 1 || !(signed_volume(s->scene) < 0))
        return 0;
    static const double uv[3][2] = {{0.5, 0.5}, {0.2, 0.7}, {0.8, 0.3}};
    for (size_t f = 0; f < s->nfaces; f++) {
        const hier_node *nd = &s->nodes[f];
        rp_vec3 n = s->faces[f].n, t, b;
        rp_v3_basis(n, &t, &b);
        for (int k = 0; k < 3; k++) {
            rp_vec3 x = hier_node_point(nd, uv[k][0], uv[k][1]);
            for (int d = 0; d < 7; d++) {
                rp_vec3 dir = n;
                if (d > 0)
                    dir = hier_ring_dir(n, t, b, 1.3, 2 * RP_PI * (d - 1) / 6.0 + 0.7 * k);
                rp_hit hit;
                if (!rp_ray_closest_from(s->rc, x, n, dir, &hit) || !hit.front)
                    return 0;
            }
        }
    }
    return 1;
}

/* The form factors node i gathers through its own links and the
 * cluster-link entries it receives (hier_cluster.c). */
static double own_sum(const hier_state *s, size_t i)
{
    double own = 0;
    if (s->link_start)
        for (uint32_t k = s->link_start[i]; k < s->link_start[i + 1]; k++)
            own += hier_link_F(&s->links[k]);
    if (s->cl_nff && i < s->cl_nn)
        own += s->cl_nff[i];
    return own;
}

/* For every node, the form factors reaching it through its own links and
 * its ancestors' (what push-pull hands a leaf): sum[i], nnodes entries;
 * with divide, each node's own part divided by its open-fraction divisor,
 * as hier_sweep divides what it gathers. */
static void chain_sums(const hier_state *s, double *sum, int divide)
{
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        double own = own_sum(s, i);
        if (divide)
            own /= hier_open_divisor(s, (uint32_t)i);
        sum[i] = own + (nd->parent != RP_NONE ? sum[nd->parent] : 0);
    }
}

/* Where open fractions divide what a node gathers (hier_open.c), a cap
 * on each leaf's divided row sum.  The form factors from the open part of
 * an element sum to at most 1 (the summation relation), so the division
 * may raise a leaf's sum up to 1, or up to its undivided sum where the
 * hierarchy's estimate already exceeds 1 (by up to 22% on the Cornell box
 * at the defaults), and no further.  A divided sum above both is an open
 * fraction measured too small: rays that start inside other geometry (a
 * large --ray-offset) find a point enclosed whose links' rays, or links
 * without rays, still carry light.  Such a leaf is scaled back to the
 * cap.  Without it the division amplified what those leaves gathered by up
 * to 16, and a furnace's solution grew to about 1e299 (a relative error of
 * +9.5e298; the stability study's thin slab at --ray-offset 1e-2).  Both
 * chain sums, plain and divided, come from one pass over the links. */
static rp_status open_row_caps(hier_state *s, rp_error *err)
{
    double *plain = malloc((s->nnodes ? s->nnodes : 1) * sizeof *plain);
    if (!plain)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for row sums");
    double *sum = s->ff_scale;
    for (size_t i = 0; i < s->nnodes; i++) {
        const uint32_t parent = s->nodes[i].parent;
        const double own = own_sum(s, i);
        plain[i] = own + (parent != RP_NONE ? plain[parent] : 0);
        sum[i] = own / hier_open_divisor(s, (uint32_t)i) + (parent != RP_NONE ? sum[parent] : 0);
    }
    for (size_t i = 0; i < s->nnodes; i++) {
        const double cap = hier_max(plain[i], 1.0);
        sum[i] = sum[i] > cap ? cap / sum[i] : 1.0;
    }
    free(plain);
    return RP_OK;
}

/* Row-sum normalisation in an enclosure.  A leaf gathers through its own
 * links and (pushed down, sec. 4.2) through its ancestors', each estimated
 * at its own receiver's centre, so the form factors reaching a leaf sum to
 * 1 only on average over the leaves (0.90 to 1.15 on the furnace at the
 * defaults), whereas the summation relation makes the exact sum 1 for
 * every element of an enclosure.  Dividing each leaf's gathered radiosity
 * by its sum restores the relation row by row, as the rows of an
 * approximate form-factor matrix are normalised to conserve energy in a
 * closed environment: a uniform enclosure (the furnace) is then solved
 * exactly, L = Le / (1 - rho) on every leaf, refined or not, and any
 * enclosure conserves energy leaf by leaf.  Open scenes are left alone
 * (their exact row sums are below 1 and not known), but for the cap of
 * open fractions (open_row_caps). */
static rp_status update_scale(hier_state *s, rp_error *err)
{
    if (!s->enclosure && !s->open_on)
        return RP_OK;
    if (s->cap_scale < s->nnodes) {
        double *a = realloc(s->ff_scale, s->cap_nodes * sizeof *a);
        if (!a)
            return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for row sums");
        s->ff_scale = a;
        if (s->linear) {
            double *l = realloc(s->ff_lin, 2 * s->cap_nodes * sizeof *l);
            if (!l)
                return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory for row sums");
            s->ff_lin = l;
        }
        s->cap_scale = s->cap_nodes;
    }
    double *sum = s->ff_scale;
    if (s->linear && s->enclosure) {
        /* --basis linear: the row sum is a linear function S0 + S1 . phi
         * over each leaf (the ancestors' links' slopes pushed down), and
         * the leaf's gathered G0 + G1 . phi is divided by it to first
         * order: G0 / S0 + (G1 - (G0 / S0) S1) / S0 . phi (hier_sweep),
         * so a uniform enclosure gets no slope at all. */
        hier_linear_chain_sums(s, sum, s->ff_lin);
        for (size_t i = 0; i < s->nnodes; i++) {
            double inv = sum[i] > 0 ? 1.0 / sum[i] : 1.0;
            s->ff_lin[2 * i] *= sum[i] > 0 ? inv : 0;
            s->ff_lin[2 * i + 1] *= sum[i] > 0 ? inv : 0;
            sum[i] = inv;
        }
        return RP_OK;
    }
    if (!s->enclosure)
        return open_row_caps(s, err);
    chain_sums(s, sum, 0);
    for (size_t i = 0; i < s->nnodes; i++)
        sum[i] = sum[i] > 0 ? 1.0 / sum[i] : 1.0;
    return RP_OK;
}

/* An option taking auto or a number in [0, hi]: auto follows what the run
 * is asked for, the value surf for surface averages alone (probe), else
 * img (an image, or both). */
static rp_status auto_by_question(const hier_state *s, const rp_options *o, const char *key, const char *surf,
                                  const char *img, double hi, double *out, rp_error *err)
{
    const char *v = rp_options_word(o, key);
    if (!v || strcmp(v, "auto") == 0) {
        unsigned w = s->want & (RP_WANT_IMAGE | RP_WANT_SURFACES);
        *out = atof(w == RP_WANT_SURFACES ? surf : img);
        return RP_OK;
    }
    if (rp_options_double(o, key, 0, hi, out, err) != RP_OK)
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not auto or a number in [0, %g]", key, v, hi);
    return RP_OK;
}

static rp_status hier_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    hier_state *s = state;
    memset(s, 0, sizeof *s);
    rp_status st;
    /* --simplify first: everything below reads the scene solved on. */
    if ((st = rp_recon_view_init(&s->view, o, scene, &scene, err)) != RP_OK)
        return st;
    /* Then --mesh: the faces as given, or cut along their discontinuities
     * (the camera sees the cut copy too: the same geometry). */
    const char *mm = rp_options_word(o, "mesh");
    if (mm && strcmp(mm, "faces") != 0 && strcmp(mm, "discontinuity") != 0)
        return rp_error_set(err, RP_ERR_INPUT, "hierarchical: --mesh: '%s' is not faces or discontinuity", mm);
    const int disc = mm && strcmp(mm, "discontinuity") == 0;
    unsigned long segs;
    if ((st = rp_rad_mesh_segments("hierarchical", o, disc, &segs, err)) != RP_OK)
        return st;
    if (disc) {
        if (s->view.sol && rp_solution_nsimplified(s->view.sol) > 0)
            return rp_error_set(err, RP_ERR_UNSUPPORTED,
                                "hierarchical: --mesh discontinuity cuts the faces as given, and --simplify "
                                "has simplified a mesh of this scene: add --simplify off");
        if ((st = disc_start_scene(s->view.scene, segs, &s->disc, err)) != RP_OK)
            return st;
        rp_recon_view_fini(&s->view); /* an unsimplified copy, if any */
        scene = s->disc;
        s->view.scene = scene;
    }
    s->scene = scene;
    s->nb = rp_scene_nbands(scene);
    s->nfaces = rp_scene_nfaces(scene);
    if (s->nb == 0 || s->nb > HIER_MAX_BANDS)
        return rp_error_set(err, RP_ERR_UNSUPPORTED, "hierarchical: %zu bands (at most %d)", s->nb,
                            HIER_MAX_BANDS);
    if (o && o->threads < 0)
        return rp_error_set(err, RP_ERR_INPUT, "hierarchical: %d threads", o->threads);
    s->threads = o && o->threads > 0 ? o->threads : omp_get_max_threads();
    s->want = o ? o->want : 0;
    s->open_ended = o ? o->open_ended : 0;
    s->log = o ? o->log : NULL;
    s->log_ctx = o ? o->log_ctx : NULL;
    s->cancel = o ? o->cancel : NULL;
    s->seed = o ? o->seed : 0;

    s->bf_rel = atof(HIER_DEFAULT_BF);
    s->min_area_rel = atof(HIER_DEFAULT_MIN_AREA);
    /* the other defaults: the option specs' fallbacks (rp_options_double,
     * rp_options_uint), written once, where --help reads them */
    unsigned long vis = 0, maxit = 0, spp = 0, gr = 0, crays = 0, cfrays = 0, vr = 0, cl = 0;
    s->max_faces = HIER_DEFAULT_MAX_FACES;
    if ((st = rp_options_double(o, "bf-epsilon", 0, 1e6, &s->bf_rel, err)) != RP_OK ||
        (st = rp_options_double(o, "min-area", 1e-15, 1, &s->min_area_rel, err)) != RP_OK ||
        (st = rp_options_double(o, "partial-weight", 0, 1e6, &s->partial_weight, err)) != RP_OK ||
        (st = rp_options_double(o, "invisible-weight", 0, 1e6, &s->invisible_weight, err)) != RP_OK ||
        (st = rp_options_double(o, "tolerance", 0, 1, &s->tolerance, err)) != RP_OK ||
        (st = rp_options_uint(o, "vis-rays", 1, HIER_MAX_VIS_RAYS, &vis, err)) != RP_OK ||
        (st = rp_options_uint(o, "max-iterations", 1, 1000000000ul, &maxit, err)) != RP_OK ||
        (st = rp_options_uint(o, "max-faces", 1, 1000000000ul, &s->max_faces, err)) != RP_OK ||
        (st = rp_options_uint(o, "spp", 1, 1u << 20, &spp, err)) != RP_OK ||
        (st = rp_options_uint(o, "gather-rays", 1, 1u << 20, &gr, err)) != RP_OK ||
        (st = rp_options_uint(o, "vertex-rays", 1, 64, &vr, err)) != RP_OK ||
        (st = rp_options_uint(o, "contact-levels", 0, 8, &cl, err)) != RP_OK ||
        (st = rp_options_uint(o, "cluster-rays", 1, 256, &crays, err)) != RP_OK ||
        (st = rp_options_uint(o, "cluster-face-rays", 1, 256, &cfrays, err)) != RP_OK)
        return st;
    /* --cluster-area auto: what the run is asked for.  A surface's average
     * is its power over its area, so for surface averages alone an
     * element's error counts by the power it carries (Smits, Arvo &
     * Greenberg 1994, sec. 4) below a larger area: measured against the
     * path tracer at seeds 1-3 or 1-4, 3e-3 keeps six clustered scenes'
     * worst surfaces about where 1e-3's seeds put them (CornellBox-Sphere
     * 1.05-2.67% against 1.29-2.39%), and the bunny scene solves in about
     * 55% of the time with 40% less memory (docs/design.md); an image
     * shows each small element's radiosity, so it keeps 1e-3. */
    if ((st = auto_by_question(s, o, "cluster-area", HIER_CLUSTER_AREA_SURFACES, HIER_CLUSTER_AREA_IMAGE, 1,
                               &s->cl_area_rel, err)) != RP_OK)
        return st;
    /* --variation-weight auto: what the run is asked for, as above.  On
     * the Cornell box at the defaults the test took the worst surface
     * average from 1.19% to 0.81% of the path tracer for about 20% more
     * time, and the image's RMSE from 0.001677 to 0.001680 for 31% more
     * (docs/design.md, stop 40). */
    if ((st = auto_by_question(s, o, "variation-weight", HIER_VARIATION_SURFACES, HIER_VARIATION_IMAGE, 1e6,
                               &s->variation_weight, err)) != RP_OK)
        return st;
    s->cluster_rays = (unsigned)crays;
    s->cluster_face_rays = (unsigned)cfrays;
    const char *cm = rp_options_word(o, "cluster"); /* defaults: the specs' */
    if (!cm || strcmp(cm, "auto") == 0)
        s->clustering = s->nfaces > HIER_CLUSTER_AUTO_FACES;
    else if (strcmp(cm, "on") == 0)
        s->clustering = 1;
    else if (strcmp(cm, "off") == 0)
        s->clustering = 0;
    else
        return rp_error_set(err, RP_ERR_INPUT, "--cluster: '%s' is not auto, on or off", cm);
    if (s->nfaces < 2)
        s->clustering = 0;
    s->tolerance_given = rp_options_get(o, "tolerance") != NULL;
    s->max_iterations_given = rp_options_get(o, "max-iterations") != NULL;
    s->vis_rays = (unsigned)vis;
    s->max_iterations = maxit;
    s->spp = (unsigned)spp;
    s->gather_rays = (unsigned)gr;
    s->vertex_rays = (unsigned)vr;
    s->contact_levels = (unsigned)cl;
    const char *bm = rp_options_word(o, "basis");
    if (bm && strcmp(bm, "constant") != 0 && strcmp(bm, "linear") != 0)
        return rp_error_set(err, RP_ERR_INPUT, "hierarchical: --basis: '%s' is not constant or linear", bm);
    s->linear = bm && strcmp(bm, "linear") == 0;
    const char *fr = rp_options_word(o, "ff-rule");
    if (fr && strcmp(fr, "midpoint") != 0 && strcmp(fr, "gauss") != 0)
        return rp_error_set(err, RP_ERR_INPUT, "hierarchical: --ff-rule: '%s' is not midpoint or gauss", fr);
    s->ff_gauss = fr && strcmp(fr, "gauss") == 0;
    const char *of = rp_options_word(o, "open-fraction");
    if (of && strcmp(of, "on") != 0 && strcmp(of, "off") != 0)
        return rp_error_set(err, RP_ERR_INPUT, "hierarchical: --open-fraction: '%s' is not on or off", of);
    const int open_fraction = !of || strcmp(of, "on") == 0;
    const char *rm = rp_options_word(o, "reconstruct");
    if (rm) {
        if (strcmp(rm, "flat") == 0)
            s->recon = HIER_RECON_FLAT;
        else if (strcmp(rm, "gouraud") == 0)
            s->recon = HIER_RECON_GOURAUD;
        else if (strcmp(rm, "gather") == 0)
            s->recon = HIER_RECON_GATHER;
        else
            return rp_error_set(err, RP_ERR_INPUT, "--reconstruct: '%s' is not flat, gouraud or gather", rm);
    }
    /* --importance auto: what the run is asked for.  An image alone
     * (render): camera.  Anything else: none.  A run scored on both (the
     * benchmarks) should not trade one answer for the other, and for
     * surface averages alone uniform importance bought nothing measured:
     * on the Cornell box 8% more leaves and 50% more links than none, and
     * with clustering the bunny's and the elephant's averages 1% further
     * from the path tracer (docs/design.md); --importance surfaces asks
     * for it. */
    const char *im = rp_options_word(o, "importance");
    if (!im || strcmp(im, "auto") == 0) {
        unsigned w = s->want & (RP_WANT_IMAGE | RP_WANT_SURFACES);
        s->importance = w == RP_WANT_IMAGE && rp_scene_camera(scene) ? HIER_IMP_CAMERA : HIER_IMP_NONE;
    } else if (strcmp(im, "camera") == 0)
        s->importance = HIER_IMP_CAMERA;
    else if (strcmp(im, "surfaces") == 0)
        s->importance = HIER_IMP_SURFACES;
    else if (strcmp(im, "none") == 0)
        s->importance = HIER_IMP_NONE;
    else
        return rp_error_set(err, RP_ERR_INPUT, "--importance: '%s' is not camera, surfaces, none or auto", im);
    if (!s->clustering && s->nfaces > s->max_faces)
        return rp_error_set(err, RP_ERR_UNSUPPORTED,
                            "hierarchical: %zu faces; the initial linking of every pair of faces "
                            "(%.3g pairs) is the limit of this method without clustering "
                            "(Smits et al. 1994, --cluster on); raise --max-faces to try anyway",
                            s->nfaces, (double)s->nfaces * (double)s->nfaces);

    /* Per-face data: plane, box, material. */
    s->faces = calloc(s->nfaces ? s->nfaces : 1, sizeof *s->faces);
    if (!s->faces)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory");
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *vs = rp_scene_vertices(scene);
    s->lit_area = 0;
    for (size_t f = 0; f < s->nfaces; f++) {
        hier_face *hf = &s->faces[f];
        const rp_material *m = rp_scene_face_material(scene, (uint32_t)f);
        hf->n = faces[f].normal;
        hf->d = rp_v3_dot(hf->n, vs[faces[f].v[0]]);
        hf->lo = hf->hi = vs[faces[f].v[0]];
        double twist = 0;
        for (uint32_t k = 1; k < faces[f].nverts; k++) {
            rp_vec3 p = vs[faces[f].v[k]];
            hf->lo = rp_v3(hier_min(hf->lo.x, p.x), hier_min(hf->lo.y, p.y), hier_min(hf->lo.z, p.z));
            hf->hi = rp_v3(hier_max(hf->hi.x, p.x), hier_max(hf->hi.y, p.y), hier_max(hf->hi.z, p.z));
            twist = hier_max(twist, fabs(rp_v3_dot(hf->n, p) - hf->d));
        }
        hf->tol = hier_box_tol(hf->lo, hf->hi) + twist;
        hf->rho = m->rho;
        hf->Le = m->Le;
        hf->surface = faces[f].surface;
        for (size_t b = 0; b < s->nb; b++) {
            hf->reflects |= m->rho[b] > 0;
            hf->lit |= m->rho[b] > 0 || m->Le[b] > 0;
            s->e_norm[b] += faces[f].area * RP_PI * m->Le[b];
        }
        if (hf->lit)
            s->lit_area += faces[f].area;
    }
    /* The oracle's scale: the area-weighted mean emitted radiosity, over
     * the faces that reflect or emit, of the band that emits most.  The
     * largest emitted radiosity would judge interreflections by a small
     * bright lamp (the Cornell box's is 150 times its scene's mean) far
     * more loosely than by a large dim one.  Areas are those of the lit
     * faces (lit_area) here and in --min-area and --cluster-area: a face
     * black in every band neither gathers nor shines, so adding one (a
     * ground plane a kilometre wide) changes no refinement. */
    double emean = 0;
    for (size_t b = 0; b < s->nb; b++)
        emean = hier_max(emean, s->e_norm[b] / s->lit_area);
    s->bf_eps = s->bf_rel * emean;
    s->min_area = s->min_area_rel * s->lit_area;
    s->min_area_contact = ldexp(s->min_area, -2 * (int)s->contact_levels);
    s->cl_area = s->cl_area_rel * s->lit_area;

    if ((st = rp_raycast_create(scene, NULL, &s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_options_ray_offset(o, s->rc, err)) != RP_OK)
        return st;
    if ((st = rp_recon_view_rays(&s->view, o, s->rc, err)) != RP_OK)
        return st;
    if ((st = hier_nodes_init(s, err)) != RP_OK)
        return st;
    if ((st = hier_cull_init(s, err)) != RP_OK)
        return st;
    if (s->clustering && (st = hier_cluster_init(s, err)) != RP_OK)
        return st;
    s->enclosure = scene_is_enclosure(s);
    s->open_on = open_fraction && !s->enclosure;
    if (s->importance != HIER_IMP_NONE) {
        if ((st = hier_importance_init(s, err)) != RP_OK)
            return st;
        s->imp_nn = s->nnodes;
        hier_log(s, "hierarchical: importance %s%s",
                 s->importance == HIER_IMP_CAMERA ? "camera (one ray per pixel centre)" : "surfaces (uniform)",
                 im && strcmp(im, "auto") != 0 ? "" : " (--importance auto)");
    }
    s->residual = -1;
    s->bytes = hier_bytes(s);
    return RP_OK;
}

/* The kernel-weighted radiosity of a link's source (nb bands into out).
 * A link carries F B_p, B_p the source's area mean, but the transfer is
 * the integral of the kernel times B over the source, and the two differ
 * by their covariance: the parts of a wall nearest the ceiling are the
 * ones the ceiling sees best and, lit at grazing angles, the darkest, so
 * every coarse link gathered the mean and the indirectly lit surfaces came
 * out 1 to 3% dark on the Cornell box.  When the source has children (some
 * other link refined it) their radiosities are weighted by the point
 * form factors from the receiver's centre to each, F_qp B_p -> sum_k
 * F_qk B_k (the link's transport integral, Hanrahan et al. 1991, eq. 2,
 * by the midpoint rule one level below the source), computed once per
 * link and kept in l->share; they sum to 1, so a uniform source, and the
 * form-factor row sums, are unchanged. */
void hier_source_mean(const hier_state *s, const hier_link *l, const double *X, double *out)
{
    const size_t nb = s->nb;
    const uint32_t pi = hier_link_src(l);
    const hier_node *p = &s->nodes[pi];
    if (p->child == RP_NONE || !(l->flags & HIER_LINK_SHARES)) {
        memcpy(out, X + (size_t)pi * nb, nb * sizeof *out);
        return;
    }
    double w[4];
    hier_link_shares(l, w);
    for (size_t b = 0; b < nb; b++)
        out[b] = 0;
    for (int k = 0; k < 4; k++) {
        const double *Xc = X + (size_t)(p->child + k) * nb;
        for (size_t b = 0; b < nb; b++)
            out[b] += w[k] * Xc[b];
    }
}

void hier_child_shares(const hier_state *s, rp_vec3 qc, rp_vec3 n, const hier_node *p, double w[4])
{
    const rp_vec3 np = s->faces[p->face].n;
    const rp_vec3 dp = rp_v3_sub(hier_node_c(p), qc);
    double ws = 0;
    /* Only the ratios matter: far from the source (r^2 above 16 times
     * its area, the near test of hier_link.c) the point-to-point
     * kernel A_k cos cos / r^2 at the children's centroids gives them
     * to about a percent (measured: the Cornell box's surface averages
     * move by under 0.01%), nearer the contour integral. */
    int far = rp_v3_dot(dp, dp) > HIER_NEAR_RATIO * hier_extent2(p);
    for (int k = 0; k < 4; k++) {
        const hier_node *c = &s->nodes[p->child + k];
        if (far) {
            rp_vec3 d = rp_v3_sub(hier_node_c(c), qc);
            double r2 = rp_v3_dot(d, d);
            w[k] = c->area * hier_max(rp_v3_dot(n, d), 0) * hier_max(-rp_v3_dot(np, d), 0) / (r2 * r2);
        } else
            w[k] = fabs(hier_point_polygon(qc, n, c->v, c->nverts));
        ws += w[k];
    }
    for (int k = 0; k < 4; k++)
        w[k] = ws > 0 ? w[k] / ws : s->nodes[p->child + k].area / p->area;
}

static void source_value(const hier_state *s, uint32_t qi, hier_link *l, const double *X, double *out)
{
    const hier_node *p = &s->nodes[hier_link_src(l)];
    /* --basis linear: the source's own linear function carries what the
     * shares would (hier_linear.c), and share[] holds the link's slot. */
    if (p->child != RP_NONE && !(l->flags & (HIER_LINK_SHARES | HIER_LINK_COEF)) && !s->linear) {
        const hier_node *q = &s->nodes[qi];
        double w[4];
        hier_child_shares(s, hier_node_c(q), s->faces[q->face].n, p, w);
        hier_link_set_shares(l, w);
    }
    hier_source_mean(s, l, X, out);
}

static void source_radiosity(const hier_state *s, uint32_t qi, hier_link *l, double *out)
{
    source_value(s, qi, l, s->B, out);
}

/* One Jacobi sweep: gather over every node's links, then push-pull.
 * Returns the relative energy change. */
/* Push-pull's pull to parent node nd: the mean of its children's values X
 * (nb each) weighted by W (the open area, hier_open.c, each child's
 * reached leaves hold; by area when none is reached) into Xi, the four
 * weights into wc (NULL: not wanted); returns the parent's weight. */
static double pull_children(const hier_state *s, const hier_node *nd, const double *W, const double *X, double *Xi,
                            double wc[4])
{
    const size_t nb = s->nb;
    double a = 0, w = 0;
    for (uint32_t c = nd->child; c < nd->child + 4; c++) {
        a += s->nodes[c].area;
        w += W[c];
    }
    for (size_t b = 0; b < nb; b++)
        Xi[b] = 0;
    for (uint32_t c = nd->child; c < nd->child + 4; c++) {
        double wk = w > 0 ? W[c] / w : s->nodes[c].area / a;
        if (wc)
            wc[c - nd->child] = wk;
        for (size_t b = 0; b < nb; b++)
            Xi[b] += wk * X[(size_t)c * nb + b];
    }
    return w;
}

static double hier_sweep(hier_state *s)
{
    const size_t nb = s->nb, nn = s->nnodes;
    double *B = s->B, *Bg = s->Bg;
    hier_link *links = s->links;
    const uint32_t *start = s->link_start;
    /* Gather (sec. 4.1): Bg_q = rho_q sum_links F B_p, in link order (B_p
     * kernel-weighted over the source's children, source_radiosity).  A
     * thread writes the fractions of its own receivers' links only. */
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256)
    for (long qi = 0; qi < (long)nn; qi++) {
        double acc[HIER_MAX_BANDS];
        const double *rho = s->faces[s->nodes[qi].face].rho;
        if (s->linear) {
            double acc1[2 * HIER_MAX_BANDS];
            hier_linear_gather(s, (uint32_t)qi, acc, acc1);
            for (size_t b = 0; b < nb; b++) {
                Bg[(size_t)qi * nb + b] = rho[b] * acc[b];
                s->Bg1[((size_t)qi * nb + b) * 2] = rho[b] * acc1[2 * b];
                s->Bg1[((size_t)qi * nb + b) * 2 + 1] = rho[b] * acc1[2 * b + 1];
            }
            continue;
        }
        for (size_t b = 0; b < nb; b++)
            acc[b] = 0;
        for (uint32_t k = start[qi]; k < start[qi + 1]; k++) {
            double Bp[HIER_MAX_BANDS];
            source_radiosity(s, (uint32_t)qi, &links[k], Bp);
            double F = hier_link_F(&links[k]);
            for (size_t b = 0; b < nb; b++)
                acc[b] += F * Bp[b];
        }
        for (size_t b = 0; b < nb; b++)
            Bg[(size_t)qi * nb + b] = rho[b] * acc[b];
    }
    hier_cluster_gather_nodes(s, Bg);
    if (s->open_on)
        /* What a node gathers is its open fraction times what its open
         * part gathers (hier_open.c). */
        for (size_t i = 0; i < nn; i++) {
            const double f = hier_open_divisor(s, (uint32_t)i);
            if (f != 1.0) {
                for (size_t b = 0; b < nb; b++)
                    Bg[i * nb + b] /= f;
                if (s->linear)
                    for (size_t b = 0; b < 2 * nb; b++)
                        s->Bg1[i * nb * 2 + b] /= f;
            }
        }
    /* Push (sec. 4.2): parents come before their children in node order,
     * so each child's Bg gains its parent's once the parent's holds what
     * it and its ancestors gathered: a leaf's Bg ends as the sum over its
     * chain.  (A separate pushed-down array held the ancestors' part
     * before stop 39; a + b = b + a in floating point, so the sums are the
     * same bits.)  W temporarily marks nodes that some link reaches
     * (theirs or an ancestor's). */
    double *W = s->W;
    for (size_t i = 0; i < nn; i++) {
        const hier_node *nd = &s->nodes[i];
        int reached = start[i + 1] > start[i] || (s->cl_nreach && i < s->cl_nn && s->cl_nreach[i]);
        if (nd->parent == RP_NONE) {
            if (s->linear)
                memset(s->Bd1 + i * nb * 2, 0, nb * 2 * sizeof *s->Bd1);
        } else
            reached |= W[nd->parent] > 0;
        W[i] = reached;
        if (nd->child == RP_NONE)
            continue;
        if (s->linear)
            hier_linear_push(s, (uint32_t)i);
        else
            for (uint32_t c = nd->child; c < nd->child + 4; c++)
                for (size_t b = 0; b < nb; b++)
                    Bg[(size_t)c * nb + b] += Bg[i * nb + b];
    }
    /* Pull: leaves get E + everything gathered on the way down; parents
     * the weighted mean of their children.  A leaf no link reaches sees
     * nothing, so nothing sees it (the floor under a box without a
     * bottom): it is left out of its parents' means, which are what other
     * elements gather, so a link to a parent carries the radiosity of the
     * part that can be seen (its form factor already counts only that part
     * through the visibility rays). */
    double change[HIER_MAX_BANDS];
    for (size_t b = 0; b < nb; b++)
        change[b] = 0;
    for (size_t i = nn; i-- > 0;) {
        const hier_node *nd = &s->nodes[i];
        double *Bi = B + i * nb;
        if (nd->child == RP_NONE) {
            const double *Le = s->faces[nd->face].Le;
            const double scale = hier_row_scale(s, i);
            int emits = 0;
            for (size_t b = 0; b < nb; b++) {
                double v = RP_PI * Le[b] + scale * Bg[i * nb + b];
                change[b] += nd->area * fabs(v - Bi[b]);
                Bi[b] = v;
                emits |= Le[b] > 0;
            }
            if (s->linear)
                for (size_t b = 0; b < nb; b++)
                    for (int k = 0; k < 2; k++) {
                        /* (G1 - (G0 / S0) S1) / S0, ff_lin = S1 / S0 (update_scale) */
                        size_t at = (i * nb + b) * 2 + (size_t)k;
                        double g0 = scale * Bg[i * nb + b];
                        double slope = s->enclosure ? s->ff_lin[2 * i + (size_t)k] : 0;
                        s->B1[at] = scale * (s->Bg1[at] + s->Bd1[at]) - g0 * slope;
                    }
            W[i] = (W[i] > 0 || emits) ? nd->area * hier_open_fraction(s, (uint32_t)i) : 0;
            continue;
        }
        double wc[4];
        W[i] = pull_children(s, nd, W, B, Bi, wc);
        if (s->linear)
            hier_linear_pull(s, (uint32_t)i, wc);
    }
    double r = 0;
    for (size_t b = 0; b < nb; b++)
        if (s->e_norm[b] > 0)
            r = hier_max(r, change[b] / s->e_norm[b]);
    return r;
}

/* One Jacobi sweep of the importance equation over the same links,
 * y_q = r_q + sum_p F_qp rho_p y_p (hier_importance.c; Smits, Arvo &
 * Salesin 1992, divided by the areas), with the radiosity sweep's
 * push-pull and row-sum normalisation.  Bg and W serve as scratch: the
 * radiosity sweep that follows rewrites both. */
static void importance_sweep(hier_state *s)
{
    const size_t nb = s->nb, nn = s->nnodes;
    double *Y = s->Y, *Yg = s->Bg, *W = s->W;
    hier_link *links = s->links;
    const uint32_t *start = s->link_start;
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256)
    for (long qi = 0; qi < (long)nn; qi++) {
        double acc[HIER_MAX_BANDS];
        for (size_t b = 0; b < nb; b++)
            acc[b] = 0;
        for (uint32_t k = start[qi]; k < start[qi + 1]; k++) {
            double Yp[HIER_MAX_BANDS];
            source_value(s, (uint32_t)qi, &links[k], Y, Yp);
            const double *rho = s->faces[s->nodes[hier_link_src(&links[k])].face].rho;
            double F = hier_link_F(&links[k]);
            for (size_t b = 0; b < nb; b++)
                acc[b] += F * rho[b] * Yp[b];
        }
        for (size_t b = 0; b < nb; b++)
            Yg[(size_t)qi * nb + b] = acc[b];
    }
    hier_cluster_gather_importance(s, Yg);
    for (size_t i = 0; i < nn; i++) {
        const hier_node *nd = &s->nodes[i];
        int reached = start[i + 1] > start[i] || (s->cl_nreach && i < s->cl_nn && s->cl_nreach[i]);
        if (nd->parent != RP_NONE)
            reached |= W[nd->parent] > 0;
        W[i] = reached;
        if (nd->child == RP_NONE)
            continue;
        for (uint32_t c = nd->child; c < nd->child + 4; c++)
            for (size_t b = 0; b < nb; b++)
                Yg[(size_t)c * nb + b] += Yg[i * nb + b];
    }
    /* Pull: a leaf no link reaches sees nothing, so no light reaches it
     * either, and it is left out of its parents' means (as in
     * hier_sweep). */
    for (size_t i = nn; i-- > 0;) {
        const hier_node *nd = &s->nodes[i];
        double *Yi = Y + i * nb;
        if (nd->child == RP_NONE) {
            const double scale = s->enclosure ? s->ff_scale[i] : 1.0;
            for (size_t b = 0; b < nb; b++)
                Yi[b] = s->Y0[i] + scale * Yg[i * nb + b];
            W[i] = W[i] > 0 ? nd->area : 0;
            continue;
        }
        W[i] = pull_children(s, nd, W, Y, Yi, NULL);
    }
    s->imp_sweeps++;
}

static void stats_fill(const hier_state *s, rp_hier_stats *o)
{
    memset(o, 0, sizeof *o);
    o->nodes = s->nnodes;
    double amin = INFINITY;
    for (size_t i = 0; i < s->nnodes; i++)
        if (s->nodes[i].child == RP_NONE) {
            o->leaves++;
            amin = hier_min(amin, s->nodes[i].area);
        }
    o->links = s->nlinks;
    o->links_full = s->links_full;
    o->links_partial = s->links_partial;
    o->links_invisible = s->links_invisible;
    o->links_refined = s->links_refined;
    o->min_leaf_area = amin;
    o->uniform_equivalent = amin > 0 ? s->lit_area / amin : 0;
    o->min_area = s->min_area;
    o->bf_epsilon = s->bf_eps;
    o->iterations = s->iterations;
    o->refine_passes = s->refine_passes;
    o->residual = s->residual;
    o->rays = s->rays;
    o->bytes = hier_bytes(s);
    o->clusters = s->ncl;
    o->cluster_links = s->nclinks;
    o->cluster_links_refined = s->clinks_refined;
    o->cluster_links_culled = s->clinks_culled;
    o->initial_links = s->links_initial + s->clinks_initial;
    o->faces = s->nfaces;
}

static rp_status hier_step(void *state, rp_step_info *info, rp_error *err)
{
    hier_state *s = state;
    rp_status st;
    double rays0 = s->rays, ff0 = s->form_factors;
    size_t crefined = 0;
    if (!s->linked) {
        if (s->clustering) {
            if ((st = hier_cluster_refine(s, &crefined, err)) != RP_OK)
                return st;
            s->linked = 1;
            hier_log(s,
                     "hierarchical: %zu faces, %zu clusters; initial links from the root cluster: %zu "
                     "face links, %zu cluster links (%.3g face pairs)",
                     s->nfaces, s->ncl, s->links_initial, s->clinks_initial,
                     (double)s->nfaces * (double)(s->nfaces - 1));
        } else {
            if ((st = hier_link_initial(s, err)) != RP_OK)
                return st;
            s->linked = 1;
            s->links_initial = s->nlinks;
            hier_log(s, "hierarchical: %zu faces, %zu initial links", s->nfaces, s->nlinks);
        }
    } else if ((st = hier_cluster_refine(s, &crefined, err)) != RP_OK)
        return st;
    size_t refined = 0;
    if ((st = hier_refine(s, &refined, err)) != RP_OK)
        return st;
    refined += crefined;
    hier_cluster_follow_splits(s);
    if (s->linear && (st = hier_linear_links(s, err)) != RP_OK)
        return st;
    if ((st = hier_open_update(s, err)) != RP_OK || (st = update_scale(s, err)) != RP_OK)
        return st;
    if (s->importance != HIER_IMP_NONE) {
        /* Importance and radiosity alternate (Smits et al. 1992): one
         * sweep of each per step, importance first (it uses Bg and W
         * as scratch). */
        if (s->imp_nn != s->nnodes) {
            if ((st = hier_importance_direct(s, err)) != RP_OK)
                return st;
            s->imp_nn = s->nnodes;
        }
        importance_sweep(s);
        hier_importance_finish(s);
    }
    s->residual = hier_sweep(s);
    s->iterations++;
    info->rays = s->rays - rays0;
    info->form_factors = s->form_factors - ff0;
    info->iterations = 1;
    info->residual = s->residual;
    info->tolerance = s->tolerance;
    s->bytes = hier_bytes(s);
    info->memory = (double)s->bytes;
    int tol_rule = s->tolerance_given || !s->open_ended;
    int it_rule = s->max_iterations_given || !s->open_ended;
    double r = s->residual;
    double p = 0;
    if (r <= 0 || r <= s->tolerance)
        p = 1;
    else if (r < 1 && s->tolerance > 0 && s->tolerance < 1)
        p = log(r) / log(s->tolerance);
    if (refined && p > 0.99)
        p = 0.99;
    info->progress = p < 0 ? 0 : (p > 1 ? 1 : p);
    info->converged = (tol_rule && refined == 0 && r <= s->tolerance) ||
                      (it_rule && s->iterations >= s->max_iterations);
    if (info->converged && s->log) {
        rp_hier_stats h;
        stats_fill(s, &h);
        hier_log(s,
                 "hierarchical: %lu sweeps, %lu refinement passes; %zu leaves (%zu nodes), "
                 "equivalent uniform mesh %.0f elements; links %zu (%zu fully visible, %zu partial, "
                 "%zu invisible not stored, %zu refined); %zu clusters, %zu cluster links (%zu refined, "
                 "%zu culled); %.3g visibility rays; %.1f MiB",
                 h.iterations, h.refine_passes, h.leaves, h.nodes, h.uniform_equivalent, h.links,
                 h.links_full, h.links_partial, h.links_invisible, h.links_refined, h.clusters,
                 h.cluster_links, h.cluster_links_refined, h.cluster_links_culled, h.rays,
                 (double)h.bytes / (1 << 20));
    }
    return RP_OK;
}

static rp_status hier_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    const hier_state *s = state;
    if (e->surface_radiance) {
        hier_surfaces(s, e->surface_radiance);
        if (e->surface_stderr)
            memset(e->surface_stderr, 0, rp_scene_nsurfaces(s->scene) * s->nb * sizeof(double));
    }
    e->samples = s->spp;
    if (e->radiance) {
        double rays = 0;
        rp_status st = hier_image(s, e->radiance, e->variance, &rays, err);
        if (st != RP_OK)
            return st;
    }
    return RP_OK;
}

void rp_hierarchical_stats(const void *state, rp_hier_stats *out) { stats_fill(state, out); }

size_t rp_hierarchical_leaves(const void *state, double *area, uint32_t *surface, double *B, size_t cap)
{
    const hier_state *s = state;
    size_t n = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        if (nd->child != RP_NONE)
            continue;
        if (n < cap) {
            if (area)
                area[n] = nd->area;
            if (surface)
                surface[n] = s->faces[nd->face].surface;
            if (B)
                memcpy(B + n * s->nb, s->B + i * s->nb, s->nb * sizeof *B);
        }
        n++;
    }
    return n;
}

void rp_hierarchical_radiosity_at(const void *state, uint32_t face, rp_vec3 p, double *B)
{
    const hier_state *s = state;
    double w[4];
    uint32_t leaf = hier_locate(s, face, p, w);
    if (s->linear)
        hier_linear_eval(s, leaf, p, B);
    else
        memcpy(B, s->B + (size_t)leaf * s->nb, s->nb * sizeof *B);
}

size_t rp_hierarchical_leaf_form_factor_sums(const void *state, double *sums, size_t cap)
{
    const hier_state *s = state;
    double *sum = malloc((s->nnodes ? s->nnodes : 1) * sizeof *sum);
    if (sum)
        chain_sums(s, sum, s->open_on);
    size_t n = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        if (s->nodes[i].child != RP_NONE)
            continue;
        if (n < cap)
            sums[n] = sum ? sum[i] : NAN;
        n++;
    }
    free(sum);
    return n;
}

int rp_hierarchical_enclosure(const void *state) { return ((const hier_state *)state)->enclosure; }

const rp_solver_type rp_solver_hierarchical = {
    .name = "hierarchical",
    .summary = "hierarchical radiosity: quadtrees per face, BF-refined links, push-pull "
               "(Hanrahan, Salzman & Aupperle 1991)",
    .options = hier_options,
    .state_size = sizeof(hier_state),
    .init = hier_init,
    .step = hier_step,
    .estimate = hier_estimate,
    .fini = hier_fini,
    .iteration_name = "sweeps",
};
