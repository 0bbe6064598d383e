#pragma once
/// @file synth_stage.hpp
/// tigerlod-synth: a deterministic synthetic nation in TIGER/Line 2020
/// format, per county `tl_2020_SSCCC_edges.zip` and `tl_2020_SSCCC_faces.zip`,
/// planar on TIGER's 1e-6 degree lattice by construction (nation.hpp), with
/// a manifest of what it wrote.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::synth {

class SynthStage final : public Stage {
  public:
    static constexpr const char* name = "synth";
    static constexpr const char* description =
        "Write a synthetic nation in TIGER/Line 2020 format (EDGES and FACES per county), planar by\n"
        "construction, the same bytes for the same seed: test and benchmark data of any size.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "synth"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    std::string m_output;
    int m_seed = 1, m_states = 2, m_counties = 4, m_threads = 0, m_target = 1'000'000;
    double m_cell_m = 400;
    bool m_overwrite = false;
}; // class SynthStage

} // namespace tigerlod::synth
