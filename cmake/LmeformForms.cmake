# lmeform_add_forms(<target> FORMS a.form b.form ... [INCLUDE_DIRS dir ...] [OUTPUT_DIR dir])
#
# Runs lmeformc on each form at build time, writing <module>_kernels.hpp and <module>.json into
# ${CMAKE_CURRENT_BINARY_DIR}/lmeform_forms/<target> (or OUTPUT_DIR), adds that directory to the
# target's include path and makes the target depend on the generated headers. Each form re-runs
# when it, any file it includes (from lmeformc's --depfile) or lmeformc itself changes.
# Works for ordinary and INTERFACE targets. The module name is taken as the form's file name (write `form NAME` to match it).
function(lmeform_add_forms target)
  cmake_parse_arguments(F "" "OUTPUT_DIR" "FORMS;INCLUDE_DIRS" ${ARGN})
  if(NOT F_FORMS)
    message(FATAL_ERROR "lmeform_add_forms(${target}): no FORMS given")
  endif()
  if(NOT F_OUTPUT_DIR)
    set(F_OUTPUT_DIR "${CMAKE_CURRENT_BINARY_DIR}/lmeform_forms/${target}")
  endif()
  file(MAKE_DIRECTORY "${F_OUTPUT_DIR}")
  set(include_args "")
  foreach(dir IN LISTS F_INCLUDE_DIRS)
    get_filename_component(dir "${dir}" ABSOLUTE)
    list(APPEND include_args -I "${dir}")
  endforeach()
  set(headers "")
  foreach(form IN LISTS F_FORMS)
    get_filename_component(form_abs "${form}" ABSOLUTE)
    get_filename_component(module "${form}" NAME_WE)
    string(MAKE_C_IDENTIFIER "${module}" module)
    set(header "${F_OUTPUT_DIR}/${module}_kernels.hpp")
    set(depfile "${F_OUTPUT_DIR}/${module}.d")
    add_custom_command(
      OUTPUT "${header}" "${F_OUTPUT_DIR}/${module}.json"
      COMMAND lmeformc "${form_abs}" -o "${F_OUTPUT_DIR}" --json --depfile "${depfile}" ${include_args}
      MAIN_DEPENDENCY "${form_abs}"
      DEPENDS lmeformc
      DEPFILE "${depfile}"
      COMMENT "lmeformc ${form}"
      VERBATIM)
    list(APPEND headers "${header}")
  endforeach()
  # A custom target owns the generation so that INTERFACE libraries (header-only consumers) work
  # too: their dependents build after it (CMake >= 3.19 follows INTERFACE library dependencies).
  add_custom_target(${target}_lmeform_forms ALL DEPENDS ${headers})
  add_dependencies(${target} ${target}_lmeform_forms)
  get_target_property(type ${target} TYPE)
  if(type STREQUAL "INTERFACE_LIBRARY")
    target_include_directories(${target} INTERFACE "${F_OUTPUT_DIR}")
    target_link_libraries(${target} INTERFACE lmeform::kernel)
  else()
    target_include_directories(${target} PRIVATE "${F_OUTPUT_DIR}")
    target_link_libraries(${target} PRIVATE lmeform::kernel)
  endif()
endfunction()
