#include "closed_form.h"

#include <gsl/gsl_integration.h>
#include <math.h>

#include "geometry/scene.h"

double rp_cf_corner_rect(double a, double b, double c)
{
    double A = a / c, B = b / c;
    return (A / sqrt(1 + A * A) * atan(B / sqrt(1 + A * A)) + B / sqrt(1 + B * B) * atan(A / sqrt(1 + B * B))) /
           (2 * RP_PI);
}

double rp_cf_point_rect(double x, double y, double a, double b, double c)
{
    /* Four corner rectangles meeting above (x, y). */
    return rp_cf_corner_rect(x, y, c) + rp_cf_corner_rect(a - x, y, c) + rp_cf_corner_rect(x, b - y, c) +
           rp_cf_corner_rect(a - x, b - y, c);
}

double rp_cf_point_rect_mean(double x0, double x1, double y0, double y1, double a, double b, double c)
{
    gsl_integration_glfixed_table *t = gsl_integration_glfixed_table_alloc(8);
    if (!t)
        return NAN;
    double sum = 0;
    for (size_t i = 0; i < t->n; i++) {
        double xi, wi, yj, wj;
        gsl_integration_glfixed_point(x0, x1, i, &xi, &wi, t);
        for (size_t j = 0; j < t->n; j++) {
            gsl_integration_glfixed_point(y0, y1, j, &yj, &wj, t);
            sum += wi * wj * rp_cf_point_rect(xi, yj, a, b, c);
        }
    }
    gsl_integration_glfixed_table_free(t);
    return sum / ((x1 - x0) * (y1 - y0));
}

double rp_cf_howell_parallel(double a, double b, double c)
{
    double X = a / c, Y = b / c, X2 = X * X, Y2 = Y * Y;
    return 2.0 / (M_PI * X * Y) *
           (0.5 * log((1 + X2) * (1 + Y2) / (1 + X2 + Y2)) + X * sqrt(1 + Y2) * atan(X / sqrt(1 + Y2)) +
            Y * sqrt(1 + X2) * atan(Y / sqrt(1 + X2)) - X * atan(X) - Y * atan(Y));
}

double rp_cf_howell_perpendicular(double w, double h, double l)
{
    double W = w / l, H = h / l, W2 = W * W, H2 = H * H, S = W2 + H2;
    double t = (1 + W2) * (1 + H2) / (1 + S) * pow(W2 * (1 + S) / ((1 + W2) * S), W2) *
               pow(H2 * (1 + S) / ((1 + H2) * S), H2);
    return 1.0 / (M_PI * W) * (W * atan(1 / W) + H * atan(1 / H) - sqrt(S) * atan(1 / sqrt(S)) + 0.25 * log(t));
}
