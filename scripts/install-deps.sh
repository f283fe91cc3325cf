#!/usr/bin/env bash
# Installs the Debian 12 packages facedyn builds and tests with (ARCHITECTURE.md,
# "Dependencies"). Idempotent: when everything is installed it only asks dpkg and exits.
# Works as root or through sudo. Nothing is downloaded except Debian packages.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake pkg-config git
  # libraries
  libeigen3-dev            # dense linear algebra, geometry
  libopenmesh-dev          # mesh I/O (OBJ/PLY), half-edge operations
  libopencv-dev libopencv-contrib-dev  # images, calibration, aruco/ChArUco
  libceres-dev             # bundle adjustment, dense fits
  libsuitesparse-dev       # CHOLMOD sparse factorisations
  libmodbus-dev            # Modbus RTU/TCP to motor drives
  libusb-1.0-0-dev         # USB platform/sync controller
  libaravis-dev            # GenICam machine-vision cameras
  libtorch-dev             # removal and synthesis networks
  libcli11-dev             # command line
  libyaml-cpp-dev          # YAML configs
  nlohmann-json3-dev       # JSON output
  libspdlog-dev libfmt-dev # logging and formatting
  libtinygltf-dev          # glTF 2.0 export (export/gltf_export)
  libssl-dev               # SHA-256 of a job's inputs (process/content_hash)
  libjs-three              # three.js, inlined into `facedyn view` pages (report/take_viewer)
  libgtest-dev libgmock-dev libbenchmark-dev  # tests and benchmarks
  # test-only peers: an independent Modbus implementation, pty pairs for RTU, USB replay
  python3-pymodbus python3-serial python3-serial-asyncio socat umockdev
  # Aravis's fake GigE Vision camera (arv-fake-gv-camera-0.8; aravis-tools-cli has only arv-tool)
  aravis-tools
  # GStreamer's videotestsrc/appsink, for the OpenCV backend's GStreamer-pipeline test
  gstreamer1.0-plugins-base
  # the demo report is checked by a screenshot in headless Chromium (tests/app/report_test)
  chromium
  # Blender reads back the exported OBJ, PC2, MDD and glTF (tests/export/blender_test)
  blender python3-numpy  # numpy: Blender's glTF importer needs it
  # the Slurm test peer (issue 25): a private munged + slurmctld + slurmd on localhost
  # (tests/support/slurm_cluster.h)
  slurm-wlm munge
  # `make fuzz`: clang with libFuzzer and the sanitizer runtimes (fuzz/)
  clang libclang-rt-14-dev
)

missing=()
# One dpkg-query for all packages keeps the nothing-to-do case fast.
installed=$(dpkg-query -W -f='${Package} ${db:Status-Status}\n' "${packages[@]}" 2>/dev/null || true)
for p in "${packages[@]}"; do
  if ! grep -qx "$p installed" <<<"$installed"; then missing+=("$p"); fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  sudo=()
elif command -v sudo >/dev/null 2>&1; then
  sudo=(sudo)
else
  echo "install-deps: missing packages (${missing[*]}) and not root; install them or run with sudo" >&2
  exit 1
fi

echo "install-deps: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
