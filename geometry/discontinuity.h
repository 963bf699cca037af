/* Discontinuity segments for discontinuity meshing: the lines on each face
 * across which radiosity, or one of its derivatives, jumps.
 *
 *   D0  where surfaces touch or cross: another face's edge lying on the face
 *       (a box standing on the floor) or the line where another face
 *       crosses the face's plane inside the face (Heckbert 1992, sec. 3:
 *       "D0 discontinuities"; Lischinski, Tampieri & Greenberg 1992, sec. 3).
 *   D1  umbra and penumbra boundaries of area lights: the critical surfaces
 *       (wedges) EV, a light vertex and an occluder edge, and VE, an
 *       occluder vertex and a light edge, traced on the receiving face's
 *       plane (Heckbert 1992, sec. 4; Lischinski et al. 1992, sec. 4).
 *       EEE surfaces (quadrics) are not traced.
 *   GAP the outline of a face that hovers over the face, projected along
 *       the face's normal, where all of it is nearer than
 *       RP_DISC_GAP_RATIO times the square root of its own area (so nearly
 *       parallel to it): a lamp panel 1 cm below a ceiling, where the
 *       ceiling above the panel sees the room only through the slit and
 *       the light falls from the room's level to nearly nothing across a
 *       band about as wide as the gap.
 *       Not a discontinuity of the exact solution, but one at the scale of
 *       any element wider than the gap: an element straddling the outline
 *       averages the dark part in and sends that diluted mean to the room
 *       (measured in docs/design.md, stop 45).  Kept whole, as D0.
 *
 * What is kept of a wedge's trace (a conservative choice, said in help):
 * it is clipped to the receiving face, and then only the pieces whose
 * midpoint sees both the occluder edge (or vertex) and the light point that
 * span the wedge through it, unblocked by other faces, remain (16 pieces per
 * trace; Heckbert's "visible" test, sampled rather than exact).  Collinear
 * overlapping traces are merged.  At most max_per_face D1 segments per face
 * are kept, the longest first; D0 segments are all kept.  The work is
 * bounded too: at most 4,000,000 (wedge, receiving face) pairs are traced
 * per scene (lights in scene order, EV before VE), which a scene of a few
 * hundred faces never reaches; past it a large scene's D1 set is partial.
 *
 * Tolerances are relative to the diagonal of the box around the faces that
 * reflect or emit (RP_DISC_REL_TOL, rp_disc_scale), never absolute units:
 * a black ground plane, however large, changes nothing. */
#ifndef RP_DISCONTINUITY_H
#define RP_DISCONTINUITY_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"
#include "status.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Points closer than this times rp_disc_scale are one point; a vertex this
 * near a plane lies on it. */
#define RP_DISC_REL_TOL 1e-7
/* The default cap on D1 segments per receiving face. */
#define RP_DISC_DEFAULT_MAX_PER_FACE 48
/* GAP outlines: a face at most this fraction of the square root of its
 * area from the receiving face (McGuire's Cornell boxes: their lamps 1 cm
 * below the ceiling, 0.021 of the lamp's; the shadow tests' occluders, a
 * third of their size away, stay out). */
#define RP_DISC_GAP_RATIO 0.05

typedef enum rp_disc_kind {
    RP_DISC_D0 = 0, /* contact or crossing of two faces */
    RP_DISC_EV = 1, /* light vertex x occluder edge */
    RP_DISC_VE = 2, /* occluder vertex x light edge */
    RP_DISC_GAP = 3 /* outline of a face hovering just over the face */
} rp_disc_kind;

typedef struct rp_disc_segment {
    uint32_t face;      /* the receiving face */
    uint32_t kind;      /* rp_disc_kind */
    uint32_t source;    /* D0, GAP: the other face; EV, VE: the light face */
    rp_vec3 a, b;       /* endpoints, on the face (scene coordinates) */
} rp_disc_segment;

typedef struct rp_disc_params {
    size_t size;          /* sizeof(rp_disc_params) */
    size_t max_per_face;  /* D1 segments kept per face; 0: RP_DISC_DEFAULT_MAX_PER_FACE */
    int no_d0, no_d1;     /* leave a kind out (no_d0: D0 and GAP) */
    unsigned long max_pairs; /* (wedge, receiving face) pairs traced at most;
                                0: RP_DISC_MAX_PAIRS */
    int *truncated;       /* out, may be NULL: 1 when D1 tracing stopped at
                             max_pairs (some boundaries missing), else 0 */
} rp_disc_params;

/* Bounded work: (wedge, receiving face) pairs traced in a scene; past it
 * the D1 boundaries of the remaining lights and occluders are not traced
 * (rp_disc_params.truncated says so). */
#define RP_DISC_MAX_PAIRS 4000000UL

/* The length tolerances are relative to: the diagonal of the bounding box
 * of the faces that reflect or emit in some band (of all faces if none). */
double rp_disc_scale(const rp_scene *scene);

/* Every discontinuity segment of the scene, sorted by face.  *out is
 * malloc'ed (free it); params may be NULL (defaults). */
rp_status rp_disc_find(const rp_scene *scene, const rp_disc_params *params, rp_disc_segment **out,
                       size_t *count, rp_error *err);

#ifdef __cplusplus
}
#endif

#endif
