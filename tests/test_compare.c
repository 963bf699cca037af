/* radpt compare: the same metric as the benchmarks (one function, one
 * mask), channel names as other renderers write them, and clear refusals. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench/report/image.h"
#include "bench/run/metrics.h"
#include "bench/run/reference.h"
#include "cli_util.h"
#include "scene_util.h"

/* A path-traced furnace against its exact reference: the RMSE radpt compare
 * prints over the benchmarks' mask equals the one rp_metrics_image gives
 * in-process on the same arrays, which is what a bench row holds. */
Test(compare, equals_the_bench_metric)
{
    char dir[64];
    snprintf(dir, sizeof dir, "/tmp/rp_compare_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
    rp_scene *scene = rp_test_load("scenes/furnace.scene");
    rp_reference_params p = {.size = sizeof p, .cache_dir = dir};
    rp_reference *ref = NULL;
    rp_error err;
    cr_assert_eq(rp_reference_get(scene, "furnace", &p, &ref, &err), RP_OK, "%s", err.message);
    char args[1400], a[128];
    snprintf(a, sizeof a, "%s/a.exr", dir);
    snprintf(args, sizeof args, "render scenes/furnace.scene --method pathtrace --spp 2 -o %s --quiet", a);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    rp_run_free(&r);
    snprintf(args, sizeof args, "compare %s %s --scene scenes/furnace.scene --json", a, ref->exr_path);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    double rmse = rp_json_number_after(r.out, "{", "rmse");
    double pixels = rp_json_number_after(r.out, "{", "pixels_compared");

    uint32_t w, h;
    size_t nc;
    char **names;
    float **planes;
    cr_assert_eq(rp_image_read_exr(a, &w, &h, &nc, &names, &planes, &err), RP_OK, "%s", err.message);
    cr_assert_eq(nc, 1); /* grey: Y */
    rp_image_metrics m;
    rp_metrics_image(planes[0], ref->radiance, ref->mask, (size_t)w * h, 1, &m);
    cr_expect(m.rmse > 0);
    cr_expect(fabs(rmse - m.rmse) <= 1e-6 * m.rmse, "compare %.9g, metrics %.9g", rmse, m.rmse);
    cr_expect_eq((size_t)pixels, ref->mask_count);
    rp_run_free(&r);

    /* against itself: zero, ratio 1 */
    snprintf(args, sizeof args, "compare %s %s --json", a, a);
    r = rp_run_radpt(args);
    cr_expect_eq(r.status, 0);
    cr_expect_eq(rp_json_number_after(r.out, "{", "rmse"), 0.0);
    cr_expect_eq(rp_json_number_after(r.out, "{", "ratio"), 1.0);
    rp_run_free(&r);
    free(names[0]);
    free(planes[0]);
    free(names);
    free(planes);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    snprintf(args, sizeof args, "rm -rf '%s'", dir);
    cr_expect_eq(system(args), 0);
}

/* Blender names its channels "ViewLayer.Combined.R" and adds alpha: R, G, B
 * are found by suffix, A is ignored; a uniform scale of 2 shows as a mean
 * ratio of 2 and an RMSE of the reference's RMS value. */
Test(compare, other_renderers_channel_names)
{
    enum { W = 4, H = 3 };
    float r[W * H], g[W * H], b[W * H], alpha[W * H], r2[W * H], g2[W * H], b2[W * H];
    double sq = 0;
    for (int i = 0; i < W * H; i++) {
        r[i] = 0.1f * (float)(i + 1);
        g[i] = 0.05f * (float)i;
        b[i] = 0.5f;
        alpha[i] = 1;
        r2[i] = 2 * r[i];
        g2[i] = 2 * g[i];
        b2[i] = 2 * b[i];
        sq += (double)r[i] * r[i] + (double)g[i] * g[i] + (double)b[i] * b[i];
    }
    const char *blender[4] = {"ViewLayer.Combined.A", "ViewLayer.Combined.B", "ViewLayer.Combined.G",
                              "ViewLayer.Combined.R"};
    const float *bp[4] = {alpha, b2, g2, r2};
    const char *plain[3] = {"B", "G", "R"};
    const float *pp[3] = {b, g, r};
    rp_image ib = {.width = W, .height = H, .nchannels = 4, .channel_names = blender, .planes = bp};
    rp_image ip = {.width = W, .height = H, .nchannels = 3, .channel_names = plain, .planes = pp};
    rp_error err;
    cr_assert_eq(rp_image_write_exr("/tmp/rp-compare-blender.exr", &ib, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_image_write_exr("/tmp/rp-compare-plain.exr", &ip, &err), RP_OK, "%s", err.message);
    rp_run run = rp_run_radpt("compare /tmp/rp-compare-blender.exr /tmp/rp-compare-plain.exr --json");
    cr_assert_eq(run.status, 0, "%s", run.err);
    cr_expect(fabs(rp_json_number_after(run.out, "{", "rmse") - sqrt(sq / (3 * W * H))) < 1e-6, "%s", run.out);
    cr_expect(fabs(rp_json_number_after(run.out, "\"channel\": \"G\"", "ratio") - 2) < 1e-6, "%s", run.out);
    rp_run_free(&run);
    /* different sizes and missing channels are input errors (exit 2) */
    const char *y[1] = {"Y"};
    rp_image iy = {.width = W, .height = H, .nchannels = 1, .channel_names = y, .planes = pp};
    cr_assert_eq(rp_image_write_exr("/tmp/rp-compare-y.exr", &iy, &err), RP_OK, "%s", err.message);
    run = rp_run_radpt("compare /tmp/rp-compare-y.exr /tmp/rp-compare-plain.exr");
    cr_expect_eq(run.status, 2);
    cr_expect(strstr(run.err, "share neither"), "%s", run.err);
    rp_run_free(&run);
    run = rp_run_radpt("compare /tmp/rp-compare-plain.exr");
    cr_expect_eq(run.status, 2);
    rp_run_free(&run);
    unlink("/tmp/rp-compare-blender.exr");
    unlink("/tmp/rp-compare-plain.exr");
    unlink("/tmp/rp-compare-y.exr");
}
