find_package(yaml-cpp CONFIG REQUIRED)
message(STATUS "yaml-cpp ${yaml-cpp_VERSION}")
