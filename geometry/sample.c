/* Uniform area sampling of surfaces and emitters.
 *
 * The face is chosen with Walker's alias method (Walker 1977; the table is
 * built by GSL's gsl_ran_discrete_preproc, after Knuth, TAOCP vol. 2,
 * 3.4.1): one uniform number picks a column and then either the column's
 * own face or its alias.  GSL's own lookup draws that number from a gsl_rng;
 * here the caller supplies it (u0), so stratified and Sobol' samplers can
 * drive the choice.  The lookup below repeats GSL 2.7's (randist/discrete.c,
 * gsl_ran_discrete, with its KNUTH_CONVENTION table in which
 * F[k] = (k + f_k) / K): with c = floor(u0 K), take c if u0 < F[c], else
 * A[c].  tests/test_sample.c checks it against gsl_ran_discrete itself.
 *
 * The point on the face is uniform in area: the square-root
 * parameterisation for triangles (Shirley 1992, "Nonuniform random point
 * sets via warping", Graphics Gems III; Pharr, Jakob & Humphreys, PBRT 3,
 * eq. 13.6), for a parallelogram the bilinear map of its two edges, and
 * for any other convex quad one of its two triangles chosen in proportion
 * to area, u1 rescaled to reuse it. */
#include "sample.h"

#include <gsl/gsl_randist.h>
#include <stdlib.h>

typedef struct rp_face_map rp_face_map;

struct rp_area_sampler {
    const rp_scene *scene;
    const rp_face *scene_faces;
    size_t count;              /* faces with non-zero weight */
    uint32_t *faces;           /* [count]: alias-table index -> scene face */
    double *pdf;               /* [nfaces of the scene]: pdf_area per face */
    rp_face_map *map;          /* [count]: how (u1, u2) maps onto the face */
    gsl_ran_discrete_t *table; /* NULL when count == 0 */
};

/* Uniform point on triangle (a, b, c): barycentrics (1 - sqrt u1,
 * u2 sqrt u1) (Shirley 1992). */
static rp_vec3 rp_triangle_sample(rp_vec3 a, rp_vec3 b, rp_vec3 c, double u1, double u2)
{
    double su = sqrt(u1);
    double b1 = u2 * su;  /* weight of b */
    double b2 = 1.0 - su; /* weight of a */
    return rp_v3_add(rp_v3_scale(a, b2),
                     rp_v3_add(rp_v3_scale(b, b1), rp_v3_scale(c, 1.0 - b1 - b2)));
}

/* A convex quad is sampled as triangles (v0, v1, v2) and (v0, v2, v3)
 * chosen by area: the first one's share of the area (1 for triangles). */
static double quad_share(const rp_scene *scene, const rp_face *fc)
{
    if (fc->nverts == 3)
        return 1.0;
    const rp_vec3 *v = rp_scene_vertices(scene);
    rp_vec3 a = v[fc->v[0]], e = rp_v3_sub(v[fc->v[2]], a);
    double a1 = rp_v3_length(rp_v3_cross(rp_v3_sub(v[fc->v[1]], a), e));
    double a2 = rp_v3_length(rp_v3_cross(e, rp_v3_sub(v[fc->v[3]], a)));
    return a1 / (a1 + a2);
}

static rp_vec3 face_point(const rp_scene *scene, const rp_face *fc, double share, double u1, double u2)
{
    const rp_vec3 *v = rp_scene_vertices(scene);
    rp_vec3 a = v[fc->v[0]], b = v[fc->v[1]], c = v[fc->v[2]];
    if (fc->nverts == 3)
        return rp_triangle_sample(a, b, c, u1, u2);
    if (u1 < share) {
        u1 /= share;
        return rp_triangle_sample(a, b, c, u1 < 1.0 ? u1 : 1.0, u2);
    }
    u1 = (u1 - share) / (1.0 - share);
    return rp_triangle_sample(a, c, v[fc->v[3]], u1 < 1.0 ? u1 : 1.0, u2);
}

/* A face prepared for sampling.  A parallelogram (most quads: boxes,
 * walls, lamps) maps (u1, u2) bilinearly, p = v0 + u1 (v1 - v0) +
 * u2 (v3 - v0): uniform in area with no square root or division, and a
 * stratified or low-discrepancy (u1, u2) stays evenly spread on the face.
 * Other faces use face_point. */
struct rp_face_map {
    rp_vec3 o, e1, e2;  /* parallelogram: origin and edges */
    const rp_face *face; /* NULL for a parallelogram */
    double share;
};

static rp_face_map face_map(const rp_scene *scene, const rp_face *fc)
{
    const rp_vec3 *v = rp_scene_vertices(scene);
    rp_face_map m = {rp_v3(0, 0, 0), rp_v3(0, 0, 0), rp_v3(0, 0, 0), fc, quad_share(scene, fc)};
    if (fc->nverts == 4) {
        rp_vec3 e1 = rp_v3_sub(v[fc->v[1]], v[fc->v[0]]), e2 = rp_v3_sub(v[fc->v[3]], v[fc->v[0]]);
        /* v2 = v1 + v3 - v0 up to rounding of the input. */
        rp_vec3 gap = rp_v3_sub(rp_v3_add(v[fc->v[0]], v[fc->v[2]]), rp_v3_add(v[fc->v[1]], v[fc->v[3]]));
        double scale = rp_v3_length(e1) + rp_v3_length(e2);
        if (rp_v3_length(gap) <= 1e-12 * scale) {
            m.o = v[fc->v[0]];
            m.e1 = e1;
            m.e2 = e2;
            m.face = NULL;
        }
    }
    return m;
}

static inline rp_vec3 face_map_point(const rp_scene *scene, const rp_face_map *m, double u1, double u2)
{
    return m->face ? face_point(scene, m->face, m->share, u1, u2)
                   : rp_v3_madd(rp_v3_madd(m->o, m->e1, u1), m->e2, u2);
}

void rp_area_sampler_destroy(rp_area_sampler *s)
{
    if (!s)
        return;
    gsl_ran_discrete_free(s->table);
    free(s->faces);
    free(s->pdf);
    free(s->map);
    free(s);
}

rp_status rp_area_sampler_create(const rp_scene *scene, uint32_t surface, rp_area_weight weight,
                                 rp_area_sampler **out, rp_error *err)
{
    *out = NULL;
    size_t nfaces = rp_scene_nfaces(scene);
    const rp_face *faces = rp_scene_faces(scene);
    uint32_t first = 0, last = (uint32_t)nfaces;
    if (surface != RP_NONE) {
        if (surface >= rp_scene_nsurfaces(scene))
            return rp_error_set(err, RP_ERR_INPUT, "area sampler: no surface %u (the scene has %zu)",
                                surface, rp_scene_nsurfaces(scene));
        const rp_surface *sf = &rp_scene_surfaces(scene)[surface];
        first = sf->first_face;
        last = sf->first_face + sf->nfaces;
    }
    if (weight != RP_WEIGHT_AREA && weight != RP_WEIGHT_POWER)
        return rp_error_set(err, RP_ERR_INPUT, "area sampler: unknown weight %d", (int)weight);

    rp_area_sampler *s = calloc(1, sizeof *s);
    double *w = malloc((nfaces ? nfaces : 1) * sizeof *w);
    if (s) {
        s->scene = scene;
        s->scene_faces = faces;
        s->pdf = calloc(nfaces ? nfaces : 1, sizeof *s->pdf);
        s->faces = malloc((nfaces ? nfaces : 1) * sizeof *s->faces);
        s->map = malloc((nfaces ? nfaces : 1) * sizeof *s->map);
    }
    if (!s || !w || !s->pdf || !s->faces || !s->map) {
        free(w);
        rp_area_sampler_destroy(s);
        return rp_error_set(err, RP_ERR_NOMEM, "area sampler: out of memory for %zu faces", nfaces);
    }

    size_t nbands = rp_scene_nbands(scene);
    double total = 0;
    for (uint32_t f = first; f < last; f++) {
        double wf = faces[f].area;
        if (weight == RP_WEIGHT_POWER) {
            /* Power up to the constant pi: area times the band-mean of Le. */
            const double *Le = rp_scene_face_material(scene, f)->Le;
            double mean = 0;
            for (size_t b = 0; b < nbands; b++)
                mean += Le[b];
            wf *= nbands ? mean / (double)nbands : 0.0;
        }
        if (wf > 0 && faces[f].area > 0) {
            s->faces[s->count] = f;
            w[s->count++] = wf;
            total += wf;
        }
    }

    if (s->count > 0) {
        for (size_t i = 0; i < s->count; i++) {
            uint32_t f = s->faces[i];
            s->pdf[f] = w[i] / (total * faces[f].area);
            s->map[i] = face_map(scene, &faces[f]);
        }
        s->table = gsl_ran_discrete_preproc(s->count, w);
        if (!s->table) {
            free(w);
            rp_area_sampler_destroy(s);
            return rp_error_set(err, RP_ERR_NOMEM, "area sampler: cannot build the alias table");
        }
    }
    free(w);
    *out = s;
    return RP_OK;
}

size_t rp_area_sampler_count(const rp_area_sampler *s)
{
    return s->count;
}

/* The alias lookup of gsl_ran_discrete (GSL 2.7) driven by u in [0, 1). */
static size_t rp_alias_lookup(const gsl_ran_discrete_t *g, double u)
{
    size_t c = (size_t)(u * (double)g->K);
    if (c >= g->K) /* u * K rounded up to K, or u outside [0, 1) */
        c = g->K - 1;
    double f = g->F[c];
    if (f == 1.0 || u < f)
        return c;
    return g->A[c];
}

void rp_area_sampler_sample(const rp_area_sampler *s, double u0, double u1, double u2,
                            rp_area_sample *out)
{
    if (s->count == 0) {
        out->p = rp_v3(0, 0, 0);
        out->n = rp_v3(0, 0, 0);
        out->face = RP_NONE;
        out->surface = RP_NONE;
        out->pdf_area = 0;
        return;
    }
    if (!(u0 >= 0))
        u0 = 0;
    size_t k = s->count == 1 ? 0 : rp_alias_lookup(s->table, u0);
    uint32_t f = s->faces[k];
    const rp_face *fc = &s->scene_faces[f];
    out->p = face_map_point(s->scene, &s->map[k], u1, u2);
    out->n = fc->normal;
    out->face = f;
    out->surface = fc->surface;
    out->pdf_area = s->pdf[f];
}

double rp_area_sampler_pdf(const rp_area_sampler *s, uint32_t face)
{
    if (face >= rp_scene_nfaces(s->scene))
        return 0;
    return s->pdf[face];
}

rp_vec3 rp_face_sample_uniform(const rp_scene *scene, uint32_t face, double u1, double u2)
{
    const rp_face *fc = &rp_scene_faces(scene)[face];
    return face_point(scene, fc, quad_share(scene, fc), u1, u2);
}
