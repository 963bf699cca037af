/* Edge-collapse simplification with Garland-Heckbert plane quadrics, and the
 * map from the input's vertices to the simplified surface (simplify.h).
 *
 * CGAL 5.5: Surface_mesh_simplification::edge_collapse with
 * GarlandHeckbert_plane_policies (needs Eigen: CGAL_EIGEN3_ENABLED, set by
 * the Makefile for this file), Constrained_placement on border edges,
 * Polygon_mesh_processing::orient_polygon_soup to cut a mesh that is not a
 * 2-manifold into one, and AABB_tree closest-point queries for the
 * distances and the map back. */
#include "geometry/cgal/simplify.h"

#ifdef _OPENMP
#include <omp.h>
#endif

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Constrained_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_plane_policies.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <map>
#include <new>
#include <vector>

namespace {

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef K::Point_3 Point;
typedef K::Triangle_3 Triangle;
typedef CGAL::Surface_mesh<Point> Mesh;
typedef boost::graph_traits<Mesh>::vertex_descriptor vertex_descriptor;
typedef boost::graph_traits<Mesh>::halfedge_descriptor halfedge_descriptor;
typedef boost::graph_traits<Mesh>::edge_descriptor edge_descriptor;
typedef boost::graph_traits<Mesh>::face_descriptor face_descriptor;
typedef std::vector<Triangle>::const_iterator Tri_iterator;
typedef CGAL::AABB_triangle_primitive<K, Tri_iterator> Primitive;
typedef CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>> Tree;

namespace SMS = CGAL::Surface_mesh_simplification;
namespace PMP = CGAL::Polygon_mesh_processing;

void set_msg(char *msg, size_t len, const char *fmt, ...)
{
    if (!msg || !len)
        return;
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(msg, len, fmt, ap);
    va_end(ap);
}

/* Stops when fewer than ratio of the edges are left, or when the cheapest
 * collapse's quadric error exceeds max_cost.  CGAL's plane policies sum one
 * unit-weight plane per input face merged into a vertex (Garland & Heckbert
 * 1997, eq. 2), so the same deviation costs more the more finely the
 * surface is cut, and a fixed bound on that sum kept more of a finer
 * tessellation of the same surface (the bunny: 7,800 triangles from its
 * 75,408, 12,922 from a midpoint subdivision to 301,632, 20,164 from
 * 1,206,528).  Each plane stands for about the input's mean triangle area
 * A, so the sum times A estimates the squared distance integrated over the
 * area merged, and the bound is on that: max_cost = tolerance^4 / A, in
 * length^2 like the sum.  Within one mesh this is the plain Garland-Heckbert
 * order and stop (a denser part, often one the scanner or modeller cut
 * finely for its detail, still weighs more); across tessellations of one
 * surface it stops at the same error.  (Weighing each plane by its own
 * triangle's area and dividing by the area merged, stop 37's first try,
 * also made the count independent of the tessellation, but on CGAL's man
 * and fandisk it left the surface averages 0.5-1% off the path tracer at
 * the face counts this gives within 0.25%: it no longer favours the finely
 * cut parts.) */
struct Stop {
    double ratio, max_cost;
    template <typename F, typename Profile>
    bool operator()(const F &cost, const Profile &, std::size_t initial, std::size_t current) const
    {
        if (static_cast<double>(current) < ratio * static_cast<double>(initial))
            return true;
        return max_cost > 0 && static_cast<double>(cost) > max_cost;
    }
};

/* Barycentric coordinates of q (on or near triangle t) in t, clamped to
 * the triangle. */
std::array<double, 3> barycentric(const Triangle &t, const Point &q)
{
    const K::Vector_3 e0 = t[1] - t[0], e1 = t[2] - t[0], d = q - t[0];
    const double d00 = e0 * e0, d01 = e0 * e1, d11 = e1 * e1, d20 = d * e0, d21 = d * e1;
    const double den = d00 * d11 - d01 * d01;
    double v = den > 0 ? (d11 * d20 - d01 * d21) / den : 0;
    double w = den > 0 ? (d00 * d21 - d01 * d20) / den : 0;
    v = std::max(0.0, v);
    w = std::max(0.0, w);
    if (v + w > 1) {
        const double s = v + w;
        v /= s;
        w /= s;
    }
    return {1 - v - w, v, w};
}

int simplify(const double *xyz, size_t nv, const uint32_t *tri, size_t nt, const rp_simplify_params *p,
             rp_simplified *out, char *msg, size_t msglen)
{
    /* One vertex per position (sorted, so equal positions are neighbours). */
    std::vector<size_t> order(nv);
    for (size_t i = 0; i < nv; i++)
        order[i] = i;
    auto pos = [&](size_t i) { return std::array<double, 3>{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}; };
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return pos(a) < pos(b) || (pos(a) == pos(b) && a < b); });
    std::vector<Point> points;
    std::vector<size_t> weld(nv);
    for (size_t r = 0; r < nv; r++) {
        const size_t i = order[r];
        if (r == 0 || pos(order[r - 1]) != pos(i))
            points.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
        weld[i] = points.size() - 1;
    }
    /* Surface_mesh::add_face refuses a face that would make the mesh
     * non-manifold or inconsistently oriented (an edge with a third face, a
     * directed edge used twice, a vertex joining separate fans). */
    Mesh mesh;
    mesh.reserve(points.size(), 3 * nt / 2 + 3, nt);
    for (const Point &q : points)
        mesh.add_vertex(q);
    std::vector<Triangle> input;
    input.reserve(nt);
    std::vector<std::array<size_t, 3>> soup;
    soup.reserve(nt);
    size_t refused = 0, degenerate = 0;
    for (size_t f = 0; f < nt; f++) {
        std::array<size_t, 3> w;
        for (int k = 0; k < 3; k++) {
            if (tri[3 * f + k] >= nv) {
                set_msg(msg, msglen, "simplify: triangle %zu uses vertex %u of %zu", f, tri[3 * f + k], nv);
                return -1;
            }
            w[k] = weld[tri[3 * f + k]];
        }
        input.emplace_back(points[w[0]], points[w[1]], points[w[2]]);
        if (w[0] == w[1] || w[1] == w[2] || w[2] == w[0]) {
            degenerate++; /* two corners at one position: no area to keep */
            continue;
        }
        soup.push_back(w);
        if (!refused && mesh.add_face(vertex_descriptor(static_cast<Mesh::size_type>(w[0])),
                                      vertex_descriptor(static_cast<Mesh::size_type>(w[1])),
                                      vertex_descriptor(static_cast<Mesh::size_type>(w[2]))) == Mesh::null_face())
            refused = f + 1;
    }
    if (refused) {
        /* A scan often pinches somewhere: an edge with a third triangle, or
         * two parts that meet at a vertex or an edge.  CGAL's
         * orient_polygon_soup (Gueziec et al. 2001, cutting and stitching)
         * duplicates the points there, so the soup becomes a manifold whose
         * cuts are borders (kept by the collapse); it may also turn
         * triangles round to make the orientation consistent, and then the
         * simplified surface's fronts would not be the input's: refused. */
        std::vector<Point> cut(points);
        std::vector<std::array<size_t, 3>> oriented(soup);
        PMP::orient_polygon_soup(cut, oriented);
        const char *why = nullptr;
        for (size_t f = 0; f < soup.size() && !why; f++) {
            const std::array<size_t, 3> &a = soup[f], &b = oriented[f];
            int same = 0;
            for (int r = 0; r < 3 && !same; r++)
                same = cut[b[r]] == points[a[0]] && cut[b[(r + 1) % 3]] == points[a[1]] &&
                       cut[b[(r + 2) % 3]] == points[a[2]];
            if (!same)
                why = "its triangles are not consistently wound";
        }
        if (!why) {
            mesh.clear();
            PMP::polygon_soup_to_polygon_mesh(cut, oriented, mesh);
            if (!is_valid_polygon_mesh(mesh) || num_faces(mesh) != soup.size())
                why = "cutting it there failed";
        }
        if (why) {
            set_msg(msg, msglen,
                    "not an oriented 2-manifold: its triangle %zu has an edge shared by more than two triangles, "
                    "or used the same way by another, or a vertex joining separate fans, and %s",
                    refused, why);
            return 1;
        }
        out->cut_points = cut.size() - points.size();
    }
    out->degenerate = degenerate;

    /* Border edges are constrained: never collapsed, their vertices never
     * moved (Constrained_placement), so an open mesh keeps its outline. */
    Mesh::Property_map<edge_descriptor, bool> border =
        mesh.add_property_map<edge_descriptor, bool>("e:border", false).first;
    size_t nborder = 0;
    for (edge_descriptor e : edges(mesh))
        if (is_border(e, mesh)) {
            put(border, e, true);
            nborder++;
        }

    SMS::GarlandHeckbert_plane_policies<Mesh, K> gh(mesh);
    SMS::Constrained_placement<SMS::GarlandHeckbert_plane_policies<Mesh, K>,
                               Mesh::Property_map<edge_descriptor, bool>>
        placement(border, gh);
    const double ratio = p->ratio > 0 && p->ratio <= 1 ? p->ratio : 1;
    double area = 0; /* of the input, for its mean triangle (Stop) */
    for (const Triangle &t : input)
        area += std::sqrt(t.squared_area());
    const double mean_area = soup.empty() ? 0 : area / static_cast<double>(soup.size());
    const Stop stop = {ratio < 1 ? ratio : 0,
                       p->tolerance > 0 && mean_area > 0 ? std::pow(p->tolerance, 4) / mean_area : 0};
    if (nborder)
        SMS::edge_collapse(mesh, stop,
                           CGAL::parameters::get_cost(gh).get_placement(placement).edge_is_constrained_map(border));
    else /* closed: nothing to hold */
        SMS::edge_collapse(mesh, stop, CGAL::parameters::get_cost(gh).get_placement(gh));

    /* The result, compacted. */
    std::vector<uint32_t> index(mesh.number_of_vertices() + mesh.number_of_removed_vertices(), UINT32_MAX);
    std::vector<Point> vout;
    for (vertex_descriptor v : vertices(mesh)) {
        index[v.idx()] = static_cast<uint32_t>(vout.size());
        vout.push_back(mesh.point(v));
    }
    std::vector<Triangle> coarse;
    std::vector<std::array<uint32_t, 3>> tout;
    for (face_descriptor f : faces(mesh)) {
        std::array<uint32_t, 3> t{};
        int k = 0;
        for (halfedge_descriptor h : halfedges_around_face(halfedge(f, mesh), mesh)) {
            if (k == 3)
                break;
            t[k++] = index[target(h, mesh).idx()];
        }
        /* around the face from halfedge(f): target of h, then of next(h),
         * then of next(next(h)): the face's own winding. */
        /* A collapse can leave a sliver of (nearly) no area: left out, with a
         * margin over the scene's own test (sine of the smallest angle
         * 1e-10), so the scene built from the result takes every triangle. */
        const Triangle tr(vout[t[0]], vout[t[1]], vout[t[2]]);
        const double l2 = std::max({CGAL::squared_distance(tr[0], tr[1]), CGAL::squared_distance(tr[1], tr[2]),
                                    CGAL::squared_distance(tr[2], tr[0])});
        if (!(std::sqrt(CGAL::cross_product(tr[1] - tr[0], tr[2] - tr[0]).squared_length()) > 1e-8 * l2))
            continue;
        tout.push_back(t);
        coarse.push_back(tr);
    }
    if (coarse.empty()) {
        set_msg(msg, msglen, "simplify: nothing left of the mesh");
        return -1;
    }

    out->nvertices = vout.size();
    out->ntriangles = tout.size();
    out->xyz = static_cast<double *>(std::malloc(3 * vout.size() * sizeof(double)));
    out->tri = static_cast<uint32_t *>(std::malloc(3 * tout.size() * sizeof(uint32_t)));
    out->vertex_tri = static_cast<uint32_t *>(std::malloc((nv ? nv : 1) * sizeof(uint32_t)));
    out->vertex_bary = static_cast<double *>(std::malloc((nv ? 3 * nv : 1) * sizeof(double)));
    if (!out->xyz || !out->tri || !out->vertex_tri || !out->vertex_bary)
        throw std::bad_alloc();
    for (size_t i = 0; i < vout.size(); i++) {
        out->xyz[3 * i] = vout[i].x();
        out->xyz[3 * i + 1] = vout[i].y();
        out->xyz[3 * i + 2] = vout[i].z();
    }
    for (size_t f = 0; f < tout.size(); f++)
        for (int k = 0; k < 3; k++)
            out->tri[3 * f + k] = tout[f][k];
    out->border_edges = nborder;

    /* Each input vertex's closest point on the simplified surface.  The
     * trees are built (with the k-d tree that seeds distance queries)
     * before the queries, which are then const and run in parallel, each
     * writing its own vertex's slots (the largest distance is the same
     * whatever the order). */
#ifdef _OPENMP
    const int threads = p->threads > 0 ? p->threads : omp_get_max_threads();
#endif
    Tree coarse_tree(coarse.cbegin(), coarse.cend());
    coarse_tree.build();
    coarse_tree.accelerate_distance_queries();
    double din = 0;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1024) reduction(max : din)
    for (long i = 0; i < static_cast<long>(nv); i++) {
        const Point &q = points[weld[i]];
        auto cp = coarse_tree.closest_point_and_primitive(q);
        const size_t f = static_cast<size_t>(cp.second - coarse.cbegin());
        const std::array<double, 3> b = barycentric(coarse[f], cp.first);
        out->vertex_tri[i] = static_cast<uint32_t>(f);
        for (int k = 0; k < 3; k++)
            out->vertex_bary[3 * i + k] = b[k];
        din = std::max(din, std::sqrt(CGAL::squared_distance(q, cp.first)));
    }
    /* And each simplified vertex's distance to the input surface. */
    Tree input_tree(input.cbegin(), input.cend());
    input_tree.build();
    input_tree.accelerate_distance_queries();
    double dout = 0;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 256) reduction(max : dout)
    for (long i = 0; i < static_cast<long>(vout.size()); i++)
        dout = std::max(dout, std::sqrt(input_tree.squared_distance(vout[static_cast<size_t>(i)])));
    out->max_distance_in = din;
    out->max_distance_out = dout;
    return 0;
}

} // namespace

extern "C" int rp_cgal_simplify(const double *xyz, size_t nvertices, const uint32_t *tri, size_t ntriangles,
                                const rp_simplify_params *params, rp_simplified *out, char *msg,
                                size_t msglen)
{
    if (!out || !params || !xyz || !tri || ntriangles == 0) {
        set_msg(msg, msglen, "simplify: no mesh");
        return -1;
    }
    std::memset(out, 0, sizeof *out);
    try {
        int r = simplify(xyz, nvertices, tri, ntriangles, params, out, msg, msglen);
        if (r != 0)
            rp_simplified_free(out);
        return r;
    } catch (const std::bad_alloc &) {
        rp_simplified_free(out);
        set_msg(msg, msglen, "simplify: out of memory");
    } catch (const std::exception &e) {
        rp_simplified_free(out);
        set_msg(msg, msglen, "simplify: CGAL: %s", e.what());
    } catch (...) {
        rp_simplified_free(out);
        set_msg(msg, msglen, "simplify: unknown C++ exception");
    }
    return -1;
}

extern "C" void rp_simplified_free(rp_simplified *s)
{
    if (!s)
        return;
    std::free(s->xyz);
    std::free(s->tri);
    std::free(s->vertex_tri);
    std::free(s->vertex_bary);
    std::memset(s, 0, sizeof *s);
}
