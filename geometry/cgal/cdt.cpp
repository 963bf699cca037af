/* The CGAL shim's constrained Delaunay triangulation (cdt.h).
 *
 * CGAL 5.5 Constrained_Delaunay_triangulation_2 over the exact-predicates,
 * inexact-constructions kernel with Exact_predicates_tag, so constraints may
 * cross (the crossing points are constructed in double precision).  The
 * inside of the domain is found by flooding from the infinite face across
 * unconstrained edges: the boundary polygon is constrained, so the flood
 * stops at it, and every finite face it does not reach is inside.  The
 * discontinuity mesh that calls this implements Heckbert 1992
 * ("Discontinuity meshing for radiosity") and Lischinski, Tampieri &
 * Greenberg 1992: its constraint segments must become element edges.
 *
 * No -g on this file (Makefile); every extern "C" function catches all
 * exceptions. */
#include "geometry/cgal/cdt.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Constrained_triangulation_face_base_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <exception>
#include <new>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace {

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
/* Vertex info: input index + 1; 0 for a vertex CGAL made. */
typedef CGAL::Triangulation_vertex_base_with_info_2<int64_t, K> Vb;
/* Face info: -1 unvisited, 0 outside, 1 inside. */
typedef CGAL::Triangulation_face_base_with_info_2<int, K> Fbi;
typedef CGAL::Constrained_triangulation_face_base_2<K, Fbi> Fb;
typedef CGAL::Triangulation_data_structure_2<Vb, Fb> Tds;
typedef CGAL::Constrained_Delaunay_triangulation_2<K, Tds, CGAL::Exact_predicates_tag> CDT;

void set_msg(char *msg, size_t msglen, const char *fmt, ...)
{
    if (!msg || msglen == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(msg, msglen, fmt, ap);
    va_end(ap);
}

int triangulate(const rp_cdt_input *in, rp_cdt_output *out, char *msg, size_t msglen)
{
    if (in->nboundary < 3 || in->nboundary > in->npoints) {
        set_msg(msg, msglen, "cdt: %zu boundary points of %zu", in->nboundary, in->npoints);
        return 1;
    }
    for (size_t i = 0; i < 2 * in->npoints; i++)
        if (!std::isfinite(in->xy[i])) {
            set_msg(msg, msglen, "cdt: point %zu is not finite", i / 2);
            return 1;
        }
    for (size_t i = 0; i < 2 * in->nsegments; i++)
        if (in->segments[i] >= in->npoints) {
            set_msg(msg, msglen, "cdt: segment %zu names point %u of %zu", i / 2, in->segments[i],
                    in->npoints);
            return 1;
        }

    CDT cdt;
    /* The info field is not initialised by CGAL: inputs are marked as they
     * go in (a repeated point keeps its first index), and every vertex not
     * marked is one CGAL made. */
    std::vector<CDT::Vertex_handle> vh(in->npoints);
    std::unordered_set<const void *> seen;
    for (size_t i = 0; i < in->npoints; i++) {
        vh[i] = cdt.insert(K::Point_2(in->xy[2 * i], in->xy[2 * i + 1]));
        if (seen.insert(&*vh[i]).second)
            vh[i]->info() = (int64_t)i + 1;
    }
    for (size_t i = 0; i < in->nboundary; i++) {
        CDT::Vertex_handle a = vh[i], b = vh[(i + 1) % in->nboundary];
        if (a != b)
            cdt.insert_constraint(a, b);
    }
    for (size_t s = 0; s < in->nsegments; s++) {
        CDT::Vertex_handle a = vh[in->segments[2 * s]], b = vh[in->segments[2 * s + 1]];
        if (a != b)
            cdt.insert_constraint(a, b);
    }

    for (CDT::Finite_vertices_iterator v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v)
        if (!seen.count(&*v))
            v->info() = 0;

    /* Flood the outside from the infinite face. */
    for (CDT::All_faces_iterator f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f)
        f->info() = -1;
    std::deque<CDT::Face_handle> queue;
    cdt.infinite_face()->info() = 0;
    queue.push_back(cdt.infinite_face());
    while (!queue.empty()) {
        CDT::Face_handle f = queue.front();
        queue.pop_front();
        for (int i = 0; i < 3; i++) {
            CDT::Face_handle n = f->neighbor(i);
            if (n->info() != -1 || cdt.is_constrained(CDT::Edge(f, i)))
                continue;
            n->info() = 0;
            queue.push_back(n);
        }
    }

    std::unordered_map<const void *, uint32_t> index;
    std::vector<double> xy;
    std::vector<int64_t> input;
    for (CDT::Finite_vertices_iterator v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
        index[&*v] = (uint32_t)input.size();
        xy.push_back(v->point().x());
        xy.push_back(v->point().y());
        input.push_back(v->info() - 1);
    }
    std::vector<uint32_t> tri;
    for (CDT::Finite_faces_iterator f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
        if (f->info() == 0)
            continue;
        for (int i = 0; i < 3; i++)
            tri.push_back(index.at(&*f->vertex(i)));
    }

    out->nvertices = input.size();
    out->ntriangles = tri.size() / 3;
    out->xy = (double *)std::malloc((xy.size() ? xy.size() : 1) * sizeof(double));
    out->input = (int64_t *)std::malloc((input.size() ? input.size() : 1) * sizeof(int64_t));
    out->tri = (uint32_t *)std::malloc((tri.size() ? tri.size() : 1) * sizeof(uint32_t));
    if (!out->xy || !out->input || !out->tri) {
        rp_cdt_output_free(out);
        set_msg(msg, msglen, "cdt: out of memory");
        return 1;
    }
    std::copy(xy.begin(), xy.end(), out->xy);
    std::copy(input.begin(), input.end(), out->input);
    std::copy(tri.begin(), tri.end(), out->tri);
    return 0;
}

} // namespace

extern "C" int rp_cgal_cdt(const rp_cdt_input *in, rp_cdt_output *out, char *msg, size_t msglen)
{
    if (!in || !out) {
        set_msg(msg, msglen, "cdt: no input or no output");
        return 1;
    }
    out->xy = NULL;
    out->input = NULL;
    out->tri = NULL;
    out->nvertices = out->ntriangles = 0;
    try {
        return triangulate(in, out, msg, msglen);
    } catch (const std::bad_alloc &) {
        rp_cdt_output_free(out);
        set_msg(msg, msglen, "cdt: out of memory");
    } catch (const std::exception &e) {
        rp_cdt_output_free(out);
        set_msg(msg, msglen, "cdt: CGAL: %s", e.what());
    } catch (...) {
        rp_cdt_output_free(out);
        set_msg(msg, msglen, "cdt: unknown C++ exception");
    }
    return 1;
}

extern "C" void rp_cdt_output_free(rp_cdt_output *out)
{
    if (!out)
        return;
    std::free(out->xy);
    std::free(out->input);
    std::free(out->tri);
    out->xy = NULL;
    out->input = NULL;
    out->tri = NULL;
    out->nvertices = out->ntriangles = 0;
}
