#include "core/log.hpp"

#include <cstdio>
#include <string>

namespace tigerlod {

double Log::elapsed_s() const
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
}

void Log::info(std::string_view message) const
{
    if (!m_verbose) {
        return;
    }
    const auto s = static_cast<long>(elapsed_s());
    std::fprintf(stderr, "[%2ld:%02ld] %.*s\n", s / 60, s % 60, static_cast<int>(message.size()), message.data());
}

} // namespace tigerlod
