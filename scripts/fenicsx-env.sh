# Sourced by the FEniCSx comparisons (demos/*/compare.sh): the Debian python that python3-dolfinx
# is installed for, one thread per process, Open MPI as root, and the packages installed when
# missing (python3-dolfinx, python3-matplotlib, python3-h5py).
#   source "$(dirname "$0")/../../scripts/fenicsx-env.sh"
py=/usr/bin/python3   # not a pyenv python: the Debian package installs dolfinx for this one
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}

if ! "$py" -c 'import dolfinx, dolfinx.fem.petsc, matplotlib, h5py' >/dev/null 2>&1; then
  echo "== installing python3-dolfinx python3-matplotlib python3-h5py"
  sudo=()
  [ "$(id -u)" -ne 0 ] && sudo=(sudo)
  export DEBIAN_FRONTEND=noninteractive
  if ! "${sudo[@]}" apt-get install -y --no-install-recommends python3-dolfinx python3-matplotlib python3-h5py; then
    "${sudo[@]}" apt-get update
    "${sudo[@]}" apt-get install -y --no-install-recommends python3-dolfinx python3-matplotlib python3-h5py
  fi
fi
