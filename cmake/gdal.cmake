find_package(GDAL CONFIG REQUIRED)
if(GDAL_VERSION VERSION_LESS 3.4)
  message(FATAL_ERROR "GDAL ${GDAL_VERSION} found, tigerlod needs 3.4 or newer")
endif()
set_package_properties(GDAL PROPERTIES DESCRIPTION "reads TIGER/Line shapefiles and TopoJSON"
                                       TYPE REQUIRED)
message(STATUS "GDAL ${GDAL_VERSION}")
