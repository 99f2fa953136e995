# cmake -DSOURCE_DIR=<project> -DOUT=<dir> -P copy_seeds.cmake: the fuzz seed corpus, every .form
# and .inc under forms/ and tests/compiler/data/, copied flat into OUT as <dir>_<subdir>_<name>.
file(REMOVE_RECURSE "${OUT}")
file(MAKE_DIRECTORY "${OUT}")
foreach(root forms tests/compiler/data)
  file(GLOB_RECURSE files RELATIVE "${SOURCE_DIR}" "${SOURCE_DIR}/${root}/*.form" "${SOURCE_DIR}/${root}/*.inc")
  foreach(f IN LISTS files)
    string(REPLACE "/" "_" flat "${f}")
    file(COPY_FILE "${SOURCE_DIR}/${f}" "${OUT}/${flat}")
  endforeach()
endforeach()
