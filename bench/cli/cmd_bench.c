/* radpt reference, radpt bench and radpt experiment: the benchmark front.
 *
 *   radpt reference SCENE [--spp N] [--samples N] [--seed S] [--cache DIR]
 *                   [--threads T] [--force] [--json]
 *                   [--checkpoint FILE [--checkpoint-every SECONDS]] [--resume FILE]
 *   radpt bench SCENE [--methods LIST] [--budget SECONDS] -o DIR [--seeds N]
 *               [--checkpoints N] [--target RMSE] [--surfaces] [--cache DIR]
 *               [--reference-spp N] [--reference-samples N] [--seed S] [--threads T]
 *   radpt experiment NAME [--quick] -o DIR [--budget SECONDS] [--seeds N]
 *               [--cache DIR] [--scenes DIR] [--threads T]
 *
 * Progress and log lines go to stderr; the result's location to stdout. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/scene.h"
#include "bench/cli/cli.h"
#include "bench/experiments/experiments.h"
#include "bench/run/harness.h"
#include "bench/report/image.h"
#include "bench/report/plot.h"
#include "bench/run/reference.h"

#define BENCH_DEFAULT_METHODS "pathtrace,southwell:elements=250,southwell:elements=1000"
#define BENCH_DEFAULT_BUDGET 10.0

/* Log lines on stderr; a progress bar in between when stderr is a tty. */
typedef struct front {
    rp_progress bar;
    int bar_open;
} front;

static void front_log(void *ctx, const char *msg)
{
    front *fr = ctx;
    if (fr && fr->bar_open) {
        rp_progress_end(&fr->bar);
        fr->bar_open = 0;
    }
    rp_cli_note("%s", msg);
}

static void front_progress(void *ctx, double fraction, const char *detail)
{
    front *fr = ctx;
    if (!fr->bar_open) {
        rp_progress_begin(&fr->bar, "");
        fr->bar_open = 1;
    }
    rp_progress_update(&fr->bar, fraction, detail);
}

static void front_done(front *fr)
{
    if (fr->bar_open)
        rp_progress_end(&fr->bar);
    fr->bar_open = 0;
}

/* Removes the flags rp_cli_parse cannot take (it gives every extra option
 * a value) from argv; *found[i] is set for flags[i]. */
static int strip_flags(int argc, char **argv, char **out, const char *const *flags, int *found)
{
    int n = 0;
    for (int i = 0; i < argc; i++) {
        int hit = 0;
        for (int k = 0; flags[k]; k++)
            if (i >= 2 && strcmp(argv[i], flags[k]) == 0) {
                found[k] = 1;
                hit = 1;
            }
        if (!hit)
            out[n++] = argv[i];
    }
    out[n] = NULL;
    return n;
}

static int seed_given(int argc, char **argv)
{
    for (int i = 2; i < argc; i++)
        if (strcmp(argv[i], "--seed") == 0 || strncmp(argv[i], "--seed=", 7) == 0)
            return 1;
    return 0;
}

static int parse_ulong(const rp_cli *cli, const char *name, unsigned long lo, unsigned long hi, unsigned long *out)
{
    const char *v = rp_cli_extra(cli, name);
    if (!v)
        return 0;
    char *end;
    errno = 0;
    unsigned long x = strtoul(v, &end, 10);
    if (*v == '-' || end == v || *end || errno || x < lo || x > hi) {
        fprintf(stderr, "radpt %s: --%s: '%s' is not a whole number in [%lu, %lu] (see radpt help)\n", cli->command,
                name, v, lo, hi);
        return 2;
    }
    *out = x;
    return 0;
}

static int parse_positive(const rp_cli *cli, const char *name, double *out)
{
    const char *v = rp_cli_extra(cli, name);
    if (!v)
        return 0;
    char *end;
    double x = strtod(v, &end);
    if (end == v || *end || !isfinite(x) || !(x > 0)) {
        fprintf(stderr, "radpt %s: --%s: '%s' is not a positive number (see radpt help)\n", cli->command, name, v);
        return 2;
    }
    *out = x;
    return 0;
}

/* --exposure EV (image.h) for the PNGs a command writes; 0 when absent. */
static int parse_exposure(const rp_cli *cli, rp_exposure *out)
{
    *out = rp_exposure_fixed(0);
    const char *v = rp_cli_extra(cli, "exposure");
    rp_error e;
    if (v && rp_exposure_parse(v, out, &e) != RP_OK) {
        fprintf(stderr, "radpt %s: %s (see radpt help)\n", cli->command, e.message);
        return 2;
    }
    return 0;
}

static void command_line(int argc, char **argv, char *buf, size_t n)
{
    size_t used = 0;
    buf[0] = '\0';
    for (int i = 0; i < argc && used < n; i++)
        used += (size_t)snprintf(buf + used, n - used, "%s%s", i ? " " : "", i == 0 ? "radpt" : argv[i]);
    if (used < n)
        snprintf(buf + used, n - used, "%s", rp_cli_plugins()); /* main took them out of argv */
}

/* ------------------------------------------------------------- studies */

/* SIGINT / SIGTERM during bench or experiment: the flag goes to the run in
 * progress (rp_options.cancel), which stops within a second or so; the
 * finished runs are already recorded in DIR/journal.txt, and the outputs
 * are written from them, marked incomplete.  A second signal ends the
 * process at once (files are written to a temporary name and renamed). */
static atomic_int study_cancel;
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the signal flag must be a lock-free atomic");

static void on_study_signal(int sig)
{
    (void)sig;
    atomic_store_explicit(&study_cancel, 1, memory_order_relaxed);
}

/* -o DIR starts a study, --resume DIR continues one: the directory and
 * whether it resumes (exit 2 on a usage error). */
static int study_dir(const rp_cli *cli, const char **dir, int *resume)
{
    const char *r = rp_cli_extra(cli, "resume");
    *resume = r != NULL;
    *dir = r ? r : cli->out;
    if (r && cli->out && strcmp(r, cli->out) != 0) {
        fprintf(stderr, "radpt %s: -o %s and --resume %s name two directories; --resume DIR alone continues the "
                        "study in DIR\n", cli->command, cli->out, r);
        return 2;
    }
    if (!*dir) {
        fprintf(stderr, "radpt %s: needs -o DIR (or --resume DIR to continue an interrupted study; see radpt help)\n",
                cli->command);
        return 2;
    }
    return 0;
}

/* The command line with --resume DIR in place of -o DIR, for the hint. */
static void resume_hint(int argc, char **argv, const char *dir, char *buf, size_t n)
{
    size_t used = 0;
    buf[0] = '\0';
    int has_resume = 0;
    for (int i = 1; i < argc; i++)
        has_resume |= strcmp(argv[i], "--resume") == 0;
    for (int i = 0; i < argc && used < n; i++) {
        if (strcmp(argv[i], "-o") == 0 && i + 1 < argc) {
            if (!has_resume)
                used += (size_t)snprintf(buf + used, n - used, " --resume %s", dir);
            i++;
            continue;
        }
        /* argv[0] as typed: ./radpt from a clone, radpt once installed */
        used += (size_t)snprintf(buf + used, n - used, "%s%s", i ? " " : "", argv[i]);
    }
}

/* The end of `radpt bench` on stdout, as hyperfine ends: per method its
 * final RMSE (mean +- sd over seeds), surface error, solver time, and its
 * time to the target RMSE against the slowest's; from the summaries
 * report.md prints (nothing computed twice). */
static void print_summary_table(const rp_bench *b)
{
    double slowest = 0;
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        double t = b->summary[mi].time_to_target;
        if (isfinite(t) && t > slowest)
            slowest = t;
    }
    size_t w = 6;
    for (size_t mi = 0; mi < b->nmethods; mi++)
        w = strlen(b->methods[mi].text) > w ? strlen(b->methods[mi].text) : w;
    if (w > 48)
        w = 48;
    printf("\n%-*s  %-22s  %-13s  %-9s  %s\n", (int)w, "method", "final RMSE (mean +- sd)", "surface error",
           "time (s)", isfinite(b->target) ? "time to target" : "");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        const rp_agg *a = &s->final;
        char rmse[64] = "n/a", surf[32] = "n/a", ttt[64] = "not reached";
        if (s->runs_ok && isfinite(a->rmse))
            snprintf(rmse, sizeof rmse, "%.4g +- %.2g", a->rmse, isfinite(a->rmse_sd) ? a->rmse_sd : 0.0);
        if (s->runs_ok && isfinite(a->surface_err))
            snprintf(surf, sizeof surf, "%.3g%%", 100 * a->surface_err);
        if (isfinite(s->time_to_target))
            snprintf(ttt, sizeof ttt, s->time_to_target >= slowest ? "%.3g s (the slowest)" : "%.3g s (%.2fx faster "
                     "than the slowest)", s->time_to_target, s->time_to_target > 0 ? slowest / s->time_to_target : 1.0);
        if (!isfinite(b->target))
            ttt[0] = '\0';
        printf("%-*.*s  %-22s  %-13s  %-9.3g  %s\n", (int)w, (int)w, b->methods[mi].text, rmse, surf,
               s->runs_ok ? a->wall_s : 0.0, ttt);
    }
    if (isfinite(b->target))
        printf("target RMSE %.4g (%s)\n", b->target, b->target_auto ? "automatic: the geometric mean of the best "
                                                                       "and worst final RMSE" : "--target");
    /* An RMSE measured against a path-traced reference is, in the mean,
     * sqrt(error^2 + the reference's own noise^2): a target at or below
     * that noise is out of reach whatever a method does (the Cornell box's
     * 2,048-spp reference: 0.00136). */
    if (isfinite(b->target) && b->ref && b->ref->rmse_se > 0 && b->target <= b->ref->rmse_se)
        printf("note: the target is at or below the reference's own noise (RMSE standard error %.3g): measured "
               "against this reference no run can be expected to reach it; report.md's debiased RMSE estimates the "
               "error against the truth, and a longer reference (--reference-spp N) has less noise\n",
               b->ref->rmse_se);
}

/* Copies DIR/NAME to path (atomically), for --export-json / --export-csv. */
static rp_status export_copy(const char *dir, const char *name, const char *path, rp_error *err)
{
    char src[1200];
    rp_path_join(src, sizeof src, dir, name);
    FILE *in = fopen(src, "rb");
    if (!in)
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot read", src);
    rp_out o;
    rp_status st = rp_out_open(&o, path, err);
    char buf[65536];
    size_t n;
    int ok = 1;
    while (st == RP_OK && (n = fread(buf, 1, sizeof buf, in)) > 0)
        ok &= fwrite(buf, 1, n, o.f) == n;
    fclose(in);
    if (st == RP_OK)
        st = rp_out_close(&o, ok, err);
    return st;
}

typedef struct bench_sink {
    const char *dir;
} bench_sink;

/* After each finished run: DIR/runs.csv holds every finished run. */
static void on_bench_run(void *ctx, const rp_bench *b)
{
    const bench_sink *s = ctx;
    rp_error e;
    if (rp_bench_write_runs_csv(b, s->dir, &e) != RP_OK)
        fprintf(stderr, "radpt: warning: %s\n", e.message);
}

/* ------------------------------------------------------------ reference */

/* radpt reference --checkpoint: SIGINT / SIGTERM stop the render at the
 * next step with its state saved. */
static volatile sig_atomic_t reference_stop;

static void on_reference_signal(int sig)
{
    (void)sig;
    reference_stop = 1;
}

int rp_cmd_reference(int argc, char **argv)
{
    static const char *const extra[] = {"spp", "samples", "cache", "checkpoint", "checkpoint-every", "resume", NULL};
    static const char *const flags[] = {"--force", NULL};
    int found[1] = {0};
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av)
        return 1;
    int ac = strip_flags(argc, argv, av, flags, found);
    rp_cli cli = {.command = "reference"};
    int rc = rp_cli_parse(&cli, ac, av, extra, 0);
    unsigned long spp = 0, samples = 0;
    if (!rc)
        rc = parse_ulong(&cli, "spp", 1, 1ul << 30, &spp);
    if (!rc)
        rc = parse_ulong(&cli, "samples", 1, 1ul << 40, &samples);
    double every = 60;
    if (!rc)
        rc = parse_positive(&cli, "checkpoint-every", &every);
    if (!rc && rp_cli_extra(&cli, "checkpoint-every") && !rp_cli_extra(&cli, "checkpoint")) {
        fprintf(stderr, "radpt reference: --checkpoint-every needs --checkpoint FILE (see radpt help)\n");
        rc = 2;
    }
    if (!rc)
        rc = rp_cli_check_output("reference", "--checkpoint", rp_cli_extra(&cli, "checkpoint"));
    if (rc) {
        free(av);
        return rc;
    }
    if (rp_cli_extra(&cli, "checkpoint"))
        rp_cli_catch_signals(on_reference_signal);
    front fr = {0};
    rp_reference_params rp = {.size = sizeof rp, .spp = spp, .samples = samples,
                              .seed = seed_given(ac, av) ? cli.seed : 0, .threads = cli.threads,
                              .cache_dir = rp_cli_extra(&cli, "cache"), .force = found[0],
                              .log = front_log, .log_ctx = &fr, .progress = front_progress, .progress_ctx = &fr,
                              .checkpoint = rp_cli_extra(&cli, "checkpoint"), .checkpoint_every = every,
                              .resume = rp_cli_extra(&cli, "resume"), .stop = &reference_stop};
    rp_error err;
    rp_scene *scene = NULL;
    rp_reference *ref = NULL;
    rp_status st = rp_load_scene(cli.scene, cli.camera, 1, &scene, &err);
    if (st == RP_OK && rp.seed == 0 && seed_given(ac, av))
        st = rp_error_set(&err, RP_ERR_INPUT, "--seed 0 is not allowed for a reference");
    if (st == RP_OK)
        st = rp_reference_get(scene, cli.scene, &rp, &ref, &err);
    front_done(&fr);
    if (st == RP_OK) {
        const rp_surface *surf = rp_scene_surfaces(scene);
        size_t nb = ref->nbands;
        if (cli.json) {
            printf("{\"scene\": ");
            rp_json_string(stdout, cli.scene);
            printf(", \"scene_hash\": \"%s\", \"options_hash\": \"%s\", \"kind\": \"%s\", \"cached\": %s, \"image\": ",
                   ref->scene_hash, ref->options_hash, ref->kind == RP_REFERENCE_EXACT ? "exact" : "pathtrace",
                   ref->cached ? "true" : "false");
            rp_json_string(stdout, ref->exr_path);
            printf(", \"json\": ");
            rp_json_string(stdout, ref->json_path);
            printf(", \"spp\": %lu, \"samples\": %lu, \"seed\": %" PRIu64 ", \"seconds\": %.3f, \"rmse_stderr\": ",
                   ref->spp, ref->samples, ref->seed, ref->seconds);
            if (isfinite(ref->rmse_se))
                printf("%.6g", ref->rmse_se);
            else
                printf("null");
            printf(", \"measured_pixels\": %zu, \"surfaces\": [", ref->mask_count);
            for (size_t s = 0; s < ref->nsurfaces; s++) {
                printf("%s{\"name\": ", s ? ", " : "");
                rp_json_string(stdout, surf[s].name);
                printf(", \"radiance\": [");
                for (size_t b = 0; b < nb; b++)
                    printf("%s%.10g", b ? ", " : "", ref->surface_radiance[s * nb + b]);
                printf("], \"stderr\": [");
                for (size_t b = 0; b < nb; b++)
                    printf("%s%.4g", b ? ", " : "", ref->surface_stderr[s * nb + b]);
                printf("]}");
            }
            printf("]}\n");
        } else {
            if (ref->kind == RP_REFERENCE_EXACT)
                printf("reference %s: exact (furnace, L = Le / (1 - rho) = %.10g in band 0)%s\n", ref->exr_path,
                       ref->exact_L[0], ref->cached ? ", cached" : "");
            else
                printf("reference %s: pathtrace, sobol, %lu spp, %lu samples per surface, seed %" PRIu64
                       ", %.1f s%s; RMSE standard error %.3g\n",
                       ref->exr_path, ref->spp, ref->samples, ref->seed, ref->seconds,
                       ref->cached ? ", cached" : "", ref->rmse_se);
            printf("parameters and surface averages: %s\n", ref->json_path);
            printf("%-20s  radiance per band +- standard error\n", "surface");
            for (size_t s = 0; s < ref->nsurfaces; s++) {
                char nm[512];
                printf("%-20s ", rp_cli_name(surf[s].name, nm, sizeof nm));
                for (size_t b = 0; b < nb; b++)
                    printf(" %.6g +- %.2g", ref->surface_radiance[s * nb + b], ref->surface_stderr[s * nb + b]);
                printf("\n");
            }
        }
    }
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    free(av);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}

/* ---------------------------------------------------------------- bench */

int rp_cmd_bench(int argc, char **argv)
{
    static const char *const extra[] = {"methods", "budget", "iterations", "seeds", "checkpoints", "target",
                                        "cache", "reference-spp", "reference-samples", "exposure", "resume",
                                        "export-json", "export-csv", NULL};
    static const char *const flags[] = {"--surfaces", NULL};
    int found[1] = {0};
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av)
        return 1;
    int ac = strip_flags(argc, argv, av, flags, found);
    rp_cli cli = {.command = "bench"};
    int rc = rp_cli_parse(&cli, ac, av, extra, 0);
    unsigned long seeds = 3, levels = 9, ref_spp = 0, ref_samples = 0;
    double budget = BENCH_DEFAULT_BUDGET, target = 0;
    if (!rc)
        rc = parse_ulong(&cli, "seeds", 1, 1000, &seeds);
    if (!rc)
        rc = parse_ulong(&cli, "checkpoints", 1, 40, &levels);
    if (!rc)
        rc = parse_ulong(&cli, "reference-spp", 1, 1ul << 30, &ref_spp);
    if (!rc)
        rc = parse_ulong(&cli, "reference-samples", 1, 1ul << 40, &ref_samples);
    if (!rc)
        rc = parse_positive(&cli, "budget", &budget);
    if (!rc)
        rc = parse_positive(&cli, "target", &target);
    /* --iterations N: the budget in the methods' iterations, so that the
     * work done (every column but times and memory) is the same on any
     * machine, rank count or load */
    double iterations = 0;
    if (!rc)
        rc = parse_positive(&cli, "iterations", &iterations);
    if (!rc && iterations > 0 && (rp_cli_extra(&cli, "budget") || cli.time_budget > 0)) {
        fprintf(stderr, "radpt bench: --iterations and --budget (or --time) exclude each other (see radpt help)\n");
        rc = 2;
    }
    rp_exposure exposure;
    if (!rc)
        rc = parse_exposure(&cli, &exposure);
    if (!rc && cli.time_budget > 0)
        budget = cli.time_budget; /* --time works as --budget */
    if (iterations > 0)
        budget = iterations;
    const char *dir = NULL;
    int resume = 0;
    if (!rc)
        rc = study_dir(&cli, &dir, &resume);
    if (!rc)
        rc = rp_cli_check_output("bench", "--export-json", rp_cli_extra(&cli, "export-json"));
    if (!rc)
        rc = rp_cli_check_output("bench", "--export-csv", rp_cli_extra(&cli, "export-csv"));
    if (!rc && cli.seed == 0) {
        fprintf(stderr, "radpt bench: --seed must be at least 1 (see radpt help)\n");
        rc = 2;
    }
    if (rc) {
        free(av);
        return rc;
    }
    const char *list = rp_cli_extra(&cli, "methods");
    if (!list)
        list = BENCH_DEFAULT_METHODS;
    rp_error err;
    rp_method_spec *methods = NULL;
    size_t nmethods = 0;
    rp_status st = rp_method_list_parse(list, &methods, &nmethods, &err);
    if (st != RP_OK) {
        fprintf(stderr, "radpt bench: --methods: %s\n", err.message);
        free(av);
        return 2;
    }
    rp_cli_catch_signals(on_study_signal);
    front fr = {0};
    rp_scene *scene = NULL;
    rp_reference *ref = NULL;
    rp_bench *bench = NULL;
    rp_journal *journal = NULL;
    st = rp_load_scene(cli.scene, cli.camera, 1, &scene, &err);
    rp_reference_params rp = {.size = sizeof rp, .spp = ref_spp, .samples = ref_samples,
                              .threads = cli.threads, .cache_dir = rp_cli_extra(&cli, "cache"),
                              .log = front_log, .log_ctx = &fr, .progress = front_progress, .progress_ctx = &fr,
                              .cancel = &study_cancel};
    if (st == RP_OK)
        st = rp_mkdirs(dir, &err);
    if (st == RP_OK) {
        /* the journal's identity: everything that changes the results */
        char keytext[1024], key[17], hash[17], identity[3000];
        st = rp_reference_key(scene, &rp, keytext, sizeof keytext, key, &err);
        rp_scene_hash(scene, hash);
        snprintf(identity, sizeof identity,
                 "bench scene %s reference %s methods %s budget %.17g%s checkpoints %lu seeds %lu seed %llu "
                 "surfaces %d",
                 hash, key, list, budget, iterations > 0 ? " iterations" : "", levels, seeds,
                 (unsigned long long)cli.seed, found[0]);
        if (st == RP_OK)
            st = rp_journal_open(dir, identity, resume, &journal, &err);
        if (st == RP_OK && resume)
            rp_cli_note("radpt bench: resuming %s: %zu finished runs recorded", dir, rp_journal_count(journal));
    }
    if (st == RP_OK) {
        st = rp_reference_get(scene, cli.scene, &rp, &ref, &err);
        front_done(&fr);
    }
    bench_sink sink = {.dir = dir};
    if (st == RP_OK) {
        rp_bench_params bp = {.size = sizeof bp, .nseeds = (unsigned)seeds, .seed = cli.seed, .target = target,
                              .log = front_log, .log_ctx = &fr, .journal = journal, .image_dir = dir,
                              .on_run = on_bench_run, .on_run_ctx = &sink};
        bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = budget, .levels = (unsigned)levels,
                                     .schedule = iterations > 0 ? RP_SCHEDULE_ITERATIONS : RP_SCHEDULE_TIME,
                                     .threads = cli.threads,
                                     .surfaces_for_mc = found[0], .keep_image = 1,
                                     .progress = front_progress, .progress_ctx = &fr, .cancel = &study_cancel};
        st = rp_bench_run(scene, cli.scene, ref, methods, nmethods, &bp, &bench, &err);
        front_done(&fr);
    }
    if (st == RP_OK) {
        char cmd[2048], note[256];
        command_line(argc, argv, cmd, sizeof cmd);
        rp_bench_output out = {.size = sizeof out, .sheet = 1, .command = cmd,
                               .exposure = rp_cli_extra(&cli, "exposure") ? &exposure : NULL};
        st = rp_bench_write(bench, dir, &out, note, &err);
        const char *ej = rp_cli_extra(&cli, "export-json"), *ec = rp_cli_extra(&cli, "export-csv");
        if (st == RP_OK && ej)
            st = export_copy(dir, "summary.json", ej, &err);
        if (st == RP_OK && ec)
            st = export_copy(dir, "runs.csv", ec, &err);
        if (st == RP_OK) {
            if (note[0])
                fprintf(stderr, "radpt bench: %s\n", note);
            print_summary_table(bench);
            printf("report: %s/report.md (runs.csv, summary.json and charts in %s)\n", dir, dir);
            if (bench->interrupted) {
                char hint[2400];
                resume_hint(argc, argv, dir, hint, sizeof hint);
                st = rp_error_set(&err, RP_ERR_INTERRUPTED,
                                  "interrupted after %zu of %zu runs (recorded in %s; the report is marked "
                                  "incomplete); continue with: %s",
                                  bench->nruns, bench->planned, rp_journal_path(journal), hint);
            } else if (bench->failures)
                st = rp_error_set(&err, RP_ERR_RUNTIME, "%zu run(s) failed; see %s/report.md", bench->failures,
                                  dir);
        }
    } else if (st == RP_ERR_INTERRUPTED) {
        char hint[2400];
        resume_hint(argc, argv, dir, hint, sizeof hint);
        rp_error_set(&err, RP_ERR_INTERRUPTED, "interrupted before any run finished; continue with: %s", hint);
    }
    if (st == RP_OK)
        rp_journal_tidy(journal); /* every record is in journal.txt */
    rp_journal_close(journal);
    rp_bench_destroy(bench);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    free(methods);
    free(av);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}

/* ----------------------------------------------------------- experiment */

int rp_cmd_experiment(int argc, char **argv)
{
    static const char *const extra[] = {"budget", "seeds", "cache", "scenes", "exposure", "resume", NULL};
    static const char *const flags[] = {"--quick", NULL};
    int found[1] = {0};
    char **av = calloc((size_t)argc + 1, sizeof *av);
    if (!av)
        return 1;
    int ac = strip_flags(argc, argv, av, flags, found);
    rp_cli cli = {.command = "experiment"};
    int rc = rp_cli_parse(&cli, ac, av, extra, 0);
    unsigned long seeds = 0;
    double budget = 0;
    if (!rc)
        rc = parse_ulong(&cli, "seeds", 1, 1000, &seeds);
    if (!rc)
        rc = parse_positive(&cli, "budget", &budget);
    rp_exposure exposure;
    if (!rc)
        rc = parse_exposure(&cli, &exposure);
    const rp_experiment *e = NULL;
    if (!rc) {
        e = rp_experiment_lookup(cli.scene);
        if (!e) {
            fprintf(stderr, "radpt experiment: unknown experiment '%s'; known:", cli.scene);
            for (const rp_experiment *const *k = rp_experiments(); *k; k++)
                fprintf(stderr, " %s", (*k)->name);
            fprintf(stderr, "\n");
            rc = 2;
        }
    }
    const char *dir = NULL;
    int resume = 0;
    if (!rc)
        rc = study_dir(&cli, &dir, &resume);
    if (rc) {
        free(av);
        return rc;
    }
    char cmd[2048];
    command_line(argc, argv, cmd, sizeof cmd);
    front fr = {0};
    rp_experiment_params p = {.size = sizeof p, .experiment = e, .quick = found[0], .out_dir = dir,
                              .cache_dir = rp_cli_extra(&cli, "cache"), .scenes_dir = rp_cli_extra(&cli, "scenes"),
                              .threads = cli.threads, .budget = budget, .nseeds = (unsigned)seeds, .command = cmd,
                              .log = front_log, .log_ctx = &fr, .progress = front_progress, .progress_ctx = &fr,
                              .exposure = rp_cli_extra(&cli, "exposure") ? &exposure : NULL,
                              .cancel = &study_cancel};
    rp_error err;
    rp_error_clear(&err);
    char identity[512];
    rp_experiment_identity(&p, identity, sizeof identity);
    rp_journal *journal = NULL;
    rp_status st = rp_mkdirs(dir, &err);
    if (st == RP_OK)
        st = rp_journal_open(dir, identity, resume, &journal, &err);
    p.journal = journal;
    if (st == RP_OK && resume)
        rp_cli_note("radpt experiment: resuming %s: %zu finished units recorded", dir, rp_journal_count(journal));
    rp_cli_catch_signals(on_study_signal);
    rp_cli_note("experiment %s%s: %s", e->name, p.quick ? " (quick)" : "", e->summary);
    if (st == RP_OK)
        st = rp_experiment_run(&p, &err);
    front_done(&fr);
    if (st == RP_OK)
        rp_journal_tidy(journal); /* every record is in journal.txt */
    rp_journal_close(journal);
    if (st == RP_OK)
        printf("report: %s/report.md\n", dir);
    if (st == RP_ERR_INTERRUPTED || (st != RP_OK && atomic_load(&study_cancel))) {
        char hint[2400], why[1100];
        resume_hint(argc, argv, dir, hint, sizeof hint);
        snprintf(why, sizeof why, "%s", err.message);
        rp_error_set(&err, RP_ERR_INTERRUPTED, "%s; what finished is recorded in %s/journal.txt (reports written "
                     "so far are marked incomplete); continue with: %s", why[0] ? why : "interrupted", dir, hint);
        st = RP_ERR_INTERRUPTED;
    }
    free(av);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}
