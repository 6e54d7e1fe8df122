#!/bin/bash
# What each particle count gives (issue 26, item 4): organs planned with `model.particles:
# N` for N in COUNTS and fitted to 87 points (0.5 mm noise) under the scale bench's known
# change (a stretch of 1.1 and a 2 mm bend), the truth measured. One line per organ and
# count: particles, radius, planning and update time (s; update = load, points and fit),
# MSD and HD95 against the truth (mm), the organ as it was, the volume change, peak memory.
# Two sets, kept apart so the default count is chosen on one and reported on the other:
#   tune:   both kidneys, a vertebra and the liver grown on ct-crlm-1004, an ellipsoid of
#           5 cm3 and one of 3 L (the ends of the range the default must cover)
#   report: the egg of 4.4 cm3, the pelvis phantom's prostate, the GTVs of ct-sts-002 and
#           ct-sts-004, the phantom lung of 2.23 L (docs/benchmarks.md's table)
#   scripts/particle_count_sweep.sh tune|report [ORGANFIT] [WORKDIR] [COUNTS...]
set -u
set_name="${1:?usage: particle_count_sweep.sh tune|report [ORGANFIT] [WORKDIR] [COUNTS...]}"
bin="${2:-$(dirname "$0")/../build/bin/organfit}"
work="${3:-$(mktemp -d)}"
shift $(($# < 3 ? $# : 3))
if (($#)); then counts=("$@"); else counts=(1000 3000 10000 30000); fi
data="$(cd "$(dirname "$0")/../.." && pwd)/shared/data"
[[ -d "$data/ct-crlm-1004" ]] || { echo "particle_count_sweep: $data is absent" >&2; exit 2; }
mkdir -p "$work"
source "$(dirname "$0")/real_organs.sh"
declare -A organ  # NAME -> the scene's sections that make the organ
body() {  # NAME SHAPE SIZE_MM
  organ[$1]=$(printf 'body:\n  shape: %s\n  size_mm: [%s]\n' "$2" "$3")
}
case "$set_name" in
  tune)
    for name in kidney_left kidney_right vertebra liver; do
      organ[$name]=$(real_organ_sections "$name" "$data")
    done
    body ellipsoid_5cm3 ellipsoid "25, 20, 19"
    body ellipsoid_3L ellipsoid "210, 170, 160"
    names=(ellipsoid_5cm3 kidney_left kidney_right vertebra liver ellipsoid_3L)
    ;;
  report)
    body egg egg "24, 20, 20"
    organ[prostate]=$(printf 'phantom:\n  kind: pelvis\norgan:\n  roi: Prostate\n')
    for name in gtv_sts002 gtv_sts004; do
      organ[$name]=$(real_organ_sections "$name" "$data")
    done
    body lung lung "250, 115, 165"
    names=(egg prostate gtv_sts002 gtv_sts004 lung)
    ;;
  *) echo "particle_count_sweep: the set is 'tune' or 'report', not '$set_name'" >&2; exit 2 ;;
esac
for name in "${names[@]}"; do
  for n in "${counts[@]}"; do
    printf '%s\nmodel:\n  particles: %s\nexport:\n  model: m.json\n' "${organ[$name]}" "$n" >"$work/plan.yaml"
    rm -rf "$work/plan" "$work/session"
    "$bin" --quiet run "$work/plan.yaml" --out "$work/plan" >/dev/null 2>&1 ||
      { echo "$name $n: planning failed"; continue; }
    printf 'planning:\n  model: %s\npoints:\n  count: 87\n  noise_mm: 0.5\n  stretch: 1.1\n  bend_mm: 2\nfit:\n  method: spread\n' \
      "$work/plan/m.json" >"$work/session.yaml"
    "$bin" --quiet run "$work/session.yaml" --out "$work/session" >/dev/null 2>&1
    code=$?
    /usr/bin/python3 -c "
import json
p = json.load(open('$work/plan/run.json')); s = json.load(open('$work/session/run.json'))
t, m = s['truth'], p['model']
update = sum(x['wall_s'] for x in s['stages'] if x['name'] in ('planning_model', 'points', 'fit'))
peak = max(p['peak_memory_mib'], s['peak_memory_mib'])
print('$name asked $n particles %d radius %.3f volume_cm3 %.1f planning_s %.2f update_s %.2f exit $code '
      'msd %.3f hd95 %.2f msd_undeformed %.3f volume_change_pct %.2f peak_mib %.0f' % (
      m['particles'], m['radius_mm'], m['body_volume_mm3'] / 1000, p['wall_s'], update,
      t['msd_mm'], t['hd95_mm'], t['msd_undeformed_mm'], s['fit']['volume_change_pct'], peak))" 2>/dev/null ||
      echo "$name $n: exit $code (no run.json)"
  done
done
