/* The registry of methods: adding a method is one new file exporting one
 * const rp_solver_type and one line here. */
#include "solver.h"

#include <stdlib.h>
#include <string.h>

extern const rp_solver_type rp_solver_pathtrace;
extern const rp_solver_type rp_solver_jacobi;
extern const rp_solver_type rp_solver_gauss_seidel;
extern const rp_solver_type rp_solver_southwell;
extern const rp_solver_type rp_solver_direct;
extern const rp_solver_type rp_solver_stochastic_jacobi;
extern const rp_solver_type rp_solver_hierarchical;

static const rp_solver_type *const types[] = {
    &rp_solver_pathtrace,
    &rp_solver_jacobi,
    &rp_solver_gauss_seidel,
    &rp_solver_southwell,
    &rp_solver_direct,
    &rp_solver_stochastic_jacobi,
    &rp_solver_hierarchical,
    NULL
};

static const rp_solver_type **all;

const rp_solver_type *const *rp_solver_types(void) { return all ? all : types; }

const rp_solver_type *rp_solver_lookup(const char *name)
{
    const rp_solver_type *const *list = rp_solver_types();
    for (size_t i = 0; list[i]; i++)
        if (strcmp(list[i]->name, name) == 0)
            return list[i];
    return NULL;
}

/* Methods registered at run time (plugins, solvers/plugin.h), after the
 * built-in ones; the list stays NULL-terminated. */
static size_t nall;

rp_status rp_solver_register(const rp_solver_type *type, rp_error *err)
{
    if (!type || !type->name || !type->name[0] || !type->init || !type->step || !type->estimate || !type->fini)
        return rp_error_set(err, RP_ERR_INPUT, "a method needs a name, init, step, estimate and fini");
    for (const char *c = type->name; *c; c++)
        if (!((*c >= 'a' && *c <= 'z') || (*c >= '0' && *c <= '9') || *c == '-' || *c == '_'))
            return rp_error_set(err, RP_ERR_INPUT, "method name '%s': only a-z, 0-9, '-' and '_'", type->name);
    if (rp_solver_lookup(type->name))
        return rp_error_set(err, RP_ERR_INPUT, "a method named '%s' already exists", type->name);
    size_t nbuiltin = sizeof types / sizeof types[0] - 1;
    if (!all) {
        all = malloc((nbuiltin + 2) * sizeof *all);
        if (!all)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        memcpy(all, types, nbuiltin * sizeof *all);
        nall = nbuiltin;
    } else {
        const rp_solver_type **grown = realloc(all, (nall + 2) * sizeof *all);
        if (!grown)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
        all = grown;
    }
    all[nall++] = type;
    all[nall] = NULL;
    return RP_OK;
}
