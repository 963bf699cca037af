/* Log lines (log.h). */
#include "log.h"

#include <stdarg.h>
#include <stdio.h>

void rp_vlogf(void (*log)(void *ctx, const char *message), void *ctx, const char *fmt, va_list ap)
{
    if (!log)
        return;
    char msg[1400];
    vsnprintf(msg, sizeof msg, fmt, ap);
    log(ctx, msg);
}

void rp_logf(void (*log)(void *ctx, const char *message), void *ctx, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    rp_vlogf(log, ctx, fmt, ap);
    va_end(ap);
}
