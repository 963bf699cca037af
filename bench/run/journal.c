/* A study's journal (journal.h). */
#include "bench/run/journal.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bench/report/files.h"
#include "bench/run/mpi.h"

#define JOURNAL_MAGIC "radpt-journal 1"

typedef struct record {
    char *key;
    char *payload;
} record;

struct rp_journal {
    char dir[1024];
    char path[1100];
    char wpath[1100]; /* where this process appends: path, or its rank's side journal */
    int fd;
    record *rec;
    size_t n, cap, loaded;
};

static record *find(const rp_journal *j, const char *key)
{
    /* newest first: a key recorded twice keeps the later payload */
    for (size_t i = j->n; i-- > 0;)
        if (strcmp(j->rec[i].key, key) == 0)
            return &j->rec[i];
    return NULL;
}

static rp_status add(rp_journal *j, const char *key, size_t klen, const char *payload, size_t plen,
                     rp_error *err)
{
    if (j->n == j->cap) {
        size_t cap = j->cap ? 2 * j->cap : 64;
        record *r = realloc(j->rec, cap * sizeof *r);
        if (!r)
            return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the journal");
        j->rec = r;
        j->cap = cap;
    }
    record *r = &j->rec[j->n];
    r->key = strndup(key, klen);
    r->payload = strndup(payload, plen);
    if (!r->key || !r->payload) {
        free(r->key);
        free(r->payload);
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory for the journal");
    }
    j->n++;
    return RP_OK;
}

/* Reads an existing journal file: its identity must match; whole records
 * load. */
static rp_status load_file(rp_journal *j, const char *path, const char *identity, rp_error *err)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot resume: %s (was the study started with -o on this "
                                               "directory?)", path, strerror(errno));
    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    rp_status st = RP_OK;
    size_t lineno = 0;
    while (st == RP_OK && (len = getline(&line, &cap, f)) >= 0) {
        lineno++;
        if (len == 0 || line[len - 1] != '\n')
            break; /* a record cut short by a crash: not finished */
        line[--len] = '\0';
        if (lineno == 1) {
            if (strcmp(line, JOURNAL_MAGIC) != 0)
                st = rp_error_set(err, RP_ERR_INPUT, "%s:1: not a radpt journal", path);
            continue;
        }
        if (lineno == 2) {
            if (strncmp(line, "identity ", 9) != 0)
                st = rp_error_set(err, RP_ERR_INPUT, "%s:2: no identity line", path);
            else if (strcmp(line + 9, identity) != 0)
                st = rp_error_set(err, RP_ERR_INPUT,
                                  "%s: cannot resume: the study there is '%s', this one is '%s' (same command, "
                                  "options and scenes needed; or start afresh with -o)",
                                  path, line + 9, identity);
            continue;
        }
        char *tab = strchr(line, '\t');
        if (!tab) {
            st = rp_error_set(err, RP_ERR_INPUT, "%s:%zu: malformed record (no tab)", path, lineno);
            break;
        }
        st = add(j, line, (size_t)(tab - line), tab + 1, strlen(tab + 1), err);
    }
    if (st == RP_OK && lineno < 2)
        st = rp_error_set(err, RP_ERR_INPUT, "%s: cannot resume: the journal has no head", path);
    free(line);
    fclose(f);
    return st;
}

/* DIR/journal.rank-R.txt: where MPI rank R > 0 records the units it
 * finishes, the moment it finishes them (mpirun kills ranks a second after
 * Ctrl-C, before they could hand their records to rank 0). */
static const char *side_path(const rp_journal *j, int rank, char *buf, size_t n)
{
    char name[64];
    snprintf(name, sizeof name, "journal.rank-%d.txt", rank);
    return rp_path_join(buf, n, j->dir, name);
}

static int is_side_name(const char *name)
{
    int rank, end = 0;
    return sscanf(name, "journal.rank-%d.txt%n", &rank, &end) == 1 && end > 0 && name[end] == '\0' && rank > 0;
}

/* The journal and, after it, every rank's side journal of the same study
 * (one of another study, left in the directory, is skipped). */
static rp_status load(rp_journal *j, const char *identity, rp_error *err)
{
    rp_status st = load_file(j, j->path, identity, err);
    DIR *d = st == RP_OK ? opendir(j->dir) : NULL;
    for (struct dirent *e; d && st == RP_OK && (e = readdir(d));) {
        if (!is_side_name(e->d_name))
            continue;
        char path[1100];
        rp_error serr;
        size_t n = j->n;
        if (load_file(j, rp_path_join(path, sizeof path, j->dir, e->d_name), identity, &serr) != RP_OK) {
            while (j->n > n) { /* not this study's: none of its records */
                j->n--;
                free(j->rec[j->n].key);
                free(j->rec[j->n].payload);
            }
        }
    }
    if (d)
        closedir(d);
    j->loaded = j->n;
    return st;
}

static rp_status write_all(rp_journal *j, const char *buf, size_t n, rp_error *err)
{
    while (n) {
        ssize_t w = write(j->fd, buf, n);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot write: %s", j->wpath, strerror(errno));
        buf += w;
        n -= (size_t)w;
    }
    if (fsync(j->fd) != 0 && errno != EINVAL)
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot sync: %s", j->wpath, strerror(errno));
    return RP_OK;
}

static rp_status write_head(rp_journal *j, const char *identity, rp_error *err)
{
    size_t n = strlen(JOURNAL_MAGIC) + strlen(identity) + 16;
    char *head = malloc(n);
    if (!head)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    snprintf(head, n, "%s\nidentity %s\n", JOURNAL_MAGIC, identity);
    rp_status st = write_all(j, head, strlen(head), err);
    free(head);
    return st;
}

rp_status rp_journal_open(const char *dir, const char *identity, int resume, rp_journal **out, rp_error *err)
{
    *out = NULL;
    if (strchr(identity, '\n'))
        return rp_error_set(err, RP_ERR_INPUT, "journal identity must be one line");
    rp_journal *j = calloc(1, sizeof *j);
    if (!j)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    j->fd = -1;
    snprintf(j->dir, sizeof j->dir, "%s", dir);
    rp_path_join(j->path, sizeof j->path, dir, "journal.txt");
    rp_status st = RP_OK;
    /* MPI ranks other than 0 read the journal but append to their own side
     * journal, which every rank reads back on --resume */
    int rank = rp_mpi_rank();
    if (rank > 0)
        side_path(j, rank, j->wpath, sizeof j->wpath);
    else
        snprintf(j->wpath, sizeof j->wpath, "%s", j->path);
    const char *wpath = j->wpath;
    /* the directory may not be there yet when rank 0 makes it */
    rp_files_own(1);
    st = rank > 0 ? rp_mkdirs(dir, err) : RP_OK;
    rp_files_own(0);
    if (st != RP_OK) {
        rp_journal_close(j);
        return st;
    }
    if (resume && rank > 0) {
        st = load(j, identity, err);
        /* this rank's side journal goes on after what it holds */
        struct stat sb;
        int fresh = stat(wpath, &sb) != 0 || sb.st_size == 0;
        if (st == RP_OK && (j->fd = open(wpath, O_WRONLY | O_CREAT | O_APPEND, 0666)) < 0)
            st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot open: %s", wpath, strerror(errno));
        if (st == RP_OK && fresh)
            st = write_head(j, identity, err);
    } else if (resume) {
        st = load(j, identity, err);
        if (st == RP_OK) {
            /* a torn last record is dropped from the file by rewriting the
             * records read (atomically, files.h), then appending goes on
             * after them */
            rp_out o;
            st = rp_out_open(&o, j->path, err);
            if (st == RP_OK) {
                fprintf(o.f, "%s\nidentity %s\n", JOURNAL_MAGIC, identity);
                for (size_t i = 0; i < j->n; i++)
                    fprintf(o.f, "%s\t%s\n", j->rec[i].key, j->rec[i].payload);
                st = rp_out_close(&o, 1, err);
            }
        }
        if (st == RP_OK && (j->fd = open(wpath, O_WRONLY | O_APPEND)) < 0)
            st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot open: %s", j->path, strerror(errno));
    } else {
        j->fd = open(wpath, O_WRONLY | O_CREAT | O_TRUNC, 0666);
        if (j->fd < 0)
            st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot create: %s", wpath, strerror(errno));
        if (st == RP_OK)
            st = write_head(j, identity, err);
    }
    if (st != RP_OK) {
        rp_journal_close(j);
        return st;
    }
    *out = j;
    return RP_OK;
}

void rp_journal_close(rp_journal *j)
{
    if (!j)
        return;
    if (j->fd >= 0)
        close(j->fd);
    for (size_t i = 0; i < j->n; i++) {
        free(j->rec[i].key);
        free(j->rec[i].payload);
    }
    free(j->rec);
    free(j);
}

const char *rp_journal_get(const rp_journal *j, const char *key)
{
    if (!j)
        return NULL;
    const record *r = find(j, key);
    return r ? r->payload : NULL;
}

rp_status rp_journal_put(rp_journal *j, const char *key, const char *payload, rp_error *err)
{
    if (!j)
        return RP_OK;
    if (strpbrk(key, "\t\n") || strchr(payload, '\n') || !*key)
        return rp_error_set(err, RP_ERR_INPUT, "journal key '%s': empty, or a tab or newline in key or payload",
                            key);
    size_t kl = strlen(key), pl = strlen(payload);
    char *line = malloc(kl + pl + 2);
    if (!line)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    memcpy(line, key, kl);
    line[kl] = '\t';
    memcpy(line + kl + 1, payload, pl);
    line[kl + 1 + pl] = '\n';
    rp_status st = write_all(j, line, kl + pl + 2, err);
    free(line);
    if (st == RP_OK)
        st = add(j, key, kl, payload, pl, err);
    return st;
}

rp_status rp_journal_put_doubles(rp_journal *j, const char *key, const double *v, size_t n, rp_error *err)
{
    if (!j)
        return RP_OK;
    size_t cap = 26 * (n + 1);
    char *buf = malloc(cap);
    if (!buf)
        return rp_error_set(err, RP_ERR_NOMEM, "out of memory");
    size_t used = 0;
    buf[0] = '\0';
    for (size_t i = 0; i < n; i++)
        used += (size_t)snprintf(buf + used, cap - used, "%s%.17g", i ? " " : "", v[i]);
    rp_status st = rp_journal_put(j, key, buf, err);
    free(buf);
    return st;
}

int rp_journal_get_doubles(const rp_journal *j, const char *key, double *v, size_t n)
{
    const char *p = rp_journal_get(j, key);
    if (!p)
        return 0;
    for (size_t i = 0; i < n; i++) {
        char *end;
        double x = strtod(p, &end);
        if (end == p)
            return 0;
        v[i] = x;
        p = end;
    }
    while (*p == ' ')
        p++;
    return *p == '\0';
}

size_t rp_journal_count(const rp_journal *j) { return j ? j->n : 0; }
size_t rp_journal_resumed(const rp_journal *j) { return j ? j->loaded : 0; }
void rp_journal_tidy(rp_journal *j)
{
    if (!j || rp_mpi_rank() > 0)
        return;
    DIR *d = opendir(j->dir);
    for (struct dirent *e; d && (e = readdir(d));) {
        char path[1100];
        if (is_side_name(e->d_name))
            unlink(rp_path_join(path, sizeof path, j->dir, e->d_name));
    }
    if (d)
        closedir(d);
}

void rp_journal_record(const rp_journal *j, size_t i, const char **key, const char **payload)
{
    *key = j->rec[i].key;
    *payload = j->rec[i].payload;
}

const char *rp_journal_path(const rp_journal *j) { return j ? j->path : ""; }
