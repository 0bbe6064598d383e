#pragma once
/// @file program.hpp
/// A GL program from a vertex and a fragment shader's sources, for every
/// user of the GL layer (simplify's raster, the renderer).

#include "gl/api.hpp"

#include <string>

namespace tigerlod::gl {

/// Compile both shaders and link them. Throws environment_error with the
/// driver's log when a shader does not compile or the program does not link.
GLuint link_program(const Api& gl, const std::string& vertex_source, const std::string& fragment_source);

} // namespace tigerlod::gl
