#pragma once
// What the tests of the simplification share: hand-made stores in grid
// units, the OSMesa context and raster engines, options with eps in grid
// metres, and a store's chains read back. Tests only (GoogleTest).

#include "core/segment_grid.hpp"
#include "gl/context.hpp"
#include "simplification/raster.hpp"
#include "simplification/simplifier.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <memory>
#include <string>
#include <vector>

namespace tigerlod::simplify::testing {

using chains::ChainStore;
using Pts = std::vector<GridPoint>;

/// A store in grid units (1 cm); every chain owned unless `halo`.
struct MapBuilder {
    ChainStore s;
    MapBuilder()
    {
        s.level_name = "test";
        s.partition = "all";
    }
    MapBuilder& chain(uint64_t id, const Pts& pts, const std::string& left = "L", const std::string& right = "R",
                      const std::string& cls = "", uint32_t flags = 0)
    {
        chains::ChainInfo c;
        c.id = id;
        c.left = s.intern(left);
        c.right = s.intern(right);
        c.feature_class = s.intern(cls);
        c.flags = flags | (pts.front() == pts.back() ? chains::chain_closed : 0U);
        s.add_chain(c, pts);
        return *this;
    }
    MapBuilder& point(const std::string& unit, GridPoint p)
    {
        s.constraints.push_back({s.intern(unit), chains::constraint_internal, p});
        return *this;
    }
};

/// The context of the tests: one, current on the tests' thread; OSMesa, or
/// the backend TIGERLOD_TEST_GL names (egl: the raster tests on a GPU).
inline gl::Context& context()
{
    static std::unique_ptr<gl::Context> ctx = [] {
        const char* name = std::getenv("TIGERLOD_TEST_GL");
        const auto backend = gl::parse_backend(name != nullptr ? name : "osmesa");
        if (!backend) {
            throw std::invalid_argument(std::string("TIGERLOD_TEST_GL: no backend ") + name);
        }
        auto c = gl::Context::create(*backend);
        std::printf("[ info ] %s\n", c->describe().c_str());
        return c;
    }();
    return *ctx;
}

/// One raster engine per mode, shared by the tests.
inline Raster& raster(Compliance mode = Compliance::ssbo, Metric metric = Metric::l2)
{
    // The context first: statics are destroyed in reverse order, so the
    // engines go before the context they use.
    gl::Context& ctx = context();
    static std::map<std::pair<int, int>, std::unique_ptr<Raster>> engines;
    auto& r = engines[{int(mode), int(metric)}];
    if (!r) {
        RasterOptions o;
        o.compliance = mode;
        o.metric = metric;
        o.max_tile_pixels = 1024;
        r = std::make_unique<Raster>(ctx, o);
    }
    return *r;
}

inline SimplifyOptions plain(Metric m = Metric::l2)
{
    SimplifyOptions o;
    o.metric = m;
    o.projection_scale = false; // eps_m / 0.01 grid units exactly
    o.color.tile_pixels = 1024;
    o.color.metric = m;
    return o;
}

inline ChainStore run(const ChainStore& in, double eps_m, SimplifyOptions o = plain(), ToleranceStats* stats = nullptr,
                      Compliance mode = Compliance::ssbo)
{
    ToleranceStats st;
    auto out = simplify_store(in, eps_m, o, &raster(mode, o.metric), nullptr, st);
    if (stats) {
        *stats = st;
    }
    return out;
}

/// As run, without the eps-Voronoi test: the exact rules alone (`--shortcut-test exact`), no OpenGL.
inline ChainStore run_exact(const ChainStore& in, double eps_m, SimplifyOptions o = plain(),
                            ToleranceStats* stats = nullptr)
{
    ToleranceStats st;
    auto out = simplify_store(in, eps_m, o, nullptr, nullptr, st);
    if (stats) {
        *stats = st;
    }
    return out;
}

inline Pts points_of(const ChainStore& s, uint64_t id)
{
    for (const auto& c : s.chains) {
        if (c.id == id) {
            const auto p = s.chain_points(c);
            return {p.begin(), p.end()};
        }
    }
    ADD_FAILURE() << "no chain " << id;
    return {};
}

/// Intersections other than shared end points among all chains of the stores.
inline size_t count_intersections(const std::vector<const ChainStore*>& stores)
{
    std::vector<Segment> segs;
    for (const auto* s : stores) {
        for (const auto& c : s->chains) {
            const auto p = s->chain_points(c);
            for (size_t i = 0; i + 1 < p.size(); ++i) {
                segs.push_back({p[i], p[i + 1], uint32_t(segs.size())});
            }
        }
    }
    return find_intersections(segs, 1).size();
}

/// Meetings, other than at shared end points, between each chain of `out`
/// (simplified) and every chain of `in` with another id (the originals,
/// halo included): what a view drawing one chain at this LOD beside its
/// neighbours at LOD 0 would show.
inline size_t count_lod_meetings(const ChainStore& out, const ChainStore& in)
{
    size_t n = 0;
    for (const auto& c : out.chains) {
        std::vector<Segment> segs;
        const auto own = out.chain_points(c);
        for (size_t i = 0; i + 1 < own.size(); ++i) {
            segs.push_back({own[i], own[i + 1], 0});
        }
        const size_t own_segments = segs.size();
        for (const auto& o : in.chains) {
            if (o.id == c.id) {
                continue;
            }
            const auto p = in.chain_points(o);
            for (size_t i = 0; i + 1 < p.size(); ++i) {
                segs.push_back({p[i], p[i + 1], 1});
            }
        }
        for (const auto& x : find_intersections(segs, 1)) {
            n += (x.first < own_segments) != (x.second < own_segments) ? 1 : 0;
        }
    }
    return n;
}

} // namespace tigerlod::simplify::testing
