#!/usr/bin/env bash
# Installs vksonar's build and test dependencies from Debian 12 packages, only those missing.
set -euo pipefail
PACKAGES=(cmake ninja-build g++ pkg-config libvulkan-dev mesa-vulkan-drivers vulkan-validationlayers glslang-tools
          libglm-dev libtinygltf-dev libstb-dev nlohmann-json3-dev libgtest-dev libbenchmark-dev clang-format
          libhdf5-dev python3-numpy python3-h5py pybind11-dev python3-dev python3-pytest
          gltfpack libmeshoptimizer-dev libdraco-dev libzstd-dev zlib1g-dev nodejs npm)
missing=()
for p in "${PACKAGES[@]}"; do
  # node and npm from elsewhere (e.g. a nodejs package that bundles npm and conflicts with Debian's) will do.
  [ "$p" = nodejs ] && command -v node >/dev/null 2>&1 && continue
  [ "$p" = npm ] && command -v npm >/dev/null 2>&1 && continue
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "installing: ${missing[*]}" >&2
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
