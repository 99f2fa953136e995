# Every dependency comes from a Debian 12 package (scripts/install-deps.sh) and is found
# through its CMake config package or pkg-config module; see docs/../shared TOOLCHAIN notes.

find_package(PkgConfig REQUIRED)

# Header-only / config-package dependencies.
find_package(Eigen3 3.4 REQUIRED CONFIG)
find_package(Boost 1.74 REQUIRED)                 # Spirit X3 is header-only: Boost::headers
find_package(nanoflann REQUIRED CONFIG)
find_package(Qhull REQUIRED CONFIG)                # Qhull::qhull_r (reentrant C API)
find_package(GTest REQUIRED)
find_package(benchmark CONFIG)                      # optional: Google Benchmark
find_package(tomlplusplus CONFIG)                   # scenes (TOML)
find_package(CLI11 CONFIG)                          # command lines
find_package(nlohmann_json 3 REQUIRED CONFIG)       # every JSON writer and reader
find_package(fmt REQUIRED CONFIG)                   # message formatting

# BLAS through Debian's libblas.so.3 alternative (OpenBLAS's serial flavour, install-deps): the
# cells' dense products (runtime/src/kernel/contractions.cpp) run on kernels chosen for the CPU.
set(BLA_VENDOR Generic)
find_package(BLAS REQUIRED)

# MPI: the C bindings only (MPI::MPI_CXX drags in the deprecated C++ bindings).
find_package(MPI REQUIRED COMPONENTS C)

# PETSc's pkg-config module carries no MPI/HDF5 include paths: those are linked beside it.
pkg_check_modules(PETSC REQUIRED IMPORTED_TARGET PETSc)

# HDF5: the openmpi flavour only.
set(HDF5_PREFER_PARALLEL TRUE)
find_package(HDF5 REQUIRED COMPONENTS C)
if(NOT HDF5_IS_PARALLEL)
  message(FATAL_ERROR "lmeform needs the parallel (openmpi) HDF5 from libhdf5-openmpi-dev; found a serial one at ${HDF5_INCLUDE_DIRS}")
endif()

# METIS 5.1 ships neither a CMake config nor a .pc file: find header and library by hand.
find_path(METIS_INCLUDE_DIR metis.h REQUIRED)
find_library(METIS_LIBRARY metis REQUIRED)
if(NOT TARGET lmeform::metis)
  add_library(lmeform::metis UNKNOWN IMPORTED)
  set_target_properties(lmeform::metis PROPERTIES
    IMPORTED_LOCATION "${METIS_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${METIS_INCLUDE_DIR}")
endif()

# Debian's python3 with matplotlib/h5py (a pyenv python3 on PATH may lack them).
find_program(LMEFORM_PYTHON NAMES python3 PATHS /usr/bin NO_DEFAULT_PATH)
if(NOT LMEFORM_PYTHON)
  find_program(LMEFORM_PYTHON NAMES python3)
endif()
