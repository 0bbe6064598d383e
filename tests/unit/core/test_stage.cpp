/// @file test_stage.cpp
/// The exit code and message a stage's exception maps to: a retry helps an
/// environment fault (3), never a fault of tigerlod's own (4).

#include "core/stage.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <new>
#include <sstream>
#include <stdexcept>
#include <system_error>

namespace {

using tigerlod::detail::report_exception;

template <class E> std::pair<int, std::string> reported(const E& e)
{
    std::ostringstream err;
    const int code = report_exception(std::make_exception_ptr(e), "pack", err);
    return {code, err.str()};
}

/// A stage whose run() throws what the test gives it.
class Thrower : public tigerlod::Stage {
  public:
    explicit Thrower(std::exception_ptr e) : m_e(std::move(e)) {}
    void add_args(tigerlod::ArgSet&) override {}
    int run(const tigerlod::StageContext&) override { std::rethrow_exception(m_e); }

  private:
    std::exception_ptr m_e;
};

} // namespace

TEST(Stage, TigerlodsOwnErrorsKeepTheirCodeAndSayTheProgramOnce)
{
    EXPECT_EQ(reported(tigerlod::usage_error("pack: option '--x' is unknown")),
              (std::pair<int, std::string>{2, "tigerlod-pack: option '--x' is unknown\n"}));
    EXPECT_EQ(reported(tigerlod::input_error("a.tlc: bad magic")).first, 1);
    EXPECT_EQ(reported(tigerlod::format_error("a.tlc: bad magic")).first, 1);
    EXPECT_EQ(reported(tigerlod::config_error("c.yaml:3: bad key")).first, 2);
    EXPECT_EQ(reported(tigerlod::environment_error("cannot write x")).first, 3);
}

TEST(Stage, TheMachinesFaultsAreWorthRetrying)
{
    EXPECT_EQ(reported(std::bad_alloc()), (std::pair<int, std::string>{3, "tigerlod-pack: out of memory\n"}));
    const auto fs_error = reported(std::filesystem::filesystem_error(
        "cannot rename", "/t/a", std::make_error_code(std::errc::no_space_on_device)));
    EXPECT_EQ(fs_error.first, 3);
    EXPECT_NE(fs_error.second.find("/t/a"), std::string::npos) << fs_error.second;
    EXPECT_EQ(
        reported(std::system_error(std::make_error_code(std::errc::resource_unavailable_try_again), "thread")).first,
        3);
}

TEST(Stage, AFaultOfTigerlodsOwnIsInternalAndNotWorthRetrying)
{
    for (const auto& [code, text] : {reported(std::logic_error("layout_tiles: a payload is not of the size given")),
                                     reported(std::out_of_range("vector::at")),
                                     reported(std::length_error("a chain has more than 2^32 shortcuts"))}) {
        EXPECT_EQ(code, tigerlod::exit_internal);
        EXPECT_EQ(text.rfind("tigerlod-pack: internal error (a fault in tigerlod", 0), 0U) << text;
        EXPECT_NE(text.find("please report it"), std::string::npos) << text;
    }
    std::ostringstream err;
    EXPECT_EQ(report_exception(std::make_exception_ptr(42), "pack", err), tigerlod::exit_internal);
    EXPECT_NE(err.str().find("internal error"), std::string::npos) << err.str();
}

TEST(Stage, RunStageMapsWhatRunThrows)
{
    char arg0[] = "tigerlod-t";
    char* argv[] = {arg0, nullptr};
    Thrower internal(std::make_exception_ptr(std::logic_error("a bug")));
    EXPECT_EQ(tigerlod::detail::run_stage_impl(internal, "t", "a test stage", 1, argv), 4);
    Thrower environment(std::make_exception_ptr(tigerlod::environment_error("disk full")));
    EXPECT_EQ(tigerlod::detail::run_stage_impl(environment, "t", "a test stage", 1, argv), 3);
    Thrower data(std::make_exception_ptr(tigerlod::input_error("bad")));
    EXPECT_EQ(tigerlod::detail::run_stage_impl(data, "t", "a test stage", 1, argv), 1);
}
