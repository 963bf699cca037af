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
    uint32_t sobol_vr[RP_SOBOL_DIMS][32];   /* the same, bit-reversed (scrambling works on
                                               reversed digits) */
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


/* The unscrambled Sobol' point's coordinate as a 32-bit fraction (tests). */
uint32_t rp_sobol_raw(const rp_sampler *s, uint32_t index, unsigned dim);

/* A 64-bit hash (the splitmix64 output function, Steele, Lea & Flood 2014). */
static inline uint64_t rp_hash64(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

#define RP_SAMPLER_GOLDEN UINT64_C(0x9e3779b97f4a7c15)

static inline double rp_u53(uint64_t h) { return (double)(h >> 11) * 0x1p-53; }

/* Independent uniform numbers: a hash of the sample's key and dim. */
static inline double rp_sampler_random(const rp_sample_point *p, unsigned dim)
{
    return rp_u53(rp_hash64(p->key + (uint64_t)(dim + 1) * RP_SAMPLER_GOLDEN));
}

/* Jittered strata (out of line: cycle-walking permutation). */
double rp_sampler_stratified(const rp_sample_point *p, unsigned dim);

static inline uint32_t rp_reverse32(uint32_t x)
{
    x = __builtin_bswap32(x);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    return ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
}

/* Owen's nested uniform scrambling (Owen 1995) by hashing, after Laine &
 * Karras (2011) and Burley (2020, "Practical hash-based Owen scrambling",
 * JCGT 9(4)).  x is the point's bit-reversed value; on it every step changes a bit
 * only as a function of the bits below it (adding, multiplying by an odd
 * number, xor with an even multiple), which bit-reversed means a digit of
 * the fraction is permuted as a function of the digits before it: a
 * nested scramble, so the (t,m,s)-net structure survives.  Adding the
 * uniform key k0 first makes every scrambled point exactly uniform, so the
 * estimate stays unbiased.  The constants are ours (even multipliers).
 * Returns the scrambled point, reversed back. */
static inline uint32_t rp_owen_scramble_reversed(uint32_t x, uint64_t key)
{
    uint32_t k0 = (uint32_t)key, k1 = (uint32_t)(key >> 32);
    x += k0;
    x ^= x * 0x6b43a9b6u;
    x *= k1 | 1u;
    x ^= x * 0x3c6ef372u;
    x += k1;
    x ^= x * 0xa54ff53au;
    x *= 0x2545f491u;
    x ^= x * 0x1b873594u;
    return rp_reverse32(x);
}

static inline double rp_sampler_sobol(const rp_sample_point *p, unsigned dim)
{
    uint64_t h = rp_hash64(p->stream_key + (uint64_t)(dim + 1) * RP_SAMPLER_GOLDEN);
    /* The Sobol' point built directly in bit-reversed form (XOR commutes
     * with the reversal), so only the scramble's result is reversed. */
    const uint32_t *vr = p->sampler->sobol_vr[dim];
    uint32_t xr = 0;
    for (uint32_t i = p->index; i; i &= i - 1)
        xr ^= vr[__builtin_ctz(i)];
    uint32_t x = rp_owen_scramble_reversed(xr, h);
    /* Digits past the 32nd are uniform under a full Owen scramble: take 20
     * of them from the per-sample key (x * 2^20 + low fits 52 bits); their
     * quality hardly matters, one multiply suffices. */
    uint64_t low = ((p->key ^ h) * RP_SAMPLER_GOLDEN) >> 44;
    return (double)(((uint64_t)x << 20) | low) * 0x1p-52;
}

/* Coordinate dim of the sample, in [0, 1).  Inline: the path tracer asks
 * for a few dozen numbers per path. */
static inline double rp_sampler_get(const rp_sample_point *p, unsigned dim)
{
    switch (p->sampler->kind) {
    case RP_SAMPLER_STRATIFIED:
        return rp_sampler_stratified(p, dim);
    case RP_SAMPLER_SOBOL:
        if (dim < RP_SOBOL_DIMS)
            return rp_sampler_sobol(p, dim);
        return rp_sampler_random(p, dim);
    case RP_SAMPLER_RANDOM:
    default:
        return rp_sampler_random(p, dim);
    }
}

#endif
