/* The registry of methods: adding a method is one new file exporting one
 * const rp_solver_type and one line here. */
#include "solver.h"

#include <string.h>

extern const rp_solver_type rp_solver_pathtrace;

static const rp_solver_type *const types[] = {
    &rp_solver_pathtrace,
    NULL
};

const rp_solver_type *const *rp_solver_types(void) { return types; }

const rp_solver_type *rp_solver_lookup(const char *name)
{
    for (size_t i = 0; types[i]; i++)
        if (strcmp(types[i]->name, name) == 0)
            return types[i];
    return NULL;
}
