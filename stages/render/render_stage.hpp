#pragma once
/// @file render_stage.hpp
/// tigerlod-render: the paper's out-of-core renderer (Section 6), off-screen.
/// Draws a Data Tree along a camera path in core (everything loaded first)
/// or out of core through the reader runtime (a byte budget that also holds
/// the skeleton, an I/O thread, with or without prefetching), and writes per
/// frame its time and what it drew, a summary per mode (Section 7.3, Fig.
/// 16), and PNG views.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::render {

class RenderStage final : public Stage {
  public:
    static constexpr const char* name = "render";
    static constexpr const char* description =
        "Draw a Data Tree along a camera path, in core or out of core under a memory budget (the paper's\n"
        "renderer and its frame-time experiment), off-screen on OSMesa or EGL.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;
    std::string config_section() const override { return "render"; }
    std::vector<std::string> config_args(const std::filesystem::path& file) const override;

  private:
    std::string m_tree, m_output, m_path = "zoom", m_mode = "all", m_size = "1280x720", m_gl = "auto";
    int m_frames = 240, m_seed = 1, m_png_every = 0;
    double m_budget_mb = 25, m_disk_latency_ms = 5, m_disk_mbps = 50, m_pixel_error = 1, m_fps = 30;
    bool m_overwrite = false;
    uint32_t m_width = 1280, m_height = 720;
}; // class RenderStage

} // namespace tigerlod::render
