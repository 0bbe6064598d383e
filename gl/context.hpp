#pragma once
/// @file context.hpp
/// An off-screen OpenGL 4.5 core context on one of two backends, both opened
/// at run time with dlopen:
///  - osmesa: Mesa's off-screen renderer (llvmpipe); runs everywhere.
///  - egl: EGL's device platform (a GPU, or Mesa's software device), falling
///    back to Mesa's surfaceless platform.
/// Rendering goes to framebuffer objects, so no window system is involved.
/// A context is current on the thread that created it and is used from there.

#include "gl/api.hpp"

#include <memory>
#include <optional>
#include <string>

namespace tigerlod::gl {

enum class Backend { osmesa, egl };

const char* backend_name(Backend b) noexcept;
std::optional<Backend> parse_backend(const std::string& name) noexcept;

class Context {
  public:
    /// Create a 4.5 core context and make it current. Throws
    /// environment_error naming the backend and the step that failed (library
    /// missing, no display or device, no 4.5 core context, entry point missing).
    static std::unique_ptr<Context> create(Backend backend);
    /// A GPU where there is one, else OSMesa: where the machine has a GPU's
    /// device node (/dev/nvidiactl, /dev/dri/renderD*), an EGL context, kept
    /// if its renderer is not a software one (llvmpipe, softpipe, swrast);
    /// else, or if EGL fails, an OSMesa context. `why` says what was chosen
    /// and why. Throws as create(osmesa) does.
    static std::unique_ptr<Context> create_auto(std::string& why);
    /// create_auto's GPU alone: an EGL context on a GPU, or null where the
    /// machine has none (no device node, EGL failing, or EGL finding only a
    /// software renderer); `why` says which.
    static std::unique_ptr<Context> create_gpu(std::string& why);
    /// Whether the machine has a GPU's device node: /dev/nvidiactl, or a
    /// render node /dev/dri/renderD*.
    static bool gpu_device_node();
    /// Whether the renderer is a software rasterizer (llvmpipe and the like).
    bool software() const;
    virtual ~Context() = default;

    const Api& api() const noexcept { return m_api; }
    Backend backend() const noexcept { return m_backend; }
    /// "OpenGL 4.5 (Core Profile) Mesa 22.3.6 on llvmpipe (LLVM 15.0.6, 256 bits)" and the like.
    std::string describe() const;

  protected:
    explicit Context(Backend b) : m_backend(b) {}
    Api m_api;
    Backend m_backend;
}; // class Context

} // namespace tigerlod::gl
