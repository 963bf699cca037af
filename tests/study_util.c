/* Comparing a study's output with another run's (study_util.h). */
#include "study_util.h"

#include <criterion/criterion.h>
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* 1 when the n characters at s contain word. */
static int holds(const char *s, size_t n, const char *word)
{
    size_t w = strlen(word);
    for (size_t i = 0; i + w <= n; i++)
        if (!strncmp(s + i, word, w))
            return 1;
    return 0;
}

/* A CSV without its measured columns (those whose header names a time:
 * "second", "wall_s", "cpu_s", "measure_s"; or where and how it ran:
 * "rank", "threads", "_mb"); quoted fields may hold commas. */
static char *computed_columns(const char *path)
{
    static const char *measured[] = {"second", "wall_s", "cpu_s", "measure_s", "rank", "threads", "_mb"};
    char *csv = rp_read_file(path);
    cr_assert_not_null(csv, "%s", path);
    /* each field kept is followed by ',' (and the line's end by '\n') */
    char *out = malloc(2 * strlen(csv) + 2), *o = out;
    cr_assert_not_null(out);
    unsigned long long drop = 0; /* bit c: column c is dropped */
    int col = 0, header = 1, quoted = 0;
    const char *field = csv;
    for (const char *c = csv;; c++) {
        if (*c == '"')
            quoted = !quoted;
        if (*c && (quoted || (*c != ',' && *c != '\n')))
            continue;
        size_t len = (size_t)(c - field);
        if (header)
            for (size_t m = 0; m < sizeof measured / sizeof measured[0]; m++)
                if (col < 64 && holds(field, len, measured[m]))
                    drop |= 1ull << col;
        if (col >= 64 || !(drop >> col & 1)) {
            memcpy(o, field, len);
            o += len;
            *o++ = ',';
        }
        if (!*c)
            break;
        if (*c == '\n') {
            *o++ = '\n';
            header = col = 0;
        } else
            col++;
        field = c + 1;
    }
    *o = '\0';
    free(csv);
    return out;
}

/* The first line where x and y differ, both as written (without their
 * ends), into ox and oy; the line's number (1 for the header). */
static int first_difference(const char *x, const char *y, char *ox, size_t nx, char *oy, size_t ny)
{
    int line = 1;
    const char *lx = x, *ly = y;
    for (; *x && *x == *y; x++, y++)
        if (*x == '\n') {
            line++;
            lx = x + 1;
            ly = y + 1;
        }
    snprintf(ox, nx, "%.*s", (int)strcspn(lx, "\n"), lx);
    snprintf(oy, ny, "%.*s", (int)strcspn(ly, "\n"), ly);
    return line;
}

int rp_study_same_tables(const char *a, const char *b, const char *what)
{
    /* b's name is written over a's in place below */
    cr_assert_eq(strlen(a), strlen(b), "%s and %s: names of different lengths", a, b);
    cr_assert(strcmp(a, b), "%s twice", a);
    DIR *d = opendir(a);
    cr_assert_not_null(d, "%s", a);
    int n = 0;
    for (struct dirent *e; (e = readdir(d));) {
        size_t len = strlen(e->d_name);
        if (len < 5 || strcmp(e->d_name + len - 4, ".csv"))
            continue;
        char pa[512], pb[512];
        snprintf(pa, sizeof pa, "%s/%s", a, e->d_name);
        snprintf(pb, sizeof pb, "%s/%s", b, e->d_name);
        /* stability's furnace runs race a 0.7 s clock (stochastic-jacobi
         * always ends there, hierarchical at rho 0.999 needs 0.5 s of it):
         * on a loaded machine their counts differ from run to run */
        if (!strcmp(e->d_name, "reflectance.csv"))
            continue;
        char *x = computed_columns(pa), *y = computed_columns(pb);
        /* messages may name the study's directory */
        for (char *at; (at = strstr(y, b));)
            memcpy(at, a, strlen(a));
        if (strcmp(x, y)) {
            /* the first line that differs, so that a failure says where */
            char lx[600], ly[600];
            int line = first_difference(x, y, lx, sizeof lx, ly, sizeof ly);
            cr_expect_fail("%s: %s differs from the plain run's at line %d (measured columns left out):\n  plain:   "
                           "%s\n  this run: %s",
                           what, e->d_name, line, lx, ly);
        }
        free(x);
        free(y);
        n++;
    }
    closedir(d);
    return n;
}

long rp_study_computed_units(const rp_run *r, long *n)
{
    const char *text = strstr(r->out, "this rank computed ") ? r->out : r->err;
    const char *at = strstr(text, "this rank computed ");
    cr_assert_not_null(at, "no hand-out in the log:\n%s\n%s", r->out, r->err);
    long m = -1;
    cr_assert_eq(sscanf(at, "this rank computed %ld of %ld units", &m, n), 2, "%s", at);
    return m;
}

void rp_study_cut_journal(const char *from, const char *dir, size_t keep)
{
    char path[200];
    snprintf(path, sizeof path, "%s/journal.txt", from);
    char *j = rp_read_file(path);
    cr_assert_not_null(j, "%s", path);
    char *c = j;
    for (size_t line = 0; line < 2 + keep; line++) {
        c = strchr(c, '\n');
        cr_assert_not_null(c, "%s has fewer than %zu records", path, keep);
        c++;
    }
    cr_assert(mkdir(dir, 0777) == 0 || errno == EEXIST, "%s", dir);
    snprintf(path, sizeof path, "%s/journal.txt", dir);
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    fwrite(j, 1, (size_t)(c - j), f);
    fclose(f);
    free(j);
}
