# Helper functions that keep target lists short.

# Warning flags for every target of ours.
function(tigerlod_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow
                                           -Wconversion -Wno-sign-conversion)
  if(TIGERLOD_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# tigerlod_add_stage(NAME lib_target [SOURCES ...]): builds tigerlod-NAME from
# stages/NAME/main.cpp over the stage library `lib_target`.
function(tigerlod_add_stage name lib)
  add_executable(tigerlod-${name} ${CMAKE_CURRENT_SOURCE_DIR}/main.cpp)
  target_link_libraries(tigerlod-${name} PRIVATE ${lib})
  tigerlod_warnings(tigerlod-${name})
endfunction()

# tigerlod_add_test(NAME SOURCES ... LIBS ... [NO_LEAK_CHECK] [OPTIMIZED]): one GoogleTest
# binary, its tests discovered by CTest. NO_LEAK_CHECK turns LeakSanitizer off
# for it in the sanitizer build (AddressSanitizer still checks memory).
# COST: ctest's estimate of each of its tests' seconds, so that a fresh
# build (no timings of its own yet) starts the long ones first and -j keeps
# every core busy to the end. The tests' own code is compiled with
# TIGERLOD_TEST_CXX_FLAGS after the build's options (OPTIMIZED: without them).
function(tigerlod_add_test name)
  cmake_parse_arguments(T "NO_LEAK_CHECK;OPTIMIZED" "COST" "SOURCES;LIBS" ${ARGN})
  if(NOT T_COST)
    set(T_COST 1)
  endif()
  set(env "LSAN_OPTIONS=suppressions=${PROJECT_SOURCE_DIR}/tests/lsan.supp:print_suppressions=0")
  if(T_NO_LEAK_CHECK)
    string(APPEND env ":detect_leaks=0")
  endif()
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE ${T_LIBS} GTest::gtest_main)
  target_compile_definitions(
    ${name} PRIVATE TIGERLOD_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
                    TIGERLOD_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}")
  tigerlod_warnings(${name})
  # OPTIMIZED: the test's own code does the heavy work (brute forces over
  # every pair), so it keeps the build's optimisation.
  if(NOT T_OPTIMIZED)
    target_compile_options(${name} PRIVATE ${TIGERLOD_TEST_CXX_FLAGS})
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT 900 COST ${T_COST} ENVIRONMENT "${env}")
endfunction()
