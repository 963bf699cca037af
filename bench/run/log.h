/* The one printf-style log line of bench/: formats and hands the line to a
 * caller's rp_log_fn (solvers/solver.h), which decides where it goes (the
 * command line prints it on stderr unless --quiet). */
#ifndef RP_LOG_H
#define RP_LOG_H

#include <stdarg.h>

#include "solvers/solver.h"

/* Nothing when log is NULL. */
void rp_logf(rp_log_fn log, void *ctx, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* The same with a va_list, for other printf-style wrappers. */
void rp_vlogf(rp_log_fn log, void *ctx, const char *fmt, va_list ap);

#endif
