#include "cli_util.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

static char *slurp(const char *path)
{
    char *s = rp_read_file(path);
    return s ? s : calloc(1, 1);
}

char *rp_read_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    size_t got = fread(s, 1, (size_t)n, f);
    s[got] = '\0';
    fclose(f);
    return s;
}

static rp_run run_prefixed(const char *prefix, const char *args)
{
    char out[64], err[64];
    snprintf(out, sizeof out, "/tmp/rp_test_out.%d", (int)getpid());
    snprintf(err, sizeof err, "/tmp/rp_test_err.%d", (int)getpid());
    size_t n = strlen(args) + 1024;
    char *cmd = malloc(n);
    snprintf(cmd, n, "cd '%s' && %s'%s' %s >%s 2>%s </dev/null", RP_SOURCE_DIR, prefix, RP_BIN, args, out, err);
    int st = system(cmd);
    free(cmd);
    rp_run r;
    r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    unlink(out);
    unlink(err);
    return r;
}

rp_run rp_run_radpt(const char *args)
{
    return run_prefixed("", args);
}

rp_run rp_run_radpt_mpi(int ranks, const char *args)
{
    /* Under make asan, LeakSanitizer is off for the ranks: Open MPI keeps
     * allocations in the components it dlopens and unloads at MPI_Finalize
     * (reported from "<unknown module>", so no suppression can name them).
     * The plain runs of the same commands are leak-checked. */
    char prefix[256];
    snprintf(prefix, sizeof prefix,
             "ASAN_OPTIONS=\"${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0\" "
             "mpirun -q --oversubscribe --bind-to none %s-np %d ",
             geteuid() == 0 ? "--allow-run-as-root " : "", ranks);
    return run_prefixed(prefix, args);
}

rp_run rp_run_radpt_env(const char *env, const char *args)
{
    char prefix[1024];
    snprintf(prefix, sizeof prefix, "env %s ", env);
    return run_prefixed(prefix, args);
}

void rp_run_free(rp_run *r)
{
    free(r->out);
    free(r->err);
    r->out = r->err = NULL;
}

double rp_json_number_after(const char *text, const char *anchor, const char *key)
{
    const char *p = strstr(text, anchor);
    if (!p)
        return NAN;
    char pat[128];
    snprintf(pat, sizeof pat, "\"%s\":", key);
    p = strstr(p, pat);
    if (!p)
        return NAN;
    return strtod(p + strlen(pat), NULL);
}

size_t rp_json_arrays(const char *text, const char *key, double *out, size_t max)
{
    char pat[128];
    snprintf(pat, sizeof pat, "\"%s\": [", key);
    size_t n = 0;
    for (const char *p = strstr(text, pat); p && n < max; p = strstr(p, pat)) {
        p += strlen(pat);
        while (*p && *p != ']' && n < max) {
            char *end;
            double v = strtod(p, &end);
            if (end == p)
                break;
            out[n++] = v;
            p = end;
            while (*p == ',' || *p == ' ')
                p++;
        }
    }
    return n;
}

size_t rp_count_lines(const char *s)
{
    size_t n = 0;
    for (; *s; s++)
        n += *s == '\n';
    return n;
}

int rp_test_tmpdir(char *buf, size_t n, const char *prefix)
{
    snprintf(buf, n, "/tmp/%s.XXXXXX", prefix);
    return mkdtemp(buf) ? 0 : -1;
}

const char *rp_test_ref_cache(void)
{
    static const char dir[] = RP_SOURCE_DIR "/build/test-refs";
    char cmd[sizeof dir + 32];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    return system(cmd) == 0 ? dir : NULL;
}

int rp_test_rmtree(const char *dir)
{
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    return system(cmd);
}
