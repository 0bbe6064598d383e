#include "gl/context.hpp"

#include "core/errors.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <dlfcn.h>

#include <array>
#include <filesystem>
#include <functional>
#include <vector>

namespace tigerlod::gl {

const char* backend_name(Backend b) noexcept
{
    return b == Backend::osmesa ? "osmesa" : "egl";
}

std::optional<Backend> parse_backend(const std::string& name) noexcept
{
    if (name == "osmesa") {
        return Backend::osmesa;
    }
    if (name == "egl") {
        return Backend::egl;
    }
    return std::nullopt;
}

std::string Context::describe() const
{
    auto str = [this](GLenum e) {
        const auto* s = reinterpret_cast<const char*>(m_api.GetString(e));
        return std::string(s ? s : "?");
    };
    return "OpenGL " + str(GL_VERSION) + " on " + str(GL_RENDERER) + " (" + backend_name(m_backend) + ")";
}

namespace {

using ProcLoader = void* (*)(const char*);

/// Fill `api` through `load`; throws naming the first missing entry point.
void load_api(Api& api, const std::string& backend, const std::function<void*(const char*)>& load)
{
#define TIGERLOD_GL_LOAD(type, name)                                                                                   \
    api.name = reinterpret_cast<type>(load("gl" #name));                                                               \
    if (!api.name) {                                                                                                   \
        throw environment_error(backend + ": OpenGL entry point gl" #name " is missing");                              \
    }
    TIGERLOD_GL_FUNCTIONS(TIGERLOD_GL_LOAD)
#undef TIGERLOD_GL_LOAD
}

/// A dlopen handle closed on destruction.
class Library {
  public:
    Library(const std::string& backend, std::initializer_list<const char*> names)
    {
        std::string tried;
        for (const char* n : names) {
            m_handle = dlopen(n, RTLD_NOW | RTLD_LOCAL);
            if (m_handle) {
                return;
            }
            tried += std::string(tried.empty() ? "" : ", ") + n;
        }
        throw environment_error(backend + ": cannot load " + tried + " (install the package that provides it)");
    }
    Library(const Library&) = delete;
    Library& operator=(const Library&) = delete;
    ~Library()
    {
        // Mesa's drivers register thread-exit and atexit handlers; unloading
        // them before exit crashes. Keep the library mapped.
    }
    template <class F> F symbol(const std::string& backend, const char* name) const
    {
        void* p = dlsym(m_handle, name);
        if (!p) {
            throw environment_error(backend + ": symbol " + std::string(name) + " is missing");
        }
        return reinterpret_cast<F>(p);
    }

  private:
    void* m_handle = nullptr;
}; // class Library

// OSMesa's interface, declared here so that no GL header other than
// glcorearb.h is needed.
using OSMesaContext = struct osmesa_context*;
constexpr int osmesa_format = 0x22, osmesa_depth_bits = 0x30, osmesa_stencil_bits = 0x31;
constexpr int osmesa_profile = 0x33, osmesa_core_profile = 0x34, osmesa_major = 0x36, osmesa_minor = 0x37;
using OSMesaCreateContextAttribsFn = OSMesaContext (*)(const int*, OSMesaContext);
using OSMesaMakeCurrentFn = GLboolean (*)(OSMesaContext, void*, GLenum, GLsizei, GLsizei);
using OSMesaDestroyContextFn = void (*)(OSMesaContext);
using OSMesaGetProcAddressFn = void* (*)(const char*);

class OsMesaContext final : public Context {
  public:
    OsMesaContext() : Context(Backend::osmesa), m_lib("osmesa", {"libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"})
    {
        const std::string b = "osmesa";
        auto create = m_lib.symbol<OSMesaCreateContextAttribsFn>(b, "OSMesaCreateContextAttribs");
        auto make_current = m_lib.symbol<OSMesaMakeCurrentFn>(b, "OSMesaMakeCurrent");
        m_destroy = m_lib.symbol<OSMesaDestroyContextFn>(b, "OSMesaDestroyContext");
        auto get_proc = m_lib.symbol<OSMesaGetProcAddressFn>(b, "OSMesaGetProcAddress");
        const std::array<int, 15> attribs{osmesa_format,
                                          static_cast<int>(GL_RGBA),
                                          osmesa_depth_bits,
                                          0,
                                          osmesa_stencil_bits,
                                          0,
                                          osmesa_profile,
                                          osmesa_core_profile,
                                          osmesa_major,
                                          4,
                                          osmesa_minor,
                                          5,
                                          0,
                                          0,
                                          0};
        m_ctx = create(attribs.data(), nullptr);
        if (!m_ctx) {
            throw environment_error("osmesa: cannot create an OpenGL 4.5 core context");
        }
        // Rendering goes to framebuffer objects; the default buffer is 1x1.
        if (!make_current(m_ctx, m_pixel.data(), GL_UNSIGNED_BYTE, 1, 1)) {
            m_destroy(m_ctx);
            throw environment_error("osmesa: cannot make the context current");
        }
        load_api(m_api, b, [get_proc](const char* n) { return get_proc(n); });
    }
    ~OsMesaContext() override { m_destroy(m_ctx); }

  private:
    Library m_lib;
    OSMesaContext m_ctx = nullptr;
    OSMesaDestroyContextFn m_destroy = nullptr;
    std::array<unsigned char, 4> m_pixel{};
}; // class OsMesaContext

class EglContext final : public Context {
  public:
    EglContext() : Context(Backend::egl), m_lib("egl", {"libEGL.so.1", "libEGL.so"})
    {
        const std::string b = "egl";
        m_get_proc = m_lib.symbol<PFNEGLGETPROCADDRESSPROC>(b, "eglGetProcAddress");
        auto initialize = m_lib.symbol<PFNEGLINITIALIZEPROC>(b, "eglInitialize");
        auto bind_api = m_lib.symbol<PFNEGLBINDAPIPROC>(b, "eglBindAPI");
        auto choose_config = m_lib.symbol<PFNEGLCHOOSECONFIGPROC>(b, "eglChooseConfig");
        auto create_context = m_lib.symbol<PFNEGLCREATECONTEXTPROC>(b, "eglCreateContext");
        auto make_current = m_lib.symbol<PFNEGLMAKECURRENTPROC>(b, "eglMakeCurrent");
        m_terminate = m_lib.symbol<PFNEGLTERMINATEPROC>(b, "eglTerminate");
        m_destroy = m_lib.symbol<PFNEGLDESTROYCONTEXTPROC>(b, "eglDestroyContext");

        m_display = open_display();
        EGLint major = 0, minor = 0;
        if (!initialize(m_display, &major, &minor)) {
            throw environment_error("egl: eglInitialize failed on the " + m_platform + " platform");
        }
        if (!bind_api(EGL_OPENGL_API)) {
            m_terminate(m_display);
            throw environment_error("egl: the " + m_platform + " platform has no desktop OpenGL");
        }
        const std::array<EGLint, 5> config_attribs{EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, 0, EGL_NONE};
        EGLConfig config = nullptr;
        EGLint n = 0;
        if (!choose_config(m_display, config_attribs.data(), &config, 1, &n) || n < 1) {
            m_terminate(m_display);
            throw environment_error("egl: no OpenGL config on the " + m_platform + " platform");
        }
        const std::array<EGLint, 7> ctx_attribs{
            EGL_CONTEXT_MAJOR_VERSION,           4,       EGL_CONTEXT_MINOR_VERSION, 5, EGL_CONTEXT_OPENGL_PROFILE_MASK,
            EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
        m_ctx = create_context(m_display, config, EGL_NO_CONTEXT, ctx_attribs.data());
        if (m_ctx == EGL_NO_CONTEXT) {
            m_terminate(m_display);
            throw environment_error("egl: cannot create an OpenGL 4.5 core context on the " + m_platform + " platform");
        }
        if (!make_current(m_display, EGL_NO_SURFACE, EGL_NO_SURFACE, m_ctx)) {
            m_destroy(m_display, m_ctx);
            m_terminate(m_display);
            throw environment_error("egl: cannot make a surfaceless context current");
        }
        auto gp = m_get_proc;
        load_api(m_api, b, [gp](const char* name) { return reinterpret_cast<void*>(gp(name)); });
    }
    ~EglContext() override
    {
        m_destroy(m_display, m_ctx);
        m_terminate(m_display);
    }

  private:
    /// The first EGL device (a GPU, or Mesa's software device), else Mesa's
    /// surfaceless platform.
    EGLDisplay open_display()
    {
        auto get_platform_display =
            reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(m_get_proc("eglGetPlatformDisplayEXT"));
        auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(m_get_proc("eglQueryDevicesEXT"));
        if (!get_platform_display) {
            throw environment_error("egl: eglGetPlatformDisplayEXT is missing (EGL_EXT_platform_base)");
        }
        if (query_devices) {
            std::array<EGLDeviceEXT, 16> devices{};
            EGLint count = 0;
            if (query_devices(static_cast<EGLint>(devices.size()), devices.data(), &count) && count > 0) {
                EGLDisplay d = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[0], nullptr);
                if (d != EGL_NO_DISPLAY) {
                    m_platform = "device";
                    return d;
                }
            }
        }
        EGLDisplay d = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
        if (d == EGL_NO_DISPLAY) {
            throw environment_error("egl: no EGL device and no surfaceless platform");
        }
        m_platform = "surfaceless";
        return d;
    }

    Library m_lib;
    PFNEGLGETPROCADDRESSPROC m_get_proc = nullptr;
    PFNEGLTERMINATEPROC m_terminate = nullptr;
    PFNEGLDESTROYCONTEXTPROC m_destroy = nullptr;
    EGLDisplay m_display = EGL_NO_DISPLAY;
    EGLContext m_ctx = EGL_NO_CONTEXT;
    std::string m_platform;
}; // class EglContext

} // namespace

std::unique_ptr<Context> Context::create(Backend backend)
{
    if (backend == Backend::osmesa) {
        return std::make_unique<OsMesaContext>();
    }
    return std::make_unique<EglContext>();
}

bool Context::software() const
{
    const auto* s = reinterpret_cast<const char*>(m_api.GetString(GL_RENDERER));
    const std::string r = s ? s : "";
    return r.find("llvmpipe") != std::string::npos || r.find("softpipe") != std::string::npos ||
           r.find("swrast") != std::string::npos || r.find("Software") != std::string::npos;
}

bool Context::gpu_device_node()
{
    std::error_code ec;
    if (std::filesystem::exists("/dev/nvidiactl", ec)) {
        return true;
    }
    for (const auto& e : std::filesystem::directory_iterator("/dev/dri", ec)) {
        if (e.path().filename().string().rfind("renderD", 0) == 0) {
            return true;
        }
    }
    return false;
}

std::unique_ptr<Context> Context::create_gpu(std::string& why)
{
    // EGL only where a GPU's device node exists: elsewhere it could only
    // find Mesa's software device, the same llvmpipe as OSMesa, so it is
    // not even opened (no libEGL loaded on a machine without a GPU).
    if (!gpu_device_node()) {
        why = "no GPU device node (/dev/nvidiactl, /dev/dri/renderD*)";
        return nullptr;
    }
    try {
        auto egl = create(Backend::egl);
        if (!egl->software()) {
            why = "a GPU through EGL";
            return egl;
        }
        why = "EGL found only a software renderer";
    } catch (const environment_error& e) {
        why = std::string("EGL failed: ") + e.what();
    }
    return nullptr;
}

std::unique_ptr<Context> Context::create_auto(std::string& why)
{
    if (auto gpu = create_gpu(why)) {
        return gpu;
    }
    return create(Backend::osmesa);
}

} // namespace tigerlod::gl
