/* Benchmark output (plot.h): runs.csv, summary.json, chart data and
 * scripts, the image sheet, report.md. */
#include "bench/report/plot.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "bench/report/files.h"
#include "bench/report/gnuplot.h"
#include "bench/report/image.h"
#include "bench/report/spectrum.h"

/* ---------------------------------------------------------- runs.csv */

const char *const rp_runs_csv_columns =
    "method: the method's registry name (pathtrace, southwell, ...)\n"
    "spec: the method spec as given, options after colons (southwell:elements=4000)\n"
    "seed: the run's seed (Monte Carlo methods run with --seeds seeds)\n"
    "checkpoint: k, the checkpoint scheduled at budget * 2^-k (0 = the whole budget)\n"
    "target_s: budget * 2^-k, the solver time the checkpoint was scheduled for\n"
    "wall_s: solver wall time when it was taken (create + steps; estimates and metrics excluded)\n"
    "cpu_s: process CPU time over the same intervals (all threads)\n"
    "steps: solver steps done\n"
    "rays: rays cast by the solver (visibility rays included)\n"
    "paths: camera or probe paths traced (path tracer)\n"
    "samples: the estimate's sample count: samples per pixel (pathtrace), sweeps or shots (radiosity)\n"
    "iterations: the steps' iteration count (passes, sweeps, shots)\n"
    "form_factors: form factors computed\n"
    "work: rays + form_factors\n"
    "residual: the solver's relative residual after the last step (-1: not reported)\n"
    "unshot: unshot power fraction (progressive radiosity; -1: not reported)\n"
    "peak_rss_mb: peak resident memory of the process during this run, MiB\n"
    "solver_mb: memory the solver reports holding, MiB\n"
    "rmse: image RMSE against the reference over measured pixels and bands, W sr^-1 m^-2\n"
    "rmse_debiased: sqrt of the mean over measured values of (x - r)^2 - var(r), the reference's estimated "
    "variance removed: the reference uses independent random numbers, so that variance estimate is unbiased "
    "and so is the debiased MSE against the truth; empty where it is not positive (not resolved)\n"
    "relmse: relative MSE, mean of (x - r)^2 / (r^2 + 0.01)\n"
    "mae: mean absolute error over measured pixels and bands, W sr^-1 m^-2\n"
    "surface_err: RMS over measured surfaces and bands of the relative error of the area-averaged radiance\n"
    "ref_rmse_se: the reference's own RMSE standard error\n"
    "ref_flag: 1 when the reference does not resolve this error: the debiased MSE of the image (or of the "
    "surfaces' relative errors) is not positive or its standard error exceeds 20% of it (the debiased RMSE "
    "then known to worse than 10%)\n"
    "converged: the method's own stopping rule was met\n"
    "final: 1 on the last row of a run (its state at the end of the budget)\n"
    "measure_s: seconds the estimate and metrics took (not counted as solver time)\n";

static void csv_field(FILE *f, const char *s)
{
    int quote = strpbrk(s, ",\"\n") != NULL;
    if (!quote) {
        fputs(s, f);
        return;
    }
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '"')
            fputc('"', f);
        fputc(*s, f);
    }
    fputc('"', f);
}

/* %.6g; a value not measured (NaN inside) is written as "?" in gnuplot
 * data (set datafile missing '?') and as an empty field in CSV, so no file
 * carries the text "nan". */
static void num(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
    else
        fputc('?', f);
}

static void csv_num(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
}

rp_status rp_bench_write_runs_csv(const rp_bench *b, const char *dir, rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "runs.csv"), err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    fputs("method,spec,seed,checkpoint,target_s,wall_s,cpu_s,steps,rays,paths,samples,iterations,"
          "form_factors,work,residual,unshot,peak_rss_mb,solver_mb,rmse,rmse_debiased,relmse,mae,surface_err,"
          "ref_rmse_se,ref_flag,converged,final,measure_s,rank,threads\n",
          f);
    for (size_t r = 0; r < b->nruns; r++) {
        const rp_trial *run = &b->runs[r];
        const rp_method_spec *m = &b->methods[run->method];
        for (size_t i = 0; i < run->ncp; i++) {
            const rp_checkpoint *c = &run->cp[i];
            csv_field(f, m->name);
            fputc(',', f);
            csv_field(f, m->text);
            fprintf(f, ",%llu,%d,", (unsigned long long)run->seed, c->index);
            double v[] = {c->target, c->wall_s, c->cpu_s, c->steps, c->rays, c->paths, c->samples,
                          c->iterations, c->form_factors, c->rays + c->form_factors, c->residual, c->unshot,
                          c->peak_rss_mb, c->solver_mb, c->rmse, c->rmse_debiased, c->relmse, c->mae, c->surface_err,
                          b->ref->rmse_se};
            for (size_t k = 0; k < sizeof v / sizeof v[0]; k++) {
                csv_num(f, v[k]);
                fputc(',', f);
            }
            fprintf(f, "%d,%d,%d,", c->ref_flag, c->converged, c->final);
            csv_num(f, c->measure_s);
            fprintf(f, ",%d,%d\n", run->rank, run->threads);
        }
    }
    return rp_out_close(&o, 1, err);
}

/* ------------------------------------------------------- summary.json */

static void jnum(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
    else
        fputs("null", f);
}

static void json_fit(FILE *f, const char *name, const rp_fit *fit)
{
    fprintf(f, "\"%s\": {\"slope\": ", name);
    jnum(f, fit->slope);
    fprintf(f, ", \"ci95\": [");
    jnum(f, fit->lo);
    fprintf(f, ", ");
    jnum(f, fit->hi);
    fprintf(f, "], \"stderr\": ");
    jnum(f, fit->slope_se);
    fprintf(f, ", \"intercept\": ");
    jnum(f, fit->intercept);
    fprintf(f, ", \"points\": %zu}", fit->n);
}

static void json_agg(FILE *f, const rp_agg *a)
{
    fprintf(f, "{\"checkpoint\": %d, \"rows\": %zu, \"wall_s\": ", a->index, a->n);
    jnum(f, a->wall_s);
    const struct {
        const char *k;
        double v;
    } kv[] = {{"wall_s_sd", a->wall_sd}, {"cpu_s", a->cpu_s}, {"samples", a->samples},
              {"iterations", a->iterations}, {"rays", a->rays}, {"form_factors", a->form_factors},
              {"work", a->work}, {"peak_rss_mb", a->peak_rss_mb}, {"rmse", a->rmse}, {"rmse_sd", a->rmse_sd},
              {"rmse_debiased", a->rmse_debiased}, {"rmse_debiased_sd", a->rmse_debiased_sd},
              {"relmse", a->relmse}, {"relmse_sd", a->relmse_sd}, {"mae", a->mae}, {"mae_sd", a->mae_sd},
              {"surface_err", a->surface_err}, {"surface_err_sd", a->surface_err_sd}};
    for (size_t i = 0; i < sizeof kv / sizeof kv[0]; i++) {
        fprintf(f, ", \"%s\": ", kv[i].k);
        jnum(f, kv[i].v);
    }
    fprintf(f, ", \"ref_flag\": %s}", a->ref_flag ? "true" : "false");
}

static rp_status write_summary_json(const rp_bench *b, const char *dir, const char *plots_note, rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "summary.json"), err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    const rp_reference *r = b->ref;
    fprintf(f, "{\n  \"scene\": ");
    rp_json_string(f, b->scene_name);
    fprintf(f, ",\n  \"scene_hash\": \"%s\",\n  \"budget\": %g,\n  \"budget_unit\": \"%s\",\n  \"checkpoints\": %u,\n"
               "  \"seeds\": %u,\n  \"first_seed\": %llu,\n  \"threads\": %d,\n  \"complete\": %s,\n"
               "  \"runs_planned\": %zu,\n  \"runs_finished\": %zu,\n  \"runs_resumed\": %zu,\n",
            b->scene_hash, b->params.run.budget,
            b->params.run.schedule == RP_SCHEDULE_ITERATIONS ? "iterations" : "seconds", b->params.run.levels,
            b->params.nseeds, (unsigned long long)b->params.seed, b->threads, b->interrupted ? "false" : "true",
            b->planned, b->nruns, b->resumed);
    fprintf(f, "  \"reference\": {\"kind\": \"%s\", \"file\": ", r->kind == RP_REFERENCE_EXACT ? "exact" : "pathtrace");
    rp_json_string(f, r->exr_path);
    fprintf(f, ", \"cached\": %s, \"spp\": %lu, \"samples\": %lu, \"seed\": %llu, \"seconds\": %.3f, "
               "\"measured_pixels\": %zu, \"rmse_stderr\": ",
            r->cached ? "true" : "false", r->spp, r->samples, (unsigned long long)r->seed, r->seconds, r->mask_count);
    jnum(f, r->rmse_se);
    fprintf(f, ", \"surface_relative_stderr\": ");
    jnum(f, r->surface_rel_se);
    fprintf(f, "},\n  \"target_rmse\": ");
    jnum(f, b->target);
    fprintf(f, ",\n  \"target_automatic\": %s,\n  \"failures\": %zu,\n  \"plots\": ", b->target_auto ? "true" : "false",
            b->failures);
    rp_json_string(f, plots_note);
    fprintf(f, ",\n  \"methods\": [");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_spec *m = &b->methods[mi];
        const rp_method_summary *s = &b->summary[mi];
        fprintf(f, "%s\n    {\"spec\": ", mi ? "," : "");
        rp_json_string(f, m->text);
        fprintf(f, ", \"method\": ");
        rp_json_string(f, m->name);
        fprintf(f, ", \"monte_carlo\": %s, \"samples_unit\": \"%s\", \"runs\": %zu, \"runs_ok\": %zu, "
                   "\"errors\": [",
                rp_method_is_monte_carlo(m) ? "true" : "false", rp_solver_samples_name(m->type), s->runs,
                s->runs_ok);
        int first = 1;
        for (size_t ri = 0; ri < b->nruns; ri++)
            if (b->runs[ri].method == mi && b->runs[ri].status != RP_OK) {
                fprintf(f, "%s", first ? "" : ", ");
                rp_json_string(f, b->runs[ri].error);
                first = 0;
            }
        fprintf(f, "],\n     \"final\": ");
        json_agg(f, &s->final);
        fprintf(f, ",\n     ");
        json_fit(f, "slope_time", &s->fit_time);
        fprintf(f, ",\n     ");
        json_fit(f, "slope_work", &s->fit_work);
        fprintf(f, ",\n     ");
        json_fit(f, "slope_samples", &s->fit_samples);
        fprintf(f, ",\n     \"time_to_target_s\": ");
        jnum(f, s->time_to_target);
        fprintf(f, ", \"target_reached_before_first_checkpoint\": %s,\n     \"checkpoints\": [",
                s->target_before ? "true" : "false");
        for (size_t i = 0; i < s->npts; i++) {
            fprintf(f, "%s\n       ", i ? "," : "");
            json_agg(f, &s->pts[i]);
        }
        fprintf(f, "]}");
    }
    fprintf(f, "\n  ]\n}\n");
    return rp_out_close(&o, 1, err);
}

/* --------------------------------------------------------- chart data */

static rp_status write_data(const rp_bench *b, const char *dir, size_t *ttt_points, rp_error *err)
{
    *ttt_points = 0;
    char sub[1024], path[1100];
    rp_path_join(sub, sizeof sub, dir, "data");
    rp_status st = rp_mkdirs(sub, err);
    for (size_t mi = 0; st == RP_OK && mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        char name[32];
        snprintf(name, sizeof name, "m%zu.dat", mi);
        rp_out o;
        if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, sub, name), err)) != RP_OK)
            break;
        fprintf(o.f, "# %s: means over seeds per checkpoint (runs.csv)\n"
                     "# k wall_s wall_sd work samples rmse lo hi relmse mae surface_err "
                     "surface_lo surface_hi rows rmse_debiased\n",
                b->methods[mi].text);
        for (size_t i = 0; i < s->npts; i++) {
            const rp_agg *a = &s->pts[i];
            /* error bars: one standard deviation over the seeds, kept
             * positive for the log axis */
            double e = a->rmse, lo = e - a->rmse_sd, slo = a->surface_err - a->surface_err_sd;
            lo = lo > 0.1 * e ? lo : 0.1 * e;
            slo = slo > 0.1 * a->surface_err ? slo : 0.1 * a->surface_err;
            double v[] = {a->wall_s, a->wall_sd, a->work, a->samples, e, lo, e + a->rmse_sd,
                          a->relmse, a->mae, a->surface_err, slo, a->surface_err + a->surface_err_sd};
            fprintf(o.f, "%d", a->index);
            for (size_t k = 0; k < sizeof v / sizeof v[0]; k++) {
                fputc(' ', o.f);
                num(o.f, v[k]);
            }
            fprintf(o.f, " %zu ", a->n);
            num(o.f, a->rmse_debiased);
            fputc('\n', o.f);
        }
        if ((st = rp_out_close(&o, 1, err)) != RP_OK)
            break;
    }
    if (st != RP_OK)
        return st;
    /* slopes */
    rp_out o;
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, sub, "slopes.dat"), err)) != RP_OK)
        return st;
    fprintf(o.f, "# i slope_time lo hi slope_work lo hi slope_samples lo hi \"spec\"\n");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        fprintf(o.f, "%zu", mi);
        const rp_fit *fits[3] = {&s->fit_time, &s->fit_work, &s->fit_samples};
        for (int k = 0; k < 3; k++) {
            fputc(' ', o.f);
            num(o.f, fits[k]->slope);
            fputc(' ', o.f);
            num(o.f, fits[k]->lo);
            fputc(' ', o.f);
            num(o.f, fits[k]->hi);
        }
        fprintf(o.f, " \"%s\"\n", b->methods[mi].text);
    }
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    /* time to reach each error level, on a log grid spanning every curve */
    double lo = INFINITY, hi = 0;
    for (size_t mi = 0; mi < b->nmethods; mi++)
        for (size_t i = 0; i < b->summary[mi].npts; i++) {
            double e = b->summary[mi].pts[i].rmse;
            if (isfinite(e) && e > 0) {
                lo = e < lo ? e : lo;
                hi = e > hi ? e : hi;
            }
        }
    if ((st = rp_out_open(&o, rp_path_join(path, sizeof path, sub, "time_to_error.dat"), err)) != RP_OK)
        return st;
    fprintf(o.f, "# per method (blocks separated by two blank lines): target_rmse seconds\n");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        fprintf(o.f, "# %s\n", b->methods[mi].text);
        double *t = malloc((s->npts + 1) * sizeof *t), *e = malloc((s->npts + 1) * sizeof *e);
        if (t && e && hi > 0) {
            for (size_t i = 0; i < s->npts; i++) {
                t[i] = s->pts[i].wall_s;
                e[i] = s->pts[i].rmse;
            }
            for (int g = 0; g <= 60; g++) {
                double level = lo * pow(hi / lo, g / 60.0);
                int before;
                double x = rp_metrics_time_to_error(t, e, s->npts, level, &before);
                if (isfinite(x) && !before) {
                    fprintf(o.f, "%.6g %.6g\n", level, x);
                    ++*ttt_points;
                }
            }
        }
        free(t);
        free(e);
        /* a point gnuplot can always read, outside the plotted range, so
         * an empty block is not an error */
        fprintf(o.f, "? ?\n\n\n");
    }
    return rp_out_close(&o, 1, err);
}

/* ------------------------------------------------------- plots.gp */

static int any_surface(const rp_bench *b)
{
    for (size_t mi = 0; mi < b->nmethods; mi++)
        for (size_t i = 0; i < b->summary[mi].npts; i++)
            if (isfinite(b->summary[mi].pts[i].surface_err))
                return 1;
    return 0;
}

static int any_image(const rp_bench *b)
{
    for (size_t mi = 0; mi < b->nmethods; mi++)
        for (size_t i = 0; i < b->summary[mi].npts; i++)
            if (isfinite(b->summary[mi].pts[i].rmse) && b->summary[mi].pts[i].rmse > 0)
                return 1;
    return 0;
}

static void gp_title(FILE *f, const char *s)
{
    /* a gnuplot single-quoted string: double the quotes */
    fputc('\'', f);
    for (; *s; s++) {
        if (*s == '\'')
            fputc('\'', f);
        fputc(*s, f);
    }
    fputc('\'', f);
}

/* One chart: the PNG, then the same plot again as SVG. */
static void gp_begin(FILE *f, const char *name)
{
    fprintf(f, "\n@PNG\nset output '%s.png'\n", name);
}

static void gp_end(FILE *f, const char *name)
{
    fprintf(f, "@SVG\nset output '%s.svg'\nreplot\nunset output\n", name);
}

/* "plot" commands over the methods: using columns, with yerrorlines. */
static void gp_plot_methods(FILE *f, const rp_bench *b, const char *using, const char *style, double hline,
                            const char *hline_title)
{
    fprintf(f, "plot ");
    int first = 1;
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        if (!b->summary[mi].npts)
            continue;
        fprintf(f, "%s'data/m%zu.dat' using %s with %s %s lw 2 pt 7 ps 0.8 title ", first ? "" : ", \\\n     ", mi,
                using, style, rp_plot_method_style(b->methods[mi].text));
        gp_title(f, b->methods[mi].text);
        first = 0;
    }
    if (hline > 0 && isfinite(hline))
        fprintf(f, ", \\\n     %.6g with lines dt 2 lc rgb '#777777' title '%s'", hline, hline_title);
    fputc('\n', f);
}

static rp_status write_plots_gp(const rp_bench *b, const char *dir, const rp_bench_output *opt, size_t ttt_points,
                                rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "plots.gp"), err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    rp_gnuplot_preamble(f, rp_gnuplot_png_terminal());
    const char *xtime = b->params.run.schedule == RP_SCHEDULE_ITERATIONS
                            ? "solver wall time (s; checkpoints by iterations)"
                            : "solver wall time (s)";
    int img = any_image(b);
    double ref_se = b->ref->rmse_se;
    if (img) {
        gp_begin(f, "error_time");
        fprintf(f, "set logscale xy\nset format y '%%g'\nset xlabel '%s'\n"
                   "set ylabel 'image RMSE (W sr^-1 m^-2)'\n"
                   "set title 'Error against time (mean and standard deviation over seeds)'\n",
                xtime);
        gp_plot_methods(f, b, "2:6:7:8", "yerrorlines", ref_se, "reference standard error");
        gp_end(f, "error_time");

        gp_begin(f, "error_work");
        fprintf(f, "set logscale xy\nset xlabel 'work: rays cast + form factors computed'\n"
                   "set ylabel 'image RMSE (W sr^-1 m^-2)'\n"
                   "set title 'Error against work'\n");
        gp_plot_methods(f, b, "4:6:7:8", "yerrorlines", ref_se, "reference standard error");
        gp_end(f, "error_work");

        if (opt && opt->samples_chart) {
            gp_begin(f, "error_samples");
            fprintf(f, "set logscale xy\nset xlabel '%s'\n"
                       "set ylabel 'image RMSE (W sr^-1 m^-2)'\n"
                       "set title 'Error against %s'\n",
                    opt->samples_label ? opt->samples_label : "samples per pixel",
                    opt->samples_label ? opt->samples_label : "samples per pixel");
            gp_plot_methods(f, b, "5:6:7:8", "yerrorlines", ref_se, "reference standard error");
            gp_end(f, "error_samples");
        }

        int col = opt && opt->samples_chart ? 8 : 2, any_fit = 0;
        for (size_t mi = 0; mi < b->nmethods; mi++)
            any_fit |= opt && opt->samples_chart ? b->summary[mi].fit_samples.ok : b->summary[mi].fit_time.ok;
        /* gnuplot stops the script at a plot with no valid point at all */
        if (any_fit) {
        gp_begin(f, "slopes");
        fprintf(f, "unset logscale\nset xrange [-0.5:%zu.5]\nset xtics rotate by -25\n"
                   "set xlabel 'method'\nset ylabel 'fitted slope of log RMSE against log %s'\nset bmargin 10\n"
                   "set title 'Convergence slopes with 95%% confidence intervals'\n"
                   "plot 'data/slopes.dat' using 1:%d:%d:%d:xticlabels(11) with yerrorbars lw 2 pt 7 ps 1.2 "
                   "title 'fitted slope', \\\n     -0.5 with lines dt 2 lc rgb '#777777' title 'Monte Carlo "
                   "N^-1/2 (-0.5)', \\\n     0 with lines dt 3 lc rgb '#aaaaaa' title 'flat (0)'\n",
                b->nmethods ? b->nmethods - 1 : 0, opt && opt->samples_chart ? "samples" : "time", col, col + 1,
                col + 2);
        gp_end(f, "slopes");
        fprintf(f, "set xtics norotate\nset autoscale x\nunset bmargin\n");
        }

        if (ttt_points) {
        gp_begin(f, "time_to_error");
        fprintf(f, "set logscale xy\nset xlabel 'target image RMSE (W sr^-1 m^-2), decreasing'\n"
                   "set ylabel '%s to reach it (interpolated)'\nset title 'Time to reach an error'\n"
                   "set xrange [*:*] reverse\n",
                xtime);
        if (isfinite(b->target))
            fprintf(f, "set arrow 1 from %.6g, graph 0 to %.6g, graph 1 nohead dt 2 lc rgb '#777777'\n"
                       "set label 1 'target RMSE %.3g' at %.6g, graph 0.98 rotate by 90 right offset -1,0 "
                       "tc rgb '#555555'\n",
                    b->target, b->target, b->target, b->target);
        fprintf(f, "plot ");
        for (size_t mi = 0; mi < b->nmethods; mi++) {
            fprintf(f, "%s'data/time_to_error.dat' index %zu using 1:2 with lines %s lw 2 title ",
                    mi ? ", \\\n     " : "", mi, rp_plot_method_style(b->methods[mi].text));
            gp_title(f, b->methods[mi].text);
        }
        fprintf(f, "\n");
        gp_end(f, "time_to_error");
        fprintf(f, "unset arrow 1\nunset label 1\nset xrange [*:*] noreverse\n");
        }
    }
    if (any_surface(b)) {
        gp_begin(f, "surface_time");
        fprintf(f, "set logscale xy\nset xlabel '%s'\n"
                   "set ylabel 'surface-average error (RMS relative error)'\n"
                   "set title 'Surface averages: error against time'\n",
                xtime);
        gp_plot_methods(f, b, "2:11:12:13", "yerrorlines", b->ref->surface_rel_se, "reference relative stderr");
        gp_end(f, "surface_time");
    }
    return rp_out_close(&o, 1, err);
}

/* -------------------------------------------------------------- sheet */

typedef struct sheet {
    uint32_t w, h;
    float *r, *g, *b;
} sheet;

static void sheet_tile(sheet *s, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h, const float *r, const float *g,
                       const float *b, double scale)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t d = (size_t)(y0 + y) * s->w + x0 + x, i = (size_t)y * w + x;
            s->r[d] = (float)(scale * r[i]);
            s->g[d] = (float)(scale * g[i]);
            s->b[d] = (float)(scale * b[i]);
        }
}

/* Reference and each method's final image (first seed) on the top row,
 * per-pixel error maps below; returns the scale of the error maps. */
static rp_status write_sheet(const rp_bench *b, const char *dir, const rp_exposure *fixed, double *err_scale,
                             size_t *ncols_out, rp_exposure *exposure_out, rp_error *err)
{
    const rp_reference *ref = b->ref;
    *err_scale = NAN;
    *ncols_out = 0;
    if (!ref->radiance)
        return RP_OK;
    const uint32_t w = ref->width, h = ref->height, gap = 4;
    const size_t npix = (size_t)w * h, nb = ref->nbands;
    const float **imgs = calloc(b->nmethods + 1, sizeof *imgs);
    if (!imgs)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    size_t ncols = 1;
    imgs[0] = ref->radiance;
    double worst_mae = 0;
    for (size_t mi = 0; mi < b->nmethods; mi++)
        for (size_t r = 0; r < b->nruns; r++)
            if (b->runs[r].method == mi && b->runs[r].image) {
                imgs[ncols++] = b->runs[r].image;
                double mae = b->summary[mi].final.mae;
                if (isfinite(mae) && mae > worst_mae)
                    worst_mae = mae;
                break;
            }
    /* error maps: 0 .. 3 x the largest final MAE */
    double scale = worst_mae > 0 ? 3 * worst_mae : 1;
    sheet s = {.w = (uint32_t)(ncols * (w + gap) + gap), .h = 2 * (h + gap) + gap};
    size_t n = (size_t)s.w * s.h;
    s.r = malloc(n * sizeof(float));
    s.g = malloc(n * sizeof(float));
    s.b = malloc(n * sizeof(float));
    float *tr = malloc(3 * npix * sizeof(float)), *emap = malloc(npix * sizeof(float));
    rp_status st = RP_OK;
    if (!s.r || !s.g || !s.b || !tr || !emap)
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory for the image sheet");
    /* One exposure for the whole sheet, so the images compare: --exposure,
     * else the reference's automatic one (image.h). */
    rp_exposure ex = fixed ? *fixed : rp_exposure_fixed(0);
    if (st == RP_OK && !fixed) {
        rp_image_to_rgb(b->scene, ref->radiance, npix, tr, tr + npix, tr + 2 * npix);
        st = rp_exposure_auto(npix, tr, tr + npix, tr + 2 * npix, &ex, err);
    }
    const double exposure = ex.scale;
    if (st == RP_OK) {
        /* mid grey background, in linear units once exposure is applied */
        float bg = (float)(0.2 / exposure);
        for (size_t i = 0; i < n; i++)
            s.r[i] = s.g[i] = s.b[i] = bg;
        for (size_t c = 0; c < ncols; c++) {
            uint32_t x0 = gap + (uint32_t)c * (w + gap);
            rp_image_to_rgb(b->scene, imgs[c], npix, tr, tr + npix, tr + 2 * npix);
            sheet_tile(&s, x0, gap, w, h, tr, tr + npix, tr + 2 * npix, 1.0);
            if (c == 0)
                continue;
            rp_metrics_error_map(imgs[c], ref->radiance, npix, nb, emap);
            for (size_t i = 0; i < npix; i++) {
                float rgb[3];
                if (ref->mask[i])
                    rp_colormap(emap[i] / scale, rgb);
                else
                    rgb[0] = rgb[1] = rgb[2] = 0.01f;
                tr[i] = rgb[0];
                tr[npix + i] = rgb[1];
                tr[2 * npix + i] = rgb[2];
            }
            sheet_tile(&s, x0, 2 * gap + h, w, h, tr, tr + npix, tr + 2 * npix, 1.0 / exposure);
        }
        /* below the reference: the colour ramp, left (0) to right (scale) */
        for (uint32_t y = 0; y < h / 8; y++)
            for (uint32_t x = 0; x < w; x++) {
                float rgb[3];
                rp_colormap((double)x / (w - 1 ? w - 1 : 1), rgb);
                size_t d = (size_t)(2 * gap + h + h / 2 + y) * s.w + gap + x;
                s.r[d] = (float)(rgb[0] / exposure);
                s.g[d] = (float)(rgb[1] / exposure);
                s.b[d] = (float)(rgb[2] / exposure);
            }
        char path[1024];
        st = rp_image_write_png(rp_path_join(path, sizeof path, dir, "sheet.png"), s.w, s.h, s.r, s.g, s.b, &ex,
                                err);
    }
    free(s.r);
    free(s.g);
    free(s.b);
    free(tr);
    free(emap);
    free(imgs);
    *err_scale = scale;
    *ncols_out = ncols;
    *exposure_out = ex;
    return st;
}

/* ------------------------------------------------------------- report */

static void md_num(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.4g", v);
    else
        fputs("n/a", f);
}

static void md_pm(FILE *f, double v, double sd, size_t n)
{
    md_num(f, v);
    if (n > 1 && isfinite(sd)) {
        fputs(" ± ", f);
        fprintf(f, "%.2g", sd);
    }
}

static void md_fit(FILE *f, const rp_fit *fit)
{
    if (!fit->ok) {
        fputs("n/a", f);
        return;
    }
    /* an error that did not change (the method met its rule before the
     * first checkpoint) has no rate: not a slope of "-0.000" */
    if (fabs(fit->slope) < 5e-4 && fabs(fit->hi - fit->lo) < 1e-3) {
        fputs("n/a (no change: converged)", f);
        return;
    }
    fprintf(f, "%.3f [%.3f, %.3f]", fit->slope, fit->lo, fit->hi);
}

static rp_status write_report(const rp_bench *b, const char *dir, const rp_bench_output *opt, const char *plots_note,
                              int charts, double err_scale, size_t sheet_cols, const rp_exposure *exposure,
                              rp_error *err)
{
    char path[1024];
    rp_out o;
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, dir, "report.md"), err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    const rp_reference *r = b->ref;
    const char *unit = b->params.run.schedule == RP_SCHEDULE_ITERATIONS ? "iterations" : "s";
    if (opt && opt->title)
        fprintf(f, "# %s\n\n", opt->title);
    else
        fprintf(f, "# radpt bench: %s\n\n", b->scene_name);
    if (b->interrupted)
        fprintf(f, "**INCOMPLETE: interrupted after %zu of %zu runs.** Every number below is from the finished runs "
                   "only. The finished runs are recorded in `journal.txt`; the same command with `--resume DIR` in "
                   "place of `-o DIR` runs the rest.\n\n",
                b->nruns, b->planned);
    if (opt && opt->preface)
        fprintf(f, "%s\n\n", opt->preface);
    fprintf(f, "Scene `%s` (hash `%s`); budget %g %s per run, checkpoints at budget × 2^-k for k = %u … 0; "
               "Monte Carlo methods with %u seeds (first seed %llu); %d threads.",
            b->scene_name, b->scene_hash, b->params.run.budget, unit, b->params.run.levels - 1, b->params.nseeds,
            (unsigned long long)b->params.seed, b->threads);
    if (b->resumed)
        fprintf(f, " %zu of the %zu runs were read back from the journal of an interrupted study (their timings "
                   "are as first measured).", b->resumed, b->nruns);
    if (opt && opt->command)
        fprintf(f, "\nCommand: `%s`", opt->command);
    fprintf(f, "\n\nEvery number below is computed from the rows of `runs.csv` (columns at the end); "
               "`summary.json` holds the same summaries.\n\n");

    /* reference */
    fprintf(f, "## Reference\n\n");
    if (r->kind == RP_REFERENCE_EXACT)
        fprintf(f, "Exact (closed form): every surface of this closed enclosure shares one reflectance and one "
                   "emission, so L = Le / (1 - rho) = %.6g everywhere (band 0). File `%s`%s.\n",
                r->exact_L[0], r->exr_path, r->cached ? " (cached)" : "");
    else
        fprintf(f, "Path traced: pathtrace, independent random numbers (so its variance estimate is unbiased), %lu "
                   "samples per pixel, %lu probe points per "
                   "surface, seed %llu (no benchmark run uses it), made in %.1f s; file `%s`%s. Its own RMSE "
                   "standard error is %.3g W sr^-1 m^-2 and its surface averages' RMS relative standard error %.3g.\n",
                r->spp, r->samples, (unsigned long long)r->seed, r->seconds, r->exr_path,
                r->cached ? " (reused from the cache)" : "", r->rmse_se, r->surface_rel_se);
    fprintf(f, "\nMeasured: %zu pixels (fully covered by front faces of surfaces that reflect; pure emitters, "
               "background and silhouette pixels excluded), and every surface that is not a pure emitter.\n",
            r->mask_count);
    int flagged = 0;
    for (size_t mi = 0; mi < b->nmethods; mi++)
        if (b->summary[mi].final.ref_flag) {
            if (!flagged)
                fputc('\n', f);
            flagged = 1;
            char deb[32] = "not positive";
            if (isfinite(b->summary[mi].final.rmse_debiased))
                snprintf(deb, sizeof deb, "%.4g", b->summary[mi].final.rmse_debiased);
            fprintf(f, "**Warning:** the reference does not resolve the error of `%s` at the end: the error with "
                       "the reference's noise removed is not positive or known to worse than 10%% (RMSE %.4g, "
                       "debiased %s, reference standard error %.3g; surface error %.4g, reference %.3g). Make a "
                       "longer reference (`radpt bench ... --reference-spp N`).\n\n",
                    b->methods[mi].text, b->summary[mi].final.rmse, deb, r->rmse_se,
                    b->summary[mi].final.surface_err, r->surface_rel_se);
        }
    if (b->failures) {
        fputc('\n', f);
        for (size_t ri = 0; ri < b->nruns; ri++)
            if (b->runs[ri].status != RP_OK)
                fprintf(f, "**Failed:** `%s` seed %llu: %s\n\n", b->methods[b->runs[ri].method].text,
                        (unsigned long long)b->runs[ri].seed, b->runs[ri].error);
    }

    /* final table */
    fprintf(f, "\n## At the end of the budget\n\nMeans over seeds (± standard deviation) of each run's last row "
               "(`final` = 1 in runs.csv).\n\n"
               "| method | runs | wall s | CPU s | samples | iterations | rays | form factors | peak RSS MiB | "
               "RMSE | RMSE debiased | relMSE | MAE | surface error | reference ok |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        const rp_agg *a = &s->final;
        fprintf(f, "| `%s` | %zu/%zu | ", b->methods[mi].text, s->runs_ok, s->runs);
        md_pm(f, a->wall_s, a->wall_sd, a->n);
        fputs(" | ", f);
        md_num(f, a->cpu_s);
        fputs(" | ", f);
        md_num(f, a->samples);
        fputs(" | ", f);
        md_num(f, a->iterations);
        fputs(" | ", f);
        md_num(f, a->rays);
        fputs(" | ", f);
        md_num(f, a->form_factors);
        fputs(" | ", f);
        md_num(f, a->peak_rss_mb);
        fputs(" | ", f);
        md_pm(f, a->rmse, a->rmse_sd, a->n);
        fputs(" | ", f);
        md_pm(f, a->rmse_debiased, a->rmse_debiased_sd, a->n);
        fputs(" | ", f);
        md_pm(f, a->relmse, a->relmse_sd, a->n);
        fputs(" | ", f);
        md_pm(f, a->mae, a->mae_sd, a->n);
        fputs(" | ", f);
        md_pm(f, a->surface_err, a->surface_err_sd, a->n);
        fprintf(f, " | %s |\n", a->n == 0 ? "n/a" : (a->ref_flag ? "**no**" : "yes"));
    }

    /* convergence */
    fprintf(f, "\n## Convergence\n\n");
    if (charts)
        fprintf(f, "![Image RMSE against solver time](error_time.png)\n\n");
    fprintf(f, "Log-log chart of image RMSE against solver wall time, all methods; error bars: one standard "
               "deviation over seeds; dashed: the reference's own RMSE standard error, the floor the plotted RMSE "
               "cannot fall below. Deterministic radiosity curves flatten at their discretisation error. "
               "(The reference is independent of every run, so the RMSE against it exceeds the RMSE against the "
               "truth by at most its own error; `RMSE debiased` subtracts its estimated variance, which is "
               "unbiased for the reference's independent random numbers, and estimates the RMSE against the truth "
               "even below the dashed line.)\n\n"
               "Fitted slopes of log RMSE against log time, log work (rays + form factors) and log samples, over "
               "every row of every seed (least squares, GSL `gsl_fit_linear`; 95%% interval from Student's t with "
               "n - 2 degrees of freedom). Monte Carlo error falls as N^-1/2: slope -0.5.\n\n"
               "| method | slope vs time [95%% CI] | slope vs work | slope vs samples | points |\n|---|---|---|---|---|\n");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        fprintf(f, "| `%s` | ", b->methods[mi].text);
        md_fit(f, &s->fit_time);
        fputs(" | ", f);
        md_fit(f, &s->fit_work);
        fputs(" | ", f);
        md_fit(f, &s->fit_samples);
        fprintf(f, " | %zu |\n", s->fit_time.n);
    }
    if (charts) {
        fprintf(f, "\n![Fitted slopes](slopes.png)\n");
        if (opt && opt->samples_chart)
            fprintf(f, "\n![Image RMSE against samples per pixel](error_samples.png)\n");
        fprintf(f, "\n![Image RMSE against work](error_work.png)\n");
        if (any_surface(b))
            fprintf(f, "\n![Surface-average error against time](surface_time.png)\n");
    }

    /* time to error */
    fprintf(f, "\n## Time to reach an error\n\nTarget image RMSE %.4g W sr^-1 m^-2 (%s). Seconds of solver time "
               "at which the mean RMSE curve first reaches it, interpolated in log-log between checkpoints.\n\n"
               "| method | seconds to RMSE %.4g |\n|---|---|\n",
            b->target,
            b->target_auto ? "automatic: geometric mean of the best and worst final RMSE; set it with --target"
                           : "given with --target",
            b->target);
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        fprintf(f, "| `%s` | ", b->methods[mi].text);
        if (!isfinite(s->time_to_target))
            fputs("not reached", f);
        else if (s->target_before)
            fprintf(f, "≤ %.4g (already at the first checkpoint)", s->time_to_target);
        else
            fprintf(f, "%.4g", s->time_to_target);
        fputs(" |\n", f);
    }
    if (charts)
        fprintf(f, "\n![Time to reach an error](time_to_error.png)\n");

    /* images */
    if (sheet_cols > 1) {
        fprintf(f, "\n## Images at equal time\n\n![Reference, methods and error maps](sheet.png)\n\n"
                   "Top row, left to right: the reference, then each method's final image (first seed) in this "
                   "order:");
        size_t c = 1;
        for (size_t mi = 0; mi < b->nmethods; mi++)
            for (size_t ri = 0; ri < b->nruns; ri++)
                if (b->runs[ri].method == mi && b->runs[ri].image) {
                    fprintf(f, " %zu. `%s`", c++, b->methods[mi].text);
                    break;
                }
        char ev[160];
        rp_exposure_describe(exposure, ev, sizeof ev);
        fprintf(f, ". One exposure for the whole top row (%s%s), so the images compare. Bottom row: per-pixel "
                   "absolute error against the reference (mean over bands), colour ramp "
                   "from 0 (dark blue) to %.3g W sr^-1 m^-2 (yellow; 3 × the largest final MAE) as drawn under the "
                   "reference; near-black pixels are not measured.\n",
                ev, exposure->automatic ? ", from the reference" : " by --exposure", err_scale);
    }

    /* per checkpoint */
    fprintf(f, "\n## Per checkpoint\n\nMeans over seeds per checkpoint k (rows of runs.csv with the same method "
               "and checkpoint).\n");
    for (size_t mi = 0; mi < b->nmethods; mi++) {
        const rp_method_summary *s = &b->summary[mi];
        fprintf(f, "\n`%s`\n\n| k | rows | wall s | samples | work | RMSE | RMSE debiased | relMSE | MAE | "
                   "surface error |\n|---|---|---|---|---|---|---|---|---|---|\n",
                b->methods[mi].text);
        for (size_t i = 0; i < s->npts; i++) {
            const rp_agg *a = &s->pts[i];
            fprintf(f, "| %d | %zu | ", a->index, a->n);
            md_num(f, a->wall_s);
            fputs(" | ", f);
            md_num(f, a->samples);
            fputs(" | ", f);
            md_num(f, a->work);
            fputs(" | ", f);
            md_pm(f, a->rmse, a->rmse_sd, a->n);
            fputs(" | ", f);
            md_pm(f, a->rmse_debiased, a->rmse_debiased_sd, a->n);
            fputs(" | ", f);
            md_num(f, a->relmse);
            fputs(" | ", f);
            md_num(f, a->mae);
            fputs(" | ", f);
            md_num(f, a->surface_err);
            fputs(" |\n", f);
        }
    }
    if (plots_note && *plots_note)
        fprintf(f, "\n**Note:** %s\n", plots_note);
    fprintf(f, "\n## Columns of runs.csv\n\n");
    for (const char *p = rp_runs_csv_columns; *p;) {
        const char *nl = strchr(p, '\n');
        size_t len = nl ? (size_t)(nl - p) : strlen(p);
        const char *colon = memchr(p, ':', len);
        if (colon)
            fprintf(f, "- `%.*s`:%.*s\n", (int)(colon - p), p, (int)(len - (size_t)(colon - p) - 1), colon + 1);
        p += len + (nl ? 1 : 0);
    }
    return rp_out_close(&o, 1, err);
}

rp_status rp_bench_write(const rp_bench *b, const char *dir, const rp_bench_output *opt, char *note, rp_error *err)
{
    char plots_note[256] = "";
    rp_status st = rp_mkdirs(dir, err);
    if (st == RP_OK)
        st = rp_bench_write_runs_csv(b, dir, err);
    size_t ttt_points = 0;
    if (st == RP_OK)
        st = write_data(b, dir, &ttt_points, err);
    if (st == RP_OK)
        st = write_plots_gp(b, dir, opt, ttt_points, err);
    int charts = 0;
    if (st == RP_OK) {
        rp_error gerr;
        rp_status gs = rp_gnuplot_run(dir, "plots.gp", &gerr);
        charts = gs == RP_OK;
        if (!charts)
            snprintf(plots_note, sizeof plots_note, "charts not drawn: %.200s", gerr.message);
    }
    double scale = NAN;
    rp_exposure exposure = rp_exposure_fixed(0);
    size_t cols = 0;
    if (st == RP_OK && (!opt || opt->sheet))
        st = write_sheet(b, dir, opt ? opt->exposure : NULL, &scale, &cols, &exposure, err);
    if (st == RP_OK)
        st = write_summary_json(b, dir, plots_note, err);
    if (st == RP_OK)
        st = write_report(b, dir, opt, plots_note, charts, scale, cols, &exposure, err);
    if (note)
        snprintf(note, 256, "%s", plots_note);
    return st;
}
