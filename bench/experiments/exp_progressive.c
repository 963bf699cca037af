/* radpt experiment progressive: progressive refinement, ambient term, overshooting. */
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

/* ---------------------------------------------------------- progressive */

rp_status rp_exp_progressive(const rp_experiment_params *p, rp_error *err)
{
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    unsigned elements = p->quick ? 150 : 500;
    double shots = p->budget > 0 ? p->budget : (p->quick ? 300 : 4000);
    char list[512];
    snprintf(list, sizeof list,
             "southwell:elements=%u,southwell:elements=%u:ambient,southwell:elements=%u:overshoot=1.5,"
             "southwell:elements=%u:ambient:overshoot=1.5",
             elements, elements, elements, elements);
    char preface[1200];
    snprintf(preface, sizeof preface,
             "Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988) on the Cornell box with "
             "%u elements, checkpoints every doubling of the number of shots up to %g: classic shooting, with "
             "the ambient term shown (unshot power spread uniformly, sec. 4 of the paper), with overshooting "
             "(1.5 x the unshot radiosity), and both. The ambient term makes early images close to the answer "
             "in the mean; overshooting speeds the convergence of the residual. The chart against samples is "
             "the error per shot (samples = shots here).",
             elements, shots);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment progressive: error per shot",
                           .preface = preface, .samples_chart = 1, .samples_label = "shots",
                           .sheet = 1, .command = p->command};
    st = rp_exp_run_bench_scheduled(p, scene, path, list, RP_SCHEDULE_ITERATIONS, shots, 10, 1, REF_SPP(p), &out,
                             p->out_dir, NULL, NULL, err);
    rp_scene_destroy(scene);
    return st;
}

