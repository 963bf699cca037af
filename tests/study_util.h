/* Comparing a study's output with another run's (tests of experiments
 * under mpirun and resumed from a journal): criterion assertions inside. */
#ifndef RP_TEST_STUDY_UTIL_H
#define RP_TEST_STUDY_UTIL_H

#include <stddef.h>

#include "cli_util.h"

/* Every CSV of directory a equals b's in its computed columns (all but
 * times, rank, threads and memory; reflectance.csv, whose furnace runs
 * race a clock, is skipped), b's name read as a's in messages, so the
 * two names have the same length; returns how many CSVs were compared. */
int rp_study_same_tables(const char *a, const char *b, const char *what);

/* "this rank computed M of N units" from rank 0's log: M, and N in *n. */
long rp_study_computed_units(const rp_run *r, long *n);

/* Makes directory dir (or uses an existing one) holding the journal an interruption after keep
 * units would have left of the study in from. */
void rp_study_cut_journal(const char *from, const char *dir, size_t keep);

#endif
