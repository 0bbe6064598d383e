// bench/simplify_peers: the peers of tigerlod-simplify on the same chain
// stores and the same eps, and the exact checker that counts what each leaves.
//
//   simplify_peers dp|geos|cgal INPUT LEVEL EPS_M     simplify a level's owned chains
//   simplify_peers tigerlod SIMPLIFIED_DIR LEVEL      check tigerlod's own output
//   simplify_peers topojson FILE GRID_M               check a TopoJSON's arcs (projected metres)
// Prints one JSON line: method, seconds (simplification only), input and
// output vertices, crossings between chains and self-intersections, counted
// exactly over the whole level (partitions together).
#include "core/segment_grid.hpp"
#include "formats/chains/chain_store.hpp"
#include "core/metric.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Constrained_triangulation_plus_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polyline_simplification_2/simplify.h>
#include <geos_c.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace fs = std::filesystem;
using namespace tigerlod;
using Chain = std::vector<GridPoint>;

namespace {

struct Level {
    std::vector<Chain> chains;
    double grid_m = 0.01;
};

Level read_level(const fs::path& dir)
{
    Level l;
    for (const auto& e : fs::directory_iterator(dir)) {
        if (e.path().extension() != ".tlc") {
            continue;
        }
        const auto s = chains::read(e.path());
        l.grid_m = s.projection.grid_m;
        for (const auto& c : s.chains) {
            if (!(c.flags & chains::chain_halo)) {
                const auto p = s.chain_points(c);
                l.chains.emplace_back(p.begin(), p.end());
            }
        }
    }
    return l;
}

size_t vertices(const std::vector<Chain>& cs)
{
    size_t n = 0;
    for (const auto& c : cs) {
        n += c.size();
    }
    return n;
}

/// Exact count of intersections other than shared end points: between chains, and within one.
std::pair<size_t, size_t> check(const std::vector<Chain>& cs)
{
    std::vector<Segment> segs;
    std::vector<uint32_t> owner;
    for (uint32_t c = 0; c < cs.size(); ++c) {
        for (size_t i = 0; i + 1 < cs[c].size(); ++i) {
            if (cs[c][i] == cs[c][i + 1]) {
                continue;
            }
            segs.push_back({cs[c][i], cs[c][i + 1], uint32_t(segs.size())});
            owner.push_back(c);
        }
    }
    size_t between = 0, self = 0;
    for (const auto& x : find_intersections(segs, 2)) {
        (owner[x.first] == owner[x.second] ? self : between)++;
    }
    return {between, self};
}

Chain douglas_peucker(const Chain& pts, const Tolerance& tol)
{
    std::vector<uint8_t> keep(pts.size(), 0);
    keep.front() = keep.back() = 1;
    std::vector<std::pair<size_t, size_t>> stack{{0, pts.size() - 1}};
    while (!stack.empty()) {
        const auto [a, b] = stack.back();
        stack.pop_back();
        double best = -1;
        size_t far = 0;
        bool all_in = true;
        for (size_t i = a + 1; i < b; ++i) {
            if (!within(pts[i], pts[a], pts[b], tol)) {
                all_in = false;
            }
            const double d = distance(pts[i], pts[a], pts[b], Metric::l2);
            if (d > best) {
                best = d;
                far = i;
            }
        }
        if (!all_in) {
            keep[far] = 1;
            stack.push_back({a, far});
            stack.push_back({far, b});
        }
    }
    Chain out;
    for (size_t i = 0; i < pts.size(); ++i) {
        if (keep[i]) {
            out.push_back(pts[i]);
        }
    }
    if (pts.front() == pts.back() && out.size() < 4) { // a ring keeps a triangle
        return pts.size() >= 4 ? Chain{pts[0], pts[pts.size() / 3], pts[2 * pts.size() / 3], pts.back()} : pts;
    }
    return out;
}

std::vector<Chain> run_geos(const std::vector<Chain>& in, double eps)
{
    GEOSContextHandle_t h = GEOS_init_r();
    std::vector<GEOSGeometry*> lines;
    for (const auto& c : in) {
        GEOSCoordSequence* seq = GEOSCoordSeq_create_r(h, unsigned(c.size()), 2);
        for (unsigned i = 0; i < c.size(); ++i) {
            GEOSCoordSeq_setXY_r(h, seq, i, c[i].x, c[i].y);
        }
        lines.push_back(GEOSGeom_createLineString_r(h, seq));
    }
    GEOSGeometry* multi = GEOSGeom_createCollection_r(h, GEOS_MULTILINESTRING, lines.data(), unsigned(lines.size()));
    GEOSGeometry* simp = GEOSTopologyPreserveSimplify_r(h, multi, eps);
    std::vector<Chain> out;
    const int n = GEOSGetNumGeometries_r(h, simp);
    for (int g = 0; g < n; ++g) {
        const GEOSCoordSequence* seq = GEOSGeom_getCoordSeq_r(h, GEOSGetGeometryN_r(h, simp, g));
        unsigned size = 0;
        GEOSCoordSeq_getSize_r(h, seq, &size);
        Chain c;
        for (unsigned i = 0; i < size; ++i) {
            double x = 0, y = 0;
            GEOSCoordSeq_getXY_r(h, seq, i, &x, &y);
            c.push_back({int32_t(std::lround(x)), int32_t(std::lround(y))});
        }
        out.push_back(std::move(c));
    }
    GEOSGeom_destroy_r(h, simp);
    GEOSGeom_destroy_r(h, multi);
    GEOS_finish_r(h);
    return out;
}

std::vector<Chain> run_cgal(const std::vector<Chain>& in, double eps)
{
    namespace PS = CGAL::Polyline_simplification_2;
    using K = CGAL::Exact_predicates_inexact_constructions_kernel;
    using Vb = PS::Vertex_base_2<K>;
    using Fb = CGAL::Constrained_triangulation_face_base_2<K>;
    using TDS = CGAL::Triangulation_data_structure_2<Vb, Fb>;
    using CDT = CGAL::Constrained_Delaunay_triangulation_2<K, TDS, CGAL::Exact_predicates_tag>;
    using CT = CGAL::Constrained_triangulation_plus_2<CDT>;
    CT ct;
    for (const auto& c : in) {
        std::vector<K::Point_2> pts;
        for (const auto& p : c) {
            pts.emplace_back(p.x, p.y);
        }
        ct.insert_constraint(pts.begin(), pts.end());
    }
    PS::simplify(ct, PS::Squared_distance_cost(), PS::Stop_above_cost_threshold(eps * eps));
    std::vector<Chain> out;
    for (auto cit = ct.constraints_begin(); cit != ct.constraints_end(); ++cit) {
        Chain c;
        for (auto vit = ct.points_in_constraint_begin(*cit); vit != ct.points_in_constraint_end(*cit); ++vit) {
            c.push_back({int32_t(std::lround(vit->x())), int32_t(std::lround(vit->y()))});
        }
        out.push_back(std::move(c));
    }
    return out;
}

std::vector<Chain> read_topojson_arcs(const fs::path& file, double grid_m)
{
    std::ifstream in(file);
    const auto j = nlohmann::json::parse(in);
    std::vector<Chain> out;
    const bool quantized = j.contains("transform");
    for (const auto& arc : j.at("arcs")) {
        Chain c;
        double x = 0, y = 0;
        for (const auto& p : arc) {
            if (quantized) {
                x += p[0].get<double>();
                y += p[1].get<double>();
            } else {
                x = p[0].get<double>();
                y = p[1].get<double>();
            }
            double gx = x, gy = y;
            if (quantized) {
                gx = x * j["transform"]["scale"][0].get<double>() + j["transform"]["translate"][0].get<double>();
                gy = y * j["transform"]["scale"][1].get<double>() + j["transform"]["translate"][1].get<double>();
            }
            c.push_back({int32_t(std::lround(gx / grid_m)), int32_t(std::lround(gy / grid_m))});
        }
        out.push_back(std::move(c));
    }
    return out;
}

} // namespace

int main(int argc, char** argv)
{
    if (argc < 4) {
        std::fprintf(stderr, "usage: simplify_peers dp|geos|cgal INPUT LEVEL EPS_M | tigerlod DIR LEVEL | "
                             "topojson FILE GRID_M\n");
        return 2;
    }
    const std::string method = argv[1];
    nlohmann::ordered_json r;
    r["method"] = method;
    std::vector<Chain> out;
    double seconds = 0;
    size_t in_vertices = 0;
    if (method == "topojson") {
        out = read_topojson_arcs(argv[2], std::stod(argv[3]));
    } else if (method == "tigerlod") {
        out = read_level(fs::path(argv[2]) / argv[3]).chains;
    } else {
        const Level l = read_level(fs::path(argv[2]) / argv[3]);
        in_vertices = vertices(l.chains);
        const double eps = std::stod(argv[4]) / l.grid_m;
        const auto t0 = std::chrono::steady_clock::now();
        if (method == "dp") {
            const Tolerance tol(eps, Metric::l2);
            for (const auto& c : l.chains) {
                out.push_back(douglas_peucker(c, tol));
            }
        } else if (method == "geos") {
            out = run_geos(l.chains, eps);
        } else if (method == "cgal") {
            out = run_cgal(l.chains, eps);
        } else {
            std::fprintf(stderr, "unknown method %s\n", method.c_str());
            return 2;
        }
        seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        r["seconds"] = seconds;
        r["input_vertices"] = in_vertices;
    }
    const auto [between, self] = check(out);
    r["output_vertices"] = vertices(out);
    r["crossings"] = between;
    r["self_intersections"] = self;
    std::cout << r.dump() << "\n";
    return 0;
}
