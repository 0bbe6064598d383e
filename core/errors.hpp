#pragma once
/// @file errors.hpp
/// The small set of exceptions that stages throw, and the exit codes that
/// run_stage() maps them to. Library code never calls exit().

#include <stdexcept>
#include <string>

namespace tigerlod {

/// Exit codes of every tigerlod executable (documented in each --help).
enum ExitCode : int {
    exit_ok = 0,          ///< done
    exit_data = 1,        ///< the stage ran, but the data failed
    exit_usage = 2,       ///< usage or config error
    exit_environment = 3, ///< environment problem (I/O, GL context); worth retrying
    exit_internal = 4     ///< a fault in tigerlod itself (an exception no stage expected): do not retry, report it
};

/// Base of all tigerlod errors; carries the exit code it maps to.
class Error : public std::runtime_error {
  public:
    Error(const std::string& what, int exit_code) : std::runtime_error(what), m_exit_code(exit_code) {}
    int exit_code() const noexcept { return m_exit_code; }

  private:
    int m_exit_code;
}; // class Error

/// Bad command line: unknown option, missing argument, invalid value.
struct usage_error : Error {
    explicit usage_error(const std::string& what) : Error(what, exit_usage) {}
};

/// Bad config file: unknown key, wrong type, invalid value.
struct config_error : Error {
    explicit config_error(const std::string& what) : Error(what, exit_usage) {}
};

/// Bad input data: missing layer, wrong geometry type, corrupt file.
struct input_error : Error {
    explicit input_error(const std::string& what) : Error(what, exit_data) {}
};

/// A tigerlod file that is not what it claims: bad magic, version, checksum.
struct format_error : Error {
    explicit format_error(const std::string& what) : Error(what, exit_data) {}
};

/// Something around us failed: cannot write, disk full, no GL context.
struct environment_error : Error {
    explicit environment_error(const std::string& what) : Error(what, exit_environment) {}
};

} // namespace tigerlod
