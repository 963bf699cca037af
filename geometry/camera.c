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

int rp_camera_project(const rp_camera_frame *f, rp_vec3 p, double *x, double *y, double *cos_theta)
{
    rp_vec3 d = rp_v3_sub(p, f->eye);
    double z = rp_v3_dot(d, f->forward);
    double len = rp_v3_length(d);
    if (!(z > 0) || !(len > 0))
        return 0;
    /* rp_camera_direction's sx, sy at unit distance along forward */
    double sx = rp_v3_dot(d, f->right) / z, sy = rp_v3_dot(d, f->up) / z;
    *x = (sx / (f->tan_half * f->aspect) + 1.0) * 0.5 * f->width;
    *y = (1.0 - sy / f->tan_half) * 0.5 * f->height;
    *cos_theta = z / len;
    return *x >= 0 && *x < f->width && *y >= 0 && *y < f->height;
}
