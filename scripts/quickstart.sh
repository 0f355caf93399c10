#!/usr/bin/env bash
# The README's two commands:
#   bash scripts/quickstart.sh render [OUT_DIR]   install deps, build, render the default scene to OUT_DIR (default: out)
#   bash scripts/quickstart.sh test               install deps, build, run every test (ctest)
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-render}"
bash scripts/install-deps.sh
BUILD_DIR="${BUILD_DIR:-build}"
WERROR=OFF
[ "${CI:-}" = "true" ] && WERROR=ON
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release -DVKSONAR_WERROR="$WERROR" >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)"
case "$mode" in
  render)
    out="${2:-out}"
    "$BUILD_DIR/vksonar" render --out "$out"
    echo "wrote $out/fan.png, $out/polar.png, $out/polar.npy, $out/polar_u16.npy, $out/meta.json"
    ;;
  test)
    ctest --test-dir "$BUILD_DIR" --output-on-failure -j"$(nproc)"
    ;;
  *)
    echo "usage: $0 render [OUT_DIR] | test" >&2
    exit 2
    ;;
esac
