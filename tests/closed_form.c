#include "closed_form.h"

#include <math.h>

#include "geometry/scene.h"

double rp_cf_corner_rect(double a, double b, double c)
{
    double A = a / c, B = b / c;
    return (A / sqrt(1 + A * A) * atan(B / sqrt(1 + A * A)) + B / sqrt(1 + B * B) * atan(A / sqrt(1 + B * B))) /
           (2 * RP_PI);
}
