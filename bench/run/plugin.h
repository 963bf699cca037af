/* Loading plugins (solvers/plugin.h): shared objects that add methods. */
#ifndef RP_PLUGIN_LOAD_H
#define RP_PLUGIN_LOAD_H

#include "geometry/status.h"

/* dlopens path, checks its ABI and calls its rp_plugin_init, which
 * registers its methods.  Every failure is RP_ERR_INPUT with a message that
 * starts with path: no such file, not a shared object (dlerror's words), no
 * rp_plugin_abi or rp_plugin_init, another ABI, a method name that exists. */
rp_status rp_plugin_load(const char *path, rp_error *err);

/* Loads what RADPT_PLUGIN_PATH names (a colon-separated list of plugin
 * files and directories, whose *.so files load in name order); unset or
 * empty: nothing. */
rp_status rp_plugin_load_env(rp_error *err);

#endif
