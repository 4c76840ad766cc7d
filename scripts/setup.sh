#!/usr/bin/env bash
# Idempotent set-up on Debian 12: installs the FEniCSx 0.5 stack with apt when missing and
# creates .venv from Debian's /usr/bin/python3 (with system site-packages, so dolfinx,
# petsc4py and numpy 1.24 are Debian's) with the package installed editable.
# Used by `make setup`, docker/Dockerfile and CI.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
    python3-dolfinx-real python3-petsc4py-real python3-slepc4py-real python3-gmsh
    python3-venv python3-pip python3-numpy python3-scipy python3-matplotlib python3-h5py
    python3-tqdm python3-threadpoolctl python3-numba python3-pytest python3-pytest-xdist python3-hypothesis python3-distributed python3-meshio python3-netcdf4 openmpi-bin
    libopenblas0-pthread xvfb xauth libgl1-mesa-dri libxrender1 python3-sphinx python3-myst-parser
)

missing=()
for package in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed" \
        || missing+=("$package")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -q
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv from /usr/bin/python3 --system-site-packages"
    /usr/bin/python3 -m venv --system-site-packages .venv
fi

stamp=.venv/.aquarom-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "setup: installing aquarom-fenics (editable) and its pip dependencies"
    .venv/bin/python -m pip install -q --no-build-isolation -e ".[test]"
    .venv/bin/python - <<'PY'
import numpy, dolfinx, petsc4py
assert numpy.__version__.startswith("1."), f"numpy {numpy.__version__}: dolfinx needs Debian's numpy 1.x"
print(f"setup: dolfinx {dolfinx.__version__}, numpy {numpy.__version__}, petsc4py {petsc4py.__version__}")
PY
    touch "$stamp"
fi

# The compiled reduced kernel (numba): compiled once into numba's cache beside its module (about half a
# minute), loaded from there afterwards (a second or two).
.venv/bin/python -m aquarom_fenics.dynamics.reduced_kernel
# The internal force's pair products (numba), the same way: a few seconds to compile.
.venv/bin/python -m aquarom_fenics.fem.pair_kernel
