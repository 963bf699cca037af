/* Mask images (see mask.h): the pixel rule over either reader of
 * bench/report/image.h. */
#include "bench/report/mask.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/report/image.h"

/* File signatures: PNG spec 5.2; OpenEXR file layout, "Magic Number"
 * (20000630 as a little-endian int). */
static const unsigned char png_magic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
static const unsigned char exr_magic[4] = {0x76, 0x2f, 0x31, 0x01};

typedef enum mask_kind { MASK_PNG, MASK_EXR } mask_kind;

static rp_status mask_kind_of(const char *path, mask_kind *kind, rp_error *err)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot open the mask: %s", path, strerror(errno));
    unsigned char head[8];
    size_t got = fread(head, 1, sizeof head, f);
    int bad = ferror(f), e = errno;
    fclose(f);
    if (bad)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot read the mask: %s", path, strerror(e));
    if (got >= sizeof exr_magic && !memcmp(head, exr_magic, sizeof exr_magic))
        *kind = MASK_EXR;
    else if (got == sizeof png_magic && !memcmp(head, png_magic, sizeof png_magic))
        *kind = MASK_PNG;
    else
        return rp_error_set(err, RP_ERR_INPUT, "%s: the mask is not a PNG (nor an OpenEXR) file", path);
    return RP_OK;
}

static rp_status mask_size(const char *path, uint32_t w, uint32_t h, uint32_t width, uint32_t height,
                           rp_error *err)
{
    if (w == width && h == height)
        return RP_OK;
    return rp_error_set(err, RP_ERR_INPUT, "%s: the mask is %u x %u but the images are %u x %u", path, w, h,
                        width, height);
}

rp_status rp_mask_read(const char *path, uint32_t width, uint32_t height, unsigned char *mask, size_t *count,
                       rp_error *err)
{
    *count = 0;
    mask_kind kind;
    rp_status st = mask_kind_of(path, &kind, err);
    if (st != RP_OK)
        return st;
    size_t npix = (size_t)width * height;
    uint32_t w, h;
    size_t nch;
    if (kind == MASK_PNG) {
        uint16_t *s;
        if ((st = rp_image_read_png(path, &w, &h, &nch, &s, err)) != RP_OK)
            return st;
        if ((st = mask_size(path, w, h, width, height, err)) == RP_OK)
            for (size_t p = 0; p < npix; p++) {
                mask[p] = 0;
                for (size_t c = 0; c < nch; c++)
                    mask[p] |= s[p * nch + c] > 0;
                *count += mask[p];
            }
        free(s);
    } else {
        char **names;
        float **planes;
        if ((st = rp_image_read_exr(path, &w, &h, &nch, &names, &planes, err)) != RP_OK)
            return st;
        if ((st = mask_size(path, w, h, width, height, err)) == RP_OK)
            for (size_t p = 0; p < npix; p++) {
                mask[p] = 0;
                for (size_t c = 0; c < nch; c++)
                    mask[p] |= planes[c][p] > 0; /* false for NaN */
                *count += mask[p];
            }
        for (size_t c = 0; c < nch; c++) {
            free(names[c]);
            free(planes[c]);
        }
        free(names);
        free(planes);
    }
    if (st == RP_OK && *count == 0)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the mask selects no pixel (none has a channel > 0)", path);
    return st;
}
