#pragma once
/// @file stage.hpp
/// The frame every tigerlod executable shares: one option table that gives
/// both parsing and --help, validation before any data is touched, and one
/// place where exceptions become exit codes.
///
/// A stage's main.cpp is one line: `return tigerlod::run_stage<MyStage>(argc, argv);`

#include "core/errors.hpp"
#include "core/log.hpp"
#include "core/progress.hpp"

#include <exception>
#include <filesystem>
#include <iosfwd>
#include <limits>
#include <string>
#include <variant>
#include <vector>

namespace tigerlod {

/// The values a numeric option (or config key) may take.
struct Limits {
    double min = -std::numeric_limits<double>::infinity();
    double max = std::numeric_limits<double>::infinity();
    bool min_open = false, max_open = false; ///< the bound itself excluded
    bool integer = false;
    bool contains(double v) const noexcept;
    /// How a message says it, after "must be ": "in 64..16384", "in (0, 0.5]",
    /// ">= 0", "> 0"; empty when anything goes.
    std::string text() const;
};

/// "a, b or c": how a message lists the values an option may take.
std::string choices_text(const std::vector<std::string>& choices);

/// The worker threads every stage takes: 0 for all cores, at most 1024.
/// Outputs never depend on it.
inline constexpr Limits thread_limits{0, 1024, false, false, true};

/// The options and positional arguments of one stage.
class ArgSet {
  public:
    using Target = std::variant<bool*, int*, double*, std::string*>;

    /// Start a new heading in --help.
    void group(std::string heading);
    /// Declare `--name` bound to `target`; its current value is the default.
    /// bool options are flags and take no value. A number outside `limits`,
    /// or text not among `choices` (when given), is a usage_error naming
    /// the option.
    void add(std::string name, Target target, std::string help, std::string value_name = "", Limits limits = {},
             std::vector<std::string> choices = {});
    /// What --help says the default of `--name` is, in place of its initial
    /// value (an option that overrides a config key: "ingest.halo_m").
    void describe_default(const std::string& name, std::string text);
    /// Declare a positional argument (all are required, in order).
    void positional(std::string name, std::string* target, std::string help);

    /// Parse argv; throws usage_error for anything unknown, missing or malformed.
    /// --help and --version are handled by run_stage before this is called.
    void parse(const std::string& stage, const std::vector<std::string>& args);
    std::string help_text(const std::string& program, const std::string& description) const;

  private:
    struct Option {
        std::string name, help, value_name, group;
        Target target;
        std::string default_text;
        Limits limits;
        std::vector<std::string> choices;
    };
    struct Positional {
        std::string name, help;
        std::string* target;
    };
    std::vector<Option> m_options;
    std::vector<Positional> m_positionals;
    std::string m_group = "Options";
}; // class ArgSet

/// What run_stage gives a stage's run().
struct StageContext {
    Log& log;
    ProgressMode progress = ProgressMode::none; ///< `--progress` (core/progress.hpp)
};

/// Log one line per leftover of a dead run that a stage removed
/// (remove_dead_leftovers in core/fs.hpp), so a rerun says what it cleaned.
void log_removed_leftovers(const Log& log, const std::vector<std::filesystem::path>& removed);

/// A stage: declares its options, validates them, then runs.
class Stage {
  public:
    virtual ~Stage() = default;
    /// Declare options and positionals.
    virtual void add_args(ArgSet& args) = 0;
    /// Validate options; open nothing. Throws usage_error.
    virtual void initialize() {}
    /// Do the work. Returns the exit code: exit_ok, or exit_data when the data failed.
    virtual int run(const StageContext& ctx) = 0;
    /// Extra lines for --version (dependency versions).
    virtual std::vector<std::string> versions() const { return {}; }
    /// Extra text for --help after the options (e.g. notes on outputs).
    virtual std::string help_notes() const { return {}; }
    /// The config section this stage takes with `--config FILE` ("" for
    /// none): run_stage declares the option, and puts config_args(FILE)
    /// before the command line's own arguments, so that flags given there win.
    virtual std::string config_section() const { return {}; }
    /// The section's keys as this stage's flags. Throws config_error naming
    /// the file, line and key.
    virtual std::vector<std::string> config_args(const std::filesystem::path& /*file*/) const { return {}; }
}; // class Stage

namespace detail {
int run_stage_impl(Stage& stage, const char* name, const char* description, int argc, char** argv);

/// Write `error`'s one-line message for tigerlod-`name` to `err` and return
/// its exit code: an Error's own; 3 for std::bad_alloc and std::system_error
/// (std::filesystem's errors among them: the machine's state); 4 for any
/// other exception, a fault in tigerlod that a retry would only repeat.
int report_exception(const std::exception_ptr& error, const char* name, std::ostream& err);
} // namespace detail

/// Parse, validate, run and map exceptions to exit codes (see ExitCode).
template <class S> int run_stage(int argc, char** argv)
{
    S stage;
    return detail::run_stage_impl(stage, S::name, S::description, argc, argv);
}

/// The tigerlod version string.
const char* tigerlod_version() noexcept;

} // namespace tigerlod
