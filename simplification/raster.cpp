#include "simplification/raster.hpp"

#include "core/errors.hpp"
#include "gl/program.hpp"
#include "simplification/cell_cover.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tigerlod::simplify {

namespace {

// The same bits on every implementation. The fragment shaders decide every
// pixel with +, - and * alone (and comparisons, abs, min, max, clamp), each
// on a variable declared precise: GLSL rounds those correctly and may not
// fuse them into an fma (GLSL 4.50, 4.7.1 and 4.8.1), so llvmpipe and any
// GPU and driver compute the same floats. Nothing else may decide:
//  - division, sqrt, length() and distance() are not correctly rounded (a
//    GPU's division is within 2.5 ulp): the reciprocals come from the CPU,
//    in double rounded once (a_k, the tested parts' direction and length);
//  - which pixels a quad covers depends on the rasterizer: the quads reach
//    past every pixel the shader can accept, and the shader decides;
//  - a 24-bit depth buffer's conversion may round or truncate: the depth
//    buffer holds 32-bit floats, the key times a power of two, exactly;
//  - a GPU may flush denormals to zero: the CPU rounds coordinates and
//    directions under 1e-20 to 0 and collapses segments shorter than 1e-6
//    pixel to a point, after which every difference and product the shaders
//    form is 0 or normal, and the shaders take a square under 1e-30 and a
//    key under 1e-25 as 0, whatever the hardware made of them.
// Pixel centres are the tile's (gl_FragCoord plus the piece's integer
// origin, exact), so how a tile is cut into pieces changes nothing either.
// On an NVIDIA H200 the shaders before these (length(), division, quad
// coverage, 24-bit depth) gave other stores than llvmpipe on the tract
// coarse and the contour ladders; these give the same bytes (BENCHMARKS.md,
// "OpenGL on a GPU"). tests/unit/simplify/test_raster_spec.cpp checks every
// decision against this arithmetic, pixel by pixel.

// The tent's key at pixel centre p for segment ab: its squared L2 distance,
// or its L1 or Linf distance (METRIC 0, 1, 2), with k from the CPU: L2
// (1 / |b - a|^2, 0, 0, 0); L1 and Linf the reciprocals of d.x, d.y,
// d.x - d.y and d.x + d.y (0 where that is 0), d = b - a. L1 and Linf: the
// minimum of a convex function of t over [0, 1], at t = 0, 1 or a breakpoint.
constexpr const char* distance_glsl = R"(
float tent_key(vec2 p, vec4 seg, vec4 k) {
    precise vec2 u = p - seg.xy;
    precise vec2 d = seg.zw - seg.xy;
#if METRIC == 0
    precise float t = u.x * d.x + u.y * d.y;
    precise float len2 = d.x * d.x + d.y * d.y;
    precise float key;
    if (t <= 0.0) {
        key = u.x * u.x + u.y * u.y;
    } else if (t >= len2) {
        precise vec2 w = p - seg.zw;
        key = w.x * w.x + w.y * w.y;
    } else {
        precise float c = u.x * d.y - u.y * d.x;
        precise float c2 = c * c;
        key = (c2 < 1e-30 ? 0.0 : c2) * k.x;
    }
    return key < 1e-25 ? 0.0 : key;
#else
#if METRIC == 1
#define MLEN(v) (abs((v).x) + abs((v).y))
#else
#define MLEN(v) max(abs((v).x), abs((v).y))
#endif
    precise vec2 w = u - d;
    precise float best = min(MLEN(u), MLEN(w));
    precise vec4 ts = vec4(u.x * k.x, u.y * k.y, (u.x - u.y) * k.z, (u.x + u.y) * k.w);
    for (int i = 0; i < 4; ++i) {
        precise vec2 v = u - clamp(ts[i], 0.0, 1.0) * d;
        best = min(best, MLEN(v));
    }
    return best < 1e-25 ? 0.0 : best;
#endif
}
)";

constexpr const char* tent_vs = R"(#version 450 core
layout(location = 0) in vec4 a_seg; // a.xy, b.xy in tile pixels
layout(location = 1) in float a_eps; // pixels
layout(location = 2) in vec2 a_clip; // the part of the segment whose quad is drawn: t0, t1
layout(location = 3) in float a_corner; // 0, 1 at a; 2, 3 at b; even: left
layout(location = 4) in vec4 a_k; // tent_key's reciprocals
uniform vec2 u_size;
uniform vec2 u_origin; // the drawn box's corner in tile pixels (integers)
uniform float u_reach;
uniform float u_pad;
uniform float u_z; // 0 for the tents (their fragments set the depth); 1 to reset
flat out vec4 v_seg;
flat out vec4 v_k;
flat out float v_eps;
void main() {
    vec2 a = a_seg.xy - u_origin, b = a_seg.zw - u_origin, d = b - a;
    float len = length(d);
    vec2 u = len > 0.0 ? d / len : vec2(1.0, 0.0);
    vec2 n = vec2(-u.y, u.x);
    float r = a_eps * u_reach + u_pad;
    int c = int(a_corner);
    // The quad of the part [t0, t1] (all of it: a and b exactly), u_pad
    // beyond eps. The fragments compute the key to the whole segment, so a
    // pixel gets the same depth from any quad that covers it.
    vec2 p = (c < 2 ? mix(a, b, a_clip.x) - u * r : mix(a, b, a_clip.y) + u * r) + ((c & 1) == 0 ? n * r : -n * r);
    gl_Position = vec4(p / u_size * 2.0 - 1.0, u_z, 1.0);
    v_seg = a_seg;
    v_k = a_k;
    v_eps = a_eps;
}
)";

constexpr const char* tent_fs_head = R"(#version 450 core
flat in vec4 v_seg;
flat in vec4 v_k;
flat in float v_eps;
uniform vec2 u_origin;
uniform float u_depth_scale; // a power of two: every key within eps lands at depth <= 1/2
layout(location = 0) out vec4 o_color;
)";

// The depth buffer holds 32-bit floats: the key times a power of two,
// exactly, so the depth test compares the keys themselves.
constexpr const char* tent_fs_main = R"(
void main() {
    o_color = vec4(0.0);
    precise vec2 p = gl_FragCoord.xy + u_origin;
    precise float key = tent_key(p, v_seg, v_k);
#if METRIC == 0
    precise float limit = v_eps * v_eps;
#else
    precise float limit = v_eps;
#endif
    if (key > limit) discard;
    gl_FragDepth = key * u_depth_scale;
}
)";

/// The reset pass: the tents' quads at depth 1 (z = 1 is depth 1.0
/// exactly), with a fragment shader that computes nothing, so the
/// rasterizer writes depth and stencil without running a distance per pixel.
constexpr const char* reset_fs = R"(#version 450 core
void main() {
}
)";

// A tested part: the pixels whose centre is within half a pixel of it
// across and between its ends along (the shader decides; the quad reaches
// 1/16 pixel further), less those within the end margin of the shortcut's
// ends a and b.
constexpr const char* test_vs = R"(#version 450 core
layout(location = 0) in vec4 a_seg; // the shortcut's a.xy, b.xy in tile pixels
layout(location = 1) in uint a_id;
layout(location = 2) in vec4 a_part; // the part's first point, and its unit direction
layout(location = 3) in float a_corner; // 0, 1 at the first point; 2, 3 at the last; even: left
layout(location = 4) in float a_len; // the part's length
uniform vec2 u_size;
uniform vec2 u_origin;
flat out vec4 v_seg;
flat out vec4 v_part;
flat out float v_len;
flat out uint v_id;
void main() {
    const float m = 1.0 / 16.0;
    vec2 u = a_part.zw, n = vec2(-u.y, u.x) * (0.5 + m);
    int c = int(a_corner);
    vec2 p = a_part.xy - u_origin + u * (c < 2 ? -m : a_len + m) + ((c & 1) == 0 ? n : -n);
    // Depth 0.9995 under GL_GREATER: only where a tent was drawn (tents'
    // depths are at most 1/2, the background is 1).
    gl_Position = vec4(p / u_size * 2.0 - 1.0, 0.999, 1.0);
    v_seg = a_seg;
    v_part = a_part;
    v_len = a_len;
    v_id = a_id;
}
)";

constexpr const char* test_in_part = R"(
flat in vec4 v_seg;
flat in vec4 v_part;
flat in float v_len;
flat in uint v_id;
uniform vec2 u_origin;
uniform float u_end_margin2;
bool tested() {
    precise vec2 p = gl_FragCoord.xy + u_origin;
    precise vec2 w = p - v_part.xy;
    precise float along = w.x * v_part.z + w.y * v_part.w;
    precise float across = w.y * v_part.z - w.x * v_part.w;
    if (along < 0.0 || along > v_len || abs(across) > 0.5) return false;
    precise vec2 ea = p - v_seg.xy;
    precise vec2 eb = p - v_seg.zw;
    precise float da = ea.x * ea.x + ea.y * ea.y;
    precise float db = eb.x * eb.x + eb.y * eb.y;
    return da >= u_end_margin2 && db >= u_end_margin2;
}
)";

constexpr const char* test_fs_ssbo_head = R"(#version 450 core
layout(early_fragment_tests) in;
layout(std430, binding = 0) buffer Flags { uint flags[]; };
)";

constexpr const char* test_fs_ssbo_main = R"(
void main() {
    if (tested()) flags[v_id] = 1u;
}
)";

constexpr const char* test_fs_readback_head = R"(#version 450 core
layout(location = 0) out vec4 o_color;
)";

constexpr const char* test_fs_readback_main = R"(
void main() {
    if (!tested()) discard;
    uint c = v_id + 1u;
    o_color = vec4(float(c & 255u), float((c >> 8) & 255u), float((c >> 16) & 255u), 255.0) / 255.0;
}
)";

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct TentInstance {
    float ax, ay, bx, by, eps;
    float t0 = 0, t1 = 1;      ///< the part whose quad is drawn
    float k[4] = {0, 0, 0, 0}; ///< tent_key's reciprocals (tent_reciprocals)
};
struct TestInstance {
    float ax, ay, bx, by; ///< the shortcut's ends
    uint32_t id;
    float t0, t1;         ///< the part tested
    float px, py, ux, uy; ///< the part's first point and unit direction (part_geometry)
    float len;            ///< the part's length
};

/// The reciprocals tent_key reads for segment ab (pixels), in double and
/// rounded once, on the CPU: the same bits on every machine.
void tent_reciprocals(TentInstance& t, Metric metric)
{
    double dx = double(t.bx) - t.ax, dy = double(t.by) - t.ay;
    if (dx * dx + dy * dy < 1e-12) { // a point: no reciprocal of a vanishing length
        t.bx = t.ax;
        t.by = t.ay;
        dx = dy = 0;
    }
    auto inv = [](double v) { return std::abs(v) >= 1e-6 ? static_cast<float>(1.0 / v) : 0.0f; };
    if (metric == Metric::l2) {
        const double len2 = dx * dx + dy * dy; // 0 or at least 1e-12
        t.k[0] = len2 > 0 ? static_cast<float>(1.0 / len2) : 0.0f;
        t.k[1] = t.k[2] = t.k[3] = 0;
    } else {
        t.k[0] = inv(dx);
        t.k[1] = inv(dy);
        t.k[2] = inv(dx - dy);
        t.k[3] = inv(dx + dy);
    }
}

/// The tested part's first point, unit direction and length (pixels),
/// from its shortcut's ends and [t0, t1], in double, each rounded once.
void part_geometry(TestInstance& t)
{
    const double dx = double(t.bx) - t.ax, dy = double(t.by) - t.ay;
    const double x0 = t.ax + double(t.t0) * dx, y0 = t.ay + double(t.t0) * dy;
    const double x1 = t.ax + double(t.t1) * dx, y1 = t.ay + double(t.t1) * dy;
    const double len = std::hypot(x1 - x0, y1 - y0);
    t.px = static_cast<float>(x0);
    t.py = static_cast<float>(y0);
    auto unit = [](double v) { return std::abs(v) >= 1e-20 ? static_cast<float>(v) : 0.0f; };
    t.ux = len > 0 ? unit((x1 - x0) / len) : 1.0f;
    t.uy = len > 0 ? unit((y1 - y0) / len) : 0.0f;
    t.len = static_cast<float>(len);
}

/// Runs of instances of one class: class -> (first, count), in drawing order.
using ClassRanges = std::vector<std::pair<uint8_t, std::pair<GLuint, GLsizei>>>;

/// Append `count` instances of class `cls` from `first` to `rs`, joining the
/// last run when it is of the same class.
void add_range(ClassRanges& rs, uint8_t cls, GLuint first, GLsizei count)
{
    if (!rs.empty() && rs.back().first == cls) {
        rs.back().second.second += count;
    } else {
        rs.push_back({cls, {first, count}});
    }
}

/// A part of a tile's box that fits in the framebuffer: the tents that
/// reach it and the tested parts in it, each by class.
struct TilePiece {
    int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0; ///< tile pixels
    std::vector<TentInstance> inst;         ///< tents, by class
    ClassRanges ranges, sranges;
    std::vector<TestInstance> tests; ///< test parts by class, id = their index in the tile's ids
};

} // namespace

/// What Raster::draw uploads and draws for a tile.
struct PreparedTile::Data {
    std::vector<TilePiece> pieces;
    std::vector<uint32_t> ids;                  ///< the caller's id of each test part
    int64_t sx0 = 0, sy0 = 0, sx1 = 0, sy1 = 0; ///< the box of the tested parts' cells, in tile pixels
    double eps_max = 0;                         ///< pixels
    size_t tent_segments = 0, tent_skipped = 0;
    double drawn_pixels = 0;
};

PreparedTile::PreparedTile() : m(std::make_unique<Data>()) {}
PreparedTile::~PreparedTile() = default;
PreparedTile::PreparedTile(PreparedTile&&) noexcept = default;
PreparedTile& PreparedTile::operator=(PreparedTile&&) noexcept = default;

namespace {

/// A quad is four vertices that carry the item and their corner, drawn as
/// two indexed triangles: one non-instanced draw, which Mesa's draw module
/// shades in wide batches (an instanced draw of four-vertex strips costs
/// several microseconds per instance on llvmpipe), and through its vertex
/// cache each corner is shaded once, not the six times of plain triangles.
template <class T> struct QuadVertex {
    T item;
    float corner;
};

/// Quads [first, first + count) of the bound vertex array, two triangles
/// each (corners 0 1 2, 2 1 3) through the shared index buffer.
void draw_quads(const gl::Api& gl, size_t first, size_t count)
{
    gl.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(count * 6), GL_UNSIGNED_INT,
                    reinterpret_cast<const void*>(first * 6 * sizeof(uint32_t)));
}

} // namespace

struct Raster::Impl {
    const gl::Api& gl;
    GLuint tent_prog = 0, reset_prog = 0, test_prog = 0;
    GLuint vao_tent = 0, vao_test = 0, vbo_tent = 0, vbo_test = 0;
    GLuint ibo = 0;       ///< quad indices 4q + {0 1 2 2 1 3}, bound to both vertex arrays
    size_t ibo_quads = 0; ///< quads it holds
    /// Grow the index buffer to at least `quads` quads.
    void ensure_indices(size_t quads)
    {
        if (quads <= ibo_quads) {
            return;
        }
        const size_t n = std::max(quads, 2 * ibo_quads);
        std::vector<uint32_t> idx(n * 6);
        for (size_t q = 0; q < n; ++q) {
            const auto b = static_cast<uint32_t>(4 * q);
            const uint32_t tri[6] = {b, b + 1, b + 2, b + 2, b + 1, b + 3};
            std::copy(tri, tri + 6, idx.begin() + static_cast<std::ptrdiff_t>(6 * q));
        }
        gl.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo); // into the bound vertex array, which has it already
        gl.BufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(idx.size() * sizeof(uint32_t)), idx.data(), GL_STATIC_DRAW);
        ibo_quads = n;
    }
    /// The quads of `items` into the bound vertex array's buffer, written
    /// in place (mapped: no copy of the batch beside the driver's), and
    /// indices for as many.
    template <class T> void upload_quads(const std::vector<T>& items)
    {
        const auto bytes = static_cast<GLsizeiptr>(std::max<size_t>(1, items.size() * 4) * sizeof(QuadVertex<T>));
        gl.BufferData(GL_ARRAY_BUFFER, bytes, nullptr, GL_STREAM_DRAW);
        if (!items.empty()) {
            void* mapped =
                gl.MapBufferRange(GL_ARRAY_BUFFER, 0, bytes, GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT);
            if (mapped == nullptr) {
                throw environment_error("OpenGL: mapping a vertex buffer of " + std::to_string(bytes) +
                                        " bytes failed");
            }
            auto* out = static_cast<QuadVertex<T>*>(mapped);
            for (size_t i = 0; i < items.size(); ++i) {
                for (size_t c = 0; c < 4; ++c) {
                    out[i * 4 + c] = {items[i], static_cast<float>(c)};
                }
            }
            if (gl.UnmapBuffer(GL_ARRAY_BUFFER) != GL_TRUE) {
                throw environment_error("OpenGL: a vertex buffer's content was lost while mapped");
            }
        }
        ensure_indices(items.size());
    }
    /// A framebuffer: depth-stencil, and colour for the read-back compliance.
    struct Target {
        GLuint fbo = 0, rb_depth = 0, rb_color = 0;
        GLsizei size = 0; ///< width and height
    };
    /// The one framebuffer, of window_pixels (at most max_tile_pixels): a
    /// tile's box larger than it is drawn in pieces of its size (Raster::draw).
    Target target;
    /// Make target t (its buffers, cleared to depth 1 and stencil 0).
    void make_target(Target& t, const gl::Context& ctx, Compliance compliance) const
    {
        const auto s = t.size;
        gl.GenFramebuffers(1, &t.fbo);
        gl.BindFramebuffer(GL_FRAMEBUFFER, t.fbo);
        gl.GenRenderbuffers(1, &t.rb_depth);
        gl.BindRenderbuffer(GL_RENDERBUFFER, t.rb_depth);
        gl.RenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH32F_STENCIL8, s, s);
        gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_STENCIL_ATTACHMENT, GL_RENDERBUFFER, t.rb_depth);
        if (compliance == Compliance::readback) {
            gl.GenRenderbuffers(1, &t.rb_color);
            gl.BindRenderbuffer(GL_RENDERBUFFER, t.rb_color);
            gl.RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, s, s);
            gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, t.rb_color);
            const GLenum buf = GL_COLOR_ATTACHMENT0;
            gl.DrawBuffers(1, &buf);
            gl.ReadBuffer(GL_COLOR_ATTACHMENT0);
        } else {
            const GLenum none = GL_NONE;
            gl.DrawBuffers(1, &none);
            gl.ReadBuffer(GL_NONE);
        }
        if (gl.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
            throw environment_error("OpenGL: a " + std::to_string(s) + "x" + std::to_string(s) +
                                    " depth-stencil framebuffer is not supported by " + ctx.describe());
        }
        gl.Viewport(0, 0, s, s);
        gl.Disable(GL_SCISSOR_TEST); // the whole buffer; tiles clip to their box
        gl.ClearDepth(1.0);
        gl.ClearStencil(0);
        gl.ClearColor(0, 0, 0, 0);
        gl.Clear(GL_DEPTH_BUFFER_BIT | GL_STENCIL_BUFFER_BIT | GL_COLOR_BUFFER_BIT);
        if (gl.GetError() != GL_NO_ERROR) {
            throw environment_error("OpenGL: making a " + std::to_string(s) + "x" + std::to_string(s) +
                                    " framebuffer failed on " + ctx.describe());
        }
    }
    bool batching = false;           ///< between begin_batch and end_batch
    size_t batch_capacity = 0;       ///< flags allocated for the batch
    std::vector<uint32_t> batch_ids; ///< the caller's id of each flag of the batch
    /// The flags' storage buffers, one per tile of a batch (reused from batch
    /// to batch). llvmpipe flushes its scene when a buffer the scene writes
    /// is bound again, and Mesa binds the storage buffers again at every
    /// change of program: with one buffer for the batch, every tile's test
    /// pass flushed (tract level at 16 m, one framebuffer: 4,289 fences for
    /// 4,279 tiles in 805 batches).
    std::vector<GLuint> flag_buffers;
    std::vector<size_t> tile_flags; ///< per tile of the batch, its first flag; then the count
    std::vector<uint32_t> zeros;
    explicit Impl(const gl::Api& api) : gl(api) {}

    GLuint link(const std::string& vs, const std::string& fs) const { return gl::link_program(gl, vs, fs); }
    GLint loc(GLuint prog, const char* name) const { return gl.GetUniformLocation(prog, name); }
};

Raster::Raster(gl::Context& ctx, const RasterOptions& opt)
    : m_ctx(ctx), m_opt(opt), m_impl(std::make_unique<Impl>(ctx.api()))
{
    auto& I = *m_impl;
    const auto& gl = ctx.api();
    const std::string metric_define = "#define METRIC " + std::to_string(int(opt.metric)) + "\n";
    I.tent_prog = I.link(tent_vs, std::string(tent_fs_head) + metric_define + distance_glsl + tent_fs_main);
    I.reset_prog = I.link(tent_vs, reset_fs);
    I.test_prog = I.link(test_vs, opt.compliance == Compliance::ssbo
                                      ? std::string(test_fs_ssbo_head) + test_in_part + test_fs_ssbo_main
                                      : std::string(test_fs_readback_head) + test_in_part + test_fs_readback_main);

    gl.GenVertexArrays(1, &I.vao_tent);
    gl.GenBuffers(1, &I.vbo_tent);
    gl.GenBuffers(1, &I.ibo);
    gl.BindVertexArray(I.vao_tent);
    gl.BindBuffer(GL_ARRAY_BUFFER, I.vbo_tent);
    gl.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, I.ibo);
    using TentVertex = QuadVertex<TentInstance>;
    gl.VertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, sizeof(TentVertex), nullptr);
    gl.VertexAttribPointer(1, 1, GL_FLOAT, GL_FALSE, sizeof(TentVertex),
                           reinterpret_cast<const void*>(offsetof(TentInstance, eps)));
    gl.VertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, sizeof(TentVertex),
                           reinterpret_cast<const void*>(offsetof(TentInstance, t0)));
    gl.VertexAttribPointer(3, 1, GL_FLOAT, GL_FALSE, sizeof(TentVertex),
                           reinterpret_cast<const void*>(offsetof(TentVertex, corner)));
    gl.VertexAttribPointer(4, 4, GL_FLOAT, GL_FALSE, sizeof(TentVertex),
                           reinterpret_cast<const void*>(offsetof(TentInstance, k)));
    for (GLuint a = 0; a < 5; ++a) {
        gl.EnableVertexAttribArray(a);
    }

    gl.GenVertexArrays(1, &I.vao_test);
    gl.GenBuffers(1, &I.vbo_test);
    gl.BindVertexArray(I.vao_test);
    gl.BindBuffer(GL_ARRAY_BUFFER, I.vbo_test);
    gl.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, I.ibo);
    using TestVertex = QuadVertex<TestInstance>;
    gl.VertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, sizeof(TestVertex), nullptr);
    gl.VertexAttribIPointer(1, 1, GL_UNSIGNED_INT, sizeof(TestVertex),
                            reinterpret_cast<const void*>(offsetof(TestInstance, id)));
    gl.VertexAttribPointer(2, 4, GL_FLOAT, GL_FALSE, sizeof(TestVertex),
                           reinterpret_cast<const void*>(offsetof(TestInstance, px)));
    gl.VertexAttribPointer(3, 1, GL_FLOAT, GL_FALSE, sizeof(TestVertex),
                           reinterpret_cast<const void*>(offsetof(TestVertex, corner)));
    gl.VertexAttribPointer(4, 1, GL_FLOAT, GL_FALSE, sizeof(TestVertex),
                           reinterpret_cast<const void*>(offsetof(TestInstance, len)));
    for (GLuint a = 0; a < 5; ++a) {
        gl.EnableVertexAttribArray(a);
    }
    gl.BindVertexArray(0);

    if (opt.max_tile_pixels < 8 || opt.max_tile_pixels > 16384 || opt.window_pixels < 8) {
        throw std::invalid_argument("RasterOptions: framebuffer sizes outside 8..16384");
    }
    I.target.size = static_cast<GLsizei>(std::min(opt.window_pixels, opt.max_tile_pixels));
    I.make_target(I.target, ctx, opt.compliance);
    gl.Enable(GL_STENCIL_TEST);
    if (gl.GetError() != GL_NO_ERROR) {
        throw environment_error("OpenGL: setting up the raster engine failed on " + ctx.describe());
    }
}

Raster::~Raster()
{
    auto& I = *m_impl;
    const auto& gl = I.gl;
    gl.DeleteProgram(I.tent_prog);
    gl.DeleteProgram(I.reset_prog);
    gl.DeleteProgram(I.test_prog);
    gl.DeleteVertexArrays(1, &I.vao_tent);
    gl.DeleteVertexArrays(1, &I.vao_test);
    gl.DeleteBuffers(1, &I.vbo_tent);
    gl.DeleteBuffers(1, &I.vbo_test);
    gl.DeleteBuffers(1, &I.ibo);
    if (!I.flag_buffers.empty()) {
        gl.DeleteBuffers(GLsizei(I.flag_buffers.size()), I.flag_buffers.data());
    }
    gl.DeleteFramebuffers(1, &I.target.fbo);
    gl.DeleteRenderbuffers(1, &I.target.rb_depth);
    if (I.target.rb_color) {
        gl.DeleteRenderbuffers(1, &I.target.rb_color);
    }
}

namespace {

/// The cells (of kCell pixels) of a tile that a tested part's fragments can
/// fall in, and their box. Only the tents reaching one of them are drawn:
/// every tent covering a tested pixel is among them, in the same order, so
/// the stencil there is what drawing them all gives.
class NearCells {
  public:
    static constexpr double kCell = 8;

    explicit NearCells(const TileSpec& tile)
        : m_cw(static_cast<int64_t>(std::ceil(tile.width / kCell))),
          m_ch(static_cast<int64_t>(std::ceil(tile.height / kCell))), m_near(size_t(m_cw * m_ch), 0), x0(m_cw), y0(m_ch)
    {
    }

    /// Mark the cells within 2 pixels of the part [t0, t1] of segment ab (pixels).
    void mark(const TestInstance& ti)
    {
        const double dx = double(ti.bx) - ti.ax, dy = double(ti.by) - ti.ay;
        cover_cells(ti.ax + ti.t0 * dx, ti.ay + ti.t0 * dy, ti.ax + ti.t1 * dx, ti.ay + ti.t1 * dy, 2.0, kCell, 0.0,
                    0.0, [&](int64_t x, int64_t y) {
                        if (in_grid(x, y)) {
                            x0 = std::min(x0, x);
                            y0 = std::min(y0, y);
                            x1 = std::max(x1, x);
                            y1 = std::max(y1, y);
                            m_near[size_t(y * m_cw + x)] = 1;
                        }
                    });
    }

    /// Whether tent `ti` (quad reaching r around its segment) covers a
    /// marked cell, and if so sets [t0, t1] to the part of its segment whose
    /// quad covers every pixel of the marked cells that the whole quad
    /// covers: a long segment near a few tested parts is rasterized there
    /// only (tract set at 16 m: 55 M tent pixels -> 25 M, before the scissor box).
    bool reaches(TentInstance& ti, double r) const
    {
        // Most of a tile's chains lie mostly outside the tile: a box test first.
        if (std::max(ti.ax, ti.bx) + r < double(x0) * kCell || std::min(ti.ax, ti.bx) - r > double(x1 + 1) * kCell ||
            std::max(ti.ay, ti.by) + r < double(y0) * kCell || std::min(ti.ay, ti.by) - r > double(y1 + 1) * kCell) {
            return false;
        }
        const double dx = double(ti.bx) - ti.ax, dy = double(ti.by) - ti.ay;
        const double len = std::sqrt(dx * dx + dy * dy);
        const double ux = len > 0 ? dx / len : 1.0, uy = len > 0 ? dy / len : 0.0;
        double s_min = INFINITY, s_max = -INFINITY; // along the segment from a, over the marked cells' corners
        cover_cells(ti.ax, ti.ay, ti.bx, ti.by, r, kCell, 0.0, 0.0, [&](int64_t x, int64_t y) {
            if (!in_grid(x, y) || m_near[size_t(y * m_cw + x)] == 0) {
                return;
            }
            for (const int64_t cx : {x, x + 1}) {
                for (const int64_t cy : {y, y + 1}) {
                    const double along = (double(cx) * kCell - ti.ax) * ux + (double(cy) * kCell - ti.ay) * uy;
                    s_min = std::min(s_min, along);
                    s_max = std::max(s_max, along);
                }
            }
        });
        if (!(s_min <= s_max)) {
            return false;
        }
        if (len <= 0) {
            return true; // a point: its whole quad
        }
        // The part's quad reaches from t0 len - r to t1 len + r along the
        // segment; a pixel's margin for rounding.
        s_min -= 1.0;
        s_max += 1.0;
        double from = std::clamp((s_min + r) / len, 0.0, 1.0), to = std::clamp((s_max - r) / len, 0.0, 1.0);
        if (from > to) { // the cells span less than the quad's 2 r: one point's quad
            from = to = std::clamp(0.5 * (s_min + s_max) / len, 0.0, 1.0);
        }
        ti.t0 = static_cast<float>(from);
        ti.t1 = static_cast<float>(to);
        return true;
    }

    /// Whether a cell of the pixels [px0, px1) x [py0, py1) is marked.
    bool any(int64_t px0, int64_t py0, int64_t px1, int64_t py1) const
    {
        const auto c = static_cast<int64_t>(kCell);
        for (int64_t y = std::max<int64_t>(0, py0 / c); y < std::min(m_ch, (py1 + c - 1) / c); ++y) {
            for (int64_t x = std::max<int64_t>(0, px0 / c); x < std::min(m_cw, (px1 + c - 1) / c); ++x) {
                if (m_near[size_t(y * m_cw + x)] != 0) {
                    return true;
                }
            }
        }
        return false;
    }

  private:
    bool in_grid(int64_t x, int64_t y) const { return x >= 0 && y >= 0 && x < m_cw && y < m_ch; }

    int64_t m_cw, m_ch; ///< the grid's width and height in cells
    std::vector<uint8_t> m_near;

  public:
    int64_t x0, y0, x1 = -1, y1 = -1; ///< the marked cells' box (empty: x1 < x0)
};

/// How far a tent's quad reaches from its segment, in pixels: eps (times
/// the metric's L2 reach) plus the margin and a pixel.
double tent_reach(double eps_px, const RasterOptions& opt)
{
    return eps_px * l2_reach(opt.metric) + opt.margin_px + 1.0;
}

/// Whether the part [t0, t1] of segment ab, grown by r, can touch piece p's pixels.
bool overlaps(float ax, float ay, float bx, float by, double t0, double t1, double r, const TilePiece& p)
{
    const double x0 = ax + t0 * (double(bx) - ax), y0 = ay + t0 * (double(by) - ay);
    const double x1 = ax + t1 * (double(bx) - ax), y1 = ay + t1 * (double(by) - ay);
    return std::max(x0, x1) + r >= double(p.x0) && std::min(x0, x1) - r <= double(p.x1) &&
           std::max(y0, y1) + r >= double(p.y0) && std::min(y0, y1) - r <= double(p.y1);
}

/// The whole box `all` (with every tent and test) in pieces of at most
/// `side` pixels: itself when it fits; else the pieces that hold a tested
/// cell, each with the tents whose quad (reach r around their part) and the
/// tests whose quad (2 pixels around theirs) overlap it, in the same order,
/// so each pixel gets what the whole box would give it.
std::vector<TilePiece> cut_into_pieces(TilePiece all, const NearCells& near, int64_t side, const RasterOptions& opt)
{
    std::vector<TilePiece> out;
    if (all.x1 - all.x0 <= side && all.y1 - all.y0 <= side) {
        out.push_back(std::move(all));
        return out;
    }
    for (int64_t oy = all.y0; oy < all.y1; oy += side) {
        for (int64_t ox = all.x0; ox < all.x1; ox += side) {
            TilePiece p;
            p.x0 = ox;
            p.y0 = oy;
            p.x1 = std::min(ox + side, all.x1);
            p.y1 = std::min(oy + side, all.y1);
            if (!near.any(p.x0, p.y0, p.x1, p.y1)) {
                continue;
            }
            for (const auto& [cls, range] : all.sranges) {
                for (GLuint k = range.first; k < range.first + GLuint(range.second); ++k) {
                    const auto& ti = all.tests[k];
                    if (overlaps(ti.ax, ti.ay, ti.bx, ti.by, ti.t0, ti.t1, 2.0, p)) {
                        add_range(p.sranges, cls, static_cast<GLuint>(p.tests.size()), 1);
                        p.tests.push_back(ti);
                    }
                }
            }
            if (p.tests.empty()) {
                continue;
            }
            for (const auto& [cls, range] : all.ranges) {
                for (GLuint k = range.first; k < range.first + GLuint(range.second); ++k) {
                    const auto& ti = all.inst[k];
                    if (overlaps(ti.ax, ti.ay, ti.bx, ti.by, ti.t0, ti.t1, tent_reach(ti.eps, opt) + 1.0, p)) {
                        add_range(p.ranges, cls, static_cast<GLuint>(p.inst.size()), 1);
                        p.inst.push_back(ti);
                    }
                }
            }
            out.push_back(std::move(p));
        }
    }
    return out;
}

} // namespace

PreparedTile Raster::prepare(const TileSpec& tile, std::span<const TentChain> tents,
                             std::span<const TestSegment> segs) const
{
    PreparedTile out;
    auto& d = *out.m;
    const double inv = 1.0 / tile.pixel;
    auto px = [&](GridPoint p, float& x, float& y) { // no denormal: see the shaders' comment
        const double fx = (double(p.x) - tile.x0) * inv, fy = (double(p.y) - tile.y0) * inv;
        x = std::abs(fx) >= 1e-20 ? static_cast<float>(fx) : 0.0f;
        y = std::abs(fy) >= 1e-20 ? static_cast<float>(fy) : 0.0f;
    };
    // The tested parts in pixels, and the cells they can fall in.
    NearCells near(tile);
    std::vector<TestInstance> tinst(segs.size());
    for (size_t k = 0; k < segs.size(); ++k) {
        const auto& sg = segs[k];
        auto& ti = tinst[k];
        px(sg.a, ti.ax, ti.ay);
        px(sg.b, ti.bx, ti.by);
        ti.t0 = sg.t0;
        ti.t1 = sg.t1;
        part_geometry(ti);
        const double dx = double(ti.bx) - ti.ax, dy = double(ti.by) - ti.ay;
        d.drawn_pixels += std::hypot(dx, dy) * (double(sg.t1) - sg.t0);
        near.mark(ti);
    }

    // Tent instances grouped by class; one draw call per class sets the stencil reference.
    std::vector<uint32_t> order(tents.size());
    for (uint32_t i = 0; i < order.size(); ++i) {
        order[i] = i;
    }
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return tents[a].cls < tents[b].cls; });
    std::vector<TentInstance> inst;
    ClassRanges ranges;
    for (uint32_t i : order) {
        const auto& t = tents[i];
        const auto eps_px = static_cast<float>(t.eps * inv);
        d.eps_max = std::max(d.eps_max, double(eps_px));
        const auto first = static_cast<GLuint>(inst.size());
        const double reach = tent_reach(eps_px, m_opt);
        for (size_t k = 0; k + 1 < t.points.size(); ++k) {
            if (!takes_part(t.keep, k)) {
                ++d.tent_skipped;
                continue;
            }
            TentInstance ti{};
            px(t.points[k], ti.ax, ti.ay);
            px(t.points[k + 1], ti.bx, ti.by);
            ti.eps = eps_px;
            tent_reciprocals(ti, m_opt.metric);
            if (near.reaches(ti, reach)) {
                inst.push_back(ti);
            } else {
                ++d.tent_skipped;
            }
        }
        if (inst.size() > first) {
            add_range(ranges, t.cls, first, static_cast<GLsizei>(inst.size() - first));
        }
    }
    d.tent_segments = inst.size();
    const auto w = static_cast<int64_t>(tile.width), h = static_cast<int64_t>(tile.height);
    // Every pass is clipped to the box of the marked cells: no tested
    // fragment falls outside it, so what is drawn there cannot change a
    // result. llvmpipe's work per tile grows with the area it rasterizes,
    // not with what is drawn: at 1 m on the tract set (178 k tiles of 4096
    // pixels, most with a few short shortcuts) the compliance step took 9.1 s
    // of CPU without the box and 4.3 s with it.
    const auto cell = static_cast<int64_t>(NearCells::kCell);
    d.sx0 = std::clamp<int64_t>(near.x0 * cell, 0, w);
    d.sy0 = std::clamp<int64_t>(near.y0 * cell, 0, h);
    d.sx1 = std::max(d.sx0, std::clamp<int64_t>((near.x1 + 1) * cell, 0, w));
    d.sy1 = std::max(d.sy0, std::clamp<int64_t>((near.y1 + 1) * cell, 0, h));

    // Test instances by class, numbered in drawing order.
    std::vector<uint32_t> sorder(segs.size());
    for (uint32_t i = 0; i < sorder.size(); ++i) {
        sorder[i] = i;
    }
    std::stable_sort(sorder.begin(), sorder.end(), [&](uint32_t a, uint32_t b) { return segs[a].cls < segs[b].cls; });
    std::vector<TestInstance> sorted(segs.size());
    ClassRanges sranges;
    d.ids.resize(segs.size());
    for (uint32_t k = 0; k < sorder.size(); ++k) {
        const auto& sg = segs[sorder[k]];
        sorted[k] = tinst[sorder[k]];
        sorted[k].id = k; // the flag's index in the tile's buffer
        d.ids[k] = sg.id;
        add_range(sranges, sg.cls, k, 1);
    }
    if (d.sx1 > d.sx0 && d.sy1 > d.sy0) {
        d.pieces = cut_into_pieces(
            {d.sx0, d.sy0, d.sx1, d.sy1, std::move(inst), std::move(ranges), std::move(sranges), std::move(sorted)},
            near, static_cast<int64_t>(std::min(m_opt.window_pixels, m_opt.max_tile_pixels)), m_opt);
    }
    return out;
}

struct Raster::Frame {
    float size = 0;       ///< the framebuffer's width and height, pixels
    float ox = 0, oy = 0; ///< the box's origin within the tile, pixels
    int64_t w = 0, h = 0; ///< the box's width and height, pixels
};

void Raster::bind_tile_flags(const PreparedTile::Data& d, size_t base)
{
    auto& I = *m_impl;
    const auto& gl = I.gl;
    // The flags land in the tile's buffer, read back by end_batch: no wait per tile.
    const size_t t = I.tile_flags.size();
    if (t == I.flag_buffers.size()) {
        I.flag_buffers.push_back(0);
        gl.GenBuffers(1, &I.flag_buffers.back());
    }
    I.tile_flags.push_back(base);
    I.batch_ids.insert(I.batch_ids.end(), d.ids.begin(), d.ids.end());
    if (I.zeros.size() < d.ids.size()) {
        I.zeros.resize(d.ids.size(), 0);
    }
    gl.BindBuffer(GL_SHADER_STORAGE_BUFFER, I.flag_buffers[t]);
    gl.BufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(std::max<size_t>(1, d.ids.size()) * 4), I.zeros.data(),
                  GL_STREAM_READ);
    gl.BindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, I.flag_buffers[t]);
}

Raster::Frame Raster::bind_frame(int64_t ox, int64_t oy, int64_t ex, int64_t ey)
{
    auto& I = *m_impl;
    const auto& gl = I.gl;
    // The piece is drawn with its corner at the framebuffer's. The shift is
    // an integer number of pixels, so the pixel centres keep their places,
    // and the shaders subtract it from coordinates within the tile exactly.
    if (ex - ox > I.target.size || ey - oy > I.target.size) {
        throw std::logic_error("piece larger than the framebuffer");
    }
    // Bound each time: engines may share a context (Mesa skips a binding
    // that changes nothing).
    gl.BindFramebuffer(GL_FRAMEBUFFER, I.target.fbo);
    gl.Viewport(0, 0, I.target.size, I.target.size);
    gl.Enable(GL_SCISSOR_TEST); // off again at the end of draw: the context may serve other engines
    gl.Scissor(0, 0, static_cast<GLsizei>(ex - ox), static_cast<GLsizei>(ey - oy));
    return {static_cast<float>(I.target.size), static_cast<float>(ox), static_cast<float>(oy), ex - ox, ey - oy};
}

void Raster::use_tent_quads(unsigned prog, const Frame& f, float z)
{
    auto& I = *m_impl;
    const auto& gl = I.gl;
    gl.UseProgram(prog);
    gl.Uniform2f(I.loc(prog, "u_size"), f.size, f.size);
    gl.Uniform2f(I.loc(prog, "u_origin"), f.ox, f.oy);
    gl.Uniform1f(I.loc(prog, "u_reach"), float(l2_reach(m_opt.metric)));
    gl.Uniform1f(I.loc(prog, "u_pad"), float(m_opt.margin_px));
    gl.Uniform1f(I.loc(prog, "u_z"), z);
}

void Raster::draw_tents(const PreparedTile::Data& d, size_t piece, const Frame& f)
{
    const auto& p = d.pieces[piece];
    auto& I = *m_impl;
    const auto& gl = I.gl;
    use_tent_quads(I.tent_prog, f, 0.0f);
    // A power of two at least twice the largest key within eps: depths at
    // most 1/2, each the key's bits with another exponent.
    const double limit = m_opt.metric == Metric::l2 ? d.eps_max * d.eps_max : d.eps_max;
    int e = 0;
    std::frexp(2 * limit + 1, &e);
    gl.Uniform1f(I.loc(I.tent_prog, "u_depth_scale"), std::ldexp(1.0f, -e));
    gl.BindVertexArray(I.vao_tent);
    gl.Enable(GL_DEPTH_TEST);
    gl.DepthFunc(GL_LESS);
    gl.DepthMask(GL_TRUE);
    gl.ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    gl.StencilMask(0xFF);
    gl.StencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
    for (const auto& [cls, range] : p.ranges) {
        gl.StencilFunc(GL_ALWAYS, cls, 0xFF);
        draw_quads(gl, range.first, size_t(range.second));
    }
}

void Raster::test_parts(const PreparedTile::Data& d, size_t piece, const Frame& f, bool ssbo,
                        std::vector<uint8_t>& removed)
{
    const auto& p = d.pieces[piece];
    auto& I = *m_impl;
    const auto& gl = I.gl;
    // A fragment fails where another class's region is: stencil != class,
    // and a tent was drawn there (depth below the background's 1). Pixels
    // outside every band are no one's region: a shortcut's half-pixel quad
    // grazing the edge of its own band is not a failure.
    gl.Enable(GL_DEPTH_TEST);
    gl.DepthFunc(GL_GREATER);
    gl.DepthMask(GL_FALSE);
    gl.StencilMask(0);
    gl.StencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
    gl.UseProgram(I.test_prog);
    gl.Uniform2f(I.loc(I.test_prog, "u_size"), f.size, f.size);
    gl.Uniform2f(I.loc(I.test_prog, "u_origin"), f.ox, f.oy);
    gl.Uniform1f(I.loc(I.test_prog, "u_end_margin2"), static_cast<float>(end_margin_px * end_margin_px));
    gl.BindVertexArray(I.vao_test);
    if (p.tests.empty()) {
        return;
    }
    if (ssbo) {
        for (const auto& [cls, range] : p.sranges) {
            gl.StencilFunc(GL_NOTEQUAL, cls, 0xFF);
            draw_quads(gl, range.first, size_t(range.second));
        }
    } else {
        read_back_failures(d, piece, f, removed);
    }
}

void Raster::read_back_failures(const PreparedTile::Data& d, size_t piece, const Frame& f,
                                std::vector<uint8_t>& removed)
{
    const auto& p = d.pieces[piece];
    auto& I = *m_impl;
    const auto& gl = I.gl;
    std::vector<uint8_t> pixels(size_t(f.w) * size_t(f.h) * 4);
    gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    for (;;) {
        ++m_stats.readback_rounds;
        gl.Clear(GL_COLOR_BUFFER_BIT);
        for (const auto& [cls, range] : p.sranges) {
            gl.StencilFunc(GL_NOTEQUAL, cls, 0xFF);
            for (GLuint k = range.first; k < range.first + GLuint(range.second); ++k) {
                if (!removed[p.tests[k].id]) {
                    draw_quads(gl, k, 1);
                }
            }
        }
        gl.PixelStorei(GL_PACK_ALIGNMENT, 1);
        gl.ReadPixels(0, 0, static_cast<GLsizei>(f.w), static_cast<GLsizei>(f.h), GL_RGBA, GL_UNSIGNED_BYTE,
                      pixels.data());
        bool changed = false;
        for (size_t i = 0; i < pixels.size(); i += 4) {
            const uint32_t c = uint32_t(pixels[i]) | (uint32_t(pixels[i + 1]) << 8) | (uint32_t(pixels[i + 2]) << 16);
            if (c != 0 && c <= removed.size() && !removed[c - 1]) {
                removed[c - 1] = 1;
                changed = true;
            }
        }
        if (!changed) {
            break;
        }
    }
    gl.ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
}

void Raster::reset_tents(const PreparedTile::Data& d, size_t piece, const Frame& f)
{
    const auto& p = d.pieces[piece];
    auto& I = *m_impl;
    const auto& gl = I.gl;
    use_tent_quads(I.reset_prog, f, 1.0f);
    gl.BindVertexArray(I.vao_tent);
    gl.Enable(GL_DEPTH_TEST);
    gl.DepthFunc(GL_ALWAYS);
    gl.DepthMask(GL_TRUE);
    gl.StencilMask(0xFF);
    gl.StencilFunc(GL_ALWAYS, 0, 0xFF);
    gl.StencilOp(GL_REPLACE, GL_REPLACE, GL_REPLACE);
    if (!p.inst.empty()) {
        draw_quads(gl, 0, p.inst.size());
    }
}

void Raster::draw(const PreparedTile& prepared, std::vector<uint8_t>& fails)
{
    auto& I = *m_impl;
    const auto& gl = I.gl;
    const auto& d = *prepared.m;
    // Outside a batch, the tile is a batch of its own.
    const bool own_batch = !I.batching;
    if (own_batch) {
        begin_batch(d.ids.size());
    }
    const bool ssbo = m_opt.compliance == Compliance::ssbo;
    const size_t base = ssbo ? I.batch_ids.size() : 0;
    if (ssbo && base + d.ids.size() > I.batch_capacity) {
        throw std::logic_error("more shortcut parts than the batch was begun for");
    }
    ++m_stats.tiles;
    m_stats.drawn_segments += d.ids.size();
    m_stats.drawn_pixels += d.drawn_pixels;
    m_stats.tent_segments += d.tent_segments;
    m_stats.tent_segments_skipped += d.tent_skipped;
    if (ssbo) {
        bind_tile_flags(d, base);
    }
    std::vector<uint8_t> removed; // Algorithm 5.1: the segments seen failing
    if (!ssbo) {
        removed.assign(d.ids.size(), 0);
    }
    m_stats.one_piece_boxes += d.pieces.size() == 1;
    for (size_t pi = 0; pi < d.pieces.size(); ++pi) {
        const auto& p = d.pieces[pi];
        const auto tw = std::chrono::steady_clock::now();
        gl.BindVertexArray(I.vao_tent);
        gl.BindBuffer(GL_ARRAY_BUFFER, I.vbo_tent);
        I.upload_quads(p.inst);
        gl.BindVertexArray(I.vao_test);
        gl.BindBuffer(GL_ARRAY_BUFFER, I.vbo_test);
        I.upload_quads(p.tests);
        const Frame f = bind_frame(p.x0, p.y0, p.x1, p.y1);
        draw_tents(d, pi, f); // Step 1
        m_stats.voronoi_seconds += seconds_since(tw);
        const auto t1 = std::chrono::steady_clock::now();
        test_parts(d, pi, f, ssbo, removed); // Step 2
        m_stats.compliance_seconds += seconds_since(t1);
        const auto t2 = std::chrono::steady_clock::now();
        reset_tents(d, pi, f);
        m_stats.voronoi_seconds += seconds_since(t2);
    }
    gl.Disable(GL_SCISSOR_TEST);
    for (uint32_t k = 0; k < removed.size(); ++k) {
        if (removed[k]) {
            fails[d.ids[k]] = 1;
        }
    }
    const GLenum err = gl.GetError();
    if (err != GL_NO_ERROR) {
        throw environment_error("OpenGL error " + std::to_string(err) + " while rendering a tile on " +
                                m_ctx.describe());
    }
    if (own_batch) {
        end_batch(fails);
    }
}

void Raster::run_tile(const TileSpec& tile, std::span<const TentChain> tents, std::span<const TestSegment> segs,
                      std::vector<uint8_t>& fails)
{
    draw(prepare(tile, tents, segs), fails);
}

void Raster::begin_batch(size_t parts)
{
    auto& I = *m_impl;
    if (I.batching) {
        throw std::logic_error("Raster::begin_batch inside a batch");
    }
    I.batching = true;
    I.batch_ids.clear();
    I.tile_flags.clear();
    I.batch_capacity = parts;
}

void Raster::end_batch(std::vector<uint8_t>& fails)
{
    auto& I = *m_impl;
    if (!I.batching) {
        throw std::logic_error("Raster::end_batch without begin_batch");
    }
    I.batching = false;
    if (I.batch_ids.empty()) {
        return;
    }
    const auto t0 = std::chrono::steady_clock::now();
    const auto& gl = I.gl;
    std::vector<uint32_t> flags(I.batch_ids.size(), 0);
    gl.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    I.tile_flags.push_back(I.batch_ids.size());
    for (size_t t = 0; t + 1 < I.tile_flags.size(); ++t) {
        const size_t first = I.tile_flags[t], count = I.tile_flags[t + 1] - first;
        if (count > 0) {
            gl.BindBuffer(GL_SHADER_STORAGE_BUFFER, I.flag_buffers[t]);
            gl.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(count * 4), flags.data() + first);
        }
    }
    I.tile_flags.clear();
    const GLenum err = gl.GetError();
    if (err != GL_NO_ERROR) {
        throw environment_error("OpenGL error " + std::to_string(err) + " while reading the compliance flags on " +
                                m_ctx.describe());
    }
    for (size_t k = 0; k < flags.size(); ++k) {
        if (flags[k]) {
            fails[I.batch_ids[k]] = 1;
        }
    }
    I.batch_ids.clear();
    m_stats.compliance_seconds += seconds_since(t0);
}

} // namespace tigerlod::simplify
