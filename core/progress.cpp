#include "core/progress.hpp"

#include "core/errors.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <unistd.h>

namespace tigerlod {

ProgressMode parse_progress_mode(const std::string& text)
{
    if (text == "auto") {
        return ::isatty(STDERR_FILENO) != 0 ? ProgressMode::bar : ProgressMode::none;
    }
    if (text == "bar") {
        return ProgressMode::bar;
    }
    if (text == "json") {
        return ProgressMode::json;
    }
    if (text == "none") {
        return ProgressMode::none;
    }
    throw usage_error("option '--progress' must be auto, bar, json or none, not '" + text + "'");
}

Progress::Progress(ProgressMode mode, std::string stage, size_t total, std::string unit, std::string amount_unit)
    : m_mode(mode), m_stage(std::move(stage)), m_unit(std::move(unit)), m_amount_unit(std::move(amount_unit)),
      m_total(total), m_t0(std::chrono::steady_clock::now())
{
}

void Progress::advance(uint64_t amount)
{
    const size_t done = ++m_done;
    const uint64_t total_amount = m_amount += amount;
    if (m_mode == ProgressMode::none) {
        return;
    }
    std::lock_guard lock(m_mutex);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_t0).count();
    if (done < m_total && s - m_last < 0.25) {
        return;
    }
    m_last = s;
    const double eta = done > 0 ? s * double(m_total - std::min(done, m_total)) / double(done) : 0;
    if (m_mode == ProgressMode::json) {
        nlohmann::ordered_json j{{"stage", m_stage},       {"done", done},
                                 {"total", m_total},       {"unit", m_unit},
                                 {"amount", total_amount}, {"amount_unit", m_amount_unit},
                                 {"seconds", s},           {"eta_s", eta}};
        std::fprintf(stderr, "%s\n", j.dump().c_str());
        std::fflush(stderr);
        return;
    }
    std::string rate;
    if (!m_amount_unit.empty()) {
        char buf[64];
        std::snprintf(buf, sizeof buf, ", %.2f M %s/s", double(total_amount) / std::max(s, 1e-9) / 1e6,
                      m_amount_unit.c_str());
        rate = buf;
    }
    std::fprintf(stderr, "\r%s: %5.1f%% %zu/%zu %s%s, ETA %.0f s ", m_stage.c_str(),
                 m_total ? 100.0 * double(done) / double(m_total) : 100.0, done, m_total, m_unit.c_str(), rate.c_str(),
                 eta);
    if (done >= m_total) {
        std::fputc('\n', stderr);
    }
    std::fflush(stderr);
}

} // namespace tigerlod
