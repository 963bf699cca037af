/* Sample generators for the path tracer: random, stratified, Sobol'.
 *
 * Every value is a pure function of (seed, stream, index, dimension): the
 * stream is a pixel or a probed surface, the index the sample number within
 * it (the pass), the dimension the coordinate of the path's sample vector.
 * Nothing is stateful, so a pixel's samples do not depend on which thread
 * drew them or in which order: output is bit-identical for any thread count.
 *
 * A stateful generator per pixel (GSL's gsl_rng, or gsl_qrng_sobol) would
 * need one allocation per pixel or a reseed per sample, and its draws would
 * depend on how many numbers the path happened to consume; a counter-based
 * hash costs a few multiplies per number and has neither problem. */
#ifndef RP_PT_SAMPLER_H
#define RP_PT_SAMPLER_H

#include <stdint.h>

#include "../../geometry/status.h"

typedef enum rp_sampler_kind {
    RP_SAMPLER_RANDOM,     /* independent uniform numbers */
    RP_SAMPLER_STRATIFIED, /* jittered m x m strata for each pair of dimensions */
    RP_SAMPLER_SOBOL       /* Owen-scrambled Sobol' points, random past the table */
} rp_sampler_kind;

/* Sobol' dimensions with direction numbers (Joe & Kuo 2008); dimensions
 * from here on are random. */
#define RP_SOBOL_DIMS 22

/* Configuration shared read-only by all threads. */
typedef struct rp_sampler {
    rp_sampler_kind kind;
    uint64_t seed;
    uint32_t grid;                          /* stratified: strata per side */
    uint32_t sobol_v[RP_SOBOL_DIMS][32];    /* Sobol' direction numbers */
} rp_sampler;

/* One sample of one stream: the keys its dimensions are hashed from. */
typedef struct rp_sample_point {
    const rp_sampler *sampler;
    uint64_t stream_key;  /* hash of (seed, stream) */
    uint64_t key;         /* hash of (seed, stream, index) */
    uint32_t index;
} rp_sample_point;

/* "random", "stratified" or "sobol"; RP_ERR_INPUT otherwise. */
rp_status rp_sampler_parse(const char *name, rp_sampler_kind *out, rp_error *err);
const char *rp_sampler_name(rp_sampler_kind kind);

/* budget is the number of samples per stream the caller means to take
 * (stratified: a grid of ceil(sqrt(budget))^2 strata; further samples start
 * a new, independently permuted grid). */
void rp_sampler_init(rp_sampler *s, rp_sampler_kind kind, uint64_t seed, uint64_t budget);

void rp_sampler_start(const rp_sampler *s, uint64_t stream, uint32_t index, rp_sample_point *out);

/* Coordinate dim of the sample, in [0, 1). */
double rp_sampler_get(const rp_sample_point *p, unsigned dim);

/* The unscrambled Sobol' point's coordinate as a 32-bit fraction (tests). */
uint32_t rp_sobol_raw(const rp_sampler *s, uint32_t index, unsigned dim);

/* A 64-bit hash (the splitmix64 output function, Steele, Lea & Flood 2014). */
static inline uint64_t rp_hash64(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

#endif
