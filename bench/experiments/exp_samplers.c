/* radpt experiment samplers: the path tracer's random, stratified and Sobol' samplers. */
#include "bench/experiments/exp_internal.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "geometry/mesh.h"
#include "geometry/raycast.h"
#include "geometry/scene.h"
#include "solvers/radiosity/formfactor.h"
#include "solvers/radiosity/hierarchical.h"
#include "bench/run/metrics.h"
#include "bench/report/files.h"
#include "bench/run/clock.h"
#include "bench/run/harness.h"
#include "bench/report/plot.h"
#include "bench/experiments/exp_internal.h"

/* ------------------------------------------------------------- samplers */

rp_status rp_exp_samplers(const rp_experiment_params *p, rp_error *err)
{
    rp_exp_start x;
    rp_status st = rp_exp_begin(p, "cornell.scene", &x, err);
    if (st != RP_OK)
        return st;
    char preface[1200];
    snprintf(preface, sizeof preface,
             "The path tracer's three samplers on the Cornell box, %g s per run, %u seeds: independent "
             "uniform numbers (random), a jittered grid per pair of dimensions (stratified) and Owen-scrambled "
             "Sobol' points. Plain Monte Carlo error falls as N^-1/2 (slope -0.5 against samples); "
             "stratification and scrambled Sobol' do better where the integrand is smooth (docs/ground-truth.md: "
             "about N^-0.75 where visibility edges cross a pixel), less so for the many-dimensional indirect "
             "light. Slopes are fitted against samples per pixel (all rows of all seeds).",
             x.set.budget, x.set.seeds);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment samplers: random, stratified and Sobol'",
                           .preface = preface, .samples_chart = 1, .sheet = 1, .command = p->command};
    st = rp_exp_run_bench(p, x.scene, x.path, x.set.methods, x.set.budget, x.set.seeds, x.set.reference_spp, &out, p->out_dir,
                          NULL, NULL, err);
    rp_scene_destroy(x.scene);
    return st;
}
