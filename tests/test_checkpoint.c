/* radpt render --checkpoint / --resume: a render stopped and resumed gives
 * the same bits as one that ran straight through (every random number is a
 * function of seed, pixel, sample index and dimension, and the sums are
 * carried exactly); a checkpoint of another scene, seed or sampler, or a
 * damaged one, is refused with exit status 2. */
#include <criterion/criterion.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "bench/report/image.h"
#include "cli_util.h"

/* A 40 x 32 Cornell box (the built-in one with a smaller image, so a pass
 * takes about a millisecond), in a directory of the test's own. */
static char dir[64];

static void make_scene(void)
{
    snprintf(dir, sizeof dir, "/tmp/rp-ckpt-%d", (int)getpid());
    mkdir(dir, 0755);
    FILE *in = fopen(RP_SOURCE_DIR "/scenes/cornell-geometry.inc", "r");
    cr_assert(in);
    char path[160];
    snprintf(path, sizeof path, "%s/geom.inc", dir);
    FILE *out = fopen(path, "w");
    cr_assert(out);
    char line[1024];
    int cameras = 0;
    while (fgets(line, sizeof line, in)) {
        char *p = strstr(line, "size 256 256");
        if (p && strncmp(line, "camera", 6) == 0) {
            strcpy(p, "size 40 32\n");
            cameras++;
        }
        fputs(line, out);
    }
    fclose(in);
    fclose(out);
    cr_assert_eq(cameras, 1);
    snprintf(path, sizeof path, "%s/cornell.scene", dir);
    out = fopen(path, "w");
    cr_assert(out);
    fputs("bands rgb\n"
          "material white  reflect 0.725 0.71 0.68\n"
          "material red    reflect 0.63 0.065 0.05\n"
          "material green  reflect 0.14 0.45 0.091\n"
          "material light  reflect 0  emit 17 12 4\n"
          "include geom.inc\n",
          out);
    fclose(out);
}

static void remove_dir(void)
{
    char cmd[200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_expect_eq(system(cmd), 0);
}

/* radpt render on the small box; fmt continues the command line. */
static rp_run render(const char *fmt, const char *a, const char *b)
{
    char tail[1024], args[2048];
    snprintf(tail, sizeof tail, fmt, a ? a : "", b ? b : "");
    snprintf(args, sizeof args, "render %s/cornell.scene --method pathtrace %s", dir, tail);
    return rp_run_radpt(args);
}

static void in_dir(char *buf, size_t n, const char *name) { snprintf(buf, n, "%s/%s", dir, name); }

/* Every channel of two EXR files bit for bit (metadata such as seconds
 * differs between runs and is not compared). */
/* Waits (at most 30 s) for the child's first checkpoint, interrupts it
 * with SIGINT and returns its exit status; asserts it stopped by itself. */
static int interrupt_after_checkpoint(pid_t pid, const char *ckpt)
{
    int seen = 0;
    for (int i = 0; i < 30000 && !seen; i++) {
        seen = access(ckpt, F_OK) == 0;
        if (!seen) {
            struct timespec ts = {0, 1000000};
            nanosleep(&ts, NULL);
        }
    }
    kill(pid, SIGINT);
    int status = 0;
    cr_assert_eq(waitpid(pid, &status, 0), pid);
    cr_assert(seen, "no checkpoint appeared");
    cr_assert(WIFEXITED(status), "killed by a signal rather than stopped");
    return status;
}

/* Returns the number of values that differ (expected 0 when same is set). */
static size_t compare_channels(const char *a, const char *b, size_t channels, int same)
{
    uint32_t w[2], h[2];
    size_t nch[2];
    char **names[2];
    float **planes[2];
    const char *path[2] = {a, b};
    for (int k = 0; k < 2; k++) {
        rp_error err;
        cr_assert_eq(rp_image_read_exr(path[k], &w[k], &h[k], &nch[k], &names[k], &planes[k], &err), RP_OK, "%s: %s",
                     path[k], err.message);
    }
    cr_assert_eq(w[0], 40);
    cr_assert_eq(h[0], 32);
    cr_assert_eq(w[0], w[1]);
    cr_assert_eq(h[0], h[1]);
    cr_assert_eq(nch[0], channels);
    cr_assert_eq(nch[0], nch[1]);
    double total = 0;
    size_t all = 0;
    for (size_t c = 0; c < nch[0]; c++) {
        cr_expect_str_eq(names[0][c], names[1][c]);
        size_t differ = 0;
        for (size_t i = 0; i < (size_t)w[0] * h[0]; i++) {
            differ += memcmp(&planes[0][c][i], &planes[1][c][i], sizeof(float)) != 0;
            total += planes[0][c][i];
        }
        if (same)
            cr_expect_eq(differ, 0, "%s vs %s: channel %s: %zu pixels differ", a, b, names[0][c], differ);
        all += differ;
    }
    cr_expect(total > 0, "an image with light in it");
    for (int k = 0; k < 2; k++) {
        for (size_t c = 0; c < nch[k]; c++) {
            free(names[k][c]);
            free(planes[k][c]);
        }
        free(names[k]);
        free(planes[k]);
    }
    return all;
}

static void expect_channels(const char *a, const char *b, size_t channels)
{
    compare_channels(a, b, channels, 1);
}

static void expect_same_pixels(const char *a, const char *b) { expect_channels(a, b, 3); }

static double header_number(const char *ckpt, const char *key)
{
    FILE *f = fopen(ckpt, "rb");
    cr_assert(f, "%s", ckpt);
    char line[1600];
    double v = -1;
    size_t k = strlen(key);
    while (fgets(line, sizeof line, f) && strcmp(line, "\n") != 0)
        if (strncmp(line, key, k) == 0 && line[k] == ' ')
            v = strtod(line + k + 1, NULL);
    fclose(f);
    return v;
}

Test(checkpoint, resumed_render_is_bit_identical)
{
    make_scene();
    char full[160], part[160], mid[160], res[160], ckpt[160];
    in_dir(full, sizeof full, "full.exr");
    in_dir(part, sizeof part, "part.exr");
    in_dir(mid, sizeof mid, "mid.exr");
    in_dir(res, sizeof res, "resumed.exr");
    in_dir(ckpt, sizeof ckpt, "render.ckpt");

    rp_run r = render("--spp 8 -o %s%s", full, NULL);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    /* 3 passes, then 3 -> 5 (resumed and checkpointed again, one thread),
     * then 5 -> 8 */
    r = render("--spp 3 --checkpoint %s -o %s", ckpt, part);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "wrote checkpoint"), "stdout: %s", r.out);
    rp_run_free(&r);
    cr_expect_eq(header_number(ckpt, "iterations"), 3);
    char args[2048];
    snprintf(args, sizeof args, "render %s/cornell.scene --method pathtrace --spp 5 --threads 1 --resume %s --checkpoint %s -o %s",
             dir, ckpt, ckpt, mid);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    cr_expect_eq(header_number(ckpt, "iterations"), 5);
    r = render("--spp 8 --resume %s -o %s", ckpt, res);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    expect_same_pixels(full, res);
    /* the comparison can tell renders apart: 3 passes are not 8 */
    cr_expect_gt(compare_channels(full, part, 3, 0), 1000);
    char *samples = rp_image_read_exr_attr(res, "radpt:samples");
    cr_expect(samples && strcmp(samples, "8") == 0, "samples %s", samples ? samples : "(none)");
    free(samples);
    remove_dir();
}

/* SIGINT stops the run at a step boundary; the checkpoint then holds the
 * passes done (some number N, whatever the timing), and resuming to N + 4
 * passes matches a straight render of N + 4. */
Test(checkpoint, interrupted_render_resumes_bit_identical)
{
    make_scene();
    char scene[160], out[160], ckpt[160], full[160], res[160];
    in_dir(scene, sizeof scene, "cornell.scene");
    in_dir(out, sizeof out, "interrupted.exr");
    in_dir(ckpt, sizeof ckpt, "run.ckpt");
    in_dir(full, sizeof full, "full.exr");
    in_dir(res, sizeof res, "resumed.exr");
    pid_t pid = fork();
    cr_assert(pid >= 0);
    if (pid == 0) {
        FILE *null = freopen("/dev/null", "w", stdout);
        null = null ? freopen("/dev/null", "w", stderr) : NULL;
        (void)null;
        execl(RP_BIN, RP_BIN, "render", scene, "--method", "pathtrace", "--spp", "1000000", "--threads", "1",
              "--checkpoint", ckpt, "--checkpoint-every", "0", "-o", out, (char *)NULL);
        _exit(127);
    }
    int status = interrupt_after_checkpoint(pid, ckpt);
    cr_expect_eq(WEXITSTATUS(status), 1, "an interrupted render exits 1");
    char *flag = rp_image_read_exr_attr(out, "radpt:interrupted");
    cr_expect(flag && strcmp(flag, "yes") == 0, "interrupted image written");
    free(flag);

    double n = header_number(ckpt, "iterations");
    cr_assert(n >= 1 && n < 1000000, "checkpoint after %g passes", n);
    char spp[32];
    snprintf(spp, sizeof spp, "%.0f", n + 4);
    rp_run r = render("--spp %s -o %s", spp, full);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    char args[2048];
    char ckpt2[160];
    in_dir(ckpt2, sizeof ckpt2, "resumed.ckpt");
    snprintf(args, sizeof args, "render %s --method pathtrace --spp %s --resume %s --checkpoint %s -o %s", scene, spp,
             ckpt, ckpt2, res);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    /* it went on from N: 4 more passes, not N + 4 from the start */
    cr_expect_eq(header_number(ckpt2, "iterations"), n + 4);
    expect_same_pixels(full, res);
    remove_dir();
}

static void expect_refused(const char *args, const char *want, const char *out)
{
    rp_run r = rp_run_radpt(args);
    cr_expect_eq(r.status, 2, "'%s' exited %d; stderr: %s", args, r.status, r.err);
    cr_expect(strstr(r.err, want) != NULL, "'%s': stderr lacks '%s': %s", args, want, r.err);
    cr_expect_eq(rp_count_lines(r.err), 1, "'%s': stderr: %s", args, r.err);
    cr_expect(access(out, F_OK) != 0, "no image from a refused run");
    rp_run_free(&r);
}

Test(checkpoint, mismatched_resume_is_refused)
{
    make_scene();
    char scene[160], ckpt[160], strat[160], out[160], first[160], args[2048];
    in_dir(scene, sizeof scene, "cornell.scene");
    in_dir(ckpt, sizeof ckpt, "seed1.ckpt");
    in_dir(strat, sizeof strat, "strat.ckpt");
    in_dir(out, sizeof out, "refused.exr");
    in_dir(first, sizeof first, "first.exr");
    rp_run r = render("--spp 4 --checkpoint %s -o %s", ckpt, first);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    r = render("--spp 4 --sampler stratified --checkpoint %s -o %s", strat, first);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);

    const char *base = RP_SOURCE_DIR "/scenes/cornell.scene";
    struct {
        const char *scene, *opts, *ck, *want;
    } cases[] = {
        {scene, "--seed 2 --spp 8", ckpt, "--seed 1, this run --seed 2"},
        {base, "--spp 8", ckpt, "another scene"},
        {scene, "--spp 8 --sampler random", ckpt, "--sampler sobol, this run random"},
        {scene, "--spp 8 --max-depth 3", ckpt, "--max-depth"},
        {scene, "--spp 3", ckpt, "more than --spp 3"},
        {scene, "--spp 9 --sampler stratified", strat, "must be equal"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        snprintf(args, sizeof args, "render %s --method pathtrace %s --resume %s -o %s", cases[i].scene,
                 cases[i].opts, cases[i].ck, out);
        expect_refused(args, cases[i].want, out);
    }
    snprintf(args, sizeof args, "render %s --method southwell --resume %s -o %s", scene, ckpt, out);
    expect_refused(args, "cannot be checkpointed", out);
    /* the stratified run resumes with its own --spp */
    snprintf(args, sizeof args, "render %s --method pathtrace --spp 4 --sampler stratified --resume %s -o %s", scene,
             strat, out);
    r = rp_run_radpt(args);
    cr_expect_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    expect_same_pixels(first, out);
    remove_dir();
}

static void copy_bytes(const char *from, const char *to, long count, long flip)
{
    FILE *in = fopen(from, "rb"), *out = fopen(to, "wb");
    cr_assert(in && out);
    int c;
    for (long i = 0; (c = fgetc(in)) != EOF && (count < 0 || i < count); i++)
        fputc(i == flip ? c ^ 0x10 : c, out);
    fclose(in);
    fclose(out);
}

Test(checkpoint, damaged_checkpoint_is_refused)
{
    make_scene();
    char scene[160], ckpt[160], bad[160], out[160], first[160], args[2048];
    in_dir(scene, sizeof scene, "cornell.scene");
    in_dir(ckpt, sizeof ckpt, "good.ckpt");
    in_dir(bad, sizeof bad, "bad.ckpt");
    in_dir(out, sizeof out, "refused.exr");
    in_dir(first, sizeof first, "first.exr");
    rp_run r = render("--spp 2 --checkpoint %s -o %s", ckpt, first);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    struct stat sb;
    cr_assert_eq(stat(ckpt, &sb), 0);
    /* 40 x 32 pixels x 3 bands x 3 sums of 8 bytes, plus headers */
    cr_expect(sb.st_size > 40 * 32 * 3 * 3 * 8);
    snprintf(args, sizeof args, "render %s --method pathtrace --spp 4 --resume %s -o %s", scene, bad, out);

    copy_bytes(ckpt, bad, sb.st_size / 2, -1);        /* cut in the sums */
    expect_refused(args, "truncated", out);
    copy_bytes(ckpt, bad, 100, -1);                   /* cut in the text header */
    expect_refused(args, "not a radpt checkpoint", out);
    copy_bytes(ckpt, bad, -1, sb.st_size - 1000);     /* one bit of one sum */
    expect_refused(args, "checksum", out);
    copy_bytes(scene, bad, -1, -1);                   /* not a checkpoint at all */
    expect_refused(args, "not a radpt checkpoint", out);
    copy_bytes(ckpt, bad, -1, -1);
    FILE *f = fopen(bad, "ab");
    fputc('x', f);
    fclose(f);
    expect_refused(args, "trailing", out);
    in_dir(bad, sizeof bad, "missing.ckpt");
    snprintf(args, sizeof args, "render %s --method pathtrace --spp 4 --resume %s -o %s", scene, bad, out);
    expect_refused(args, "cannot open", out);
    remove_dir();
}

/* radpt reference --checkpoint: the same for a path-traced reference
 * (image, variance and surface averages), stopped by SIGINT and resumed
 * with a smaller --spp than it was started with (the probe batch, 256 per
 * step, does not depend on it). */
Test(checkpoint, interrupted_reference_resumes_bit_identical)
{
    make_scene();
    char scene[160], ckpt[160], cache_a[160], cache_b[160];
    in_dir(scene, sizeof scene, "cornell.scene");
    in_dir(ckpt, sizeof ckpt, "ref.ckpt");
    in_dir(cache_a, sizeof cache_a, "refs-straight");
    in_dir(cache_b, sizeof cache_b, "refs-resumed");
    pid_t pid = fork();
    cr_assert(pid >= 0);
    if (pid == 0) {
        FILE *null = freopen("/dev/null", "w", stdout);
        null = null ? freopen("/dev/null", "w", stderr) : NULL;
        (void)null;
        execl(RP_BIN, RP_BIN, "reference", scene, "--spp", "1000000", "--threads", "1", "--cache", cache_b,
              "--checkpoint", ckpt, "--checkpoint-every", "1e-6", (char *)NULL);
        _exit(127);
    }
    int status = interrupt_after_checkpoint(pid, ckpt);
    cr_expect_eq(WEXITSTATUS(status), 1, "an interrupted reference exits 1");

    double n = header_number(ckpt, "iterations");
    cr_assert(n >= 1 && n < 1000000, "checkpoint after %g steps", n);
    char args[2048];
    snprintf(args, sizeof args, "reference %s --spp %.0f --cache %s --json", scene, n + 3, cache_a);
    rp_run a = rp_run_radpt(args);
    cr_assert_eq(a.status, 0, "stderr: %s", a.err);
    snprintf(args, sizeof args, "reference %s --spp %.0f --cache %s --resume %s --checkpoint %s --json", scene, n + 3,
             cache_b, ckpt, ckpt);
    rp_run b = rp_run_radpt(args);
    cr_assert_eq(b.status, 0, "stderr: %s", b.err);
    cr_expect_eq(header_number(ckpt, "steps"), n + 3, "went on from the checkpoint");
    /* the same key, so the same file name in each cache */
    const char *ia = strstr(a.out, "\"image\": \""), *ib = strstr(b.out, "\"image\": \"");
    cr_assert(ia && ib, "%s", a.out);
    char pa[256], pb[256];
    sscanf(ia + 10, "%255[^\"]", pa);
    sscanf(ib + 10, "%255[^\"]", pb);
    expect_channels(pa, pb, 6);
    const char *attrs[] = {"radpt:surface_radiance", "radpt:surface_stderr", "radpt:reference_key"};
    for (int k = 0; k < 3; k++) {
        char *va = rp_image_read_exr_attr(pa, attrs[k]), *vb = rp_image_read_exr_attr(pb, attrs[k]);
        cr_expect(va && vb && strcmp(va, vb) == 0, "%s differs", attrs[k]);
        free(va);
        free(vb);
    }
    rp_run_free(&a);
    rp_run_free(&b);
    remove_dir();
}
