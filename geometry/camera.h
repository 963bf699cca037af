/* Pinhole camera rays, shared by every solver that answers for pixels, so
 * the path tracer's and radiosity's images are comparable pixel for pixel. */
#ifndef RP_CAMERA_H
#define RP_CAMERA_H

#include "scene.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A camera's orthonormal frame and image-plane scale, precomputed. */
typedef struct rp_camera_frame {
    rp_vec3 eye;
    rp_vec3 forward, right, up; /* right = forward x up: with the Cornell
                                   camera, +x (the red wall) is on the left */
    double tan_half;            /* tan(fov / 2), vertical */
    double aspect;              /* width / height */
    uint32_t width, height;
} rp_camera_frame;

void rp_camera_frame_init(rp_camera_frame *f, const rp_camera *cam);

/* The unit direction through image position (x, y) in pixels from the
 * top-left corner of the image (pixel (i, j) covers [i, i+1) x [j, j+1)). */
rp_vec3 rp_camera_direction(const rp_camera_frame *f, double x, double y);

/* The inverse: where the point p appears, as image position (*x, *y) in
 * pixels from the top-left corner, and *cos_theta, the cosine between the
 * camera's axis and the direction from the eye to p.  Returns 1 when p is
 * in front of the eye and inside the image, else 0.  (For particle and
 * light tracing: the image plane at distance 1 from the eye has area
 * 4 tan_half^2 aspect, so a pixel's importance along a direction is
 * width*height / (4 tan_half^2 aspect cos_theta^4).) */
int rp_camera_project(const rp_camera_frame *f, rp_vec3 p, double *x, double *y, double *cos_theta);

#ifdef __cplusplus
}
#endif

#endif
