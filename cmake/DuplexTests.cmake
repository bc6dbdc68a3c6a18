# Unit tests live beside what they test: each library folder and each object type's folder lists its
# own with duplex_add_unit_tests. One executable per test file, so that ctest runs them in parallel
# and a failure names its area. Included by the top-level CMakeLists.txt before the libraries.

find_package(GTest REQUIRED)
include(GoogleTest)

# Real meshes come from the shared data folder next to the repository; tests that need one skip with
# a message when it is absent. Small fixtures of our own live in objects/mesh/tests/data.
set(DUPLEX_SHARED_DATA_DIR "${PROJECT_SOURCE_DIR}/../shared/data" CACHE PATH
    "Shared data folder with meshes/ (spot, koala, ...) used by the unit tests when present")

# What every test may include: tests/support (fixtures, brute-force references, invariant checkers).
add_library(duplex_test_support INTERFACE)
target_include_directories(duplex_test_support INTERFACE ${PROJECT_SOURCE_DIR}/tests/support)
target_compile_definitions(duplex_test_support INTERFACE
  DUPLEX_SHARED_DATA="${DUPLEX_SHARED_DATA_DIR}"
  DUPLEX_TEST_DATA="${PROJECT_SOURCE_DIR}/objects/mesh/tests/data"
  DUPLEX_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
target_link_libraries(duplex_test_support INTERFACE duplex::duplex GTest::gtest GTest::gtest_main duplex_warnings)

# duplex_add_unit_tests(TESTS name... [DIR dir] [PRIVATE_INCLUDE dir...] [LIBS target...] [ISA_VARIANTS])
# Adds <dir>/<name>.cpp of the calling folder (dir: "tests" unless given; "." for the folder itself)
# as executable duplex_<name>, its GoogleTest cases
# discovered into CTest (label "unit"). PRIVATE_INCLUDE: folders of private headers the tests check
# directly (relative to the calling folder). ISA_VARIANTS: the cases run again with DUPLEX_ISA=sse2
# and avx2 (except the kd-tree's, whose parameter names start with kdtree), so each narrower SIMD path is tested on any x86-64 machine (Release only: the sanitizer
# build runs the widest path).
function(duplex_add_unit_tests)
  cmake_parse_arguments(arg "ISA_VARIANTS" "DIR" "TESTS;PRIVATE_INCLUDE;LIBS" ${ARGN})
  if(NOT arg_DIR)
    set(arg_DIR tests)
  endif()
  foreach(test_name IN LISTS arg_TESTS)
    # The ThreadSanitizer build has only its concurrency tests.
    if(DUPLEX_TSAN AND NOT test_name IN_LIST DUPLEX_TSAN_TESTS)
      continue()
    endif()
    add_executable(duplex_${test_name} ${arg_DIR}/${test_name}.cpp)
    foreach(dir IN LISTS arg_PRIVATE_INCLUDE)
      target_include_directories(duplex_${test_name} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/${dir})
    endforeach()
    target_link_libraries(duplex_${test_name} PRIVATE duplex_test_support ${arg_LIBS})
    # The sanitizer build compiles the tests' own code without optimisation (the library keeps its
    # flags): their compile time is most of that build's, and the sanitizers check the same.
    if(DUPLEX_SANITIZE)
      target_compile_options(duplex_${test_name} PRIVATE -O0)
    endif()
    # Listing the tests runs the executable: give sanitizer builds time for that.
    if(DUPLEX_SANITIZE)
      gtest_discover_tests(duplex_${test_name} DISCOVERY_TIMEOUT 120 PROPERTIES LABELS unit TIMEOUT 900
        ENVIRONMENT "LSAN_OPTIONS=suppressions=${PROJECT_SOURCE_DIR}/tests/support/lsan.supp:print_suppressions=0")
    else()
      gtest_discover_tests(duplex_${test_name} DISCOVERY_TIMEOUT 120 PROPERTIES LABELS unit TIMEOUT 900)
      if(arg_ISA_VARIANTS)
        # The kd-tree's queries have no run-time chosen kernels: its cases (parameters named
        # kdtree...) run once, in the default run.
        set(isa_filter "-*/kdtree:*/kdtree_*")
        foreach(isa sse2 avx2)
          gtest_discover_tests(duplex_${test_name} TEST_PREFIX "${isa}." DISCOVERY_TIMEOUT 120
            TEST_FILTER "${isa_filter}" PROPERTIES LABELS unit TIMEOUT 900 ENVIRONMENT "DUPLEX_ISA=${isa}")
        endforeach()
      endif()
    endif()
  endforeach()
endfunction()
