#!/usr/bin/env bash
# One entry point that works on a fresh Debian machine (as root, or with sudo):
#   bash run.sh demo [emu demo options]   install what is missing, then run the demo
#   bash run.sh test                      install what is missing, then C++ tests (ctest) and pytest
#   bash run.sh setup                     only install
#   bash run.sh docs                      the documentation site (MkDocs) into site/; --strict: a broken
#                                         link or reference fails it
#   bash run.sh sanitize                  the C++ core, its tests and a subset of the Python tests
#                                         under ASan + UBSan (CMakePresets.json)
set -euo pipefail
cd "$(dirname "$0")"

APT_PACKAGES="build-essential cmake libeigen3-dev libsuitesparse-dev libspectra-dev libopenblas-dev"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PY="${PYTHON:-python3}"

setup() {
  local missing=""
  for p in $APT_PACKAGES; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
  if [ -n "$missing" ]; then
    echo "[emu] installing Debian packages:$missing"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
  fi
  # CHOLMOD runs on the system BLAS: select OpenBLAS (the reference BLAS is several times slower).
  for lib in libblas.so.3 liblapack.so.3; do
    local alt="${lib}-$(uname -m)-linux-gnu"
    local target="/usr/lib/$(uname -m)-linux-gnu/openblas-pthread/${lib}"
    if [ -e "$target" ] && update-alternatives --query "$alt" >/dev/null 2>&1; then
      $SUDO update-alternatives --set "$alt" "$target" >/dev/null
    fi
  done
  "$PY" -m pip install -q --disable-pip-version-check "scikit-build-core>=0.8" "pybind11>=2.11" numpy "meshio>=5.3" \
    "matplotlib>=3.5" "pooch>=1.6" pytest scipy "hypothesis>=6" "ipctk>=1.6" "dask[distributed]>=2023.1" \
    "pytetwild>=0.2.3,<0.3" "usd-core>=23.11" 2>&1 | grep -v -i "warning" || true
  echo "[emu] building and installing the emu package"
  "$PY" -m pip install -q --disable-pip-version-check --no-build-isolation -e . 2>&1 | grep -v -i "warning" || true
  "$PY" -c "import emu" || { echo "[emu] the package did not install"; exit 1; }
}

cpp_tests() {
  # the C++ microbenchmarks (bench/micro) build and run once too: Google Benchmark
  dpkg -s libbenchmark-dev >/dev/null 2>&1 || {
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libbenchmark-dev >/dev/null
  }
  cmake -S . -B build/ctest -DEMU_BUILD_TESTS=ON -DEMU_BUILD_MICROBENCH=ON -DCMAKE_BUILD_TYPE=Release >/dev/null
  echo "[emu] setup done at ${SECONDS} s"
  cmake --build build/ctest -j "$(nproc)" >/dev/null
  echo "[emu] C++ tests built at ${SECONDS} s"
  (cd build/ctest && ctest --output-on-failure)
}

# the Python tests run under the sanitizers by `bash run.sh sanitize` (the solvers, bones,
# operators, lagged factor, contact, fuzzing and the stress suite: about 5 minutes)
SANITIZED_TESTS="tests/test_energy.py tests/test_solvers.py tests/test_bones.py tests/test_emu_operators.py
  tests/test_lagged_factor.py tests/test_contact.py tests/test_fuzz.py tests/stress"
# the constant Schur preconditioner's numpy check in two of its eight settings (each flag both
# ways): the same C++ paths, and the dense numpy reference is most of its time under ASan
for p in 0.0-300.0-0.12 0.2-300.0-0.0 0.0-30.0-0.12 0.2-30.0-0.0 0.0-300.0-0.0 0.2-30.0-0.12; do
  SANITIZED_TESTS="$SANITIZED_TESTS --deselect tests/test_emu_operators.py::test_constant_schur_preconditioner_against_numpy[$p]"
done

sanitize() {
  # the C++ core, its tests and the extension under AddressSanitizer +
  # UndefinedBehaviorSanitizer (CMakePresets.json "sanitize"; any report fails):
  # the C++ tests with leak detection, then a subset of the Python tests on the
  # sanitized extension (runtimes preloaded; no leak detection: CPython keeps
  # its interned objects to the end by design)
  local python runtimes
  python="$("$PY" -c 'import sys; print(sys.executable)')"   # the interpreter itself, not a shim script
  cmake --preset sanitize -Dpybind11_DIR="$("$PY" -m pybind11 --cmakedir)" -DPython_EXECUTABLE="$python" >/dev/null
  cmake --build --preset sanitize -j "$(nproc)" >/dev/null
  echo "[emu] sanitize build done at ${SECONDS} s"
  ctest --preset sanitize
  echo "[emu] sanitized C++ tests done at ${SECONDS} s"
  runtimes="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)"
  # shellcheck disable=SC2086
  LD_PRELOAD="$runtimes" ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:strict_string_checks=1 \
    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    "$python" tests/sanitized.py build/sanitize -q $SANITIZED_TESTS "$@"
}

cmd="${1:-demo}"
shift || true
case "$cmd" in
  setup) setup ;;
  sanitize) setup; sanitize "$@" ;;
  demo) setup; emu demo "$@" ;;
  test) setup; cpp_tests; "$PY" -m pytest -q tests "$@" ;;
  docs)
    "$PY" -m pip install -q --disable-pip-version-check "mkdocs>=1.6" \
      "mkdocstrings[python]>=0.26" 2>&1 | grep -v -i "warning" || true
    "$PY" -m mkdocs build --strict "$@" ;;
  *) echo "usage: bash run.sh [setup|demo|test|sanitize|docs] [options]"; exit 2 ;;
esac
