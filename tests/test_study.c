/* Nothing lost: a bench interrupted after its first run and resumed from
 * its journal gives the same rows as an uninterrupted bench (timings
 * aside), in-process with an iteration schedule (deterministic), and end
 * to end with the binary and SIGINT. */
#include <criterion/criterion.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "bench/report/plot.h"
#include "bench/run/harness.h"
#include "bench/run/journal.h"
#include "bench/run/reference.h"
#include "cli_util.h"
#include "scene_util.h"

static void remove_tree(const char *dir)
{
    char cmd[256];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_expect_eq(system(cmd), 0);
}

static atomic_int cancel_flag;

/* Cancels the study once its first run has finished. */
static void cancel_after_first(void *ctx, const rp_bench *b)
{
    (void)ctx;
    if (b->nruns == 1)
        atomic_store(&cancel_flag, 1);
}

/* Runs the furnace bench (exact reference, iteration budget) into dir with
 * journal j; on_run may cancel it. */
static rp_bench *furnace_bench(rp_scene *scene, const rp_reference *ref, rp_journal *j, const char *dir,
                               void (*on_run)(void *, const rp_bench *))
{
    rp_method_spec *methods = NULL;
    size_t nm = 0;
    rp_error err;
    cr_assert_eq(rp_method_list_parse("jacobi:elements=24,pathtrace:spp=64,southwell:elements=24", &methods, &nm,
                                      &err),
                 RP_OK, "%s", err.message);
    rp_bench_params bp = {.size = sizeof bp, .nseeds = 2, .seed = 1, .journal = j, .image_dir = dir,
                          .on_run = on_run};
    bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = 8, .levels = 3,
                                 .schedule = RP_SCHEDULE_ITERATIONS, .keep_image = 1, .cancel = &cancel_flag};
    rp_bench *b = NULL;
    cr_assert_eq(rp_bench_run(scene, "furnace", ref, methods, nm, &bp, &b, &err), RP_OK, "%s", err.message);
    free(methods);
    return b;
}

/* Every field of every row except the measured times and memory. */
static void expect_same_rows(const rp_bench *a, const rp_bench *b)
{
    cr_assert_eq(a->nruns, b->nruns);
    for (size_t r = 0; r < a->nruns; r++) {
        const rp_trial *x = &a->runs[r], *y = &b->runs[r];
        cr_assert_eq(x->method, y->method);
        cr_assert_eq(x->seed, y->seed);
        cr_assert_eq(x->ncp, y->ncp, "run %zu", r);
        for (size_t i = 0; i < x->ncp; i++) {
            const rp_checkpoint *c = &x->cp[i], *d = &y->cp[i];
            double u[] = {c->index, c->target, c->steps, c->rays, c->paths, c->iterations, c->form_factors,
                          c->samples, c->residual, c->unshot, c->rmse, c->relmse, c->mae, c->surface_err,
                          c->converged, c->final};
            double v[] = {d->index, d->target, d->steps, d->rays, d->paths, d->iterations, d->form_factors,
                          d->samples, d->residual, d->unshot, d->rmse, d->relmse, d->mae, d->surface_err,
                          d->converged, d->final};
            for (size_t k = 0; k < sizeof u / sizeof u[0]; k++)
                cr_expect(memcmp(&u[k], &v[k], sizeof u[k]) == 0, "run %zu row %zu field %zu: %.17g vs %.17g", r,
                          i, k, u[k], v[k]);
        }
        size_t npix = (size_t)a->ref->width * a->ref->height * a->ref->nbands;
        cr_assert_eq(!x->image, !y->image, "run %zu: kept image", r);
        if (x->image)
            cr_expect(memcmp(x->image, y->image, npix * sizeof *x->image) == 0, "run %zu: image", r);
    }
}

Test(study, interrupted_bench_resumes_to_the_same_rows)
{
    char dir[64], whole[80];
    snprintf(dir, sizeof dir, "/tmp/rp_study_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
    snprintf(whole, sizeof whole, "%s/whole", dir);
    char part[80];
    snprintf(part, sizeof part, "%s/part", dir);
    rp_error err;
    cr_assert_eq(rp_mkdirs(whole, &err), RP_OK);
    cr_assert_eq(rp_mkdirs(part, &err), RP_OK);
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    rp_reference_params rp = {.size = sizeof rp, .cache_dir = dir};
    rp_reference *ref = NULL;
    cr_assert_eq(rp_reference_get(scene, "furnace", &rp, &ref, &err), RP_OK, "%s", err.message);

    atomic_store(&cancel_flag, 0);
    rp_bench *full = furnace_bench(scene, ref, NULL, whole, NULL);
    cr_assert_eq(full->nruns, 4); /* Jacobi, two path tracer seeds, Southwell */
    cr_assert_eq(full->interrupted, 0);

    rp_journal *j = NULL;
    cr_assert_eq(rp_journal_open(part, "study test", 0, &j, &err), RP_OK, "%s", err.message);
    rp_bench *cut = furnace_bench(scene, ref, j, part, cancel_after_first);
    rp_journal_close(j);
    cr_expect_eq(cut->interrupted, 1);
    cr_expect_eq(cut->nruns, 1, "the runs after the cancel are neither run nor recorded");
    cr_expect_eq(cut->planned, 4);
    char note[256];
    rp_bench_output o = {.size = sizeof o, .sheet = 0};
    cr_assert_eq(rp_bench_write(cut, part, &o, note, &err), RP_OK, "%s", err.message);
    char path[128];
    snprintf(path, sizeof path, "%s/report.md", part);
    char *report = rp_read_file(path);
    cr_assert_not_null(report);
    cr_expect(strstr(report, "INCOMPLETE: interrupted after 1 of 4 runs"), "%.300s", report);
    free(report);
    rp_bench_destroy(cut);

    atomic_store(&cancel_flag, 0);
    cr_assert_eq(rp_journal_open(part, "study test", 1, &j, &err), RP_OK, "%s", err.message);
    cr_expect_eq(rp_journal_resumed(j), 1);
    rp_bench *resumed = furnace_bench(scene, ref, j, part, NULL);
    rp_journal_close(j);
    cr_expect_eq(resumed->resumed, 1);
    cr_expect_eq(resumed->interrupted, 0);
    expect_same_rows(full, resumed);
    cr_assert_eq(rp_bench_write(resumed, part, &o, note, &err), RP_OK, "%s", err.message);
    report = rp_read_file(path);
    cr_expect(report && !strstr(report, "INCOMPLETE"));
    free(report);

    rp_bench_destroy(resumed);
    rp_bench_destroy(full);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_tree(dir);
}

/* The binary: SIGINT once the first run is in the journal, then --resume. */
Test(study, sigint_then_resume_with_the_binary, .timeout = 300)
{
    char dir[64], cache[96], out[96];
    snprintf(dir, sizeof dir, "/tmp/rp_study_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
    snprintf(cache, sizeof cache, "%s/refs", dir);
    snprintf(out, sizeof out, "%s/out", dir);
    char args[1024];
    snprintf(args, sizeof args,
             "bench " RP_SOURCE_DIR "/scenes/furnace.scene --methods jacobi:elements=24,southwell:elements=24,"
             "gauss-seidel:elements=24 --budget 0.5 --checkpoints 2 --cache %s",
             cache);
    pid_t pid = fork();
    cr_assert(pid >= 0);
    if (pid == 0) {
        char cmd[1300];
        snprintf(cmd, sizeof cmd, "exec " RP_BIN " %s -o %s --quiet > /dev/null 2>&1", args, out);
        execl("/bin/sh", "sh", "-c", cmd, (char *)NULL);
        _exit(127);
    }
    /* wait for the first record (the journal's third line), then interrupt */
    char journal[128];
    snprintf(journal, sizeof journal, "%s/journal.txt", out);
    int recorded = 0;
    for (int i = 0; i < 6000 && !recorded; i++) {
        char *text = rp_read_file(journal);
        recorded = text && strstr(text, "\njacobi:elements=24 seed 1\t");
        free(text);
        if (!recorded)
            usleep(10000);
    }
    cr_assert(recorded, "no run was recorded");
    kill(pid, SIGINT);
    int status;
    cr_assert_eq(waitpid(pid, &status, 0), pid);
    cr_assert(WIFEXITED(status));
    int code = WEXITSTATUS(status);
    char csv[128];
    snprintf(csv, sizeof csv, "%s/runs.csv", out);
    if (code == 1) {
        /* stopped: the finished runs are in runs.csv, the report says so */
        char rep[128];
        snprintf(rep, sizeof rep, "%s/report.md", out);
        char *report = rp_read_file(rep);
        cr_assert_not_null(report);
        cr_expect(strstr(report, "INCOMPLETE"));
        free(report);
    } else {
        cr_expect_eq(code, 0, "the study ended before the signal came: exit %d", code);
    }
    char resume[1300];
    snprintf(resume, sizeof resume, "%s --resume %s", args, out);
    rp_run r = rp_run_radpt(resume);
    cr_expect_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.err, "recorded, read back"), "%s", r.err);
    rp_run_free(&r);
    char *rows = rp_read_file(csv);
    cr_assert_not_null(rows);
    /* each of the three methods once, with its final row (field 27) */
    static const char *const methods[3] = {"\njacobi,", "\nsouthwell,", "\ngauss-seidel,"};
    for (int k = 0; k < 3; k++) {
        size_t finals = 0;
        for (const char *line = strstr(rows, methods[k]); line; line = strstr(line + 1, methods[k])) {
            const char *f = line + 1;
            for (int comma = 0; comma < 26 && f; comma++)
                f = strchr(f, ',') ? strchr(f, ',') + 1 : NULL;
            finals += f && f[0] == '1';
        }
        cr_expect_eq(finals, 1, "%s: %zu final rows in\n%s", methods[k] + 1, finals, rows);
    }
    free(rows);
    char rep[128];
    snprintf(rep, sizeof rep, "%s/report.md", out);
    char *report = rp_read_file(rep);
    cr_expect(report && !strstr(report, "INCOMPLETE"));
    free(report);
    remove_tree(dir);
}

/* Southwell on a furnace shoots until no unshot power is left; a step after
 * that does no work and counts no shot, so an open-ended run by iterations
 * (which the method's rule does not stop) still ends, and its last row says
 * converged, with as many shots as steps that shot. */
Test(study, southwell_counts_no_shot_after_convergence)
{
    char dir[64];
    snprintf(dir, sizeof dir, "/tmp/rp_study_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    rp_reference_params rp = {.size = sizeof rp, .cache_dir = dir};
    rp_reference *ref = NULL;
    rp_error err;
    cr_assert_eq(rp_reference_get(scene, "furnace", &rp, &ref, &err), RP_OK, "%s", err.message);
    rp_method_spec m;
    cr_assert_eq(rp_method_spec_parse("southwell:elements=24", &m, &err), RP_OK, "%s", err.message);
    rp_harness_params hp = {.size = sizeof hp, .budget = 1e12, .levels = 1, .schedule = RP_SCHEDULE_ITERATIONS};
    rp_trial run;
    cr_assert_eq(rp_harness_run(scene, ref, &m, 1, &hp, &run, &err), RP_OK);
    cr_assert_eq(run.status, RP_OK, "%s", run.error);
    cr_assert_eq(run.ncp, 1);
    const rp_checkpoint *cp = &run.cp[0];
    cr_expect_eq(cp->converged, 1);
    cr_expect_eq(cp->residual, 0.0);
    cr_expect_eq(cp->iterations, cp->steps - 1, "%.0f shots in %.0f steps: only the last did no work",
                 cp->iterations, cp->steps);
    cr_expect(cp->iterations > 24, "%.0f shots", cp->iterations);
    rp_trial_free(&run);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_tree(dir);
}
