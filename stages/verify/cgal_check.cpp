#include "stages/verify/cgal_check.hpp"

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <set>
#include <tuple>
#include <unordered_set>

namespace tigerlod::verify {

namespace {

using Kernel = CGAL::Exact_predicates_exact_constructions_kernel;
using Point = Kernel::Point_2;
using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 2, size_t>;

/// A level's chains at one LOD, each once.
struct LodMap {
    std::vector<uint64_t> ids;
    std::vector<std::vector<GridPoint>> chains;
};

/// One segment: its chain (index into a LodMap) and its ends.
struct Seg {
    uint32_t chain = 0;
    GridPoint a, b;
};

Point point(GridPoint p)
{
    return {double(p.x), double(p.y)}; // 32-bit integers: exact in a double
}

/// Whether two segments meet other than at a point that is an end of both:
/// they cross, touch, or overlap. CGAL's exact predicates alone.
bool meet(const Seg& s, const Seg& t)
{
    const Point s0 = point(s.a), s1 = point(s.b), t0 = point(t.a), t1 = point(t.b);
    if (!CGAL::do_intersect(Kernel::Segment_2(s0, s1), Kernel::Segment_2(t0, t1))) {
        return false;
    }
    // A shared end p: the segments meet only there unless they run on
    // together from it (so and to: their other ends).
    GridPoint p, so, to;
    if (s.a == t.a) {
        p = s.a, so = s.b, to = t.b;
    } else if (s.a == t.b) {
        p = s.a, so = s.b, to = t.a;
    } else if (s.b == t.a) {
        p = s.b, so = s.a, to = t.b;
    } else if (s.b == t.b) {
        p = s.b, so = s.a, to = t.a;
    } else {
        return true; // they meet, and not at an end of both
    }
    if (so == to) {
        return true; // the same segment, twice
    }
    const Point q = point(p), a = point(so), b = point(to);
    if (CGAL::orientation(q, a, b) != CGAL::COLLINEAR) {
        return false; // two directions from one point: only the point is shared
    }
    return CGAL::angle(a, q, b) == CGAL::ACUTE; // collinear the same way: they overlap
}

std::vector<Seg> segments_of(const LodMap& m)
{
    std::vector<Seg> out;
    for (uint32_t c = 0; c < m.chains.size(); ++c) {
        const auto& pts = m.chains[c];
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            if (pts[i] != pts[i + 1]) { // a zero-length segment is the subsequence check's
                out.push_back({c, pts[i], pts[i + 1]});
            }
        }
    }
    return out;
}

std::vector<Box> boxes_of(const std::vector<Seg>& segs)
{
    std::vector<Box> boxes;
    boxes.reserve(segs.size());
    for (size_t i = 0; i < segs.size(); ++i) {
        const auto& s = segs[i];
        boxes.emplace_back(CGAL::Bbox_2(std::min(s.a.x, s.b.x), std::min(s.a.y, s.b.y), std::max(s.a.x, s.b.x),
                                        std::max(s.a.y, s.b.y)),
                           i);
    }
    return boxes;
}

using Pair = std::pair<uint64_t, uint64_t>;

Pair ordered(uint64_t a, uint64_t b)
{
    return {std::min(a, b), std::max(a, b)};
}

/// The directed segments of every chain of a LodMap, by chain id, to ask
/// whether a chain has a segment at another LOD.
struct SegmentKey {
    uint64_t id;
    GridPoint a, b;
    friend bool operator==(const SegmentKey&, const SegmentKey&) = default;
};
struct SegmentKeyHash {
    size_t operator()(const SegmentKey& k) const noexcept
    {
        uint64_t h = k.id * 0x9E3779B97F4A7C15ULL;
        for (const int32_t v : {k.a.x, k.a.y, k.b.x, k.b.y}) {
            h = (h ^ uint32_t(v)) * 0x100000001B3ULL;
        }
        return size_t(h ^ (h >> 29));
    }
};

/// What verify found, keyed as the CGAL check keys its own: meetings within
/// one LOD by (level, LOD, chains), across two LODs by (level, chains).
using Within = std::set<std::tuple<std::string, uint32_t, uint64_t, uint64_t>>;
using Across = std::set<std::tuple<std::string, uint64_t, uint64_t>>;

void verify_pairs(const Report& report, Within& within, Across& across)
{
    for (const auto& v : report.items) {
        if (v.chains.empty()) {
            continue;
        }
        if (v.kind == "crossings" || v.kind == "overlaps" || v.kind == "self_intersections") {
            within.insert({v.level, v.lod, v.chains.front(), v.chains.back()});
        } else if (v.kind == "lod_crossings") {
            across.insert({v.level, v.chains.front(), v.chains.back()});
        }
    }
}

/// Level l's chains at every LOD, each once, from the first node that shows
/// it; a payload that does not decode is left out (verify reports it).
std::vector<LodMap> level_maps(const reader::Tree& tree, uint32_t l)
{
    const auto& sk = tree.skeleton();
    const size_t lods = sk.lod_eps_m.size();
    std::vector<LodMap> maps(lods);
    std::vector<std::set<uint64_t>> seen(lods);
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        if (sk.nodes[n].level != l || sk.nodes[n].chains == 0) {
            continue;
        }
        datatree::ChainTable table;
        if (!tree.read_table(n, table).ok()) {
            continue;
        }
        for (uint32_t k = 0; k < lods; ++k) {
            datatree::Geometry g;
            if (!tree.read_geometry(n, k, g).ok()) {
                continue;
            }
            for (size_t c = 0; c < table.chains.size() && c < g.chain_count(); ++c) {
                if (seen[k].insert(table.chains[c].id).second) {
                    const auto pts = g.chain(c);
                    maps[k].ids.push_back(table.chains[c].id);
                    maps[k].chains.emplace_back(pts.begin(), pts.end());
                }
            }
        }
    }
    return maps;
}

/// One level at every LOD: its segments, their boxes (made once per LOD;
/// each sweep sorts a copy) and each LOD's directed segments by chain.
struct LevelSegments {
    std::vector<LodMap> maps;
    std::vector<std::vector<Seg>> segs;
    std::vector<std::vector<Box>> boxes;
    std::vector<std::unordered_set<SegmentKey, SegmentKeyHash>> has;
};

LevelSegments level_segments(std::vector<LodMap> maps)
{
    LevelSegments ls;
    ls.maps = std::move(maps);
    const size_t lods = ls.maps.size();
    ls.segs.resize(lods);
    ls.boxes.resize(lods);
    ls.has.resize(lods);
    for (size_t k = 0; k < lods; ++k) {
        ls.segs[k] = segments_of(ls.maps[k]);
        ls.boxes[k] = boxes_of(ls.segs[k]);
        for (const auto& s : ls.segs[k]) {
            ls.has[k].insert({ls.maps[k].ids[s.chain], s.a, s.b});
        }
    }
    return ls;
}

/// The chain pairs that meet at LOD k (a chain meeting itself included).
std::set<Pair> meetings_within(const LevelSegments& ls, size_t k)
{
    std::set<Pair> found;
    auto boxes = ls.boxes[k];
    CGAL::box_self_intersection_d(boxes.begin(), boxes.end(), [&](const Box& x, const Box& y) {
        const Seg &s = ls.segs[k][x.info()], &t = ls.segs[k][y.info()];
        if (meet(s, t)) {
            found.insert(ordered(ls.maps[k].ids[s.chain], ls.maps[k].ids[t.chain]));
        }
    });
    return found;
}

/// The pairs of different chains that meet at LODs i and j, but for a
/// meeting that one of the two segments also has at the other LOD (that
/// LOD's own, found within it).
std::set<Pair> meetings_across(const LevelSegments& ls, size_t i, size_t j)
{
    std::set<Pair> across;
    auto bi = ls.boxes[i], bj = ls.boxes[j];
    CGAL::box_intersection_d(bi.begin(), bi.end(), bj.begin(), bj.end(), [&](const Box& x, const Box& y) {
        const Seg &s = ls.segs[i][x.info()], &t = ls.segs[j][y.info()];
        const uint64_t a = ls.maps[i].ids[s.chain], b = ls.maps[j].ids[t.chain];
        if (a == b || ls.has[i].contains({b, t.a, t.b}) || ls.has[j].contains({a, s.a, s.b})) {
            return;
        }
        if (meet(s, t)) {
            across.insert(ordered(a, b));
        }
    });
    return across;
}

} // namespace

CgalCheck cgal_check(const reader::Tree& tree, const Report& report)
{
    const auto t0 = std::chrono::steady_clock::now();
    const auto& sk = tree.skeleton();
    const size_t lods = sk.lod_eps_m.size();
    CgalCheck out;
    Within verify_within, cgal_within;
    Across verify_across, cgal_across;
    verify_pairs(report, verify_within, verify_across);
    for (uint32_t l = 0; l < sk.level_names.size(); ++l) {
        const std::string& level = sk.level_names[l];
        const LevelSegments ls = level_segments(level_maps(tree, l));
        for (const auto& segs : ls.segs) {
            out.segments += segs.size();
        }
        // Within each LOD; LOD 0's meetings are the input's.
        std::set<Pair> input;
        for (uint32_t k = 0; k < lods; ++k) {
            const std::set<Pair> found = meetings_within(ls, k);
            if (k == 0) {
                input = found;
            }
            for (const auto& p : found) {
                if (!input.contains(p)) {
                    cgal_within.insert({level, k, p.first, p.second});
                }
            }
        }
        out.input_pairs += input.size();
        for (uint32_t i = 0; i < lods; ++i) {
            for (uint32_t j = i + 1; j < lods; ++j) {
                for (const auto& p : meetings_across(ls, i, j)) {
                    if (!input.contains(p)) {
                        cgal_across.insert({level, p.first, p.second});
                    }
                }
            }
        }
    }
    out.within_pairs = cgal_within.size();
    out.across_pairs = cgal_across.size();

    auto note = [&](const std::string& s) {
        if (out.disagreements.size() < 20) {
            out.disagreements.push_back(s);
        }
    };
    if (report.items_dropped > 0) {
        // Not every item is listed: compare the counts.
        auto count = [&](const char* k) {
            const auto it = report.violations.find(k);
            return it == report.violations.end() ? uint64_t{0} : it->second;
        };
        const uint64_t within = count("crossings") + count("overlaps") + count("self_intersections");
        if (within != out.within_pairs) {
            note("meetings within a LOD: verify counts " + std::to_string(within) + ", CGAL finds " +
                 std::to_string(out.within_pairs));
        }
        if (count("lod_crossings") != out.across_pairs) {
            note("meetings across LODs: verify counts " + std::to_string(count("lod_crossings")) + ", CGAL finds " +
                 std::to_string(out.across_pairs));
        }
    } else {
        for (const auto& [level, k, a, b] : cgal_within) {
            if (!verify_within.contains({level, k, a, b})) {
                note(level + " LOD " + std::to_string(k) + ": CGAL finds chains " + std::to_string(a) + " and " +
                     std::to_string(b) + " meeting; verify does not");
            }
        }
        for (const auto& [level, k, a, b] : verify_within) {
            if (!cgal_within.contains({level, k, a, b})) {
                note(level + " LOD " + std::to_string(k) + ": verify finds chains " + std::to_string(a) + " and " +
                     std::to_string(b) + " meeting; CGAL does not");
            }
        }
        for (const auto& [level, a, b] : cgal_across) {
            if (!verify_across.contains({level, a, b})) {
                note(level + ": CGAL finds chains " + std::to_string(a) + " and " + std::to_string(b) +
                     " meeting across LODs; verify does not");
            }
        }
        for (const auto& [level, a, b] : verify_across) {
            if (!cgal_across.contains({level, a, b})) {
                note(level + ": verify finds chains " + std::to_string(a) + " and " + std::to_string(b) +
                     " meeting across LODs; CGAL does not");
            }
        }
    }
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return out;
}

} // namespace tigerlod::verify
