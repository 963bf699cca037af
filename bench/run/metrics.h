/* Error metrics of an answer against a reference, and the fits the
 * benchmark reports (bench/ only; nothing here allocates or prints).
 *
 * Image metrics run over the pixels a mask selects (the reference's
 * "measured" pixels: see reference.h) and over every band of those pixels:
 *
 *     RMSE   = sqrt( 1/K sum (x - r)^2 )
 *     relMSE = 1/K sum (x - r)^2 / (r^2 + eps)      eps = RP_RELMSE_EPS
 *     MAE    = 1/K sum |x - r|
 *
 * with K = (masked pixels) x (bands).  relMSE follows Rousselle, Knaus &
 * Zwicker 2011 ("Adaptive sampling and reconstruction using greedy error
 * minimization"): the regulariser eps keeps dark pixels from
 * dominating; it is in squared radiance units (W sr^-1 m^-2)^2.
 *
 * Surface error: the RMS over surfaces and bands of the relative error of
 * the area-averaged radiance,
 *
 *     surface_err = sqrt( 1/M sum_{s,b} ((x_sb - r_sb) / r_sb)^2 ),
 *
 * over the surfaces the surface mask selects and the bands with r_sb > 0. */
#ifndef RP_METRICS_H
#define RP_METRICS_H

#include <stddef.h>
#include <stdint.h>

#define RP_RELMSE_EPS 0.01

typedef struct rp_image_metrics {
    double rmse, relmse, mae;
    size_t count;  /* K: values compared (masked pixels x bands) */
} rp_image_metrics;

/* img and ref are npix * nb, band fastest; mask (npix, may be NULL: all
 * pixels) selects pixels.  With nothing selected every metric is NaN. */
void rp_metrics_image(const float *img, const float *ref, const unsigned char *mask, size_t npix,
                      size_t nb, rp_image_metrics *out);

/* The standard error of a reference's RMSE against the truth: the RMS of
 * the per-value standard deviations, sqrt(1/K sum var), over the same
 * values as rp_metrics_image.  0 when var is NULL (an exact reference),
 * infinite when some variance is (a pixel with a single sample). */
double rp_metrics_reference_rmse_se(const float *var, const unsigned char *mask, size_t npix,
                                    size_t nb);

/* The mean squared error against the truth, estimated through a Monte
 * Carlo reference r whose per-value variance of the mean v is estimated
 * without bias (independent samples).  r is independent of x, so
 *
 *     E[(x - r)^2 - v] = (x - L)^2        against the truth L,
 *
 * and mse = 1/K sum t_k with t_k = (x_k - r_k)^2 - v_k is unbiased for the
 * MSE against L (it may be negative when the reference's noise hides the
 * error).  se is the standard error of that mean.  Given the errors e_k,
 * Var(t_k) = 4 e_k^2 v_k + 2 v_k^2 when r_k's error is normal (its
 * "normal" estimate, with e_k^2 estimated by max(t_k, 0) and v_k by its
 * estimate, sums these: se = sqrt(sum) / K).  Two estimates, each above
 * the truth in expectation for its own reason:
 *   empirical: sd(t) / sqrt(K) (GSL's running statistics), which also
 *              counts how e_k^2 itself varies over the values (fixed, not
 *              random): too high where the answer has outliers (a Monte
 *              Carlo answer's fireflies);
 *   normal:    the sum above, whose v_k^2 is too high where the
 *              reference's variance estimate is heavy-tailed (its own
 *              fireflies: 3x too high between two 128-spp references of
 *              the Cornell box, where the empirical one is exact).
 * The image takes the smaller; surfaces (tens of values, each the mean of
 * thousands of samples, so nearly normal) the normal one.
 * With every v = 0 (an exact reference) mse is the plain MSE and se is 0.
 * An infinite v (a pixel of one sample) makes mse -inf: nothing is
 * resolved. */
typedef struct rp_debiased_mse {
    double mse, se;
    size_t count;  /* K; mse and se NaN when 0 */
} rp_debiased_mse;

/* Over the pixels and bands rp_metrics_image uses; var may be NULL (0). */
void rp_metrics_debiased_image(const float *img, const float *ref, const float *var,
                               const unsigned char *mask, size_t npix, size_t nb,
                               rp_debiased_mse *out);

/* Relative to the reference, over the values surface_err uses:
 * t = ((x - r) / r)^2 - (se_r / r)^2; rse may be NULL (0). */
void rp_metrics_debiased_surfaces(const double *x, const double *ref, const double *rse,
                                  const unsigned char *smask, size_t ns, size_t nb,
                                  rp_debiased_mse *out);

/* A reference resolves an error when the debiased RMSE is known to 10%:
 * its standard error, se / (2 mse) to first order, is at most
 * RP_RESOLVED_REL_SE of it; an exact reference (se = 0) resolves any
 * error.  1 resolved, 0 not (mse <= 0 or too uncertain, or no values). */
#define RP_RESOLVED_REL_SE 0.1
int rp_metrics_resolved(const rp_debiased_mse *d);

/* surface_err as above; x and ref are ns * nb; smask (ns, may be NULL)
 * selects surfaces.  *count (may be NULL) gets M.  NaN when M = 0. */
double rp_metrics_surface_error(const double *x, const double *ref, const unsigned char *smask,
                                size_t ns, size_t nb, size_t *count);

/* Per-pixel absolute error averaged over bands, npix values (an error map). */
void rp_metrics_error_map(const float *img, const float *ref, size_t npix, size_t nb, float *out);

/* Least-squares line through (log x, log y) (natural logs) with a two-sided
 * confidence interval for the slope from Student's t with n - 2 degrees of
 * freedom (gsl_fit_linear, gsl_cdf_tdist_Pinv).  Points with x or y not
 * positive and finite are skipped. */
typedef struct rp_fit {
    double slope, intercept;  /* log y = intercept + slope log x */
    double slope_se;          /* standard error of the slope */
    double lo, hi;            /* confidence interval of the slope */
    double level;             /* e.g. 0.95 */
    size_t n;                 /* points used */
    int ok;                   /* 0: fewer than 3 distinct points */
} rp_fit;

void rp_fit_loglog(const double *x, const double *y, size_t n, double level, rp_fit *out);

/* Time to reach an error: the first crossing of y below target along the
 * curve (x[i], y[i]) in increasing x, interpolated linearly in log-log
 * space.  Returns x[0] when y[0] <= target already (*before = 1), NaN when
 * the curve never reaches it. */
double rp_metrics_time_to_error(const double *x, const double *y, size_t n, double target,
                                int *before);

/* Mean and sample standard deviation of n values (NaNs skipped); *used
 * (may be NULL) gets how many were finite. */
void rp_metrics_mean_sd(const double *v, size_t n, double *mean, double *sd, size_t *used);

#endif
