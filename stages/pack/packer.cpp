#include "stages/pack/packer.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"
#include "core/parallel.hpp"
#include "formats/chains/chain_store.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <fstream>
#include <set>
#include <unordered_map>

namespace fs = std::filesystem;

namespace tigerlod::pack {

namespace {

/// The chain store files of one folder (ORIGINAL or one eps-<E>m), by level folder and file name.
std::vector<fs::path> store_files(const fs::path& dir)
{
    std::vector<fs::path> out;
    if (!fs::is_directory(dir)) {
        throw input_error(dir.string() + ": not a folder of chain stores");
    }
    for (const auto& level : fs::directory_iterator(dir)) {
        if (!level.is_directory() || level.path().filename().string().starts_with("eps-")) {
            continue;
        }
        for (const auto& f : fs::directory_iterator(level.path())) {
            if (f.path().extension() == ".tlc") {
                out.push_back(fs::relative(f.path(), dir));
            }
        }
    }
    std::sort(out.begin(), out.end());
    return out;
}

/// Largest distance of an original vertex from the simplified chain, which must be a
/// subsequence with the same endpoints; -1 if it is not.
double deviation(std::span<const GridPoint> orig, std::span<const GridPoint> simp)
{
    std::vector<size_t> at;
    if (!match_subsequence(orig, simp, at)) {
        return -1.0;
    }
    double worst = 0.0;
    for (size_t i = 0; i + 1 < simp.size(); ++i) {
        for (size_t m = at[i] + 1; m < at[i + 1]; ++m) {
            worst = std::max(worst, point_segment_distance(orig[m], simp[i], simp[i + 1]));
        }
    }
    return worst;
}

struct NodeBuild {
    uint32_t level = 0;
    std::string partition;
    std::vector<std::string> units; ///< the partition's units at this level (sorted)
    std::vector<uint64_t> ids;      ///< its chains, sorted
    datatree::Geometry original;
    std::string table;
    std::vector<std::string> lod_payloads;
    double last_error = 0.0;
    bool tiles = false; ///< the root of a line layer cut into tiles: no chains, no store
};

/// Where each owned chain of a level lies, by id.
using ChainIndex = std::unordered_map<uint64_t, std::pair<const chains::ChainStore*, const chains::ChainInfo*>>;

ChainIndex index_owned(const std::vector<chains::ChainStore>& stores, const std::vector<fs::path>& paths)
{
    ChainIndex index;
    for (size_t s = 0; s < stores.size(); ++s) {
        for (const auto& c : stores[s].chains) {
            if ((c.flags & chains::chain_halo) == 0 && !index.try_emplace(c.id, &stores[s], &c).second) {
                throw input_error(paths[s].string() + ": chain " + std::to_string(c.id) +
                                  " is owned by two partitions of its level");
            }
        }
    }
    return index;
}

std::vector<chains::ChainStore> read_all(const std::vector<fs::path>& paths, unsigned threads)
{
    std::vector<chains::ChainStore> out(paths.size());
    parallel_each(paths.size(), threads, [&](size_t i) { out[i] = chains::read(paths[i]); });
    return out;
}

} // namespace

namespace {

/// build_tree step by step: the LODs (ORIGINAL and each eps folder), the
/// levels, the partitions and their units (pass 1), the hierarchy of nodes
/// from them, then every node's table and payload at each level and LOD
/// (pass 2), laid out in tiles.
class TreeBuilder {
  public:
    TreeBuilder(const fs::path& original, const fs::path& simplified, const PackOptions& options)
        : m_original(original), m_simplified(simplified), m_options(options), m_rel(store_files(original))
    {
        if (m_rel.empty()) {
            throw input_error(original.string() + ": no chain stores (<level>/<partition>.tlc)");
        }
    }

    PackedTree build()
    {
        find_lods();
        find_levels();
        build_hierarchy(read_partitions());
        name_nodes();
        index_units();
        m_tree.lods.resize(m_lod_eps.size());
        for (size_t k = 0; k < m_lod_eps.size(); ++k) {
            m_tree.lods[k].eps_m = m_lod_eps[k];
        }
        for (uint32_t l = 0; l < m_level_names.size(); ++l) {
            pack_level(l);
        }
        if (m_nodes.front().tiles) {
            auto& root = m_tree.skeleton.nodes.front();
            datatree::Box box{INT32_MAX, INT32_MAX, INT32_MIN, INT32_MIN};
            for (uint32_t c = root.first_child; c < root.first_child + root.child_count; ++c) {
                const auto& b = m_tree.skeleton.nodes[c].box;
                box = {std::min(box.min_x, b.min_x), std::min(box.min_y, b.min_y), std::max(box.max_x, b.max_x),
                       std::max(box.max_y, b.max_y)};
            }
            root.box = box;
        }
        std::vector<std::vector<std::string>> payloads(m_nodes.size());
        for (size_t i = 0; i < m_nodes.size(); ++i) {
            payloads[i].push_back(std::move(m_nodes[i].table));
            for (auto& p : m_nodes[i].lod_payloads) {
                payloads[i].push_back(std::move(p));
            }
        }
        layout_tiles(m_tree, std::move(payloads), m_options.tile_bytes);
        return std::move(m_tree);
    }

  private:
    /// The stores of level l, relative to ORIGINAL (none if it has no folder).
    const std::vector<fs::path>& files_of(uint32_t l) const
    {
        static const std::vector<fs::path> none;
        const auto it = m_level_files.find(l);
        return it == m_level_files.end() ? none : it->second;
    }

    /// LOD 0 from ORIGINAL, LOD k from the k-th smallest eps folder.
    void find_lods()
    {
        const fs::path& original = m_original;
        const fs::path& simplified = m_simplified;
        const auto& rel = m_rel;
        auto& lod_dirs = m_lod_dirs;
        auto& lod_eps = m_lod_eps;
        lod_dirs = {original};
        lod_eps = {0.0};
        std::vector<std::pair<double, fs::path>> eps_dirs;
        if (fs::is_directory(simplified)) {
            for (const auto& d : fs::directory_iterator(simplified)) {
                if (d.is_directory() && d.path().filename().string().starts_with("eps-")) {
                    const auto files = store_files(d.path());
                    if (files != rel) {
                        throw input_error(d.path().string() + ": its chain stores are not those of " +
                                          original.string() + " (" + std::to_string(files.size()) + " against " +
                                          std::to_string(rel.size()) + ")");
                    }
                    const auto first = chains::read(d.path() / rel.front());
                    eps_dirs.emplace_back(first.eps_m, d.path());
                }
            }
        } else {
            throw input_error(simplified.string() + ": not a tigerlod-simplify output folder");
        }
        if (eps_dirs.empty()) {
            throw input_error(simplified.string() + ": no eps-<E>m folders: not a tigerlod-simplify output folder");
        }
        std::sort(eps_dirs.begin(), eps_dirs.end());
        for (const auto& [eps, dir] : eps_dirs) {
            if (!(eps > lod_eps.back())) {
                throw input_error(dir.string() + ": tolerance " + std::to_string(eps) +
                                  " m is not above the previous one");
            }
            lod_eps.push_back(eps);
            lod_dirs.push_back(dir);
        }
    }

    /// The levels, from each level folder's first store; the projection too.
    void find_levels()
    {
        const fs::path& original = m_original;
        auto& sk = m_tree.skeleton;
        const auto& rel = m_rel;
        auto& level_names = m_level_names;
        auto& level_files = m_level_files;
        std::map<std::string, uint32_t> index_of_dir;
        for (const auto& r : rel) {
            const std::string dir = r.parent_path().string();
            if (!index_of_dir.contains(dir)) {
                const auto s = chains::read(original / r);
                index_of_dir[dir] = s.level_index;
                if (level_names.empty()) {
                    level_names.resize(s.level_count);
                    const auto& p = s.projection;
                    sk.projection_kind = static_cast<uint8_t>(p.kind);
                    sk.utm_north = p.utm_north ? 1 : 0;
                    sk.utm_zone = p.utm_zone;
                    const double v[10] = {p.lon0_deg,        p.lat0_deg,         p.stdlat1_deg, p.stdlat2_deg, p.k0,
                                          p.false_easting_m, p.false_northing_m, p.grid_m,      p.a_m,         p.f};
                    std::copy(std::begin(v), std::end(v), std::begin(sk.projection));
                }
                if (s.level_index >= level_names.size() || s.level_count != level_names.size()) {
                    throw input_error((original / r).string() + ": level " + std::to_string(s.level_index) + " of " +
                                      std::to_string(s.level_count) + " does not fit the other stores");
                }
                level_names[s.level_index] = s.level_name;
            }
            level_files[index_of_dir[dir]].push_back(r);
        }
        sk.level_names = level_names;
        sk.lod_eps_m = m_lod_eps;
    }

    /// Pass 1: each level's partitions and their units (partition -> units).
    std::vector<std::map<std::string, std::vector<std::string>>> read_partitions() const
    {
        const auto nlevels = static_cast<uint32_t>(m_level_names.size());
        std::vector<std::map<std::string, std::vector<std::string>>> units(nlevels);
        for (uint32_t l = 0; l < nlevels; ++l) {
            std::vector<fs::path> paths;
            for (const auto& r : files_of(l)) {
                paths.push_back(m_original / r);
            }
            // One store at a time per thread, keeping only its units: a
            // level's stores at once were the pack's peak on the 100 M nation
            // (the block level, 1.7 GB, before pack_level read them again).
            struct Read {
                std::string partition;
                std::vector<std::string> units;
                ProjectionParams projection;
                bool level_ok = false;
            };
            std::vector<Read> read(paths.size());
            parallel_each(paths.size(), m_options.threads, [&](size_t i) {
                const auto s = chains::read(paths[i]);
                std::set<std::string> u;
                for (const auto& c : s.constraints) {
                    if (c.kind == chains::constraint_internal) {
                        u.insert(s.strings[c.unit]);
                    }
                }
                read[i] = {s.partition, {u.begin(), u.end()}, s.projection, s.level_index == l};
            });
            for (size_t i = 0; i < read.size(); ++i) {
                if (!read[i].level_ok || read[i].projection != read.front().projection) {
                    throw input_error(paths[i].string() + ": level or projection differs from the other stores");
                }
                units[l][read[i].partition] = std::move(read[i].units);
            }
        }
        return units;
    }

    /// The nodes, breadth first from the top level's one partition: a
    /// partition of level l + 1 is a child of the node whose unit it is.
    void build_hierarchy(const std::vector<std::map<std::string, std::vector<std::string>>>& units)
    {
        const auto nlevels = static_cast<uint32_t>(m_level_names.size());
        const fs::path& original = m_original;
        const auto& level_names = m_level_names;
        auto& sk = m_tree.skeleton;
        auto& nodes = m_nodes;
        if (units[0].empty()) {
            throw input_error(original.string() + "/" + level_names[0] + ": no stores");
        }
        if (units[0].size() == 1) {
            nodes.push_back({0, units[0].begin()->first, units[0].begin()->second, {}, {}, {}, {}, 0.0});
        } else {
            // A top level of several partitions (a line layer cut into
            // tiles): the root holds no chains, its children are the tiles.
            if (nlevels != 1) {
                throw input_error(original.string() + "/" + level_names[0] + ": the top level of a map of " +
                                  std::to_string(nlevels) + " levels must have one partition, it has " +
                                  std::to_string(units[0].size()));
            }
            nodes.push_back({0, "", {}, {}, {}, {}, {}, 0.0});
            nodes.front().tiles = true;
        }
        sk.nodes.push_back({});
        for (size_t i = 0; i < nodes.size(); ++i) {
            const uint32_t l = nodes[i].level;
            auto& n = sk.nodes[i];
            n.level = l;
            n.first_child = static_cast<uint32_t>(nodes.size());
            if (nodes[i].tiles) {
                for (const auto& [tile, tile_units] : units[0]) {
                    nodes.push_back({0, tile, tile_units, {}, {}, {}, {}, 0.0});
                    datatree::Node child;
                    child.parent = static_cast<uint32_t>(i);
                    sk.nodes.push_back(child);
                    ++sk.nodes[i].child_count;
                }
            } else if (l + 1 < nlevels) {
                for (const auto& u : nodes[i].units) {
                    if (auto it = units[l + 1].find(u); it != units[l + 1].end()) {
                        nodes.push_back({l + 1, u, it->second, {}, {}, {}, {}, 0.0});
                        datatree::Node child;
                        child.parent = static_cast<uint32_t>(i);
                        sk.nodes.push_back(child);
                        ++sk.nodes[i].child_count;
                    }
                }
            }
            if (sk.nodes[i].child_count == 0) {
                sk.nodes[i].first_child = 0;
            }
        }
        {
            std::vector<size_t> per_level(nlevels);
            for (const auto& n : nodes) {
                per_level[n.level] += n.tiles ? 0 : 1;
            }
            for (uint32_t l = 0; l < nlevels; ++l) {
                if (per_level[l] != units[l].size()) {
                    throw input_error(original.string() + "/" + level_names[l] + ": " +
                                      std::to_string(units[l].size() - per_level[l]) +
                                      " partitions are not units of the level above");
                }
            }
        }
    }

    /// The node whose map has each unit as its own, per level.
    void index_units()
    {
        m_unit_node.assign(m_level_names.size(), {});
        for (uint32_t i = 0; i < m_nodes.size(); ++i) {
            for (const auto& u : m_nodes[i].units) {
                m_unit_node[m_nodes[i].level].emplace(u, i);
            }
        }
    }

    /// The border level of a chain of level l between units a and b: the
    /// coarsest level whose map has a border along it (0 for the map's outer
    /// edge, or a chain with no unit on a side; l between two units of one
    /// node). Nodes of level l are l steps below the root, so a unit's
    /// ancestor node at each coarser level is found by walking up.
    uint32_t border_level(uint32_t l, const std::string& a, const std::string& b) const
    {
        if (a.empty() || b.empty()) {
            return 0;
        }
        const auto ia = m_unit_node[l].find(a), ib = m_unit_node[l].find(b);
        if (ia == m_unit_node[l].end() || ib == m_unit_node[l].end()) {
            return l;
        }
        const auto& nodes = m_tree.skeleton.nodes;
        uint32_t na = ia->second, nb = ib->second, level = l;
        while (na != nb && level > 0 && nodes[na].parent != datatree::no_node &&
               nodes[nb].parent != datatree::no_node) {
            na = nodes[na].parent;
            nb = nodes[nb].parent;
            --level;
        }
        return na == nb ? level : 0;
    }

    /// Each node's code in the skeleton's strings (the root's is empty).
    void name_nodes()
    {
        auto& sk = m_tree.skeleton;
        const auto& nodes = m_nodes;
        std::unordered_map<std::string, uint32_t> string_index;
        for (size_t i = 0; i < nodes.size(); ++i) {
            const std::string code = i == 0 ? std::string() : nodes[i].partition;
            auto [it, fresh] = string_index.try_emplace(code, 0);
            if (fresh) {
                if (!code.empty()) {
                    it->second = static_cast<uint32_t>(sk.strings.size());
                    sk.strings.push_back(code);
                }
            }
            sk.nodes[i].code = it->second;
        }
    }

    /// Pass 2 for level l: at each LOD, every node's geometry, error and payload.
    void pack_level(uint32_t l)
    {
        std::vector<size_t> at_level;
        for (size_t i = 0; i < m_nodes.size(); ++i) {
            if (m_nodes[i].level == l) {
                at_level.push_back(i);
            }
        }
        auto& sk = m_tree.skeleton;
        pack_originals(l, at_level);
        for (size_t k = 1; k < m_lod_eps.size(); ++k) {
            std::vector<fs::path> paths;
            for (const auto& r : files_of(l)) {
                paths.push_back(m_lod_dirs[k] / r);
            }
            const auto stores = read_all(paths, m_options.threads);
            std::map<std::string, size_t> store_of;
            for (size_t s = 0; s < stores.size(); ++s) {
                store_of[stores[s].partition] = s;
                if (stores[s].eps_m != m_lod_eps[k] || stores[s].metric != stores.front().metric) {
                    throw input_error(paths[s].string() + ": tolerance or metric differs from its folder's");
                }
            }
            if (k == 1) {
                sk.metric = stores.front().metric;
            }
            const ChainIndex owned = index_owned(stores, paths);
            parallel_each(at_level.size(), m_options.threads, [&](size_t a) {
                if (m_nodes[at_level[a]].tiles) {
                    pack_tiles_root(m_nodes[at_level[a]], sk.nodes[at_level[a]], k);
                    return;
                }
                const auto sit = store_of.find(m_nodes[at_level[a]].partition);
                if (sit == store_of.end()) {
                    throw input_error(paths.front().parent_path().string() + ": no store for partition " +
                                      m_nodes[at_level[a]].partition);
                }
                pack_node(m_nodes[at_level[a]], sk.nodes[at_level[a]], stores, sit->second, paths, owned, k);
            });
            add_lod_totals(at_level, k);
        }
        for (size_t i : at_level) {
            m_nodes[i].original = {};
            m_tree.table_bytes += m_nodes[i].table.size();
        }
    }

    void add_lod_totals(const std::vector<size_t>& at_level, size_t k)
    {
        const auto& sk = m_tree.skeleton;
        for (size_t i : at_level) {
            m_tree.lods[k].vertices += sk.nodes[i].lods[k].vertices;
            m_tree.lods[k].payload_bytes += m_nodes[i].lod_payloads[k].size();
            m_tree.lods[k].raw_bytes += sk.nodes[i].lods[k].vertices * sizeof(GridPoint);
        }
    }

    /// LOD 0 of level l, node by node from its own store alone (each a
    /// thread's at a time): a store's halo holds the borders of its units
    /// that neighbours own, as whole chains with their owner's points, so
    /// no other store is needed. A level's stores at once were the pack's
    /// peak on the 100 M nation (the block level's, with their halos).
    void pack_originals(uint32_t l, const std::vector<size_t>& at_level)
    {
        auto& sk = m_tree.skeleton;
        std::map<std::string, fs::path> path_of;
        for (const auto& r : files_of(l)) {
            path_of[r.stem().string()] = m_lod_dirs[0] / r;
        }
        parallel_each(at_level.size(), m_options.threads, [&](size_t a) {
            NodeBuild& nb = m_nodes[at_level[a]];
            if (nb.tiles) {
                pack_tiles_root(nb, sk.nodes[at_level[a]], 0);
                return;
            }
            const auto it = path_of.find(nb.partition);
            if (it == path_of.end()) {
                throw input_error((m_lod_dirs[0] / m_level_names[l]).string() + ": no store for partition " +
                                  nb.partition);
            }
            const std::vector<fs::path> paths{it->second};
            std::vector<chains::ChainStore> one(1);
            one[0] = chains::read(it->second);
            if (one[0].partition != nb.partition) {
                throw input_error(it->second.string() + ": holds partition " + one[0].partition +
                                  ", not the one its name says");
            }
            ChainIndex chains_of; // owned and halo: at LOD 0 a halo chain is its owner's, point for point
            for (const auto& c : one[0].chains) {
                chains_of.try_emplace(c.id, &one[0], &c);
            }
            pack_node(nb, sk.nodes[at_level[a]], one, 0, paths, chains_of, 0);
        });
        add_lod_totals(at_level, 0);
    }

    /// The root of a line layer cut into tiles at LOD k: no chains; its box
    /// (every tile's, set once the tiles are packed) and errors (0) follow.
    void pack_tiles_root(NodeBuild& nb, datatree::Node& node, size_t k) const
    {
        if (k == 0) {
            node.chains = 0;
            nb.table = datatree::encode_table({});
            node.lods.resize(m_lod_eps.size());
        }
        node.lods[k] = {};
        nb.lod_payloads.push_back(datatree::encode_geometry({}, {0, 0}, {m_options.draco_speed}));
    }

    /// One node at LOD k from its partition's store (stores[store_index]):
    /// at LOD 0 its chains (the ones it owns and the borders of its units
    /// that neighbours own), its table and box; at every LOD its geometry,
    /// its error (never below the LOD before) and its payload.
    void pack_node(NodeBuild& nb, datatree::Node& node, const std::vector<chains::ChainStore>& stores,
                   size_t store_index, const std::vector<fs::path>& paths, const ChainIndex& owned, size_t k) const
    {
        const auto& sk = m_tree.skeleton;
        const size_t nlods = m_lod_eps.size();
        const auto& store = stores[store_index];
        if (k == 0) {
            // The node's map: the chains it owns, and the borders of its units owned by neighbours.
            const std::set<std::string> mine(nb.units.begin(), nb.units.end());
            for (const auto& c : store.chains) {
                if ((c.flags & chains::chain_halo) == 0 || mine.contains(store.strings[c.left]) ||
                    mine.contains(store.strings[c.right])) {
                    nb.ids.push_back(c.id);
                }
            }
            std::sort(nb.ids.begin(), nb.ids.end());
            node.chains = static_cast<uint32_t>(nb.ids.size());
        }
        datatree::Geometry g;
        g.offsets.reserve(nb.ids.size() + 1);
        datatree::ChainTable table;
        std::map<std::string, uint32_t> table_strings{{"", 0}};
        auto table_string = [&](const std::string& s) {
            auto [it, fresh] = table_strings.try_emplace(s, static_cast<uint32_t>(table.strings.size()));
            if (fresh) {
                table.strings.push_back(s);
            }
            return it->second;
        };
        double error = 0.0;
        for (size_t ci = 0; ci < nb.ids.size(); ++ci) {
            const auto it = owned.find(nb.ids[ci]);
            if (it == owned.end()) {
                throw input_error(paths[store_index].string() + ": chain " + std::to_string(nb.ids[ci]) +
                                  " is in no store of its level at this tolerance");
            }
            const auto& [os, oc] = it->second;
            const auto pts = os->chain_points(*oc);
            if (k == 0) {
                const std::string& left = os->strings[oc->left];
                const std::string& right = os->strings[oc->right];
                table.chains.push_back({oc->id, table_string(left), table_string(right),
                                        table_string(os->strings[oc->feature_class]),
                                        (oc->flags & ~uint32_t{chains::chain_halo}) |
                                            (border_level(nb.level, left, right) << datatree::border_level_shift)});
            } else {
                const double d = deviation(nb.original.chain(ci), pts);
                if (d < 0) {
                    throw input_error(paths[size_t(os - stores.data())].string() + ": chain " + std::to_string(oc->id) +
                                      " is not a subsequence of its original with the same endpoints");
                }
                error = std::max(error, d);
            }
            g.add_chain(pts);
        }
        if (k == 0) {
            datatree::Box box{INT32_MAX, INT32_MAX, INT32_MIN, INT32_MIN};
            for (const auto& p : g.points) {
                box = {std::min(box.min_x, p.x), std::min(box.min_y, p.y), std::max(box.max_x, p.x),
                       std::max(box.max_y, p.y)};
            }
            if (g.points.empty()) {
                box = {};
            }
            node.box = box;
            nb.table = datatree::encode_table(table);
            node.lods.resize(nlods);
        }
        const double error_m = std::max(nb.last_error, error * sk.grid_m());
        nb.last_error = error_m;
        node.lods[k].error_m = error_m;
        node.lods[k].vertices = g.points.size();
        nb.lod_payloads.push_back(
            datatree::encode_geometry(g, {node.box.min_x, node.box.min_y}, {m_options.draco_speed}));
        if (k == 0) {
            nb.original = std::move(g);
        }
    }

    const fs::path m_original, m_simplified;
    const PackOptions m_options;
    const std::vector<fs::path> m_rel; ///< the stores, relative to ORIGINAL and each eps folder
    std::vector<fs::path> m_lod_dirs;
    std::vector<double> m_lod_eps;
    std::map<uint32_t, std::vector<fs::path>> m_level_files;
    std::vector<std::string> m_level_names;
    std::vector<NodeBuild> m_nodes;
    std::vector<std::unordered_map<std::string, uint32_t>> m_unit_node; ///< per level: unit -> node (index_units)
    PackedTree m_tree;
}; // class TreeBuilder

} // namespace

PackedTree build_tree(const fs::path& original, const fs::path& simplified, const PackOptions& options)
{
    return TreeBuilder(original, simplified, options).build();
}

void layout_tiles(PackedTree& tree, std::vector<std::vector<std::string>>&& payloads, uint64_t tile_bytes)
{
    auto& sk = tree.skeleton;
    sk.tiles.clear();
    tree.tile_bytes.clear();
    // Tiles: a subtree that fits in tile_bytes is one tile; a node whose
    // subtree does not keeps its own payloads in a tile of its own and its
    // children are tiled the same way. Each decision depends on the node's own
    // subtree only, so a change in one region rewrites that region's tile and,
    // only if its size crosses the target, the tiling just above it.
    std::vector<uint64_t> subtree(sk.nodes.size());
    for (size_t i = sk.nodes.size(); i-- > 0;) {
        subtree[i] += payloads[i][0].size();
        for (size_t k = 1; k < payloads[i].size(); ++k) {
            subtree[i] += payloads[i][k].size();
        }
        if (i > 0) {
            subtree[sk.nodes[i].parent] += subtree[i];
        }
    }
    std::vector<uint32_t> groups; // the root of each tile's subtree
    std::vector<bool> lone;       // the tile holds that node's own payloads only
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
        const uint32_t n = stack.back();
        stack.pop_back();
        const auto& node = sk.nodes[n];
        const bool whole = subtree[n] <= tile_bytes || node.child_count == 0;
        groups.push_back(n);
        lone.push_back(!whole);
        if (!whole) {
            for (uint32_t c = node.first_child + node.child_count; c-- > node.first_child;) {
                stack.push_back(c);
            }
        }
    }
    for (size_t t = 0; t < groups.size(); ++t) {
        // The nodes of this tile in breadth-first (index) order.
        std::vector<uint32_t> members;
        if (lone[t]) {
            members = {groups[t]};
        } else {
            std::vector<uint32_t> todo{groups[t]};
            while (!todo.empty()) {
                const uint32_t n = todo.back();
                todo.pop_back();
                members.push_back(n);
                for (uint32_t c = sk.nodes[n].first_child; c < sk.nodes[n].first_child + sk.nodes[n].child_count; ++c) {
                    todo.push_back(c);
                }
            }
            std::sort(members.begin(), members.end());
        }
        std::string bytes = datatree::tile_header(0);
        const auto tile_index = static_cast<uint32_t>(sk.tiles.size());
        auto place = [&](std::string& payload) {
            datatree::PayloadRef ref{tile_index, bytes.size(), static_cast<uint32_t>(payload.size()),
                                     crc32(std::as_bytes(std::span(payload.data(), payload.size())))};
            bytes += payload;
            std::string().swap(payload); // in its tile now
            return ref;
        };
        for (uint32_t n : members) {
            sk.nodes[n].table = place(payloads[n][0]);
            for (size_t k = 0; k < sk.nodes[n].lods.size(); ++k) {
                sk.nodes[n].lods[k].payload = place(payloads[n][1 + k]);
            }
        }
        const std::string head = datatree::tile_header(bytes.size());
        std::copy(head.begin(), head.end(), bytes.begin());
        Sha256 sha;
        sha.update(std::as_bytes(std::span(bytes.data(), bytes.size())));
        const std::string code = groups[t] == 0 ? std::string("root") : sk.strings[sk.nodes[groups[t]].code];
        std::string safe;
        for (char ch : code) {
            safe += std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' ? ch : '_';
        }
        sk.tiles.push_back({"tiles/" + safe + "-" + sha.hex_digest().substr(0, 16) + ".tlt", bytes.size()});
        tree.tile_bytes.push_back(std::move(bytes));
    }
}

namespace {

/// Whether `path` holds exactly `bytes`: a tile is named by its content, so
/// a file of its name that differs (a flipped byte, a truncation) is damaged.
bool holds_exactly(const fs::path& path, std::string_view bytes)
{
    std::error_code ec;
    if (!fs::is_regular_file(path, ec) || fs::file_size(path, ec) != bytes.size() || ec) {
        return false;
    }
    std::ifstream in(path, std::ios::binary);
    std::string have(bytes.size(), '\0');
    in.read(have.data(), static_cast<std::streamsize>(have.size()));
    return in.gcount() == static_cast<std::streamsize>(have.size()) && have == bytes;
}

} // namespace

WriteStats write_tree(const fs::path& dir, const PackedTree& tree, std::string_view manifest)
{
    WriteStats st;
    std::error_code ec;
    fs::create_directories(dir / "tiles", ec);
    if (ec) {
        throw environment_error(dir.string() + ": cannot create: " + ec.message());
    }
    for (const fs::path& folder : {dir, dir / "tiles"}) {
        auto removed = remove_dead_leftovers(folder);
        st.leftovers_removed.insert(st.leftovers_removed.end(), removed.begin(), removed.end());
    }
    std::set<std::string> names;
    // Tiles this run wrote where there was no file: a failed run removes
    // them, leaving the folder as it found it.
    std::vector<fs::path> created;
    try {
        for (size_t t = 0; t < tree.skeleton.tiles.size(); ++t) {
            const auto& tile = tree.skeleton.tiles[t];
            names.insert(fs::path(tile.file).filename().string());
            const fs::path path = dir / tile.file;
            if (holds_exactly(path, tree.tile_bytes[t])) {
                ++st.tiles_kept;
            } else {
                const bool existed = fs::exists(path, ec);
                write_file_atomic(path, tree.tile_bytes[t]);
                if (existed) {
                    ++st.tiles_repaired;
                } else {
                    created.push_back(path);
                    ++st.tiles_written;
                }
            }
            st.tree_bytes += tile.size;
        }
        // The manifest before the skeleton, which is the commit point: a run
        // killed between them leaves the old skeleton beside the new
        // manifest, and verify refuses the pair until pack runs again (the
        // manifest then names another ingest or simplify output than the
        // skeleton was packed from only if the inputs changed).
        write_file_atomic(dir / "manifest.json", manifest);
        const std::string skeleton = datatree::encode_skeleton(tree.skeleton);
        write_file_atomic(dir / "skeleton.tls", skeleton);
        st.skeleton_bytes = skeleton.size();
        st.tree_bytes += skeleton.size();
    } catch (...) {
        for (const fs::path& p : created) {
            fs::remove(p, ec);
        }
        throw;
    }
    std::vector<fs::path> unnamed;
    for (const auto& f : fs::directory_iterator(dir / "tiles")) {
        if (f.path().extension() == ".tlt" && !names.contains(f.path().filename().string())) {
            unnamed.push_back(f.path());
        }
    }
    for (const fs::path& p : unnamed) {
        fs::remove(p, ec);
        ++st.tiles_removed;
    }
    return st;
}

bool is_pack_leftover(const fs::path& dir)
{
    // skeleton.tls is written last: without it, pack's own files are its
    // temporaries, its manifest, its report and tiles/ holding only tiles.
    auto temporary_of = [](const std::string& name, const std::string& of) { return name.rfind(of + ".tmp-", 0) == 0; };
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name == "tiles" && it->is_directory(ec)) {
            for (fs::directory_iterator t(it->path(), ec); !ec && t != end; t.increment(ec)) {
                const std::string tile = t->path().filename().string();
                if (!t->is_regular_file(ec) ||
                    !(t->path().extension() == ".tlt" || tile.find(".tlt.tmp-") != std::string::npos)) {
                    return false;
                }
            }
        } else if (!(name == "pack-report.json" || temporary_of(name, "pack-report.json") || name == "manifest.json" ||
                     temporary_of(name, "manifest.json") || temporary_of(name, "skeleton.tls"))) {
            return false;
        }
    }
    return !ec;
}

} // namespace tigerlod::pack
