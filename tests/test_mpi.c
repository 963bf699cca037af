/* radpt under Open MPI (issue 14; docs/design.md, "MPI as a layer"): the
 * binary run by mpirun with 2 and 3 ranks gives what one plain process
 * gives.  The answers checked are a plain run's, not numbers of our own:
 *   - path-traced renders: every pixel bit-identical, for K = 1, 2, 3, and
 *     a checkpoint written by 3 ranks resumed by 2;
 *   - path-traced surface averages (probe chunks split by rank): equal;
 *   - bench with an iteration budget: every runs.csv column but the times,
 *     memory, rank and threads equal;
 *   - a bad input: exit 2 and the one message a plain run prints;
 *   - plainly, MPI is not initialised; under mpirun every rank knows K;
 *   - experiments with tables of their own (formfactors here; stability,
 *     resumed from a plain run's partial journal, in test_stability.c):
 *     their units handed out to ranks, every CSV column but the times
 *     equal to a plain run's. */
#include <criterion/criterion.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench/report/image.h"
#include "cli_util.h"
#include "study_util.h"

#define SCENE "scenes/cornell.scene"

static char tmpdir[64];

static void make_tmpdir(void)
{
    cr_assert_eq(rp_test_tmpdir(tmpdir, sizeof tmpdir, "rp_mpi_test"), 0);
}

static void remove_tmpdir(void)
{
    cr_expect_eq(rp_test_rmtree(tmpdir), 0);
}

/* 1 when every channel of every pixel of the two EXRs is the same float. */
static int same_pixels(const char *a, const char *b)
{
    uint32_t wa, ha, wb, hb;
    size_t na, nb;
    char **names_a, **names_b;
    float **pa, **pb;
    rp_error err;
    cr_assert_eq(rp_image_read_exr(a, &wa, &ha, &na, &names_a, &pa, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_image_read_exr(b, &wb, &hb, &nb, &names_b, &pb, &err), RP_OK, "%s", err.message);
    int same = wa == wb && ha == hb && na == nb;
    for (size_t c = 0; same && c < na; c++)
        same = !strcmp(names_a[c], names_b[c]) && !memcmp(pa[c], pb[c], (size_t)wa * ha * sizeof(float));
    for (size_t c = 0; c < na; c++) {
        free(pa[c]);
        free(names_a[c]);
    }
    for (size_t c = 0; c < nb; c++) {
        free(pb[c]);
        free(names_b[c]);
    }
    free(pa);
    free(pb);
    free(names_a);
    free(names_b);
    return same;
}

TestSuite(mpi, .init = make_tmpdir, .fini = remove_tmpdir, .timeout = 300);

Test(mpi, pathtrace_render_is_bit_identical_for_any_rank_count)
{
    char args[512], plain[128], path[128];
    snprintf(plain, sizeof plain, "%s/plain.exr", tmpdir);
    snprintf(args, sizeof args, "render " SCENE " --method pathtrace --spp 8 --threads 2 -o %s", plain);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    for (int k = 1; k <= 3; k++) {
        snprintf(path, sizeof path, "%s/k%d.exr", tmpdir, k);
        /* other thread counts too: 1 per rank, then 2 */
        snprintf(args, sizeof args, "render " SCENE " --method pathtrace --spp 8 --threads %d -o %s", 1 + k % 2,
                 path);
        r = rp_run_radpt_mpi(k, args);
        cr_assert_eq(r.status, 0, "K=%d: %s", k, r.err);
        cr_expect(same_pixels(plain, path), "K=%d: pixels differ from the plain render", k);
        /* rank 0 alone prints */
        cr_expect_eq(rp_count_lines(r.out), 1, "K=%d: %s", k, r.out);
        rp_run_free(&r);
    }
}

Test(mpi, checkpoint_of_three_ranks_resumes_on_two)
{
    char args[512], plain[128], ckpt[128], out[128];
    snprintf(plain, sizeof plain, "%s/plain16.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/run.ckpt", tmpdir);
    snprintf(out, sizeof out, "%s/resumed.exr", tmpdir);
    snprintf(args, sizeof args, "render " SCENE " --method pathtrace --spp 12 -o %s", plain);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    snprintf(args, sizeof args, "render " SCENE " --method pathtrace --spp 5 --threads 1 --checkpoint %s -o %s/half.exr",
             ckpt, tmpdir);
    r = rp_run_radpt_mpi(3, args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    snprintf(args, sizeof args, "render " SCENE " --method pathtrace --spp 12 --threads 1 --resume %s -o %s", ckpt,
             out);
    r = rp_run_radpt_mpi(2, args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(same_pixels(plain, out), "a run resumed on 2 ranks from 3 ranks' checkpoint differs");
    rp_run_free(&r);
}

/* The surface list of probe --json (everything after "surfaces"). */
static const char *surfaces_of(const char *json)
{
    const char *s = strstr(json, "\"surfaces\"");
    cr_assert_not_null(s, "%s", json);
    return s;
}

Test(mpi, pathtrace_surface_averages_equal)
{
    const char *args = "probe " SCENE " --method pathtrace --surface-averages --samples 2048 --batch 512 --json";
    rp_run plain = rp_run_radpt(args);
    cr_assert_eq(plain.status, 0, "%s", plain.err);
    for (int k = 2; k <= 3; k++) {
        rp_run r = rp_run_radpt_mpi(k, args);
        cr_assert_eq(r.status, 0, "%s", r.err);
        cr_expect_str_eq(surfaces_of(r.out), surfaces_of(plain.out), "K=%d", k);
        rp_run_free(&r);
    }
    rp_run_free(&plain);
}

/* runs.csv without the columns that are measured rather than computed:
 * wall_s, cpu_s, peak_rss_mb, solver_mb, measure_s, rank, threads. */
static char *work_columns(const char *path)
{
    char *csv = rp_read_file(path);
    cr_assert_not_null(csv, "%s", path);
    static const int timing[] = {5, 6, 16, 17, 27, 28, 29}; /* 0-based */
    char *out = malloc(strlen(csv) + 1), *o = out;
    int col = 0;
    for (const char *c = csv; *c; c++) {
        int skip = 0;
        for (size_t t = 0; t < sizeof timing / sizeof timing[0]; t++)
            skip |= col == timing[t];
        if (*c == ',' || *c == '\n') {
            if (!skip || *c == '\n')
                *o++ = *c;
            col = *c == '\n' ? 0 : col + 1;
        } else if (!skip)
            *o++ = *c;
    }
    *o = '\0';
    free(csv);
    return out;
}

Test(mpi, bench_runs_are_the_same_on_any_rank_count)
{
    char args[768], path[160];
    const char *study = "bench " SCENE " --methods pathtrace,gauss-seidel:elements=200 --iterations 4 "
                        "--checkpoints 2 --seeds 2 --threads 1 --reference-spp 16";
    snprintf(args, sizeof args, "%s --cache %s/refs -o %s/b1", study, tmpdir, tmpdir);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    snprintf(path, sizeof path, "%s/b1/runs.csv", tmpdir);
    char *plain = work_columns(path);
    cr_assert_eq(rp_count_lines(plain), 1 + 3 * 2, "%s", plain);
    for (int k = 2; k <= 3; k++) {
        snprintf(args, sizeof args, "%s --cache %s/refs -o %s/b%d", study, tmpdir, tmpdir, k);
        r = rp_run_radpt_mpi(k, args);
        cr_assert_eq(r.status, 0, "%s", r.err);
        rp_run_free(&r);
        snprintf(path, sizeof path, "%s/b%d/runs.csv", tmpdir, k);
        char *got = work_columns(path);
        cr_expect_str_eq(got, plain, "K=%d", k);
        /* the rank column says where each run went: run k to rank k mod K */
        char *csv = rp_read_file(path);
        cr_expect(strstr(csv, ",1,1\n"), "K=%d: no run on rank 1:\n%s", k, csv);
        free(csv);
        free(got);
    }
    free(plain);
}

Test(mpi, bad_input_exits_2_with_one_message)
{
    rp_run plain = rp_run_radpt("render scenes/no-such.scene --method pathtrace -o /tmp/never.exr");
    cr_assert_eq(plain.status, 2);
    for (int k = 2; k <= 3; k++) {
        rp_run r = rp_run_radpt_mpi(k, "render scenes/no-such.scene --method pathtrace -o /tmp/never.exr");
        cr_expect_eq(r.status, 2, "K=%d", k);
        cr_expect_str_eq(r.err, plain.err, "K=%d", k);
        cr_expect_eq(rp_count_lines(r.err), 1, "K=%d: %s", k, r.err);
        rp_run_free(&r);
    }
    cr_expect_eq(access("/tmp/never.exr", F_OK), -1);
    rp_run_free(&plain);
}

Test(mpi, plain_runs_start_no_mpi)
{
    rp_run plain = rp_run_radpt("--version");
    cr_assert_eq(plain.status, 0);
    cr_expect(strstr(plain.out, "not under mpirun: MPI not initialised"), "%s", plain.out);
    rp_run_free(&plain);
    rp_run r = rp_run_radpt_mpi(3, "--version");
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "rank 0 of 3"), "%s", r.out);
    rp_run_free(&r);
}

Test(mpi, experiment_units_are_handed_out_to_ranks)
{
    char args[512], dir[160];
    snprintf(args, sizeof args, "experiment formfactors --quick -o %s/f1", tmpdir);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    snprintf(dir, sizeof dir, "%s/f1", tmpdir);
    /* 3 ranks, not a power of two (2 ranks hand out the stability study's
     * units in tests/test_stability.c, quick_atlas) */
    {
        const int k = 3;
        char other[160];
        snprintf(other, sizeof other, "%s/f%d", tmpdir, k);
        snprintf(args, sizeof args, "experiment formfactors --quick -o %s", other);
        r = rp_run_radpt_mpi(k, args);
        cr_assert_eq(r.status, 0, "K=%d: %s", k, r.err);
        /* rank 0 took units 0, K, 2K, ... of the 36 */
        long n = 0, m = rp_study_computed_units(&r, &n);
        cr_expect_eq(n, 36, "K=%d", k);
        cr_expect_eq(m, (n + k - 1) / k, "K=%d: rank 0 computed %ld of %ld", k, m, n);
        rp_run_free(&r);
        cr_expect_eq(rp_study_same_tables(dir, other, "K=3"), 1);
        /* the journal holds every unit once: its two head lines and 36 */
        char path[200];
        snprintf(path, sizeof path, "%s/journal.txt", other);
        char *j = rp_read_file(path);
        cr_assert_not_null(j);
        cr_expect_eq(rp_count_lines(j), 2 + 36, "K=%d", k);
        free(j);
        /* the ranks' side journals went once the study ended */
        snprintf(path, sizeof path, "%s/journal.rank-1.txt", other);
        cr_expect_eq(access(path, F_OK), -1, "K=%d: %s left", k, path);
    }
}

