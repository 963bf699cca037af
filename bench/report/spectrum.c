#include "bench/report/spectrum.h"

#include <math.h>

/* Piecewise Gaussian with different widths left and right of its mean. */
static double lobe(double x, double mu, double s_left, double s_right)
{
    double t = (x - mu) / (x < mu ? s_left : s_right);
    return exp(-0.5 * t * t);
}

/* Wyman, Sloan & Shirley 2013, "Simple Analytic Approximations to the CIE
 * XYZ Color Matching Functions", JCGT 2(2), the multi-lobe fit (eq. 2).
 * Hand-written: neither GSL nor another Debian C library ships the CIE
 * tables, and the fit is within the tables' own precision for a preview. */
void rp_cie1931_xyz(double nm, double xyz[3])
{
    xyz[0] = 1.056 * lobe(nm, 599.8, 37.9, 31.0) + 0.362 * lobe(nm, 442.0, 16.0, 26.7)
           - 0.065 * lobe(nm, 501.1, 20.4, 26.2);
    xyz[1] = 0.821 * lobe(nm, 568.8, 46.9, 40.5) + 0.286 * lobe(nm, 530.9, 16.3, 31.1);
    xyz[2] = 1.217 * lobe(nm, 437.0, 11.8, 36.0) + 0.681 * lobe(nm, 459.0, 26.0, 13.8);
}

void rp_spectrum_rgb_weights(const double *nm, size_t nbands, double *m)
{
    /* IEC 61966-2-1 (sRGB) XYZ -> linear RGB, D65. */
    static const double xyz_to_rgb[3][3] = {
        {3.2404542, -1.5371385, -0.4985314},
        {-0.9692660, 1.8760108, 0.0415560},
        {0.0556434, -0.2040259, 1.0572252},
    };
    double ysum = 0;
    double wxyz[3];
    for (size_t i = 0; i < nbands; i++) {
        /* trapezoid rule over the sampled wavelengths */
        double w = 1.0;
        if (nbands > 1) {
            double lo = i > 0 ? nm[i - 1] : nm[i];
            double hi = i + 1 < nbands ? nm[i + 1] : nm[i];
            w = 0.5 * (hi - lo);
        }
        rp_cie1931_xyz(nm[i], wxyz);
        for (int c = 0; c < 3; c++) {
            double v = 0;
            for (int k = 0; k < 3; k++)
                v += xyz_to_rgb[c][k] * wxyz[k];
            m[c * nbands + i] = w * v;
        }
        ysum += w * wxyz[1];
    }
    if (ysum > 0)
        for (size_t i = 0; i < 3 * nbands; i++)
            m[i] /= ysum;
}
