#!/usr/bin/python3
"""Generates the bad-input corpus: each case a folder with its inputs and case.json
{"args": [...], "code": 2, "expect": "...", "names": "..."}. `{case}` in args is the
case's folder, `{data}` the real data folder. DICOM cases are made from a small pelvis
phantom written by `organfit synth pelvis` and altered with pydicom.

usage: make_corpus.py OUT_DIR ORGANFIT_BINARY SHARED_DATA_DIR
"""
import json, os, shutil, subprocess, sys
import pydicom

out, organfit, data = sys.argv[1], sys.argv[2], sys.argv[3]
os.makedirs(out, exist_ok=True)
base = os.path.join(out, '_phantom')
subprocess.run([organfit, '--quiet', 'synth', 'pelvis', '--out', base, '--columns', '64', '--rows', '64',
                '--pixel-mm', '6', '--slices', '12', '--slice-mm', '5'], check=True, stdout=subprocess.DEVNULL)
ct_files = sorted(os.listdir(os.path.join(base, 'ct')))
SEGMENT = ['segment', '--ct', '{case}/ct', '--seed', '0,0,0', '--hu', '20,80', '--out', '{case}/out/mask.nrrd']
IMPORT = ['segment', '--ct', '{case}/ct', '--rtstruct', '{case}/rtstruct.dcm', '--roi', 'Prostate', '--out', '{case}/out/mask.nrrd']

def case(name, args, expect, code=2, names=None, ct=True, rtstruct=False):
    d = os.path.join(out, name)
    os.makedirs(d, exist_ok=True)
    if ct:
        shutil.copytree(os.path.join(base, 'ct'), os.path.join(d, 'ct'))
    if rtstruct:
        shutil.copy(os.path.join(base, 'rtstruct.dcm'), os.path.join(d, 'rtstruct.dcm'))
    with open(os.path.join(d, 'case.json'), 'w') as f:
        json.dump({'args': args, 'code': code, 'expect': expect, 'names': names}, f)
    return d

def edit_ct(d, index, fn):
    path = os.path.join(d, 'ct', ct_files[index])
    ds = pydicom.dcmread(path)
    fn(ds)
    ds.save_as(path)

def edit_all(d, fn):
    for i in range(len(ct_files)):
        edit_ct(d, i, fn)

# --- CT series defects -------------------------------------------------------------
d = case('ct_truncated_slice', SEGMENT, 'CT0006.dcm: a truncated or corrupt DICOM file', names='CT0006.dcm')
with open(os.path.join(d, 'ct', 'CT0006.dcm'), 'r+b') as f:
    f.truncate(os.path.getsize(os.path.join(d, 'ct', 'CT0006.dcm')) // 2)
d = case('ct_two_series_no_choice', SEGMENT, '2 CT series; choose one')
os.makedirs(os.path.join(d, 'tmp'))
for i, name in enumerate(ct_files):
    ds = pydicom.dcmread(os.path.join(d, 'ct', name))
    ds.SeriesInstanceUID = '1.2.826.0.1.3680043.2.1125.99.1'
    ds.SOPInstanceUID = f'1.2.826.0.1.3680043.2.1125.99.2.{i}'
    ds.save_as(os.path.join(d, 'ct', 'b_' + name))
os.rmdir(os.path.join(d, 'tmp'))
d = case('ct_missing_slice', SEGMENT, 'missing slice')
os.remove(os.path.join(d, 'ct', ct_files[5]))
d = case('ct_duplicate_positions', SEGMENT, 'duplicate slice position')
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[3]))
ds.SOPInstanceUID = '1.2.826.0.1.3680043.2.1125.99.3'
ds.save_as(os.path.join(d, 'ct', 'again.dcm'))
d = case('ct_inconsistent_pixel_spacing', SEGMENT, 'pixel spacing')
edit_ct(d, 4, lambda ds: setattr(ds, 'PixelSpacing', [5.5, 5.5]))
d = case('ct_gantry_tilt', SEGMENT, 'gantry tilt')
edit_all(d, lambda ds: setattr(ds, 'GantryDetectorTilt', 12))
d = case('ct_non_axial', SEGMENT, 'non-axial')
edit_all(d, lambda ds: setattr(ds, 'ImageOrientationPatient', [1, 0, 0, 0, 0, -1]))
d = case('ct_irregular_spacing', SEGMENT, 'irregular slice spacing')
edit_ct(d, 6, lambda ds: setattr(ds, 'ImagePositionPatient', [ds.ImagePositionPatient[0], ds.ImagePositionPatient[1], float(ds.ImagePositionPatient[2]) + 2.0]))
d = case('ct_empty_folder', SEGMENT, 'empty', ct=False)
os.makedirs(os.path.join(d, 'ct'))
d = case('ct_only_other_files', SEGMENT, 'no CT series', ct=False)
os.makedirs(os.path.join(d, 'ct'))
open(os.path.join(d, 'ct', 'README'), 'w').write('not DICOM\n')
d = case('ct_not_a_folder', ['segment', '--ct', '{case}/ct', '--seed', '0,0,0', '--hu', '20,80', '--out', '{case}/out/m.nrrd'], 'not a folder', ct=False)
open(os.path.join(d, 'ct'), 'w').write('a file\n')
d = case('ct_rows_differ', SEGMENT, 'differ')
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[2]))
ds.Rows = 32
ds.PixelData = ds.PixelData[: 32 * 64 * 2]
ds.save_as(os.path.join(d, 'ct', ct_files[2]))

# --- RT Structure Set defects -------------------------------------------------------
case('rtss_roi_missing', IMPORT[:-3] + ['Bladderr', '--out', '{case}/out/mask.nrrd'], "no ROI named 'Bladderr'", rtstruct=True)
def edit_rtss(d, fn):
    path = os.path.join(d, 'rtstruct.dcm')
    ds = pydicom.dcmread(path)
    fn(ds)
    ds.save_as(path)
def prostate(ds):
    number = next(r.ROINumber for r in ds.StructureSetROISequence if r.ROIName == 'Prostate')
    return next(c for c in ds.ROIContourSequence if c.ReferencedROINumber == number)
d = case('rtss_contour_outside_image', IMPORT, 'outside the image', rtstruct=True)
def shift(ds):
    for c in prostate(ds).ContourSequence:
        c.ContourData = [v + 1000 if i % 3 == 0 else v for i, v in enumerate(c.ContourData)]
edit_rtss(d, shift)
d = case('rtss_two_point_contour', IMPORT, 'fewer than 3', rtstruct=True)
def two(ds):
    c = prostate(ds).ContourSequence[0]
    c.ContourData = c.ContourData[:6]
    c.NumberOfContourPoints = 2
edit_rtss(d, two)
d = case('rtss_open_contour', IMPORT, 'OPEN_PLANAR', rtstruct=True)
edit_rtss(d, lambda ds: setattr(prostate(ds).ContourSequence[0], 'ContourGeometricType', 'OPEN_PLANAR'))
d = case('rtss_other_frame_of_reference', IMPORT, 'Frame of Reference', rtstruct=True)
def other_for(ds):
    for r in ds.StructureSetROISequence:
        r.ReferencedFrameOfReferenceUID = '1.2.826.0.1.3680043.2.1125.99.9'
    ds.ReferencedFrameOfReferenceSequence[0].FrameOfReferenceUID = '1.2.826.0.1.3680043.2.1125.99.9'
edit_rtss(d, other_for)
d = case('rtss_is_a_ct_slice', ['segment', '--ct', '{case}/ct', '--rtstruct', '{case}/ct/CT0001.dcm', '--roi', 'Prostate', '--out', '{case}/out/m.nrrd'], 'not an RT Structure Set')
d = case('rtss_truncated', IMPORT, 'rtstruct.dcm', rtstruct=True)
with open(os.path.join(d, 'rtstruct.dcm'), 'r+b') as f:
    f.truncate(300)

# --- ultrasound -------------------------------------------------------------------------
case('us_dicom_without_regions', ['us-points', '--us', '{data}/us-dicom/US1_UNCR.dcm', '--out', '{case}/out/p.csv'], 'no calibrated ultrasound region', ct=False)
d = case('us_missing_raw_file', ['us-points', '--us', '{case}/video.mhd', '--out', '{case}/out/p.csv'], 'is missing', ct=False)
text = open(os.path.join(data, 'us-plus', 'Prostate10_video.igs.mhd')).read()
open(os.path.join(d, 'video.mhd'), 'w').write(text)
tracker = open(os.path.join(data, 'us-plus', 'Prostate10_tracker.igs.mha'), 'rb').read()
d = case('us_transform_not_rigid', ['us-points', '--us', '{data}/us-plus/Prostate10_video.igs.mhd', '--tracker', '{case}/tracker.mha', '--out', '{case}/out/p.csv'], 'not a rigid transform', ct=False)
open(os.path.join(d, 'tracker.mha'), 'wb').write(tracker.replace(b'ToolToTrackerTransform = -0.20585', b'ToolToTrackerTransform = -2.0585'))
d = case('us_every_status_invalid', ['us-points', '--us', '{data}/us-plus/Prostate10_video.igs.mhd', '--tracker', '{case}/tracker.mha', '--out', '{case}/out/p.csv'], 'no usable frame', ct=False)
open(os.path.join(d, 'tracker.mha'), 'wb').write(tracker.replace(b'TransformStatus = OK', b'TransformStatus = INVALID'))
d = case('us_registration_not_rigid', ['us-points', '--us', '{data}/us-plus/BoneUltrasound_L14.igs.mha', '--registration', '1,0,0,0,0,3,0,0,0,0,1,0,0,0,0,1', '--out', '{case}/out/p.csv'], 'not a rigid transform', ct=False)
d = case('us_not_an_image', ['us-points', '--us', '{case}/x.nrrd', '--out', '{case}/out/p.csv'], 'x.nrrd', ct=False)
open(os.path.join(d, 'x.nrrd'), 'w').write('NRRD0004\ntype: garbage\n\n')

# --- point files through a scene ------------------------------------------------------------
def points_case(name, content, expect):
    d = case(name, ['run', '{case}/scene.yaml', '--out', '{case}/out'], expect, ct=False)
    open(os.path.join(d, 'points.csv'), 'w').write(content)
    open(os.path.join(d, 'scene.yaml'), 'w').write('body:\n  size_mm: [20, 16, 12]\nmodel:\n  radius_mm: 1.5\n'
                                                   'points:\n  source: file\n  file: points.csv\nfit:\n  method: spread\n')
points_case('points_nan', 'x,y,z\n1,2,3\n4,nan,6\n', 'points.csv:3: non-finite coordinate')
points_case('points_inf', 'x,y,z\n1,2,inf\n', 'points.csv:2: non-finite coordinate')
points_case('points_text', 'x,y,z\n1,two,3\n', "'two' is not a number")
points_case('points_missing_column', 'x,y,z\n1,2\n', 'expected x,y,z[,confidence], got 2 columns')
points_case('points_bad_confidence', 'x,y,z,c\n1,2,3,1.5\n', 'confidence must be in (0, 1]')
points_case('points_empty', 'x,y,z\n', 'no points')

# --- scene files ------------------------------------------------------------------------------
def scene_case(name, text, expect, args=None):
    d = case(name, args or ['run', '{case}/scene.yaml', '--out', '{case}/out'], expect, ct=False)
    open(os.path.join(d, 'scene.yaml'), 'w').write(text)
    return d
scene_case('scene_unknown_key', 'body:\nmodel:\n  raduis_mm: 2\n', "unknown key (did you mean 'radius_mm'?)")
scene_case('scene_wrong_type', 'body:\nmodel:\n  radius_mm: two\n', "expected a number, got 'two'")
scene_case('scene_negative_radius', 'body:\nmodel:\n  radius_mm: -1\n', 'out of range')
scene_case('scene_m_not_below_n', 'body:\nmodel:\n  exponent_m: 12\n  exponent_n: 6\n', 'must exceed the attractive m')
scene_case('scene_missing_input', 'ct:\n  folder: no-such-folder\n', 'no such file or folder')
scene_case('scene_out_is_its_folder', 'body:\nmodel:\n', "is the scene's own folder", args=['run', '{case}/scene.yaml', '--out', '{case}'])
scene_case('scene_out_unwritable', 'body:\nmodel:\n', 'cannot create the output folder', args=['run', '{case}/scene.yaml', '--out', '/proc/organfit/out'])
scene_case('scene_unknown_section', 'modle:\n  radius_mm: 2\n', "unknown section (did you mean 'model'?)")
scene_case('scene_yaml_syntax', 'body: [1, 2\nmodel:\n', 'scene.yaml:')
scene_case('scene_missing_required', 'phantom:\norgan:\n  source: rtstruct\n', 'organ.roi')
scene_case('scene_registration_not_rigid', 'body:\nmodel:\npoints:\n  source: ultrasound\nultrasound:\n  source: volume\n  file: scene.yaml\n  registration: [2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n', 'not a rigid transform')
scene_case('scene_export_into_a_folder', 'body:\nmodel:\nexport:\n  mesh: sub/organ.stl\n', 'a file name inside --out')
scene_case('scene_not_a_file', '', 'cannot read the scene file', args=['run', '{case}/missing.yaml', '--out', '{case}/out'])

# --- commands -------------------------------------------------------------------------------
case('segment_seed_outside_ct', ['segment', '--ct', '{case}/ct', '--seed', '0,0,900', '--hu', '20,80', '--out', '{case}/out/m.nrrd'], 'outside the CT')
case('segment_window_inverted', ['segment', '--ct', '{case}/ct', '--seed', '0,0,0', '--hu', '80,20', '--out', '{case}/out/m.nrrd'], 'window is empty')
d = case('export_not_a_model', ['export', '--model', '{case}/model.json', '--mesh', '{case}/out/m.stl'], 'not an organfit model', ct=False)
open(os.path.join(d, 'model.json'), 'w').write('{"format": "something else"}\n')
d = case('synth_into_a_full_folder', ['synth', 'pelvis', '--out', '{case}/full'], 'exists and is not an empty folder', ct=False)
os.makedirs(os.path.join(d, 'full'))
open(os.path.join(d, 'full', 'keep.txt'), 'w').write('mine\n')

# --- tolerated: a warning and a correct result ---------------------------------------------------
d = case('tolerated_stray_files', SEGMENT, 'not DICOM were ignored', code=0)
open(os.path.join(d, 'ct', 'README'), 'w').write('notes\n')
from pydicom.dataset import FileDataset, FileMetaDataset
meta = FileMetaDataset()
meta.MediaStorageSOPClassUID = '1.2.840.10008.1.3.10'  # Media Storage Directory
meta.MediaStorageSOPInstanceUID = '1.2.826.0.1.3680043.2.1125.99.7'
meta.TransferSyntaxUID = '1.2.840.10008.1.2.1'
dicomdir = FileDataset(os.path.join(d, 'ct', 'DICOMDIR'), {}, file_meta=meta, preamble=b'\0' * 128)
dicomdir.FileSetID = 'ORGANFIT'
dicomdir.is_little_endian, dicomdir.is_implicit_VR = True, False
dicomdir.save_as(os.path.join(d, 'ct', 'DICOMDIR'), write_like_original=False)
d = case('tolerated_compressed_slices', SEGMENT, '', code=0)
for name in ct_files:
    p = os.path.join(d, 'ct', name)
    subprocess.run(['gdcmconv', '--rle', p, p], check=True)
if os.path.isdir(os.path.join(data, 'ct-sts-002')):
    case('tolerated_references_by_position', ['segment', '--ct', '{data}/ct-sts-002/ct', '--rtstruct', '{data}/ct-sts-002/rtstruct.dcm',
         '--roi', 'GTV_Mass_CT', '--out', '{case}/out/m.nrrd'], 'matched by position', code=0, ct=False)
shutil.rmtree(base)
print(len([n for n in os.listdir(out) if os.path.isdir(os.path.join(out, n))]), 'cases')
