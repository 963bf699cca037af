/* Checkpoint files of long renders (radpt render --checkpoint / --resume).
 *
 * A checkpoint is a short text header, one "key value" line each, which
 * says what the state belongs to (scene hash, method, seed, image size,
 * bands) and what the run had done (steps, rays, seconds, ...), ended by an
 * empty line; then the solver's own binary record (rp_solver_save:
 * little-endian fields with a checksum).  Written atomically: PATH.tmp.PID,
 * then rename(2), so an interrupted write leaves the previous checkpoint. */
#ifndef RP_RESUME_H
#define RP_RESUME_H

#include <stddef.h>
#include <stdint.h>

#include "geometry/status.h"
#include "solvers/solver.h"

#define RP_RESUME_FORMAT 1

typedef struct rp_resume_info {
    /* what the state belongs to: checked on load */
    char scene_hash[17];
    char method[64];
    uint64_t seed;
    uint32_t width, height;  /* 0 x 0 without an image */
    size_t nbands;
    /* for people: the scene file and the method options the run was given */
    char scene[512];
    char options[1024];
    /* what the run had done: carried on by the resumed run */
    double steps, iterations, rays, paths, form_factors, seconds;
} rp_resume_info;

/* Writes info and the solver's state to path (atomically). */
rp_status rp_resume_save(const char *path, const rp_resume_info *info, const rp_solver *solver,
                         rp_error *err);

/* Reads path into *got and into solver (fresh from rp_solver_create), after
 * checking that the scene hash, method, seed, image size and bands match
 * *expect; *last gets what the solver reports for the loaded state
 * (rp_solver_load).  RP_ERR_INPUT, with a message that starts with path
 * and names what differs, for a mismatch, a truncated or corrupt file. */
rp_status rp_resume_load(const char *path, const rp_resume_info *expect, rp_resume_info *got,
                         rp_solver *solver, rp_step_info *last, rp_error *err);

#endif
