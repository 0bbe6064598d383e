#include "core/log.hpp"

#include <cstdio>
#include <string>
#include <unistd.h>

namespace tigerlod {

double Log::elapsed_s() const
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
}

namespace {

/// Resident memory of this process in MiB, or -1 where /proc does not say.
long resident_mib()
{
    std::FILE* f = std::fopen("/proc/self/statm", "r");
    if (f == nullptr) {
        return -1;
    }
    long size = 0, resident = -1;
    if (std::fscanf(f, "%ld %ld", &size, &resident) != 2) {
        resident = -1;
    }
    std::fclose(f);
    return resident < 0 ? -1
                        : static_cast<long>(static_cast<double>(resident) * double(sysconf(_SC_PAGESIZE)) / 1048576.0);
}

} // namespace

void Log::info(std::string_view message) const
{
    if (!m_verbose) {
        return;
    }
    const auto s = static_cast<long>(elapsed_s());
    const long mib = resident_mib();
    if (mib >= 0) {
        std::fprintf(stderr, "[%2ld:%02ld %5ld MiB] %.*s\n", s / 60, s % 60, mib, static_cast<int>(message.size()),
                     message.data());
    } else {
        std::fprintf(stderr, "[%2ld:%02ld] %.*s\n", s / 60, s % 60, static_cast<int>(message.size()), message.data());
    }
}

} // namespace tigerlod
