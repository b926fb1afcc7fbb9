#!/usr/bin/env bash
# Installs gimlod's build and runtime dependencies from Debian packages, only when one is missing.
# Safe to run repeatedly; needs root (or sudo) the first time.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config ccache
  libopenmesh-dev libcgal-dev libeigen3-dev libopenimageio-dev
  libgdal-dev gdal-bin
  libglfw3-dev libglm-dev libepoxy-dev libegl-dev libegl-mesa0 libgl1-mesa-dri libgl-dev
  libimgui-dev xvfb xdotool
  libtbb-dev libcli11-dev libspdlog-dev libfmt-dev nlohmann-json3-dev libzstd-dev zstd libxxhash-dev
  libsleef-dev
  openmpi-bin libopenmpi-dev slurm-wlm munge
  libgtest-dev clang libclang-rt-dev clang-format clang-tidy libpng-dev
  python3-matplotlib libmeshoptimizer-dev
  chromium
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "gimlod: installing missing packages: ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
