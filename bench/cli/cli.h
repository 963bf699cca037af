/* Command-line plumbing shared by the radpt subcommands: argument parsing,
 * usage errors, progress on stderr, JSON string output. */
#ifndef RP_CLI_H
#define RP_CLI_H

#include <stdint.h>
#include <stdio.h>

#include "geometry/scene.h"
#include "geometry/status.h"
#include "solvers/solver.h"
#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "bench/run/load.h"

#define RP_CLI_MAX_OPTIONS 64

typedef struct rp_cli {
    const char *command;
    const char *scene;         /* the positional argument */
    const char *method;
    const char *out;           /* -o */
    const char *png;           /* --png */
    const char *camera;        /* --camera "eye X Y Z look ... size W H" */
    uint64_t seed;
    int threads;
    double time_budget;        /* --time, seconds; 0 = none */
    int json;
    int quiet;                 /* --quiet: no progress or log lines */
    int surface_averages;
    /* method options, passed through to the solver */
    const char *keys[RP_CLI_MAX_OPTIONS];
    const char *values[RP_CLI_MAX_OPTIONS];
    size_t noptions;
    /* generic options a command accepts besides the method's, e.g. "from" */
    const char *extra_keys[RP_CLI_MAX_OPTIONS];
    const char *extra_values[RP_CLI_MAX_OPTIONS];
    size_t nextra;
} rp_cli;

/* Parses argv[2..] for a command.  allowed_extra lists extra "--name"
 * options (each taking a value) the command accepts, NULL-terminated.
 * On a usage error prints "radpt COMMAND: ..." and returns 2. */
int rp_cli_parse(rp_cli *cli, int argc, char **argv, const char *const *allowed_extra,
                 int wants_method);

/* An extra option's value or NULL. */
const char *rp_cli_extra(const rp_cli *cli, const char *name);

/* Routes SIGINT and SIGTERM to handler (which should only set a flag the
 * run loop polls, and the solver through rp_options.cancel), so long runs
 * stop within a second or so; a second signal ends the process at once. */
void rp_cli_catch_signals(void (*handler)(int));

/* 0 when the directory a file is to be written into (path's parent) exists
 * and is writable; otherwise prints "radpt COMMAND: OPTION PATH: ..." and
 * returns 2, so a long run is refused before it starts, not after. */
int rp_cli_check_output(const char *command, const char *option, const char *path);

/* Prints "radpt: message" for an error and returns its exit code. */
int rp_cli_fail(rp_status st, const rp_error *err);

/* Set by --quiet: progress bars and log lines are not shown (warnings and
 * errors still are). */
extern int rp_cli_quiet;

/* A log line on stderr (a newline is added), unless --quiet. */
void rp_cli_note(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

/* Progress on stderr, a bar only when stderr is a terminal. */
typedef struct rp_progress {
    int tty;
    double last;
    const char *label;
} rp_progress;
void rp_progress_begin(rp_progress *p, const char *label);
void rp_progress_update(rp_progress *p, double fraction, const char *detail);
void rp_progress_end(rp_progress *p);



/* A name as a text column shows it: as is when it is a plain word, else
 * in double quotes with \" and \\ escaped and control characters as \xHH
 * (names with spaces, quotes, '#' or nothing in them).  Into buf; returns
 * buf. */
const char *rp_cli_name(const char *name, char *buf, size_t len);

/* " --plugin PATH ..." for each plugin loaded from the command line (main
 * removes them from argv), so that commands a report prints can be rerun;
 * "" when none. */
void rp_cli_add_plugin(const char *path);
const char *rp_cli_plugins(void);

#endif
