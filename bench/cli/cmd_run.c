/* radpt render and radpt probe: the harness loop around one solver.
 *
 * The harness owns the clock: it calls step until the method's own rule is
 * met or the --time budget runs out, then estimate once; the cost of the
 * estimate is not solver time. */
#include <math.h>
#include <omp.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/scene.h"
#include "solvers/solver.h"
#include "bench/cli/cli.h"
#include "bench/cli/commands.h"
#include "bench/report/image.h"
#include "bench/run/clock.h"
#include "bench/run/driver.h"
#include "bench/run/mpi.h"
#include "bench/run/resume.h"
#include "bench/report/spectrum.h"

/* SIGINT / SIGTERM stop a run.  The flag is the solver's cancellation flag
 * (rp_options.cancel), polled inside set-up and steps: a method stopped
 * there returns RP_ERR_INTERRUPTED and nothing is written.  Noticed at a
 * step boundary (a path tracer's pass), the image reached so far is still
 * written (marked interrupted).  Either way the exit status is 1.  A
 * lock-free atomic: written by the handler, read by the solver's threads
 * (C11 7.14.1.1). */
static atomic_int interrupted;
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the signal flag must be a lock-free atomic");

static void on_signal(int sig)
{
    (void)sig;
    atomic_store_explicit(&interrupted, 1, memory_order_relaxed);
}

/* render --checkpoint / --resume (resume.h). */
typedef struct run_ckpt {
    const char *path;       /* --checkpoint FILE, NULL: none */
    double every;           /* --checkpoint-every, seconds of the run */
    rp_resume_info info;    /* the run's identity; totals filled when written */
    int converged;          /* the resumed state already meets the method's rule */
    size_t written;
} run_ckpt;

/* Writes the checkpoint; the time it takes is not solver time (returned
 * in *spent). */
static rp_status write_ckpt(run_ckpt *ck, const rp_solver *solver, const rp_drive_totals *tot, double *spent,
                            rp_error *err)
{
    double t = rp_clock();
    ck->info.steps = (double)tot->steps;
    ck->info.iterations = tot->sum.iterations;
    ck->info.rays = tot->sum.rays;
    ck->info.paths = tot->sum.paths;
    ck->info.form_factors = tot->sum.form_factors;
    ck->info.seconds = tot->wall_s;
    rp_status st = rp_resume_save(ck->path, &ck->info, solver, err);
    ck->written += st == RP_OK;
    *spent += rp_clock() - t;
    return st;
}

/* render's periodic state saving, after a step of the driver (not after
 * the last: that one is saved once the run has ended). */
typedef struct saving {
    run_ckpt *ck;
    double last;
} saving;

static int save_after_step(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    saving *sv = ctx;
    double excluded = 0;
    /* solver seconds, which all MPI ranks share (the driver's), so that
     * they save (collectively) together */
    if (sv->ck && sv->ck->path && t->stop == RP_STOP_NONE && t->wall_s - sv->last >= sv->ck->every) {
        *st = write_ckpt(sv->ck, s, t, &excluded, err);
        sv->last = t->wall_s;
    }
    return 0;
}

static void bar_progress(void *ctx, double fraction, const char *detail)
{
    rp_progress_update(ctx, fraction, detail);
}

/* Runs the solver through the driver (bench/run/driver.h): to the method's
 * rule, --time (this run's seconds only) or a signal.  tot comes in zeroed,
 * or with a resumed run's totals, which it carries on. */
static rp_status run_solver(rp_solver *solver, const rp_cli *cli, const char *label,
                            rp_drive_totals *tot, run_ckpt *ck, rp_error *err)
{
    rp_progress bar;
    rp_progress_begin(&bar, label);
    double excluded = 0;
    if (ck && ck->converged) {
        rp_progress_end(&bar);
        return ck->path ? write_ckpt(ck, solver, tot, &excluded, err) : RP_OK;
    }
    saving sv = {.ck = ck, .last = tot->wall_s};
    rp_drive_params dp = {.size = sizeof dp, .budget = cli->time_budget, .stop_at_rule = 1, .cancel = &interrupted,
                          .after_step = save_after_step, .ctx = &sv, .progress = bar_progress,
                          .progress_ctx = &bar};
    rp_status st = rp_drive(solver, &dp, tot, err);
    rp_progress_end(&bar);
    if (st != RP_OK)
        return st;
    /* the last state, whether converged, out of time or interrupted */
    return ck && ck->path ? write_ckpt(ck, solver, tot, &excluded, err) : RP_OK;
}

/* What a method says about its set-up and its result (hierarchical
 * radiosity's leaves and links, a uniform solver's mesh and matrix) goes
 * to stderr, as progress does. */
static void stderr_log(void *ctx, const char *message)
{
    (void)ctx;
    rp_cli_note("radpt: %s", message);
}

static void fill_options(rp_options *o, const rp_cli *cli, unsigned want)
{
    memset(o, 0, sizeof *o);
    o->size = sizeof *o;
    o->want = want;
    o->seed = cli->seed;
    o->threads = cli->threads;
    o->keys = cli->keys;
    o->values = cli->values;
    o->count = cli->noptions;
    o->open_ended = cli->time_budget > 0;
    o->log = stderr_log;
    o->cancel = &interrupted;
    o->comm = rp_mpi_world(); /* used by methods that split their work */
}

/* Under mpirun, a method that does not split its work runs on rank 0
 * alone: the other ranks stop here (after loading the scene, so that bad
 * input fails alike everywhere) and wait in rp_mpi_finish. */
static int idle_rank(const char *method)
{
    const rp_solver_type *t = rp_solver_lookup(method);
    return rp_mpi_rank() != 0 && t && !t->distributed;
}

/* Whether the run met its method's tolerance: known for methods that
 * report a residual and a tolerance (the radiosity solvers). */
typedef struct run_convergence {
    int known, converged;
    double residual, tolerance;
    const char *stopped_by; /* "rule" (the method's own), "iterations" (its cap,
                               short of the tolerance), "time", "signal" */
} run_convergence;

/* Fills c; for a run that stopped short of its tolerance, warns on stderr
 * "radpt: warning: METHOD stopped by WHAT after N UNIT, residual R >
 * tolerance T: not converged". */
static void run_convergence_report(const rp_cli *cli, const rp_drive_totals *tot, run_convergence *c)
{
    const rp_solver_type *t = rp_solver_lookup(cli->method);
    c->residual = tot->last.residual;
    c->tolerance = tot->last.tolerance;
    c->known = c->residual >= 0 && c->tolerance >= 0;
    c->converged = c->known && c->residual <= c->tolerance;
    int given = 0;
    for (size_t i = 0; i < cli->noptions; i++)
        given |= strcmp(cli->keys[i], "max-iterations") == 0;
    const char *why = tot->stop == RP_STOP_BUDGET ? "--time"
                      : tot->stop == RP_STOP_SIGNAL ? "a signal"
                      : given ? "--max-iterations"
                              : "its default --max-iterations";
    c->stopped_by = tot->stop == RP_STOP_BUDGET ? "time"
                    : tot->stop == RP_STOP_SIGNAL ? "signal"
                    : c->converged || !c->known ? "rule"
                                                : "iterations";
    if (c->known && !c->converged)
        fprintf(stderr, "radpt: warning: %s stopped by %s after %.17g %s, residual %.3g > tolerance %.3g: "
                        "not converged\n",
                cli->method, why, tot->sum.iterations, t && t->iteration_name ? t->iteration_name : "iterations",
                c->residual, c->tolerance);
}

static void options_text(const rp_cli *cli, char *buf, size_t n)
{
    buf[0] = '\0';
    size_t used = 0;
    for (size_t i = 0; i < cli->noptions && used < n; i++)
        used += (size_t)snprintf(buf + used, n - used, "%s--%s %s", i ? " " : "", cli->keys[i],
                                 cli->values[i]);
}

/* The method's options left at their defaults, as "--name value" words
 * (radpt:defaults): with radpt:options, every setting the run used. */
static void defaults_text(const rp_cli *cli, char *buf, size_t n)
{
    buf[0] = '\0';
    const rp_solver_type *t = rp_solver_lookup(cli->method);
    size_t used = 0;
    for (const rp_option_spec *o = t ? t->options : NULL; o && o->name && used < n; o++) {
        if (!o->fallback || !o->arg)
            continue;
        int given = 0;
        for (size_t i = 0; i < cli->noptions && !given; i++)
            given = strcmp(cli->keys[i], o->name) == 0;
        if (!given)
            used += (size_t)snprintf(buf + used, n - used, "%s--%s %s", used ? " " : "", o->name, o->fallback);
    }
}

/* Channel names and planes for a scene's bands (docs/design.md, "Images"). */
typedef struct image_planes {
    size_t nchannels;
    char **names;
    float **planes;
} image_planes;

static void planes_free(image_planes *p)
{
    for (size_t c = 0; c < p->nchannels; c++) {
        free(p->names ? p->names[c] : NULL);
        free(p->planes ? p->planes[c] : NULL);
    }
    free(p->names);
    free(p->planes);
}

static rp_status planes_make(const rp_scene *scene, const float *radiance, size_t npix,
                             image_planes *p, rp_error *err)
{
    size_t nb = rp_scene_nbands(scene);
    rp_band_kind kind = rp_scene_band_kind(scene);
    p->nchannels = kind == RP_BANDS_SPECTRAL ? nb + 3 : nb;
    p->names = calloc(p->nchannels, sizeof *p->names);
    p->planes = calloc(p->nchannels, sizeof *p->planes);
    if (!p->names || !p->planes)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the image");
    for (size_t c = 0; c < p->nchannels; c++) {
        p->names[c] = malloc(32);
        p->planes[c] = calloc(npix, sizeof(float));
        if (!p->names[c] || !p->planes[c])
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the image");
    }
    static const char *rgb[3] = {"R", "G", "B"};
    if (kind == RP_BANDS_GREY)
        strcpy(p->names[0], "Y");
    else if (kind == RP_BANDS_RGB)
        for (int c = 0; c < 3; c++)
            strcpy(p->names[c], rgb[c]);
    else {
        const double *nm = rp_scene_wavelengths(scene);
        for (size_t b = 0; b < nb; b++)
            snprintf(p->names[b], 32, "L%g", nm[b]);
        for (int c = 0; c < 3; c++)
            strcpy(p->names[nb + (size_t)c], rgb[c]);
    }
    for (size_t b = 0; b < nb; b++)
        for (size_t i = 0; i < npix; i++)
            p->planes[b][i] = radiance[i * nb + b];
    if (kind == RP_BANDS_SPECTRAL) {
        double *m = malloc(3 * nb * sizeof *m);
        if (!m)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the image");
        rp_spectrum_rgb_weights(rp_scene_wavelengths(scene), nb, m);
        for (size_t i = 0; i < npix; i++)
            for (size_t c = 0; c < 3; c++) {
                double v = 0;
                for (size_t b = 0; b < nb; b++)
                    v += m[c * nb + b] * radiance[i * nb + b];
                p->planes[nb + c][i] = (float)v;
            }
        free(m);
    }
    return RP_OK;
}

int rp_cmd_render(int argc, char **argv)
{
    static const char *const extra[] = {"checkpoint", "checkpoint-every", "resume", "exposure", NULL};
    rp_cli cli = {.command = "render"};
    int rc = rp_cli_parse(&cli, argc, argv, extra, 1);
    if (rc)
        return rc;
    if (!cli.out) {
        fprintf(stderr, "radpt render: needs -o OUT.exr|.png|.pfm (see radpt help)\n");
        return 2;
    }
    /* the format is the extension's: EXR (every band, metadata), PNG (an
     * sRGB preview) or PFM (linear RGB) */
    const rp_image_format format = rp_image_format_of(cli.out);
    if (format == RP_IMAGE_UNKNOWN) {
        fprintf(stderr, "radpt render: -o %s: unknown image format; the extension chooses it: .exr (linear "
                        "radiance, every band, metadata), .png (sRGB preview) or .pfm (linear RGB)\n", cli.out);
        return 2;
    }
    if (cli.png && rp_image_format_of(cli.png) != RP_IMAGE_PNG) {
        fprintf(stderr, "radpt render: --png %s: the preview is a PNG; name it .png\n", cli.png);
        return 2;
    }
    rp_exposure exposure = rp_exposure_fixed(0); /* --exposure EV, else automatic */
    const char *ev_text = rp_cli_extra(&cli, "exposure");
    if (ev_text) {
        rp_error e;
        int has_png = cli.png || format == RP_IMAGE_PNG;
        if (rp_exposure_parse(ev_text, &exposure, &e) != RP_OK || !has_png) {
            fprintf(stderr, "radpt render: %s (see radpt help)\n",
                    has_png ? e.message : "--exposure needs a PNG (--png OUT.png or -o OUT.png)");
            return 2;
        }
    }
    const char *ckpt_path = rp_cli_extra(&cli, "checkpoint"), *resume_path = rp_cli_extra(&cli, "resume");
    const char *every_text = rp_cli_extra(&cli, "checkpoint-every");
    double every = 60;
    if (every_text) {
        char *end;
        every = strtod(every_text, &end);
        if (end == every_text || *end || !isfinite(every) || every < 0) {
            fprintf(stderr, "radpt render: --checkpoint-every: '%s' is not a number of seconds >= 0 "
                            "(see radpt help)\n", every_text);
            return 2;
        }
        if (!ckpt_path) {
            fprintf(stderr, "radpt render: --checkpoint-every needs --checkpoint FILE (see radpt help)\n");
            return 2;
        }
    }
    if ((rc = rp_cli_check_output("render", "-o", cli.out)) != 0 ||
        (rc = rp_cli_check_output("render", "--png", cli.png)) != 0 ||
        (rc = rp_cli_check_output("render", "--checkpoint", ckpt_path)) != 0)
        return rc;
    rp_cli_catch_signals(on_signal);
    if ((ckpt_path || resume_path) && !rp_solver_can_checkpoint(rp_solver_lookup(cli.method))) {
        fprintf(stderr, "radpt render: method %s cannot be checkpointed or resumed (only pathtrace can)\n",
                cli.method);
        return 2;
    }
    rp_error err;
    rp_scene *scene = NULL;
    rp_solver *solver = NULL;
    image_planes planes = {0};
    float *radiance = NULL;
    rp_status st = rp_load_scene(cli.scene, cli.camera, 1, &scene, &err);
    if (st != RP_OK)
        goto done;
    const rp_camera *cam = rp_scene_camera(scene);
    if (!cam) {
        st = rp_error_set(&err, RP_ERR_INPUT, "%s: the scene has no camera to render from", cli.scene);
        goto done;
    }
    if (idle_rank(cli.method))
        goto done;
    rp_options opts;
    fill_options(&opts, &cli, RP_WANT_IMAGE);
    st = rp_solver_create(rp_solver_lookup(cli.method), scene, &opts, &solver, &err);
    if (st != RP_OK)
        goto done;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    run_ckpt ck;
    memset(&ck, 0, sizeof ck);
    if (ckpt_path || resume_path) {
        ck.path = ckpt_path;
        ck.every = every;
        rp_scene_hash(scene, ck.info.scene_hash);
        snprintf(ck.info.method, sizeof ck.info.method, "%s", cli.method);
        ck.info.seed = cli.seed;
        ck.info.width = cam->width;
        ck.info.height = cam->height;
        ck.info.nbands = rp_scene_nbands(scene);
        snprintf(ck.info.scene, sizeof ck.info.scene, "%s", cli.scene);
        options_text(&cli, ck.info.options, sizeof ck.info.options);
    }
    if (resume_path) {
        rp_resume_info got;
        rp_step_info last;
        st = rp_resume_load(resume_path, &ck.info, &got, solver, &last, &err);
        if (st != RP_OK)
            goto done;
        tot.steps = got.steps;
        tot.sum.iterations = got.iterations;
        tot.sum.rays = got.rays;
        tot.sum.paths = got.paths;
        tot.sum.form_factors = got.form_factors;
        tot.wall_s = got.seconds;
        tot.last = last;
        ck.converged = last.converged;
    }
    st = run_solver(solver, &cli, "render", &tot, ckpt_path || resume_path ? &ck : NULL, &err);
    if (st != RP_OK)
        goto done;
    run_convergence conv;
    run_convergence_report(&cli, &tot, &conv);

    size_t nb = rp_scene_nbands(scene), npix = (size_t)cam->width * cam->height;
    radiance = malloc(npix * nb * sizeof *radiance);
    if (!radiance) {
        st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory for the image");
        goto done;
    }
    rp_estimate est = {.radiance = radiance};
    st = rp_solver_estimate(solver, &est, &err);
    if (st != RP_OK)
        goto done;
    for (size_t i = 0; i < npix * nb; i++)
        if (!isfinite(radiance[i])) {
            st = rp_error_set(&err, RP_ERR_RUNTIME, "method %s produced a non-finite radiance at pixel (%zu, %zu); "
                              "no image written", cli.method, (i / nb) % cam->width, (i / nb) / cam->width);
            goto done;
        }
    st = planes_make(scene, radiance, npix, &planes, &err);
    if (st != RP_OK)
        goto done;

    char hash[17], seed[32], samples[32], seconds[32], threads[16], rays[32], optstr[1024], defstr[2048],
        residual[32], tolerance[32];
    rp_scene_hash(scene, hash);
    snprintf(seed, sizeof seed, "%llu", (unsigned long long)cli.seed);
    snprintf(samples, sizeof samples, "%.17g", est.samples);
    snprintf(seconds, sizeof seconds, "%.6f", tot.wall_s);
    snprintf(threads, sizeof threads, "%d", cli.threads ? cli.threads : omp_get_max_threads());
    snprintf(rays, sizeof rays, "%.17g", tot.sum.rays);
    options_text(&cli, optstr, sizeof optstr);
    defaults_text(&cli, defstr, sizeof defstr);
    snprintf(residual, sizeof residual, "%.17g", conv.residual);
    snprintf(tolerance, sizeof tolerance, "%.17g", conv.tolerance);
    /* The convergence attributes come last, only for methods with a
     * residual and a tolerance. */
    rp_image_attr attrs[] = {
        {"radpt:scene", cli.scene}, {"radpt:scene_hash", hash}, {"radpt:method", cli.method},
        {"radpt:options", optstr},  {"radpt:defaults", defstr}, {"radpt:seed", seed},
        {"radpt:samples", samples},
        {"radpt:seconds", seconds}, {"radpt:threads", threads}, {"radpt:rays", rays},
        {"radpt:interrupted", interrupted ? "yes" : "no"},
        {"radpt:converged", conv.converged ? "yes" : "no"}, {"radpt:residual", residual},
        {"radpt:tolerance", tolerance}, {"radpt:stopped_by", conv.stopped_by},
    };
    rp_image img = {
        .width = cam->width, .height = cam->height, .nchannels = planes.nchannels,
        .channel_names = (const char *const *)planes.names,
        .planes = (const float *const *)planes.planes,
        .attrs = attrs, .nattrs = sizeof attrs / sizeof attrs[0] - (conv.known ? 0 : 4),
    };
    /* R, G, B: the last three planes (grey: Y three times) */
    size_t r0 = planes.nchannels >= 3 ? planes.nchannels - 3 : 0;
    const float *pr = planes.planes[r0], *pg = planes.planes[planes.nchannels >= 3 ? r0 + 1 : 0],
                *pb = planes.planes[planes.nchannels >= 3 ? r0 + 2 : 0];
    if (format == RP_IMAGE_EXR)
        st = rp_image_write_exr(cli.out, &img, &err);
    else if (format == RP_IMAGE_PFM)
        st = rp_image_write_pfm(cli.out, cam->width, cam->height, pr, pg, pb, &err);
    if (st != RP_OK)
        goto done;
    const char *pngs[2] = {format == RP_IMAGE_PNG ? cli.out : NULL, cli.png};
    if ((pngs[0] || pngs[1]) && !ev_text && (st = rp_exposure_auto(npix, pr, pg, pb, &exposure, &err)) != RP_OK)
        goto done;
    for (int k = 0; k < 2; k++) {
        if (!pngs[k])
            continue;
        if ((st = rp_image_write_png(pngs[k], cam->width, cam->height, pr, pg, pb, &exposure, &err)) != RP_OK)
            goto done;
        char note[160];
        rp_exposure_describe(&exposure, note, sizeof note);
        rp_cli_note("radpt: %s: exposure %s", pngs[k], note);
    }
    printf("wrote %s: %u x %u, %s, %.17g samples, %.3f s", cli.out, cam->width, cam->height,
           cli.method, est.samples, tot.wall_s);
    if (tot.sum.rays > 0 && tot.wall_s > 0)
        printf(", %.3g rays/s", tot.sum.rays / tot.wall_s);
    if (tot.sum.paths > 0 && tot.wall_s > 0)
        printf(", %.3g paths/s", tot.sum.paths / tot.wall_s);
    if (tot.sum.form_factors > 0)
        printf(", %.4g form factors", tot.sum.form_factors);
    if (tot.last.memory > 0)
        printf(", %.1f MiB held by the method", tot.last.memory / 1048576.0);
    if (!rp_solver_comm(solver))
        printf(", peak resident %.1f MiB", rp_peak_rss_mb());
    if (rp_solver_comm(solver)) {
        /* split over ranks: the largest rank's memory (make bench-mpi) */
        double mem[2] = {tot.last.memory / 1048576.0, rp_peak_rss_mb()};
        rp_comm_max(rp_solver_comm(solver), mem, 2);
        printf(", %d ranks (per rank at most:", rp_mpi_size());
        if (mem[0] > 0)
            printf(" %.1f MiB held by the method,", mem[0]);
        printf(" peak RSS %.1f MiB)", mem[1]);
    } else if (rp_mpi_size() > 1)
        printf(", on rank 0 alone (%s does not split its work over ranks)", cli.method);
    printf("\n");
    if (cli.png)
        printf("wrote %s\n", cli.png);
    if (ck.written)
        printf("wrote checkpoint %s (%.17g iterations)\n", ck.path, tot.sum.iterations);
    if (interrupted)
        st = rp_error_set(&err, RP_ERR_RUNTIME, "interrupted after %.17g samples; wrote what was reached",
                          est.samples);
done:
    planes_free(&planes);
    free(radiance);
    rp_solver_destroy(solver);
    rp_scene_destroy(scene);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}

int rp_cmd_probe(int argc, char **argv)
{
    rp_cli cli = {.command = "probe"};
    int rc = rp_cli_parse(&cli, argc, argv, NULL, 1);
    if (rc)
        return rc;
    if (!cli.surface_averages) {
        fprintf(stderr, "radpt probe: say what to probe: --surface-averages (see radpt help)\n");
        return 2;
    }
    rp_error err;
    rp_scene *scene = NULL;
    rp_solver *solver = NULL;
    double *mean = NULL, *se = NULL;
    rp_cli_catch_signals(on_signal);
    rp_status st = rp_load_scene(cli.scene, cli.camera, 0, &scene, &err);
    if (st != RP_OK || idle_rank(cli.method))
        goto done;
    rp_options opts;
    fill_options(&opts, &cli, RP_WANT_SURFACES);
    st = rp_solver_create(rp_solver_lookup(cli.method), scene, &opts, &solver, &err);
    if (st != RP_OK)
        goto done;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    st = run_solver(solver, &cli, "probe", &tot, NULL, &err);
    if (st != RP_OK)
        goto done;
    run_convergence conv;
    run_convergence_report(&cli, &tot, &conv);
    size_t nb = rp_scene_nbands(scene), ns = rp_scene_nsurfaces(scene);
    mean = calloc(ns * nb, sizeof *mean);
    se = calloc(ns * nb, sizeof *se);
    if (!mean || !se) {
        st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
        goto done;
    }
    rp_estimate est = {.surface_radiance = mean, .surface_stderr = se};
    st = rp_solver_estimate(solver, &est, &err);
    if (st != RP_OK)
        goto done;
    if (interrupted)
        fprintf(stderr, "radpt probe: interrupted; printing what was reached\n");
    for (size_t i = 0; i < ns * nb; i++)
        if (!isfinite(mean[i]) || !isfinite(se[i])) {
            st = rp_error_set(&err, RP_ERR_RUNTIME, "method %s produced a non-finite value", cli.method);
            goto done;
        }
    const rp_surface *surf = rp_scene_surfaces(scene);
    if (cli.json) {
        char hash[17];
        rp_scene_hash(scene, hash);
        printf("{\"scene\": ");
        rp_json_string(stdout, cli.scene);
        printf(", \"hash\": \"%s\", \"method\": ", hash);
        rp_json_string(stdout, cli.method);
        printf(", \"seed\": %llu, \"samples\": %.17g, \"seconds\": %.6f, \"rays\": %.17g, "
               "\"form_factors\": %.17g, \"memory_bytes\": %.17g, \"peak_rss_bytes\": %.17g",
               (unsigned long long)cli.seed, est.samples, tot.wall_s, tot.sum.rays, tot.sum.form_factors,
               tot.last.memory, rp_peak_rss_mb() * 1048576.0);
        /* null where the method has no residual and tolerance */
        if (conv.known)
            printf(", \"converged\": %s, \"residual\": %.17g, \"tolerance\": %.17g", conv.converged ? "true" : "false",
                   conv.residual, conv.tolerance);
        else
            printf(", \"converged\": null, \"residual\": null, \"tolerance\": null");
        printf(", \"stopped_by\": \"%s\", \"surfaces\": [", conv.stopped_by);
        for (size_t s = 0; s < ns; s++) {
            printf("%s{\"name\": ", s ? ", " : "");
            rp_json_string(stdout, surf[s].name);
            printf(", \"area\": %.12g, \"radiance\": [", surf[s].area);
            for (size_t b = 0; b < nb; b++)
                printf("%s%.10g", b ? ", " : "", mean[s * nb + b]);
            printf("], \"stderr\": [");
            for (size_t b = 0; b < nb; b++)
                printf("%s%.6g", b ? ", " : "", se[s * nb + b]);
            printf("]}");
        }
        printf("]}\n");
    } else {
        printf("# %s, method %s, %.17g samples, %.3f s", cli.scene, cli.method, est.samples, tot.wall_s);
        if (tot.last.memory > 0)
            printf(", %.1f MiB held by the method", tot.last.memory / 1048576.0);
        printf(", peak resident %.1f MiB", rp_peak_rss_mb());
        printf("; radiance W sr^-1 m^-2 per band +- standard error\n");
        printf("%-20s %14s  radiance\n", "surface", "area");
        for (size_t s = 0; s < ns; s++) {
            char nm[512];
            printf("%-20s %14.6f ", rp_cli_name(surf[s].name, nm, sizeof nm), surf[s].area);
            for (size_t b = 0; b < nb; b++)
                printf(" %.6g +- %.2g", mean[s * nb + b], se[s * nb + b]);
            printf("\n");
        }
    }
    if (interrupted)
        st = rp_error_set(&err, RP_ERR_RUNTIME, "interrupted after %.17g samples", est.samples);
done:
    free(mean);
    free(se);
    rp_solver_destroy(solver);
    rp_scene_destroy(scene);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}
