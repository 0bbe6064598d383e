#pragma once
/// @file fs.hpp
/// Writing outputs so that nothing is ever half-written: every file and
/// every output folder is written under a temporary name beside its final
/// place and renamed on success.

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod {

/// The temporary name of `path` for this process: `<name><kind><host>-<pid>`
/// beside it, `kind` being ".tmp-" (being written) or ".old-" (moved aside
/// to be replaced). Host and process id together let a later run tell a dead
/// process's leftovers from a live one's, on a folder shared by machines.
std::filesystem::path temp_sibling(const std::filesystem::path& path, std::string_view kind = ".tmp-");

/// The same for a file whose extension must stay last (GDAL picks a driver
/// by it): `<stem>.tmp-<host>-<pid><extension>`.
std::filesystem::path temp_sibling_keeping_extension(const std::filesystem::path& path);

/// Remove what dead runs left in `folder`: entries named as temp_sibling and
/// temp_sibling_keeping_extension name them, written by a process of this
/// host that no longer exists (an empty `folder` is the current one). With `base` given, only leftovers of that
/// name (`<base>.tmp-...`, `<base>.old-...`). Entries of live processes, of
/// other hosts and of any other name are left alone. Returns what it
/// removed; throws nothing (what cannot be removed stays).
std::vector<std::filesystem::path> remove_dead_leftovers(const std::filesystem::path& folder,
                                                         std::string_view base = {});

/// Durability: files are synced to disk before they are renamed into place
/// and their folders after, so a rename survives power loss, not only a
/// kill. TIGERLOD_FSYNC=0 in the environment turns syncing off (scratch
/// outputs; the cost is in BENCHMARKS.md).
///
/// Sync a file or folder to disk (fsync); nothing where the file system has
/// nothing to sync. Throws environment_error.
void sync_to_disk(const std::filesystem::path& path);

/// Write `data` to `path` through a temporary file and rename. Throws
/// environment_error on any I/O failure; the temporary is removed then.
void write_file_atomic(const std::filesystem::path& path, std::string_view data);

/// write_file_atomic without the sync of the folder: for many files of one
/// folder, whose writer syncs the folder once after the last of them.
void write_file_atomic_unsynced_folder(const std::filesystem::path& path, std::string_view data);

/// Write `data` to `path` directly, for files inside an OutputDir: the
/// folder, renamed into place whole, is what keeps them from being seen
/// half-written. Throws environment_error on any I/O failure; a file it
/// began is removed then.
void write_file(const std::filesystem::path& path, std::string_view data);

/// The bytes of a file. Throws environment_error naming it if it cannot be read.
std::string read_file(const std::filesystem::path& path);

/// For outputs updated in place that a workflow engine follows by their
/// times: write `data` to `path` as write_file_atomic_unsynced_folder does,
/// unless the file already holds exactly these bytes, which then keeps its
/// modification time. Returns whether it wrote.
bool write_file_if_changed(const std::filesystem::path& path, std::string_view data);

/// Throws usage_error if writing `output` would replace or remove one of
/// `inputs` or write into it: the same file or folder, a folder that holds
/// it, or a path inside an input folder (symbolic links and `..` resolved). A stage checks this before anything else,
/// so
/// `--overwrite` can never delete what the stage reads.
void refuse_to_replace_inputs(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs);

/// Whether `folder` is a tigerlod stage's output: it holds manifest.json
/// with the schema tigerlod.manifest/1 (render: summary.json,
/// tigerlod.render-summary/1).
bool is_stage_output(const std::filesystem::path& folder);

/// Throws usage_error unless `output`, which exists, is a folder that
/// --overwrite may replace: a tigerlod stage's output (is_stage_output) or
/// an empty folder. The message names a file found there, so a folder of the
/// user's (notes, a thesis) is never deleted by a mistyped OUTPUT.
void refuse_to_replace_foreign(const std::filesystem::path& output);

/// A lock on a folder a stage updates in place, held while it lives:
/// flock(2) on the folder itself, so no lock file is left in or beside it,
/// and a run killed anywhere releases it. The folder is made if missing.
///
/// Exclusive for what rewrites the folder as a whole (pack's tree, a
/// --finish, the swap of a whole run's output into place); shared for the
/// partition jobs of one run, which write disjoint files and run side by
/// side. A run that cannot have the lock waits (saying so on stderr)
/// rather than interleaving its files with another's; if the holder
/// removed or replaced the folder meanwhile, the lock is taken again on
/// the folder now of that name. On a file system without locks (flock
/// fails with ENOLCK, ENOSYS or EOPNOTSUPP: some cluster mounts) the run
/// goes on unguarded, saying so once on stderr.
class FolderLock {
  public:
    enum class Mode { exclusive, shared };
    /// Throws environment_error naming `folder` if it cannot be made,
    /// opened or locked. `who` names the stage in the waiting message.
    FolderLock(const std::filesystem::path& folder, const std::string& who, Mode mode = Mode::exclusive);
    FolderLock(const FolderLock&) = delete;
    FolderLock& operator=(const FolderLock&) = delete;
    ~FolderLock();
    /// Whether the folder was empty when the lock was taken (a new output).
    bool was_empty() const noexcept { return m_was_empty; }

  private:
    int m_fd = -1;
    bool m_was_empty = false;
}; // class FolderLock

/// An output folder built under a temporary name and renamed into place by
/// commit(). Destroyed without commit(), it removes what it wrote.
class OutputDir {
  public:
    /// Prepare `final_path`, removing what dead runs left beside it
    /// (remove_dead_leftovers). Throws usage_error if it would replace one of
    /// `inputs` (refuse_to_replace_inputs), if it exists and `overwrite` is
    /// false ("Use --overwrite to replace it."), or if it exists and is not a
    /// stage's output or an empty folder (refuse_to_replace_foreign), environment_error if the
    /// temporary folder cannot be made.
    OutputDir(std::filesystem::path final_path, bool overwrite, const std::vector<std::filesystem::path>& inputs = {});
    OutputDir(const OutputDir&) = delete;
    OutputDir& operator=(const OutputDir&) = delete;
    ~OutputDir();

    /// The folder to write into (temporary until commit()).
    const std::filesystem::path& path() const noexcept { return m_tmp; }
    /// Move the temporary folder into place, replacing an old one.
    void commit();
    /// At commit(), give each new file named `*<extension>` whose bytes
    /// equal the old output's file at the same place that file's
    /// modification time. A workflow engine that compares times (Snakemake)
    /// then reruns only the jobs of the files that changed: after one
    /// county's input changed, ingest rewrites its folder whole, and the
    /// stores of other regions keep their times. Other files (the manifest
    /// that tells the engine the stage ran) get new times. Costs a read of
    /// both files where the sizes match.
    void keep_times_of_unchanged_files(std::string extension) { m_keep_times = std::move(extension); }
    /// What dead runs had left beside the output, removed by the
    /// constructor (remove_dead_leftovers), for the stage to log.
    const std::vector<std::filesystem::path>& removed_leftovers() const noexcept { return m_removed; }

  private:
    /// commit()'s swap, under its lock: the old output aside, the new one in.
    void swap_into_place();

    std::filesystem::path m_final;
    std::filesystem::path m_tmp;
    std::vector<std::filesystem::path> m_removed;
    bool m_overwrite = false;
    bool m_committed = false;
    std::string m_keep_times; ///< the extension of files whose times are kept; empty: none
};                            // class OutputDir

} // namespace tigerlod
