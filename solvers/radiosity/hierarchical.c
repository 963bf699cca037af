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
 * so every node holds the area mean of the leaves below it.
 *
 * A step is one refinement pass with the current radiosities (BF
 * refinement starts from B = E and refines the links from brighter sources
 * as their light arrives) followed by one sweep.  The method has converged
 * when a pass refined nothing and the sweep changed the energy by less than
 * --tolerance:
 *     max_b sum_leaves A |B' - B| / sum_faces A E,
 * the same power norm the uniform solvers use for their residual. */
#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hier_internal.h"

/* Defaults, relative to the scene (see the option help).  Chosen on the
 * Cornell box and the cube scenes: surface averages within 1% of a fine
 * reference (tests/test_hierarchical.c, README notes in the report). */
#define HIER_DEFAULT_BF "5e-3"
#define HIER_DEFAULT_MIN_AREA "2e-5"

static const rp_option_spec hier_options[] = {
    {"bf-epsilon", "EPS",
     "refine a link while rho_receiver x B_source x F exceeds EPS x the scene's mean emitted "
     "radiosity (BF refinement)",
     HIER_DEFAULT_BF},
    {"min-area", "FRAC", "smallest element area, as a fraction of the scene's total surface area",
     HIER_DEFAULT_MIN_AREA},
    {"partial-weight", "W",
     "partially visible links (and pairs crossing each other's planes) are judged by W x their "
     "unoccluded form factor, so shadow boundaries are refined first",
     "10"},
    {"vis-rays", "N", "visibility rays per link (rounded to a square, at most 64)", "16"},
    {"tolerance", "EPS",
     "stop when a sweep changes the energy by less than EPS (relative, worst band) and no link "
     "was refined",
     "1e-6"},
    {"max-iterations", "N", "stop after N sweeps", "1000"},
    {"max-faces", "N", "refuse scenes with more faces (the initial linking is O(faces^2))",
     "4096"},
    {"reconstruct", "flat|gouraud|gather",
     "image: leaf value, crack-free vertex interpolation, or a one-bounce final gather", "gouraud"},
    {"spp", "N", "image: camera rays per pixel (stratified, box filter)", "16"},
    {"gather-rays", "N", "image with --reconstruct gather: cosine-distributed rays per camera ray",
     "16"},
    {NULL, NULL, NULL, NULL}
};

static void hier_log(const hier_state *s, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void hier_log(const hier_state *s, const char *fmt, ...)
{
    if (!s->log)
        return;
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    s->log(s->log_ctx, msg);
}

static void hier_fini(void *state)
{
    hier_state *s = state;
    rp_raycast_destroy(s->rc);
    free(s->faces);
    free(s->nodes);
    free(s->B);
    free(s->Bg);
    free(s->Bd);
    free(s->W);
    free(s->links);
    free(s->link_start);
    free(s->pair_off);
    free(s->pair_cnt);
    free(s->cand);
    memset(s, 0, sizeof *s);
}

static rp_status hier_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    hier_state *s = state;
    memset(s, 0, sizeof *s);
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
    s->seed = o ? o->seed : 0;

    rp_status st;
    s->bf_rel = atof(HIER_DEFAULT_BF);
    s->min_area_rel = atof(HIER_DEFAULT_MIN_AREA);
    s->partial_weight = 10;
    s->tolerance = 1e-6;
    unsigned long vis = 16, maxit = 1000, spp = 16, gr = 16;
    s->max_faces = HIER_DEFAULT_MAX_FACES;
    if ((st = rp_options_double(o, "bf-epsilon", 0, 1e6, &s->bf_rel, err)) != RP_OK ||
        (st = rp_options_double(o, "min-area", 1e-15, 1, &s->min_area_rel, err)) != RP_OK ||
        (st = rp_options_double(o, "partial-weight", 0, 1e6, &s->partial_weight, err)) != RP_OK ||
        (st = rp_options_double(o, "tolerance", 0, 1, &s->tolerance, err)) != RP_OK ||
        (st = rp_options_uint(o, "vis-rays", 1, 64, &vis, err)) != RP_OK ||
        (st = rp_options_uint(o, "max-iterations", 1, 1000000000ul, &maxit, err)) != RP_OK ||
        (st = rp_options_uint(o, "max-faces", 1, 1000000000ul, &s->max_faces, err)) != RP_OK ||
        (st = rp_options_uint(o, "spp", 1, 1u << 20, &spp, err)) != RP_OK ||
        (st = rp_options_uint(o, "gather-rays", 1, 1u << 20, &gr, err)) != RP_OK)
        return st;
    s->tolerance_given = rp_options_get(o, "tolerance") != NULL;
    s->max_iterations_given = rp_options_get(o, "max-iterations") != NULL;
    s->vis_rays = (unsigned)vis;
    s->max_iterations = maxit;
    s->spp = (unsigned)spp;
    s->gather_rays = (unsigned)gr;
    s->recon = HIER_RECON_GOURAUD;
    const char *rm = rp_options_get(o, "reconstruct");
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
    if (s->nfaces > s->max_faces)
        return rp_error_set(err, RP_ERR_UNSUPPORTED,
                            "hierarchical: %zu faces; the initial linking of every pair of faces "
                            "(%.3g pairs) is the limit of this method without clustering "
                            "(Smits et al. 1994); raise --max-faces to try anyway",
                            s->nfaces, (double)s->nfaces * (double)s->nfaces);

    /* Per-face data: plane, box, material. */
    s->faces = calloc(s->nfaces ? s->nfaces : 1, sizeof *s->faces);
    if (!s->faces)
        return rp_error_set(err, RP_ERR_NOMEM, "hierarchical: out of memory");
    const rp_face *faces = rp_scene_faces(scene);
    const rp_vec3 *vs = rp_scene_vertices(scene);
    for (size_t f = 0; f < s->nfaces; f++) {
        hier_face *hf = &s->faces[f];
        const rp_material *m = rp_scene_face_material(scene, (uint32_t)f);
        hf->n = faces[f].normal;
        hf->d = rp_v3_dot(hf->n, vs[faces[f].v[0]]);
        hf->lo = hf->hi = vs[faces[f].v[0]];
        for (uint32_t k = 1; k < faces[f].nverts; k++) {
            rp_vec3 p = vs[faces[f].v[k]];
            hf->lo = rp_v3(hier_min(hf->lo.x, p.x), hier_min(hf->lo.y, p.y), hier_min(hf->lo.z, p.z));
            hf->hi = rp_v3(hier_max(hf->hi.x, p.x), hier_max(hf->hi.y, p.y), hier_max(hf->hi.z, p.z));
        }
        hf->rho = m->rho;
        hf->Le = m->Le;
        hf->surface = faces[f].surface;
        for (size_t b = 0; b < s->nb; b++) {
            hf->reflects |= m->rho[b] > 0;
            s->e_norm[b] += faces[f].area * RP_PI * m->Le[b];
        }
    }
    s->total_area = rp_scene_total_area(scene);
    /* The oracle's scale: the area-weighted mean emitted radiosity of the
     * band that emits most.  The largest emitted radiosity would judge
     * interreflections by a small bright lamp (the Cornell box's is 150
     * times its scene's mean) far more loosely than by a large dim one. */
    double emean = 0;
    for (size_t b = 0; b < s->nb; b++)
        emean = hier_max(emean, s->e_norm[b] / rp_scene_total_area(scene));
    s->bf_eps = s->bf_rel * emean;
    s->min_area = s->min_area_rel * s->total_area;
    s->eps = 1e-9 * rp_scene_diagonal(scene);

    if ((st = rp_raycast_create(scene, NULL, &s->rc, err)) != RP_OK)
        return st;
    if ((st = hier_nodes_init(s, err)) != RP_OK)
        return st;
    if ((st = hier_cull_init(s, err)) != RP_OK)
        return st;
    s->residual = -1;
    s->bytes = hier_bytes(s);
    return RP_OK;
}

/* One Jacobi sweep: gather over every node's links, then push-pull.
 * Returns the relative energy change. */
static double hier_sweep(hier_state *s)
{
    const size_t nb = s->nb, nn = s->nnodes;
    double *B = s->B, *Bg = s->Bg, *Bd = s->Bd;
    const hier_link *links = s->links;
    const uint32_t *start = s->link_start;
    /* Gather (sec. 4.1): Bg_q = rho_q sum_links F B_p, in link order. */
#pragma omp parallel for num_threads(s->threads) schedule(dynamic, 256)
    for (long qi = 0; qi < (long)nn; qi++) {
        double acc[HIER_MAX_BANDS];
        for (size_t b = 0; b < nb; b++)
            acc[b] = 0;
        for (uint32_t k = start[qi]; k < start[qi + 1]; k++) {
            const double *Bp = B + (size_t)links[k].src * nb;
            double F = links[k].F;
            for (size_t b = 0; b < nb; b++)
                acc[b] += F * Bp[b];
        }
        const double *rho = s->faces[s->nodes[qi].face].rho;
        for (size_t b = 0; b < nb; b++)
            Bg[(size_t)qi * nb + b] = rho[b] * acc[b];
    }
    /* Push (sec. 4.2): parents come before their children in node order.
     * W temporarily marks nodes that some link reaches (theirs or an
     * ancestor's). */
    double *W = s->W;
    for (size_t i = 0; i < nn; i++) {
        const hier_node *nd = &s->nodes[i];
        int reached = start[i + 1] > start[i];
        if (nd->parent == RP_NONE)
            for (size_t b = 0; b < nb; b++)
                Bd[i * nb + b] = 0;
        else
            reached |= W[nd->parent] > 0;
        W[i] = reached;
        if (nd->child == RP_NONE)
            continue;
        for (uint32_t c = nd->child; c < nd->child + 4; c++)
            for (size_t b = 0; b < nb; b++)
                Bd[(size_t)c * nb + b] = Bd[i * nb + b] + Bg[i * nb + b];
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
            int emits = 0;
            for (size_t b = 0; b < nb; b++) {
                double v = RP_PI * Le[b] + Bg[i * nb + b] + Bd[i * nb + b];
                change[b] += nd->area * fabs(v - Bi[b]);
                Bi[b] = v;
                emits |= Le[b] > 0;
            }
            W[i] = (W[i] > 0 || emits) ? nd->area : 0;
            continue;
        }
        double a = 0, w = 0;
        for (uint32_t c = nd->child; c < nd->child + 4; c++) {
            a += s->nodes[c].area;
            w += W[c];
        }
        for (size_t b = 0; b < nb; b++)
            Bi[b] = 0;
        for (uint32_t c = nd->child; c < nd->child + 4; c++) {
            double wc = w > 0 ? W[c] / w : s->nodes[c].area / a;
            for (size_t b = 0; b < nb; b++)
                Bi[b] += wc * B[(size_t)c * nb + b];
        }
        W[i] = w;
    }
    double r = 0;
    for (size_t b = 0; b < nb; b++)
        if (s->e_norm[b] > 0)
            r = hier_max(r, change[b] / s->e_norm[b]);
    return r;
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
    o->uniform_equivalent = amin > 0 ? s->total_area / amin : 0;
    o->min_area = s->min_area;
    o->bf_epsilon = s->bf_eps;
    o->iterations = s->iterations;
    o->refine_passes = s->refine_passes;
    o->residual = s->residual;
    o->rays = s->rays;
    o->bytes = hier_bytes(s);
}

static rp_status hier_step(void *state, rp_step_info *info, rp_error *err)
{
    hier_state *s = state;
    rp_status st;
    double rays0 = s->rays, ff0 = s->form_factors;
    if (!s->linked) {
        if ((st = hier_link_initial(s, err)) != RP_OK)
            return st;
        s->linked = 1;
        hier_log(s, "hierarchical: %zu faces, %zu initial links", s->nfaces, s->nlinks);
    }
    size_t refined = 0;
    if ((st = hier_refine(s, &refined, err)) != RP_OK)
        return st;
    s->residual = hier_sweep(s);
    s->iterations++;
    info->rays = s->rays - rays0;
    info->form_factors = s->form_factors - ff0;
    info->iterations = 1;
    info->residual = s->residual;
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
                 "%zu invisible not stored, %zu refined); %.3g visibility rays; %.1f MiB",
                 h.iterations, h.refine_passes, h.leaves, h.nodes, h.uniform_equivalent, h.links,
                 h.links_full, h.links_partial, h.links_invisible, h.links_refined, h.rays,
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

size_t rp_hierarchical_leaf_form_factor_sums(const void *state, double *sums, size_t cap)
{
    const hier_state *s = state;
    double *down = calloc(s->nnodes ? s->nnodes : 1, sizeof *down);
    size_t n = 0;
    for (size_t i = 0; i < s->nnodes; i++) {
        const hier_node *nd = &s->nodes[i];
        double own = 0;
        if (s->link_start)
            for (uint32_t k = s->link_start[i]; k < s->link_start[i + 1]; k++)
                own += s->links[k].F;
        double here = (down ? down[i] : 0) + own;
        if (nd->child != RP_NONE) {
            if (down)
                for (uint32_t c = nd->child; c < nd->child + 4; c++)
                    down[c] = here;
            continue;
        }
        if (n < cap)
            sums[n] = down ? here : NAN;
        n++;
    }
    free(down);
    return n;
}

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
};
