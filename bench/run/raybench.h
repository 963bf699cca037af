/* Ray-throughput microbenchmark: how many closest-hit queries per second the
 * ray caster answers on a scene, with rays shaped like a path tracer's
 * (origins uniform in area over the surfaces, cosine-distributed directions
 * about the front normal) but incoherent.  It is the practical ceiling a
 * path tracer's rays per second is compared to. */
#ifndef RP_RAYBENCH_H
#define RP_RAYBENCH_H

#include <stddef.h>
#include <stdint.h>

#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "geometry/status.h"

/* Casts nrays rays with rp_ray_closest_from over `threads` OpenMP threads
 * (<= 0: all available) and stores nrays / (seconds spent casting) in
 * *rays_per_second.  Ray generation is not timed.  The rays depend only on
 * the scene and seed, not on the thread count.  Prints nothing. */
rp_status rp_raybench_run(const rp_scene *scene, const rp_raycast *rc, size_t nrays, int threads,
                          uint64_t seed, double *rays_per_second, rp_error *err);

#endif
