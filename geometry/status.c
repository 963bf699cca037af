#include "status.h"

#include <stdarg.h>
#include <stdio.h>

rp_status rp_error_set(rp_error *err, rp_status status, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->message, sizeof err->message, fmt, ap);
        va_end(ap);
    }
    return status;
}

void rp_error_clear(rp_error *err)
{
    if (err)
        err->message[0] = '\0';
}

int rp_status_exit_code(rp_status status)
{
    switch (status) {
    case RP_OK: return 0;
    case RP_ERR_INPUT: return 2;
    default: return 1;
    }
}

const char *rp_status_string(rp_status status)
{
    switch (status) {
    case RP_OK: return "ok";
    case RP_ERR_INPUT: return "bad input";
    case RP_ERR_RUNTIME: return "runtime failure";
    case RP_ERR_NOMEM: return "out of memory";
    case RP_ERR_UNSUPPORTED: return "unsupported";
    case RP_ERR_INTERRUPTED: return "interrupted";
    }
    return "unknown status";
}
