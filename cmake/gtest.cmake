find_package(GTest CONFIG REQUIRED)
include(GoogleTest)
message(STATUS "GoogleTest ${GTest_VERSION}")
