# Test and benchmark registration shared by every area of the project.
#
#   lmeform_add_test(NAME SOURCES a.cpp ... [LIBS ...] [MPI_RANKS n] [LABELS ...])
#     builds a GoogleTest executable and registers it with CTest; with MPI_RANKS it is
#     started by mpiexec with that many ranks (as root, as CI runs it).
#   lmeform_add_benchmark(NAME SOURCES ... [LIBS ...])
#     builds an executable that `make bench` runs as `NAME --quick --out build/bench`.

set(LMEFORM_MPI_ENV
  OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
  OMPI_MCA_rmaps_base_oversubscribe=1)

function(lmeform_add_test name)
  cmake_parse_arguments(T "" "MPI_RANKS;TIMEOUT" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main lmeform_warnings)
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 600)
  endif()
  if(T_MPI_RANKS)
    add_test(NAME ${name}
      COMMAND ${MPIEXEC_EXECUTABLE} ${MPIEXEC_NUMPROC_FLAG} ${T_MPI_RANKS} $<TARGET_FILE:${name}>)
    set_tests_properties(${name} PROPERTIES PROCESSORS ${T_MPI_RANKS}
      ENVIRONMENT "${LMEFORM_MPI_ENV}" LABELS "mpi;${T_LABELS}" TIMEOUT ${T_TIMEOUT})
  else()
    add_test(NAME ${name} COMMAND ${name})
    set_tests_properties(${name} PROPERTIES
      ENVIRONMENT "${LMEFORM_MPI_ENV}" LABELS "${T_LABELS}" TIMEOUT ${T_TIMEOUT})
  endif()
endfunction()

set_property(GLOBAL PROPERTY LMEFORM_BENCHMARKS "")
function(lmeform_add_benchmark name)
  cmake_parse_arguments(B "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${B_SOURCES})
  target_link_libraries(${name} PRIVATE ${B_LIBS} lmeform_warnings)
  set_property(GLOBAL APPEND PROPERTY LMEFORM_BENCHMARKS "$<TARGET_FILE:${name}>")
endfunction()

# Writes build/benchmarks.txt: one executable per line, read by scripts/run-benchmarks.sh.
function(lmeform_write_benchmark_list)
  get_property(benches GLOBAL PROPERTY LMEFORM_BENCHMARKS)
  list(JOIN benches "\n" content)
  file(GENERATE OUTPUT "${CMAKE_BINARY_DIR}/benchmarks.txt" CONTENT "${content}\n")
endfunction()
