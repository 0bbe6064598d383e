#include "simplification/stage_output.hpp"

#include "core/errors.hpp"
#include "core/manifest.hpp"
#include "core/partitions.hpp"

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace tigerlod::simplify {

std::vector<StoreFile> select_stores(const std::vector<StoreFile>& all, const std::string& spec, const fs::path& input)
{
    std::vector<std::pair<std::string, std::string>> names;
    for (const auto& s : all) {
        names.emplace_back(s.level, s.partition);
    }
    const std::vector<bool> chosen = select_partitions(names, spec, input);
    std::vector<StoreFile> out;
    for (size_t i = 0; i < all.size(); ++i) {
        if (chosen[i]) {
            out.push_back(all[i]);
        }
    }
    return out;
}

StageOutput::StageOutput(const CommonOptions& options, const std::vector<fs::path>& reads, const std::string& stage)
    : m_options(options), m_stage(stage)
{
    if (!options.in_place()) {
        m_whole.emplace(options.output, options.overwrite, reads);
        m_removed = m_whole->removed_leftovers();
        return;
    }
    m_dir = options.output;
    refuse_to_replace_inputs(m_dir, reads);
    m_lock.emplace(m_dir, "tigerlod-" + stage, options.finish ? FolderLock::Mode::exclusive : FolderLock::Mode::shared);
    std::error_code ec;
    if (fs::exists(m_dir / "manifest.json", ec)) {
        try {
            (void)read_manifest(m_dir, stage);
        } catch (const input_error& e) {
            throw usage_error(std::string(e.what()) + "; --partitions and --finish update a tigerlod-" + stage +
                              " output in place, and nothing else");
        }
    }
    // A folder without a manifest is taken as a new output: jobs of one run
    // start at once, and the first to finish writes the manifest. Nothing
    // but the partitions' files is written there, and --finish removes only
    // the stage's own files (eps-* folders).
    fs::create_directories(m_dir, ec);
    if (ec) {
        throw environment_error(m_dir.string() + ": cannot create folder: " + ec.message());
    }
}

const fs::path& StageOutput::path() const noexcept
{
    return m_whole ? m_whole->path() : m_dir;
}

const std::vector<fs::path>& StageOutput::removed_leftovers() const noexcept
{
    return m_removed;
}

void StageOutput::write(const fs::path& relative, std::string_view data) const
{
    const fs::path file = path() / relative;
    const fs::path folder = file.parent_path();
    if (m_whole) {
        fs::create_directories(folder);
        write_file(file, data); // inside the output folder, renamed into place whole
        return;
    }
    {
        std::lock_guard lock(m_mutex);
        if (m_folders.insert(folder).second) {
            fs::create_directories(folder);
            auto removed = remove_dead_leftovers(folder);
            m_removed.insert(m_removed.end(), removed.begin(), removed.end());
        }
    }
    write_file_atomic_unsynced_folder(file, data); // the folders are synced once, at commit
}

void StageOutput::write_report(std::string_view data) const
{
    if (m_whole) {
        write_file_atomic(path() / (m_stage + "-report.json"), data);
    } else if (!m_options.report.empty()) {
        const fs::path file(m_options.report);
        if (file.has_parent_path()) {
            fs::create_directories(file.parent_path());
        }
        write_file_atomic(file, data);
    }
}

void StageOutput::commit(std::string_view manifest)
{
    // In place, the renames of this run's files, then the manifest. Every
    // job of a run writes the same manifest (it holds the options and the
    // input's digest, never the partitions): the last rename wins with the
    // bytes of any.
    for (const fs::path& folder : m_folders) {
        sync_to_disk(folder);
    }
    write_file_atomic(path() / "manifest.json", manifest);
    if (m_whole) {
        m_whole->commit();
    }
}

std::vector<fs::path> finish_in_place(const fs::path& out, const std::vector<StoreFile>& stores,
                                      const std::vector<double>& tolerances, const std::string& extension)
{
    std::set<std::string> ladder;
    for (const double eps : tolerances) {
        ladder.insert(tolerance_dir(eps));
        for (const auto& sf : stores) {
            const fs::path file = out / tolerance_dir(eps) / sf.level / (sf.partition + extension);
            std::error_code ec;
            if (!fs::is_regular_file(file, ec)) {
                throw usage_error(file.string() + " is missing: the job of " + sf.level + "/" + sf.partition +
                                  " has not run at this ladder; run the stage with --partitions " + sf.level + "/" +
                                  sf.partition + " first");
            }
        }
    }
    std::set<std::string> levels;
    std::set<std::pair<std::string, std::string>> owned;
    for (const auto& sf : stores) {
        levels.insert(sf.level);
        owned.insert({sf.level, sf.partition + extension});
    }
    std::vector<fs::path> removed;
    auto remove = [&](const fs::path& p) {
        std::error_code ec;
        fs::remove_all(p, ec);
        removed.push_back(p);
    };
    auto removed_leftovers = remove_dead_leftovers(out);
    removed.insert(removed.end(), removed_leftovers.begin(), removed_leftovers.end());
    auto listing = [](const fs::path& dir) {
        std::vector<fs::path> entries;
        for (const auto& e : fs::directory_iterator(dir)) {
            entries.push_back(e.path());
        }
        std::sort(entries.begin(), entries.end());
        return entries;
    };
    for (const fs::path& eps_dir : listing(out)) {
        const std::string name = eps_dir.filename().string();
        if (!fs::is_directory(eps_dir) || !name.starts_with("eps-")) {
            continue; // manifest, reports: the stage's own files
        }
        if (!ladder.contains(name)) {
            remove(eps_dir);
            continue;
        }
        for (const fs::path& level_dir : listing(eps_dir)) {
            const std::string level = level_dir.filename().string();
            if (!levels.contains(level)) {
                remove(level_dir);
                continue;
            }
            auto leftovers = remove_dead_leftovers(level_dir);
            removed.insert(removed.end(), leftovers.begin(), leftovers.end());
            for (const fs::path& f : listing(level_dir)) {
                // A live process's temporary (a name that does not end so) is left alone.
                const std::string file = f.filename().string();
                if (file.ends_with(extension) && !owned.contains({level, file})) {
                    remove(f);
                }
            }
        }
    }
    std::sort(removed.begin(), removed.end());
    return removed;
}

} // namespace tigerlod::simplify
