/* Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991), registered as
 * "hierarchical": what the harness and tests can ask of its state beyond
 * the solver interface (solver.h).
 *
 * The state pointer is the one the method's init filled (a caller that
 * wants these numbers allocates rp_solver_hierarchical.state_size bytes and
 * drives init / step / estimate / fini itself). */
#ifndef RP_HIERARCHICAL_H
#define RP_HIERARCHICAL_H

#include <stddef.h>
#include <stdint.h>

#include "../solver.h"

extern const rp_solver_type rp_solver_hierarchical;

/* Counts after the last step, as SPLASH-2's radiosity reports them. */
typedef struct rp_hier_stats {
    size_t nodes;             /* quadtree nodes, roots included */
    size_t leaves;            /* leaf elements (the solution's unknowns) */
    size_t links;             /* links stored: links_full + links_partial */
    size_t links_full;        /* every visibility ray got through */
    size_t links_partial;     /* some rays blocked */
    size_t links_invisible;   /* every ray blocked: found, counted, not stored */
    size_t links_refined;     /* links replaced by finer ones so far */
    double min_leaf_area;     /* smallest leaf, scene units squared */
    double uniform_equivalent; /* lit area (faces that reflect or emit) /
                                  min_leaf_area: the element count of a
                                  uniform mesh as fine */
    double min_area;          /* the refinement floor in use (absolute) */
    double bf_epsilon;        /* the oracle's threshold in use (absolute, W m^-2) */
    unsigned long iterations; /* gather + push-pull sweeps */
    unsigned long refine_passes;
    double residual;          /* relative energy change of the last sweep */
    double rays;              /* visibility rays cast so far */
    size_t bytes;             /* memory held: nodes, radiosities, links */
    /* Clustering (Smits, Arvo & Greenberg 1994), 0 when it is off. */
    size_t clusters;          /* clusters above the face roots */
    size_t cluster_links;     /* links stored with a cluster at one end or both */
    size_t cluster_links_refined; /* cluster links replaced by finer ones so far */
    size_t cluster_links_culled;  /* dropped: normal cones show nothing can pass */
    size_t initial_links;     /* face plus cluster links after the first linking */
    size_t faces;             /* faces solved on: the scene's, or fewer with --simplify */
} rp_hier_stats;

void rp_hierarchical_stats(const void *state, rp_hier_stats *out);

/* The leaf elements: returns their count and, for the first min(count, cap)
 * of them in a fixed order, fills those of area (scene units squared),
 * surface (scene surface index) and B (radiosity, nbands per leaf, W m^-2)
 * that are non-NULL.  With --open-fraction (hier_open.c) B is the
 * radiosity of the leaf's open part, so area x B overstates the power of
 * a leaf partly enclosed by other geometry. */
size_t rp_hierarchical_leaves(const void *state, double *area, uint32_t *surface, double *B,
                              size_t cap);

/* The radiosity (nbands values, W m^-2) the solution holds at point p of
 * scene face `face` (of the scene solved on: with --simplify or --mesh
 * discontinuity not the scene given): the value of the leaf containing p
 * (of its open part, hier_open.c), or with --basis linear its linear
 * function at p. */
void rp_hierarchical_radiosity_at(const void *state, uint32_t face, rp_vec3 p, double *B);

/* The sum of the form factors that reach a leaf through the links of the
 * leaf and of its ancestors (pushed down by push-pull), per leaf in the
 * order of rp_hierarchical_leaves; returns the leaf count.  In a closed
 * enclosure with every pair visible the exact sum is 1.  With open
 * fractions each node's own form factors are divided by its divisor, as
 * the sweep divides what it gathers (before the sweep's cap, open_row_caps). */
size_t rp_hierarchical_leaf_form_factor_sums(const void *state, double *sums, size_t cap);

/* 1 if the scene was found to be an enclosure seen from inside (closed,
 * fronts inward, fixed test rays all landing on fronts): each leaf's
 * gathered radiosity is then divided by its form-factor sum above, so the
 * sums are 1 in effect (row-sum normalisation, hierarchical.c). */
int rp_hierarchical_enclosure(const void *state);

#endif
