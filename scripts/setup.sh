#!/usr/bin/env bash
# organfit setup: install the Debian 12 packages the project needs (skipping those
# present), configure and build in Release, then (unless --no-run) run the default scene.
#
#   scripts/setup.sh            install, build, run pipelines/default.yaml into out/default
#   scripts/setup.sh --no-run   install and build only (what CI and the test command use)
#
# Environment: BUILD_DIR (default build), JOBS (default: all cores).
set -euo pipefail
cd "$(dirname "$0")/.."

run_default=1
[[ "${1:-}" == "--no-run" ]] && run_default=0

# Build and run-time dependencies (libraries), then tools the tests use.
packages=(
  build-essential cmake ninja-build ccache pkg-config
  libeigen3-dev libyaml-cpp-dev libcli11-dev libspdlog-dev libfmt-dev nlohmann-json3-dev zlib1g-dev
  libgtest-dev libbenchmark-dev libomp-dev libnanoflann-dev
  libinsighttoolkit5-dev libgdcm-dev libgdcm-tools libvtk9-dev libdcmtk-dev
)
# orthanc: a real DICOM node for the network tests (run in a network namespace of their
# own: iproute2 brings its loopback up); dcmtk: storescu loads it independently of us.
# python3-getfem, tetgen, python3-scipy: the FEM ground truth (testdata/fem/fem_cases.py),
# with OpenBLAS under its MUMPS solver (3x faster than the reference BLAS). time: GNU
# time's peak memory of a run (the fuzz regressions' bound). strace: how many times a
# command starts (the huge-page request restarts the heavy ones).
test_tools=(lammps python3 plastimatch dicom3tools python3-pydicom chromium clang-format
  orthanc dcmtk iproute2 curl python3-getfem python3-scipy tetgen libopenblas0-pthread time
  strace)

missing=()
for p in "${packages[@]}" "${test_tools[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  SUDO=""
  [[ $(id -u) -ne 0 ]] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

build_dir="${BUILD_DIR:-build}"
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
if [[ ! -f "$build_dir/CMakeCache.txt" ]]; then
  cmake -S . -B "$build_dir" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build "$build_dir" --parallel "${JOBS:-$(nproc)}"
echo "setup: built $build_dir/bin/organfit"

if ((run_default)); then
  "$build_dir/bin/organfit" run pipelines/default.yaml --out out/default
  echo "setup: outputs in out/default: run.json, prostate_fit_rtstruct.dcm, prostate_fit.stl, phantom/ (the CT)"
fi
