# Debian's GeographicLib ships a find module, not a package config, and the
# module sets no version: read it from the installed Config.h.
list(APPEND CMAKE_MODULE_PATH /usr/share/cmake/geographiclib)
find_package(GeographicLib REQUIRED)
find_file(TIGERLOD_GEOGRAPHICLIB_CONFIG GeographicLib/Config.h
          HINTS ${GeographicLib_INCLUDE_DIRS} REQUIRED)
file(STRINGS ${TIGERLOD_GEOGRAPHICLIB_CONFIG} _geo_version
     REGEX "define GEOGRAPHICLIB_VERSION_STRING")
string(REGEX MATCH "[0-9]+\\.[0-9]+(\\.[0-9]+)?" GeographicLib_VERSION "${_geo_version}")
if(GeographicLib_VERSION VERSION_LESS 1.50)
  message(FATAL_ERROR "GeographicLib ${GeographicLib_VERSION} found, tigerlod needs 1.50 or newer")
endif()
add_library(tigerlod_geographiclib INTERFACE)
target_include_directories(tigerlod_geographiclib SYSTEM INTERFACE ${GeographicLib_INCLUDE_DIRS})
target_link_libraries(tigerlod_geographiclib INTERFACE ${GeographicLib_LIBRARIES})
add_library(GeographicLib::GeographicLib ALIAS tigerlod_geographiclib)
message(STATUS "GeographicLib ${GeographicLib_VERSION}")
