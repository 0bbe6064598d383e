#pragma once
/// @file dump_stage.hpp
/// tigerlod-dump: print any tigerlod file as canonical sorted text.

#include "core/stage.hpp"

#include <string>

namespace tigerlod::dump {

class DumpStage final : public Stage {
  public:
    static constexpr const char* name = "dump";
    static constexpr const char* description =
        "Print a tigerlod file (chain store .tlc) as canonical sorted text on stdout.";
    void add_args(ArgSet& args) override;
    int run(const StageContext& ctx) override;

  private:
    std::string m_input;
}; // class DumpStage

} // namespace tigerlod::dump
