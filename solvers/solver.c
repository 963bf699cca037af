/* Generic solver object around a method's type table (the GSL pattern:
 * gsl_root_fsolver_alloc / _iterate / _free around a const type). */
#include "solver.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

struct rp_solver {
    const rp_solver_type *type;
    void *state;
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
    st = type->init(s->state, scene, options, err);
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
    info->unshot = -1;
    return s->type->step(s->state, info, err);
}

rp_status rp_solver_estimate(const rp_solver *s, rp_estimate *estimate, rp_error *err)
{
    return s->type->estimate(s->state, estimate, err);
}

const rp_solver_type *rp_solver_type_of(const rp_solver *s) { return s->type; }

const void *rp_solver_state(const rp_solver *s) { return s->state; }

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

rp_status rp_options_double(const rp_options *o, const char *name, double lo, double hi,
                            double *out, rp_error *err)
{
    const char *v = rp_options_get(o, name);
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
        return RP_OK;
    char *end;
    errno = 0;
    if (*v == '-' || *v == '+')
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not a whole number", name, v);
    unsigned long x = strtoul(v, &end, 10);
    if (end == v || *end != '\0' || errno == ERANGE)
        return rp_error_set(err, RP_ERR_INPUT, "--%s: '%s' is not a whole number", name, v);
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
