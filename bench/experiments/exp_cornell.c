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
    char path[1024];
    rp_status st = rp_experiment_scene_path(p, "cornell.scene", path, sizeof path, err);
    if (st != RP_OK)
        return st;
    rp_scene *scene = NULL;
    if ((st = rp_scene_load(path, &scene, err)) != RP_OK)
        return st;
    double budget = p->budget > 0 ? p->budget : (p->quick ? 1.0 : 6.0);
    unsigned seeds = p->nseeds ? p->nseeds : (p->quick ? 2 : 3);
    /* the reference needs about 9 x the path tracer's samples for its
     * standard error to stay below a third of the error measured */
    unsigned long ref_spp = REF_SPP(p);
    const char *list = p->quick ? "pathtrace:sampler=random,pathtrace,southwell:elements=150,southwell:elements=600,"
                                  "hierarchical:bf-epsilon=0.05:min-area=1e-4,stochastic-jacobi"
                                : "pathtrace:sampler=random,pathtrace,southwell:elements=250,"
                                  "southwell:elements=1000,gauss-seidel:elements=1000:reconstruct=gouraud,"
                                  "hierarchical,stochastic-jacobi";
    char preface[1600];
    snprintf(preface, sizeof preface,
             "Every method on the Cornell box at equal time (%g s per run): Monte Carlo path tracing "
             "(next-event estimation with MIS, Russian roulette) against finite-element radiosity: "
             "progressive refinement and Gauss-Seidel at two mesh sizes, hierarchical radiosity (Hanrahan, "
             "Salzman & Aupperle 1991, Gouraud images from vertex values gathered through its links) and "
             "Monte Carlo radiosity (stochastic Jacobi). The path tracer runs twice: "
             "with independent random numbers (`sampler=random`, plain Monte Carlo, whose error falls as "
             "N^-1/2: slope -0.5) and with its default Owen-scrambled Sobol' points, which converge "
             "somewhat faster where the integrand is smooth (see `radpt experiment samplers`). A "
             "radiosity curve flattens at its mesh's discretisation error, lower for the finer mesh.",
             budget);
    rp_bench_output out = {.size = sizeof out, .title = "Experiment cornell: all methods at equal time",
                           .preface = preface, .sheet = 1, .command = p->command};
    st = rp_exp_run_bench(p, scene, path, list, budget, seeds, ref_spp, &out, p->out_dir, NULL, NULL, err);
    rp_scene_destroy(scene);
    return st;
}

