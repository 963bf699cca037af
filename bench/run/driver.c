/* The one driver (driver.h). */
#include "bench/run/driver.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "bench/run/clock.h"

rp_status rp_drive_create(const rp_solver_type *type, const rp_scene *scene, const rp_options *options,
                          rp_solver **out, rp_drive_totals *tot, rp_error *err)
{
    double t0 = rp_clock(), c0 = rp_cpu_clock();
    rp_status st = rp_solver_create(type, scene, options, out, err);
    tot->wall_s += rp_clock() - t0;
    tot->cpu_s += rp_cpu_clock() - c0;
    return st;
}

/* "label: 120 iterations, 3.2 s, ETA 5 s" */
static void report(const rp_drive_params *p, const rp_drive_totals *tot, double fraction, double spent,
                   const char *unit)
{
    char eta[48] = "";
    if (fraction > 0.01 && fraction < 1)
        snprintf(eta, sizeof eta, ", ETA %.0f s", spent * (1 - fraction) / fraction);
    char detail[200];
    snprintf(detail, sizeof detail, "%s%s%.0f %s, %.3g s%s", p->label ? p->label : "", p->label ? ": " : "",
             tot->sum.iterations, unit, tot->wall_s, eta);
    p->progress(p->progress_ctx, fraction, detail);
}

/* Under a communicator (a method split over MPI ranks) the ranks agree
 * after each step, in one collective, so that they stop together and call
 * the collective estimate and save together: a rank's failure (the lowest
 * failing rank's status and message then go to every rank), a cancel flag
 * on any rank, and rank 0's stopping decision and solver time.  Returns
 * the agreed status. */
static rp_status agree(const rp_comm *c, rp_status st, rp_error *err, int cancelled, rp_stop *stop,
                       double *wall)
{
    double v[4] = {st != RP_OK ? (double)(c->size - c->rank) : 0, cancelled, c->rank == 0 ? (double)*stop : 0,
                   c->rank == 0 ? *wall : -1};
    rp_comm_max(c, v, 4);
    if (v[0] > 0) {
        int failed = c->size - (int)v[0];
        struct {
            int status;
            char message[sizeof err->message];
        } why = {(int)st, ""};
        if (c->rank == failed && err)
            memcpy(why.message, err->message, sizeof why.message);
        rp_comm_bcast(c, &why, sizeof why, failed);
        why.message[sizeof why.message - 1] = '\0';
        if (err)
            memcpy(err->message, why.message, sizeof why.message);
        return (rp_status)why.status;
    }
    *stop = v[1] ? RP_STOP_SIGNAL : (rp_stop)v[2];
    *wall = v[3];
    return RP_OK;
}

rp_status rp_drive(rp_solver *s, const rp_drive_params *p, rp_drive_totals *tot, rp_error *err)
{
    const rp_comm *comm = rp_solver_comm(s);
    const double cpu0 = tot->cpu_s;
    const rp_step_info sum0 = tot->sum;
    const char *unit = rp_solver_type_of(s)->iteration_name ? rp_solver_type_of(s)->iteration_name : "iterations";
    double spent = 0, last_report = -1, start = rp_clock();
    const double iter0 = tot->sum.iterations, steps0 = tot->steps;
    tot->stop = RP_STOP_NONE;
    rp_status st = RP_OK;
    while (st == RP_OK && tot->stop == RP_STOP_NONE) {
        rp_step_info info;
        memset(&info, 0, sizeof info);
        double t0 = rp_clock(), c0 = rp_cpu_clock();
        st = rp_solver_step(s, &info, err);
        double dt = rp_clock() - t0;
        tot->wall_s += dt;
        tot->cpu_s += rp_cpu_clock() - c0;
        spent += dt;
        if (st != RP_OK) {
            if (comm) {
                rp_stop none = RP_STOP_NONE;
                double w = tot->wall_s;
                st = agree(comm, st, err, 0, &none, &w);
            }
            break;
        }
        tot->steps++;
        tot->sum.rays += info.rays;
        tot->sum.paths += info.paths;
        tot->sum.form_factors += info.form_factors;
        tot->sum.iterations += info.iterations;
        tot->last = info;
        if (!comm && rp_cancelled(p->cancel)) {
            tot->stop = RP_STOP_SIGNAL;
            break;
        }
        double clock = p->schedule == RP_SCHEDULE_ITERATIONS ? tot->sum.iterations - iter0
                       : p->schedule == RP_SCHEDULE_STEPS    ? tot->steps - steps0
                                                             : p->budget_base + spent;
        /* a converged method that did no work in its step has nothing
         * left to do, whatever stop_at_rule says */
        if (info.converged && (p->stop_at_rule || (info.iterations == 0 && info.rays == 0 &&
                                                   info.form_factors == 0 && info.paths == 0)))
            tot->stop = RP_STOP_RULE;
        else if (p->budget > 0 && clock >= p->budget)
            tot->stop = RP_STOP_BUDGET;
        if (comm) {
            /* rank 0's clock decides for all */
            double w = tot->wall_s;
            if ((st = agree(comm, RP_OK, err, rp_cancelled(p->cancel), &tot->stop, &w)) != RP_OK)
                break;
            spent += w - tot->wall_s;
            tot->wall_s = w;
            if (tot->stop == RP_STOP_SIGNAL)
                break;
        }
        if (p->progress) {
            double now = rp_clock();
            if (now - last_report >= 0.1 || tot->stop != RP_STOP_NONE) {
                double f = info.progress;
                if (p->budget > 0 && clock / p->budget > f)
                    f = clock / p->budget;
                report(p, tot, f > 1 ? 1 : f, now - start, unit);
                last_report = now;
            }
        }
        if (p->after_step) {
            rp_status cs = RP_OK;
            int end = p->after_step(p->ctx, s, tot, &cs, err);
            if (comm) {
                /* rank 0's hook decides whether the run ends there */
                rp_stop want = end ? RP_STOP_CALLER : RP_STOP_NONE;
                double w = tot->wall_s;
                cs = agree(comm, cs, err, 0, &want, &w);
                end = want == RP_STOP_CALLER;
            }
            if (cs != RP_OK)
                st = cs;
            else if (end && tot->stop == RP_STOP_NONE)
                tot->stop = RP_STOP_CALLER;
        }
    }
    if (comm) {
        /* The work and CPU time of the run are every rank's together (the
         * iterations are the same on every rank). */
        double d[4] = {tot->sum.rays - sum0.rays, tot->sum.paths - sum0.paths,
                       tot->sum.form_factors - sum0.form_factors, tot->cpu_s - cpu0};
        rp_comm_sum(comm, d, 4);
        tot->sum.rays = sum0.rays + d[0];
        tot->sum.paths = sum0.paths + d[1];
        tot->sum.form_factors = sum0.form_factors + d[2];
        tot->cpu_s = cpu0 + d[3];
    }
    return st;
}
