#include "stages/verify/verifier.hpp"

#include "core/errors.hpp"
#include "core/geometry.hpp"
#include "core/parallel.hpp"
#include "core/projection.hpp"
#include "core/segment_grid.hpp"
#include "formats/chains/chain_store.hpp"
#include "reader/tree_view.hpp"
#include "core/metric.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <iterator>
#include <cmath>
#include <mutex>
#include <optional>
#include <set>
#include <unordered_map>

namespace fs = std::filesystem;

namespace tigerlod::verify {

namespace {

int sign(int128 v)
{
    return (v > 0) - (v < 0);
}

/// A chain's segments for meetings_by_window: its points, and the layer
/// and group find_intersections_between tells apart.
struct ChainSegments {
    std::span<const GridPoint> pts;
    uint32_t layer = 0, group = 0;
};

/// What find_intersections (or, with `between`, find_intersections_between
/// by layer and group) finds over the segments of all `chains`, segment s
/// of chain c numbered base[c] + s (base: each chain's first segment,
/// counting every segment; zero-length ones take no part), sorted, each
/// pair once: the same pairs, relations and points as one call over them
/// all, since a pair that meets has its point in one window and both its
/// chains in that window. The level's box is cut into windows of about
/// `window_segments`, each chain in every window its box touches, so memory
/// follows a window, not the level (the whole level at once held 40 bytes a
/// segment and the grid over them: 10 GB for the block level of a 100 M
/// vertex nation).
std::vector<Intersection> meetings_by_window(const std::vector<ChainSegments>& chains, std::vector<uint64_t>& base,
                                             bool between, size_t window_segments, unsigned threads)
{
    base.assign(chains.size() + 1, 0);
    GridBox box;
    for (size_t c = 0; c < chains.size(); ++c) {
        base[c + 1] = base[c] + (chains[c].pts.empty() ? 0 : chains[c].pts.size() - 1);
        for (const GridPoint p : chains[c].pts) {
            box.extend(p);
        }
    }
    if (base.back() > UINT32_MAX) {
        throw std::length_error("verify: a level of more than 2^32 segments");
    }
    if (box.empty()) {
        return {};
    }
    const int64_t side = std::max<int64_t>(
        1, std::llround(std::ceil(std::sqrt(double(base.back()) / double(std::max<size_t>(window_segments, 1))))));
    const int64_t wx = std::max<int64_t>(1, (box.max_x - box.min_x) / side + 1);
    const int64_t wy = std::max<int64_t>(1, (box.max_y - box.min_y) / side + 1);
    std::vector<std::vector<uint32_t>> in_window(size_t(side * side));
    for (size_t c = 0; c < chains.size(); ++c) {
        GridBox cb;
        for (const GridPoint p : chains[c].pts) {
            cb.extend(p);
        }
        if (cb.empty()) {
            continue;
        }
        for (int64_t y = (cb.min_y - box.min_y) / wy; y <= (cb.max_y - box.min_y) / wy; ++y) {
            for (int64_t x = (cb.min_x - box.min_x) / wx; x <= (cb.max_x - box.min_x) / wx; ++x) {
                in_window[size_t(y * side + x)].push_back(uint32_t(c));
            }
        }
    }
    std::vector<Intersection> all;
    std::vector<Segment> segs;
    std::vector<uint32_t> layer, group, global;
    for (const auto& window : in_window) {
        segs.clear();
        layer.clear();
        group.clear();
        global.clear();
        for (const uint32_t c : window) { // in chain order: local order is global order
            const auto pts = chains[c].pts;
            for (size_t i = 0; i + 1 < pts.size(); ++i) {
                if (pts[i] == pts[i + 1]) {
                    continue; // a zero-length segment is the subsequence check's to report
                }
                segs.push_back({pts[i], pts[i + 1], uint32_t(segs.size())});
                layer.push_back(chains[c].layer);
                group.push_back(chains[c].group);
                global.push_back(uint32_t(base[c] + i));
            }
        }
        auto found =
            between ? find_intersections_between(segs, layer, group, threads) : find_intersections(segs, threads);
        for (auto& x : found) {
            x.first = global[x.first];
            x.second = global[x.second];
            all.push_back(x);
        }
    }
    std::sort(all.begin(), all.end(), [](const Intersection& a, const Intersection& b) {
        return std::tie(a.first, a.second) < std::tie(b.first, b.second);
    });
    all.erase(std::unique(all.begin(), all.end(),
                          [](const Intersection& a, const Intersection& b) {
                              return a.first == b.first && a.second == b.second;
                          }),
              all.end());
    return all;
}

/// The chain and segment of a segment numbered by meetings_by_window.
std::pair<size_t, uint32_t> chain_segment(const std::vector<uint64_t>& base, uint32_t global)
{
    const size_t c = size_t(std::upper_bound(base.begin(), base.end(), uint64_t{global}) - base.begin()) - 1;
    return {c, uint32_t(global - base[c])};
}

/// Which units of a node's map hold a point, in one pass over the segments
/// that cross the point's row: each segment of a chain with different units
/// on its two sides flips both units' even-odd state where it crosses the
/// ray to the right of the point (PointInPolygon's rule), so a unit whose
/// state ends odd holds the point, for every unit at once. The segments are
/// bucketed by rows of equal height, about sqrt(segments) of them.
class UnitLocator {
  public:
    UnitLocator(const datatree::ChainTable& table, const datatree::Geometry& geometry)
    {
        int64_t lo = INT64_MAX, hi = INT64_MIN;
        for (size_t c = 0; c < table.chains.size(); ++c) {
            const auto& e = table.chains[c];
            if (e.left == e.right) {
                continue;
            }
            const auto pts = geometry.chain(c);
            for (size_t i = 0; i + 1 < pts.size(); ++i) {
                m_segs.push_back({pts[i], pts[i + 1], e.left, e.right});
                lo = std::min<int64_t>({lo, pts[i].y, pts[i + 1].y});
                hi = std::max<int64_t>({hi, pts[i].y, pts[i + 1].y});
            }
        }
        if (m_segs.empty()) {
            return;
        }
        m_y0 = lo;
        const auto rows = static_cast<int64_t>(std::ceil(std::sqrt(double(m_segs.size()))));
        m_row = std::max<int64_t>(1, (hi - lo) / rows + 1);
        m_first.assign(static_cast<size_t>((hi - lo) / m_row + 2), 0);
        auto each_row = [&](const Seg& g, auto&& f) {
            for (int64_t r = (std::min(g.a.y, g.b.y) - m_y0) / m_row; r <= (std::max(g.a.y, g.b.y) - m_y0) / m_row;
                 ++r) {
                f(static_cast<size_t>(r));
            }
        };
        for (const Seg& g : m_segs) {
            each_row(g, [&](size_t r) { ++m_first[r + 1]; });
        }
        for (size_t r = 1; r < m_first.size(); ++r) {
            m_first[r] += m_first[r - 1];
        }
        m_in_row.resize(m_first.back());
        std::vector<uint32_t> fill(m_first.begin(), m_first.end() - 1);
        for (uint32_t i = 0; i < m_segs.size(); ++i) {
            each_row(m_segs[i], [&](size_t r) { m_in_row[fill[r]++] = i; });
        }
    }

    /// The units strictly holding p (sorted), and those on whose boundary it lies.
    void locate(GridPoint p, std::vector<uint32_t>& inside, std::vector<uint32_t>& boundary) const
    {
        inside.clear();
        boundary.clear();
        if (m_segs.empty() || p.y < m_y0 || (p.y - m_y0) / m_row + 1 >= int64_t(m_first.size())) {
            return;
        }
        const auto r = static_cast<size_t>((p.y - m_y0) / m_row);
        std::vector<uint32_t> flips;
        for (uint32_t k = m_first[r]; k < m_first[r + 1]; ++k) {
            const Seg& g = m_segs[m_in_row[k]];
            if (orientation(g.a, g.b, p) == 0 && in_span(g.a, g.b, p)) {
                boundary.push_back(g.left);
                boundary.push_back(g.right);
                continue;
            }
            if (crosses_ray_right(g.a, g.b, p)) {
                flips.push_back(g.left);
                flips.push_back(g.right);
            }
        }
        std::sort(flips.begin(), flips.end());
        for (size_t i = 0; i < flips.size();) {
            size_t j = i;
            while (j < flips.size() && flips[j] == flips[i]) {
                ++j;
            }
            if ((j - i) % 2 == 1 && flips[i] != 0) {
                inside.push_back(flips[i]);
            }
            i = j;
        }
        std::sort(boundary.begin(), boundary.end());
        boundary.erase(std::unique(boundary.begin(), boundary.end()), boundary.end());
        // On a boundary is not inside, whatever the parity says.
        std::erase_if(inside, [&](uint32_t u) { return std::binary_search(boundary.begin(), boundary.end(), u); });
    }

  private:
    struct Seg {
        GridPoint a, b;
        uint32_t left, right;
    };
    std::vector<Seg> m_segs;
    int64_t m_y0 = 0, m_row = 1;
    std::vector<uint32_t> m_first;  ///< per row, its first entry in m_in_row; rows + 1 entries
    std::vector<uint32_t> m_in_row; ///< segment indices, row by row
};                                  // class UnitLocator

/// An original chain of a level: its store, its record and its tolerance at the LOD.
struct Original {
    const chains::ChainStore* store = nullptr;
    const chains::ChainInfo* info = nullptr;
    size_t index = 0;   ///< in its store
    double scale = 0.0; ///< the least projection scale over the chain's box (with the ground check)
};

/// What one node contributes at one LOD.
struct NodeResult {
    std::vector<Violation> violations;
    datatree::ChainTable table;
    datatree::Geometry geometry;
    bool ok = false;
    uint64_t points = 0;
    double ground_ratio = 0; ///< LevelLod::ground_ratio_max of the node
    uint64_t ground_geodesics = 0;
    double ground_seconds = 0; ///< spent in check_ground
};

/// Which unit of a node's map contains each user point (found on the original map).
struct UserPoint {
    size_t index = 0; ///< in Options::user_points
    GridPoint p;
    std::string unit; ///< the unit that holds it in the original map
};

/// The items in report order, the first `max_items` of them kept, the
/// rest counted as dropped: whatever order they were found in, and however
/// many runs found them, the same items are kept.
void keep_first_items(Report& r, size_t max_items)
{
    auto& items = r.items;
    const auto order = [](const Violation& a, const Violation& b) {
        return std::tie(a.level, a.lod, a.kind, a.node, a.chains, a.x, a.y, a.detail) <
               std::tie(b.level, b.lod, b.kind, b.node, b.chains, b.x, b.y, b.detail);
    };
    if (items.size() > max_items) {
        std::nth_element(items.begin(), items.begin() + static_cast<std::ptrdiff_t>(max_items), items.end(), order);
        r.items_dropped += items.size() - max_items;
        items.resize(max_items);
    }
    std::sort(items.begin(), items.end(), order);
}

class Verifier {
  public:
    Verifier(const reader::Tree& tree, const fs::path& original, const Options& options, const Selection* selection)
        : m_tree(tree), m_sk(tree.skeleton()), m_original(original), m_options(options), m_selection(selection),
          m_proj(view::projection_of(m_sk)), m_metric(static_cast<Metric>(m_sk.metric))
    {
        m_opt = options.tolerance;
        m_opt.metric = m_metric;
    }

    Report run()
    {
        const auto t0 = std::chrono::steady_clock::now();
        for (const char* k : kinds) {
            m_report.violations[k] = 0;
        }
        m_report.nodes = m_sk.nodes.size();
        m_report.lods = m_sk.lod_eps_m.size();
        m_report.ground = m_options.ground;
        for (uint32_t l = 0; l < m_sk.level_names.size(); ++l) {
            verify_level(l);
        }
        m_report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        keep_first_items(m_report, m_options.max_items);
        return std::move(m_report);
    }

  private:
    void add(LevelLod& ll, Violation v)
    {
        if (v.kind == "input_problem") {
            ++ll.input_problems;
            ++m_report.input_problems;
        } else {
            ++ll.violations[v.kind];
            ++m_report.violations[v.kind];
        }
        m_proj.to_lonlat(v.x, v.y, v.lon, v.lat);
        std::sort(v.chains.begin(), v.chains.end());
        m_report.items.push_back(std::move(v));
        if (m_report.items.size() >= 2 * std::max<size_t>(m_options.max_items, 1)) {
            keep_first_items(m_report, m_options.max_items); // memory follows max_items, not the violations
        }
    }

    std::string node_code(uint32_t n) const { return m_sk.strings[m_sk.nodes[n].code]; }
    /// The root of a line layer cut into tiles: no chains, its children
    /// the tiles, of its own level. It shows nothing and has no store.
    bool tiles_root(uint32_t n) const
    {
        const auto& node = m_sk.nodes[n];
        return n == 0 && node.chains == 0 && node.child_count > 0 && m_sk.nodes[node.first_child].level == node.level;
    }
    /// The chain store partition whose map node `n` shows.
    std::string partition_of(uint32_t n) const { return n == 0 ? std::string("all") : node_code(n); }

    /// The original stores a level is checked with, the owned chains by id,
    /// the stores by partition, and each store's chains (own and halo) by id.
    struct LevelStores {
        std::vector<chains::ChainStore> stores;
        std::unordered_map<uint64_t, Original> owned;
        std::map<std::string, const chains::ChainStore*> by_partition;
        std::map<const chains::ChainStore*, std::vector<uint64_t>> halo; ///< each store's halo chains, sorted
        double scale_seconds = 0; ///< finding the owned chains' scales (the ground check's), summed over threads
    };

    /// Read the stores of `partitions` (all of the level's folder when
    /// empty) into `ls`.
    void read_level(const fs::path& dir, const std::set<std::string>& partitions, LevelStores& ls) const
    {
        std::vector<fs::path> paths;
        if (partitions.empty()) {
            for (const auto& f : fs::directory_iterator(dir)) {
                if (f.path().extension() == ".tlc") {
                    paths.push_back(f.path());
                }
            }
        } else {
            for (const auto& p : partitions) {
                paths.push_back(dir / (p + ".tlc"));
                if (!fs::exists(paths.back())) {
                    throw input_error(dir.string() + ": no store for partition " + p);
                }
            }
        }
        std::sort(paths.begin(), paths.end());
        ls.stores.resize(paths.size());
        parallel_each(paths.size(), m_options.threads, [&](size_t i) { ls.stores[i] = chains::read(paths[i]); });
        for (const auto& s : ls.stores) {
            ls.by_partition[s.partition] = &s;
            auto& halo = ls.halo[&s];
            for (size_t i = 0; i < s.chains.size(); ++i) {
                if (s.chains[i].flags & chains::chain_halo) {
                    halo.push_back(s.chains[i].id);
                } else {
                    ls.owned[s.chains[i].id] = {&s, &s.chains[i], i, 0.0};
                }
            }
            std::sort(halo.begin(), halo.end());
        }
        if (m_options.ground) { // once a chain, for every LOD's ground check
            std::vector<Original*> all;
            all.reserve(ls.owned.size());
            for (auto& [id, o] : ls.owned) {
                all.push_back(&o);
            }
            std::atomic<int64_t> ns{0};
            parallel_blocks(all.size(), m_options.threads, 1024, [&](size_t b, size_t e) {
                const auto t0 = std::chrono::steady_clock::now();
                for (size_t i = b; i < e; ++i) {
                    GridBox box;
                    for (const auto& p : all[i]->store->chain_points(*all[i]->info)) {
                        box.extend(p);
                    }
                    all[i]->scale = m_proj.smallest_scale(box);
                }
                ns +=
                    std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count();
            });
            ls.scale_seconds = double(ns.load()) * 1e-9;
        }
    }

    /// A chain of the level at one LOD as its home node shows it: the node
    /// of the store that owns it (every node shows all its store owns).
    struct HomeChain {
        uint64_t id = 0;
        uint32_t home = 0;  ///< skeleton node
        uint32_t chain = 0; ///< in its home's table (16 bytes a chain: a level of the 100 M nation holds 15 M)
    };
    /// Each checked or decoded node's result, by node index.
    using ByNode = std::vector<NodeResult*>;
    static std::span<const GridPoint> points_of(const ByNode& by_node, const HomeChain& u)
    {
        return by_node[u.home]->geometry.chain(u.chain);
    }

    /// Whether a meeting of chains `a` and `b` is this run's to report, and
    /// which of them it is filed under: a meeting belongs to the chain of the
    /// smaller (home node, id), and is reported by the run that checks that
    /// chain's home node, if the other chain is in its home's store (own or
    /// halo). Two chains of a level that meet in the tree lie within the
    /// halo of each other's store unless one strays farther than its
    /// tolerance from its original (reported as eps_exceeded), so a tree is
    /// clean exactly when every node's checks are. The same rule whole or by
    /// partitions, so the report is the same.
    struct MeetingRule {
        const std::set<uint32_t>* selected;
        const std::map<uint32_t, const std::vector<uint64_t>*>* store_halo; ///< home node -> its store's halo ids
        /// The chain the meeting is filed under, or nullptr when not this run's.
        const HomeChain* owner(const HomeChain& a, const HomeChain& b) const
        {
            const HomeChain& first = std::tie(a.home, a.id) <= std::tie(b.home, b.id) ? a : b;
            const HomeChain& other = &first == &a ? b : a;
            if (!selected->contains(first.home)) {
                return nullptr;
            }
            if (other.home == first.home) {
                return &first; // both the store's own
            }
            const auto it = store_halo->find(first.home);
            return it != store_halo->end() && std::binary_search(it->second->begin(), it->second->end(), other.id)
                       ? &first
                       : nullptr;
        }
    };

    /// One level at every LOD: each selected node checked against its
    /// original store (check_node), each chain it shows from a neighbour
    /// compared with the neighbour's (border_mismatch), then the meetings
    /// near the selected nodes' chains (check_meetings, check_across_lods),
    /// into the report. The selected nodes: the level's, or those of the
    /// stores given (verify_stores); beside them the nodes of the stores
    /// that own a chain of their halos are decoded, not checked.
    void verify_level(uint32_t l)
    {
        const std::string& level = m_sk.level_names[l];
        std::map<std::string, uint32_t> node_of; // partition -> node of the level
        for (uint32_t n = 0; n < m_sk.nodes.size(); ++n) {
            if (m_sk.nodes[n].level == l && !tiles_root(n)) {
                node_of[partition_of(n)] = n;
            }
        }
        std::vector<uint32_t> nodes; // selected, in order
        std::set<std::string> partitions;
        for (const auto& [partition, n] : node_of) {
            if (!m_selection || m_selection->stores.contains(level + "/" + partition)) {
                nodes.push_back(n);
                if (m_selection) {
                    partitions.insert(partition);
                    const auto it = m_selection->near.find(level + "/" + partition);
                    for (const auto& other : it == m_selection->near.end() ? std::vector<std::string>{} : it->second) {
                        partitions.insert(fs::path(other).filename().string());
                    }
                }
            }
        }
        std::sort(nodes.begin(), nodes.end());
        if (nodes.empty()) {
            return;
        }
        const fs::path dir = m_original / level;
        if (!fs::is_directory(dir)) {
            throw input_error(dir.string() + ": no stores for level '" + level + "' of the tree");
        }
        LevelStores ls;
        read_level(dir, partitions, ls);
        m_report.ground_seconds += ls.scale_seconds;
        for (uint32_t n : nodes) {
            if (!ls.by_partition.contains(partition_of(n))) {
                throw input_error(dir.string() + ": no store for partition " + partition_of(n) + " (node " +
                                  std::to_string(n) + ")");
            }
        }
        // The working stores' nodes, in node order: the selected and those decoded beside them.
        std::vector<uint32_t> homes;
        std::map<const chains::ChainStore*, uint32_t> home_of_store;
        std::map<uint32_t, const std::vector<uint64_t>*> store_halo;
        for (const auto& [partition, store] : ls.by_partition) {
            const auto it = node_of.find(partition);
            if (it == node_of.end()) {
                throw input_error((dir / (partition + ".tlc")).string() + ": the tree has no node for this store");
            }
            homes.push_back(it->second);
            home_of_store[store] = it->second;
            store_halo[it->second] = &ls.halo.at(store);
        }
        std::sort(homes.begin(), homes.end());
        const std::set<uint32_t> selected(nodes.begin(), nodes.end());
        const MeetingRule rule{&selected, &store_halo};
        // The units whose boundary each node's original map holds, and their original area sign.
        std::set<std::pair<uint64_t, uint64_t>> input_meetings; // chain pairs that meet at LOD 0
        std::vector<LodChains> lods(m_sk.lod_eps_m.size());     // each LOD's chains, for check_across_lods
        std::vector<std::vector<UserPoint>> user_points(nodes.size());
        std::vector<std::map<std::string, int>> area_sign(nodes.size());
        parallel_each(nodes.size(), m_options.threads, [&](size_t i) {
            original_facts(*ls.by_partition.at(partition_of(nodes[i])), area_sign[i], user_points[i]);
        });

        // What each chain's tolerance is scaled by, once for every LOD.
        std::vector<std::optional<simplify::ChainScales>> scales(ls.stores.size());
        parallel_each(ls.stores.size(), m_options.threads, [&](size_t i) { scales[i].emplace(ls.stores[i], m_opt); });
        for (uint32_t k = 0; k < m_sk.lod_eps_m.size(); ++k) {
            LevelLod ll;
            ll.level = level;
            ll.lod = k;
            ll.eps_m = m_sk.lod_eps_m[k];
            for (const char* kind : kinds) {
                ll.violations[kind] = 0;
            }
            // Tolerances of the LOD, per original chain.
            std::map<const chains::ChainStore*, std::vector<double>> eps;
            if (k > 0) {
                for (size_t i = 0; i < ls.stores.size(); ++i) {
                    eps[&ls.stores[i]] = scales[i]->tolerances(ll.eps_m);
                }
            }
            // The selected nodes checked, the others decoded.
            std::vector<NodeResult> results(homes.size()); // parallel to homes
            parallel_each(homes.size(), m_options.threads, [&](size_t i) {
                const uint32_t n = homes[i];
                NodeResult& r = results[i];
                if (selected.contains(n)) {
                    const size_t slot = size_t(std::lower_bound(nodes.begin(), nodes.end(), n) - nodes.begin());
                    r = check_node(n, k, ls.owned, *ls.by_partition.at(partition_of(n)), eps, area_sign[slot],
                                   user_points[slot]);
                } else {
                    r.ok = m_tree.read_table(n, r.table).ok() && m_tree.read_geometry(n, k, r.geometry).ok();
                }
            });
            ByNode by_node(m_sk.nodes.size(), nullptr);
            for (size_t i = 0; i < homes.size(); ++i) {
                by_node[homes[i]] = &results[i];
            }
            // Each chain once, from its home node, in (home, id) order.
            std::vector<HomeChain> unique;
            for (const uint32_t n : homes) {
                const NodeResult& r = *by_node[n];
                if (!r.ok) {
                    continue;
                }
                for (size_t c = 0; c < r.table.chains.size(); ++c) {
                    const auto it = ls.owned.find(r.table.chains[c].id);
                    if (it != ls.owned.end() && home_of_store.at(it->second.store) == n) {
                        unique.push_back({r.table.chains[c].id, n, static_cast<uint32_t>(c)});
                    }
                }
            }
            gather_nodes(ll, nodes, by_node, unique, ls, home_of_store);
            check_meetings(ll, by_node, unique, rule, input_meetings);
            keep_for_lods(lods[k], by_node, unique);
            m_report.chains += ll.chains;
            m_report.segments += ll.segments;
            m_report.points += ll.points;
            m_report.ground_ratio_max = std::max(m_report.ground_ratio_max, ll.ground_ratio_max);
            m_report.ground_geodesics += ll.ground_geodesics;
            if (m_options.on_level_lod) {
                m_options.on_level_lod(ll.segments);
            }
            m_report.by_level_lod.push_back(std::move(ll));
        }
        check_across_lods(level, lods, rule, input_meetings);
    }

    /// A level's chains at one LOD, each once, for the check across LODs.
    struct LodChains {
        std::vector<uint64_t> ids;
        std::vector<uint32_t> nodes; ///< the home node of each (a string each held 0.3 GB at 100 M vertices)
        datatree::Geometry geometry;
    };

    void keep_for_lods(LodChains& out, const ByNode& by_node, const std::vector<HomeChain>& unique) const
    {
        for (const auto& u : unique) {
            out.ids.push_back(u.id);
            out.nodes.push_back(u.home);
            out.geometry.add_chain(points_of(by_node, u));
        }
    }

    /// Every LOD of a chain against every other LOD of each chain near it,
    /// within and across nodes: a viewer's front holds neighbouring nodes at
    /// different LODs, and a chain shown by two of them is drawn at one. A
    /// meeting of a at LOD i with b at LOD j that is one of the same LOD in
    /// disguise (b's segment is also b's at LOD i, or a's also a's at LOD j)
    /// was reported by that LOD's check and is left out. One violation per
    /// pair of chains, filed under the coarser LOD of its worst meeting (the
    /// first found) and the home node of the chain there, as MeetingRule
    /// says. Chains that already meet in the original map are input problems.
    void check_across_lods(const std::string& level, const std::vector<LodChains>& lods, const MeetingRule& rule,
                           const std::set<std::pair<uint64_t, uint64_t>>& input_meetings)
    {
        if (lods.size() < 2) {
            return;
        }
        std::unordered_map<uint64_t, uint32_t> group_of; // chain id -> group
        std::vector<std::vector<uint32_t>> index_of;     // per group, the chain's index at each LOD
        std::vector<ChainSegments> chains;
        struct Where {
            uint32_t lod, chain, segment;
        };
        std::vector<std::pair<uint32_t, uint32_t>> chain_at; // (LOD, chain) of each of `chains`
        for (uint32_t k = 0; k < lods.size(); ++k) {
            const auto& lc = lods[k];
            for (uint32_t c = 0; c < lc.ids.size(); ++c) {
                const auto [it, fresh] = group_of.try_emplace(lc.ids[c], static_cast<uint32_t>(group_of.size()));
                if (fresh) {
                    index_of.emplace_back(lods.size(), UINT32_MAX);
                }
                index_of[it->second][k] = c;
                chains.push_back({lc.geometry.chain(c), k, it->second});
                chain_at.emplace_back(k, c);
            }
        }
        std::vector<uint64_t> base;
        const auto found = meetings_by_window(chains, base, true, m_options.window_segments, m_options.threads);
        auto where_of = [&](uint32_t global) {
            const auto [c, s] = chain_segment(base, global);
            return Where{chain_at[c].first, chain_at[c].second, s};
        };
        auto segment_of = [&](const Where& w) {
            const auto pts = lods[w.lod].geometry.chain(w.chain);
            return Segment{pts[w.segment], pts[w.segment + 1], 0};
        };
        auto home_chain = [&](const Where& w) {
            return HomeChain{lods[w.lod].ids[w.chain], lods[w.lod].nodes[w.chain], 0};
        };
        // Whether segment s of chain `g` is also one of its segments at LOD k.
        auto has_segment = [&](uint32_t g, uint32_t k, const Segment& seg) {
            const uint32_t c = index_of[g][k];
            if (c == UINT32_MAX) {
                return false;
            }
            const auto pts = lods[k].geometry.chain(c);
            for (size_t i = 0; i + 1 < pts.size(); ++i) {
                if (pts[i] == seg.a && pts[i + 1] == seg.b) {
                    return true;
                }
            }
            return false;
        };
        auto rank_of = [](SegmentRelation r) {
            return r == SegmentRelation::overlap ? 3 : r == SegmentRelation::cross ? 2 : 1;
        };
        std::map<std::pair<uint64_t, uint64_t>, std::pair<Intersection, int>> meetings; // by chain ids
        for (const auto& x : found) {
            const Where a = where_of(x.first), b = where_of(x.second);
            if (!rule.owner(home_chain(a), home_chain(b))) {
                continue; // another run's, or of chains the partition contract keeps apart
            }
            const uint32_t ga = group_of.at(lods[a.lod].ids[a.chain]), gb = group_of.at(lods[b.lod].ids[b.chain]);
            if (has_segment(gb, a.lod, segment_of(b)) || has_segment(ga, b.lod, segment_of(a))) {
                continue; // the same meeting at one LOD
            }
            const uint64_t ida = lods[a.lod].ids[a.chain], idb = lods[b.lod].ids[b.chain];
            const auto key = std::make_pair(std::min(ida, idb), std::max(ida, idb));
            const int rank = rank_of(x.relation);
            auto [it, fresh] = meetings.try_emplace(key, x, rank);
            if (!fresh && rank > it->second.second) {
                it->second = {x, rank};
            }
        }
        for (const auto& [ids, m] : meetings) {
            const auto& x = m.first;
            Where a = where_of(x.first), b = where_of(x.second);
            if (a.lod > b.lod) {
                std::swap(a, b);
            }
            const char* rel = x.relation == SegmentRelation::cross     ? "cross"
                              : x.relation == SegmentRelation::touch   ? "touch"
                              : x.relation == SegmentRelation::overlap ? "overlap"
                                                                       : "meet";
            auto ll = std::find_if(m_report.by_level_lod.begin(), m_report.by_level_lod.end(),
                                   [&](const LevelLod& l) { return l.level == level && l.lod == b.lod; });
            add(*ll, {input_meetings.contains(ids) ? "input_problem" : "lod_crossings", level, b.lod,
                      node_code(rule.owner(home_chain(a), home_chain(b))->home),
                      std::vector<uint64_t>{ids.first, ids.second}, x.x, x.y, 0, 0,
                      "chain " + std::to_string(lods[a.lod].ids[a.chain]) + " at LOD " + std::to_string(a.lod) +
                          " segment " + std::to_string(a.segment) + " and chain " +
                          std::to_string(lods[b.lod].ids[b.chain]) + " at LOD " + std::to_string(b.lod) + " segment " +
                          std::to_string(b.segment) + " " + rel});
        }
    }

    /// The selected nodes, in order: their own findings into `ll`, their
    /// chains and points counted, and each chain a node shows from a
    /// neighbour's store compared with the neighbour's (border_mismatch,
    /// filed under the node that shows it from the neighbour).
    void gather_nodes(LevelLod& ll, const std::vector<uint32_t>& nodes, const ByNode& by_node,
                      const std::vector<HomeChain>& unique, const LevelStores& ls,
                      const std::map<const chains::ChainStore*, uint32_t>& home_of_store)
    {
        const std::string& level = ll.level;
        const uint32_t k = ll.lod;
        const std::set<uint32_t> selected(nodes.begin(), nodes.end());
        for (const uint32_t n : nodes) {
            auto& r = *by_node[n];
            ++ll.nodes;
            ll.points += r.points;
            ll.ground_ratio_max = std::max(ll.ground_ratio_max, r.ground_ratio);
            ll.ground_geodesics += r.ground_geodesics;
            m_report.ground_seconds += r.ground_seconds;
            for (auto& v : r.violations) {
                v.level = level;
                v.lod = k;
                add(ll, std::move(v));
            }
            if (!r.ok) {
                continue;
            }
            for (size_t c = 0; c < r.table.chains.size(); ++c) {
                const uint64_t id = r.table.chains[c].id;
                const auto it = ls.owned.find(id);
                if (it == ls.owned.end()) {
                    continue; // check_chain reported it
                }
                const uint32_t home = home_of_store.at(it->second.store);
                if (home == n) {
                    continue;
                }
                const auto& h = *by_node[home];
                if (!h.ok) {
                    continue; // the home node's own check reports it unreadable
                }
                const auto at = std::lower_bound(h.table.chains.begin(), h.table.chains.end(), id,
                                                 [](const auto& e, uint64_t v) { return e.id < v; });
                const auto b = r.geometry.chain(c);
                const bool shown = at != h.table.chains.end() && at->id == id;
                std::string fault;
                if (!shown) {
                    fault =
                        "shown by node " + node_code(n) + " and not by " + node_code(home) + ", whose store owns it";
                } else if (const auto a = h.geometry.chain(size_t(at - h.table.chains.begin()));
                           !std::equal(a.begin(), a.end(), b.begin(), b.end())) {
                    fault =
                        "shown by nodes " + node_code(home) + " and " + node_code(n) + " with different coordinates";
                }
                if (!fault.empty()) {
                    add(ll, {"border_mismatch",
                             level,
                             k,
                             node_code(n),
                             {id},
                             double(b.front().x),
                             double(b.front().y),
                             0,
                             0,
                             std::move(fault)});
                }
            }
        }
        for (const auto& u : unique) {
            if (selected.contains(u.home)) {
                const auto pts = points_of(by_node, u);
                ll.chains += 1;
                ll.vertices += pts.size();
                for (size_t s = 0; s + 1 < pts.size(); ++s) {
                    ll.segments += pts[s] == pts[s + 1] ? 0 : 1; // a zero-length one is the subsequence check's
                }
            }
        }
    }

    /// Crossings, overlaps and self-intersections near the selected nodes'
    /// chains at one LOD, one violation per pair of chains (or per chain,
    /// meeting itself) as MeetingRule files it: the worst way they meet
    /// (overlap, then cross, then touch), at the first place found in (home
    /// node, id) order. Pairs that already meet at LOD 0 are input problems
    /// (ingest reported and flagged them), listed, not counted.
    void check_meetings(LevelLod& ll, const ByNode& by_node, const std::vector<HomeChain>& unique,
                        const MeetingRule& rule, std::set<std::pair<uint64_t, uint64_t>>& input_meetings)
    {
        const std::string& level = ll.level;
        const uint32_t k = ll.lod;
        std::vector<ChainSegments> chains; // the unique chains, in order
        for (const auto& u : unique) {
            chains.push_back({points_of(by_node, u), 0, 0});
        }
        std::vector<uint64_t> base;
        const auto found = meetings_by_window(chains, base, false, m_options.window_segments, m_options.threads);
        struct Meeting {
            Intersection x;
            size_t ua, ub;
            int rank;
        };
        auto rank_of = [](SegmentRelation r) {
            return r == SegmentRelation::overlap ? 3 : r == SegmentRelation::cross ? 2 : 1;
        };
        std::map<std::pair<uint64_t, uint64_t>, Meeting> meetings;
        for (const auto& x : found) {
            const size_t ua = chain_segment(base, x.first).first, ub = chain_segment(base, x.second).first;
            const uint64_t ida = unique[ua].id, idb = unique[ub].id;
            const auto key = std::make_pair(std::min(ida, idb), std::max(ida, idb));
            if (k == 0) {
                input_meetings.insert(key);
            }
            if (!rule.owner(unique[ua], unique[ub])) {
                continue; // another run's, or of chains the partition contract keeps apart
            }
            const int rank = rank_of(x.relation);
            auto [it, fresh] = meetings.try_emplace(key, Meeting{x, ua, ub, rank});
            if (!fresh && rank > it->second.rank) {
                it->second = Meeting{x, ua, ub, rank};
            }
        }
        for (const auto& [ids, m] : meetings) {
            // Chains that already meet in the original map: an input problem
            // (ingest reported and flagged it), not one the pipeline made.
            const char* kind = input_meetings.contains(ids)               ? "input_problem"
                               : m.ua == m.ub                             ? "self_intersections"
                               : m.x.relation == SegmentRelation::overlap ? "overlaps"
                                                                          : "crossings";
            const char* rel = m.x.relation == SegmentRelation::cross     ? "cross"
                              : m.x.relation == SegmentRelation::touch   ? "touch"
                              : m.x.relation == SegmentRelation::overlap ? "overlap"
                                                                         : "meet";
            std::vector<uint64_t> chain_ids{ids.first};
            if (ids.second != ids.first) {
                chain_ids.push_back(ids.second);
            }
            add(ll,
                {kind, level, k, node_code(rule.owner(unique[m.ua], unique[m.ub])->home), chain_ids, m.x.x, m.x.y, 0, 0,
                 std::string("segments ") + std::to_string(chain_segment(base, m.x.first).second) + " and " +
                     std::to_string(chain_segment(base, m.x.second).second) + " " + rel});
        }
    }

    /// From a node's original store: each unit's area sign, and the unit holding each user point.
    void original_facts(const chains::ChainStore& store, std::map<std::string, int>& area_sign,
                        std::vector<UserPoint>& user_points) const
    {
        const std::set<std::string> units = own_units(store);
        std::vector<GridPoint> grid(m_options.user_points.size());
        std::vector<bool> valid(grid.size(), false);
        for (size_t i = 0; i < grid.size(); ++i) {
            const auto g = m_proj.to_grid(m_options.user_points[i].lon, m_options.user_points[i].lat);
            if (g) {
                grid[i] = *g;
                valid[i] = true;
            }
        }
        for (const auto& unit : units) {
            int128 a = 0;
            std::vector<PointInPolygon> pips;
            for (size_t i = 0; i < grid.size(); ++i) {
                pips.emplace_back(grid[i]);
            }
            for (const auto& c : store.chains) {
                const bool left = store.strings[c.left] == unit, right = store.strings[c.right] == unit;
                if (left == right) {
                    continue;
                }
                const auto pts = store.chain_points(c);
                const int128 part = twice_area(pts);
                a += left ? part : -part;
                for (auto& pip : pips) {
                    for (size_t s = 0; s + 1 < pts.size(); ++s) {
                        pip.add_segment(pts[s], pts[s + 1]);
                    }
                }
            }
            area_sign[unit] = sign(a);
            for (size_t i = 0; i < grid.size(); ++i) {
                if (valid[i] && pips[i].location() == PointLocation::inside) {
                    user_points.push_back({i, grid[i], unit});
                }
            }
        }
    }

    /// The codes of the partition's own units: those with a point in its
    /// store other than a neighbour's (another partition's unit, checked in
    /// its own node).
    static std::set<std::string> own_units(const chains::ChainStore& store)
    {
        std::set<std::string> units;
        for (const auto& c : store.constraints) {
            if (c.kind != chains::constraint_neighbour) {
                units.insert(store.strings[c.unit]);
            }
        }
        return units;
    }

    /// The table indices of the partition's own units (those whose whole boundary the node holds).
    static std::vector<uint32_t> units_in_table(const datatree::ChainTable& t, const chains::ChainStore& store)
    {
        const std::set<std::string> mine = own_units(store);
        std::vector<uint32_t> out;
        for (uint32_t i = 1; i < t.strings.size(); ++i) {
            if (mine.contains(t.strings[i])) {
                out.push_back(i);
            }
        }
        return out;
    }

    /// Sign of the unit's area from its chains (left side positive): exact.
    static int unit_area_sign(const NodeResult& r, uint32_t unit)
    {
        int128 a = 0;
        for (size_t c = 0; c < r.table.chains.size(); ++c) {
            const auto& e = r.table.chains[c];
            if ((e.left == unit) == (e.right == unit)) {
                continue;
            }
            const int128 part = twice_area(r.geometry.chain(c));
            a += e.left == unit ? part : -part;
        }
        return sign(a);
    }

    /// Adds a violation to a node's result.
    struct Emit {
        NodeResult& r;
        uint32_t k;
        const std::string& code;
        void operator()(const char* kind, std::vector<uint64_t> ids, GridPoint at, std::string detail) const
        {
            r.violations.push_back(
                {kind, "", k, code, std::move(ids), double(at.x), double(at.y), 0, 0, std::move(detail)});
        }
    };

    /// Node n at LOD k against its original store: each chain (checks 1, 2
    /// and 4, and its points in the node's box), the LOD's error bound
    /// (check 7), the units (checks 5 and 6) and the points.
    NodeResult check_node(uint32_t n, uint32_t k, const std::unordered_map<uint64_t, Original>& owned,
                          const chains::ChainStore& store,
                          const std::map<const chains::ChainStore*, std::vector<double>>& eps,
                          const std::map<std::string, int>& area_sign, const std::vector<UserPoint>& user_points) const
    {
        NodeResult r;
        const auto& node = m_sk.nodes[n];
        const std::string code = node_code(n);
        const Emit violation{r, k, code};
        const GridPoint corner{node.box.min_x, node.box.min_y};
        if (auto st = m_tree.read_table(n, r.table); !st.ok()) {
            violation("skeleton", {}, corner, st.error);
            return r;
        }
        if (auto st = m_tree.read_geometry(n, k, r.geometry); !st.ok()) {
            violation("skeleton", {}, corner, st.error);
            return r;
        }
        r.ok = true;
        double worst = 0.0; // largest L2 deviation, grid units
        for (size_t c = 0; c < r.table.chains.size(); ++c) {
            check_chain(r, c, n, k, owned, eps, violation, worst);
        }
        // Check 7: the skeleton's error bound holds.
        if (worst * m_sk.grid_m() > node.lods[k].error_m * (1 + 1e-9) + 1e-9) {
            violation("skeleton", {}, corner,
                      "LOD error_m " + std::to_string(node.lods[k].error_m) + " below the measured " +
                          std::to_string(worst * m_sk.grid_m()));
        }
        check_units(r, store, area_sign, violation);
        if (k == 0) {
            check_unit_table(n, store, violation, corner);
        }
        if (m_options.tolerance.point_constraints) { // else simplify let points change side
            check_points(r, store, user_points, violation);
        }
        return r;
    }

    /// A 2.2 node's units payload (read_units) against its original store:
    /// its own units (kind 0 points), each with that point, and the name
    /// and values ingest recorded for it.
    void check_unit_table(uint32_t n, const chains::ChainStore& store, const Emit& violation, GridPoint corner) const
    {
        if (m_sk.minor < 2) {
            return; // a tree before the units payload
        }
        datatree::UnitTable t;
        if (auto st = m_tree.read_units(n, t); !st.ok()) {
            violation("skeleton", {}, corner, st.error);
            return;
        }
        std::map<std::string, const datatree::UnitTable::Unit*> by_code;
        for (const auto& u : t.units) {
            by_code.emplace(u.code, &u);
        }
        std::map<uint32_t, const chains::UnitRecord*> records;
        for (const auto& rec : store.units) {
            records.emplace(rec.unit, &rec);
        }
        size_t own = 0;
        for (const auto& c : store.constraints) {
            if (c.kind != chains::constraint_internal) {
                continue;
            }
            ++own;
            const std::string& code = store.strings[c.unit];
            const auto it = by_code.find(code);
            if (it == by_code.end() || !(it->second->point == c.p)) {
                violation("skeleton", {}, c.p,
                          "units payload: unit " + code + (it == by_code.end() ? " missing" : " has another point"));
                continue;
            }
            const auto rec = records.find(c.unit);
            const std::string name = rec == records.end() ? std::string() : rec->second->name;
            std::vector<std::string> values(store.fields.size());
            if (rec != records.end()) {
                std::copy_n(rec->second->values.begin(), std::min(values.size(), rec->second->values.size()),
                            values.begin());
            }
            if (it->second->name != name || it->second->values != values || t.fields.size() != store.fields.size()) {
                violation("skeleton", {}, c.p,
                          "units payload: unit " + code +
                              "'s name or attributes differ from "
                              "its store's");
            }
        }
        if (own != t.units.size()) {
            violation("skeleton", {}, corner,
                      "units payload: " + std::to_string(t.units.size()) + " units, the store has " +
                          std::to_string(own));
        }
    }

    /// Chain c of a node's result: its points in the node's box, a chain of
    /// the original stores, check 1 (a subsequence with the same ends),
    /// check 2 (every skipped vertex within eps, exactly, and the reverse
    /// direction), check 4 (a ring keeps 3 vertices and its orientation).
    /// `worst` gets the largest L2 deviation, grid units.
    void check_chain(NodeResult& r, size_t c, uint32_t n, uint32_t k,
                     const std::unordered_map<uint64_t, Original>& owned,
                     const std::map<const chains::ChainStore*, std::vector<double>>& eps, const Emit& violation,
                     double& worst) const
    {
        const auto& node = m_sk.nodes[n];
        const auto& e = r.table.chains[c];
        const auto pts = r.geometry.chain(c);
        for (const auto& p : pts) {
            if (p.x < node.box.min_x || p.x > node.box.max_x || p.y < node.box.min_y || p.y > node.box.max_y) {
                violation("skeleton", {e.id}, p, "point outside the node's bounding box");
                break;
            }
        }
        const auto it = owned.find(e.id);
        if (it == owned.end()) {
            violation("skeleton", {e.id}, pts.front(), "chain not in the original stores of its level");
            return;
        }
        const Original& o = it->second;
        const auto orig = o.store->chain_points(*o.info);
        // Check 1: a subsequence with the same ends.
        std::vector<size_t> at; // position in orig of each simplified point
        const bool subsequence = match_subsequence(orig, pts, at);
        if (!subsequence) {
            violation("not_subsequence", {e.id}, pts.front(),
                      "not a subsequence of its original (" + std::to_string(orig.size()) +
                          " points) with the same ends");
            return;
        }
        // Check 2: every skipped vertex within eps (exact), and the reverse direction.
        const Tolerance tol(k == 0 ? 0.0 : eps.at(o.store)[o.index], m_metric);
        bool exceeded = false;
        for (size_t i = 0; i + 1 < pts.size() && !exceeded; ++i) {
            for (size_t m = at[i] + 1; m < at[i + 1]; ++m) {
                worst = std::max(worst, point_segment_distance(orig[m], pts[i], pts[i + 1]));
                if (!within(orig[m], pts[i], pts[i + 1], tol)) {
                    violation("eps_exceeded", {e.id}, orig[m],
                              "original vertex " + std::to_string(m) + " farther than eps " +
                                  std::to_string(tol.eps * m_sk.grid_m()) + " m (grid units " +
                                  std::to_string(tol.eps) + ")");
                    exceeded = true;
                    break;
                }
            }
            if (!exceeded && m_metric != Metric::l2 && at[i + 1] > at[i] + 1) {
                exceeded = reverse_exceeded(orig.subspan(at[i], at[i + 1] - at[i] + 1), pts[i], pts[i + 1], tol);
                if (exceeded) {
                    violation("eps_exceeded", {e.id}, pts[i],
                              "segment " + std::to_string(i) + " strays farther than eps from its original");
                }
            }
        }
        if (k > 0 && m_options.ground) {
            // Measured even where the planar check failed (the report's
            // largest ratio is then the ground's), reported only where it did not.
            const auto g0 = std::chrono::steady_clock::now();
            check_ground(r, e.id, o, orig, pts, at, k, exceeded ? nullptr : &violation);
            r.ground_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - g0).count();
        }
        // Check 4: rings keep 3 vertices and their orientation.
        if (e.flags & chains::chain_closed) {
            std::set<GridPoint> distinct(pts.begin(), pts.end());
            if (pts.size() < 4 || pts.front() != pts.back() || distinct.size() < 3) {
                violation("ring_collapsed", {e.id}, pts.front(),
                          "closed ring with " + std::to_string(distinct.size()) + " distinct vertices");
            } else if (sign(twice_area(pts)) != sign(twice_area(orig))) {
                violation("ring_orientation", {e.id}, pts.front(), "orientation differs from the original's");
            }
        }
    }

    /// Check 2 on the ellipsoid, independent of simplify's model: every
    /// skipped vertex within its ground eps (eps_m times its class's scale;
    /// times sqrt(2) for Linf, whose unit ball reaches that far) of the
    /// image on the ellipsoid of the segment that replaced it. Fast path,
    /// proven: a planar distance d within the segment's box (the segment and
    /// the vertices it skips) is at most d / s ground metres, s the least
    /// scale over that box (Projection::smallest_scale). Where that bound
    /// is within 1e-6 of eps, or over it, the geodesic distance itself
    /// (ground_distance_m). One violation per chain, at its farthest vertex,
    /// unless `violation` is null (the planar check reported the chain).
    /// A vertex whose bound over the whole chain's box is within the chain's
    /// largest ratio so far cannot raise it and is not measured further: the
    /// same largest ratio and vertex, at a fraction of the projections (at
    /// 100 M vertices the check had taken 40-45 % of verify).
    void check_ground(NodeResult& r, uint64_t id, const Original& o, std::span<const GridPoint> orig,
                      std::span<const GridPoint> pts, const std::vector<size_t>& at, uint32_t k,
                      const Emit* violation) const
    {
        double eps_m = m_sk.lod_eps_m[k];
        if (!m_opt.class_scale.empty()) {
            const auto it = m_opt.class_scale.find(o.store->strings[o.info->feature_class]);
            eps_m *= it == m_opt.class_scale.end() ? 1.0 : it->second;
        }
        if (m_metric == Metric::linf) {
            eps_m *= std::sqrt(2.0);
        }
        double worst = 0; // the chain's largest ratio, and its vertex
        size_t worst_at = 0;
        // The least scale over the whole chain's box is at most any of its
        // segments': d over its reach bounds every vertex's ratio from above,
        // so a segment whose vertices are all within the chain's worst so far
        // by that bound cannot change it, and its own box (seven projections)
        // is not needed. The result is the same as measuring every segment.
        const double chain_reach = o.scale * eps_m / m_sk.grid_m(); // grid units
        std::vector<double> d;
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            if (at[i + 1] <= at[i] + 1) {
                continue; // an original edge: nothing skipped
            }
            d.clear();
            bool may_beat = false;
            for (size_t m = at[i] + 1; m < at[i + 1]; ++m) {
                d.push_back(point_segment_distance(orig[m], pts[i], pts[i + 1]));
                may_beat = may_beat || (d.back() > 0 && !(chain_reach > 0 && d.back() / chain_reach <= worst));
            }
            if (!may_beat) {
                continue;
            }
            GridBox box;
            box.extend(pts[i]);
            box.extend(pts[i + 1]);
            for (size_t m = at[i] + 1; m < at[i + 1]; ++m) {
                box.extend(orig[m]);
            }
            const double reach = m_proj.smallest_scale(box) * eps_m / m_sk.grid_m(); // grid units
            for (size_t m = at[i] + 1; m < at[i + 1]; ++m) {
                const double dm = d[m - at[i] - 1];
                if (dm > 0 && chain_reach > 0 && dm / chain_reach <= worst) {
                    continue; // bounded by the chain's reach within the worst so far
                }
                double ratio = dm == 0 ? 0.0 : reach > 0 ? dm / reach : INFINITY;
                if (ratio > 1 - 1e-6) {
                    ratio = ground_distance_m(orig[m], pts[i], pts[i + 1]) / eps_m;
                    ++r.ground_geodesics;
                }
                if (ratio > worst) {
                    worst = ratio;
                    worst_at = m;
                }
            }
        }
        r.ground_ratio = std::max(r.ground_ratio, worst);
        if (worst > 1 && violation) {
            char detail[256];
            std::snprintf(detail, sizeof detail,
                          "on the ground: original vertex %zu is %.3f m from its shortcut on the ellipsoid, "
                          "%.6f times its eps of %.3f m (the chain's farthest)",
                          worst_at, worst * eps_m, worst, eps_m);
            (*violation)("eps_exceeded", {id}, orig[worst_at], detail);
        }
    }

    /// The geodesic distance in metres from grid point v to the image on
    /// the ellipsoid of the grid segment ab: the least geodesic distance
    /// from v to a + t (b - a), t in [0, 1], found by sampling t at 64 steps
    /// and the planar foot, then golden-section search around the best. The
    /// function is unimodal wherever the projection is nearly affine over
    /// the segment (the ground image of a short planar segment is nearly
    /// straight); every value is a distance that is reached, so the result
    /// never falls below the true least distance by more than the
    /// search's resolution (about 1e-12 of the segment).
    double ground_distance_m(GridPoint v, GridPoint a, GridPoint b) const
    {
        double vlon = 0, vlat = 0;
        m_proj.to_lonlat(v.x, v.y, vlon, vlat);
        const double dx = double(b.x) - a.x, dy = double(b.y) - a.y;
        auto g = [&](double t) {
            double lon = 0, lat = 0;
            m_proj.to_lonlat(a.x + t * dx, a.y + t * dy, lon, lat);
            return m_proj.geodesic_m(vlon, vlat, lon, lat);
        };
        constexpr int steps = 64;
        double best = INFINITY, best_t = 0;
        auto take = [&](double t) {
            const double d = g(t);
            if (d < best) {
                best = d;
                best_t = t;
            }
        };
        for (int j = 0; j <= steps; ++j) {
            take(double(j) / steps);
        }
        const double len2 = dx * dx + dy * dy;
        if (len2 > 0) {
            take(std::clamp(((double(v.x) - a.x) * dx + (double(v.y) - a.y) * dy) / len2, 0.0, 1.0));
        }
        double lo = std::max(0.0, best_t - 1.0 / steps), hi = std::min(1.0, best_t + 1.0 / steps);
        constexpr double phi = 0.6180339887498949;
        double t1 = hi - phi * (hi - lo), t2 = lo + phi * (hi - lo);
        double g1 = g(t1), g2 = g(t2);
        for (int it = 0; it < 60 && hi - lo > 1e-13; ++it) {
            if (g1 < g2) {
                hi = t2;
                t2 = t1;
                g2 = g1;
                t1 = hi - phi * (hi - lo);
                g1 = g(t1);
            } else {
                lo = t1;
                t1 = t2;
                g1 = g2;
                t2 = lo + phi * (hi - lo);
                g2 = g(t2);
            }
        }
        return std::min({best, g1, g2});
    }

    /// Checks 5 and 6: every unit's boundary closes, with its original area sign.
    void check_units(const NodeResult& r, const chains::ChainStore& store, const std::map<std::string, int>& area_sign,
                     const Emit& violation) const
    {
        for (uint32_t u : units_in_table(r.table, store)) {
            const auto rings = view::unit_rings(r.table, r.geometry, u);
            bool closed = !rings.empty();
            for (const auto& ring : rings) {
                if (!ring.closed) {
                    closed = false;
                    violation("invalid_polygons", {}, ring.points.back(),
                              "unit " + r.table.strings[u] + ": boundary does not close");
                    break;
                }
            }
            if (closed) {
                const auto want = area_sign.find(r.table.strings[u]);
                const int now = unit_area_sign(r, u);
                if (want != area_sign.end() && now != want->second) {
                    violation("invalid_polygons", {}, rings.front().points.front(),
                              "unit " + r.table.strings[u] + ": area sign " + std::to_string(now) + ", originally " +
                                  std::to_string(want->second));
                }
            }
        }
    }

    /// The points: every internal point strictly inside its own unit (a
    /// neighbour's unit is checked in the node of the partition that owns
    /// it), and inside no other unit of the node: a hole or an island that
    /// a shortcut passed to the other side of a chain leaves the points of
    /// the units in it inside the unit around them too, though each stays in
    /// its own. Every user point in the unit it was in.
    void check_points(NodeResult& r, const chains::ChainStore& store, const std::vector<UserPoint>& user_points,
                      const Emit& violation) const
    {
        const UnitLocator locator(r.table, r.geometry);
        std::vector<uint8_t> own(r.table.strings.size(), 0);
        for (const uint32_t u : units_in_table(r.table, store)) {
            own[u] = 1;
        }
        std::vector<uint32_t> inside, boundary;
        for (const auto& cp : store.constraints) {
            const std::string& unit = store.strings[cp.unit];
            const auto ui = std::find(r.table.strings.begin(), r.table.strings.end(), unit);
            const uint32_t u = static_cast<uint32_t>(ui - r.table.strings.begin());
            locator.locate(cp.p, inside, boundary);
            const std::string what = std::string(chains::constraint_kind_name(cp.kind)) + " point of " + unit;
            if (cp.kind != chains::constraint_neighbour) {
                ++r.points;
                if (ui == r.table.strings.end() || !std::binary_search(inside.begin(), inside.end(), u)) {
                    violation("point_constraints", {}, cp.p, what + " not inside it");
                    continue; // one violation per point
                }
            }
            for (const uint32_t other : inside) {
                if (other != u && own[other]) {
                    violation("point_constraints", {}, cp.p,
                              what + " inside unit " + r.table.strings[other] + ", which must not overlap it");
                    break;
                }
            }
        }
        for (const auto& up : user_points) {
            ++r.points;
            const auto ui = std::find(r.table.strings.begin(), r.table.strings.end(), up.unit);
            locator.locate(up.p, inside, boundary);
            if (ui == r.table.strings.end() ||
                !std::binary_search(inside.begin(), inside.end(),
                                    static_cast<uint32_t>(ui - r.table.strings.begin()))) {
                violation("point_constraints", {}, up.p,
                          "user point " + std::to_string(up.index) + " left unit " + up.unit);
            }
        }
    }

    /// The reverse direction for L1 and Linf (for L2 it follows from the
    /// forward one): points of the segment, at every original vertex's
    /// projection and half-way between, within eps of the original subchain.
    /// In double precision; an excess below 1e-9 of eps is not reported.
    bool reverse_exceeded(std::span<const GridPoint> sub, GridPoint a, GridPoint b, const Tolerance& tol) const
    {
        const double dx = double(b.x) - a.x, dy = double(b.y) - a.y, len2 = dx * dx + dy * dy;
        std::vector<double> ts{0.0, 1.0};
        for (const auto& p : sub) {
            ts.push_back(len2 > 0 ? std::clamp(((p.x - a.x) * dx + (p.y - a.y) * dy) / len2, 0.0, 1.0) : 0.0);
        }
        std::sort(ts.begin(), ts.end());
        const size_t n = ts.size();
        for (size_t i = 0; i + 1 < n; ++i) {
            ts.push_back(0.5 * (ts[i] + ts[i + 1]));
        }
        for (double t : ts) {
            const double qx = a.x + t * dx, qy = a.y + t * dy;
            double best = INFINITY;
            for (size_t s = 0; s + 1 < sub.size(); ++s) {
                best = std::min(best, point_segment(qx, qy, sub[s], sub[s + 1]));
            }
            if (best > tol.eps * (1 + 1e-9)) {
                return true;
            }
        }
        return false;
    }

    /// Distance in the metric from (qx, qy) to segment ab, double, by ternary search on the convex function.
    double point_segment(double qx, double qy, GridPoint a, GridPoint b) const
    {
        auto d = [&](double t) {
            const double px = a.x + t * (double(b.x) - a.x) - qx, py = a.y + t * (double(b.y) - a.y) - qy;
            return m_metric == Metric::l1 ? std::abs(px) + std::abs(py) : std::max(std::abs(px), std::abs(py));
        };
        double lo = 0, hi = 1;
        for (int i = 0; i < 60; ++i) {
            const double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
            if (d(m1) < d(m2)) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        return std::min({d(0), d(1), d(0.5 * (lo + hi))});
    }

    const reader::Tree& m_tree;
    const datatree::Skeleton& m_sk;
    fs::path m_original;
    const Options& m_options;
    const Selection* m_selection; ///< nullptr: every node
    simplify::SimplifyOptions m_opt;
    Projection m_proj;
    Metric m_metric;
    Report m_report;
};

} // namespace

Report verify_tree(const reader::Tree& tree, const fs::path& original, const Options& options,
                   const Selection* selection)
{
    Verifier v(tree, original, options, selection);
    return v.run();
}

Report merge_reports(std::vector<Report>&& shares, const std::vector<std::string>& levels, size_t max_items)
{
    Report out;
    std::map<std::pair<size_t, uint32_t>, LevelLod> by; // (level index, LOD)
    for (auto& r : shares) {
        out.nodes = r.nodes;
        out.lods = r.lods;
        out.chains += r.chains;
        out.segments += r.segments;
        out.points += r.points;
        out.input_problems += r.input_problems;
        out.items_dropped += r.items_dropped;
        out.seconds += r.seconds;
        out.ground = r.ground;
        out.ground_ratio_max = std::max(out.ground_ratio_max, r.ground_ratio_max);
        out.ground_geodesics += r.ground_geodesics;
        out.ground_seconds += r.ground_seconds;
        for (const auto& [k, v] : r.violations) {
            out.violations[k] += v;
        }
        for (auto& ll : r.by_level_lod) {
            const auto li = size_t(std::find(levels.begin(), levels.end(), ll.level) - levels.begin());
            auto [it, fresh] = by.try_emplace({li, ll.lod}, ll);
            if (!fresh) {
                auto& m = it->second;
                m.nodes += ll.nodes;
                m.chains += ll.chains;
                m.segments += ll.segments;
                m.vertices += ll.vertices;
                m.points += ll.points;
                m.input_problems += ll.input_problems;
                m.ground_ratio_max = std::max(m.ground_ratio_max, ll.ground_ratio_max);
                m.ground_geodesics += ll.ground_geodesics;
                for (const auto& [k, v] : ll.violations) {
                    m.violations[k] += v;
                }
            }
        }
        std::move(r.items.begin(), r.items.end(), std::back_inserter(out.items));
        std::vector<Violation>().swap(r.items);
    }
    for (const char* k : kinds) {
        out.violations[k] += 0;
    }
    for (auto& [key, ll] : by) {
        out.by_level_lod.push_back(std::move(ll));
    }
    keep_first_items(out, max_items);
    return out;
}

} // namespace tigerlod::verify
