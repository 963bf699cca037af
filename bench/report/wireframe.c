/* Mesh overlays from an item buffer (wireframe.h). */
#include "bench/report/wireframe.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "geometry/camera.h"
#include "geometry/raycast.h"

/* sub-pixels per pixel side */
#define WF_SUB 3

rp_status rp_wireframe_png(const char *path, const rp_scene *scene, const rp_mesh *mesh, const float *const rgb[3],
                           const rp_exposure *exposure, rp_error *err)
{
    const rp_camera *cam = rp_scene_camera(scene);
    if (!cam)
        return rp_error_set(err, RP_ERR_INPUT, "%s: the scene has no camera to draw its mesh from", path);
    rp_camera_frame fr;
    rp_camera_frame_init(&fr, cam);
    const size_t W = fr.width, H = fr.height, SW = W * WF_SUB, SH = H * WF_SUB, npix = W * H;
    rp_raycast *rc = NULL;
    rp_status st = rp_raycast_create(scene, mesh, &rc, err);
    if (st != RP_OK)
        return st;
    uint32_t *item = malloc(SW * SH * sizeof *item);
    float *plane[3] = {malloc(npix * sizeof(float)), malloc(npix * sizeof(float)), malloc(npix * sizeof(float))};
    if (!item || !plane[0] || !plane[1] || !plane[2]) {
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory for the mesh overlay %s", path);
        goto done;
    }
    /* the item buffer: the element each sub-pixel's camera ray sees */
    for (size_t sy = 0; sy < SH; sy++)
        for (size_t sx = 0; sx < SW; sx++) {
            rp_vec3 d = rp_camera_direction(&fr, ((double)sx + 0.5) / WF_SUB, ((double)sy + 0.5) / WF_SUB);
            rp_hit h;
            item[sy * SW + sx] = rp_ray_closest(rc, fr.eye, d, INFINITY, &h) ? h.element : RP_NONE;
        }
    for (size_t i = 0; i < npix; i++)
        for (int c = 0; c < 3; c++)
            plane[c][i] = rgb ? rgb[c][i] : 0.5f;
    rp_exposure e;
    if (exposure)
        e = *exposure;
    else if ((st = rp_exposure_auto(npix, plane[0], plane[1], plane[2], &e, err)) != RP_OK)
        goto done;
    /* yellow, full scale after the exposure; a boundary crossing a pixel
     * (WF_SUB of its sub-pixels) draws it fully, a corner partly */
    const double line = e.scale > 0 ? 1 / e.scale : 1;
    for (size_t y = 0; y < H; y++)
        for (size_t x = 0; x < W; x++) {
            int on = 0;
            for (size_t j = 0; j < WF_SUB; j++)
                for (size_t i = 0; i < WF_SUB; i++) {
                    size_t sx = x * WF_SUB + i, sy = y * WF_SUB + j;
                    uint32_t a = item[sy * SW + sx];
                    on += (sx + 1 < SW && item[sy * SW + sx + 1] != a) || (sy + 1 < SH && item[(sy + 1) * SW + sx] != a);
                }
            double w = on >= WF_SUB ? 1 : (double)on / WF_SUB, target[3] = {line, line, 0};
            for (int c = 0; c < 3; c++)
                plane[c][y * W + x] = (float)((1 - w) * plane[c][y * W + x] + w * target[c]);
        }
    st = rp_image_write_png(path, (uint32_t)W, (uint32_t)H, plane[0], plane[1], plane[2], &e, err);
done:
    free(item);
    for (int c = 0; c < 3; c++)
        free(plane[c]);
    rp_raycast_destroy(rc);
    return st;
}
