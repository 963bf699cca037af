/* Checkpoint files (resume.h). */
#include "bench/run/resume.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench/report/plot.h"

#define MAGIC_LINE "radpt-checkpoint"

rp_status rp_resume_save(const char *path, const rp_resume_info *info, const rp_solver *solver,
                         rp_error *err)
{
    rp_out o;
    rp_status st = rp_out_open(&o, path, err);
    if (st != RP_OK)
        return st;
    FILE *f = o.f;
    /* scene and options are free text: keep them on one line */
    char scene[sizeof info->scene], options[sizeof info->options];
    snprintf(scene, sizeof scene, "%s", info->scene);
    snprintf(options, sizeof options, "%s", info->options);
    scene[strcspn(scene, "\r\n")] = '\0';
    options[strcspn(options, "\r\n")] = '\0';
    fprintf(f, "%s %d\n", MAGIC_LINE, RP_RESUME_FORMAT);
    fprintf(f, "scene %s\nscene_hash %s\nmethod %s\noptions %s\nseed %" PRIu64 "\nsize %" PRIu32 " %" PRIu32
               "\nbands %zu\n",
            scene, info->scene_hash, info->method, options, info->seed, info->width, info->height,
            info->nbands);
    fprintf(f, "steps %.17g\niterations %.17g\nrays %.17g\npaths %.17g\nform_factors %.17g\nseconds %.17g\n\n",
            info->steps, info->iterations, info->rays, info->paths, info->form_factors, info->seconds);
    st = rp_solver_save(solver, f, err);
    rp_status cst = rp_out_close(&o, st == RP_OK, err);
    return st != RP_OK ? st : cst;
}

/* One "key value" header line into value (without the newline); -1 when
 * the line is missing, too long or has another key. */
static int header_line(FILE *f, const char *key, char *value, size_t n)
{
    char line[1600];
    if (!fgets(line, sizeof line, f))
        return -1;
    size_t len = strlen(line);
    if (len == 0 || line[len - 1] != '\n')
        return -1;
    line[len - 1] = '\0';
    size_t k = strlen(key);
    if (strncmp(line, key, k) != 0 || (line[k] != ' ' && line[k] != '\0'))
        return -1;
    const char *v = line[k] ? line + k + 1 : line + k;
    if (strlen(v) >= n)
        return -1;
    strcpy(value, v);
    return 0;
}

static int parse_number(const char *s, double *out)
{
    char *end;
    errno = 0;
    *out = strtod(s, &end);
    return end == s || *end || errno ? -1 : 0;
}

static rp_status corrupt(const char *path, const char *what, rp_error *err)
{
    return rp_error_set(err, RP_ERR_INPUT, "%s: not a radpt checkpoint, or truncated or corrupt (%s)", path, what);
}

static rp_status read_header(FILE *f, const char *path, rp_resume_info *got, rp_error *err)
{
    char v[1600];
    char expect_magic[64];
    snprintf(expect_magic, sizeof expect_magic, "%d", RP_RESUME_FORMAT);
    if (header_line(f, MAGIC_LINE, v, sizeof v) != 0)
        return corrupt(path, "first line", err);
    if (strcmp(v, expect_magic) != 0)
        return rp_error_set(err, RP_ERR_INPUT, "%s: checkpoint format %s, this radpt reads format %d", path, v,
                            RP_RESUME_FORMAT);
    if (header_line(f, "scene", got->scene, sizeof got->scene) != 0)
        return corrupt(path, "scene", err);
    if (header_line(f, "scene_hash", got->scene_hash, sizeof got->scene_hash) != 0 ||
        strlen(got->scene_hash) != 16)
        return corrupt(path, "scene_hash", err);
    if (header_line(f, "method", got->method, sizeof got->method) != 0)
        return corrupt(path, "method", err);
    if (header_line(f, "options", got->options, sizeof got->options) != 0)
        return corrupt(path, "options", err);
    char *end;
    if (header_line(f, "seed", v, sizeof v) != 0 || v[0] == '-' || (errno = 0, got->seed = strtoull(v, &end, 10),
                                                                    end == v || *end || errno))
        return corrupt(path, "seed", err);
    unsigned long w, h;
    int used = 0;
    if (header_line(f, "size", v, sizeof v) != 0 || sscanf(v, "%lu %lu%n", &w, &h, &used) != 2 || v[used] ||
        w > UINT32_MAX || h > UINT32_MAX)
        return corrupt(path, "size", err);
    got->width = (uint32_t)w;
    got->height = (uint32_t)h;
    double x;
    if (header_line(f, "bands", v, sizeof v) != 0 || parse_number(v, &x) != 0 || x < 1 || x > 1e6)
        return corrupt(path, "bands", err);
    got->nbands = (size_t)x;
    static const char *const keys[] = {"steps", "iterations", "rays", "paths", "form_factors", "seconds"};
    double *dst[] = {&got->steps, &got->iterations, &got->rays, &got->paths, &got->form_factors, &got->seconds};
    for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++)
        if (header_line(f, keys[i], v, sizeof v) != 0 || parse_number(v, dst[i]) != 0 || !(*dst[i] >= 0))
            return corrupt(path, keys[i], err);
    if (!fgets(v, sizeof v, f) || strcmp(v, "\n") != 0)
        return corrupt(path, "end of header", err);
    return RP_OK;
}

rp_status rp_resume_load(const char *path, const rp_resume_info *expect, rp_resume_info *got,
                         rp_solver *solver, rp_step_info *last, rp_error *err)
{
    memset(got, 0, sizeof *got);
    FILE *f = fopen(path, "rb");
    if (!f)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot open the checkpoint: %s", path, strerror(errno));
    rp_status st = read_header(f, path, got, err);
    if (st == RP_OK && strcmp(got->method, expect->method) != 0)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the checkpoint is of method %s, this run uses %s", path,
                          got->method, expect->method);
    else if (st == RP_OK && strcmp(got->scene_hash, expect->scene_hash) != 0)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the checkpoint is of another scene (%s, hash %s; this scene's "
                          "hash is %s)", path, got->scene, got->scene_hash, expect->scene_hash);
    else if (st == RP_OK && got->seed != expect->seed)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the checkpoint has --seed %" PRIu64 ", this run --seed %" PRIu64,
                          path, got->seed, expect->seed);
    else if (st == RP_OK && (got->width != expect->width || got->height != expect->height))
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the checkpoint's image is %" PRIu32 " x %" PRIu32 ", this run's %"
                          PRIu32 " x %" PRIu32, path, got->width, got->height, expect->width, expect->height);
    else if (st == RP_OK && got->nbands != expect->nbands)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: the checkpoint has %zu bands, this scene %zu", path, got->nbands,
                          expect->nbands);
    if (st == RP_OK) {
        rp_error e2;
        st = rp_solver_load(solver, f, last, &e2);
        if (st == RP_OK && fgetc(f) != EOF)
            st = rp_error_set(&e2, RP_ERR_INPUT, "trailing bytes after the solver state");
        if (st != RP_OK)
            rp_error_set(err, st, "%s: %s (the checkpoint was made with: %s)", path, e2.message,
                         got->options[0] ? got->options : "default options");
    }
    fclose(f);
    return st;
}
