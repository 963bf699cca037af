/* The plugin ABI: how a method built outside radpt joins it (README.md,
 * "Your own method").
 *
 * A plugin is a shared object that exports two symbols:
 *
 *     RP_PLUGIN_DECLARE_ABI;   (the ABI it was built for: const int rp_plugin_abi)
 *     rp_status rp_plugin_init(const rp_plugin_host *host, int abi, rp_error *err);
 *
 * radpt reads rp_plugin_abi after dlopen and refuses a plugin built for
 * another ABI, naming both versions; then it calls rp_plugin_init once,
 * with the ABI version it implements.  The plugin hands
 * each of its methods to host->register_type: a const rp_solver_type
 * (solvers/solver.h), the very table the built-in methods fill.  From then
 * on the method is one of radpt's: render, probe, bench, experiment and
 * `help METHOD` find it by name.  A plugin sees only radpt's installed
 * headers (include/radpt/) and calls only the functions declared there.
 *
 * The ABI version changes whenever rp_solver_type, rp_options,
 * rp_step_info, rp_estimate or this host table change in a way an older
 * plugin would misread; radpt refuses a plugin built for another version,
 * naming both. */
#ifndef RP_PLUGIN_H
#define RP_PLUGIN_H

#include "solver.h"

#ifdef __cplusplus
extern "C" {
#endif

#define RP_PLUGIN_ABI 1
#define RP_PLUGIN_ENTRY "rp_plugin_init"
#define RP_PLUGIN_ABI_SYMBOL "rp_plugin_abi"

/* Put this line in one source file of the plugin. */
#define RP_PLUGIN_DECLARE_ABI const int rp_plugin_abi = RP_PLUGIN_ABI

typedef struct rp_plugin_host rp_plugin_host;
struct rp_plugin_host {
    size_t size;            /* sizeof(rp_plugin_host) as radpt knows it */
    int abi;                /* RP_PLUGIN_ABI of the radpt that loads you */
    const char *version;    /* radpt's release, e.g. "0.16.0" */
    const char *path;       /* the plugin's file, for messages */
    /* Registers a method; its name must be new (RP_ERR_INPUT otherwise).
     * type must outlive the process (a static const table). */
    rp_status (*register_type)(const rp_plugin_host *host, const rp_solver_type *type, rp_error *err);
    void *impl;
};

typedef rp_status (*rp_plugin_init_fn)(const rp_plugin_host *host, int abi, rp_error *err);


#ifdef __cplusplus
}
#endif

#endif
