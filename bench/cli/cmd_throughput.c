/* radpt throughput and radpt samplers: the path tracer's performance
 * benchmarks (make bench).
 *
 * throughput: the random-ray limit (bench/raybench.c: incoherent closest-hit
 * rays through the same Embree scene) and the path tracer's rays/s and
 * paths/s, measured in one process, one after the other, so their ratio is
 * meaningful on a shared, noisy machine.
 *
 * samplers: each sampler renders for the same wall time; their RMSE
 * against a reference rendered with another seed says which wins at equal
 * time. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/solver.h"
#include "bench/cli/cli.h"
#include "bench/cli/commands.h"
#include "bench/run/driver.h"
#include "bench/run/metrics.h"
#include "bench/run/reference.h"
#include "bench/run/raybench.h"

static int parse_count(const rp_cli *cli, const char *name, unsigned long fallback, unsigned long *out)
{
    const char *v = rp_cli_extra(cli, name);
    *out = fallback;
    if (!v)
        return 0;
    char *end;
    unsigned long x = strtoul(v, &end, 10);
    if (end == v || *end || x == 0 || *v == '-') {
        fprintf(stderr, "radpt %s: --%s: '%s' is not a positive whole number\n", cli->command, name, v);
        return 2;
    }
    *out = x;
    return 0;
}

/* Renders with pathtrace until spp passes or `seconds` (if > 0) elapse;
 * fills image (npix * nbands) and the totals. */
static rp_status render(const rp_scene *scene, const char *sampler, unsigned long spp, double seconds,
                        uint64_t seed, int threads, float *image, double *rays, double *paths,
                        double *elapsed, double *samples, rp_error *err)
{
    char spp_text[32];
    snprintf(spp_text, sizeof spp_text, "%lu", spp);
    const char *keys[2] = {"sampler", "spp"};
    const char *values[2] = {sampler, spp_text};
    rp_options o = {.size = sizeof o, .want = RP_WANT_IMAGE, .seed = seed, .threads = threads,
                    .keys = keys, .values = values, .count = seconds > 0 ? 1 : 2,
                    .open_ended = seconds > 0};
    rp_solver *s = NULL;
    rp_status st = rp_solver_create(rp_solver_lookup("pathtrace"), scene, &o, &s, err);
    if (st != RP_OK)
        return st;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_drive_params dp = {.size = sizeof dp, .budget = seconds, .stop_at_rule = 1};
    st = rp_drive(s, &dp, &tot, err);
    *rays = tot.sum.rays;
    *paths = tot.sum.paths;
    *elapsed = tot.wall_s;
    if (st == RP_OK) {
        rp_estimate est = {.radiance = image};
        st = rp_solver_estimate(s, &est, err);
        *samples = est.samples;
    }
    rp_solver_destroy(s);
    return st;
}

int rp_cmd_throughput(int argc, char **argv)
{
    static const char *const extra[] = {"spp", "rays", NULL};
    rp_cli cli = {.command = "throughput"};
    int rc = rp_cli_parse(&cli, argc, argv, extra, 0);
    if (rc)
        return rc;
    unsigned long spp, nrays;
    if ((rc = parse_count(&cli, "spp", 64, &spp)) || (rc = parse_count(&cli, "rays", 20000000, &nrays)))
        return rc;
    rp_error err;
    rp_scene *scene = NULL;
    rp_raycast *rc_ = NULL;
    float *image = NULL;
    rp_status st = rp_load_scene(cli.scene, cli.camera, 1, &scene, &err);
    if (st == RP_OK)
        st = rp_raycast_create(scene, NULL, &rc_, &err);
    double limit = 0;
    if (st == RP_OK) {
        rp_cli_note("casting %lu random rays...", nrays);
        st = rp_raybench_run(scene, rc_, nrays, cli.threads, cli.seed, &limit, &err);
    }
    const rp_camera *cam = scene ? rp_scene_camera(scene) : NULL;
    if (st == RP_OK && !cam)
        st = rp_error_set(&err, RP_ERR_INPUT, "%s: the scene has no camera", cli.scene);
    double rays = 0, paths = 0, seconds = 0, samples = 0;
    if (st == RP_OK) {
        image = malloc((size_t)cam->width * cam->height * rp_scene_nbands(scene) * sizeof *image);
        if (!image)
            st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
    }
    if (st == RP_OK) {
        rp_cli_note("path tracing %lu spp...", spp);
        st = render(scene, "sobol", spp, 0, cli.seed, cli.threads, image, &rays, &paths, &seconds,
                    &samples, &err);
    }
    if (st == RP_OK) {
        double rps = rays / seconds;
        if (cli.json) {
            printf("{\"scene\": ");
            rp_json_string(stdout, cli.scene);
            printf(", \"width\": %u, \"height\": %u, \"spp\": %.0f, \"threads\": %d, "
                   "\"random_rays_per_s\": %.6g, \"pathtrace_seconds\": %.6g, \"paths_per_s\": %.6g, "
                   "\"rays_per_s\": %.6g, \"fraction_of_limit\": %.4f}\n",
                   cam->width, cam->height, samples, cli.threads, limit, seconds, paths / seconds, rps,
                   rps / limit);
        } else {
            printf("scene             %s, %u x %u, %.0f spp, threads %s\n", cli.scene, cam->width,
                   cam->height, samples, cli.threads ? "as given" : "all");
            printf("random-ray limit  %.4g rays/s (%lu incoherent closest-hit rays)\n", limit, nrays);
            printf("path tracer       %.3f s, %.4g paths/s, %.4g rays/s\n", seconds, paths / seconds, rps);
            printf("fraction          %.3f of the random-ray limit\n", rps / limit);
        }
    }
    free(image);
    rp_raycast_destroy(rc_);
    rp_scene_destroy(scene);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}

int rp_cmd_samplers(int argc, char **argv)
{
    static const char *const extra[] = {"spp", "reference-spp", "seeds", "cache", NULL};
    rp_cli cli = {.command = "samplers"};
    int rc = rp_cli_parse(&cli, argc, argv, extra, 0);
    if (rc)
        return rc;
    unsigned long spp, ref_spp, nseeds;
    if ((rc = parse_count(&cli, "spp", 64, &spp)) || (rc = parse_count(&cli, "reference-spp", 1024, &ref_spp)) ||
        (rc = parse_count(&cli, "seeds", 3, &nseeds)))
        return rc;
    rp_error err;
    rp_scene *scene = NULL;
    rp_reference *ref = NULL;
    float *img = NULL;
    rp_status st = rp_load_scene(cli.scene, cli.camera, 1, &scene, &err);
    const rp_camera *cam = scene ? rp_scene_camera(scene) : NULL;
    if (st == RP_OK && !cam)
        st = rp_error_set(&err, RP_ERR_INPUT, "%s: the scene has no camera", cli.scene);
    size_t nb = scene ? rp_scene_nbands(scene) : 0, npix = cam ? (size_t)cam->width * cam->height : 0;
    if (st == RP_OK && !(img = malloc(npix * nb * sizeof *img)))
        st = rp_error_set(&err, RP_ERR_NOMEM, "out of memory");
    /* The reference, the pixels and the metric are the benchmarks': the
     * cached reference of this many spp (bench/run/reference.h), its mask
     * of measured pixels (light and silhouette pixels out), and
     * rp_metrics_image.  So this RMSE is the one `radpt bench`, `radpt
     * experiment samplers` and `radpt compare --scene` report. */
    if (st == RP_OK) {
        rp_reference_params rp = {.size = sizeof rp, .spp = ref_spp, .threads = cli.threads,
                                  .cache_dir = rp_cli_extra(&cli, "cache")};
        st = rp_reference_get(scene, cli.scene, &rp, &ref, &err);
        if (st == RP_OK && !ref->radiance)
            st = rp_error_set(&err, RP_ERR_INPUT, "%s: the reference has no image", cli.scene);
    }
    double rays, paths, secs, samples;
    /* Each sampler renders the same spp; at equal time the error of an
     * unbiased estimator scales as MSE * seconds (its inverse is the usual
     * efficiency, Veach 1997 sec. 2.4 / Pharr et al.), so that product ranks
     * them at equal time without relying on noisy wall-clock stops. */
    static const char *const names[] = {"random", "stratified", "sobol"};
    double eff[3] = {0};
    if (st == RP_OK && !cli.json)
        printf("# %s, %lu spp, %lu seeds; reference %s (%lu spp, %s); RMSE over its %zu measured pixels\n"
               "# (the benchmarks' metric: radpt help compare); MSE x s: mean squared error times render\n"
               "# seconds (lower wins at equal time)\n"
               "%-12s %8s %12s %12s %12s %12s\n",
               cli.scene, spp, nseeds, ref->exr_path, ref->spp, ref->cached ? "cached" : "made now", ref->mask_count,
               "sampler", "seconds", "RMSE", "RMSE sd", "MSE x s", "vs random");
    if (st == RP_OK && cli.json) {
        printf("{\"scene\": ");
        rp_json_string(stdout, cli.scene);
        printf(", \"spp\": %lu, \"seeds\": %lu, \"reference_spp\": %lu, \"reference\": ", spp, nseeds, ref->spp);
        rp_json_string(stdout, ref->exr_path);
        printf(", \"measured_pixels\": %zu, \"samplers\": [", ref->mask_count);
    }
    for (int k = 0; k < 3 && st == RP_OK; k++) {
        double sum = 0, sum2 = 0, mse_sum = 0, sec_sum = 0;
        for (unsigned long s = 0; s < nseeds && st == RP_OK; s++) {
            rp_cli_note("%s, seed %lu...", names[k], cli.seed + s);
            st = render(scene, names[k], spp, 0, cli.seed + s, cli.threads, img, &rays, &paths, &secs,
                        &samples, &err);
            if (st != RP_OK)
                break;
            rp_image_metrics m;
            rp_metrics_image(img, ref->radiance, ref->mask, npix, nb, &m);
            double mse = m.rmse * m.rmse;
            sum += m.rmse;
            sum2 += mse;
            mse_sum += mse;
            sec_sum += secs;
        }
        if (st != RP_OK)
            break;
        double mean = sum / (double)nseeds;
        double sd = nseeds > 1 ? sqrt(fmax(0, (sum2 - sum * mean) / (double)(nseeds - 1))) : 0;
        double secs_mean = sec_sum / (double)nseeds, mse_mean = mse_sum / (double)nseeds;
        eff[k] = mse_mean * secs_mean;
        if (cli.json)
            printf("%s{\"sampler\": \"%s\", \"seconds\": %.4g, \"rmse\": %.6g, \"rmse_sd\": %.3g, "
                   "\"mse_times_seconds\": %.6g}",
                   k ? ", " : "", names[k], secs_mean, mean, sd, eff[k]);
        else
            printf("%-12s %8.3f %12.6g %12.3g %12.4g %11.2fx\n", names[k], secs_mean, mean, sd, eff[k],
                   eff[0] / eff[k]);
        fflush(stdout);
    }
    if (st == RP_OK && cli.json)
        printf("]}\n");
    rp_reference_destroy(ref);
    free(img);
    rp_scene_destroy(scene);
    return st == RP_OK ? 0 : rp_cli_fail(st, &err);
}
