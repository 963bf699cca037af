/* Image files: OpenEXR through the OpenEXRCore C API (the only module that
 * calls exr_*), and a tone-mapped sRGB PNG preview through libpng.  Writes
 * are atomic: a temporary name in the same directory, then rename(2), so a
 * failed run leaves no partial file. */
#ifndef RP_IMAGE_H
#define RP_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#include "../geometry/status.h"

typedef struct rp_image_attr {
    const char *name;   /* e.g. "radpt:method" */
    const char *value;  /* string attribute */
} rp_image_attr;

/* A float image: nchannels planes of width * height values, row-major
 * from the top-left; plane c is named channel_names[c]. */
typedef struct rp_image {
    uint32_t width, height;
    size_t nchannels;
    const char *const *channel_names;
    const float *const *planes;
    const rp_image_attr *attrs;
    size_t nattrs;
} rp_image;

/* Writes 32-bit float channels, ZIP compression, with the attributes as
 * string metadata. */
rp_status rp_image_write_exr(const char *path, const rp_image *img, rp_error *err);

/* Reads an EXR written by rp_image_write_exr back (all channels as float).
 * The caller frees *planes[i], *planes, *names[i] and *names with free(). */
rp_status rp_image_read_exr(const char *path, uint32_t *width, uint32_t *height,
                            size_t *nchannels, char ***names, float ***planes,
                            rp_error *err);

/* Reads one string attribute; returns a malloc'd copy or NULL. */
char *rp_image_read_exr_attr(const char *path, const char *name);

/* A preview: linear RGB (3 planes) scaled by exposure, then the sRGB
 * transfer curve, 8 bits per channel. */
rp_status rp_image_write_png(const char *path, uint32_t width, uint32_t height,
                             const float *r, const float *g, const float *b,
                             double exposure, rp_error *err);

#endif
