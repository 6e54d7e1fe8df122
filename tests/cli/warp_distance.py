"""The planning organ warped by our displacement field through plastimatch, the way a
structure is resampled between thick slices: its signed distance (written here, with
scipy, to our definition in geometry/signed_distance.h: at a voxel centre the distance to
the nearest centre across the boundary less half the smallest spacing, negative inside)
warped linearly by `plastimatch convert --xf`, kept where below the organ's level at the
pre-image's place between the planning slices (run.json `export.organ_level_by_slice_phase_mm`,
joined as geometry/signed_distance.h's volume_level_at joins them; the pre-image of q is
q + v(q), the field's convention). Prints the Dice against our exported label map and
asserts it is at least MIN_DICE.

A label map warped linearly and kept where >= 0.5 takes the union of two slices at their
midplane, and warped by nearest neighbour gains or loses whole slices with the phase of
the samples: on 2.5 mm slices they differ from the organ moved by the same field by a few
percent of its volume (docs/decisions.md), which the signed distance does not.

usage: warp_distance.py PLANNING_LABELS.nrrd FIELD.mha OURS.nrrd WORK_FOLDER MIN_DICE RUN_JSON"""
import json
import os
import subprocess
import sys

import numpy as np
from scipy import ndimage


def read_mha(path):
    """(array z, y, x[, c], header dict) of an uncompressed MetaImage."""
    data = open(path, "rb").read()
    key = b"ElementDataFile = LOCAL\n"
    start = data.index(key) + len(key)
    header = dict(
        (k.strip(), v.strip())
        for k, v in (line.split("=", 1) for line in data[:start].decode().splitlines() if "=" in line)
    )
    dtype = {"MET_UCHAR": np.uint8, "MET_FLOAT": np.float32, "MET_SHORT": np.int16}[header["ElementType"]]
    size = [int(x) for x in header["DimSize"].split()][::-1]
    channels = int(header.get("ElementNumberOfChannels", "1"))
    values = np.frombuffer(data[start:], dtype=dtype)
    return values.reshape(size + ([channels] if channels > 1 else [])), header


def write_mha(path, values, header):
    keys = ["ObjectType", "NDims", "BinaryData", "BinaryDataByteOrderMSB", "CompressedData",
            "TransformMatrix", "Offset", "CenterOfRotation", "AnatomicalOrientation",
            "ElementSpacing", "DimSize"]
    text = "".join(f"{k} = {header[k]}\n" for k in keys if k in header and k != "CompressedData")
    text += "CompressedData = False\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n"
    with open(path, "wb") as f:
        f.write(text.encode())
        f.write(values.astype(np.float32).tobytes())


def plastimatch(*args):
    subprocess.run(["plastimatch", *args], check=True, stdout=subprocess.DEVNULL)


def level_at_pre_images(field, planning_header, levels):
    """The organ's level (mm) at each voxel's pre-image q + v(q) (axial grids: the slices'
    normal is z), from the four levels by slice phase at t = 1/16, 3/16, 5/16, 7/16 of a slice,
    joined linearly, the end pieces' lines extended, kept within half the smallest spacing."""
    v, header = read_mha(field)
    assert [float(x) for x in header["TransformMatrix"].split()] == [1, 0, 0, 0, 1, 0, 0, 0, 1]
    assert planning_header["TransformMatrix"] == header["TransformMatrix"]
    origin_z = float(header["Offset"].split()[2])
    spacing_z = float(header["ElementSpacing"].split()[2])
    z = origin_z + spacing_z * np.arange(v.shape[0])[:, None, None] + v[..., 2]
    planning_spacing = [float(x) for x in planning_header["ElementSpacing"].split()]
    index = (z - float(planning_header["Offset"].split()[2])) / planning_spacing[2]
    t = np.abs(index - np.round(index))
    c = np.asarray(levels)
    piece = np.clip(np.floor((t - 1 / 16) * 8).astype(int), 0, 2)
    f = (t - (piece + 0.5) / 8) * 8
    level = c[piece] + f * (c[piece + 1] - c[piece])
    half = 0.5 * min(planning_spacing)
    return np.clip(level, np.nextafter(-half, 0), half)


def main(planning, field, ours, work, min_dice, levels):
    plastimatch("convert", "--input", planning, "--output-img", os.path.join(work, "planning.mha"),
                "--output-type", "uchar")
    plastimatch("convert", "--input", ours, "--output-img", os.path.join(work, "ours.mha"),
                "--output-type", "uchar")
    mask, header = read_mha(os.path.join(work, "planning.mha"))
    spacing = [float(x) for x in header["ElementSpacing"].split()][::-1]  # z, y, x
    inside = mask > 0
    half = 0.5 * min(spacing)
    to_outside = ndimage.distance_transform_edt(inside, sampling=spacing)
    to_inside = ndimage.distance_transform_edt(~inside, sampling=spacing)
    distance = np.where(inside, -(to_outside - half), to_inside - half)
    write_mha(os.path.join(work, "distance.mha"), distance, header)
    plastimatch("convert", "--input", os.path.join(work, "distance.mha"), "--xf", field,
                "--output-img", os.path.join(work, "warped.mha"), "--interpolation", "linear",
                "--default-value", "1000")
    warped, _ = read_mha(os.path.join(work, "warped.mha"))
    ours_mask, _ = read_mha(os.path.join(work, "ours.mha"))
    level = level_at_pre_images(field, header, levels)
    assert level.shape == warped.shape
    a, b = warped < level, ours_mask > 0
    dice = 2.0 * np.count_nonzero(a & b) / (np.count_nonzero(a) + np.count_nonzero(b))
    print(f"dice {dice:.5f} (warped {np.count_nonzero(a)} voxels, ours {np.count_nonzero(b)})")
    assert dice >= min_dice, dice


if __name__ == "__main__":
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    main(*sys.argv[1:5], float(sys.argv[5]),
         json.load(open(sys.argv[6]))["export"]["organ_level_by_slice_phase_mm"])
