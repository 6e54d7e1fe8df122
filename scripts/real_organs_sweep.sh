#!/bin/bash
# Real organs under the session's deformations: the left and right kidneys, a vertebra and
# the liver grown from seeds on ct-crlm-1004 (5 mm slices; radius 1.5 mm, the liver's 1.8
# mm: 49,000 particles), and the GTVs of ct-sts-002 and ct-sts-004 from their structure
# sets (3.27 mm slices), each planned once and fitted to 87 points on half its surface (0.5
# mm noise) of seven known deformations. One line per session: exit
# code, MSD and HD95 against the truth, the organ left as it was, the volume change, and
# HARM where ours is over the undeformed organ's MSD + 0.1 mm (issue 27's do-no-harm).
# A last line counts the sessions that exit 3, break do-no-harm, and meet MSD <= 1 mm and
# HD95 <= 2.5 mm.
#   scripts/real_organs_sweep.sh [ORGANFIT] [WORKDIR]
set -u
bin="${1:-$(dirname "$0")/../build/bin/organfit}"
work="${2:-$(mktemp -d)}"
data="$(cd "$(dirname "$0")/../.." && pwd)/shared/data"
[[ -d "$data/ct-crlm-1004" ]] || { echo "real_organs_sweep: $data is absent" >&2; exit 2; }
mkdir -p "$work"
source "$(dirname "$0")/real_organs.sh"
for organ in kidney_left kidney_right vertebra liver gtv_sts002 gtv_sts004; do
  case $organ in liver) radius=1.8 ;; gtv_*) radius=2.0 ;; *) radius=1.5 ;; esac
  { real_organ_sections "$organ" "$data"
    printf 'model:\n  radius_mm: %s\nexport:\n  model: m.json\n' "$radius"; } >"$work/plan_$organ.yaml"
done
deformations=("none:" "stretch_1.1:  stretch: 1.1" "bend_5:  bend_mm: 5" "twist_10:  twist_deg: 10"
  "probe_5:  indent_mm: -5" "push_5:  push_mm: 5" "default:  stretch: 1.15\n  bend_mm: 2")
: >"$work/lines.txt"
for organ in kidney_left kidney_right vertebra liver gtv_sts002 gtv_sts004; do
  "$bin" --quiet run "$work/plan_$organ.yaml" --out "$work/plan_$organ" >/dev/null 2>&1 ||
    { echo "$organ: planning failed"; continue; }
  for d in "${deformations[@]}"; do
    name=${d%%:*}
    printf "planning:\n  model: %s\npoints:\n  count: 87\n  noise_mm: 0.5\n  coverage: half\n${d#*:}\nfit:\n  method: spread\n" \
      "$work/plan_$organ/m.json" >"$work/session.yaml"
    rm -rf "$work/session"
    "$bin" --quiet run "$work/session.yaml" --out "$work/session" >/dev/null 2>&1
    code=$?
    /usr/bin/python3 -c "
import json; d = json.load(open('$work/session/run.json')); t, f = d['truth'], d['fit']
print('$organ $name exit $code msd %.3f undeformed %.3f hd95 %.2f volume %.2f%%%s' % (t['msd_mm'],
      t['msd_undeformed_mm'], t['hd95_mm'], f['volume_change_pct'],
      ' HARM' if t['msd_mm'] > t['msd_undeformed_mm'] + 0.1 else ''))" 2>/dev/null ||
      echo "$organ $name exit $code (no run.json)"
  done
done | tee -a "$work/lines.txt"
# The counts the benchmarks' tables give (docs/benchmarks.md).
/usr/bin/python3 -c "
import re
lines = [l for l in open('$work/lines.txt') if ' exit ' in l]
msd = [float(m.group(1)) for l in lines for m in [re.search(r'msd ([0-9.]+)', l)] if m]
hd95 = [float(m.group(1)) for l in lines for m in [re.search(r'hd95 ([0-9.]+)', l)] if m]
print('%d sessions: exit 3 in %d, do-no-harm broken in %d, MSD <= 1 mm in %d, HD95 <= 2.5 mm in %d' % (
      len(lines), sum(' exit 3 ' in l for l in lines), sum('HARM' in l for l in lines),
      sum(v <= 1 for v in msd), sum(v <= 2.5 for v in hd95)))"
