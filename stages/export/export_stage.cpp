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

} // namespace

int ExportStage::run(const StageContext& ctx)
{
    std::string error;
    const auto tree = reader::Tree::open(m_tree, error);
    if (!tree) {
        throw format_error(error);
    }
    const auto& s = tree->skeleton();
    std::vector<uint32_t> nodes;
    if (!m_level.empty()) {
        uint32_t level = UINT32_MAX;
        for (uint32_t l = 0; l < s.level_names.size(); ++l) {
            level = s.level_names[l] == m_level ? l : level;
        }
        if (level == UINT32_MAX) {
            throw usage_error("export: no level '" + m_level + "' in the tree");
        }
        for (uint32_t n = 0; n < s.nodes.size(); ++n) {
            if (s.nodes[n].level == level) {
                nodes.push_back(n);
            }
        }
    } else {
        nodes.push_back(view::find_node(s, m_node));
    }
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
    OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
    OSRImportFromEPSG(srs, 4269);
    OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
    OGRLayerH chains_layer = nullptr, units_layer = nullptr;
    if (gpkg || m_layer == "chains") {
        chains_layer = GDALDatasetCreateLayer(g.ds, "chains", srs, wkbLineString, nullptr);
        field(chains_layer, "chain_id", OFTInteger64);
        field(chains_layer, "node", OFTString);
        field(chains_layer, "left", OFTString);
        field(chains_layer, "right", OFTString);
        field(chains_layer, "class", OFTString);
        field(chains_layer, "lod", OFTInteger);
        field(chains_layer, "eps_m", OFTReal);
    }
    if (gpkg || m_layer == "units") {
        units_layer = GDALDatasetCreateLayer(g.ds, "units", srs, wkbMultiPolygon, nullptr);
        field(units_layer, "unit", OFTString);
        field(units_layer, "node", OFTString);
        field(units_layer, "lod", OFTInteger);
        field(units_layer, "eps_m", OFTReal);
    }
    OSRDestroySpatialReference(srs);
    auto to_line = [&](std::span<const GridPoint> pts) {
        OGRGeometryH line = OGR_G_CreateGeometry(wkbLineString);
        for (const auto& p : pts) {
            double lon = 0, lat = 0;
            proj.to_lonlat(p.x, p.y, lon, lat);
            OGR_G_AddPoint_2D(line, lon, lat);
        }
        return line;
    };
    std::set<uint64_t> written;
    // A unit shows in the map of the node that holds it and, in part, in its
    // neighbours' (across their outlines); whole there too when it is an
    // island in a neighbour, but without its own holes. Its own node holds
    // every chain of its boundary, any other node a subset: each unit is
    // written once, from the node with the most of its boundary chains (the
    // first of those).
    std::map<std::string, std::pair<size_t, uint32_t>> home; // unit -> (boundary chains, node)
    if (units_layer != nullptr && nodes.size() > 1) {
        for (uint32_t n : nodes) {
            datatree::ChainTable t;
            if (auto st = tree->read_table(n, t); !st.ok()) {
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
    }
    size_t nchains = 0, nunits = 0, incomplete = 0;
    for (uint32_t n : nodes) {
        const auto m = view::read_node(*tree, n, lod);
        const std::string code = n == 0 ? "root" : s.strings[s.nodes[n].code];
        if (chains_layer != nullptr) {
            for (size_t i = 0; i < m.table.chains.size(); ++i) {
                const auto& c = m.table.chains[i];
                if (!written.insert(c.id).second) {
                    continue; // a border shown by two nodes: once
                }
                OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(chains_layer));
                OGR_F_SetFieldInteger64(f, 0, static_cast<GIntBig>(c.id));
                OGR_F_SetFieldString(f, 1, code.c_str());
                OGR_F_SetFieldString(f, 2, m.table.strings[c.left].c_str());
                OGR_F_SetFieldString(f, 3, m.table.strings[c.right].c_str());
                OGR_F_SetFieldString(f, 4, m.table.strings[c.feature_class].c_str());
                OGR_F_SetFieldInteger(f, 5, m_lod);
                OGR_F_SetFieldDouble(f, 6, s.lod_eps_m[lod]);
                OGR_F_SetGeometryDirectly(f, to_line(m.geometry.chain(i)));
                if (OGR_L_CreateFeature(chains_layer, f) != OGRERR_NONE) {
                    OGR_F_Destroy(f);
                    throw environment_error("export: cannot write to " + tmp.string());
                }
                OGR_F_Destroy(f);
                ++nchains;
            }
        }
        if (units_layer != nullptr) {
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
                auto to_ring = [&](const std::vector<GridPoint>& pts) {
                    auto* ring = new OGRLinearRing;
                    for (const auto& p : pts) {
                        double lon = 0, lat = 0;
                        proj.to_lonlat(p.x, p.y, lon, lat);
                        ring->addPoint(lon, lat);
                    }
                    return ring;
                };
                auto* polygons = new OGRMultiPolygon;
                for (const auto& up : unit.polygons) {
                    auto* poly = new OGRPolygon;
                    poly->addRingDirectly(to_ring(up.outer));
                    for (const auto& h : up.holes) {
                        poly->addRingDirectly(to_ring(h));
                    }
                    polygons->addGeometryDirectly(poly);
                }
                OGRGeometryH multi = OGRGeometry::ToHandle(polygons);
                OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(units_layer));
                OGR_F_SetFieldString(f, 0, m.table.strings[u].c_str());
                OGR_F_SetFieldString(f, 1, code.c_str());
                OGR_F_SetFieldInteger(f, 2, m_lod);
                OGR_F_SetFieldDouble(f, 3, s.lod_eps_m[lod]);
                OGR_F_SetGeometryDirectly(f, multi);
                if (OGR_L_CreateFeature(units_layer, f) != OGRERR_NONE) {
                    OGR_F_Destroy(f);
                    throw environment_error("export: cannot write to " + tmp.string());
                }
                OGR_F_Destroy(f);
                ++nunits;
            }
        }
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
                nodes.size(), nchains, nunits, incomplete, m_output.c_str());
    return exit_ok;
}

} // namespace tigerlod::exporter
