#include "stages/pack/packer.hpp"

#include "core/bytes.hpp"
#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"
#include "core/metric.hpp"
#include "core/parallel.hpp"
#include "formats/chains/chain_store.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
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
                out.push_back(level.path().filename() / f.path().filename()); // not fs::relative: its stats
            }
        }
    }
    std::sort(out.begin(), out.end());
    return out;
}

/// What differs between a tolerance folder's stores and ORIGINAL's (both
/// sorted): the first store it lacks and the first it has beyond them, each
/// with how many more.
std::string store_difference(const std::vector<fs::path>& have, const std::vector<fs::path>& want)
{
    std::vector<fs::path> missing, extra;
    std::set_difference(want.begin(), want.end(), have.begin(), have.end(), std::back_inserter(missing));
    std::set_difference(have.begin(), have.end(), want.begin(), want.end(), std::back_inserter(extra));
    auto named = [](const std::vector<fs::path>& v) {
        return v.front().string() + (v.size() > 1 ? " and " + std::to_string(v.size() - 1) + " more" : "");
    };
    std::string text;
    if (!missing.empty()) {
        text = "it lacks " + named(missing);
    }
    if (!extra.empty()) {
        text += (text.empty() ? "it has " : ", and has ") + named(extra) + ", which ORIGINAL has not";
    }
    return text;
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

/// The file of a store at LOD k, relative to its root: ORIGINAL's
/// <level>/<partition>.tlc at LOD 0, else under SIMPLIFIED's eps folder.
struct Source {
    uint32_t lod = 0;
    std::string file; ///< relative to ORIGINAL (LOD 0) or SIMPLIFIED (eps-<E>m/...)
    friend auto operator<=>(const Source&, const Source&) = default;
};

/// The CRC-32 a chain store ends with (its trailer, over every byte before
/// it): a store's identity, read without the store.
uint32_t trailer_crc(const fs::path& path)
{
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    uint32_t crc = 0;
    if (!in || in.tellg() < 4 || !in.seekg(-4, std::ios::end) || !in.read(reinterpret_cast<char*>(&crc), 4)) {
        throw environment_error(path.string() + ": cannot read its checksum");
    }
    return crc;
}

/// One node while it is packed: from its partition's stores, its chains,
/// table (border levels not yet set), box, and each LOD's error, vertex
/// count and payload.
struct NodeBuild {
    uint32_t level = 0;
    std::string partition;
    std::vector<std::string> units; ///< the partition's own units at this level (sorted)
    std::vector<uint64_t> ids;      ///< its chains, sorted
    datatree::Geometry original;
    datatree::Node node;               ///< chains, box, lods (error_m, vertices); no links or refs yet
    std::string table;                 ///< encoded, border levels 0 (assemble sets them)
    std::string unit_table;            ///< the units payload (format 2.2), encoded
    std::vector<std::string> payloads; ///< geometry per LOD
    std::vector<Source> sources;       ///< the stores it was made from (write_parts records them)
    double last_error = 0.0;
};

/// A store's own units (those with a kind 0 point), each with its point and
/// the record ingest wrote for it (name and attributes), as a node's units
/// payload holds them.
datatree::UnitTable unit_table(const chains::ChainStore& s)
{
    datatree::UnitTable t;
    for (const auto& f : s.fields) {
        t.fields.push_back({f.name, static_cast<uint8_t>(f.type)});
    }
    std::unordered_map<uint32_t, const chains::UnitRecord*> record;
    for (const auto& u : s.units) {
        record.emplace(u.unit, &u);
    }
    for (const auto& c : s.constraints) {
        if (c.kind != chains::constraint_internal) {
            continue;
        }
        datatree::UnitTable::Unit u{s.strings[c.unit], {}, c.p, std::vector<std::string>(s.fields.size())};
        if (const auto it = record.find(c.unit); it != record.end()) {
            u.name = it->second->name;
            for (size_t k = 0; k < u.values.size() && k < it->second->values.size(); ++k) {
                u.values[k] = it->second->values[k];
            }
        }
        t.units.push_back(std::move(u));
    }
    std::sort(t.units.begin(), t.units.end(), [](const auto& a, const auto& b) { return a.code < b.code; });
    return t;
}

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

/// The units of a store's own partition: those with an internal point.
std::vector<std::string> own_units(const chains::ChainStore& s)
{
    std::set<std::string> u;
    for (const auto& c : s.constraints) {
        if (c.kind == chains::constraint_internal) {
            u.insert(s.strings[c.unit]);
        }
    }
    return {u.begin(), u.end()};
}

/// The chains a node shows: those its store owns, and the halo chains that
/// bound one of its own units (owned by a neighbour).
bool shows(const chains::ChainStore& s, const chains::ChainInfo& c, const std::set<std::string>& mine)
{
    return (c.flags & chains::chain_halo) == 0 || mine.contains(s.strings[c.left]) || mine.contains(s.strings[c.right]);
}

/// What a tree is packed at: its stores, levels, projection and LODs, from
/// ORIGINAL and SIMPLIFIED.
class TreeContext {
  public:
    /// `some`: for jobs on some stores, whose eps folders may lack the
    /// stores of jobs still to run (pack_level names a missing one it reads).
    TreeContext(const fs::path& original, const fs::path& simplified, const PackOptions& options, bool some = false)
        : m_original(original), m_simplified(simplified), m_options(options), m_rel(store_files(original)), m_some(some)
    {
        if (m_rel.empty()) {
            throw input_error(original.string() + ": no chain stores (<level>/<partition>.tlc)");
        }
        find_lods();
        find_levels();
    }

    const std::vector<fs::path>& stores() const noexcept { return m_rel; }
    const std::vector<double>& lod_eps() const noexcept { return m_lod_eps; }
    const std::vector<std::string>& level_names() const noexcept { return m_level_names; }
    /// The skeleton's header: projection, levels, LODs (metric set by pack_level).
    const datatree::Skeleton& header() const noexcept { return m_header; }
    const fs::path& original() const noexcept { return m_original; }
    const fs::path& lod_dir(size_t k) const { return m_lod_dirs[k]; }
    /// The file of store `rel` at LOD k, and its name relative to its root.
    fs::path lod_path(size_t k, const fs::path& rel) const { return m_lod_dirs[k] / rel; }
    Source source(size_t k, const fs::path& rel) const
    {
        return {static_cast<uint32_t>(k), (k == 0 ? rel : m_lod_dirs[k].filename() / rel).string()};
    }
    fs::path source_path(const Source& s) const { return (s.lod == 0 ? m_original : m_simplified) / s.file; }

    /// The stores of level l, relative to ORIGINAL (none if it has no folder).
    const std::vector<fs::path>& files_of(uint32_t l) const
    {
        static const std::vector<fs::path> none;
        const auto it = m_level_files.find(l);
        return it == m_level_files.end() ? none : it->second;
    }
    /// The level index of a level folder's name.
    uint32_t level_of(const std::string& name) const
    {
        const auto it = std::find(m_level_names.begin(), m_level_names.end(), name);
        if (it == m_level_names.end()) {
            throw input_error(m_original.string() + ": no level " + name);
        }
        return static_cast<uint32_t>(it - m_level_names.begin());
    }

    /// Pass 2 for `nodes` (all of level l, each its partition set): at LOD
    /// 0 from its own store, then at each LOD its geometry, error and
    /// payload, every chain taken from the store of `reads` (relative to
    /// ORIGINAL: the level's stores, or the nodes' own and their
    /// neighbours') that owns it. With `record`, each node's sources.
    void pack_level(uint32_t l, std::vector<NodeBuild>& nodes, const std::vector<fs::path>& reads, bool record)
    {
        pack_originals(l, nodes, record);
        for (size_t k = 1; k < m_lod_eps.size(); ++k) {
            std::vector<fs::path> paths;
            for (const auto& r : reads) {
                paths.push_back(m_lod_dirs[k] / r);
                if (m_some && !fs::exists(paths.back())) {
                    throw usage_error(paths.back().string() + " is missing: the simplify job of " +
                                      fs::path(r).replace_extension().string() + " has not run");
                }
            }
            const auto stores = read_all(paths, m_options.threads);
            std::map<std::string, size_t> store_of;
            for (size_t s = 0; s < stores.size(); ++s) {
                // As at LOD 0: a store holds the partition its name says (two
                // files swapped would pack the same tree, but would leave
                // simplify's next incremental run comparing the wrong stores).
                if (stores[s].partition != paths[s].stem().string()) {
                    throw input_error(paths[s].string() + ": holds partition " + stores[s].partition +
                                      ", not the one its name says; re-run tigerlod-simplify on this ingest output");
                }
                store_of[stores[s].partition] = s;
                // The folder's tolerance is its name's (find_lods), so a
                // store that differs is itself the odd one out.
                if (stores[s].eps_m != m_lod_eps[k]) {
                    throw input_error(misplaced(paths[s], stores[s].eps_m, m_lod_dirs[k]));
                }
                if (stores[s].metric != stores.front().metric) {
                    throw input_error(paths[s].string() + ": simplified in the metric " +
                                      metric_name(Metric(stores[s].metric)) + ", " + paths.front().string() + " in " +
                                      metric_name(Metric(stores.front().metric)) +
                                      "; re-run tigerlod-simplify on this ingest output");
                }
            }
            if (!stores.empty()) {
                m_metric = stores.front().metric;
            }
            const ChainIndex owned = index_owned(stores, paths);
            parallel_each(nodes.size(), m_options.threads, [&](size_t a) {
                const auto sit = store_of.find(nodes[a].partition);
                if (sit == store_of.end()) {
                    throw input_error(m_lod_dirs[k].string() + "/" + m_level_names[l] + ": no store for partition " +
                                      nodes[a].partition);
                }
                std::set<size_t> used;
                pack_node(nodes[a], stores, sit->second, paths, owned, k, used);
                if (record) {
                    for (const size_t s : used) {
                        nodes[a].sources.push_back(source(k, reads[s]));
                    }
                }
            });
        }
        for (auto& nb : nodes) {
            nb.original = {};
        }
    }

    uint8_t metric() const noexcept { return m_metric; }

  private:
    /// "DIR/F.tlc: simplified at 200m, not at the 50m its folder's name
    /// says (moved or copied from eps-200m?); ...".
    static std::string misplaced(const fs::path& file, double eps, const fs::path& folder)
    {
        return file.string() + ": simplified at " + chains::tolerance_dir(eps).substr(4) + ", not at the " +
               folder.filename().string().substr(4) + " its folder's name says (moved or copied from " +
               chains::tolerance_dir(eps) + "?); re-run tigerlod-simplify on this ingest output";
    }

    /// The tolerance of an eps folder: that of its stores, which must be the
    /// one its name says (tolerance_dir). Read from the first store whose
    /// tolerance the name says, so that a store moved in from another
    /// folder is named as the odd one, not an intact store beside it.
    static double folder_tolerance(const fs::path& dir, const std::vector<fs::path>& files)
    {
        const std::string name = dir.filename().string();
        const auto first = chains::read(dir / files.front());
        if (chains::tolerance_dir(first.eps_m) == name) {
            return first.eps_m;
        }
        for (size_t i = 1; i < files.size(); ++i) {
            if (chains::tolerance_dir(chains::read(dir / files[i]).eps_m) == name) {
                throw input_error(misplaced(dir / files.front(), first.eps_m, dir));
            }
        }
        throw input_error(dir.string() + ": its stores are simplified at " +
                          chains::tolerance_dir(first.eps_m).substr(4) +
                          ", not at what the folder's name says; not a folder tigerlod-simplify wrote");
    }

    /// LOD 0 from ORIGINAL, LOD k from the k-th smallest eps folder (of
    /// options.lods, if given).
    void find_lods()
    {
        m_lod_dirs = {m_original};
        m_lod_eps = {0.0};
        std::vector<std::pair<double, fs::path>> eps_dirs;
        if (!fs::is_directory(m_simplified)) {
            throw input_error(m_simplified.string() + ": not a tigerlod-simplify output folder");
        }
        for (const auto& d : fs::directory_iterator(m_simplified)) {
            if (d.is_directory() && d.path().filename().string().starts_with("eps-")) {
                const auto files = store_files(d.path());
                if (files.empty()) {
                    continue; // a tolerance of no store: an earlier ladder's folder that simplify --finish removes
                }
                const auto eps = folder_tolerance(d.path(), files);
                const auto& want = m_options.lods;
                if (!want.empty() && std::find(want.begin(), want.end(), eps) == want.end()) {
                    continue;
                }
                if (!m_some && files != m_rel) {
                    throw input_error(d.path().string() + ": its chain stores are not those of " + m_original.string() +
                                      " (" + std::to_string(files.size()) + " against " + std::to_string(m_rel.size()) +
                                      "): " + store_difference(files, m_rel) +
                                      "; re-run tigerlod-simplify on this ingest output");
                }
                eps_dirs.emplace_back(eps, d.path());
            }
        }
        if (eps_dirs.empty()) {
            throw input_error(m_simplified.string() + ": no eps-<E>m folders: not a tigerlod-simplify output folder");
        }
        std::sort(eps_dirs.begin(), eps_dirs.end());
        for (const auto& [eps, dir] : eps_dirs) {
            if (!(eps > m_lod_eps.back())) {
                throw input_error(dir.string() + ": tolerance " + std::to_string(eps) +
                                  " m is not above the previous one");
            }
            m_lod_eps.push_back(eps);
            m_lod_dirs.push_back(dir);
        }
        for (const double e : m_options.lods) {
            if (std::find(m_lod_eps.begin(), m_lod_eps.end(), e) == m_lod_eps.end()) {
                const std::string dir = chains::tolerance_dir(e); // "eps-4m"
                throw input_error(m_simplified.string() + ": no stores simplified at " + dir.substr(4, dir.size() - 5) +
                                  " m (no " + dir + " folder): run tigerlod-simplify first");
            }
        }
        m_header.lod_eps_m = m_lod_eps;
    }

    /// The levels, from each level folder's first store; the projection too.
    void find_levels()
    {
        auto& sk = m_header;
        std::map<std::string, uint32_t> index_of_dir;
        for (const auto& r : m_rel) {
            const std::string dir = r.parent_path().string();
            if (!index_of_dir.contains(dir)) {
                const auto s = chains::read(m_original / r);
                index_of_dir[dir] = s.level_index;
                if (m_level_names.empty()) {
                    m_level_names.resize(s.level_count);
                    const auto& p = s.projection;
                    sk.projection_kind = static_cast<uint8_t>(p.kind);
                    sk.utm_north = p.utm_north ? 1 : 0;
                    sk.utm_zone = p.utm_zone;
                    const double v[10] = {p.lon0_deg,        p.lat0_deg,         p.stdlat1_deg, p.stdlat2_deg, p.k0,
                                          p.false_easting_m, p.false_northing_m, p.grid_m,      p.a_m,         p.f};
                    std::copy(std::begin(v), std::end(v), std::begin(sk.projection));
                    m_projection = p;
                }
                if (s.level_index >= m_level_names.size() || s.level_count != m_level_names.size()) {
                    throw input_error((m_original / r).string() + ": level " + std::to_string(s.level_index) + " of " +
                                      std::to_string(s.level_count) + " does not fit the other stores");
                }
                if (!m_level_names[s.level_index].empty() && m_level_names[s.level_index] != s.level_name) {
                    throw input_error((m_original / r).string() + ": level " + std::to_string(s.level_index) + " is " +
                                      s.level_name + " here and " + m_level_names[s.level_index] +
                                      " in another folder");
                }
                m_level_names[s.level_index] = s.level_name;
            }
            m_level_files[index_of_dir[dir]].push_back(r);
        }
        sk.level_names = m_level_names;
    }

    /// LOD 0 of level l, node by node from its own store alone (each a
    /// thread's at a time): a store's halo holds the borders of its units
    /// that neighbours own, as whole chains with their owner's points, so
    /// no other store is needed. A level's stores at once were the pack's
    /// peak on the 100 M nation (the block level's, with their halos).
    void pack_originals(uint32_t l, std::vector<NodeBuild>& nodes, bool record)
    {
        parallel_each(nodes.size(), m_options.threads, [&](size_t a) {
            NodeBuild& nb = nodes[a];
            const fs::path rel = fs::path(m_level_names[l]) / (nb.partition + ".tlc");
            const fs::path path = m_lod_dirs[0] / rel;
            if (!fs::exists(path)) {
                throw input_error((m_lod_dirs[0] / m_level_names[l]).string() + ": no store for partition " +
                                  nb.partition);
            }
            const std::vector<fs::path> paths{path};
            std::vector<chains::ChainStore> one(1);
            one[0] = chains::read(path);
            if (one[0].partition != nb.partition) {
                throw input_error(path.string() + ": holds partition " + one[0].partition +
                                  ", not the one its name says");
            }
            if (one[0].level_index != l || one[0].projection != m_projection) {
                throw input_error(path.string() + ": level or projection differs from the other stores");
            }
            nb.units = own_units(one[0]);
            ChainIndex chains_of; // owned and halo: at LOD 0 a halo chain is its owner's, point for point
            for (const auto& c : one[0].chains) {
                chains_of.try_emplace(c.id, &one[0], &c);
            }
            std::set<size_t> used;
            pack_node(nb, one, 0, paths, chains_of, 0, used);
            nb.unit_table = datatree::encode_units(unit_table(one[0]), {nb.node.box.min_x, nb.node.box.min_y});
            if (record) {
                nb.sources.push_back(source(0, rel));
            }
        });
    }

    /// One node at LOD k from its partition's store (stores[store_index]):
    /// at LOD 0 its chains (the ones it owns and the borders of its units
    /// that neighbours own), its table and box; at every LOD its geometry,
    /// its error (never below the LOD before) and its payload. `used` gets
    /// the stores its chains were taken from.
    void pack_node(NodeBuild& nb, const std::vector<chains::ChainStore>& stores, size_t store_index,
                   const std::vector<fs::path>& paths, const ChainIndex& owned, size_t k, std::set<size_t>& used) const
    {
        datatree::Node& node = nb.node;
        const size_t nlods = m_lod_eps.size();
        const auto& store = stores[store_index];
        if (k == 0) {
            const std::set<std::string> mine(nb.units.begin(), nb.units.end());
            for (const auto& c : store.chains) {
                if (shows(store, c, mine)) {
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
            used.insert(size_t(os - stores.data()));
            const auto pts = os->chain_points(*oc);
            if (k == 0) {
                table.chains.push_back(
                    {oc->id, table_string(os->strings[oc->left]), table_string(os->strings[oc->right]),
                     table_string(os->strings[oc->feature_class]), oc->flags & ~uint32_t{chains::chain_halo}});
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
        const double error_m = std::max(nb.last_error, error * m_header.grid_m());
        nb.last_error = error_m;
        node.lods[k].error_m = error_m;
        node.lods[k].vertices = g.points.size();
        nb.payloads.push_back(datatree::encode_geometry(g, {node.box.min_x, node.box.min_y}, {m_options.draco_speed}));
        if (k == 0) {
            nb.original = std::move(g);
        }
    }

    const fs::path m_original, m_simplified;
    const PackOptions m_options;
    const std::vector<fs::path> m_rel; ///< the stores, relative to ORIGINAL and each eps folder
    const bool m_some;
    std::vector<fs::path> m_lod_dirs;
    std::vector<double> m_lod_eps;
    std::map<uint32_t, std::vector<fs::path>> m_level_files;
    std::vector<std::string> m_level_names;
    ProjectionParams m_projection;
    datatree::Skeleton m_header;
    uint8_t m_metric = 0;
}; // class TreeContext

/// A node as the assembly takes it: what pack_level made, its payloads in
/// memory or in a part file.
struct PartNode {
    uint32_t level = 0;
    std::string partition;
    std::vector<std::string> units;
    datatree::Node node;
    std::string table;           ///< encoded, border levels 0
    std::vector<uint64_t> sizes; ///< geometry payloads per LOD
    std::string unit_table;      ///< the units payload, encoded
};

/// The root of a line layer cut into tiles has no store: its place in `order`.
constexpr size_t no_part = SIZE_MAX;

/// assemble, step 1: the nodes, breadth first from the top level's one
/// partition (a partition of level l + 1 is a child of the node whose unit
/// it is), into `sk`; returns each node's part (no_part for a tiles root).
std::vector<size_t> build_hierarchy(const TreeContext& ctx, const std::vector<PartNode>& parts, datatree::Skeleton& sk)
{
    const auto& level_names = ctx.level_names();
    const auto nlevels = static_cast<uint32_t>(level_names.size());
    // Each level's parts by partition.
    std::vector<std::map<std::string, size_t>> by_level(nlevels);
    for (size_t i = 0; i < parts.size(); ++i) {
        by_level[parts[i].level][parts[i].partition] = i;
    }
    if (by_level[0].empty()) {
        throw input_error(ctx.original().string() + "/" + level_names[0] + ": no stores");
    }
    std::vector<size_t> order; // skeleton node -> part
    if (by_level[0].size() == 1) {
        order.push_back(by_level[0].begin()->second);
    } else {
        if (nlevels != 1) {
            throw input_error(ctx.original().string() + "/" + level_names[0] + ": the top level of a map of " +
                              std::to_string(nlevels) + " levels must have one partition, it has " +
                              std::to_string(by_level[0].size()));
        }
        order.push_back(no_part);
    }
    sk.nodes.push_back({});
    for (size_t i = 0; i < order.size(); ++i) {
        auto& n = sk.nodes[i];
        n.first_child = static_cast<uint32_t>(order.size());
        auto add_child = [&](size_t part) {
            order.push_back(part);
            datatree::Node child;
            child.parent = static_cast<uint32_t>(i);
            sk.nodes.push_back(child);
            ++sk.nodes[i].child_count;
        };
        if (order[i] == no_part) {
            for (const auto& [tile, part] : by_level[0]) {
                add_child(part);
            }
        } else if (const uint32_t l = parts[order[i]].level; l + 1 < nlevels) {
            for (const auto& u : parts[order[i]].units) {
                if (auto it = by_level[l + 1].find(u); it != by_level[l + 1].end()) {
                    add_child(it->second);
                }
            }
        }
        if (sk.nodes[i].child_count == 0) {
            sk.nodes[i].first_child = 0;
        }
    }
    {
        std::vector<size_t> per_level(nlevels);
        for (const size_t p : order) {
            per_level[p == no_part ? 0 : parts[p].level] += p == no_part ? 0 : 1;
        }
        for (uint32_t l = 0; l < nlevels; ++l) {
            if (per_level[l] != by_level[l].size()) {
                throw input_error(ctx.original().string() + "/" + level_names[l] + ": " +
                                  std::to_string(by_level[l].size() - per_level[l]) +
                                  " partitions are not units of the level above");
            }
        }
    }
    return order;
}

/// assemble, step 2: each node's code, fields and table with its chains'
/// border levels, the LOD totals, and a tiles root's box. Returns the tables.
std::vector<std::string> fill_nodes(const TreeContext& ctx, std::vector<PartNode>& parts,
                                    const std::vector<size_t>& order, PackedTree& tree)
{
    auto& sk = tree.skeleton;
    const auto nlevels = static_cast<uint32_t>(ctx.level_names().size());
    const size_t nlods = ctx.lod_eps().size();
    // The node whose map has each unit as its own, per level.
    std::vector<std::unordered_map<std::string, uint32_t>> unit_node(nlevels);
    for (uint32_t i = 0; i < order.size(); ++i) {
        if (order[i] != no_part) {
            for (const auto& u : parts[order[i]].units) {
                unit_node[parts[order[i]].level].emplace(u, i);
            }
        }
    }
    // The border level of a chain of level l between units a and b: the
    // coarsest level whose map has a border along it (0 for the map's outer
    // edge, or a chain with no unit on a side; l between two units of one
    // node). Nodes of level l are l steps below the root, so a unit's
    // ancestor node at each coarser level is found by walking up.
    auto border_level = [&](uint32_t l, const std::string& a, const std::string& b) -> uint32_t {
        if (a.empty() || b.empty()) {
            return 0;
        }
        const auto ia = unit_node[l].find(a), ib = unit_node[l].find(b);
        if (ia == unit_node[l].end() || ib == unit_node[l].end()) {
            return l;
        }
        uint32_t na = ia->second, nb = ib->second, level = l;
        while (na != nb && level > 0 && sk.nodes[na].parent != datatree::no_node &&
               sk.nodes[nb].parent != datatree::no_node) {
            na = sk.nodes[na].parent;
            nb = sk.nodes[nb].parent;
            --level;
        }
        return na == nb ? level : 0;
    };
    // Each node's code in the skeleton's strings (the root's is empty), its
    // fields, and its table with the border levels.
    std::unordered_map<std::string, uint32_t> string_index;
    std::vector<std::string> tables(order.size());
    tree.lods.resize(nlods);
    for (size_t k = 0; k < nlods; ++k) {
        tree.lods[k].eps_m = ctx.lod_eps()[k];
    }
    for (size_t i = 0; i < order.size(); ++i) {
        auto& n = sk.nodes[i];
        if (order[i] == no_part) {
            n.chains = 0;
            n.lods.assign(nlods, {});
            tables[i] = datatree::encode_table({});
            continue;
        }
        PartNode& p = parts[order[i]];
        const std::string code = i == 0 ? std::string() : p.partition;
        auto [it, fresh] = string_index.try_emplace(code, 0);
        if (fresh && !code.empty()) {
            it->second = static_cast<uint32_t>(sk.strings.size());
            sk.strings.push_back(code);
        }
        n.code = it->second;
        n.level = p.level;
        n.chains = p.node.chains;
        n.box = p.node.box;
        n.lods = p.node.lods;
        auto t = datatree::decode_table(std::as_bytes(std::span(p.table.data(), p.table.size())), p.partition);
        for (auto& e : t.chains) {
            e.flags |= border_level(p.level, t.strings[e.left], t.strings[e.right]) << datatree::border_level_shift;
        }
        tables[i] = datatree::encode_table(t);
        std::string().swap(p.table);
        for (size_t k = 0; k < nlods; ++k) {
            tree.lods[k].vertices += n.lods[k].vertices;
            tree.lods[k].payload_bytes += p.sizes[k];
            tree.lods[k].raw_bytes += n.lods[k].vertices * sizeof(GridPoint);
        }
    }
    if (order.front() == no_part) {
        auto& root = sk.nodes.front();
        root.level = 0;
        datatree::Box box{INT32_MAX, INT32_MAX, INT32_MIN, INT32_MIN};
        for (uint32_t c = root.first_child; c < root.first_child + root.child_count; ++c) {
            const auto& b = sk.nodes[c].box;
            box = {std::min(box.min_x, b.min_x), std::min(box.min_y, b.min_y), std::max(box.max_x, b.max_x),
                   std::max(box.max_y, b.max_y)};
        }
        root.box = box;
    }
    return tables;
}

/// The tree of `parts` (one per store, any order): the hierarchy of nodes,
/// each chain's border level, and the tiles, each payload fetched
/// (`fetch(part, k)`, LOD k's geometry) as its tile is built.
PackedTree assemble(const TreeContext& ctx, uint8_t metric, std::vector<PartNode>& parts,
                    const std::function<std::string(size_t, size_t)>& fetch, uint64_t tile_bytes, int draco_speed)
{
    PackedTree tree;
    auto& sk = tree.skeleton;
    sk = ctx.header();
    sk.metric = metric;
    const size_t nlods = ctx.lod_eps().size();
    const std::vector<size_t> order = build_hierarchy(ctx, parts, sk);
    std::vector<std::string> tables = fill_nodes(ctx, parts, order, tree);
    const std::string empty_geometry = datatree::encode_geometry({}, {0, 0}, {draco_speed});
    const std::string no_units = datatree::encode_units({}, {0, 0});
    std::vector<std::vector<uint64_t>> sizes(order.size());
    for (size_t i = 0; i < order.size(); ++i) {
        tree.table_bytes += tables[i].size();
        sizes[i].push_back(tables[i].size());
        for (size_t k = 0; k < nlods; ++k) {
            sizes[i].push_back(order[i] == no_part ? empty_geometry.size() : parts[order[i]].sizes[k]);
        }
        sizes[i].push_back(order[i] == no_part ? no_units.size() : parts[order[i]].unit_table.size());
        tree.unit_bytes += sizes[i].back();
    }
    layout_tiles(
        tree, sizes,
        [&](uint32_t n, size_t j) {
            if (j == 0) {
                return std::move(tables[n]);
            }
            if (j == nlods + 1) {
                return order[n] == no_part ? no_units : std::move(parts[order[n]].unit_table);
            }
            return order[n] == no_part ? empty_geometry : fetch(order[n], j - 1);
        },
        tile_bytes);
    return tree;
}

/// A part file (write_parts): "TLDPART1", the header's size (u64), the
/// header (ByteWriter fields, its CRC-32 last), then the geometry payloads
/// back to back. Work files of one pack, not a published format.
constexpr std::string_view part_magic = "TLDPART2"; // 2: the units payload

struct PartHeader {
    PartNode node;
    int draco_speed = 0;
    std::vector<double> lod_eps;
    std::vector<uint32_t> crcs;                       ///< of each payload
    std::vector<std::pair<Source, uint32_t>> sources; ///< and their trailers' CRCs
    uint64_t payloads_at = 0;                         ///< where the first payload begins
};

std::string encode_part(const NodeBuild& nb, const std::vector<double>& lod_eps, int draco_speed,
                        const std::vector<std::pair<Source, uint32_t>>& sources)
{
    ByteWriter h;
    h.put<uint32_t>(nb.level);
    h.put_str(nb.partition);
    h.put<int32_t>(draco_speed);
    h.put<uint32_t>(static_cast<uint32_t>(nb.units.size()));
    for (const auto& u : nb.units) {
        h.put_str(u);
    }
    h.put<uint32_t>(nb.node.chains);
    h.put<int32_t>(nb.node.box.min_x);
    h.put<int32_t>(nb.node.box.min_y);
    h.put<int32_t>(nb.node.box.max_x);
    h.put<int32_t>(nb.node.box.max_y);
    h.put<uint32_t>(static_cast<uint32_t>(lod_eps.size()));
    for (size_t k = 0; k < lod_eps.size(); ++k) {
        const auto& p = nb.payloads[k];
        h.put<double>(lod_eps[k]);
        h.put<double>(nb.node.lods[k].error_m);
        h.put<uint64_t>(nb.node.lods[k].vertices);
        h.put<uint64_t>(p.size());
        h.put<uint32_t>(crc32(std::as_bytes(std::span(p.data(), p.size()))));
    }
    h.put_str(nb.table);
    h.put_str(nb.unit_table);
    h.put<uint32_t>(static_cast<uint32_t>(sources.size()));
    for (const auto& [s, crc] : sources) {
        h.put<uint32_t>(s.lod);
        h.put_str(s.file);
        h.put<uint32_t>(crc);
    }
    h.put<uint32_t>(crc32(std::as_bytes(std::span(h.bytes().data(), h.bytes().size()))));
    ByteWriter out;
    out.put_bytes(part_magic);
    out.put<uint64_t>(h.size());
    out.put_bytes(h.bytes());
    for (const auto& p : nb.payloads) {
        out.put_bytes(p);
    }
    return std::move(out.bytes());
}

PartHeader read_part_header(const fs::path& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw environment_error(path.string() + ": cannot read");
    }
    char head[16];
    if (!in.read(head, 16) || std::string_view(head, 8) != part_magic) {
        throw input_error(path.string() + ": not a pack part file (run tigerlod-pack --partitions again)");
    }
    uint64_t n = 0;
    std::memcpy(&n, head + 8, 8);
    std::string bytes(n < (uint64_t{1} << 32) ? n : 0, '\0');
    if (bytes.size() < 4 || !in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()))) {
        throw input_error(path.string() + ": truncated pack part file (run tigerlod-pack --partitions again)");
    }
    uint32_t crc = 0;
    std::memcpy(&crc, bytes.data() + bytes.size() - 4, 4);
    if (crc32(std::as_bytes(std::span(bytes.data(), bytes.size() - 4))) != crc) {
        throw input_error(path.string() + ": checksum mismatch in a pack part file (run tigerlod-pack "
                                          "--partitions again)");
    }
    ByteReader r(std::as_bytes(std::span(bytes.data(), bytes.size() - 4)), path.string());
    PartHeader h;
    h.node.level = r.get<uint32_t>("level");
    h.node.partition = r.get_str("partition");
    h.draco_speed = r.get<int32_t>("draco speed");
    h.node.units.resize(r.get<uint32_t>("units"));
    for (auto& u : h.node.units) {
        u = r.get_str("unit");
    }
    h.node.node.chains = r.get<uint32_t>("chains");
    h.node.node.box.min_x = r.get<int32_t>("box");
    h.node.node.box.min_y = r.get<int32_t>("box");
    h.node.node.box.max_x = r.get<int32_t>("box");
    h.node.node.box.max_y = r.get<int32_t>("box");
    const auto nlods = r.get<uint32_t>("LODs");
    for (uint32_t k = 0; k < nlods; ++k) {
        h.lod_eps.push_back(r.get<double>("LOD"));
        datatree::LodInfo lod;
        lod.error_m = r.get<double>("LOD");
        lod.vertices = r.get<uint64_t>("LOD");
        h.node.node.lods.push_back(lod);
        h.node.sizes.push_back(r.get<uint64_t>("LOD"));
        h.crcs.push_back(r.get<uint32_t>("LOD"));
    }
    h.node.table = r.get_str("table");
    h.node.unit_table = r.get_str("units");
    const auto nsources = r.get<uint32_t>("sources");
    for (uint32_t i = 0; i < nsources; ++i) {
        Source s;
        s.lod = r.get<uint32_t>("source");
        s.file = r.get_str("source");
        h.sources.emplace_back(s, r.get<uint32_t>("source"));
    }
    if (r.left() != 0) {
        r.fail("trailing bytes in the header");
    }
    h.payloads_at = 16 + n;
    return h;
}

/// The nodes of level l named by `partitions`, built.
std::vector<NodeBuild> nodes_of(uint32_t l, const std::vector<std::string>& partitions)
{
    std::vector<NodeBuild> nodes(partitions.size());
    for (size_t i = 0; i < partitions.size(); ++i) {
        nodes[i].level = l;
        nodes[i].partition = partitions[i];
    }
    return nodes;
}

} // namespace

PackedTree build_tree(const fs::path& original, const fs::path& simplified, const PackOptions& options)
{
    TreeContext ctx(original, simplified, options);
    std::vector<PartNode> parts;
    std::vector<std::vector<std::string>> payloads;
    for (uint32_t l = 0; l < ctx.level_names().size(); ++l) {
        std::vector<std::string> names;
        for (const auto& r : ctx.files_of(l)) {
            names.push_back(r.stem().string());
        }
        auto nodes = nodes_of(l, names);
        ctx.pack_level(l, nodes, ctx.files_of(l), false);
        if (options.on_level) {
            options.on_level(nodes.size());
        }
        for (auto& nb : nodes) {
            PartNode p{nb.level,
                       nb.partition,
                       std::move(nb.units),
                       std::move(nb.node),
                       std::move(nb.table),
                       {},
                       std::move(nb.unit_table)};
            for (const auto& g : nb.payloads) {
                p.sizes.push_back(g.size());
            }
            parts.push_back(std::move(p));
            payloads.push_back(std::move(nb.payloads));
        }
    }
    return assemble(
        ctx, ctx.metric(), parts, [&](size_t part, size_t k) { return std::move(payloads[part][k]); },
        options.tile_bytes, options.draco_speed);
}

std::vector<std::pair<std::string, std::string>> stores_of(const fs::path& original)
{
    std::vector<std::pair<std::string, std::string>> out;
    for (const auto& r : store_files(original)) {
        out.emplace_back(r.parent_path().string(), r.stem().string());
    }
    return out;
}

PackPlan plan_parts(const fs::path& original, unsigned threads)
{
    const auto rel = store_files(original);
    if (rel.empty()) {
        throw input_error(original.string() + ": no chain stores (<level>/<partition>.tlc)");
    }
    // Per level: each store's owned chains (sorted ids) and the halo chains its node shows.
    std::map<std::string, std::vector<size_t>> levels;
    for (size_t i = 0; i < rel.size(); ++i) {
        levels[rel[i].parent_path().string()].push_back(i);
    }
    PackPlan plan;
    for (const auto& entry : levels) {
        const std::string& level = entry.first; // (a lambda uses them: no structured binding for Clang 14)
        const std::vector<size_t>& members = entry.second;
        std::vector<std::vector<uint64_t>> owned(members.size()), shown(members.size()), halo(members.size());
        parallel_each(members.size(), threads, [&](size_t a) {
            const auto s = chains::read(original / rel[members[a]]);
            const auto units = own_units(s);
            const std::set<std::string> mine(units.begin(), units.end());
            for (const auto& c : s.chains) {
                if ((c.flags & chains::chain_halo) == 0) {
                    owned[a].push_back(c.id);
                } else {
                    halo[a].push_back(c.id);
                    if (shows(s, c, mine)) {
                        shown[a].push_back(c.id);
                    }
                }
            }
            std::sort(owned[a].begin(), owned[a].end());
        });
        std::vector<std::pair<uint64_t, uint32_t>> owner; // (chain, store of the level)
        for (size_t a = 0; a < members.size(); ++a) {
            for (const uint64_t id : owned[a]) {
                owner.emplace_back(id, static_cast<uint32_t>(a));
            }
            std::vector<uint64_t>().swap(owned[a]);
        }
        std::sort(owner.begin(), owner.end());
        auto owners = [&](size_t a, const std::vector<uint64_t>& ids) {
            std::set<std::string> out;
            for (const uint64_t id : ids) {
                const auto it = std::lower_bound(owner.begin(), owner.end(), std::pair<uint64_t, uint32_t>{id, 0});
                if (it == owner.end() || it->first != id) {
                    throw input_error((original / rel[members[a]]).string() + ": chain " + std::to_string(id) +
                                      " of its halo is owned by no store of its level");
                }
                out.insert((fs::path(level) / rel[members[it->second]].stem()).string());
            }
            return std::vector<std::string>(out.begin(), out.end());
        };
        for (size_t a = 0; a < members.size(); ++a) {
            const std::string key = (fs::path(level) / rel[members[a]].stem()).string();
            plan.reads[key] = owners(a, shown[a]);
            plan.near[key] = owners(a, halo[a]);
        }
    }
    return plan;
}

std::string plan_json(const PackPlan& plan)
{
    nlohmann::ordered_json doc;
    doc["schema"] = "tigerlod.pack-plan/1";
    doc["ingest"] = plan.ingest_sha256;
    for (const auto* which : {&plan.reads, &plan.near}) {
        nlohmann::ordered_json stores = nlohmann::ordered_json::object();
        for (const auto& [store, others] : *which) {
            stores[store] = others;
        }
        doc[which == &plan.reads ? "reads" : "near"] = std::move(stores);
    }
    return doc.dump(1) + "\n";
}

PackPlan plan_from_json(const std::string& text, const std::string& name)
{
    try {
        const auto doc = nlohmann::json::parse(text);
        if (doc.at("schema") != "tigerlod.pack-plan/1") {
            throw input_error(name + ": not a tigerlod pack plan (schema tigerlod.pack-plan/1)");
        }
        PackPlan plan;
        plan.reads = doc.at("reads").get<std::map<std::string, std::vector<std::string>>>();
        plan.near = doc.at("near").get<std::map<std::string, std::vector<std::string>>>();
        plan.ingest_sha256 = doc.at("ingest").get<std::string>();
        return plan;
    } catch (const nlohmann::json::exception& e) {
        throw input_error(name + ": not a tigerlod pack plan: " + e.what());
    }
}

std::vector<LodTotals> write_parts(const fs::path& original, const fs::path& simplified,
                                   const std::vector<std::string>& stores, const PackPlan& plan, const fs::path& parts,
                                   const PackOptions& options, std::map<std::string, uint32_t>* content)
{
    TreeContext ctx(original, simplified, options, true);
    std::map<uint32_t, std::vector<std::string>> by_level;
    for (const auto& s : stores) {
        const fs::path p(s);
        by_level[ctx.level_of(p.parent_path().string())].push_back(p.filename().string());
    }
    std::vector<LodTotals> totals(ctx.lod_eps().size());
    for (size_t k = 0; k < totals.size(); ++k) {
        totals[k].eps_m = ctx.lod_eps()[k];
    }
    for (const auto& [l, names] : by_level) {
        const std::string level = ctx.level_names()[l];
        std::set<fs::path> reads;
        for (const auto& n : names) {
            const std::string key = level + "/" + n;
            const auto it = plan.reads.find(key);
            if (it == plan.reads.end()) {
                throw usage_error("the pack plan has no store " + key +
                                  ": it is older than the stores (run tigerlod-pack --plan again)");
            }
            reads.insert(fs::path(key + ".tlc"));
            for (const auto& other : it->second) {
                reads.insert(fs::path(other + ".tlc"));
            }
        }
        auto nodes = nodes_of(l, names);
        ctx.pack_level(l, nodes, {reads.begin(), reads.end()}, true);
        fs::create_directories(parts / level);
        remove_dead_leftovers(parts / level);
        parallel_each(nodes.size(), options.threads, [&](size_t a) {
            auto& nb = nodes[a];
            std::sort(nb.sources.begin(), nb.sources.end());
            std::vector<std::pair<Source, uint32_t>> sources;
            for (const auto& s : nb.sources) {
                sources.emplace_back(s, trailer_crc(ctx.source_path(s)));
            }
            write_file_atomic_unsynced_folder(parts / level / (nb.partition + ".tlp"),
                                              encode_part(nb, ctx.lod_eps(), options.draco_speed, sources));
        });
        if (options.on_level) {
            options.on_level(nodes.size());
        }
        sync_to_disk(parts / level);
        for (const auto& nb : nodes) {
            if (content) {
                const std::string bytes = encode_part(nb, ctx.lod_eps(), options.draco_speed, {});
                (*content)[level + "/" + nb.partition] = crc32(std::as_bytes(std::span(bytes.data(), bytes.size())));
            }
            for (size_t k = 0; k < totals.size(); ++k) {
                totals[k].vertices += nb.node.lods[k].vertices;
                totals[k].payload_bytes += nb.payloads[k].size();
                totals[k].raw_bytes += nb.node.lods[k].vertices * sizeof(GridPoint);
            }
        }
    }
    return totals;
}

PackedTree assemble_parts(const fs::path& original, const fs::path& simplified, const fs::path& parts_dir,
                          const PackOptions& options)
{
    TreeContext ctx(original, simplified, options);
    const auto& rel = ctx.stores();
    std::vector<PartHeader> heads(rel.size());
    std::vector<fs::path> files(rel.size());
    parallel_each(rel.size(), options.threads, [&](size_t i) {
        files[i] = parts_dir / fs::path(rel[i]).replace_extension(".tlp");
        const std::string store = fs::path(rel[i]).replace_extension().string();
        if (!fs::exists(files[i])) {
            throw usage_error(files[i].string() + " is missing: the pack job of " + store + " has not run");
        }
        heads[i] = read_part_header(files[i]);
        const auto& h = heads[i];
        const uint32_t l = ctx.level_of(fs::path(rel[i]).parent_path().string());
        if (h.node.level != l || h.node.partition != fs::path(rel[i]).stem().string()) {
            throw input_error(files[i].string() + ": holds the part of another store");
        }
        if (h.draco_speed != options.draco_speed || h.lod_eps != ctx.lod_eps()) {
            throw usage_error(files[i].string() +
                              ": packed with other options or tolerances than this run's: run "
                              "tigerlod-pack --partitions " +
                              store + " again");
        }
        for (const auto& [s, crc] : h.sources) {
            std::error_code ec;
            if (!fs::exists(ctx.source_path(s), ec) || trailer_crc(ctx.source_path(s)) != crc) {
                throw usage_error(files[i].string() + " is stale: " + ctx.source_path(s).string() +
                                  " changed since it was packed; run tigerlod-pack --partitions " + store + " again");
            }
        }
    });
    std::vector<PartNode> parts;
    for (auto& h : heads) {
        parts.push_back(std::move(h.node));
    }
    // The metric: of the simplified stores (every part's, checked by simplify and pack_level).
    const auto first = chains::read(ctx.lod_dir(1) / rel.front());
    return assemble(
        ctx, first.metric, parts,
        [&](size_t part, size_t k) {
            if (k == 0 && options.on_level) {
                options.on_level(1); // a store's part, taken into its tile
            }
            const auto& h = heads[part];
            uint64_t at = h.payloads_at;
            for (size_t j = 0; j < k; ++j) {
                at += parts[part].sizes[j];
            }
            std::string bytes(parts[part].sizes[k], '\0');
            std::ifstream in(files[part], std::ios::binary);
            if (!in || !in.seekg(static_cast<std::streamoff>(at)) ||
                !in.read(bytes.data(), static_cast<std::streamsize>(bytes.size())) ||
                crc32(std::as_bytes(std::span(bytes.data(), bytes.size()))) != h.crcs[k]) {
                throw input_error(files[part].string() + ": a payload is damaged or cut short (run tigerlod-pack "
                                                         "--partitions again)");
            }
            return bytes;
        },
        options.tile_bytes, options.draco_speed);
}

std::vector<fs::path> prune_parts(const fs::path& original, const fs::path& parts)
{
    std::set<fs::path> want;
    for (const auto& r : store_files(original)) {
        want.insert(fs::path(r).replace_extension(".tlp"));
    }
    std::vector<fs::path> removed;
    if (!fs::is_directory(parts)) {
        return removed;
    }
    std::error_code ec;
    for (const auto& level : fs::directory_iterator(parts)) {
        if (!level.is_directory()) {
            continue;
        }
        for (const auto& p : remove_dead_leftovers(level.path())) {
            removed.push_back(p);
        }
        for (const auto& f : fs::directory_iterator(level.path())) {
            if (f.path().extension() == ".tlp" && !want.contains(level.path().filename() / f.path().filename())) {
                removed.push_back(f.path());
            }
        }
    }
    for (const auto& p : removed) {
        fs::remove(p, ec);
    }
    for (const auto& level : fs::directory_iterator(parts)) {
        if (level.is_directory() && fs::is_empty(level.path(), ec)) {
            fs::remove(level.path(), ec);
        }
    }
    return removed;
}

void layout_tiles(PackedTree& tree, std::vector<std::vector<std::string>>&& payloads, uint64_t tile_bytes)
{
    std::vector<std::vector<uint64_t>> sizes(payloads.size());
    for (size_t n = 0; n < payloads.size(); ++n) {
        for (const auto& p : payloads[n]) {
            sizes[n].push_back(p.size());
        }
    }
    layout_tiles(
        tree, sizes, [&](uint32_t n, size_t j) { return std::move(payloads[n][j]); }, tile_bytes);
}

void layout_tiles(PackedTree& tree, const std::vector<std::vector<uint64_t>>& sizes,
                  const std::function<std::string(uint32_t, size_t)>& fetch, uint64_t tile_bytes)
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
        for (const uint64_t b : sizes[i]) {
            subtree[i] += b;
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
        auto place = [&](uint32_t n, size_t j) {
            const std::string payload = fetch(n, j);
            if (payload.size() != sizes[n][j]) {
                throw std::logic_error("layout_tiles: a payload is not of the size given");
            }
            datatree::PayloadRef ref{tile_index, bytes.size(), static_cast<uint32_t>(payload.size()),
                                     crc32(std::as_bytes(std::span(payload.data(), payload.size())))};
            bytes += payload;
            return ref;
        };
        for (uint32_t n : members) {
            sk.nodes[n].table = place(n, 0);
            for (size_t k = 0; k < sk.nodes[n].lods.size(); ++k) {
                sk.nodes[n].lods[k].payload = place(n, 1 + k);
            }
            if (sizes[n].size() > 1 + sk.nodes[n].lods.size()) {
                place(n, 1 + sk.nodes[n].lods.size()); // the units payload: where units_at says, no reference
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
