#!/usr/bin/python3
"""Generates the bad-input corpus: each case a folder with its inputs and case.json
{"args": [...], "code": 2, "expect": "...", "names": "..."}. `{case}` in args is the
case's folder, `{data}` the real data folder. DICOM cases are made from a small pelvis
phantom written by `organfit synth pelvis` and altered with pydicom.

usage: make_corpus.py OUT_DIR ORGANFIT_BINARY SHARED_DATA_DIR
"""
import json, os, shutil, struct, subprocess, sys
import pydicom
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'cli'))
import model_checksum

out, organfit, data = sys.argv[1], sys.argv[2], sys.argv[3]
os.makedirs(out, exist_ok=True)
base = os.path.join(out, '_phantom')
subprocess.run([organfit, '--quiet', 'synth', 'pelvis', '--out', base, '--columns', '64', '--rows', '64',
                '--pixel-mm', '6', '--slices', '12', '--slice-mm', '5'], check=True, stdout=subprocess.DEVNULL)
ct_files = sorted(os.listdir(os.path.join(base, 'ct')))
SEGMENT = ['segment', '--ct', '{case}/ct', '--seed', '0,0,0', '--hu', '20,80', '--out', '{case}/out/mask.nrrd']
IMPORT = ['segment', '--ct', '{case}/ct', '--rtstruct', '{case}/rtstruct.dcm', '--roi', 'Prostate', '--out', '{case}/out/mask.nrrd']

def case(name, args, expect, code=2, names=None, ct=True, rtstruct=False, secrets=(), cls='other'):
    """One case. `secrets`: strings (patient names, IDs) that must appear in no output line;
    `cls`: the class of defect it belongs to (issue 23's list), for the count."""
    d = os.path.join(out, name)
    os.makedirs(d, exist_ok=True)
    if ct:
        shutil.copytree(os.path.join(base, 'ct'), os.path.join(d, 'ct'))
    if rtstruct:
        shutil.copy(os.path.join(base, 'rtstruct.dcm'), os.path.join(d, 'rtstruct.dcm'))
    with open(os.path.join(d, 'case.json'), 'w') as f:
        json.dump({'args': args, 'code': code, 'expect': expect, 'names': names,
                   'secrets': ['Phantom^Pelvis', 'PELVIS-1'] + list(secrets), 'class': cls}, f)
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
# A study's export as a clinic makes it: the planning CT beside a topogram (a localizer, a
# projection: left out), and beside a second axial series 1 m away (a 4D average, a CBCT):
# the one the structure set was drawn on is read; one it does not reference, refused.
d = case('tolerated_localizer_beside_the_ct', SEGMENT, '1 localizer image(s) (scout or topogram', code=0)
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[0]))
ds.SeriesInstanceUID, ds.SOPInstanceUID = '1.2.826.0.1.3680043.2.1125.99.31', '1.2.826.0.1.3680043.2.1125.99.32'
ds.ImageType = ['ORIGINAL', 'PRIMARY', 'LOCALIZER']
ds.ImageOrientationPatient = [1, 0, 0, 0, 0, -1]
ds.save_as(os.path.join(d, 'ct', 'topogram.dcm'))
# A scanner's dose report: a screen capture (Secondary Capture) of Modality CT, its own
# series, without a slice's geometry.
d = case('tolerated_dose_report_beside_the_ct', SEGMENT, '1 object(s) of Modality CT that are not CT images', code=0)
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[0]))
ds.SOPClassUID = ds.file_meta.MediaStorageSOPClassUID = '1.2.840.10008.5.1.4.1.1.7'
ds.SeriesInstanceUID, ds.SOPInstanceUID = '1.2.826.0.1.3680043.2.1125.99.36', '1.2.826.0.1.3680043.2.1125.99.37'
ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
ds.SeriesDescription = 'Dose Report'
for keyword in ['ImagePositionPatient', 'ImageOrientationPatient', 'PixelSpacing', 'SliceThickness']:
    if keyword in ds:
        delattr(ds, keyword)
ds.save_as(os.path.join(d, 'ct', 'dose_report.dcm'))
# A localizer in the CT's own series (some scanners' exports): it had been refused as
# "slices differ in orientation".
d = case('tolerated_localizer_in_the_ct_series', SEGMENT, '1 localizer image(s) (scout or topogram', code=0)
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[0]))
ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID = '1.2.826.0.1.3680043.2.1125.99.38'
ds.ImageType = ['ORIGINAL', 'PRIMARY', 'LOCALIZER']
ds.ImageOrientationPatient = [1, 0, 0, 0, 0, -1]
ds.save_as(os.path.join(d, 'ct', 'scout.dcm'))
def second_series(d):
    for i, name in enumerate(ct_files):
        ds = pydicom.dcmread(os.path.join(d, 'ct', name))
        ds.SeriesInstanceUID = '1.2.826.0.1.3680043.2.1125.99.33'
        ds.SOPInstanceUID = f'1.2.826.0.1.3680043.2.1125.99.34.{i}'
        ds.ImagePositionPatient[2] += 1000  # the structure set's contours lie on none of it
        ds.save_as(os.path.join(d, 'ct', 'b_' + name))
d = case('tolerated_two_series_the_structure_set_chooses', IMPORT, 'read: the series the structure set references, of 2 CT series', code=0, rtstruct=True)
second_series(d)
d = case('ct_two_series_the_structure_set_references_neither', IMPORT, '2 CT series; choose one by Series Instance UID or description (the structure set references none of them)', rtstruct=True)
second_series(d)
rtss = pydicom.dcmread(os.path.join(d, 'rtstruct.dcm'))
for f in rtss.ReferencedFrameOfReferenceSequence:
    for study in f.RTReferencedStudySequence:
        for series in study.RTReferencedSeriesSequence:
            series.SeriesInstanceUID = '1.2.826.0.1.3680043.2.1125.99.35'
rtss.save_as(os.path.join(d, 'rtstruct.dcm'))
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
# A scanner's Enhanced CT: the whole scan in one multi-frame object, its geometry in
# functional groups (no Image Position at the top level): named as what it is.
d = case('ct_enhanced_multi_frame', SEGMENT, 'enhanced.dcm is a multi-frame CT object (Enhanced CT, 12 frames)',
         names='enhanced.dcm')
slices = sorted((pydicom.dcmread(os.path.join(d, 'ct', f)) for f in ct_files),
                key=lambda ds: float(ds.ImagePositionPatient[2]))
ds = slices[0]
ds.SOPClassUID = ds.file_meta.MediaStorageSOPClassUID = '1.2.840.10008.5.1.4.1.1.2.1'
ds.NumberOfFrames = len(slices)
shared, measures, plane = pydicom.Dataset(), pydicom.Dataset(), pydicom.Dataset()
measures.PixelSpacing, measures.SliceThickness = ds.PixelSpacing, ds.SliceThickness
plane.ImageOrientationPatient = ds.ImageOrientationPatient
shared.PixelMeasuresSequence, shared.PlaneOrientationSequence = [measures], [plane]
ds.SharedFunctionalGroupsSequence = [shared]
frames = []
for s in slices:
    frame, position = pydicom.Dataset(), pydicom.Dataset()
    position.ImagePositionPatient = s.ImagePositionPatient
    frame.PlanePositionSequence = [position]
    frames.append(frame)
ds.PerFrameFunctionalGroupsSequence = frames
for t in ('ImagePositionPatient', 'ImageOrientationPatient', 'PixelSpacing', 'SliceThickness'):
    delattr(ds, t)
ds.PixelData = b''.join(s.PixelData for s in slices)
for f in ct_files:
    os.remove(os.path.join(d, 'ct', f))
ds.save_as(os.path.join(d, 'ct', 'enhanced.dcm'))
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

# --- one slice of another scan, or edited: named, never read as if it were the series' -----------
def set_attr(name, value):
    def edit(ds):
        if value is None:
            delattr(ds, name)
        else:
            setattr(ds, name, value)
    return edit
for name, edit, expect in [
        ('another_frame_of_reference', set_attr('FrameOfReferenceUID', '1.2.826.0.1.3680043.2.1125.99.7'),
         "slice CT0004.dcm's Frame of Reference UID is not the other slices'"),
        ('another_study', set_attr('StudyInstanceUID', '1.2.826.0.1.3680043.2.1125.99.8'),
         "slice CT0004.dcm's Study Instance UID is not the other slices'"),
        ('no_sop_instance_uid', set_attr('SOPInstanceUID', ''), 'slice CT0004.dcm has no SOP Instance UID'),
        ('no_rescale_intercept', set_attr('RescaleIntercept', None),
         'slice CT0004.dcm states no Rescale Intercept where the other slices do'),
        ('bits_stored_differ', set_attr('BitsStored', 7), "slice CT0004.dcm's pixels are described otherwise"),
        ('pixel_data_short', lambda ds: setattr(ds, 'PixelData', ds.PixelData[: len(ds.PixelData) // 2]),
         'CT0004.dcm: its pixel data hold 4096 bytes where its 64 x 64 pixels of 2 bytes take 8192'),
        ('pixel_data_long', lambda ds: setattr(ds, 'PixelData', ds.PixelData * 2),
         'CT0004.dcm: its pixel data hold 16384 bytes where'),
        ('rescale_not_ct_numbers', set_attr('RescaleSlope', 1e30), 'CT0004.dcm: its Rescale Slope 1e+30'),
        ]:
    d = case('ct_slice_' + name, SEGMENT, expect, names='CT0004.dcm', cls='disagree')
    edit_ct(d, 3, edit)
d = case('ct_bits_no_dicom_layout', SEGMENT, 'stored 12, high bit 3 and pixel representation 0: not a layout', cls='disagree')
edit_all(d, set_attr('HighBit', 3))

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
def two(ds):
    c = prostate(ds).ContourSequence[0]
    c.ContourData = c.ContourData[:6]
    c.NumberOfContourPoints = 2
# A slice's contours are read by the even-odd rule: a contour exported twice would cancel
# itself out (read once, said); two contours that overlap are refused; one within another is
# a hole.
import copy
def repeat_contour(ds, dx, scale=1.0):
    contours = prostate(ds).ContourSequence
    middle = contours[len(contours) // 2]
    points = [float(v) for v in middle.ContourData]
    centre = [sum(points[a::3]) / (len(points) // 3) for a in range(2)]
    again = copy.deepcopy(middle)
    again.ContourData = [v if i % 3 == 2 else centre[i % 3] + scale * (v - centre[i % 3]) + (dx if i % 3 == 0 else 0)
                         for i, v in enumerate(points)]
    contours.append(again)
d = case('tolerated_contour_exported_twice', IMPORT, 'encloses the same voxels as contour 5 on slice 6', code=0, rtstruct=True, cls='geometry')
edit_rtss(d, lambda ds: repeat_contour(ds, 0.0))
d = case('rtss_contours_overlapping', IMPORT, 'overlap: neither apart nor one within the other', rtstruct=True, cls='geometry')
edit_rtss(d, lambda ds: repeat_contour(ds, 4.0))
d = case('tolerated_contour_with_a_hole', IMPORT, '', code=0, rtstruct=True, cls='geometry')
edit_rtss(d, lambda ds: repeat_contour(ds, 0.0, 0.5))
# CLOSED_PLANAR means every point on the contour's slice, not only their mean (one point
# 1.5 mm off the phantom's 5 mm slices); a slice left out between contoured ones is said.
def lift_one_point(ds):
    c = prostate(ds).ContourSequence[4]
    c.ContourData = [float(v) + 1.5 if i == 2 else float(v) for i, v in enumerate(c.ContourData)]
d = case('rtss_contour_not_planar', IMPORT, 'is not planar: a point of it lies 1.50 mm off that slice', rtstruct=True, cls='geometry')
edit_rtss(d, lift_one_point)
# A contour crossing itself: wound twice around its area (its points gone round again),
# the even-odd rule would read a hole: refused; a figure eight (each lobe wound once) is read.
def wind_twice(ds):
    c = prostate(ds).ContourSequence[4]
    c.ContourData = list(c.ContourData) * 2
    c.NumberOfContourPoints = 2 * int(c.NumberOfContourPoints)
d = case('rtss_contour_wound_twice', IMPORT, 'crosses itself and winds twice around', rtstruct=True, cls='geometry')
edit_rtss(d, wind_twice)
def figure_eight(ds):
    c = prostate(ds).ContourSequence[4]
    z = float(c.ContourData[2])
    c.ContourData = [v for x, y in [(-12, -8), (12, 8), (12, -8), (-12, 8)] for v in (x, y, z)]
    c.NumberOfContourPoints = 4
d = case('tolerated_contour_figure_eight', IMPORT, '', code=0, rtstruct=True, cls='geometry')
edit_rtss(d, figure_eight)
d = case('tolerated_contour_slice_left_out', IMPORT, 'has no contour on 1 slice(s) between its first and last', code=0, rtstruct=True, cls='geometry')
edit_rtss(d, lambda ds: prostate(ds).ContourSequence.__delitem__(4))
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
# A damaged calibration: a region beyond the image, a pixel size a unit off (1e-9 cm: the
# boundary search had stepped by half of it, for minutes and gigabytes), a volume's spacing.
def aloka(d, name, fn):
    ds = pydicom.dcmread(os.path.join(data, 'us-dicom', 'gdcm-US-ALOKA-16.dcm'))
    fn(ds.SequenceOfUltrasoundRegions[0])
    ds.save_as(os.path.join(d, name))
d = case('us_dicom_region_beyond_the_image', ['us-points', '--us', '{case}/us.dcm', '--out', '{case}/out/p.csv'], 'its ultrasound region 1 spans pixels (32, 24) to (65535, 415), not within its 640 x 480 pixels', ct=False, cls='geometry')
aloka(d, 'us.dcm', lambda r: setattr(r, 'RegionLocationMaxX1', 65535))
d = case('us_dicom_pixel_size_not_ultrasound', ['us-points', '--us', '{case}/us.dcm', '--out', '{case}/out/p.csv'], 'not an ultrasound image', ct=False, cls='geometry')
aloka(d, 'us.dcm', lambda r: setattr(r, 'PhysicalDeltaX', 1e-9))
d = case('us_volume_spacing_not_ultrasound', ['us-points', '--us', '{case}/v.mha', '--out', '{case}/out/p.csv'], 'v.mha: its field of view is 0.147 x 0.106 x 0.104 mm: not an ultrasound image', ct=False, cls='geometry')
spine = open(os.path.join(data, 'us-plus', 'SpinePhantomFreehandReconstructed.mha'), 'rb').read()
open(os.path.join(d, 'v.mha'), 'wb').write(spine.replace(b'ElementSpacing = 0.5 0.5 0.5', b'ElementSpacing = 0.001 0.001 0.001', 1))
d = case('us_not_an_image', ['us-points', '--us', '{case}/x.nrrd', '--out', '{case}/out/p.csv'], 'x.nrrd', ct=False)
open(os.path.join(d, 'x.nrrd'), 'w').write('NRRD0004\ntype: garbage\n\n')

# --- point files through a scene ------------------------------------------------------------
def points_case(name, content, expect, cls='points'):
    d = case(name, ['run', '{case}/scene.yaml', '--out', '{case}/out'], expect, ct=False, cls=cls)
    open(os.path.join(d, 'points.csv'), 'w').write(content)
    open(os.path.join(d, 'scene.yaml'), 'w').write('body:\n  size_mm: [20, 16, 12]\nmodel:\n  radius_mm: 1.5\n'
                                                   'points:\n  source: file\n  file: points.csv\nfit:\n  method: spread\n')
points_case('points_nan', 'x,y,z\n1,2,3\n4,nan,6\n', 'points.csv:3: non-finite coordinate')
points_case('points_inf', 'x,y,z\n1,2,inf\n', 'points.csv:2: non-finite coordinate')
points_case('points_text', 'x,y,z\n1,two,3\n', "'two' is not a number")
points_case('points_missing_column', 'x,y,z\n1,2\n', 'expected x,y,z[,confidence], got 2 columns')
points_case('points_bad_confidence', 'x,y,z,c\n1,2,3,1.5\n', 'confidence must be in (0, 1]')
points_case('points_empty', 'x,y,z\n', 'no points')

# Point sets in VTK's formats, damaged: VTK 9.1 read a file cut short without a word (the
# points it lacked as copies or zeros), faulted on a PLY without a 'y', and printed several
# lines on a broken XML file.
def points_file_case(name, file, content, expect, cls='points'):
    d = case(name, ['run', '{case}/scene.yaml', '--out', '{case}/out'], expect, ct=False, cls=cls)
    open(os.path.join(d, file), 'wb').write(content if isinstance(content, bytes) else content.encode())
    open(os.path.join(d, 'scene.yaml'), 'w').write('body:\n  size_mm: [20, 16, 12]\nmodel:\n  radius_mm: 1.5\n'
                                                   'points:\n  source: file\n  file: ' + file + '\nfit:\n  method: spread\n')
PLY_HEADER = 'ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n'
points_file_case('points_ply_cut_short', 'p.ply', PLY_HEADER + '10 0 0\n-10 0 0\n',
                 'p.ply: its header declares 4 vertices, but the file holds 2: cut short or damaged')
points_file_case('points_ply_binary_cut_short', 'p.ply',
                 PLY_HEADER.replace('ascii', 'binary_little_endian').encode() + struct.pack('<7f', 10, 0, 0, -10, 0, 0, 0),
                 'p.ply: its header declares 4 vertices (48 bytes of data), but the file holds 28 bytes after its header: cut short or damaged')
points_file_case('points_ply_value_not_a_number', 'p.ply', PLY_HEADER + '10 0 0\n-10 0 0\n0 8-1 0\n0 0 7\n',
                 "p.ply:10: '8-1' is not a number: damaged")
points_file_case('points_ply_no_y', 'p.ply', PLY_HEADER.replace('property float y', 'property double x') + '10 0 0\n-10 0 0\n0 8 0\n0 0 7\n',
                 "p.ply: header: element vertex has two properties 'x'")
points_file_case('points_vtk_cut_short', 'p.vtk', '# vtk DataFile Version 3.0\np\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n10 0 0 -10 0 0 0 8\n',
                 'p.vtk: POINTS declares 3 points (9 values), but the file holds 8 values: cut short or damaged')
points_file_case('points_vtp_broken_xml', 'p.vtp', '<?xml version="1.0"?>\n<VTKFile type="PolyData"><garbage',
                 'p.vtp: no points (or not readable)')

# --- scene files ------------------------------------------------------------------------------
def scene_case(name, text, expect, args=None, cls='scenes'):
    d = case(name, args or ['run', '{case}/scene.yaml', '--out', '{case}/out'], expect, ct=False, cls=cls)
    open(os.path.join(d, 'scene.yaml'), 'w').write(text)
    return d
scene_case('scene_unknown_key', 'body:\nmodel:\n  raduis_mm: 2\n', "unknown key (did you mean 'radius_mm'?)")
scene_case('scene_method_key_one_level_up', 'body:\nmodel:\npoints:\nfit:\n  max_global_stretch: 2\n', "fit.max_global_stretch: unknown key (did you mean 'fit.spread.max_global_stretch'?)")
scene_case('scene_wrong_type', 'body:\nmodel:\n  radius_mm: two\n', "expected a number, got 'two'")
scene_case('scene_negative_radius', 'body:\nmodel:\n  radius_mm: -1\n', 'out of range')
# A radius in the wrong unit (0.01 mm for 1 cm): hundreds of millions of particles, refused
# before the fill (which had run for minutes into gigabytes).
scene_case('scene_radius_beyond_a_models_particles', 'body:\nmodel:\n  radius_mm: 0.01\n', 'scene.yaml:3: model.radius_mm: a radius of 0.01 mm fills this organ with about')
scene_case('scene_m_not_below_n', 'body:\nmodel:\n  exponent_m: 12\n  exponent_n: 6\n', 'must exceed the attractive m')
scene_case('scene_missing_input', 'ct:\n  folder: no-such-folder\n', 'no such file or folder')
scene_case('scene_out_is_its_folder', 'body:\nmodel:\n', "--out is the folder of input", args=['run', '{case}/scene.yaml', '--out', '{case}'])
scene_case('scene_out_unwritable', 'body:\nmodel:\n', 'cannot create the output folder', args=['run', '{case}/scene.yaml', '--out', '/proc/organfit/out'])
scene_case('scene_unknown_section', 'modle:\n  radius_mm: 2\n', "unknown section (did you mean 'model'?)")
scene_case('scene_yaml_syntax', 'body: [1, 2\nmodel:\n', 'scene.yaml:')
scene_case('scene_indented_with_a_tab', 'body:\nmodel:\n\tradius_mm: 2\n', 'scene.yaml:3: YAML syntax error: this line is indented with a tab')
scene_case('scene_missing_required', 'phantom:\norgan:\n  source: rtstruct\n', 'organ.roi')
scene_case('scene_registration_not_rigid', 'body:\nmodel:\npoints:\n  source: ultrasound\nultrasound:\n  source: volume\n  file: scene.yaml\n  registration: [2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n', 'not a rigid transform')
scene_case('scene_export_into_a_folder', 'body:\nmodel:\nexport:\n  mesh: sub/organ.stl\n', 'a file name inside --out')
scene_case('scene_output_named_as_the_run_record', 'body:\nmodel:\nexport:\n  model: run.json\n', "export.model: 'run.json' is already the run's record's name in --out")
scene_case('scene_output_named_twice', 'body:\nmodel:\nexport:\n  mesh: organ.stl\nreport:\n  file: organ.stl\n', "report.file: 'organ.stl' is already export.mesh's name in --out")
scene_case('scene_second_document', 'body:\nmodel:\n---\nexport:\n  mesh: organ.stl\n', 'scene.yaml:4: a second YAML document')
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

# --- inputs that disagree with each other ---------------------------------------------------
d = case('rtss_other_patient', IMPORT, 'its Patient ID differs from the CT', rtstruct=True, secrets=['OTHER-77'], cls='disagree')
edit_rtss(d, lambda ds: setattr(ds, 'PatientID', 'OTHER-77'))
d = case('rtss_other_study', IMPORT, 'its Study Instance UID differs from the CT', rtstruct=True, cls='disagree')
edit_rtss(d, lambda ds: setattr(ds, 'StudyInstanceUID', '1.2.826.0.1.3680043.2.1125.99.11'))
def no_frame(ds, keep_references):
    for r in ds.StructureSetROISequence:
        del r.ReferencedFrameOfReferenceUID
    del ds.ReferencedFrameOfReferenceSequence
    if not keep_references:
        for c in prostate(ds).ContourSequence:
            del c.ContourImageSequence
d = case('rtss_no_frame_of_reference', IMPORT, 'names no Frame of Reference', rtstruct=True, cls='disagree')
edit_rtss(d, lambda ds: no_frame(ds, False))
d = case('tolerated_no_frame_of_reference_but_references', IMPORT, '', code=0, rtstruct=True, cls='disagree')
edit_rtss(d, lambda ds: no_frame(ds, True))
d = case('ct_two_files_one_sop_instance', SEGMENT, 'have the same SOP Instance UID', cls='disagree')
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[3]))
ds.ImagePositionPatient = [ds.ImagePositionPatient[0], ds.ImagePositionPatient[1], 400.0]
ds.save_as(os.path.join(d, 'ct', 'zz_copy.dcm'))
def rename_bladder(ds):
    next(r for r in ds.StructureSetROISequence if r.ROIName == 'Bladder').ROIName = 'Prostate'
d = case('rtss_two_rois_one_name', IMPORT, "2 ROIs are named 'Prostate' (ROI numbers 2, 4)", rtstruct=True, cls='disagree')
edit_rtss(d, rename_bladder)
d = case('tolerated_roi_number_chooses', IMPORT[:-2] + ['--roi-number', '4', '--out', '{case}/out/mask.nrrd'], '', code=0, rtstruct=True, cls='disagree')
edit_rtss(d, rename_bladder)
d = case('rtss_roi_number_not_that_name', IMPORT[:-2] + ['--roi-number', '2', '--out', '{case}/out/mask.nrrd'], "ROI number 2 is named 'Bladder', not 'Prostate'", rtstruct=True, cls='disagree')

# --- folders read completely or not at all ------------------------------------------------------
d = case('tolerated_fifo_in_ct_folder', SEGMENT, '1 entry that are not regular files', code=0, cls='folders')
os.mkfifo(os.path.join(d, 'ct', 'pipe'))
d = case('tolerated_dangling_link_in_ct_folder', SEGMENT, '1 entry that are not regular files', code=0, cls='folders')
os.symlink('no-such-file.dcm', os.path.join(d, 'ct', 'gone.dcm'))
d = case('tolerated_looping_links_in_ct_folder', SEGMENT, '2 entries that are not regular files', code=0, cls='folders')
os.symlink('b.dcm', os.path.join(d, 'ct', 'a.dcm'))
os.symlink('a.dcm', os.path.join(d, 'ct', 'b.dcm'))
d = case('tolerated_subfolder_and_socket', SEGMENT, '2 entries that are not regular files', code=0, cls='folders')
os.makedirs(os.path.join(d, 'ct', 'sub'))
import socket
sock = socket.socket(socket.AF_UNIX)
sock.bind(os.path.join(d, 'ct', 'sock'))
sock.close()
d = case('ct_dcm_file_that_is_not_dicom', SEGMENT, 'junk.dcm: a truncated or corrupt DICOM file', cls='folders')
open(os.path.join(d, 'ct', 'junk.dcm'), 'w').write('this is not DICOM at all\n' * 20)
d = case('ct_dicm_marker_then_garbage', SEGMENT, 'bad: a truncated or corrupt DICOM file', cls='folders')
open(os.path.join(d, 'ct', 'bad'), 'wb').write(b'\0' * 128 + b'DICM' + b'\xff' * 300)

# --- geometry is never invented ---------------------------------------------------------------
def one_slice(d, keep):
    for n in ct_files[1:]:
        os.remove(os.path.join(d, 'ct', n))
    def strip(ds):
        if 'SpacingBetweenSlices' in ds: del ds.SpacingBetweenSlices
        if not keep: del ds.SliceThickness
    edit_ct(d, 0, strip)
d = case('ct_one_slice_without_thickness', SEGMENT, 'states neither Spacing Between Slices nor Slice Thickness', cls='geometry')
one_slice(d, False)
d = case('tolerated_one_slice_with_thickness', ['segment', '--ct', '{case}/ct', '--seed', '0,0,-27.5', '--hu', '-2000,4000', '--search-box', '0', '--out', '{case}/out/mask.nrrd'], '', code=0, cls='geometry')
one_slice(d, True)
d = case('rtss_contour_value_count', IMPORT, 'not 3 x Number of Contour Points', rtstruct=True, cls='geometry')
edit_rtss(d, lambda ds: setattr(prostate(ds).ContourSequence[0], 'NumberOfContourPoints', 9))
d = case('rtss_contour_off_its_slice', IMPORT, 'lies on no slice of the CT', rtstruct=True, cls='geometry')
def off(ds):
    c = prostate(ds).ContourSequence[0]
    c.ContourData = [v + 2.0 if i % 3 == 2 else v for i, v in enumerate(c.ContourData)]
edit_rtss(d, off)
d = case('ct_odd_slice_is_named', SEGMENT, 'slice CT0007.dcm lies at', cls='geometry')
edit_ct(d, 6, lambda ds: setattr(ds, 'ImagePositionPatient', [ds.ImagePositionPatient[0], ds.ImagePositionPatient[1], float(ds.ImagePositionPatient[2]) + 1.5]))
d = case('ct_odd_size_is_named', SEGMENT, 'slice CT0003.dcm is 64 x 32 pixels', cls='geometry')
ds = pydicom.dcmread(os.path.join(d, 'ct', ct_files[2]))
ds.Rows = 32
ds.PixelData = ds.PixelData[: 32 * 64 * 2]
ds.save_as(os.path.join(d, 'ct', ct_files[2]))
d = case('tolerated_two_point_contour', IMPORT, 'has 2 point(s), fewer than 3: skipped', code=0, rtstruct=True, cls='geometry')
edit_rtss(d, two)
d = case('tolerated_zero_area_contour', IMPORT, 'has zero area: skipped', code=0, rtstruct=True, cls='geometry')
def flat(ds):
    c = prostate(ds).ContourSequence[1]
    xyz = list(c.ContourData)
    c.ContourData = [xyz[0], xyz[1], xyz[2], xyz[0] + 5, xyz[1], xyz[2], xyz[0] + 10, xyz[1], xyz[2]]
    c.NumberOfContourPoints = 3
edit_rtss(d, flat)

# --- every legal encoding is read -----------------------------------------------------------------
for name, flag in [('jpegls', '--jpegls'), ('jpeg2000', '--j2k'), ('jpeg_lossless', '--jpeg'), ('big_endian', None), ('deflated', None)]:
    d = case('tolerated_ct_' + name, SEGMENT, '', code=0, cls='encodings')
    for n in ct_files:
        p = os.path.join(d, 'ct', n)
        if flag:
            subprocess.run(['gdcmconv', flag, p, p], check=True)
        else:
            ds = pydicom.dcmread(p)
            if name == 'big_endian':
                ds.file_meta.TransferSyntaxUID = pydicom.uid.ExplicitVRBigEndian
                ds.is_little_endian, ds.is_implicit_VR = False, False
                swapped = bytearray(ds.PixelData)  # 16-bit words, most significant byte first
                swapped[0::2], swapped[1::2] = ds.PixelData[1::2], ds.PixelData[0::2]
                ds.PixelData = bytes(swapped)
            else:
                ds.file_meta.TransferSyntaxUID = pydicom.uid.DeflatedExplicitVRLittleEndian
                ds.is_little_endian, ds.is_implicit_VR = True, False
            ds.save_as(p, write_like_original=False)
d = case('tolerated_rtss_deflated', IMPORT, '', code=0, rtstruct=True, cls='encodings')
def deflate(ds):
    ds.file_meta.TransferSyntaxUID = pydicom.uid.DeflatedExplicitVRLittleEndian
edit_rtss(d, deflate)
def private_sequence(ds):
    block = ds.private_block(0x0071, 'ORGANFIT TEST', create=True)
    item = pydicom.Dataset()
    item.add_new(0x00711001, 'LO', 'inside')
    block.add_new(0x02, 'SQ', [item])
d = case('tolerated_rtss_un_sequence', IMPORT, '', code=0, rtstruct=True, cls='encodings')
edit_rtss(d, private_sequence)
p = os.path.join(d, 'rtstruct.dcm')
ds = pydicom.dcmread(p)
ds.file_meta.TransferSyntaxUID = pydicom.uid.ImplicitVRLittleEndian
ds.is_implicit_VR = True
ds.save_as(p, write_like_original=False)
subprocess.run(['gdcmconv', '--explicit', p, p], check=True)  # the private sequence becomes UN, undefined length
d = case('tolerated_ct_un_sequences', SEGMENT, '', code=0, cls='encodings')
for n in ct_files:
    p = os.path.join(d, 'ct', n)
    ds = pydicom.dcmread(p)
    private_sequence(ds)
    ds.file_meta.TransferSyntaxUID = pydicom.uid.ImplicitVRLittleEndian
    ds.is_implicit_VR = True
    ds.save_as(p, write_like_original=False)
    subprocess.run(['gdcmconv', '--explicit', p, p], check=True)

# --- output folders are safe ---------------------------------------------------------------------
BODY_SCENE = 'body:\n  size_mm: [20, 16, 12]\nmodel:\n  radius_mm: 2\n'
def out_case(name, out_arg, expect, extra=None, ct=False):
    d = case(name, ['run', '{case}/scene.yaml', '--out', out_arg], expect, ct=ct, cls='outputs')
    open(os.path.join(d, 'scene.yaml'), 'w').write(extra or BODY_SCENE)
    return d
out_case('out_is_root', '/', '--out is the root folder')
out_case('out_is_tmp', '/tmp', '--out is a top-level system folder')
out_case('out_is_etc', '/etc', '--out is a top-level system folder')
out_case('out_is_home', os.environ.get('HOME', '/root'), '--out is')
CT_SCENE = 'ct:\n  folder: ct\norgan:\n  source: seed\n  roi: organ\n  seed_mm: [0, 0, 0]\nmodel:\n  radius_mm: 4\n'
out_case('out_is_the_ct_folder', '{case}/ct', '--out is the folder of input', CT_SCENE, ct=True)
out_case('out_inside_the_ct_folder', '{case}/ct/out', '--out is inside input folder', CT_SCENE, ct=True)
d = case('out_parent_of_the_points', ['run', '{case}/in/scene.yaml', '--out', '{case}'], '--out is a parent of the folder of input', ct=False, cls='outputs')
os.makedirs(os.path.join(d, 'in'))
open(os.path.join(d, 'in', 'points.csv'), 'w').write('1,2,3\n4,5,6\n7,8,9\n')
open(os.path.join(d, 'in', 'scene.yaml'), 'w').write(BODY_SCENE + 'points:\n  source: file\n  file: points.csv\n')
d = out_case('out_phantom_folder_holds_foreign_files', '{case}/out', 'phantom: exists and was not written by organfit', 'phantom:\n  columns: 64\n  rows: 64\n  slices: 12\n  pixel_mm: 6\n  slice_mm: 5\n')
os.makedirs(os.path.join(d, 'out', 'phantom'))
open(os.path.join(d, 'out', 'phantom', 'my_notes.txt'), 'w').write('mine\n')
d = out_case('out_foreign_file_of_an_output_name', '{case}/out', 'run.json: exists and was not written by organfit')
os.makedirs(os.path.join(d, 'out'))
open(os.path.join(d, 'out', 'run.json'), 'w').write('{"mine": true}\n')
case('segment_out_into_the_ct_folder', ['segment', '--ct', '{case}/ct', '--seed', '0,0,0', '--hu', '20,80', '--out', '{case}/ct/mask.nrrd'], '--out is the folder of input', cls='outputs')
d = case('us_points_out_beside_its_input', ['us-points', '--us', '{case}/us/v.mha', '--out', '{case}/us/points.csv'], '--out is the folder of input', ct=False, cls='outputs')
os.makedirs(os.path.join(d, 'us'))
open(os.path.join(d, 'us', 'v.mha'), 'w').write('ObjectType = Image\n')
case('synth_into_root', ['synth', 'pelvis', '--out', '/'], 'exists and is not an empty folder', ct=False, cls='outputs')

# --- point files as users write them ----------------------------------------------------------------
points_case('points_beyond_ten_metres', 'x,y,z\n1,2,3\n1,2,15000\n', 'points.csv:3: coordinate 15000 mm lies beyond 10 m')
points_case('points_in_microns', 'x;y;z\n12500;-3000;800\n', 'points.csv:2: coordinate 12500 mm lies beyond 10 m')
points_case('points_too_many', 'x,y,z\n' + '1,2,3\n' * 100001, 'more than 100000 points')
points_case('points_binary', 'x,y,z\n1,2,3\n\0\0\0\0', 'not a text file')
points_case('points_text_in_a_later_row', 'x,y,z\n1,2,3\n4,five,6\n', "points.csv:3: 'five' is not a number")
def tolerated_points(name, content):
    d = case(name, ['validate', '{case}/scene.yaml'], '', code=0, ct=False, cls='points')
    open(os.path.join(d, 'points.csv'), 'wb').write(content)
    open(os.path.join(d, 'scene.yaml'), 'w').write(BODY_SCENE + 'points:\n  source: file\n  file: points.csv\nfit:\n  method: spread\n')
tolerated_points('tolerated_points_utf16_excel', 'x\ty\tz\r\n1,5\t2\t3\r\n4\t5,5\t6\r\n'.encode('utf-16'))
tolerated_points('tolerated_points_semicolon_decimal_comma', 'x;y;z;confidence\r\n1,5;2;3;0,9\r\n'.encode())
tolerated_points('tolerated_points_bom_crlf', '\ufeffx,y,z\r\n1.5,2,3\r\n'.encode('utf-8'))
tolerated_points('tolerated_points_old_mac_lines', '1 2 3\r4 5 6\r'.encode())

# --- keys the run would ignore -------------------------------------------------------------------------
scene_case('scene_points_file_with_generate', BODY_SCENE + 'points:\n  file: scene.yaml\n', "points.file: not used when points.source is 'generate'", cls='ignored_keys')
scene_case('scene_tracker_with_a_volume', BODY_SCENE + 'points:\n  source: ultrasound\nultrasound:\n  source: volume\n  file: scene.yaml\n  tracker: scene.yaml\n', "ultrasound.tracker: not used when ultrasound.source is 'volume'", cls='ignored_keys')
scene_case('scene_paper_key_with_spread', BODY_SCENE + 'points:\nfit:\n  method: spread\n  paper:\n    alpha: 3\n', "fit.paper.alpha: not used when fit.method is 'spread'", cls='ignored_keys')
# A global basis finer than a millimetre (a unit slip: fields of 0.02 mm took 96 s and 10 GB
# on the default scene, a flow of 0.05 mm 12 GB): refused at the key.
scene_case('scene_global_flow_finer_than_a_millimetre', BODY_SCENE + 'points:\nfit:\n  method: spread\n  spread:\n    global_flow_mm: 0.05\n', "fit.spread.global_flow_mm: 0.05 mm is finer than the global map resolves")
scene_case('scene_spread_key_with_paper', BODY_SCENE + 'points:\nfit:\n  method: paper\n  spread:\n    global_shear_field_mm: 5\n', "fit.spread.global_shear_field_mm: not used when fit.method is 'paper'", cls='ignored_keys')
scene_case('scene_paper_section_with_spread', BODY_SCENE + 'points:\nfit:\n  paper:\n', "fit.paper: not used when fit.method is 'spread'", cls='ignored_keys')
scene_case('scene_seed_key_with_rtstruct', 'phantom:\norgan:\n  roi: Prostate\n  hu_low: 10\n', "organ.hu_low: not used when organ.source is 'rtstruct'", cls='ignored_keys')
scene_case('scene_stretch_with_a_real_volume', BODY_SCENE + 'points:\n  source: ultrasound\n  stretch: 1.1\nultrasound:\n  source: volume\n  file: scene.yaml\n', "points.stretch: not used when ultrasound.source is 'volume'", cls='ignored_keys')
scene_case('scene_noise_with_points_from_a_file', BODY_SCENE + 'points:\n  source: file\n  file: scene.yaml\n  noise_mm: 1\n', "points.noise_mm: not used when points.source is 'file'", cls='ignored_keys')

# --- messages are bounded ------------------------------------------------------------------------------
scene_case('scene_very_long_enum_value', BODY_SCENE + 'fit:\n  method: ' + 'x' * 5000 + '\n', "fit.method: '" + 'x' * 80 + "...' is not one of", cls='messages')
scene_case('scene_very_long_key', BODY_SCENE.replace('radius_mm', 'r' * 1000), 'unknown key', cls='messages')
points_case('points_very_long_cell', 'x,y,z\n1,2,' + '7' * 50 + 'z' * 5000 + '\n', "' is not a number", cls='messages')
case('segment_very_long_roi_name', IMPORT[:-3] + ['R' * 4000, '--out', '{case}/out/mask.nrrd'], "no ROI named '" + 'R' * 80 + "...'", rtstruct=True, cls='messages')

# --- a planning model and the CT a session names -------------------------------------------------------
def shared_run(name, scene):
    """A run several cases read (a planning model, a fitted one): OUT/NAME/out from `scene`."""
    folder = os.path.join(out, name)
    os.makedirs(folder)
    open(os.path.join(folder, 'scene.yaml'), 'w').write(scene)
    subprocess.run([organfit, '--quiet', 'run', os.path.join(folder, 'scene.yaml'), '--out', os.path.join(folder, 'out')],
                   check=True, stdout=subprocess.DEVNULL)
    return folder
planning = shared_run('_planning',
    'phantom:\n  columns: 64\n  rows: 64\n  slices: 12\n  pixel_mm: 6\n  slice_mm: 5\n'
    'organ:\n  roi: Prostate\nmodel:\n  radius_mm: 3\nexport:\n  model: model.json\n')
SESSION = 'planning:\n  model: ../_planning/out/model.json\nct:\n  folder: ct\npoints:\n  count: 20\nfit:\n  method: spread\n'
def other_series(ds):
    ds.SeriesInstanceUID = '1.2.826.0.1.3680043.2.1125.99.21'
d = case('session_ct_of_another_series', ['--quiet', 'run', '{case}/scene.yaml', '--out', '{case}/out'], 'the planning model was built on another CT series', cls='disagree')
edit_all(d, other_series)
open(os.path.join(d, 'scene.yaml'), 'w').write(SESSION)
d = case('tolerated_session_ct_of_the_model', ['run', '{case}/scene.yaml', '--out', '{case}/out'], '', code=0, cls='disagree')
open(os.path.join(d, 'scene.yaml'), 'w').write(SESSION)
# The model's CT folder holding a second series too (a 4D average beside the planning CT):
# the model's is read, by a session and by an export alike.
d = case('tolerated_session_ct_folder_of_two_series', ['run', '{case}/scene.yaml', '--out', '{case}/out'], 'read: the series the planning model references, of 2 CT series', code=0, cls='disagree')
second_series(d)
open(os.path.join(d, 'scene.yaml'), 'w').write(SESSION)
d = case('tolerated_export_ct_folder_of_two_series', ['export', '--model', '{case}/../_planning/out/model.json', '--ct', '{case}/ct', '--labels', '{case}/out/l.nrrd'], 'read: the series the model references, of 2 CT series', code=0, cls='disagree')
second_series(d)
d = case('export_ct_of_another_series', ['export', '--model', '{case}/../_planning/out/model.json', '--ct', '{case}/ct', '--labels', '{case}/out/l.nrrd'], 'is not the model', cls='disagree')
edit_all(d, other_series)
planned_ct = json.load(open(os.path.join(planning, 'out', 'model.json')))['ct']
# A model of a body (no CT): a session exporting on the CT's grid is refused before its fit.
shared_run('_planning_body', BODY_SCENE + 'export:\n  model: model.json\n')
for key in ['labels: l.nrrd', 'uncertainty: s.nrrd']:
    scene_case('session_export_on_the_ct_of_a_body_model_' + key.split(':')[0],
               'planning:\n  model: ../_planning_body/out/model.json\npoints:\n  count: 20\nfit:\n  method: spread\nexport:\n  ' + key + '\n',
               'model.json: the model has no planning CT to export on', cls='disagree')
# A fitted model's uncertainty: asked of a planning model, or one that does not hold together
# (a residual short of its points), refused before anything is written.
fitted = shared_run('_fitted',
    'planning:\n  model: ../_planning_body/out/model.json\npoints:\n  count: 20\nfit:\n  method: spread\n'
    'export:\n  model: fitted.json\n')
case('export_roi_name_not_a_dicom_lo',
     ['export', '--model', '{case}/../_planning/out/model.json', '--rtstruct', '{case}/out/f.dcm', '--roi-name', 'P' * 65],
     '--roi-name: a ROI Name is at most 64 characters', ct=False)
case('export_registration_grid_beyond_dicom',
     ['export', '--model', '{case}/../_planning/out/model.json', '--registration', '{case}/out/reg.dcm', '--field-spacing', '0.25'],
     'is more than a DICOM registration\'s Vector Grid Data holds', ct=False)
# A field's grid no machine holds (26 TB of floats): refused naming the key, not as a run
# out of memory.
case('export_field_grid_beyond_memory',
     ['export', '--model', '{case}/../_planning/out/model.json', '--displacement-field', '{case}/out/f.mha', '--field-spacing', '0.02'],
     'is more than this run\'s memory holds: choose a coarser export.field_spacing_mm', ct=False)
case('export_two_outputs_one_file',
     ['export', '--model', '{case}/../_planning/out/model.json', '--labels', '{case}/out/x.nrrd', '--jacobian', '{case}/out/x.nrrd'],
     'named by both --labels and --jacobian', ct=False)
case('export_uncertainty_of_a_planning_model',
     ['export', '--model', '{case}/../_planning_body/out/model.json', '--uncertainty', '{case}/out/s.nrrd'],
     "model.json: the model holds no fit's uncertainty", ct=False, cls='disagree')
d = case('export_model_uncertainty_a_residual_short',
         ['export', '--model', '{case}/fitted.json', '--mesh', '{case}/out/m.vtp'],
         'fitted.json: invalid model: uncertainty: SurfaceUncertainty: one residual per point', ct=False)
model = json.load(open(os.path.join(fitted, 'out', 'fitted.json')))
model['uncertainty']['residuals_mm'].pop()
model_checksum.write_model(model, os.path.join(d, 'fitted.json'))
# A model changed after organfit wrote it, still valid JSON and a plausible model (a digit of
# a position; the organ's mask moved by 3 mm): refused by its checksum, by a session and by
# an export alike.
planned_text = open(os.path.join(planning, 'out', 'model.json')).read()
at = planned_text.index('"positions_mm":[') + len('"positions_mm":[') + 1
changed_digit = planned_text[:at] + ('2' if planned_text[at] == '1' else '1') + planned_text[at + 1:]
moved = json.loads(planned_text)
moved.pop('checksum')
moved['shape']['mask']['origin_mm'][0] += 3
moved_mask = json.dumps(moved, separators=(',', ':'))[:-1] + planned_text[planned_text.rindex(',"checksum":"'):]
for name, text in [('digit', changed_digit), ('mask_moved', moved_mask)]:
    d = case('session_model_changed_after_writing_' + name, ['--quiet', 'run', '{case}/scene.yaml', '--out', '{case}/out'],
             'model.json: the file was changed or damaged after organfit wrote it', ct=False, cls='disagree')
    open(os.path.join(d, 'model.json'), 'w').write(text)
    open(os.path.join(d, 'scene.yaml'), 'w').write(SESSION.replace('../_planning/out/model.json', 'model.json').replace('ct:\n  folder: ct\n', ''))
    d = case('export_model_changed_after_writing_' + name, ['export', '--model', '{case}/model.json', '--mesh', '{case}/out/m.stl'],
             'model.json: the file was changed or damaged after organfit wrote it', ct=False, cls='disagree')
    open(os.path.join(d, 'model.json'), 'w').write(text)
def points_in_ct(name, series, frame, expect, code=2):
    d = case(name, ['--quiet', 'run', '{case}/scene.yaml', '--out', '{case}/out'], expect, code=code, ct=False, cls='disagree')
    open(os.path.join(d, 'points.csv'), 'w').write(
        f'# series_instance_uid: {series}\n# frame_of_reference_uid: {frame}\nx,y,z\n'
        '0,0,10\n0,10,0\n10,0,0\n0,0,-10\n0,-10,0\n-10,0,0\n')
    open(os.path.join(d, 'scene.yaml'), 'w').write(
        'planning:\n  model: ../_planning/out/model.json\npoints:\n  source: file\n  file: points.csv\n')
points_in_ct('points_declared_in_another_series', '1.2.826.0.1.3680043.2.1125.99.31', planned_ct['frame_of_reference_uid'],
             "its Series Instance UID is not the planning CT's")
points_in_ct('points_declared_in_another_frame', planned_ct['series_instance_uid'], '1.2.826.0.1.3680043.2.1125.99.32',
             "its Frame of Reference UID is not the planning CT's")
# A binary PLY declares no CT: its points are taken as they are, not read as text.
d = case('tolerated_binary_ply_points_in_a_session', ['--quiet', 'run', '{case}/scene.yaml', '--out', '{case}/out'], '', code=0, ct=False, cls='points')
import struct
open(os.path.join(d, 'points.ply'), 'wb').write(
    b'ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n'
    b'property float z\nend_header\n' + b''.join(struct.pack('<fff', *p) for p in [(0, 0, 10), (0, 10, 0), (10, 0, 0), (0, 0, -10)]))
open(os.path.join(d, 'scene.yaml'), 'w').write(
    'planning:\n  model: ../_planning/out/model.json\npoints:\n  source: file\n  file: points.ply\n')
points_in_ct('tolerated_points_declared_in_their_ct', planned_ct['series_instance_uid'], planned_ct['frame_of_reference_uid'], '', code=0)
shutil.rmtree(base)
print(len([n for n in os.listdir(out) if os.path.isdir(os.path.join(out, n))]), 'cases')
