#!/usr/bin/env bash
# Every tracked C++ source is formatted as .clang-format says (clang-format 14, Debian
# 12's). Prints the files that are not, and exits non-zero; skips without clang-format.
set -u
root="${1:?usage: check_format.sh REPO_ROOT}"
cd "$root" || exit 2
if ! command -v clang-format > /dev/null 2>&1; then
  echo "skip: clang-format not installed"
  exit 0
fi
files=$(git ls-files '*.cpp' '*.h' 2> /dev/null || find apps modules tests testdata -name '*.cpp' -o -name '*.h')
bad=0
for f in $files; do
  if ! clang-format --dry-run --Werror "$f" > /dev/null 2>&1; then
    echo "not formatted: $f (clang-format -i $f)"
    bad=$((bad + 1))
  fi
done
echo "$bad file(s) not formatted"
[[ $bad -eq 0 ]]
