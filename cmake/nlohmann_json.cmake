find_package(nlohmann_json 3.10 CONFIG REQUIRED)
message(STATUS "nlohmann_json ${nlohmann_json_VERSION}")
