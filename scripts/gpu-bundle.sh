#!/usr/bin/env bash
# Packs this build for a GPU machine that has no build tools or Debian packages of its own (an NVIDIA
# driver is all it needs): the CLI and the test binary, the shared libraries they load (the C and C++
# runtimes excepted: the target's are newer), the Vulkan loader, the validation layer with its
# manifest, the GL dispatch libraries an NVIDIA Vulkan driver loads (libglvnd), and the built shader
# headers StageTable.ShadersAreBuilt looks for. scripts/gpu-check.sh runs it there.
#
#   bash scripts/gpu-bundle.sh [BUILD_DIR] [OUT.tar.xz]     (defaults: build, gpu-bundle.tar.xz)
#
# libglvnd's libraries come from the Debian packages libglvnd0 libglx0 libegl1 libgl1 libopengl0
# libgles2 if they are installed here; else `apt-get download` fetches them (no root needed).
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build}"
out="${2:-gpu-bundle.tar.xz}"
for f in "$build/vksonar" "$build/tests/vksonar_tests"; do
  [ -x "$f" ] || { echo "gpu-bundle: $f: not built (cmake --build $build)" >&2; exit 1; }
done
layer_so=/usr/lib/x86_64-linux-gnu/libVkLayer_khronos_validation.so
layer_json=/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json
[ -f "$layer_so" ] || { echo "gpu-bundle: $layer_so: missing (apt-get install vulkan-validationlayers)" >&2; exit 1; }
stage="$(mktemp -d)"
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/bin" "$stage/lib" "$stage/layer" "$stage/shaders"
cp "$build/vksonar" "$build/tests/vksonar_tests" "$stage/bin/"
pwd >"$stage/source_dir" # the test binary finds assets/ and tests/data/ by this absolute path
cp "$build"/shaders/*.spv.h "$stage/shaders/"
for f in "$build/vksonar" "$build/tests/vksonar_tests" "$layer_so"; do
  ldd "$f" | awk '/=>/ {print $3}'
done | sort -u | grep -v -E '/(libc|libm|libstdc\+\+|libgcc_s|ld-linux[^/]*|libpthread|libdl|librt)\.so' |
  while read -r lib; do cp -L "$lib" "$stage/lib/"; done
cp "$layer_so" "$stage/lib/"
sed 's#"library_path": *"[^"]*"#"library_path": "../lib/libVkLayer_khronos_validation.so"#' "$layer_json" \
  >"$stage/layer/VkLayer_khronos_validation.json"
glvnd="libGLdispatch.so.0 libGLX.so.0 libEGL.so.1 libGL.so.1 libOpenGL.so.0 libGLESv2.so.2"
missing=""
for lib in $glvnd; do
  if [ -e "/usr/lib/x86_64-linux-gnu/$lib" ]; then cp -L "/usr/lib/x86_64-linux-gnu/$lib" "$stage/lib/"; else missing=1; fi
done
if [ -n "$missing" ]; then
  debs="$(mktemp -d)"
  (cd "$debs" && apt-get download libglvnd0 libglx0 libegl1 libgl1 libopengl0 libgles2 >/dev/null)
  for deb in "$debs"/*.deb; do dpkg -x "$deb" "$debs/x"; done
  cp -a "$debs"/x/usr/lib/x86_64-linux-gnu/lib*.so* "$stage/lib/"
  rm -rf "$debs"
fi
tar -C "$stage" -cJf "$out" .
echo "gpu-bundle: wrote $out ($(du -h "$out" | cut -f1)); on the GPU machine, from a checkout of this commit: bash scripts/gpu-check.sh $out"
