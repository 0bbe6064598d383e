#pragma once
/// @file verify_stage.hpp
/// tigerlod-verify: exact verification of a Data Tree against the original
/// chain stores; a JSON report, a GeoPackage of the violations, a summary.

#include "core/stage.hpp"

#include <filesystem>
#include <string>

namespace tigerlod::reader {
class Tree;
}

namespace tigerlod::verify {

struct Report;

/// violations.gpkg: the report's items as points in NAD83 lon/lat (layer
/// `violations`: kind, level, lod, node, chains, detail), and with `tree`
/// their chains as the tree holds them at the item's LOD, in the tree's own
/// projection where its segments are straight (layer `violation_chains`:
/// violation, the point's fid; kind, level, lod, eps_m, node, chain_id, and
/// the unit codes left and right). An item of a node that does not decode
/// has no lines. Throws environment_error if the file cannot be written
/// whole.
void write_violations_gpkg(const std::filesystem::path& path, const Report& r, const reader::Tree* tree);

class VerifyStage final : public Stage {
  public:
    static constexpr const char* name = "verify";
    static constexpr const char* description =
        "Verify a Data Tree as a reader decodes it against the original chain stores, exactly: subsequences,\n"
        "eps, no crossings or overlaps within and across nodes, rings, internal and user points, unit\n"
        "polygons, skeleton consistency. Exit 0 when clean, 1 when any violation is found.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "verify"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    int run_partitions(const StageContext& ctx);

    std::string m_tree, m_original, m_output, m_compare;
    std::string m_partitions, m_plan, m_report, m_shares;
    bool m_finish = false;
    bool m_cgal = false;
    bool m_overwrite = false;
    int m_threads = 0;
    int m_max_items = 10000;
}; // class VerifyStage

} // namespace tigerlod::verify
