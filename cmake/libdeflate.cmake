# libdeflate: whole-buffer deflate, several times zlib's speed at its fastest
# levels (tigerlod-synth's zip members). Debian ships a pkg-config file only.
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBDEFLATE REQUIRED IMPORTED_TARGET libdeflate)
message(STATUS "libdeflate ${LIBDEFLATE_VERSION}")
