# ctest driver: install the reader package from BUILD_DIR into a scratch
# prefix, build tests/package against it with CXX_FLAGS, and run it on a
# synthetic tree written by MAKE_TREE.
set(work ${BUILD_DIR}/package-test)
file(REMOVE_RECURSE ${work})
set(TREE ${work}/tree)
execute_process(COMMAND ${MAKE_TREE} ${TREE} RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "make_test_tree failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${work}/prefix
                RESULT_VARIABLE rc OUTPUT_QUIET)
if(rc)
  message(FATAL_ERROR "install failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR}/tests/package -B ${work}/build -G Ninja
                        -DCMAKE_PREFIX_PATH=${work}/prefix "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}"
                RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "configuring the consumer failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${work}/build RESULT_VARIABLE rc)
if(rc)
  message(FATAL_ERROR "building the consumer failed")
endif()
execute_process(COMMAND ${work}/build/consumer ${TREE} RESULT_VARIABLE rc OUTPUT_VARIABLE out)
message(STATUS "${out}")
if(rc)
  message(FATAL_ERROR "the consumer failed on ${TREE}")
endif()
