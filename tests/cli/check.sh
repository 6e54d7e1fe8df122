# Sourced by the whole-program test scripts, with the source folder as $1: sets src, bin
# (the binary, from $ORGANFIT), py (the Python with pydicom) and tmp (a scratch folder
# removed on exit; a script that traps EXIT itself removes it there). `check NAME
# COMMAND...` runs COMMAND with its output in $tmp/check.log and prints "ok   NAME", or
# "FAIL NAME:" with the log's last lines; `finish` prints "N passed, N failed" and fails
# on any failure.
set -u
src="$1"
bin="${ORGANFIT:?set ORGANFIT to the organfit binary}"
py=/usr/bin/python3
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0
check() {
  local name="$1"
  shift
  if "$@" >"$tmp/check.log" 2>&1; then
    echo "ok   $name"; passed=$((passed + 1))
  else
    echo "FAIL $name: $(tail -c 800 "$tmp/check.log")"; failed=$((failed + 1))
  fi
}
finish() {
  echo "$passed passed, $failed failed"
  [[ $failed -eq 0 ]]
}
