#include "stages/export/export_stage.hpp"

#include "core/fs.hpp"
#include "core/gdal_output.hpp"
#include "core/manifest.hpp"
#include "core/progress.hpp"
#include "reader/tree_view.hpp"
#include "simplification/stage_options.hpp"
#include "stages/export/lonlat_line.hpp"

#include <nlohmann/json.hpp>

#include <gdal.h>
#include <ogr_api.h>
#include <ogr_geometry.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <utility>

namespace fs = std::filesystem;

namespace tigerlod::exporter {

void ExportStage::add_args(ArgSet& args)
{
    args.positional("TREE", &m_tree, "a Data Tree folder");
    args.positional("OUTPUT", &m_output, "a .gpkg or .geojson file, written under a temporary name and renamed");
    args.group("What");
    args.add("node", &m_node, "one node's map (a node index or a unit code; root for the root)", "NODE");
    args.add("level", &m_level, "every node showing this level's map, each chain once (default: the root's map)",
             "NAME");
    args.add("lod", &m_lod, "the LOD, 0 for the original chains", "K");
    args.add("layer", &m_layer,
             "for GeoJSON, which layer: chains, units (polygons) or unit_points (each unit's internal point); a "
             "GeoPackage holds all three",
             "NAME");
    args.group("Coordinates");
    args.add("crs", &m_crs,
             "tree: the tree's projection in metres, its CRS named (EPSG:5070 for the default CONUS Albers, else "
             "WKT), straight segments as in the tree; lonlat: NAD83 longitude/latitude, each segment densified",
             "NAME");
    args.add("max-bow", &m_max_bow,
             "with --crs lonlat: how far a lon/lat line may stray from the tree's segment on the ground, as a "
             "fraction of the LOD's eps (LOD 0: of the ladder's smallest)",
             "F");
    args.add("overwrite", &m_overwrite, "replace OUTPUT if it exists");
}

void ExportStage::initialize()
{
    if (!m_node.empty() && !m_level.empty()) {
        throw usage_error("export: give '--node' or '--level', not both");
    }
    if (m_lod < 0) {
        throw usage_error("export: option '--lod' must be >= 0");
    }
    if (m_crs != "tree" && m_crs != "lonlat") {
        throw usage_error("export: option '--crs' must be tree or lonlat");
    }
    if (!(m_max_bow > 0) || !(m_max_bow <= 1)) {
        throw usage_error("export: option '--max-bow' must be in (0, 1]");
    }
    if (m_layer != "chains" && m_layer != "units" && m_layer != "unit_points") {
        throw usage_error("export: option '--layer' must be chains, units or unit_points");
    }
    const auto ext = fs::path(m_output).extension();
    if (ext != ".gpkg" && ext != ".geojson" && ext != ".json") {
        throw usage_error("export: OUTPUT must end in .gpkg or .geojson");
    }
    refuse_to_replace_inputs(m_output, {m_tree});
    if (fs::exists(m_output) && !m_overwrite) {
        throw usage_error("export: " + m_output + " exists. Use --overwrite to replace it.");
    }
}

std::vector<std::string> ExportStage::versions() const
{
    return {std::string("GDAL ") + GDALVersionInfo("RELEASE_NAME"), datatree::format_version_text()};
}

std::string ExportStage::help_notes() const
{
    return "Units whose boundary is not complete in a node (neighbours across its border) get no polygon\n"
           "there; every unit is complete in the node of its parent unit. A chain's eps_m is its own: the\n"
           "LOD's tolerance times its feature class's scale, which holds on the ground (docs/guarantees.md).\n"
           "Exit codes: 0 done; 1 bad data in the tree (the message names file, node and fault);\n"
           "  2 usage error; 3 environment (cannot write).\n";
}

namespace {

/// The dataset being written under a temporary name: closed, and the file
/// removed, unless it was renamed into place (nothing half-written is left).
struct TempDataset {
    GDALDatasetH ds = nullptr;
    fs::path path;
    bool kept = false;
    ~TempDataset()
    {
        if (ds != nullptr) {
            GDALClose(ds);
        }
        if (!kept) {
            std::error_code ec;
            fs::remove(path, ec);
        }
    }
};

OGRFieldDefnH field(OGRLayerH layer, const char* name, OGRFieldType type)
{
    OGRFieldDefnH fd = OGR_Fld_Create(name, type);
    if (OGR_L_CreateField(layer, fd, TRUE) != OGRERR_NONE) {
        OGR_Fld_Destroy(fd);
        throw environment_error(std::string("export: cannot create field ") + name);
    }
    OGR_Fld_Destroy(fd);
    return nullptr;
}

/// The nodes whose map is exported: every node of `level`, or the one `node` names.
std::vector<uint32_t> nodes_to_export(const datatree::Skeleton& s, const std::string& level_name,
                                      const std::string& node)
{
    std::vector<uint32_t> nodes;
    if (level_name.empty()) {
        nodes.push_back(view::find_node(s, node));
        return nodes;
    }
    uint32_t level = UINT32_MAX;
    for (uint32_t l = 0; l < s.level_names.size(); ++l) {
        level = s.level_names[l] == level_name ? l : level;
    }
    if (level == UINT32_MAX) {
        throw usage_error("export: no level '" + level_name + "' in the tree");
    }
    for (uint32_t n = 0; n < s.nodes.size(); ++n) {
        if (s.nodes[n].level == level) {
            nodes.push_back(n);
        }
    }
    return nodes;
}

/// The node each unit is written from. A unit shows in the map of the node
/// that holds it and, in part, in its neighbours' (across their outlines);
/// whole there too when it is an island in a neighbour, but without its own
/// holes. Its own node holds every chain of its boundary, any other node a
/// subset: each unit is written once, from the node with the most of its
/// boundary chains (the first of those). Empty for one node.
std::map<std::string, std::pair<size_t, uint32_t>> home_nodes(const reader::Tree& tree,
                                                              const std::vector<uint32_t>& nodes)
{
    std::map<std::string, std::pair<size_t, uint32_t>> home; // unit -> (boundary chains, node)
    if (nodes.size() < 2) {
        return home;
    }
    for (uint32_t n : nodes) {
        datatree::ChainTable t;
        if (auto st = tree.read_table(n, t); !st.ok()) {
            throw input_error(st.error);
        }
        std::vector<size_t> count(t.strings.size(), 0);
        for (const auto& c : t.chains) {
            if (c.left != c.right) {
                ++count[c.left];
                ++count[c.right];
            }
        }
        for (uint32_t u = 1; u < t.strings.size(); ++u) {
            auto [it, added] = home.try_emplace(t.strings[u], count[u], n);
            if (!added && count[u] > it->second.first) {
                it->second = {count[u], n};
            }
        }
    }
    return home;
}

/// The units of the exported nodes' maps (their units payloads, Data Tree
/// 2.2): each with its node, and the fields they carry, each field's type
/// joined over the nodes as ingest joins it over files.
struct ExportUnits {
    std::vector<datatree::UnitTable::Field> fields;
    /// (map level, code) -> (node, the unit); a unit is in one node's table.
    std::map<std::pair<uint32_t, std::string>, std::pair<uint32_t, const datatree::UnitTable::Unit*>> by_code;
    std::vector<datatree::UnitTable> tables; ///< per exported node
};

ExportUnits export_units(const reader::Tree& tree, const std::vector<uint32_t>& nodes)
{
    ExportUnits out;
    out.tables.resize(nodes.size());
    for (size_t i = 0; i < nodes.size(); ++i) {
        if (const auto st = tree.read_units(nodes[i], out.tables[i]); !st.ok()) {
            throw format_error("export: " + st.error);
        }
        const auto& t = out.tables[i];
        for (const auto& f : t.fields) {
            auto it =
                std::find_if(out.fields.begin(), out.fields.end(), [&](const auto& g) { return g.name == f.name; });
            if (it == out.fields.end()) {
                out.fields.push_back(f);
            } else if (it->type != f.type) {
                it->type = it->type == 0 || f.type == 0 ? 0 : 2; // text in either: text; integer and real: real
            }
        }
    }
    for (size_t i = 0; i < nodes.size(); ++i) {
        for (const auto& u : out.tables[i].units) {
            out.by_code.emplace(std::pair{tree.skeleton().nodes[nodes[i]].level, u.code}, std::pair{nodes[i], &u});
        }
    }
    return out;
}

/// The layers of the file being written, and what went into them.
class Writer {
  public:
    /// `max_bow_m` > 0: lon/lat, densified to it; 0: the tree's projection.
    Writer(GDALDatasetH ds, bool with_chains, bool with_units, bool with_points, const Projection& proj, int lod,
           double eps_m, double max_bow_m, std::map<std::string, double> class_scale, const ExportUnits& unit_tables,
           fs::path tmp, const GdalErrorTrap& trap)
        : m_proj(proj), m_lod(lod), m_eps_m(eps_m), m_max_bow_m(max_bow_m), m_class_scale(std::move(class_scale)),
          m_tmp(std::move(tmp)), m_trap(trap), m_units_of(unit_tables)
    {
        OGRSpatialReferenceH srs = nullptr;
        if (m_max_bow_m > 0) {
            srs = OSRNewSpatialReference(nullptr);
            OSRImportFromEPSG(srs, 4269);
        } else {
            srs = tree_srs(proj.params(), "export");
        }
        OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
        if (with_chains) {
            m_chains = layer(ds, "chains", srs, wkbLineString);
            field(m_chains, "chain_id", OFTInteger64);
            field(m_chains, "node", OFTString);
            field(m_chains, "left", OFTString);
            field(m_chains, "right", OFTString);
            field(m_chains, "class", OFTString);
            field(m_chains, "lod", OFTInteger);
            field(m_chains, "eps_m", OFTReal);
        }
        m_geographic = m_max_bow_m > 0;
        if (with_units) {
            m_units = layer(ds, "units", srs, wkbMultiPolygon);
            field(m_units, "unit", OFTString);
            field(m_units, "node", OFTString);
            field(m_units, "lod", OFTInteger);
            field(m_units, "eps_m", OFTReal);
            attribute_fields(m_units);
        }
        if (with_points) {
            m_points = layer(ds, "unit_points", srs, wkbPoint);
            field(m_points, "unit", OFTString);
            field(m_points, "node", OFTString);
            attribute_fields(m_points);
        }
        OSRDestroySpatialReference(srs);
    }
    bool writes_units() const { return m_units != nullptr; }

    /// The internal point of each unit of the node's map (its units payload), with its name and attributes.
    void write_points(const datatree::UnitTable& t, const std::string& code)
    {
        if (m_points == nullptr) {
            return;
        }
        for (const auto& u : t.units) {
            OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(m_points));
            OGR_F_SetFieldString(f, 0, u.code.c_str());
            OGR_F_SetFieldString(f, 1, code.c_str());
            set_attributes(f, 2, t, u);
            double x = 0, y = 0;
            if (m_geographic) {
                m_proj.to_lonlat(double(u.point.x), double(u.point.y), x, y);
            } else {
                x = double(u.point.x) * m_proj.params().grid_m;
                y = double(u.point.y) * m_proj.params().grid_m;
            }
            OGRGeometryH pt = OGR_G_CreateGeometry(wkbPoint);
            OGR_G_SetPoint_2D(pt, 0, x, y);
            OGR_F_SetGeometryDirectly(f, pt);
            create(m_points, f);
            ++points;
        }
    }

    /// The node's chains not written before (a border shown by two nodes: once).
    void write_chains(const view::NodeMap& m, const std::string& code)
    {
        if (m_chains == nullptr) {
            return;
        }
        for (size_t i = 0; i < m.table.chains.size(); ++i) {
            const auto& c = m.table.chains[i];
            if (!m_written.insert(c.id).second) {
                continue;
            }
            OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(m_chains));
            OGR_F_SetFieldInteger64(f, 0, static_cast<GIntBig>(c.id));
            OGR_F_SetFieldString(f, 1, code.c_str());
            OGR_F_SetFieldString(f, 2, m.table.strings[c.left].c_str());
            OGR_F_SetFieldString(f, 3, m.table.strings[c.right].c_str());
            OGR_F_SetFieldString(f, 4, m.table.strings[c.feature_class].c_str());
            OGR_F_SetFieldInteger(f, 5, m_lod);
            // The chain's own eps on the ground: its class's scale applied.
            const auto cs = m_class_scale.find(m.table.strings[c.feature_class]);
            OGR_F_SetFieldDouble(f, 6, m_eps_m * (cs == m_class_scale.end() ? 1.0 : cs->second));
            OGR_F_SetGeometryDirectly(f, to_line(m.geometry.chain(i)));
            create(m_chains, f);
            ++chains;
        }
    }

    /// The node's units whose home it is, as valid multipolygons; a unit
    /// whose boundary does not close here is counted in `incomplete`.
    void write_units(const view::NodeMap& m, const std::string& code, uint32_t n, uint32_t level,
                     const std::map<std::string, std::pair<size_t, uint32_t>>& home)
    {
        if (m_units == nullptr) {
            return;
        }
        for (uint32_t u = 1; u < m.table.strings.size(); ++u) {
            if (const auto h = home.find(m.table.strings[u]); h != home.end() && h->second.second != n) {
                continue; // written from its own node
            }
            const auto unit = view::unit_polygons(m.table, m.geometry, u);
            if (!unit.complete) {
                ++incomplete;
                continue;
            }
            if (unit.polygons.empty()) {
                continue; // a feature class, or a unit with no chain here
            }
            auto* polygons = new OGRMultiPolygon;
            for (const auto& up : unit.polygons) {
                auto* poly = new OGRPolygon;
                poly->addRingDirectly(to_ring(up.outer));
                for (const auto& hole : up.holes) {
                    poly->addRingDirectly(to_ring(hole));
                }
                polygons->addGeometryDirectly(poly);
            }
            OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(m_units));
            OGR_F_SetFieldString(f, 0, m.table.strings[u].c_str());
            OGR_F_SetFieldString(f, 1, code.c_str());
            OGR_F_SetFieldInteger(f, 2, m_lod);
            OGR_F_SetFieldDouble(f, 3, m_eps_m);
            const auto rec = m_units_of.by_code.find({level, m.table.strings[u]});
            if (rec != m_units_of.by_code.end()) {
                const auto& t = m_units_of.tables[table_index(rec->second.first)];
                set_attributes(f, 4, t, *rec->second.second);
            }
            OGR_F_SetGeometryDirectly(f, OGRGeometry::ToHandle(polygons));
            create(m_units, f);
            ++units;
        }
    }

    size_t chains = 0, units = 0, incomplete = 0, points = 0;
    /// Where the node's units table is in ExportUnits::tables: the exported nodes, in order.
    std::function<size_t(uint32_t)> table_index;

  private:
    /// `name`, then the units' attribute fields, typed (ExportUnits::fields).
    void attribute_fields(OGRLayerH l) const
    {
        field(l, "name", OFTString);
        for (const auto& a : m_units_of.fields) {
            field(l, a.name.c_str(), a.type == 1 ? OFTInteger64 : a.type == 2 ? OFTReal : OFTString);
        }
    }
    /// The unit's name at field `first`, then its values (null where it has none).
    void set_attributes(OGRFeatureH f, int first, const datatree::UnitTable& t,
                        const datatree::UnitTable::Unit& u) const
    {
        OGR_F_SetFieldString(f, first, u.name.c_str());
        for (size_t k = 0; k < t.fields.size(); ++k) {
            const auto it = std::find_if(m_units_of.fields.begin(), m_units_of.fields.end(),
                                         [&](const auto& g) { return g.name == t.fields[k].name; });
            const int i = first + 1 + static_cast<int>(it - m_units_of.fields.begin());
            const std::string& v = u.values[k];
            if (v.empty()) {
                OGR_F_SetFieldNull(f, i);
            } else if (it->type == 1) {
                int64_t n = 0;
                const auto r = std::from_chars(v.data(), v.data() + v.size(), n);
                r.ec == std::errc() && r.ptr == v.data() + v.size() ? OGR_F_SetFieldInteger64(f, i, n)
                                                                    : OGR_F_SetFieldNull(f, i);
            } else if (it->type == 2) {
                double d = 0;
                const auto r = std::from_chars(v.data(), v.data() + v.size(), d);
                r.ec == std::errc() && r.ptr == v.data() + v.size() ? OGR_F_SetFieldDouble(f, i, d)
                                                                    : OGR_F_SetFieldNull(f, i);
            } else {
                OGR_F_SetFieldString(f, i, v.c_str());
            }
        }
    }
    /// The points a line of the file gets for `pts`: projected metres (grid
    /// units times the grid step), or lon/lat densified.
    std::vector<std::pair<double, double>> coordinates(std::span<const GridPoint> pts) const
    {
        if (m_geographic) {
            return densify_lonlat(m_proj, pts, m_max_bow_m);
        }
        std::vector<std::pair<double, double>> out;
        out.reserve(pts.size());
        const double g = m_proj.params().grid_m;
        for (const auto& p : pts) {
            out.emplace_back(double(p.x) * g, double(p.y) * g);
        }
        return out;
    }
    OGRGeometryH to_line(std::span<const GridPoint> pts) const
    {
        OGRGeometryH line = OGR_G_CreateGeometry(wkbLineString);
        for (const auto& [x, y] : coordinates(pts)) {
            OGR_G_AddPoint_2D(line, x, y);
        }
        return line;
    }
    OGRLinearRing* to_ring(const std::vector<GridPoint>& pts) const
    {
        auto* ring = new OGRLinearRing;
        for (const auto& [x, y] : coordinates(pts)) {
            ring->addPoint(x, y);
        }
        return ring;
    }
    /// A new layer; throws environment_error (with GDAL's reason) if it cannot be made.
    OGRLayerH layer(GDALDatasetH ds, const char* name, OGRSpatialReferenceH srs, OGRwkbGeometryType type) const
    {
        OGRLayerH l = GDALDatasetCreateLayer(ds, name, srs, type, nullptr);
        if (l == nullptr) {
            OSRDestroySpatialReference(srs);
            throw environment_error("export: cannot create the layer " + std::string(name) + " in " + m_tmp.string() +
                                    ": " + m_trap.first());
        }
        return l;
    }
    /// Write feature `f` to `layer` and destroy it.
    void create(OGRLayerH layer, OGRFeatureH f) const
    {
        const bool ok = layer != nullptr && OGR_L_CreateFeature(layer, f) == OGRERR_NONE;
        OGR_F_Destroy(f);
        if (!ok) {
            throw environment_error("export: cannot write to " + m_tmp.string() + ": " +
                                    (m_trap.failed() ? m_trap.first() : std::string("GDAL refused a feature")));
        }
    }

    const Projection& m_proj;
    const int m_lod;
    const double m_eps_m;
    const double m_max_bow_m;
    const std::map<std::string, double> m_class_scale;
    bool m_geographic = false;
    const fs::path m_tmp;
    const GdalErrorTrap& m_trap;
    const ExportUnits& m_units_of;
    OGRLayerH m_chains = nullptr, m_units = nullptr, m_points = nullptr;
    std::set<uint64_t> m_written;
};

} // namespace

int ExportStage::run(const StageContext& ctx)
{
    std::string error;
    const auto tree = reader::Tree::open(m_tree, error);
    if (!tree) {
        throw format_error(error);
    }
    const auto& s = tree->skeleton();
    const std::vector<uint32_t> nodes = nodes_to_export(s, m_level, m_node);
    const auto lod = static_cast<uint32_t>(m_lod);
    if (lod >= s.lod_eps_m.size()) {
        throw usage_error("export: no LOD " + std::to_string(lod) + " (the tree has " +
                          std::to_string(s.lod_eps_m.size()) + ")");
    }
    const Projection proj(view::projection_of(s));
    const fs::path out(m_output);
    const bool gpkg = out.extension() == ".gpkg";
    const fs::path tmp = temp_sibling_keeping_extension(out);
    log_removed_leftovers(ctx.log, remove_dead_leftovers(out.parent_path(), out.stem().string()));
    GDALAllRegister();
    fix_gdal_dates();
    GDALDriverH driver = GDALGetDriverByName(gpkg ? "GPKG" : "GeoJSON");
    GdalErrorTrap trap; // every write's and the close's errors (a full disk), checked at the close
    TempDataset g;
    g.path = tmp;
    g.ds = GDALCreate(driver, tmp.c_str(), 0, 0, 0, GDT_Unknown, nullptr);
    if (g.ds == nullptr) {
        throw environment_error("export: cannot create " + tmp.string() + ": " + trap.first());
    }
    // The bow allowed in lon/lat: a fraction of the LOD's eps (LOD 0: of the ladder's smallest).
    const double bow_eps = lod > 0 ? s.lod_eps_m[lod] : s.lod_eps_m.size() > 1 ? s.lod_eps_m[1] : 1.0;
    const double max_bow_m = m_crs == "lonlat" ? m_max_bow * bow_eps : 0.0;
    // The class scales simplify had (the tree's manifest), for each chain's own eps.
    std::map<std::string, double> class_scale;
    try {
        const Manifest packed = read_manifest(m_tree, "pack");
        if (packed.doc.contains("simplify")) {
            class_scale =
                simplify::tolerance_contract(packed.doc.at("simplify"), (fs::path(m_tree) / "manifest.json").string())
                    .class_scale;
        }
    } catch (const input_error&) {
        // A tree without pack's manifest (made by hand): the LOD's eps for every chain.
    }
    const ExportUnits units = export_units(*tree, nodes);
    Writer writer(g.ds, gpkg || m_layer == "chains", gpkg || m_layer == "units", gpkg || m_layer == "unit_points", proj,
                  m_lod, s.lod_eps_m[lod], max_bow_m, std::move(class_scale), units, tmp, trap);
    std::map<uint32_t, size_t> index_of;
    for (size_t i = 0; i < nodes.size(); ++i) {
        index_of.emplace(nodes[i], i);
    }
    writer.table_index = [&](uint32_t n) { return index_of.at(n); };
    const auto home =
        writer.writes_units() ? home_nodes(*tree, nodes) : std::map<std::string, std::pair<size_t, uint32_t>>{};
    Progress progress(ctx.progress, "export", nodes.size(), "nodes", "chains");
    for (uint32_t n : nodes) {
        const auto m = view::read_node(*tree, n, lod);
        const std::string code = n == 0 ? "root" : s.strings[s.nodes[n].code];
        writer.write_chains(m, code);
        writer.write_units(m, code, n, s.nodes[n].level, home);
        writer.write_points(units.tables[index_of.at(n)], code);
        progress.advance(m.table.chains.size());
    }
    std::map<std::string, int64_t> expected;
    if (gpkg || m_layer == "chains") {
        expected["chains"] = static_cast<int64_t>(writer.chains);
    }
    if (writer.writes_units()) {
        expected["units"] = static_cast<int64_t>(writer.units);
    }
    if (gpkg || m_layer == "unit_points") {
        expected["unit_points"] = static_cast<int64_t>(writer.points);
    }
    GDALDatasetH ds = std::exchange(g.ds, nullptr);
    close_and_check(ds, tmp, expected, trap, "export");
    sync_to_disk(tmp);
    std::error_code ec;
    fs::rename(tmp, out, ec);
    if (ec) {
        throw environment_error("export: cannot rename " + tmp.string() + " to " + m_output);
    }
    g.kept = true;
    sync_to_disk(out.parent_path());
    ctx.log.info("export: done");
    std::printf("export: %zu nodes, %zu chains, %zu unit polygons (%zu units not whole in their node, skipped), "
                "%zu unit points\n"
                "outputs in %s\n",
                nodes.size(), writer.chains, writer.units, writer.incomplete, writer.points, m_output.c_str());
    return exit_ok;
}

} // namespace tigerlod::exporter
