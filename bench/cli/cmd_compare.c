/* radpt compare A.exr B.exr: image A against reference image B, with the
 * metrics the benchmarks use (bench/run/metrics.h: the same function, the
 * same definitions), on radpt's EXRs or other renderers' (pbrt, Blender:
 * half or float, scanline or tiled images, channels R G B found by name or
 * suffix, alpha ignored).
 *
 *   radpt compare A.exr B.exr [--json] [-o DIFF.png] [--mask MASK.png|MASK.exr]
 *                 [--scene SCENE [--camera WORDS]]
 *
 * --scene restricts the comparison to the pixels the benchmarks measure
 * (rp_reference_pixel_mask: pixels fully covered by front faces of
 * reflecting surfaces); --mask to the pixels a mask image selects (any
 * channel > 0, bench/report/mask.h); both together to the pixels both
 * select (the intersection: the mask can only narrow what the benchmarks
 * measure); without either every pixel counts.  Pixels left out count in
 * no metric, mean or maximum, and are grey in the difference image. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/cli/cli.h"
#include "bench/cli/commands.h"
#include "bench/report/gnuplot.h"
#include "bench/report/image.h"
#include "bench/report/mask.h"
#include "bench/run/metrics.h"
#include "bench/run/reference.h"

typedef struct loaded {
    uint32_t w, h;
    size_t n;
    char **names;
    float **planes;
} loaded;

static void loaded_free(loaded *l)
{
    for (size_t i = 0; i < l->n; i++) {
        free(l->names[i]);
        free(l->planes[i]);
    }
    free(l->names);
    free(l->planes);
    memset(l, 0, sizeof *l);
}

/* The channel whose name is want, or ends in ".want" (Blender's
 * "ViewLayer.Combined.R"); -1 if none. */
static long find_channel(const loaded *l, const char *want)
{
    size_t wl = strlen(want);
    for (size_t i = 0; i < l->n; i++) {
        const char *s = l->names[i];
        size_t sl = strlen(s);
        if (strcmp(s, want) == 0 || (sl > wl && s[sl - wl - 1] == '.' && strcmp(s + sl - wl, want) == 0))
            return (long)i;
    }
    return -1;
}

/* The channels compared: R, G, B when both have them, else Y. */
static int pick_channels(const loaded *a, const loaded *b, long ia[3], long ib[3], size_t *nb, const char **label)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    int ok = 1;
    for (int c = 0; c < 3; c++) {
        ia[c] = find_channel(a, rgb[c]);
        ib[c] = find_channel(b, rgb[c]);
        ok &= ia[c] >= 0 && ib[c] >= 0;
    }
    if (ok) {
        *nb = 3;
        *label = "R,G,B";
        return 1;
    }
    ia[0] = find_channel(a, "Y");
    ib[0] = find_channel(b, "Y");
    *nb = 1;
    *label = "Y";
    return ia[0] >= 0 && ib[0] >= 0;
}

void rp_cmd_compare_help(FILE *f)
{
    fputs("radpt compare A.exr B.exr [--json] [-o DIFF.png] [--mask MASK.png|MASK.exr]\n"
          "              [--scene SCENE [--camera WORDS]]\n"
          "\n"
          "Scores image A against the reference B with the benchmarks' own metric function\n"
          "(bench/run/metrics.c): RMSE, relMSE ((A - B)^2 / (B^2 + 0.01), Rousselle et al. 2011)\n"
          "and MAE over every channel of R, G, B (Y unless both images have R, G, B), the\n"
          "per-channel means of A and B and their ratio, and the largest |A - B| with its\n"
          "pixel and channel.\n"
          "\n"
          "Images: OpenEXR (part 0), scanline or tiled (mipmaps and ripmaps: level 0),\n"
          "half, float or uint channels, any compression OpenEXRCore reads; from radpt or\n"
          "any renderer. Channels are found by name or by suffix (Blender's\n"
          "ViewLayer.Combined.R); alpha is ignored. A and B must have the same size. Deep\n"
          "and subsampled images are refused.\n"
          "\n"
          "Which pixels count (every pixel without --scene and --mask):\n"
          "  --scene SCENE  the pixels the benchmarks measure: fully covered by front faces\n"
          "                 of surfaces that reflect (the light, silhouettes and background\n"
          "                 left out), so the RMSE is the one radpt bench reports; the\n"
          "                 scene's camera (or --camera WORDS) must have the images' size\n"
          "  --mask FILE    the pixels where any channel of FILE is > 0, FILE of the images'\n"
          "                 size. PNG: grey, grey+alpha, RGB or RGBA, 8 or 16 bits (grey also\n"
          "                 1, 2 or 4): alpha is a channel like the others, so an opaque black\n"
          "                 pixel of an RGBA mask counts; a palette PNG by its colours' R, G, B\n"
          "                 (tRNS transparency is not a channel). EXR: any channel > 0 (0,\n"
          "                 negative and NaN do not count). The kind is read from the file's\n"
          "                 first bytes, not its name.\n"
          "  both           the pixels both select: the mask narrows the benchmarks' pixels.\n"
          "Pixels left out count in no metric, mean or maximum, and are grey in DIFF.png.\n"
          "\n"
          "  -o DIFF.png    A - B (mean over the channels) in false colour: dark blue at minus\n"
          "                 the largest difference, crimson at 0, yellow at plus it\n"
          "  --json         one object: a, reference, mask_file (with --mask), width, height,\n"
          "                 channels, pixels_compared, mask (all, reference, file, or file and\n"
          "                 reference), rmse, relmse, mae, max_abs_diff, max_at {x, y,\n"
          "                 channel}, channel_means [{channel, a, reference, ratio}]\n"
          "\n"
          "Exit status 2, with a message naming the file: an image that is missing or not an\n"
          "EXR, or holds a non-finite value; images of different sizes or without common\n"
          "channels; a scene whose camera has another size; a mask that is missing, not a\n"
          "PNG or EXR, cut short or corrupt, of another size, or selects no pixel (with\n"
          "--scene: none of the measured ones).\n",
          f);
}

int rp_cmd_compare(int argc, char **argv)
{
    const char *files[2] = {NULL, NULL}, *out = NULL, *scene_path = NULL, *camera = NULL, *mask_path = NULL;
    int json = 0, nfiles = 0;
    for (int i = 2; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--json"))
            json = 1;
        else if (!strcmp(a, "--quiet"))
            rp_cli_quiet = 1;
        else if ((!strcmp(a, "-o") || !strcmp(a, "--scene") || !strcmp(a, "--camera") || !strcmp(a, "--mask")) &&
                 i + 1 < argc) {
            const char **dst = !strcmp(a, "-o")        ? &out
                               : !strcmp(a, "--scene") ? &scene_path
                               : !strcmp(a, "--mask")  ? &mask_path
                                                       : &camera;
            *dst = argv[++i];
        } else if (a[0] == '-' && a[1]) {
            fprintf(stderr, "radpt compare: %s: unknown option or missing value (radpt compare A.exr B.exr [--json] "
                            "[-o DIFF.png] [--mask MASK.png|MASK.exr] [--scene SCENE [--camera WORDS]])\n", a);
            return 2;
        } else if (nfiles < 2)
            files[nfiles++] = a;
        else {
            fprintf(stderr, "radpt compare: unexpected argument '%s' (two images: A, then the reference B)\n", a);
            return 2;
        }
    }
    if (nfiles != 2) {
        fprintf(stderr, "radpt compare: needs two images, A.exr and the reference B.exr (see radpt help)\n");
        return 2;
    }
    if (out && rp_image_format_of(out) != RP_IMAGE_PNG) {
        fprintf(stderr, "radpt compare: -o %s: the difference image is a PNG; name it .png\n", out);
        return 2;
    }
    if (camera && !scene_path) {
        fprintf(stderr, "radpt compare: --camera needs --scene SCENE\n");
        return 2;
    }
    int rc;
    if ((rc = rp_cli_check_output("compare", "-o", out)) != 0)
        return rc;
    rp_error err;
    loaded im[2];
    memset(im, 0, sizeof im);
    rp_status st = RP_OK;
    for (int k = 0; k < 2 && st == RP_OK; k++)
        st = rp_image_read_exr(files[k], &im[k].w, &im[k].h, &im[k].n, &im[k].names, &im[k].planes, &err);
    long ia[3], ib[3];
    size_t nb = 0;
    const char *label = "";
    if (st == RP_OK && (im[0].w != im[1].w || im[0].h != im[1].h))
        st = rp_error_set(&err, RP_ERR_INPUT, "%s is %u x %u but the reference %s is %u x %u", files[0], im[0].w,
                          im[0].h, files[1], im[1].w, im[1].h);
    if (st == RP_OK && !pick_channels(&im[0], &im[1], ia, ib, &nb, &label))
        st = rp_error_set(&err, RP_ERR_INPUT, "%s and %s share neither R, G, B nor Y channels", files[0], files[1]);
    size_t npix = (size_t)im[0].w * im[0].h;
    float *x = NULL, *r = NULL;
    unsigned char *mask = NULL, *file_mask = NULL;
    size_t masked = npix;
    rp_scene *scene = NULL;
    if (st == RP_OK && (scene_path || mask_path) && !(mask = malloc(npix)))
        st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
    if (st == RP_OK && scene_path) {
        st = rp_load_scene(scene_path, camera, 1, &scene, &err);
        const rp_camera *cam = scene ? rp_scene_camera(scene) : NULL;
        if (st == RP_OK && (cam->width != im[0].w || cam->height != im[0].h))
            st = rp_error_set(&err, RP_ERR_INPUT, "--scene %s: its camera is %u x %u, the images %u x %u",
                              scene_path, cam->width, cam->height, im[0].w, im[0].h);
        if (st == RP_OK)
            st = rp_reference_pixel_mask(scene, mask, &masked, &err);
    }
    if (st == RP_OK && mask_path) {
        size_t selected = 0;
        if (!(file_mask = malloc(npix)))
            st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
        if (st == RP_OK)
            st = rp_mask_read(mask_path, im[0].w, im[0].h, file_mask, &selected, &err);
        if (st == RP_OK && scene) {
            size_t measured = masked;
            masked = 0;
            for (size_t p = 0; p < npix; p++) {
                mask[p] = mask[p] && file_mask[p];
                masked += mask[p];
            }
            if (!masked)
                st = rp_error_set(&err, RP_ERR_INPUT,
                                  "--mask %s selects %zu pixels, none of them among the %zu the benchmarks measure "
                                  "in --scene %s",
                                  mask_path, selected, measured, scene_path);
        } else if (st == RP_OK) {
            memcpy(mask, file_mask, npix);
            masked = selected;
        }
    }
    if (st == RP_OK) {
        x = malloc(npix * nb * sizeof *x);
        r = malloc(npix * nb * sizeof *r);
        if (!x || !r)
            st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
    }
    if (st == RP_OK) {
        /* interleave, band fastest, as rp_metrics_image reads */
        for (size_t p = 0; p < npix; p++)
            for (size_t c = 0; c < nb; c++) {
                x[p * nb + c] = im[0].planes[ia[c]][p];
                r[p * nb + c] = im[1].planes[ib[c]][p];
            }
        for (size_t i = 0; i < npix * nb && st == RP_OK; i++)
            if (!isfinite(x[i]) || !isfinite(r[i]))
                st = rp_error_set(&err, RP_ERR_INPUT, "%s: a non-finite value at pixel (%zu, %zu)",
                                  isfinite(x[i]) ? files[1] : files[0], (i / nb) % im[0].w, (i / nb) / im[0].w);
    }
    rp_image_metrics m = {0};
    double mean_a[3] = {0}, mean_b[3] = {0}, maxd = 0;
    size_t maxp = 0, maxc = 0;
    if (st == RP_OK) {
        rp_metrics_image(x, r, mask, npix, nb, &m);
        int first = 1; /* the maximum is at a compared pixel, even when it is 0 */
        for (size_t p = 0; p < npix; p++) {
            if (mask && !mask[p])
                continue;
            for (size_t c = 0; c < nb; c++) {
                mean_a[c] += x[p * nb + c];
                mean_b[c] += r[p * nb + c];
                double d = fabs((double)x[p * nb + c] - r[p * nb + c]);
                if (d > maxd || first) {
                    first = 0;
                    maxd = d;
                    maxp = p;
                    maxc = c;
                }
            }
        }
        for (size_t c = 0; c < nb; c++) {
            mean_a[c] /= masked ? (double)masked : 1;
            mean_b[c] /= masked ? (double)masked : 1;
        }
        if (!masked)
            st = rp_error_set(&err, RP_ERR_INPUT, "--scene %s: no pixel is measured", scene_path);
    }
    if (st == RP_OK && out) {
        /* signed difference A - B through the false-colour ramp
         * (rp_colormap), -maxd dark blue, 0 crimson, +maxd yellow; grey,
         * which the ramp never gives, where the mask leaves a pixel out */
        float *pl[3];
        for (int c = 0; c < 3; c++)
            pl[c] = malloc(npix * sizeof *pl[c]);
        if (!pl[0] || !pl[1] || !pl[2])
            st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
        for (size_t p = 0; st == RP_OK && p < npix; p++) {
            double d = 0;
            for (size_t c = 0; c < nb; c++)
                d += (double)x[p * nb + c] - r[p * nb + c];
            d /= (double)nb;
            float rgb[3] = {0.5f, 0.5f, 0.5f};
            if (!mask || mask[p])
                rp_colormap(maxd > 0 ? 0.5 + 0.5 * d / maxd : 0.5, rgb);
            for (int c = 0; c < 3; c++)
                pl[c][p] = rgb[c];
        }
        if (st == RP_OK) {
            rp_exposure unit = rp_exposure_fixed(0);
            st = rp_image_write_png(out, im[0].w, im[0].h, pl[0], pl[1], pl[2], &unit, &err);
        }
        for (int c = 0; c < 3; c++)
            free(pl[c]);
    }
    if (st == RP_OK) {
        const uint32_t mx = (uint32_t)(maxp % im[0].w), my = (uint32_t)(maxp / im[0].w);
        const char *chn = nb == 3 ? (const char *[]){"R", "G", "B"}[maxc] : "Y";
        /* which pixels count: every one, the benchmarks' (--scene), the
         * mask file's, or both */
        const char *mask_name = mask_path ? (scene ? "file and reference" : "file") : scene ? "reference" : "all";
        if (json) {
            printf("{\"a\": ");
            rp_json_string(stdout, files[0]);
            printf(", \"reference\": ");
            rp_json_string(stdout, files[1]);
            if (mask_path) {
                printf(", \"mask_file\": ");
                rp_json_string(stdout, mask_path);
            }
            printf(", \"width\": %u, \"height\": %u, \"channels\": \"%s\", \"pixels_compared\": %zu, "
                   "\"mask\": \"%s\", \"rmse\": %.9g, \"relmse\": %.9g, \"mae\": %.9g, \"max_abs_diff\": %.9g, "
                   "\"max_at\": {\"x\": %u, \"y\": %u, \"channel\": \"%s\"}, \"channel_means\": [",
                   im[0].w, im[0].h, label, masked, mask_name, m.rmse, m.relmse, m.mae, maxd, mx, my, chn);
            for (size_t c = 0; c < nb; c++)
                printf("%s{\"channel\": \"%s\", \"a\": %.9g, \"reference\": %.9g, \"ratio\": %.9g}", c ? ", " : "",
                       nb == 3 ? (const char *[]){"R", "G", "B"}[c] : "Y", mean_a[c], mean_b[c],
                       mean_b[c] != 0 ? mean_a[c] / mean_b[c] : NAN);
            printf("]}\n");
        } else {
            printf("%s against the reference %s: %u x %u, channels %s, %zu pixels compared (", files[0], files[1],
                   im[0].w, im[0].h, label, masked);
            if (mask_path)
                printf("the pixels %s selects%s)\n", mask_path,
                       scene ? " among the benchmarks' measured pixels of --scene" : "");
            else
                printf("%s)\n", scene ? "the benchmarks' measured pixels of --scene" : "every pixel");
            printf("RMSE     %.6g\nrelMSE   %.6g  (eps %g)\nMAE      %.6g\nmax |A - B| %.6g at pixel (%u, %u) "
                   "channel %s\n",
                   m.rmse, m.relmse, RP_RELMSE_EPS, m.mae, maxd, mx, my, chn);
            for (size_t c = 0; c < nb; c++)
                printf("mean %s: A %.6g, reference %.6g, ratio %.6g\n", nb == 3 ? (const char *[]){"R", "G", "B"}[c] : "Y",
                       mean_a[c], mean_b[c], mean_b[c] != 0 ? mean_a[c] / mean_b[c] : NAN);
            if (out)
                printf("wrote %s: A - B, channel mean, dark blue -%.3g .. crimson 0 .. yellow +%.3g\n", out, maxd,
                       maxd);
        }
    }
    free(x);
    free(r);
    free(mask);
    free(file_mask);
    rp_scene_destroy(scene);
    loaded_free(&im[0]);
    loaded_free(&im[1]);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}
