#pragma once
/// @file dump_stage.hpp
/// tigerlod-dump: print any tigerlod file as canonical sorted text: a chain
/// store, a Data Tree's skeleton, or one node's payload (text or GeoJSON).

#include "core/stage.hpp"

#include <string>

namespace tigerlod::dump {

class DumpStage final : public Stage {
  public:
    static constexpr const char* name = "dump";
    static constexpr const char* description =
        "Print a tigerlod file on stdout: a chain store (.tlc) as canonical sorted text, a Data Tree\n"
        "(its folder or skeleton.tls) as its skeleton, or with --node one node's map at one LOD.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;

  private:
    std::string m_input;
    std::string m_node;
    int m_lod = 0;
    bool m_geojson = false;
}; // class DumpStage

} // namespace tigerlod::dump
