/* Ray-throughput microbenchmark (see raybench.h).
 *
 * Rays are generated in chunks, untimed, then cast in parallel, timed with
 * omp_get_wtime (a monotonic wall clock).  Random numbers come from a
 * counter-based hash (SplitMix64, Steele, Lea & Flood 2014) of (seed, ray,
 * dimension), so the rays are the same for any thread count. */
#include "bench/run/raybench.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>

#include "geometry/sample.h"

/* Rays generated and cast per chunk: 64 Ki rays are about 4.5 MB of origins,
 * normals and directions, enough to amortise the parallel-region start. */
#define RP_RAYBENCH_CHUNK 65536

#define RP_RAYBENCH_PI 3.14159265358979323846

static uint64_t rp_splitmix64(uint64_t x)
{
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

/* Uniform in [0, 1) with 53 random bits. */
static double rp_uniform(uint64_t seed, uint64_t ray, unsigned dim)
{
    uint64_t h = rp_splitmix64(seed ^ rp_splitmix64(ray * 8u + dim));
    return (double)(h >> 11) * 0x1.0p-53;
}

rp_status rp_raybench_run(const rp_scene *scene, const rp_raycast *rc, size_t nrays, int threads,
                          uint64_t seed, double *rays_per_second, rp_error *err)
{
    *rays_per_second = 0;
    if (nrays == 0)
        return rp_error_set(err, RP_ERR_INPUT, "raybench: zero rays");
    if (threads <= 0)
        threads = omp_get_max_threads();

    rp_area_sampler *sampler = NULL;
    rp_status st = rp_area_sampler_create(scene, RP_NONE, RP_WEIGHT_AREA, &sampler, err);
    if (st != RP_OK)
        return st;
    if (rp_area_sampler_count(sampler) == 0) {
        rp_area_sampler_destroy(sampler);
        return rp_error_set(err, RP_ERR_INPUT, "raybench: the scene has no surface to start rays on");
    }

    size_t chunk = nrays < RP_RAYBENCH_CHUNK ? nrays : RP_RAYBENCH_CHUNK;
    rp_vec3 *p = malloc(chunk * sizeof *p);
    rp_vec3 *n = malloc(chunk * sizeof *n);
    rp_vec3 *d = malloc(chunk * sizeof *d);
    if (!p || !n || !d) {
        free(p);
        free(n);
        free(d);
        rp_area_sampler_destroy(sampler);
        return rp_error_set(err, RP_ERR_NOMEM, "raybench: out of memory for %zu rays", chunk);
    }

    double seconds = 0;
    for (size_t start = 0; start < nrays; start += chunk) {
        long m = (long)(nrays - start < chunk ? nrays - start : chunk);

#pragma omp parallel for num_threads(threads) schedule(static)
        for (long i = 0; i < m; i++) {
            uint64_t id = (uint64_t)start + (uint64_t)i;
            rp_area_sample s;
            rp_area_sampler_sample(sampler, rp_uniform(seed, id, 0), rp_uniform(seed, id, 1),
                                   rp_uniform(seed, id, 2), &s);
            /* Cosine-weighted direction about the front normal (Malley's
             * method: uniform on the disk, projected up to the hemisphere). */
            double u = rp_uniform(seed, id, 3), phi = 2.0 * RP_RAYBENCH_PI * rp_uniform(seed, id, 4);
            double r = sqrt(u), z = sqrt(1.0 - u);
            rp_vec3 t, b;
            rp_v3_basis(s.n, &t, &b);
            p[i] = s.p;
            n[i] = s.n;
            d[i] = rp_v3_add(rp_v3_scale(s.n, z),
                             rp_v3_add(rp_v3_scale(t, r * cos(phi)), rp_v3_scale(b, r * sin(phi))));
        }

        double t0 = omp_get_wtime();
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1024)
        for (long i = 0; i < m; i++) {
            rp_hit h;
            rp_ray_closest_from(rc, p[i], n[i], d[i], &h);
        }
        seconds += omp_get_wtime() - t0;
    }
    free(p);
    free(n);
    free(d);
    rp_area_sampler_destroy(sampler);

    if (!(seconds > 0))
        return rp_error_set(err, RP_ERR_RUNTIME, "raybench: the clock did not advance over %zu rays",
                            nrays);
    *rays_per_second = (double)nrays / seconds;
    return RP_OK;
}
