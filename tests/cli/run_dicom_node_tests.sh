#!/usr/bin/env bash
# organfit against a real DICOM node: Debian's Orthanc, started with a temporary
# configuration and storage inside a network namespace of its own (unshare --net: only
# its loopback exists, so the Orthanc, which binds every interface, is reachable from
# nowhere else). The phantom's CT and structure set are loaded with dcmtk's storescu; a
# scene pulls them (C-FIND, C-GET), fits, and sends the RT Structure Set and the
# registration back (C-STORE); Orthanc's REST API then shows them in the study,
# referencing the CT. Also: `organfit dicom echo|find|pull|push`, and the failures (node
# down, wrong AE title, a study that is not there, a silent node, a failed send). Prints
# "N passed, N failed" and exits non-zero on any failure.
set -u
if [[ -z "${ORGANFIT_NETNS:-}" ]]; then
  exec unshare --net env ORGANFIT_NETNS=1 bash "$0" "$@" ||
    { echo "FAIL cannot make a network namespace (unshare --net)"; exit 1; }
fi
ip link set lo up || { echo "FAIL cannot bring up the namespace's loopback"; exit 1; }
source "$(dirname "$0")/check.sh"
orthanc_pid=""
cleanup() {
  [[ -n "$orthanc_pid" ]] && kill "$orthanc_pid" 2>/dev/null && wait "$orthanc_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
node="ORTHANC@127.0.0.1:4242"
rest="http://127.0.0.1:8042"

# The node: ORGANFIT is a known modality (Orthanc lets known modalities C-GET); a called
# AE title other than ORTHANC is refused.
mkdir -p "$tmp/storage"
cat >"$tmp/orthanc.json" <<EOF
{
  "Name": "organfit-test",
  "StorageDirectory": "$tmp/storage",
  "IndexDirectory": "$tmp/storage",
  "DicomAet": "ORTHANC",
  "DicomPort": 4242,
  "HttpPort": 8042,
  "RemoteAccessAllowed": false,
  "AuthenticationEnabled": false,
  "DicomCheckCalledAet": true,
  "DicomModalities": { "organfit": [ "ORGANFIT", "127.0.0.1", 11112 ] },
  "Plugins": [],
  "LuaScripts": []
}
EOF
Orthanc "$tmp/orthanc.json" >"$tmp/orthanc.log" 2>&1 &
orthanc_pid=$!
for _ in $(seq 1 100); do
  curl -sf "$rest/system" >/dev/null && break
  sleep 0.2
done
if ! curl -sf "$rest/system" >/dev/null; then
  echo "FAIL Orthanc did not start: $(tail -c 800 "$tmp/orthanc.log")"
  exit 1
fi

# The planning data, loaded by a tool of its own.
"$bin" -q synth pelvis --out "$tmp/pelvis" --columns 160 --rows 160 --pixel-mm 2.5 >/dev/null
storescu -aet LOADER -aec ORTHANC +sd 127.0.0.1 4242 "$tmp/pelvis/ct" "$tmp/pelvis/rtstruct.dcm" \
  >"$tmp/storescu.log" 2>&1
study=$($py -c "import pydicom; print(pydicom.dcmread('$tmp/pelvis/rtstruct.dcm').StudyInstanceUID)")
rt_series=$($py -c "import pydicom; print(pydicom.dcmread('$tmp/pelvis/rtstruct.dcm').SeriesInstanceUID)")
ct_series=$($py -c "
import pydicom, glob; print(pydicom.dcmread(sorted(glob.glob('$tmp/pelvis/ct/*'))[0]).SeriesInstanceUID)")
check "storescu loaded the CT and the structure set into Orthanc" $py -c "
import json, urllib.request
s = json.load(urllib.request.urlopen('$rest/statistics'))
n = len(__import__('os').listdir('$tmp/pelvis/ct'))
assert s['CountInstances'] == n + 1, (s, n)"

check "dicom echo" bash -c "'$bin' dicom echo $node | grep -q 'answered C-ECHO'"
check "dicom find lists the CT and RTSTRUCT series of the study, no patient" bash -c "
  '$bin' dicom find $node --study $study --json >'$tmp/find.json' &&
  $py -c \"
import json; f = json.load(open('$tmp/find.json'))
assert sorted(s['modality'] for s in f) == ['CT', 'RTSTRUCT'], f
assert all(s['study_uid'] == '$study' for s in f), f
ct = [s for s in f if s['modality'] == 'CT'][0]
assert ct['series_uid'] == '$ct_series' and ct['instances'] == 56, ct
assert 'Phantom' not in open('$tmp/find.json').read()\""
check "dicom pull writes the series into OUT/<series UID>/, byte for byte the pixels" bash -c "
  '$bin' -q dicom pull $node --study $study --modality CT --out '$tmp/pulled' &&
  test \$(ls '$tmp/pulled/$ct_series' | wc -l) -eq 56 &&
  $py -c \"
import pydicom, glob
a = {pydicom.dcmread(f).SOPInstanceUID: pydicom.dcmread(f).PixelData for f in glob.glob('$tmp/pelvis/ct/*')}
b = {pydicom.dcmread(f).SOPInstanceUID: pydicom.dcmread(f).PixelData for f in glob.glob('$tmp/pulled/$ct_series/*')}
assert a == b\""

# A scene that pulls the CT and the structure set, fits, and sends the results back.
cat >"$tmp/node.yaml" <<EOF
scene:
  name: node
network:
  aet: ORGANFIT
  timeout_s: 20
ct:
  node: $node
  study_uid: $study
organ:
  node: $node
  roi: Prostate
model:
  radius_mm: 2.4
points:
  count: 87
  noise_mm: 0.5
  bend_mm: 2.0
fit:
  method: spread
export:
  rtstruct: prostate_fit_rtstruct.dcm
  registration: prostate_fit_reg.dcm
  send_to: $node
report:
  file: report.html
EOF
check "a scene pulls, fits and sends (exit 0)" "$bin" -q run "$tmp/node.yaml" --out "$tmp/run"
check "run.json records the pulls and the send, with their times" $py -c "
import json; d = json.load(open('$tmp/run/run.json'))
assert d['status'] == 'ok', d['status']
assert d['ct_pulled']['objects'] == 56 and d['ct_pulled']['series_uid'] == '$ct_series', d['ct_pulled']
assert d['organ_pulled']['objects'] == 1, d['organ_pulled']
s = d['export']['sent']
assert s['sent'] == 2 and s['files'] == ['prostate_fit_rtstruct.dcm', 'prostate_fit_reg.dcm'], s
names = [st['name'] for st in d['stages']]
assert 'ct_pull' in names and 'organ_pull' in names and 'send' in names, names
assert 'cache/' in d['outputs'], d['outputs']
print({st['name']: round(st['wall_s'], 3) for st in d['stages']})"
$py -c "
import json; d = json.load(open('$tmp/run/run.json'))
print('     stage times (s):', {st['name']: round(st['wall_s'], 3) for st in d['stages']})
print('     C-FIND/C-GET (s): CT', round(d['ct_pulled']['find_s'], 3), round(d['ct_pulled']['get_s'], 3),
      '/ RTSTRUCT', round(d['organ_pulled']['find_s'], 3), round(d['organ_pulled']['get_s'], 3),
      '/ send', round(d['export']['sent']['wall_s'], 3))" 2>/dev/null
check "the sent RT Structure Set is in Orthanc, in the CT's study, referencing the CT" $py -c "
import json, urllib.request, pydicom
get = lambda p: json.load(urllib.request.urlopen('$rest' + p))
ours = pydicom.dcmread('$tmp/run/prostate_fit_rtstruct.dcm')
found = get('/tools/lookup?' if False else '/instances?expand')
inst = [i for i in found if i['MainDicomTags']['SOPInstanceUID'] == ours.SOPInstanceUID]
assert len(inst) == 1, 'not in Orthanc'
series = get('/series/' + inst[0]['ParentSeries'])
study = get('/studies/' + series['ParentStudy'])
assert study['MainDicomTags']['StudyInstanceUID'] == '$study', study['MainDicomTags']
tags = get('/instances/' + inst[0]['ID'] + '/simplified-tags')
ref = tags['ReferencedFrameOfReferenceSequence'][0]['RTReferencedStudySequence'][0]['RTReferencedSeriesSequence'][0]
assert ref['SeriesInstanceUID'] == '$ct_series', ref
assert tags['StructureSetROISequence'][0]['ROIName'] == 'Prostate_fit', tags['StructureSetROISequence']
reg = [i for i in found if i['MainDicomTags']['SOPInstanceUID'] == pydicom.dcmread('$tmp/run/prostate_fit_reg.dcm').SOPInstanceUID]
assert len(reg) == 1, 'the registration is not in Orthanc'"

# By Patient ID (a C-FIND of the patient's studies), the structure set named by its
# series; the log names neither the patient nor the ID.
sed "s/study_uid: .*/patient_id: PELVIS-1/; s/^  roi: Prostate/  roi: Prostate\n  series_uid: $rt_series/" \
  "$tmp/node.yaml" >"$tmp/by_patient.yaml"
check "by patient ID and organ.series_uid; no patient name or ID in the log" bash -c "
  '$bin' run '$tmp/by_patient.yaml' --out '$tmp/run-patient' >'$tmp/patient.log' 2>&1 &&
  ! grep -q -i -e 'PELVIS-1' -e 'Phantom' '$tmp/patient.log' && grep -q 'pulled from' '$tmp/patient.log' &&
  $py -c \"
import json; d = json.load(open('$tmp/run-patient/run.json'))
assert d['ct_pulled']['series_uid'] == '$ct_series' and d['organ_pulled']['series_uid'] == '$rt_series', d
assert 'PELVIS-1' not in json.dumps(d)\""
# Failures: one line, exit 2, nothing partial.
fails_with() {  # fails_with PATTERN COMMAND... : exit 2 and PATTERN on stderr's one line
  local pattern="$1"
  shift
  "$@" >"$tmp/out.log" 2>"$tmp/err.log"
  local code=$?
  [[ $code -eq 2 ]] || { echo "exit $code, expected 2: $(cat "$tmp/err.log")"; return 1; }
  [[ $(wc -l <"$tmp/err.log") -eq 1 ]] || { echo "not one line: $(cat "$tmp/err.log")"; return 1; }
  grep -q -- "$pattern" "$tmp/err.log" || { echo "no '$pattern' in: $(cat "$tmp/err.log")"; return 1; }
}
scene_with() {  # scene_with NAME SED-EXPRESSION: a variant of node.yaml
  sed "$2" "$tmp/node.yaml" >"$tmp/$1.yaml"
}
scene_with down "s/127.0.0.1:4242/127.0.0.1:4299/"
check "node down: exit 2 naming ct.node, no --out left" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'ct.node: ORTHANC@127.0.0.1:4299: cannot connect: Connection refused' \
    '$bin' -q run '$tmp/down.yaml' --out '$tmp/run-down' && test ! -e '$tmp/run-down'"
scene_with wrong_aet "s/ORTHANC@127.0.0.1:4242/PACS@127.0.0.1:4242/"
check "wrong AE title: the association is refused, exit 2" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with \"refused the association: check the node's AE title ('PACS')\" \
    '$bin' -q run '$tmp/wrong_aet.yaml' --out '$tmp/run-aet' && test ! -e '$tmp/run-aet'"
scene_with no_study "s/study_uid: .*/study_uid: 1.2.826.0.1.3680043.2.1125.999/"
check "a study that is not there: exit 2 naming ct.study_uid" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'ct.study_uid: ORTHANC@127.0.0.1:4242 holds: no CT series for study 1.2.826.0.1.3680043.2.1125.999' \
    '$bin' -q run '$tmp/no_study.yaml' --out '$tmp/run-nostudy' && test ! -e '$tmp/run-nostudy'"
check "dicom pull of a study that is not there: exit 2" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'no series matches' '$bin' dicom pull $node --study 1.2.3.4 --out '$tmp/pull-none' &&
  test ! -e '$tmp/pull-none'"
# A silent node: a listener that accepts and never answers.
$py -c "
import socket, time
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind(('127.0.0.1', 4300)); s.listen(8); conns = []
while True:
    c, _ = s.accept(); conns.append(c)" &
silent_pid=$!
sleep 0.3
scene_with silent "s/127.0.0.1:4242/127.0.0.1:4300/; s/timeout_s: 20/timeout_s: 2/"
check "a silent node fails after network.timeout_s" bash -c "
  $(declare -f fails_with); tmp='$tmp'; start=\$(date +%s)
  fails_with 'did not answer within 2 s (network.timeout_s)' \
    '$bin' -q run '$tmp/silent.yaml' --out '$tmp/run-silent' && test \$((\$(date +%s) - start)) -lt 10"
# A failed send: the fit's files stay in --out, run.json says why, exit 2.
scene_with send_down "s/send_to: .*/send_to: ORTHANC@127.0.0.1:4299/"
check "a failed send leaves the written files in --out and says so (exit 2)" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'export.send_to: ORTHANC@127.0.0.1:4299: cannot connect.*the written files are in' \
    '$bin' -q run '$tmp/send_down.yaml' --out '$tmp/run-send' &&
  test -s '$tmp/run-send/prostate_fit_rtstruct.dcm' && test -s '$tmp/run-send/prostate_fit_reg.dcm' &&
  $py -c \"
import json; d = json.load(open('$tmp/run-send/run.json'))
assert d['status'] == 'send_failed' and 'cannot connect' in d['export']['send_failed'], d['export']
# The study held the phantom's structure set and the fits sent back (theirs hold
# Prostate_fit): without organ.series_uid, the one holding organ.roi was chosen.
assert d['organ_pulled']['series_uid'] == '$rt_series', d['organ_pulled']\""
scene_with send_silent "s/send_to: .*/send_to: ORTHANC@127.0.0.1:4300/; s/timeout_s: 20/timeout_s: 2/"
check "a send to a silent node times out, files kept (exit 2)" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'export.send_to: ORTHANC@127.0.0.1:4300: did not answer within 2 s' \
    '$bin' -q run '$tmp/send_silent.yaml' --out '$tmp/run-send-silent' &&
  test -s '$tmp/run-send-silent/prostate_fit_rtstruct.dcm'"
kill $silent_pid 2>/dev/null
check "dicom push of the run's RT Structure Set (already there: Orthanc keeps one)" bash -c "
  '$bin' dicom push $node '$tmp/run/prostate_fit_rtstruct.dcm' | grep -q '1 object(s) sent'"
check "dicom push of a file that is not DICOM: exit 2 before any connection" bash -c "
  $(declare -f fails_with); tmp='$tmp'; echo text >'$tmp/not.dcm'
  fails_with 'not a DICOM file' '$bin' dicom push ORTHANC@127.0.0.1:4299 '$tmp/not.dcm'"
check "the scene's network keys are checked as the file is read" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  sed 's/node: ORTHANC@127.0.0.1:4242/node: ORTHANC-127.0.0.1:4242/' '$tmp/node.yaml' >'$tmp/bad1.yaml'
  fails_with 'bad1.yaml:[0-9]*: ct.node: .*is not a DICOM node' '$bin' validate '$tmp/bad1.yaml' &&
  sed 's/  aet: ORGANFIT/  aet: A_TITLE_TOO_LONG_X/' '$tmp/node.yaml' >'$tmp/bad2.yaml' &&
  fails_with 'network.aet: an AE title has 1 to 16' '$bin' validate '$tmp/bad2.yaml'"

check "an AE title the node does not know: exit 2, saying so" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with \"the node closed the association (does it let our AE title 'STRANGER'\" \
    '$bin' dicom find $node --study $study --aet STRANGER"
# An error status: a structure set without its Series Instance UID, which Orthanc cannot
# file (its own checks, not ours, refuse it).
$py -c "
import pydicom; d = pydicom.dcmread('$tmp/run/prostate_fit_rtstruct.dcm')
del d.SeriesInstanceUID; d.SOPInstanceUID = pydicom.uid.generate_uid()
d.file_meta.MediaStorageSOPInstanceUID = d.SOPInstanceUID; d.save_as('$tmp/broken.dcm')"
check "a C-STORE the node answers with an error status: exit 2 naming the file and status" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  fails_with 'refused broken.dcm: status 0x[A-C]' '$bin' dicom push $node '$tmp/broken.dcm'"

check "network keys the run would not use are refused" bash -c "
  $(declare -f fails_with); tmp='$tmp'
  printf 'scene: {name: x}\nnetwork: {aet: ORGANFIT}\nbody: {shape: ellipsoid}\n' >'$tmp/unused.yaml'
  fails_with 'unused.yaml:2: network: no DICOM node is used' '$bin' validate '$tmp/unused.yaml' &&
  printf 'ct: {folder: .., study_uid: 1.2.3}\n' >'$tmp/folder_uid.yaml' &&
  fails_with 'ct.study_uid: used only with ct.node' '$bin' validate '$tmp/folder_uid.yaml' &&
  printf 'ct: {node: \"A@h:1\", folder: ..}\n' >'$tmp/both.yaml' &&
  fails_with 'ct.node: the CT comes from ct.folder or from ct.node, not both' '$bin' validate '$tmp/both.yaml' &&
  printf 'ct: {node: \"A@h:1\"}\n' >'$tmp/nostudy.yaml' &&
  fails_with 'ct.node: name the CT.s study' '$bin' validate '$tmp/nostudy.yaml'"

finish
