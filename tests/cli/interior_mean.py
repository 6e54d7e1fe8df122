"""Mean of an image over a mask's interior (voxels whose 6 neighbours are in the mask), for
two image/mask pairs: asserts the two means agree within TOLERANCE.

usage: interior_mean.py IMAGE_A MASK_A IMAGE_B MASK_B TOLERANCE
Images: MetaImage (.mha, float, raw or zlib); masks: NRRD (gzip or raw, unsigned char)."""
import array
import gzip
import sys
import zlib


def read_mha(path):
    data = open(path, "rb").read()
    key = b"ElementDataFile = LOCAL\n"
    start = data.index(key) + len(key)
    header = data[:start].decode()
    size = [int(x) for x in header.split("DimSize = ")[1].split("\n")[0].split()]
    body = data[start:]
    if "CompressedData = True" in header:
        body = zlib.decompress(body)
    values = array.array("f")
    values.frombytes(body)
    return size, values


def read_nrrd(path):
    data = open(path, "rb").read()
    start = data.index(b"\n\n") + 2
    header = data[:start].decode()
    size = [int(x) for x in header.split("sizes: ")[1].split("\n")[0].split()]
    body = gzip.decompress(data[start:]) if "encoding: gzip" in header else data[start:]
    return size, body


def interior_mean(image_path, mask_path):
    size, image = read_mha(image_path)
    msize, mask = read_nrrd(mask_path)
    assert size == msize, (size, msize)
    nx, ny, nz = size
    total, count = 0.0, 0
    for v, m in enumerate(mask):
        if m != 1:
            continue
        i, j, k = v % nx, (v // nx) % ny, v // (nx * ny)
        if not (0 < i < nx - 1 and 0 < j < ny - 1 and 0 < k < nz - 1):
            continue
        if all(mask[w] == 1 for w in (v - 1, v + 1, v - nx, v + nx, v - nx * ny, v + nx * ny)):
            total += image[v]
            count += 1
    return total / count, count


a, na = interior_mean(sys.argv[1], sys.argv[2])
b, nb = interior_mean(sys.argv[3], sys.argv[4])
print(f"planning {a:.2f} HU over {na} voxels, today {b:.2f} HU over {nb} voxels")
assert abs(a - b) <= float(sys.argv[5]), (a, b)
