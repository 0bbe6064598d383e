#pragma once
/// @file simplify_stage.hpp
/// tigerlod-simplify: every chain store of an ingest output at every
/// tolerance of the ladder: the eps-Voronoi raster on OpenGL where a GPU draws
/// it, the exact rules on the CPU elsewhere (`--shortcut-test auto`).

#include "core/stage.hpp"
#include "gl/context.hpp"
#include "simplification/simplifier.hpp"
#include "simplification/stage_options.hpp"
#include "simplification/stage_output.hpp"

#include <memory>
#include <optional>

namespace tigerlod::simplify {

class SimplifyStage final : public Stage {
  public:
    static constexpr const char* name = "simplify";
    static constexpr const char* description =
        "Simplify chain stores at a ladder of tolerances, with the eps-Voronoi diagram drawn by OpenGL where a\n"
        "GPU draws it and the exact rules elsewhere:\n"
        "every chain stays within eps of its original, no two chains cross, every constraint point keeps its side.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "simplify"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    /// One store at every tolerance of the ladder, written to `out`; its
    /// statistics per tolerance.
    std::vector<ToleranceStats> simplify_one(const StoreFile& sf, const SimplifyOptions& so, Raster* raster,
                                             const StageOutput& out) const;
    /// Every store, several at once, each on a worker with its share of the
    /// threads, the GL work on this thread; the statistics summed per
    /// tolerance in store order (the same whatever the threads).
    std::vector<ToleranceStats> simplify_stores(const std::vector<StoreFile>& stores, const StageOutput& out,
                                                Raster* raster, bool llvmpipe_inline, const StageContext& ctx) const;
    /// simplify-report.json.
    nlohmann::ordered_json report_json(size_t stores, const std::string& gl, const std::vector<ToleranceStats>& totals,
                                       double seconds) const;
    /// manifest.json: the inputs' digests and the options, the user points themselves included.
    nlohmann::ordered_json manifest_json(const Manifest& ingest, const std::optional<Manifest>& colored,
                                         const std::string& points_sha256) const;
    /// The lines on stdout.
    void print_summary(size_t stores, const std::string& gl, const std::vector<ToleranceStats>& totals,
                       double seconds) const;

    /// The shortcut test a run makes, and why: --shortcut-test itself, or
    /// what `auto` took (voronoi with --colors, or where a GPU draws it
    /// through EGL, whose context `gpu` then holds; exact elsewhere).
    struct ShortcutTest {
        std::string name, why;
    };
    ShortcutTest resolve_shortcut_test(std::unique_ptr<gl::Context>& gpu) const;

    CommonOptions m_common;
    std::string m_points;
    std::string m_shortcut_test = "auto";
    ShortcutTest m_test; ///< what run() resolved m_shortcut_test to
    std::string m_compliance = "ssbo";
    std::string m_gl = "auto";
    std::string m_colors;
    bool m_lazy = false; ///< the default, said explicitly
    bool m_exhaustive = false;
    bool m_no_point_constraints = false;
    int m_max_reach = 0;
    int m_end_sample = 256;
    int m_window_pixels = 1024;
}; // class SimplifyStage

} // namespace tigerlod::simplify
