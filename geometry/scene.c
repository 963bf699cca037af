/* The scene model and its two readers: scene format 1 (docs/design.md, "Scene
 * files") and Wavefront OBJ/MTL through the CGAL shim.
 *
 * Choices the format leaves open, made here:
 *
 * - A scene without a `bands` statement is grey (one band).
 * - Statements may come in any order except that `bands` precedes every
 *   material and a material is declared before a surface uses it.  At most
 *   one `bands` and one `camera` statement.  Paths (include, mesh) contain no
 *   white space and are relative to the directory of the file naming them.
 * - Numbers are whole tokens read by strtod (decimal, no hex); NaN and
 *   infinities are refused.
 * - `reflect` / `emit` spectra `nm:value` are piecewise linear, constant
 *   beyond the end points, and reduced to the scene's bands as follows:
 *   spectral: sampled at each band's wavelength; grey: mean over 400-700 nm;
 *   rgb: box means, B over 400-500, G over 500-600, R over 600-700 nm.  The
 *   box filter is a crude stand-in for colour matching, but it keeps
 *   reflectance in [0, 1], maps a flat spectrum to the same value in every
 *   band, and maps the Cornell light's measured emission (400:0 500:8
 *   600:15.6 700:18.4) to (17, 11.8, 4), the RGB radiance in common use.
 * - Degenerate faces: a triangle whose edge vectors have a cross product
 *   below 1e-10 of its longest edge squared (angle below 1e-10 rad) or a
 *   quad whose diagonals do likewise; and any face whose area is below
 *   (1e-9 * its own largest coordinate)^2: a speck whose edges, normal and
 *   area would be the rounding of its corners (relative error above about
 *   2e-7).  Neither test looks at the rest of the scene, so adding a huge
 *   ground plane refuses nothing.
 * - rp_scene_is_closed welds corners closer than 1e-7 of the shortest edge
 *   in the scene: far below any real feature (no face can collapse), yet
 *   far above the rounding of generated corners.
 * - Quads: planar when the two diagonals are at most 1e-6 of the longer
 *   diagonal apart along the quad's normal (the normal is the direction of
 *   diagonal x diagonal, so the twist is |(v1 - v0) . n|).  At that twist the
 *   area formula (half the diagonals' cross product) and the bilinear
 *   parametrisation are off by O(1e-12) relative; any quad written with 7
 *   or more significant digits passes, and the Cornell red wall (one corner
 *   3.2 mm off the plane of the others) is refused.  Convex when every
 *   corner turns the same way as the normal, by more than 1e-10 rad.
 * - `reflect` lies in [0, 1]: 1 is a perfect reflector, as an MTL's Kd 1
 *   is.  A closed scene that reflects 1 on every surface in a band where it
 *   emits is refused: its radiance is infinite (L = Le / (1 - rho)).  The
 *   exact furnace reference refuses rho = 1 as well.
 * - Meshes: zero-area faces and exact duplicates (same positions, same
 *   winding) are dropped by the reader, with one warning per kind naming
 *   the first one's line.  `mesh NAME MATERIAL FILE` is one surface: edges
 *   used twice in the same direction are an error (its faces must agree on
 *   their front).  `mesh NAME mtl FILE.obj` places an OBJ scene with its own
 *   MTL materials, named "NAME/material", and surfaces "NAME/group" (as an
 *   OBJ scene's, below).  Its RGB enters a grey scene as Rec. 709 luminance
 *   (0.2126 R + 0.7152 G + 0.0722 B); a spectral scene refuses it, as an RGB
 *   colour has no one spectrum.  `mtl` cannot name a material.
 * - OBJ scenes are rgb, without a camera.  Each (group, MTL material) pair
 *   is a surface named after the group (o or g; "default" before any), or
 *   "group.material" when the group mixes materials; a name already taken
 *   gets "~2", "~3", ... appended.  Kd is reflect, Ke is emit (a material
 *   with both is a light that reflects).  A face without a material is
 *   refused: no default reflectance is made up.  Faces keep their own
 *   winding; inconsistent orientation is a warning (with the line of the
 *   first face concerned), as an OBJ scene is many authored surfaces rather
 *   than one skin.  What the reader ignores (Ks, Ns, maps, vt, vn, ...) is
 *   listed in one warning per file.  Warnings live in the scene
 *   (rp_scene_warning); nothing here prints them. */
/* realpath (include cycles) is an X/Open extension in glibc. */
#define _XOPEN_SOURCE 700

#include "scene.h"

#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cgal/import.h"
#include "hash.h"

#define RELATIVE_COLLINEAR 1e-10 /* sine of the smallest corner angle */
#define RELATIVE_TWIST 1e-6      /* quad twist / longest diagonal */
#define RELATIVE_WELD 1e-7       /* weld tolerance / shortest edge */
#define RELATIVE_SPECK 1e-9      /* smallest face size / its largest coordinate */
#define MAX_INCLUDE_DEPTH 64
#define MAX_IMAGE_SIZE 65536

/* The grey and RGB reductions of a spectrum (see the comment above). */
#define VISIBLE_LO 400.0
#define VISIBLE_HI 700.0

struct rp_scene {
    rp_band_kind band_kind;
    size_t nbands;
    double *wavelengths;

    rp_material *materials; /* names, rho, Le owned */
    size_t nmaterials, cap_materials;
    rp_surface *surfaces; /* names owned; file points into files */
    size_t nsurfaces, cap_surfaces;
    rp_face *faces;
    size_t nfaces, cap_faces;
    rp_vec3 *vertices;
    size_t nvertices, cap_vertices;

    int has_camera;
    rp_camera camera;

    char **files; /* every file name a surface or camera may cite */
    size_t nfiles, cap_files;

    char **warnings; /* "FILE:LINE: what", in the order found */
    size_t nwarnings, cap_warnings;

    rp_vec3 lo, hi;
    double total_area;
};

/* ---------------------------------------------------------------- memory */

static int grow(void **p, size_t *cap, size_t need, size_t elem)
{
    if (need <= *cap)
        return 1;
    size_t n = *cap ? *cap : 16;
    while (n < need) {
        if (n > SIZE_MAX / 2 / elem)
            return 0;
        n *= 2;
    }
    void *q = realloc(*p, n * elem);
    if (!q)
        return 0;
    *p = q;
    *cap = n;
    return 1;
}

static char *dup_string(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d)
        memcpy(d, s, n);
    return d;
}

void rp_scene_destroy(rp_scene *s)
{
    if (!s)
        return;
    free(s->wavelengths);
    for (size_t i = 0; i < s->nmaterials; i++) {
        free((void *)s->materials[i].name);
        free((void *)s->materials[i].rho);
        free((void *)s->materials[i].Le);
    }
    free(s->materials);
    for (size_t i = 0; i < s->nsurfaces; i++)
        free((void *)s->surfaces[i].name);
    free(s->surfaces);
    free(s->faces);
    free(s->vertices);
    for (size_t i = 0; i < s->nfiles; i++)
        free(s->files[i]);
    free(s->files);
    for (size_t i = 0; i < s->nwarnings; i++)
        free(s->warnings[i]);
    free(s->warnings);
    free(s);
}

static rp_scene *scene_new(void)
{
    rp_scene *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->band_kind = RP_BANDS_GREY;
    s->nbands = 1;
    return s;
}

/* ---------------------------------------------------------------- parser */

/* One file being read: its name for messages, its directory for paths. */
typedef struct source {
    const char *name; /* owned by the scene's file list */
    char *dir;        /* NULL: current directory */
    int depth;
} source;

typedef struct parser {
    rp_scene *s;
    rp_error *err;
    char **stack; /* canonical paths of the files being read (cycles) */
    size_t nstack, cap_stack;
    int bands_declared;
    const char *bands_file;
    int bands_line;
    const char *camera_file;
    int camera_line;
} parser;

static rp_status failv(parser *p, rp_status st, const char *file, int line, const char *fmt, va_list ap)
{
    char what[768];
    vsnprintf(what, sizeof what, fmt, ap);
    if (line > 0)
        return rp_error_set(p->err, st, "%s:%d: %s", file, line, what);
    return rp_error_set(p->err, st, "%s: %s", file, what);
}

#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static rp_status fail(parser *p, const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    rp_status st = failv(p, RP_ERR_INPUT, file, line, fmt, ap);
    va_end(ap);
    return st;
}

static rp_status nomem(parser *p)
{
    return rp_error_set(p->err, RP_ERR_NOMEM, "out of memory while reading the scene");
}

/* Records a whole warning message. */
static rp_status keep_warning(parser *p, const char *text)
{
    rp_scene *s = p->s;
    char *d = dup_string(text);
    if (!d || !grow((void **)&s->warnings, &s->cap_warnings, s->nwarnings + 1, sizeof *s->warnings)) {
        free(d);
        return nomem(p);
    }
    s->warnings[s->nwarnings++] = d;
    return RP_OK;
}

/* Records a warning "FILE:LINE: what" ("FILE: what" when line is 0). */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static rp_status add_warning(parser *p, const char *file, size_t line, const char *fmt, ...)
{
    char what[1024], full[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    if (line > 0)
        snprintf(full, sizeof full, "%s:%zu: %s", file, line, what);
    else
        snprintf(full, sizeof full, "%s: %s", file, what);
    return keep_warning(p, full);
}

/* Keeps a copy of a file name for the scene's lifetime. */
static const char *keep_file_name(parser *p, const char *name)
{
    rp_scene *s = p->s;
    if (!grow((void **)&s->files, &s->cap_files, s->nfiles + 1, sizeof *s->files))
        return NULL;
    char *d = dup_string(name);
    if (!d)
        return NULL;
    s->files[s->nfiles++] = d;
    return d;
}

/* dir/path, or path itself when absolute or dir is NULL. */
static char *join_path(const char *dir, const char *path)
{
    if (!dir || !*dir || path[0] == '/')
        return dup_string(path);
    size_t a = strlen(dir), b = strlen(path);
    char *r = malloc(a + b + 2);
    if (!r)
        return NULL;
    memcpy(r, dir, a);
    r[a] = '/';
    memcpy(r + a + 1, path, b + 1);
    return r;
}

/* The directory part of path; NULL (the current directory) when there is
 * none, so that messages name "x.inc" rather than "./x.inc".  *ok is 0
 * when memory ran out. */
static char *dir_name(const char *path, int *ok)
{
    const char *slash = strrchr(path, '/');
    *ok = 1;
    if (!slash)
        return NULL;
    *ok = 0;
    size_t n = slash == path ? 1 : (size_t)(slash - path); /* "/x" lives in "/" */
    char *r = malloc(n + 1);
    if (!r)
        return NULL;
    memcpy(r, path, n);
    r[n] = '\0';
    *ok = 1;
    return r;
}

/* Reads a whole file; NULL with errno set on failure. */
/* The whole file as a string.  A NUL byte means the file is not text: NULL
 * with errno EILSEQ and the byte's line in *nul_line. */
static char *read_text(const char *path, int *nul_line)
{
    *nul_line = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    size_t cap = 1 << 16, n = 0;
    char *buf = malloc(cap);
    while (buf) {
        if (n + 1 >= cap) {
            char *q = cap > SIZE_MAX / 2 ? NULL : realloc(buf, cap * 2);
            if (!q) {
                free(buf);
                buf = NULL;
                errno = ENOMEM;
                break;
            }
            buf = q;
            cap *= 2;
        }
        size_t got = fread(buf + n, 1, cap - 1 - n, f);
        n += got;
        if (got == 0) {
            if (ferror(f)) {
                free(buf);
                buf = NULL;
                errno = EIO;
            }
            break;
        }
    }
    fclose(f);
    if (buf) {
        buf[n] = '\0';
        const char *nul = memchr(buf, '\0', n);
        if (nul) {
            *nul_line = 1;
            for (const char *c = buf; c < nul; c++)
                *nul_line += *c == '\n';
            free(buf);
            errno = EILSEQ;
            return NULL;
        }
    }
    return buf;
}

/* A whole-token decimal number.  Returns 1 and sets *v, 0 for "not a
 * number", -1 for a number that is NaN or infinite (or overflows). */
static int parse_number(const char *tok, double *v)
{
    if (!*tok || strchr(tok, 'x') || strchr(tok, 'X'))
        return 0;
    char *end;
    errno = 0;
    double x = strtod(tok, &end);
    if (end == tok || *end)
        return 0;
    if (!isfinite(x))
        return -1;
    *v = x;
    return 1;
}

static rp_status number(parser *p, const source *src, int line, const char *tok, double *v)
{
    int r = parse_number(tok, v);
    if (r > 0)
        return RP_OK;
    if (r < 0)
        return fail(p, src->name, line, "'%.64s' is not a finite number", tok);
    return fail(p, src->name, line, "'%.64s' is not a number", tok);
}

static rp_status numbers(parser *p, const source *src, int line, char **tok, size_t n, double *v)
{
    for (size_t i = 0; i < n; i++) {
        rp_status st = number(p, src, line, tok[i], &v[i]);
        if (st)
            return st;
    }
    return RP_OK;
}

static const char *band_word(const rp_scene *s)
{
    switch (s->band_kind) {
    case RP_BANDS_GREY: return "grey";
    case RP_BANDS_RGB: return "rgb";
    case RP_BANDS_SPECTRAL: return "spectral";
    }
    return "?";
}

/* ------------------------------------------------------------- spectra */

/* The piecewise linear spectrum through (nm[k], val[k]), constant beyond
 * the ends. */
static double spectrum_at(const double *nm, const double *val, size_t n, double x)
{
    if (x <= nm[0])
        return val[0];
    if (x >= nm[n - 1])
        return val[n - 1];
    size_t k = 1;
    while (nm[k] < x)
        k++;
    double t = (x - nm[k - 1]) / (nm[k] - nm[k - 1]);
    return val[k - 1] + t * (val[k] - val[k - 1]);
}

/* Mean of the spectrum over [a, b]: trapezoids between the knots inside
 * the interval, exact for a piecewise linear function. */
static double spectrum_mean(const double *nm, const double *val, size_t n, double a, double b)
{
    double sum = 0, x = a, fx = spectrum_at(nm, val, n, a);
    for (size_t k = 0; k <= n; k++) {
        double next = k < n ? nm[k] : b;
        if (next <= x)
            continue;
        if (next > b)
            next = b;
        double fn = spectrum_at(nm, val, n, next);
        sum += 0.5 * (fx + fn) * (next - x);
        x = next;
        fx = fn;
        if (x >= b)
            break;
    }
    return sum / (b - a);
}

static void spectrum_to_bands(const rp_scene *s, const double *nm, const double *val, size_t n, double *out)
{
    switch (s->band_kind) {
    case RP_BANDS_GREY:
        out[0] = spectrum_mean(nm, val, n, VISIBLE_LO, VISIBLE_HI);
        break;
    case RP_BANDS_RGB:
        out[0] = spectrum_mean(nm, val, n, 600.0, 700.0);
        out[1] = spectrum_mean(nm, val, n, 500.0, 600.0);
        out[2] = spectrum_mean(nm, val, n, 400.0, 500.0);
        break;
    case RP_BANDS_SPECTRAL:
        for (size_t i = 0; i < s->nbands; i++)
            out[i] = spectrum_at(nm, val, n, s->wavelengths[i]);
        break;
    }
}

/* ----------------------------------------------------------- statements */

static rp_status st_bands(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    rp_scene *s = p->s;
    if (p->bands_declared)
        return fail(p, src->name, line, "second 'bands' statement (the first is at %s:%d)", p->bands_file,
                    p->bands_line);
    if (s->nmaterials > 0)
        return fail(p, src->name, line, "'bands' must come before every material ('%s' is already declared)",
                    s->materials[0].name);
    if (ntok < 2)
        return fail(p, src->name, line, "'bands' needs grey, rgb or a list of wavelengths in nm");
    if (!strcmp(tok[1], "grey") || !strcmp(tok[1], "gray") || !strcmp(tok[1], "rgb")) {
        if (ntok != 2)
            return fail(p, src->name, line, "'bands %s' takes nothing after it", tok[1]);
        s->band_kind = tok[1][0] == 'r' ? RP_BANDS_RGB : RP_BANDS_GREY;
        s->nbands = tok[1][0] == 'r' ? 3 : 1;
    } else {
        size_t n = ntok - 1;
        double *w = malloc(n * sizeof *w);
        if (!w)
            return nomem(p);
        rp_status st = numbers(p, src, line, tok + 1, n, w);
        for (size_t i = 0; !st && i < n; i++) {
            if (w[i] <= 0)
                st = fail(p, src->name, line, "wavelength %g nm is not positive", w[i]);
            else if (i > 0 && w[i] <= w[i - 1])
                st = fail(p, src->name, line, "wavelengths are not ascending (%g after %g)", w[i], w[i - 1]);
        }
        if (st) {
            free(w);
            return st;
        }
        s->band_kind = RP_BANDS_SPECTRAL;
        s->nbands = n;
        s->wavelengths = w;
    }
    p->bands_declared = 1;
    p->bands_file = src->name;
    p->bands_line = line;
    return RP_OK;
}

/* A keyword ends a list of numbers: a token that starts like a word and
 * is not "nan" or "inf" (those are numbers, refused as not finite). */
static int is_word(const char *tok)
{
    double v;
    return (isalpha((unsigned char)tok[0]) || tok[0] == '_') && parse_number(tok, &v) == 0;
}

/* Reads the values after `reflect` or `emit` starting at tok[*i] into
 * out[nbands]; kind is "reflect" or "emit". */
static rp_status material_values(parser *p, const source *src, int line, char **tok, size_t ntok, size_t *i,
                                 const char *kind, double *out)
{
    rp_scene *s = p->s;
    int reflect = kind[0] == 'r';
    size_t j = *i;
    rp_status st = RP_OK;
    if (j < ntok && !strcmp(tok[j], "spectrum")) {
        j++;
        size_t first = j;
        while (j < ntok && !is_word(tok[j]))
            j++;
        size_t n = j - first;
        if (n == 0)
            return fail(p, src->name, line, "'%s spectrum' needs points nm:value", kind);
        double *nm = malloc(2 * n * sizeof *nm);
        if (!nm)
            return nomem(p);
        double *val = nm + n;
        for (size_t k = 0; !st && k < n; k++) {
            const char *t = tok[first + k];
            const char *colon = strchr(t, ':');
            char left[128];
            size_t ll = colon ? (size_t)(colon - t) : 0;
            if (!colon || strchr(colon + 1, ':') || ll == 0 || ll >= sizeof left || parse_number(colon + 1, &val[k]) <= 0) {
                st = fail(p, src->name, line, "malformed spectrum point '%.64s' (expected nm:value)", t);
                break;
            }
            memcpy(left, t, ll);
            left[ll] = '\0';
            if (parse_number(left, &nm[k]) <= 0 || nm[k] <= 0)
                st = fail(p, src->name, line, "malformed spectrum point '%.64s' (expected nm:value)", t);
            else if (k > 0 && nm[k] <= nm[k - 1])
                st = fail(p, src->name, line, "spectrum wavelengths are not ascending ('%.64s' after %g nm)", t,
                          nm[k - 1]);
            else if (reflect && (val[k] < 0 || val[k] > 1))
                st = fail(p, src->name, line, "reflect %g at %g nm outside [0, 1]", val[k], nm[k]);
            else if (!reflect && val[k] < 0)
                st = fail(p, src->name, line, "negative emit %g at %g nm", val[k], nm[k]);
        }
        if (!st)
            spectrum_to_bands(s, nm, val, n, out);
        free(nm);
        *i = j;
        return st;
    }
    size_t first = j;
    while (j < ntok && !is_word(tok[j]))
        j++;
    size_t n = j - first;
    if (n != 1 && n != s->nbands) {
        if (s->nbands == 1)
            return fail(p, src->name, line, "'%s' has %zu values; this grey scene needs 1", kind, n);
        return fail(p, src->name, line, "'%s' has %zu values; this %s scene needs 1 or %zu (or 'spectrum')", kind, n,
                    band_word(s), s->nbands);
    }
    for (size_t k = 0; k < n; k++) {
        double v;
        st = number(p, src, line, tok[first + k], &v);
        if (st)
            return st;
        if (reflect && (v < 0 || v > 1))
            return fail(p, src->name, line, "reflect %g outside [0, 1]", v);
        if (!reflect && v < 0)
            return fail(p, src->name, line, "negative emit %g", v);
        out[k] = v;
    }
    if (n == 1)
        for (size_t k = 1; k < s->nbands; k++)
            out[k] = out[0];
    *i = j;
    return RP_OK;
}

static uint32_t find_material(const rp_scene *s, const char *name)
{
    for (size_t i = 0; i < s->nmaterials; i++)
        if (!strcmp(s->materials[i].name, name))
            return (uint32_t)i;
    return RP_NONE;
}

/* Adds a material with fresh zeroed rho and Le; returns its index. */
static rp_status add_material(parser *p, const char *name, uint32_t *index)
{
    rp_scene *s = p->s;
    if (!grow((void **)&s->materials, &s->cap_materials, s->nmaterials + 1, sizeof *s->materials))
        return nomem(p);
    rp_material *m = &s->materials[s->nmaterials];
    memset(m, 0, sizeof *m);
    m->name = dup_string(name);
    m->rho = calloc(s->nbands, sizeof(double));
    m->Le = calloc(s->nbands, sizeof(double));
    if (!m->name || !m->rho || !m->Le) {
        free((void *)m->name);
        free((void *)m->rho);
        free((void *)m->Le);
        return nomem(p);
    }
    *index = (uint32_t)s->nmaterials++;
    return RP_OK;
}

static void material_finish(const rp_scene *s, rp_material *m)
{
    m->emitter = 0;
    for (size_t b = 0; b < s->nbands; b++)
        if (m->Le[b] > 0)
            m->emitter = 1;
}

static rp_status st_material(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    rp_scene *s = p->s;
    if (ntok < 2)
        return fail(p, src->name, line, "'material' needs a name");
    const char *name = tok[1];
    if (find_material(s, name) != RP_NONE)
        return fail(p, src->name, line, "duplicate material name '%.64s'", name);
    if (!strcmp(name, "mtl"))
        return fail(p, src->name, line, "'mtl' cannot name a material: 'mesh NAME mtl FILE' means the OBJ's own "
                                        "MTL materials");
    if (ntok == 2)
        return fail(p, src->name, line, "material '%.64s' has neither reflect nor emit", name);
    double *rho = calloc(2 * s->nbands, sizeof *rho);
    if (!rho)
        return nomem(p);
    double *Le = rho + s->nbands;
    int seen_reflect = 0, seen_emit = 0;
    rp_status st = RP_OK;
    size_t i = 2;
    while (!st && i < ntok) {
        const char *kw = tok[i];
        if (!strcmp(kw, "reflect") || !strcmp(kw, "emit")) {
            int *seen = kw[0] == 'r' ? &seen_reflect : &seen_emit;
            if (*seen) {
                st = fail(p, src->name, line, "'%s' given twice", kw);
                break;
            }
            *seen = 1;
            i++;
            st = material_values(p, src, line, tok, ntok, &i, kw, kw[0] == 'r' ? rho : Le);
        } else {
            st = fail(p, src->name, line,
                      "unknown material property '%.64s' (radpt models diffuse 'reflect' and 'emit' only)", kw);
        }
    }
    if (!st) {
        uint32_t m;
        st = add_material(p, name, &m);
        if (!st) {
            memcpy((void *)s->materials[m].rho, rho, s->nbands * sizeof *rho);
            memcpy((void *)s->materials[m].Le, Le, s->nbands * sizeof *Le);
            material_finish(s, &s->materials[m]);
        }
    }
    free(rho);
    return st;
}

/* NULL when c is a usable pinhole camera, else what is wrong (in buf). */
static const char *camera_problem(const rp_camera *c, char *buf, size_t len)
{
    if (!rp_v3_isfinite(c->eye) || !rp_v3_isfinite(c->look) || !rp_v3_isfinite(c->up) || !isfinite(c->fov_deg))
        return "camera has a non-finite number";
    if (!(c->fov_deg > 0 && c->fov_deg < 180)) {
        snprintf(buf, len, "camera fov %g degrees outside (0, 180)", c->fov_deg);
        return buf;
    }
    if (c->width < 1 || c->height < 1 || c->width > MAX_IMAGE_SIZE || c->height > MAX_IMAGE_SIZE) {
        snprintf(buf, len, "camera size %u x %u is not in [1, %d] pixels", c->width, c->height, MAX_IMAGE_SIZE);
        return buf;
    }
    rp_vec3 dir = rp_v3_sub(c->look, c->eye);
    double ld = rp_v3_length(dir), lu = rp_v3_length(c->up);
    if (!(ld > 0))
        return "camera eye and look are the same point";
    if (!(lu > 0) || rp_v3_length(rp_v3_cross(dir, c->up)) <= 1e-9 * ld * lu)
        return "camera up is zero or parallel to the view direction";
    return NULL;
}

/* The camera words tok[first..ntok): eye X Y Z look X Y Z up X Y Z fov F
 * size W H, each once, in any order. */
static rp_status camera_words(parser *p, const source *src, int line, char **tok, size_t ntok, size_t first,
                              rp_camera *out)
{
    rp_camera c;
    memset(&c, 0, sizeof c);
    int seen[5] = {0, 0, 0, 0, 0};
    static const char *const keys[5] = {"eye", "look", "up", "fov", "size"};
    static const size_t arity[5] = {3, 3, 3, 1, 2};
    size_t i = first;
    while (i < ntok) {
        int k = 0;
        while (k < 5 && strcmp(tok[i], keys[k]))
            k++;
        if (k == 5)
            return fail(p, src->name, line, "unknown camera keyword '%.64s' (eye, look, up, fov, size)", tok[i]);
        if (seen[k])
            return fail(p, src->name, line, "camera '%s' given twice", keys[k]);
        seen[k] = 1;
        size_t n = 0;
        while (i + 1 + n < ntok && n < arity[k] && !is_word(tok[i + 1 + n]))
            n++;
        if (n != arity[k])
            return fail(p, src->name, line, "camera '%s' takes %zu number%s", keys[k], arity[k],
                        arity[k] > 1 ? "s" : "");
        double v[3];
        rp_status st = numbers(p, src, line, tok + i + 1, n, v);
        if (st)
            return st;
        switch (k) {
        case 0: c.eye = rp_v3(v[0], v[1], v[2]); break;
        case 1: c.look = rp_v3(v[0], v[1], v[2]); break;
        case 2: c.up = rp_v3(v[0], v[1], v[2]); break;
        case 3:
            if (!(v[0] > 0 && v[0] < 180))
                return fail(p, src->name, line, "camera fov %g degrees outside (0, 180)", v[0]);
            c.fov_deg = v[0];
            break;
        case 4:
            for (int j = 0; j < 2; j++)
                if (v[j] != floor(v[j]) || v[j] < 1 || v[j] > MAX_IMAGE_SIZE)
                    return fail(p, src->name, line, "camera size %g is not a whole number of pixels in [1, %d]",
                                v[j], MAX_IMAGE_SIZE);
            c.width = (uint32_t)v[0];
            c.height = (uint32_t)v[1];
            break;
        }
        i += 1 + n;
    }
    for (int k = 0; k < 5; k++)
        if (!seen[k])
            return fail(p, src->name, line, "camera lacks '%s'", keys[k]);
    char buf[160];
    const char *bad = camera_problem(&c, buf, sizeof buf);
    if (bad)
        return fail(p, src->name, line, "%s", bad);
    *out = c;
    return RP_OK;
}

static rp_status st_camera(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    if (p->s->has_camera)
        return fail(p, src->name, line, "second 'camera' statement (the first is at %s:%d)", p->camera_file,
                    p->camera_line);
    rp_camera c;
    rp_status st = camera_words(p, src, line, tok, ntok, 1, &c);
    if (st)
        return st;
    p->s->camera = c;
    p->s->has_camera = 1;
    p->camera_file = src->name;
    p->camera_line = line;
    return RP_OK;
}

rp_status rp_camera_parse(const char *words, const char *what, rp_camera *out, rp_error *err)
{
    if (!words || !out)
        return rp_error_set(err, RP_ERR_INPUT, "rp_camera_parse: no words");
    if (!what)
        what = "camera";
    char *copy = dup_string(words);
    char **tok = NULL;
    size_t ntok = 0, cap = 0;
    parser p;
    memset(&p, 0, sizeof p);
    p.err = err;
    if (!copy)
        return nomem(&p);
    rp_status st = RP_OK;
    for (char *q = copy;;) {
        while (*q && isspace((unsigned char)*q))
            q++;
        if (!*q)
            break;
        if (!grow((void **)&tok, &cap, ntok + 1, sizeof *tok)) {
            st = nomem(&p);
            break;
        }
        tok[ntok++] = q;
        while (*q && !isspace((unsigned char)*q))
            q++;
        if (*q)
            *q++ = '\0';
    }
    const source src = {what, NULL, 0};
    if (!st && ntok == 0)
        st = fail(&p, what, 0, "no camera words (eye X Y Z look X Y Z up X Y Z fov F size W H)");
    /* A scene file's whole statement may be pasted, keyword and all. */
    if (!st)
        st = camera_words(&p, &src, 0, tok, ntok, strcmp(tok[0], "camera") == 0 ? 1 : 0, out);
    free(tok);
    free(copy);
    return st;
}

rp_status rp_scene_set_camera(rp_scene *s, const rp_camera *cam, rp_error *err)
{
    if (!s || !cam)
        return rp_error_set(err, RP_ERR_INPUT, "rp_scene_set_camera: no scene or camera");
    char buf[160];
    const char *bad = camera_problem(cam, buf, sizeof buf);
    if (bad)
        return rp_error_set(err, RP_ERR_INPUT, "%s", bad);
    s->camera = *cam;
    s->has_camera = 1;
    return RP_OK;
}

/* ------------------------------------------------------------- geometry */

static rp_status add_vertex(parser *p, rp_vec3 v, uint32_t *index)
{
    rp_scene *s = p->s;
    if (s->nvertices >= UINT32_MAX - 1)
        return rp_error_set(p->err, RP_ERR_INPUT, "too many vertices");
    if (!grow((void **)&s->vertices, &s->cap_vertices, s->nvertices + 1, sizeof *s->vertices))
        return nomem(p);
    s->vertices[s->nvertices] = v;
    *index = (uint32_t)s->nvertices++;
    return RP_OK;
}

/* Checks a face and computes its normal and area; returns NULL when it is
 * acceptable, otherwise what is wrong (in buf). */
static const char *face_check(const rp_vec3 *v, uint32_t n, rp_vec3 *normal, double *area, char *buf, size_t len)
{
    if (n == 3) {
        rp_vec3 e1 = rp_v3_sub(v[1], v[0]), e2 = rp_v3_sub(v[2], v[0]), e3 = rp_v3_sub(v[2], v[1]);
        double l = fmax(rp_v3_length(e1), fmax(rp_v3_length(e2), rp_v3_length(e3)));
        rp_vec3 c = rp_v3_cross(e1, e2);
        double lc = rp_v3_length(c);
        if (!(lc > RELATIVE_COLLINEAR * l * l))
            return "degenerate triangle (zero area: coincident or collinear vertices)";
        *normal = rp_v3_scale(c, 1.0 / lc);
        *area = 0.5 * lc;
        return NULL;
    }
    rp_vec3 d1 = rp_v3_sub(v[2], v[0]), d2 = rp_v3_sub(v[3], v[1]);
    double l = fmax(rp_v3_length(d1), rp_v3_length(d2));
    rp_vec3 a = rp_v3_cross(d1, d2);
    double la = rp_v3_length(a);
    if (!(la > RELATIVE_COLLINEAR * l * l))
        return "degenerate quad (zero area, or self-intersecting with parallel diagonals)";
    rp_vec3 nrm = rp_v3_scale(a, 1.0 / la);
    double twist = fabs(rp_v3_dot(rp_v3_sub(v[1], v[0]), nrm));
    if (twist > RELATIVE_TWIST * l) {
        snprintf(buf, len,
                 "quad is not planar: its diagonals are %g apart along the normal (tolerance %g, 1e-6 of the "
                 "diagonal); split it into two triangles",
                 twist, RELATIVE_TWIST * l);
        return buf;
    }
    for (int i = 0; i < 4; i++) {
        rp_vec3 ea = rp_v3_sub(v[(i + 1) % 4], v[i]), eb = rp_v3_sub(v[(i + 2) % 4], v[(i + 1) % 4]);
        double turn = rp_v3_dot(rp_v3_cross(ea, eb), nrm);
        if (!(turn > RELATIVE_COLLINEAR * rp_v3_length(ea) * rp_v3_length(eb))) {
            snprintf(buf, len, "quad is not convex or crosses itself (at vertex %d)", (i + 1) % 4);
            return buf;
        }
    }
    *normal = rp_v3_normalize(rp_v3_cross(rp_v3_sub(v[1], v[0]), rp_v3_sub(v[3], v[0])));
    *area = 0.5 * la;
    return NULL;
}

/* Appends a face over existing vertices idx[0..n) to the last surface. */
static rp_status add_face(parser *p, const source *src, int line, const uint32_t *idx, uint32_t n, const char *what)
{
    rp_scene *s = p->s;
    rp_vec3 v[4];
    for (uint32_t i = 0; i < n; i++)
        v[i] = s->vertices[idx[i]];
    char buf[256];
    rp_face f;
    memset(&f, 0, sizeof f);
    const char *bad = face_check(v, n, &f.normal, &f.area, buf, sizeof buf);
    if (bad)
        return fail(p, src->name, line, "%s%s", what ? what : "", bad);
    if (s->nfaces >= UINT32_MAX - 1)
        return fail(p, src->name, line, "too many faces");
    if (!grow((void **)&s->faces, &s->cap_faces, s->nfaces + 1, sizeof *s->faces))
        return nomem(p);
    for (uint32_t i = 0; i < 4; i++)
        f.v[i] = i < n ? idx[i] : RP_NONE;
    f.nverts = n;
    f.surface = (uint32_t)(s->nsurfaces - 1);
    s->faces[s->nfaces++] = f;
    rp_surface *surf = &s->surfaces[s->nsurfaces - 1];
    surf->nfaces++;
    surf->area += f.area;
    return RP_OK;
}

/* Opens a surface; its faces follow.  On failure nothing is added. */
static rp_status begin_surface(parser *p, const source *src, int line, const char *name, const char *mat,
                               rp_surface_kind kind)
{
    rp_scene *s = p->s;
    uint32_t m = find_material(s, mat);
    if (m == RP_NONE)
        return fail(p, src->name, line, "unknown material '%.64s'", mat);
    for (size_t i = 0; i < s->nsurfaces; i++)
        if (!strcmp(s->surfaces[i].name, name))
            return fail(p, src->name, line, "duplicate surface name '%.64s' (first at %s:%d)", name,
                        s->surfaces[i].file, s->surfaces[i].line);
    if (s->nsurfaces >= UINT32_MAX - 1)
        return fail(p, src->name, line, "too many surfaces");
    if (!grow((void **)&s->surfaces, &s->cap_surfaces, s->nsurfaces + 1, sizeof *s->surfaces))
        return nomem(p);
    rp_surface *surf = &s->surfaces[s->nsurfaces];
    memset(surf, 0, sizeof *surf);
    surf->name = dup_string(name);
    if (!surf->name)
        return nomem(p);
    surf->kind = kind;
    surf->material = m;
    surf->first_face = (uint32_t)s->nfaces;
    surf->file = src->name;
    surf->line = line;
    s->nsurfaces++;
    return RP_OK;
}

/* Removes a surface whose faces could not all be added (the caller has
 * already set the error), with its faces and vertices. */
static void drop_last_surface(rp_scene *s, size_t nvertices_before)
{
    rp_surface *surf = &s->surfaces[s->nsurfaces - 1];
    s->nfaces = surf->first_face;
    free((void *)surf->name);
    s->nsurfaces--;
    s->nvertices = nvertices_before;
}

static rp_status st_polygon(parser *p, const source *src, int line, char **tok, size_t ntok, uint32_t n)
{
    const char *kw = n == 3 ? "triangle" : "quad";
    if (ntok != 3 + 3 * (size_t)n)
        return fail(p, src->name, line, "'%s' takes a name, a material and %u numbers (%u vertices), not %zu tokens",
                    kw, 3 * n, n, ntok - 1);
    double c[12];
    rp_status st = numbers(p, src, line, tok + 3, 3 * (size_t)n, c);
    if (st)
        return st;
    rp_scene *s = p->s;
    size_t nv = s->nvertices;
    st = begin_surface(p, src, line, tok[1], tok[2], n == 3 ? RP_SURFACE_TRIANGLE : RP_SURFACE_QUAD);
    if (st)
        return st;
    uint32_t idx[4];
    for (uint32_t i = 0; !st && i < n; i++)
        st = add_vertex(p, rp_v3(c[3 * i], c[3 * i + 1], c[3 * i + 2]), &idx[i]);
    if (!st)
        st = add_face(p, src, line, idx, n, NULL);
    if (st)
        drop_last_surface(s, nv);
    return st;
}

static rp_status st_box(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    if (ntok != 10)
        return fail(p, src->name, line,
                    "'box' takes a name, a material, xmin ymin zmin xmax ymax zmax and inward|outward");
    double c[6];
    rp_status st = numbers(p, src, line, tok + 3, 6, c);
    if (st)
        return st;
    int inward;
    if (!strcmp(tok[9], "inward"))
        inward = 1;
    else if (!strcmp(tok[9], "outward"))
        inward = 0;
    else
        return fail(p, src->name, line, "box orientation '%.64s' is neither inward nor outward", tok[9]);
    for (int a = 0; a < 3; a++)
        if (!(c[a] < c[a + 3]))
            return fail(p, src->name, line, "box %c range [%g, %g] is empty (min must be below max)", "xyz"[a], c[a],
                        c[a + 3]);
    rp_scene *s = p->s;
    size_t nv = s->nvertices;
    st = begin_surface(p, src, line, tok[1], tok[2], RP_SURFACE_BOX);
    if (st)
        return st;
    /* Corner (i, j, k) is index i + 2 j + 4 k; each face counter-clockwise
     * seen from inside the box (normal into the box). */
    static const int face[6][4] = {
        {0, 4, 5, 1}, /* y = ymin, normal +y */
        {2, 3, 7, 6}, /* y = ymax, normal -y */
        {0, 2, 6, 4}, /* x = xmin, normal +x */
        {1, 5, 7, 3}, /* x = xmax, normal -x */
        {0, 1, 3, 2}, /* z = zmin, normal +z */
        {4, 6, 7, 5}, /* z = zmax, normal -z */
    };
    uint32_t corner[8];
    for (int k = 0; !st && k < 8; k++)
        st = add_vertex(p, rp_v3(c[(k & 1) ? 3 : 0], c[(k & 2) ? 4 : 1], c[(k & 4) ? 5 : 2]), &corner[k]);
    for (int f = 0; !st && f < 6; f++) {
        uint32_t idx[4];
        for (int i = 0; i < 4; i++)
            idx[i] = corner[face[f][inward ? i : (4 - i) % 4]];
        st = add_face(p, src, line, idx, 4, "box face: ");
    }
    if (st)
        drop_last_surface(s, nv);
    return st;
}

/* ---------------------------------------------------------------- meshes */

/* Rec. ITU-R BT.709 luminance of linear RGB: how an MTL colour enters a
 * grey scene (a reflectance in [0, 1] stays in [0, 1]). */
static double luminance(const double *rgb)
{
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}

/* Appends m's vertices moved to scale * p + t; *base is the first one's
 * index.  Errors name src:line (the statement placing the mesh). */
static rp_status mesh_vertices(parser *p, const source *src, int line, const char *path, const rp_tri_mesh *m,
                               double scale, const double *t, uint32_t *base)
{
    rp_scene *s = p->s;
    if (m->nvertices >= UINT32_MAX - 1 - s->nvertices)
        return fail(p, src->name, line, "mesh '%.200s' has too many vertices", path);
    *base = (uint32_t)s->nvertices;
    for (size_t i = 0; i < m->nvertices; i++) {
        uint32_t idx;
        rp_vec3 v = rp_v3(scale * m->xyz[3 * i] + t[0], scale * m->xyz[3 * i + 1] + t[1],
                          scale * m->xyz[3 * i + 2] + t[2]);
        if (!rp_v3_isfinite(v))
            return fail(p, src->name, line, "mesh '%.200s': vertex %zu is not finite", path, i);
        rp_status st = add_vertex(p, v, &idx);
        if (st)
            return st;
    }
    for (size_t f = 0; f < 3 * m->ntriangles; f++)
        if (m->tri[f] >= m->nvertices)
            return fail(p, src->name, line, "mesh '%.200s': face %zu has a bad vertex index", path, f / 3);
    return RP_OK;
}

/* 1 if triangle tr of m (its vertices from base on) has the area every
 * face must have (face_check), which the reader's exact zero-area test
 * does not guarantee. */
static int mesh_triangle_ok(const rp_scene *s, const rp_tri_mesh *m, uint32_t base, size_t tr)
{
    rp_vec3 v[3], n;
    double a;
    char buf[16];
    for (int k = 0; k < 3; k++)
        v[k] = s->vertices[base + m->tri[3 * tr + k]];
    return face_check(v, 3, &n, &a, buf, sizeof buf) == NULL;
}

/* The line of triangle tr's face in m's file (0: unknown). */
static size_t mesh_line(const rp_tri_mesh *m, size_t tr)
{
    return m->tri_line ? m->tri_line[tr] : 0;
}

/* One warning per kind of face the reading dropped (path names m's file);
 * dropped / dropped_line add the faces face_check refused here. */
static rp_status mesh_drop_warnings(parser *p, const char *path, const rp_tri_mesh *m, size_t dropped,
                                    size_t dropped_line)
{
    rp_status st = RP_OK;
    for (size_t i = 0; !st && i < m->nwarnings; i++)
        st = keep_warning(p, m->warnings[i]);
    size_t nzero = m->degenerate_faces + dropped;
    size_t zline = m->degenerate_line;
    if (dropped_line > 0 && (zline == 0 || dropped_line < zline))
        zline = dropped_line;
    if (!st && nzero > 0)
        st = add_warning(p, path, zline, "%zu zero-area face%s dropped (the first on this line)", nzero,
                         nzero > 1 ? "s" : "");
    if (!st && m->duplicate_faces > 0)
        st = add_warning(p, path, m->duplicate_line,
                         "%zu exact duplicate face%s dropped (the first on this line; same vertex positions "
                         "and winding as an earlier face)",
                         m->duplicate_faces, m->duplicate_faces > 1 ? "s" : "");
    return st;
}

/* The surface name base, or base~2, base~3, ... if taken. */
static void unique_surface_name(const rp_scene *s, const char *base, char *out, size_t len)
{
    snprintf(out, len, "%s", base);
    for (unsigned k = 2; rp_scene_find_surface(s, out) != RP_NONE; k++)
        snprintf(out, len, "%.*s~%u", (int)(len > 16 ? len - 16 : 0), base, k);
}

typedef struct obj_key {
    uint32_t group, material, tri;
} obj_key;

static int obj_key_cmp(const void *a, const void *b)
{
    const obj_key *x = a, *y = b;
    if (x->group != y->group)
        return x->group < y->group ? -1 : 1;
    if (x->material != y->material)
        return x->material < y->material ? -1 : 1;
    return x->tri < y->tri ? -1 : x->tri > y->tri;
}

/* Places an OBJ scene read by rp_obj_read_scene: its materials (named
 * "prefix/name" when prefix is not NULL) and one surface per (group,
 * material) pair, named after the group ("default" before any o/g), or
 * "group.material" when the group mixes materials, with "prefix/" in
 * front, and "~2", "~3" ... after a name already taken.  Vertices move to
 * scale * p + t.  src:line is the statement that places it (the OBJ itself
 * for an OBJ scene).  Faces keep their own winding: inconsistent
 * orientation is a warning here, since an OBJ scene's faces are surfaces
 * each author-oriented, not one closed skin. */
static rp_status obj_place(parser *p, const source *src, int line, const char *file, const rp_tri_mesh *m,
                           const char *prefix, double scale, const double *t)
{
    rp_scene *s = p->s;
    if (m->ntriangles == 0)
        return fail(p, file, 0, "no faces");
    if (s->band_kind == RP_BANDS_SPECTRAL)
        return fail(p, src->name, line,
                    "'%.200s' has MTL materials, which are RGB; an RGB colour has no one spectrum, so they cannot "
                    "enter this spectral scene (place it with 'mesh NAME MATERIAL FILE' and a spectral material)",
                    file);
    size_t nm = m->nmaterials;
    uint32_t *mat_of = malloc((nm ? nm : 1) * sizeof *mat_of);
    obj_key *keys = malloc((m->ntriangles ? m->ntriangles : 1) * sizeof *keys);
    char *name = malloc(1024), *mname = malloc(1024);
    rp_status st = RP_OK;
    if (!mat_of || !keys || !name || !mname)
        st = nomem(p);
    for (size_t i = 0; !st && i < nm; i++) {
        const char *mn = m->material_names && m->material_names[i] ? m->material_names[i] : "";
        if (prefix)
            snprintf(mname, 1024, "%s/%s", prefix, mn);
        else
            snprintf(mname, 1024, "%s", mn);
        if (find_material(s, mname) != RP_NONE) {
            st = fail(p, src->name, line, "material '%.200s' from '%.200s' is already declared", mname, file);
            break;
        }
        const double *kd = m->material_kd + 3 * i, *ke = m->material_ke + 3 * i;
        for (int c = 0; c < 3 && !st; c++)
            if (!isfinite(kd[c]) || kd[c] < 0 || kd[c] > 1 || !isfinite(ke[c]) || ke[c] < 0)
                st = fail(p, file, 0, "material '%.64s': Kd %g outside [0, 1] or Ke %g negative", mn, kd[c], ke[c]);
        if (!st)
            st = add_material(p, mname, &mat_of[i]);
        if (st)
            break;
        rp_material *mat = &s->materials[mat_of[i]];
        if (s->band_kind == RP_BANDS_GREY) {
            *(double *)mat->rho = luminance(kd);
            *(double *)mat->Le = luminance(ke);
        } else {
            memcpy((void *)mat->rho, kd, 3 * sizeof *kd);
            memcpy((void *)mat->Le, ke, 3 * sizeof *ke);
        }
        material_finish(s, mat);
    }
    uint32_t base = 0;
    if (!st)
        st = mesh_vertices(p, src, line, file, m, scale, t, &base);
    size_t nkeys = 0, dropped = 0, dropped_line = 0;
    for (size_t tr = 0; !st && tr < m->ntriangles; tr++) {
        uint32_t mat = m->tri_material ? m->tri_material[tr] : UINT32_MAX;
        uint32_t g = m->tri_group ? m->tri_group[tr] : 0;
        if (mat == UINT32_MAX || mat >= nm)
            st = fail(p, file, mesh_line(m, tr), "face has no material (no usemtl before it): radpt needs "
                      "Kd and Ke for every face and invents none");
        else if (m->tri_group && g >= m->ngroups)
            st = fail(p, file, mesh_line(m, tr), "face has a bad group index");
        else if (!mesh_triangle_ok(s, m, base, tr)) {
            if (dropped++ == 0)
                dropped_line = mesh_line(m, tr);
        } else
            keys[nkeys++] = (obj_key){g, mat, (uint32_t)tr};
    }
    if (!st && nkeys == 0)
        st = fail(p, file, 0, "every face is degenerate (zero area)");
    if (!st)
        qsort(keys, nkeys, sizeof *keys, obj_key_cmp);
    for (size_t k = 0; !st && k < nkeys;) {
        uint32_t g = keys[k].group, mat = keys[k].material;
        /* Does group g use more than one material? Its keys are contiguous. */
        size_t g0 = k, g1 = k;
        while (g0 > 0 && keys[g0 - 1].group == g)
            g0--;
        while (g1 < nkeys && keys[g1].group == g)
            g1++;
        int mixed = keys[g0].material != keys[g1 - 1].material;
        const char *gname =
            m->group_names && g < m->ngroups && m->group_names[g] && m->group_names[g][0] ? m->group_names[g]
                                                                                          : "default";
        const char *mn = m->material_names[mat] ? m->material_names[mat] : "";
        snprintf(mname, 1024, "%s%s%.400s%s%.400s", prefix ? prefix : "", prefix ? "/" : "", gname,
                 mixed ? "." : "", mixed ? mn : "");
        unique_surface_name(s, mname, name, 1024);
        const source osrc = {file, NULL, 0};
        st = begin_surface(p, &osrc, (int)mesh_line(m, keys[k].tri), name, s->materials[mat_of[mat]].name,
                           RP_SURFACE_MESH);
        for (; !st && k < nkeys && keys[k].group == g && keys[k].material == mat; k++) {
            uint32_t tr = keys[k].tri;
            uint32_t idx[3] = {base + m->tri[3 * tr], base + m->tri[3 * tr + 1], base + m->tri[3 * tr + 2]};
            st = add_face(p, &osrc, (int)mesh_line(m, tr), idx, 3, NULL);
        }
    }
    if (!st)
        st = mesh_drop_warnings(p, file, m, dropped, dropped_line);
    if (!st && m->orientation_conflicts > 0)
        st = add_warning(p, file, m->orientation_line,
                         "faces wound inconsistently: %zu edge%s used twice in the same direction (the first by "
                         "the face on this line); each face keeps its own winding, its front being the side "
                         "that reflects and emits",
                         m->orientation_conflicts, m->orientation_conflicts > 1 ? "s" : "");
    free(mat_of);
    free(keys);
    free(name);
    free(mname);
    return st;
}

/* `mesh NAME MATERIAL FILE`: one surface of one material.  Zero-area and
 * duplicate faces are dropped with a warning; inconsistent orientation is
 * an error, because one surface of one material is meant as one skin whose
 * front is the side lit, and radpt will not guess which faces are the
 * wrong way round (an OBJ scene, or `mesh NAME mtl FILE`, keeps each
 * face's own winding instead). */
static rp_status mesh_one_material(parser *p, const source *src, int line, const char *name, const char *mat,
                                   const char *path, double scale, const double *t)
{
    rp_scene *s = p->s;
    rp_tri_mesh m;
    memset(&m, 0, sizeof m);
    char msg[512] = "";
    if (rp_cgal_read_mesh(path, 0, &m, msg, sizeof msg) != 0) {
        rp_tri_mesh_free(&m);
        return fail(p, src->name, line, "mesh: %s", msg[0] ? msg : path);
    }
    rp_status st = RP_OK;
    if (m.orientation_conflicts > 0) {
        char where[64] = "";
        if (m.orientation_line > 0)
            snprintf(where, sizeof where, ":%zu", m.orientation_line);
        st = fail(p, src->name, line,
                  "mesh '%.200s' is inconsistently oriented: %zu edge%s used twice in the same direction "
                  "(first at %.200s%s); a one-material mesh is one surface whose faces must agree on their front",
                  path, m.orientation_conflicts, m.orientation_conflicts > 1 ? "s" : "", path, where);
    } else if (m.ntriangles == 0) {
        st = fail(p, src->name, line, "mesh '%.200s' has no faces", path);
    }
    size_t nv = s->nvertices;
    uint32_t base = 0;
    if (!st)
        st = mesh_vertices(p, src, line, path, &m, scale, t, &base);
    size_t kept = 0, dropped = 0, dropped_line = 0;
    char *keep = st ? NULL : calloc(m.ntriangles, 1);
    if (!st && !keep)
        st = nomem(p);
    for (size_t f = 0; !st && f < m.ntriangles; f++) {
        keep[f] = (char)mesh_triangle_ok(s, &m, base, f);
        kept += (size_t)keep[f];
        if (!keep[f] && dropped++ == 0)
            dropped_line = mesh_line(&m, f);
    }
    if (!st && kept == 0)
        st = fail(p, src->name, line, "mesh '%.200s': every face is degenerate (zero area)", path);
    if (!st) {
        st = begin_surface(p, src, line, name, mat, RP_SURFACE_MESH);
        for (size_t f = 0; !st && f < m.ntriangles; f++) {
            if (!keep[f])
                continue;
            uint32_t idx[3] = {base + m.tri[3 * f], base + m.tri[3 * f + 1], base + m.tri[3 * f + 2]};
            char what[64];
            snprintf(what, sizeof what, "mesh face %zu: ", f);
            st = add_face(p, src, line, idx, 3, what);
        }
        if (st)
            drop_last_surface(s, nv);
    }
    if (!st)
        st = mesh_drop_warnings(p, path, &m, dropped, dropped_line);
    else
        s->nvertices = nv;
    free(keep);
    rp_tri_mesh_free(&m);
    return st;
}

/* `mesh NAME mtl FILE.obj`: the OBJ with its own MTL materials. */
static rp_status mesh_mtl(parser *p, const source *src, int line, const char *name, const char *path,
                          double scale, const double *t)
{
    rp_tri_mesh m;
    memset(&m, 0, sizeof m);
    char msg[512] = "";
    if (rp_obj_read_scene(path, &m, msg, sizeof msg) != 0) {
        rp_tri_mesh_free(&m);
        return fail(p, src->name, line, "mesh %.64s mtl: %s", name, msg[0] ? msg : path);
    }
    const char *file = keep_file_name(p, path);
    rp_status st = file ? obj_place(p, src, line, file, &m, name, scale, t) : nomem(p);
    rp_tri_mesh_free(&m);
    return st;
}

static rp_status st_mesh(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    if (ntok < 4)
        return fail(p, src->name, line,
                    "'mesh' takes a name, a material (or 'mtl' for the OBJ's own), a path and [scale S] "
                    "[translate X Y Z]");
    double scale = 1, t[3] = {0, 0, 0};
    int seen_scale = 0, seen_translate = 0;
    rp_status st;
    for (size_t i = 4; i < ntok;) {
        if (!strcmp(tok[i], "scale")) {
            if (seen_scale)
                return fail(p, src->name, line, "mesh 'scale' given twice");
            if (i + 1 >= ntok)
                return fail(p, src->name, line, "mesh 'scale' takes one number");
            if ((st = number(p, src, line, tok[i + 1], &scale)))
                return st;
            if (!(scale > 0))
                return fail(p, src->name, line, "mesh scale %g is not positive", scale);
            seen_scale = 1;
            i += 2;
        } else if (!strcmp(tok[i], "translate")) {
            if (seen_translate)
                return fail(p, src->name, line, "mesh 'translate' given twice");
            if (i + 3 >= ntok)
                return fail(p, src->name, line, "mesh 'translate' takes three numbers");
            if ((st = numbers(p, src, line, tok + i + 1, 3, t)))
                return st;
            seen_translate = 1;
            i += 4;
        } else {
            return fail(p, src->name, line, "unknown mesh option '%.64s' (scale, translate)", tok[i]);
        }
    }
    rp_scene *s = p->s;
    int mtl = !strcmp(tok[2], "mtl");
    if (!mtl && find_material(s, tok[2]) == RP_NONE)
        return fail(p, src->name, line, "unknown material '%.64s'", tok[2]);
    char *path = join_path(src->dir, tok[3]);
    if (!path)
        return nomem(p);
    FILE *probe = fopen(path, "rb");
    if (!probe) {
        st = fail(p, src->name, line, "cannot open mesh '%.200s': %s", path, strerror(errno));
        free(path);
        return st;
    }
    fclose(probe);
    if (mtl)
        st = mesh_mtl(p, src, line, tok[1], path, scale, t);
    else
        st = mesh_one_material(p, src, line, tok[1], tok[2], path, scale, t);
    free(path);
    return st;
}

static rp_status parse_source(parser *p, char *text, const source *src, int *nlines);

static rp_status st_include(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    if (ntok != 2)
        return fail(p, src->name, line, "'include' takes one path");
    if (src->depth + 1 > MAX_INCLUDE_DEPTH)
        return fail(p, src->name, line, "includes nested deeper than %d", MAX_INCLUDE_DEPTH);
    char *path = join_path(src->dir, tok[1]);
    if (!path)
        return nomem(p);
    rp_status st = RP_OK;
    char *real = realpath(path, NULL);
    char *text = NULL;
    if (!real) {
        st = fail(p, src->name, line, "cannot open include '%.200s': %s", path, strerror(errno));
        goto done;
    }
    for (size_t i = 0; i < p->nstack; i++)
        if (!strcmp(p->stack[i], real)) {
            st = fail(p, src->name, line, "include cycle: '%.200s' is already being read", path);
            goto done;
        }
    int nul_line;
    text = read_text(path, &nul_line);
    if (!text && nul_line) {
        st = fail(p, src->name, line, "include '%.200s' is not a text file (a NUL byte on its line %d)",
                  path, nul_line);
        goto done;
    }
    if (!text) {
        st = fail(p, src->name, line, "cannot read include '%.200s': %s", path, strerror(errno));
        goto done;
    }
    source inc;
    inc.name = keep_file_name(p, path);
    int ok;
    inc.dir = dir_name(path, &ok);
    inc.depth = src->depth + 1;
    if (!inc.name || !ok || !grow((void **)&p->stack, &p->cap_stack, p->nstack + 1, sizeof *p->stack)) {
        free(inc.dir);
        st = nomem(p);
        goto done;
    }
    p->stack[p->nstack++] = real;
    real = NULL;
    int nlines;
    st = parse_source(p, text, &inc, &nlines);
    free(p->stack[--p->nstack]);
    free(inc.dir);
done:
    free(text);
    free(real);
    free(path);
    return st;
}

static rp_status statement(parser *p, const source *src, int line, char **tok, size_t ntok)
{
    const char *kw = tok[0];
    if (!strcmp(kw, "bands"))
        return st_bands(p, src, line, tok, ntok);
    if (!strcmp(kw, "camera"))
        return st_camera(p, src, line, tok, ntok);
    if (!strcmp(kw, "material"))
        return st_material(p, src, line, tok, ntok);
    if (!strcmp(kw, "quad"))
        return st_polygon(p, src, line, tok, ntok, 4);
    if (!strcmp(kw, "triangle"))
        return st_polygon(p, src, line, tok, ntok, 3);
    if (!strcmp(kw, "box"))
        return st_box(p, src, line, tok, ntok);
    if (!strcmp(kw, "mesh"))
        return st_mesh(p, src, line, tok, ntok);
    if (!strcmp(kw, "include"))
        return st_include(p, src, line, tok, ntok);
    return fail(p, src->name, line, "unknown statement '%.64s'", kw);
}

/* Parses text (modified in place) line by line. */
static rp_status parse_source(parser *p, char *text, const source *src, int *nlines)
{
    char **tok = NULL;
    size_t cap = 0;
    int line = 0;
    rp_status st = RP_OK;
    char *cur = text;
    while (!st && cur && *cur) {
        line++;
        char *nl = strchr(cur, '\n');
        char *next = nl ? nl + 1 : NULL;
        if (nl)
            *nl = '\0';
        char *hash = strchr(cur, '#');
        if (hash)
            *hash = '\0';
        size_t ntok = 0;
        char *q = cur;
        for (;;) {
            while (*q && isspace((unsigned char)*q))
                q++;
            if (!*q)
                break;
            if (!grow((void **)&tok, &cap, ntok + 1, sizeof *tok)) {
                st = nomem(p);
                break;
            }
            tok[ntok++] = q;
            while (*q && !isspace((unsigned char)*q))
                q++;
            if (*q)
                *q++ = '\0';
        }
        if (!st && ntok > 0)
            st = statement(p, src, line, tok, ntok);
        cur = next;
    }
    free(tok);
    *nlines = line;
    return st;
}

/* ---------------------------------------------------------- finishing */

static void compute_bounds(rp_scene *s)
{
    s->lo = rp_v3(0, 0, 0);
    s->hi = rp_v3(0, 0, 0);
    for (size_t i = 0; i < s->nvertices; i++) {
        rp_vec3 v = s->vertices[i];
        if (i == 0) {
            s->lo = s->hi = v;
            continue;
        }
        s->lo = rp_v3(fmin(s->lo.x, v.x), fmin(s->lo.y, v.y), fmin(s->lo.z, v.z));
        s->hi = rp_v3(fmax(s->hi.x, v.x), fmax(s->hi.y, v.y), fmax(s->hi.z, v.z));
    }
    s->total_area = 0;
    for (size_t i = 0; i < s->nsurfaces; i++)
        s->total_area += s->surfaces[i].area;
}

/* Checks that need the whole scene: specks and its emitters.  A scene
 * without an emitter is blamed on name:line (its last line; 0: no line). */
static rp_status finish(parser *p, const char *name, int line)
{
    rp_scene *s = p->s;
    compute_bounds(s);
    for (size_t f = 0; f < s->nfaces; f++) {
        double m = 0;
        for (uint32_t k = 0; k < s->faces[f].nverts; k++) {
            rp_vec3 v = s->vertices[s->faces[f].v[k]];
            m = fmax(m, fmax(fabs(v.x), fmax(fabs(v.y), fabs(v.z))));
        }
        double tiny = RELATIVE_SPECK * m * RELATIVE_SPECK * m;
        if (!(s->faces[f].area > tiny)) {
            const rp_surface *surf = &s->surfaces[s->faces[f].surface];
            return fail(p, surf->file, surf->line,
                        "degenerate face in '%s' (area %g, below (1e-9 x its largest coordinate %g)^2: "
                        "its shape would be rounding)",
                        surf->name, s->faces[f].area, m);
        }
    }
    int emitting = 0;
    for (size_t i = 0; i < s->nsurfaces; i++)
        if (s->materials[s->surfaces[i].material].emitter)
            emitting = 1;
    if (!emitting)
        return fail(p, name, line, "the scene has no emitter (no surface's material emits)");
    return RP_OK;
}

/* A closed scene that reflects everything in some band (reflect 1 on every
 * surface) and emits in that band keeps all the light it makes: its
 * radiance is infinite (the furnace's Le / (1 - rho)), so it is refused.
 * Closedness is only tested when the reflectances call for it. */
static rp_status finite_radiance(parser *p)
{
    rp_scene *s = p->s;
    for (size_t b = 0; b < s->nbands; b++) {
        int all = s->nsurfaces > 0, emits = 0;
        for (size_t i = 0; i < s->nsurfaces; i++) {
            const rp_material *m = &s->materials[s->surfaces[i].material];
            all &= m->rho[b] >= 1;
            emits |= m->Le[b] > 0;
        }
        if (all && emits && rp_scene_is_closed(s) == 1) {
            const rp_surface *surf = &s->surfaces[0];
            char band[32] = "";
            if (s->nbands > 1)
                snprintf(band, sizeof band, " in band %zu", b);
            return fail(p, surf->file, surf->line,
                        "the scene is closed, reflects everything%s (reflect 1 on every surface) and emits: its "
                        "radiance is infinite (a furnace's Le / (1 - rho))",
                        band);
        }
    }
    return RP_OK;
}

static void parser_free(parser *p)
{
    for (size_t i = 0; i < p->nstack; i++)
        free(p->stack[i]);
    free(p->stack);
}

/* Parses text named name; real is the canonical path of the file when the
 * text came from one (for include cycles), else NULL. */
static rp_status parse_top(const char *text, const char *name, const char *dir, const char *real, rp_scene **out,
                           rp_error *err)
{
    *out = NULL;
    parser p;
    memset(&p, 0, sizeof p);
    p.err = err;
    p.s = scene_new();
    char *copy = dup_string(text);
    char *dcopy = dir ? dup_string(dir) : NULL;
    source src = {NULL, dcopy, 0};
    rp_status st = RP_OK;
    if (!p.s || !copy || (dir && !dcopy) || !(src.name = keep_file_name(&p, name)))
        st = nomem(&p);
    if (!st && real) {
        char *r = dup_string(real);
        if (!r || !grow((void **)&p.stack, &p.cap_stack, 1, sizeof *p.stack)) {
            free(r);
            st = nomem(&p);
        } else {
            p.stack[p.nstack++] = r;
        }
    }
    int nlines = 0;
    if (!st)
        st = parse_source(&p, copy, &src, &nlines);
    if (!st)
        st = finish(&p, src.name, nlines > 0 ? nlines : 1);
    if (!st)
        st = finite_radiance(&p);
    free(copy);
    free(dcopy);
    parser_free(&p);
    if (st) {
        rp_scene_destroy(p.s);
        return st;
    }
    rp_error_clear(err);
    *out = p.s;
    return RP_OK;
}

rp_status rp_scene_parse(const char *text, const char *name, const char *dir, rp_scene **out, rp_error *err)
{
    if (!text || !out)
        return rp_error_set(err, RP_ERR_INPUT, "rp_scene_parse: no text");
    return parse_top(text, name ? name : "<scene>", dir, NULL, out, err);
}

/* ---------------------------------------------------------------- OBJ */

static int ends_with_obj(const char *path)
{
    size_t n = strlen(path);
    return n >= 4 && path[n - 4] == '.' && tolower((unsigned char)path[n - 3]) == 'o' &&
           tolower((unsigned char)path[n - 2]) == 'b' && tolower((unsigned char)path[n - 1]) == 'j';
}

static rp_status load_obj(const char *path, rp_scene **out, rp_error *err)
{
    parser p;
    memset(&p, 0, sizeof p);
    p.err = err;
    p.s = scene_new();
    if (!p.s)
        return nomem(&p);
    const char *name = keep_file_name(&p, path);
    if (!name) {
        rp_scene_destroy(p.s);
        return nomem(&p);
    }
    rp_tri_mesh m;
    memset(&m, 0, sizeof m);
    char msg[512] = "";
    rp_status st = RP_OK;
    if (rp_obj_read_scene(path, &m, msg, sizeof msg) != 0)
        st = rp_error_set(err, RP_ERR_INPUT, "%s", msg[0] ? msg : "cannot read the OBJ scene");
    const source src = {name, NULL, 0};
    const double origin[3] = {0, 0, 0};
    p.s->band_kind = RP_BANDS_RGB;
    p.s->nbands = 3;
    if (!st)
        st = obj_place(&p, &src, 0, name, &m, NULL, 1, origin);
    if (!st)
        st = finish(&p, name, 0);
    if (!st)
        st = finite_radiance(&p);
    rp_tri_mesh_free(&m);
    if (st) {
        rp_scene_destroy(p.s);
        return st;
    }
    rp_error_clear(err);
    *out = p.s;
    return RP_OK;
}

rp_status rp_scene_load(const char *path, rp_scene **out, rp_error *err)
{
    if (!out)
        return rp_error_set(err, RP_ERR_INPUT, "rp_scene_load: no output");
    *out = NULL;
    if (!path)
        return rp_error_set(err, RP_ERR_INPUT, "rp_scene_load: no path");
    char *real = realpath(path, NULL);
    if (!real)
        return rp_error_set(err, RP_ERR_INPUT, "%s: cannot open: %s", path, strerror(errno));
    rp_status st;
    if (ends_with_obj(path)) {
        free(real);
        return load_obj(path, out, err);
    }
    int nul_line;
    char *text = read_text(path, &nul_line);
    if (!text && nul_line) {
        free(real);
        return rp_error_set(err, RP_ERR_INPUT, "%s:%d: a NUL byte: not a text scene file", path, nul_line);
    }
    if (!text) {
        st = rp_error_set(err, RP_ERR_INPUT, "%s: cannot read: %s", path, strerror(errno));
        free(real);
        return st;
    }
    int ok;
    char *dir = dir_name(path, &ok);
    if (!ok)
        st = rp_error_set(err, RP_ERR_NOMEM, "out of memory while reading the scene");
    else
        st = parse_top(text, path, dir, real, out, err);
    free(dir);
    free(text);
    free(real);
    return st;
}

/* ------------------------------------------------------------ accessors */

rp_band_kind rp_scene_band_kind(const rp_scene *s) { return s->band_kind; }
size_t rp_scene_nbands(const rp_scene *s) { return s->nbands; }
const double *rp_scene_wavelengths(const rp_scene *s) { return s->wavelengths; }
size_t rp_scene_nmaterials(const rp_scene *s) { return s->nmaterials; }
const rp_material *rp_scene_materials(const rp_scene *s) { return s->materials; }
size_t rp_scene_nsurfaces(const rp_scene *s) { return s->nsurfaces; }
const rp_surface *rp_scene_surfaces(const rp_scene *s) { return s->surfaces; }
size_t rp_scene_nfaces(const rp_scene *s) { return s->nfaces; }
const rp_face *rp_scene_faces(const rp_scene *s) { return s->faces; }
size_t rp_scene_nvertices(const rp_scene *s) { return s->nvertices; }
const rp_vec3 *rp_scene_vertices(const rp_scene *s) { return s->vertices; }

const rp_material *rp_scene_face_material(const rp_scene *s, uint32_t face)
{
    return &s->materials[s->surfaces[s->faces[face].surface].material];
}

int rp_material_pure_emitter(const rp_material *m, size_t nb)
{
    if (!m->emitter)
        return 0;
    for (size_t b = 0; b < nb; b++)
        if (m->rho[b] > 0)
            return 0;
    return 1;
}

const rp_camera *rp_scene_camera(const rp_scene *s) { return s->has_camera ? &s->camera : NULL; }

size_t rp_scene_nwarnings(const rp_scene *s) { return s->nwarnings; }

const char *rp_scene_warning(const rp_scene *s, size_t i) { return i < s->nwarnings ? s->warnings[i] : NULL; }

uint32_t rp_scene_find_surface(const rp_scene *s, const char *name)
{
    for (size_t i = 0; i < s->nsurfaces; i++)
        if (!strcmp(s->surfaces[i].name, name))
            return (uint32_t)i;
    return RP_NONE;
}

void rp_scene_surface_power(const rp_scene *s, uint32_t surface, double *power)
{
    const rp_surface *surf = &s->surfaces[surface];
    const rp_material *m = &s->materials[surf->material];
    /* Lambertian emitter: exitance pi Le over the area. */
    for (size_t b = 0; b < s->nbands; b++)
        power[b] = RP_PI * m->Le[b] * surf->area;
}

double rp_scene_total_area(const rp_scene *s) { return s->total_area; }

void rp_scene_bounds(const rp_scene *s, rp_vec3 *lo, rp_vec3 *hi)
{
    if (lo)
        *lo = s->lo;
    if (hi)
        *hi = s->hi;
}

double rp_scene_diagonal(const rp_scene *s) { return rp_v3_length(rp_v3_sub(s->hi, s->lo)); }

rp_vec3 rp_scene_face_point(const rp_scene *s, uint32_t face, double u, double v)
{
    const rp_face *f = &s->faces[face];
    const rp_vec3 *V = s->vertices;
    rp_vec3 v0 = V[f->v[0]], v1 = V[f->v[1]], v2 = V[f->v[2]];
    if (f->nverts == 3)
        return rp_v3_madd(rp_v3_madd(v0, rp_v3_sub(v1, v0), u), rp_v3_sub(v2, v0), v);
    rp_vec3 v3 = V[f->v[3]];
    rp_vec3 p = rp_v3_scale(v0, (1 - u) * (1 - v));
    p = rp_v3_madd(p, v1, u * (1 - v));
    p = rp_v3_madd(p, v2, u * v);
    return rp_v3_madd(p, v3, (1 - u) * v);
}

/* --------------------------------------------------------------- hash */

typedef struct fnv {
    uint64_t h;
} fnv;

/* FNV-1a, 64 bit (hash.h). */
static void fnv_bytes(fnv *f, const void *data, size_t n) { f->h = rp_fnv1a64(f->h, data, n); }

/* Integers and doubles are hashed as little-endian bytes so the hash does
 * not depend on the host. */
static void fnv_u64(fnv *f, uint64_t x)
{
    unsigned char b[8];
    for (int i = 0; i < 8; i++)
        b[i] = (unsigned char)(x >> (8 * i));
    fnv_bytes(f, b, 8);
}

static void fnv_double(fnv *f, double x)
{
    uint64_t u;
    if (x == 0)
        x = 0; /* -0 and +0 hash alike */
    memcpy(&u, &x, sizeof u);
    fnv_u64(f, u);
}

static void fnv_string(fnv *f, const char *s) { fnv_bytes(f, s, strlen(s) + 1); }

static void fnv_vec(fnv *f, rp_vec3 v)
{
    fnv_double(f, v.x);
    fnv_double(f, v.y);
    fnv_double(f, v.z);
}

void rp_scene_hash(const rp_scene *s, char out[17])
{
    fnv f = {RP_FNV1A64_INIT};
    fnv_string(&f, "radpt scene 1");
    fnv_u64(&f, (uint64_t)s->band_kind);
    fnv_u64(&f, s->nbands);
    for (size_t b = 0; s->wavelengths && b < s->nbands; b++)
        fnv_double(&f, s->wavelengths[b]);
    fnv_u64(&f, s->nmaterials);
    for (size_t i = 0; i < s->nmaterials; i++) {
        fnv_string(&f, s->materials[i].name);
        for (size_t b = 0; b < s->nbands; b++) {
            fnv_double(&f, s->materials[i].rho[b]);
            fnv_double(&f, s->materials[i].Le[b]);
        }
    }
    fnv_u64(&f, s->nsurfaces);
    for (size_t i = 0; i < s->nsurfaces; i++) {
        const rp_surface *surf = &s->surfaces[i];
        fnv_string(&f, surf->name);
        fnv_u64(&f, (uint64_t)surf->kind);
        fnv_u64(&f, surf->material);
        fnv_u64(&f, surf->first_face);
        fnv_u64(&f, surf->nfaces);
    }
    fnv_u64(&f, s->nfaces);
    for (size_t i = 0; i < s->nfaces; i++) {
        fnv_u64(&f, s->faces[i].nverts);
        for (uint32_t k = 0; k < s->faces[i].nverts; k++)
            fnv_u64(&f, s->faces[i].v[k]);
    }
    fnv_u64(&f, s->nvertices);
    for (size_t i = 0; i < s->nvertices; i++)
        fnv_vec(&f, s->vertices[i]);
    fnv_u64(&f, (uint64_t)s->has_camera);
    if (s->has_camera) {
        fnv_vec(&f, s->camera.eye);
        fnv_vec(&f, s->camera.look);
        fnv_vec(&f, s->camera.up);
        fnv_double(&f, s->camera.fov_deg);
        fnv_u64(&f, s->camera.width);
        fnv_u64(&f, s->camera.height);
    }
    snprintf(out, 17, "%016llx", (unsigned long long)f.h);
}

/* ----------------------------------------------------------- closedness */

int rp_scene_is_closed(const rp_scene *s)
{
    if (s->nfaces == 0)
        return 0;
    size_t ntri = 0;
    for (size_t i = 0; i < s->nfaces; i++)
        ntri += s->faces[i].nverts == 4 ? 2 : 1;
    double *xyz = malloc(3 * s->nvertices * sizeof *xyz);
    uint32_t *tri = malloc(3 * ntri * sizeof *tri);
    if (!xyz || !tri) {
        free(xyz);
        free(tri);
        return -1;
    }
    for (size_t i = 0; i < s->nvertices; i++) {
        xyz[3 * i] = s->vertices[i].x;
        xyz[3 * i + 1] = s->vertices[i].y;
        xyz[3 * i + 2] = s->vertices[i].z;
    }
    size_t t = 0;
    for (size_t i = 0; i < s->nfaces; i++) {
        const uint32_t *v = s->faces[i].v;
        tri[3 * t] = v[0], tri[3 * t + 1] = v[1], tri[3 * t + 2] = v[2];
        t++;
        if (s->faces[i].nverts == 4) {
            tri[3 * t] = v[0], tri[3 * t + 1] = v[2], tri[3 * t + 2] = v[3];
            t++;
        }
    }
    /* The weld tolerance, from the shortest edge (the header comment). */
    double shortest = INFINITY;
    for (size_t i = 0; i < s->nfaces; i++)
        for (uint32_t k = 0; k < s->faces[i].nverts; k++) {
            rp_vec3 a = s->vertices[s->faces[i].v[k]], b = s->vertices[s->faces[i].v[(k + 1) % s->faces[i].nverts]];
            shortest = fmin(shortest, rp_v3_length(rp_v3_sub(b, a)));
        }
    int r = rp_cgal_is_closed(xyz, s->nvertices, tri, ntri, RELATIVE_WELD * shortest);
    free(xyz);
    free(tri);
    return r;
}

/* ------------------------------------------------- derived scenes */

static rp_status copy_strings(char **from, size_t n, char ***to)
{
    *to = n ? calloc(n, sizeof **to) : NULL;
    if (n && !*to)
        return RP_ERR_NOMEM;
    for (size_t i = 0; i < n; i++)
        if (!((*to)[i] = dup_string(from[i])))
            return RP_ERR_NOMEM;
    return RP_OK;
}

static rp_status with_surfaces(const rp_scene *a, const rp_surface_triangles *const *replace, rp_scene *s,
                               size_t *dropped)
{
    const size_t nb = a->nbands;
    s->band_kind = a->band_kind;
    s->nbands = nb;
    if (a->wavelengths) {
        if (!(s->wavelengths = malloc(nb * sizeof *s->wavelengths)))
            return RP_ERR_NOMEM;
        memcpy(s->wavelengths, a->wavelengths, nb * sizeof *s->wavelengths);
    }
    if (copy_strings(a->files, a->nfiles, &s->files) != RP_OK)
        return RP_ERR_NOMEM;
    s->nfiles = s->cap_files = a->nfiles;
    if (copy_strings(a->warnings, a->nwarnings, &s->warnings) != RP_OK)
        return RP_ERR_NOMEM;
    s->nwarnings = s->cap_warnings = a->nwarnings;
    if (a->nmaterials && !(s->materials = calloc(a->nmaterials, sizeof *s->materials)))
        return RP_ERR_NOMEM;
    s->nmaterials = s->cap_materials = a->nmaterials;
    for (size_t i = 0; i < a->nmaterials; i++) {
        rp_material *m = &s->materials[i];
        double *rho = malloc(nb * sizeof *rho), *Le = malloc(nb * sizeof *Le);
        m->name = dup_string(a->materials[i].name);
        m->rho = rho;
        m->Le = Le;
        if (!rho || !Le || !m->name)
            return RP_ERR_NOMEM;
        memcpy(rho, a->materials[i].rho, nb * sizeof *rho);
        memcpy(Le, a->materials[i].Le, nb * sizeof *Le);
        m->emitter = a->materials[i].emitter;
    }
    s->has_camera = a->has_camera;
    s->camera = a->camera;

    /* Kept surfaces keep their vertices (renumbered); replaced ones get
     * their new triangles' vertices. */
    uint32_t *map = malloc((a->nvertices ? a->nvertices : 1) * sizeof *map);
    if (!map)
        return RP_ERR_NOMEM;
    for (size_t i = 0; i < a->nvertices; i++)
        map[i] = RP_NONE;
    if (a->nsurfaces && !(s->surfaces = calloc(a->nsurfaces, sizeof *s->surfaces))) {
        free(map);
        return RP_ERR_NOMEM;
    }
    s->cap_surfaces = a->nsurfaces;
    rp_status st = RP_OK;
    for (size_t k = 0; k < a->nsurfaces && st == RP_OK; k++) {
        const rp_surface *from = &a->surfaces[k];
        rp_surface *to = &s->surfaces[s->nsurfaces++];
        *to = *from;
        to->first_face = (uint32_t)s->nfaces;
        to->nfaces = 0;
        to->area = 0;
        to->file = NULL;
        for (size_t i = 0; i < a->nfiles; i++)
            if (from->file == a->files[i])
                to->file = s->files[i];
        if (!(to->name = dup_string(from->name))) {
            st = RP_ERR_NOMEM;
            break;
        }
        const rp_surface_triangles *r = replace ? replace[k] : NULL;
        size_t base = s->nvertices;
        if (r) {
            if (!grow((void **)&s->vertices, &s->cap_vertices, s->nvertices + r->nvertices, sizeof *s->vertices)) {
                st = RP_ERR_NOMEM;
                break;
            }
            for (size_t i = 0; i < r->nvertices; i++)
                s->vertices[s->nvertices++] = rp_v3(r->xyz[3 * i], r->xyz[3 * i + 1], r->xyz[3 * i + 2]);
        }
        size_t nf = r ? r->ntriangles : from->nfaces;
        if (!grow((void **)&s->faces, &s->cap_faces, s->nfaces + nf, sizeof *s->faces)) {
            st = RP_ERR_NOMEM;
            break;
        }
        for (size_t j = 0; j < nf; j++) {
            rp_face f;
            memset(&f, 0, sizeof f);
            if (r) {
                f.nverts = 3;
                for (int i = 0; i < 3; i++)
                    f.v[i] = (uint32_t)(base + r->tri[3 * j + i]);
                f.v[3] = RP_NONE;
                rp_vec3 v[3] = {s->vertices[f.v[0]], s->vertices[f.v[1]], s->vertices[f.v[2]]};
                char buf[8];
                if (face_check(v, 3, &f.normal, &f.area, buf, sizeof buf)) {
                    (*dropped)++; /* a collapse left a sliver of no area */
                    continue;
                }
            } else {
                f = a->faces[from->first_face + j];
                for (uint32_t i = 0; i < f.nverts && st == RP_OK; i++) {
                    uint32_t v = f.v[i];
                    if (map[v] == RP_NONE) {
                        if (!grow((void **)&s->vertices, &s->cap_vertices, s->nvertices + 1, sizeof *s->vertices))
                            st = RP_ERR_NOMEM;
                        else {
                            s->vertices[s->nvertices] = a->vertices[v];
                            map[v] = (uint32_t)s->nvertices++;
                        }
                    }
                    f.v[i] = map[v];
                }
            }
            f.surface = (uint32_t)k;
            s->faces[s->nfaces++] = f;
            to->nfaces++;
            to->area += f.area;
        }
    }
    free(map);
    if (st == RP_OK)
        compute_bounds(s);
    return st;
}

rp_status rp_scene_with_surfaces(const rp_scene *scene, const rp_surface_triangles *const *replace,
                                 rp_scene **out, size_t *dropped, rp_error *err)
{
    *out = NULL;
    size_t nd = 0;
    rp_scene *s = calloc(1, sizeof *s);
    rp_status st = s ? with_surfaces(scene, replace, s, &nd) : RP_ERR_NOMEM;
    if (st != RP_OK) {
        rp_scene_destroy(s);
        return rp_error_set(err, st, "out of memory copying the scene");
    }
    if (dropped)
        *dropped = nd;
    *out = s;
    return RP_OK;
}
