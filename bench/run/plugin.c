/* Loading plugins (plugin.h). */
#include "bench/run/plugin.h"

#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "solvers/plugin.h"

#ifndef RP_VERSION
#define RP_VERSION "unknown"
#endif

static rp_status host_register(const rp_plugin_host *host, const rp_solver_type *type, rp_error *err)
{
    rp_status st = rp_solver_register(type, err);
    if (st != RP_OK && err) {
        char msg[sizeof err->message];
        snprintf(msg, sizeof msg, "%s", err->message);
        rp_error_set(err, st, "%s: %s", host->path, msg);
    }
    return st;
}

rp_status rp_plugin_load(const char *path, rp_error *err)
{
    struct stat sb;
    if (stat(path, &sb) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot load the plugin: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode))
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot load the plugin: not a file", path);
    /* dlopen searches the library path for a name without a slash: a
     * plugin is always the file named */
    char file[4096];
    snprintf(file, sizeof file, "%s%s", strchr(path, '/') ? "" : "./", path);
    void *h = dlopen(file, RTLD_NOW | RTLD_LOCAL);
    if (!h)
        return rp_error_set(err, RP_ERR_INPUT, "%s: not a loadable shared object: %s", path, dlerror());
    const int *abi = dlsym(h, RP_PLUGIN_ABI_SYMBOL);
    rp_plugin_init_fn init;
    *(void **)&init = dlsym(h, RP_PLUGIN_ENTRY); /* POSIX: a function pointer through void * */
    rp_status st = RP_OK;
    if (!abi || !init)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: not a radpt plugin: it does not export %s (declare it with "
                          "RP_PLUGIN_DECLARE_ABI and define %s, solvers/plugin.h)", path,
                          !abi ? RP_PLUGIN_ABI_SYMBOL : RP_PLUGIN_ENTRY, RP_PLUGIN_ENTRY);
    else if (*abi != RP_PLUGIN_ABI)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: built for radpt plugin ABI %d; this radpt (%s) loads ABI %d: "
                          "rebuild the plugin against this radpt's headers", path, *abi, RP_VERSION, RP_PLUGIN_ABI);
    else {
        rp_plugin_host host = {.size = sizeof host, .abi = RP_PLUGIN_ABI, .version = RP_VERSION, .path = path,
                               .register_type = host_register};
        rp_error perr;
        rp_error_clear(&perr);
        st = init(&host, RP_PLUGIN_ABI, &perr);
        if (st != RP_OK) {
            /* register_type's messages already name the file */
            if (!strncmp(perr.message, path, strlen(path)))
                rp_error_set(err, RP_ERR_INPUT, "%s", perr.message);
            else
                rp_error_set(err, RP_ERR_INPUT, "%s: %s failed: %s", path, RP_PLUGIN_ENTRY,
                             perr.message[0] ? perr.message : rp_status_string(st));
            st = RP_ERR_INPUT;
        }
    }
    /* A loaded plugin stays loaded (its types are registered); one that
     * failed before registering anything is closed. */
    if (st != RP_OK && (!abi || !init || *abi != RP_PLUGIN_ABI))
        dlclose(h);
    return st;
}

static int by_name(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every *.so file of dir, in name order. */
static rp_status load_dir(const char *dir, rp_error *err)
{
    DIR *d = opendir(dir);
    if (!d)
        return rp_error_set(err, RP_ERR_INPUT, "RADPT_PLUGIN_PATH: %s: %s", dir, strerror(errno));
    char **names = NULL;
    size_t n = 0, cap = 0;
    rp_status st = RP_OK;
    for (struct dirent *e; st == RP_OK && (e = readdir(d));) {
        size_t len = strlen(e->d_name);
        if (len < 4 || strcmp(e->d_name + len - 3, ".so") != 0)
            continue;
        if (n == cap) {
            size_t c = cap ? 2 * cap : 8;
            char **grown = realloc(names, c * sizeof *names);
            if (!grown) {
                st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
                break;
            }
            names = grown;
            cap = c;
        }
        size_t sz = strlen(dir) + len + 2;
        if (!(names[n] = malloc(sz))) {
            st = rp_error_set(err, RP_ERR_NOMEM, "out of memory");
            break;
        }
        snprintf(names[n++], sz, "%s/%s", dir, e->d_name);
    }
    closedir(d);
    if (n)
        qsort(names, n, sizeof *names, by_name);
    for (size_t i = 0; i < n; i++) {
        if (st == RP_OK)
            st = rp_plugin_load(names[i], err);
        free(names[i]);
    }
    free(names);
    return st;
}

rp_status rp_plugin_load_env(rp_error *err)
{
    const char *v = getenv("RADPT_PLUGIN_PATH");
    if (!v || !*v)
        return RP_OK;
    char *list = strdup(v);
    if (!list)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    rp_status st = RP_OK;
    char *save = NULL;
    for (char *item = strtok_r(list, ":", &save); item && st == RP_OK; item = strtok_r(NULL, ":", &save)) {
        struct stat sb;
        if (stat(item, &sb) == 0 && S_ISDIR(sb.st_mode))
            st = load_dir(item, err);
        else
            st = rp_plugin_load(item, err);
    }
    free(list);
    return st;
}
