#include "camera.h"

void rp_camera_frame_init(rp_camera_frame *f, const rp_camera *cam)
{
    f->eye = cam->eye;
    f->forward = rp_v3_normalize(rp_v3_sub(cam->look, cam->eye));
    f->right = rp_v3_normalize(rp_v3_cross(f->forward, cam->up));
    f->up = rp_v3_cross(f->right, f->forward);
    f->tan_half = tan(0.5 * cam->fov_deg * RP_PI / 180.0);
    f->width = cam->width;
    f->height = cam->height;
    f->aspect = (double)cam->width / (double)cam->height;
}

rp_vec3 rp_camera_direction(const rp_camera_frame *f, double x, double y)
{
    double sx = (2.0 * x / f->width - 1.0) * f->tan_half * f->aspect;
    double sy = (1.0 - 2.0 * y / f->height) * f->tan_half;
    rp_vec3 d = rp_v3_add(f->forward, rp_v3_add(rp_v3_scale(f->right, sx), rp_v3_scale(f->up, sy)));
    return rp_v3_normalize(d);
}
