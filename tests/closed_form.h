/* Closed forms the tests check against, written from the published
 * formulas (not from radpt's code). */
#ifndef RP_TEST_CLOSED_FORM_H
#define RP_TEST_CLOSED_FORM_H

/* The form factor from a differential area to a parallel a x b rectangle
 * at distance c, the area's normal through a corner of the rectangle
 * (Howell's catalog, B-3).  Any parallel rectangle follows by
 * superposition. */
double rp_cf_corner_rect(double a, double b, double c);

/* B-3 by superposition: from a point (x, y) of the plane z = 0 (normal +z)
 * to the parallel rectangle [0, a] x [0, b] at height c, the point's
 * projection inside it. */
double rp_cf_point_rect(double x, double y, double a, double b, double c);

/* rp_cf_point_rect averaged over the square [x0, x1] x [y0, y1] of the
 * plane (a pixel's footprint), by 8 x 8-point Gauss-Legendre (GSL). */
double rp_cf_point_rect_mean(double x0, double x1, double y0, double y1, double a, double b, double c);

/* Howell's catalog C-11: directly opposed parallel a x b rectangles at
 * distance c (docs/ground-truth.md; 0.1998248957 for a = b = c = 1). */
double rp_cf_howell_parallel(double a, double b, double c);

/* Howell's C-14: perpendicular rectangles sharing an edge of length l, from
 * the one of width w to the one of height h (0.2000437761 for 1, 1, 1). */
double rp_cf_howell_perpendicular(double w, double h, double l);

#endif
