/* Output files (files.h): directories, atomic text files, JSON strings. */
#include "bench/report/files.h"

#include <errno.h>
#include <fcntl.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Set on MPI ranks other than 0 (bench/run/mpi.c): rank 0 owns the files.
 * Writers run as usual (a checkpoint's save is collective) but write to
 * /dev/null, and no directory is made. */
static int discarding;

void rp_files_discard(int on)
{
    discarding = on;
}

int rp_files_discarding(void)
{
    return discarding;
}

/* rp_files_own: this rank writes its own files for now. */
static int own;

void rp_files_own(int on)
{
    own = on;
}

/* rp_files_discard_under's directory ("": none). */
static char held[1024];

void rp_files_discard_under(const char *dir)
{
    snprintf(held, sizeof held, "%s", dir ? dir : "");
    size_t n = strlen(held);
    while (n > 1 && held[n - 1] == '/')
        held[--n] = '\0';
}

int rp_files_discarded(const char *path)
{
    size_t n = strlen(held);
    return (discarding && !own) || (n && strncmp(path, held, n) == 0 && (path[n] == '/' || path[n] == '\0'));
}

rp_status rp_mkdirs(const char *path, rp_error *err)
{
    if (discarding && !own)
        return RP_OK;
    char buf[1024];
    size_t n = strlen(path);
    if (n == 0 || n >= sizeof buf)
        return rp_error_set(err, RP_ERR_INPUT, "bad directory name '%s'", path);
    memcpy(buf, path, n + 1);
    for (size_t i = 1; i <= n; i++) {
        if (buf[i] != '/' && buf[i] != '\0')
            continue;
        char c = buf[i];
        buf[i] = '\0';
        if (mkdir(buf, 0777) != 0 && errno != EEXIST)
            return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot create the directory: %s", buf, strerror(errno));
        buf[i] = c;
    }
    struct stat sb;
    if (stat(path, &sb) != 0 || !S_ISDIR(sb.st_mode))
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: not a directory", path);
    return RP_OK;
}

const char *rp_path_join(char *buf, size_t n, const char *dir, const char *name)
{
    size_t d = strlen(dir);
    if (d == 0)
        snprintf(buf, n, "%s", name);
    else
        snprintf(buf, n, "%s%s%s", dir, dir[d - 1] == '/' ? "" : "/", name);
    return buf;
}

/* Opens a fresh PATH.tmp.PID.N for writing; the name goes to *tmp_out
 * (malloc'd).  Mode 0666 lets the umask decide the final permissions, as
 * for any ordinary file the program creates. */
rp_status rp_temp_open(const char *path, int *fd_out, char **tmp_out, rp_error *err)
{
    static atomic_uint counter;
    if (rp_files_discarded(path)) {
        int fd = open("/dev/null", O_WRONLY | O_CLOEXEC);
        if (fd < 0)
            return rp_error_set(err, RP_ERR_RUNTIME, "/dev/null: %s", strerror(errno));
        *fd_out = fd;
        *tmp_out = NULL;
        return RP_OK;
    }
    size_t n = strlen(path) + 64;
    char *tmp = malloc(n);
    if (!tmp)
        return rp_error_set(err, RP_ERR_NOMEM, "%s: out of memory", path);
    for (int attempt = 0; attempt < 1000; attempt++) {
        unsigned k = atomic_fetch_add(&counter, 1u);
        snprintf(tmp, n, "%s.tmp.%ld.%u", path, (long)getpid(), k);
        int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd >= 0) {
            *fd_out = fd;
            *tmp_out = tmp;
            return RP_OK;
        }
        if (errno != EEXIST)
            break;
    }
    int e = errno;
    free(tmp);
    return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot create a temporary file: %s", path,
                        strerror(e));
}

/* Flushes fd to disk, closes it and renames tmp to path; on failure removes
 * tmp.  Always frees tmp. */
rp_status rp_temp_commit(int fd, char *tmp, const char *path, rp_error *err)
{
    rp_status st = RP_OK;
    if (!tmp) { /* discarding (rp_files_discard) */
        close(fd);
        return RP_OK;
    }
    if (fsync(fd) != 0)
        st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot flush: %s", path, strerror(errno));
    if (close(fd) != 0 && st == RP_OK)
        st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot close: %s", path, strerror(errno));
    if (st == RP_OK && rename(tmp, path) != 0)
        st = rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot rename the temporary file into place: %s",
                          path, strerror(errno));
    if (st != RP_OK)
        unlink(tmp);
    free(tmp);
    return st;
}

/* Gives up on a temporary file. */
void rp_temp_discard(int fd, char *tmp)
{
    if (fd >= 0)
        close(fd);
    if (tmp)
        unlink(tmp);
    free(tmp);
}

rp_status rp_out_open(rp_out *o, const char *path, rp_error *err)
{
    memset(o, 0, sizeof *o);
    snprintf(o->path, sizeof o->path, "%s", path);
    int fd = -1;
    char *tmp = NULL;
    rp_status st = rp_temp_open(path, &fd, &tmp, err);
    if (st != RP_OK)
        return st;
    snprintf(o->tmp, sizeof o->tmp, "%s", tmp ? tmp : ""); /* "": discarding */
    free(tmp);
    o->f = fdopen(fd, "w");
    if (!o->f) {
        close(fd);
        if (o->tmp[0])
            unlink(o->tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot write: %s", o->tmp, strerror(errno));
    }
    return RP_OK;
}

rp_status rp_out_close(rp_out *o, int ok, rp_error *err)
{
    if (!o->f)
        return RP_OK;
    int bad = fflush(o->f) != 0 || ferror(o->f);
    int fd = dup(fileno(o->f));
    bad |= fclose(o->f) != 0;
    o->f = NULL;
    char *tmp = o->tmp[0] ? strdup(o->tmp) : NULL;
    if (!ok || bad || fd < 0 || (o->tmp[0] && !tmp)) {
        rp_temp_discard(fd, tmp);
        return ok ? rp_error_set(err, RP_ERR_RUNTIME, "%s: write failed", o->path) : RP_OK;
    }
    return rp_temp_commit(fd, tmp, o->path, err);
}

void rp_json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (const unsigned char *c = (const unsigned char *)s; *c; c++) {
        if (*c == '"' || *c == '\\')
            fprintf(f, "\\%c", *c);
        else if (*c < 0x20)
            fprintf(f, "\\u%04x", *c);
        else
            fputc(*c, f);
    }
    fputc('"', f);
}
