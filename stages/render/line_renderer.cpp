#include "stages/render/line_renderer.hpp"

#include "core/errors.hpp"
#include "gl/program.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>

namespace tigerlod::render {

namespace {

/// Vertices per batch: 6 a segment (two triangles), about 11,000 segments.
constexpr size_t batch_vertices = 6 * 10922;

const char* vertex_shader = R"(#version 450 core
layout(location = 0) in vec2 position; // pixels, origin at the bottom left
layout(location = 1) in vec4 colour;
uniform vec2 size;
out vec4 v_colour;
void main()
{
    v_colour = colour;
    gl_Position = vec4(position / size * 2.0 - 1.0, 0.0, 1.0);
}
)";

const char* fragment_shader = R"(#version 450 core
in vec4 v_colour;
out vec4 out_colour;
void main()
{
    out_colour = v_colour;
}
)";

} // namespace

size_t LineRenderer::buffer_bytes() noexcept
{
    return batch_vertices * sizeof(Vertex);
}

LineRenderer::LineRenderer(gl::Context& context, uint32_t width, uint32_t height)
    : gl(context.api()), m_width(width), m_height(height)
{
    gl.GenFramebuffers(1, &m_fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, m_fbo);
    gl.GenRenderbuffers(1, &m_rb_color);
    gl.BindRenderbuffer(GL_RENDERBUFFER, m_rb_color);
    gl.RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, GLsizei(width), GLsizei(height));
    gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_rb_color);
    if (gl.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        throw environment_error("render: the driver refuses a " + std::to_string(width) + "x" + std::to_string(height) +
                                " RGBA framebuffer");
    }
    m_program = gl::link_program(gl, vertex_shader, fragment_shader);
    m_size_loc = gl.GetUniformLocation(m_program, "size");
    gl.GenVertexArrays(1, &m_vao);
    gl.BindVertexArray(m_vao);
    gl.GenBuffers(1, &m_vbo);
    gl.BindBuffer(GL_ARRAY_BUFFER, m_vbo);
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(buffer_bytes()), nullptr, GL_STREAM_DRAW);
    gl.VertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, sizeof(Vertex), reinterpret_cast<void*>(offsetof(Vertex, x)));
    gl.EnableVertexAttribArray(0);
    gl.VertexAttribPointer(1, 4, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(Vertex),
                           reinterpret_cast<void*>(offsetof(Vertex, r)));
    gl.EnableVertexAttribArray(1);
    m_batch.reserve(batch_vertices);
}

LineRenderer::~LineRenderer()
{
    gl.DeleteBuffers(1, &m_vbo);
    gl.DeleteVertexArrays(1, &m_vao);
    gl.DeleteProgram(m_program);
    gl.DeleteRenderbuffers(1, &m_rb_color);
    gl.DeleteFramebuffers(1, &m_fbo);
}

void LineRenderer::flush()
{
    if (m_batch.empty()) {
        return;
    }
    // A fresh store each batch (orphaning): the GL need not wait for the last draw.
    gl.BufferData(GL_ARRAY_BUFFER, GLsizeiptr(buffer_bytes()), nullptr, GL_STREAM_DRAW);
    void* p = gl.MapBufferRange(GL_ARRAY_BUFFER, 0, GLsizeiptr(m_batch.size() * sizeof(Vertex)),
                                GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT);
    if (p == nullptr) {
        throw environment_error("render: the driver cannot map the vertex buffer");
    }
    std::copy(m_batch.begin(), m_batch.end(), static_cast<Vertex*>(p));
    gl.UnmapBuffer(GL_ARRAY_BUFFER);
    gl.DrawArrays(GL_TRIANGLES, 0, GLsizei(m_batch.size()));
    m_batch.clear();
}

DrawStats LineRenderer::draw(const reader::View& view, const std::vector<reader::Drawable>& front,
                             const std::vector<reader::DrawChain>& list, uint32_t levels)
{
    DrawStats st;
    gl.BindFramebuffer(GL_FRAMEBUFFER, m_fbo);
    gl.Viewport(0, 0, GLsizei(m_width), GLsizei(m_height));
    gl.ClearColor(1, 1, 1, 1);
    gl.Clear(GL_COLOR_BUFFER_BIT);
    gl.UseProgram(m_program);
    gl.Uniform2f(m_size_loc, float(m_width), float(m_height));
    gl.BindVertexArray(m_vao);
    gl.BindBuffer(GL_ARRAY_BUFFER, m_vbo);
    const double scale = 1.0 / view.units_per_pixel;
    const double ox = view.center_x - 0.5 * m_width * view.units_per_pixel;
    const double oy = view.center_y - 0.5 * m_height * view.units_per_pixel;
    // The border levels present, finest first.
    uint32_t deepest = 0;
    for (const auto& dc : list) {
        deepest = std::max(deepest, (front[dc.item].chains->flags[dc.chain] & datatree::border_level_mask) >>
                                        datatree::border_level_shift);
    }
    for (uint32_t level = deepest + 1; level-- > 0;) {
        const Style style = reader::line_style(level, levels);
        const float half = 0.5F * style.width;
        const double margin = style.width;
        for (const auto& dc : list) {
            const auto& d = front[dc.item];
            if (((d.chains->flags[dc.chain] & datatree::border_level_mask) >> datatree::border_level_shift) != level) {
                continue;
            }
            const auto pts = d.geometry->chain(dc.chain);
            ++st.chains;
            st.vertices += pts.size();
            double px = (pts[0].x - ox) * scale, py = (pts[0].y - oy) * scale;
            for (size_t i = 1; i < pts.size(); ++i) {
                const double qx = (pts[i].x - ox) * scale, qy = (pts[i].y - oy) * scale;
                const bool out = std::max(px, qx) < -margin || std::min(px, qx) > m_width + margin ||
                                 std::max(py, qy) < -margin || std::min(py, qy) > m_height + margin;
                if (!out) {
                    const double dx = qx - px, dy = qy - py;
                    const double len = std::hypot(dx, dy);
                    // A segment under a pixel long still covers its width.
                    const double ux = len > 0 ? dx / len : 1.0, uy = len > 0 ? dy / len : 0.0;
                    const auto nx = float(-uy * half), ny = float(ux * half);
                    const auto ex = float(ux * half), ey = float(uy * half);
                    const float ax = float(px) - ex, ay = float(py) - ey, bx = float(qx) + ex, by = float(qy) + ey;
                    const Vertex c[4] = {{ax + nx, ay + ny, style.r, style.g, style.b, 255},
                                         {ax - nx, ay - ny, style.r, style.g, style.b, 255},
                                         {bx + nx, by + ny, style.r, style.g, style.b, 255},
                                         {bx - nx, by - ny, style.r, style.g, style.b, 255}};
                    if (m_batch.size() + 6 > batch_vertices) {
                        flush();
                    }
                    for (const int k : {0, 1, 2, 2, 1, 3}) {
                        m_batch.push_back(c[k]);
                    }
                    ++st.segments;
                }
                px = qx;
                py = qy;
            }
        }
        flush();
    }
    gl.Finish();
    return st;
}

std::vector<uint8_t> LineRenderer::read_rgb() const
{
    std::vector<uint8_t> rgba(size_t(m_width) * m_height * 4);
    gl.BindFramebuffer(GL_FRAMEBUFFER, m_fbo);
    gl.ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl.PixelStorei(GL_PACK_ALIGNMENT, 1);
    gl.ReadPixels(0, 0, GLsizei(m_width), GLsizei(m_height), GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
    std::vector<uint8_t> rgb(size_t(m_width) * m_height * 3);
    for (uint32_t y = 0; y < m_height; ++y) {
        const uint8_t* src = rgba.data() + size_t(m_height - 1 - y) * m_width * 4; // GL rows start at the bottom
        uint8_t* dst = rgb.data() + size_t(y) * m_width * 3;
        for (uint32_t x = 0; x < m_width; ++x) {
            dst[3 * x] = src[4 * x];
            dst[3 * x + 1] = src[4 * x + 1];
            dst[3 * x + 2] = src[4 * x + 2];
        }
    }
    return rgb;
}

} // namespace tigerlod::render
