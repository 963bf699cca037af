/* Generic solver object around a method's type table (the GSL pattern:
 * gsl_root_fsolver_alloc / _iterate / _free around a const type). */
#include "solver.h"

#include "../geometry/hash.h"
#include "../geometry/raycast.h"
#include "../geometry/simplify.h"

#include <errno.h>
#include <stddef.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

struct rp_solver {
    const rp_solver_type *type;
    void *state;
    const rp_comm *comm;
};

rp_status rp_solver_create(const rp_solver_type *type, const rp_scene *scene,
                           const rp_options *options, rp_solver **out, rp_error *err)
{
    *out = NULL;
    rp_status st = rp_options_check(options, type, err);
    if (st != RP_OK)
        return st;
    rp_solver *s = calloc(1, sizeof *s);
    if (!s)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    s->type = type;
    s->state = calloc(1, type->state_size ? type->state_size : 1);
    if (!s->state) {
        free(s);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    }
    /* the type's specs go with the options: defaults come from them */
    rp_options with = {.size = sizeof with};
    if (options)
        memcpy(&with, options, options->size < sizeof with ? options->size : sizeof with);
    with.size = sizeof with;
    with.specs = type->options;
    if (!type->distributed || rp_comm_size(with.comm) <= 1)
        with.comm = NULL;
    s->comm = with.comm;
    st = type->init(s->state, scene, &with, err);
    if (st != RP_OK) {
        /* init cleans up after itself on failure; fini must accept the
         * zeroed or partly built state as well. */
        type->fini(s->state);
        free(s->state);
        free(s);
        return st;
    }
    *out = s;
    return RP_OK;
}

rp_status rp_solver_step(rp_solver *s, rp_step_info *info, rp_error *err)
{
    memset(info, 0, sizeof *info);
    info->residual = -1;
    info->tolerance = -1;
    info->unshot = -1;
    return s->type->step(s->state, info, err);
}

rp_status rp_solver_estimate(const rp_solver *s, rp_estimate *estimate, rp_error *err)
{
    return s->type->estimate(s->state, estimate, err);
}

const rp_solver_type *rp_solver_type_of(const rp_solver *s) { return s->type; }

const void *rp_solver_state(const rp_solver *s) { return s->state; }

const rp_comm *rp_solver_comm(const rp_solver *s) { return s->comm; }

void rp_solver_destroy(rp_solver *s)
{
    if (!s)
        return;
    s->type->fini(s->state);
    free(s->state);
    free(s);
}

const char *rp_options_get(const rp_options *o, const char *name)
{
    if (!o)
        return NULL;
    const char *found = NULL;
    for (size_t i = 0; i < o->count; i++)
        if (strcmp(o->keys[i], name) == 0)
            found = o->values[i]; /* the last one given wins */
    return found;
}

/* The fallback text of name's spec, when it is all a number. */
static const char *numeric_fallback(const rp_options *o, const char *name)
{
    if (!o || o->size < offsetof(rp_options, specs) + sizeof o->specs || !o->specs)
        return NULL;
    for (const rp_option_spec *sp = o->specs; sp->name; sp++)
        if (strcmp(sp->name, name) == 0 && sp->fallback) {
            char *end;
            (void)strtod(sp->fallback, &end);
            return end != sp->fallback && *end == '\0' ? sp->fallback : NULL;
        }
    return NULL;
}

const char *rp_options_word(const rp_options *o, const char *name)
{
    const char *v = rp_options_get(o, name);
    if (v || !o || o->size < offsetof(rp_options, specs) + sizeof o->specs || !o->specs)
        return v;
    for (const rp_option_spec *sp = o->specs; sp->name; sp++)
        if (strcmp(sp->name, name) == 0)
            return sp->fallback;
    return NULL;
}

rp_status rp_options_double(const rp_options *o, const char *name, double lo, double hi,
                            double *out, rp_error *err)
{
    const char *v = rp_options_get(o, name);
    if (!v)
        v = numeric_fallback(o, name);
    if (!v)
        return RP_OK;
    char *end;
    errno = 0;
    double x = strtod(v, &end);
    if (end == v || *end != '\0' || errno == ERANGE || !isfinite(x))
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not a number", name, v);
    if (x < lo || x > hi)
        return rp_error_set(err, RP_ERR_INPUT, "--%s: %s is outside [%g, %g]", name, v, lo, hi);
    *out = x;
    return RP_OK;
}

rp_status rp_options_uint(const rp_options *o, const char *name, unsigned long lo,
                          unsigned long hi, unsigned long *out, rp_error *err)
{
    const char *v = rp_options_get(o, name);
    if (!v)
        v = numeric_fallback(o, name);
    if (!v)
        return RP_OK;
    char *end;
    errno = 0;
    if (*v == '-' || *v == '+')
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not a whole number in [%lu, %lu] (no sign)", name, v,
                            lo, hi);
    unsigned long x = strtoul(v, &end, 10);
    if (end == v || *end != '\0')
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not a whole number", name, v);
    if (errno == ERANGE)
        return rp_error_set(err, RP_ERR_INPUT, "--%s: %s is outside [%lu, %lu]", name, v, lo, hi);
    if (x < lo || x > hi)
        return rp_error_set(err, RP_ERR_INPUT, "--%s: %s is outside [%lu, %lu]", name, v, lo, hi);
    *out = x;
    return RP_OK;
}

rp_status rp_options_check(const rp_options *o, const rp_solver_type *type, rp_error *err)
{
    if (!o)
        return RP_OK;
    for (size_t i = 0; i < o->count; i++) {
        const rp_option_spec *spec = type->options;
        while (spec && spec->name && strcmp(spec->name, o->keys[i]) != 0)
            spec++;
        if (!spec || !spec->name)
            return rp_error_set(err, RP_ERR_INPUT, "method %s has no option --%s (see radpt help %s)",
                                type->name, o->keys[i], type->name);
    }
    return RP_OK;
}

/* ---------------------------------------------------- checkpoint/resume */

#define RP_STATE_MAGIC "RPSTATE1"
/* Sanity bounds on a record's fields before trusting them to malloc. */
#define RP_STATE_MAX_NAME 256
#define RP_STATE_MAX_BYTES (UINT64_C(1) << 40)

static uint64_t fnv1a64(const unsigned char *p, size_t n) { return rp_fnv1a64(RP_FNV1A64_INIT, p, n); }

int rp_solver_put_u64(FILE *f, const uint64_t *v, size_t n)
{
    unsigned char buf[8 * 256];
    while (n > 0) {
        size_t k = n < 256 ? n : 256;
        for (size_t i = 0; i < k; i++)
            for (int b = 0; b < 8; b++)
                buf[8 * i + (size_t)b] = (unsigned char)(v[i] >> (8 * b));
        if (fwrite(buf, 8, k, f) != k)
            return -1;
        v += k;
        n -= k;
    }
    return 0;
}

int rp_solver_get_u64(FILE *f, uint64_t *v, size_t n)
{
    unsigned char buf[8 * 256];
    while (n > 0) {
        size_t k = n < 256 ? n : 256;
        if (fread(buf, 8, k, f) != k)
            return -1;
        for (size_t i = 0; i < k; i++) {
            uint64_t x = 0;
            for (int b = 7; b >= 0; b--)
                x = x << 8 | buf[8 * i + (size_t)b];
            v[i] = x;
        }
        v += k;
        n -= k;
    }
    return 0;
}

/* Doubles travel as their IEEE 754 bit patterns, so a value read back is
 * bit-identical to the one written. */
int rp_solver_put_f64(FILE *f, const double *v, size_t n)
{
    uint64_t u[256];
    while (n > 0) {
        size_t k = n < 256 ? n : 256;
        memcpy(u, v, k * sizeof *u);
        if (rp_solver_put_u64(f, u, k) != 0)
            return -1;
        v += k;
        n -= k;
    }
    return 0;
}

int rp_solver_get_f64(FILE *f, double *v, size_t n)
{
    uint64_t u[256];
    while (n > 0) {
        size_t k = n < 256 ? n : 256;
        if (rp_solver_get_u64(f, u, k) != 0)
            return -1;
        memcpy(v, u, k * sizeof *u);
        v += k;
        n -= k;
    }
    return 0;
}

int rp_solver_can_checkpoint(const rp_solver_type *type)
{
    return type && type->save && type->load;
}

static rp_status no_checkpoint(const rp_solver_type *type, rp_error *err)
{
    return rp_error_set(err, RP_ERR_UNSUPPORTED, "method %s cannot be checkpointed or resumed (only pathtrace can)",
                        type->name);
}

/* The method writes its fields to a memory stream first, so that the record
 * can carry their length and checksum ahead of / after them. */
rp_status rp_solver_save(const rp_solver *s, FILE *f, rp_error *err)
{
    if (!rp_solver_can_checkpoint(s->type))
        return no_checkpoint(s->type, err);
    char *buf = NULL;
    size_t len = 0;
    FILE *mem = open_memstream(&buf, &len);
    if (!mem)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the solver state");
    rp_status st = s->type->save(s->state, mem, err);
    if (fclose(mem) != 0 && st == RP_OK)
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory for the solver state");
    if (st == RP_OK) {
        size_t nlen = strlen(s->type->name);
        uint64_t head[1] = {nlen}, tail[2] = {len, fnv1a64((const unsigned char *)buf, len)};
        int bad = fwrite(RP_STATE_MAGIC, 1, 8, f) != 8;
        bad = bad || rp_solver_put_u64(f, head, 1) != 0;
        bad = bad || fwrite(s->type->name, 1, nlen, f) != nlen;
        bad = bad || rp_solver_put_u64(f, &tail[0], 1) != 0;
        bad = bad || (len && fwrite(buf, 1, len, f) != len);
        bad = bad || rp_solver_put_u64(f, &tail[1], 1) != 0;
        if (bad)
            st = rp_error_set(err, RP_ERR_RUNTIME, "writing the solver state failed");
    }
    free(buf);
    return st;
}

rp_status rp_solver_load(rp_solver *s, FILE *f, rp_step_info *info, rp_error *err)
{
    memset(info, 0, sizeof *info);
    info->residual = -1;
    info->tolerance = -1;
    info->unshot = -1;
    if (!rp_solver_can_checkpoint(s->type))
        return no_checkpoint(s->type, err);
    char magic[8], name[RP_STATE_MAX_NAME + 1];
    uint64_t nlen, len, sum;
    if (fread(magic, 1, 8, f) != 8 || memcmp(magic, RP_STATE_MAGIC, 8) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "no solver state record (bad magic)");
    if (rp_solver_get_u64(f, &nlen, 1) != 0 || nlen > RP_STATE_MAX_NAME || fread(name, 1, nlen, f) != nlen)
        return rp_error_set(err, RP_ERR_INPUT, "solver state record truncated or corrupt (method name)");
    name[nlen] = '\0';
    if (strcmp(name, s->type->name) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "the state is method %s's, not %s's", name, s->type->name);
    if (rp_solver_get_u64(f, &len, 1) != 0 || len > RP_STATE_MAX_BYTES)
        return rp_error_set(err, RP_ERR_INPUT, "solver state record truncated or corrupt (length)");
    char *buf = malloc(len ? (size_t)len : 1);
    if (!buf)
        return rp_error_set(err, RP_ERR_INPUT, "solver state record corrupt (length %llu bytes)",
                            (unsigned long long)len);
    rp_status st = RP_OK;
    if (fread(buf, 1, (size_t)len, f) != len || rp_solver_get_u64(f, &sum, 1) != 0)
        st = rp_error_set(err, RP_ERR_INPUT, "solver state truncated (%llu bytes of fields expected)",
                          (unsigned long long)len);
    else if (sum != fnv1a64((const unsigned char *)buf, (size_t)len))
        st = rp_error_set(err, RP_ERR_INPUT, "solver state corrupt (checksum mismatch)");
    FILE *mem = NULL;
    if (st == RP_OK && !(mem = fmemopen(buf, len ? (size_t)len : 1, "rb")))
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory for the solver state");
    if (st == RP_OK) {
        st = s->type->load(s->state, mem, info, err);
        if (st == RP_OK && (uint64_t)ftell(mem) != len)
            st = rp_error_set(err, RP_ERR_INPUT, "solver state has %llu bytes the method did not read",
                              (unsigned long long)(len - (uint64_t)ftell(mem)));
    }
    if (mem)
        fclose(mem);
    free(buf);
    return st;
}

rp_status rp_options_ray_offset(const rp_options *o, struct rp_raycast *rc, rp_error *err)
{
    if (!rp_options_get(o, "ray-offset"))
        return RP_OK;
    double rel = RP_RAYCAST_DEFAULT_OFFSET;
    rp_status st = rp_options_double(o, "ray-offset", 0, 0.1, &rel, err);
    if (st == RP_OK)
        rp_raycast_set_offset(rc, rel);
    return st;
}

const char *rp_solver_samples_name(const rp_solver_type *type)
{
    return type->samples_name ? type->samples_name : type->iteration_name ? type->iteration_name : "iterations";
}

int rp_options_cancelled(const rp_options *o)
{
    return o && rp_cancelled(o->cancel);
}

int rp_options_image_unwanted(const rp_options *o)
{
    return o && o->want && !(o->want & RP_WANT_IMAGE);
}

rp_status rp_options_simplify(const rp_options *o, const rp_scene *scene, struct rp_solution **out, rp_error *err)
{
    *out = NULL;
    const char *sm = rp_options_word(o, "simplify");
    if (!sm || strcmp(sm, "off") == 0)
        return RP_OK;
    double ratio = 0;
    if (strcmp(sm, "auto") != 0) {
        char *end = NULL;
        ratio = strtod(sm, &end);
        if (end == sm || *end || !(ratio > 0 && ratio < 1))
            return rp_error_set(err, RP_ERR_INPUT, "--simplify: '%s' is not off, auto or a fraction in (0, 1)", sm);
    }
    rp_status st = rp_solution_create(scene, ratio, 0, o ? o->threads : 0, out, o ? o->log : NULL, o ? o->log_ctx : NULL, err);
    if (st == RP_OK && rp_options_image_unwanted(o))
        rp_solution_drop_maps(*out);
    return st;
}
