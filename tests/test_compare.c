/* radpt compare: the same metric as the benchmarks (one function, one
 * mask), channel names as other renderers write them, tiled EXRs read as
 * their scanline twins, masks from PNG and EXR files, and clear refusals.
 * Expected numbers are computed here from the values the tests write. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <OpenEXR/openexr.h>
#include <png.h>

#include "bench/report/image.h"
#include "bench/run/load.h"
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

/* ---------------------------------------------------------------------
 * Tiled EXRs (OpenEXR file layout, "Tiles"): written here with
 * OpenEXRCore, tile by tile, and read by radpt as the same pixels written
 * as scanlines. */

/* An image as OpenEXRCore writes it: storage, tiling, compression, data
 * window origin, channels with their stored types.  Values are given as
 * float; half channels get values a half holds exactly (the encoder
 * converts), so what radpt reads back is what the test wrote. */
typedef struct core_exr {
    exr_storage_t storage;
    exr_tile_level_mode_t levels;
    exr_tile_round_mode_t round;
    uint32_t tile_w, tile_h;
    exr_compression_t compression;
    int32_t x0, y0;
    int32_t w, h;
    int n;
    const char *const *names;
    const exr_pixel_type_t *types;
    const float *const *planes;
} core_exr;

static void exr_ok(exr_result_t rv, const char *call)
{
    cr_assert_eq(rv, EXR_ERR_SUCCESS, "%s: %s", call, exr_get_default_error_message(rv));
}
#define EXR_OK(call) exr_ok((call), #call)

/* OpenEXRCore 3.1's ZIP and PXR24 encoders keep a compressed chunk as
 * large as the raw data, which readers take for raw data (a 2 x 7 edge
 * tile of this test's ZIPS file did): stored raw instead, as
 * rp_image_write_exr does (bench/report/image.c, exr_compress_guarded). */
static exr_result_t (*core_default_compress)(exr_encode_pipeline_t *);

static exr_result_t core_compress(exr_encode_pipeline_t *enc)
{
    exr_result_t rv = core_default_compress(enc);
    if (rv == EXR_ERR_SUCCESS && enc->compressed_bytes >= enc->packed_bytes) {
        memcpy(enc->compressed_buffer, enc->packed_buffer, enc->packed_bytes);
        enc->compressed_bytes = enc->packed_bytes;
    }
    return rv;
}

/* One chunk through the encoder: channel planes[k] (k by name) from pixel
 * (x, y), rows stride floats apart; pixels of levels other than (0, 0)
 * (filler != NULL) all hold *filler. */
static void core_encode(exr_context_t ctx, const core_exr *s, exr_chunk_info_t *ci, exr_encode_pipeline_t *enc,
                        int *first, size_t x, size_t y, size_t stride, const float *filler)
{
    EXR_OK(*first ? exr_encoding_initialize(ctx, 0, ci, enc) : exr_encoding_update(ctx, 0, ci, enc));
    for (int16_t c = 0; c < enc->channel_count; c++) {
        exr_coding_channel_info_t *ch = &enc->channels[c];
        int k = -1;
        for (int j = 0; j < s->n; j++)
            if (!strcmp(s->names[j], ch->channel_name))
                k = j;
        cr_assert(k >= 0, "channel %s", ch->channel_name);
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = sizeof(float);
        ch->user_pixel_stride = sizeof(float);
        ch->user_line_stride = (int32_t)(stride * sizeof(float));
        ch->encode_from_ptr = (const uint8_t *)(filler ? filler : s->planes[k] + y * stride + x);
    }
    if (*first) {
        EXR_OK(exr_encoding_choose_default_routines(ctx, 0, enc));
        if (enc->compress_fn) {
            core_default_compress = enc->compress_fn;
            enc->compress_fn = core_compress;
        }
    }
    *first = 0;
    EXR_OK(exr_encoding_run(ctx, 0, enc));
}

static void core_write(const char *path, const core_exr *s)
{
    exr_context_t ctx = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    EXR_OK(exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init));
    int part;
    EXR_OK(exr_add_part(ctx, NULL, s->storage, &part));
    exr_attr_box2i_t dw;
    dw.min.x = s->x0;
    dw.min.y = s->y0;
    dw.max.x = s->x0 + s->w - 1;
    dw.max.y = s->y0 + s->h - 1;
    exr_attr_v2f_t centre;
    centre.x = centre.y = 0;
    EXR_OK(exr_initialize_required_attr(ctx, part, &dw, &dw, 1, &centre, 1, EXR_LINEORDER_INCREASING_Y,
                                        s->compression));
    for (int c = 0; c < s->n; c++)
        EXR_OK(exr_add_channel(ctx, part, s->names[c], s->types[c], EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1));
    if (s->storage == EXR_STORAGE_TILED)
        EXR_OK(exr_set_tile_descriptor(ctx, part, s->tile_w, s->tile_h, s->levels, s->round));
    EXR_OK(exr_write_header(ctx));

    exr_encode_pipeline_t enc;
    memset(&enc, 0, sizeof enc);
    exr_chunk_info_t ci;
    int first = 1;
    if (s->storage == EXR_STORAGE_SCANLINE) {
        int32_t lines;
        EXR_OK(exr_get_scanlines_per_chunk(ctx, part, &lines));
        for (int32_t y = s->y0; y < s->y0 + s->h; y += lines) {
            EXR_OK(exr_write_scanline_chunk_info(ctx, part, y, &ci));
            core_encode(ctx, s, &ci, &enc, &first, 0, (size_t)(ci.start_y - s->y0), (size_t)s->w, NULL);
        }
    } else {
        /* One level or mipmap levels (l, l).  Not ripmaps: OpenEXRCore 3.1
         * numbers the chunks of rip level (lx, ly > 0) wrongly (it adds
         * the levels (< lx, < ly) before it, not every x level of the rows
         * above; fixed upstream later), and refuses to write them. */
        cr_assert(s->levels != EXR_TILE_RIPMAP_LEVELS);
        int32_t nlx, nly;
        EXR_OK(exr_get_tile_levels(ctx, part, &nlx, &nly));
        float *filler = malloc((size_t)s->w * (size_t)s->h * sizeof *filler);
        cr_assert_not_null(filler);
        for (size_t i = 0; i < (size_t)s->w * (size_t)s->h; i++)
            filler[i] = 64; /* any other level must not be what is read */
        for (int32_t l = 0; l < nlx && l < nly; l++) {
            int32_t lx = l, ly = l, lw, lh, tw, th;
            EXR_OK(exr_get_level_sizes(ctx, part, lx, ly, &lw, &lh));
            EXR_OK(exr_get_tile_sizes(ctx, part, lx, ly, &tw, &th));
            for (int32_t ty = 0; ty * th < lh; ty++)
                for (int32_t tx = 0; tx * tw < lw; tx++) {
                    EXR_OK(exr_write_tile_chunk_info(ctx, part, tx, ty, lx, ly, &ci));
                    core_encode(ctx, s, &ci, &enc, &first, (size_t)(tx * tw), (size_t)(ty * th),
                                lx || ly ? (size_t)lw : (size_t)s->w, lx || ly ? filler : NULL);
                }
        }
        free(filler);
    }
    EXR_OK(exr_encoding_destroy(ctx, &enc));
    EXR_OK(exr_finish(&ctx));
}

enum { TW = 37, TH = 23 };

/* Channel c of pixel i: k / 64 for an integer k in [0, 255], which a half
 * holds exactly (11 significant bits), as it does 1.5 times that. */
static float tiled_value(int c, int i)
{
    return (float)((i * 7 + c * 53 + (i / TW) * 11) % 256) / 64.0f;
}

/* radpt reads what was written, value for value. */
static void expect_pixels(const char *path, const core_exr *s)
{
    uint32_t w, h;
    size_t n;
    char **names;
    float **planes;
    rp_error err;
    cr_assert_eq(rp_image_read_exr(path, &w, &h, &n, &names, &planes, &err), RP_OK, "%s", err.message);
    cr_assert_eq(w, (uint32_t)s->w);
    cr_assert_eq(h, (uint32_t)s->h);
    cr_assert_eq(n, (size_t)s->n);
    for (size_t c = 0; c < n; c++) {
        int k = -1;
        for (int j = 0; j < s->n; j++)
            if (!strcmp(s->names[j], names[c]))
                k = j;
        cr_assert(k >= 0, "%s: channel %s", path, names[c]);
        size_t bad = 0, first = 0;
        for (size_t i = 0; i < (size_t)s->w * (size_t)s->h; i++)
            if (planes[c][i] != s->planes[k][i] && !bad++)
                first = i;
        cr_expect_eq(bad, 0, "%s: channel %s: %zu pixels differ, the first (%zu, %zu): %g, wrote %g", path,
                     names[c], bad, first % (size_t)s->w, first / (size_t)s->w, planes[c][first],
                     s->planes[k][first]);
        free(names[c]);
        free(planes[c]);
    }
    free(names);
    free(planes);
}

/* A 37 x 23 image (data window from (-3, 5)) with half and float channels,
 * tiled 16 x 16 (tiles cut at the right and bottom edges), 5 x 7 and
 * 64 x 64 (one tile larger than the image), in every lossless compression
 * and PXR24 (lossless on these values: 8 significant bits): radpt reads the
 * values written, as it does the same image in scanlines, and radpt
 * compare gives 0 between the two. */
Test(compare, tiled_reads_as_scanline)
{
    static const char *const names[4] = {"A", "B", "G", "R"};
    static const exr_pixel_type_t types[4] = {EXR_PIXEL_FLOAT, EXR_PIXEL_HALF, EXR_PIXEL_FLOAT, EXR_PIXEL_HALF};
    static float v[4][TW * TH];
    for (int c = 0; c < 4; c++)
        for (int i = 0; i < TW * TH; i++)
            v[c][i] = tiled_value(c, i);
    const float *planes[4] = {v[0], v[1], v[2], v[3]};
    char dir[64], scan[96], tiled[96], args[300];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-tiled"), 0);
    snprintf(scan, sizeof scan, "%s/scan.exr", dir);
    snprintf(tiled, sizeof tiled, "%s/tiled.exr", dir);
    static const exr_compression_t comps[] = {EXR_COMPRESSION_NONE, EXR_COMPRESSION_RLE, EXR_COMPRESSION_ZIPS,
                                              EXR_COMPRESSION_ZIP, EXR_COMPRESSION_PIZ, EXR_COMPRESSION_PXR24};
    static const uint32_t tiles[3][2] = {{16, 16}, {5, 7}, {64, 64}};
    for (size_t k = 0; k < sizeof comps / sizeof comps[0]; k++)
        for (size_t t = 0; t < 3; t++) {
            core_exr s = {.storage = EXR_STORAGE_SCANLINE, .compression = comps[k], .x0 = -3, .y0 = 5, .w = TW,
                          .h = TH, .n = 4, .names = names, .types = types, .planes = planes};
            core_write(scan, &s);
            expect_pixels(scan, &s);
            s.storage = EXR_STORAGE_TILED;
            s.levels = EXR_TILE_ONE_LEVEL;
            s.round = EXR_TILE_ROUND_DOWN;
            s.tile_w = tiles[t][0];
            s.tile_h = tiles[t][1];
            core_write(tiled, &s);
            expect_pixels(tiled, &s);
            snprintf(args, sizeof args, "compare %s %s --json", tiled, scan);
            rp_run r = rp_run_radpt(args);
            cr_assert_eq(r.status, 0, "compression %d, tiles %u x %u: %s", (int)comps[k], s.tile_w, s.tile_h,
                         r.err);
            cr_expect_eq(rp_json_number_after(r.out, "{", "rmse"), 0.0, "%s", r.out);
            cr_expect_eq(rp_json_number_after(r.out, "{", "max_abs_diff"), 0.0, "%s", r.out);
            cr_expect_eq(rp_json_number_after(r.out, "{", "pixels_compared"), (double)(TW * TH), "%s", r.out);
            rp_run_free(&r);
        }
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* Blender's naming (ViewLayer.Combined.R, G, B, A) on a tiled image with
 * half and float channels, against the same values times 1.5 in plain R,
 * G, B scanlines: every metric is computed here from the values written
 * (A - B = -0.5 v over the 3 x 37 x 23 values of R, G, B; alpha ignored). */
Test(compare, tiled_known_rmse_blender_names)
{
    static const char *const blender[4] = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B",
                                           "ViewLayer.Combined.A"};
    static const char *const plain[3] = {"R", "G", "B"};
    static const exr_pixel_type_t types[4] = {EXR_PIXEL_HALF, EXR_PIXEL_FLOAT, EXR_PIXEL_HALF, EXR_PIXEL_FLOAT};
    static float v[4][TW * TH], v15[3][TW * TH];
    double sq = 0, abs_sum = 0, rel = 0, maxd = 0, sum_a[3] = {0}, sum_b[3] = {0};
    for (int c = 0; c < 4; c++)
        for (int i = 0; i < TW * TH; i++) {
            v[c][i] = tiled_value(c, i);
            if (c == 3)
                continue;
            v15[c][i] = 1.5f * v[c][i]; /* exact: k / 64 * 1.5 = 3k / 128 */
            double x = v[c][i], r = v15[c][i], d = x - r;
            sq += d * d;
            abs_sum += fabs(d);
            rel += d * d / (r * r + RP_RELMSE_EPS);
            maxd = fmax(maxd, fabs(d));
            sum_a[c] += x;
            sum_b[c] += r;
        }
    const double k = 3.0 * TW * TH;
    const float *pa[4] = {v[0], v[1], v[2], v[3]}, *pb[3] = {v15[0], v15[1], v15[2]};
    char dir[64], a[96], b[96], args[300];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-blender"), 0);
    snprintf(a, sizeof a, "%s/blender-tiled.exr", dir);
    snprintf(b, sizeof b, "%s/plain-scan.exr", dir);
    core_exr sa = {.storage = EXR_STORAGE_TILED, .levels = EXR_TILE_ONE_LEVEL, .tile_w = 16, .tile_h = 16,
                   .compression = EXR_COMPRESSION_ZIP, .w = TW, .h = TH, .n = 4, .names = blender, .types = types,
                   .planes = pa};
    core_exr sb = {.storage = EXR_STORAGE_SCANLINE, .compression = EXR_COMPRESSION_PIZ, .w = TW, .h = TH, .n = 3,
                   .names = plain, .types = types, .planes = pb};
    core_write(a, &sa);
    core_write(b, &sb);
    snprintf(args, sizeof args, "compare %s %s --json", a, b);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "\"channels\": \"R,G,B\""), "%s", r.out);
    cr_expect_eq(rp_json_number_after(r.out, "{", "pixels_compared"), (double)(TW * TH), "%s", r.out);
    const double want[4] = {sqrt(sq / k), rel / k, abs_sum / k, maxd};
    const char *key[4] = {"rmse", "relmse", "mae", "max_abs_diff"};
    for (int m = 0; m < 4; m++) {
        double got = rp_json_number_after(r.out, "{", key[m]);
        /* printed with 9 significant digits; float inputs, double sums */
        cr_expect(fabs(got - want[m]) <= 1e-7 * want[m], "%s: radpt %.9g, expected %.9g", key[m], got, want[m]);
    }
    const char *anchor[3] = {"\"channel\": \"R\", \"a\"", "\"channel\": \"G\", \"a\"", "\"channel\": \"B\", \"a\""};
    for (int c = 0; c < 3; c++) {
        double got = rp_json_number_after(r.out, anchor[c], "ratio");
        cr_expect(fabs(got - sum_a[c] / sum_b[c]) <= 1e-7, "%s ratio %.9g", plain[c], got);
    }
    rp_run_free(&r);
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* Mipmapped files, levels rounded down and up: radpt reads level 0, the
 * full image; every other level holds 64 everywhere, so reading one would
 * show.  Tiled files made by the C++ library (exrmaketiled, Debian's
 * openexr) from the scanline image, one level, mipmapped and ripmapped
 * (which OpenEXRCore 3.1 cannot write), read the same. */
Test(compare, tiled_levels_read_level_0)
{
    static const char *const names[3] = {"B", "G", "R"};
    static const exr_pixel_type_t types[3] = {EXR_PIXEL_HALF, EXR_PIXEL_FLOAT, EXR_PIXEL_HALF};
    static float v[3][TW * TH];
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < TW * TH; i++)
            v[c][i] = tiled_value(c, i);
    const float *planes[3] = {v[0], v[1], v[2]};
    char dir[64], scan[96], tiled[96], args[400];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-levels"), 0);
    snprintf(scan, sizeof scan, "%s/scan.exr", dir);
    snprintf(tiled, sizeof tiled, "%s/tiled.exr", dir);
    core_exr s = {.storage = EXR_STORAGE_SCANLINE, .compression = EXR_COMPRESSION_ZIP, .x0 = 2, .y0 = -4, .w = TW,
                  .h = TH, .n = 3, .names = names, .types = types, .planes = planes};
    core_write(scan, &s);
    static const exr_tile_round_mode_t rounds[2] = {EXR_TILE_ROUND_DOWN, EXR_TILE_ROUND_UP};
    for (int rd = 0; rd < 2; rd++) {
        core_exr t = s;
        t.storage = EXR_STORAGE_TILED;
        t.levels = EXR_TILE_MIPMAP_LEVELS;
        t.round = rounds[rd];
        t.tile_w = t.tile_h = 16;
        core_write(tiled, &t);
        expect_pixels(tiled, &t);
        snprintf(args, sizeof args, "compare %s %s --json", tiled, scan);
        rp_run r = rp_run_radpt(args);
        cr_assert_eq(r.status, 0, "mipmap, round %d: %s", (int)rounds[rd], r.err);
        cr_expect_eq(rp_json_number_after(r.out, "{", "rmse"), 0.0, "%s", r.out);
        cr_expect_eq(rp_json_number_after(r.out, "{", "max_abs_diff"), 0.0, "%s", r.out);
        rp_run_free(&r);
    }
    if (system("command -v exrmaketiled >/dev/null 2>&1") != 0)
        cr_log_warn("exrmaketiled not installed: tiled files of the C++ library not checked");
    else {
        static const char *const opts[4] = {"-t 16 16", "-t 5 7 -z piz", "-m -t 16 16", "-r -u -t 16 16 -z rle"};
        for (int o = 0; o < 4; o++) {
            snprintf(args, sizeof args, "exrmaketiled %s '%s' '%s' >/dev/null 2>&1", opts[o], scan, tiled);
            cr_assert_eq(system(args), 0, "%s", args);
            core_exr t = s;
            expect_pixels(tiled, &t);
            snprintf(args, sizeof args, "compare %s %s --json", tiled, scan);
            rp_run r = rp_run_radpt(args);
            cr_assert_eq(r.status, 0, "exrmaketiled %s: %s", opts[o], r.err);
            cr_expect_eq(rp_json_number_after(r.out, "{", "rmse"), 0.0, "exrmaketiled %s: %s", opts[o], r.out);
            rp_run_free(&r);
        }
    }
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* ---------------------------------------------------------------------
 * Masks (--mask): the pixels a PNG or EXR selects (any channel > 0), as
 * --scene's benchmark mask leaves the others out. */

/* A PNG written with libpng: type and depth as given, samples (channel
 * fastest) as the file stores them (indices for a palette image, whose
 * colours and tRNS alpha are given too). */
typedef struct test_png {
    int type, depth, interlace;
    size_t nch;
    const png_color *palette;
    int npalette;
    const png_byte *trns;
    int ntrns;
} test_png;

static void write_png(const char *path, uint32_t w, uint32_t h, const test_png *t, const uint16_t *samples)
{
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f, "%s", path);
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    cr_assert(png && info);
    size_t bytes = t->depth == 16 ? 2 : 1, rowbytes = (size_t)w * t->nch * bytes;
    png_bytep data = malloc(rowbytes * h);
    png_bytepp rows = malloc(h * sizeof *rows);
    cr_assert(data && rows);
    for (uint32_t y = 0; y < h; y++) {
        rows[y] = data + (size_t)y * rowbytes;
        for (size_t i = 0; i < (size_t)w * t->nch; i++) {
            uint16_t v = samples[(size_t)y * w * t->nch + i];
            if (bytes == 2) {
                rows[y][2 * i] = (png_byte)(v >> 8); /* PNG: big-endian */
                rows[y][2 * i + 1] = (png_byte)v;
            } else
                rows[y][i] = (png_byte)v;
        }
    }
    cr_assert_eq(setjmp(png_jmpbuf(png)), 0, "libpng failed writing %s", path);
    png_init_io(png, f);
    png_set_IHDR(png, info, w, h, t->depth, t->type, t->interlace, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    if (t->palette)
        png_set_PLTE(png, info, t->palette, t->npalette);
    if (t->trns)
        png_set_tRNS(png, info, t->trns, t->ntrns, NULL);
    png_write_info(png, info);
    if (t->depth < 8)
        png_set_packing(png); /* one sample per byte in, packed bits out */
    png_set_interlace_handling(png);
    png_write_image(png, rows);
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    fclose(f);
    free(data);
    free(rows);
}

/* The RGB of every pixel of a PNG (libpng, 8-bit RGB files only). */
static png_byte *read_png_rgb(const char *path, uint32_t *w, uint32_t *h)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f, "%s", path);
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    cr_assert(png && info);
    cr_assert_eq(setjmp(png_jmpbuf(png)), 0, "libpng failed reading %s", path);
    png_init_io(png, f);
    png_read_info(png, info);
    *w = png_get_image_width(png, info);
    *h = png_get_image_height(png, info);
    cr_assert_eq(png_get_color_type(png, info), PNG_COLOR_TYPE_RGB);
    cr_assert_eq(png_get_bit_depth(png, info), 8);
    png_byte *data = malloc((size_t)*w * *h * 3);
    cr_assert_not_null(data);
    for (uint32_t y = 0; y < *h; y++)
        png_read_row(png, data + (size_t)y * *w * 3, NULL);
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return data;
}

enum { MW = 9, MH = 7 };

/* The pixels the masks below select: a third of them, not the one with
 * the largest difference (pixel 0). */
static int mask_on(int i)
{
    return i % 3 == 1;
}

/* 9 x 7 RGB images A and B (B = reference) with a difference d(i, c) that
 * is largest, 5, at the unselected pixel 0; the expected numbers over the
 * selected pixels only, computed here. */
typedef struct mask_case {
    float a[3][MW * MH], b[3][MW * MH];
    double rmse, mae, maxd, ratio[3];
    int max_at;
    size_t count;
} mask_case;

static void mask_case_write(mask_case *m, const char *pa, const char *pb, const unsigned char *extra)
{
    double sq = 0, ab = 0, sa[3] = {0}, sb[3] = {0};
    m->maxd = -1;
    m->count = 0;
    for (int i = 0; i < MW * MH; i++) {
        int on = mask_on(i) && (!extra || extra[i]);
        m->count += (size_t)on;
        for (int c = 0; c < 3; c++) {
            m->b[c][i] = 0.25f * (float)(1 + (i + c) % 5);
            double d = i == 0 ? 5 : 0.125 * ((i * 7 + c * 3) % 11) - 0.5;
            m->a[c][i] = (float)(m->b[c][i] + d); /* exact: multiples of 1/8 */
            if (!on)
                continue;
            sq += d * d;
            ab += fabs(d);
            sa[c] += m->a[c][i];
            sb[c] += m->b[c][i];
            if (fabs(d) > m->maxd) {
                m->maxd = fabs(d);
                m->max_at = i;
            }
        }
    }
    m->rmse = sqrt(sq / (3.0 * (double)m->count));
    m->mae = ab / (3.0 * (double)m->count);
    for (int c = 0; c < 3; c++)
        m->ratio[c] = sa[c] / sb[c];
    static const char *const names[3] = {"R", "G", "B"};
    const float *pla[3] = {m->a[0], m->a[1], m->a[2]}, *plb[3] = {m->b[0], m->b[1], m->b[2]};
    rp_image ia = {.width = MW, .height = MH, .nchannels = 3, .channel_names = names, .planes = pla};
    rp_image ib = {.width = MW, .height = MH, .nchannels = 3, .channel_names = names, .planes = plb};
    rp_error err;
    cr_assert_eq(rp_image_write_exr(pa, &ia, &err), RP_OK, "%s", err.message);
    cr_assert_eq(rp_image_write_exr(pb, &ib, &err), RP_OK, "%s", err.message);
}

static void expect_mask_case(const mask_case *m, const char *json, const char *what)
{
    cr_expect_eq(rp_json_number_after(json, "{", "pixels_compared"), (double)m->count, "%s: %s", what, json);
    double got = rp_json_number_after(json, "{", "rmse");
    cr_expect(fabs(got - m->rmse) <= 1e-8 * m->rmse, "%s: RMSE %.9g, expected %.9g", what, got, m->rmse);
    got = rp_json_number_after(json, "{", "mae");
    cr_expect(fabs(got - m->mae) <= 1e-8 * m->mae, "%s: MAE %.9g, expected %.9g", what, got, m->mae);
    cr_expect_eq(rp_json_number_after(json, "{", "max_abs_diff"), m->maxd, "%s: %s", what, json);
    cr_expect_eq(rp_json_number_after(json, "max_at", "x"), (double)(m->max_at % MW), "%s: %s", what, json);
    cr_expect_eq(rp_json_number_after(json, "max_at", "y"), (double)(m->max_at / MW), "%s: %s", what, json);
    got = rp_json_number_after(json, "\"channel\": \"B\", \"a\"", "ratio");
    cr_expect(fabs(got - m->ratio[2]) <= 1e-8, "%s: B ratio %.9g, expected %.9g", what, got, m->ratio[2]);
}

/* The same pixels selected by masks of every PNG colour type, each with
 * the smallest value that counts in a different channel (8-bit 1; 16-bit
 * 1 and 256, low and high byte), by an interlaced 1-bit grey PNG, a
 * palette PNG whose unselected colour is opaque black by tRNS (not a
 * channel), and an EXR mask whose unselected values are 0, -1 and NaN:
 * every number is the one computed here over those pixels alone, and the
 * difference image is grey exactly where pixels are left out. */
Test(compare, mask_selects_pixels)
{
    static mask_case m;
    char dir[64], a[96], b[96], mk[96], diff[96], args[500];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-mask"), 0);
    snprintf(a, sizeof a, "%s/a.exr", dir);
    snprintf(b, sizeof b, "%s/b.exr", dir);
    snprintf(diff, sizeof diff, "%s/diff.png", dir);
    mask_case_write(&m, a, b, NULL);
    cr_assert_eq(m.count, 21);

    static const png_color pal[2] = {{0, 0, 0}, {0, 0, 1}};
    static const png_byte opaque[2] = {255, 255};
    struct {
        const char *name;
        test_png t;
        uint16_t on[4];
    } kinds[] = {
        {"grey8", {PNG_COLOR_TYPE_GRAY, 8, PNG_INTERLACE_NONE, 1, NULL, 0, NULL, 0}, {1}},
        {"grey16", {PNG_COLOR_TYPE_GRAY, 16, PNG_INTERLACE_NONE, 1, NULL, 0, NULL, 0}, {1}},
        {"grey1-interlaced", {PNG_COLOR_TYPE_GRAY, 1, PNG_INTERLACE_ADAM7, 1, NULL, 0, NULL, 0}, {1}},
        {"grey-alpha8", {PNG_COLOR_TYPE_GRAY_ALPHA, 8, PNG_INTERLACE_NONE, 2, NULL, 0, NULL, 0}, {0, 1}},
        {"grey-alpha16", {PNG_COLOR_TYPE_GRAY_ALPHA, 16, PNG_INTERLACE_NONE, 2, NULL, 0, NULL, 0}, {256, 0}},
        {"rgb8", {PNG_COLOR_TYPE_RGB, 8, PNG_INTERLACE_NONE, 3, NULL, 0, NULL, 0}, {0, 0, 1}},
        {"rgb16", {PNG_COLOR_TYPE_RGB, 16, PNG_INTERLACE_NONE, 3, NULL, 0, NULL, 0}, {0, 256, 0}},
        {"rgba8", {PNG_COLOR_TYPE_RGB_ALPHA, 8, PNG_INTERLACE_NONE, 4, NULL, 0, NULL, 0}, {1, 0, 0, 0}},
        {"rgba16", {PNG_COLOR_TYPE_RGB_ALPHA, 16, PNG_INTERLACE_ADAM7, 4, NULL, 0, NULL, 0}, {0, 0, 0, 1}},
        {"palette4-trns", {PNG_COLOR_TYPE_PALETTE, 4, PNG_INTERLACE_NONE, 1, pal, 2, opaque, 2}, {1}},
    };
    for (size_t k = 0; k < sizeof kinds / sizeof kinds[0]; k++) {
        uint16_t s[MW * MH * 4] = {0};
        for (int i = 0; i < MW * MH; i++)
            for (size_t c = 0; c < kinds[k].t.nch; c++)
                s[(size_t)i * kinds[k].t.nch + c] = mask_on(i) ? kinds[k].on[c] : 0;
        snprintf(mk, sizeof mk, "%s/%s.png", dir, kinds[k].name);
        write_png(mk, MW, MH, &kinds[k].t, s);
        snprintf(args, sizeof args, "compare %s %s --json --mask %s", a, b, mk);
        rp_run r = rp_run_radpt(args);
        cr_assert_eq(r.status, 0, "%s: %s", kinds[k].name, r.err);
        expect_mask_case(&m, r.out, kinds[k].name);
        cr_expect(strstr(r.out, "\"mask\": \"file\""), "%s", r.out);
        rp_run_free(&r);
    }

    /* an EXR mask: > 0 selects; 0, -1 and NaN do not */
    float y[MW * MH];
    for (int i = 0; i < MW * MH; i++)
        y[i] = mask_on(i) ? 0.5f : (i % 3 == 0 ? 0.0f : (i % 2 ? -1.0f : NAN));
    const char *yn[1] = {"Y"};
    const float *yp[1] = {y};
    rp_image iy = {.width = MW, .height = MH, .nchannels = 1, .channel_names = yn, .planes = yp};
    rp_error err;
    snprintf(mk, sizeof mk, "%s/mask.exr", dir);
    cr_assert_eq(rp_image_write_exr(mk, &iy, &err), RP_OK, "%s", err.message);
    snprintf(args, sizeof args, "compare %s %s --json --mask %s -o %s", a, b, mk, diff);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    expect_mask_case(&m, r.out, "EXR mask");
    rp_run_free(&r);

    /* grey, sRGB-encoded 0.5 (IEC 61966-2-1), exactly at the pixels left out */
    const png_byte grey = (png_byte)floor(255 * (1.055 * pow(0.5, 1 / 2.4) - 0.055) + 0.5);
    uint32_t dw, dh;
    png_byte *rgb = read_png_rgb(diff, &dw, &dh);
    cr_assert_eq(dw * dh, MW * MH);
    for (int i = 0; i < MW * MH; i++) {
        int is_grey = rgb[3 * i] == grey && rgb[3 * i + 1] == grey && rgb[3 * i + 2] == grey;
        if (!mask_on(i))
            cr_expect(is_grey, "pixel %d left out but coloured %u %u %u", i, rgb[3 * i], rgb[3 * i + 1],
                      rgb[3 * i + 2]);
    }
    /* the largest compared difference is at full colour, not grey */
    const png_byte *mx = rgb + 3 * m.max_at;
    cr_expect(!(mx[0] == grey && mx[1] == grey && mx[2] == grey), "pixel %d", m.max_at);
    free(rgb);

    /* without a mask, pixel 0's difference of 5 is the largest */
    snprintf(args, sizeof args, "compare %s %s --json", a, b);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect_eq(rp_json_number_after(r.out, "{", "max_abs_diff"), 5.0, "%s", r.out);
    cr_expect_eq(rp_json_number_after(r.out, "{", "pixels_compared"), (double)(MW * MH), "%s", r.out);
    rp_run_free(&r);
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

#define CORNELL_9X7 "eye 278 273 -800 look 278 273 0 up 0 1 0 fov 39.3077 size 9 7"

/* --mask with --scene counts the pixels both select: the numbers are the
 * ones computed here over that intersection (the benchmarks' mask of the
 * Cornell box seen at 9 x 7 from rp_reference_pixel_mask); a mask that
 * selects only pixels the benchmarks leave out is refused. */
Test(compare, mask_and_scene_intersect)
{
    rp_scene *scene = NULL;
    rp_error err;
    cr_assert_eq(rp_load_scene("scenes/cornell.scene", CORNELL_9X7, 1, &scene, &err), RP_OK, "%s", err.message);
    unsigned char ref[MW * MH], in[MW * MH];
    size_t nref = 0, nin = 0;
    cr_assert_eq(rp_reference_pixel_mask(scene, ref, &nref, &err), RP_OK, "%s", err.message);
    rp_scene_destroy(scene);
    for (int i = 0; i < MW * MH; i++) {
        in[i] = mask_on(i) && ref[i];
        nin += in[i];
    }
    cr_assert(nin > 0 && nin < 21 && nref < MW * MH, "%zu of %zu measured pixels masked", nin, nref);

    static mask_case m;
    char dir[64], a[96], b[96], mk[96], args[600];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-mask-scene"), 0);
    snprintf(a, sizeof a, "%s/a.exr", dir);
    snprintf(b, sizeof b, "%s/b.exr", dir);
    snprintf(mk, sizeof mk, "%s/mask.png", dir);
    mask_case_write(&m, a, b, ref);
    cr_assert_eq(m.count, nin);
    test_png t = {PNG_COLOR_TYPE_GRAY, 8, PNG_INTERLACE_NONE, 1, NULL, 0, NULL, 0};
    uint16_t s[MW * MH];
    for (int i = 0; i < MW * MH; i++)
        s[i] = mask_on(i) ? 255 : 0;
    write_png(mk, MW, MH, &t, s);
    snprintf(args, sizeof args, "compare %s %s --json --mask %s --scene scenes/cornell.scene --camera '%s'", a, b, mk,
             CORNELL_9X7);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    expect_mask_case(&m, r.out, "mask and scene");
    cr_expect(strstr(r.out, "\"mask\": \"file and reference\""), "%s", r.out);
    rp_run_free(&r);
    /* the text form says which pixels count */
    snprintf(args, sizeof args, "compare %s %s --mask %s --scene scenes/cornell.scene --camera '%s'", a, b, mk,
             CORNELL_9X7);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    char want[200];
    snprintf(want, sizeof want, "%zu pixels compared (the pixels %s selects among the benchmarks' measured", nin, mk);
    cr_expect(strstr(r.out, want), "%s", r.out);
    rp_run_free(&r);

    /* only pixels the benchmarks leave out: nothing to compare */
    size_t nout = 0;
    for (int i = 0; i < MW * MH; i++) {
        s[i] = ref[i] ? 0 : 7;
        nout += !ref[i];
    }
    write_png(mk, MW, MH, &t, s);
    snprintf(args, sizeof args, "compare %s %s --mask %s --scene scenes/cornell.scene --camera '%s'", a, b, mk,
             CORNELL_9X7);
    r = rp_run_radpt(args);
    cr_expect_eq(r.status, 2, "%s", r.err);
    snprintf(want, sizeof want, "--mask %s selects %zu pixels, none of them among the %zu", mk, nout, nref);
    cr_expect(strstr(r.err, want) && strstr(r.err, "scenes/cornell.scene"), "%s", r.err);
    rp_run_free(&r);
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* Every bad mask exits 2 naming the file: missing, not a PNG, a PNG cut
 * short or corrupt, another size (both sizes named, PNG and EXR), no pixel
 * selected; --mask without a file is a usage error. */
Test(compare, mask_bad_inputs)
{
    static mask_case m;
    char dir[64], a[96], b[96], mk[96], args[600];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-mask-bad"), 0);
    snprintf(a, sizeof a, "%s/a.exr", dir);
    snprintf(b, sizeof b, "%s/b.exr", dir);
    mask_case_write(&m, a, b, NULL);
    test_png t = {PNG_COLOR_TYPE_GRAY, 8, PNG_INTERLACE_NONE, 1, NULL, 0, NULL, 0};
    uint16_t ones[MW * MH], zeros[MW * MH] = {0};
    for (int i = 0; i < MW * MH; i++)
        ones[i] = 255;

    struct {
        const char *name, *says;
    } cases[] = {
        {"absent.png", "cannot open the mask: No such file"},
        {"text.png", "not a PNG"},
        {"cut.png", "cannot read PNG"},
        {"corrupt.png", "cannot read PNG"},
        {"small.png", "the mask is 5 x 4 but the images are 9 x 7"},
        {"small.exr", "the mask is 3 x 2 but the images are 9 x 7"},
        {"zeros.png", "the mask selects no pixel"},
    };
    char path[128];
    FILE *f;
    snprintf(path, sizeof path, "%s/text.png", dir);
    cr_assert_not_null(f = fopen(path, "w"));
    fputs("P2 9 7 255\n", f);
    fclose(f);
    /* a whole PNG, then its first 40 bytes (signature, IHDR, no data) */
    snprintf(path, sizeof path, "%s/whole.png", dir);
    write_png(path, MW, MH, &t, ones);
    char *whole = rp_read_file(path);
    cr_assert_not_null(whole);
    snprintf(path, sizeof path, "%s/cut.png", dir);
    cr_assert_not_null(f = fopen(path, "wb"));
    fwrite(whole, 1, 40, f);
    fclose(f);
    /* signature and IHDR intact, the rest garbage */
    snprintf(path, sizeof path, "%s/corrupt.png", dir);
    cr_assert_not_null(f = fopen(path, "wb"));
    fwrite(whole, 1, 33, f);
    for (int i = 0; i < 64; i++)
        fputc(0x5a, f);
    fclose(f);
    free(whole);
    snprintf(path, sizeof path, "%s/small.png", dir);
    write_png(path, 5, 4, &t, ones);
    snprintf(path, sizeof path, "%s/zeros.png", dir);
    write_png(path, MW, MH, &t, zeros);
    const char *yn[1] = {"Y"};
    const float y6[6] = {1, 1, 1, 1, 1, 1}, *yp[1] = {y6};
    rp_image iy = {.width = 3, .height = 2, .nchannels = 1, .channel_names = yn, .planes = yp};
    rp_error err;
    snprintf(path, sizeof path, "%s/small.exr", dir);
    cr_assert_eq(rp_image_write_exr(path, &iy, &err), RP_OK, "%s", err.message);

    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        snprintf(mk, sizeof mk, "%s/%s", dir, cases[k].name);
        snprintf(args, sizeof args, "compare %s %s --mask %s", a, b, mk);
        rp_run r = rp_run_radpt(args);
        cr_expect_eq(r.status, 2, "%s: exit %d: %s", cases[k].name, r.status, r.err);
        cr_expect(strstr(r.err, mk), "%s: the message does not name the file: %s", cases[k].name, r.err);
        cr_expect(strstr(r.err, cases[k].says), "%s: %s", cases[k].name, r.err);
        cr_expect_eq(r.out[0], '\0', "%s: %s", cases[k].name, r.out);
        rp_run_free(&r);
    }
    snprintf(args, sizeof args, "compare %s %s --mask", a, b);
    rp_run r = rp_run_radpt(args);
    cr_expect_eq(r.status, 2);
    cr_expect(strstr(r.err, "--mask"), "%s", r.err);
    rp_run_free(&r);
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* The difference image's colours as help and README give them: an image
 * against itself is 0 everywhere, crimson (sRGB 0.80, 0.20, 0.35, the
 * middle of rp_colormap's ramp) where compared and mid grey (linear 0.5,
 * sRGB-encoded by IEC 61966-2-1) where the mask leaves pixels out. */
Test(compare, diff_image_colours)
{
    static mask_case m;
    char dir[64], a[96], b[96], mk[96], diff[96], args[600];
    cr_assert_eq(rp_test_tmpdir(dir, sizeof dir, "rp-compare-colours"), 0);
    snprintf(a, sizeof a, "%s/a.exr", dir);
    snprintf(b, sizeof b, "%s/b.exr", dir);
    snprintf(mk, sizeof mk, "%s/mask.png", dir);
    snprintf(diff, sizeof diff, "%s/diff.png", dir);
    mask_case_write(&m, a, b, NULL);
    test_png t = {PNG_COLOR_TYPE_GRAY, 8, PNG_INTERLACE_NONE, 1, NULL, 0, NULL, 0};
    uint16_t s[MW * MH];
    for (int i = 0; i < MW * MH; i++)
        s[i] = mask_on(i) ? 255 : 0;
    write_png(mk, MW, MH, &t, s);
    snprintf(args, sizeof args, "compare %s %s --mask %s -o %s", a, a, mk, diff);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "dark blue -0 .. crimson 0 .. yellow +0"), "%s", r.out);
    rp_run_free(&r);
    const int grey = (int)floor(255 * (1.055 * pow(0.5, 1 / 2.4) - 0.055) + 0.5);
    const int crimson[3] = {204, 51, 89}; /* 255 x (0.80, 0.20, 0.35) */
    uint32_t w, h;
    png_byte *rgb = read_png_rgb(diff, &w, &h);
    for (int i = 0; i < MW * MH; i++)
        for (int c = 0; c < 3; c++) {
            int want = mask_on(i) ? crimson[c] : grey;
            /* +-1: sRGB decoded to linear and encoded again */
            cr_expect(abs(rgb[3 * i + c] - want) <= 1, "pixel %d channel %d: %d, want %d", i, c, rgb[3 * i + c], want);
        }
    free(rgb);
    cr_expect_eq(rp_test_rmtree(dir), 0);
}

/* radpt help compare says what counts; radpt help points to it. */
Test(compare, help)
{
    rp_run r = rp_run_radpt("help compare");
    cr_assert_eq(r.status, 0, "%s", r.err);
    const char *says[] = {"--mask FILE", "any channel of FILE is > 0", "the pixels both select", "tiled",
                          "opaque black", "crimson at 0"};
    for (size_t i = 0; i < sizeof says / sizeof says[0]; i++)
        cr_expect(strstr(r.out, says[i]), "help compare lacks \"%s\"", says[i]);
    rp_run_free(&r);
    r = rp_run_radpt("help");
    cr_assert_eq(r.status, 0, "%s", r.err);
    cr_expect(strstr(r.out, "[--mask MASK.png|MASK.exr]") && strstr(r.out, "radpt help compare"), "%s", r.out);
    rp_run_free(&r);
}
