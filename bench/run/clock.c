/* Clocks and peak memory of runs (clock.h). */
#include "bench/run/clock.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

double rp_clock(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

double rp_cpu_clock(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int hwm_reset_ok = -1;

void rp_peak_rss_reset(void)
{
    FILE *f = fopen("/proc/self/clear_refs", "w");
    int ok = 0;
    if (f) {
        ok = fputs("5", f) >= 0;
        ok = (fclose(f) == 0) && ok;
    }
    hwm_reset_ok = ok;
}

double rp_peak_rss_mb(void)
{
    if (hwm_reset_ok == 1) {
        FILE *f = fopen("/proc/self/status", "r");
        char line[256];
        double kb = -1;
        while (f && fgets(line, sizeof line, f))
            if (strncmp(line, "VmHWM:", 6) == 0)
                kb = strtod(line + 6, NULL);
        if (f)
            fclose(f);
        if (kb >= 0)
            return kb / 1024.0;
    }
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return (double)ru.ru_maxrss / 1024.0; /* Linux: kilobytes */
}
