# Small helpers so each module's CMakeLists.txt stays a few lines long (STYLE.md §1).

set(FACEDYN_WARNING_FLAGS -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
    -Wno-deprecated-copy)  # Eigen 3.4 and OpenMesh 9 trip -Wdeprecated-copy in their headers.

function(_facedyn_common_options target)
  target_compile_options(${target} PRIVATE ${FACEDYN_WARNING_FLAGS})
  if(FACEDYN_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  # -fno-sanitize-recover=all: a UBSan finding ends the process (and fails the test) instead of
  # printing a line that a passing run would hide.
  if(FACEDYN_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=all)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
  # FACEDYN_FUZZ: libFuzzer's coverage instrumentation everywhere, the fuzzer's main only in
  # the fuzz targets (fuzz/CMakeLists.txt links them with -fsanitize=fuzzer).
  if(FACEDYN_FUZZ)
    target_compile_options(${target} PRIVATE -fsanitize=fuzzer-no-link,address,undefined
                                             -fno-omit-frame-pointer -fno-sanitize-recover=all)
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
  if(FACEDYN_SANITIZE OR FACEDYN_FUZZ)
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

include(GoogleTest)

# Exit code of tests/support/test_main.cc when every case that ran was skipped; CTest reports
# such a test as "Skipped" instead of counting it as passed. 77 is the automake convention.
set(FACEDYN_TEST_SKIP_CODE 77)

# facedyn_add_test(<module> <name> [DEPS ...] [TIMEOUT s] [ONE_PROCESS [LABELS ...]])
#   Builds tests/<module>/<name>.cc into one GoogleTest binary. Each of its cases is one CTest
#   test named "<module>/<name>.<Suite>.<Case>" (e.g. core/pc2_test.Pc2.RoundTrip), so
#   `ctest -R core/pc2_test` runs the binary's cases, and a case that skips (its peer is missing)
#   is reported as skipped on its own while the cases that ran are reported as passed: with
#   one CTest test per binary, a binary with one skipped case would have to count as wholly
#   passed (the skip invisible) or wholly skipped (the passes invisible). The cases of one
#   binary keep running one at a time (RESOURCE_LOCK), as they did in one process: some share
#   ports, pty names or mount points. TIMEOUT applies to each case.
#   ONE_PROCESS keeps the binary as a single CTest test "<module>/<name>", for binaries whose
#   cases share an expensive process-wide fixture (a function-local static built once); there
#   the binary is reported skipped only when every case skipped (test_main.cc), and a partial
#   skip counts as passed - such binaries should not contain skippable cases.
#   Tests find the shared assets through FACEDYN_SHARED_DIR (defaults to ../shared beside the
#   source tree).
function(facedyn_add_test module name)
  cmake_parse_arguments(ARG "ONE_PROCESS" "TIMEOUT" "DEPS;LABELS;SOURCES" ${ARGN})
  set(target ${module}_${name})
  # The shared main(), compiled once (a static library: the linker takes main from it).
  if(NOT TARGET facedyn_test_main)
    add_library(facedyn_test_main STATIC ${PROJECT_SOURCE_DIR}/tests/support/test_main.cc)
    target_link_libraries(facedyn_test_main PUBLIC GTest::gtest)
    target_compile_definitions(facedyn_test_main
                               PRIVATE FACEDYN_TEST_SKIP_CODE=${FACEDYN_TEST_SKIP_CODE})
    _facedyn_common_options(facedyn_test_main)
  endif()
  add_executable(${target} ${name}.cc ${ARG_SOURCES})
  # For facedyn_add_sanitizer_ci_target (the module's tests, by binary and CTest prefix).
  set_property(GLOBAL APPEND PROPERTY FACEDYN_TEST_TARGETS ${target})
  set_target_properties(${target} PROPERTIES FACEDYN_TEST_MODULE ${module}
                                             FACEDYN_TEST_NAME ${module}/${name})
  target_link_libraries(${target} PRIVATE facedyn_test_main facedyn_test_support ${ARG_DEPS}
                                          GTest::gtest GTest::gmock)
  target_compile_definitions(${target} PRIVATE FACEDYN_TEST_SKIP_CODE=${FACEDYN_TEST_SKIP_CODE})
  _facedyn_common_options(${target})
  # A test's own source only sets up, calls and checks: the code under test is in the libraries,
  # built as the build type says. In a Release build the test sources get -O1 (after the
  # type's -O3 on the command line, so it wins): measured on three test sources, 42 -> 35 s,
  # 17.6 -> 12.6 s and 11.6 -> 9.8 s to compile, and test sources are about half of what a
  # fresh `make test` compiles.
  if(CMAKE_BUILD_TYPE STREQUAL "Release")
    target_compile_options(${target} PRIVATE -O1)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set(properties TIMEOUT ${ARG_TIMEOUT} SKIP_RETURN_CODE ${FACEDYN_TEST_SKIP_CODE}
      ENVIRONMENT "FACEDYN_BINARY_DIR=${PROJECT_BINARY_DIR}")
  if(ARG_ONE_PROCESS)
    add_test(NAME ${module}/${name} COMMAND ${target})
    set_tests_properties(${module}/${name} PROPERTIES ${properties}
                         LABELS "${module};${ARG_LABELS}")
  else()
    # gtest_discover_tests passes PROPERTIES through two generated scripts that split any list
    # value (checked with CMake 3.25: "core;extra" became LABELS core plus a property "extra"),
    # so a discovered case carries one label, its module.
    if(ARG_LABELS)
      message(FATAL_ERROR "facedyn_add_test(${module} ${name}): extra LABELS need ONE_PROCESS "
                          "(discovered cases can carry only their module label)")
    endif()
    # PRE_TEST: the case list is read when ctest runs, not at build time, so building never
    # runs a test binary (sanitizer builds, partial builds of a few targets).
    gtest_discover_tests(${target} TEST_PREFIX "${module}/${name}." DISCOVERY_MODE PRE_TEST
                         DISCOVERY_TIMEOUT 120 PROPERTIES ${properties} LABELS ${module}
                         RESOURCE_LOCK ${target})
  endif()
endfunction()

# facedyn_add_sanitizer_ci_target(<target> MODULES ...)
#   A target that builds the test binaries of MODULES (and the fuzz replays) but not the ones
#   that run the `facedyn` executable (add_dependencies(... facedyn)): those need every library
#   of the project, which is what makes a full sanitizer build long. The CTest names of the
#   tests left out are written, as one regular expression for `ctest -E`, to
#   <build>/<target>_exclude.txt (`make asan-ci` reads it), so ctest does not report their
#   unbuilt binaries as failures. Call after every facedyn_add_test.
function(facedyn_add_sanitizer_ci_target name)
  cmake_parse_arguments(ARG "" "" "MODULES" ${ARGN})
  get_property(all GLOBAL PROPERTY FACEDYN_TEST_TARGETS)
  set(built "")
  set(left_out "")
  foreach(target IN LISTS all)
    get_target_property(module ${target} FACEDYN_TEST_MODULE)
    get_target_property(test_name ${target} FACEDYN_TEST_NAME)
    if(NOT module IN_LIST ARG_MODULES)
      continue()
    endif()
    get_target_property(manual ${target} MANUALLY_ADDED_DEPENDENCIES)
    if(manual AND "facedyn" IN_LIST manual)
      list(APPEND left_out "^${test_name}([.]|$)")
    else()
      list(APPEND built ${target})
    endif()
  endforeach()
  add_custom_target(${name} DEPENDS ${built} fuzz_all)
  list(JOIN left_out "|" regex)
  if(NOT regex)
    set(regex "^$")
  endif()
  file(WRITE ${PROJECT_BINARY_DIR}/${name}_exclude.txt "${regex}\n")
endfunction()
