/* Running ./radpt from tests: exit status, stdout and stderr captured. */
#ifndef RP_TEST_CLI_UTIL_H
#define RP_TEST_CLI_UTIL_H

#include <stddef.h>

typedef struct rp_run {
    int status;   /* exit status, or -1 if killed by a signal */
    char *out;    /* stdout, NUL-terminated (malloc'd) */
    char *err;    /* stderr */
} rp_run;

/* Runs "RP_BIN args" from the source directory. */
rp_run rp_run_radpt(const char *args);
void rp_run_free(rp_run *r);

/* Runs "mpirun -np ranks RP_BIN args" the same way (--oversubscribe, no
 * core binding, -q; --allow-run-as-root when run as root, as CI is). */
rp_run rp_run_radpt_mpi(int ranks, const char *args);

/* The same with "NAME=VALUE ..." set in its environment. */
rp_run rp_run_radpt_env(const char *env, const char *args);

/* The number in a JSON object following "key": after the first occurrence
 * of anchor (a string that must occur in text); NAN if absent. */
double rp_json_number_after(const char *text, const char *anchor, const char *key);

/* Every number of every "key": [...] array in text, in order, into out
 * (at most max); returns how many. */
size_t rp_json_arrays(const char *text, const char *key, double *out, size_t max);

/* A whole file, NUL-terminated (malloc'd), or NULL if it cannot be read. */
char *rp_read_file(const char *path);

/* A fresh directory /tmp/PREFIX.XXXXXX in buf; 0, or -1 on failure. */
int rp_test_tmpdir(char *buf, size_t n, const char *prefix);
/* The reference cache the experiment tests share, made if missing:
 * build/test-refs in the source tree, whichever build runs the tests, so
 * `make asan` after `make test` (CI) reads the path-traced references the
 * release build computed instead of tracing them again under the
 * sanitizers (the reference's own code is checked under them by
 * test_driver.c and test_cli.c).  A reference is keyed by its scene's hash
 * and its options (bench/run/reference.c), and `make clean` removes it;
 * NULL if it cannot be made. */
const char *rp_test_ref_cache(void);

/* rm -rf dir; 0 on success. */
int rp_test_rmtree(const char *dir);

/* Number of lines in s. */
size_t rp_count_lines(const char *s);

#endif
