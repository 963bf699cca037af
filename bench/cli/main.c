/* radpt: the command-line front (docs/design.md, "Command line"). */
#include <gsl/gsl_errno.h>
#include <stdio.h>
#include <string.h>
#ifdef __GLIBC__ /* set by any libc header */
#include <malloc.h>
#endif

#include "solvers/solver.h"
#include "bench/cli/cli.h"
#include "bench/cli/commands.h"
#include "bench/experiments/experiments.h"
#include "bench/run/mpi.h"
#include "bench/run/plugin.h"

#ifndef RP_VERSION
#define RP_VERSION "unknown"
#endif
#ifndef RP_GIT_DESCRIBE
#define RP_GIT_DESCRIBE "unknown"
#endif

static void print_usage(FILE *f)
{
    fputs("usage:\n"
          "  radpt info SCENE [--json]\n"
          "      bands, camera, surfaces (material, faces, area, emitted power), whether the\n"
          "      scene is closed, and the default radiosity subdivision with its quality\n"
          "  radpt render SCENE --method M [method options] [--seed S] [--threads T]\n"
          "               [--time SECONDS] -o OUT.exr|OUT.png|OUT.pfm [--png OUT.png] [--exposure EV]\n"
          "               [--checkpoint FILE [--checkpoint-every SECONDS]] [--resume FILE]\n"
          "      render the scene's camera view: -o by its extension an EXR or PFM of linear\n"
          "      radiance or a PNG preview; --png adds a PNG preview to an EXR or PFM.\n"
          "      The preview's exposure is automatic (the 99th-percentile luminance maps\n"
          "      to 0.9 before the sRGB curve) unless --exposure EV fixes it (radiance x 2^EV;\n"
          "      EV 0 shows radiance 1 as white); the exposure used goes to stderr and into\n"
          "      the PNG (tEXt radpt:exposure).\n"
          "      --checkpoint saves the run's state (pathtrace only) every 60 s (or SECONDS),\n"
          "      at the end and on SIGINT/SIGTERM; --resume FILE continues such a run (same\n"
          "      scene, seed and options; --spp may grow): bit-identical to an unbroken one\n"
          "  radpt probe SCENE --method M [method options] --surface-averages [--json]\n"
          "               [--seed S] [--threads T] [--time SECONDS]\n"
          "      area-averaged outgoing radiance of every surface, with standard errors\n"
          "  radpt reference SCENE [--spp N] [--samples N] [--seed S] [--cache DIR] [--force] [--json]\n"
          "               [--checkpoint FILE [--checkpoint-every SECONDS]] [--resume FILE]\n"
          "      the converged answer runs are scored against: exact for a furnace, else a long\n"
          "      path-traced render; cached as refs/<scenehash>-<optionshash>.exr and .json;\n"
          "      --checkpoint / --resume as for render (--spp may change, the seed may not)\n"
          "  radpt bench SCENE [--methods M[:opt=v...],...] [--budget SECONDS | --iterations N]\n"
          "               -o DIR | --resume DIR\n"
          "               [--seeds N] [--checkpoints N] [--target RMSE] [--surfaces] [--reference-spp N]\n"
          "               [--cache DIR] [--exposure EV] [--export-json FILE] [--export-csv FILE]\n"
          "      each method with checkpoints at budget * 2^-k (seconds, or with --iterations the\n"
          "      methods' iterations: the same work on any machine); DIR/report.md, runs.csv,\n"
          "      summary.json, charts and an image sheet (sheet.png, one exposure for all its\n"
          "      images: the reference's automatic one, or --exposure EV)\n"
          "  radpt experiment NAME [--quick] -o DIR | --resume DIR [--budget SECONDS] [--seeds N]\n"
          "               [--cache DIR] [--exposure EV]\n"
          "  radpt experiment --list\n"
          "      a named study that ends in DIR/report.md with its charts (list below;\n"
          "      radpt help experiment NAME says what it runs and what it checks)\n"
          "  radpt formfactor SCENE --from S --to S [--method analytic|montecarlo|hemicube]\n"
          "               [--samples N] [--resolution R] [--rays N] [--tolerance T]\n"
          "               [--elements N | --max-edge L] [--seed S] [--threads T] [--json]\n"
          "      the form factor from surface S to surface S (area-weighted over elements)\n"
          "  radpt throughput SCENE [--spp N] [--rays N] [--threads T] [--json]\n"
          "      the random-ray limit of the ray caster, then the path tracer's rays/s,\n"
          "      paths/s and their fraction of that limit, in one run\n"
          "  radpt samplers SCENE [--spp N] [--seeds N] [--reference-spp N] [--cache DIR] [--json]\n"
          "      random, stratified and Sobol' sampling: RMSE against the cached reference over\n"
          "      its measured pixels (the benchmarks' metric), and MSE x seconds, which ranks\n"
          "      them at equal time\n"
          "  radpt compare A.exr B.exr [--json] [-o DIFF.png] [--mask MASK.png|MASK.exr]\n"
          "               [--scene SCENE [--camera WORDS]]\n"
          "      image A against the reference B with the benchmarks' metrics (RMSE, relMSE with\n"
          "      eps 0.01, MAE over every channel of R,G,B or Y; per-channel means and their ratio;\n"
          "      the largest difference and where); half or float, scanline or tiled EXRs from any\n"
          "      renderer; --scene: only the pixels benchmarks measure; --mask: only where a channel\n"
          "      of the mask (PNG or EXR) is > 0; both: the pixels both select; -o: false-colour\n"
          "      A - B (radpt help compare: the details)\n"
          "  radpt help [METHOD | compare | experiment NAME]\n"
          "      this text, a method's options, compare in detail, or what an experiment runs and\n"
          "      checks\n"
          "  radpt --version\n"
          "      the release, and whether MPI was initialised (only under mpirun)\n"
          "  radpt COMMAND ... --plugin PATH.so\n"
          "      load a method of your own (README.md, \"Your own method\"); repeatable, on\n"
          "      every command; RADPT_PLUGIN_PATH (files, directories, ':'-separated) too\n"
          "  mpirun -np K ./radpt COMMAND ...\n"
          "      any command on K ranks (README.md, \"On a cluster\"): the path tracer splits\n"
          "      its pixels and probe points, bench and experiment hand out their runs; the\n"
          "      answers are a plain run's; rank 0 alone prints and writes files\n"
          "\n"
          "SCENE is a scene file (format 1, see README.md) or a Wavefront .obj with its .mtl.\n"
          "Every command reading SCENE takes --camera \"eye X Y Z look X Y Z up X Y Z fov F size W H\"\n"
          "(the scene format's camera words), which gives or replaces its camera; a scene without\n"
          "one gets, where a camera is needed, a default one, printed as such --camera words.\n"
          "What reading drops or ignores is printed as 'radpt: warning: FILE:LINE: ...'.\n"
          "--time stops a run after SECONDS; without it a method stops by its own rule\n"
          "(e.g. --spp for pathtrace). --seed defaults to 1, --threads to all cores.\n"
          "Options a command does not take are refused (exit 2). --quiet: no progress or log lines.\n"
          "Exit status: 0 success, 1 runtime failure, 2 bad input or usage.\n\nmethods:\n",
          f);
    for (const rp_solver_type *const *t = rp_solver_types(); *t; t++)
        fprintf(f, "  %-18s %s\n", (*t)->name, (*t)->summary);
    fputs("\nexperiments:\n", f);
    for (const rp_experiment *const *e = rp_experiments(); *e; e++)
        fprintf(f, "  %-18s %s\n", (*e)->name, (*e)->summary);
}

static void list_experiments(FILE *f)
{
    for (const rp_experiment *const *e = rp_experiments(); *e; e++)
        fprintf(f, "%-14s %s\n", (*e)->name, (*e)->summary);
}

static int print_experiment(const char *name)
{
    const rp_experiment *e = name ? rp_experiment_lookup(name) : NULL;
    if (!e) {
        fprintf(stderr, "radpt help experiment: %s%s%s; known experiments:", name ? "unknown experiment '" : "needs a NAME",
                name ? name : "", name ? "'" : "");
        for (const rp_experiment *const *k = rp_experiments(); *k; k++)
            fprintf(stderr, " %s", (*k)->name);
        fprintf(stderr, "\n");
        return 2;
    }
    rp_experiment_describe(e, stdout);
    return 0;
}

static int print_method(const char *name)
{
    const rp_solver_type *t = rp_solver_lookup(name);
    if (!t) {
        fprintf(stderr, "radpt help: unknown method '%s'; known methods:", name);
        for (const rp_solver_type *const *k = rp_solver_types(); *k; k++)
            fprintf(stderr, " %s", (*k)->name);
        fprintf(stderr, " (a command's options: radpt --help)\n");
        return 2;
    }
    printf("method %s: %s\n\noptions:\n", t->name, t->summary);
    for (const rp_option_spec *o = t->options; o && o->name; o++) {
        char head[64];
        snprintf(head, sizeof head, "--%s%s%s", o->name, o->arg ? " " : "", o->arg ? o->arg : "");
        printf("  %-28s %s", head, o->help);
        if (o->fallback)
            printf(" (default %s)", o->fallback);
        printf("\n");
    }
    return 0;
}

static int dispatch(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "radpt: no command; usage: radpt info|render|probe|reference|bench|experiment|"
                        "formfactor|throughput|samplers|compare|help|--version ... (see radpt help)\n");
        return 2;
    }
    const char *cmd = argv[1];
    if (!strcmp(cmd, "--version") || !strcmp(cmd, "version")) {
        char mpi[256];
        rp_mpi_describe(mpi, sizeof mpi);
        printf("radpt %s (git %s)\n%s\n", RP_VERSION, RP_GIT_DESCRIBE, mpi);
        return 0;
    }
    if (!strcmp(cmd, "help") || !strcmp(cmd, "--help") || !strcmp(cmd, "-h")) {
        if (argc > 2 && !strcmp(argv[2], "experiment"))
            return print_experiment(argc > 3 ? argv[3] : NULL);
        if (argc > 2 && !strcmp(argv[2], "compare")) {
            rp_cmd_compare_help(stdout);
            return 0;
        }
        if (argc > 2)
            return print_method(argv[2]);
        print_usage(stdout);
        return 0;
    }
    if (!strcmp(cmd, "experiment") && argc == 3 && !strcmp(argv[2], "--list")) {
        list_experiments(stdout);
        return 0;
    }
    for (int i = 2; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            print_usage(stdout);
            return 0;
        }
    if (!strcmp(cmd, "info"))
        return rp_cmd_info(argc, argv);
    if (!strcmp(cmd, "render"))
        return rp_cmd_render(argc, argv);
    if (!strcmp(cmd, "probe"))
        return rp_cmd_probe(argc, argv);
    if (!strcmp(cmd, "reference"))
        return rp_cmd_reference(argc, argv);
    if (!strcmp(cmd, "bench"))
        return rp_cmd_bench(argc, argv);
    if (!strcmp(cmd, "experiment"))
        return rp_cmd_experiment(argc, argv);
    if (!strcmp(cmd, "formfactor"))
        return rp_cmd_formfactor(argc, argv);
    if (!strcmp(cmd, "throughput"))
        return rp_cmd_throughput(argc, argv);
    if (!strcmp(cmd, "samplers"))
        return rp_cmd_samplers(argc, argv);
    if (!strcmp(cmd, "compare"))
        return rp_cmd_compare(argc, argv);
    fprintf(stderr, "radpt: unknown command '%s' (see radpt help)\n", cmd);
    return 2;
}

/* Loads RADPT_PLUGIN_PATH's plugins, then each --plugin PATH (or
 * --plugin=PATH) of the command line, which it removes from argv: a
 * plugin's methods are then known to every command, `help METHOD`
 * included.  Returns 0, or 2 after the message. */
static int load_plugins(int *argc, char **argv)
{
    rp_error err;
    if (rp_plugin_load_env(&err) != RP_OK) {
        fprintf(stderr, "radpt: %s\n", err.message);
        return 2;
    }
    int out = 1;
    for (int i = 1; i < *argc; i++) {
        const char *path = NULL;
        if (!strcmp(argv[i], "--plugin")) {
            if (i + 1 >= *argc) {
                fprintf(stderr, "radpt: --plugin needs a PATH.so (see radpt help)\n");
                return 2;
            }
            path = argv[++i];
        } else if (!strncmp(argv[i], "--plugin=", 9))
            path = argv[i] + 9;
        if (!path) {
            argv[out++] = argv[i];
            continue;
        }
        if (rp_plugin_load(path, &err) != RP_OK) {
            fprintf(stderr, "radpt: %s\n", err.message);
            return 2;
        }
        rp_cli_add_plugin(path);
    }
    argv[out] = NULL;
    *argc = out;
    return 0;
}

int main(int argc, char **argv)
{
    gsl_set_error_handler_off();
#ifdef __GLIBC__
    /* Blocks of 128 KiB and more are mapped, and given back when freed,
     * at every size.  glibc otherwise raises this threshold to the size of
     * each mapped block freed (up to 32 MiB), after which the solvers'
     * growing arrays (a link list reallocated each refinement pass) land in
     * the heap and leave holes there: the bunny scene's hierarchical probe
     * peaked at 162-173 MiB resident instead of 127 MiB (docs/design.md). */
    mallopt(M_MMAP_THRESHOLD, 128 * 1024);
#endif
    /* Under mpirun every rank runs the same command; plainly, no MPI. */
    if (rp_mpi_start(&argc, &argv) != 0)
        return 1;
    int rc = load_plugins(&argc, argv);
    return rp_mpi_finish(rc ? rc : dispatch(argc, argv));
}
