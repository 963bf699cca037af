/* Status codes and error messages shared by every radpt module.
 *
 * Library code never prints, exits or aborts: it returns an rp_status and,
 * when the caller passed an rp_error, a message naming the file, line and
 * what is wrong ("scenes/x.scene:12: reflect 1.2 outside [0, 1)"). */
#ifndef RP_STATUS_H
#define RP_STATUS_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum rp_status {
    RP_OK = 0,
    RP_ERR_INPUT,       /* bad input: scene, mesh file, option (exit 2) */
    RP_ERR_RUNTIME,     /* the run failed: I/O, library error (exit 1) */
    RP_ERR_NOMEM,       /* allocation failed (exit 1) */
    RP_ERR_UNSUPPORTED, /* the method cannot answer this request (exit 1) */
    RP_ERR_INTERRUPTED  /* stopped on request (rp_options.cancel) (exit 1) */
} rp_status;

typedef struct rp_error {
    char message[1024];
} rp_error;

/* Formats a message into err (which may be NULL) and returns status. */
rp_status rp_error_set(rp_error *err, rp_status status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Clears err (which may be NULL). */
void rp_error_clear(rp_error *err);

/* Exit status the command line uses for a status: 0, 1 or 2. */
int rp_status_exit_code(rp_status status);

/* A short name for a status ("bad input", "out of memory", ...). */
const char *rp_status_string(rp_status status);

#ifdef __cplusplus
}
#endif

#endif
