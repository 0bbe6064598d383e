#pragma once
/// @file raster.hpp
/// Steps 1 and 2 of the paper on OpenGL: the eps-Voronoi diagram of the
/// chains in the stencil buffer, then the compliance test of shortcuts drawn
/// under "stencil != own class".
///
/// Work per tile is proportional to the geometry, not to the tile's area:
/// the depth-stencil buffer is cleared once, and after each tile the tents'
/// footprints are drawn again to restore it (depth 1, stencil 0), so a
/// county at a 25 cm pixel never pays for clearing billions of pixels.

#include "gl/context.hpp"
#include "simplification/coloring.hpp"
#include "core/metric.hpp"

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace tigerlod::simplify {

enum class Compliance { ssbo, readback };

struct RasterOptions {
    Metric metric = Metric::l2;
    Compliance compliance = Compliance::ssbo;
    /// Two framebuffers: a tile's box (where its tested parts are) is drawn in
    /// the small one when it fits, else in the large one. llvmpipe pays per
    /// flush for every 64-pixel bin of the framebuffer, and most boxes are small.
    uint32_t window_pixels = 1024;   ///< the framebuffer's width and height: larger boxes are drawn in pieces
    uint32_t max_tile_pixels = 4096; ///< the largest tile
    /// Tents' quads reach this far beyond eps (pixels): every pixel centre
    /// within eps is inside, with room for the float rounding of the
    /// corners (a few units in the last place: under 0.1 pixel for endpoints
    /// 2^17 pixels away, a 33 km segment at eps 1 m). The reset pass covers
    /// the same quads. It was 1 pixel: 0.25 left every store of the tract
    /// and contour ladders the same, and both ran 5-6% faster.
    double margin_px = 0.25;
    // Fragments within end_margin_px (coloring.hpp) of a shortcut's ends are
    // not tested: a constant, since simplify and tigerlod-color settle the
    // shortcuts too short for a tested pixel by it.
};

/// A chain drawn into the Voronoi diagram.
struct TentChain {
    std::span<const GridPoint> points;
    double eps = 0; ///< grid units
    uint8_t cls = 0;
    std::span<const uint8_t> keep = {}; ///< as ChainGeom::keep: segment i is drawn only if empty or keep[i]
};

/// A shortcut to test; `id` indexes the caller's result vector. Only the
/// part between a + t0 (b - a) and a + t1 (b - a) is drawn, where the caller
/// knows the rest cannot fail; the ends' margin stays that of a and b. One
/// shortcut may be given as several parts with the same id.
struct TestSegment {
    GridPoint a, b;
    uint8_t cls = 0;
    uint32_t id = 0;
    float t0 = 0, t1 = 1;
};

struct RasterStats {
    size_t tiles = 0;
    size_t one_piece_boxes = 0;       ///< tiles whose tested parts fit in the framebuffer (drawn in one piece)
    size_t tent_segments = 0;         ///< drawn: those whose reach touches a tested part
    size_t tent_segments_skipped = 0; ///< of the tiles' chains, too far from every tested part
    size_t drawn_segments = 0;        ///< parts drawn
    double drawn_pixels = 0;          ///< their length in pixels
    size_t readback_rounds = 0;
    double voronoi_seconds = 0;
    double compliance_seconds = 0;
};

/// A tile's geometry ready for the GPU, computed without OpenGL, so on any
/// thread: Raster::prepare, then Raster::draw on the GL thread.
class PreparedTile {
  public:
    PreparedTile();
    ~PreparedTile();
    PreparedTile(PreparedTile&&) noexcept;
    PreparedTile& operator=(PreparedTile&&) noexcept;

  private:
    friend class Raster;
    struct Data;
    std::unique_ptr<Data> m;
}; // class PreparedTile

class Raster {
  public:
    /// Compiles the shaders and makes the framebuffers. Throws environment_error.
    Raster(gl::Context& ctx, const RasterOptions& opt);
    ~Raster();
    Raster(const Raster&) = delete;
    Raster& operator=(const Raster&) = delete;

    /// Draw the eps-Voronoi diagram of `tents` in `tile`, test `segs`, and set
    /// fails[seg.id] = 1 for each that leaves its chain's region (inside a
    /// batch: at end_batch). Only the
    /// tents whose reach comes near a tested part are drawn: the diagram is
    /// exact where it is read, and its cost follows the tested geometry.
    void run_tile(const TileSpec& tile, std::span<const TentChain> tents, std::span<const TestSegment> segs,
                  std::vector<uint8_t>& fails);
    /// run_tile's work without OpenGL (the cells near the tested parts, the
    /// tents that reach them, the instances by class): thread-safe, so the
    /// GL thread is left only the drawing. run_tile = draw(prepare(...)).
    PreparedTile prepare(const TileSpec& tile, std::span<const TentChain> tents,
                         std::span<const TestSegment> segs) const;
    /// Draws a prepared tile: sets fails[seg.id] = 1 for each failing segment
    /// (inside a batch: at end_batch).
    void draw(const PreparedTile& tile, std::vector<uint8_t>& fails);

    /// Batches the tiles run until end_batch, holding at most `parts` test
    /// segments in all: with the storage-buffer compliance their flags are
    /// read back once at the end, so the GL pipeline never waits per tile
    /// (with the read-back compliance each tile still reads its pixels).
    void begin_batch(size_t parts);
    /// Sets fails[seg.id] = 1 for each failing segment of the batch.
    void end_batch(std::vector<uint8_t>& fails);

    const RasterStats& stats() const noexcept { return m_stats; }

  private:
    struct Impl;
    /// Where a tile's box is drawn: the framebuffer's size, the box's
    /// origin in pixels, its width and height.
    struct Frame;
    /// With the storage-buffer compliance: the buffer the tile's test
    /// shader writes its flags into, from index `base` of the batch.
    void bind_tile_flags(const PreparedTile::Data& d, size_t base);
    /// The framebuffer, bound, with the box's piece [ox, ex) x [oy, ey) at its
    /// corner, scissored to it.
    Frame bind_frame(int64_t ox, int64_t oy, int64_t ex, int64_t ey);
    /// Use `prog` on the tents' quads as tent_vs places them (the tent and
    /// the reset pass share it, so both cover the same pixels).
    void use_tent_quads(unsigned prog, const Frame& f, float z);
    /// The passes below draw one piece of the tile's box (PreparedTile::Data::Piece).
    /// Step 1: the lower envelope of the distance tents; the stencil gets each region's class.
    void draw_tents(const PreparedTile::Data& d, size_t piece, const Frame& f);
    /// Step 2: the shortcut parts under stencil != class; with the
    /// read-back compliance, `removed` gets the parts seen failing.
    void test_parts(const PreparedTile::Data& d, size_t piece, const Frame& f, bool ssbo,
                    std::vector<uint8_t>& removed);
    /// The paper's Algorithm 5.1: unique colours, read back, drop the
    /// colours seen, repeat until nothing changes (a part may hide another).
    void read_back_failures(const PreparedTile::Data& d, size_t piece, const Frame& f, std::vector<uint8_t>& removed);
    /// Restore the buffer where the tents were drawn: depth 1, stencil 0.
    void reset_tents(const PreparedTile::Data& d, size_t piece, const Frame& f);

    gl::Context& m_ctx;
    RasterOptions m_opt;
    RasterStats m_stats;
    std::unique_ptr<Impl> m_impl;
}; // class Raster

} // namespace tigerlod::simplify
