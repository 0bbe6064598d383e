#pragma once
/// @file log.hpp
/// Verbose output to stderr, each line prefixed with the elapsed time and the
/// process's resident memory, `[ m:ss  NNN MiB]` (the memory where /proc gives
/// it). Silent unless enabled, so a successful run writes nothing to stderr by
/// default.

#include <chrono>
#include <string_view>

namespace tigerlod {

class Log {
  public:
    Log() : m_start(std::chrono::steady_clock::now()) {}
    void set_verbose(bool verbose) noexcept { m_verbose = verbose; }
    bool verbose() const noexcept { return m_verbose; }
    /// Print one line when verbose.
    void info(std::string_view message) const;
    /// Seconds since this log was created.
    double elapsed_s() const;

  private:
    std::chrono::steady_clock::time_point m_start;
    bool m_verbose = false;
}; // class Log

} // namespace tigerlod
