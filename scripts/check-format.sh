#!/usr/bin/env bash
# House style (.clang-format): every tracked C/C++ source and header, the GLSL/C++ shared headers
# included, is exactly as clang-format writes it with the repo's .clang-format. Lists the files that
# are not and exits 1 (fix: clang-format -i FILE). Run by ctest as `clang_format`.
# Other clang-format versions lay some constructs out differently, so the check runs only with
# Debian 12's clang-format 14 (scripts/install-deps.sh installs it) and skips (77) otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format >/dev/null 2>&1; then
  echo "check-format: skipped, clang-format is not installed (scripts/install-deps.sh installs it)" >&2
  exit 77
fi
major=$(clang-format --version | sed -n 's/.*version \([0-9]*\).*/\1/p' | head -1)
if [ "$major" != "14" ]; then
  echo "check-format: skipped, clang-format $major is not Debian 12's 14" >&2
  exit 77
fi
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files '*.cpp' '*.h' '*.hpp')
else
  mapfile -t files < <(find include src shaders tests examples fuzz -type f \( -name '*.cpp' -o -name '*.h' -o -name '*.hpp' \))
fi
bad=()
for f in "${files[@]}"; do
  clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "check-format: ${#bad[@]} of ${#files[@]} files differ from clang-format's layout (clang-format -i FILE):" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "check-format: ${#files[@]} files as clang-format writes them"
