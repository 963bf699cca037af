/* End-to-end: the radpt command as a user runs it (docs/design.md, "Command
 * line"): exit statuses, one-line errors, JSON, no partial output files. */
#include <criterion/criterion.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include "bench/report/image.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench/experiments/experiments.h"
#include "cli_util.h"

/* Area of a planar polygon from its vertices (Newell's method), written
 * here independently of geometry/scene.c. */
static double polygon_area(const double (*v)[3], int n)
{
    double nx = 0, ny = 0, nz = 0;
    for (int i = 0; i < n; i++) {
        const double *a = v[i], *b = v[(i + 1) % n];
        nx += (a[1] - b[1]) * (a[2] + b[2]);
        ny += (a[2] - b[2]) * (a[0] + b[0]);
        nz += (a[0] - b[0]) * (a[1] + b[1]);
    }
    return 0.5 * sqrt(nx * nx + ny * ny + nz * nz);
}

static double surface_area(const char *json, const char *name)
{
    char anchor[96];
    snprintf(anchor, sizeof anchor, "\"name\": \"%s\"", name);
    /* surfaces come after materials, which may share a name ("light") */
    const char *surfaces = strstr(json, "\"surfaces\":");
    return surfaces ? rp_json_number_after(surfaces, anchor, "area") : NAN;
}

/* docs/ground-truth.md, the Cornell box (millimetres). */
Test(cli, cornell_info_areas_match_measured_geometry)
{
    rp_run r = rp_run_radpt("info scenes/cornell.scene --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    const double floor_v[4][3] = {{552.8, 0, 0}, {0, 0, 0}, {0, 0, 559.2}, {549.6, 0, 559.2}};
    const double back_v[4][3] = {{549.6, 0, 559.2}, {0, 0, 559.2}, {0, 548.8, 559.2}, {556.0, 548.8, 559.2}};
    const double green_v[4][3] = {{0, 0, 559.2}, {0, 0, 0}, {0, 548.8, 0}, {0, 548.8, 559.2}};
    const double red_a[3][3] = {{552.8, 0, 0}, {549.6, 0, 559.2}, {556.0, 548.8, 559.2}};
    const double red_b[3][3] = {{552.8, 0, 0}, {556.0, 548.8, 559.2}, {556.0, 548.8, 0}};
    const double light = 130.0 * 105.0;
    const double ceiling = 556.0 * 559.2 - light;
    const double tol = 1e-4; /* 0.01% */

    double floor = surface_area(r.out, "floor");
    cr_expect(fabs(floor / polygon_area(floor_v, 4) - 1) < tol, "floor %g", floor);
    cr_expect(fabs(surface_area(r.out, "back") / polygon_area(back_v, 4) - 1) < tol);
    cr_expect(fabs(surface_area(r.out, "right-green") / polygon_area(green_v, 4) - 1) < tol);
    double red = surface_area(r.out, "left-red-low") + surface_area(r.out, "left-red-high");
    cr_expect(fabs(red / (polygon_area(red_a, 3) + polygon_area(red_b, 3)) - 1) < tol, "red %g", red);
    cr_expect(fabs(surface_area(r.out, "light") / light - 1) < tol);
    double ceil_sum = surface_area(r.out, "ceiling-front") + surface_area(r.out, "ceiling-back") +
                      surface_area(r.out, "ceiling-left") + surface_area(r.out, "ceiling-right");
    cr_expect(fabs(ceil_sum / ceiling - 1) < tol, "ceiling %g vs %g", ceil_sum, ceiling);
    /* Short block top: 130 165 65 | 82 165 225 | 240 165 272 | 290 165 114 */
    const double short_top[4][3] = {{130, 165, 65}, {82, 165, 225}, {240, 165, 272}, {290, 165, 114}};
    cr_expect(fabs(surface_area(r.out, "short-top") / polygon_area(short_top, 4) - 1) < tol);
    cr_expect(strstr(r.out, "\"closed\": false") != NULL, "the Cornell box is open");
    rp_run_free(&r);
}

Test(cli, furnace_is_closed)
{
    rp_run r = rp_run_radpt("info scenes/furnace.scene --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "\"closed\": true") != NULL, "%s", r.out);
    rp_run_free(&r);
}

Test(cli, unknown_method_lists_the_known_ones)
{
    rp_run r = rp_run_radpt("render scenes/cornell.scene --method nosuch -o /tmp/rp_nosuch.exr");
    cr_expect_eq(r.status, 2);
    cr_expect(strstr(r.err, "nosuch") && strstr(r.err, "pathtrace"), "stderr: %s", r.err);
    cr_expect(access("/tmp/rp_nosuch.exr", F_OK) != 0);
    rp_run_free(&r);
}

Test(cli, usage_errors_exit_2)
{
    /* Outputs go to a fresh directory, so a file left by anyone else
     * cannot stand in for (or hide) one written by a refused run. */
    char dir[] = "/tmp/radpt-usage-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    const char *cases[] = {
        "",
        "frobnicate scenes/cornell.scene",
        "info",
        "info scenes/cornell.scene --bogus",
        "render scenes/cornell.scene -o @/x.exr",
        "render scenes/cornell.scene --method pathtrace",
        "render scenes/cornell.scene --method pathtrace --threads 0 -o @/x.exr",
        "render scenes/cornell.scene --method pathtrace --time -3 -o @/x.exr",
        "render scenes/cornell.scene --method pathtrace --seed banana -o @/x.exr",
        "render scenes/cornell.scene --method pathtrace --spp 0 -o @/x.exr",
        "render scenes/cornell.scene --method pathtrace --no-such-option 3 -o @/x.exr",
        "probe scenes/cornell.scene --method pathtrace",
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char cmd[512], *at;
        snprintf(cmd, sizeof cmd, "%s", cases[i]);
        if ((at = strchr(cmd, '@')) != NULL) /* @ stands for the directory */
            snprintf(at, sizeof cmd - (size_t)(at - cmd), "%s/x.exr", dir);
        rp_run r = rp_run_radpt(cmd);
        cr_expect_eq(r.status, 2, "'%s' exited %d; stderr: %s", cases[i], r.status, r.err);
        cr_expect(r.err[0] != '\0', "'%s' says nothing on stderr", cases[i]);
        rp_run_free(&r);
    }
    /* A count's message says what is wrong with it. */
    const char *counts[][2] = {
        {"render scenes/cornell.scene --method pathtrace --spp -4 -o @/x.exr", "'-4' is not a whole number in [1, "},
        {"render scenes/cornell.scene --method pathtrace --spp 99999999999999999999 -o @/x.exr",
         "99999999999999999999 is outside [1, "},
        {"render scenes/cornell.scene --method pathtrace --spp 4x -o @/x.exr", "'4x' is not a whole number"},
    };
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++) {
        char cmd[512], *at;
        snprintf(cmd, sizeof cmd, "%s", counts[i][0]);
        if ((at = strchr(cmd, '@')) != NULL)
            snprintf(at, sizeof cmd - (size_t)(at - cmd), "%s/x.exr", dir);
        rp_run r = rp_run_radpt(cmd);
        cr_expect_eq(r.status, 2, "'%s' exited %d", counts[i][0], r.status);
        cr_expect(strstr(r.err, counts[i][1]) != NULL, "'%s': %s", counts[i][0], r.err);
        rp_run_free(&r);
    }
    char out[64];
    snprintf(out, sizeof out, "%s/x.exr", dir);
    cr_expect(access(out, F_OK) != 0, "no output file from a refused run");
    cr_expect_eq(rmdir(dir), 0, "%s holds a file from a refused run", dir);
}

Test(cli, help_lists_commands_and_methods)
{
    rp_run r = rp_run_radpt("help");
    cr_expect_eq(r.status, 0);
    cr_expect(strstr(r.out, "radpt info") && strstr(r.out, "radpt render") && strstr(r.out, "pathtrace"));
    rp_run_free(&r);
    r = rp_run_radpt("help pathtrace");
    cr_expect_eq(r.status, 0);
    cr_expect(strstr(r.out, "--spp") && strstr(r.out, "--sampler"), "%s", r.out);
    rp_run_free(&r);
}

/* Every malformed scene in tests/bad/ gets one line, FILE:LINE:, status 2. */
Test(cli, bad_scenes_one_line_error_status_2)
{
    FILE *ls = popen("cd '" RP_SOURCE_DIR "' && ls tests/bad/*.scene", "r");
    cr_assert(ls);
    char path[512];
    int n = 0;
    while (fgets(path, sizeof path, ls)) {
        path[strcspn(path, "\n")] = '\0';
        char args[600];
        snprintf(args, sizeof args, "info %s", path);
        rp_run r = rp_run_radpt(args);
        cr_expect_eq(r.status, 2, "%s exited %d", path, r.status);
        cr_expect_eq(rp_count_lines(r.err), 1, "%s: stderr has %zu lines: %s", path,
                     rp_count_lines(r.err), r.err);
        /* "radpt: FILE:LINE: what" where FILE is the scene or what it includes */
        const char *msg = strncmp(r.err, "radpt: ", 7) == 0 ? r.err + 7 : r.err;
        const char *colon = strchr(msg, ':');
        cr_expect(colon && colon[1] >= '0' && colon[1] <= '9', "%s: no FILE:LINE: in '%s'", path, r.err);
        cr_expect_eq(r.out[0], '\0', "%s: printed on stdout", path);
        rp_run_free(&r);
        n++;
    }
    pclose(ls);
    cr_expect(n >= 20, "only %d bad scenes", n);
}

Test(cli, render_writes_exr_with_metadata_and_fails_cleanly)
{
    unlink("/tmp/rp_cli_furnace.exr");
    rp_run r = rp_run_radpt("render scenes/furnace.scene --method pathtrace --spp 2 --seed 7 "
                            "-o /tmp/rp_cli_furnace.exr");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(access("/tmp/rp_cli_furnace.exr", F_OK) == 0);
    rp_run_free(&r);
    FILE *h = popen("exrheader /tmp/rp_cli_furnace.exr 2>&1", "r");
    if (h) {
        char buf[8192];
        size_t got = fread(buf, 1, sizeof buf - 1, h);
        buf[got] = '\0';
        pclose(h);
        if (strstr(buf, "channels")) {
            cr_expect(strstr(buf, "Y, 32-bit floating-point") != NULL, "%s", buf);
            cr_expect(strstr(buf, "radpt:seed") && strstr(buf, "radpt:method"), "%s", buf);
            /* the options given, and every other one at its default */
            const char *o = strstr(buf, "radpt:options"), *d = strstr(buf, "radpt:defaults");
            cr_assert(o && d, "%s", buf);
            char line[512];
            snprintf(line, sizeof line, "%.*s", (int)strcspn(o, "\n"), o);
            cr_expect(strstr(line, "\"--spp 2\""), "%s", line);
            snprintf(line, sizeof line, "%.*s", (int)strcspn(d, "\n"), d);
            cr_expect(strstr(line, "--sampler sobol") && strstr(line, "--max-depth unlimited"), "%s", line);
            cr_expect_null(strstr(line, "--spp"), "a given option among the defaults: %s", line);
        }
    }
    unlink("/tmp/rp_cli_furnace.exr");

    r = rp_run_radpt("render scenes/furnace.scene --method pathtrace --spp 1 "
                     "-o /tmp/rp-no-such-dir/out.exr");
    /* refused before rendering: a usage error, not a failure at the end */
    cr_expect_eq(r.status, 2, "stderr: %s", r.err);
    cr_expect(strstr(r.err, "does not exist") != NULL, "stderr: %s", r.err);
    cr_expect(access("/tmp/rp-no-such-dir", F_OK) != 0);
    rp_run_free(&r);

    /* an output name that is a directory: refused before rendering too,
     * not when the finished image is renamed onto it */
    cr_assert(mkdir("/tmp/rp_cli_dir.exr", 0700) == 0 || errno == EEXIST);
    r = rp_run_radpt("render scenes/furnace.scene --method pathtrace --spp 1 -o /tmp/rp_cli_dir.exr");
    cr_expect_eq(r.status, 2, "stderr: %s", r.err);
    cr_expect(strstr(r.err, "is a directory") != NULL, "stderr: %s", r.err);
    rp_run_free(&r);
    rmdir("/tmp/rp_cli_dir.exr");
}

/* tests/bad/commands.tsv: malformed command lines and non-scene inputs, each
 * with its exit status and a piece of its one-line message. */
Test(cli, command_catalogue)
{
    FILE *f = fopen(RP_SOURCE_DIR "/tests/bad/commands.tsv", "r");
    cr_assert(f);
    char line[1024];
    int n = 0;
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\n")] = '\0';
        if (line[0] == '#' || line[0] == '\0')
            continue;
        char *tab1 = strchr(line, '\t');
        char *tab2 = tab1 ? strchr(tab1 + 1, '\t') : NULL;
        cr_assert(tab1 && tab2, "malformed catalogue line: %s", line);
        *tab1 = *tab2 = '\0';
        int status = atoi(line);
        const char *args = tab1 + 1, *want = tab2 + 1;
        rp_run r = rp_run_radpt(args);
        cr_expect_eq(r.status, status, "'%s' exited %d, not %d; stderr: %s", args, r.status, status, r.err);
        cr_expect(strstr(r.err, want) != NULL, "'%s': stderr lacks '%s': %s", args, want, r.err);
        cr_expect_eq(rp_count_lines(r.err), 1, "'%s': stderr has %zu lines", args, rp_count_lines(r.err));
        rp_run_free(&r);
        n++;
    }
    fclose(f);
    cr_expect(n >= 30, "only %d catalogue entries", n);
    cr_expect(access("/tmp/radpt-bad.exr", F_OK) != 0, "no output file from a refused run");
    cr_expect(access("/tmp/radpt-bad-dir", F_OK) != 0, "no output directory from a refused run");
}

/* Hierarchical radiosity reports what SPLASH-2's radiosity does (issue 5):
 * leaves, links split into fully visible, partial and invisible, and the
 * equivalent uniform mesh, on stderr with the method's other messages. */
Test(cli, hierarchical_reports_leaves_and_links)
{
    rp_run r = rp_run_radpt(
        "probe scenes/cornell.scene --method hierarchical --bf-epsilon 0.3 --min-area 1e-3 --surface-averages");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    const char *want[] = {"leaves", "fully visible", "partial", "invisible", "equivalent uniform mesh", "initial links"};
    for (size_t k = 0; k < sizeof want / sizeof *want; k++)
        cr_expect(strstr(r.err, want[k]) != NULL, "stderr lacks '%s': %s", want[k], r.err);
    rp_run_free(&r);
}

/* ------------------------------------------------------ OBJ scenes, --camera */

#define MCGUIRE "tests/data/CornellBox-Original.obj"

/* The n-th (0-based) occurrence of needle in s, or NULL. */
static const char *nth(const char *s, const char *needle, int n)
{
    const char *p = strstr(s, needle);
    while (p && n-- > 0)
        p = strstr(p + 1, needle);
    return p;
}

static int count_of(const char *s, const char *needle)
{
    int n = 0;
    while (nth(s, needle, n))
        n++;
    return n;
}

/* The words inside --camera "..." in text, into buf. */
static int camera_words_in(const char *text, char *buf, size_t len)
{
    const char *p = strstr(text, "--camera \"");
    if (!p)
        return 0;
    p += strlen("--camera \"");
    const char *q = strchr(p, '"');
    if (!q || (size_t)(q - p) >= len)
        return 0;
    memcpy(buf, p, (size_t)(q - p));
    buf[q - p] = '\0';
    return 1;
}

/* The 16 hex digits after "key": " in a JSON text. */
static void json_hash(const char *json, const char *key, char out[17])
{
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\": \"", key);
    const char *p = strstr(json, pat);
    cr_assert_not_null(p, "no %s in %s", key, json);
    memcpy(out, p + strlen(pat), 16);
    out[16] = '\0';
}

/* Every command that loads a scene takes an OBJ directly; the ones that
 * need a camera use the default one and say which, as --camera words. */
Test(cli, obj_scene_on_every_command)
{
    char dir[] = "/tmp/radpt-obj-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char args[1024];
    const char *cmds[] = {
        "info " MCGUIRE,
        "probe " MCGUIRE " --method pathtrace --surface-averages --samples 64",
        "formfactor " MCGUIRE " --from light --to floor --method montecarlo --samples 1000",
        "render " MCGUIRE " --method pathtrace --spp 1 -o @/r.exr",
        "reference " MCGUIRE " --spp 1 --samples 64 --cache @/refs",
        "bench " MCGUIRE " --methods pathtrace:spp=1 --budget 0.2 --checkpoints 1 --seeds 1 --reference-spp 1 "
        "--reference-samples 64 --cache @/refs -o @/bench",
        "throughput " MCGUIRE " --spp 1 --rays 1000",
        "samplers " MCGUIRE " --spp 1 --reference-spp 2 --seeds 1",
    };
    const int needs_camera[] = {0, 0, 0, 1, 1, 1, 1, 1};
    for (size_t i = 0; i < sizeof cmds / sizeof *cmds; i++) {
        /* @ stands for the directory */
        size_t n = 0;
        for (const char *c = cmds[i]; *c && n + 64 < sizeof args; c++)
            n += (size_t)(*c == '@' ? snprintf(args + n, sizeof args - n, "%s", dir)
                                    : snprintf(args + n, sizeof args - n, "%c", *c));
        rp_run r = rp_run_radpt(args);
        cr_expect_eq(r.status, 0, "'%s' exited %d: %s", args, r.status, r.err);
        /* the .mtl's two warnings, once each */
        cr_expect_eq(count_of(r.err, "radpt: warning: tests/data/CornellBox-Original.mtl:"), 2, "'%s': %s", args,
                     r.err);
        cr_expect_eq(strstr(r.err, "using the default, which is --camera \"") != NULL, needs_camera[i],
                     "'%s': %s", args, r.err);
        rp_run_free(&r);
    }
    snprintf(args, sizeof args, "rm -rf '%s'", dir);
    cr_expect_eq(system(args), 0);
}

/* The printed default camera, given back with --camera, is the same
 * camera: the reference's scene hash (which includes the camera) matches
 * info's for the scene with that --camera, and differs without it. */
Test(cli, default_camera_printed_and_given_back)
{
    char dir[] = "/tmp/radpt-cam-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char args[1024], words[512], h_ref[17], h_cam[17], h_none[17];
    snprintf(args, sizeof args, "reference " MCGUIRE " --spp 1 --samples 16 --cache %s --json", dir);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_assert(camera_words_in(r.err, words, sizeof words), "no --camera words in: %s", r.err);
    json_hash(r.out, "scene_hash", h_ref);
    rp_run_free(&r);
    snprintf(args, sizeof args, "info " MCGUIRE " --json --camera \"%s\"", words);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    json_hash(r.out, "hash", h_cam);
    cr_expect(strstr(r.out, "\"fov_deg\": 40,") != NULL, "%s", r.out);
    rp_run_free(&r);
    r = rp_run_radpt("info " MCGUIRE " --json");
    json_hash(r.out, "hash", h_none);
    /* info needs no camera: none set, the default one shown */
    cr_expect(strstr(r.out, "\"camera\": null") != NULL);
    cr_expect(strstr(r.out, words) != NULL, "default_camera '%s' not in %s", words, r.out);
    rp_run_free(&r);
    cr_expect_str_eq(h_ref, h_cam);
    cr_expect_str_neq(h_ref, h_none);
    snprintf(args, sizeof args, "rm -rf '%s'", dir);
    cr_expect_eq(system(args), 0);
}

/* --camera replaces a scene's own camera. */
Test(cli, camera_overrides)
{
    rp_run r = rp_run_radpt("info scenes/cornell.scene --json");
    char h0[17], h1[17];
    json_hash(r.out, "hash", h0);
    rp_run_free(&r);
    r = rp_run_radpt("info scenes/cornell.scene --json --camera 'eye 1 2 3 look 1 2 4 up 0 1 0 fov 30 size 64 32'");
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "\"camera\": {\"eye\": [1, 2, 3], \"look\": [1, 2, 4], \"up\": [0, 1, 0], "
                            "\"fov_deg\": 30, \"width\": 64, \"height\": 32}") != NULL,
              "%s", r.out);
    json_hash(r.out, "hash", h1);
    cr_expect_str_neq(h0, h1);
    rp_run_free(&r);
    /* and the render is that camera's size */
    unlink("/tmp/rp_cli_camera.exr");
    r = rp_run_radpt("render scenes/furnace.scene --method pathtrace --spp 1 --camera "
                     "'eye 0.5 0.5 0.5 look 0.5 0.5 0 up 0 1 0 fov 60 size 12 7' -o /tmp/rp_cli_camera.exr");
    cr_expect_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "12 x 7") != NULL, "%s", r.out);
    rp_run_free(&r);
    unlink("/tmp/rp_cli_camera.exr");
}

Test(cli, bad_camera_words_exit_2)
{
    const char *cases[] = {
        "info scenes/cornell.scene --camera 'eye 1 2'",
        "info scenes/cornell.scene --camera ''",
        "probe scenes/cornell.scene --method pathtrace --surface-averages --camera 'eye 0 0 0 look 0 0 0 up 0 1 0 "
        "fov 40 size 8 8'",
        "render scenes/cornell.scene --method pathtrace --camera 'eye 0 0 0 look 0 0 1 up 0 1 0 fov 200 size 8 8' "
        "-o /tmp/radpt-bad.exr",
        "formfactor scenes/plates-parallel.scene --from emitter --to receiver --camera 'fov 40'",
        "reference scenes/cornell.scene --camera 'eye 0 0 0 look 0 0 1 up 0 1 0 fov 40 size 8 8 roll 3'",
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        rp_run r = rp_run_radpt(cases[i]);
        cr_expect_eq(r.status, 2, "'%s' exited %d", cases[i], r.status);
        cr_expect(strncmp(r.err, "radpt: --camera: ", 17) == 0, "'%s': %s", cases[i], r.err);
        cr_expect_eq(rp_count_lines(r.err), 1, "'%s': %s", cases[i], r.err);
        rp_run_free(&r);
    }
    cr_expect(access("/tmp/radpt-bad.exr", F_OK) != 0);
}

/* Names with a space are quoted in info's columns, plain in JSON; every
 * warning is printed once and listed in JSON. */
Test(cli, names_quoted_warnings_listed)
{
    rp_run r = rp_run_radpt("info tests/data/names.obj");
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "\n\"left wall\" ") != NULL, "%s", r.out);
    cr_expect(strstr(r.out, "\na.white~2 ") != NULL, "%s", r.out);
    rp_run_free(&r);
    r = rp_run_radpt("info tests/data/names.obj --json");
    cr_expect(strstr(r.out, "{\"name\": \"left wall\", \"material\": \"white\"") != NULL, "%s", r.out);
    rp_run_free(&r);
    r = rp_run_radpt("info tests/data/drops.obj --json");
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect_eq(count_of(r.err, "radpt: warning: tests/data/drops.obj:"), 3, "%s", r.err);
    cr_expect_eq(rp_count_lines(r.err), 3, "%s", r.err);
    const char *w = strstr(r.out, "\"warnings\": [");
    cr_assert_not_null(w, "%s", r.out);
    cr_expect(strstr(w, "\"tests/data/drops.obj:20: 2 exact duplicate faces dropped") != NULL, "%s", w);
    cr_expect(strstr(w, "\"tests/data/drops.obj:26: 2 zero-area faces dropped") != NULL, "%s", w);
    rp_run_free(&r);
}

/* An OBJ's groups are surfaces the command line can name: scene.obj's floor
 * and lamp are directly opposed unit squares 1 apart, whose form factor is
 * Howell's C-11 with a = b = c = 1 (docs/ground-truth.md). */
Test(cli, formfactor_between_obj_groups)
{
    rp_run r = rp_run_radpt("formfactor tests/data/scene.obj --from floor --to lamp --method analytic --json");
    cr_assert_eq(r.status, 0, "%s", r.err);
    double f = rp_json_number_after(r.out, "{", "form_factor");
    cr_expect(fabs(f - 0.1998248957) < 1e-6, "F = %.10g: %s", f, r.out);
    rp_run_free(&r);
}

/* An OBJ furnace: a closed cube, Kd 0.5 and Ke 1 on every face (one value:
 * grey), so L = Le / (1 - rho) = 2 in every band.  The reference is exact;
 * the path tracer's surface average lies within 4 standard errors. */
Test(cli, obj_furnace_closed_form)
{
    char dir[] = "/tmp/radpt-furnace-XXXXXX", args[512];
    cr_assert_not_null(mkdtemp(dir));
    snprintf(args, sizeof args, "reference tests/data/furnace-cube.obj --cache %s --json", dir);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "\"kind\": \"exact\"") != NULL, "%s", r.out);
    cr_expect(strstr(r.out, "\"radiance\": [2, 2, 2]") != NULL, "%s", r.out);
    rp_run_free(&r);
    snprintf(args, sizeof args, "rm -rf '%s'", dir);
    cr_expect_eq(system(args), 0);

    r = rp_run_radpt("probe tests/data/furnace-cube.obj --method pathtrace --surface-averages --samples 4096 "
                     "--seed 3 --json");
    cr_assert_eq(r.status, 0, "%s", r.err);
    const char *p = strstr(r.out, "\"radiance\": [");
    const char *q = strstr(r.out, "\"stderr\": [");
    cr_assert(p && q, "%s", r.out);
    p += strlen("\"radiance\": [");
    q += strlen("\"stderr\": [");
    for (int b = 0; b < 3; b++) {
        char *e1, *e2;
        double L = strtod(p, &e1), se = strtod(q, &e2);
        cr_expect(fabs(L - 2) <= 4 * se + 1e-12, "band %d: L = %g +- %g, not 2", b, L, se);
        cr_expect_gt(se, 0);
        p = e1 + 1;
        q = e2 + 1;
    }
    rp_run_free(&r);
}

/* McGuire's box: the path tracer's surface averages agree with radiosity
 * (Gauss-Seidel, 400 elements, an independent method on the same scene)
 * within 4 of the path tracer's standard errors plus 2% of the value (the
 * radiosity mesh's own error), and the light, which emits 17 12 4 and
 * reflects 0.78, shows more than its emission by many standard errors. */
Test(cli, mcguire_box_path_tracer_agrees_with_radiosity)
{
    rp_run pt = rp_run_radpt("probe " MCGUIRE " --method pathtrace --surface-averages --samples 16384 --json");
    rp_run gs = rp_run_radpt("probe " MCGUIRE " --method gauss-seidel --elements 400 --surface-averages --json");
    cr_assert_eq(pt.status, 0, "%s", pt.err);
    cr_assert_eq(gs.status, 0, "%s", gs.err);
    const char *names[] = {"floor", "ceiling", "backWall", "rightWall", "leftWall", "light"};
    for (size_t i = 0; i < sizeof names / sizeof *names; i++) {
        char anchor[64];
        snprintf(anchor, sizeof anchor, "{\"name\": \"%s\"", names[i]);
        const char *a = strstr(pt.out, anchor), *b = strstr(gs.out, anchor);
        cr_assert(a && b, "%s missing", names[i]);
        a = strstr(a, "\"radiance\": [") + 13;
        b = strstr(b, "\"radiance\": [") + 13;
        const char *s = strstr(a, "\"stderr\": [") + 11;
        for (int k = 0; k < 3; k++) {
            char *ea, *eb, *es;
            double x = strtod(a, &ea), y = strtod(b, &eb), se = strtod(s, &es);
            cr_expect(fabs(x - y) <= 4 * se + 0.02 * y, "%s band %d: path tracer %g +- %g, radiosity %g", names[i],
                      k, x, se, y);
            cr_expect_gt(x, 0, "%s band %d is black", names[i], k);
            if (!strcmp(names[i], "light")) {
                const double le[3] = {17, 12, 4};
                cr_expect_gt(x - le[k], 10 * se, "light band %d: %g +- %g reflects nothing beyond Le", k, x, se);
            }
            a = ea + 1, b = eb + 1, s = es + 1;
        }
    }
    rp_run_free(&pt);
    rp_run_free(&gs);
}

/* ---- runs that stop early (issue 13, part 4) ---------------------------- */

static double mono_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* SIGTERM while a uniform solver computes its form-factor matrix (the
 * set-up: n^2 / 2 pairs, about 15 s of CPU for 8,000 elements of the
 * Cornell box, minutes under a sanitizer): the run ends at once, exit
 * status 1, no output file, and the message says it was interrupted.
 * The bound on the time to stop is generous (10 s) for loaded machines;
 * without the cancellation flag the set-up alone takes longer. */
Test(cli, sigterm_during_uniform_setup_ends_the_run, .timeout = 300)
{
    char out[64], errp[64];
    snprintf(out, sizeof out, "/tmp/rp_sigterm.%d.exr", (int)getpid());
    snprintf(errp, sizeof errp, "/tmp/rp_sigterm.%d.err", (int)getpid());
    unlink(out);
    unlink(errp);
    pid_t pid = fork();
    cr_assert_geq(pid, 0);
    if (pid == 0) {
        int fe = open(errp, O_WRONLY | O_CREAT | O_TRUNC, 0644), fo = open("/dev/null", O_WRONLY);
        if (fe < 0 || fo < 0 || chdir(RP_SOURCE_DIR) != 0)
            _exit(127);
        dup2(fe, 2);
        dup2(fo, 1);
        execl(RP_BIN, RP_BIN, "render", "scenes/cornell.scene", "--method", "gauss-seidel", "--elements", "8000",
              "-o", out, (char *)NULL);
        _exit(127);
    }
    /* The solver's first message ends its init; the matrix comes next. */
    int started = 0, status = 0;
    for (int i = 0; i < 2400 && !started; i++) {
        char *e = rp_read_file(errp);
        started = e && strstr(e, "dense single-precision matrix");
        free(e);
        if (!started) {
            cr_assert_eq(waitpid(pid, &status, WNOHANG), 0, "radpt ended before its set-up");
            struct timespec ts = {0, 50000000};
            nanosleep(&ts, NULL);
        }
    }
    if (!started)
        kill(pid, SIGKILL);
    cr_assert(started, "no set-up message from radpt in 120 s");
    struct timespec ts = {0, 500000000};
    nanosleep(&ts, NULL);
    double t0 = mono_seconds();
    cr_assert_eq(kill(pid, SIGTERM), 0);
    cr_assert_eq(waitpid(pid, &status, 0), pid);
    double dt = mono_seconds() - t0;
    char *e = rp_read_file(errp);
    cr_assert(e);
    cr_expect(WIFEXITED(status) && WEXITSTATUS(status) == 1, "status %d; stderr: %s", status, e);
    cr_expect_lt(dt, 10.0, "took %.1f s to stop after SIGTERM", dt);
    cr_expect(strstr(e, "interrupted") != NULL, "stderr: %s", e);
    cr_expect(strstr(e, "form factors computed") == NULL, "the matrix was finished: %s", e);
    cr_expect(access(out, F_OK) != 0, "an interrupted run left %s", out);
    free(e);
    unlink(errp);
    unlink(out);
}

/* --target-error stops the path tracer's probe; render says it ignores it
 * rather than silently rendering the same image. */
Test(cli, target_error_applies_to_probe_only, .timeout = 60)
{
    char out[64], args[256];
    snprintf(out, sizeof out, "/tmp/rp_target_error.%d.exr", (int)getpid());
    snprintf(args, sizeof args, "render scenes/cornell.scene --method pathtrace --spp 1 --target-error 0.01 -o %s", out);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.err, "warning: pathtrace: --target-error 0.01 ignored: it applies to surface averages") != NULL,
              "stderr: %s", r.err);
    rp_run_free(&r);
    unlink(out);
    r = rp_run_radpt("probe scenes/cornell.scene --method pathtrace --surface-averages --target-error 0.05 "
                     "--samples 1048576 --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.err, "ignored") == NULL, "stderr: %s", r.err);
    double n = rp_json_number_after(r.out, "{", "samples");
    cr_expect(n >= 1024 && n < 1048576, "%g samples per surface", n);
    rp_run_free(&r);
}

/* A run cut short by --max-iterations or --time reports converged: false
 * and its residual (probe --json; render's EXR metadata) and warns on
 * stderr; a converged one reports converged: true with residual <=
 * tolerance; a method without a residual reports null.  probe --json
 * gives the process's peak resident size beside the method's memory. */
Test(cli, unconverged_runs_say_so, .timeout = 120)
{
    rp_run r = rp_run_radpt("probe scenes/cornell.scene --method gauss-seidel --elements 200 --max-iterations 2 "
                            "--surface-averages --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "\"converged\": false") != NULL, "%s", r.out);
    double res = rp_json_number_after(r.out, "{", "residual"), tol = rp_json_number_after(r.out, "{", "tolerance");
    cr_expect(res > tol && tol == 1e-6, "residual %g, tolerance %g", res, tol);
    cr_expect(strstr(r.out, "\"stopped_by\": \"iterations\"") != NULL, "%s", r.out);
    /* the process's peak resident size holds at least what the method
     * says it holds */
    double held = rp_json_number_after(r.out, "{", "memory_bytes"), peak = rp_json_number_after(r.out, "{", "peak_rss_bytes");
    cr_expect(held > 0 && peak >= held, "memory_bytes %g, peak_rss_bytes %g", held, peak);
    cr_expect(strstr(r.err, "warning: gauss-seidel stopped by --max-iterations after 2 sweeps, residual") &&
                  strstr(r.err, "not converged"),
              "stderr: %s", r.err);
    rp_run_free(&r);

    r = rp_run_radpt("probe scenes/cornell.scene --method southwell --elements 200 --time 1e-9 "
                     "--surface-averages --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "\"converged\": false") && strstr(r.out, "\"stopped_by\": \"time\""), "%s", r.out);
    cr_expect(strstr(r.err, "warning: southwell stopped by --time after 1 shots") != NULL, "stderr: %s", r.err);
    rp_run_free(&r);

    r = rp_run_radpt("probe scenes/cornell.scene --method gauss-seidel --elements 200 --tolerance 1e-4 "
                     "--surface-averages --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "\"converged\": true") != NULL, "%s", r.out);
    res = rp_json_number_after(r.out, "{", "residual");
    cr_expect(res <= 1e-4 && res >= 0, "residual %g", res);
    cr_expect(strstr(r.err, "not converged") == NULL, "stderr: %s", r.err);
    rp_run_free(&r);

    r = rp_run_radpt("probe scenes/cornell.scene --method pathtrace --samples 16 --surface-averages --json");
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.out, "\"converged\": null, \"residual\": null") != NULL, "%s", r.out);
    rp_run_free(&r);

    char out[64];
    snprintf(out, sizeof out, "/tmp/rp_unconverged.%d.exr", (int)getpid());
    char args[256];
    snprintf(args, sizeof args, "render scenes/cornell.scene --method jacobi --elements 200 --max-iterations 3 --spp 1 "
             "-o %s", out);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_expect(strstr(r.err, "warning: jacobi stopped by --max-iterations after 3 sweeps") != NULL, "stderr: %s", r.err);
    char *conv = rp_image_read_exr_attr(out, "radpt:converged");
    char *rtext = rp_image_read_exr_attr(out, "radpt:residual");
    cr_expect(conv && strcmp(conv, "no") == 0, "radpt:converged %s", conv ? conv : "(none)");
    cr_expect(rtext && strtod(rtext, NULL) > 1e-6, "radpt:residual %s", rtext ? rtext : "(none)");
    free(conv);
    free(rtext);
    rp_run_free(&r);
    unlink(out);
}

/* `help` and `experiment --list` are generated from the registry: every
 * registered experiment is named in both, with its summary. */
Test(cli, help_and_list_name_every_experiment)
{
    rp_run h = rp_run_radpt("help"), l = rp_run_radpt("experiment --list");
    cr_assert_eq(h.status, 0);
    cr_assert_eq(l.status, 0);
    size_t n = 0;
    for (const rp_experiment *const *e = rp_experiments(); *e; e++, n++) {
        cr_expect(strstr(h.out, (*e)->name) && strstr(h.out, (*e)->summary), "help lacks %s", (*e)->name);
        cr_expect(strstr(l.out, (*e)->name) && strstr(l.out, (*e)->summary), "--list lacks %s", (*e)->name);
        char args[128];
        snprintf(args, sizeof args, "help experiment %s", (*e)->name);
        rp_run d = rp_run_radpt(args);
        cr_expect_eq(d.status, 0);
        cr_expect(strstr(d.out, "claim checked:") && (*e)->claim && strstr(d.out, (*e)->claim), "%s", d.out);
        rp_run_free(&d);
    }
    cr_expect_eq(rp_count_lines(l.out), n, "one line per experiment");
    cr_expect(strstr(h.out, "stability"));
    rp_run_free(&h);
    rp_run_free(&l);
}

Test(cli, version_names_the_release)
{
    rp_run r = rp_run_radpt("--version");
    cr_expect_eq(r.status, 0);
    cr_expect(strncmp(r.out, "radpt 0.", 8) == 0 && strstr(r.out, "(git "), "%s", r.out);
    rp_run_free(&r);
}

/* --quiet leaves stderr without progress or log lines, but keeps the
 * output on stdout. */
Test(cli, quiet_silences_logs)
{
    rp_run loud = rp_run_radpt("throughput scenes/cornell.scene --spp 1 --rays 1000");
    rp_run quiet = rp_run_radpt("throughput scenes/cornell.scene --spp 1 --rays 1000 --quiet");
    cr_assert_eq(loud.status, 0);
    cr_assert_eq(quiet.status, 0);
    cr_expect(strstr(loud.err, "casting"), "%s", loud.err);
    cr_expect_str_eq(quiet.err, "");
    cr_expect(strstr(quiet.out, "rays/s"), "%s", quiet.out);
    rp_run_free(&loud);
    rp_run_free(&quiet);
}

/* -o's extension chooses the format: a PFM holds the same linear RGB as
 * the EXR of the same run (bottom row first, little-endian floats, scale
 * -1), a PNG is a PNG, and an unknown extension is refused before any
 * work. */
Test(cli, output_format_follows_the_extension)
{
    const char *exr = "/tmp/rp-fmt.exr", *pfm = "/tmp/rp-fmt.pfm", *png = "/tmp/rp-fmt.png";
    rp_run a = rp_run_radpt("render scenes/cornell.scene --method pathtrace --spp 2 --camera "
                            "\"eye 278 273 -800 look 278 273 0 up 0 1 0 fov 39.3 size 24 16\" -o /tmp/rp-fmt.exr");
    rp_run b = rp_run_radpt("render scenes/cornell.scene --method pathtrace --spp 2 --camera "
                            "\"eye 278 273 -800 look 278 273 0 up 0 1 0 fov 39.3 size 24 16\" -o /tmp/rp-fmt.pfm");
    rp_run c = rp_run_radpt("render scenes/cornell.scene --method pathtrace --spp 2 --camera "
                            "\"eye 278 273 -800 look 278 273 0 up 0 1 0 fov 39.3 size 24 16\" -o /tmp/rp-fmt.png");
    rp_run d = rp_run_radpt("render scenes/cornell.scene --method pathtrace --spp 2 -o /tmp/rp-fmt.tiff");
    cr_assert_eq(a.status, 0, "%s", a.err);
    cr_assert_eq(b.status, 0, "%s", b.err);
    cr_assert_eq(c.status, 0, "%s", c.err);
    cr_expect_eq(d.status, 2);
    cr_expect(strstr(d.err, ".exr") && strstr(d.err, ".pfm"), "%s", d.err);
    uint32_t w, h;
    size_t nc;
    char **names;
    float **planes;
    rp_error err;
    cr_assert_eq(rp_image_read_exr(exr, &w, &h, &nc, &names, &planes, &err), RP_OK);
    cr_assert_eq(nc, 3);
    const float *rgb[3] = {NULL, NULL, NULL}; /* EXR keeps channels sorted by name */
    for (size_t i = 0; i < nc; i++)
        rgb[strcmp(names[i], "R") == 0 ? 0 : strcmp(names[i], "G") == 0 ? 1 : 2] = planes[i];
    cr_assert(rgb[0] && rgb[1] && rgb[2]);
    FILE *f = fopen(pfm, "rb");
    cr_assert_not_null(f);
    char magic[3] = {0};
    unsigned pw, ph;
    double scale;
    cr_assert_eq(fscanf(f, "%2s %u %u %lf", magic, &pw, &ph, &scale), 4);
    fgetc(f); /* the single white space after the scale */
    cr_expect_str_eq(magic, "PF");
    cr_expect(pw == w && ph == h && scale == -1.0);
    size_t mismatches = 0;
    for (uint32_t y = h; y-- > 0;)
        for (uint32_t x = 0; x < w; x++)
            for (int ch = 0; ch < 3; ch++) {
                unsigned char le[4];
                cr_assert_eq(fread(le, 1, 4, f), 4);
                uint32_t u = (uint32_t)le[0] | (uint32_t)le[1] << 8 | (uint32_t)le[2] << 16 | (uint32_t)le[3] << 24;
                float v;
                memcpy(&v, &u, 4);
                mismatches += v != rgb[ch][(size_t)y * w + x];
            }
    cr_expect_eq(fgetc(f), EOF, "no bytes after the pixels");
    fclose(f);
    cr_expect_eq(mismatches, 0);
    char *p = rp_read_file(png);
    cr_expect(p && memcmp(p, "\x89PNG", 4) == 0);
    free(p);
    for (size_t i = 0; i < nc; i++) {
        free(planes[i]);
        free(names[i]);
    }
    free(planes);
    free(names);
    unlink(exr);
    unlink(pfm);
    unlink(png);
    rp_run_free(&a);
    rp_run_free(&b);
    rp_run_free(&c);
    rp_run_free(&d);
}

/* bench says when --target lies at or below the reference's own noise (an
 * RMSE against a path-traced reference is, in the mean, sqrt(error^2 +
 * its noise^2)), and not when the target lies above it: a 2-spp reference
 * on the Cornell box, whose noise is far above 1e-4 and far below 10. */
Test(cli, bench_target_below_the_reference_noise_is_named, .timeout = 120)
{
    char dir[] = "/tmp/radpt-target-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    const char *targets[2] = {"1e-4", "10"};
    for (int k = 0; k < 2; k++) {
        char args[512];
        snprintf(args, sizeof args,
                 "bench scenes/cornell.scene --methods pathtrace:spp=1 --budget 0.1 --checkpoints 1 --seeds 1 "
                 "--reference-spp 2 --reference-samples 64 --cache %s/refs --target %s -o %s/b%d",
                 dir, targets[k], dir, k);
        rp_run r = rp_run_radpt(args);
        cr_assert_eq(r.status, 0, "'%s': %s", args, r.err);
        static const char prefix[] = "note: the target is at or below the reference's own noise (RMSE standard "
                                     "error ";
        const char *note = strstr(r.out, prefix);
        if (k == 0) {
            cr_assert_not_null(note, "%s", r.out);
            double se = strtod(note + strlen(prefix), NULL);
            cr_expect(se > 1e-4 && se < 10, "reference noise %g", se);
        } else
            cr_expect_null(note, "%s", r.out);
        rp_run_free(&r);
    }
    rp_test_rmtree(dir);
}
