/* radpt experiment cornell: every method at equal time on the Cornell box. */
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

/* -------------------------------------------------------------- cornell */

rp_status rp_exp_cornell(const rp_experiment_params *p, rp_error *err)
{
    rp_exp_start x;
    rp_status st = rp_exp_begin(p, "cornell.scene", &x, err);
    if (st != RP_OK)
        return st;
    char preface[2400];
    snprintf(preface, sizeof preface,
             "Every method on the Cornell box at equal time (%g s per run, %u seeds per Monte Carlo method): "
             "%s. The path tracer is Monte Carlo path tracing with next-event estimation, MIS and Russian "
             "roulette; with independent random numbers (`sampler=random`) its error falls as N^-1/2 (slope "
             "-0.5), with its default Owen-scrambled Sobol' points somewhat faster where the integrand is smooth "
             "(see `radpt experiment samplers`). Southwell is progressive refinement, hierarchical is Hanrahan, "
             "Salzman & Aupperle 1991 (Gouraud images from vertex values gathered through its links), "
             "stochastic-jacobi is Monte Carlo radiosity. A radiosity curve flattens at its mesh's "
             "discretisation error, lower for a finer mesh.",
             x.set.budget, x.set.seeds, x.methods);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment cornell: all methods at equal time",
                           .preface = preface, .sheet = 1, .command = p->command};
    st = rp_exp_run_bench(p, x.scene, x.path, x.set.methods, x.set.budget, x.set.seeds, x.set.reference_spp, &out, p->out_dir,
                          NULL, NULL, err);
    rp_scene_destroy(x.scene);
    return st;
}
