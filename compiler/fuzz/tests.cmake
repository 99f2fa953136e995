# Tests of the form compiler's fuzz target, included by tests/CMakeLists.txt with the compiler area
# (this file lives beside the target: compiler/fuzz/, docs/fuzzing.md).
#
#   fuzz_replay          every build: the entry point over the seed corpus and regressions/ (< 10 s)
#   fuzz_lmeformc_short  LMEFORM_FUZZ=ON: 30 s of libFuzzer from the seeds, the crashers and what
#                        earlier runs found (<build>/compiler/fuzz/corpus)

lmeform_add_test(fuzz_replay
  SOURCES ${CMAKE_CURRENT_LIST_DIR}/fuzz_replay.cpp ${CMAKE_CURRENT_LIST_DIR}/fuzz_lmeformc.cpp
  LIBS lmeform_compiler
  LABELS compiler fuzz
  TIMEOUT 120)
target_compile_definitions(fuzz_replay PRIVATE LMEFORM_SOURCE_DIR="${PROJECT_SOURCE_DIR}")

if(TARGET fuzz_lmeformc)
  add_test(NAME fuzz_lmeformc_short
    COMMAND fuzz_lmeformc -max_total_time=30 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1
            -dict=${CMAKE_CURRENT_LIST_DIR}/lmeform.dict
            $<TARGET_FILE_DIR:fuzz_lmeformc>/corpus $<TARGET_FILE_DIR:fuzz_lmeformc>/seeds
            ${CMAKE_CURRENT_LIST_DIR}/regressions
    # The artifacts of a failing run (crash-*, timeout-*) land in the working directory.
    WORKING_DIRECTORY $<TARGET_FILE_DIR:fuzz_lmeformc>)
  set_tests_properties(fuzz_lmeformc_short PROPERTIES LABELS fuzz TIMEOUT 120)
endif()
