#!/usr/bin/python3
"""Biomechanical ground truth for `organfit bench fit --fem`: an organ of nearly
incompressible neo-Hookean tissue deformed by what moves a prostate, solved by GetFEM.

    fem_cases.py --surface ORGAN.stl --load probe|bladder --magnitudes 2,5,8,12 --out DIR

What it solves (units: mm, N, MPa):
  mesh      TetGen (`tetgen -pq1.5 -a<V>`) fills the closed surface with about --tetrahedra
            tetrahedra (V = 6 x the enclosed volume / that count: the quality bound adds
            about 6 per largest volume);
  material  incompressible neo-Hookean, W = C1 (I1 - 3), C1 = 0.005 MPa (shear modulus
            10 kPa, soft tissue), with det F = 1 held by a pressure multiplier: GetFEM's
            Incompressible_Neo_Hookean law and finite-strain incompressibility brick, mixed
            u-p elements P2/P1 (Taylor-Hood), Newton with MUMPS;
  load      probe: a balloon pressed anteriorly on the patch of surface within R of the
            organ's most posterior point (LPS +y) that faces posterior: there u_y = -d w(s),
            w = cos^2(pi s / 2), s the distance from that point over R (a smooth contact
            profile, 0 at the patch's rim), u_x and u_z held (no sliding: with them free the
            incompressible body has near-free modes and Newton's method lands on different
            states from run to run); the anterior quarter of the
            surface (along y) held fixed (the prostate between a transrectal probe and the
            pubic bone). bladder: the same from the most superior point (+z) pressing
            inferiorly, the inferior quarter held (bladder filling against the pelvic floor).
            R is 0.3 times the organ's smallest extent. Displacement control: Newton's method
            converges where a prescribed pressure on a soft incompressible patch did not
            (docs/decisions.md);
  magnitude the largest displacement over the organ, mm: for each requested magnitude the
            indentation d is found by secant steps (at most 1.5 mm at once) from the previous
            solution until the largest displacement is within 1% of it. Where no solution is
            found further along the load (20 load steps), the larger magnitudes are not made
            and cases.json lists those that were.
With displacements prescribed, the field does not depend on C1 (only the reaction would).

Writes DIR/u_<m>mm.mha for each magnitude: the displacement u (mm, LPS, float, 3
components, MetaImage) on a regular grid covering the organ with a margin, such that a
planning point x moves to x + u(x) (planning -> deformed); outside the mesh u is the value
at the nearest point inside (the field is read only on and inside the organ). DIR/cases.json
holds, per magnitude, the largest displacement reached, the indentation d (mm), the FEM's own
volume change (integral of det F over the reference mesh, %), Newton iterations, and the
mesh's size and the solve's wall time.
FEM_VERBOSE=1 in the environment prints each load step (indentation, displacement, Newton
iterations).
Reproducible: TetGen and the solver have no random element (the threaded solver's sums
may differ in the last bits from run to run; bench fit --fem reads a case from its cache).
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

SCRIPT_VERSION = 1
C1_MPA = 0.005
STEP_MM = 1.5  # the largest increase of displacement per load step
MAX_NEWTON = 12


def fail(message):
    print("fem_cases: " + message, file=sys.stderr)
    sys.exit(2)


def read_tetgen(stem):
    node_rows = np.loadtxt(stem + ".node", skiprows=1, comments="#", ndmin=2)
    tets = np.loadtxt(stem + ".ele", skiprows=1, comments="#", dtype=np.int64, ndmin=2)[:, 1:5]
    first = int(node_rows[0, 0])  # TetGen numbers from the input's first index (0 or 1)
    return node_rows[:, 1:4], tets - first


def stl_vertices(path):
    """The vertices of an STL file (binary or ASCII), n x 3."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) >= 84:
        n = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if len(data) == 84 + 50 * n:
            rec = np.frombuffer(data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), n, 84)
            return rec["v"].reshape(-1, 3).astype(float)
    rows = [line.split()[1:4] for line in data.decode(errors="replace").splitlines()
            if line.strip().startswith("vertex")]
    if not rows:
        fail("%s: not an STL surface" % path)
    return np.array(rows, float)


def mesh_organ(triangles, work, volume):
    """TetGen on the surface as a .smesh (its STL reader takes ASCII only): nodes merged."""
    points, index = np.unique(triangles.reshape(-1, 3).round(6), axis=0, return_inverse=True)
    faces = index.reshape(-1, 3)
    local = os.path.join(work, "organ.smesh")
    with open(local, "w") as f:
        f.write("%d 3 0 0\n" % len(points))
        for i, p in enumerate(points):
            f.write("%d %.6f %.6f %.6f\n" % (i, p[0], p[1], p[2]))
        f.write("%d 0\n" % len(faces))
        for t in faces:
            f.write("3 %d %d %d\n" % (t[0], t[1], t[2]))
        f.write("0\n0\n")
    run = subprocess.run(["tetgen", "-pq1.5a%.4fQ" % volume, local], capture_output=True, text=True)
    if run.returncode != 0 or not os.path.exists(os.path.join(work, "organ.1.ele")):
        fail("TetGen could not mesh the surface: %s" % (run.stdout + run.stderr).strip()[-300:])
    return read_tetgen(os.path.join(work, "organ.1"))


def write_mha(path, origin, spacing, shape, u):
    """u: (nz, ny, nx, 3) float32, x fastest on disk."""
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
        "CompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\n"
        "Offset = %.6f %.6f %.6f\nCenterOfRotation = 0 0 0\nAnatomicalOrientation = RAI\n"
        "ElementSpacing = %.6f %.6f %.6f\nDimSize = %d %d %d\nElementNumberOfChannels = 3\n"
        "ElementType = MET_FLOAT\nElementDataFile = LOCAL\n"
        % (origin[0], origin[1], origin[2], spacing, spacing, spacing, shape[0], shape[1], shape[2])
    )
    tmp = path + ".part"
    with open(tmp, "wb") as f:
        f.write(header.encode())
        f.write(np.ascontiguousarray(u, dtype="<f4").tobytes())
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--surface", required=True, help="closed organ surface (.stl), LPS mm")
    ap.add_argument("--load", required=True, choices=["probe", "bladder"])
    ap.add_argument("--magnitudes", required=True, help="largest displacements, mm, e.g. 2,5,8,12")
    ap.add_argument("--out", required=True, help="folder for u_<m>mm.mha and cases.json")
    ap.add_argument("--tetrahedra", type=int, default=1000,
                    help="about this many tetrahedra (TetGen adds more where the surface is fine)")
    ap.add_argument("--grid-mm", type=float, default=1.0, help="spacing of the written field, mm")
    a = ap.parse_args()
    try:
        magnitudes = sorted(float(m) for m in a.magnitudes.split(","))
    except ValueError:
        fail("--magnitudes: numbers separated by commas expected, not '%s'" % a.magnitudes)
    if not magnitudes or magnitudes[0] <= 0:
        fail("--magnitudes: positive values expected")
    if not os.path.isfile(a.surface):
        fail("%s: no such file" % a.surface)
    try:
        import getfem as gf
    except ImportError:
        fail("GetFEM's Python module is missing (Debian: apt-get install python3-getfem)")
    if shutil.which("tetgen") is None:
        fail("tetgen is missing (Debian: apt-get install tetgen)")
    gf.util_trace_level(0)
    gf.util_warning_level(0)
    os.makedirs(a.out, exist_ok=True)
    work = os.path.join(a.out, "mesh")
    os.makedirs(work, exist_ok=True)
    t0 = time.time()

    # The mesh, its extents and the edge length from the surface alone.
    triangles = stl_vertices(a.surface).reshape(-1, 3, 3)
    enclosed = abs(float(np.einsum("ij,ij->i", triangles[:, 0],
                                   np.cross(triangles[:, 1], triangles[:, 2])).sum()) / 6)
    # TetGen's quality bound (radius-edge 1.5) adds about 6 tetrahedra per largest volume.
    max_volume = 6 * enclosed / a.tetrahedra
    nodes, tets = mesh_organ(triangles, work, max_volume)
    lo, hi = nodes.min(0), nodes.max(0)
    extent = hi - lo

    m = gf.Mesh("empty", 3)
    m.add_convex(gf.GeoTrans("GT_PK(3,1)"), nodes[tets].transpose(2, 1, 0))
    faces = m.outer_faces()
    normals = m.normal_of_faces(faces)
    centres = np.empty((3, faces.shape[1]))
    for k in range(faces.shape[1]):
        centres[:, k] = m.pts(m.pid_in_faces(faces[:, k:k + 1])).mean(axis=1)

    axis = 1 if a.load == "probe" else 2  # LPS: +y posterior, +z superior
    pole = nodes[np.argmax(nodes[:, axis])]
    radius = 0.3 * float(extent.min())
    patch = (np.linalg.norm(centres - pole[:, None], axis=0) < radius) & (normals[axis] > 0)
    held = centres[axis] < lo[axis] + 0.25 * extent[axis]
    if patch.sum() == 0 or held.sum() == 0:
        fail("%s: no surface to load or to hold" % a.surface)
    m.set_region(1, faces[:, patch])
    m.set_region(2, faces[:, held])

    mfu = gf.MeshFem(m, 3)
    mfu.set_fem(gf.Fem("FEM_PK(3,2)"))
    mfp = gf.MeshFem(m, 1)
    mfp.set_fem(gf.Fem("FEM_PK(3,1)"))
    mim = gf.MeshIm(m, gf.Integ("IM_TETRAHEDRON(3)"))
    md = gf.Model("real")
    md.add_fem_variable("u", mfu)
    md.add_fem_variable("p", mfp)
    md.add_initialized_data("params", [C1_MPA])
    md.add_finite_strain_elasticity_brick(mim, "Incompressible_Neo_Hookean", "u", "params")
    md.add_finite_strain_incompressibility_brick(mim, "u", "p")
    # The probe's balloon (or the bladder) presses along -axis with a smooth profile: on the
    # patch the axis component of u is -d w(s), w = cos^2(pi s / 2), s the distance from the
    # pole over R (0 at the rim, where the free surface begins); the others held.
    md.add_initialized_data("H", np.eye(3).flatten())
    dof_xyz = mfu.basic_dof_nodes()  # 3 x ndof (each node repeated per component)
    s_rim = np.linalg.norm(dof_xyz - pole[:, None], axis=0) / radius
    profile = np.where(s_rim < 1, np.cos(0.5 * np.pi * np.minimum(s_rim, 1)) ** 2, 0.0)
    on_axis = np.arange(mfu.nbdof()) % 3 == axis
    md.add_initialized_fem_data("r", mfu, np.zeros(mfu.nbdof()))
    md.add_generalized_Dirichlet_condition_with_multipliers(mim, "u", mfu, 1, "r", "H")
    md.add_Dirichlet_condition_with_multipliers(mim, "u", mfu, 2)  # the held side: u = 0
    volume0 = gf.asm_generic(mim, 0, "1", -1, md)

    def solve(indent):
        md.set_variable("r", np.where(on_axis, -indent * profile, 0.0))
        iterations = md.solve("max_res", 1e-9, "max_iter", MAX_NEWTON, "lsolver", "mumps")
        iterations = int(iterations[0] if isinstance(iterations, tuple) else iterations)
        U = md.variable("u")
        largest = float(np.sqrt((U.reshape(-1, 3) ** 2).sum(1)).max())
        return iterations, largest

    # The grid the fields are written on: the organ's box, grown by the largest magnitude
    # plus 2 voxels.
    g = a.grid_mm
    margin = magnitudes[-1] + 2 * g
    origin = lo - margin
    shape = np.ceil((extent + 2 * margin) / g).astype(int) + 1
    xs = [origin[d] + g * np.arange(shape[d]) for d in range(3)]
    Z, Y, X = np.meshgrid(xs[2], xs[1], xs[0], indexing="ij")
    grid_pts = np.vstack([X.ravel(), Y.ravel(), Z.ravel()])
    ones = np.ones(mfp.nbdof())
    inside = gf.compute_interpolate_on(mfp, ones, grid_pts) > 0.5
    from scipy import ndimage
    nearest = ndimage.distance_transform_edt(~inside.reshape(Z.shape), return_distances=False,
                                             return_indices=True)

    cases = []
    indent, reached = 0.0, 0.0
    slope = 1.0  # largest displacement per mm of indentation: about 1 (a bulge adds a little)
    gave_up = False
    for target in magnitudes:
        t_case = time.time()
        guess = indent + min(target - reached, STEP_MM) / slope
        total_iterations, steps = 0, 0
        last_good = (indent, reached, md.variable("u"), md.variable("p"))
        while True:
            steps += 1
            if steps > 20:  # no solution further along this load: the cases so far are kept
                print("fem_cases: %s %s: no solution beyond %.3f mm; %g mm and above not made" %
                      (os.path.basename(a.surface), a.load, reached, target), file=sys.stderr)
                gave_up = True
                break
            try:
                its, largest = solve(guess)
                ok = its < MAX_NEWTON and np.isfinite(largest)
            except RuntimeError:
                ok = False
            if os.environ.get("FEM_VERBOSE") and not ok:
                print("  indentation %.4f mm: no convergence" % guess, file=sys.stderr, flush=True)
            if not ok:  # back to the last solution, half the step
                p_prev, u_prev, U_prev, P_prev = last_good
                md.set_variable("u", U_prev)
                md.set_variable("p", P_prev)
                guess = p_prev + 0.5 * (guess - p_prev)
                continue
            if os.environ.get("FEM_VERBOSE"):
                print("  indentation %.4f mm: %.3f mm, %d Newton iterations" % (guess, largest, its),
                      file=sys.stderr, flush=True)
            total_iterations += its
            if guess != last_good[0]:  # bounded: one noisy step must not send d far off
                slope = min(max((largest - last_good[1]) / (guess - last_good[0]), 0.5), 2.0)
            last_good = (guess, largest, md.variable("u"), md.variable("p"))
            indent, reached = guess, largest
            if abs(largest - target) <= 0.01 * target:
                break
            # A secant step of at most 1.5 mm more displacement at once: Newton's method
            # converges in a few iterations from there (the response stiffens as the tissue
            # is compressed against the held side).
            guess = indent + min(target - reached, STEP_MM) / max(slope, 1e-12)
        if gave_up:
            break
        change = gf.asm_generic(mim, 0, "Det(Id(meshdim)+Grad_u)", -1, md) / volume0 - 1
        U = md.variable("u")
        values = gf.compute_interpolate_on(mfu, U, grid_pts).reshape(3, -1)
        field = np.empty(Z.shape + (3,), dtype=np.float32)
        for d in range(3):
            component = values[d].reshape(Z.shape)
            field[..., d] = component[tuple(nearest)]
        name = "u_%gmm.mha" % target
        write_mha(os.path.join(a.out, name), origin, g, shape, field)
        cases.append({
            "magnitude_mm": target,
            "largest_displacement_mm": reached,
            "indentation_mm": indent,
            "volume_change_pct": 100 * change,
            "newton_iterations": total_iterations,
            "load_steps": steps,
            "field": name,
            "wall_s": time.time() - t_case,
        })
        print("fem_cases: %s %s %g mm: %.3f mm at an indentation of %.3f mm, volume %+.2e %%, %.1f s" %
              (os.path.basename(a.surface), a.load, target, reached, indent, 100 * change,
               time.time() - t_case), file=sys.stderr, flush=True)

    report = {
        "script_version": SCRIPT_VERSION,
        "surface": os.path.basename(a.surface),
        "load": a.load,
        "material": {"law": "incompressible neo-Hookean", "c1_mpa": C1_MPA,
                     "elements": "P2 displacement / P1 pressure"},
        "mesh": {"tetrahedra": int(tets.shape[0]), "nodes": int(nodes.shape[0]), "largest_tetrahedron_mm3": max_volume,
                 "dofs": int(mfu.nbdof() + mfp.nbdof()), "volume_mm3": float(volume0),
                 "loaded_faces": int(patch.sum()), "held_faces": int(held.sum()),
                 "patch_radius_mm": radius},
        "grid": {"origin_mm": origin.tolist(), "spacing_mm": g, "size": shape.tolist()},
        "cases": cases,
        "wall_s": time.time() - t0,
    }
    tmp = os.path.join(a.out, "cases.json.part")
    with open(tmp, "w") as f:
        json.dump(report, f, indent=1)
    os.replace(tmp, os.path.join(a.out, "cases.json"))


if __name__ == "__main__":
    main()
