#pragma once
/// @file color_stage.hpp
/// tigerlod-color: render tiles and stencil classes for every chain store at
/// every tolerance of the ladder.

#include "core/stage.hpp"
#include "simplification/stage_options.hpp"

namespace tigerlod::color {

class ColorStage final : public Stage {
  public:
    static constexpr const char* name = "color";
    static constexpr const char* description =
        "Colour the chains of each chain store into stencil classes 1..255 per render tile and tolerance,\n"
        "so that chains whose tolerance neighbourhoods can overlap never share a class; split tiles that need more.";
    void add_args(ArgSet& args) override { m_common.add(args); }
    void initialize() override { m_common.initialize(name); }
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "simplify"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    simplify::CommonOptions m_common;
}; // class ColorStage

} // namespace tigerlod::color
