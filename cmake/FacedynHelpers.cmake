# Small helpers so each module's CMakeLists.txt stays a few lines long (STYLE.md §1).

set(FACEDYN_WARNING_FLAGS -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
    -Wno-deprecated-copy)  # Eigen 3.4 and OpenMesh 9 trip -Wdeprecated-copy in their headers.

function(_facedyn_common_options target)
  target_compile_options(${target} PRIVATE ${FACEDYN_WARNING_FLAGS})
  if(FACEDYN_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(FACEDYN_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
endfunction()

# facedyn_add_library(<module> SOURCES ... DEPS ...)
#   Creates target facedyn_<module> from the module folder; headers are included as
#   "<module>/<file>.h" from the project root.
function(facedyn_add_library module)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  set(target facedyn_${module})
  add_library(${target} STATIC ${ARG_SOURCES})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR}/generated)
  target_link_libraries(${target} PUBLIC ${ARG_DEPS})
  _facedyn_common_options(${target})
  if(FACEDYN_SANITIZE)
    target_link_options(${target} PUBLIC -fsanitize=address,undefined)
  endif()
endfunction()

# facedyn_add_executable(<name> SOURCES ... DEPS ...)
function(facedyn_add_executable name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS})
  _facedyn_common_options(${name})
endfunction()

# facedyn_add_test(<module> <name> [DEPS ...] [LABELS ...] [TIMEOUT s])
#   Builds tests/<module>/<name>.cc into one GoogleTest binary registered with CTest as
#   "<module>/<name>" (e.g. core/pc2_test). Tests find the shared assets through
#   FACEDYN_SHARED_DIR (defaults to ../shared beside the source tree).
function(facedyn_add_test module name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "DEPS;LABELS;SOURCES" ${ARGN})
  set(target ${module}_${name})
  add_executable(${target} ${name}.cc ${ARG_SOURCES})
  target_link_libraries(${target} PRIVATE facedyn_test_support ${ARG_DEPS} GTest::gtest
                                          GTest::gmock GTest::gtest_main)
  _facedyn_common_options(${target})
  add_test(NAME ${module}/${name} COMMAND ${target})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set_tests_properties(${module}/${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT} LABELS "${module};${ARG_LABELS}"
      ENVIRONMENT "FACEDYN_BINARY_DIR=${PROJECT_BINARY_DIR}")
endfunction()
