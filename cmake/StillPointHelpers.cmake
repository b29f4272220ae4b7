# Shared CMake helpers: one library per module folder, one test binary per test file.

function(sp_module_enabled module out)
  if(SP_ONLY_MODULES STREQUAL "" OR module IN_LIST SP_ONLY_MODULES)
    set(${out} TRUE PARENT_SCOPE)
  else()
    set(${out} FALSE PARENT_SCOPE)
  endif()
endfunction()

function(sp_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  if(SP_SANITIZE STREQUAL "address")
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  elseif(SP_SANITIZE STREQUAL "thread")
    target_compile_options(${target} PRIVATE -fsanitize=thread -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=thread)
  endif()
endfunction()

# sp_add_module(NAME <module> SOURCES ... DEPS ...): library sp_<module> with src/ as include root.
function(sp_add_module)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;DEPS" ${ARGN})
  add_library(sp_${ARG_NAME} STATIC ${ARG_SOURCES})
  target_include_directories(sp_${ARG_NAME} PUBLIC ${CMAKE_SOURCE_DIR}/src)
  target_link_libraries(sp_${ARG_NAME} PUBLIC ${ARG_DEPS})
  set_target_properties(sp_${ARG_NAME} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  sp_set_warnings(sp_${ARG_NAME})
endfunction()

# sp_add_test(NAME <name> SOURCES ... DEPS ...): a GoogleTest binary whose tests CTest discovers.
# Tests read ../shared through SP_SHARED_DIR and write under SP_TEST_TMP_DIR.
function(sp_add_test)
  cmake_parse_arguments(ARG "" "NAME;TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${ARG_NAME} ${ARG_SOURCES})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${ARG_NAME} PRIVATE
    SP_SHARED_DIR="${SP_SHARED_DIR}"
    SP_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
    SP_TEST_TMP_DIR="${CMAKE_BINARY_DIR}/test_tmp")
  sp_set_warnings(${ARG_NAME})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  gtest_discover_tests(${ARG_NAME} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT ${ARG_TIMEOUT} LABELS "${ARG_LABELS}")
endfunction()
