#!/usr/bin/env bash
# The GPU checks in one run, for a machine with an NVIDIA GPU and driver but nothing else (run as root
# from a checkout of the commit the bundle was built from; it links the checkout to the source path the
# bundle was built in, where the test binary looks for the assets): `vksonar bench speed` on the bundled scenes, the CPU-device
# work layout against the GPU one in the same run, the planar geometry and a 2M-triangle terrain;
# `bench effects`; then the whole test binary with the validation layer, in as many shards as cores,
# stopped after TEST_SECONDS (default 240) so a hung device cannot eat the machine's lease.
#
#   bash scripts/gpu-check.sh BUNDLE.tar.xz [OUT_DIR]     (scripts/gpu-bundle.sh makes the bundle)
#
# OUT_DIR (default gpu-check-out) gets speed.txt, effects.txt and tests.log; the summary goes to stdout.
set -uo pipefail
cd "$(dirname "$0")/.."
bundle="${1:?usage: gpu-check.sh BUNDLE.tar.xz [OUT_DIR]}"
out="${2:-gpu-check-out}"
mkdir -p "$out"
root="$PWD"
unpacked="$(mktemp -d)"
tar -C "$unpacked" -xJf "$bundle" || exit 1
export LD_LIBRARY_PATH="$unpacked/lib" VK_LAYER_PATH="$unpacked/layer"
for icd in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json \
  /etc/vulkan/icd.d/nvidia_icd.json; do
  [ -f "$icd" ] && export VK_DRIVER_FILES="$icd" && break
done
nvidia-smi -L 2>/dev/null
echo "cores: $(nproc); $(uptime)"
source_dir="$(cat "$unpacked/source_dir")"
if [ "$source_dir" != "$root" ] && [ ! -e "$source_dir" ]; then
  mkdir -p "$(dirname "$source_dir")" && ln -s "$root" "$source_dir"
fi
mkdir -p build/tests build/shaders
cp "$unpacked/bin/vksonar" build/
cp "$unpacked/bin/vksonar_tests" build/tests/
cp "$unpacked"/shaders/* build/shaders/
cli="$root/build/vksonar"
"$cli" info 2>&1 | head -3

speed() {
  local name="$1"
  shift
  echo "== $name"
  echo "== $name" >>"$out/speed.txt"
  timeout 120 "$cli" bench speed --backend vulkan "$@" 2>&1 | tee -a "$out/speed.txt" |
    grep -E '^\| (depth|normals|echo|beamform|noise|\(full|\*\*full)|frames/s'
}
speed default --frames 500
VKSONAR_LAYOUT=cpu_device speed default_cpu_device_layout --frames 300
speed default_no_vertical_sidelobes --frames 300 --set effects.vertical_sidelobes=off
speed harbour --frames 300 --scene assets/scenes/harbour.gltf
speed planar --frames 300 --set beam_geometry=planar
if python3 tools/gen_terrain.py 1000 120 /tmp/gpu_check_terrain.glb >/dev/null; then
  speed terrain_2m --frames 100 --scene /tmp/gpu_check_terrain.glb --pose 0,0,3,0,10,0
fi
echo "== effects"
timeout 120 "$cli" bench effects --backend vulkan --frames 60 2>&1 | tee "$out/effects.txt" | grep '^| '

echo "== tests ($(nproc) shards, validation on, at most ${TEST_SECONDS:-240} s)"
shards="$(nproc)"
export VKSONAR_VALIDATION=1 VKSONAR_REQUIRE_VULKAN=1 GTEST_TOTAL_SHARDS="$shards"
for ((i = 0; i < shards; ++i)); do
  GTEST_SHARD_INDEX=$i timeout -k 5 "${TEST_SECONDS:-240}" build/tests/vksonar_tests >"$out/shard_$i.log" 2>&1 &
done
wait
cat "$out"/shard_*.log >"$out/tests.log"
rm -f "$out"/shard_*.log
grep -h -E '^\[(normals\]   worst|chebyshev|depth\]|labels\] gpu)' "$out/tests.log" | head -20
passed=$(grep -c '^\[       OK \]' "$out/tests.log")
failed=$(grep -E '^\[  FAILED  \] .*\([0-9]+ ms\)$' "$out/tests.log" | sort -u)
lost=$(grep -c 'VK_ERROR_DEVICE_LOST' "$out/tests.log")
finished=$(grep -c '^\[==========\] .* ran\.' "$out/tests.log")
echo "tests: $passed passed, $(printf '%s' "$failed" | grep -c .) failed, device lost $lost times;" \
  "$finished of $shards shards finished within ${TEST_SECONDS:-240} s"
[ -n "$failed" ] && printf '%s\n' "$failed" | cut -c1-160
rm -rf "$unpacked"
