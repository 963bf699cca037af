/* Image files: OpenEXR through the OpenEXRCore C API, sRGB PNG previews
 * through libpng.  See image.h.
 *
 * Both writers go through the same atomic scheme: create PATH.tmp.PID.N with
 * O_EXCL next to the target (same directory, so same file system), write
 * and fsync it, then rename(2) it over PATH.  Any failure unlinks the
 * temporary file, so PATH either holds a complete new image or is left as
 * it was. */
#include "bench/report/image.h"

#include "bench/report/files.h"

#include <OpenEXR/openexr.h>
#include <png.h>

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>


/* ---------------------------------------------------------------------
 * OpenEXRCore glue */

/* OpenEXRCore reports errors through a callback that by default prints to
 * stderr.  Ours stores the first message of the current call in a
 * thread-local buffer so it can go into the rp_error instead.  (The
 * context's user_data is not usable for this when reading: the built-in
 * file reader keeps its own handle there.) */
typedef struct exr_capture {
    char message[512];
} exr_capture;

static _Thread_local exr_capture *exr_current_capture;

static void exr_capture_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    exr_capture *cap = exr_current_capture;
    if (cap && cap->message[0] == '\0')
        snprintf(cap->message, sizeof cap->message, "%s (%s)", msg ? msg : "",
                 exr_get_error_code_as_string(code));
}

/* Message for a failed exr_* call: the captured text, else the library's
 * generic text for the code. */
static const char *exr_message(const exr_capture *cap, exr_result_t rv)
{
    return cap->message[0] ? cap->message : exr_get_default_error_message(rv);
}

/* Write sink: pwrite(2) onto the temporary file's descriptor. */
typedef struct exr_sink {
    int fd;
} exr_sink;

static int64_t exr_sink_write(exr_const_context_t ctxt, void *userdata, const void *buffer,
                              uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    const exr_sink *sink = userdata;
    const unsigned char *p = buffer;
    uint64_t done = 0;
    while (done < sz) {
        uint64_t chunk = sz - done;
        if (chunk > (uint64_t)1 << 30)
            chunk = (uint64_t)1 << 30;
        if (offset + done > (uint64_t)INT64_MAX) {
            if (error_cb)
                error_cb(ctxt, EXR_ERR_WRITE_IO, "write offset out of range");
            return -1;
        }
        ssize_t n = pwrite(sink->fd, p + done, (size_t)chunk, (off_t)(offset + done));
        if (n < 0) {
            if (errno == EINTR)
                continue;
            if (error_cb)
                error_cb(ctxt, EXR_ERR_WRITE_IO, "cannot write %llu bytes: %s",
                         (unsigned long long)chunk, strerror(errno));
            return -1;
        }
        done += (uint64_t)n;
    }
    return (int64_t)done;
}

/* OpenEXR 2.0 and later allow names up to 255 bytes only with the long
 * names flag; without it the limit is 31. */
#define EXR_SHORT_NAME_MAX 31
#define EXR_LONG_NAME_MAX 255

static rp_status exr_check_image(const char *path, const rp_image *img, int *longnames,
                                 rp_error *err)
{
    if (!path || !*path)
        return rp_error_set(err, RP_ERR_INPUT, "EXR output: no file name");
    if (!img)
        return rp_error_set(err, RP_ERR_INPUT, "%s: no image", path);
    if (img->width == 0 || img->height == 0 || img->width > INT32_MAX / 2 ||
        img->height > INT32_MAX / 2)
        return rp_error_set(err, RP_ERR_INPUT, "%s: image size %u x %u out of range", path,
                            img->width, img->height);
    if (img->nchannels == 0 || img->nchannels > INT16_MAX)
        return rp_error_set(err, RP_ERR_INPUT, "%s: %zu channels (need 1 to %d)", path,
                            img->nchannels, INT16_MAX);
    if (!img->channel_names || !img->planes)
        return rp_error_set(err, RP_ERR_INPUT, "%s: channel names or planes missing", path);
    if (img->nattrs > 0 && !img->attrs)
        return rp_error_set(err, RP_ERR_INPUT, "%s: attributes missing", path);
    *longnames = 0;
    for (size_t c = 0; c < img->nchannels; c++) {
        const char *name = img->channel_names[c];
        if (!name || !*name)
            return rp_error_set(err, RP_ERR_INPUT, "%s: channel %zu has no name", path, c);
        if (!img->planes[c])
            return rp_error_set(err, RP_ERR_INPUT, "%s: channel %s has no data", path, name);
        size_t len = strlen(name);
        if (len > EXR_LONG_NAME_MAX)
            return rp_error_set(err, RP_ERR_INPUT, "%s: channel name %.40s... longer than %d bytes",
                                path, name, EXR_LONG_NAME_MAX);
        if (len > EXR_SHORT_NAME_MAX)
            *longnames = 1;
        for (size_t d = 0; d < c; d++)
            if (strcmp(name, img->channel_names[d]) == 0)
                return rp_error_set(err, RP_ERR_INPUT, "%s: channel %s appears twice", path, name);
    }
    for (size_t a = 0; a < img->nattrs; a++) {
        const rp_image_attr *at = &img->attrs[a];
        if (!at->name || !*at->name || !at->value)
            return rp_error_set(err, RP_ERR_INPUT, "%s: attribute %zu has no name or value", path,
                                a);
        size_t len = strlen(at->name);
        if (len > EXR_LONG_NAME_MAX)
            return rp_error_set(err, RP_ERR_INPUT,
                                "%s: attribute name %.40s... longer than %d bytes", path, at->name,
                                EXR_LONG_NAME_MAX);
        if (len > EXR_SHORT_NAME_MAX)
            *longnames = 1;
        if (strlen(at->value) > INT32_MAX / 2)
            return rp_error_set(err, RP_ERR_INPUT, "%s: attribute %s too long", path, at->name);
    }
    return RP_OK;
}

/* Index of the image plane named name, or -1. */
static long plane_index(const rp_image *img, const char *name)
{
    for (size_t c = 0; c < img->nchannels; c++)
        if (strcmp(img->channel_names[c], name) == 0)
            return (long)c;
    return -1;
}

/* OpenEXRCore 3.1's ZIP, ZIPS and PXR24 encoders keep a compressed chunk
 * exactly as large as the raw data, which readers (OpenEXRCore and the C++
 * library alike) then take for raw data: in the file layout a chunk whose
 * stored size equals its raw size is uncompressed.  A 5 x 1 float image
 * 0, 0.25, 0, 0.25, 0 read back as zlib bytes.  Upstream fixed ZIP later
 * (openexr PR #2307, "compbufsz >= packed_bytes").  This wraps the chosen
 * compressor and stores such a chunk raw, as the library does with one
 * that grew. */
typedef struct exr_compress_guard {
    exr_result_t (*compress)(exr_encode_pipeline_t *enc);
} exr_compress_guard;

static exr_result_t exr_compress_guarded(exr_encode_pipeline_t *enc)
{
    const exr_compress_guard *g = enc->encoding_user_data;
    exr_result_t rv = g->compress(enc);
    if (rv == EXR_ERR_SUCCESS && enc->compressed_bytes >= enc->packed_bytes) {
        memcpy(enc->compressed_buffer, enc->packed_buffer, (size_t)enc->packed_bytes);
        enc->compressed_bytes = (size_t)enc->packed_bytes;
    }
    return rv;
}

/* Header and pixels of one scanline part.  Returns the failing call's
 * result, with *what naming the step. */
static exr_result_t exr_write_image(exr_context_t ctx, const rp_image *img, int longnames,
                                    const char **what)
{
    exr_result_t rv;
    int part = 0;

    *what = "add part";
    if ((rv = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part)) != EXR_ERR_SUCCESS)
        return rv;
    /* ZIP: lossless deflate over 16-scanline blocks (OpenEXR file layout). */
    *what = "set required attributes";
    if ((rv = exr_initialize_required_attr_simple(ctx, part, (int32_t)img->width,
                                                  (int32_t)img->height, EXR_COMPRESSION_ZIP)) !=
        EXR_ERR_SUCCESS)
        return rv;
    if (longnames) {
        *what = "enable long names";
        if ((rv = exr_set_longname_support(ctx, 1)) != EXR_ERR_SUCCESS)
            return rv;
    }
    *what = "add channel";
    for (size_t c = 0; c < img->nchannels; c++)
        if ((rv = exr_add_channel(ctx, part, img->channel_names[c], EXR_PIXEL_FLOAT,
                                  EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1)) != EXR_ERR_SUCCESS)
            return rv;
    *what = "set attribute";
    for (size_t a = 0; a < img->nattrs; a++)
        if ((rv = exr_attr_set_string(ctx, part, img->attrs[a].name, img->attrs[a].value)) !=
            EXR_ERR_SUCCESS)
            return rv;
    *what = "write header";
    if ((rv = exr_write_header(ctx)) != EXR_ERR_SUCCESS)
        return rv;

    int32_t lines_per_chunk = 0;
    *what = "query scanlines per chunk";
    if ((rv = exr_get_scanlines_per_chunk(ctx, part, &lines_per_chunk)) != EXR_ERR_SUCCESS)
        return rv;
    if (lines_per_chunk <= 0)
        return EXR_ERR_UNKNOWN;

    exr_encode_pipeline_t enc;
    memset(&enc, 0, sizeof enc);
    exr_compress_guard guard = {NULL};
    int initialised = 0;
    int32_t line_stride = (int32_t)(img->width * sizeof(float));
    for (int32_t y = 0; y < (int32_t)img->height; y += lines_per_chunk) {
        exr_chunk_info_t cinfo;
        *what = "prepare chunk";
        if ((rv = exr_write_scanline_chunk_info(ctx, part, y, &cinfo)) != EXR_ERR_SUCCESS)
            break;
        rv = initialised ? exr_encoding_update(ctx, part, &cinfo, &enc)
                         : exr_encoding_initialize(ctx, part, &cinfo, &enc);
        if (rv != EXR_ERR_SUCCESS)
            break;
        /* OpenEXRCore lists channels sorted by name, not in the order they
         * were added: map each by name.  Pointers are set for every chunk;
         * the last chunk may hold fewer lines than lines_per_chunk. */
        for (int16_t c = 0; c < enc.channel_count; c++) {
            exr_coding_channel_info_t *ch = &enc.channels[c];
            long k = plane_index(img, ch->channel_name);
            if (k < 0) {
                *what = "match channel";
                rv = EXR_ERR_UNKNOWN;
                break;
            }
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_bytes_per_element = (int16_t)sizeof(float);
            ch->user_pixel_stride = (int32_t)sizeof(float);
            ch->user_line_stride = line_stride;
            ch->encode_from_ptr =
                (const uint8_t *)(img->planes[k] + (size_t)cinfo.start_y * img->width);
        }
        if (rv != EXR_ERR_SUCCESS)
            break;
        if (!initialised) {
            *what = "choose encoder";
            if ((rv = exr_encoding_choose_default_routines(ctx, part, &enc)) != EXR_ERR_SUCCESS)
                break;
            initialised = 1;
            if (enc.compress_fn) {
                guard.compress = enc.compress_fn;
                enc.encoding_user_data = &guard;
                enc.compress_fn = exr_compress_guarded;
            }
        }
        *what = "encode chunk";
        if ((rv = exr_encoding_run(ctx, part, &enc)) != EXR_ERR_SUCCESS)
            break;
    }
    if (initialised || enc.channels)
        exr_encoding_destroy(ctx, &enc);
    return rv;
}

rp_status rp_image_write_exr(const char *path, const rp_image *img, rp_error *err)
{
    int longnames = 0;
    rp_status st = exr_check_image(path, img, &longnames, err);
    if (st != RP_OK)
        return st;

    int fd = -1;
    char *tmp = NULL;
    if ((st = rp_temp_open(path, &fd, &tmp, err)) != RP_OK)
        return st;

    exr_capture cap = {{0}};
    exr_capture *saved = exr_current_capture;
    exr_current_capture = &cap;

    exr_sink sink = {fd};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    init.user_data = &sink;
    init.write_fn = exr_sink_write;

    exr_context_t ctx = NULL;
    const char *what = "start writing";
    /* the name is for messages only: the sink writes to fd (tmp is NULL
     * where files are discarded, rp_files_discard) */
    exr_result_t rv = exr_start_write(&ctx, tmp ? tmp : path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_image(ctx, img, longnames, &what);
    if (ctx) {
        /* exr_finish writes the chunk offset table, so its result counts. */
        exr_result_t frv = exr_finish(&ctx);
        if (rv == EXR_ERR_SUCCESS && frv != EXR_ERR_SUCCESS) {
            rv = frv;
            what = "finish";
        }
    }
    exr_current_capture = saved;

    if (rv != EXR_ERR_SUCCESS) {
        rp_temp_discard(fd, tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: OpenEXR %s failed: %s", path, what,
                            exr_message(&cap, rv));
    }
    return rp_temp_commit(fd, tmp, path, err);
}

/* Decodes one chunk (a block of scanlines or a tile) into the planes
 * (width x height floats each, in the order of chlist): the chunk's first
 * pixel goes to (x0, y0) of the image, its rows width floats apart. */
static exr_result_t exr_decode_chunk(exr_context_t ctx, const exr_chunk_info_t *cinfo,
                                     exr_decode_pipeline_t *dec, int *initialised,
                                     const exr_attr_chlist_t *chlist, float **planes, size_t width,
                                     size_t height, size_t x0, size_t y0, const char **what)
{
    exr_result_t rv;
    if (cinfo->width < 0 || cinfo->height < 0 || x0 + (size_t)cinfo->width > width ||
        y0 + (size_t)cinfo->height > height) {
        *what = "place chunk";
        return EXR_ERR_CORRUPT_CHUNK;
    }
    rv = *initialised ? exr_decoding_update(ctx, 0, cinfo, dec)
                      : exr_decoding_initialize(ctx, 0, cinfo, dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    /* Pointers and strides are set for every chunk: edge chunks (the last
     * scanline block, the right and bottom tiles) are smaller. */
    for (int16_t c = 0; c < dec->channel_count; c++) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        long k = -1;
        for (int j = 0; j < chlist->num_channels; j++)
            if (strcmp(chlist->entries[j].name.str, ch->channel_name) == 0)
                k = j;
        if (k < 0) {
            *what = "match channel";
            return EXR_ERR_CORRUPT_CHUNK;
        }
        /* Whatever the stored type (half, float, uint), ask for float. */
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = (int16_t)sizeof(float);
        ch->user_pixel_stride = (int32_t)sizeof(float);
        ch->user_line_stride = (int32_t)(width * sizeof(float));
        ch->decode_to_ptr = (uint8_t *)(planes[k] + y0 * width + x0);
    }
    if (!*initialised) {
        *what = "choose decoder";
        if ((rv = exr_decoding_choose_default_routines(ctx, 0, dec)) != EXR_ERR_SUCCESS)
            return rv;
        *initialised = 1;
    }
    *what = "decode chunk";
    return exr_decoding_run(ctx, 0, dec);
}

/* Decodes every channel of part 0 into the planes (width * height floats
 * each, in the order of chlist).  A scanline part is read block by block;
 * a tiled part tile by tile at level (0, 0), which in every level mode
 * (one level, mipmap, ripmap) is the full-resolution image the data
 * window describes (OpenEXR file layout, "Tiles"); tile (tx, ty) holds the
 * pixels from (tx * tile width, ty * tile height) of the data window, and
 * the right and bottom tiles are cut at its edge. */
static exr_result_t exr_read_pixels(exr_context_t ctx, exr_storage_t storage,
                                    const exr_attr_box2i_t *dw, const exr_attr_chlist_t *chlist,
                                    float **planes, const char **what)
{
    exr_result_t rv = EXR_ERR_SUCCESS;
    size_t width = (size_t)((int64_t)dw->max.x - dw->min.x + 1);
    size_t height = (size_t)((int64_t)dw->max.y - dw->min.y + 1);
    exr_decode_pipeline_t dec;
    memset(&dec, 0, sizeof dec);
    int initialised = 0;
    exr_chunk_info_t cinfo;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines_per_chunk = 0;
        *what = "query scanlines per chunk";
        if ((rv = exr_get_scanlines_per_chunk(ctx, 0, &lines_per_chunk)) != EXR_ERR_SUCCESS)
            return rv;
        if (lines_per_chunk <= 0)
            return EXR_ERR_CORRUPT_CHUNK;
        for (int64_t y = dw->min.y; y <= dw->max.y && rv == EXR_ERR_SUCCESS; y += lines_per_chunk) {
            *what = "read chunk";
            if ((rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &cinfo)) != EXR_ERR_SUCCESS)
                break;
            if (cinfo.start_y < dw->min.y) {
                *what = "place chunk";
                rv = EXR_ERR_CORRUPT_CHUNK;
                break;
            }
            rv = exr_decode_chunk(ctx, &cinfo, &dec, &initialised, chlist, planes, width, height, 0,
                                  (size_t)((int64_t)cinfo.start_y - dw->min.y), what);
        }
    } else {
        int32_t tw = 0, th = 0, lw = 0, lh = 0;
        *what = "query tile size";
        if ((rv = exr_get_tile_sizes(ctx, 0, 0, 0, &tw, &th)) != EXR_ERR_SUCCESS)
            return rv;
        *what = "query level size";
        if ((rv = exr_get_level_sizes(ctx, 0, 0, 0, &lw, &lh)) != EXR_ERR_SUCCESS)
            return rv;
        if (tw <= 0 || th <= 0 || (size_t)lw != width || (size_t)lh != height) {
            *what = "check tile layout";
            return EXR_ERR_CORRUPT_CHUNK;
        }
        for (int32_t ty = 0; (int64_t)ty * th < lh && rv == EXR_ERR_SUCCESS; ty++)
            for (int32_t tx = 0; (int64_t)tx * tw < lw && rv == EXR_ERR_SUCCESS; tx++) {
                *what = "read tile";
                if ((rv = exr_read_tile_chunk_info(ctx, 0, tx, ty, 0, 0, &cinfo)) != EXR_ERR_SUCCESS)
                    break;
                rv = exr_decode_chunk(ctx, &cinfo, &dec, &initialised, chlist, planes, width, height,
                                      (size_t)tx * (size_t)tw, (size_t)ty * (size_t)th, what);
            }
    }
    if (initialised || dec.channels)
        exr_decoding_destroy(ctx, &dec);
    return rv;
}

static void free_planes(size_t n, char **names, float **planes)
{
    for (size_t c = 0; c < n; c++) {
        if (names)
            free(names[c]);
        if (planes)
            free(planes[c]);
    }
    free(names);
    free(planes);
}

rp_status rp_image_read_exr(const char *path, uint32_t *width, uint32_t *height,
                            size_t *nchannels, char ***names, float ***planes, rp_error *err)
{
    if (!path || !width || !height || !nchannels || !names || !planes)
        return rp_error_set(err, RP_ERR_INPUT, "EXR input: missing argument");
    *width = *height = 0;
    *nchannels = 0;
    *names = NULL;
    *planes = NULL;

    exr_capture cap = {{0}};
    exr_capture *saved = exr_current_capture;
    exr_current_capture = &cap;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;

    rp_status st = RP_OK;
    exr_context_t ctx = NULL;
    const char *what = "open";
    char **nm = NULL;
    float **pl = NULL;
    size_t n = 0;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS)
        goto exr_failed;

    exr_storage_t storage;
    what = "query storage";
    if ((rv = exr_get_storage(ctx, 0, &storage)) != EXR_ERR_SUCCESS)
        goto exr_failed;
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        st = rp_error_set(err, RP_ERR_UNSUPPORTED,
                          "%s: a deep EXR image (several samples per pixel); radpt reads flat scanline "
                          "and tiled images", path);
        goto done;
    }
    exr_attr_box2i_t dw;
    what = "query data window";
    if ((rv = exr_get_data_window(ctx, 0, &dw)) != EXR_ERR_SUCCESS)
        goto exr_failed;
    int64_t w = (int64_t)dw.max.x - dw.min.x + 1, h = (int64_t)dw.max.y - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > UINT32_MAX || h > UINT32_MAX ||
        (uint64_t)w > SIZE_MAX / sizeof(float) / (uint64_t)h) {
        st = rp_error_set(err, RP_ERR_INPUT, "%s: data window out of range", path);
        goto done;
    }
    const exr_attr_chlist_t *chlist = NULL;
    what = "query channels";
    if ((rv = exr_get_channels(ctx, 0, &chlist)) != EXR_ERR_SUCCESS)
        goto exr_failed;
    if (!chlist || chlist->num_channels <= 0) {
        st = rp_error_set(err, RP_ERR_INPUT, "%s: no channels", path);
        goto done;
    }
    for (int j = 0; j < chlist->num_channels; j++)
        if (chlist->entries[j].x_sampling != 1 || chlist->entries[j].y_sampling != 1) {
            st = rp_error_set(err, RP_ERR_UNSUPPORTED, "%s: channel %s is subsampled", path,
                              chlist->entries[j].name.str);
            goto done;
        }

    size_t count = (size_t)chlist->num_channels;
    size_t npix = (size_t)w * (size_t)h;
    nm = calloc(count, sizeof *nm);
    pl = calloc(count, sizeof *pl);
    if (!nm || !pl) {
        st = rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", path);
        goto done;
    }
    n = count;
    for (size_t c = 0; c < count; c++) {
        const exr_attr_string_t *s = &chlist->entries[c].name;
        nm[c] = malloc((size_t)s->length + 1);
        pl[c] = malloc(npix * sizeof(float));
        if (!nm[c] || !pl[c]) {
            st = rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", path);
            goto done;
        }
        memcpy(nm[c], s->str, (size_t)s->length);
        nm[c][s->length] = '\0';
    }
    if ((rv = exr_read_pixels(ctx, storage, &dw, chlist, pl, &what)) != EXR_ERR_SUCCESS)
        goto exr_failed;

    *width = (uint32_t)w;
    *height = (uint32_t)h;
    *nchannels = count;
    *names = nm;
    *planes = pl;
    nm = NULL;
    pl = NULL;
    n = 0;
    goto done;

exr_failed:
    /* A missing or non-EXR file is the caller's bad input (exit 2). */
    st = rp_error_set(err,
                      rv == EXR_ERR_FILE_ACCESS || rv == EXR_ERR_FILE_BAD_HEADER ? RP_ERR_INPUT
                                                                                  : RP_ERR_RUNTIME,
                      "%s: OpenEXR %s failed: %s", path, what, exr_message(&cap, rv));
done:
    free_planes(n, nm, pl);
    if (ctx)
        exr_finish(&ctx);
    exr_current_capture = saved;
    return st;
}

char *rp_image_read_exr_attr(const char *path, const char *name)
{
    if (!path || !name)
        return NULL;
    /* Failures here mean "no such attribute": capture and drop messages. */
    exr_capture cap = {{0}};
    exr_capture *saved = exr_current_capture;
    exr_current_capture = &cap;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    init.flags = EXR_CONTEXT_FLAG_SILENT_HEADER_PARSE;

    char *copy = NULL;
    exr_context_t ctx = NULL;
    if (exr_start_read(&ctx, path, &init) == EXR_ERR_SUCCESS) {
        const exr_attribute_t *attr = NULL;
        if (exr_get_attribute_by_name(ctx, 0, name, &attr) == EXR_ERR_SUCCESS && attr &&
            attr->type == EXR_ATTR_STRING) {
            int32_t len = 0;
            const char *s = NULL;
            if (exr_attr_get_string(ctx, 0, name, &len, &s) == EXR_ERR_SUCCESS && s && len >= 0 &&
                (copy = malloc((size_t)len + 1)) != NULL) {
                memcpy(copy, s, (size_t)len);
                copy[len] = '\0';
            }
        }
    }
    if (ctx)
        exr_finish(&ctx);
    exr_current_capture = saved;
    return copy;
}

/* ---------------------------------------------------------------------
 * Exposure */

rp_exposure rp_exposure_fixed(double ev)
{
    return (rp_exposure){.ev = ev, .scale = exp2(ev), .automatic = 0, .anchor = 0};
}

rp_status rp_exposure_parse(const char *text, rp_exposure *out, rp_error *err)
{
    char *end = NULL;
    double ev = text ? strtod(text, &end) : NAN;
    if (!text || end == text || *end || !isfinite(ev) || fabs(ev) > 100)
        return rp_error_set(err, RP_ERR_INPUT, "--exposure: '%s' is not a number of stops in [-100, 100]",
                            text ? text : "");
    *out = rp_exposure_fixed(ev);
    return RP_OK;
}

/* The k-th smallest (0-based) of v[0..n-1] (no NaN), reordering v: Hoare's
 * FIND (quickselect) with a median-of-three pivot and a three-way
 * partition (Dijkstra), so runs of equal values cost nothing; expected
 * O(n). */
static double select_kth(double *v, size_t n, size_t k)
{
    size_t lo = 0, hi = n - 1;
    while (lo < hi) {
        double a = v[lo], b = v[lo + (hi - lo) / 2], c = v[hi];
        double pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        /* v[lo..lt-1] < pivot, v[lt..i-1] == pivot, v[gt+1..hi] > pivot;
         * a value equal to the pivot stays at or below gt, so gt >= lt. */
        size_t lt = lo, i = lo, gt = hi;
        while (i <= gt) {
            double t = v[i];
            if (t < pivot) {
                v[i++] = v[lt];
                v[lt++] = t;
            } else if (t > pivot) {
                v[i] = v[gt];
                v[gt] = t;
                if (gt == lt)
                    break;
                gt--;
            } else {
                i++;
            }
        }
        if (k < lt)
            hi = lt - 1;
        else if (k > gt)
            lo = gt + 1;
        else
            return pivot;
    }
    return v[k];
}

rp_status rp_exposure_auto(size_t npix, const float *r, const float *g, const float *b, rp_exposure *out,
                           rp_error *err)
{
    *out = rp_exposure_fixed(0);
    out->automatic = 1;
    if (npix == 0)
        return RP_OK;
    double *y = malloc(npix * sizeof *y);
    if (!y)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the exposure of a %zu-pixel image", npix);
    size_t n = 0;
    for (size_t i = 0; i < npix; i++) {
        /* ITU-R BT.709 luminance of linear RGB; a grey pixel is its value
         * exactly (the weights' sum rounds to 1 only nearly). */
        double Y = r[i] == g[i] && g[i] == b[i] ? (double)r[i]
                                                 : 0.2126 * r[i] + 0.7152 * g[i] + 0.0722 * b[i];
        if (isfinite(Y) && Y > 0)
            y[n++] = Y;
    }
    if (n > 0) {
        /* Nearest rank: the ceil(p n)-th smallest value. */
        size_t rank = (size_t)ceil(RP_EXPOSURE_PERCENTILE * (double)n);
        rank = rank < 1 ? 1 : (rank > n ? n : rank);
        double y99 = select_kth(y, n, rank - 1);
        double scale = RP_EXPOSURE_WHITE / y99;
        if (isfinite(scale) && scale > 0) {
            out->scale = scale;
            out->ev = log2(scale);
            out->anchor = y99;
        }
    }
    free(y);
    return RP_OK;
}

void rp_exposure_describe(const rp_exposure *e, char *buf, size_t n)
{
    if (!e->automatic)
        snprintf(buf, n, "EV %.6g (scale %.6g), fixed", e->ev, e->scale);
    else if (e->anchor > 0)
        snprintf(buf, n, "EV %.6g (scale %.6g), automatic: %gth-percentile luminance %.6g -> %g", e->ev,
                 e->scale, 100 * RP_EXPOSURE_PERCENTILE, e->anchor, RP_EXPOSURE_WHITE);
    else
        snprintf(buf, n, "EV %.6g (scale %.6g), automatic: no lit pixel", e->ev, e->scale);
}

/* ---------------------------------------------------------------------
 * PNG preview */

/* Linear value to an 8-bit sRGB code: IEC 61966-2-1 transfer function,
 * 12.92 v below 0.0031308, else 1.055 v^(1/2.4) - 0.055; clamped to
 * [0, 1] first (NaN counts as 0), rounded to nearest. */
static uint8_t srgb_encode8(double v)
{
    if (!(v > 0.0))
        return 0;
    if (v >= 1.0)
        return 255;
    double e = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
    return (uint8_t)floor(255.0 * e + 0.5);
}

typedef struct png_capture {
    char message[256];
} png_capture;

/* libpng's default handlers print to stderr (and the error one aborts
 * without a jump buffer): store the message and jump back instead. */
static void png_capture_error(png_structp png, png_const_charp msg)
{
    png_capture *cap = png_get_error_ptr(png);
    if (cap)
        snprintf(cap->message, sizeof cap->message, "%s", msg ? msg : "libpng error");
    png_longjmp(png, 1);
}

static void png_ignore_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* Everything that touches libpng after setjmp, kept in one function so no
 * local of the caller changes between setjmp and a longjmp. */
static int png_encode(png_structp png, png_infop info, FILE *fp, uint32_t width, uint32_t height,
                      const float *r, const float *g, const float *b, double scale, const char *note,
                      unsigned char *row)
{
    if (setjmp(png_jmpbuf(png)))
        return -1;
    png_init_io(png, fp);
    png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    /* Tag the file as sRGB (with matching gAMA/cHRM for older readers). */
    png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    /* The exposure used, so a preview says how bright it was made. */
    png_text text = {.compression = PNG_TEXT_COMPRESSION_NONE,
                     .key = (png_charp) "radpt:exposure",
                     .text = (png_charp)note};
    png_set_text(png, info, &text, 1);
    png_write_info(png, info);
    for (uint32_t y = 0; y < height; y++) {
        size_t base = (size_t)y * width;
        for (uint32_t x = 0; x < width; x++) {
            row[3 * (size_t)x + 0] = srgb_encode8(scale * (double)r[base + x]);
            row[3 * (size_t)x + 1] = srgb_encode8(scale * (double)g[base + x]);
            row[3 * (size_t)x + 2] = srgb_encode8(scale * (double)b[base + x]);
        }
        png_write_row(png, row);
    }
    png_write_end(png, info);
    return 0;
}

/* ---------------------------------------------------------------------
 * PNG input */

/* What one read allocates, kept outside png_decode's frame so that a
 * longjmp out of libpng leaves it to be freed. */
typedef struct png_in {
    png_bytep data;  /* the rows as libpng delivers them */
    png_bytepp rows;
    uint16_t *samples;
    uint32_t width, height;
    size_t channels;
} png_in;

/* Everything that touches libpng after setjmp (see png_encode).  The
 * signature's 8 bytes are already read.  Grey below 8 bits is widened
 * (png_set_expand_gray_1_2_4_to_8: 0 stays 0), a palette index is looked
 * up in PLTE; no tRNS expansion, no gamma or 16-to-8 reduction, so every
 * sample keeps its stored value (8 or 16 bits; 16-bit rows are
 * big-endian, PNG spec 7.1). */
static int png_decode(png_structp png, png_infop info, FILE *fp, png_in *in)
{
    if (setjmp(png_jmpbuf(png)))
        return -1;
    png_init_io(png, fp);
    png_set_sig_bytes(png, 8);
    png_read_info(png, info);
    int type = png_get_color_type(png, info);
    if (type == PNG_COLOR_TYPE_PALETTE)
        png_set_packing(png); /* one index per byte */
    else if (png_get_bit_depth(png, info) < 8)
        png_set_expand_gray_1_2_4_to_8(png);
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    size_t rowbytes = png_get_rowbytes(png, info), nch = png_get_channels(png, info);
    int wide = png_get_bit_depth(png, info) == 16;
    png_colorp palette = NULL;
    int npalette = 0;
    if (type == PNG_COLOR_TYPE_PALETTE && !png_get_PLTE(png, info, &palette, &npalette))
        png_error(png, "palette image without a PLTE chunk");
    size_t outch = type == PNG_COLOR_TYPE_PALETTE ? 3 : nch;
    if (w == 0 || h == 0 || rowbytes > SIZE_MAX / h || (size_t)w * h > SIZE_MAX / sizeof(uint16_t) / outch)
        png_error(png, "image too large");
    if (!(in->data = malloc(rowbytes * h)) || !(in->rows = malloc(h * sizeof *in->rows)) ||
        !(in->samples = malloc((size_t)w * h * outch * sizeof *in->samples)))
        png_error(png, "out of memory");
    for (png_uint_32 y = 0; y < h; y++)
        in->rows[y] = in->data + (size_t)y * rowbytes;
    png_read_image(png, in->rows);
    png_read_end(png, NULL);
    for (png_uint_32 y = 0; y < h; y++) {
        const png_byte *row = in->rows[y];
        uint16_t *out = in->samples + (size_t)y * w * outch;
        for (png_uint_32 x = 0; x < w; x++) {
            if (type == PNG_COLOR_TYPE_PALETTE) {
                if (row[x] >= npalette)
                    png_error(png, "palette index out of range");
                out[3 * (size_t)x + 0] = palette[row[x]].red;
                out[3 * (size_t)x + 1] = palette[row[x]].green;
                out[3 * (size_t)x + 2] = palette[row[x]].blue;
                continue;
            }
            for (size_t c = 0; c < nch; c++) {
                size_t i = (size_t)x * nch + c;
                out[i] = wide ? (uint16_t)(row[2 * i] << 8 | row[2 * i + 1]) : row[i];
            }
        }
    }
    in->width = w;
    in->height = h;
    in->channels = outch;
    return 0;
}

rp_status rp_image_read_png(const char *path, uint32_t *width, uint32_t *height, size_t *channels,
                            uint16_t **samples, rp_error *err)
{
    *width = *height = 0;
    *channels = 0;
    *samples = NULL;
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot open: %s", path, strerror(errno));
    png_byte sig[8];
    size_t got = fread(sig, 1, sizeof sig, fp);
    if (got != sizeof sig && ferror(fp)) {
        int e = errno;
        fclose(fp);
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot read: %s", path, strerror(e));
    }
    if (got != sizeof sig || png_sig_cmp(sig, 0, sizeof sig) != 0) {
        fclose(fp);
        return rp_error_set(err, RP_ERR_INPUT, "%s: not a PNG file (no PNG signature)", path);
    }
    png_capture cap = {{0}};
    png_in in = {0};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &cap, png_capture_error, png_ignore_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    int rc = -1;
    if (png && info)
        rc = png_decode(png, info, fp, &in);
    else
        snprintf(cap.message, sizeof cap.message, "cannot create libpng structures");
    png_destroy_read_struct(png ? &png : NULL, info ? &info : NULL, NULL);
    fclose(fp);
    free(in.data);
    free(in.rows);
    if (rc != 0) {
        free(in.samples);
        return rp_error_set(err, strcmp(cap.message, "out of memory") ? RP_ERR_INPUT : RP_ERR_NOMEM,
                            "%s: cannot read PNG: %s", path, cap.message);
    }
    *width = in.width;
    *height = in.height;
    *channels = in.channels;
    *samples = in.samples;
    return RP_OK;
}

/* ---------------------------------------------------------------------
 * PFM */

rp_status rp_image_write_pfm(const char *path, uint32_t width, uint32_t height, const float *r, const float *g,
                             const float *b, rp_error *err)
{
    if (width == 0 || height == 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: empty image", path);
    size_t row = (size_t)width * 3;
    float *line = malloc(row * sizeof *line);
    if (!line)
        return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", path);
    int fd;
    char *tmp;
    rp_status st = rp_temp_open(path, &fd, &tmp, err);
    if (st != RP_OK) {
        free(line);
        return st;
    }
    /* Header "PF" (colour), the size, and a negative scale: little-endian
     * floats; rows go from the bottom of the image to its top. */
    char head[64];
    int hn = snprintf(head, sizeof head, "PF\n%u %u\n-1.0\n", width, height);
    int ok = write(fd, head, (size_t)hn) == hn;
    for (uint32_t y = height; ok && y-- > 0;) {
        for (uint32_t x = 0; x < width; x++) {
            size_t i = (size_t)y * width + x;
            float v[3] = {r[i], g[i], b[i]};
            for (int c = 0; c < 3; c++) {
                /* to little-endian whatever the host */
                uint32_t u;
                memcpy(&u, &v[c], 4);
                unsigned char *o = (unsigned char *)&line[3 * (size_t)x + (size_t)c];
                o[0] = (unsigned char)u;
                o[1] = (unsigned char)(u >> 8);
                o[2] = (unsigned char)(u >> 16);
                o[3] = (unsigned char)(u >> 24);
            }
        }
        ok = write(fd, line, row * sizeof *line) == (ssize_t)(row * sizeof *line);
    }
    free(line);
    if (!ok) {
        int e = errno;
        rp_temp_discard(fd, tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: write failed: %s", path, strerror(e));
    }
    return rp_temp_commit(fd, tmp, path, err);
}

rp_image_format rp_image_format_of(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash))
        return RP_IMAGE_UNKNOWN;
    if (!strcasecmp(dot, ".exr"))
        return RP_IMAGE_EXR;
    if (!strcasecmp(dot, ".png"))
        return RP_IMAGE_PNG;
    if (!strcasecmp(dot, ".pfm"))
        return RP_IMAGE_PFM;
    return RP_IMAGE_UNKNOWN;
}

rp_status rp_image_write_png(const char *path, uint32_t width, uint32_t height,
                             const float *r, const float *g, const float *b,
                             const rp_exposure *exposure, rp_error *err)
{
    if (!path || !*path)
        return rp_error_set(err, RP_ERR_INPUT, "PNG output: no file name");
    if (!r || !g || !b)
        return rp_error_set(err, RP_ERR_INPUT, "%s: missing colour plane", path);
    /* PNG allows up to 2^31 - 1 per side (PNG spec, IHDR); libpng's default
     * user limit is 10^6. */
    if (width == 0 || height == 0 || width > 1000000 || height > 1000000)
        return rp_error_set(err, RP_ERR_INPUT, "%s: image size %u x %u out of range", path, width,
                            height);
    rp_exposure ex;
    if (exposure) {
        ex = *exposure;
        if (!isfinite(ex.scale) || !(ex.scale > 0.0))
            return rp_error_set(err, RP_ERR_INPUT, "%s: exposure scale %g is not a finite value > 0", path,
                                ex.scale);
    } else {
        rp_status est = rp_exposure_auto((size_t)width * height, r, g, b, &ex, err);
        if (est != RP_OK)
            return est;
    }
    char note[160];
    rp_exposure_describe(&ex, note, sizeof note);

    unsigned char *row = malloc(3 * (size_t)width);
    if (!row)
        return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", path);

    int fd = -1;
    char *tmp = NULL;
    rp_status st = rp_temp_open(path, &fd, &tmp, err);
    if (st != RP_OK) {
        free(row);
        return st;
    }
    /* A duplicate descriptor for stdio, so fclose leaves fd for fsync. */
    int fd2 = dup(fd);
    FILE *fp = fd2 >= 0 ? fdopen(fd2, "wb") : NULL;
    if (!fp) {
        int e = errno;
        if (fd2 >= 0)
            close(fd2);
        free(row);
        rp_temp_discard(fd, tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot open stream: %s", path, strerror(e));
    }

    png_capture cap = {{0}};
    png_structp png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, &cap, png_capture_error, png_ignore_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    int rc = -1;
    if (png && info)
        rc = png_encode(png, info, fp, width, height, r, g, b, ex.scale, note, row);
    else
        snprintf(cap.message, sizeof cap.message, "cannot create libpng structures");
    png_destroy_write_struct(png ? &png : NULL, info ? &info : NULL);
    free(row);

    if (rc == 0 && fflush(fp) != 0) {
        rc = -1;
        snprintf(cap.message, sizeof cap.message, "%s", strerror(errno));
    }
    if (fclose(fp) != 0 && rc == 0) {
        rc = -1;
        snprintf(cap.message, sizeof cap.message, "%s", strerror(errno));
    }
    if (rc != 0) {
        rp_temp_discard(fd, tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot write PNG: %s", path, cap.message);
    }
    return rp_temp_commit(fd, tmp, path, err);
}
