#pragma once
/// @file run_tool.hpp
/// For tests that run the stage binaries: a file's bytes, and one stage run
/// with its output in a log file.

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <sys/wait.h>

namespace tigerlod::testing {

/// The whole file, or "" if it cannot be read.
inline std::string slurp(const std::filesystem::path& p)
{
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Runs `tigerlod-TOOL ARGS` from `bin_dir`, stdout and stderr to `log`;
/// returns the exit code (-1 if it did not exit).
inline int run_tool(const std::filesystem::path& bin_dir, const std::string& tool, const std::string& args,
                    const std::filesystem::path& log)
{
    const std::string cmd = (bin_dir / ("tigerlod-" + tool)).string() + " " + args + " >" + log.string() + " 2>&1";
    const int status = std::system(cmd.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

} // namespace tigerlod::testing
