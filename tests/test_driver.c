/* The one driver (bench/run/driver.h) and the numbers it records: budgets by
 * iterations and by time, the method's rule, the harness's checkpoint
 * thresholds (budget * 2^-k), the cancel flag, totals carried over by a
 * resumed run; the benchmarks' `converged` column, the threads recorded in
 * a render's EXR, and Southwell doing no work once converged.  Most tests
 * drive a fake solver whose every step is known in advance, so what the
 * driver should do is computed here by hand, not by the driver. */
#include <criterion/criterion.h>
#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bench/report/image.h"
#include "bench/run/clock.h"
#include "bench/run/driver.h"
#include "bench/run/harness.h"
#include "bench/run/reference.h"
#include "cli_util.h"
#include "scene_util.h"

/* ------------------------------------------------------- a fake solver */

/* Step k (from 1) adds fake_per_step iterations, residual 2^-k; the rule
 * is residual <= 2^-5 (met at step 5), enforced unless open_ended, like the
 * real methods (solver.h, rp_options.open_ended).  A step sleeps
 * fake_sleep_ns.  The estimate is the furnace's exact answer, 2. */
static double fake_per_step = 1;
static long fake_sleep_ns = 0;
static const atomic_int *fake_seen_cancel;

typedef struct fake_state {
    const rp_scene *scene;
    int open_ended;
    int k;
    double last_step_s;
} fake_state;

static const rp_option_spec fake_options[] = {{NULL, NULL, NULL, NULL}};

static rp_status fake_init(void *state, const rp_scene *scene, const rp_options *o, rp_error *err)
{
    (void)err;
    fake_state *s = state;
    s->scene = scene;
    s->open_ended = o->open_ended;
    fake_seen_cancel = o->cancel;
    return RP_OK;
}

static rp_status fake_step(void *state, rp_step_info *info, rp_error *err)
{
    (void)err;
    fake_state *s = state;
    double t0 = rp_clock();
    if (fake_sleep_ns) {
        struct timespec ts = {0, fake_sleep_ns};
        nanosleep(&ts, NULL);
    }
    s->k++;
    info->iterations = fake_per_step;
    info->residual = ldexp(1, -s->k);
    info->tolerance = ldexp(1, -5);
    info->converged = !s->open_ended && info->residual <= info->tolerance;
    info->progress = s->k / 5.0 < 1 ? s->k / 5.0 : 1;
    s->last_step_s = rp_clock() - t0;
    return RP_OK;
}

static rp_status fake_estimate(const void *state, rp_estimate *e, rp_error *err)
{
    (void)err;
    const fake_state *s = state;
    const rp_camera *cam = rp_scene_camera(s->scene);
    size_t nb = rp_scene_nbands(s->scene), ns = rp_scene_nsurfaces(s->scene);
    if (e->radiance)
        for (size_t i = 0; i < (size_t)cam->width * cam->height * nb; i++)
            e->radiance[i] = 2.0f;
    for (size_t i = 0; i < ns * nb; i++) {
        if (e->surface_radiance)
            e->surface_radiance[i] = 2.0;
        if (e->surface_stderr)
            e->surface_stderr[i] = 0;
    }
    e->samples = s->k;
    return RP_OK;
}

static void fake_fini(void *state) { (void)state; }

static const rp_solver_type fake_type = {
    .name = "fake", .summary = "test double", .options = fake_options, .state_size = sizeof(fake_state),
    .init = fake_init, .step = fake_step, .estimate = fake_estimate, .fini = fake_fini,
    .monte_carlo = 0, .samples_name = "steps",
};

static rp_scene *furnace(void) { return rp_test_load("scenes/furnace.scene"); }

static rp_solver *fake_create(const rp_scene *scene, int open_ended, const atomic_int *cancel, rp_drive_totals *tot)
{
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .open_ended = open_ended, .cancel = cancel};
    rp_solver *s = NULL;
    rp_error err;
    memset(tot, 0, sizeof *tot);
    cr_assert_eq(rp_drive_create(&fake_type, scene, &o, &s, tot, &err), RP_OK, "%s", err.message);
    return s;
}

static void fake_reset(double per_step, long sleep_ns)
{
    fake_per_step = per_step;
    fake_sleep_ns = sleep_ns;
    fake_seen_cancel = NULL;
}

/* ----------------------------------------------------------- budgets */

Test(driver, iteration_budget_counts_the_methods_iterations)
{
    fake_reset(3, 0);
    rp_scene *scene = furnace();
    rp_drive_totals tot;
    rp_solver *s = fake_create(scene, 1, NULL, &tot);
    rp_drive_params p = {.size = sizeof p, .budget = 10, .schedule = RP_SCHEDULE_ITERATIONS};
    rp_error err;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    /* 3, 6, 9, 12: the first boundary at or past 10 */
    cr_expect_eq(tot.steps, 4);
    cr_expect_eq(tot.sum.iterations, 12);
    cr_expect_eq(tot.stop, RP_STOP_BUDGET);
    cr_expect_eq(tot.last.residual, ldexp(1, -4));
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

Test(driver, time_budget_ends_at_the_first_boundary_past_it)
{
    fake_reset(1, 2000000); /* 2 ms a step */
    rp_scene *scene = furnace();
    rp_drive_totals tot;
    rp_solver *s = fake_create(scene, 1, NULL, &tot);
    const double budget = 0.03, created = tot.wall_s;
    rp_drive_params p = {.size = sizeof p, .budget = budget, .budget_base = created};
    rp_error err;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    cr_expect_eq(tot.stop, RP_STOP_BUDGET);
    /* past the budget, and not one step later than needed */
    cr_expect_geq(tot.wall_s, budget);
    double before_last = tot.wall_s - ((const fake_state *)rp_solver_state(s))->last_step_s;
    cr_expect_lt(before_last, budget + 1e-3, "%g s before the last step", before_last);
    cr_expect_geq(tot.steps, 2);
    cr_expect_geq(tot.cpu_s, 0);
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

Test(driver, the_methods_rule_ends_the_run)
{
    fake_reset(1, 0);
    rp_scene *scene = furnace();
    rp_drive_totals tot;
    rp_solver *s = fake_create(scene, 0, NULL, &tot);
    rp_drive_params p = {.size = sizeof p, .budget = 100, .schedule = RP_SCHEDULE_ITERATIONS, .stop_at_rule = 1};
    rp_error err;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    cr_expect_eq(tot.steps, 5); /* 2^-5 <= 2^-5 */
    cr_expect_eq(tot.stop, RP_STOP_RULE);
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

Test(driver, resumed_run_carries_totals_over)
{
    fake_reset(2, 0);
    rp_scene *scene = furnace();
    rp_drive_totals tot;
    rp_solver *s = fake_create(scene, 1, NULL, &tot);
    rp_drive_params p = {.size = sizeof p, .budget = 4, .schedule = RP_SCHEDULE_ITERATIONS};
    rp_error err;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    cr_expect_eq(tot.steps, 2);
    double wall = tot.wall_s;
    /* a second leg of 6 more iterations on the same totals */
    p.budget = 6;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    cr_expect_eq(tot.steps, 5);
    cr_expect_eq(tot.sum.iterations, 10);
    cr_expect_geq(tot.wall_s, wall);
    cr_expect_eq(tot.last.residual, ldexp(1, -5));
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

/* ------------------------------------------------------- cancellation */

typedef struct cancel_at {
    atomic_int *flag;
    double at_step;
    int calls;
} cancel_at;

static int set_cancel(void *ctx, rp_solver *s, const rp_drive_totals *t, rp_status *st, rp_error *err)
{
    (void)s, (void)st, (void)err;
    cancel_at *c = ctx;
    c->calls++;
    if (t->steps == c->at_step)
        atomic_store(c->flag, 1);
    return 0;
}

Test(driver, cancel_flag_stops_at_the_next_step_boundary)
{
    fake_reset(1, 0);
    rp_scene *scene = furnace();
    atomic_int flag = 0;
    rp_drive_totals tot;
    rp_solver *s = fake_create(scene, 1, &flag, &tot);
    cr_expect_eq(fake_seen_cancel, &flag, "the solver gets the flag through rp_options.cancel");
    cancel_at c = {.flag = &flag, .at_step = 3};
    rp_drive_params p = {.size = sizeof p, .budget = 1000, .schedule = RP_SCHEDULE_ITERATIONS,
                         .cancel = &flag, .after_step = set_cancel, .ctx = &c};
    rp_error err;
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK);
    cr_expect_eq(tot.stop, RP_STOP_SIGNAL);
    cr_expect_eq(tot.steps, 4);
    cr_expect_eq(c.calls, 3, "after_step is not called for the step that saw the flag");
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

/* ------------------------------------------- the harness's checkpoints */

static rp_reference *furnace_reference(const rp_scene *scene, char *dir, size_t n)
{
    snprintf(dir, n, "/tmp/rp_driver_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
    rp_reference_params rp = {.size = sizeof rp, .cache_dir = dir};
    rp_reference *ref = NULL;
    rp_error err;
    cr_assert_eq(rp_reference_get(scene, "furnace", &rp, &ref, &err), RP_OK, "%s", err.message);
    return ref;
}

static void remove_dir(const char *dir)
{
    char cmd[256];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_expect_eq(system(cmd), 0);
}

static rp_method_spec fake_spec(void)
{
    rp_method_spec m;
    memset(&m, 0, sizeof m);
    snprintf(m.text, sizeof m.text, "fake");
    snprintf(m.name, sizeof m.name, "fake");
    m.type = &fake_type;
    return m;
}

/* Budget 16 iterations, levels 5: thresholds 1, 2, 4, 8, 16 (k = 4 .. 0).
 * Steps of 3 iterations end at 3, 6, 9, 12, 15, 18: 3 passes both 1 and 2
 * (only k = 3 is recorded), 6 passes 4 (k = 2), 9 passes 8 (k = 1), 18
 * passes 16 (k = 0) and ends the run. */
Test(driver, harness_checkpoint_thresholds)
{
    fake_reset(3, 0);
    rp_scene *scene = furnace();
    char dir[64];
    rp_reference *ref = furnace_reference(scene, dir, sizeof dir);
    rp_method_spec m = fake_spec();
    rp_harness_params hp = {.size = sizeof hp, .budget = 16, .levels = 5, .schedule = RP_SCHEDULE_ITERATIONS};
    rp_trial run;
    rp_error err;
    cr_assert_eq(rp_harness_run(scene, ref, &m, 1, &hp, &run, &err), RP_OK);
    cr_assert_eq(run.status, RP_OK, "%s", run.error);
    const int k[] = {3, 2, 1, 0};
    const double it[] = {3, 6, 9, 18};
    cr_assert_eq(run.ncp, 4);
    for (size_t i = 0; i < 4; i++) {
        cr_expect_eq(run.cp[i].index, k[i], "row %zu", i);
        cr_expect_eq(run.cp[i].iterations, it[i], "row %zu", i);
        cr_expect_eq(run.cp[i].target, ldexp(16, -k[i]), "row %zu", i);
        cr_expect_eq(run.cp[i].final, i == 3);
        cr_expect_eq(run.cp[i].rmse, 0.0); /* the fake answers 2 exactly */
        /* converged: the rule (2^-step <= 2^-5) is met from step 5 on,
         * although the open-ended run does not stop for it */
        cr_expect_eq(run.cp[i].converged, it[i] / 3 >= 5, "row %zu", i);
    }
    rp_trial_free(&run);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_dir(dir);
}

static void cancel_on_progress(void *ctx, double fraction, const char *detail)
{
    (void)fraction, (void)detail;
    atomic_store((atomic_int *)ctx, 1);
}

/* The flag set during step 1's progress report: step 1's row is taken
 * (after_step runs after progress), the run ends at step 2's boundary. */
Test(driver, harness_cancelled_run_keeps_its_rows)
{
    fake_reset(1, 0);
    rp_scene *scene = furnace();
    char dir[64];
    rp_reference *ref = furnace_reference(scene, dir, sizeof dir);
    rp_method_spec m = fake_spec();
    atomic_int flag = 0;
    rp_harness_params hp = {.size = sizeof hp, .budget = 64, .levels = 7, .schedule = RP_SCHEDULE_ITERATIONS,
                            .cancel = &flag, .progress = cancel_on_progress, .progress_ctx = &flag};
    rp_trial run;
    rp_error err;
    cr_assert_eq(rp_harness_run(scene, ref, &m, 1, &hp, &run, &err), RP_OK);
    cr_expect_eq(run.status, RP_ERR_INTERRUPTED);
    cr_assert_eq(run.ncp, 1);
    cr_expect_eq(run.cp[0].index, 6);
    cr_expect_eq(run.cp[0].iterations, 1);
    rp_trial_free(&run);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_dir(dir);
}

/* ------------------------------------------------ the numbers recorded */

/* Gauss-Seidel on the furnace under an iteration budget (open-ended, so
 * its default tolerance does not stop it): each row's `converged` is
 * whether that row's residual is at or below 1e-6 (the default). */
Test(driver, converged_column_says_whether_the_rule_was_met)
{
    rp_scene *scene = furnace();
    char dir[64];
    rp_reference *ref = furnace_reference(scene, dir, sizeof dir);
    rp_method_spec m;
    rp_error err;
    cr_assert_eq(rp_method_spec_parse("gauss-seidel:elements=24", &m, &err), RP_OK, "%s", err.message);
    rp_harness_params hp = {.size = sizeof hp, .budget = 64, .levels = 7, .schedule = RP_SCHEDULE_ITERATIONS};
    rp_trial run;
    cr_assert_eq(rp_harness_run(scene, ref, &m, 1, &hp, &run, &err), RP_OK);
    cr_assert_eq(run.status, RP_OK, "%s", run.error);
    int yes = 0, no = 0;
    for (size_t i = 0; i < run.ncp; i++) {
        int met = run.cp[i].residual >= 0 && run.cp[i].residual <= 1e-6;
        cr_expect_eq(run.cp[i].converged, met, "row %zu: residual %g", i, run.cp[i].residual);
        yes += met;
        no += !met;
    }
    cr_expect(yes > 0 && no > 0, "rows before and after convergence (%d, %d)", no, yes);
    rp_trial_free(&run);
    rp_reference_destroy(ref);
    rp_scene_destroy(scene);
    remove_dir(dir);
}

/* Southwell on the furnace (rho 0.5): once its residual bound is at the
 * tolerance a step shoots nothing and counts nothing, and the driver ends
 * an open-ended run there instead of spinning to its budget. */
Test(driver, southwell_does_no_work_once_converged)
{
    rp_scene *scene = furnace();
    const char *keys[] = {"elements", "tolerance"}, *values[] = {"24", "1e-4"};
    rp_options o = {.size = sizeof o, .want = RP_WANT_SURFACES, .keys = keys, .values = values, .count = 2,
                    .open_ended = 1};
    rp_solver *s = NULL;
    rp_drive_totals tot;
    memset(&tot, 0, sizeof tot);
    rp_error err;
    cr_assert_eq(rp_drive_create(rp_solver_lookup("southwell"), scene, &o, &s, &tot, &err), RP_OK, "%s",
                 err.message);
    rp_drive_params p = {.size = sizeof p, .budget = 1e6, .schedule = RP_SCHEDULE_ITERATIONS};
    cr_assert_eq(rp_drive(s, &p, &tot, &err), RP_OK, "%s", err.message);
    cr_expect_eq(tot.stop, RP_STOP_RULE);
    cr_expect_leq(tot.last.residual, 1e-4);
    cr_expect_lt(tot.sum.iterations, 1e5);
    /* exactly one idle step after the converging one */
    cr_expect_eq(tot.steps, tot.sum.iterations + 1);
    rp_step_info info;
    cr_assert_eq(rp_solver_step(s, &info, &err), RP_OK);
    cr_expect_eq(info.iterations, 0);
    cr_expect_eq(info.form_factors, 0);
    cr_expect_eq(info.converged, 1);
    rp_solver_destroy(s);
    rp_scene_destroy(scene);
}

/* A render asked for the default thread count records the count used. */
Test(driver, render_records_threads_used)
{
    char out[] = "/tmp/rp_driver_threads_XXXXXX.exr";
    int fd = mkstemps(out, 4);
    cr_assert_geq(fd, 0);
    close(fd);
    char args[512];
    snprintf(args, sizeof args, "render %s/scenes/furnace.scene --method gauss-seidel --elements 24 -o %s",
             RP_SOURCE_DIR, out);
    rp_run r = rp_run_radpt(args);
    cr_assert_eq(r.status, 0, "%s", r.out);
    char *t = rp_image_read_exr_attr(out, "radpt:threads");
    cr_assert_not_null(t);
    cr_expect_eq(atoi(t), omp_get_max_threads(), "radpt:threads %s", t);
    free(t);
    rp_run_free(&r);
    unlink(out);
}
