// The config schema: the reference in configs/README.md is the schema's, the
// example configs pass it, a section becomes exactly its stage's flags, and
// a bad value is named by file, line and key.

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/errors.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using namespace tigerlod;

namespace {

std::string slurp(const fs::path& p)
{
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

class ConfigFiles : public ::testing::Test {
  protected:
    void SetUp() override
    {
        m_dir = fs::temp_directory_path() /
                ("tigerlod-config-" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    fs::path write(const std::string& text)
    {
        const fs::path p = m_dir / "cfg.yaml";
        std::ofstream(p) << text;
        return p;
    }
    std::string error_of(const std::string& text)
    {
        try {
            config::ConfigFile::load(write(text));
        } catch (const config_error& e) {
            return e.what();
        }
        return "no error";
    }
    fs::path m_dir;
};

} // namespace

TEST(ConfigDoc, ReadmeIsTheSchemasReference)
{
    const fs::path readme = fs::path(TIGERLOD_SOURCE_DIR) / "configs" / "README.md";
    const std::string want = config::reference_markdown();
    if (const char* update = std::getenv("TIGERLOD_UPDATE_CONFIG_DOC"); update != nullptr && *update == '1') {
        std::ofstream(readme, std::ios::binary) << want;
    }
    EXPECT_EQ(slurp(readme), want) << "configs/README.md is generated from config/schema.cpp: run scripts/config-doc";
}

TEST(ConfigSchema, EveryExampleConfigPassesIt)
{
    size_t n = 0;
    for (const auto& e : fs::directory_iterator(fs::path(TIGERLOD_SOURCE_DIR) / "configs")) {
        if (e.path().extension() == ".yaml") {
            SCOPED_TRACE(e.path().string());
            EXPECT_NO_THROW(config::ConfigFile::load(e.path()));
            ++n;
        }
    }
    EXPECT_GE(n, 5U);
}

TEST(ConfigSchema, KeysAreUniqueAndEachStageKeyHasAFlag)
{
    std::set<std::string> names;
    for (const auto& k : config::keys()) {
        EXPECT_TRUE(names.insert(k.name).second) << k.name;
        EXPECT_FALSE(k.doc.empty()) << k.name;
        if (!k.stages.empty()) {
            EXPECT_FALSE(k.flag.empty()) << k.name;
        }
        // A section is declared before the keys in it.
        const auto dot = k.name.rfind('.');
        if (dot != std::string::npos) {
            EXPECT_TRUE(names.contains(k.name.substr(0, dot))) << k.name;
        }
    }
    EXPECT_THROW(config::key("simplify.nope"), std::logic_error);
}

TEST(ConfigSchema, LimitsSayWhatTheyAllow)
{
    const Limits fraction{0, 0.5, true};
    EXPECT_EQ(fraction.text(), "in (0, 0.5]");
    EXPECT_FALSE(fraction.contains(0));
    EXPECT_TRUE(fraction.contains(0.5));
    EXPECT_EQ(thread_limits.text(), "in 0..1024");
    EXPECT_FALSE(thread_limits.contains(1.5));
    EXPECT_EQ((Limits{0, std::numeric_limits<double>::infinity(), false, false, true}).text(), ">= 0");
    EXPECT_EQ((Limits{0, std::numeric_limits<double>::infinity(), true}).text(), "> 0");
    EXPECT_EQ(Limits{}.text(), "");
}

TEST(ConfigSchema, AViewportIsTwoIntegersInItsLimitsAndNothingElse)
{
    const auto& limits = config::key("render.size").limits;
    using P = std::pair<unsigned, unsigned>;
    EXPECT_EQ(config::parse_viewport("1280x720", limits), P(1280, 720));
    EXPECT_EQ(config::parse_viewport("16x16384", limits), P(16, 16384));
    for (const char* bad : {"big", "15x720", "1280x16385", "1280x", "x720", "1280X720", "1280x720x3", " 1280x720",
                            "1280 x 720", "+1280x720", "-1x720", "1280.5x720", "99999999999x720", ""}) {
        SCOPED_TRACE(bad);
        EXPECT_FALSE(config::parse_viewport(bad, limits));
    }
}

TEST_F(ConfigFiles, ASectionBecomesExactlyItsStagesFlags)
{
    const fs::path file = write("name: t\n"
                                "simplify:\n"
                                "  tolerances_m: [1, 4.5]\n"
                                "  metric: l1\n"
                                "  class_scale: {S1400: 0.5, H3010: 2}\n"
                                "  projection_scale: false\n"
                                "  point_constraints: true\n"
                                "  lazy: false\n"
                                "  points: pts/p.csv\n"
                                "  tile_pixels: 2048\n"
                                "pack: {tile_mb: 2}\n");
    using V = std::vector<std::string>;
    EXPECT_EQ(config::stage_args(file, "color"),
              (V{"--tolerances=1,4.5", "--metric=l1", "--class-scale=S1400=0.5,H3010=2", "--no-projection-scale",
                 "--tile-pixels=2048"}));
    EXPECT_EQ(config::stage_args(file, "simplify"),
              (V{"--tolerances=1,4.5", "--metric=l1", "--class-scale=S1400=0.5,H3010=2", "--no-projection-scale",
                 "--points=" + (m_dir / "pts" / "p.csv").string(), "--exhaustive", "--tile-pixels=2048"}));
    EXPECT_EQ(config::stage_args(file, "pack"), (V{"--tile-mb=2"}));
    EXPECT_EQ(config::stage_args(file, "verify"), V{});
}

TEST_F(ConfigFiles, ABadValueIsNamedByFileLineAndKey)
{
    const std::string f = (m_dir / "cfg.yaml").string();
    EXPECT_EQ(error_of("name: t\nsimplify:\n  tile_pixels: 10\n"),
              f + ":3: 'simplify.tile_pixels' must be in 64..16384");
    EXPECT_EQ(error_of("simplify:\n  tolerances_m: [4, 1]\n"),
              f + ":2: 'simplify.tolerances_m' must increase: 1 follows 4");
    EXPECT_EQ(error_of("simplify:\n  tolerances_m: [0, 1]\n"),
              f + ":2: 'simplify.tolerances_m'[0] must be in [0.0001, 1e+06]");
    EXPECT_EQ(error_of("simplify:\n  class_scale: {S1400: 0}\n"), f + ":2: 'simplify.class_scale'[S1400] must be > 0");
    EXPECT_EQ(error_of("simplify:\n  metric: l3\n"), f + ":2: 'simplify.metric' must be l2, l1 or linf, got 'l3'");
    EXPECT_EQ(error_of("verify: {threads: 2000}\n"), f + ":1: 'verify.threads' must be in 0..1024");
    EXPECT_EQ(error_of("verify:\n  color: 1\n"), f + ":2: unknown key 'verify.color' (known: max_items, threads)");
    EXPECT_EQ(error_of("dataset:\n  fetch: {npm: x, from: y}\n"),
              f + ":2: unknown key 'dataset.fetch.from' (known: npm, into)");
    EXPECT_EQ(error_of("- a\n"), f + ":1: 'the config' must be a mapping");
    EXPECT_EQ(error_of("name: [\n").rfind(f + ":2: not valid YAML: ", 0), 0U); // yaml-cpp's words follow
    // A key given twice (yaml-cpp reads the first, the workflow's PyYAML the
    // last): refused at the second, anywhere in the document.
    EXPECT_EQ(error_of("name: a\nname: b\n"), f + ":2: duplicate key 'name' (first at line 1): give each key once");
    EXPECT_EQ(error_of("simplify:\n  tolerances_m: [1, 2]\n  threads: 1\n  tolerances_m: [4]\n"),
              f + ":4: duplicate key 'tolerances_m' (first at line 2): give each key once");
    EXPECT_EQ(error_of("levels:\n  - {name: a, code: X, name: b}\n"),
              f + ":2: duplicate key 'name' (first at line 2): give each key once");
}
