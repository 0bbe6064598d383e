// Outputs written under temporary names, and what dead runs left of them:
// removed by the next run, and only what a dead process of this host left.
#include "core/errors.hpp"
#include "core/fs.hpp"

#include "../../support/processes.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <future>
#include <memory>
#include <set>
#include <string>

namespace fs = std::filesystem;
using namespace tigerlod;

namespace {

class Fs : public ::testing::Test {
  protected:
    void SetUp() override
    {
        m_dir = fs::temp_directory_path() / ("tigerlod-fs-" + std::to_string(::getpid()));
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    void touch(const std::string& name) { std::ofstream(m_dir / name) << "x"; }
    std::set<std::string> names() const
    {
        std::set<std::string> out;
        for (const auto& e : fs::directory_iterator(m_dir)) {
            out.insert(e.path().filename().string());
        }
        return out;
    }
    fs::path m_dir;
};

} // namespace

TEST_F(Fs, TemporaryNamesCarryHostAndProcess)
{
    const std::string mine = temp_sibling(m_dir / "out").filename().string();
    ASSERT_EQ(mine.rfind("out.tmp-", 0), 0U) << mine;
    EXPECT_EQ(mine.substr(mine.rfind('-') + 1), std::to_string(::getpid()));
    EXPECT_EQ(mine.find('.', 4), std::string::npos) << "the host part holds no '.': " << mine;
    const std::string old = temp_sibling(m_dir / "out", ".old-").filename().string();
    EXPECT_EQ(old.rfind("out.old-", 0), 0U) << old;
    const std::string gpkg = temp_sibling_keeping_extension(m_dir / "x.gpkg").filename().string();
    EXPECT_EQ(gpkg, "x" + mine.substr(3) + ".gpkg");
}

TEST_F(Fs, OnlyLeftoversOfDeadProcessesOfThisHostAreRemoved)
{
    const std::string dead = std::to_string(tigerlod::testing::dead_pid()), live = std::to_string(::getpid());
    // This host's id, as this process writes it, with a dead process's id.
    const std::string mine = temp_sibling(m_dir / "out").filename().string();
    const std::string host = mine.substr(8, mine.rfind('-') - 8);
    touch("out.tmp-" + host + "-" + dead);                                    // dead, this host: removed
    fs::create_directories(m_dir / ("out.old-" + host + "-" + dead) / "sub"); // a folder, whole
    touch("out.tmp-" + dead);                      // a name from before hosts were in it: this host's
    touch("x.tmp-" + host + "-" + dead + ".gpkg"); // an extension after the id
    touch("out.tmp-" + host + "-" + live);         // this process: alive
    touch("out.tmp-" + host + "-1");               // init: alive
    touch("out.tmp-elsewhere-" + dead);            // another host: cannot tell, kept
    touch("out.tmp-");                             // not a temporary name
    touch("out.tmp-12a");
    touch("out");
    touch("notes.txt");
    const auto removed = remove_dead_leftovers(m_dir);
    EXPECT_EQ(removed.size(), 4U);
    EXPECT_EQ(names(),
              (std::set<std::string>{"out.tmp-" + host + "-" + live, "out.tmp-" + host + "-1",
                                     "out.tmp-elsewhere-" + dead, "out.tmp-", "out.tmp-12a", "out", "notes.txt"}));
    // With a base, only that name's leftovers.
    touch("out.tmp-" + dead);
    touch("outer.tmp-" + dead);
    EXPECT_EQ(remove_dead_leftovers(m_dir, "out").size(), 1U);
    EXPECT_TRUE(fs::exists(m_dir / ("outer.tmp-" + dead)));
    // No folder part: the current folder, as for an output named without one.
    touch("out.tmp-" + dead);
    const fs::path cwd = fs::current_path();
    fs::current_path(m_dir);
    const auto here = remove_dead_leftovers("", "out");
    fs::current_path(cwd);
    ASSERT_EQ(here.size(), 1U);
    EXPECT_FALSE(fs::exists(m_dir / ("out.tmp-" + dead)));
    // A folder that does not exist: nothing, no throw.
    EXPECT_TRUE(remove_dead_leftovers(m_dir / "none").empty());
}

TEST_F(Fs, AZombieCountsAsDead)
{
    // A process killed with its parent is left unreaped where PID 1 does not
    // reap (containers): it has exited, and its leftovers are removed.
    const pid_t zombie = ::fork();
    if (zombie == 0) {
        ::_exit(0);
    }
    for (int i = 0; i < 1000; ++i) {
        std::ifstream stat("/proc/" + std::to_string(zombie) + "/stat");
        std::string line;
        std::getline(stat, line);
        if (line.find(") Z") != std::string::npos) {
            break;
        }
        ::usleep(1000);
    }
    touch("out.tmp-" + std::to_string(zombie));
    EXPECT_EQ(remove_dead_leftovers(m_dir).size(), 1U);
    int status = 0;
    ::waitpid(zombie, &status, 0);
}

TEST_F(Fs, AnOutputFolderCleansWhatADeadRunLeftBesideIt)
{
    const std::string dead = std::to_string(tigerlod::testing::dead_pid());
    fs::create_directories(m_dir / ("out.tmp-" + dead));
    fs::create_directories(m_dir / ("out.old-" + dead));
    touch("other.tmp-" + dead);
    {
        OutputDir out(m_dir / "out", false);
        EXPECT_EQ(out.removed_leftovers().size(), 2U);
        write_file(out.path() / "a", "1");
        out.commit();
    }
    EXPECT_EQ(names(), (std::set<std::string>{"out", "other.tmp-" + dead}));
    EXPECT_THROW(OutputDir(m_dir / "out", false), usage_error);
}

TEST_F(Fs, AnOutputMadeByAnotherRunMeanwhileIsNotReplacedWithoutOverwrite)
{
    {
        OutputDir out(m_dir / "out", false);
        write_file(out.path() / "a", "mine");
        // Another run (or a person) makes OUTPUT while this one works.
        fs::create_directories(m_dir / "out");
        write_file(m_dir / "out" / "a", "theirs");
        EXPECT_THROW(out.commit(), usage_error);
    }
    EXPECT_EQ(names(), (std::set<std::string>{"out"})); // no temporary left
    EXPECT_EQ(read_file(m_dir / "out" / "a"), "theirs");
    // A run whose OUTPUT is still missing at the swap leaves its own there.
    fs::remove_all(m_dir / "out");
    {
        OutputDir out(m_dir / "out", false);
        write_file(out.path() / "a", "mine");
        out.commit();
    }
    EXPECT_EQ(read_file(m_dir / "out" / "a"), "mine");
    EXPECT_EQ(names(), (std::set<std::string>{"out"}));
}

TEST_F(Fs, AnOutputIsLookedAtUnderItsLockNotWhileAnotherRunSwapsIt)
{
    // A run beside this one is swapping its output into place (it holds the
    // lock alone): this run's look at what OUTPUT holds waits for it, so it
    // never sees the folder half moved.
    {
        OutputDir first(m_dir / "out", false);
        write_file(first.path() / "manifest.json", R"({"schema": "tigerlod.manifest/1"})");
        first.commit();
    }
    auto holder = std::make_unique<FolderLock>(m_dir / "out", "test");
    auto second = std::async(std::launch::async, [&] {
        OutputDir out(m_dir / "out", true);
        return true;
    });
    EXPECT_EQ(second.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout)
        << "the look at OUTPUT did not wait for the lock";
    holder.reset();
    EXPECT_TRUE(second.get());
}

TEST_F(Fs, OverwriteReplacesOnlyAStagesOutputOrAnEmptyFolder)
{
    // A folder of the user's is refused, naming a file in it, and kept.
    fs::create_directories(m_dir / "thesis");
    write_file(m_dir / "thesis" / "notes.txt", "years of work");
    write_file(m_dir / "thesis" / "manifest.json", R"({"schema": "someone-else/1"})");
    try {
        OutputDir out(m_dir / "thesis", true);
        FAIL() << "a folder that is no stage's output was accepted";
    } catch (const usage_error& e) {
        EXPECT_NE(std::string(e.what()).find("is not a tigerlod stage's output (it holds manifest.json and 1 more"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_EQ(read_file(m_dir / "thesis" / "notes.txt"), "years of work");
    // A file is refused too.
    write_file(m_dir / "file", "x");
    EXPECT_THROW(OutputDir(m_dir / "file", true), usage_error);
    EXPECT_EQ(read_file(m_dir / "file"), "x");
    // An empty folder, a stage's output (its manifest) and render's (its summary) are replaced.
    fs::create_directories(m_dir / "empty");
    fs::create_directories(m_dir / "stage");
    write_file(m_dir / "stage" / "manifest.json", R"({"schema": "tigerlod.manifest/1", "stage": "color"})");
    write_file(m_dir / "stage" / "store.tlc", "old");
    fs::create_directories(m_dir / "render");
    write_file(m_dir / "render" / "summary.json", R"({"schema": "tigerlod.render-summary/1"})");
    for (const char* name : {"empty", "stage", "render"}) {
        OutputDir out(m_dir / name, true);
        write_file(out.path() / "new", "1");
        out.commit();
        EXPECT_EQ(read_file(m_dir / name / "new"), "1") << name;
        EXPECT_FALSE(fs::exists(m_dir / name / "store.tlc")) << name;
    }
    // A damaged manifest is no stage's mark.
    fs::create_directories(m_dir / "damaged");
    write_file(m_dir / "damaged" / "manifest.json", R"({"schema": "tigerlod.manif)");
    EXPECT_THROW(OutputDir(m_dir / "damaged", true), usage_error);
}

TEST_F(Fs, AnOutputInsideAnInputFolderIsRefused)
{
    fs::create_directories(m_dir / "ingest" / "county");
    write_file(m_dir / "ingest" / "county" / "a.tlc", "store");
    for (const fs::path& out :
         {m_dir / "ingest" / "county", m_dir / "ingest" / "new", m_dir / "ingest" / "county" / "x"}) {
        try {
            refuse_to_replace_inputs(out, {m_dir / "ingest"});
            FAIL() << out << " inside the input was accepted";
        } catch (const usage_error& e) {
            EXPECT_NE(std::string(e.what()).find("lies inside the input"), std::string::npos) << e.what();
        }
    }
    EXPECT_EQ(read_file(m_dir / "ingest" / "county" / "a.tlc"), "store");
    // A sibling, and a folder beside an input file, are fine.
    EXPECT_NO_THROW(refuse_to_replace_inputs(m_dir / "color", {m_dir / "ingest"}));
    EXPECT_NO_THROW(refuse_to_replace_inputs(m_dir / "ingest" / "out", {m_dir / "ingest" / "county" / "a.tlc"}));
}

TEST_F(Fs, AnOutputFolderKeepsTheTimesOfFilesWhoseBytesDidNotChange)
{
    // A workflow engine reruns the jobs whose input files are newer than
    // their outputs: after a rebuild, a store with the same bytes must keep
    // its time, and a changed one (or a new one) must not.
    {
        OutputDir out(m_dir / "out", false);
        write_file(out.path() / "same.tlc", "abc");
        write_file(out.path() / "changed.tlc", "abc");
        write_file(out.path() / "longer.tlc", "abc");
        write_file(out.path() / "manifest.json", R"({"schema": "tigerlod.manifest/1"})");
        fs::create_directories(out.path() / "level");
        write_file(out.path() / "level" / "deep.tlc", "deep");
        out.commit();
    }
    const auto old = fs::file_time_type::clock::now() - std::chrono::hours(24);
    for (const char* f : {"same.tlc", "changed.tlc", "longer.tlc", "manifest.json", "level/deep.tlc"}) {
        fs::last_write_time(m_dir / "out" / f, old);
    }
    OutputDir out(m_dir / "out", true);
    out.keep_times_of_unchanged_files(".tlc");
    write_file(out.path() / "same.tlc", "abc");
    write_file(out.path() / "manifest.json", R"({"schema": "tigerlod.manifest/1"})"); // the same bytes: a new time
    write_file(out.path() / "changed.tlc", "abd");
    write_file(out.path() / "longer.tlc", "abcd");
    write_file(out.path() / "new.tlc", "abc");
    fs::create_directories(out.path() / "level");
    write_file(out.path() / "level" / "deep.tlc", "deep");
    out.commit();
    EXPECT_EQ(fs::last_write_time(m_dir / "out" / "same.tlc"), old);
    EXPECT_EQ(fs::last_write_time(m_dir / "out" / "level" / "deep.tlc"), old);
    EXPECT_GT(fs::last_write_time(m_dir / "out" / "changed.tlc"), old);
    EXPECT_GT(fs::last_write_time(m_dir / "out" / "longer.tlc"), old);
    EXPECT_GT(fs::last_write_time(m_dir / "out" / "new.tlc"), old);
    EXPECT_GT(fs::last_write_time(m_dir / "out" / "manifest.json"), old);
    std::ifstream in(m_dir / "out" / "changed.tlc");
    std::string text;
    in >> text;
    EXPECT_EQ(text, "abd");
}
