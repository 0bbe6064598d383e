#pragma once
/// @file pack_stage.hpp
/// tigerlod-pack: build or update the Data Tree from the original and
/// simplified chain stores.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::pack {

class PackStage final : public Stage {
  public:
    static constexpr const char* name = "pack";
    static constexpr const char* description =
        "Pack the original and simplified chain stores into a Data Tree: a skeleton and tile files of\n"
        "Draco-compressed payloads, one node per unit with the map of its child units at every LOD.\n"
        "An existing tree in OUTPUT is updated: unchanged tiles are kept, the skeleton is swapped atomically.\n"
        "As the workflow's jobs: --plan, then --partitions jobs writing part files, then --finish.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "pack"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    /// usage_error unless OUTPUT is missing, a Data Tree, or what a killed
    /// first pack left (only pack's own files); under the tree's lock.
    void refuse_foreign_output() const;
    int run_plan(const StageContext& ctx);
    int run_partitions(const StageContext& ctx);

    std::string m_original, m_simplified, m_output;
    std::string m_parts, m_partitions, m_report, m_tolerances;
    bool m_plan = false, m_finish = false;
    double m_tile_mb = 4;
    int m_draco_speed = 0;
    int m_threads = 0;
}; // class PackStage

} // namespace tigerlod::pack
