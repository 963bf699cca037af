/* Mask images: which pixels of an image a comparison counts (radpt
 * compare --mask).  A pixel is selected when any channel of the mask file
 * holds a value > 0 there:
 *
 *   PNG: any stored channel (grey, grey + alpha, R G B, R G B A; 8 or 16
 *        bits, grey also 1, 2 or 4 bits), sample > 0; a palette image by
 *        its colours' R, G, B; tRNS transparency is not a channel
 *        (rp_image_read_png);
 *   EXR: any channel, value > 0 (0, negative and NaN values select
 *        nothing) (rp_image_read_exr).
 *
 * The kind is told by the file's first bytes, not its name. */
#ifndef RP_MASK_H
#define RP_MASK_H

#include <stddef.h>
#include <stdint.h>

#include "geometry/status.h"

/* Reads the mask at path for an image of width x height into mask (width *
 * height bytes, 1 selected, 0 not; row-major from the top-left) and its
 * number of selected pixels into *count.  RP_ERR_INPUT, with path in the
 * message: a missing or unreadable file, neither PNG nor EXR, a size
 * other than width x height (both sizes named), no pixel selected. */
rp_status rp_mask_read(const char *path, uint32_t width, uint32_t height, unsigned char *mask, size_t *count,
                       rp_error *err);

#endif
