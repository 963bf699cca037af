/* Spectral bands to display RGB, through the CIE 1931 2-degree observer. */
#ifndef RP_SPECTRUM_H
#define RP_SPECTRUM_H

#include <stddef.h>

/* CIE 1931 colour matching functions at wavelength nm (analytic fit). */
void rp_cie1931_xyz(double nm, double xyz[3]);

/* Weights m[3 * nbands] so that linear sRGB c = sum_i m[c * nbands + i] L_i
 * for radiance L_i sampled at the ascending wavelengths nm[i]; a flat
 * spectrum of value 1 maps to luminance Y = 1. */
void rp_spectrum_rgb_weights(const double *nm, size_t nbands, double *m);

#endif
