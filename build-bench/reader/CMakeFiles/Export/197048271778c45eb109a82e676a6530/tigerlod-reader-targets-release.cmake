#----------------------------------------------------------------
# Generated CMake target import file for configuration "Release".
#----------------------------------------------------------------

# Commands may need to know the format version.
set(CMAKE_IMPORT_FILE_VERSION 1)

# Import target "tigerlod::reader" for configuration "Release"
set_property(TARGET tigerlod::reader APPEND PROPERTY IMPORTED_CONFIGURATIONS RELEASE)
set_target_properties(tigerlod::reader PROPERTIES
  IMPORTED_LINK_INTERFACE_LANGUAGES_RELEASE "CXX"
  IMPORTED_LOCATION_RELEASE "${_IMPORT_PREFIX}/lib/libtigerlod_reader.a"
  )

list(APPEND _cmake_import_check_targets tigerlod::reader )
list(APPEND _cmake_import_check_files_for_tigerlod::reader "${_IMPORT_PREFIX}/lib/libtigerlod_reader.a" )

# Import target "tigerlod::datatree" for configuration "Release"
set_property(TARGET tigerlod::datatree APPEND PROPERTY IMPORTED_CONFIGURATIONS RELEASE)
set_target_properties(tigerlod::datatree PROPERTIES
  IMPORTED_LINK_INTERFACE_LANGUAGES_RELEASE "CXX"
  IMPORTED_LOCATION_RELEASE "${_IMPORT_PREFIX}/lib/libtigerlod_datatree.a"
  )

list(APPEND _cmake_import_check_targets tigerlod::datatree )
list(APPEND _cmake_import_check_files_for_tigerlod::datatree "${_IMPORT_PREFIX}/lib/libtigerlod_datatree.a" )

# Import target "tigerlod::base" for configuration "Release"
set_property(TARGET tigerlod::base APPEND PROPERTY IMPORTED_CONFIGURATIONS RELEASE)
set_target_properties(tigerlod::base PROPERTIES
  IMPORTED_LINK_INTERFACE_LANGUAGES_RELEASE "CXX"
  IMPORTED_LOCATION_RELEASE "${_IMPORT_PREFIX}/lib/libtigerlod_base.a"
  )

list(APPEND _cmake_import_check_targets tigerlod::base )
list(APPEND _cmake_import_check_files_for_tigerlod::base "${_IMPORT_PREFIX}/lib/libtigerlod_base.a" )

# Commands beyond this point should not need to know the version.
set(CMAKE_IMPORT_FILE_VERSION)
