#pragma once
/// @file export_stage.hpp
/// tigerlod-export: write a node's map, or a whole level, at one LOD to
/// GeoPackage or GeoJSON in lon/lat, with the unit codes: the chains, and the
/// units' polygons rebuilt from them, for QGIS.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::exporter {

class ExportStage final : public Stage {
  public:
    static constexpr const char* name = "export";
    static constexpr const char* description =
        "Export chains and rebuilt unit polygons of a Data Tree at one LOD to GeoPackage (.gpkg, layers\n"
        "'chains' and 'units') or GeoJSON (.geojson, one layer: --layer), in lon/lat (NAD83).";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;

  private:
    std::string m_tree, m_output, m_node, m_level, m_layer = "chains";
    int m_lod = 0;
    bool m_overwrite = false;
}; // class ExportStage

} // namespace tigerlod::exporter
