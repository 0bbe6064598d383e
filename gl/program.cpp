#include "gl/program.hpp"

#include "core/errors.hpp"

namespace tigerlod::gl {

namespace {

/// The info log of a shader or program (glGetShaderInfoLog / glGetProgramInfoLog).
template <class Get> std::string info_log(Get get, GLuint object)
{
    std::string log(4096, '\0');
    GLsizei n = 0;
    get(object, GLsizei(log.size()), &n, log.data());
    log.resize(size_t(n));
    return log;
}

GLuint compile(const Api& gl, GLenum type, const std::string& src)
{
    const GLuint s = gl.CreateShader(type);
    const char* p = src.c_str();
    gl.ShaderSource(s, 1, &p, nullptr);
    gl.CompileShader(s);
    GLint ok = 0;
    gl.GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        const std::string log = info_log(gl.GetShaderInfoLog, s);
        gl.DeleteShader(s);
        throw environment_error("OpenGL shader does not compile on this driver: " + log);
    }
    return s;
}

} // namespace

GLuint link_program(const Api& gl, const std::string& vertex_source, const std::string& fragment_source)
{
    const GLuint v = compile(gl, GL_VERTEX_SHADER, vertex_source);
    const GLuint f = compile(gl, GL_FRAGMENT_SHADER, fragment_source);
    const GLuint p = gl.CreateProgram();
    gl.AttachShader(p, v);
    gl.AttachShader(p, f);
    gl.LinkProgram(p);
    gl.DeleteShader(v);
    gl.DeleteShader(f);
    GLint ok = 0;
    gl.GetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        const std::string log = info_log(gl.GetProgramInfoLog, p);
        gl.DeleteProgram(p);
        throw environment_error("OpenGL program does not link on this driver: " + log);
    }
    return p;
}

} // namespace tigerlod::gl
