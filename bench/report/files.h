/* Output files shared by bench/: directories, text files written
 * atomically, JSON string literals. */
#ifndef RP_FILES_H
#define RP_FILES_H

#include <stddef.h>
#include <stdio.h>

#include "geometry/status.h"

/* mkdir -p. */
rp_status rp_mkdirs(const char *path, rp_error *err);

/* A text file written atomically: rp_out_open makes PATH.tmp.PID, and
 * rp_out_close renames it over PATH (or removes it when ok is 0 or a write
 * failed). */
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
