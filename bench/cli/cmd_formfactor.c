/* radpt formfactor SCENE --from SURFACE --to SURFACE [--method M] ...:
 * the form factor between two surfaces of a scene, from the element form
 * factors of solvers/radiosity/formfactor.h,
 *
 *     F_AB = sum_{i in A} sum_{j in B} A_i F_ij / A_A,
 *
 * with the Monte Carlo standard error combined over the (independent) pairs,
 * sqrt(sum (A_i / A_A)^2 se_ij^2).  Both surfaces are meshed by
 * rp_mesh_create: by default with a longest element edge equal to the
 * longest edge of any face, i.e. one element per face (the analytic
 * method's contour integral is exact over the source and its outer
 * quadrature adaptive, so no subdivision is needed for accuracy). */
#include <errno.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/radiosity/formfactor.h"
#include "bench/cli/cli.h"
#include "bench/cli/commands.h"

static int ff_usage(const char *fmt, const char *a)
{
    fprintf(stderr, "radpt formfactor: ");
    fprintf(stderr, fmt, a);
    fprintf(stderr, " (see radpt help)\n");
    return 2;
}

static int ff_parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out)
{
    char *end;
    errno = 0;
    if (!s || *s == '-' || *s == '\0')
        return -1;
    unsigned long long v = strtoull(s, &end, 10);
    if (*end || errno || v < lo || v > hi)
        return -1;
    *out = v;
    return 0;
}

static int ff_parse_double(const char *s, double lo, double hi, double *out)
{
    char *end;
    errno = 0;
    if (!s || *s == '\0')
        return -1;
    double v = strtod(s, &end);
    if (*end || errno || !isfinite(v) || !(v > lo) || v > hi)
        return -1;
    *out = v;
    return 0;
}

/* Lists the scene's surface names after an unknown one. */
static int ff_unknown_surface(const rp_scene *scene, const char *opt, const char *name)
{
    char nm[512];
    fprintf(stderr, "radpt formfactor: %s: no surface named '%s'; the scene has:", opt, name);
    const rp_surface *s = rp_scene_surfaces(scene);
    for (size_t k = 0; k < rp_scene_nsurfaces(scene); k++)
        fprintf(stderr, " %s", rp_cli_name(s[k].name, nm, sizeof nm));
    fprintf(stderr, "\n");
    return 2;
}

int rp_cmd_formfactor(int argc, char **argv)
{
    const char *scene_path = NULL, *from = NULL, *to = NULL, *method_name = "analytic", *camera = NULL;
    uint64_t samples = 0, resolution = 0, rays_opt = 0, elements = 0, seed = 1, threads = 0;
    double max_edge = 0, tolerance = 0;
    int json = 0, have_samples = 0, have_resolution = 0, have_rays = 0, have_tol = 0;

    for (int a = 2; a < argc; a++) {
        const char *arg = argv[a];
        if (arg[0] != '-' || arg[1] == '\0') {
            if (scene_path)
                return ff_usage("unexpected argument '%s'", arg);
            scene_path = arg;
            continue;
        }
        if (strcmp(arg, "--json") == 0) {
            json = 1;
            continue;
        }
        /* Every other option takes a value: --name value or --name=value. */
        char name[32];
        const char *eq = strchr(arg, '=');
        size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        if (strncmp(arg, "--", 2) != 0 || len >= sizeof name)
            return ff_usage("unknown option '%s'", arg);
        memcpy(name, arg, len);
        name[len] = '\0';
        const char *val = eq ? eq + 1 : NULL;
        if (!val) {
            if (a + 1 >= argc)
                return ff_usage("%s needs a value", name);
            val = argv[++a];
        }
        if (strcmp(name, "--from") == 0) {
            from = val;
        } else if (strcmp(name, "--to") == 0) {
            to = val;
        } else if (strcmp(name, "--method") == 0) {
            method_name = val;
        } else if (strcmp(name, "--camera") == 0) {
            camera = val;
        } else if (strcmp(name, "--samples") == 0) {
            if (ff_parse_u64(val, 1, 1000000000, &samples))
                return ff_usage("--samples: '%s' is not an integer in [1, 1e9]", val);
            have_samples = 1;
        } else if (strcmp(name, "--resolution") == 0) {
            if (ff_parse_u64(val, 2, 16384, &resolution) || resolution % 2)
                return ff_usage("--resolution: '%s' is not an even integer in [2, 16384]", val);
            have_resolution = 1;
        } else if (strcmp(name, "--rays") == 0) {
            if (ff_parse_u64(val, 1, 4096, &rays_opt))
                return ff_usage("--rays: '%s' is not an integer in [1, 4096]", val);
            have_rays = 1;
        } else if (strcmp(name, "--tolerance") == 0) {
            if (ff_parse_double(val, 0, 0.1, &tolerance) || tolerance < 1e-14)
                return ff_usage("--tolerance: '%s' is not a number in [1e-14, 0.1]", val);
            have_tol = 1;
        } else if (strcmp(name, "--elements") == 0) {
            if (ff_parse_u64(val, 1, UINT32_MAX / 4, &elements))
                return ff_usage("--elements: '%s' is not a positive element count", val);
        } else if (strcmp(name, "--max-edge") == 0) {
            if (ff_parse_double(val, 0, INFINITY, &max_edge))
                return ff_usage("--max-edge: '%s' is not a positive length", val);
        } else if (strcmp(name, "--seed") == 0) {
            if (ff_parse_u64(val, 0, UINT64_MAX, &seed))
                return ff_usage("--seed: '%s' is not a non-negative integer", val);
        } else if (strcmp(name, "--threads") == 0) {
            if (ff_parse_u64(val, 1, 1024, &threads))
                return ff_usage("--threads: '%s' is not a thread count in [1, 1024]", val);
        } else {
            return ff_usage("unknown option '%s'", name);
        }
    }
    if (!scene_path)
        return ff_usage("needs a scene file%s", "");
    if (!from || !to)
        return ff_usage("needs --from SURFACE and --to SURFACE%s", "");
    if (elements && max_edge > 0)
        return ff_usage("give --elements or --max-edge, not both%s", "");

    rp_error err = {""};
    rp_ff_params fp = {.size = sizeof fp, .seed = seed};
    rp_status st = rp_ff_method_parse(method_name, &fp.method, &err);
    if (st != RP_OK)
        return ff_usage("%s", err.message);
    if (have_samples && fp.method != RP_FF_MONTECARLO)
        return ff_usage("--samples applies to --method montecarlo%s", "");
    if (have_resolution && fp.method != RP_FF_HEMICUBE)
        return ff_usage("--resolution applies to --method hemicube%s", "");
    if ((have_rays || have_tol) && fp.method != RP_FF_ANALYTIC)
        return ff_usage("--rays and --tolerance apply to --method analytic%s", "");
    fp.samples = (unsigned)samples;
    fp.resolution = (unsigned)resolution;
    fp.visibility_rays = (unsigned)rays_opt;
    fp.tolerance = tolerance;

    rp_scene *scene = NULL;
    if ((st = rp_load_scene(scene_path, camera, 0, &scene, &err)) != RP_OK)
        return rp_cli_fail(st, &err);
    uint32_t sa = rp_scene_find_surface(scene, from), sb = rp_scene_find_surface(scene, to);
    if (sa == RP_NONE || sb == RP_NONE) {
        int rc = ff_unknown_surface(scene, sa == RP_NONE ? "--from" : "--to", sa == RP_NONE ? from : to);
        rp_scene_destroy(scene);
        return rc;
    }

    rp_mesh_params mp = {.size = sizeof mp};
    if (elements)
        mp.target_count = (size_t)elements;
    else if (max_edge > 0)
        mp.max_edge = max_edge;
    else {
        /* One element per face: no face has a longer edge. */
        const rp_face *fcs = rp_scene_faces(scene);
        const rp_vec3 *vs = rp_scene_vertices(scene);
        for (size_t f = 0; f < rp_scene_nfaces(scene); f++)
            for (uint32_t k = 0; k < fcs[f].nverts; k++)
                mp.max_edge = fmax(mp.max_edge, rp_v3_length(rp_v3_sub(vs[fcs[f].v[(k + 1) % fcs[f].nverts]],
                                                                        vs[fcs[f].v[k]])));
    }
    rp_mesh *mesh = NULL;
    rp_raycast *rc = NULL;
    rp_ff_context *ctx = NULL;
    int status = 0;
    double *contrib = NULL, *var = NULL;
    if ((st = rp_mesh_create(scene, &mp, &mesh, &err)) != RP_OK ||
        (st = rp_raycast_create(scene, mesh, &rc, &err)) != RP_OK ||
        (st = rp_ff_context_create(scene, mesh, rc, &fp, &ctx, &err)) != RP_OK) {
        status = rp_cli_fail(st, &err);
        goto done;
    }

    uint32_t a0, na, b0, nb;
    rp_mesh_surface_elements(mesh, sa, &a0, &na);
    rp_mesh_surface_elements(mesh, sb, &b0, &nb);
    const rp_element *E = rp_mesh_elements(mesh);
    contrib = calloc(na ? na : 1, sizeof *contrib);
    var = calloc(na ? na : 1, sizeof *var);
    if (!contrib || !var) {
        status = rp_cli_fail(rp_error_set(&err, RP_ERR_NOMEM, "formfactor: out of memory"), &err);
        goto done;
    }
    int nthreads = threads ? (int)threads : omp_get_max_threads();
    double rays = 0, t0 = rp_clock();
    int failed = 0;
    /* Per receiver element, summed in index order afterwards, so the answer
     * does not depend on the thread count. */
#pragma omp parallel num_threads(nthreads) reduction(+ : rays) reduction(| : failed)
    {
        rp_ff_scratch *scratch = NULL;
        rp_error terr;
        if (rp_ff_scratch_create(ctx, &scratch, &terr) != RP_OK)
            failed = 1;
#pragma omp for schedule(dynamic, 1)
        for (long t = 0; t < (long)na; t++) {
            if (!scratch)
                continue;
            uint32_t i = a0 + (uint32_t)t;
            double sum = 0, v = 0;
            for (uint32_t j = b0; j < b0 + nb; j++) {
                double se = 0;
                sum += rp_ff_pair(ctx, scratch, i, j, &se, &rays);
                v += se * se;
            }
            contrib[t] = E[i].area * sum;
            var[t] = E[i].area * E[i].area * v;
        }
        rp_ff_scratch_destroy(scratch);
    }
    double seconds = rp_clock() - t0;
    rp_ff_params used;
    rp_ff_context_params(ctx, &used);
    if (failed) {
        status = rp_cli_fail(rp_error_set(&err, RP_ERR_NOMEM, "formfactor: out of memory"), &err);
        goto done;
    }
    double area = 0, F = 0, V = 0;
    for (uint32_t t = 0; t < na; t++) {
        area += E[a0 + t].area;
        F += contrib[t];
        V += var[t];
    }
    F /= area;
    double se = sqrt(V) / area;

    if (json) {
        printf("{\"scene\": ");
        rp_json_string(stdout, scene_path);
        printf(", \"from\": ");
        rp_json_string(stdout, from);
        printf(", \"to\": ");
        rp_json_string(stdout, to);
        printf(", \"method\": \"%s\", \"form_factor\": %.12g", rp_ff_method_name(fp.method), F);
        if (fp.method == RP_FF_MONTECARLO)
            printf(", \"stderr\": %.6g, \"samples\": %u", se, used.samples);
        else if (fp.method == RP_FF_HEMICUBE)
            printf(", \"resolution\": %u", used.resolution);
        else
            printf(", \"tolerance\": %.3g", used.tolerance);
        printf(", \"elements_from\": %u, \"elements_to\": %u, \"elements\": %zu, \"area_from\": %.12g"
               ", \"rays\": %.0f, \"seconds\": %.6f, \"seed\": %llu, \"threads\": %d}\n",
               na, nb, rp_mesh_nelements(mesh), area, rays, seconds, (unsigned long long)seed, nthreads);
    } else {
        printf("F(%s -> %s) = %.10f", from, to, F);
        if (fp.method == RP_FF_MONTECARLO)
            printf(" +- %.2g (standard error, %u point pairs per element pair)", se, used.samples);
        printf("\n");
        printf("method    %s", rp_ff_method_name(fp.method));
        if (fp.method == RP_FF_HEMICUBE)
            printf(", resolution %u", used.resolution);
        else if (fp.method == RP_FF_ANALYTIC)
            printf(", tolerance %g", used.tolerance);
        printf("\nelements  %u from, %u to (%zu in the scene)\n", na, nb, rp_mesh_nelements(mesh));
        printf("rays      %.0f\ntime      %.3f s on %d thread%s\n", rays, seconds, nthreads,
               nthreads == 1 ? "" : "s");
    }

done:
    free(contrib);
    free(var);
    rp_ff_context_destroy(ctx);
    rp_raycast_destroy(rc);
    rp_mesh_destroy(mesh);
    rp_scene_destroy(scene);
    return status;
}
