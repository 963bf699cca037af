/* Clocks and peak memory of runs.
 *
 * Wall time is CLOCK_MONOTONIC; CPU time is CLOCK_PROCESS_CPUTIME_ID (all
 * threads).  Peak memory: rp_peak_rss_reset clears the kernel's high-water
 * mark (Linux /proc/self/clear_refs, "5") so that rp_peak_rss_mb reads this
 * run's peak (VmHWM); where the reset is not possible, getrusage's
 * ru_maxrss, the process's lifetime peak. */
#ifndef RP_CLOCK_H
#define RP_CLOCK_H

/* Monotonic wall clock, seconds. */
double rp_clock(void);
/* CPU time of the process, all threads, seconds. */
double rp_cpu_clock(void);
void rp_peak_rss_reset(void);
double rp_peak_rss_mb(void);

#endif
