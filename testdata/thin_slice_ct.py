#!/usr/bin/python3
"""A thin-slice copy of a CT series, and a lung-sized organ's structure set on it.

Planning CTs of the lung and the liver are often cut at 0.5 to 1.5 mm; the CTs in
../shared/data are cut at 3.27 and 5 mm. This writes OUT/ct/ (the series re-sliced at
--slice-mm by linear interpolation between its slices, new Series and SOP Instance UIDs,
the same Frame of Reference) and OUT/rtstruct.dcm (one ROI 'lung_like': an ellipsoid of
--axes-mm semi-axes about --centre-mm, one 120-point contour per slice), for timing the
planning of a large organ on many thin slices (docs/decisions.md):

  testdata/thin_slice_ct.py ../shared/data/ct-crlm-1004/ct /tmp/thin
  organfit run SCENE (ct.folder: /tmp/thin/ct, organ.rtstruct: /tmp/thin/rtstruct.dcm,
                      organ.roi: lung_like, model.radius_mm: 2)

Needs python3-pydicom and numpy. Nothing is written into the input's folder.
"""
import argparse
import copy
import glob
import os

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileDataset, FileMetaDataset
from pydicom.uid import ExplicitVRLittleEndian, generate_uid


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('ct', help='folder of one axial CT series')
    ap.add_argument('out', help='folder to write (created; must not exist)')
    ap.add_argument('--slice-mm', type=float, default=0.5)
    ap.add_argument('--centre-mm', type=float, nargs=3, default=[-60.0, -20.0, -275.0])
    ap.add_argument('--axes-mm', type=float, nargs=3, default=[125.0, 57.5, 82.5])
    a = ap.parse_args()
    os.makedirs(os.path.join(a.out, 'ct'))
    slices = [pydicom.dcmread(f) for f in glob.glob(os.path.join(a.ct, '*'))]
    slices = [d for d in slices if getattr(d, 'Modality', '') == 'CT' and 'PixelData' in d]
    slices.sort(key=lambda d: float(d.ImagePositionPatient[2]))
    z = np.array([float(d.ImagePositionPatient[2]) for d in slices])
    pixels = np.stack([d.pixel_array.astype(np.float32) for d in slices])
    count = int(round((z[-1] - z[0]) / a.slice_mm)) + 1
    series = generate_uid()
    template = slices[0]
    written = []
    for k in range(count):
        zk = z[0] + k * a.slice_mm
        i = min(int(np.searchsorted(z, zk, side='right')) - 1, len(z) - 2)
        t = (zk - z[i]) / (z[i + 1] - z[i])
        image = ((1 - t) * pixels[i] + t * pixels[i + 1]).round()
        d = copy.deepcopy(template)
        d.ImagePositionPatient = [template.ImagePositionPatient[0],
                                  template.ImagePositionPatient[1], float(zk)]
        d.SliceLocation = float(zk)
        d.SliceThickness = a.slice_mm
        d.InstanceNumber = k + 1
        d.SeriesInstanceUID = series
        d.SOPInstanceUID = generate_uid()
        d.file_meta.MediaStorageSOPInstanceUID = d.SOPInstanceUID
        d.PixelData = image.astype(template.pixel_array.dtype).tobytes()
        d.save_as(os.path.join(a.out, 'ct', 'CT%04d.dcm' % k))
        written.append((zk, d.SOPInstanceUID))

    # The structure set: one closed planar contour per slice the ellipsoid cuts.
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = '1.2.840.10008.5.1.4.1.1.481.3'
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    rs = FileDataset(None, {}, file_meta=meta, preamble=b'\0' * 128)
    for key in ('PatientName', 'PatientID', 'PatientBirthDate', 'PatientSex', 'StudyInstanceUID',
                'StudyDate', 'StudyTime', 'StudyID', 'AccessionNumber',
                'ReferringPhysicianName', 'FrameOfReferenceUID'):
        if key in template:
            setattr(rs, key, getattr(template, key))
    rs.SOPClassUID = meta.MediaStorageSOPClassUID
    rs.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    rs.Modality = 'RTSTRUCT'
    rs.SeriesInstanceUID = generate_uid()
    rs.SeriesNumber = 99
    rs.InstanceNumber = 1
    rs.StructureSetLabel = 'thin'
    rs.StructureSetDate, rs.StructureSetTime = template.get('StudyDate', ''), ''
    frame = Dataset()
    frame.FrameOfReferenceUID = template.FrameOfReferenceUID
    study = Dataset()
    study.ReferencedSOPClassUID = '1.2.840.10008.3.1.2.3.1'
    study.ReferencedSOPInstanceUID = template.StudyInstanceUID
    series_item = Dataset()
    series_item.SeriesInstanceUID = series
    images = []
    for _, uid in written:
        im = Dataset()
        im.ReferencedSOPClassUID = template.SOPClassUID
        im.ReferencedSOPInstanceUID = uid
        images.append(im)
    series_item.ContourImageSequence = images
    study.RTReferencedSeriesSequence = [series_item]
    frame.RTReferencedStudySequence = [study]
    rs.ReferencedFrameOfReferenceSequence = [frame]
    roi = Dataset()
    roi.ROINumber = 1
    roi.ReferencedFrameOfReferenceUID = template.FrameOfReferenceUID
    roi.ROIName = 'lung_like'
    roi.ROIGenerationAlgorithm = 'MANUAL'
    rs.StructureSetROISequence = [roi]
    cx, cy, cz = a.centre_mm
    ax, ay, az = a.axes_mm
    contours = []
    for zk, uid in written:
        t = 1 - ((zk - cz) / az) ** 2
        if t <= 4e-4:
            continue
        angle = np.linspace(0, 2 * np.pi, 120, endpoint=False)
        points = np.stack([cx + ax * np.sqrt(t) * np.cos(angle), cy + ay * np.sqrt(t) * np.sin(angle),
                           np.full(angle.size, zk)], 1)
        c = Dataset()
        im = Dataset()
        im.ReferencedSOPClassUID = template.SOPClassUID
        im.ReferencedSOPInstanceUID = uid
        c.ContourImageSequence = [im]
        c.ContourGeometricType = 'CLOSED_PLANAR'
        c.NumberOfContourPoints = int(angle.size)
        c.ContourData = [round(float(v), 3) for v in points.ravel()]
        contours.append(c)
    item = Dataset()
    item.ReferencedROINumber = 1
    item.ROIDisplayColor = [255, 0, 0]
    item.ContourSequence = contours
    rs.ROIContourSequence = [item]
    observation = Dataset()
    observation.ObservationNumber = 1
    observation.ReferencedROINumber = 1
    observation.RTROIInterpretedType = 'ORGAN'
    observation.ROIInterpreter = ''
    rs.RTROIObservationsSequence = [observation]
    rs.save_as(os.path.join(a.out, 'rtstruct.dcm'), write_like_original=False)
    print('%d slices of %g mm, %d contours, ellipsoid %.1f cm3' %
          (count, a.slice_mm, len(contours), 4 / 3 * np.pi * ax * ay * az / 1000))


if __name__ == '__main__':
    main()
