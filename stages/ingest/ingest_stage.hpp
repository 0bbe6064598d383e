#pragma once
/// @file ingest_stage.hpp
/// tigerlod-ingest: raw TIGER/Line (or any polygon or line layer) to chain
/// stores, one per (semantic level, partition), with a report and manifest.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::ingest {

class IngestStage final : public Stage {
  public:
    static constexpr const char* name = "ingest";
    static constexpr const char* description =
        "Read TIGER/Line EDGES+FACES, polygon layers or line layers named by a config, snap, project,\n"
        "check the planar map with exact predicates, and write one chain store per (level, partition).";
    void add_args(ArgSet& args) override;
    int run(const StageContext& ctx) override;
    std::vector<std::string> versions() const override;
    std::string help_notes() const override;

  private:
    struct Resolved;
    int run_list(const StageContext& ctx, const Resolved& r);
    int run_read(const StageContext& ctx, const Resolved& r);
    int run_plan(const StageContext& ctx, const Resolved& r);
    int run_region(const StageContext& ctx, const Resolved& r);
    int run_finish(const StageContext& ctx, const Resolved& r);

  private:
    std::string m_config, m_output;
    bool m_overwrite = false;
    bool m_validate = false;
    bool m_whole_map = false;
    std::string m_parts;   ///< --parts DIR: the jobs' folder
    bool m_list = false;   ///< --list
    std::string m_read;    ///< --read NAME
    std::string m_select;  ///< --select PARTS
    bool m_plan = false;   ///< --plan
    std::string m_region;  ///< --region JOB
    bool m_finish = false; ///< --finish
    double m_halo_m = -1.0;
    double m_line_tile_km = -1.0;
    int m_threads = -1;
    int m_max_problem_samples = 200;
}; // class IngestStage

} // namespace tigerlod::ingest
