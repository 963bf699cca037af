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
    rp_exp_start x;
    rp_status st = rp_exp_begin(p, "cornell.scene", &x, err);
    if (st != RP_OK)
        return st;
    char preface[1600];
    snprintf(preface, sizeof preface,
             "Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988) on the Cornell box, "
             "checkpoints every doubling of the number of shots up to %g: %s. `ambient` shows the ambient term "
             "(unshot power spread uniformly, sec. 4 of the paper), `overshoot` shoots more than the unshot "
             "radiosity. The ambient term makes early images close to the answer in the mean; overshooting "
             "speeds the convergence of the residual. The chart against samples is the error per shot "
             "(samples = shots here).",
             x.set.budget, x.methods);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment progressive: error per shot",
                           .preface = preface, .samples_chart = 1, .samples_label = "shots",
                           .sheet = 1, .command = p->command};
    st = rp_exp_run_bench_scheduled(p, x.scene, x.path, x.set.methods, RP_SCHEDULE_ITERATIONS, x.set.budget, 10, 1,
                                    x.set.reference_spp, &out, p->out_dir, NULL, NULL, err);
    rp_scene_destroy(x.scene);
    return st;
}
