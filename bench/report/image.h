/* Image files: OpenEXR through the OpenEXRCore C API (the only module that
 * calls exr_*), a tone-mapped sRGB PNG preview and PNG input (masks)
 * through libpng.  Writes
 * are atomic: a temporary name in the same directory, then rename(2), so a
 * failed run leaves no partial file. */
#ifndef RP_IMAGE_H
#define RP_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#include "geometry/status.h"

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

/* Reads part 0 of an EXR (rp_image_write_exr's, or another program's):
 * every channel as float (half, float or uint stored, any compression
 * OpenEXRCore decodes), the data window's pixels; scanline or tiled
 * storage, a tiled image read at level 0 (mipmaps and ripmaps: the full
 * resolution).  Deep and subsampled images are refused (RP_ERR_UNSUPPORTED);
 * a missing or non-EXR file is RP_ERR_INPUT.  The caller frees
 * *planes[i], *planes, *names[i] and *names with free(). */
rp_status rp_image_read_exr(const char *path, uint32_t *width, uint32_t *height,
                            size_t *nchannels, char ***names, float ***planes,
                            rp_error *err);

/* Reads one string attribute; returns a malloc'd copy or NULL. */
char *rp_image_read_exr_attr(const char *path, const char *name);

/* The exposure of a PNG preview: linear radiance is multiplied by scale
 * (2^ev, ev in stops) before the sRGB transfer curve. */
typedef struct rp_exposure {
    double ev;      /* stops: scale = 2^ev */
    double scale;   /* the linear multiplier */
    int automatic;  /* 1: chosen from the image by rp_exposure_auto */
    double anchor;  /* automatic: the image's 99th-percentile luminance
                       (0: no pixel with a finite luminance > 0) */
} rp_exposure;

/* The automatic exposure maps the RP_EXPOSURE_PERCENTILE quantile of the
 * pixels' luminance to RP_EXPOSURE_WHITE (before the sRGB curve), so a few
 * bright pixels (a lamp) clip and the rest of the image is seen. */
#define RP_EXPOSURE_PERCENTILE 0.99
#define RP_EXPOSURE_WHITE 0.9

/* A fixed exposure of ev stops (scale 2^ev). */
rp_exposure rp_exposure_fixed(double ev);

/* Parses an --exposure value: a finite number of stops in [-100, 100];
 * the message names the value and says what is wrong. */
rp_status rp_exposure_parse(const char *text, rp_exposure *out, rp_error *err);

/* The automatic exposure of linear RGB planes (npix values each): Y the
 * Rec. 709 luminance 0.2126 R + 0.7152 G + 0.0722 B (R for a grey pixel,
 * R = G = B); over the pixels whose Y is finite and > 0, the
 * nearest-rank 99th percentile Y99 (the ceil(0.99 n)-th smallest of n)
 * maps to 0.9: scale = 0.9 / Y99.  Without such a pixel (an all-black
 * image) the scale is 1 (ev 0), so black stays black.  RP_ERR_NOMEM when
 * scratch memory runs out. */
rp_status rp_exposure_auto(size_t npix, const float *r, const float *g, const float *b, rp_exposure *out,
                           rp_error *err);

/* "EV 3.16993 (scale 9), automatic: 99th-percentile luminance 0.1 -> 0.9" or
 * "EV 2 (scale 4), fixed"; the text radpt prints and stores in PNGs. */
void rp_exposure_describe(const rp_exposure *e, char *buf, size_t n);

/* A preview: linear RGB (3 planes) multiplied by the exposure's scale,
 * then the sRGB transfer curve (IEC 61966-2-1), 8 bits per channel.
 * exposure NULL: rp_exposure_auto of these planes.  The exposure used is
 * stored as a tEXt chunk "radpt:exposure" (rp_exposure_describe). */
rp_status rp_image_write_png(const char *path, uint32_t width, uint32_t height,
                             const float *r, const float *g, const float *b,
                             const rp_exposure *exposure, rp_error *err);

/* Reads a PNG's samples as stored (libpng): grey, grey + alpha, RGB or
 * RGBA at 8 or 16 bits, interlaced or not; grey at 1, 2 or 4 bits is
 * widened to 8 (0 stays 0); a palette image gives its colours' R, G, B.
 * Transparency from a tRNS chunk is not a channel and is ignored; no gamma
 * is applied.  *channels gets 1 to 4, *samples width * height * channels
 * values (channel fastest, rows from the top), 0..255 or 0..65535.  A
 * missing, unreadable, non-PNG or corrupt file is RP_ERR_INPUT with the
 * file named.  The caller frees *samples. */
rp_status rp_image_read_png(const char *path, uint32_t *width, uint32_t *height, size_t *channels,
                            uint16_t **samples, rp_error *err);

/* Portable Float Map (Debevec's PFM): "PF", width height, scale -1.0
 * (little-endian floats), rows from the bottom up; linear radiance as
 * given.  Written like the others (temporary name, fsync, rename). */
rp_status rp_image_write_pfm(const char *path, uint32_t width, uint32_t height, const float *r, const float *g,
                             const float *b, rp_error *err);

/* An output format, chosen by the file name's extension (any case). */
typedef enum rp_image_format { RP_IMAGE_UNKNOWN, RP_IMAGE_EXR, RP_IMAGE_PNG, RP_IMAGE_PFM } rp_image_format;
rp_image_format rp_image_format_of(const char *path);

#endif
