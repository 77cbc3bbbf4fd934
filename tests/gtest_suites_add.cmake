# Script (cmake -P) run after a gtest binary is built, for SHADOWTILE_TEST_PER_SUITE
# (tests/gtest_suites.cmake): lists the binary's tests and writes CTEST_FILE with one
# add_test per suite that has an enabled case.
# In: TEST_EXECUTABLE, TEST_EXECUTOR (a list, may be empty), CTEST_FILE, TEST_TIMEOUT.
execute_process(COMMAND ${TEST_EXECUTOR} "${TEST_EXECUTABLE}" --gtest_list_tests
  OUTPUT_VARIABLE listing RESULT_VARIABLE rc TIMEOUT 60)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${TEST_EXECUTABLE} --gtest_list_tests failed (${rc}):\n${listing}")
endif()
# Drop the "# TypeParam = ..." / "# GetParam() = ..." notes (their brackets and semicolons
# would break CMake's list handling); keep suite lines ("Suite." or "Prefix/Suite.") and
# case lines ("  Case").
string(REGEX REPLACE "[ \t]*#[^\n]*" "" listing "${listing}")
string(REGEX REPLACE "[][;]" "" listing "${listing}")
string(REPLACE "\n" ";" lines "${listing}")
set(suites)
set(suite)
foreach(line IN LISTS lines)
  if(line MATCHES "^([A-Za-z0-9_/]+)\\.$")
    set(suite "${CMAKE_MATCH_1}")
  elseif(suite AND line MATCHES "^  ([A-Za-z0-9_/]+)$")
    # A suite counts once it has a case gtest runs without --gtest_also_run_disabled_tests.
    if(NOT CMAKE_MATCH_1 MATCHES "^DISABLED_" AND NOT suite MATCHES "(^|/)DISABLED_")
      list(APPEND suites "${suite}")
    endif()
  endif()
endforeach()
list(REMOVE_DUPLICATES suites)
if(NOT suites)
  message(FATAL_ERROR "${TEST_EXECUTABLE} lists no test suite")
endif()
set(script "")
set(executor "")
foreach(arg IN LISTS TEST_EXECUTOR)
  string(APPEND executor " [==[${arg}]==]")
endforeach()
foreach(s IN LISTS suites)
  string(APPEND script "add_test([==[${s}.*]==]${executor} [==[${TEST_EXECUTABLE}]==] [==[--gtest_filter=${s}.*]==])\n")
  string(APPEND script "set_tests_properties([==[${s}.*]==] PROPERTIES TIMEOUT ${TEST_TIMEOUT})\n")
endforeach()
file(WRITE "${CTEST_FILE}" "${script}")
