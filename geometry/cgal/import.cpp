/* The CGAL shim: mesh import (CGAL stream readers; radpt's own line-numbered
 * reader for OBJ+MTL scenes) and closedness of triangle soups.  See import.h.
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
#include <set>
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
    std::vector<Record> other; /* OBJ: every other statement, text = keyword */
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
        else
            r.other.push_back({n, key});
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
            data.push_back({n, std::move(s)});
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
    r.vertices.reserve((std::size_t)std::min<long long>(nv, (long long)data.size()));
    r.faces.reserve((std::size_t)std::min<long long>(nf, (long long)data.size()));
    for (long long i = 0; i < nv && at < data.size(); ++i, ++at)
        r.vertices.push_back(std::move(data[at]));
    for (long long i = 0; i < nf && at < data.size(); ++i, ++at)
        r.faces.push_back(std::move(data[at]));
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
    std::size_t line; /* that face's line in the file (0: unknown) */
};

/* How many of something, and the line of the first (0: unknown). */
struct Tally {
    std::size_t count = 0, line = 0;
    void add(std::size_t l)
    {
        if (count++ == 0)
            line = l;
    }
};

/* Edges traversed twice in the same direction: each such repetition is one
 * orientation conflict between two faces (a consistently oriented 2-manifold
 * uses every directed edge at most once).  Counted on the faces' own
 * boundaries, not their triangles: a quad's diagonal runs both ways inside
 * it, so a two-sided sheet of quads would otherwise conflict with itself.
 * The line is the earliest line of a face that repeats an edge of a face
 * before it. */
Tally orientation_conflicts(const std::vector<Polygon> &polys, const std::vector<char> &kept,
                            const std::vector<std::size_t> &lines)
{
    struct Edge {
        std::size_t a, b, face;
        bool operator<(const Edge &o) const
        {
            return a != o.a ? a < o.a : b != o.b ? b < o.b : face < o.face;
        }
    };
    std::vector<Edge> edges;
    for (std::size_t f = 0; f < polys.size(); ++f) {
        if (!kept[f])
            continue;
        const Polygon &p = polys[f];
        for (std::size_t k = 0; k < p.size(); ++k)
            if (p[k] != p[(k + 1) % p.size()])
                edges.push_back({p[k], p[(k + 1) % p.size()], f});
    }
    std::sort(edges.begin(), edges.end());
    Tally conflicts;
    for (std::size_t i = 1; i < edges.size(); ++i)
        if (edges[i].a == edges[i - 1].a && edges[i].b == edges[i - 1].b) {
            const std::size_t l = edges[i].face < lines.size() ? lines[edges[i].face] : 0;
            ++conflicts.count;
            if (l > 0 && (conflicts.line == 0 || l < conflicts.line))
                conflicts.line = l;
        }
    return conflicts;
}

/* Flags the faces that repeat an earlier face exactly: the same vertex
 * positions in the same cyclic order, from any starting corner.  Positions,
 * not indices, so a copy over duplicated vertices is found too; the reverse
 * order is another face (the back of a two-sided sheet).  Each face is
 * brought to its lexicographically smallest rotation and hashed (FNV-1a
 * over the coordinates' bits); faces with equal hashes are compared in
 * full. */
std::vector<char> duplicate_faces(const std::vector<Point> &pts, const std::vector<Polygon> &polys)
{
    auto coord = [&](const Polygon &p, std::size_t k, int c) {
        const Point &q = pts[p[k % p.size()]];
        const double v = c == 0 ? q.x() : c == 1 ? q.y() : q.z();
        return v == 0 ? 0.0 : v; /* -0 and +0 are one position */
    };
    /* <0, 0, >0: corner sequence of p from rotation i against q from j */
    auto compare = [&](const Polygon &p, std::size_t i, const Polygon &q, std::size_t j) {
        for (std::size_t k = 0; k < p.size(); ++k)
            for (int c = 0; c < 3; ++c) {
                const double a = coord(p, i + k, c), b = coord(q, j + k, c);
                if (a != b)
                    return a < b ? -1 : 1;
            }
        return 0;
    };
    const std::size_t n = polys.size();
    std::vector<std::size_t> rot(n, 0);
    std::vector<std::pair<uint64_t, std::size_t> > order(n);
    for (std::size_t f = 0; f < n; ++f) {
        const Polygon &p = polys[f];
        for (std::size_t r = 1; r < p.size(); ++r)
            if (compare(p, r, p, rot[f]) < 0)
                rot[f] = r;
        uint64_t h = UINT64_C(0xcbf29ce484222325) ^ p.size();
        for (std::size_t k = 0; k < p.size(); ++k)
            for (int c = 0; c < 3; ++c) {
                const double v = coord(p, rot[f] + k, c);
                uint64_t bits;
                std::memcpy(&bits, &v, sizeof bits);
                for (int byte = 0; byte < 8; ++byte) {
                    h ^= (bits >> (8 * byte)) & 0xff;
                    h *= UINT64_C(0x100000001b3);
                }
            }
        order[f] = {h, f};
    }
    std::sort(order.begin(), order.end());
    std::vector<char> dup(n, 0);
    for (std::size_t i = 0; i < n;) {
        std::size_t j = i;
        while (j < n && order[j].first == order[i].first)
            ++j;
        /* a run of equal hashes, in file order: each face against the
         * earlier ones not already found to be copies */
        for (std::size_t a = i + 1; a < j; ++a)
            for (std::size_t b = i; b < a && !dup[order[a].second]; ++b) {
                const std::size_t fa = order[a].second, fb = order[b].second;
                if (!dup[fb] && polys[fa].size() == polys[fb].size() &&
                    compare(polys[fa], rot[fa], polys[fb], rot[fb]) == 0)
                    dup[fa] = 1;
            }
        i = j;
    }
    return dup;
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
                                     std::size_t face, std::size_t line)
{
    std::vector<Tri> out;
    if (poly.size() == 3) {
        out.push_back({{poly[0], poly[1], poly[2]}, face, line});
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
        out.push_back({{poly[a], poly[b], poly[c]}, face, line});
    }
    return out;
}

bool degenerate(const std::vector<Point> &pts, const Tri &t)
{
    /* Exact predicate: zero area exactly, not within a tolerance. */
    return CGAL::collinear(pts[t.v[0]], pts[t.v[1]], pts[t.v[2]]);
}

/* Every face triangulated, exact duplicates and zero-area faces dropped
 * and counted (lines[f] is face f's line, 0 if unknown).  A face is
 * zero-area when none of its triangles has area (or CGAL finds no
 * triangulation); zero-area slivers of a face with area are left out
 * without counting, as they carry nothing. */
struct Triangulation {
    std::vector<Tri> tris;
    Tally degenerate, duplicate, orientation;
    std::size_t first_degenerate_face = SIZE_MAX;
};

Triangulation triangulate_faces(const std::vector<Point> &points, const std::vector<Polygon> &polys,
                                const std::vector<std::size_t> &lines)
{
    Triangulation out;
    out.tris.reserve(polys.size());
    const std::vector<char> dup = duplicate_faces(points, polys);
    std::vector<char> kept_face(polys.size(), 0);
    for (std::size_t f = 0; f < polys.size(); ++f) {
        const std::size_t line = f < lines.size() ? lines[f] : 0;
        if (dup[f]) {
            out.duplicate.add(line);
            continue;
        }
        std::size_t kept = 0;
        for (const Tri &t : triangulate_polygon(points, polys[f], f, line))
            if (!degenerate(points, t)) {
                out.tris.push_back(t);
                ++kept;
            }
        kept_face[f] = kept > 0;
        if (kept == 0) {
            out.degenerate.add(line);
            if (out.first_degenerate_face == SIZE_MAX)
                out.first_degenerate_face = f;
        }
    }
    out.orientation = orientation_conflicts(polys, kept_face, lines);
    return out;
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
    m->tri_line = alloc_array<uint32_t>(tris.size());
    for (std::size_t i = 0; i < tris.size(); ++i) {
        for (int k = 0; k < 3; ++k)
            m->tri[3 * i + k] = (uint32_t)tris[i].v[k];
        m->tri_line[i] = tris[i].line <= UINT32_MAX ? (uint32_t)tris[i].line : 0;
    }
}

/* The reader's drop counts and messages into m. */
void fill_diagnostics(rp_tri_mesh *m, const Triangulation &t, const std::vector<std::string> &warnings)
{
    m->degenerate_faces = t.degenerate.count;
    m->degenerate_line = t.degenerate.line;
    m->duplicate_faces = t.duplicate.count;
    m->duplicate_line = t.duplicate.line;
    m->orientation_conflicts = t.orientation.count;
    m->orientation_line = t.orientation.line;
    m->warnings = alloc_array<char *>(warnings.size());
    m->nwarnings = warnings.size();
    for (std::size_t i = 0; i < warnings.size(); ++i)
        m->warnings[i] = dup_string(warnings[i]);
}

void free_mesh(rp_tri_mesh *m)
{
    if (!m)
        return;
    std::free(m->xyz);
    std::free(m->tri);
    std::free(m->tri_line);
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
    if (m->warnings)
        for (std::size_t i = 0; i < m->nwarnings; ++i)
            std::free(m->warnings[i]);
    std::free(m->warnings);
    std::memset(m, 0, sizeof *m);
}

/* Statements a reader does not use, counted by keyword in the order first
 * seen: "Ks (8 materials), Ns (8), ...". */
struct Ignored {
    std::vector<std::string> order;
    std::map<std::string, std::size_t> count;
    std::size_t first_line = 0;
    void add(const std::string &key, std::size_t line)
    {
        std::string k = printable(key);
        if (count.find(k) == count.end())
            order.push_back(k);
        ++count[k];
        if (first_line == 0 || (line > 0 && line < first_line))
            first_line = line;
    }
    /* unit is singular ("line", "material"); an s is added after counts
     * other than 1. */
    std::string list(const char *unit) const
    {
        std::string s;
        for (std::size_t i = 0; i < order.size(); ++i) {
            const std::size_t n = count.at(order[i]);
            s += (i ? ", " : "") + order[i] + " (" + std::to_string(n);
            if (i == 0)
                s += std::string(" ") + unit + (n == 1 ? "" : "s");
            s += ")";
        }
        return s;
    }

private:
    /* A keyword from the file as a message can show it: at most 32
     * characters, anything unprintable as '?'. */
    static std::string printable(const std::string &k)
    {
        std::string r = k.substr(0, 32);
        for (char &c : r)
            if ((unsigned char)c < 0x20 || (unsigned char)c >= 0x7f)
                c = '?';
        return r;
    }
};

/* ---- header counts --------------------------------------------------------- */

/* One count of a header: absurd when the file cannot hold that many
 * entries of at least min_bytes each (scale-free: no fixed limit), or
 * when it is negative or not a whole number.  Checked before any reader
 * allocates for it. */
bool count_fits(const std::string &tok, long long bytes, long long min_bytes, long long *out)
{
    if (tok.empty() || tok.find_first_not_of("0123456789") != std::string::npos || tok.size() > 18)
        return false;
    const long long v = std::stoll(tok);
    *out = v;
    return v <= bytes / min_bytes;
}

/* Refuses an OFF or PLY header whose vertex or face count the file cannot
 * hold, with FILE:LINE and the count, before CGAL's reader reserves room
 * for it: at least 6 bytes a vertex ("x y z" and a newline; 12 in binary)
 * and 8 a face ("3 a b c" and a newline; 4 in binary PLY). */
int check_header_counts(const std::string &path, Format fmt, char *msg, size_t msglen)
{
    if (fmt != FMT_OFF && fmt != FMT_PLY)
        return 0;
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in)
        return 0;
    const long long bytes = (long long)in.tellg();
    in.seekg(0);
    std::string line;
    std::size_t n = 0;
    const long long vmin = fmt == FMT_OFF ? 6 : 3, fmin = fmt == FMT_OFF ? 8 : 4;
    auto check = [&](const std::string &what, const std::string &tok, long long min) -> int {
        long long v = 0;
        if (count_fits(tok, bytes, min, &v))
            return 0;
        std::string why = tok.find_first_not_of("0123456789") != std::string::npos || tok.empty()
                              ? "'" + tok + "' is not a " + what + " count (a whole number >= 0)"
                              : what + " count " + tok + " is more than the file's " + std::to_string(bytes) +
                                    " bytes can hold (at least " + std::to_string(min) + " bytes a " + what + ")";
        return fail(msg, msglen, path, n, why);
    };
    if (fmt == FMT_OFF) {
        /* the first line that is not blank or a comment: "OFF" alone or with
         * the counts, else the counts themselves (keyword optional) */
        bool keyword_seen = false;
        while (std::getline(in, line)) {
            ++n;
            std::string s = strip_comment(line);
            if (blank(s))
                continue;
            std::istringstream ss(s);
            std::string a, b, c;
            ss >> a;
            if (!keyword_seen && a.size() >= 3 && a.compare(a.size() - 3, 3, "OFF") == 0) {
                if (a.find("BINARY") != std::string::npos || s.find("BINARY") != std::string::npos)
                    return 0;
                keyword_seen = true;
                if (!(ss >> b))
                    continue; /* counts on the next line */
                a = b;
            }
            ss >> b;
            if (int rc = check("vertex", a, vmin))
                return rc;
            if (int rc = check("face", b, fmin))
                return rc;
            return 0;
        }
        return 0;
    }
    /* PLY: "element vertex N", "element face N" up to end_header */
    while (std::getline(in, line)) {
        ++n;
        std::istringstream ss(line);
        std::string key, name, count;
        ss >> key;
        if (key == "end_header")
            break;
        if (key != "element")
            continue;
        ss >> name >> count;
        if (name == "vertex") {
            if (int rc = check("vertex", count, vmin))
                return rc;
        } else if (name == "face") {
            if (int rc = check("face", count, fmin))
                return rc;
        }
    }
    return 0;
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
    if (int rc = check_header_counts(path, fmt, msg, msglen))
        return rc;

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

    /* Lines of the faces, when the file is ASCII and scans as CGAL read it. */
    const Records rec = scan_records(path, fmt);
    const bool lined = rec.ok && rec.faces.size() == polygons.size();
    std::vector<std::size_t> lines(polygons.size(), 0);
    for (std::size_t f = 0; lined && f < polygons.size(); ++f)
        lines[f] = rec.faces[f].line;

    const Triangulation t = triangulate_faces(points, polygons, lines);
    if (t.degenerate.count > 0 && reject_degenerate)
        return fail(msg, msglen, path, t.degenerate.line,
                    "face " + std::to_string(t.first_degenerate_face) + " is degenerate (zero area)");
    if (t.tris.empty())
        return fail(msg, msglen, path, 0, "every face is degenerate (zero area) or a duplicate");

    /* An OBJ's other statements are not read by a one-material mesh. */
    std::vector<std::string> warnings;
    if (fmt == FMT_OBJ && rec.ok) {
        Ignored ignored;
        for (const Record &r : rec.other)
            ignored.add(r.text, r.line);
        if (ignored.first_line > 0)
            warnings.push_back(path + ":" + std::to_string(ignored.first_line) +
                               ": a mesh is geometry with one material; ignored: " +
                               ignored.list("line"));
    }

    rp_tri_mesh m;
    std::memset(&m, 0, sizeof m);
    try {
        fill_geometry(&m, points, t.tris);
        fill_diagnostics(&m, t, warnings);
    } catch (...) {
        free_mesh(&m);
        throw;
    }
    *out = m;
    return 0;
}

/* ---- rp_obj_read_scene: radpt's own OBJ + MTL reader ----------------------
 *
 * Wavefront's "Object Files (.obj)" and "Material Library Files (.mtl)"
 * (Advanced Visualizer manual, appendices B1 and B2), read for what a
 * diffuse scene uses: v, f, o, g, usemtl, mtllib; newmtl, Kd, Ke.  Every
 * other statement is counted and listed in one warning per file.  '#'
 * starts a comment anywhere on a line; a line ending in a backslash
 * continues on the next (the statement keeps its first line's number).
 * Numbers are whole tokens read by strtod; NaN and infinities are refused.
 * Names (o, g, newmtl, usemtl) are the rest of the line, words joined by
 * one space. */

struct Statement {
    std::size_t line;
    std::vector<std::string> tok;
};

/* The file's statements; false with errno's text in *why if it cannot be
 * read. */
bool read_statements(const std::string &path, std::vector<Statement> *out, std::string *why)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        *why = std::strerror(errno);
        return false;
    }
    std::string raw, joined;
    std::size_t n = 0, first = 0;
    auto flush = [&]() {
        std::istringstream ss(strip_comment(joined));
        Statement st;
        st.line = first;
        std::string t;
        while (ss >> t)
            st.tok.push_back(t);
        if (!st.tok.empty())
            out->push_back(std::move(st));
        joined.clear();
    };
    while (std::getline(in, raw)) {
        ++n;
        if (!raw.empty() && raw.back() == '\r')
            raw.pop_back();
        if (joined.empty())
            first = n;
        const bool more = !raw.empty() && raw.back() == '\\';
        if (more)
            raw.back() = ' ';
        joined += raw;
        if (!more)
            flush();
        else
            joined += ' ';
    }
    if (!joined.empty())
        flush();
    if (in.bad()) {
        *why = "read error";
        return false;
    }
    return true;
}

/* Words tok[from..] joined by one space. */
std::string rest_of(const Statement &st, std::size_t from)
{
    std::string s;
    for (std::size_t i = from; i < st.tok.size(); ++i)
        s += (i > from ? " " : "") + st.tok[i];
    return s;
}

/* An error at path:line; what names the problem. */
struct Read_error {
    std::string path;
    std::size_t line;
    std::string what;
};

struct Mtl_material {
    std::string name, file;
    std::size_t line = 0;    /* its newmtl */
    double kd[3] = {0, 0, 0}, ke[3] = {0, 0, 0};
    bool has_kd = false, has_ke = false;
    std::size_t ks_line = 0; /* a non-zero Ks, 0 if none */
};

struct Mtl_library {
    std::vector<Mtl_material> mats;
    std::map<std::string, std::size_t> index;
};

/* Kd, Ke: one value (grey: MTL says "if only r is specified, g and b are
 * assumed equal to r") or three, each finite and in [lo, hi]. */
void mtl_color(const std::string &path, const Statement &st, double lo, double hi, double out[3])
{
    const std::string &key = st.tok[0];
    const std::size_t n = st.tok.size() - 1;
    if (n >= 1 && (st.tok[1] == "spectral" || st.tok[1] == "xyz"))
        throw Read_error{path, st.line,
                         "'" + key + " " + st.tok[1] + "' is not supported (radpt reads RGB " + key + " only)"};
    if (n != 1 && n != 3)
        throw Read_error{path, st.line,
                         key + " takes 1 value (grey) or 3 (r g b), not " + std::to_string(n)};
    for (std::size_t i = 0; i < n; ++i) {
        const std::string &t = st.tok[1 + i];
        double v;
        if (!parse_double(t, &v) || t.find_first_of("xX") != std::string::npos)
            throw Read_error{path, st.line, key + ": '" + t.substr(0, 64) + "' is not a number"};
        if (!std::isfinite(v))
            throw Read_error{path, st.line, key + ": '" + t.substr(0, 64) + "' is not finite"};
        if (v < lo || v > hi) {
            char b[160];
            if (hi < HUGE_VAL)
                std::snprintf(b, sizeof b, "%s %g outside [%g, %g]", key.c_str(), v, lo, hi);
            else
                std::snprintf(b, sizeof b, "%s %g is negative", key.c_str(), v);
            throw Read_error{path, st.line, b};
        }
        out[i] = v;
    }
    if (n == 1)
        out[1] = out[2] = out[0];
}

/* Reads one MTL file into lib; warnings (one list of ignored statements,
 * materials that come out black) go to warnings. */
void read_mtl(const std::string &path, std::size_t obj_line, const std::string &obj_path, Mtl_library *lib,
              std::vector<std::string> *warnings)
{
    std::vector<Statement> sts;
    std::string why;
    if (!read_statements(path, &sts, &why))
        throw Read_error{obj_path, obj_line, "material library '" + path + "' not found (" + why + ")"};
    Ignored ignored;
    std::set<std::string> seen; /* keywords of the current material */
    Mtl_material *cur = nullptr;
    const std::size_t first = lib->mats.size();
    for (const Statement &st : sts) {
        const std::string &key = st.tok[0];
        if (key == "newmtl") {
            const std::string name = rest_of(st, 1);
            if (name.empty())
                throw Read_error{path, st.line, "newmtl needs a name"};
            auto it = lib->index.find(name);
            if (it != lib->index.end()) {
                const Mtl_material &m = lib->mats[it->second];
                throw Read_error{path, st.line,
                                 "material '" + name + "' defined twice (first at " + m.file + ":" +
                                     std::to_string(m.line) + ")"};
            }
            lib->index[name] = lib->mats.size();
            lib->mats.push_back(Mtl_material());
            cur = &lib->mats.back();
            cur->name = name;
            cur->file = path;
            cur->line = st.line;
            seen.clear();
            continue;
        }
        const bool kd = key == "Kd", ke = key == "Ke";
        if ((kd || ke) && !cur)
            throw Read_error{path, st.line, "'" + key + "' before any newmtl"};
        if (kd || ke) {
            bool &has = kd ? cur->has_kd : cur->has_ke;
            if (has)
                throw Read_error{path, st.line, key + " given twice for material '" + cur->name + "'"};
            has = true;
            mtl_color(path, st, 0, kd ? 1 : HUGE_VAL, kd ? cur->kd : cur->ke);
            continue;
        }
        /* Not read: listed once per material using it. */
        if (!cur || seen.insert(key).second)
            ignored.add(key, st.line);
        if (key == "Ks" && cur) {
            /* Read leniently, only to say when a material is black here. */
            for (std::size_t i = 1; i < st.tok.size(); ++i) {
                double v;
                if (parse_double(st.tok[i], &v) && v > 0 && cur->ks_line == 0)
                    cur->ks_line = st.line;
            }
        }
    }
    if (ignored.first_line > 0)
        warnings->push_back(path + ":" + std::to_string(ignored.first_line) +
                            ": radpt models diffuse surfaces; ignored: " + ignored.list("material"));
    std::string shiny, dark;
    std::size_t shiny_line = 0, dark_line = 0, nshiny = 0, ndark = 0;
    for (std::size_t i = first; i < lib->mats.size(); ++i) {
        const Mtl_material &m = lib->mats[i];
        const bool black = m.kd[0] == 0 && m.kd[1] == 0 && m.kd[2] == 0;
        const bool emits = m.ke[0] > 0 || m.ke[1] > 0 || m.ke[2] > 0;
        if (black && m.ks_line > 0) {
            shiny += (nshiny++ ? ", " : "") + m.name;
            if (shiny_line == 0)
                shiny_line = m.ks_line;
        } else if (!m.has_kd && !emits) {
            dark += (ndark++ ? ", " : "") + m.name;
            if (dark_line == 0)
                dark_line = m.line;
        }
    }
    if (nshiny > 0)
        warnings->push_back(path + ":" + std::to_string(shiny_line) + ": " +
                            (nshiny > 1 ? "materials " : "material ") + shiny +
                            (nshiny > 1 ? " have" : " has") +
                            " Kd 0 but a non-zero Ks: radpt models diffuse reflection only, so " +
                            (nshiny > 1 ? "they are" : "it is") + " black here");
    if (ndark > 0)
        warnings->push_back(path + ":" + std::to_string(dark_line) + ": " +
                            (ndark > 1 ? "materials " : "material ") + dark +
                            (ndark > 1 ? " have" : " has") +
                            " no Kd and no Ke: black (Kd 0), as radpt invents no reflectance");
}

/* A face corner "v", "v/vt", "v/vt/vn" or "v//vn": the vertex index,
 * 0-based, from OBJ's 1-based or negative (relative to the vertices read
 * so far) index.  Range against the final count is checked later. */
long long obj_corner(const std::string &path, const Statement &st, const std::string &tok, std::size_t nv)
{
    const std::string v = tok.substr(0, tok.find('/'));
    long long k;
    if (!parse_long(v, &k))
        throw Read_error{path, st.line, "'" + tok.substr(0, 64) + "' is not a vertex index"};
    if (k == 0)
        throw Read_error{path, st.line, "vertex index 0 (OBJ counts vertices from 1)"};
    if (k < 0) {
        const long long idx = (long long)nv + k;
        if (idx < 0)
            throw Read_error{path, st.line,
                             "relative vertex index " + v + " reaches before the first vertex (" +
                                 std::to_string(nv) + " read so far)"};
        return idx;
    }
    return k - 1;
}

int read_scene(const std::string &path, rp_tri_mesh *out, char *msg, size_t msglen)
{
    std::string ext;
    if (format_of(path, &ext) != FMT_OBJ)
        return fail(msg, msglen, path, 0, "a scene mesh must be .obj, not '" + ext + "'");
    std::vector<Statement> sts;
    std::string why;
    if (!read_statements(path, &sts, &why))
        return fail(msg, msglen, path, 0, "cannot open: " + why);
    const std::size_t slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "" : path.substr(0, slash + 1);

    std::vector<std::string> warnings;
    Mtl_library lib;
    std::vector<Point> points;
    std::vector<Polygon> polys;
    std::vector<std::size_t> lines;
    std::vector<uint32_t> face_group, face_material;
    std::vector<std::string> group_names;
    std::map<std::string, uint32_t> group_of;
    try {
        /* Libraries first, so a usemtl before its mtllib still resolves. */
        std::set<std::string> loaded;
        for (const Statement &st : sts) {
            if (st.tok[0] != "mtllib")
                continue;
            if (st.tok.size() < 2)
                throw Read_error{path, st.line, "mtllib needs a file name"};
            for (std::size_t i = 1; i < st.tok.size(); ++i) {
                const std::string file = st.tok[i][0] == '/' ? st.tok[i] : dir + st.tok[i];
                if (!loaded.insert(file).second)
                    continue;
                try {
                    read_mtl(file, st.line, path, &lib, &warnings);
                } catch (Read_error &e) {
                    /* say which OBJ asked for the library */
                    if (e.path != path)
                        e.what += " (material library of " + path + ":" + std::to_string(st.line) + ")";
                    throw;
                }
            }
        }

        Ignored ignored;
        std::string group;
        uint32_t material = UINT32_MAX;
        std::vector<long long> corners;
        for (const Statement &st : sts) {
            const std::string &key = st.tok[0];
            if (key == "v") {
                const std::size_t n = st.tok.size() - 1;
                if (n != 3 && n != 4 && n != 6)
                    throw Read_error{path, st.line,
                                     "vertex " + std::to_string(points.size() + 1) + " has " +
                                         std::to_string(n) + " numbers (x y z, x y z w or x y z r g b)"};
                double c[3];
                for (std::size_t i = 0; i < n; ++i) {
                    const std::string &t = st.tok[1 + i];
                    double v;
                    if (!parse_double(t, &v))
                        throw Read_error{path, st.line,
                                         "vertex " + std::to_string(points.size() + 1) + ": '" +
                                             t.substr(0, 64) + "' is not a number"};
                    if (i < 3 && !std::isfinite(v))
                        throw Read_error{path, st.line,
                                         "vertex " + std::to_string(points.size() + 1) + ": coordinate '" +
                                             t.substr(0, 64) + "' is not finite"};
                    if (i < 3)
                        c[i] = v;
                }
                if (n == 6)
                    ignored.add("vertex colours", st.line);
                points.emplace_back(c[0], c[1], c[2]);
            } else if (key == "f") {
                if (st.tok.size() < 4)
                    throw Read_error{path, st.line,
                                     "face " + std::to_string(polys.size()) + " has fewer than 3 vertices"};
                corners.clear();
                for (std::size_t i = 1; i < st.tok.size(); ++i)
                    corners.push_back(obj_corner(path, st, st.tok[i], points.size()));
                Polygon poly;
                for (long long k : corners)
                    poly.push_back((std::size_t)k);
                auto g = group_of.find(group);
                if (g == group_of.end()) {
                    g = group_of.emplace(group, (uint32_t)group_names.size()).first;
                    group_names.push_back(group);
                }
                polys.push_back(std::move(poly));
                lines.push_back(st.line);
                face_group.push_back(g->second);
                face_material.push_back(material);
            } else if (key == "o" || key == "g") {
                /* One current group; a later o or g replaces it.  Several
                 * names on a g line (membership in several groups) are kept
                 * together as one name, as most readers do. */
                group = rest_of(st, 1);
            } else if (key == "usemtl") {
                const std::string name = rest_of(st, 1);
                if (name.empty())
                    throw Read_error{path, st.line, "usemtl needs a material name"};
                auto it = lib.index.find(name);
                if (it == lib.index.end())
                    throw Read_error{path, st.line,
                                     "usemtl '" + name + "': no such material" +
                                         (loaded.empty() ? " (the file names no mtllib)"
                                                         : " in its material libraries")};
                material = (uint32_t)it->second;
            } else if (key != "mtllib") {
                ignored.add(key, st.line);
            }
        }
        if (ignored.first_line > 0)
            warnings.insert(warnings.begin(), path + ":" + std::to_string(ignored.first_line) +
                                                  ": radpt models diffuse polygons; ignored: " +
                                                  ignored.list("line"));
        if (points.empty())
            return fail(msg, msglen, path, 0, "no vertices");
        if (polys.empty())
            return fail(msg, msglen, path, 0, "no faces");
        if (points.size() > UINT32_MAX)
            return fail(msg, msglen, path, 0, "too many vertices for 32-bit indices");
        for (std::size_t f = 0; f < polys.size(); ++f)
            for (std::size_t v : polys[f])
                if (v >= points.size())
                    throw Read_error{path, lines[f],
                                     "face " + std::to_string(f) + ": vertex index " + std::to_string(v + 1) +
                                         " out of range (" + std::to_string(points.size()) + " vertices)"};
    } catch (const Read_error &e) {
        return fail(msg, msglen, e.path, e.line, e.what);
    }

    const Triangulation t = triangulate_faces(points, polys, lines);
    if (t.tris.empty())
        return fail(msg, msglen, path, 0, "every face is degenerate (zero area) or a duplicate");

    rp_tri_mesh m;
    std::memset(&m, 0, sizeof m);
    try {
        fill_geometry(&m, points, t.tris);
        fill_diagnostics(&m, t, warnings);
        m.tri_group = alloc_array<uint32_t>(t.tris.size());
        m.tri_material = alloc_array<uint32_t>(t.tris.size());
        for (std::size_t i = 0; i < t.tris.size(); ++i) {
            m.tri_group[i] = face_group[t.tris[i].face];
            m.tri_material[i] = face_material[t.tris[i].face];
        }
        m.group_names = alloc_array<char *>(group_names.size());
        m.ngroups = group_names.size();
        for (std::size_t i = 0; i < group_names.size(); ++i)
            m.group_names[i] = dup_string(group_names[i]);
        const std::size_t nm = lib.mats.size();
        m.nmaterials = nm;
        m.material_names = alloc_array<char *>(nm);
        m.material_kd = alloc_array<double>(3 * nm);
        m.material_ke = alloc_array<double>(3 * nm);
        for (std::size_t i = 0; i < nm; ++i) {
            m.material_names[i] = dup_string(lib.mats[i].name);
            for (int c = 0; c < 3; ++c) {
                m.material_kd[3 * i + c] = lib.mats[i].kd[c];
                m.material_ke[3 * i + c] = lib.mats[i].ke[c];
            }
        }
    } catch (...) {
        free_mesh(&m);
        throw;
    }
    *out = m;
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
