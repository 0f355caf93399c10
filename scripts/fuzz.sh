#!/usr/bin/env bash
# Bounded libFuzzer runs of the glTF loader and the config parser (fuzz/*.cpp), built with clang,
# ASan and UBSan, each seeded from the regression corpus.
#   bash scripts/fuzz.sh                     # CI: a fixed number of inputs from a fixed seed (below)
#   FUZZ_SECONDS=3600 bash scripts/fuzz.sh   # exploring: a timed run from a random seed whose corpus
#                                            # grows across runs (see docs/hard_cases.md)
# The CI run tries the same inputs every time (same seed, input count, empty starting corpus and the
# settings in run_target; checked here and from a fresh clone elsewhere, though a machine with another
# environment may still differ slightly), so a CI result can be replayed here and a new finding comes
# from a change to the code rather than from the luck of a timed run. Findings come from exploring.
# Installs clang and its libFuzzer runtime with apt-get when missing; if that is impossible it prints
# why and exits 0 (the fuzz job is skipped, not failed). A crash or sanitizer report exits non-zero
# and leaves the reproducer in $BUILD_DIR/crashes/: add it to tests/data/bad_gltf (or
# fuzz/corpus/config) as a regression test.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${BUILD_DIR:-build-fuzz}"
SECONDS_PER_TARGET="${FUZZ_SECONDS:-}"
FUZZ_SEED="${FUZZ_SEED:-1}"
# About 40 s each on a 2-core CI machine (fuzz_gltf ~1.5k inputs/s, fuzz_config ~200/s: every
# config is parsed, validated and round-tripped).
declare -A CI_RUNS=([fuzz_gltf]=60000 [fuzz_config]=8000)

skip() {
  echo "fuzz: skipped: $*" >&2
  exit 0
}

have_libfuzzer() {
  command -v clang++ >/dev/null 2>&1 || return 1
  local dir
  dir=$(mktemp -d)
  printf '#include <cstdint>\n#include <cstddef>\nextern "C" int LLVMFuzzerTestOneInput(const uint8_t*, size_t) { return 0; }\n' >"$dir/t.cpp"
  clang++ -fsanitize=fuzzer,address,undefined "$dir/t.cpp" -o "$dir/t" >/dev/null 2>&1
  local ok=$?
  rm -rf "$dir"
  return $ok
}

bash scripts/install-deps.sh
if ! have_libfuzzer; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  if command -v apt-get >/dev/null 2>&1; then
    echo "fuzz: installing clang and its libFuzzer runtime" >&2
    $SUDO apt-get update -qq || true
    # Debian 12: clang is clang-14; libFuzzer lives in libclang-rt-14-dev (only recommended by clang).
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends clang >/dev/null || true
    version=$(clang++ --version 2>/dev/null | sed -n 's/.*clang version \([0-9]*\).*/\1/p' | head -1)
    [ -n "$version" ] && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      "libclang-rt-$version-dev" >/dev/null 2>&1 || true
  fi
  have_libfuzzer || skip "clang with libFuzzer (-fsanitize=fuzzer) is not available and could not be installed"
fi

start=$(date +%s)
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g" \
  -DCMAKE_CXX_COMPILER=clang++ -DVKSONAR_FUZZ=ON -DVKSONAR_SANITIZE=ON -DVKSONAR_BUILD_TESTS=OFF \
  -DVKSONAR_BUILD_BENCH=OFF >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)" --target fuzz_gltf fuzz_config
echo "fuzz: build took $(($(date +%s) - start)) s" >&2

export ASAN_OPTIONS="halt_on_error=1:abort_on_error=1:detect_leaks=1"
# fuzz_gltf writes each input to a file under $TMPDIR: keep those inside the build tree, under a
# relative path so that the file's path (which every error message quotes) is the same everywhere.
export TMPDIR="$BUILD_DIR/tmp"
mkdir -p "$TMPDIR"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
mkdir -p "$BUILD_DIR/crashes"
status=0
run_target() { # target, seed dirs...
  local target=$1
  shift
  local work budget launcher=()
  if [ -n "$SECONDS_PER_TARGET" ]; then
    work="$BUILD_DIR/corpus/$target" # grows across runs; the seeds are never written to
    budget=(-max_total_time="$SECONDS_PER_TARGET")
    echo "fuzz: $target for ${SECONDS_PER_TARGET} s" >&2
  else
    work="$BUILD_DIR/corpus-ci/$target" # starts empty every time, so the run is the same everywhere
    rm -rf "$work"
    # -reload=0: no rereading of the corpus directory once a second (a timing-dependent change of
    # the corpus); -use_cmp=0: no mutations from traced comparison operands, which include pointer
    # values that differ from run to run under ASLR.
    budget=(-runs="${CI_RUNS[$target]}" -seed="$FUZZ_SEED" -reload=0 -use_cmp=0)
    # Address randomization off where allowed: some inlined library code takes address-dependent
    # branches, which changes coverage and so the inputs that follow. With all three, two runs here
    # end with the same coverage, features and corpus (docs/hard_cases.md).
    if setarch "$(uname -m)" -R true 2>/dev/null; then launcher=(setarch "$(uname -m)" -R); fi
    echo "fuzz: $target, ${CI_RUNS[$target]} inputs from seed $FUZZ_SEED" >&2
  fi
  mkdir -p "$work"
  # -rss_limit_mb / -malloc_limit_mb / -timeout: a hang, a large resident set or any single allocation
  # past 256 MB is a finding too. Inputs are at most 64 kB and every size a file declares (a buffer's
  # byteLength, a GLB chunk, an accessor's count) is checked against the bytes present before anything
  # of that size is allocated, so no input should ask for more than a few MB.
  local start_target
  start_target=$(date +%s)
  if ! "${launcher[@]}" "$BUILD_DIR/fuzz/$target" "$work" "$@" "${budget[@]}" -timeout=10 \
      -rss_limit_mb=2048 -malloc_limit_mb=256 -max_len=65536 -print_final_stats=1 -artifact_prefix="$BUILD_DIR/crashes/$target-" \
      2>"$BUILD_DIR/$target.log"; then
    tail -50 "$BUILD_DIR/$target.log" >&2
    echo "fuzz: $target FAILED; reproducer(s) in $BUILD_DIR/crashes/" >&2
    status=1
  else
    grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb|^#[0-9]+.*DONE" "$BUILD_DIR/$target.log" >&2 || true
    echo "fuzz: $target took $(($(date +%s) - start_target)) s" >&2
  fi
}
run_target fuzz_gltf tests/data/bad_gltf tests/data/scenes
run_target fuzz_config fuzz/corpus/config assets/presets
exit $status
