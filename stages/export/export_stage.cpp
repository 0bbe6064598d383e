#include "stages/export/export_stage.hpp"

#include "core/fs.hpp"
#include "reader/tree_view.hpp"

#include <gdal.h>
#include <ogr_api.h>
#include <ogr_geometry.h>
#include <ogr_srs_api.h>

#include <filesystem>
#include <map>
#include <set>

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
    args.add("layer", &m_layer, "for GeoJSON, which layer: chains or units", "NAME");
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
    if (m_layer != "chains" && m_layer != "units") {
        throw usage_error("export: option '--layer' must be chains or units");
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
           "there; every unit is complete in the node of its parent unit.\n"
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

/// The layers of the file being written, and what went into them.
class Writer {
  public:
    Writer(GDALDatasetH ds, bool with_chains, bool with_units, const Projection& proj, int lod, double eps_m,
           fs::path tmp)
        : m_proj(proj), m_lod(lod), m_eps_m(eps_m), m_tmp(std::move(tmp))
    {
        OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
        OSRImportFromEPSG(srs, 4269);
        OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
        if (with_chains) {
            m_chains = GDALDatasetCreateLayer(ds, "chains", srs, wkbLineString, nullptr);
            field(m_chains, "chain_id", OFTInteger64);
            field(m_chains, "node", OFTString);
            field(m_chains, "left", OFTString);
            field(m_chains, "right", OFTString);
            field(m_chains, "class", OFTString);
            field(m_chains, "lod", OFTInteger);
            field(m_chains, "eps_m", OFTReal);
        }
        if (with_units) {
            m_units = GDALDatasetCreateLayer(ds, "units", srs, wkbMultiPolygon, nullptr);
            field(m_units, "unit", OFTString);
            field(m_units, "node", OFTString);
            field(m_units, "lod", OFTInteger);
            field(m_units, "eps_m", OFTReal);
        }
        OSRDestroySpatialReference(srs);
    }
    bool writes_units() const { return m_units != nullptr; }

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
            OGR_F_SetFieldDouble(f, 6, m_eps_m);
            OGR_F_SetGeometryDirectly(f, to_line(m.geometry.chain(i)));
            create(m_chains, f);
            ++chains;
        }
    }

    /// The node's units whose home it is, as valid multipolygons; a unit
    /// whose boundary does not close here is counted in `incomplete`.
    void write_units(const view::NodeMap& m, const std::string& code, uint32_t n,
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
            OGR_F_SetGeometryDirectly(f, OGRGeometry::ToHandle(polygons));
            create(m_units, f);
            ++units;
        }
    }

    size_t chains = 0, units = 0, incomplete = 0;

  private:
    OGRGeometryH to_line(std::span<const GridPoint> pts) const
    {
        OGRGeometryH line = OGR_G_CreateGeometry(wkbLineString);
        for (const auto& p : pts) {
            double lon = 0, lat = 0;
            m_proj.to_lonlat(p.x, p.y, lon, lat);
            OGR_G_AddPoint_2D(line, lon, lat);
        }
        return line;
    }
    OGRLinearRing* to_ring(const std::vector<GridPoint>& pts) const
    {
        auto* ring = new OGRLinearRing;
        for (const auto& p : pts) {
            double lon = 0, lat = 0;
            m_proj.to_lonlat(p.x, p.y, lon, lat);
            ring->addPoint(lon, lat);
        }
        return ring;
    }
    /// Write feature `f` to `layer` and destroy it.
    void create(OGRLayerH layer, OGRFeatureH f) const
    {
        const bool ok = OGR_L_CreateFeature(layer, f) == OGRERR_NONE;
        OGR_F_Destroy(f);
        if (!ok) {
            throw environment_error("export: cannot write to " + m_tmp.string());
        }
    }

    const Projection& m_proj;
    const int m_lod;
    const double m_eps_m;
    const fs::path m_tmp;
    OGRLayerH m_chains = nullptr, m_units = nullptr;
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
    GDALDriverH driver = GDALGetDriverByName(gpkg ? "GPKG" : "GeoJSON");
    TempDataset g;
    g.path = tmp;
    g.ds = GDALCreate(driver, tmp.c_str(), 0, 0, 0, GDT_Unknown, nullptr);
    if (g.ds == nullptr) {
        throw environment_error("export: cannot create " + tmp.string() + ": " + CPLGetLastErrorMsg());
    }
    Writer writer(g.ds, gpkg || m_layer == "chains", gpkg || m_layer == "units", proj, m_lod, s.lod_eps_m[lod], tmp);
    const auto home =
        writer.writes_units() ? home_nodes(*tree, nodes) : std::map<std::string, std::pair<size_t, uint32_t>>{};
    for (uint32_t n : nodes) {
        const auto m = view::read_node(*tree, n, lod);
        const std::string code = n == 0 ? "root" : s.strings[s.nodes[n].code];
        writer.write_chains(m, code);
        writer.write_units(m, code, n, home);
    }
    GDALClose(g.ds);
    g.ds = nullptr;
    sync_to_disk(tmp);
    std::error_code ec;
    fs::rename(tmp, out, ec);
    if (ec) {
        throw environment_error("export: cannot rename " + tmp.string() + " to " + m_output);
    }
    g.kept = true;
    sync_to_disk(out.parent_path());
    ctx.log.info("export: done");
    std::printf("export: %zu nodes, %zu chains, %zu unit polygons (%zu units not whole in their node, skipped)\n"
                "outputs in %s\n",
                nodes.size(), writer.chains, writer.units, writer.incomplete, m_output.c_str());
    return exit_ok;
}

} // namespace tigerlod::exporter
