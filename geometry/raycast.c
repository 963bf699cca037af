/* Ray casting through Embree 3.13: the only module that calls rtc*.
 *
 * Geometry.  Every scene face goes into one Embree scene, as triangles of
 * one RTC_GEOMETRY_TYPE_TRIANGLE geometry: a quad is cut into (v0, v1, v3)
 * and (v2, v3, v1), the diagonal Embree itself uses for
 * RTC_GEOMETRY_TYPE_QUAD, with the second triangle's (u, v) mirrored to
 * (1 - u, 1 - v), so hit.u/v are Embree's quad parameterisation
 * (p = v0 + u (v1 - v0) + v (v3 - v0) on a parallelogram) either way.  A map
 * turns Embree's primID back into the scene face.  Measured with
 * rp_raybench_run and rp_ray_closest_n on the Cornell box (mostly quads) and
 * on a 68k-face scene of boxes and triangles, split quads traced 10-15%
 * faster than one native quad geometry plus one triangle geometry (the
 * machine was shared, so +-15% noise per run; means of 4 runs); the native
 * path is kept behind RP_RAYCAST_SPLIT_QUADS=0 for re-measuring.  The scene
 * is built with RTC_BUILD_QUALITY_HIGH (static scenes; the build takes ~25 ms
 * for 68k faces) and RTC_SCENE_FLAG_ROBUST, which keeps edges watertight
 * (no light leaks where faces meet) at a measured cost of about 10%.
 *
 * Precision.  Embree works in single precision.  Vertices are stored
 * relative to the centre of the scene's bounds, so the float rounding error
 * of a position is about 2^-24 times half the scene diagonal D, wherever the
 * scene sits in space.  The self-intersection epsilon is
 *
 *     eps = 1e-5 * D,
 *
 * 80 to 170 float ulps of the largest (centred) coordinate: far above the
 * rounding of vertices, ray origins and Embree's hit distances (a few ulps
 * each), and far below any gap a scene should model (the Cornell box, 556
 * units wide in millimetres, gets eps = 0.0096, about 10 micrometres).  Rays that
 * leave a surface start eps off the face's plane on the side they travel to,
 * so they cannot re-hit their own (planar) face whatever their angle.
 *
 * Hit points.  Embree's float distance is refined in double by intersecting
 * the ray with the hit face's plane, so hit.p lies on the face to double
 * precision (element location and the next ray's offset rely on that); at
 * grazing angles, where the plane intersection is ill-conditioned, Embree's
 * own distance is kept.
 *
 * Threads.  rp_raycast_create is single-threaded; the committed Embree scene
 * is read-only, and every query uses its own RTCIntersectContext on the
 * stack, so queries may run from many threads at once. */
#include "raycast.h"

#include <embree3/rtcore.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef RP_RAYCAST_SPLIT_QUADS
#define RP_RAYCAST_SPLIT_QUADS 1
#endif
#ifndef RP_RAYCAST_ROBUST
#define RP_RAYCAST_ROBUST 1
#endif

/* Relative self-intersection epsilon (see the header comment). */
#define RP_RAYCAST_EPS_REL RP_RAYCAST_DEFAULT_OFFSET

/* Below this |cos| between ray and face normal the double-precision plane
 * refinement of the hit distance is not used. */
#define RP_RAYCAST_REFINE_COS 1e-6

/* Shortening of the occlusion segment, relative to its length. */
#define RP_RAYCAST_OCCLUDE_SHORTEN 1e-6

/* Rays per rtcIntersect1M call in rp_ray_closest_n.  (Measured on incoherent
 * rays: the same speed as a loop of rtcIntersect1 within the +-10% noise;
 * both about 10% faster than a loop of rp_ray_closest calls.) */
#define RP_RAYCAST_STREAM 64

enum { RP_GEOM_TRI = 0, RP_GEOM_QUAD = 1, RP_GEOM_COUNT = 2 };

struct rp_raycast {
    const rp_scene *scene;
    const rp_mesh *mesh;
    const rp_face *faces;
    const rp_vec3 *vertices;
    RTCDevice device;
    RTCScene rtc;
    /* primID -> face for the geometry whose Embree id is geom_id[k]. */
    uint32_t *prim_face[RP_GEOM_COUNT];
    unsigned geom_id[RP_GEOM_COUNT];
    /* With split quads, triangle primitive i that is the second half of a
     * quad has tri_second[i] = 1 (its (u,v) are mirrored). */
    unsigned char *tri_second;
    rp_vec3 centre;
    double eps;
};

/* Collects the first Embree error raised while building. */
typedef struct rp_rtc_errbuf {
    enum RTCError code;
    char message[512];
} rp_rtc_errbuf;

static void rp_rtc_error_cb(void *user, enum RTCError code, const char *str)
{
    rp_rtc_errbuf *buf = user;
    if (buf->code != RTC_ERROR_NONE)
        return;
    buf->code = code;
    snprintf(buf->message, sizeof buf->message, "%s", str ? str : "(no message)");
}

static const char *rp_rtc_error_name(enum RTCError code)
{
    switch (code) {
    case RTC_ERROR_NONE: return "no error";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    }
    return "unrecognised error";
}

void rp_raycast_destroy(rp_raycast *rc)
{
    if (!rc)
        return;
    if (rc->rtc)
        rtcReleaseScene(rc->rtc);
    if (rc->device)
        rtcReleaseDevice(rc->device);
    for (int g = 0; g < RP_GEOM_COUNT; g++)
        free(rc->prim_face[g]);
    free(rc->tri_second);
    free(rc);
}

/* Builds one geometry of the given type from index data and attaches it. */
static unsigned rp_attach(rp_raycast *rc, RTCBuffer vbuf, size_t nverts, enum RTCGeometryType type,
                          const uint32_t *index, size_t nprims)
{
    unsigned per = type == RTC_GEOMETRY_TYPE_QUAD ? 4 : 3;
    RTCGeometry geom = rtcNewGeometry(rc->device, type);
    if (!geom)
        return RTC_INVALID_GEOMETRY_ID;
    rtcSetGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vbuf, 0,
                         3 * sizeof(float), nverts);
    uint32_t *ibuf = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                             per == 4 ? RTC_FORMAT_UINT4 : RTC_FORMAT_UINT3,
                                             per * sizeof(uint32_t), nprims);
    if (!ibuf) {
        rtcReleaseGeometry(geom);
        return RTC_INVALID_GEOMETRY_ID;
    }
    memcpy(ibuf, index, nprims * per * sizeof(uint32_t));
    rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
    rtcCommitGeometry(geom);
    unsigned id = rtcAttachGeometry(rc->rtc, geom);
    rtcReleaseGeometry(geom); /* the scene holds its own reference */
    return id;
}

static rp_status rp_build(rp_raycast *rc, rp_rtc_errbuf *ebuf, rp_error *err)
{
    size_t nfaces = rp_scene_nfaces(rc->scene);
    size_t nverts = rp_scene_nvertices(rc->scene);

    size_t ntri = 0, nquad = 0;
    for (size_t f = 0; f < nfaces; f++) {
        if (rc->faces[f].nverts == 4) {
            if (RP_RAYCAST_SPLIT_QUADS)
                ntri += 2;
            else
                nquad++;
        } else {
            ntri++;
        }
    }

    rc->rtc = rtcNewScene(rc->device);
    if (!rc->rtc)
        return rp_error_set(err, RP_ERR_RUNTIME, "embree: cannot create a scene: %s",
                            ebuf->message);
    rtcSetSceneBuildQuality(rc->rtc, RTC_BUILD_QUALITY_HIGH);
    rtcSetSceneFlags(rc->rtc, RP_RAYCAST_ROBUST ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);

    if (nfaces > 0) {
        /* One float vertex buffer shared by both geometries; Embree reads
         * vertices with 16-byte loads, so pad the last one. */
        RTCBuffer vbuf = rtcNewBuffer(rc->device, (3 * nverts + 4) * sizeof(float));
        if (!vbuf)
            return rp_error_set(err, RP_ERR_NOMEM, "embree: cannot allocate %zu vertices: %s",
                                nverts, ebuf->message);
        float *vf = rtcGetBufferData(vbuf);
        for (size_t i = 0; i < nverts; i++) {
            rp_vec3 q = rp_v3_sub(rc->vertices[i], rc->centre);
            vf[3 * i + 0] = (float)q.x;
            vf[3 * i + 1] = (float)q.y;
            vf[3 * i + 2] = (float)q.z;
        }
        vf[3 * nverts] = vf[3 * nverts + 1] = vf[3 * nverts + 2] = vf[3 * nverts + 3] = 0.0f;

        uint32_t *tri_idx = malloc((ntri ? ntri : 1) * 3 * sizeof(uint32_t));
        uint32_t *quad_idx = malloc((nquad ? nquad : 1) * 4 * sizeof(uint32_t));
        rc->prim_face[RP_GEOM_TRI] = malloc((ntri ? ntri : 1) * sizeof(uint32_t));
        rc->prim_face[RP_GEOM_QUAD] = malloc((nquad ? nquad : 1) * sizeof(uint32_t));
        rc->tri_second = calloc(ntri ? ntri : 1, 1);
        if (!tri_idx || !quad_idx || !rc->prim_face[0] || !rc->prim_face[1] || !rc->tri_second) {
            free(tri_idx);
            free(quad_idx);
            rtcReleaseBuffer(vbuf);
            return rp_error_set(err, RP_ERR_NOMEM, "raycast: out of memory for %zu faces",
                                nfaces);
        }

        size_t it = 0, iq = 0;
        for (size_t f = 0; f < nfaces; f++) {
            const rp_face *fc = &rc->faces[f];
            if (fc->nverts == 4 && !RP_RAYCAST_SPLIT_QUADS) {
                memcpy(&quad_idx[4 * iq], fc->v, 4 * sizeof(uint32_t));
                rc->prim_face[RP_GEOM_QUAD][iq++] = (uint32_t)f;
            } else if (fc->nverts == 4) {
                /* Embree's own quad split: (v0, v1, v3) and (v2, v3, v1). */
                uint32_t a[3] = {fc->v[0], fc->v[1], fc->v[3]};
                uint32_t b[3] = {fc->v[2], fc->v[3], fc->v[1]};
                memcpy(&tri_idx[3 * it], a, sizeof a);
                rc->prim_face[RP_GEOM_TRI][it++] = (uint32_t)f;
                memcpy(&tri_idx[3 * it], b, sizeof b);
                rc->tri_second[it] = 1;
                rc->prim_face[RP_GEOM_TRI][it++] = (uint32_t)f;
            } else {
                memcpy(&tri_idx[3 * it], fc->v, 3 * sizeof(uint32_t));
                rc->prim_face[RP_GEOM_TRI][it++] = (uint32_t)f;
            }
        }

        rc->geom_id[RP_GEOM_TRI] = rc->geom_id[RP_GEOM_QUAD] = RTC_INVALID_GEOMETRY_ID;
        int failed = 0;
        if (ntri > 0) {
            rc->geom_id[RP_GEOM_TRI] =
                rp_attach(rc, vbuf, nverts, RTC_GEOMETRY_TYPE_TRIANGLE, tri_idx, ntri);
            failed |= rc->geom_id[RP_GEOM_TRI] == RTC_INVALID_GEOMETRY_ID;
        }
        if (nquad > 0 && !failed) {
            rc->geom_id[RP_GEOM_QUAD] =
                rp_attach(rc, vbuf, nverts, RTC_GEOMETRY_TYPE_QUAD, quad_idx, nquad);
            failed |= rc->geom_id[RP_GEOM_QUAD] == RTC_INVALID_GEOMETRY_ID;
        }
        free(tri_idx);
        free(quad_idx);
        rtcReleaseBuffer(vbuf); /* the geometries hold their references */
        if (failed)
            return rp_error_set(err, RP_ERR_RUNTIME, "embree: cannot create geometry: %s (%s)",
                                ebuf->message, rp_rtc_error_name(ebuf->code));
    }

    rtcCommitScene(rc->rtc);
    if (ebuf->code != RTC_ERROR_NONE)
        return rp_error_set(err, ebuf->code == RTC_ERROR_OUT_OF_MEMORY ? RP_ERR_NOMEM : RP_ERR_RUNTIME,
                            "embree: %s (%s)", ebuf->message, rp_rtc_error_name(ebuf->code));
    return RP_OK;
}

rp_status rp_raycast_create(const rp_scene *scene, const rp_mesh *mesh, rp_raycast **out,
                            rp_error *err)
{
    *out = NULL;
    if (!scene)
        return rp_error_set(err, RP_ERR_INPUT, "raycast: no scene");
    rp_raycast *rc = calloc(1, sizeof *rc);
    if (!rc)
        return rp_error_set(err, RP_ERR_NOMEM, "raycast: out of memory");
    rc->scene = scene;
    rc->mesh = mesh;
    rc->faces = rp_scene_faces(scene);
    rc->vertices = rp_scene_vertices(scene);

    rp_vec3 lo, hi;
    rp_scene_bounds(scene, &lo, &hi);
    rc->centre = rp_v3_scale(rp_v3_add(lo, hi), 0.5);
    if (!rp_v3_isfinite(rc->centre))
        rc->centre = rp_v3(0, 0, 0);
    double diag = rp_scene_diagonal(scene);
    rc->eps = RP_RAYCAST_EPS_REL * (isfinite(diag) && diag > 0 ? diag : 1.0);

    rp_rtc_errbuf ebuf = {RTC_ERROR_NONE, ""};
    rc->device = rtcNewDevice(NULL);
    if (!rc->device) {
        enum RTCError code = rtcGetDeviceError(NULL);
        free(rc);
        return rp_error_set(err, RP_ERR_RUNTIME, "embree: cannot create a device (%s)",
                            rp_rtc_error_name(code));
    }
    rtcSetDeviceErrorFunction(rc->device, rp_rtc_error_cb, &ebuf);
    rp_status st = rp_build(rc, &ebuf, err);
    /* ebuf lives on this stack frame: detach it before returning.  Errors in
     * later (read-only) queries can only be programmer errors. */
    rtcSetDeviceErrorFunction(rc->device, NULL, NULL);
    if (st != RP_OK) {
        rp_raycast_destroy(rc);
        return st;
    }
    *out = rc;
    return RP_OK;
}

double rp_raycast_epsilon(const rp_raycast *rc)
{
    return rc->eps;
}

void rp_raycast_set_offset(rp_raycast *rc, double rel)
{
    double diag = rp_scene_diagonal(rc->scene);
    rc->eps = rel * (isfinite(diag) && diag > 0 ? diag : 1.0);
}

/* A ray from o (double, world space) along unit d over (0, tfar]. */
static void rp_ray_init(const rp_raycast *rc, struct RTCRay *ray, rp_vec3 o, rp_vec3 d, double tfar)
{
    rp_vec3 q = rp_v3_sub(o, rc->centre);
    ray->org_x = (float)q.x;
    ray->org_y = (float)q.y;
    ray->org_z = (float)q.z;
    ray->tnear = 0.0f;
    ray->dir_x = (float)d.x;
    ray->dir_y = (float)d.y;
    ray->dir_z = (float)d.z;
    ray->time = 0.0f;
    ray->tfar = tfar >= (double)FLT_MAX ? INFINITY : (float)tfar;
    ray->mask = 0xFFFFFFFFu;
    ray->id = 0;
    ray->flags = 0;
}

static void rp_rayhit_init(const rp_raycast *rc, struct RTCRayHit *rh, rp_vec3 o, rp_vec3 d,
                           double tfar)
{
    rp_ray_init(rc, &rh->ray, o, d, tfar);
    rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh->hit.primID = RTC_INVALID_GEOMETRY_ID;
    for (int l = 0; l < RTC_MAX_INSTANCE_LEVEL_COUNT; l++)
        rh->hit.instID[l] = RTC_INVALID_GEOMETRY_ID;
}

/* Fills hit from Embree's answer to a ray that started at o_emb (the offset
 * origin actually traced) along unit d; distances are reported from o, the
 * caller's point, which lies on the same line up to the offset along n. */
static int rp_hit_fill(const rp_raycast *rc, const struct RTCRayHit *rh, rp_vec3 o, rp_vec3 o_emb,
                       rp_vec3 d, rp_hit *hit)
{
    if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    int kind = rh->hit.geomID == rc->geom_id[RP_GEOM_QUAD] ? RP_GEOM_QUAD : RP_GEOM_TRI;
    uint32_t face = rc->prim_face[kind][rh->hit.primID];
    const rp_face *fc = &rc->faces[face];

    /* Embree's hit, in double, measured from o. */
    rp_vec3 p_emb = rp_v3_madd(o_emb, d, (double)rh->ray.tfar);
    double t = rp_v3_dot(rp_v3_sub(p_emb, o), d);
    rp_vec3 p = p_emb;

    double cosd = rp_v3_dot(d, fc->normal);
    if (fabs(cosd) > RP_RAYCAST_REFINE_COS) {
        /* Intersect o + t d with the face's plane in double. */
        double tr = rp_v3_dot(rp_v3_sub(rc->vertices[fc->v[0]], o), fc->normal) / cosd;
        if (tr > 0 && fabs(tr - t) <= 4 * rc->eps + 1e-5 * fabs(t)) {
            t = tr;
            p = rp_v3_madd(o, d, tr);
        }
    }

    hit->t = t;
    hit->p = p;
    hit->n = fc->normal;
    hit->face = face;
    hit->surface = fc->surface;
    hit->u = rh->hit.u;
    hit->v = rh->hit.v;
    if (RP_RAYCAST_SPLIT_QUADS && kind == RP_GEOM_TRI && rc->tri_second[rh->hit.primID]) {
        hit->u = 1.0 - hit->u;
        hit->v = 1.0 - hit->v;
    }
    hit->front = cosd < 0;
    hit->element = rc->mesh ? rp_mesh_locate(rc->mesh, face, p) : RP_NONE;
    return 1;
}

int rp_ray_closest(const rp_raycast *rc, rp_vec3 o, rp_vec3 d, double tmax, rp_hit *hit)
{
    /* d need not be unit: it is normalised, and t, tmax are distances. */
    rp_vec3 du = rp_v3_normalize(d);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rp_rayhit_init(rc, &rh, o, du, tmax);
    rtcIntersect1(rc->rtc, &ctx, &rh);
    return rp_hit_fill(rc, &rh, o, o, du, hit);
}

/* p moved eps off its plane (normal n) to the side direction d points to. */
static rp_vec3 rp_offset(const rp_raycast *rc, rp_vec3 p, rp_vec3 n, rp_vec3 d)
{
    return rp_v3_madd(p, n, rp_v3_dot(d, n) >= 0 ? rc->eps : -rc->eps);
}

int rp_ray_closest_from(const rp_raycast *rc, rp_vec3 p, rp_vec3 n, rp_vec3 d, rp_hit *hit)
{
    /* Directions built from an orthonormal frame (the path tracer's) are
     * unit to rounding: the square root and division are skipped then. */
    double l2 = rp_v3_dot(d, d);
    rp_vec3 du = fabs(l2 - 1.0) <= 1e-12 || !(l2 > 0) ? d : rp_v3_scale(d, 1.0 / sqrt(l2));
    rp_vec3 o = rp_offset(rc, p, n, du);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rp_rayhit_init(rc, &rh, o, du, INFINITY);
    rtcIntersect1(rc->rtc, &ctx, &rh);
    return rp_hit_fill(rc, &rh, p, o, du, hit);
}

int rp_ray_occluded(const rp_raycast *rc, rp_vec3 a, rp_vec3 na, rp_vec3 b, rp_vec3 nb)
{
    rp_vec3 ab = rp_v3_sub(b, a);
    rp_vec3 a2 = rp_offset(rc, a, na, ab);
    rp_vec3 b2 = rp_offset(rc, b, nb, rp_v3_scale(ab, -1.0));
    rp_vec3 d = rp_v3_sub(b2, a2);
    double len = rp_v3_length(d);
    if (!(len > 0))
        return 0;
    d = rp_v3_scale(d, 1.0 / len);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay ray;
    rp_ray_init(rc, &ray, a2, d, len * (1.0 - RP_RAYCAST_OCCLUDE_SHORTEN));
    rtcOccluded1(rc->rtc, &ctx, &ray);
    /* Embree sets tfar to -inf when the ray is occluded. */
    return ray.tfar < 0.0f;
}

void rp_ray_occluded_n(const rp_raycast *rc, size_t n, const rp_vec3 *a, rp_vec3 na, const rp_vec3 *b, rp_vec3 nb,
                       unsigned char *blocked)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    struct RTCRay ray[RP_RAYCAST_STREAM];
    for (size_t start = 0; start < n; start += RP_RAYCAST_STREAM) {
        size_t m = n - start < RP_RAYCAST_STREAM ? n - start : RP_RAYCAST_STREAM;
        for (size_t i = 0; i < m; i++) {
            /* As rp_ray_occluded; a degenerate segment is a free ray of
             * length 0. */
            rp_vec3 ab = rp_v3_sub(b[start + i], a[start + i]);
            rp_vec3 a2 = rp_offset(rc, a[start + i], na, ab);
            rp_vec3 b2 = rp_offset(rc, b[start + i], nb, rp_v3_scale(ab, -1.0));
            rp_vec3 d = rp_v3_sub(b2, a2);
            double len = rp_v3_length(d);
            if (len > 0)
                d = rp_v3_scale(d, 1.0 / len);
            rp_ray_init(rc, &ray[i], a2, d, len > 0 ? len * (1.0 - RP_RAYCAST_OCCLUDE_SHORTEN) : 0.0);
        }
        rtcOccluded1M(rc->rtc, &ctx, ray, (unsigned)m, sizeof ray[0]);
        for (size_t i = 0; i < m; i++)
            blocked[start + i] = ray[i].tfar < 0.0f;
    }
}

/* n rays through rtcIntersect1M in blocks of RP_RAYCAST_STREAM; the
 * origin of ray i is o[i * o_stride] (stride 0: one origin for all). */
static void rp_ray_stream(const rp_raycast *rc, size_t n, const rp_vec3 *o, size_t o_stride, const rp_vec3 *d,
                          double tmax, enum RTCIntersectContextFlags flags, rp_hit *hits,
                          unsigned char *hit_mask)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = flags;
    struct RTCRayHit rh[RP_RAYCAST_STREAM];
    rp_vec3 du[RP_RAYCAST_STREAM];
    for (size_t start = 0; start < n; start += RP_RAYCAST_STREAM) {
        size_t m = n - start < RP_RAYCAST_STREAM ? n - start : RP_RAYCAST_STREAM;
        for (size_t i = 0; i < m; i++) {
            du[i] = rp_v3_normalize(d[start + i]);
            rp_rayhit_init(rc, &rh[i], o[(start + i) * o_stride], du[i], tmax);
        }
        rtcIntersect1M(rc->rtc, &ctx, rh, (unsigned)m, sizeof rh[0]);
        for (size_t i = 0; i < m; i++) {
            rp_vec3 oi = o[(start + i) * o_stride];
            hit_mask[start + i] = (unsigned char)rp_hit_fill(rc, &rh[i], oi, oi, du[i], &hits[start + i]);
        }
    }
}

void rp_ray_closest_coherent(const rp_raycast *rc, size_t n, rp_vec3 o, const rp_vec3 *d, rp_hit *hits,
                             unsigned char *hit_mask)
{
    /* Rays from one point through neighbouring pixels: Embree may trace
     * them as packets (RTC_INTERSECT_CONTEXT_FLAG_COHERENT, Embree 3 manual,
     * rtcIntersect1M). */
    rp_ray_stream(rc, n, &o, 0, d, INFINITY, RTC_INTERSECT_CONTEXT_FLAG_COHERENT, hits, hit_mask);
}

void rp_ray_closest_n(const rp_raycast *rc, size_t n, const rp_vec3 *o, const rp_vec3 *d,
                      double tmax, rp_hit *hits, unsigned char *hit_mask)
{
    rp_ray_stream(rc, n, o, 1, d, tmax, RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT, hits, hit_mask);
}
