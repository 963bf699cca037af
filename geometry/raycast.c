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
 * relative to a centre c, the centre of the bounding box of the faces that
 * reflect or emit light (faces black in every band only block light, so a
 * huge black ground plane cannot move the centre and coarsen the float
 * resolution of everything else).  Two rules keep a ray from re-hitting the
 * surface it leaves, and neither depends on the scene's size or units:
 *
 * 1. Offset.  A ray leaving surface point p starts
 *
 *        delta(p) = r * |p - c|_inf
 *
 *    off the face's plane on the side it travels to, r = --ray-offset
 *    (default 1e-5: about 170 float ulps of the point's own coordinates as
 *    Embree holds them; a bound on the float error of the point in the
 *    spirit of pbrt-v3's, Pharr, Jakob & Humphreys 2016, sec. 3.9).  It
 *    covers the rounding of the origin and of faces no larger than the
 *    point's distance from c (Cornell box: 0.1 to 3 micrometres).
 *
 * 2. Rejection.  A ray that leaves a plane at a non-zero angle meets that
 *    plane only at t = 0, so a hit on a face whose plane holds the ray's
 *    origin (to double rounding and the face's own planarity, plane_tol)
 *    is never real: it is the face left, a coplanar neighbour (the Cornell
 *    light in its ceiling) or a coincident twin, misplaced by float
 *    rounding, which grows with the face's own size (Embree's plane through
 *    far vertices) and so is beyond any offset of rule 1 on a face much
 *    larger than the point's distance from c.  Such hits are skipped
 *    exactly, whatever the face's size: closest-hit rays are traced again
 *    beyond the rejected hit (rare; the test costs one comparison, the
 *    plane distance is computed for the refinement below anyway), and
 *    occlusion segments reject them in an Embree occlusion filter, which
 *    Embree calls only on a hit, for either end of the segment.
 *
 * Occlusion segments also end delta(b) off their far end b and are
 * shortened by 1e-6 of their length (the float rounding of the direction
 * moves their far end by about 6e-8 of it).
 *
 * With --ray-offset 0 rule 2 alone keeps rays off their own face (no acne);
 * an offset larger than a real gap makes rays start beyond it (leaks):
 * radpt experiment stability, section 6, measures both.
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

/* A point lies on a face's plane when its distance from the plane is at
 * most the face's non-planarity plus this many double ulps of the
 * magnitudes involved (the point's and the face's vertices' coordinates):
 * rounding of hit points refined onto the plane, of points interpolated on
 * the face, and of the plane offset n . v0. */
#define RP_RAYCAST_PLANE_ULPS 64.0

/* Closest-hit rays from a surface skip at most this many rejected hits
 * (coplanar faces crossed in float) before giving up as a miss. */
#define RP_RAYCAST_MAX_SKIPS 16

/* Float ulps of the magnitudes involved by which Embree's hit distance may
 * differ from the double plane intersection before the refinement below is
 * distrusted. */
#define RP_RAYCAST_REFINE_ULPS 256.0

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
    double cmag;        /* |c|_inf */
    double offset_rel;  /* --ray-offset: delta(p) = offset_rel |p - c|_inf */
    /* Per face: the plane offset n . v0 (world coordinates), the distance
     * within which a point counts as on the plane (its non-planarity and
     * the rounding of its vertices' magnitudes; add the point's own, see
     * rp_on_plane) and the largest |v - c|_inf of its vertices (its float
     * magnitude in Embree). */
    double *plane_d, *plane_tol, *fmag;
};

/* An occlusion query's context: Embree hands it to the occlusion filter,
 * which needs the segments' ends (Embree 3 manual, "rtcInitIntersectContext":
 * the context may be extended by the application). */
typedef struct rp_occ_context {
    struct RTCIntersectContext ctx; /* first member */
    const rp_raycast *rc;
    const rp_vec3 *a, *b;           /* ends of ray id i: a[i], b[i] */
} rp_occ_context;

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
    free(rc->plane_d);
    free(rc->plane_tol);
    free(rc->fmag);
    free(rc);
}

/* max(|x|, |y|, |z|); with plain comparisons, which compile to max
 * instructions, where fmax (NaN rules) is a call into libm. */
static inline double rp_inf_norm(rp_vec3 v)
{
    double x = fabs(v.x), y = fabs(v.y), z = fabs(v.z);
    double m = x > y ? x : y;
    return m > z ? m : z;
}

/* 1 if point p lies on the plane of face f (rule 2 of the header). */
static int rp_on_plane(const rp_raycast *rc, uint32_t f, rp_vec3 p)
{
    double dist = rp_v3_dot(rc->faces[f].normal, p) - rc->plane_d[f];
    return fabs(dist) <= rc->plane_tol[f] + RP_RAYCAST_PLANE_ULPS * DBL_EPSILON * rp_inf_norm(p);
}

/* The scene face of Embree primitive prim of geometry geom. */
static uint32_t rp_prim_face(const rp_raycast *rc, unsigned geom, unsigned prim)
{
    return rc->prim_face[geom == rc->geom_id[RP_GEOM_QUAD] ? RP_GEOM_QUAD : RP_GEOM_TRI][prim];
}

/* Embree's occlusion filter (called on each hit of an occlusion ray):
 * rejects hits on faces whose plane holds either end of the segment.  The
 * ray and hit packets of width N are read with the layout of
 * rtcore_ray.h's RTCRayN_id, RTCHitN_primID and RTCHitN_geomID (C++ only
 * there). */
static void rp_occluded_filter(const struct RTCFilterFunctionNArguments *args)
{
    const rp_occ_context *oc = (const rp_occ_context *)args->context;
    const unsigned N = args->N;
    const unsigned *ray = (const unsigned *)args->ray, *hit = (const unsigned *)args->hit;
    for (unsigned i = 0; i < N; i++) {
        if (args->valid[i] != -1)
            continue;
        unsigned id = ray[10 * N + i];
        uint32_t f = rp_prim_face(oc->rc, hit[6 * N + i], hit[5 * N + i]);
        if (rp_on_plane(oc->rc, f, oc->a[id]) || rp_on_plane(oc->rc, f, oc->b[id]))
            args->valid[i] = 0;
    }
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
    rtcSetGeometryOccludedFilterFunction(geom, rp_occluded_filter);
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

/* The centre (see the header comment) and the per-face plane data. */
static rp_status rp_planes(rp_raycast *rc, rp_error *err)
{
    const size_t nfaces = rp_scene_nfaces(rc->scene), nb = rp_scene_nbands(rc->scene);
    rp_vec3 lo = rp_v3(INFINITY, INFINITY, INFINITY), hi = rp_v3(-INFINITY, -INFINITY, -INFINITY);
    rp_vec3 alo = lo, ahi = hi;
    for (size_t f = 0; f < nfaces; f++) {
        const rp_material *m = rp_scene_face_material(rc->scene, (uint32_t)f);
        int lit = 0;
        for (size_t b = 0; b < nb; b++)
            lit |= m->rho[b] > 0 || m->Le[b] > 0;
        for (uint32_t k = 0; k < rc->faces[f].nverts; k++) {
            rp_vec3 v = rc->vertices[rc->faces[f].v[k]];
            alo = rp_v3(fmin(alo.x, v.x), fmin(alo.y, v.y), fmin(alo.z, v.z));
            ahi = rp_v3(fmax(ahi.x, v.x), fmax(ahi.y, v.y), fmax(ahi.z, v.z));
            if (lit) {
                lo = rp_v3(fmin(lo.x, v.x), fmin(lo.y, v.y), fmin(lo.z, v.z));
                hi = rp_v3(fmax(hi.x, v.x), fmax(hi.y, v.y), fmax(hi.z, v.z));
            }
        }
    }
    if (!(lo.x <= hi.x)) { /* nothing reflects or emits: every face */
        lo = alo;
        hi = ahi;
    }
    rc->centre = rp_v3_scale(rp_v3_add(lo, hi), 0.5);
    if (!rp_v3_isfinite(rc->centre))
        rc->centre = rp_v3(0, 0, 0);
    rc->cmag = rp_inf_norm(rc->centre);

    rc->plane_d = malloc((nfaces ? nfaces : 1) * sizeof *rc->plane_d);
    rc->plane_tol = malloc((nfaces ? nfaces : 1) * sizeof *rc->plane_tol);
    rc->fmag = malloc((nfaces ? nfaces : 1) * sizeof *rc->fmag);
    if (!rc->plane_d || !rc->plane_tol || !rc->fmag) {
        free(rc->plane_d);
        free(rc->plane_tol);
        free(rc->fmag);
        return rp_error_set(err, RP_ERR_NOMEM, "raycast: out of memory for %zu faces", nfaces);
    }
    for (size_t f = 0; f < nfaces; f++) {
        const rp_face *fc = &rc->faces[f];
        rp_vec3 v0 = rc->vertices[fc->v[0]];
        double d = rp_v3_dot(fc->normal, v0), twist = 0, mag = 0, fmag = 0;
        for (uint32_t k = 0; k < fc->nverts; k++) {
            rp_vec3 v = rc->vertices[fc->v[k]];
            twist = fmax(twist, fabs(rp_v3_dot(fc->normal, v) - d));
            mag = fmax(mag, rp_inf_norm(v));
            fmag = fmax(fmag, rp_inf_norm(rp_v3_sub(v, rc->centre)));
        }
        rc->plane_d[f] = d;
        rc->plane_tol[f] = twist + RP_RAYCAST_PLANE_ULPS * DBL_EPSILON * mag;
        rc->fmag[f] = fmag;
    }
    return RP_OK;
}

rp_status rp_raycast_create(const rp_scene *scene, const rp_mesh *mesh, rp_raycast **out,
                            rp_error *err)
{
    *out = NULL;
    rp_status st;
    if (!scene)
        return rp_error_set(err, RP_ERR_INPUT, "raycast: no scene");
    rp_raycast *rc = calloc(1, sizeof *rc);
    if (!rc)
        return rp_error_set(err, RP_ERR_NOMEM, "raycast: out of memory");
    rc->scene = scene;
    rc->mesh = mesh;
    rc->faces = rp_scene_faces(scene);
    rc->vertices = rp_scene_vertices(scene);

    rc->offset_rel = RP_RAYCAST_DEFAULT_OFFSET;
    st = rp_planes(rc, err);
    if (st != RP_OK) {
        free(rc);
        return st;
    }

    rp_rtc_errbuf ebuf = {RTC_ERROR_NONE, ""};
    rc->device = rtcNewDevice(NULL);
    if (!rc->device) {
        enum RTCError code = rtcGetDeviceError(NULL);
        free(rc);
        return rp_error_set(err, RP_ERR_RUNTIME, "embree: cannot create a device (%s)",
                            rp_rtc_error_name(code));
    }
    rtcSetDeviceErrorFunction(rc->device, rp_rtc_error_cb, &ebuf);
    st = rp_build(rc, &ebuf, err);
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

static inline double rp_offset_at(const rp_raycast *rc, rp_vec3 p)
{
    return rc->offset_rel * rp_inf_norm(rp_v3_sub(p, rc->centre));
}

double rp_raycast_offset(const rp_raycast *rc, rp_vec3 p)
{
    return rp_offset_at(rc, p);
}

void rp_raycast_set_offset(rp_raycast *rc, double rel)
{
    rc->offset_rel = rel;
}

/* A ray from o (double, world space) along unit d over [tnear, tfar]. */
static void rp_ray_init(const rp_raycast *rc, struct RTCRay *ray, rp_vec3 o, rp_vec3 d, float tnear, double tfar)
{
    rp_vec3 q = rp_v3_sub(o, rc->centre);
    ray->org_x = (float)q.x;
    ray->org_y = (float)q.y;
    ray->org_z = (float)q.z;
    ray->tnear = tnear;
    ray->dir_x = (float)d.x;
    ray->dir_y = (float)d.y;
    ray->dir_z = (float)d.z;
    ray->time = 0.0f;
    ray->tfar = tfar >= (double)FLT_MAX ? INFINITY : (float)tfar;
    ray->mask = 0xFFFFFFFFu;
    ray->id = 0;
    ray->flags = 0;
}

static void rp_rayhit_init(const rp_raycast *rc, struct RTCRayHit *rh, rp_vec3 o, rp_vec3 d, float tnear,
                           double tfar)
{
    rp_ray_init(rc, &rh->ray, o, d, tnear, tfar);
    rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh->hit.primID = RTC_INVALID_GEOMETRY_ID;
    for (int l = 0; l < RTC_MAX_INSTANCE_LEVEL_COUNT; l++)
        rh->hit.instID[l] = RTC_INVALID_GEOMETRY_ID;
}

/* Fills hit from Embree's answer to a ray that started at o_emb (the offset
 * origin actually traced, delta from o) along unit d; distances are
 * reported from o, the caller's point, which lies on the same line up to
 * the offset along n.  mag is |o - c|_inf (< 0: not computed yet; it is
 * needed only from surfaces and in a rare branch).  With from_surface, a hit on a
 * face whose plane holds o is rejected (rule 2 of the header; |o|_inf is
 * bounded by mag + |c|_inf): returns -1 then, 0 on a miss, 1 on a hit. */
static inline int rp_hit_fill(const rp_raycast *rc, const struct RTCRayHit *rh, rp_vec3 o, rp_vec3 o_emb, double mag,
                              double delta, rp_vec3 d, int from_surface, rp_hit *hit)
{
    if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    int kind = rh->hit.geomID == rc->geom_id[RP_GEOM_QUAD] ? RP_GEOM_QUAD : RP_GEOM_TRI;
    uint32_t face = rc->prim_face[kind][rh->hit.primID];
    const rp_face *fc = &rc->faces[face];

    /* o's signed distance from the face's plane, in double. */
    double h = rp_v3_dot(rp_v3_sub(rc->vertices[fc->v[0]], o), fc->normal);
    if (from_surface && fabs(h) <= rc->plane_tol[face] + RP_RAYCAST_PLANE_ULPS * DBL_EPSILON * (mag + rc->cmag))
        return -1;

    /* Embree's hit distance, measured from o. */
    double t = (double)rh->ray.tfar + rp_v3_dot(rp_v3_sub(o_emb, o), d);
    double cosd = rp_v3_dot(d, fc->normal);
    int refined = 0;
    if (fabs(cosd) > RP_RAYCAST_REFINE_COS) {
        /* Intersect o + t d with the face's plane in double.  Embree's
         * distance differs from it by the float rounding of the origin and
         * the face (their float magnitudes) over |cos|, and by the offset
         * between o and o_emb. */
        double tr = h / cosd, dt = fabs(tr - t);
        if (tr > 0 && !(dt <= 1e-5 * fabs(t)) && mag < 0)
            mag = rp_inf_norm(rp_v3_sub(o, rc->centre));
        if (tr > 0 && (dt <= 1e-5 * fabs(t) ||
                       dt * fabs(cosd) <= RP_RAYCAST_REFINE_ULPS * FLT_EPSILON * (mag + delta + rc->fmag[face]) +
                                              4 * delta)) {
            t = tr;
            refined = 1;
        }
    }
    rp_vec3 p = refined ? rp_v3_madd(o, d, t) : rp_v3_madd(o_emb, d, (double)rh->ray.tfar);

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
    rp_rayhit_init(rc, &rh, o, du, 0.0f, tmax);
    rtcIntersect1(rc->rtc, &ctx, &rh);
    return rp_hit_fill(rc, &rh, o, o, -1, 0, du, 0, hit);
}

/* p moved delta(p) off its plane (normal n) to the side direction d points
 * to (rule 1 of the header); *mag gets |p - c|_inf and *delta delta(p). */
static inline rp_vec3 rp_offset(const rp_raycast *rc, rp_vec3 p, rp_vec3 n, rp_vec3 d, double *mag, double *delta)
{
    *mag = rp_inf_norm(rp_v3_sub(p, rc->centre));
    *delta = rc->offset_rel * *mag;
    return rp_v3_madd(p, n, rp_v3_dot(d, n) >= 0 ? *delta : -*delta);
}

int rp_ray_closest_from(const rp_raycast *rc, rp_vec3 p, rp_vec3 n, rp_vec3 d, rp_hit *hit)
{
    /* Directions built from an orthonormal frame (the path tracer's) are
     * unit to rounding: the square root and division are skipped then. */
    double l2 = rp_v3_dot(d, d);
    rp_vec3 du = fabs(l2 - 1.0) <= 1e-12 || !(l2 > 0) ? d : rp_v3_scale(d, 1.0 / sqrt(l2));
    double mag, delta;
    rp_vec3 o = rp_offset(rc, p, n, du, &mag, &delta);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rp_rayhit_init(rc, &rh, o, du, 0.0f, INFINITY);
    rtcIntersect1(rc->rtc, &ctx, &rh);
    int r = rp_hit_fill(rc, &rh, p, o, mag, delta, du, 1, hit);
    /* A rejected hit (rare with an offset): trace again beyond it. */
    for (int skip = 0; r < 0 && skip < RP_RAYCAST_MAX_SKIPS; skip++) {
        float tnear = nextafterf(rh.ray.tfar, INFINITY);
        rp_rayhit_init(rc, &rh, o, du, tnear, INFINITY);
        rtcIntersect1(rc->rtc, &ctx, &rh);
        r = rp_hit_fill(rc, &rh, p, o, mag, delta, du, 1, hit);
    }
    return r > 0;
}

/* An occlusion ray for the segment a -> b between surface points (normals
 * na, nb): both ends offset off their surfaces (rule 1), shortened. */
static inline double rp_segment_init(const rp_raycast *rc, struct RTCRay *ray, rp_vec3 a, rp_vec3 na, rp_vec3 b,
                              rp_vec3 nb, unsigned id)
{
    rp_vec3 ab = rp_v3_sub(b, a);
    double ma, mb, da, db;
    rp_vec3 a2 = rp_offset(rc, a, na, ab, &ma, &da);
    rp_vec3 b2 = rp_offset(rc, b, nb, rp_v3_scale(ab, -1.0), &mb, &db);
    rp_vec3 d = rp_v3_sub(b2, a2);
    double len = rp_v3_length(d);
    /* A degenerate segment is a free ray of length 0. */
    if (len > 0)
        d = rp_v3_scale(d, 1.0 / len);
    rp_ray_init(rc, ray, a2, d, 0.0f, len > 0 ? len * (1.0 - RP_RAYCAST_OCCLUDE_SHORTEN) : 0.0);
    ray->id = id;
    return len;
}

int rp_ray_occluded(const rp_raycast *rc, rp_vec3 a, rp_vec3 na, rp_vec3 b, rp_vec3 nb)
{
    struct RTCRay ray;
    if (!(rp_segment_init(rc, &ray, a, na, b, nb, 0) > 0))
        return 0;
    rp_occ_context oc = {.rc = rc, .a = &a, .b = &b};
    rtcInitIntersectContext(&oc.ctx);
    rtcOccluded1(rc->rtc, &oc.ctx, &ray);
    /* Embree sets tfar to -inf when the ray is occluded. */
    return ray.tfar < 0.0f;
}

void rp_ray_occluded_n(const rp_raycast *rc, size_t n, const rp_vec3 *a, rp_vec3 na, const rp_vec3 *b, rp_vec3 nb,
                       unsigned char *blocked)
{
    rp_occ_context oc = {.rc = rc};
    rtcInitIntersectContext(&oc.ctx);
    oc.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    struct RTCRay ray[RP_RAYCAST_STREAM];
    for (size_t start = 0; start < n; start += RP_RAYCAST_STREAM) {
        size_t m = n - start < RP_RAYCAST_STREAM ? n - start : RP_RAYCAST_STREAM;
        oc.a = a + start;
        oc.b = b + start;
        for (size_t i = 0; i < m; i++)
            rp_segment_init(rc, &ray[i], a[start + i], na, b[start + i], nb, (unsigned)i);
        rtcOccluded1M(rc->rtc, &oc.ctx, ray, (unsigned)m, sizeof ray[0]);
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
            rp_rayhit_init(rc, &rh[i], o[(start + i) * o_stride], du[i], 0.0f, tmax);
        }
        rtcIntersect1M(rc->rtc, &ctx, rh, (unsigned)m, sizeof rh[0]);
        for (size_t i = 0; i < m; i++) {
            rp_vec3 oi = o[(start + i) * o_stride];
            hit_mask[start + i] = (unsigned char)rp_hit_fill(rc, &rh[i], oi, oi, -1, 0, du[i], 0, &hits[start + i]);
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
