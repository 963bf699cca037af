/* Sample generators for the path tracer (see sampler.h). */
#include "sampler.h"

#include <math.h>
#include <string.h>

#define GOLDEN RP_SAMPLER_GOLDEN
/* The largest double below 1. */
#define ONE_MINUS_ULP 0x1.fffffffffffffp-1

/* Joe & Kuo (2008), "Constructing Sobol sequences with better
 * two-dimensional projections", SIAM J. Sci. Comput. 30:2635, file
 * new-joe-kuo-6.21201, dimensions d = 2..22: degree s of the primitive
 * polynomial, its inner coefficients a (a_1 most significant) and the
 * initial direction integers m_1..m_s.  Dimension 1 is van der Corput. */
static const struct {
    unsigned s, a, m[7];
} joe_kuo[RP_SOBOL_DIMS - 1] = {
    {1, 0, {1}},
    {2, 1, {1, 3}},
    {3, 1, {1, 3, 1}},
    {3, 2, {1, 1, 1}},
    {4, 1, {1, 1, 3, 3}},
    {4, 4, {1, 3, 5, 13}},
    {5, 2, {1, 1, 5, 5, 17}},
    {5, 4, {1, 1, 5, 5, 5}},
    {5, 7, {1, 1, 7, 11, 19}},
    {5, 11, {1, 1, 5, 1, 1}},
    {5, 13, {1, 1, 1, 3, 11}},
    {5, 14, {1, 3, 5, 5, 31}},
    {6, 1, {1, 3, 3, 9, 7, 49}},
    {6, 13, {1, 1, 1, 15, 21, 21}},
    {6, 16, {1, 3, 1, 13, 27, 49}},
    {6, 19, {1, 1, 1, 15, 7, 5}},
    {6, 22, {1, 3, 1, 15, 13, 25}},
    {6, 25, {1, 1, 5, 5, 19, 61}},
    {7, 1, {1, 3, 7, 11, 23, 15, 103}},
    {7, 4, {1, 3, 7, 13, 13, 15, 69}},
    {7, 7, {1, 1, 3, 13, 7, 35, 63}},
};

rp_status rp_sampler_parse(const char *name, rp_sampler_kind *out, rp_error *err)
{
    if (strcmp(name, "random") == 0)
        *out = RP_SAMPLER_RANDOM;
    else if (strcmp(name, "stratified") == 0)
        *out = RP_SAMPLER_STRATIFIED;
    else if (strcmp(name, "sobol") == 0)
        *out = RP_SAMPLER_SOBOL;
    else
        return rp_error_set(err, RP_ERR_INPUT,
                            "--sampler: '%s' is not one of random, stratified, sobol", name);
    return RP_OK;
}

const char *rp_sampler_name(rp_sampler_kind kind)
{
    switch (kind) {
    case RP_SAMPLER_RANDOM: return "random";
    case RP_SAMPLER_STRATIFIED: return "stratified";
    case RP_SAMPLER_SOBOL: return "sobol";
    }
    return "?";
}

/* Direction numbers V_k = m_k 2^(32-k), then the recurrence of Joe & Kuo's
 * "Notes on generating Sobol' sequences" (2008), eq. (2), in 32 bits. */
static void sobol_directions(rp_sampler *s)
{
    for (unsigned k = 0; k < 32; k++)
        s->sobol_v[0][k] = UINT32_C(1) << (31 - k);
    for (unsigned d = 1; d < RP_SOBOL_DIMS; d++) {
        unsigned deg = joe_kuo[d - 1].s, a = joe_kuo[d - 1].a;
        uint32_t *v = s->sobol_v[d];
        for (unsigned k = 0; k < deg && k < 32; k++)
            v[k] = (uint32_t)joe_kuo[d - 1].m[k] << (31 - k);
        for (unsigned k = deg; k < 32; k++) {
            uint32_t x = v[k - deg] ^ (v[k - deg] >> deg);
            for (unsigned i = 1; i < deg; i++)
                if ((a >> (deg - 1 - i)) & 1u)
                    x ^= v[k - i];
            v[k] = x;
        }
    }
    for (unsigned d = 0; d < RP_SOBOL_DIMS; d++)
        for (unsigned k = 0; k < 32; k++)
            s->sobol_vr[d][k] = rp_reverse32(s->sobol_v[d][k]);
}

void rp_sampler_init(rp_sampler *s, rp_sampler_kind kind, uint64_t seed, uint64_t budget)
{
    memset(s, 0, sizeof *s);
    s->kind = kind;
    s->seed = seed;
    uint64_t m = (uint64_t)ceil(sqrt((double)(budget ? budget : 1)));
    while (m * m < budget)
        m++;
    if (m > 65535) /* m * m must fit in 32 bits */
        m = 65535;
    s->grid = (uint32_t)(m ? m : 1);
    sobol_directions(s);
}

void rp_sampler_start(const rp_sampler *s, uint64_t stream, uint32_t index, rp_sample_point *out)
{
    out->sampler = s;
    out->index = index;
    out->stream_key = rp_hash64(rp_hash64(s->seed + GOLDEN) ^ (stream * GOLDEN + 1));
    out->key = rp_hash64(out->stream_key ^ rp_hash64((uint64_t)index + 0x632be59bd9b4e019));
}

/* A keyed bijection of [0, n): cycle-walking (Black & Rogaway 2002) over
 * the next power of two, with a mix of steps each invertible modulo 2^w
 * (xor with a key, multiplication by an odd number, xorshift right), the
 * construction of Kensler's "Correlated Multi-Jittered Sampling" (2013),
 * with our own constants. */
static uint32_t permute(uint32_t i, uint32_t n, uint64_t key)
{
    if (n <= 1)
        return 0;
    uint32_t w = n - 1;
    w |= w >> 1; w |= w >> 2; w |= w >> 4; w |= w >> 8; w |= w >> 16;
    uint32_t k0 = (uint32_t)key, k1 = (uint32_t)(key >> 32);
    unsigned half = 0;
    for (uint32_t t = w; t; t >>= 2)
        half++;
    do {
        i = (i ^ k0) & w;
        i = (i * 0xe170893du) & w;
        i ^= i >> half;
        i = (i + k1) & w;
        i = (i * 0x0929eb3fu) & w;
        i ^= i >> (half > 1 ? half - 1 : 1);
        i = (i ^ (k1 >> 7)) & w;
        i = (i * 0x6935fa69u) & w;
        i ^= i >> 3;
    } while (i >= n);
    return i;
}

/* Jittered strata for the pair of dimensions (2q, 2q+1): sample index i
 * falls in stratum perm(i mod m^2) of an m x m grid, each pair and each
 * round of m^2 samples with its own permutation (the padding of Pharr,
 * Jakob & Humphreys, PBRT 3rd ed., sec. 7.3), jittered within it.  Each
 * sample is uniform on [0,1)^2, so estimates stay unbiased. */
double rp_sampler_stratified(const rp_sample_point *p, unsigned dim)
{
    uint32_t m = p->sampler->grid;
    uint32_t mm = m * m;
    uint32_t round = p->index / mm, cell = p->index % mm;
    uint64_t pkey = rp_hash64(p->stream_key ^ ((uint64_t)(dim >> 1) << 32 | round));
    uint32_t stratum = permute(cell, mm, pkey);
    uint32_t c = (dim & 1) ? stratum / m : stratum % m;
    double u = ((double)c + rp_sampler_random(p, dim)) / (double)m;
    return u < 1.0 ? u : ONE_MINUS_ULP;
}

uint32_t rp_sobol_raw(const rp_sampler *s, uint32_t index, unsigned dim)
{
    const uint32_t *v = s->sobol_v[dim];
    uint32_t x = 0;
    for (; index; index &= index - 1) /* one XOR per set bit of the index */
        x ^= v[__builtin_ctz(index)];
    return x;
}
