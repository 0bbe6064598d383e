#include "core/stage.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <exception>
#include <iostream>
#include <new>
#include <sstream>
#include <string_view>
#include <system_error>

namespace tigerlod {

const char* tigerlod_version() noexcept
{
    return "0.1.0";
}

void ArgSet::group(std::string heading)
{
    m_group = std::move(heading);
}

bool Limits::contains(double v) const noexcept
{
    if (std::isnan(v) || (integer && v != std::floor(v))) {
        return false;
    }
    return (min_open ? v > min : v >= min) && (max_open ? v < max : v <= max);
}

std::string Limits::text() const
{
    auto num = [](double v) {
        std::ostringstream s;
        s << v;
        return s.str();
    };
    const bool has_min = std::isfinite(min), has_max = std::isfinite(max);
    if (has_min && has_max) {
        if (integer) {
            return "in " + num(min) + ".." + num(max);
        }
        return std::string("in ") + (min_open ? "(" : "[") + num(min) + ", " + num(max) + (max_open ? ")" : "]");
    }
    if (has_min) {
        return std::string(min_open ? "> " : ">= ") + num(min);
    }
    if (has_max) {
        return std::string(max_open ? "< " : "<= ") + num(max);
    }
    return {};
}

std::string choices_text(const std::vector<std::string>& choices)
{
    std::string out;
    for (size_t i = 0; i < choices.size(); ++i) {
        out += (i == 0 ? "" : i + 1 == choices.size() ? " or " : ", ") + choices[i];
    }
    return out;
}

void ArgSet::add(std::string name, Target target, std::string help, std::string value_name, Limits limits,
                 std::vector<std::string> choices)
{
    std::string def = std::visit(
        [](auto* p) -> std::string {
            using T = std::remove_pointer_t<decltype(p)>;
            if constexpr (std::is_same_v<T, bool>) {
                return "";
            } else if constexpr (std::is_same_v<T, std::string>) {
                return *p;
            } else {
                std::ostringstream s;
                s << *p;
                return s.str();
            }
        },
        target);
    m_options.push_back(
        {std::move(name), std::move(help), std::move(value_name), m_group, target, def, limits, std::move(choices)});
}

void ArgSet::describe_default(const std::string& name, std::string text)
{
    for (auto& o : m_options) {
        if (o.name == name) {
            o.default_text = std::move(text);
        }
    }
}

void ArgSet::positional(std::string name, std::string* target, std::string help)
{
    m_positionals.push_back({std::move(name), std::move(help), target});
}

namespace {

template <class T> T parse_number(const std::string& stage, const std::string& option, const std::string& text)
{
    T value{};
    const char* end = text.data() + text.size();
    auto [ptr, ec] = std::from_chars(text.data(), end, value);
    if (ec != std::errc{} || ptr != end) {
        throw usage_error(stage + ": option '--" + option + "' needs a number, got '" + text + "'");
    }
    return value;
}

} // namespace

void ArgSet::parse(const std::string& stage, const std::vector<std::string>& args)
{
    size_t next_positional = 0;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        if (arg.size() > 1 && arg[0] == '-') {
            std::string name = arg.substr(arg[1] == '-' ? 2 : 1);
            std::string value;
            bool has_value = false;
            if (auto eq = name.find('='); eq != std::string::npos) {
                value = name.substr(eq + 1);
                name.resize(eq);
                has_value = true;
            }
            auto it = std::find_if(m_options.begin(), m_options.end(), [&](const Option& o) { return o.name == name; });
            if (it == m_options.end()) {
                throw usage_error(stage + ": unknown option '" + arg + "'. Try --help.");
            }
            if (std::holds_alternative<bool*>(it->target)) {
                if (has_value) {
                    throw usage_error(stage + ": option '--" + name + "' takes no value");
                }
                *std::get<bool*>(it->target) = true;
                continue;
            }
            if (!has_value) {
                if (i + 1 >= args.size()) {
                    throw usage_error(stage + ": option '--" + name + "' needs a value");
                }
                value = args[++i];
            }
            std::visit(
                [&](auto* p) {
                    using T = std::remove_pointer_t<decltype(p)>;
                    if constexpr (std::is_same_v<T, std::string>) {
                        if (!it->choices.empty() &&
                            std::find(it->choices.begin(), it->choices.end(), value) == it->choices.end()) {
                            throw usage_error(stage + ": option '--" + name + "' must be " + choices_text(it->choices) +
                                              ", not '" + value + "'");
                        }
                        *p = value;
                    } else if constexpr (!std::is_same_v<T, bool>) {
                        *p = parse_number<T>(stage, name, value);
                        if (!it->limits.contains(static_cast<double>(*p))) {
                            throw usage_error(stage + ": option '--" + name + "' must be " + it->limits.text());
                        }
                    }
                },
                it->target);
        } else {
            if (next_positional >= m_positionals.size()) {
                throw usage_error(stage + ": unexpected argument '" + arg + "'. Try --help.");
            }
            *m_positionals[next_positional++].target = arg;
        }
    }
    if (next_positional < m_positionals.size()) {
        throw usage_error(stage + ": missing argument " + m_positionals[next_positional].name + ". Try --help.");
    }
}

std::string ArgSet::help_text(const std::string& program, const std::string& description) const
{
    std::ostringstream out;
    out << "Usage: " << program << " [OPTIONS]";
    for (const auto& p : m_positionals) {
        out << ' ' << p.name;
    }
    out << "\n\n" << description << "\n";
    if (!m_positionals.empty()) {
        out << "\nArguments:\n";
        for (const auto& p : m_positionals) {
            out << "  " << p.name << "\n      " << p.help << "\n";
        }
    }
    std::string group;
    for (const auto& o : m_options) {
        if (o.group != group) {
            group = o.group;
            out << "\n" << group << ":\n";
        }
        out << "  --" << o.name;
        if (!o.value_name.empty()) {
            out << ' ' << o.value_name;
        }
        out << "\n      " << o.help;
        if (!o.default_text.empty()) {
            out << " (default: " << o.default_text << ")";
        }
        out << "\n";
    }
    return out.str();
}

void log_removed_leftovers(const Log& log, const std::vector<std::filesystem::path>& removed)
{
    for (const auto& p : removed) {
        log.info("removed " + p.string() + ", left by a run that died");
    }
}

namespace detail {

int run_stage_impl(Stage& stage, const char* name, const char* description, int argc, char** argv)
{
    const std::string program = std::string("tigerlod-") + name;
    try {
        ArgSet args;
        bool help = false, version = false, verbose = false;
        std::string progress = "auto";
        args.group("General");
        args.add("help", &help, "print this help and exit");
        args.add("version", &version, "print versions of tigerlod and its libraries and exit");
        args.add("verbose", &verbose,
                 "log progress to stderr, each line with the elapsed time and the memory resident then");
        args.add("progress", &progress,
                 "auto (a progress line on stderr when it is a terminal), bar (always), json (one JSON object a "
                 "line on stderr, for a workflow engine) or none",
                 "MODE");
        stage.add_args(args);
        std::string config_file;
        const std::string section = stage.config_section();
        if (!section.empty()) {
            args.group("Config");
            args.add("config", &config_file,
                     "take options from the '" + section +
                         "' section of this config file (keys in configs/README.md); options given on the command "
                         "line win",
                     "FILE");
        }
        std::vector<std::string> argv_list(argv + 1, argv + argc);
        for (auto& a : argv_list) { // -h and -v as short forms
            if (a == "-h") {
                a = "--help";
            } else if (a == "-v") {
                a = "--verbose";
            }
        }
        // --help and --version win over missing positionals.
        for (const auto& a : argv_list) {
            help = help || a == "--help";
            version = version || a == "--version";
        }
        if (help) {
            std::cout << args.help_text(program, description) << stage.help_notes()
                      << "\nDiagnostics:\n"
                         "  Exit codes: 0 done; 1 the stage ran but the data failed (bad or corrupt\n"
                         "  input, problems over budget); 2 usage or config error; 3 environment\n"
                         "  problem (I/O, GL context), worth retrying; 4 internal error (a fault in\n"
                         "  tigerlod): do not retry, report it. Messages name the file, the place\n"
                         "  and the fault.\n";
            return exit_ok;
        }
        if (version) {
            std::cout << program << ' ' << tigerlod_version() << '\n';
            for (const auto& line : stage.versions()) {
                std::cout << "  " << line << '\n';
            }
            return exit_ok;
        }
        if (!section.empty()) {
            // The config's flags first: the command line's own come after and win.
            for (size_t i = 0; i < argv_list.size(); ++i) {
                if (argv_list[i] == "--config" && i + 1 < argv_list.size()) {
                    config_file = argv_list[i + 1];
                } else if (argv_list[i].rfind("--config=", 0) == 0) {
                    config_file = argv_list[i].substr(9);
                }
            }
            if (!config_file.empty()) {
                auto from_config = stage.config_args(config_file);
                argv_list.insert(argv_list.begin(), from_config.begin(), from_config.end());
            }
        }
        args.parse(name, argv_list);
        stage.initialize();
        Log log;
        log.set_verbose(verbose);
        StageContext ctx{log, parse_progress_mode(progress)};
        return stage.run(ctx);
    } catch (...) {
        return report_exception(std::current_exception(), name, std::cerr);
    }
}

int report_exception(const std::exception_ptr& error, const char* name, std::ostream& err)
{
    const std::string program = std::string("tigerlod-") + name;
    try {
        std::rethrow_exception(error);
    } catch (const Error& e) {
        // Messages thrown as "pack: ..." by a stage: the program name says it once.
        std::string_view what = e.what();
        const std::string own = std::string(name) + ": ";
        if (what.substr(0, own.size()) == own) {
            what.remove_prefix(own.size());
        }
        err << program << ": " << what << '\n';
        return e.exit_code();
    } catch (const std::bad_alloc&) {
        err << program << ": out of memory\n";
        return exit_environment;
    } catch (const std::system_error& e) {
        // The system said no (std::filesystem, threads, streams with
        // exceptions on): the machine's state, not the code's.
        err << program << ": " << e.what() << '\n';
        return exit_environment;
    } catch (const std::exception& e) {
        err << program
            << ": internal error (a fault in tigerlod, not in its input or the machine; running it again "
               "will not help, please report it): "
            << e.what() << '\n';
        return exit_internal;
    } catch (...) {
        err << program << ": internal error (a fault in tigerlod: an exception of no known kind; please report it)\n";
        return exit_internal;
    }
}

} // namespace detail
} // namespace tigerlod
