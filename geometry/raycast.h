/* Ray casting through Embree 3: the only module that calls rtc*.
 *
 * Built once over every face of a scene (triangles and quads), then shared
 * read-only by all threads.  A ray leaving a surface starts a little off
 * it (an offset relative to the point's own coordinates), and hits on any
 * face whose plane holds the ray's origin are rejected, so it does not hit
 * its own surface again (self-intersection), whatever the scene's size or
 * units (raycast.c, "Precision"). */
#ifndef RP_RAYCAST_H
#define RP_RAYCAST_H

#include <stddef.h>
#include <stdint.h>

#include "mesh.h"
#include "scene.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rp_raycast rp_raycast;

typedef struct rp_hit {
    double t;          /* distance along the (unit) direction */
    rp_vec3 p;         /* hit point */
    rp_vec3 n;         /* the face's unit front normal */
    uint32_t face;
    uint32_t surface;
    uint32_t element;  /* RP_NONE unless the raycaster was given a mesh */
    double u, v;       /* Embree's barycentrics on the face */
    int front;         /* 1 if the ray arrived on the front (dot(d, n) < 0) */
} rp_hit;

/* mesh may be NULL; with one, hits also name the element. */
rp_status rp_raycast_create(const rp_scene *scene, const rp_mesh *mesh,
                            rp_raycast **out, rp_error *err);
void rp_raycast_destroy(rp_raycast *rc);

/* The distance off its surface at which a ray leaving surface point p
 * starts: the relative offset times p's largest coordinate as the ray
 * caster holds it, |p - c|_inf, c a centre of the lit part of the scene
 * (see raycast.c). */
double rp_raycast_offset(const rp_raycast *rc, rp_vec3 p);

/* The default relative offset (about 170 float ulps of the point's
 * coordinates). */
#define RP_RAYCAST_DEFAULT_OFFSET 1e-5

/* Sets the relative offset (rel >= 0; 0 starts rays on the surface itself,
 * where the rejection of hits on planes holding the origin still keeps
 * them off it; an offset above a real gap makes rays start beyond it:
 * leaks).  For experiments (radpt experiment stability); call before the
 * raycaster is shared between threads. */
void rp_raycast_set_offset(rp_raycast *rc, double rel);

/* Closest hit along o + t d, t in (0, tmax]; d need not be unit.
 * Returns 1 and fills hit on a hit, 0 on a miss. */
int rp_ray_closest(const rp_raycast *rc, rp_vec3 o, rp_vec3 d, double tmax, rp_hit *hit);

/* Closest hit of a ray leaving surface point p with normal n (the face's
 * front normal) in direction d: the origin is offset along +-n to the side
 * d points to, and hits on faces whose plane holds p (the face left and
 * any coplanar one) are skipped. */
int rp_ray_closest_from(const rp_raycast *rc, rp_vec3 p, rp_vec3 n, rp_vec3 d, rp_hit *hit);

/* 1 if the segment between surface points a (normal na) and b (normal nb)
 * is blocked by any face; both ends are offset off their surfaces, and
 * faces whose plane holds a or b never block. */
int rp_ray_occluded(const rp_raycast *rc, rp_vec3 a, rp_vec3 na, rp_vec3 b, rp_vec3 nb);

/* rp_ray_occluded for n segments a[i] -> b[i] between two surfaces
 * (normals na, nb), traced as one coherent stream: blocked[i] = 1 when
 * segment i is blocked. */
void rp_ray_occluded_n(const rp_raycast *rc, size_t n, const rp_vec3 *a, rp_vec3 na, const rp_vec3 *b, rp_vec3 nb,
                       unsigned char *blocked);

/* Closest hits of n rays from one origin o (camera rays through
 * neighbouring pixels), traced as a coherent stream; otherwise as
 * rp_ray_closest_n with tmax infinite. */
void rp_ray_closest_coherent(const rp_raycast *rc, size_t n, rp_vec3 o, const rp_vec3 *d, rp_hit *hits,
                             unsigned char *hit_mask);

/* Packets of independent rays (rtcIntersect1M / rtcOccluded1M) for
 * throughput.  hit_mask[i] is 1 on a hit. */
void rp_ray_closest_n(const rp_raycast *rc, size_t n, const rp_vec3 *o, const rp_vec3 *d,
                      double tmax, rp_hit *hits, unsigned char *hit_mask);

/* Counts of rays cast so far are the caller's business (rays are cheap to
 * count where they are cast). */

#ifdef __cplusplus
}
#endif

#endif
