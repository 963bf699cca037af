#include "bench/cli/cli.h"

#include "geometry/default_camera.h"

#include <errno.h>
#include <stdarg.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>


static int usage(const rp_cli *cli, const char *fmt, const char *a)
{
    fprintf(stderr, "radpt %s: ", cli->command);
    fprintf(stderr, fmt, a);
    fprintf(stderr, " (see radpt help)\n");
    return 2;
}

static int parse_u64(const char *s, uint64_t *out)
{
    char *end;
    errno = 0;
    if (*s == '-')
        return -1;
    unsigned long long v = strtoull(s, &end, 0);
    if (end == s || *end || errno)
        return -1;
    *out = v;
    return 0;
}

/* The generic options each command takes (besides its own extras and its
 * method's options); any other generic option is refused, not ignored. */
static const struct {
    const char *command;
    const char *takes; /* space-separated, "o" for -o */
} generic_options[] = {
    {"info", "json camera quiet"},
    {"render", "method o png camera seed threads time quiet"},
    {"probe", "method surface-averages json camera seed threads time quiet"},
    {"reference", "json camera seed threads quiet"},
    {"bench", "o camera seed threads time quiet"},
    {"experiment", "o threads quiet"},
    {"throughput", "json camera seed threads quiet"},
    {"samplers", "json camera seed threads quiet"},
};

/* 1 when command takes the generic option name (commands not in the
 * table take them all). */
static int takes_generic(const char *command, const char *name)
{
    for (size_t i = 0; i < sizeof generic_options / sizeof generic_options[0]; i++)
        if (strcmp(generic_options[i].command, command) == 0) {
            const char *t = generic_options[i].takes;
            size_t n = strlen(name);
            for (const char *w = t; *w;) {
                size_t len = strcspn(w, " ");
                if (len == n && strncmp(w, name, n) == 0)
                    return 1;
                w += len;
                while (*w == ' ')
                    w++;
            }
            return 0;
        }
    return 1;
}

static int not_applicable(const rp_cli *cli, const char *option, const char *const *extra)
{
    const char *takes = "";
    for (size_t i = 0; i < sizeof generic_options / sizeof generic_options[0]; i++)
        if (strcmp(generic_options[i].command, cli->command) == 0)
            takes = generic_options[i].takes;
    fprintf(stderr, "radpt %s: %s does not apply to %s (its common options:", cli->command, option, cli->command);
    for (const char *w = takes; *w;) {
        size_t len = strcspn(w, " ");
        fprintf(stderr, " %s%.*s", len == 1 ? "-" : "--", (int)len, w);
        w += len;
        while (*w == ' ')
            w++;
    }
    if (extra && *extra) {
        fprintf(stderr, "; its own:");
        for (const char *const *e = extra; *e; e++)
            fprintf(stderr, " --%s", *e);
    }
    fprintf(stderr, "; see radpt --help)\n");
    return 2;
}

int rp_cli_quiet;

void rp_cli_note(const char *fmt, ...)
{
    if (rp_cli_quiet)
        return;
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static const rp_option_spec *method_option(const rp_solver_type *t, const char *name)
{
    for (const rp_option_spec *o = t ? t->options : NULL; o && o->name; o++)
        if (strcmp(o->name, name) == 0)
            return o;
    return NULL;
}

int rp_cli_parse(rp_cli *cli, int argc, char **argv, const char *const *allowed_extra,
                 int wants_method)
{
    const char *command = cli->command;
    memset(cli, 0, sizeof *cli);
    cli->command = command;
    cli->seed = 1;

    /* The method decides which options are flags: find it first. */
    const rp_solver_type *type = NULL;
    for (int i = 2; i < argc; i++) {
        if (strcmp(argv[i], "--method") == 0 && i + 1 < argc)
            cli->method = argv[i + 1];
        else if (strncmp(argv[i], "--method=", 9) == 0)
            cli->method = argv[i] + 9;
    }
    if (cli->method) {
        if (!wants_method)
            return usage(cli, "takes no --method%s", "");
        type = rp_solver_lookup(cli->method);
        if (!type) {
            fprintf(stderr, "radpt %s: unknown method '%s'; known methods:", command, cli->method);
            for (const rp_solver_type *const *t = rp_solver_types(); *t; t++)
                fprintf(stderr, " %s", (*t)->name);
            fprintf(stderr, "\n");
            return 2;
        }
    }

    for (int i = 2; i < argc; i++) {
        char *a = argv[i];
        if (a[0] != '-' || a[1] == '\0') {
            if (cli->scene)
                return usage(cli, "unexpected argument '%s'", a);
            cli->scene = a;
            continue;
        }
        if (strcmp(a, "-o") == 0) {
            if (!takes_generic(command, "o"))
                return not_applicable(cli, "-o", allowed_extra);
            if (i + 1 >= argc)
                return usage(cli, "-o needs a file name%s", "");
            cli->out = argv[++i];
            continue;
        }
        if (strncmp(a, "--", 2) != 0)
            return usage(cli, "unknown option '%s'", a);
        /* --name value or --name=value */
        char name[64];
        const char *value = NULL;
        const char *eq = strchr(a + 2, '=');
        size_t len = eq ? (size_t)(eq - (a + 2)) : strlen(a + 2);
        if (len == 0 || len >= sizeof name)
            return usage(cli, "bad option '%s'", a);
        memcpy(name, a + 2, len);
        name[len] = '\0';

        int is_flag = strcmp(name, "json") == 0 || strcmp(name, "surface-averages") == 0 ||
                      strcmp(name, "quiet") == 0;
        const rp_option_spec *spec = method_option(type, name);
        if (spec && !spec->arg)
            is_flag = 1;
        int extra = 0;
        for (const char *const *e = allowed_extra; e && *e; e++)
            extra |= strcmp(*e, name) == 0;
        int generic = !spec && !extra &&
                      (!strcmp(name, "json") || !strcmp(name, "surface-averages") || !strcmp(name, "quiet") ||
                       !strcmp(name, "method") || !strcmp(name, "png") || !strcmp(name, "camera") ||
                       !strcmp(name, "seed") || !strcmp(name, "threads") || !strcmp(name, "time"));
        if (generic && !takes_generic(command, name)) {
            char opt[80];
            snprintf(opt, sizeof opt, "--%s", name);
            return not_applicable(cli, opt, allowed_extra);
        }
        int known = is_flag || spec || generic || extra;
        if (!known) {
            if (type)
                fprintf(stderr, "radpt %s: method %s has no option '--%s' (see radpt help %s)\n", command,
                        type->name, name, type->name);
            else
                fprintf(stderr, "radpt %s: unknown option '--%s' (see radpt help)\n", command, name);
            return 2;
        }
        if (is_flag) {
            if (eq)
                return usage(cli, "option '--%s' takes no value", name);
            value = "1";
        } else if (eq) {
            value = eq + 1;
        } else {
            /* "--spp -o x": the next word is an option, not this one's value
             * (negative numbers still pass, to be refused by range checks). */
            if (i + 1 >= argc || !strcmp(argv[i + 1], "-o") || !strncmp(argv[i + 1], "--", 2))
                return usage(cli, "option '--%s' needs a value", name);
            value = argv[++i];
        }

        if (strcmp(name, "method") == 0) {
            /* found in the first pass */
        } else if (strcmp(name, "json") == 0) {
            cli->json = 1;
        } else if (strcmp(name, "quiet") == 0) {
            cli->quiet = 1;
            rp_cli_quiet = 1;
        } else if (strcmp(name, "surface-averages") == 0) {
            cli->surface_averages = 1;
        } else if (strcmp(name, "png") == 0) {
            cli->png = value;
        } else if (strcmp(name, "camera") == 0) {
            cli->camera = value;
        } else if (strcmp(name, "seed") == 0) {
            if (parse_u64(value, &cli->seed))
                return usage(cli, "--seed: '%s' is not a non-negative integer", value);
        } else if (strcmp(name, "threads") == 0) {
            uint64_t t;
            if (parse_u64(value, &t) || t < 1 || t > 1024)
                return usage(cli, "--threads: '%s' is not a thread count in [1, 1024]", value);
            cli->threads = (int)t;
        } else if (strcmp(name, "time") == 0) {
            char *end;
            double t = strtod(value, &end);
            if (end == value || *end || !isfinite(t) || t <= 0)
                return usage(cli, "--time: '%s' is not a positive number of seconds", value);
            cli->time_budget = t;
        } else if (spec) {
            if (cli->noptions == RP_CLI_MAX_OPTIONS)
                return usage(cli, "too many options%s", "");
            cli->keys[cli->noptions] = spec->name;
            cli->values[cli->noptions++] = value;
        } else {
            if (cli->nextra == RP_CLI_MAX_OPTIONS)
                return usage(cli, "too many options%s", "");
            /* keep the static name from allowed_extra, not the stack copy */
            for (const char *const *e = allowed_extra; *e; e++)
                if (strcmp(*e, name) == 0)
                    cli->extra_keys[cli->nextra] = *e;
            cli->extra_values[cli->nextra++] = value;
        }
    }
    if (!cli->scene && strcmp(command, "experiment") == 0) {
        fprintf(stderr, "radpt experiment: needs an experiment NAME (radpt experiment --list shows them)\n");
        return 2;
    }
    if (!cli->scene)
        return usage(cli, "needs a scene file%s", "");
    if (wants_method && !cli->method)
        return usage(cli, "needs --method M%s", "");
    return 0;
}

const char *rp_cli_extra(const rp_cli *cli, const char *name)
{
    const char *v = NULL;
    for (size_t i = 0; i < cli->nextra; i++)
        if (strcmp(cli->extra_keys[i], name) == 0)
            v = cli->extra_values[i];
    return v;
}

int rp_cli_fail(rp_status st, const rp_error *err)
{
    fprintf(stderr, "radpt: %s\n", err && err->message[0] ? err->message : rp_status_string(st));
    return rp_status_exit_code(st);
}

void rp_progress_begin(rp_progress *p, const char *label)
{
    p->tty = isatty(STDERR_FILENO);
    p->last = -1;
    p->label = label;
}

void rp_progress_update(rp_progress *p, double fraction, const char *detail)
{
    if (!p->tty || rp_cli_quiet)
        return;
    double now = rp_clock();
    if (now - p->last < 0.1 && fraction < 1)
        return;
    p->last = now;
    if (fraction < 0)
        fraction = 0;
    if (fraction > 1)
        fraction = 1;
    int width = 30, filled = (int)(fraction * width + 0.5);
    fprintf(stderr, "\r%s [", p->label);
    for (int i = 0; i < width; i++)
        fputc(i < filled ? '#' : '.', stderr);
    fprintf(stderr, "] %3.0f%% %s\033[K", 100 * fraction, detail ? detail : "");
    fflush(stderr);
}

void rp_progress_end(rp_progress *p)
{
    if (p->tty && p->last >= 0 && !rp_cli_quiet)
        fputc('\n', stderr);
}


int rp_cli_check_output(const char *command, const char *option, const char *path)
{
    if (!path)
        return 0;
    char dir[4096];
    const char *slash = strrchr(path, '/');
    if (!slash)
        snprintf(dir, sizeof dir, ".");
    else if (slash == path)
        snprintf(dir, sizeof dir, "/");
    else
        snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path);
    struct stat st;
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        fprintf(stderr, "radpt %s: %s %s: directory '%s' does not exist (create it first)\n", command, option,
                path, dir);
        return 2;
    }
    if (access(dir, W_OK) != 0) {
        fprintf(stderr, "radpt %s: %s %s: directory '%s' is not writable\n", command, option, path, dir);
        return 2;
    }
    /* refused now, not after the run when the file is renamed into place */
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) {
        fprintf(stderr, "radpt %s: %s %s: is a directory, not a file name\n", command, option, path);
        return 2;
    }
    return 0;
}

void rp_cli_catch_signals(void (*handler)(int))
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = handler;
    /* once: a second signal ends the process at once (files are written
     * to a temporary name and renamed, so none is left half written) */
    sa.sa_flags = SA_RESETHAND;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}


const char *rp_cli_name(const char *name, char *buf, size_t len)
{
    int plain = name[0] != '\0';
    for (const unsigned char *c = (const unsigned char *)name; *c && plain; c++)
        plain = *c > ' ' && *c != '"' && *c != '\\' && *c != '#' && *c != 0x7f;
    if (plain) {
        snprintf(buf, len, "%s", name);
        return buf;
    }
    size_t n = 0;
    if (len < 3) {
        if (len)
            buf[0] = '\0';
        return buf;
    }
    buf[n++] = '"';
    for (const unsigned char *c = (const unsigned char *)name; *c && n + 5 < len; c++) {
        if (*c == '"' || *c == '\\') {
            buf[n++] = '\\';
            buf[n++] = (char)*c;
        } else if (*c < ' ' || *c == 0x7f) {
            n += (size_t)snprintf(buf + n, len - n, "\\x%02x", *c);
        } else {
            buf[n++] = (char)*c;
        }
    }
    buf[n++] = '"';
    buf[n] = '\0';
    return buf;
}

static char plugin_args[4096];

void rp_cli_add_plugin(const char *path)
{
    size_t used = strlen(plugin_args);
    snprintf(plugin_args + used, sizeof plugin_args - used, " --plugin %s", path);
}

const char *rp_cli_plugins(void)
{
    return plugin_args;
}
