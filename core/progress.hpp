#pragma once
/// @file progress.hpp
/// A stage's progress on stderr, as every stage's `--progress MODE` asks:
/// `bar`, a line rewritten in place (percent, items, rate, ETA); `json`, one
/// object a line for an engine (`{"stage", "done", "total", "unit",
/// "amount", "amount_unit", "seconds", "eta_s"}`); `none`; `auto` (the
/// default), a bar when stderr is a terminal, else nothing. At most four
/// updates a second, and always the last.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace tigerlod {

enum class ProgressMode { none, bar, json };

/// Parse `auto`, `bar`, `json` or `none` (auto resolved against stderr);
/// throws usage_error otherwise.
ProgressMode parse_progress_mode(const std::string& text);

class Progress {
  public:
    /// `total` items of `unit` ("stores"); `amount_unit` names what
    /// advance()'s second argument counts ("vertices"), for the rate.
    Progress(ProgressMode mode, std::string stage, size_t total, std::string unit, std::string amount_unit = "");
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;
    /// One item done, `amount` of the amount unit with it. Thread-safe.
    void advance(uint64_t amount = 0);

  private:
    ProgressMode m_mode;
    std::string m_stage, m_unit, m_amount_unit;
    size_t m_total;
    std::atomic<size_t> m_done{0};
    std::atomic<uint64_t> m_amount{0};
    std::chrono::steady_clock::time_point m_t0;
    std::mutex m_mutex;
    double m_last = -1;
}; // class Progress

} // namespace tigerlod
