# Unit tests live beside what they test: each library folder and each object type's folder lists its
# own with duplex_add_unit_tests. One executable per folder (duplex_tests_<folder>: accel,
# scenegraph, objects_mesh, sensors_transport, ...), its GoogleTest cases discovered into CTest one by
# one, so that ctest lists every case, runs them in parallel, and a failure names its case and (label)
# its folder. Included by the top-level CMakeLists.txt before the libraries.

find_package(GTest REQUIRED)
include(GoogleTest)

# Real meshes come from the shared data folder next to the repository; tests that need one skip with
# a message when it is absent. Small fixtures of our own live in objects/mesh/tests/data.
set(DUPLEX_SHARED_DATA_DIR "${PROJECT_SOURCE_DIR}/../shared/data" CACHE PATH
    "Shared data folder with meshes/ (spot, koala, ...) used by the unit tests when present")

# What every test may include: tests/support (fixtures, brute-force references, invariant checkers).
# Its headers declare; the larger functions are compiled once, by layer, into static libraries
# (duplex_test_support_objects: meshes, structure checkers, scratch folders;
# duplex_test_support_sensors: the sensor-run fixture) instead of into every test file.
add_library(duplex_test_support_headers INTERFACE)
target_include_directories(duplex_test_support_headers INTERFACE ${PROJECT_SOURCE_DIR}/tests/support)
target_compile_definitions(duplex_test_support_headers INTERFACE
  DUPLEX_SHARED_DATA="${DUPLEX_SHARED_DATA_DIR}"
  DUPLEX_TEST_DATA="${PROJECT_SOURCE_DIR}/objects/mesh/tests/data"
  DUPLEX_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
target_link_libraries(duplex_test_support_headers INTERFACE GTest::gtest duplex_warnings)
# Compiled at -O1, as the tests' own code (see _duplex_add_to_test_executable).
set(duplex_test_support_dir ${PROJECT_SOURCE_DIR}/tests/support)
add_library(duplex_test_support_objects STATIC EXCLUDE_FROM_ALL
  ${duplex_test_support_dir}/TestSupport.cpp ${duplex_test_support_dir}/KdTreeChecks.cpp
  ${duplex_test_support_dir}/BvhChecks.cpp ${duplex_test_support_dir}/MeshChecks.cpp)
target_link_libraries(duplex_test_support_objects PUBLIC duplex_test_support_headers duplex::objects)
set(duplex_test_support_libraries duplex_test_support_objects)
# The ThreadSanitizer build's tests (DUPLEX_TSAN_TESTS: a scene queried while another thread commits)
# use meshes and the scene graph only; that build leaves duplex::sensors out (CMakeLists.txt).
if(NOT DUPLEX_TSAN)
  add_library(duplex_test_support_sensors STATIC EXCLUDE_FROM_ALL ${duplex_test_support_dir}/SensorFixture.cpp)
  target_link_libraries(duplex_test_support_sensors PUBLIC duplex_test_support_objects duplex::sensors)
  list(APPEND duplex_test_support_libraries duplex_test_support_sensors)
endif()
foreach(library IN LISTS duplex_test_support_libraries)
  target_compile_options(${library} PRIVATE $<$<CONFIG:Release,RelWithDebInfo,MinSizeRel>:-O1>)
endforeach()
add_library(duplex_test_support INTERFACE)
if(DUPLEX_TSAN)
  set(duplex_test_libraries duplex::accel duplex::scenegraph duplex::objects)
else()
  set(duplex_test_libraries duplex::duplex)
endif()
target_link_libraries(duplex_test_support INTERFACE ${duplex_test_support_libraries} ${duplex_test_libraries}
                      GTest::gtest_main)

# duplex_add_unit_tests(TESTS name... [DIR dir] [PRIVATE_INCLUDE dir...] [LIBS target...] [ISA_VARIANTS]
#                       [OWN_EXECUTABLE])
# Adds <dir>/<name>.cpp of the calling folder (dir: "tests" unless given; "." for the folder itself)
# to the folder's test executable duplex_tests_<folder> (a folder may call this several times),
# its GoogleTest cases discovered into CTest (labels "unit" and the folder, e.g. "objects/mesh").
# PRIVATE_INCLUDE: folders of private headers these files check directly (relative to the calling
# folder; given to these files only). LIBS: what these files need besides the library and GoogleTest.
# ISA_VARIANTS: these files' cases run again with DUPLEX_ISA=sse2 and avx2 (except the kd-tree's,
# whose parameter names start with kdtree), so each narrower SIMD path is tested on any x86-64
# machine (Release only: the sanitizer build runs the widest path). OWN_EXECUTABLE: each file in an
# executable of its own (duplex_tests_<folder>_<name>), for files that change the whole process
# (a replaced global operator new).
function(duplex_add_unit_tests)
  cmake_parse_arguments(arg "ISA_VARIANTS;OWN_EXECUTABLE" "DIR" "TESTS;PRIVATE_INCLUDE;LIBS" ${ARGN})
  if(NOT arg_DIR)
    set(arg_DIR tests)
  endif()
  set(sources)
  foreach(test_name IN LISTS arg_TESTS)
    # The ThreadSanitizer build has only its concurrency tests.
    if(DUPLEX_TSAN AND NOT test_name IN_LIST DUPLEX_TSAN_TESTS)
      continue()
    endif()
    list(APPEND sources ${CMAKE_CURRENT_SOURCE_DIR}/${arg_DIR}/${test_name}.cpp)
  endforeach()
  if(NOT sources)
    return()
  endif()

  file(RELATIVE_PATH area ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_SOURCE_DIR})
  string(REGEX REPLACE "^tests/" "" area "${area}")
  string(REPLACE "/" "_" folder_target "${area}")
  set(folder_target duplex_tests_${folder_target})
  if(arg_OWN_EXECUTABLE)
    # A file that replaces process-wide behaviour (the global operator new) gets an executable of
    # its own, duplex_tests_<folder>_<name>, so that the folder's other cases do not run with it.
    foreach(source IN LISTS sources)
      get_filename_component(name ${source} NAME_WE)
      _duplex_add_to_test_executable(${folder_target}_${name} ${area} ${source})
    endforeach()
  else()
    _duplex_add_to_test_executable(${folder_target} ${area} ${sources})
  endif()
endfunction()

# Adds the sources to the test executable `target` (created on first use) with the arguments of the
# calling duplex_add_unit_tests (arg_PRIVATE_INCLUDE, arg_LIBS, arg_ISA_VARIANTS).
macro(_duplex_add_to_test_executable target area)
  set(duplex_target_sources ${ARGN})
  if(NOT TARGET ${target})
    add_executable(${target})
    target_link_libraries(${target} PRIVATE duplex_test_support)
    # What most test files include, parsed once per build (GoogleTest alone is about a second of
    # every test file's compile without optimisation): the first test executable (accel's, whose
    # compile definitions every other one also has; clang refuses a header precompiled with a
    # definition its user lacks) precompiles it, the others use its file.
    get_property(duplex_pch_owner GLOBAL PROPERTY DUPLEX_TEST_PCH_OWNER)
    if(duplex_pch_owner)
      target_precompile_headers(${target} REUSE_FROM ${duplex_pch_owner})
    else()
      target_precompile_headers(${target} PRIVATE <gtest/gtest.h> <algorithm> <cmath> <filesystem> <fstream>
        <limits> <memory> <random> <sstream> <string> <vector> <glm/geometric.hpp>)
      set_property(GLOBAL PROPERTY DUPLEX_TEST_PCH_OWNER ${target})
    endif()
    # The tests' own code (checks, brute-force references, fixtures) is compiled at -O1 in every
    # optimised build, the sanitizer builds included, while the library keeps its flags: GCC's -O3
    # costs much more compile time on a test file, and the tests check the library as it was built.
    # Not -O0 under the sanitizers: the brute-force references then dominate the suite's run time
    # (glm's small functions uninlined and instrumented), far more than -O1 adds to the compile.
    # -ffp-contract=off holds for both, so floating-point results do not depend on the level.
    target_compile_options(${target} PRIVATE $<$<CONFIG:Release,RelWithDebInfo,MinSizeRel>:-O1>)
    # The cases are discovered once all of the folder's files are added (end of the folder's CMakeLists.txt).
    cmake_language(EVAL CODE "cmake_language(DEFER CALL duplex_discover_unit_tests ${target} ${area})")
  endif()
  target_sources(${target} PRIVATE ${duplex_target_sources})
  foreach(dir IN LISTS arg_PRIVATE_INCLUDE)
    set_property(SOURCE ${duplex_target_sources} APPEND PROPERTY INCLUDE_DIRECTORIES ${CMAKE_CURRENT_SOURCE_DIR}/${dir})
  endforeach()
  if(arg_LIBS)
    target_link_libraries(${target} PRIVATE ${arg_LIBS})
  endif()
  if(arg_ISA_VARIANTS)
    # The GoogleTest filter of these files' cases: their suites (TEST*(Suite, ...)), plain or with an
    # instantiation prefix (Prefix/Suite.Case/parameter).
    foreach(duplex_source IN LISTS duplex_target_sources)
      file(STRINGS ${duplex_source} duplex_lines REGEX "^ *(TEST|TEST_F|TEST_P|TYPED_TEST)\\( *[A-Za-z0-9_]+ *,")
      foreach(duplex_line IN LISTS duplex_lines)
        string(REGEX REPLACE "^ *[A-Z_]+\\( *([A-Za-z0-9_]+) *,.*$" "\\1" duplex_suite "${duplex_line}")
        set_property(TARGET ${target} APPEND PROPERTY DUPLEX_ISA_SUITES ${duplex_suite})
      endforeach()
    endforeach()
  endif()
endmacro()

# Discovers the cases of a folder's test executable into CTest: once as they are, and, for the
# suites of the ISA_VARIANTS files (Release only), once per narrower ISA with the prefix "<isa>.".
function(duplex_discover_unit_tests target area)
  set(labels_file ${CMAKE_CURRENT_BINARY_DIR}/${target}_labels.cmake)
  if(DUPLEX_SANITIZE)
    gtest_discover_tests(${target} DISCOVERY_TIMEOUT 120 PROPERTIES TIMEOUT 900
      ENVIRONMENT "LSAN_OPTIONS=suppressions=${PROJECT_SOURCE_DIR}/tests/support/lsan.supp:print_suppressions=0")
  else()
    gtest_discover_tests(${target} DISCOVERY_TIMEOUT 120 PROPERTIES TIMEOUT 900)
    get_property(suites TARGET ${target} PROPERTY DUPLEX_ISA_SUITES)
    if(suites)
      list(REMOVE_DUPLICATES suites)
      set(positive)
      foreach(suite IN LISTS suites)
        list(APPEND positive "${suite}.*" "*/${suite}.*")
      endforeach()
      list(JOIN positive ":" positive)
      # The kd-tree's queries have no run-time chosen kernels: its cases (parameters named
      # kdtree...) run once, in the default run.
      foreach(isa sse2 avx2)
        gtest_discover_tests(${target} TEST_PREFIX "${isa}." TEST_LIST ${target}_${isa}_TESTS DISCOVERY_TIMEOUT 120
          TEST_FILTER "${positive}-*/kdtree:*/kdtree_*" PROPERTIES TIMEOUT 900 ENVIRONMENT "DUPLEX_ISA=${isa}")
      endforeach()
    endif()
  endif()
  # Labels "unit" and the folder on every discovered case (a list cannot pass through
  # gtest_discover_tests' PROPERTIES): a file CTest reads after the discovered cases.
  file(WRITE ${labels_file}
    "foreach(duplex_list ${target}_TESTS ${target}_sse2_TESTS ${target}_avx2_TESTS)\n"
    "  foreach(duplex_case IN LISTS \${duplex_list})\n"
    "    set_tests_properties(\"\${duplex_case}\" PROPERTIES LABELS \"unit;${area}\")\n"
    "  endforeach()\n"
    "endforeach()\n")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES ${labels_file})
endfunction()
