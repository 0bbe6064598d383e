#pragma once
/// @file export_stage.hpp
/// tigerlod-export: write a node's map, or a whole level, at one LOD to
/// GeoPackage or GeoJSON with the unit codes: the chains, and the units'
/// polygons rebuilt from them, for QGIS. In the tree's own projection by
/// default (its CRS named: EPSG:5070 for the default CONUS Albers), so a
/// segment is straight there as it is in the tree; in lon/lat with --crs
/// lonlat, each segment densified until the lon/lat line stays within a
/// stated fraction of the LOD's eps of it.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::exporter {

class ExportStage final : public Stage {
  public:
    static constexpr const char* name = "export";
    static constexpr const char* description =
        "Export chains and rebuilt unit polygons of a Data Tree at one LOD to GeoPackage (.gpkg, layers\n"
        "'chains' and 'units') or GeoJSON (.geojson, one layer: --layer), in the tree's projection or in\n"
        "lon/lat (--crs lonlat, densified so that no segment bows by more than --max-bow of its eps).";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;

  private:
    std::string m_tree, m_output, m_node, m_level, m_layer = "chains", m_crs = "tree";
    int m_lod = 0;
    double m_max_bow = 0.01;
    bool m_overwrite = false;
}; // class ExportStage

} // namespace tigerlod::exporter
