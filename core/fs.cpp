#include "core/fs.hpp"

#include "core/errors.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <mutex>
#include <optional>
#include <string>
#include <system_error>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace tigerlod {

namespace {

/// This host's short name, reduced to letters, digits and '-' (a '.' would
/// read as an extension, and the name is split at its last '-').
const std::string& host_name()
{
    static const std::string name = [] {
        char buf[256] = {};
        std::string h;
        if (::gethostname(buf, sizeof buf - 1) == 0) {
            h = buf;
        }
        h = h.substr(0, h.find('.'));
        for (char& c : h) {
            if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-') {
                c = '_';
            }
        }
        return h.empty() ? std::string("host") : h;
    }();
    return name;
}

std::string temp_id()
{
    return host_name() + "-" + std::to_string(::getpid());
}

/// A temporary name taken apart: `<base><kind><host>-<pid>[<ext>]`.
struct Leftover {
    std::string base, host;
    long pid = 0;
};

std::optional<Leftover> parse_leftover(const std::string& name)
{
    const size_t tmp = name.rfind(".tmp-"), old = name.rfind(".old-");
    const size_t at = tmp == std::string::npos ? old : old == std::string::npos ? tmp : std::max(tmp, old);
    if (at == std::string::npos || at == 0) {
        return std::nullopt;
    }
    std::string id = name.substr(at + 5);
    id = id.substr(0, id.find('.')); // an extension after the id
    const size_t dash = id.rfind('-');
    const std::string digits = dash == std::string::npos ? id : id.substr(dash + 1);
    if (digits.empty() || digits.size() > 9 ||
        !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) {
        return std::nullopt;
    }
    Leftover l;
    l.base = name.substr(0, at);
    // Names from before hosts were part of them: this host's.
    l.host = dash == std::string::npos ? host_name() : id.substr(0, dash);
    l.pid = std::stol(digits);
    return l.host.empty() ? std::nullopt : std::optional<Leftover>(l);
}

bool process_is_gone(long pid)
{
    if (pid <= 0 || pid == ::getpid()) {
        return false;
    }
    // EPERM: it exists, run by someone else.
    if (::kill(static_cast<pid_t>(pid), 0) != 0) {
        return errno == ESRCH;
    }
    // A zombie has exited; only its parent has not reaped it yet (or no one
    // will, where the parent died too and PID 1 does not reap).
    std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
    std::string line;
    if (!std::getline(stat, line)) {
        return false;
    }
    const size_t close = line.rfind(')'); // the command may hold spaces and ')'
    return close != std::string::npos && close + 2 < line.size() && (line[close + 2] == 'Z' || line[close + 2] == 'X');
}

bool durable()
{
    static const bool on = [] {
        const char* v = std::getenv("TIGERLOD_FSYNC");
        return v == nullptr || std::string_view(v) != "0";
    }();
    return on;
}

/// fsync, where the file system can: EINVAL and EROFS mean it has nothing to
/// make durable (pipes, special or read-only file systems).
bool sync_fd(int fd)
{
    return ::fsync(fd) == 0 || errno == EINVAL || errno == EROFS;
}

/// Write `data` to `file` and sync it to disk; messages name `name`. Throws
/// environment_error, after removing what was created if the write failed.
void write_to(const fs::path& file, const fs::path& name, std::string_view data)
{
    std::FILE* f = std::fopen(file.c_str(), "wb");
    if (f == nullptr) {
        throw environment_error(name.string() + ": cannot create: " + std::strerror(errno));
    }
    bool ok = std::fwrite(data.data(), 1, data.size(), f) == data.size() && std::fflush(f) == 0;
    ok = ok && (!durable() || sync_fd(::fileno(f)));
    const bool closed = std::fclose(f) == 0;
    if (!ok || !closed) {
        std::error_code ec;
        fs::remove(file, ec);
        throw environment_error(name.string() + ": write failed (disk full?)");
    }
}

} // namespace

void sync_to_disk(const fs::path& path)
{
    if (!durable()) {
        return;
    }
    const int fd = ::open(path.empty() ? "." : path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        throw environment_error(path.string() + ": cannot open to sync it to disk: " + std::strerror(errno));
    }
    const bool ok = sync_fd(fd);
    const int err = errno;
    ::close(fd);
    if (!ok) {
        throw environment_error(path.string() + ": cannot sync to disk: " + std::strerror(err));
    }
}

fs::path temp_sibling(const fs::path& path, std::string_view kind)
{
    return path.parent_path() / (path.filename().string() + std::string(kind) + temp_id());
}

fs::path temp_sibling_keeping_extension(const fs::path& path)
{
    return path.parent_path() / (path.stem().string() + ".tmp-" + temp_id() + path.extension().string());
}

std::vector<fs::path> remove_dead_leftovers(const fs::path& folder, std::string_view base)
{
    std::vector<fs::path> removed;
    std::error_code ec;
    std::vector<fs::path> found;
    // An empty folder is the current one, as a file name with no folder part has it.
    for (fs::directory_iterator it(folder.empty() ? fs::path(".") : folder, ec), end; !ec && it != end;
         it.increment(ec)) {
        found.push_back(it->path());
    }
    std::sort(found.begin(), found.end());
    for (const fs::path& p : found) {
        const auto l = parse_leftover(p.filename().string());
        if (!l || (!base.empty() && l->base != base) || l->host != host_name() || !process_is_gone(l->pid)) {
            continue;
        }
        std::error_code rm;
        fs::remove_all(p, rm);
        if (!rm) {
            removed.push_back(p);
        }
    }
    return removed;
}

void write_file_atomic_unsynced_folder(const fs::path& path, std::string_view data)
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

void write_file_atomic(const fs::path& path, std::string_view data)
{
    write_file_atomic_unsynced_folder(path, data);
    sync_to_disk(path.parent_path());
}

void write_file(const fs::path& path, std::string_view data)
{
    write_to(path, path, data);
}

std::string read_file(const fs::path& path)
{
    std::ifstream in(path, std::ios::binary);
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    if (!in || ec) {
        throw environment_error(path.string() +
                                ": cannot read: " + (ec ? ec.message() : std::string(std::strerror(errno))));
    }
    std::string data(static_cast<size_t>(size), '\0');
    in.read(data.data(), static_cast<std::streamsize>(data.size()));
    if (static_cast<uintmax_t>(in.gcount()) != size || in.peek() != std::char_traits<char>::eof()) {
        throw environment_error(path.string() + ": cannot read: it changed while being read");
    }
    return data;
}

bool write_file_if_changed(const fs::path& path, std::string_view data)
{
    std::error_code ec;
    if (fs::is_regular_file(path, ec) && fs::file_size(path, ec) == data.size() && !ec) {
        std::ifstream in(path, std::ios::binary);
        std::string old(data.size(), '\0');
        if (in.read(old.data(), static_cast<std::streamsize>(old.size())) && old == data) {
            return false;
        }
    }
    write_file_atomic_unsynced_folder(path, data);
    return true;
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
        // in is one of out's parents: the output would be written into an
        // input's folder (a level folder of an ingest output, a tree's
        // tiles/), replacing or adding to what the stage reads.
        std::error_code ec;
        if ((i == in.end() || (std::next(i) == in.end() && i->empty())) && fs::is_directory(in, ec)) {
            throw usage_error(output.string() + ": lies inside the input " + input.string() +
                              ", which this stage reads; write the output elsewhere");
        }
    }
}

bool is_stage_output(const fs::path& folder)
{
    // Each stage's output folder holds manifest.json (tigerlod.manifest/1),
    // render's summary.json (tigerlod.render-summary/1); read only their
    // "schema", small files, so a damaged or foreign file is simply "not".
    const std::pair<const char*, const char*> marks[] = {{"manifest.json", "tigerlod.manifest/"},
                                                         {"summary.json", "tigerlod.render-summary/"}};
    for (const auto& [file, schema] : marks) {
        std::error_code ec;
        const fs::path p = folder / file;
        if (!fs::is_regular_file(p, ec) || fs::file_size(p, ec) > (1U << 24)) {
            continue;
        }
        try {
            const auto doc = nlohmann::json::parse(read_file(p));
            if (doc.is_object() && doc.contains("schema") && doc["schema"].is_string() &&
                doc["schema"].get<std::string>().rfind(schema, 0) == 0) {
                return true;
            }
        } catch (const std::exception&) {
            // not JSON, or unreadable: not a stage's mark
        }
    }
    return false;
}

void refuse_to_replace_foreign(const fs::path& output)
{
    std::error_code ec;
    if (!fs::is_directory(output, ec)) {
        throw usage_error(output.string() + " exists and is not a folder: --overwrite replaces only a tigerlod "
                                            "stage's output folder or an empty folder; remove it yourself or write "
                                            "elsewhere");
    }
    if (is_stage_output(output)) {
        return;
    }
    std::vector<std::string> names;
    for (fs::directory_iterator it(output, ec), end; !ec && it != end; it.increment(ec)) {
        names.push_back(it->path().filename().string());
    }
    if (ec) {
        throw environment_error(output.string() + ": cannot list: " + ec.message());
    }
    if (names.empty()) {
        return;
    }
    std::sort(names.begin(), names.end());
    throw usage_error(output.string() + " is not a tigerlod stage's output (it holds " + names.front() +
                      (names.size() > 1 ? " and " + std::to_string(names.size() - 1) + " more" : std::string()) +
                      ", and no tigerlod manifest.json): --overwrite replaces only a stage's output or an empty "
                      "folder; remove it yourself or write elsewhere");
}

namespace {

bool same_bytes(const fs::path& a, const fs::path& b)
{
    std::ifstream fa(a, std::ios::binary);
    std::ifstream fb(b, std::ios::binary);
    std::vector<char> ba(1 << 16);
    std::vector<char> bb(1 << 16);
    while (fa && fb) {
        fa.read(ba.data(), std::streamsize(ba.size()));
        fb.read(bb.data(), std::streamsize(bb.size()));
        if (fa.gcount() != fb.gcount() || !std::equal(ba.begin(), ba.begin() + fa.gcount(), bb.begin())) {
            return false;
        }
    }
    return !fa.bad() && !fb.bad() && fa.eof() && fb.eof();
}

/// Each file `*<extension>` under `fresh` whose bytes equal the file at the
/// same place under `old_root` gets that file's modification time (nothing
/// on error: a time is only a hint to the engine).
void keep_times(const fs::path& fresh, const fs::path& old_root, const std::string& extension)
{
    std::error_code ec;
    if (!fs::is_directory(old_root, ec)) {
        return;
    }
    for (fs::recursive_directory_iterator it(fresh, ec), end; !ec && it != end; it.increment(ec)) {
        if (!it->is_regular_file(ec) || !it->path().filename().string().ends_with(extension)) {
            continue;
        }
        const fs::path old = old_root / fs::relative(it->path(), fresh, ec);
        std::error_code e2;
        if (fs::is_regular_file(old, e2) && fs::file_size(old, e2) == it->file_size(e2) && !e2 &&
            same_bytes(it->path(), old)) {
            const auto t = fs::last_write_time(old, e2);
            if (!e2) {
                fs::last_write_time(it->path(), t, e2);
            }
        }
    }
}

} // namespace

FolderLock::FolderLock(const fs::path& folder, const std::string& who, Mode mode)
{
    const int op = mode == Mode::shared ? LOCK_SH : LOCK_EX;
    for (;;) {
        std::error_code ec;
        fs::create_directories(folder, ec);
        if (ec) {
            throw environment_error(folder.string() + ": cannot create: " + ec.message());
        }
        m_fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (m_fd < 0) {
            throw environment_error(folder.string() + ": cannot open to lock it: " + std::strerror(errno));
        }
        if (::flock(m_fd, op | LOCK_NB) != 0) {
            if (const int err = errno; err == ENOLCK || err == ENOSYS || err == EOPNOTSUPP) {
                static std::once_flag said;
                std::call_once(said, [&] {
                    std::fprintf(stderr, "%s: %s cannot be locked (%s): concurrent runs on it are not guarded\n",
                                 who.c_str(), folder.c_str(), std::strerror(err));
                });
                ::close(m_fd);
                m_fd = -1;
                break;
            }
            if (errno != EWOULDBLOCK) {
                const int err = errno;
                ::close(m_fd);
                throw environment_error(folder.string() + ": cannot lock: " + std::strerror(err));
            }
            std::fprintf(stderr, "%s: another run is updating %s; waiting for it\n", who.c_str(), folder.c_str());
            int rc = 0;
            while ((rc = ::flock(m_fd, op)) != 0 && errno == EINTR) {
            }
            if (rc != 0) {
                const int err = errno;
                ::close(m_fd);
                throw environment_error(folder.string() + ": cannot lock: " + std::strerror(err));
            }
        }
        // Still the folder of that name? The run we waited for may have
        // removed it (a new output it could not finish).
        struct stat held {
        }, named{};
        if (::fstat(m_fd, &held) == 0 && ::stat(folder.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
            held.st_ino == named.st_ino) {
            break;
        }
        ::close(m_fd);
        m_fd = -1;
    }
    std::error_code ec;
    m_was_empty = fs::is_empty(folder, ec) && !ec;
}

FolderLock::~FolderLock()
{
    if (m_fd >= 0) {
        ::close(m_fd); // releases the flock
    }
}

OutputDir::OutputDir(fs::path final_path, bool overwrite, const std::vector<fs::path>& inputs)
    : m_final(std::move(final_path)), m_overwrite(overwrite)
{
    if (m_final.filename().empty()) {
        m_final = m_final.parent_path();
    }
    refuse_to_replace_inputs(m_final, inputs);
    if (fs::exists(m_final) && !overwrite) {
        throw usage_error(m_final.string() + " exists. Use --overwrite to replace it.");
    }
    if (std::error_code dir_ec; fs::is_directory(m_final, dir_ec)) {
        // Looked at under a shared lock: another run's swap into place
        // (which takes it alone) then cannot move the folder between the
        // read of its manifest and the listing, which would show the new
        // folder's files with no manifest read: "not a stage's output".
        const FolderLock look(m_final, program_invocation_short_name, FolderLock::Mode::shared);
        refuse_to_replace_foreign(m_final);
    } else if (fs::exists(m_final)) {
        refuse_to_replace_foreign(m_final);
    }
    m_tmp = temp_sibling(m_final, ".tmp-");
    m_removed = remove_dead_leftovers(m_final.parent_path(), m_final.filename().string());
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
    // Files were synced as they were written; their folders' entries now,
    // then the rename's.
    std::vector<fs::path> folders{m_tmp};
    for (fs::recursive_directory_iterator it(m_tmp, ec), end; !ec && it != end; it.increment(ec)) {
        if (it->is_directory(ec)) {
            folders.push_back(it->path());
        }
    }
    if (ec) {
        throw environment_error(m_tmp.string() + ": cannot list: " + ec.message());
    }
    for (const fs::path& f : folders) {
        sync_to_disk(f);
    }
    // The swap under an exclusive lock on the output: a run beside this one
    // on the same OUTPUT (another whole run, a --finish, partition jobs)
    // neither swaps at the same instant nor writes into the folder being
    // moved aside. The lock makes OUTPUT if missing (an empty folder, moved
    // aside and removed below like an old output; removed again if the swap
    // fails, fs::remove leaving it if another run filled it meanwhile).
    const bool existed = fs::exists(m_final);
    const FolderLock lock(m_final, program_invocation_short_name);
    try {
        swap_into_place();
    } catch (...) {
        if (!existed) {
            std::error_code ignored;
            fs::remove(m_final, ignored);
        }
        throw;
    }
}

void OutputDir::swap_into_place()
{
    std::error_code ec;
    if (!m_overwrite && !fs::is_empty(m_final, ec)) {
        throw usage_error(m_final.string() + " was made by another run meanwhile. Use --overwrite to replace it.");
    }
    if (!m_keep_times.empty()) {
        keep_times(m_tmp, m_final, m_keep_times);
    }
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
    sync_to_disk(m_final.parent_path());
    if (!old.empty()) {
        fs::remove_all(old, ec);
    }
}

} // namespace tigerlod
