#include "core/fs.hpp"

#include "core/errors.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <string>
#include <system_error>
#include <unistd.h>

namespace fs = std::filesystem;

namespace tigerlod {

namespace {

fs::path temp_sibling(const fs::path& path, const char* tag)
{
    return path.parent_path() / (path.filename().string() + tag + std::to_string(::getpid()));
}

/// Write `data` to `file`; messages name `name`. Throws environment_error,
/// after removing what was created if the write failed.
void write_to(const fs::path& file, const fs::path& name, std::string_view data)
{
    std::FILE* f = std::fopen(file.c_str(), "wb");
    if (f == nullptr) {
        throw environment_error(name.string() + ": cannot create: " + std::strerror(errno));
    }
    const bool ok = std::fwrite(data.data(), 1, data.size(), f) == data.size();
    const bool closed = std::fclose(f) == 0;
    if (!ok || !closed) {
        std::error_code ec;
        fs::remove(file, ec);
        throw environment_error(name.string() + ": write failed (disk full?)");
    }
}

} // namespace

void write_file_atomic(const fs::path& path, std::string_view data)
{
    const fs::path tmp = temp_sibling(path, ".tmp-");
    write_to(tmp, path, data);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        throw environment_error(path.string() + ": cannot rename into place: " + ec.message());
    }
}

void write_file(const fs::path& path, std::string_view data)
{
    write_to(path, path, data);
}

void refuse_to_replace_inputs(const fs::path& output, const std::vector<fs::path>& inputs)
{
    // Links resolved where the path can be read; lexically otherwise (an
    // empty result would compare as a parent of everything).
    auto resolve = [](const fs::path& p) {
        std::error_code ec;
        const fs::path abs = fs::absolute(p, ec).lexically_normal();
        const fs::path real = fs::weakly_canonical(abs, ec);
        return ec || real.empty() ? abs : real;
    };
    const fs::path out = resolve(output);
    for (const fs::path& input : inputs) {
        if (input.empty()) {
            continue;
        }
        const fs::path in = resolve(input);
        // out is in itself, or one of its parents.
        auto o = out.begin();
        auto i = in.begin();
        for (; o != out.end() && i != in.end() && *o == *i; ++o, ++i) {
        }
        if (o == out.end() || (std::next(o) == out.end() && o->empty())) {
            throw usage_error(output.string() + ": " +
                              (i == in.end() ? std::string("is the input ") : std::string("holds the input ")) +
                              input.string() + ", which this stage reads; write the output elsewhere");
        }
    }
}

OutputDir::OutputDir(fs::path final_path, bool overwrite, const std::vector<fs::path>& inputs)
    : m_final(std::move(final_path))
{
    if (m_final.filename().empty()) {
        m_final = m_final.parent_path();
    }
    refuse_to_replace_inputs(m_final, inputs);
    if (fs::exists(m_final) && !overwrite) {
        throw usage_error(m_final.string() + " exists. Use --overwrite to replace it.");
    }
    m_tmp = temp_sibling(m_final, ".tmp-");
    std::error_code ec;
    fs::remove_all(m_tmp, ec);
    fs::create_directories(m_tmp, ec);
    if (ec) {
        throw environment_error(m_tmp.string() + ": cannot create folder: " + ec.message());
    }
}

OutputDir::~OutputDir()
{
    if (!m_committed) {
        std::error_code ec;
        fs::remove_all(m_tmp, ec);
    }
}

void OutputDir::commit()
{
    std::error_code ec;
    fs::path old;
    if (fs::exists(m_final)) {
        old = temp_sibling(m_final, ".old-");
        fs::remove_all(old, ec);
        fs::rename(m_final, old, ec);
        if (ec) {
            throw environment_error(m_final.string() + ": cannot move the old output aside: " + ec.message());
        }
    }
    fs::rename(m_tmp, m_final, ec);
    if (ec) {
        if (!old.empty()) {
            std::error_code ignored;
            fs::rename(old, m_final, ignored);
        }
        throw environment_error(m_final.string() + ": cannot rename into place: " + ec.message());
    }
    m_committed = true;
    if (!old.empty()) {
        fs::remove_all(old, ec);
    }
}

} // namespace tigerlod
