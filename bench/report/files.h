/* Output files shared by bench/: directories, text files written
 * atomically, JSON string literals. */
#ifndef RP_FILES_H
#define RP_FILES_H

#include <stddef.h>
#include <stdio.h>

#include "geometry/status.h"

/* mkdir -p. */
rp_status rp_mkdirs(const char *path, rp_error *err);

/* on: every file written through rp_temp_open and rp_out goes to /dev/null
 * and rp_mkdirs makes nothing (MPI ranks other than 0, bench/run/mpi.h). */
void rp_files_discard(int on);
int rp_files_discarding(void);
/* Also goes to /dev/null: every file written under dir (NULL: none), as
 * in the hand-out pass of rp_experiment_run, which writes nothing into the
 * study's directory while files elsewhere (the reference cache) are
 * written as usual.  rp_files_discarded: 1 when a file written to path
 * goes to /dev/null. */
void rp_files_discard_under(const char *dir);
/* on: files are written even on a discarding rank (rp_files_discard), for
 * the records a rank keeps of its own work (journal.h) until it is off. */
void rp_files_own(int on);
int rp_files_discarded(const char *path);

/* The one atomic file writer of radpt: a fresh PATH.tmp.PID.N (O_EXCL),
 * written, flushed to disk (fsync), closed and renamed over PATH; any
 * failure removes the temporary file, so PATH is either the old file or
 * the whole new one.  rp_temp_commit and rp_temp_discard free tmp. */
rp_status rp_temp_open(const char *path, int *fd, char **tmp, rp_error *err);
rp_status rp_temp_commit(int fd, char *tmp, const char *path, rp_error *err);
void rp_temp_discard(int fd, char *tmp);

/* A text file through that writer: rp_out_open opens the temporary file as
 * a stream, and rp_out_close commits it (or removes it when ok is 0 or a
 * write failed). */
typedef struct rp_out {
    FILE *f;
    char path[1024];
    char tmp[1100];
} rp_out;
rp_status rp_out_open(rp_out *o, const char *path, rp_error *err);
rp_status rp_out_close(rp_out *o, int ok, rp_error *err);

/* Joins dir and name into buf. */
const char *rp_path_join(char *buf, size_t n, const char *dir, const char *name);

/* Writes s as a JSON string literal (with quotes). */
void rp_json_string(FILE *f, const char *s);

#endif
