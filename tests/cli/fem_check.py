"""Checks of testdata/fem/fem_cases.py on a small ellipsoid (semi-axes 20, 15, 13 mm):
    fem_check.py make SURFACE.stl      writes the ellipsoid's surface (icosphere, 320 faces)
    fem_check.py check OUT MAGNITUDE   checks cases.json and the written field
    fem_check.py same A.mha B.mha TOL  the two fields agree to TOL mm
"""
import json
import os
import sys

import numpy as np

SEMI = np.array([20.0, 15.0, 13.0])


def make(path):
    t = (1 + 5 ** 0.5) / 2
    v = [np.array(p, float) for p in [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t],
                                      [0, 1, t], [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1],
                                      [-t, 0, -1], [-t, 0, 1]]]
    v = [p / np.linalg.norm(p) for p in v]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    for _ in range(2):
        mids, nf = {}, []

        def mid(a, b):
            k = (min(a, b), max(a, b))
            if k not in mids:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                mids[k] = len(v) - 1
            return mids[k]
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = nf
    pts = np.array(v) * SEMI
    with open(path, "w") as o:
        o.write("solid ellipsoid\n")
        for tri in f:
            o.write("facet normal 0 0 0\nouter loop\n")
            for i in tri:
                o.write("vertex %.6f %.6f %.6f\n" % tuple(pts[i]))
            o.write("endloop\nendfacet\n")
        o.write("endsolid ellipsoid\n")


def read_mha(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"ElementDataFile = LOCAL\n") + len(b"ElementDataFile = LOCAL\n")
    header = dict(line.split(" = ", 1) for line in data[:end].decode().splitlines())
    size = [int(x) for x in header["DimSize"].split()]
    origin = np.array([float(x) for x in header["Offset"].split()])
    spacing = np.array([float(x) for x in header["ElementSpacing"].split()])
    assert header["ElementType"] == "MET_FLOAT" and header["ElementNumberOfChannels"] == "3"
    u = np.frombuffer(data[end:], "<f4").reshape(size[2], size[1], size[0], 3)
    return origin, spacing, u


def at(origin, spacing, u, p):
    i = np.round((np.asarray(p) - origin) / spacing).astype(int)
    return u[i[2], i[1], i[0]].astype(float)


def check(out, magnitude):
    report = json.load(open(os.path.join(out, "cases.json")))
    (case,) = report["cases"]
    failures = []
    if abs(case["largest_displacement_mm"] - magnitude) > 0.01 * magnitude:
        failures.append("largest displacement %.4f mm, not %g within 1%%" % (case["largest_displacement_mm"], magnitude))
    if abs(case["volume_change_pct"]) > 1e-6:
        failures.append("FEM volume change %.3e %%" % case["volume_change_pct"])
    origin, spacing, u = read_mha(os.path.join(out, case["field"]))
    post = at(origin, spacing, u, [0, SEMI[1] - 1, 0])   # under the probe (posterior, +y)
    ant = at(origin, spacing, u, [0, -SEMI[1] + 1, 0])   # the held anterior side
    if not post[1] < -0.6 * magnitude:
        failures.append("posterior pole moved %s, not anteriorly by most of %g mm" % (post, magnitude))
    if np.linalg.norm(ant) > 0.05 * magnitude:
        failures.append("held anterior pole moved %s" % ant)
    if not np.isfinite(u).all() or np.sqrt((u ** 2).sum(-1)).max() > 1.05 * magnitude:
        failures.append("field not finite or beyond the largest displacement")
    if report["mesh"]["tetrahedra"] < 100:
        failures.append("mesh of %d tetrahedra" % report["mesh"]["tetrahedra"])
    print("largest %.4f mm, volume %.2e %%, indentation %.3f mm, posterior pole %s, tetrahedra %d" %
          (case["largest_displacement_mm"], case["volume_change_pct"], case["indentation_mm"], post,
           report["mesh"]["tetrahedra"]))
    if failures:
        print("\n".join(failures))
        sys.exit(1)


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(sys.argv[2])
    elif sys.argv[1] == "same":
        (oa, sa, ua), (ob, sb, ub) = read_mha(sys.argv[2]), read_mha(sys.argv[3])
        diff = np.abs(ua - ub).max() if ua.shape == ub.shape else float("inf")
        print("largest difference %.3g mm" % diff)
        sys.exit(0 if np.allclose(oa, ob) and np.allclose(sa, sb) and diff <= float(sys.argv[4]) else 1)
    else:
        check(sys.argv[2], float(sys.argv[3]))
