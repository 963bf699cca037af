/* bench/report/image.c: EXR round trips (bit-exact), attributes, atomic writes,
 * and the sRGB PNG preview checked against IEC 61966-2-1 by hand. */
#include <criterion/criterion.h>

#include <dirent.h>
#include <errno.h>
#include <float.h>
#include <math.h>
#include <png.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bench/report/image.h"
#include "cli_util.h"

/* ---------------------------------------------------------------------
 * Helpers */

static char *make_dir(void)
{
    char *d = strdup("/tmp/rp_test_image_XXXXXX");
    cr_assert_not_null(d);
    cr_assert_not_null(mkdtemp(d), "mkdtemp: %s", strerror(errno));
    return d;
}

static char *join(const char *dir, const char *name)
{
    size_t n = strlen(dir) + strlen(name) + 2;
    char *p = malloc(n);
    cr_assert_not_null(p);
    snprintf(p, n, "%s/%s", dir, name);
    return p;
}

/* Entries of dir other than . and ..; *temps counts those that look like
 * our temporary files. */
static int count_entries(const char *dir, int *temps)
{
    DIR *d = opendir(dir);
    cr_assert_not_null(d, "opendir %s: %s", dir, strerror(errno));
    int n = 0, t = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        n++;
        if (strstr(e->d_name, ".tmp."))
            t++;
    }
    closedir(d);
    if (temps)
        *temps = t;
    return n;
}

static void remove_dir(char *dir)
{
    DIR *d = opendir(dir);
    if (d) {
        struct dirent *e;
        while ((e = readdir(d)) != NULL) {
            if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
                continue;
            char *p = join(dir, e->d_name);
            if (unlink(p) != 0)
                rmdir(p);
            free(p);
        }
        closedir(d);
    }
    rmdir(dir);
    free(dir);
}

static int path_exists(const char *p)
{
    struct stat sb;
    return stat(p, &sb) == 0;
}

/* xorshift64* (Vigna 2016), fixed seed: the same "random" images every run. */
static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
static uint64_t rng_next(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 0x2545F4914F6CDD1Dull;
}

static float bits_float(uint32_t u)
{
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Values chosen to break any lossy or converting path: arbitrary bit
 * patterns (including NaNs with payloads), denormals, negatives, values
 * near FLT_MAX, infinities, -0. */
static float awkward_float(size_t i)
{
    uint32_t u = (uint32_t)(rng_next() >> 32);
    switch (i % 8) {
    case 0: return bits_float(u);
    case 1: return bits_float((u & 0x807FFFFFu) | 1u);      /* denormal */
    case 2: return -(float)(u % 100000) / 7.0f;             /* negative */
    case 3: return (u & 1 ? -1.0f : 1.0f) * FLT_MAX / (float)(1 + u % 7);
    case 4: return u & 1 ? -INFINITY : INFINITY;
    case 5: return -0.0f;
    default: return (float)(u >> 8) / 16777216.0f;
    }
}

static float *random_plane(size_t n)
{
    float *p = malloc(n * sizeof *p);
    cr_assert_not_null(p);
    for (size_t i = 0; i < n; i++)
        p[i] = awkward_float(i + rng_next() % 8);
    return p;
}

/* Writes an image of random planes, reads it back and demands every plane
 * back bit for bit, found by name. */
static void roundtrip(const char *path, uint32_t w, uint32_t h, size_t nch,
                      const char *const *names, const rp_image_attr *attrs, size_t nattrs)
{
    float **planes = calloc(nch, sizeof *planes);
    cr_assert_not_null(planes);
    for (size_t c = 0; c < nch; c++)
        planes[c] = random_plane((size_t)w * h);
    rp_image img = {
        .width = w, .height = h, .nchannels = nch, .channel_names = names,
        .planes = (const float *const *)planes, .attrs = attrs, .nattrs = nattrs,
    };
    rp_error err = {{0}};
    rp_status st = rp_image_write_exr(path, &img, &err);
    cr_assert_eq(st, RP_OK, "write %s: %s", path, err.message);

    uint32_t rw = 0, rh = 0;
    size_t rn = 0;
    char **rnames = NULL;
    float **rplanes = NULL;
    st = rp_image_read_exr(path, &rw, &rh, &rn, &rnames, &rplanes, &err);
    cr_assert_eq(st, RP_OK, "read %s: %s", path, err.message);
    cr_assert_eq(rw, w);
    cr_assert_eq(rh, h);
    cr_assert_eq(rn, nch);
    for (size_t c = 0; c < nch; c++) {
        size_t k = rn;
        for (size_t j = 0; j < rn; j++)
            if (strcmp(rnames[j], names[c]) == 0)
                k = j;
        cr_assert_lt(k, rn, "channel %s not read back", names[c]);
        cr_assert_eq(memcmp(rplanes[k], planes[c], (size_t)w * h * sizeof(float)), 0,
                     "channel %s (%u x %u) differs after the round trip", names[c], w, h);
    }
    for (size_t j = 0; j < rn; j++) {
        free(rnames[j]);
        free(rplanes[j]);
    }
    free(rnames);
    free(rplanes);
    for (size_t c = 0; c < nch; c++)
        free(planes[c]);
    free(planes);
}

/* Runs exrheader (Debian package openexr) on path and checks that its
 * output mentions every needle.  Skipped with a warning if it is absent. */
static void check_exrheader(const char *path, const char *const *needles, size_t n)
{
    if (system("command -v exrheader >/dev/null 2>&1") != 0) {
        cr_log_warn("exrheader not installed: independent header check skipped");
        return;
    }
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "exrheader '%s' 2>&1", path);
    FILE *p = popen(cmd, "r");
    cr_assert_not_null(p);
    size_t cap = 1 << 16, len = 0;
    char *out = malloc(cap);
    cr_assert_not_null(out);
    size_t got;
    while ((got = fread(out + len, 1, cap - 1 - len, p)) > 0 && len + got < cap - 1)
        len += got;
    len += got;
    out[len] = '\0';
    int rc = pclose(p);
    cr_assert_eq(rc, 0, "exrheader failed on %s:\n%s", path, out);
    for (size_t i = 0; i < n; i++)
        cr_assert_not_null(strstr(out, needles[i]), "exrheader output lacks \"%s\":\n%s",
                           needles[i], out);
    free(out);
}

/* OpenEXRCore 3.1's ZIP encoder kept a compressed chunk exactly as large
 * as the raw data, which readers take for raw data: the 5 x 1 image 0,
 * 0.25, 0, 0.25, 0 read back as zlib bytes, and so did 34 of 2000 small
 * images tried.  432 small images of periodic values (i a mod m) / 8,
 * the family that one came from, of which 8 came back wrong, all come back
 * exactly. */
Test(image, exr_zip_chunk_as_large_as_raw)
{
    char *dir = make_dir();
    char *path = join(dir, "small.exr");
    const char *names[1] = {"Y"};
    size_t tried = 0;
    for (uint32_t w = 1; w <= 12; w++)
        for (uint32_t a = 1; a <= 6; a++)
            for (uint32_t m = 2; m <= 7; m++) {
                float v[12];
                for (uint32_t i = 0; i < w; i++)
                    v[i] = (float)((i * a) % m) / 8.0f;
                const float *planes[1] = {v};
                rp_image img = {.width = w, .height = 1, .nchannels = 1, .channel_names = names, .planes = planes};
                rp_error err;
                cr_assert_eq(rp_image_write_exr(path, &img, &err), RP_OK, "%s", err.message);
                uint32_t rw, rh;
                size_t rn;
                char **rnames;
                float **rplanes;
                cr_assert_eq(rp_image_read_exr(path, &rw, &rh, &rn, &rnames, &rplanes, &err), RP_OK, "%s",
                             err.message);
                cr_assert_eq(rw * rh, w);
                cr_expect_eq(memcmp(rplanes[0], v, w * sizeof(float)), 0, "width %u, (i %u mod %u) / 8: read %g %g ...",
                             w, a, m, rplanes[0][0], w > 1 ? rplanes[0][1] : 0.0f);
                free(rnames[0]);
                free(rplanes[0]);
                free(rnames);
                free(rplanes);
                tried++;
            }
    cr_expect_eq(tried, 432);
    free(path);
    remove_dir(dir);
}

/* ---------------------------------------------------------------------
 * EXR */

Test(image, exr_rgb_roundtrip_and_attributes)
{
    char *dir = make_dir();
    char *path = join(dir, "rgb.exr");
    const char *names[] = {"R", "G", "B"};
    const rp_image_attr attrs[] = {
        {"radpt:method", "pathtrace"},
        {"radpt:seed", "42"},
        {"radpt:empty", ""},
    };
    /* 37 x 19: ZIP packs 16 lines per chunk, so the second chunk has 3. */
    roundtrip(path, 37, 19, 3, names, attrs, 3);

    char *v = rp_image_read_exr_attr(path, "radpt:method");
    cr_assert_not_null(v);
    cr_assert_str_eq(v, "pathtrace");
    free(v);
    v = rp_image_read_exr_attr(path, "radpt:seed");
    cr_assert_not_null(v);
    cr_assert_str_eq(v, "42");
    free(v);
    v = rp_image_read_exr_attr(path, "radpt:empty");
    cr_assert_not_null(v);
    cr_assert_str_eq(v, "");
    free(v);
    cr_assert_null(rp_image_read_exr_attr(path, "radpt:absent"));
    /* A required attribute of another type is not a string. */
    cr_assert_null(rp_image_read_exr_attr(path, "dataWindow"));

    const char *needles[] = {"R, 32-bit floating-point", "G, 32-bit floating-point",
                             "B, 32-bit floating-point", "radpt:method", "pathtrace", "zip"};
    check_exrheader(path, needles, sizeof needles / sizeof *needles);

    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1);
    cr_assert_eq(temps, 0);
    free(path);
    remove_dir(dir);
}

Test(image, exr_grey_roundtrip_sizes)
{
    char *dir = make_dir();
    char *path = join(dir, "grey.exr");
    const char *names[] = {"Y"};
    /* 1 x 1; exactly one chunk (16 lines); one line over; odd and tall. */
    const uint32_t sizes[][2] = {{1, 1}, {5, 16}, {3, 17}, {37, 19}, {1, 100}, {101, 33}};
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++)
        roundtrip(path, sizes[i][0], sizes[i][1], 1, names, NULL, 0);
    const char *needles[] = {"Y, 32-bit floating-point"};
    check_exrheader(path, needles, 1);
    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1);
    cr_assert_eq(temps, 0);
    free(path);
    remove_dir(dir);
}

Test(image, exr_spectral_roundtrip_long_names)
{
    char *dir = make_dir();
    char *path = join(dir, "spectral.exr");
    /* Given out of alphabetical order on purpose: the file sorts them. */
    const char *names[] = {"L400", "L550", "R", "G", "B"};
    /* 39 bytes: past the 31-byte limit of files without the long-names flag. */
    const char *longname = "radpt:an_attribute_name_longer_than_31";
    const rp_image_attr attrs[] = {{longname, "long"}, {"radpt:scene", "cornell.scene"}};
    roundtrip(path, 37, 19, 5, names, attrs, 2);

    char *v = rp_image_read_exr_attr(path, longname);
    cr_assert_not_null(v);
    cr_assert_str_eq(v, "long");
    free(v);
    v = rp_image_read_exr_attr(path, "radpt:scene");
    cr_assert_not_null(v);
    cr_assert_str_eq(v, "cornell.scene");
    free(v);

    const char *needles[] = {"L400, 32-bit floating-point", "L550, 32-bit floating-point",
                             "R, 32-bit", "G, 32-bit", "B, 32-bit", longname, "radpt:scene"};
    check_exrheader(path, needles, sizeof needles / sizeof *needles);
    free(path);
    remove_dir(dir);
}

Test(image, exr_overwrite_replaces_whole_file)
{
    char *dir = make_dir();
    char *path = join(dir, "again.exr");
    const char *big[] = {"R", "G", "B"};
    const char *small[] = {"Y"};
    roundtrip(path, 40, 40, 3, big, NULL, 0);
    roundtrip(path, 2, 3, 1, small, NULL, 0);
    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1);
    cr_assert_eq(temps, 0);
    free(path);
    remove_dir(dir);
}

static const float one_pixel[1] = {1.0f};

Test(image, exr_missing_directory_fails_cleanly)
{
    char *dir = make_dir();
    char *sub = join(dir, "no_such_dir");
    char *path = join(sub, "x.exr");
    const char *names[] = {"Y"};
    const float *planes[] = {one_pixel};
    rp_image img = {.width = 1, .height = 1, .nchannels = 1, .channel_names = names,
                    .planes = planes};
    rp_error err = {{0}};
    rp_status st = rp_image_write_exr(path, &img, &err);
    cr_assert_eq(st, RP_ERR_RUNTIME);
    cr_assert_not_null(strstr(err.message, path), "message: %s", err.message);
    cr_assert_not_null(strstr(err.message, "No such file"), "message: %s", err.message);
    cr_assert(!path_exists(path));
    cr_assert(!path_exists(sub));
    cr_assert_eq(count_entries(dir, NULL), 0);
    free(path);
    free(sub);
    remove_dir(dir);
}

/* A failure after the temporary file exists (OpenEXR refuses a string
 * attribute named like the required "channels" attribute) must remove it
 * and leave nothing at PATH. */
Test(image, exr_library_failure_leaves_nothing)
{
    char *dir = make_dir();
    char *path = join(dir, "bad.exr");
    const char *names[] = {"Y"};
    const float *planes[] = {one_pixel};
    const rp_image_attr attrs[] = {{"channels", "oops"}};
    rp_image img = {.width = 1, .height = 1, .nchannels = 1, .channel_names = names,
                    .planes = planes, .attrs = attrs, .nattrs = 1};
    rp_error err = {{0}};
    rp_status st = rp_image_write_exr(path, &img, &err);
    cr_assert_eq(st, RP_ERR_RUNTIME);
    cr_assert_not_null(strstr(err.message, path), "message: %s", err.message);
    cr_assert_not_null(strstr(err.message, "attribute"), "message: %s", err.message);
    cr_assert(!path_exists(path));
    cr_assert_eq(count_entries(dir, NULL), 0);
    free(path);
    remove_dir(dir);
}

/* rename(2) onto an existing directory fails after a complete write. */
Test(image, exr_rename_failure_leaves_no_temp)
{
    char *dir = make_dir();
    char *path = join(dir, "taken");
    cr_assert_eq(mkdir(path, 0700), 0);
    const char *names[] = {"Y"};
    const float *planes[] = {one_pixel};
    rp_image img = {.width = 1, .height = 1, .nchannels = 1, .channel_names = names,
                    .planes = planes};
    rp_error err = {{0}};
    cr_assert_eq(rp_image_write_exr(path, &img, &err), RP_ERR_RUNTIME);
    cr_assert_not_null(strstr(err.message, "rename"), "message: %s", err.message);
    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1); /* the directory itself */
    cr_assert_eq(temps, 0);
    free(path);
    remove_dir(dir);
}

Test(image, exr_bad_input_refused)
{
    char *dir = make_dir();
    char *path = join(dir, "in.exr");
    const char *dup_names[] = {"R", "R"};
    const float *planes[] = {one_pixel, one_pixel};
    rp_error err = {{0}};
    rp_image img = {.width = 1, .height = 1, .nchannels = 2, .channel_names = dup_names,
                    .planes = planes};
    cr_assert_eq(rp_image_write_exr(path, &img, &err), RP_ERR_INPUT);
    cr_assert_not_null(strstr(err.message, "twice"), "message: %s", err.message);

    const char *names[] = {"Y"};
    rp_image empty = {.width = 0, .height = 1, .nchannels = 1, .channel_names = names,
                      .planes = planes};
    cr_assert_eq(rp_image_write_exr(path, &empty, &err), RP_ERR_INPUT);
    rp_image nochan = {.width = 1, .height = 1, .nchannels = 0, .channel_names = names,
                       .planes = planes};
    cr_assert_eq(rp_image_write_exr(path, &nochan, &err), RP_ERR_INPUT);
    cr_assert_eq(count_entries(dir, NULL), 0);
    free(path);
    remove_dir(dir);
}

Test(image, exr_read_errors)
{
    char *dir = make_dir();
    char *path = join(dir, "absent.exr");
    uint32_t w = 7, h = 7;
    size_t n = 7;
    char **names = (char **)&w;
    float **planes = (float **)&h;
    rp_error err = {{0}};
    cr_assert_neq(rp_image_read_exr(path, &w, &h, &n, &names, &planes, &err), RP_OK);
    cr_assert_not_null(strstr(err.message, path), "message: %s", err.message);
    cr_assert_null(names);
    cr_assert_null(planes);
    cr_assert_eq(n, 0);
    cr_assert_null(rp_image_read_exr_attr(path, "radpt:method"));

    /* Not an EXR file. */
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    fputs("P3 1 1 255 0 0 0\n", f);
    fclose(f);
    err.message[0] = '\0';
    cr_assert_neq(rp_image_read_exr(path, &w, &h, &n, &names, &planes, &err), RP_OK);
    cr_assert_neq(err.message[0], '\0');
    cr_assert_null(rp_image_read_exr_attr(path, "radpt:method"));
    free(path);
    remove_dir(dir);
}

/* ---------------------------------------------------------------------
 * PNG */

/* The sRGB OETF, IEC 61966-2-1, written out again here. */
static int srgb_ref(double v)
{
    if (isnan(v) || v <= 0)
        return 0;
    if (v >= 1)
        return 255;
    double e = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055;
    return (int)floor(255 * e + 0.5);
}

/* Reads an 8-bit RGB PNG with libpng's simplified API. */
static unsigned char *read_png_rgb(const char *path, uint32_t *w, uint32_t *h)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    cr_assert(png_image_begin_read_from_file(&im, path), "libpng: %s", im.message);
    cr_assert_eq(im.format & PNG_FORMAT_FLAG_COLOR, PNG_FORMAT_FLAG_COLOR);
    im.format = PNG_FORMAT_RGB;
    unsigned char *buf = malloc(PNG_IMAGE_SIZE(im));
    cr_assert_not_null(buf);
    cr_assert(png_image_finish_read(&im, NULL, buf, 0, NULL), "libpng: %s", im.message);
    *w = im.width;
    *h = im.height;
    return buf;
}

static int file_contains(const char *path, const char *needle)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f);
    unsigned char buf[4096];
    size_t n = fread(buf, 1, sizeof buf, f);
    fclose(f);
    size_t m = strlen(needle);
    for (size_t i = 0; i + m <= n; i++)
        if (memcmp(buf + i, needle, m) == 0)
            return 1;
    return 0;
}

Test(image, png_srgb_values)
{
    char *dir = make_dir();
    char *path = join(dir, "p.png");
    /* 4 x 2, row-major from the top left. */
    const float r[8] = {0.5f, 0.0f, 1.0f, 2.0f, -1.0f, NAN, 0.002f, 0.18f};
    const float g[8] = {0.25f, 0.0031308f, 0.04f, INFINITY, -INFINITY, 0.9f, 0.5f, 1e-30f};
    const float b[8] = {0.0f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f};
    rp_error err = {{0}};
    const rp_exposure ev0 = rp_exposure_fixed(0), ev1 = rp_exposure_fixed(1);
    cr_assert_float_eq(ev0.scale, 1.0, 0);
    cr_assert_float_eq(ev1.scale, 2.0, 0);
    cr_assert_eq(rp_image_write_png(path, 4, 2, r, g, b, &ev0, &err), RP_OK, "%s", err.message);

    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(path, &w, &h);
    cr_assert_eq(w, 4);
    cr_assert_eq(h, 2);
    /* Hand-computed: 1.055 * 0.5^(1/2.4) - 0.055 = 0.735357, * 255 = 187.52. */
    cr_assert_eq(px[0], 188);
    /* 12.92 * 0.002 * 255 = 6.59 (linear segment). */
    cr_assert_eq(px[3 * 6 + 0], 7);
    cr_assert_eq(px[3 * 1 + 0], 0);   /* 0 */
    cr_assert_eq(px[3 * 2 + 0], 255); /* 1 */
    cr_assert_eq(px[3 * 3 + 0], 255); /* 2 clamps */
    cr_assert_eq(px[3 * 4 + 0], 0);   /* -1 clamps */
    cr_assert_eq(px[3 * 5 + 0], 0);   /* NaN */
    cr_assert_eq(px[3 * 3 + 1], 255); /* +inf */
    cr_assert_eq(px[3 * 4 + 1], 0);   /* -inf */
    for (int i = 0; i < 8; i++) {
        cr_assert_eq(px[3 * i + 0], srgb_ref(r[i]), "pixel %d red", i);
        cr_assert_eq(px[3 * i + 1], srgb_ref(g[i]), "pixel %d green", i);
        cr_assert_eq(px[3 * i + 2], srgb_ref(b[i]), "pixel %d blue", i);
    }
    free(px);
    cr_assert(file_contains(path, "sRGB"), "no sRGB chunk");

    /* Exposure scales before the curve: EV 1, 0.25 * 2 = 0.5 -> 188. */
    cr_assert_eq(rp_image_write_png(path, 4, 2, g, g, g, &ev1, &err), RP_OK, "%s", err.message);
    px = read_png_rgb(path, &w, &h);
    cr_assert_eq(px[0], 188);
    cr_assert_eq(px[1], 188);
    cr_assert_eq(px[2], 188);
    for (int i = 0; i < 8; i++)
        cr_assert_eq(px[3 * i], srgb_ref(2.0 * g[i]), "pixel %d", i);
    free(px);

    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1);
    cr_assert_eq(temps, 0);
    free(path);
    remove_dir(dir);
}

Test(image, png_odd_size_grey)
{
    char *dir = make_dir();
    char *path = join(dir, "grey.png");
    uint32_t W = 37, H = 19;
    float *y = malloc((size_t)W * H * sizeof *y);
    cr_assert_not_null(y);
    for (size_t i = 0; i < (size_t)W * H; i++)
        y[i] = (float)i / (float)(W * H - 1); /* ramp 0..1 */
    rp_error err = {{0}};
    const rp_exposure ev0 = rp_exposure_fixed(0);
    cr_assert_eq(rp_image_write_png(path, W, H, y, y, y, &ev0, &err), RP_OK, "%s", err.message);
    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(path, &w, &h);
    cr_assert_eq(w, W);
    cr_assert_eq(h, H);
    for (size_t i = 0; i < (size_t)W * H; i++) {
        int want = srgb_ref(y[i]);
        cr_assert_eq(px[3 * i], want, "pixel %zu", i);
        cr_assert_eq(px[3 * i + 1], want);
        cr_assert_eq(px[3 * i + 2], want);
    }
    cr_assert_eq(px[0], 0);
    cr_assert_eq(px[3 * ((size_t)W * H - 1)], 255);
    free(px);
    free(y);
    free(path);
    remove_dir(dir);
}

Test(image, png_failures_leave_nothing)
{
    char *dir = make_dir();
    char *sub = join(dir, "missing");
    char *path = join(sub, "p.png");
    const float v[1] = {0.5f};
    rp_error err = {{0}};
    const rp_exposure ev0 = rp_exposure_fixed(0), bad = {.ev = NAN, .scale = NAN};
    cr_assert_eq(rp_image_write_png(path, 1, 1, v, v, v, &ev0, &err), RP_ERR_RUNTIME);
    cr_assert_not_null(strstr(err.message, path), "message: %s", err.message);
    cr_assert(!path_exists(path));

    char *ok = join(dir, "p.png");
    cr_assert_eq(rp_image_write_png(ok, 1, 1, v, v, v, &bad, &err), RP_ERR_INPUT);
    cr_assert_eq(rp_image_write_png(ok, 0, 1, v, v, v, &ev0, &err), RP_ERR_INPUT);
    cr_assert_eq(rp_image_write_png(ok, 1, 1, v, NULL, v, &ev0, &err), RP_ERR_INPUT);
    /* The target is a directory: the write succeeds, the rename fails. */
    cr_assert_eq(mkdir(ok, 0700), 0);
    cr_assert_eq(rp_image_write_png(ok, 1, 1, v, v, v, &ev0, &err), RP_ERR_RUNTIME);
    int temps = -1;
    cr_assert_eq(count_entries(dir, &temps), 1);
    cr_assert_eq(temps, 0);
    free(ok);
    free(path);
    free(sub);
    remove_dir(dir);
}

/* ---------------------------------------------------------------------
 * Exposure (image.h): the 99th-percentile luminance maps to 0.9 */

/* The tEXt value stored under key, read back with libpng (malloc'd), or
 * NULL. */
static char *read_png_text(const char *path, const char *key)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f, "%s: %s", path, strerror(errno));
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    cr_assert(png && info);
    char *found = NULL;
    if (setjmp(png_jmpbuf(png)) == 0) {
        png_init_io(png, f);
        png_read_info(png, info);
        png_textp text = NULL;
        int n = 0;
        png_get_text(png, info, &text, &n);
        for (int i = 0; i < n && !found; i++)
            if (strcmp(text[i].key, key) == 0)
                found = strdup(text[i].text);
    }
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return found;
}

/* The scale a stored "EV e (scale s), ..." text gives, NAN if none. */
static double text_scale(const char *text)
{
    double ev, scale;
    if (!text || sscanf(text, "EV %lf (scale %lf)", &ev, &scale) != 2)
        return NAN;
    return scale;
}

/* 15 x 15 grey pixels: the values 1 .. 200 in a scrambled order, 20 zeros,
 * 2 NaN, 2 +inf and one -3.  Ignoring the zeros, the non-finite and the
 * negative, 200 values are left; the nearest-rank 99th percentile is the
 * ceil(0.99 * 200) = 198th smallest, 198, so scale = 0.9 / 198. */
Test(image, png_auto_exposure_is_the_99th_percentile)
{
    enum { W = 15, H = 15, N = W * H };
    float v[N];
    size_t k = 0;
    for (int i = 0; i < 200; i++)
        v[k++] = (float)((i * 77) % 200 + 1); /* 77 is prime to 200: a permutation */
    for (int i = 0; i < 20; i++)
        v[k++] = 0.0f;
    v[k++] = NAN;
    v[k++] = INFINITY;
    v[k++] = -3.0f;
    v[k++] = NAN;
    v[k++] = INFINITY;
    cr_assert_eq(k, (size_t)N);
    /* move the odd pixels around so they are not all at the end */
    for (size_t i = 0; i < N; i += 7) {
        float t = v[i];
        v[i] = v[N - 1 - i / 7];
        v[N - 1 - i / 7] = t;
    }
    rp_error err = {{0}};
    rp_exposure ex;
    cr_assert_eq(rp_exposure_auto(N, v, v, v, &ex, &err), RP_OK, "%s", err.message);
    cr_assert(ex.automatic);
    cr_assert_float_eq(ex.anchor, 198.0, 0);
    cr_assert_float_eq(ex.scale, 0.9 / 198.0, 0);
    cr_assert_float_eq(ex.ev, log2(0.9 / 198.0), 1e-12);

    /* The PNG with exposure NULL (automatic) against the sRGB formula. */
    char *dir = make_dir();
    char *path = join(dir, "auto.png");
    cr_assert_eq(rp_image_write_png(path, W, H, v, v, v, NULL, &err), RP_OK, "%s", err.message);
    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(path, &w, &h);
    cr_assert_eq(w, W);
    cr_assert_eq(h, H);
    int saw198 = 0;
    for (size_t i = 0; i < N; i++) {
        int want = srgb_ref(0.9 / 198.0 * (double)v[i]);
        cr_assert_eq(px[3 * i], want, "pixel %zu (%g): %d, want %d", i, v[i], px[3 * i], want);
        cr_assert_eq(px[3 * i + 1], want);
        cr_assert_eq(px[3 * i + 2], want);
        if (v[i] == 198.0f) {
            /* 0.9 -> 1.055 * 0.9^(1/2.4) - 0.055 = 0.95469, * 255 = 243.45 */
            cr_assert_eq(px[3 * i], 243);
            saw198 = 1;
        }
        if (v[i] == 200.0f) /* 0.90909 -> 0.95892, * 255 = 244.53 */
            cr_assert_eq(px[3 * i], 245);
    }
    cr_assert(saw198);
    free(px);
    char *text = read_png_text(path, "radpt:exposure");
    cr_assert_not_null(text, "no radpt:exposure tEXt chunk");
    cr_assert_not_null(strstr(text, "automatic"), "%s", text);
    cr_assert_float_eq(text_scale(text), 0.9 / 198.0, 1e-6 * 0.9 / 198.0, "%s", text);
    free(text);
    free(path);
    remove_dir(dir);
}

/* Colour: the percentile is of the Rec. 709 luminance, not of a channel.
 * 100 red pixels R = 1 .. 100 (Y = 0.2126 R) and 100 blue ones B = 1 ..
 * 100 (Y = 0.0722 B): the 99th percentile of the 200 luminances is the
 * 198th smallest, 0.2126 * 98 (the largest blue Y, 7.22, is below the
 * red 0.2126 * 34 = 7.23); a per-channel maximum would pick 99 or 100. */
Test(image, png_auto_exposure_uses_luminance)
{
    enum { N = 200 };
    float r[N] = {0}, g[N] = {0}, b[N] = {0};
    for (int i = 0; i < 100; i++) {
        r[2 * i] = (float)(i + 1);
        b[2 * i + 1] = (float)(100 - i);
    }
    rp_error err = {{0}};
    rp_exposure ex;
    cr_assert_eq(rp_exposure_auto(N, r, g, b, &ex, &err), RP_OK, "%s", err.message);
    double y98 = 0.2126 * 98.0;
    cr_assert_float_eq(ex.anchor, y98, 1e-12 * y98);
    cr_assert_float_eq(ex.scale, 0.9 / y98, 1e-12);

    char *dir = make_dir();
    char *path = join(dir, "rgb.png");
    cr_assert_eq(rp_image_write_png(path, 20, 10, r, g, b, &ex, &err), RP_OK, "%s", err.message);
    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(path, &w, &h);
    for (size_t i = 0; i < N; i++) {
        cr_assert_eq(px[3 * i], srgb_ref(ex.scale * r[i]), "pixel %zu red", i);
        cr_assert_eq(px[3 * i + 1], 0);
        cr_assert_eq(px[3 * i + 2], srgb_ref(ex.scale * b[i]), "pixel %zu blue", i);
    }
    free(px);
    free(path);
    remove_dir(dir);
}

/* An all-black image (zeros, NaN, negative) stays black: scale 1, EV 0,
 * every code 0, no NaN anywhere. */
Test(image, png_auto_exposure_black_image)
{
    const float v[6] = {0.0f, 0.0f, NAN, -1.0f, -0.0f, 0.0f};
    rp_error err = {{0}};
    rp_exposure ex;
    cr_assert_eq(rp_exposure_auto(6, v, v, v, &ex, &err), RP_OK, "%s", err.message);
    cr_assert_float_eq(ex.scale, 1.0, 0);
    cr_assert_float_eq(ex.ev, 0.0, 0);
    cr_assert_float_eq(ex.anchor, 0.0, 0);
    char *dir = make_dir();
    char *path = join(dir, "black.png");
    cr_assert_eq(rp_image_write_png(path, 3, 2, v, v, v, NULL, &err), RP_OK, "%s", err.message);
    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(path, &w, &h);
    for (int i = 0; i < 18; i++)
        cr_assert_eq(px[i], 0, "byte %d", i);
    free(px);
    char *text = read_png_text(path, "radpt:exposure");
    cr_assert_not_null(text);
    cr_assert_float_eq(text_scale(text), 1.0, 0, "%s", text);
    cr_assert_null(strstr(text, "nan"), "%s", text);
    free(text);
    free(path);
    remove_dir(dir);
}

/* The percentile against a sort, on large images with many ties (the
 * selection is a quickselect, image.c): 20 pseudo-random images of up to
 * 5000 values drawn from few levels. */
static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

Test(image, png_auto_exposure_matches_a_sort)
{
    enum { NMAX = 5000 };
    float *v = malloc(NMAX * sizeof *v);
    double *sorted = malloc(NMAX * sizeof *sorted);
    cr_assert(v && sorted);
    uint64_t state = 12345;
    for (int trial = 0; trial < 20; trial++) {
        size_t n = 1 + (size_t)(trial * 263) % NMAX, m = 0;
        unsigned levels = 1 + (unsigned)trial * 3;
        for (size_t i = 0; i < n; i++) {
            state = state * UINT64_C(6364136223846793005) + UINT64_C(1442695040888963407);
            unsigned l = (unsigned)(state >> 33) % (levels + 1); /* level 0: a zero pixel */
            v[i] = (float)l * 0.37f;
            if (l > 0)
                sorted[m++] = v[i];
        }
        rp_error err = {{0}};
        rp_exposure ex;
        cr_assert_eq(rp_exposure_auto(n, v, v, v, &ex, &err), RP_OK, "%s", err.message);
        if (m == 0) {
            cr_assert_float_eq(ex.scale, 1.0, 0);
            continue;
        }
        qsort(sorted, m, sizeof *sorted, cmp_double);
        size_t rank = (size_t)ceil(0.99 * (double)m);
        cr_assert_float_eq(ex.anchor, sorted[rank - 1], 0, "trial %d: n %zu, %zu lit", trial, n, m);
    }
    free(v);
    free(sorted);
}

Test(image, exposure_parse)
{
    rp_error err = {{0}};
    rp_exposure ex;
    cr_assert_eq(rp_exposure_parse("-1.5", &ex, &err), RP_OK, "%s", err.message);
    cr_assert_float_eq(ex.scale, 1.0 / sqrt(8.0), 1e-15);
    cr_assert(!ex.automatic);
    cr_assert_eq(rp_exposure_parse("3", &ex, &err), RP_OK);
    cr_assert_float_eq(ex.scale, 8.0, 0);
    const char *bad[] = {"", "x", "1e9", "nan", "inf", "2 stops", "-101"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        cr_assert_eq(rp_exposure_parse(bad[i], &ex, &err), RP_ERR_INPUT, "'%s' accepted", bad[i]);
        cr_assert_not_null(strstr(err.message, "--exposure"), "%s", err.message);
    }
}

/* ---------------------------------------------------------------------
 * The PNGs radpt writes */

/* render --png: with no --exposure the preview is the EXR's radiance
 * times 0.9 / Y99, Y99 the nearest-rank 99th percentile of the lit pixels
 * computed here with a sort; --exposure -1 halves the radiance; the
 * exposure is on stderr and in the PNG. */
Test(image, render_png_exposure, .timeout = 60)
{
    char *dir = make_dir();
    char *exr = join(dir, "f.exr"), *png = join(dir, "f.png");
    char args[1024];
    snprintf(args, sizeof args,
             "render scenes/cube-ceiling.scene --method pathtrace --spp 2 --seed 3 -o %s --png %s", exr, png);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_assert_not_null(strstr(r.err, "exposure EV"), "stderr: %s", r.err);
    cr_assert_not_null(strstr(r.err, "automatic"), "stderr: %s", r.err);
    rp_run_free(&r);

    uint32_t W = 0, H = 0;
    size_t nc = 0;
    char **names = NULL;
    float **planes = NULL;
    rp_error err = {{0}};
    cr_assert_eq(rp_image_read_exr(exr, &W, &H, &nc, &names, &planes, &err), RP_OK, "%s", err.message);
    cr_assert_eq(nc, 1u);
    cr_assert_str_eq(names[0], "Y");
    const float *y = planes[0];
    size_t npix = (size_t)W * H, m = 0;
    double *lit = malloc(npix * sizeof *lit);
    cr_assert_not_null(lit);
    for (size_t i = 0; i < npix; i++)
        if (isfinite(y[i]) && y[i] > 0)
            lit[m++] = y[i];
    cr_assert_gt(m, npix / 2);
    qsort(lit, m, sizeof *lit, cmp_double);
    double scale = 0.9 / lit[(size_t)ceil(0.99 * (double)m) - 1];

    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(png, &w, &h);
    cr_assert_eq(w, W);
    cr_assert_eq(h, H);
    size_t bright = 0;
    for (size_t i = 0; i < npix; i++) {
        cr_assert_eq(px[3 * i], srgb_ref(scale * y[i]), "pixel %zu: %g", i, y[i]);
        bright += px[3 * i] > 128;
    }
    cr_assert_gt(bright, npix / 10, "only %zu of %zu pixels brighter than mid-grey", bright, npix);
    free(px);
    char *text = read_png_text(png, "radpt:exposure");
    cr_assert_float_eq(text_scale(text), scale, 1e-5 * scale, "%s", text);
    free(text);

    snprintf(args, sizeof args,
             "render scenes/cube-ceiling.scene --method pathtrace --spp 2 --seed 3 -o %s --png %s --exposure -1",
             exr, png);
    r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    cr_assert_not_null(strstr(r.err, "fixed"), "stderr: %s", r.err);
    rp_run_free(&r);
    px = read_png_rgb(png, &w, &h);
    for (size_t i = 0; i < npix; i++)
        cr_assert_eq(px[3 * i], srgb_ref(0.5 * y[i]), "pixel %zu: %g", i, y[i]);
    free(px);

    /* bad values, and --exposure without a PNG, are usage errors */
    const char *bad[] = {"--png %s --exposure bright", "--png %s --exposure nan", "--exposure 1"};
    for (size_t k = 0; k < 3; k++) {
        char tail[512];
        snprintf(tail, sizeof tail, bad[k], png);
        snprintf(args, sizeof args, "render scenes/cube-ceiling.scene --method pathtrace --spp 1 -o %s %s", exr,
                 tail);
        r = rp_run_radpt(args);
        cr_expect_eq(r.status, 2, "%s: stderr %s", tail, r.err);
        cr_expect_not_null(strstr(r.err, "--exposure"), "%s: stderr %s", tail, r.err);
        rp_run_free(&r);
    }
    for (size_t c = 0; c < nc; c++) {
        free(names[c]);
        free(planes[c]);
    }
    free(names);
    free(planes);
    free(lit);
    free(exr);
    free(png);
    remove_dir(dir);
}

/* bench's image sheet: one exposure for every image on it, the automatic
 * one of the reference (the furnace's exact reference is L = 2 at every
 * pixel, so 0.9 / 2), or --exposure.  The reference tile's pixels must be
 * the sRGB code of 0.45 * 2 = 0.9 (243), then of 2^-2 * 2 = 0.5 (188). */
static void sheet_case(const char *extra, double scale, int code)
{
    char *dir = make_dir();
    char args[1024];
    snprintf(args, sizeof args,
             "bench scenes/furnace.scene --methods jacobi:elements=24 --budget 0.1 --checkpoints 1 --seeds 1 "
             "--cache %s -o %s/b %s",
             dir, dir, extra);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "stderr: %s", r.err);
    rp_run_free(&r);
    char *sheet = join(dir, "b/sheet.png");
    char *text = read_png_text(sheet, "radpt:exposure");
    cr_assert_float_eq(text_scale(text), scale, 1e-6 * scale, "%s", text);
    uint32_t w = 0, h = 0;
    unsigned char *px = read_png_rgb(sheet, &w, &h);
    /* the sheet has a 4-pixel margin; the reference is the first tile */
    cr_assert_gt(w, 2 * 128u);
    for (uint32_t y = 4; y < 4 + 128; y += 9)
        for (uint32_t x = 4; x < 4 + 128; x += 7)
            cr_assert_eq(px[3 * ((size_t)y * w + x)], code, "(%u, %u)", x, y);
    free(px);
    free(text);
    free(sheet);
    char cmd[1100];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_assert_eq(system(cmd), 0);
    free(dir);
}

Test(image, bench_sheet_one_exposure, .timeout = 60)
{
    cr_assert_eq(srgb_ref(0.9), 243);
    cr_assert_eq(srgb_ref(0.5), 188);
    sheet_case("", 0.45, 243);
    sheet_case("--exposure -2", 0.25, 188);
}
