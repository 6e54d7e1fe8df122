#!/usr/bin/env bash
# The fit as a deformation (fitting/deformation.h) through whole runs: the exported organ
# keeps the planning organ's topology and volume under a 10 mm bend, on the phantom's
# prostate and on the real GTVs; the displacement field warps the planning label map
# through plastimatch onto our exported one; the Jacobian file is positive. Prints
# "N passed, N failed" and exits non-zero on any failure.
source "$(dirname "$0")/check.sh"

# The checks every export makes, as run.json reports them.
checks_hold() {  # checks_hold RUN_JSON
  $py -c "
import json, sys; d = json.load(open('$1')); c = d['export']['checks']
assert c['topology_kept'], c
t = c['topology_exported']
assert t['single_voxel_components'] == 0 and t['single_voxel_cavities'] == 0, t
assert c['volume_kept'], c
assert c['jacobian']['lattice_min'] > 0 and d['fit']['deformation']['min_volume_ratio'] > 0, c
assert not any('export:' in w for w in d['warnings']), d['warnings']"
}

# The phantom's prostate: planning (the organ at rest, phi = identity), then a session
# under a 10 mm bend writing the label map, the field and the Jacobian.
cp "$src/pipelines/prostate-planning.yaml" "$tmp/planning.yaml"
sed -i 's/^  kind: pelvis/  kind: pelvis\n  columns: 160\n  rows: 160\n  pixel_mm: 2.5/' "$tmp/planning.yaml"
check prostate.planning "$bin" --quiet run "$tmp/planning.yaml" --out "$tmp/plan" --set export.labels=planning.nrrd
check prostate.at_rest_is_the_planning_organ $py -c "
import json; d = json.load(open('$tmp/plan/run.json')); c = d['export']['checks']
assert c['volume_difference_cm3'] == 0 and c['topology_kept'], c
assert abs(d['export']['volume_on_ct_grid_cm3'] - d['organ']['volume_cm3']) < 1e-9, d['export']"
check prostate.session_bend_10mm "$bin" --quiet run "$src/pipelines/prostate-session.yaml" --out "$tmp/session" \
  --set "planning.model=$tmp/plan/prostate_model.json" --set points.bend_mm=10 \
  --set export.labels=fit.nrrd --set export.displacement_field=vf.mha --set export.jacobian=jacobian.nrrd \
  --set export.registration=reg.dcm
check prostate.checks_hold checks_hold "$tmp/session/run.json"
# plastimatch warps the planning label map by our field (output(q) = input(q + v(q))),
# linearly, kept where >= 0.5: Dice against our exported label map.
warp_dice() {  # warp_dice PLANNING_LABELS FIELD OURS MIN_DICE
  plastimatch convert --input "$1" --output-img "$tmp/planning_f.mha" --output-type float >/dev/null &&
    plastimatch convert --input "$tmp/planning_f.mha" --xf "$2" --output-img "$tmp/warped.mha" \
      --interpolation linear >/dev/null &&
    plastimatch threshold --input "$tmp/warped.mha" --output "$tmp/warped.nrrd" --above 0.5 >/dev/null &&
    plastimatch dice --all "$tmp/warped.nrrd" "$3" >"$tmp/dice.txt" &&
    $py -c "
d = float([l.split()[1] for l in open('$tmp/dice.txt') if l.startswith('DICE')][0])
print('dice', d); assert d >= $4, d"
}
if command -v plastimatch >/dev/null; then
  check prostate.plastimatch_warp_gives_our_organ warp_dice "$tmp/plan/planning.nrrd" "$tmp/session/vf.mha" "$tmp/session/fit.nrrd" 0.98
  check prostate.jacobian_positive_and_one_far_away bash -c "
plastimatch stats '$tmp/session/jacobian.nrrd' | tee '$tmp/jac.txt' &&
$py -c \"
w = open('$tmp/jac.txt').read().split(); mn = float(w[w.index('MIN') + 1]); mx = float(w[w.index('MAX') + 1])
assert 0.5 < mn <= 1.0 <= mx < 2.0, (mn, mx)\""
else
  echo "FAIL plastimatch is not installed (scripts/setup.sh installs it)"; failed=$((failed + 1))
fi

# Warping the planning CT by the field: over our exported organ's interior (its voxels
# whose 6 neighbours are inside too: the boundary voxels mix in the fat round it) the mean
# HU of the warped CT is the planning organ's interior mean HU in the planning CT.
if command -v plastimatch >/dev/null; then
  check prostate.warped_ct_keeps_the_organs_hu bash -c "
plastimatch convert --input '$tmp/plan/phantom/ct' --output-img '$tmp/ct.mha' --output-type float >/dev/null &&
plastimatch convert --input '$tmp/ct.mha' --xf '$tmp/session/vf.mha' --output-img '$tmp/ct_today.mha' >/dev/null &&
$py '$src/tests/cli/interior_mean.py' '$tmp/ct.mha' '$tmp/plan/planning.nrrd' '$tmp/ct_today.mha' '$tmp/session/fit.nrrd' 2.0"
fi
# organfit export --model writes the same field from the saved fitted model.
check prostate.export_command_writes_the_same_field bash -c "
'$bin' --quiet run '$src/pipelines/prostate-session.yaml' --out '$tmp/session2' \
  --set 'planning.model=$tmp/plan/prostate_model.json' --set points.bend_mm=10 --set export.model=fitted.json &&
'$bin' --quiet export --model '$tmp/session2/fitted.json' --displacement-field '$tmp/exported_vf.mha' &&
cmp '$tmp/exported_vf.mha' '$tmp/session/vf.mha'"

# A stated grid: 2.5 mm over the CT's box (the phantom CT's 320 x 320 x 56 at 1.25 x 1.25 x
# 2.5 mm gives 160 x 160 x 56); plastimatch warps onto the CT with --fixed. Refused where
# no field is written.
check prostate.field_on_a_stated_grid bash -c "
'$bin' --quiet run '$src/pipelines/prostate-session.yaml' --out '$tmp/coarse' \
  --set 'planning.model=$tmp/plan/prostate_model.json' --set points.bend_mm=10 \
  --set export.labels=fit.nrrd --set export.displacement_field=vf.mha --set export.registration=reg.dcm \
  --set export.field_spacing_mm=2.5 &&
$py -c \"
import json, pydicom; d = json.load(open('$tmp/coarse/run.json'))
assert d['export']['field_grid'] == {'size': [160, 160, 56], 'spacing_mm': [2.5, 2.5, 2.5]}, d['export']
g = pydicom.dcmread('$tmp/coarse/reg.dcm').DeformableRegistrationSequence[0].DeformableRegistrationGridSequence[0]
assert [int(x) for x in g.GridDimensions] == [160, 160, 56] and [float(x) for x in g.GridResolution] == [2.5] * 3\" &&
plastimatch convert --input '$tmp/plan/planning.nrrd' --output-img '$tmp/coarse/pf.mha' --output-type float >/dev/null &&
plastimatch convert --input '$tmp/coarse/pf.mha' --xf '$tmp/coarse/vf.mha' --fixed '$tmp/coarse/pf.mha' --output-img '$tmp/coarse/w.mha' >/dev/null &&
plastimatch threshold --input '$tmp/coarse/w.mha' --output '$tmp/coarse/w.nrrd' --above 0.5 >/dev/null &&
plastimatch dice --all '$tmp/coarse/w.nrrd' '$tmp/coarse/fit.nrrd' | $py -c \"
import sys; d = float([l.split()[1] for l in sys.stdin if l.startswith('DICE')][0]); assert d >= 0.98, d\""
check prostate.field_spacing_without_a_field_is_refused bash -c "
! '$bin' validate '$src/pipelines/default.yaml' --set export.field_spacing_mm=2 2>'$tmp/err.txt' &&
grep -q 'export.field_spacing_mm=2: sets the grid of export.displacement_field' '$tmp/err.txt'"

# The REG object: dciodvfy finds no error; pydicom reads its grid (the CT's) and its
# vectors, which are the displacement field's to the float.
if command -v dciodvfy >/dev/null; then
  check prostate.registration_dciodvfy_no_error bash -c "dciodvfy '$tmp/session/reg.dcm' 2>&1 | tee '$tmp/dciodvfy.txt' >/dev/null; ! grep -q '^Error' '$tmp/dciodvfy.txt'"
else
  echo "FAIL dciodvfy is not installed (scripts/setup.sh installs dicom3tools)"; failed=$((failed + 1))
fi
check prostate.registration_reads_back $py -c "
import pydicom, zlib, array
d = pydicom.dcmread('$tmp/session/reg.dcm')
assert d.SOPClassUID == '1.2.840.10008.5.1.4.1.1.66.3' and d.Modality == 'REG'
item = d.DeformableRegistrationSequence[0]
ct = pydicom.dcmread(sorted(__import__('glob').glob('$tmp/plan/phantom/ct/*'))[0])
assert item.SourceFrameOfReferenceUID == d.FrameOfReferenceUID == ct.FrameOfReferenceUID
assert d.ReferencedSeriesSequence[0].SeriesInstanceUID == ct.SeriesInstanceUID
g = item.DeformableRegistrationGridSequence[0]
assert [int(x) for x in g.GridDimensions] == [ct.Columns, ct.Rows, len(d.ReferencedSeriesSequence[0].ReferencedInstanceSequence)]
v = array.array('f'); v.frombytes(g.VectorGridData)
raw = open('$tmp/session/vf.mha', 'rb').read(); k = b'ElementDataFile = LOCAL\\n'; i = raw.index(k) + len(k)
body = zlib.decompress(raw[i:]) if b'CompressedData = True' in raw[:i] else raw[i:]
f = array.array('f'); f.frombytes(body)
assert len(v) == len(f) and max(abs(a - b) for a, b in zip(v, f)) <= 1e-4"

# Real GTVs (skipped where ../shared/data is absent): a 10 mm bend keeps their topology.
for case in ct-sts-002:GTV_Mass_CT ct-sts-004:GTV_Mass_CT; do
  folder="${case%%:*}" roi="${case#*:}"
  [[ -d "$src/../shared/data/$folder" ]] || continue
  check "real.$folder.bend_10mm" "$bin" --quiet run "$src/pipelines/real-sts-002.yaml" --out "$tmp/$folder" \
    --set "ct.folder=$src/../shared/data/$folder/ct" --set "organ.rtstruct=$src/../shared/data/$folder/rtstruct.dcm" \
    --set "organ.roi=$roi" --set points.bend_mm=10
  check "real.$folder.checks_hold" checks_hold "$tmp/$folder/run.json"
done

finish
