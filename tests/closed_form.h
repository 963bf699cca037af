/* Closed forms the tests check against, written from the published
 * formulas (not from radpt's code). */
#ifndef RP_TEST_CLOSED_FORM_H
#define RP_TEST_CLOSED_FORM_H

/* The form factor from a differential area to a parallel a x b rectangle
 * at distance c, the area's normal through a corner of the rectangle
 * (Howell's catalog, B-3).  Any parallel rectangle follows by
 * superposition. */
double rp_cf_corner_rect(double a, double b, double c);

#endif
