/* Named experiments: the registry and the helpers every experiment shares
 * (experiments.h, exp_internal.h). */
#include "bench/experiments/experiments.h"

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
#include "bench/run/load.h"
#include "geometry/log.h"
#include "bench/run/mpi.h"

/* ------------------------------------------------------------- helpers */

void rp_exp_log(const rp_experiment_params *p, const char *fmt, ...)
{
    /* the hand-out pass logs only the units it computes (rp_exp_unit):
     * the numbers of the others are not known there */
    if (rp_exp_handing_out(p))
        return;
    va_list ap;
    va_start(ap, fmt);
    rp_vlogf(p->log, p->log_ctx, fmt, ap);
    va_end(ap);
}

static int is_file(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
}

rp_status rp_experiment_scene_path(const rp_experiment_params *p, const char *name, char *out, size_t n,
                                   rp_error *err)
{
    if (p->scenes_dir) {
        rp_path_join(out, n, p->scenes_dir, name);
        if (is_file(out))
            return RP_OK;
        return rp_error_set(err, RP_ERR_INPUT, "%s: no such scene", out);
    }
    rp_path_join(out, n, "scenes", name);
    if (is_file(out))
        return RP_OK;
    /* next to the binary: radpt lives at the top of the source tree */
    char exe[1024];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (len > 0) {
        exe[len] = '\0';
        char *slash = strrchr(exe, '/');
        for (int up = 0; slash && up < 3; up++) {
            *slash = '\0';
            char dir[1100];
            snprintf(dir, sizeof dir, "%s/scenes", exe);
            rp_path_join(out, n, dir, name);
            if (is_file(out))
                return RP_OK;
            slash = strrchr(exe, '/');
        }
    }
    return rp_error_set(err, RP_ERR_INPUT, "scenes/%s not found (run from the source tree or give --scenes DIR)", name);
}

rp_reference_params rp_exp_ref_params(const rp_experiment_params *p, unsigned long spp)
{
    rp_reference_params r = {.size = sizeof r, .spp = spp, .threads = p->threads, .cache_dir = p->cache_dir,
                             .log = p->log, .log_ctx = p->log_ctx, .progress = p->progress,
                             .progress_ctx = p->progress_ctx, .cancel = p->cancel};
    return r;
}

/* Gets the scene's reference, runs a bench over a method list with
 * checkpoints at budget x 2^-k, k < levels (budget in seconds or, with
 * RP_SCHEDULE_ITERATIONS, in iterations) and writes the standard output
 * into dir. */
rp_status rp_exp_run_bench_scheduled(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                                     const char *list, rp_schedule schedule, double budget, unsigned levels,
                                     unsigned nseeds, unsigned long ref_spp, const rp_bench_output *out,
                                     const char *dir, rp_bench **bench_out, rp_reference **ref_out, rp_error *err)
{
    rp_method_spec *methods = NULL;
    size_t n = 0;
    rp_reference *ref = NULL;
    rp_bench *b = NULL;
    rp_status st = rp_method_list_parse(list, &methods, &n, err);
    if (st == RP_OK) {
        rp_reference_params rp = rp_exp_ref_params(p, ref_spp);
        st = rp_reference_get(scene, scene_name, &rp, &ref, err);
    }
    /* each bench of an experiment keys its runs by its method list, so two
     * benches in one study do not share records */
    char prefix[600];
    snprintf(prefix, sizeof prefix, "bench %s | ", list);
    /* a bench hands out its runs itself: in rp_experiment_run's hand-out
     * pass only the reference is made, and the bench runs in the next */
    int later = rp_exp_handing_out(p);
    if (st == RP_OK && !later) {
        rp_bench_params bp = {.size = sizeof bp, .nseeds = nseeds, .seed = 1, .log = p->log, .log_ctx = p->log_ctx,
                              .journal = p->journal, .journal_prefix = prefix, .image_dir = dir};
        bp.run = (rp_harness_params){.size = sizeof bp.run, .budget = budget, .levels = levels,
                                     .schedule = schedule, .threads = p->threads, .keep_image = 1,
                                     .progress = p->progress, .progress_ctx = p->progress_ctx,
                                     .cancel = p->cancel};
        st = rp_bench_run(scene, scene_name, ref, methods, n, &bp, &b, err);
    }
    if (st == RP_OK && !later) {
        char note[256];
        rp_bench_output o = *out;
        if (!o.exposure)
            o.exposure = p->exposure;
        st = rp_bench_write(b, dir, &o, note, err);
        if (st == RP_OK && note[0])
            rp_exp_log(p, "%s", note);
        if (st == RP_OK && b->interrupted)
            st = rp_error_set(err, RP_ERR_INTERRUPTED, "interrupted after %zu of %zu runs", b->nruns, b->planned);
    }
    free(methods);
    if (st == RP_OK && bench_out) {
        *bench_out = b;
        b = NULL;
    }
    if (st == RP_OK && ref_out) {
        *ref_out = ref;
        ref = NULL;
    }
    rp_bench_destroy(b);
    rp_reference_destroy(ref);
    return st;
}

/* run_bench_scheduled by time, 9 checkpoints. */
rp_status rp_exp_run_bench(const rp_experiment_params *p, const rp_scene *scene, const char *scene_name,
                           const char *list, double budget, unsigned nseeds, unsigned long ref_spp,
                           const rp_bench_output *out, const char *dir, rp_bench **bench_out,
                           rp_reference **ref_out, rp_error *err)
{
    return rp_exp_run_bench_scheduled(p, scene, scene_name, list, RP_SCHEDULE_TIME, budget, 9, nseeds, ref_spp, out, dir,
                               bench_out, ref_out, err);
}

/* -------------------------------------------------------------- gnuplot */

/* Writes DIR/plots.gp from body (after the shared preamble) and runs it;
 * a missing gnuplot is a note, not a failure. */
rp_status rp_exp_draw(const rp_experiment_params *p, const char *body, char *note, size_t nn, rp_error *err)
{
    char path[1024];
    rp_out o;
    note[0] = '\0';
    rp_status st = rp_out_open(&o, rp_path_join(path, sizeof path, p->out_dir, "plots.gp"), err);
    if (st != RP_OK)
        return st;
    rp_gnuplot_preamble(o.f, rp_gnuplot_png_terminal());
    fputs(body, o.f);
    if ((st = rp_out_close(&o, 1, err)) != RP_OK)
        return st;
    rp_error gerr;
    if (rp_gnuplot_run(p->out_dir, "plots.gp", &gerr) != RP_OK) {
        snprintf(note, nn, "charts not drawn: %.200s", gerr.message);
        rp_exp_log(p, "%s", note);
    }
    return RP_OK;
}

/* ------------------------------------------------ units and hand-out */

/* rp_experiment_run's state while it hands an experiment's units out to
 * ranks (pass 0) and reads them back (pass 1). */
struct rp_exp_handout {
    const rp_comm *comm;
    int pass;
    size_t next;     /* pass 0: units counted so far (those not recorded) */
    size_t mine;     /* pass 0: units this rank computed */
    size_t last;     /* pass 0: index of the last unit this rank took */
};

int rp_exp_handing_out(const rp_experiment_params *p)
{
    return p->handout && p->handout->pass == 0;
}

int rp_exp_unit(const rp_experiment_params *p, const char *key, double *v, size_t n)
{
    int recorded = v ? rp_journal_get_doubles(p->journal, key, v, n) : rp_journal_get(p->journal, key) != NULL;
    if (recorded) {
        /* in the pass after a hand-out every unit is recorded: only a
         * resumed study's units are news */
        if (!p->handout)
            rp_exp_log(p, "%s: recorded, read back from the journal", key);
        return 1;
    }
    if (!rp_exp_handing_out(p))
        return 0;
    struct rp_exp_handout *h = p->handout;
    size_t k = h->next++;
    if (!rp_comm_owns(h->comm, k)) {
        for (size_t i = 0; v && i < n; i++)
            v[i] = NAN;
        return -1;
    }
    h->mine++;
    h->last = k;
    rp_logf(p->log, p->log_ctx, "unit %zu: %s", k + 1, key);
    return 0;
}

/* Puts the records that each rank added to its journal since record mark
 * into every other rank's journal (rank 0's writes them to disk), rank by
 * rank in rank order.  Collective. */
static rp_status handout_exchange(rp_journal *j, const rp_comm *c, size_t mark, size_t *received, rp_error *err)
{
    rp_status st = RP_OK;
    size_t mine = rp_journal_count(j);
    *received = 0;
    for (int r = 0; r < c->size; r++) {
        char *buf = NULL;
        size_t len = 0;
        if (c->rank == r) {
            FILE *f = open_memstream(&buf, &len);
            for (size_t i = mark; f && i < mine; i++) {
                const char *key, *payload;
                rp_journal_record(j, i, &key, &payload);
                fprintf(f, "%s\t%s\n", key, payload);
            }
            if (!f || fclose(f) != 0) {
                free(buf);
                buf = NULL;
                len = 0;
            }
        }
        double size = (double)len;
        rp_comm_bcast(c, &size, sizeof size, r);
        len = (size_t)size;
        double short_of_memory = 0;
        if (c->rank != r && len && !(buf = malloc(len)))
            short_of_memory = 1;
        rp_comm_max(c, &short_of_memory, 1);
        if (short_of_memory) {
            free(buf);
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory collecting the ranks' journal records");
        }
        if (len)
            rp_comm_bcast(c, buf, len, r);
        for (char *line = buf; c->rank != r && st == RP_OK && line < buf + len;) {
            char *nl = memchr(line, '\n', (size_t)(buf + len - line));
            char *tab = nl ? memchr(line, '\t', (size_t)(nl - line)) : NULL;
            if (!tab)
                break;
            *tab = *nl = '\0';
            st = rp_journal_put(j, line, tab + 1, err);
            (*received)++;
            line = nl + 1;
        }
        free(buf);
    }
    return st;
}

/* After the hand-out pass: the error a single process would have given
 * is the one of the earliest unit that failed.  The ranks agree on it
 * (the failing rank with the lowest unit index tells the others). */
static rp_status handout_agree(const rp_comm *c, const struct rp_exp_handout *h, rp_status st, rp_error *err)
{
    int failed = st != RP_OK && st != RP_ERR_INTERRUPTED;
    double v[2] = {failed ? -(double)h->last : -INFINITY, 0};
    rp_comm_max(c, v, 1);
    if (v[0] == -INFINITY)
        return RP_OK;
    v[1] = failed && -(double)h->last == v[0] ? -(double)c->rank : -INFINITY;
    rp_comm_max(c, &v[1], 1);
    int holder = (int)-v[1];
    struct {
        int status;
        char message[sizeof err->message];
    } e = {0};
    if (c->rank == holder) {
        e.status = st;
        snprintf(e.message, sizeof e.message, "%s", err->message);
    }
    rp_comm_bcast(c, &e, sizeof e, holder);
    return rp_error_set(err, (rp_status)e.status, "%s", e.message);
}

void rp_experiment_identity(const rp_experiment_params *p, char *buf, size_t n)
{
    snprintf(buf, n, "experiment %s quick %d budget %.17g seeds %u", p->experiment->name, p->quick, p->budget,
             p->nseeds);
}

rp_status rp_experiment_run(const rp_experiment_params *p, rp_error *err)
{
    const rp_experiment *e = p->experiment;
    const rp_comm *comm = rp_mpi_world();
    if (!e->own_units || !p->journal || rp_comm_size(comm) < 2)
        return e->run(p, err);
    struct rp_exp_handout h = {.comm = comm};
    rp_experiment_params q = *p;
    q.handout = &h;
    size_t mark = rp_journal_count(p->journal);
    rp_exp_log(p, "experiment %s: handing out its units to %d ranks", e->name, comm->size);
    /* pass 0: this rank's units, nothing written into the study's
     * directory (the journal, opened before, still records them; the
     * reference cache, elsewhere, is written) */
    rp_files_discard_under(p->out_dir);
    rp_status st = e->run(&q, err);
    rp_files_discard_under(NULL);
    st = handout_agree(comm, &h, st, err);
    size_t received = 0;
    rp_error xerr;
    rp_status xst = handout_exchange(p->journal, comm, mark, &received, &xerr);
    if (xst != RP_OK && st == RP_OK) {
        *err = xerr;
        st = xst;
    }
    if (st != RP_OK)
        return st;
    rp_exp_log(p, "experiment %s: this rank computed %zu of %zu units, %zu came from the other ranks", e->name,
               h.mine, h.next, received);
    /* pass 1: everything read back (a unit no rank reached, here computed) */
    h.pass = 1;
    return e->run(&q, err);
}

/* A CSV number; not reached or not measured: an empty field. */
void rp_exp_fnum(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
}

/* The same in gnuplot data: "?" (the plots' `set datafile missing`). */
void rp_exp_dnum(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.6g", v);
    else
        fputc('?', f);
}

rp_status rp_exp_begin(const rp_experiment_params *p, const char *scene_file, rp_exp_start *x, rp_error *err)
{
    memset(x, 0, sizeof *x);
    rp_status st = rp_experiment_setting_of(p, &x->set, err);
    if (st == RP_OK && x->set.methods)
        rp_exp_describe_methods(x->set.methods, x->methods, sizeof x->methods);
    if (st == RP_OK && scene_file)
        st = rp_experiment_scene_path(p, scene_file, x->path, sizeof x->path, err);
    if (st == RP_OK && scene_file)
        st = rp_load_scene(x->path, NULL, 1, &x->scene, err);
    return st;
}

void rp_exp_describe_methods(const char *list, char *out, size_t n)
{
    out[0] = '\0';
    rp_method_spec *m = NULL;
    size_t count = 0, used = 0;
    rp_error err;
    if (rp_method_list_parse(list, &m, &count, &err) != RP_OK)
        return;
    for (size_t i = 0; i < count && used < n; i++) {
        /* methods in list order, each with the variants (options) it runs */
        size_t first = i;
        for (size_t k = 0; k < i; k++)
            if (strcmp(m[k].name, m[i].name) == 0)
                first = k;
        if (first != i)
            continue;
        size_t variants = 0;
        for (size_t k = i; k < count; k++)
            variants += strcmp(m[k].name, m[i].name) == 0;
        used += (size_t)snprintf(out + used, n - used, "%s%s", used ? "; " : "", m[i].name);
        if (variants > 1 || m[i].count) {
            used += (size_t)snprintf(out + used, used < n ? n - used : 0, " (");
            size_t shown = 0;
            for (size_t k = i; k < count && used < n; k++) {
                if (strcmp(m[k].name, m[i].name) != 0)
                    continue;
                const char *colon = strchr(m[k].text, ':');
                used += (size_t)snprintf(out + used, used < n ? n - used : 0, "%s%s", shown++ ? ", " : "",
                                         colon ? colon + 1 : "defaults");
            }
            used += (size_t)snprintf(out + used, used < n ? n - used : 0, ")");
        }
    }
    free(m);
}

static void describe_setting(FILE *f, const char *label, const rp_experiment_setting *s, const char *unit)
{
    fprintf(f, "%s:", label);
    if (s->budget > 0)
        fprintf(f, " %g %s per run;", s->budget, unit ? unit : "s");
    if (s->seeds)
        fprintf(f, " %u seeds per Monte Carlo method;", s->seeds);
    if (s->reference_spp)
        fprintf(f, " reference %lu spp;", s->reference_spp);
    if (s->methods)
        fprintf(f, " methods %s", s->methods);
    if (!(s->budget > 0) && !s->seeds && !s->reference_spp && !s->methods)
        fputs(" the experiment's own (its sections and methods are in README.md)", f);
    fputc('\n', f);
}

void rp_experiment_describe(const rp_experiment *e, FILE *f)
{
    fprintf(f, "experiment %s: %s\n", e->name, e->summary);
    if (e->scenes)
        fprintf(f, "scenes: %s\n", e->scenes);
    if (e->claim)
        fprintf(f, "claim checked: %s\n", e->claim);
    describe_setting(f, "full", &e->full, e->budget_unit);
    describe_setting(f, "--quick", &e->quick, e->budget_unit);
    fprintf(f, "run: radpt experiment %s [--quick] -o DIR; --budget and --seeds override the settings\n", e->name);
}

rp_status rp_experiment_setting_of(const rp_experiment_params *p, rp_experiment_setting *out, rp_error *err)
{
    if (!p->experiment)
        return rp_error_set(err, RP_ERR_INPUT, "experiment parameters name no experiment");
    *out = p->quick ? p->experiment->quick : p->experiment->full;
    if (p->budget > 0)
        out->budget = p->budget;
    if (p->nseeds)
        out->seeds = p->nseeds;
    return RP_OK;
}

/* ------------------------------------------------------------- registry */

static const rp_experiment experiments[] = {
    {.name = "cornell",
     .summary = "all methods at equal time on the Cornell box",
     .scenes = "scenes/cornell.scene",
     .claim = "at equal time every method's image RMSE against the path-traced reference falls with time; "
              "the path tracer with independent numbers falls as N^-1/2 (fitted slope near -0.5 against "
              "samples) and radiosity curves flatten at their mesh's discretisation error",
     .quick = {1.0, 2, 256,
               "pathtrace:sampler=random,pathtrace,southwell:elements=150,southwell:elements=600,"
               "hierarchical:bf-epsilon=0.1:min-area=1e-3,stochastic-jacobi"},
     .full = {6.0, 3, 2048,
              "pathtrace:sampler=random,pathtrace,southwell:elements=250,southwell:elements=1000,"
              "gauss-seidel:elements=1000:reconstruct=gouraud,hierarchical,stochastic-jacobi"},
     .run = rp_exp_cornell},
    {.name = "samplers",
     .summary = "random, stratified and Sobol' sampling: RMSE against spp and slopes",
     .scenes = "scenes/cornell.scene",
     .claim = "random sampling's RMSE falls as N^-1/2; stratified and Sobol' reach a lower RMSE at equal samples",
     .quick = {1.0, 2, 256, "pathtrace:sampler=random,pathtrace:sampler=stratified,pathtrace:sampler=sobol"},
     .full = {10.0, 3, 2048, "pathtrace:sampler=random,pathtrace:sampler=stratified,pathtrace:sampler=sobol"},
     .run = rp_exp_samplers},
    {.name = "furnace",
     .summary = "reflectance 0.1 to 0.99: sweeps and time to tolerance, iterative solvers and path tracer",
     .scenes = "closed furnaces built in memory (reflectance 0.1 to 0.99)",
     .claim = "every method converges to the closed form L = Le / (1 - rho); the iterative solvers' sweeps to a "
              "tolerance grow like 1 / (1 - rho)",
     /* runs stop at the tolerance: the budget is only a cap, with room for
      * a loaded machine (the iterative solvers need about 1 s idle; the
      * path tracer may use all of it) */
     .quick = {5.0, 0, 0, NULL},
     .full = {20.0, 0, 0, NULL},
     .own_units = 1,
     .run = rp_exp_furnace},
    {.name = "formfactors",
     .summary = "analytic, Monte Carlo and hemicube form factors against Howell's closed forms",
     .scenes = "rectangle pairs built in memory (Howell C-11 and C-14)",
     .claim = "the analytic form factor equals Howell's closed forms; Monte Carlo error falls as N^-1/2; the "
              "hemicube's error is bounded by its resolution",
     .own_units = 1,
     .run = rp_exp_formfactors},
    {.name = "meshing",
     .summary = "radiosity error against element size, observed order",
     .scenes = "scenes/cornell.scene",
     .claim = "radiosity error falls with element size h at an observed order near 1 (flat) and higher with "
              "Gouraud reconstruction",
     .quick = {20.0, 0, 256, NULL},
     .full = {300.0, 0, 2048, NULL},
     .own_units = 1,
     .run = rp_exp_meshing},
    {.name = "discontinuity",
     .summary = "uniform and discontinuity meshes (and hierarchical refinement from the faces and from their "
                "discontinuity mesh, with constant and linear bases): error against elements and time, meshes drawn",
     .scenes = "scenes/cornell.scene and scenes/real/CornellBox-Original.obj (boxes on the floor: contact shadows)",
     .claim = "at the same element count asked, Gauss-Seidel on a discontinuity mesh (elements following contact "
              "lines and shadow boundaries) has a lower surface error than on a uniform mesh (hierarchical radiosity, "
              "from the faces and from their discontinuity mesh, with constant and linear bases, runs its defaults "
              "for 20 s whatever --budget says, or in the quick form --bf-epsilon 0.05 --min-area 1e-4 to "
              "convergence; the report also says whether the linear basis beats the constant one from the "
              "discontinuity mesh)",
     .quick = {60.0, 0, 256, NULL},
     .full = {300.0, 0, 2048, NULL},
     .own_units = 1,
     .run = rp_exp_discontinuity},
    {.name = "progressive",
     .summary = "progressive radiosity with and without ambient term and overshooting: error per shot",
     .scenes = "scenes/cornell.scene",
     .claim = "the ambient term lowers the early error; overshooting lowers the error per shot",
     .quick = {300, 1, 256,
               "southwell:elements=150,southwell:elements=150:ambient,southwell:elements=150:overshoot=1.5,"
               "southwell:elements=150:ambient:overshoot=1.5"},
     .full = {4000, 1, 2048,
              "southwell:elements=500,southwell:elements=500:ambient,southwell:elements=500:overshoot=1.5,"
              "southwell:elements=500:ambient:overshoot=1.5"},
     .budget_unit = "shots",
     .run = rp_exp_progressive},
    {.name = "hierarchy",
     .summary = "hierarchical radiosity against the classic solvers, and links against leaves as bf-epsilon "
                "shrinks",
     .scenes = "scenes/cornell.scene",
     .claim = "hierarchical radiosity reaches a given error sooner than the uniform solvers, and its links grow "
              "about linearly with its leaves, not quadratically",
     .quick = {2.0, 1, 256, "hierarchical,gauss-seidel:elements=250"},
     .full = {20.0, 1, 2048, "hierarchical,gauss-seidel:elements=1000,southwell:elements=1000"},
     .own_units = 1,
     .run = rp_exp_hierarchy},
    {.name = "stability",
     .summary = "the stability atlas: each method pushed past its comfort zone (reflectance near 1, tiny lights, "
                "corners, contact, shadows, thin geometry, non-physical input)",
     .scenes = "configurations built in memory, with closed forms where they exist",
     .claim = "each method's failure mode is where the theory puts it, and non-physical input is refused",
     .own_units = 1,
     .run = rp_exp_stability},
    {.name = "realscenes",
     .summary = "published OBJ/MTL scenes and scanned meshes: every method against the path tracer per "
                "surface, time and memory",
     .scenes = "scenes/real/ (McGuire's Cornell boxes, the teapot, CGAL's elephant and armadillo)",
     .claim = "on scenes nobody in the project wrote, every radiosity method agrees with the path tracer per "
              "surface within the stated tolerance",
     .quick = {8.0, 0, 16, NULL},
     .full = {60.0, 0, 256, NULL},
     .run = rp_exp_realscenes},
    {.name = "modelsize",
     .summary = "scanned meshes: surface-average error against time and memory for the path tracer and "
                "hierarchical radiosity on full and simplified meshes, and growth with the face count",
     .scenes = "scenes/bunny.scene, scenes/real/elephant-box.scene, scenes/real/armadillo-box.scene (full form), and "
               "the bunny at 3,000 to 1.2 million faces (CGAL simplifications and midpoint subdivisions)",
     .claim = "solving on a simplified mesh (--simplify auto) keeps the largest surface-average error within half a "
              "percentage point of the full mesh's solve on a fraction of its faces and memory, and its memory grows "
              "far slower than the face count (fitted log-log slopes with 95% intervals)",
     .own_units = 1,
     .run = rp_exp_modelsize},
};

static const rp_experiment *const experiment_list[] = {&experiments[0], &experiments[1], &experiments[2],
                                                       &experiments[3], &experiments[4], &experiments[5],
                                                       &experiments[6], &experiments[7], &experiments[8],
                                                       &experiments[9], &experiments[10], NULL};

const rp_experiment *const *rp_experiments(void) { return experiment_list; }

const rp_experiment *rp_experiment_lookup(const char *name)
{
    for (const rp_experiment *const *e = experiment_list; *e; e++)
        if (strcmp((*e)->name, name) == 0)
            return *e;
    return NULL;
}
