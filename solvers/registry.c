/* The registry of methods: adding a method is one new file exporting one
 * const rp_solver_type and one line here. */
#include "solver.h"

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

const rp_solver_type *const *rp_solver_types(void) { return types; }

const rp_solver_type *rp_solver_lookup(const char *name)
{
    for (size_t i = 0; types[i]; i++)
        if (strcmp(types[i]->name, name) == 0)
            return types[i];
    return NULL;
}
