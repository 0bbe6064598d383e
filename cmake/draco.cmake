find_package(draco CONFIG REQUIRED)
set_package_properties(draco PROPERTIES DESCRIPTION "compresses the Data Tree's geometry payloads" TYPE REQUIRED)
message(STATUS "Draco ${draco_VERSION}")
