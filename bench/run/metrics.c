/* Error metrics and log-log fits (metrics.h). */
#include "bench/run/metrics.h"

#include <gsl/gsl_cdf.h>
#include <gsl/gsl_fit.h>
#include <gsl/gsl_rstat.h>
#include <math.h>
#include <stdlib.h>

void rp_metrics_image(const float *img, const float *ref, const unsigned char *mask, size_t npix,
                      size_t nb, rp_image_metrics *out)
{
    double se = 0, rel = 0, ae = 0;
    size_t k = 0;
    for (size_t i = 0; i < npix; i++) {
        if (mask && !mask[i])
            continue;
        for (size_t b = 0; b < nb; b++) {
            double r = ref[i * nb + b], d = (double)img[i * nb + b] - r;
            se += d * d;
            rel += d * d / (r * r + RP_RELMSE_EPS);
            ae += fabs(d);
            k++;
        }
    }
    out->count = k;
    if (k == 0) {
        out->rmse = out->relmse = out->mae = NAN;
        return;
    }
    out->rmse = sqrt(se / (double)k);
    out->relmse = rel / (double)k;
    out->mae = ae / (double)k;
}

double rp_metrics_reference_rmse_se(const float *var, const unsigned char *mask, size_t npix,
                                    size_t nb)
{
    if (!var)
        return 0;
    double s = 0;
    size_t k = 0;
    for (size_t i = 0; i < npix; i++) {
        if (mask && !mask[i])
            continue;
        for (size_t b = 0; b < nb; b++) {
            double v = var[i * nb + b];
            /* a pixel with one sample has an unknown (infinite) variance:
             * so has the whole reference */
            if (!isfinite(v))
                return INFINITY;
            s += v > 0 ? v : 0;
            k++;
        }
    }
    return k ? sqrt(s / (double)k) : NAN;
}

/* Var(t_k) for a reference value with a normal error of variance v
 * around a fixed error e (metrics.h): 4 e^2 v + 2 v^2, with e^2
 * estimated by max(t, 0). */
static double t_variance_normal(double t, double v) { return 4 * (t > 0 ? t : 0) * v + 2 * v * v; }

void rp_metrics_debiased_image(const float *img, const float *ref, const float *var,
                               const unsigned char *mask, size_t npix, size_t nb,
                               rp_debiased_mse *out)
{
    gsl_rstat_workspace *w = gsl_rstat_alloc();
    if (!w) {
        out->mse = out->se = NAN;
        out->count = 0;
        return;
    }
    int noisy = 0;
    double model = 0;
    for (size_t i = 0; i < npix; i++) {
        if (mask && !mask[i])
            continue;
        for (size_t b = 0; b < nb; b++) {
            size_t k = i * nb + b;
            double d = (double)img[k] - ref[k], v = var ? var[k] : 0, t = d * d - v;
            noisy |= v != 0;
            gsl_rstat_add(t, w);
            model += t_variance_normal(t, v);
        }
    }
    size_t K = gsl_rstat_n(w);
    out->count = K;
    out->mse = K ? gsl_rstat_mean(w) : NAN;
    if (!K)
        out->se = NAN;
    else if (!noisy)
        out->se = 0;
    else if (K < 2)
        out->se = INFINITY;
    else {
        /* both overestimate the standard error, for different reasons
         * (metrics.h): the smaller is nearer */
        double empirical = gsl_rstat_sd_mean(w), normal = sqrt(model) / (double)K;
        out->se = empirical < normal ? empirical : normal;
    }
    gsl_rstat_free(w);
}

void rp_metrics_debiased_surfaces(const double *x, const double *ref, const double *rse,
                                  const unsigned char *smask, size_t ns, size_t nb,
                                  rp_debiased_mse *out)
{
    double st = 0, var = 0;
    size_t m = 0;
    for (size_t i = 0; i < ns; i++) {
        if (smask && !smask[i])
            continue;
        for (size_t b = 0; b < nb; b++) {
            double r = ref[i * nb + b];
            if (!(r > 0))
                continue;
            double e = (x[i * nb + b] - r) / r, s = rse ? rse[i * nb + b] / r : 0, t = e * e - s * s;
            st += t;
            var += t_variance_normal(t, s * s);
            m++;
        }
    }
    out->count = m;
    out->mse = m ? st / (double)m : NAN;
    out->se = m ? sqrt(var) / (double)m : NAN;
}

int rp_metrics_resolved(const rp_debiased_mse *d)
{
    if (!d->count || !isfinite(d->mse) || !isfinite(d->se))
        return 0;
    /* an exact reference resolves every error, 0 included */
    if (d->se == 0)
        return d->mse >= 0;
    return d->mse > 0 && d->se <= 2 * RP_RESOLVED_REL_SE * d->mse;
}

double rp_metrics_surface_error(const double *x, const double *ref, const unsigned char *smask,
                                size_t ns, size_t nb, size_t *count)
{
    /* with no reference noise the debiased MSE is the plain one */
    rp_debiased_mse d;
    rp_metrics_debiased_surfaces(x, ref, NULL, smask, ns, nb, &d);
    if (count)
        *count = d.count;
    return d.count ? sqrt(d.mse) : NAN;
}

void rp_metrics_error_map(const float *img, const float *ref, size_t npix, size_t nb, float *out)
{
    for (size_t i = 0; i < npix; i++) {
        double a = 0;
        for (size_t b = 0; b < nb; b++)
            a += fabs((double)img[i * nb + b] - ref[i * nb + b]);
        out[i] = (float)(a / (double)nb);
    }
}

void rp_fit_loglog(const double *x, const double *y, size_t n, double level, rp_fit *out)
{
    out->slope = out->intercept = out->slope_se = out->lo = out->hi = NAN;
    out->level = level;
    out->n = 0;
    out->ok = 0;
    double *lx = malloc((n ? n : 1) * sizeof *lx), *ly = malloc((n ? n : 1) * sizeof *ly);
    if (!lx || !ly) {
        free(lx);
        free(ly);
        return;
    }
    size_t m = 0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(x[i]) && isfinite(y[i]) && x[i] > 0 && y[i] > 0) {
            lx[m] = log(x[i]);
            ly[m] = log(y[i]);
            m++;
        }
    out->n = m;
    /* a slope needs two distinct abscissae; its interval needs a third point */
    int distinct = 0;
    for (size_t i = 1; i < m && !distinct; i++)
        distinct = lx[i] != lx[0];
    if (m >= 3 && distinct) {
        double c0, c1, cov00, cov01, cov11, sumsq;
        if (gsl_fit_linear(lx, 1, ly, 1, m, &c0, &c1, &cov00, &cov01, &cov11, &sumsq) == 0) {
            /* gsl_fit_linear scales the covariance by the residual variance
             * sumsq / (n - 2), so cov11 is the slope's squared standard error. */
            double t = gsl_cdf_tdist_Pinv(0.5 + 0.5 * level, (double)(m - 2));
            out->slope = c1;
            out->intercept = c0;
            out->slope_se = sqrt(cov11);
            out->lo = c1 - t * out->slope_se;
            out->hi = c1 + t * out->slope_se;
            out->ok = 1;
        }
    }
    free(lx);
    free(ly);
}

double rp_metrics_time_to_error(const double *x, const double *y, size_t n, double target,
                                int *before)
{
    if (before)
        *before = 0;
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(y[i]) || !(y[i] <= target))
            continue;
        if (i == 0 || !isfinite(y[i - 1])) {
            if (before)
                *before = i == 0;
            return x[i];
        }
        /* y[i-1] > target >= y[i]: interpolate log y against log x */
        double x0 = x[i - 1], x1 = x[i], y0 = y[i - 1], y1 = y[i];
        if (!(x0 > 0 && x1 > 0 && y0 > 0 && y1 > 0) || target <= 0 || y0 == y1)
            return x1;
        double f = (log(target) - log(y0)) / (log(y1) - log(y0));
        return exp(log(x0) + f * (log(x1) - log(x0)));
    }
    return NAN;
}

void rp_metrics_mean_sd(const double *v, size_t n, double *mean, double *sd, size_t *used)
{
    double s = 0;
    size_t k = 0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(v[i])) {
            s += v[i];
            k++;
        }
    double m = k ? s / (double)k : NAN, q = 0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(v[i]))
            q += (v[i] - m) * (v[i] - m);
    *mean = m;
    *sd = k > 1 ? sqrt(q / (double)(k - 1)) : (k == 1 ? 0 : NAN);
    if (used)
        *used = k;
}
