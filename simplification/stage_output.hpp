#pragma once
/// @file stage_output.hpp
/// Where tigerlod-color and tigerlod-simplify write, whole or partition by
/// partition. A whole run builds OUTPUT under a temporary name and renames
/// it into place. A run on some partitions (`--partitions`, the workflow's
/// job) updates OUTPUT in place: each file of its partitions is written
/// under a temporary name and renamed alone, the files of every other
/// partition are left as they are, and the bytes it writes are those a
/// whole run writes for the same partitions. `--finish`, after the
/// partitions' jobs, makes OUTPUT what a whole run makes: it checks that
/// every store has its files, removes those of stores and tolerances the
/// run no longer has, and writes manifest.json.

#include "core/fs.hpp"
#include "simplification/stage_options.hpp"

#include <filesystem>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod::simplify {

/// The stores of `all` that `spec` names: items separated by commas, or
/// `@FILE` with one item a line; an item is `LEVEL/PARTITION`,
/// `LEVEL/PREFIX*` (the partitions of LEVEL whose names begin with PREFIX)
/// or `LEVEL/*`. Sorted as `all` is, each once. Throws usage_error naming
/// the item that matches no store of `input` (a name misspelt, a partition
/// that ingest did not write), and input_error if FILE cannot be read.
std::vector<StoreFile> select_stores(const std::vector<StoreFile>& all, const std::string& spec,
                                     const std::filesystem::path& input);

class StageOutput {
  public:
    /// `stage` names the stage whose output OUTPUT must be when updated in
    /// place (its manifest.json, if any, is that stage's: usage_error if
    /// not). Whole: an OutputDir (see it for `overwrite` and `reads`).
    StageOutput(const CommonOptions& options, const std::vector<std::filesystem::path>& reads,
                const std::string& stage);

    /// The folder files go into: temporary until commit() for a whole run,
    /// OUTPUT itself in place.
    const std::filesystem::path& path() const noexcept;
    bool in_place() const noexcept { return !m_whole; }
    /// Write a partition's file, `relative` to path(). Thread-safe. In
    /// place: under a temporary name renamed into place; the first write
    /// into a folder removes what dead runs left there, and commit() syncs
    /// the folders written into (once each, not once a file: a level folder
    /// of a national run holds ten thousand stores).
    void write(const std::filesystem::path& relative, std::string_view data) const;
    /// The stage's report: OUTPUT/<stage>-report.json for a whole run; in
    /// place to `--report FILE` if given (a job's share), else nowhere.
    void write_report(std::string_view data) const;
    /// manifest.json, then (whole) the rename into place.
    void commit(std::string_view manifest);
    /// What dead runs had left: beside OUTPUT (whole, from the start), or in
    /// the folders written into so far (in place).
    const std::vector<std::filesystem::path>& removed_leftovers() const noexcept;

  private:
    const CommonOptions& m_options;
    std::string m_stage;
    std::optional<OutputDir> m_whole;
    std::filesystem::path m_dir;
    /// In place: shared for --partitions (jobs side by side), exclusive for
    /// --finish (which removes what no job wrote).
    std::optional<FolderLock> m_lock;
    mutable std::vector<std::filesystem::path> m_removed;
    mutable std::mutex m_mutex;
    mutable std::set<std::filesystem::path> m_folders; ///< written into, in place
};                                                     // class StageOutput

/// `--finish`: throws usage_error naming the first store of `stores` that
/// has no file `<store's partition><extension>` under
/// `out/eps-<E>m/<level>/` at a tolerance of the ladder; then removes every
/// `eps-*` folder of another tolerance, level folder of another level and
/// file of another partition (and dead runs' temporaries). Returns what it removed.
std::vector<std::filesystem::path> finish_in_place(const std::filesystem::path& out,
                                                   const std::vector<StoreFile>& stores,
                                                   const std::vector<double>& tolerances, const std::string& extension);

} // namespace tigerlod::simplify
