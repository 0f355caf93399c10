#!/usr/bin/env bash
# ctest mcap_ros2: installs the readers of package.json (exact versions, package-lock.json) with npm
# into BUILD_DIR/mcap_check, then runs check_mcap.js against the CLI.
#     run_check.sh path/to/vksonar BUILD_DIR
# Without node and npm (Debian: nodejs, npm) or without a network for the first install, the test
# reports itself skipped (exit 77) and says why; VKSONAR_REQUIRE_MCAP_CHECK=1 turns that into a failure.
set -uo pipefail
cli=$1
work=$2/mcap_check
here=$(cd "$(dirname "$0")" && pwd)

skip() {
  if [ "${VKSONAR_REQUIRE_MCAP_CHECK:-0}" = "1" ]; then
    echo "mcap_ros2: FAILED: $1 (VKSONAR_REQUIRE_MCAP_CHECK=1)"
    exit 1
  fi
  echo "mcap_ros2: skipped: $1"
  exit 77
}

command -v node >/dev/null 2>&1 || skip "node is not installed (apt-get install nodejs npm)"
command -v npm >/dev/null 2>&1 || skip "npm is not installed (apt-get install npm)"
mkdir -p "$work" || exit 1
# Install again only when the lockfile changed.
if ! cmp -s "$here/package-lock.json" "$work/package-lock.json" || [ ! -d "$work/node_modules/@mcap/core" ]; then
  cp "$here/package.json" "$here/package-lock.json" "$work/" || exit 1
  if ! (cd "$work" && npm ci --no-audit --no-fund --loglevel=error >npm.log 2>&1); then
    rm -f "$work/package-lock.json" # try again next time
    skip "npm ci could not install the readers (no network?): $(tail -n 3 "$work/npm.log" | tr '\n' ' ')"
  fi
fi
rm -rf "$work/run"
NODE_PATH="$work/node_modules" node "$here/check_mcap.js" "$cli" "$work/run"
