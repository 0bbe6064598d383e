#pragma once
/// @file line_renderer.hpp
/// Draws a front's chains as lines into an off-screen framebuffer (OpenGL
/// 4.5 core on OSMesa or EGL), styled by each chain's border level: the
/// coarser the level whose map has the border, the heavier and darker the
/// line. Each segment is a quad of its line's width (core profiles guarantee
/// no wide lines), streamed through one vertex buffer of fixed size, so the
/// renderer's own memory does not grow with the front.

#include "gl/context.hpp"
#include "reader/reader.hpp"

#include <cstdint>
#include <vector>

namespace tigerlod::render {

/// A line style (reader::line_style: the viewer draws with the same).
using Style = reader::LineStyle;

struct DrawStats {
    uint64_t chains = 0, vertices = 0, segments = 0; ///< drawn (segments: those in view)
};

class LineRenderer {
  public:
    /// Makes the framebuffer and the program. Throws environment_error if
    /// the driver refuses them.
    LineRenderer(gl::Context& context, uint32_t width, uint32_t height);
    ~LineRenderer();
    LineRenderer(const LineRenderer&) = delete;
    LineRenderer& operator=(const LineRenderer&) = delete;

    /// Clear, draw the chains of `list` (from `front`) in `view`, finest
    /// border level first so that coarser borders lie on top, and wait for
    /// the GL to finish.
    DrawStats draw(const reader::View& view, const std::vector<reader::Drawable>& front,
                   const std::vector<reader::DrawChain>& list, uint32_t levels);

    /// The framebuffer's pixels, RGB, rows from the top.
    std::vector<uint8_t> read_rgb() const;

    uint32_t width() const noexcept { return m_width; }
    uint32_t height() const noexcept { return m_height; }
    /// Bytes of the vertex buffer (client and GL side each).
    static size_t buffer_bytes() noexcept;

  private:
    struct Vertex {
        float x, y;
        uint8_t r, g, b, a;
    };
    void flush();

    const gl::Api& gl; // the context's, which must outlive this
    uint32_t m_width, m_height;
    GLuint m_fbo = 0, m_rb_color = 0, m_program = 0, m_vao = 0, m_vbo = 0;
    GLint m_size_loc = -1;
    std::vector<Vertex> m_batch;
}; // class LineRenderer

} // namespace tigerlod::render
