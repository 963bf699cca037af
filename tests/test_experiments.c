/* Every experiment's quick form runs, and its claim (its declaration in
 * bench/experiments/experiments.c) holds in the numbers it wrote, checked
 * here against closed forms and fits the test computes itself.  (stability
 * and realscenes have their own files: test_stability.c and
 * test_realscenes.c.)  The Cornell-box experiments run in one test, and
 * every test here reads its path-traced references from the cache shared
 * by the test builds (rp_test_ref_cache). */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/experiments/experiments.h"
#include "cli_util.h"
#include "closed_form.h"
#include "bench/report/image.h"

static void nolog(void *ctx, const char *m)
{
    (void)ctx;
    (void)m;
}

/* The quick form of experiment name, with its runs cut to budget seconds
 * each where budget > 0 (`--budget`; the runs that stop by time are the
 * tests' fixed cost, paid once plain and once under the sanitizers). */
static void run_quick_budget(const char *name, const char *root, const char *cache, double budget)
{
    const rp_experiment *e = rp_experiment_lookup(name);
    cr_assert_not_null(e, "%s", name);
    char out[256];
    snprintf(out, sizeof out, "%s/%s", root, name);
    rp_experiment_params p = {.size = sizeof p, .experiment = e, .quick = 1, .out_dir = out, .cache_dir = cache,
                              .scenes_dir = RP_SOURCE_DIR "/scenes", .threads = 2, .log = nolog, .budget = budget};
    rp_error err;
    rp_error_clear(&err);
    cr_assert_eq(e->run(&p, &err), RP_OK, "%s: %s", name, err.message);
}

static void run_quick(const char *name, const char *root, const char *cache) { run_quick_budget(name, root, cache, 0); }

static char *read_out(const char *root, const char *name, const char *file)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s/%s", root, name, file);
    char *text = rp_read_file(path);
    cr_assert_not_null(text, "%s missing", path);
    return text;
}

/* Field k (0-based) of a CSV line as a number. */
static double field(const char *line, int k)
{
    const char *f = line;
    for (int i = 0; i < k && f; i++)
        f = strchr(f, ',') ? strchr(f, ',') + 1 : NULL;
    return f && *f != ',' && *f != '\n' ? strtod(f, NULL) : NAN;
}

/* The rmse (field 18) of runs.csv's row for spec, seed 1, checkpoint k. */
static double rmse_at(const char *csv, const char *spec, int k)
{
    char key[256];
    snprintf(key, sizeof key, ",%s,1,%d,", spec, k);
    const char *hit = strstr(csv, key);
    if (!hit)
        return NAN;
    while (hit > csv && hit[-1] != '\n')
        hit--;
    return field(hit, 18);
}

/* The rmse of the first and of the final row of spec's seed-1 run. */
static void rmse_first_last(const char *csv, const char *spec, double *first, double *last)
{
    char key[256];
    snprintf(key, sizeof key, ",%s,1,", spec);
    *first = *last = NAN;
    for (const char *hit = strstr(csv, key); hit; hit = strstr(hit + 1, key)) {
        const char *line = hit;
        while (line > csv && line[-1] != '\n')
            line--;
        double r = field(line, 18);
        if (isnan(*first))
            *first = r;
        *last = r;
    }
}

/* A number of summary.json's entry for spec: the first "key" after
 * "within" (e.g. "slope_samples", "final") inside it. */
static double summary_number(const char *json, const char *spec, const char *within, const char *key)
{
    char anchor[256];
    snprintf(anchor, sizeof anchor, "{\"spec\": \"%s\"", spec);
    const char *p = strstr(json, anchor);
    cr_assert_not_null(p, "%s not in summary.json", spec);
    p = strstr(p, within);
    cr_assert_not_null(p);
    return rp_json_number_after(p, within, key);
}

/* The experiment's reference resolves every method's error (issue 15:
 * no built-in experiment warns about its own reference): no run is
 * flagged in summary.json and the report carries no warning. */
static void reference_resolves_all(const char *root, const char *name)
{
    char *json = read_out(root, name, "summary.json"), *md = read_out(root, name, "report.md");
    cr_expect(strstr(json, "\"ref_flag\": false") != NULL, "%s: summary.json has no ref_flag", name);
    cr_expect(strstr(json, "\"ref_flag\": true") == NULL, "%s: a run's error is not resolved by the reference",
              name);
    cr_expect(strstr(md, "**Warning:** the reference does not resolve") == NULL, "%s: report.md warns about its reference",
              name);
    free(json);
    free(md);
}

/* Least-squares slope of log y against log x. */
static double loglog_slope(const double *x, const double *y, size_t n)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (size_t i = 0; i < n; i++) {
        double a = log(x[i]), b = log(y[i]);
        sx += a;
        sy += b;
        sxx += a * a;
        sxy += a * b;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

Test(experiments, cornell_box_quick_forms_hold_their_claims, .timeout = 900)
{
    char root[64], cache[512];
    snprintf(root, sizeof root, "/tmp/rp_exp_XXXXXX");
    cr_assert_not_null(mkdtemp(root));
    cr_assert_not_null(rp_test_ref_cache());
    snprintf(cache, sizeof cache, "%s", rp_test_ref_cache());

    /* cornell: plain Monte Carlo falls as N^-1/2 against samples, and every
     * Monte Carlo run's error falls from its first checkpoint to its last */
    run_quick_budget("cornell", root, cache, 0.5);
    reference_resolves_all(root, "cornell");
    char *json = read_out(root, "cornell", "summary.json"), *csv = read_out(root, "cornell", "runs.csv");
    double slope = summary_number(json, "pathtrace:sampler=random", "\"slope_samples\"", "slope");
    cr_expect(slope > -0.75 && slope < -0.3, "random sampling's RMSE slope against samples %g, not near -1/2", slope);
    for (int k = 0; k < 2; k++) {
        const char *spec = k ? "pathtrace" : "pathtrace:sampler=random";
        double first, last;
        rmse_first_last(csv, spec, &first, &last);
        cr_expect(last < first, "%s: RMSE %g at the first checkpoint, %g at the last", spec, first, last);
    }
    free(json);
    free(csv);

    /* samplers: at equal samples Sobol' and stratified end below random.
     * Runs stop by time, so their sample counts differ a little: each
     * final RMSE is brought to one sample count by the N^-1/2 of plain
     * Monte Carlo (which favours random, the slowest to converge). */
    run_quick_budget("samplers", root, cache, 0.5);
    reference_resolves_all(root, "samplers");
    json = read_out(root, "samplers", "summary.json");
    double rnd = summary_number(json, "pathtrace:sampler=random", "\"final\"", "rmse") *
                 sqrt(summary_number(json, "pathtrace:sampler=random", "\"final\"", "samples"));
    double sob = summary_number(json, "pathtrace:sampler=sobol", "\"final\"", "rmse") *
                 sqrt(summary_number(json, "pathtrace:sampler=sobol", "\"final\"", "samples"));
    double str = summary_number(json, "pathtrace:sampler=stratified", "\"final\"", "rmse") *
                 sqrt(summary_number(json, "pathtrace:sampler=stratified", "\"final\"", "samples"));
    cr_expect(sob < rnd, "RMSE x sqrt(spp): Sobol' %g, random %g", sob, rnd);
    cr_expect(str < rnd, "RMSE x sqrt(spp): stratified %g, random %g", str, rnd);
    free(json);

    /* progressive: after the first shots the ambient term's image is closer
     * to the answer than plain shooting's */
    run_quick("progressive", root, cache);
    reference_resolves_all(root, "progressive");
    csv = read_out(root, "progressive", "runs.csv");
    double plain = rmse_at(csv, "southwell:elements=150", 9), amb = rmse_at(csv, "southwell:elements=150:ambient", 9);
    cr_expect(amb < plain, "first checkpoint: ambient %g, plain %g", amb, plain);
    free(csv);

    /* hierarchy: links grow about linearly with leaves (exponent well
     * below the 2 of a full matrix) */
    run_quick_budget("hierarchy", root, cache, 1.0);
    reference_resolves_all(root, "hierarchy");
    csv = read_out(root, "hierarchy", "links.csv");
    double leaves[8], links[8];
    size_t n = 0;
    for (const char *line = strchr(csv, '\n'); line && line[1] && n < 8; line = strchr(line + 1, '\n')) {
        leaves[n] = field(line + 1, 2);
        links[n] = field(line + 1, 3);
        n++;
    }
    cr_assert_geq(n, 3);
    double exponent = loglog_slope(leaves, links, n);
    cr_expect(exponent > 0.5 && exponent < 1.5, "links ~ leaves^%g", exponent);
    free(csv);

    /* meshing: the error falls as elements shrink (a positive observed
     * order in h) */
    run_quick("meshing", root, cache);
    csv = read_out(root, "meshing", "meshing.csv");
    double h[8], err[8];
    n = 0;
    for (const char *line = strchr(csv, '\n'); line && line[1] && n < 8; line = strchr(line + 1, '\n')) {
        h[n] = field(line + 1, 2);
        err[n] = field(line + 1, 5);
        n++;
    }
    cr_assert_geq(n, 3);
    double order = loglog_slope(h, err, n);
    cr_expect(order > 0.2 && order < 3, "surface error ~ h^%g", order);
    free(csv);

    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
    cr_expect_eq(system(cmd), 0);
}

Test(experiments, furnace_and_formfactors_quick_forms_hold_their_claims, .timeout = 600)
{
    char root[64], cache[512];
    snprintf(root, sizeof root, "/tmp/rp_exp_XXXXXX");
    cr_assert_not_null(mkdtemp(root));
    cr_assert_not_null(rp_test_ref_cache());
    snprintf(cache, sizeof cache, "%s", rp_test_ref_cache());

    /* furnace: every iterative method reaches L = Le / (1 - rho) within the
     * quick tolerance 1e-2; Jacobi needs about ln(tol) / ln(rho) - 1 sweeps
     * (its error after k sweeps is rho^(k+1)), Gauss-Seidel no more */
    run_quick("furnace", root, cache);
    char *csv = read_out(root, "furnace", "furnace.csv");
    size_t rows = 0;
    double jacobi_sweeps[3] = {NAN, NAN, NAN}, gs_sweeps[3] = {NAN, NAN, NAN};
    const double rhos[3] = {0.3, 0.7, 0.9};
    for (const char *line = strchr(csv, '\n'); line && line[1]; line = strchr(line + 1, '\n')) {
        const char *l = line + 1;
        double rho = field(l, 0);
        int k = -1;
        for (int i = 0; i < 3; i++)
            if (fabs(rho - rhos[i]) < 1e-9)
                k = i;
        cr_assert_geq(k, 0, "rho %g", rho);
        int iterative = !strncmp(strchr(l, ',') + 1, "jacobi", 6) || !strncmp(strchr(l, ',') + 1, "gauss", 5) ||
                        !strncmp(strchr(l, ',') + 1, "southwell", 9);
        if (iterative) {
            cr_expect_eq(field(l, 2), 1, "not reached: %.80s", l);
            cr_expect(field(l, 7) <= 1e-2, "error %g: %.80s", field(l, 7), l);
        }
        if (!strncmp(strchr(l, ',') + 1, "jacobi", 6))
            jacobi_sweeps[k] = field(l, 5);
        if (!strncmp(strchr(l, ',') + 1, "gauss", 5))
            gs_sweeps[k] = field(l, 5);
        rows++;
    }
    cr_expect_eq(rows, 3 * 4, "three reflectances, four methods");
    for (int k = 0; k < 3; k++) {
        double theory = log(1e-2) / log(rhos[k]) - 1;
        cr_expect(jacobi_sweeps[k] <= ceil(theory) + 1, "rho %g: Jacobi %g sweeps, theory %g", rhos[k],
                  jacobi_sweeps[k], theory);
        cr_expect(gs_sweeps[k] <= jacobi_sweeps[k], "rho %g: Gauss-Seidel %g sweeps, Jacobi %g", rhos[k],
                  gs_sweeps[k], jacobi_sweeps[k]);
    }
    free(csv);

    /* formfactors: the analytic form factor of the parallel pair equals
     * Howell's C-11 (tests/closed_form.c, apart from the experiment's) */
    run_quick("formfactors", root, cache);
    csv = read_out(root, "formfactors", "formfactors.csv");
    size_t checked = 0;
    for (const char *line = strchr(csv, '\n'); line && line[1]; line = strchr(line + 1, '\n')) {
        const char *l = line + 1;
        char method[32] = "";
        if (strncmp(l, "cost,parallel,", 14) != 0 || sscanf(l, "cost,parallel,%*[^,],%31[^,]", method) != 1 ||
            strcmp(method, "analytic") != 0)
            continue;
        double c = field(l, 2), F = field(l, 7);
        double ref = rp_cf_howell_parallel(1, 1, c);
        cr_expect(fabs(F - ref) <= 1e-5 * ref, "c %g: analytic %.10g, Howell %.10g", c, F, ref);
        checked++;
    }
    cr_expect_gt(checked, 0);
    free(csv);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
    cr_expect_eq(system(cmd), 0);
}

/* discontinuity: at each element count asked, Gauss-Seidel's surface error
 * on the discontinuity mesh is below the uniform mesh's on both scenes
 * (against each scene's path-traced reference), hierarchical radiosity's
 * four variants converge close to that reference, and the mesh overlays are
 * images of the camera's size with element boundaries drawn in yellow. */
Test(experiments, discontinuity_quick_form_holds_its_claim, .timeout = 900)
{
    char root[64], cache[512];
    snprintf(root, sizeof root, "/tmp/rp_exp_XXXXXX");
    cr_assert_not_null(mkdtemp(root));
    cr_assert_not_null(rp_test_ref_cache());
    snprintf(cache, sizeof cache, "%s", rp_test_ref_cache());
    run_quick("discontinuity", root, cache);
    char *csv = read_out(root, "discontinuity", "discontinuity.csv");
    static const char *const scenes[2] = {"cornell", "original"};
    static const char *const targets[2] = {"250", "1000"};
    for (int s = 0; s < 2; s++)
        for (int c = 0; c < 2; c++) {
            double err[2] = {NAN, NAN};
            for (int m = 0; m < 2; m++) {
                char key[96];
                snprintf(key, sizeof key, "\n%s,%s,%s,", scenes[s], m ? "discontinuity" : "uniform", targets[c]);
                const char *hit = strstr(csv, key);
                cr_assert_not_null(hit, "%s missing", key + 1);
                err[m] = field(hit + 1, 6);
            }
            cr_expect(err[1] < err[0], "%s at %s elements: discontinuity %g, uniform %g", scenes[s], targets[c], err[1],
                      err[0]);
        }
    /* hierarchical radiosity, run to convergence at the quick form's coarse
     * setting: every variant's RMS surface error within 3% of the
     * path-traced reference, the bound tests/test_realscenes.c puts on
     * published scenes (measured 0.45 to 1.8%; solves cut off by a 2 s
     * budget, as the quick form ran them before, read 17 to 50%) */
    static const char *const hr[4] = {"hierarchical", "hierarchical-discontinuity", "hierarchical-linear",
                                      "hierarchical-discontinuity-linear"};
    for (int s = 0; s < 2; s++)
        for (int h = 0; h < 4; h++) {
            char key[96];
            snprintf(key, sizeof key, "\n%s,%s,", scenes[s], hr[h]);
            const char *hit = strstr(csv, key);
            cr_assert_not_null(hit, "%s missing", key + 1);
            double e = field(hit + 1, 6), converged = field(hit + 1, 8);
            cr_expect(e < 0.03, "%s %s: surface error %g", scenes[s], hr[h], e);
            cr_expect_eq(converged, 1, "%s %s did not converge", scenes[s], hr[h]);
        }
    free(csv);
    for (int s = 0; s < 2; s++)
        for (int m = 0; m < 2; m++) {
            char path[256];
            snprintf(path, sizeof path, "%s/discontinuity/mesh-%s-%s.png", root, scenes[s],
                     m ? "discontinuity" : "uniform");
            uint32_t w, h;
            size_t ch;
            uint16_t *px = NULL;
            rp_error e;
            cr_assert_eq(rp_image_read_png(path, &w, &h, &ch, &px, &e), RP_OK, "%s", e.message);
            cr_expect(w == 256 && h == 256 && ch == 3, "%s: %u x %u x %zu", path, w, h, ch);
            size_t yellow = 0;
            for (size_t i = 0; i < (size_t)w * h; i++)
                yellow += px[i * ch] == 255 && px[i * ch + 1] == 255 && px[i * ch + 2] == 0;
            /* at 1000 elements the boundaries cover a few percent of the
             * image at least */
            cr_expect(yellow > (size_t)w * h / 50, "%s: %zu yellow pixels", path, yellow);
            free(px);
        }
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
    cr_expect_eq(system(cmd), 0);
}

/* The row of methods.csv for scene and method label. */
static const char *ms_row(const char *csv, const char *scene, const char *label)
{
    char key[128];
    snprintf(key, sizeof key, "\n%s,%s,", scene, label);
    const char *hit = strstr(csv, key);
    cr_assert_not_null(hit, "methods.csv: no row %s", key + 1);
    return hit + 1;
}

/* modelsize: on a simplified solution mesh (--simplify auto) hierarchical
 * radiosity solves on fewer faces with less memory (far fewer on the dense
 * bunny), and its surface
 * averages stay as close to the path-traced reference as the full mesh's
 * (within half a percentage point); the bunny's within 2.5% at the quick
 * form's fast setting.  That is a regression check of one run (seed 1),
 * bounded by the spread over seeds: at that setting the bunny's worst
 * band reads +0.31 to +2.45% against a 2M-sample path tracer over seeds 1
 * to 7 at stop 28, +0.37 to +1.61% at stop 31 before the cluster links
 * kept their bound in 16 bits and +0.70 to +1.64% after (docs/design.md);
 * the 1% this asked before was met by 3 or 4 seeds of 7.  Growth:
 * four times the faces (the same surface, subdivided) costs the
 * simplified solve under 1.5 times the memory. */
Test(experiments, modelsize_quick_form_holds_its_claim, .timeout = 900)
{
    char root[64], cache[512];
    snprintf(root, sizeof root, "/tmp/rp_exp_XXXXXX");
    cr_assert_not_null(mkdtemp(root));
    cr_assert_not_null(rp_test_ref_cache());
    snprintf(cache, sizeof cache, "%s", rp_test_ref_cache());
    run_quick("modelsize", root, cache);
    char *csv = read_out(root, "modelsize", "methods.csv");
    /* columns: scene,method,seconds,memory_mib,faces,leaves,links,cluster_links,max_surface_err,worst */
    const char *full = ms_row(csv, "elephant", "hierarchical:simplify=off");
    const char *simp = ms_row(csv, "elephant", "hierarchical:simplify=auto");
    const char *bunny = ms_row(csv, "bunny", "hierarchical:simplify=auto");
    /* The elephant is a coarse mesh for its size: since stop 37 auto, which
     * bounds the error integrated over the merged area, keeps 4,644 of its
     * 5,590 faces (3,024 before, when a fixed bound on the quadric sum let
     * coarse meshes go further); the bunny below carries "far fewer". */
    cr_expect(field(simp, 4) < 0.9 * field(full, 4), "faces %g against %g", field(simp, 4), field(full, 4));
    cr_expect(field(simp, 3) < field(full, 3), "memory %g against %g MiB", field(simp, 3), field(full, 3));
    cr_expect(field(simp, 8) < field(full, 8) + 0.005, "error %g against %g", field(simp, 8), field(full, 8));
    cr_expect(field(bunny, 4) < 0.15 * 75415, "bunny solved on %g faces", field(bunny, 4));
    cr_expect(field(bunny, 8) < 0.025, "bunny: largest surface error %g", field(bunny, 8));
    free(csv);
    char *grow = read_out(root, "modelsize", "growth.csv");
    /* faces,hr_seconds,hr_memory_mib,hr_faces_solved,hr_links,hr_max_surface_err,pt_seconds,... */
    const char *pub = strstr(grow, "\n5558,"), *sub = strstr(grow, "\n22232,");
    cr_assert(pub && sub, "%s", grow);
    cr_expect(field(sub + 1, 2) < 1.5 * field(pub + 1, 2), "memory %g MiB at 22232 faces, %g at 5558",
              field(sub + 1, 2), field(pub + 1, 2));
    cr_expect(field(sub + 1, 5) < 0.03, "error at 22232 faces %g", field(sub + 1, 5));
    free(grow);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
    cr_expect_eq(system(cmd), 0);
}
