/* The one printf-style log line of radpt: formats and hands the line to a
 * caller's log function (rp_log_fn of solvers/solver.h, the same type
 * spelled out here because geometry/ comes below solvers/), which decides
 * where it goes (the command line prints it on stderr unless --quiet). */
#ifndef RP_LOG_H
#define RP_LOG_H

#include <stdarg.h>

/* Nothing when log is NULL. */
void rp_logf(void (*log)(void *ctx, const char *message), void *ctx, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* The same with a va_list, for other printf-style wrappers. */
void rp_vlogf(void (*log)(void *ctx, const char *message), void *ctx, const char *fmt, va_list ap);

#endif
