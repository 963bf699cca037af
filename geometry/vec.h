/* Three-vectors in double precision; small inline helpers only. */
#ifndef RP_VEC_H
#define RP_VEC_H

#include <math.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RP_PI 3.14159265358979323846

typedef struct rp_vec3 {
    double x, y, z;
} rp_vec3;

static inline rp_vec3 rp_v3(double x, double y, double z)
{
    rp_vec3 v = {x, y, z};
    return v;
}
static inline rp_vec3 rp_v3_add(rp_vec3 a, rp_vec3 b) { return rp_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline rp_vec3 rp_v3_sub(rp_vec3 a, rp_vec3 b) { return rp_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline rp_vec3 rp_v3_scale(rp_vec3 a, double s) { return rp_v3(a.x * s, a.y * s, a.z * s); }
/* a + s b */
static inline rp_vec3 rp_v3_madd(rp_vec3 a, rp_vec3 b, double s) { return rp_v3(a.x + s * b.x, a.y + s * b.y, a.z + s * b.z); }
static inline double rp_v3_dot(rp_vec3 a, rp_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline rp_vec3 rp_v3_cross(rp_vec3 a, rp_vec3 b)
{
    return rp_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double rp_v3_length(rp_vec3 a) { return sqrt(rp_v3_dot(a, a)); }
static inline rp_vec3 rp_v3_normalize(rp_vec3 a)
{
    double l = rp_v3_length(a);
    return l > 0 ? rp_v3_scale(a, 1.0 / l) : a;
}
static inline int rp_v3_isfinite(rp_vec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }

/* An orthonormal basis (t, b, n) around unit n (Duff et al. 2017,
 * "Building an Orthonormal Basis, Revisited"). */
static inline void rp_v3_basis(rp_vec3 n, rp_vec3 *t, rp_vec3 *b)
{
    double sign = copysign(1.0, n.z);
    double a = -1.0 / (sign + n.z);
    double c = n.x * n.y * a;
    *t = rp_v3(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = rp_v3(c, sign + n.y * n.y * a, -n.y);
}

#ifdef __cplusplus
}
#endif

#endif
