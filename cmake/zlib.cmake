find_package(ZLIB REQUIRED)
message(STATUS "zlib ${ZLIB_VERSION_STRING}")
