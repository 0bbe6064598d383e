#pragma once
/// @file serve_stage.hpp
/// tigerlod-serve: a small HTTP server over the reader runtime, for the
/// viewer in the browser and anyone who reads a tree over HTTP. What it
/// answers is serve::Site (site.hpp); this is the transport (cpp-httplib).

#include "core/stage.hpp"

#include <string>

namespace tigerlod::serve {

class ServeStage final : public Stage {
  public:
    static constexpr const char* name = "serve";
    static constexpr const char* description =
        "Serve a Data Tree over HTTP: the skeleton and its tiles at immutable URLs (ETags, ranges), the front\n"
        "for a view, decoded payloads and units through a bounded cache, the verify report, and the viewer.";
    void add_args(ArgSet& args) override;
    void initialize() override;
    int run(const StageContext& ctx) override;
    std::string help_notes() const override;
    std::vector<std::string> versions() const override;

  private:
    std::string m_tree;
    std::string m_host = "127.0.0.1";
    int m_port = 8765;
    std::string m_verify;
    std::string m_viewer;
    double m_cache_mb = 64;
}; // class ServeStage

} // namespace tigerlod::serve
