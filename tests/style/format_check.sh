#!/usr/bin/env bash
# Every C++ file follows the checked-in .clang-format: clang-format would change nothing.
# Fix with: clang-format -i $(git ls-files '*.cc' '*.h')
set -u
src=$1
cd "$src" || exit 2
command -v clang-format > /dev/null || { echo "clang-format is not installed (deploy/setup.sh installs it)"; exit 1; }
if git rev-parse --is-inside-work-tree > /dev/null 2>&1; then
  mapfile -t files < <(git ls-files '*.cc' '*.h')
else
  mapfile -t files < <(find . -path ./build -prune -o \( -name '*.cc' -o -name '*.h' \) -print)
fi
bad=()
for f in "${files[@]}"; do
  clang-format --dry-run --Werror "$f" > /dev/null 2>&1 || bad+=("$f")
done
if ((${#bad[@]})); then
  echo "${#bad[@]} of ${#files[@]} files differ from .clang-format:"
  printf '  %s\n' "${bad[@]}"
  echo "fix: clang-format -i ${bad[*]}"
  exit 1
fi
echo "format: ${#files[@]} files follow .clang-format"
