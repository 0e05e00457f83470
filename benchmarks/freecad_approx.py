"""FreeCAD side of ``reconstruct_vs_peers.py``: ReverseEngineering.approxSurface per segment.

Run by the system python that FreeCAD's modules are built for (never in the OCP process: the
two bundle different OpenCASCADE builds)::

    /usr/bin/python3 benchmarks/freecad_approx.py WORKDIR [--poles 8] [--sew-tol 0.01] ...

Reads ``WORKDIR/points.npy`` (N, 3) and ``WORKDIR/labels.npy`` (N,), fits one bicubic
B-spline surface per label with ``ReverseEngineering.approxSurface`` (smoothing on), builds
the untrimmed faces, sews them with ``Shape.sewShape`` and writes

* ``WORKDIR/freecad.step`` -- the sewn shape (measured by the OCP process),
* ``WORKDIR/samples.npy`` -- a ``--grid`` x ``--grid`` sample grid of every surface over its
  full parameter box (stacked, (F * grid**2, 3)), with ``WORKDIR/sample_labels.npy``,
* ``WORKDIR/freecad.json`` -- timings, pole counts, sewing result, errors.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

sys.path.append("/usr/lib/freecad-python3/lib")

import numpy as np  # noqa: E402

import FreeCAD  # noqa: E402,F401
import Part  # noqa: E402
import ReverseEngineering  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("workdir")
    ap.add_argument("--poles", type=int, default=8)
    ap.add_argument("--weight", type=float, default=0.1)
    ap.add_argument("--grad", type=float, default=1.0)
    ap.add_argument("--bend", type=float, default=0.0)
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--patch-factor", type=float, default=1.0)
    ap.add_argument("--sew-tol", type=float, default=1e-2, help="absolute sewing tolerance")
    ap.add_argument("--grid", type=int, default=30)
    args = ap.parse_args()
    wd = args.workdir.rstrip("/")
    pts = np.load(f"{wd}/points.npy")
    lab = np.load(f"{wd}/labels.npy")
    out: dict = {"fit_s": 0.0, "faces": [], "errors": []}
    faces, samples, sample_labels = [], [], []
    g = np.linspace(0.0, 1.0, args.grid)
    for label in sorted(set(lab.tolist())):
        seg = pts[lab == label]
        tup = [tuple(map(float, p)) for p in seg]
        t0 = time.perf_counter()
        try:
            surf = ReverseEngineering.approxSurface(
                Points=tup, UDegree=3, VDegree=3, NbUPoles=args.poles, NbVPoles=args.poles,
                Smooth=True, Weight=args.weight, Grad=args.grad, Bend=args.bend,
                Iterations=args.iterations, Correction=True, PatchFactor=args.patch_factor,
            )
        except Exception as exc:  # noqa: BLE001 - report, keep going
            out["errors"].append(f"label {label}: {exc}")
            continue
        out["fit_s"] += time.perf_counter() - t0
        u0, u1, v0, v1 = surf.bounds()
        grid = [surf.value(u0 + a * (u1 - u0), v0 + b * (v1 - v0)) for a in g for b in g]
        samples.append(np.array([[p.x, p.y, p.z] for p in grid]))
        sample_labels.append(np.full(len(grid), label))
        faces.append(Part.Face(surf))
        out["faces"].append({"label": int(label), "poles": [surf.NbUPoles, surf.NbVPoles]})
    t0 = time.perf_counter()
    shape = Part.Compound(faces)
    try:
        shape.sewShape(args.sew_tol)
        out["sewed"] = True
    except Exception as exc:  # noqa: BLE001
        out["sewed"] = False
        out["errors"].append(f"sewShape: {exc}")
    out["sew_s"] = time.perf_counter() - t0
    out["shape_type"] = shape.ShapeType
    out["n_shells"] = len(shape.Shells)
    out["valid"] = bool(shape.isValid())
    shape.exportStep(f"{wd}/freecad.step")
    np.save(f"{wd}/samples.npy", np.vstack(samples) if samples else np.zeros((0, 3)))
    np.save(f"{wd}/sample_labels.npy", np.concatenate(sample_labels) if sample_labels else np.zeros(0))
    with open(f"{wd}/freecad.json", "w") as fh:
        json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
