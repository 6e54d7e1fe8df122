#!/usr/bin/env bash
# The FEM ground truth (testdata/fem/fem_cases.py, GetFEM): on a small ellipsoid pressed by
# a probe from posterior, the largest displacement reached within 1%, volume kept to 1e-6 %,
# the posterior pole pushed anteriorly and the held side still, the same field twice (to 1e-4 mm); bad
# arguments refused with one line; bench fit --fem's exclusive options refused; a stop while
# it solves ends the solver too.
source "$(dirname "$0")/check.sh"
script="$src/testdata/fem/fem_cases.py"
$py "$src/tests/cli/fem_check.py" make "$tmp/ellipsoid.stl"

check "probe 3 mm: magnitude, volume, direction" bash -c "
  '$py' '$script' --surface '$tmp/ellipsoid.stl' --load probe --magnitudes 3 --out '$tmp/a' &&
  '$py' '$src/tests/cli/fem_check.py' check '$tmp/a' 3"
check "reproducible: the same field twice, to 1e-4 mm" bash -c "
  '$py' '$script' --surface '$tmp/ellipsoid.stl' --load probe --magnitudes 3 --out '$tmp/b' &&
  '$py' '$src/tests/cli/fem_check.py' same '$tmp/a/u_3mm.mha' '$tmp/b/u_3mm.mha' 1e-4"
refused() {  # refused EXPECTED_TEXT ARGS...: exit 2, one line naming it, nothing written
  local want="$1"; shift
  rm -rf "$tmp/bad"
  ! "$py" "$script" "$@" --out "$tmp/bad" >"$tmp/err" 2>&1 || return 1
  [[ $(wc -l <"$tmp/err") -eq 1 ]] && grep -q -- "$want" "$tmp/err" && [[ ! -e "$tmp/bad/cases.json" ]]
}
check "a missing surface is named" refused "$tmp/none.stl: no such file" \
  --surface "$tmp/none.stl" --load probe --magnitudes 2
check "bad magnitudes are refused" refused "magnitudes" \
  --surface "$tmp/ellipsoid.stl" --load probe --magnitudes two
check "a file that is not a surface is refused" refused "not an STL surface" \
  --surface "$src/README.md" --load probe --magnitudes 2
check "bench fit --fem excludes --quick" bash -c "
  ! '$bin' bench fit --fem --quick --out '$tmp/bf' 2>'$tmp/bf.err' &&
  grep -q 'excludes --quick' '$tmp/bf.err' && [[ ! -e '$tmp/bf' ]]"
# A stop while the FEM solves: the solver stops with organfit (130, one line), and the
# cache keeps nothing of the unfinished solve.
stopped_while_solving() {
  "$bin" bench fit --fem --fem-cache "$tmp/cache" --cases 1 --methods spread --defaults-only \
    --out "$tmp/stop" >/dev/null 2>"$tmp/stop.err" &
  local pid=$! code
  for _ in $(seq 600); do grep -q "solving with GetFEM" "$tmp/stop.err" && break; sleep 0.05; done
  sleep 1
  kill -TERM $pid
  wait $pid
  code=$?
  sleep 0.5
  [[ $code -eq 130 ]] && ! pgrep -f "fem_cases.py.*$tmp/cache" >/dev/null &&
    [[ -z $(ls -A "$tmp/cache") && ! -e "$tmp/stop" ]] &&
    [[ $(grep -c "organfit: error" "$tmp/stop.err") -eq 1 ]]
}
check "a stop ends the FEM solver too and leaves no partial case" stopped_while_solving
finish
