/* Output files (files.h): directories, atomic text files, JSON strings. */
#include "bench/report/files.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

rp_status rp_mkdirs(const char *path, rp_error *err)
{
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

rp_status rp_out_open(rp_out *o, const char *path, rp_error *err)
{
    memset(o, 0, sizeof *o);
    snprintf(o->path, sizeof o->path, "%s", path);
    snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%ld", path, (long)getpid());
    o->f = fopen(o->tmp, "w");
    if (!o->f)
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot write: %s", o->tmp, strerror(errno));
    return RP_OK;
}

rp_status rp_out_close(rp_out *o, int ok, rp_error *err)
{
    if (!o->f)
        return RP_OK;
    int bad = ferror(o->f);
    bad |= fclose(o->f) != 0;
    o->f = NULL;
    if (!ok || bad) {
        unlink(o->tmp);
        return ok ? rp_error_set(err, RP_ERR_RUNTIME, "%s: write failed", o->path) : RP_OK;
    }
    if (rename(o->tmp, o->path) != 0) {
        unlink(o->tmp);
        return rp_error_set(err, RP_ERR_RUNTIME, "%s: cannot rename the temporary file into place: %s", o->path,
                            strerror(errno));
    }
    return RP_OK;
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
