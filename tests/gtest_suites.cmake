# shadowtile_discover_tests(TARGET TIMEOUT): the gtest binary's tests for ctest. By default
# one ctest test per test case (gtest_discover_tests). With SHADOWTILE_TEST_PER_SUITE (on in
# the sanitized build) one ctest test per test suite (`--gtest_filter=Suite.*`, named
# `Suite.*`): every case still runs, in fewer processes. A sanitized test process costs
# about 0.3-0.5 s of CPU to start and stop (ASan's shadow memory, the leak check at exit)
# before its first check, and a suite's cases share one start and one SetUpTestSuite: over
# ~660 cases in ~160 suites that is several CPU-minutes of a CI run. A skipped case
# (GTEST_SKIP) leaves its suite passed, not skipped; a failing case fails its suite, and the
# output names it. Run one case with `tests/BINARY --gtest_filter=Suite.Case`.
option(SHADOWTILE_TEST_PER_SUITE "One ctest test per gtest suite instead of per case" ${SHADOWTILE_SANITIZE})
function(shadowtile_discover_tests target timeout)
  if(NOT SHADOWTILE_TEST_PER_SUITE)
    gtest_discover_tests(${target} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT ${timeout})
    return()
  endif()
  set(tests_file "${CMAKE_CURRENT_BINARY_DIR}/${target}_suites.cmake")
  set(include_file "${CMAKE_CURRENT_BINARY_DIR}/${target}_suites_include.cmake")
  get_property(emulator TARGET ${target} PROPERTY CROSSCOMPILING_EMULATOR)
  add_custom_command(TARGET ${target} POST_BUILD BYPRODUCTS "${tests_file}"
    COMMAND "${CMAKE_COMMAND}" -D "TEST_EXECUTABLE=$<TARGET_FILE:${target}>"
            -D "TEST_EXECUTOR=${emulator}" -D "CTEST_FILE=${tests_file}" -D "TEST_TIMEOUT=${timeout}"
            -P "${PROJECT_SOURCE_DIR}/tests/gtest_suites_add.cmake"
    VERBATIM)
  file(WRITE "${include_file}"
    "if(EXISTS \"${tests_file}\")\n  include(\"${tests_file}\")\nelse()\n"
    "  add_test(${target}_NOT_BUILT ${target}_NOT_BUILT)\nendif()\n")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES "${include_file}")
endfunction()
