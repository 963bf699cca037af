/* The CGAL shim: mesh import (CGAL stream readers, tinyobjloader for OBJ+MTL
 * scenes) and closedness of triangle soups.  See import.h.
 *
 * One translation unit on purpose: every CGAL TU costs tens of seconds and
 * over a gigabyte to compile.  Every extern "C" entry point catches all
 * exceptions; nothing here prints (CGAL's verbose readers are captured into a
 * string and quoted in the error message instead). */
#include "geometry/cgal/import.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/OBJ.h>
#include <CGAL/IO/OFF.h>
#include <CGAL/IO/PLY.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>

#define TINYOBJLOADER_USE_DOUBLE /* the Debian library is tinyobjloader_double */
#include <tiny_obj_loader.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

namespace {

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef K::Point_3 Point;
typedef std::vector<std::size_t> Polygon;
namespace PMP = CGAL::Polygon_mesh_processing;

enum Format { FMT_NONE, FMT_OBJ, FMT_OFF, FMT_PLY };

void set_msg(char *msg, size_t msglen, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

void set_msg(char *msg, size_t msglen, const char *fmt, ...)
{
    if (!msg || msglen == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, msglen, fmt, ap);
    va_end(ap);
}

void clear_msg(char *msg, size_t msglen)
{
    if (msg && msglen > 0)
        msg[0] = '\0';
}

Format format_of(const std::string &path, std::string *ext_out)
{
    std::size_t dot = path.find_last_of('.');
    std::size_t slash = path.find_last_of('/');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) {
        *ext_out = "";
        return FMT_NONE;
    }
    std::string ext = path.substr(dot + 1);
    *ext_out = ext;
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return (char)std::tolower(c); });
    if (ext == "obj")
        return FMT_OBJ;
    if (ext == "off")
        return FMT_OFF;
    if (ext == "ply")
        return FMT_PLY;
    return FMT_NONE;
}

/* CGAL's readers report problems on std::cerr (and OBJ notes on std::cout)
 * when verbose; library code must not print, so both streams are captured
 * for the duration of a read and restored even if the reader throws. */
class Capture_streams {
public:
    Capture_streams()
        : old_err_(std::cerr.rdbuf(err_.rdbuf())), old_out_(std::cout.rdbuf(out_.rdbuf()))
    {
    }
    ~Capture_streams()
    {
        std::cerr.rdbuf(old_err_);
        std::cout.rdbuf(old_out_);
    }
    /* The first non-blank line CGAL wrote to cerr, trimmed. */
    std::string first_error() const
    {
        std::istringstream in(err_.str());
        std::string line;
        while (std::getline(in, line)) {
            std::size_t b = line.find_first_not_of(" \t\r");
            if (b == std::string::npos)
                continue;
            std::size_t e = line.find_last_not_of(" \t\r");
            line = line.substr(b, e - b + 1);
            if (line != "File_scanner_OFF::")
                return line;
        }
        return "";
    }

private:
    std::ostringstream err_, out_;
    std::streambuf *old_err_, *old_out_;
};

/* ---- Line-numbered diagnostics for ASCII files ---------------------------
 *
 * CGAL's readers say whether a file is valid, not where it is not.  To name
 * the line of a bad vertex or face, the ASCII formats are re-scanned here
 * into (line, text) records of vertices and faces, and those are checked.
 * This only locates problems; the mesh itself always comes from CGAL. */

struct Record {
    std::size_t line;
    std::string text; /* the record's fields, keyword and comments removed */
};

struct Records {
    bool ok = false; /* false: binary or unrecognised layout, no line numbers */
    std::vector<Record> vertices, faces;
};

std::string strip_comment(const std::string &s)
{
    std::size_t pos = s.find('#');
    return pos == std::string::npos ? s : s.substr(0, pos);
}

bool blank(const std::string &s)
{
    return s.find_first_not_of(" \t\r\n") == std::string::npos;
}

Records scan_obj(std::istream &in)
{
    Records r;
    std::string line;
    std::size_t n = 0;
    while (std::getline(in, line)) {
        ++n;
        std::istringstream ss(strip_comment(line));
        std::string key;
        if (!(ss >> key))
            continue;
        std::string rest;
        std::getline(ss, rest);
        if (key == "v")
            r.vertices.push_back({n, rest});
        else if (key == "f")
            r.faces.push_back({n, rest});
    }
    r.ok = true;
    return r;
}

/* OFF: [keyword line] counts line, one vertex per line, one face per line;
 * blank and comment lines skipped (the layout CGAL's scanner accepts for
 * ASCII files). */
Records scan_off(std::istream &in)
{
    Records r;
    std::vector<Record> data;
    std::string line;
    std::size_t n = 0;
    while (std::getline(in, line)) {
        ++n;
        std::string s = strip_comment(line);
        if (!blank(s))
            data.push_back({n, s});
    }
    if (data.empty())
        return r;
    std::size_t at = 0;
    std::istringstream head(data[0].text);
    std::string key;
    head >> key;
    if (key.find("BINARY") != std::string::npos)
        return r;
    std::string counts;
    if (key.size() >= 3 && key.compare(key.size() - 3, 3, "OFF") == 0) {
        std::getline(head, counts);
        if (blank(counts)) {
            if (data.size() < 2)
                return r;
            counts = data[1].text;
            at = 2;
        } else {
            at = 1;
        }
    } else {
        counts = data[0].text;
        at = 1;
    }
    std::istringstream cs(counts);
    long long nv = -1, nf = -1;
    if (!(cs >> nv >> nf) || nv < 0 || nf < 0)
        return r;
    for (long long i = 0; i < nv && at < data.size(); ++i, ++at)
        r.vertices.push_back(data[at]);
    for (long long i = 0; i < nf && at < data.size(); ++i, ++at)
        r.faces.push_back(data[at]);
    r.ok = true;
    return r;
}

/* PLY (ASCII only): elements in header order, one record per line. */
Records scan_ply(std::istream &in)
{
    Records r;
    std::string line;
    std::size_t n = 0;
    bool ascii = false;
    std::vector<std::pair<std::string, long long> > elements;
    bool header_done = false;
    while (std::getline(in, line)) {
        ++n;
        std::istringstream ss(line);
        std::string key;
        ss >> key;
        if (key == "format") {
            std::string f;
            ss >> f;
            ascii = (f == "ascii");
        } else if (key == "element") {
            std::string name;
            long long count = -1;
            if (!(ss >> name >> count) || count < 0)
                return r;
            elements.push_back({name, count});
        } else if (key == "end_header") {
            header_done = true;
            break;
        }
    }
    if (!header_done || !ascii)
        return r;
    for (const auto &el : elements) {
        for (long long i = 0; i < el.second; ++i) {
            if (!std::getline(in, line))
                break;
            ++n;
            if (el.first == "vertex")
                r.vertices.push_back({n, line});
            else if (el.first == "face")
                r.faces.push_back({n, line});
        }
    }
    r.ok = true;
    return r;
}

Records scan_records(const std::string &path, Format fmt)
{
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return Records();
    switch (fmt) {
    case FMT_OBJ: return scan_obj(in);
    case FMT_OFF: return scan_off(in);
    case FMT_PLY: return scan_ply(in);
    default: return Records();
    }
}

/* Parses one number the way strtod does (so "nan" and "inf" are numbers, and
 * then rejected as non-finite by the caller). */
bool parse_double(const std::string &tok, double *v)
{
    if (tok.empty())
        return false;
    char *end = nullptr;
    errno = 0;
    *v = std::strtod(tok.c_str(), &end);
    return end && *end == '\0';
}

bool parse_long(const std::string &tok, long long *v)
{
    if (tok.empty())
        return false;
    char *end = nullptr;
    errno = 0;
    *v = std::strtoll(tok.c_str(), &end, 10);
    return end && *end == '\0' && errno == 0;
}

/* First problem in the vertex records: fewer than three numbers or a
 * non-finite coordinate.  Returns false if all vertices are fine. */
bool check_vertex_records(const Records &r, std::size_t *line, std::string *what)
{
    for (std::size_t i = 0; i < r.vertices.size(); ++i) {
        std::istringstream ss(r.vertices[i].text);
        for (int c = 0; c < 3; ++c) {
            std::string tok;
            double v;
            if (!(ss >> tok)) {
                *line = r.vertices[i].line;
                *what = "vertex " + std::to_string(i) + " has fewer than 3 coordinates";
                return true;
            }
            if (!parse_double(tok, &v)) {
                *line = r.vertices[i].line;
                *what = "vertex " + std::to_string(i) + ": '" + tok + "' is not a number";
                return true;
            }
            if (!std::isfinite(v)) {
                *line = r.vertices[i].line;
                *what = "vertex " + std::to_string(i) + ": coordinate '" + tok +
                        "' is not finite";
                return true;
            }
        }
    }
    return false;
}

/* First problem in the face records: fewer than three corners, a corner that
 * is not an integer, or an index out of range. */
bool check_face_records(const Records &r, Format fmt, std::size_t *line, std::string *what)
{
    const long long nv = (long long)r.vertices.size();
    for (std::size_t i = 0; i < r.faces.size(); ++i) {
        const Record &rec = r.faces[i];
        std::istringstream ss(rec.text);
        std::vector<std::string> corners;
        std::string tok;
        if (fmt == FMT_OBJ) {
            while (ss >> tok)
                corners.push_back(tok.substr(0, tok.find('/')));
        } else {
            long long count;
            if (!(ss >> tok) || !parse_long(tok, &count) || count < 0) {
                *line = rec.line;
                *what = "face " + std::to_string(i) + ": bad vertex count";
                return true;
            }
            for (long long c = 0; c < count; ++c) {
                if (!(ss >> tok)) {
                    *line = rec.line;
                    *what = "face " + std::to_string(i) + ": expected " +
                            std::to_string(count) + " vertex indices";
                    return true;
                }
                corners.push_back(tok);
            }
        }
        if (corners.size() < 3) {
            *line = rec.line;
            *what = "face " + std::to_string(i) + " has fewer than 3 vertices";
            return true;
        }
        for (const std::string &c : corners) {
            long long k;
            if (!parse_long(c, &k)) {
                *line = rec.line;
                *what = "face " + std::to_string(i) + ": '" + c + "' is not a vertex index";
                return true;
            }
            long long idx = k;
            if (fmt == FMT_OBJ)
                idx = k > 0 ? k - 1 : (k < 0 ? nv + k : -1); /* 1-based, negative relative */
            if (idx < 0 || idx >= nv) {
                *line = rec.line;
                *what = "face " + std::to_string(i) + ": vertex index " + c +
                        " out of range (" + std::to_string(nv) + " vertices)";
                return true;
            }
        }
    }
    return false;
}

/* The line of face `index` in an ASCII file (0 if unknown). */
std::size_t face_line(const std::string &path, Format fmt, std::size_t index)
{
    Records r = scan_records(path, fmt);
    return r.ok && index < r.faces.size() ? r.faces[index].line : 0;
}

/* Writes "PATH:LINE: what" (or "PATH: what" with no line). */
int fail(char *msg, size_t msglen, const std::string &path, std::size_t line,
         const std::string &what)
{
    if (line > 0)
        set_msg(msg, msglen, "%s:%zu: %s", path.c_str(), line, what.c_str());
    else
        set_msg(msg, msglen, "%s: %s", path.c_str(), what.c_str());
    return 1;
}

/* Looks for a located problem in an ASCII file; true if one was reported. */
bool fail_located(char *msg, size_t msglen, const std::string &path, Format fmt)
{
    Records r = scan_records(path, fmt);
    if (!r.ok)
        return false;
    std::size_t line = 0;
    std::string what;
    if (check_vertex_records(r, &line, &what) || check_face_records(r, fmt, &line, &what)) {
        fail(msg, msglen, path, line, what);
        return true;
    }
    return false;
}

/* ---- Triangle bookkeeping shared by both readers ------------------------- */

struct Tri {
    std::size_t v[3];
    std::size_t face; /* input face (polygon) it came from */
};

/* Edges traversed twice in the same direction: each such repetition is one
 * orientation conflict between two faces (a consistently oriented 2-manifold
 * uses every directed edge at most once). */
std::size_t count_orientation_conflicts(const std::vector<Tri> &tris)
{
    std::vector<std::pair<std::size_t, std::size_t> > edges;
    edges.reserve(3 * tris.size());
    for (const Tri &t : tris)
        for (int k = 0; k < 3; ++k)
            edges.push_back({t.v[k], t.v[(k + 1) % 3]});
    std::sort(edges.begin(), edges.end());
    std::size_t conflicts = 0;
    for (std::size_t i = 1; i < edges.size(); ++i)
        if (edges[i] == edges[i - 1])
            ++conflicts;
    return conflicts;
}

/* Newell's normal of a polygon (its area vector times two), well defined for
 * non-planar and non-convex polygons. */
K::Vector_3 newell_normal(const std::vector<Point> &pts)
{
    double nx = 0, ny = 0, nz = 0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const Point &a = pts[i], &b = pts[(i + 1) % pts.size()];
        nx += (a.y() - b.y()) * (a.z() + b.z());
        ny += (a.z() - b.z()) * (a.x() + b.x());
        nz += (a.x() - b.x()) * (a.y() + b.y());
    }
    return K::Vector_3(nx, ny, nz);
}

/* Triangulates one polygon with CGAL's hole filling (Liepa 2003): a 2D
 * constrained Delaunay triangulation in the fitting plane for (near-)planar
 * polygons, convex or not, and a minimum-area search otherwise.  Each
 * triangle keeps the polygon's winding.  Empty if CGAL finds none. */
std::vector<Tri> triangulate_polygon(const std::vector<Point> &points, const Polygon &poly,
                                     std::size_t face)
{
    std::vector<Tri> out;
    if (poly.size() == 3) {
        out.push_back({{poly[0], poly[1], poly[2]}, face});
        return out;
    }
    std::vector<Point> ring;
    ring.reserve(poly.size());
    for (std::size_t v : poly)
        ring.push_back(points[v]);
    std::vector<CGAL::Triple<int, int, int> > patch;
    PMP::triangulate_hole_polyline(
        ring, std::back_inserter(patch),
        CGAL::parameters::use_2d_constrained_delaunay_triangulation(true));
    const K::Vector_3 n = newell_normal(ring);
    for (const auto &t : patch) {
        std::size_t a = (std::size_t)t.first, b = (std::size_t)t.second,
                    c = (std::size_t)t.third;
        if (a >= poly.size() || b >= poly.size() || c >= poly.size())
            continue;
        const K::Vector_3 tn = CGAL::cross_product(ring[b] - ring[a], ring[c] - ring[a]);
        if (tn * n < 0)
            std::swap(b, c);
        out.push_back({{poly[a], poly[b], poly[c]}, face});
    }
    return out;
}

bool degenerate(const std::vector<Point> &pts, const Tri &t)
{
    /* Exact predicate: zero area exactly, not within a tolerance. */
    return CGAL::collinear(pts[t.v[0]], pts[t.v[1]], pts[t.v[2]]);
}

template <class T> T *alloc_array(std::size_t n)
{
    void *p = std::calloc(n > 0 ? n : 1, sizeof(T));
    if (!p)
        throw std::bad_alloc();
    return static_cast<T *>(p);
}

char *dup_string(const std::string &s)
{
    char *p = alloc_array<char>(s.size() + 1);
    std::memcpy(p, s.c_str(), s.size() + 1);
    return p;
}

void fill_geometry(rp_tri_mesh *m, const std::vector<Point> &pts, const std::vector<Tri> &tris)
{
    m->nvertices = pts.size();
    m->xyz = alloc_array<double>(3 * pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) {
        m->xyz[3 * i + 0] = pts[i].x();
        m->xyz[3 * i + 1] = pts[i].y();
        m->xyz[3 * i + 2] = pts[i].z();
    }
    m->ntriangles = tris.size();
    m->tri = alloc_array<uint32_t>(3 * tris.size());
    for (std::size_t i = 0; i < tris.size(); ++i)
        for (int k = 0; k < 3; ++k)
            m->tri[3 * i + k] = (uint32_t)tris[i].v[k];
}

void free_mesh(rp_tri_mesh *m)
{
    if (!m)
        return;
    std::free(m->xyz);
    std::free(m->tri);
    std::free(m->tri_group);
    if (m->group_names)
        for (std::size_t i = 0; i < m->ngroups; ++i)
            std::free(m->group_names[i]);
    std::free(m->group_names);
    std::free(m->tri_material);
    if (m->material_names)
        for (std::size_t i = 0; i < m->nmaterials; ++i)
            std::free(m->material_names[i]);
    std::free(m->material_names);
    std::free(m->material_kd);
    std::free(m->material_ke);
    std::memset(m, 0, sizeof *m);
}

/* ---- rp_cgal_read_mesh ---------------------------------------------------- */

int read_mesh(const std::string &path, int reject_degenerate, rp_tri_mesh *out, char *msg,
              size_t msglen)
{
    std::string ext;
    const Format fmt = format_of(path, &ext);
    if (fmt == FMT_NONE)
        return fail(msg, msglen, path, 0,
                    "unknown mesh extension '" + ext + "' (expected .obj, .off or .ply)");
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return fail(msg, msglen, path, 0, std::string("cannot open: ") + std::strerror(errno));

    std::vector<Point> points;
    std::vector<Polygon> polygons;
    bool ok;
    std::string cgal_says;
    {
        Capture_streams capture;
        const auto np = CGAL::parameters::verbose(true);
        if (fmt == FMT_OBJ)
            ok = CGAL::IO::read_OBJ(in, points, polygons, np);
        else if (fmt == FMT_OFF)
            ok = CGAL::IO::read_OFF(in, points, polygons, np);
        else
            ok = CGAL::IO::read_PLY(in, points, polygons, np);
        cgal_says = capture.first_error();
    }
    const char *name = fmt == FMT_OBJ ? "OBJ" : fmt == FMT_OFF ? "OFF" : "PLY";
    if (!ok) {
        if (fail_located(msg, msglen, path, fmt))
            return 1;
        if (points.empty() && polygons.empty() && cgal_says.find("empty") != std::string::npos)
            return fail(msg, msglen, path, 0, "no vertices or no faces");
        std::string what = std::string("not a valid ") + name + " file";
        if (!cgal_says.empty())
            what += " (CGAL: " + cgal_says + ")";
        return fail(msg, msglen, path, 0, what);
    }
    if (points.empty())
        return fail(msg, msglen, path, 0, "no vertices");
    if (polygons.empty())
        return fail(msg, msglen, path, 0, "no faces");
    if (points.size() > UINT32_MAX)
        return fail(msg, msglen, path, 0, "too many vertices for 32-bit indices");

    /* CGAL accepts some of these (non-finite numbers in some formats, one
     * past the last vertex in OBJ): check again, and locate if we can. */
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Point &p = points[i];
        if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
            if (fail_located(msg, msglen, path, fmt))
                return 1;
            return fail(msg, msglen, path, 0,
                        "vertex " + std::to_string(i) + " has a non-finite coordinate");
        }
    }
    for (std::size_t f = 0; f < polygons.size(); ++f) {
        const Polygon &poly = polygons[f];
        bool bad = poly.size() < 3;
        for (std::size_t v : poly)
            bad = bad || v >= points.size();
        if (bad) {
            if (fail_located(msg, msglen, path, fmt))
                return 1;
            return fail(msg, msglen, path, face_line(path, fmt, f),
                        "face " + std::to_string(f) +
                            (poly.size() < 3 ? " has fewer than 3 vertices"
                                             : " has a vertex index out of range"));
        }
    }

    std::vector<Tri> tris;
    tris.reserve(polygons.size());
    std::size_t ndegenerate = 0;
    for (std::size_t f = 0; f < polygons.size(); ++f) {
        std::vector<Tri> t = triangulate_polygon(points, polygons[f], f);
        std::size_t bad = t.empty() ? polygons[f].size() - 2 : 0;
        for (const Tri &tri : t) {
            if (degenerate(points, tri))
                ++bad;
            else
                tris.push_back(tri);
        }
        if (bad > 0 && reject_degenerate)
            return fail(msg, msglen, path, face_line(path, fmt, f),
                        "face " + std::to_string(f) + " is degenerate (zero area)");
        ndegenerate += bad;
    }
    if (tris.empty())
        return fail(msg, msglen, path, 0, "every face is degenerate (zero area)");

    rp_tri_mesh m;
    std::memset(&m, 0, sizeof m);
    try {
        fill_geometry(&m, points, tris);
    } catch (...) {
        free_mesh(&m);
        throw;
    }
    m.degenerate_faces = ndegenerate;
    m.orientation_conflicts = count_orientation_conflicts(tris);
    *out = m;
    return 0;
}

/* ---- rp_obj_read_scene ---------------------------------------------------- */

/* tinyobjloader only warns when an mtllib file is missing and carries on with
 * default materials; a scene must not silently lose its materials, so the
 * file reader is wrapped to remember which libraries failed. */
class Checked_material_reader : public tinyobj::MaterialReader {
public:
    explicit Checked_material_reader(const std::string &basedir) : inner_(basedir) {}
    bool operator()(const std::string &mat_id, std::vector<tinyobj::material_t> *materials,
                    std::map<std::string, int> *mat_map, std::string *warn,
                    std::string *err) override
    {
        bool ok = inner_(mat_id, materials, mat_map, warn, err);
        if (!ok)
            missing.push_back(mat_id);
        return ok;
    }
    std::vector<std::string> missing;

private:
    tinyobj::MaterialFileReader inner_;
};

std::string first_line(const std::string &s)
{
    std::istringstream in(s);
    std::string line;
    while (std::getline(in, line))
        if (!blank(line))
            return line;
    return "";
}

/* tinyobjloader reports " (line N.)" inside some warnings: split it out. */
std::size_t line_in_warning(std::string *w)
{
    std::size_t p = w->find("(line ");
    if (p == std::string::npos)
        return 0;
    std::size_t n = (std::size_t)std::strtoull(w->c_str() + p + 6, nullptr, 10);
    std::size_t b = p;
    while (b > 0 && (*w)[b - 1] == ' ')
        --b;
    w->erase(b);
    return n;
}

int read_scene(const std::string &path, rp_tri_mesh *out, char *msg, size_t msglen)
{
    std::string ext;
    if (format_of(path, &ext) != FMT_OBJ)
        return fail(msg, msglen, path, 0, "a scene mesh must be .obj, not '" + ext + "'");
    std::ifstream in(path);
    if (!in)
        return fail(msg, msglen, path, 0, std::string("cannot open: ") + std::strerror(errno));

    /* tinyobjloader reads "nan" as 0 without a word, and reports bad face
     * indices without their line: check both first. */
    {
        Records r = scan_records(path, FMT_OBJ);
        std::size_t line = 0;
        std::string what;
        if (check_vertex_records(r, &line, &what) ||
            check_face_records(r, FMT_OBJ, &line, &what))
            return fail(msg, msglen, path, line, what);
        /* tinyobjloader stores a face's corner count in an unsigned char. */
        for (const Record &f : r.faces) {
            std::istringstream ss(f.text);
            std::string tok;
            std::size_t n = 0;
            while (ss >> tok)
                ++n;
            if (n > 255)
                return fail(msg, msglen, path, f.line,
                            "face with " + std::to_string(n) +
                                " vertices (at most 255 in an OBJ scene)");
        }
    }

    std::size_t slash = path.find_last_of('/');
    std::string basedir = slash == std::string::npos ? "" : path.substr(0, slash + 1);
    Checked_material_reader reader(basedir);
    tinyobj::attrib_t attrib;
    std::vector<tinyobj::shape_t> shapes;
    std::vector<tinyobj::material_t> materials;
    std::string warn, err;
    /* Polygons are triangulated below by CGAL, as in rp_cgal_read_mesh, so
     * both readers split a polygon the same way. */
    bool ok = tinyobj::LoadObj(&attrib, &shapes, &materials, &warn, &err, &in, &reader,
                               false /* triangulate */, false);
    if (!ok || !err.empty()) {
        std::string e = first_line(err);
        return fail(msg, msglen, path, 0, e.empty() ? "not a valid OBJ file" : e);
    }
    if (!reader.missing.empty())
        return fail(msg, msglen, path, 0,
                    "material library '" + reader.missing[0] + "' not found");
    /* Warnings that would change the scene are errors; the rest are passed
     * on in msg with a successful return. */
    {
        std::istringstream ws(warn);
        std::string w;
        while (std::getline(ws, w)) {
            if (w.find("not found") != std::string::npos ||
                w.find("out of bounds") != std::string::npos) {
                std::size_t line = line_in_warning(&w);
                return fail(msg, msglen, path, line, w);
            }
        }
    }

    const std::size_t nv = attrib.vertices.size() / 3;
    if (nv == 0)
        return fail(msg, msglen, path, 0, "no vertices");
    if (nv > UINT32_MAX)
        return fail(msg, msglen, path, 0, "too many vertices for 32-bit indices");
    std::vector<Point> points;
    points.reserve(nv);
    for (std::size_t i = 0; i < nv; ++i)
        points.emplace_back(attrib.vertices[3 * i], attrib.vertices[3 * i + 1],
                            attrib.vertices[3 * i + 2]);
    for (std::size_t i = 0; i < nv; ++i)
        if (!std::isfinite(points[i].x()) || !std::isfinite(points[i].y()) ||
            !std::isfinite(points[i].z()))
            return fail(msg, msglen, path, 0,
                        "vertex " + std::to_string(i) + " has a non-finite coordinate");

    /* Groups by name: a name used by several o/g statements is one group. */
    std::vector<std::string> group_names;
    std::map<std::string, std::size_t> group_of;
    std::vector<Tri> tris;
    std::vector<uint32_t> tri_group, tri_material;
    std::size_t ndegenerate = 0, face = 0;
    for (const tinyobj::shape_t &s : shapes) {
        const tinyobj::mesh_t &mesh = s.mesh;
        if (mesh.num_face_vertices.empty())
            continue;
        auto g = group_of.find(s.name);
        std::size_t gi;
        if (g == group_of.end()) {
            gi = group_names.size();
            group_of[s.name] = gi;
            group_names.push_back(s.name);
        } else {
            gi = g->second;
        }
        std::size_t at = 0;
        for (std::size_t f = 0; f < mesh.num_face_vertices.size(); ++f, ++face) {
            const std::size_t nc = mesh.num_face_vertices[f];
            if (nc < 3 || at + nc > mesh.indices.size())
                return fail(msg, msglen, path, 0,
                            "face " + std::to_string(face) + " has fewer than 3 vertices");
            Polygon poly(nc);
            for (std::size_t k = 0; k < nc; ++k) {
                int vi = mesh.indices[at + k].vertex_index;
                if (vi < 0 || (std::size_t)vi >= nv)
                    return fail(msg, msglen, path, 0,
                                "face " + std::to_string(face) + ": vertex index out of range");
                poly[k] = (std::size_t)vi;
            }
            at += nc;
            const int mat = f < mesh.material_ids.size() ? mesh.material_ids[f] : -1;
            const uint32_t mi = mat >= 0 && (std::size_t)mat < materials.size()
                                    ? (uint32_t)mat
                                    : UINT32_MAX;
            std::vector<Tri> t = triangulate_polygon(points, poly, face);
            if (t.empty())
                ndegenerate += nc - 2;
            for (const Tri &tri : t) {
                if (degenerate(points, tri)) {
                    ++ndegenerate;
                    continue;
                }
                tris.push_back(tri);
                tri_group.push_back((uint32_t)gi);
                tri_material.push_back(mi);
            }
        }
    }
    if (face == 0)
        return fail(msg, msglen, path, 0, "no faces");
    if (tris.empty())
        return fail(msg, msglen, path, 0, "every face is degenerate (zero area)");

    rp_tri_mesh m;
    std::memset(&m, 0, sizeof m);
    try {
        fill_geometry(&m, points, tris);
        m.tri_group = alloc_array<uint32_t>(tris.size());
        m.tri_material = alloc_array<uint32_t>(tris.size());
        std::copy(tri_group.begin(), tri_group.end(), m.tri_group);
        std::copy(tri_material.begin(), tri_material.end(), m.tri_material);
        m.group_names = alloc_array<char *>(group_names.size());
        m.ngroups = group_names.size();
        for (std::size_t i = 0; i < group_names.size(); ++i)
            m.group_names[i] = dup_string(group_names[i]);
        m.nmaterials = materials.size();
        m.material_names = alloc_array<char *>(materials.size());
        m.material_kd = alloc_array<double>(3 * materials.size());
        m.material_ke = alloc_array<double>(3 * materials.size());
        for (std::size_t i = 0; i < materials.size(); ++i) {
            m.material_names[i] = dup_string(materials[i].name);
            for (int c = 0; c < 3; ++c) {
                m.material_kd[3 * i + c] = materials[i].diffuse[c];
                m.material_ke[3 * i + c] = materials[i].emission[c];
            }
        }
    } catch (...) {
        free_mesh(&m);
        throw;
    }
    m.degenerate_faces = ndegenerate;
    m.orientation_conflicts = count_orientation_conflicts(tris);
    *out = m;

    std::string w = first_line(warn);
    if (!w.empty())
        set_msg(msg, msglen, "%s: %s", path.c_str(), w.c_str());
    return 0;
}

/* ---- rp_cgal_is_closed ---------------------------------------------------- */

/* Welds vertices closer than tol to the first vertex seen within tol of
 * them, using a uniform grid of cell size tol (so neighbours are found in
 * the 27 surrounding cells).  Returns the representative of each vertex. */
std::vector<std::size_t> weld(const double *xyz, std::size_t n, double tol)
{
    std::vector<std::size_t> rep(n);
    if (!(tol > 0)) {
        std::map<std::array<double, 3>, std::size_t> seen;
        for (std::size_t i = 0; i < n; ++i) {
            std::array<double, 3> key = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};
            rep[i] = seen.emplace(key, i).first->second;
        }
        return rep;
    }
    struct Cell_hash {
        std::size_t operator()(const std::array<long long, 3> &c) const
        {
            return (std::size_t)((unsigned long long)c[0] * 73856093ULL ^
                                 (unsigned long long)c[1] * 19349663ULL ^
                                 (unsigned long long)c[2] * 83492791ULL);
        }
    };
    std::unordered_map<std::array<long long, 3>, std::vector<std::size_t>, Cell_hash> grid;
    const double tol2 = tol * tol;
    for (std::size_t i = 0; i < n; ++i) {
        const double *p = xyz + 3 * i;
        std::array<long long, 3> c;
        /* Clamped so that huge coordinates over a tiny tolerance stay
         * representable; a clamped cell is only a fuller bucket. */
        for (int k = 0; k < 3; ++k)
            c[k] = (long long)std::max(-0x1p62, std::min(0x1p62, std::floor(p[k] / tol)));
        std::size_t found = i;
        for (int dx = -1; dx <= 1 && found == i; ++dx)
            for (int dy = -1; dy <= 1 && found == i; ++dy)
                for (int dz = -1; dz <= 1 && found == i; ++dz) {
                    auto it = grid.find({c[0] + dx, c[1] + dy, c[2] + dz});
                    if (it == grid.end())
                        continue;
                    for (std::size_t j : it->second) {
                        const double *q = xyz + 3 * j;
                        double d2 = (p[0] - q[0]) * (p[0] - q[0]) +
                                    (p[1] - q[1]) * (p[1] - q[1]) +
                                    (p[2] - q[2]) * (p[2] - q[2]);
                        if (d2 <= tol2) {
                            found = j;
                            break;
                        }
                    }
                }
        rep[i] = found;
        if (found == i)
            grid[c].push_back(i);
    }
    return rep;
}

int is_closed(const double *xyz, size_t nvertices, const uint32_t *tri, size_t ntriangles,
              double tol)
{
    if (!xyz || !tri || nvertices == 0 || ntriangles == 0 || !(tol >= 0) || !std::isfinite(tol))
        return -1;
    for (std::size_t i = 0; i < 3 * nvertices; ++i)
        if (!std::isfinite(xyz[i]))
            return -1;
    for (std::size_t i = 0; i < 3 * ntriangles; ++i)
        if (tri[i] >= nvertices)
            return -1;
    const std::vector<std::size_t> rep = weld(xyz, nvertices, tol);

    /* A closed surface: every undirected edge is shared by exactly two
     * triangles (a 2-manifold without boundary; four triangles on one edge
     * is non-manifold and not counted as closed).  Triangles that welding
     * collapsed to a segment or a point have no area and are ignored. */
    std::vector<std::pair<std::size_t, std::size_t> > edges;
    edges.reserve(3 * ntriangles);
    for (std::size_t t = 0; t < ntriangles; ++t) {
        std::size_t v[3] = {rep[tri[3 * t]], rep[tri[3 * t + 1]], rep[tri[3 * t + 2]]};
        if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2])
            continue;
        for (int k = 0; k < 3; ++k) {
            std::size_t a = v[k], b = v[(k + 1) % 3];
            edges.push_back({std::min(a, b), std::max(a, b)});
        }
    }
    if (edges.empty())
        return 0;
    std::sort(edges.begin(), edges.end());
    for (std::size_t i = 0; i < edges.size();) {
        std::size_t j = i;
        while (j < edges.size() && edges[j] == edges[i])
            ++j;
        if (j - i != 2)
            return 0;
        i = j;
    }
    return 1;
}

} // namespace

extern "C" int rp_cgal_read_mesh(const char *path, int reject_degenerate, rp_tri_mesh *out,
                                 char *msg, size_t msglen)
{
    clear_msg(msg, msglen);
    if (!path || !out) {
        set_msg(msg, msglen, "rp_cgal_read_mesh: NULL argument");
        return 1;
    }
    std::memset(out, 0, sizeof *out);
    try {
        return read_mesh(path, reject_degenerate, out, msg, msglen);
    } catch (const std::bad_alloc &) {
        set_msg(msg, msglen, "%s: out of memory", path);
    } catch (const std::exception &e) {
        set_msg(msg, msglen, "%s: %s", path, e.what());
    } catch (...) {
        set_msg(msg, msglen, "%s: unexpected error while reading", path);
    }
    return 1;
}

extern "C" int rp_obj_read_scene(const char *path, rp_tri_mesh *out, char *msg, size_t msglen)
{
    clear_msg(msg, msglen);
    if (!path || !out) {
        set_msg(msg, msglen, "rp_obj_read_scene: NULL argument");
        return 1;
    }
    std::memset(out, 0, sizeof *out);
    try {
        return read_scene(path, out, msg, msglen);
    } catch (const std::bad_alloc &) {
        set_msg(msg, msglen, "%s: out of memory", path);
    } catch (const std::exception &e) {
        set_msg(msg, msglen, "%s: %s", path, e.what());
    } catch (...) {
        set_msg(msg, msglen, "%s: unexpected error while reading", path);
    }
    return 1;
}

extern "C" void rp_tri_mesh_free(rp_tri_mesh *m)
{
    free_mesh(m);
}

extern "C" int rp_cgal_is_closed(const double *xyz, size_t nvertices, const uint32_t *tri,
                                 size_t ntriangles, double weld_tolerance)
{
    try {
        return is_closed(xyz, nvertices, tri, ntriangles, weld_tolerance);
    } catch (...) {
        return -1;
    }
}
