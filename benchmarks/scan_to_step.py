"""Benchmark: meshes and scans without labels -> STEP (automatic layout) beside open3d Poisson.

Usage (the project's venv python)::

    python benchmarks/scan_to_step.py                 # every case, 3 variants each
    python benchmarks/scan_to_step.py --cases ellipsoid,torus --variants mesh,noisy
    python benchmarks/scan_to_step.py --json out.json --continuity c1

Cases, none designed for this project: the STL models shipped by Debian's OpenCASCADE data
package (``/usr/share/opencascade/data/stl``, when installed), trimesh's analytic primitives
(an ellipsoid, a torus of genus 1, a capsule) and a filleted box made with build123d (when
installed) and tessellated, and mechanical parts made with build123d (a filleted box with a
hole, a revolved knob, an L bracket, a flange with a bolt circle). Variants: the mesh itself
(faces kept), ``SAMPLES`` clean points sampled on it, and those points with Gaussian noise of
``NOISE`` x the diagonal D.

Per case and variant, in a fresh process with a ``--timeout``: ``pde2cad`` (read, automatic
layout, reconstruction, STEP written and read back) and open3d Poisson (normals from 20
neighbours, oriented over the tangent-plane graph, depth 8) on the same points. Printed:

* valid / closed (solid) / free edges / max gap over D, from the STEP read back;
* seam: max normal angle across seams away from irregular corners (deg);
* in->f: mean distance of the input points to the faces over D (each point to its patch at
  its fitted parameters: an upper bound of the closest distance);
* f->in p95: 95th percentile of the distance of face samples (a 40 x 40 grid per patch, or
  Poisson's vertices) to the true surface (``REFERENCE`` points sampled on the mesh), over D;
* >1%D: fraction of the input farther than 0.01 D from the faces;
* time (s, wall);
* creases: the range of the normal angle across the edges kept sharp (deg; the part's
  dihedral angles where they are known, e.g. 90 and 53 on the knob).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import pde2cad  # noqa: F401
except ImportError:  # plain checkout without an installed package
    sys.path.insert(0, str(ROOT / "src"))

SAMPLES = 50_000
NOISE = 0.002
REFERENCE = 300_000
OCC_STL = Path("/usr/share/opencascade/data/stl")


#: Environment variable with the ``--mesh-dir`` folders (the cases run in spawned processes).
MESH_DIRS = "PDE2CAD_BENCH_MESH_DIRS"


def _analytic() -> dict[str, Any]:
    import trimesh

    cases = {
        "ellipsoid": lambda: trimesh.creation.icosphere(5).apply_scale((1.0, 0.6, 0.35)),
        "torus": lambda: trimesh.creation.torus(1.0, 0.35, 128, 64),
        "capsule": lambda: trimesh.creation.capsule(height=1.5, radius=0.5, count=(64, 64)),
    }
    try:
        import build123d as bd

        def filleted_box() -> Any:
            part = bd.fillet(bd.Box(2, 1.4, 1).edges(), radius=0.2)
            path = Path(tempfile.mkdtemp()) / "box.stl"
            bd.export_stl(part, str(path), tolerance=1e-3, angular_tolerance=0.1)
            return trimesh.load(str(path), force="mesh")

        cases["filleted_box"] = filleted_box
        for part in _cad_parts(bd):
            cases[part] = lambda part=part: _tessellated(bd, _cad_parts(bd)[part]())
    except ImportError:
        pass
    for path in sorted(OCC_STL.glob("*.stl")) if OCC_STL.is_dir() else []:
        cases[f"occ_{path.stem}"] = lambda p=path: trimesh.load(str(p), force="mesh")
    for folder in (Path(p) for p in os.environ.get(MESH_DIRS, "").split(os.pathsep) if p):
        for path in sorted(folder.iterdir()):
            if path.suffix.lower() in (".off", ".stl", ".obj", ".ply"):
                cases[path.stem] = lambda p=path: trimesh.load(str(p), force="mesh")
    return cases


def _cad_parts(bd: Any) -> dict[str, Any]:
    """Mechanical parts of the kinds issue 10 names (exact B-reps, sharp edges and fillets):
    a filleted box with a through hole (genus 1), a revolved knob (a 53-deg cone between
    cylinders), an L bracket, a flange with a bolt circle (genus 4)."""

    def holed_box() -> Any:
        box = bd.fillet(bd.Box(4, 3, 1).edges().filter_by(bd.Axis.Z), radius=0.4)
        return box - bd.Cylinder(0.6, 2)

    def knob() -> Any:
        with bd.BuildPart() as part:
            with bd.BuildSketch(bd.Plane.XZ):
                with bd.BuildLine():
                    bd.Polyline((0, 0), (1, 0), (1, 0.3), (0.6, 0.6), (0.6, 1.2), (0, 1.2), (0, 0))
                bd.make_face()
            bd.revolve(axis=bd.Axis.Z)
        return part.part

    def bracket() -> Any:
        low = (bd.Align.MIN,) * 3
        return bd.Box(3, 1, 0.4, align=low) + bd.Box(0.4, 1, 2, align=low)

    def flange() -> Any:
        part = bd.Cylinder(2, 0.5) - bd.Cylinder(0.6, 1)
        for loc in bd.PolarLocations(1.4, 3):
            part = part - loc * bd.Cylinder(0.2, 1)
        return part

    return {"cad_holed_box": holed_box, "cad_knob": knob, "cad_bracket": bracket,
            "cad_flange": flange}


def _tessellated(bd: Any, part: Any) -> Any:
    """A build123d part as a trimesh mesh (STL at 1e-3 / 0.1 rad)."""
    import trimesh

    path = Path(tempfile.mkdtemp()) / "part.stl"
    bd.export_stl(part, str(path), tolerance=1e-3, angular_tolerance=0.1)
    return trimesh.load(str(path), force="mesh")


def _input(mesh: Any, variant: str, diagonal: float, work: Path) -> Path:
    """The file pde2cad reads for a variant: the mesh (OFF) or points (XYZ)."""
    if variant == "mesh":
        path = work / "in.off"
        mesh.export(path)
        return path
    import trimesh

    pts = trimesh.sample.sample_surface(mesh, SAMPLES, seed=1)[0]
    if variant == "noisy":
        pts = pts + np.random.default_rng(2).normal(scale=NOISE * diagonal / np.sqrt(3), size=pts.shape)
    path = work / "in.xyz"
    np.savetxt(path, pts)
    return path


def _ours(path: Path, reference: np.ndarray, diagonal: float, continuity: str) -> dict[str, Any]:
    from scipy.spatial import cKDTree

    from pde2cad.io.meshes import read_surface, reconstruct_auto
    from pde2cad.occ import write_step
    from pde2cad.occ.build import quiet_messages
    from pde2cad.report import build_report

    t0 = time.perf_counter()
    # a mesh is sampled as the CLI samples it (its default count); points are read as given
    surface = read_surface(path)
    with quiet_messages():
        rec, layout = reconstruct_auto(surface, continuity=continuity)
        step = path.with_suffix(".step")
        write_step(rec.shape, step)
    elapsed = time.perf_counter() - t0
    s = build_report(rec, step, orthogonal=False)["summary"]
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points,
                                          axis=1) for p in rec.patches.values()])
    g = np.linspace(0.0, 1.0, 40)
    uu, vv = (a.ravel() for a in np.meshgrid(g, g))
    faces = np.concatenate([p.evaluate(uu, vv) for p in rec.patches.values()])
    back = cKDTree(reference).query(faces, workers=-1)[0]
    return {
        "valid": s["valid"], "closed": s["solid"] or s["closed"], "free_edges": s["free_edges"],
        "gap": s["max_gap_rel"], "seam": s.get("max_angle_deg_regular", s["max_angle_deg"]),
        "creases": s.get("crease_angle_deg"),
        "in_f": float(dist.mean() / diagonal), "f_in95": float(np.percentile(back, 95) / diagonal),
        "far": float(np.mean(dist > 0.01 * diagonal)), "time": elapsed,
        "patches": layout.summary["patches"], "stages": rec.timings,
    }


def _poisson(points: np.ndarray, reference: np.ndarray, diagonal: float) -> dict[str, Any]:
    import open3d as o3d
    from scipy.spatial import cKDTree

    t0 = time.perf_counter()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(20))
    pcd.orient_normals_consistent_tangent_plane(12)
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=8)
    elapsed = time.perf_counter() - t0
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    dist = scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
    back = cKDTree(reference).query(np.asarray(mesh.vertices), workers=-1)[0]
    return {
        # closed = every edge has two faces; ``is_watertight`` would also run open3d's
        # all-pairs self-intersection test, which takes many minutes on a depth-8 mesh
        "valid": True, "closed": bool(mesh.is_edge_manifold(allow_boundary_edges=False)),
        "free_edges": None, "gap": None,
        "seam": None, "in_f": float(dist.mean() / diagonal),
        "f_in95": float(np.percentile(back, 95) / diagonal),
        "far": float(np.mean(dist > 0.01 * diagonal)), "time": elapsed, "patches": None,
    }


def _run(name: str, variant: str, continuity: str, queue: Any) -> None:
    import trimesh

    mesh = _analytic()[name]()
    diagonal = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    reference = trimesh.sample.sample_surface(mesh, REFERENCE, seed=7)[0]
    work = Path(tempfile.mkdtemp())
    path = _input(mesh, variant, diagonal, work)
    out: dict[str, Any] = {}
    try:
        out["ours"] = _ours(path, reference, diagonal, continuity)
    except Exception as exc:  # noqa: BLE001 - a benchmark row, not a crash
        out["ours"] = {"error": f"{type(exc).__name__}: {str(exc)[:160]}"}
    pts = np.loadtxt(path) if variant != "mesh" else trimesh.sample.sample_surface(mesh, SAMPLES, seed=1)[0]
    try:
        out["poisson"] = _poisson(np.asarray(pts, dtype=float), reference, diagonal)
    except Exception as exc:  # noqa: BLE001
        out["poisson"] = {"error": f"{type(exc).__name__}: {exc}"}
    queue.put(out)


def _row(name: str, variant: str, method: str, r: dict[str, Any]) -> str:
    if "error" in r:
        return f"{name:18s} {variant:6s} {method:8s} ERROR {r['error']}"

    def f(v: Any, fmt: str) -> str:
        width = "".join(ch for ch in fmt if ch.isdigit() or ch == ".").split(".")[0]
        return format("-", f">{width}") if v is None else format(v, fmt)

    return (f"{name:18s} {variant:6s} {method:8s} {f(r['patches'], '>4d')} {str(r['valid']):>5s} "
            f"{str(r['closed']):>6s} {f(r['free_edges'], '>4d')} {f(r['gap'], '>8.1e')} "
            f"{f(r['seam'], '>6.2f')} {r['in_f']:>8.1e} {r['f_in95']:>8.1e} {r['far']:>6.3f} "
            f"{r['time']:>6.1f} {_crease_text(r.get('creases'))}")


def _crease_text(span: Any) -> str:
    """The range of the normal angle across the creases kept sharp, e.g. ``80-97``."""
    return "-" if not span else f"{span[0]:.0f}-{span[1]:.0f}"


def _collect(proc: Any, queue: Any, limit: float) -> dict[str, Any]:
    """The case's result, read before joining (a child blocks on a full pipe until read).

    1. Poll the queue each second for up to ``limit`` s while the child lives.
    2. Nothing came: a timeout if the child still runs (it is terminated), else a crash.
    """
    import queue as queues

    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        try:
            out: dict[str, Any] = queue.get(timeout=1.0)
            proc.join(10)
            return out
        except queues.Empty:
            if not proc.is_alive() and queue.empty():
                break
    why = "timeout" if proc.is_alive() else "crashed"
    proc.terminate()
    proc.join(10)
    return {"ours": {"error": why}, "poisson": {"error": why}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", help="comma-separated case names (default: all)")
    parser.add_argument("--variants", default="mesh,clean,noisy")
    parser.add_argument("--continuity", choices=["c0", "c1"], default="c1")
    parser.add_argument("--timeout", type=float, default=120.0)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--mesh-dir", type=Path, action="append", default=[],
                        help="a folder of meshes (OFF/STL/OBJ/PLY), each one more case")
    args = parser.parse_args()
    os.environ[MESH_DIRS] = os.pathsep.join(str(p.resolve()) for p in args.mesh_dir)
    names = args.cases.split(",") if args.cases else list(_analytic())
    print(f"{'case':18s} {'var':6s} {'method':8s} {'pat':>4s} {'valid':>5s} {'closed':>6s} "
          f"{'free':>4s} {'gap/D':>8s} {'seam':>6s} {'in->f/D':>8s} {'f->in95':>8s} {'>1%D':>6s} "
          f"{'time':>6s} creases")
    results: list[dict[str, Any]] = []
    ctx = mp.get_context("spawn")
    for name in names:
        for variant in args.variants.split(","):
            queue = ctx.Queue()
            proc = ctx.Process(target=_run, args=(name, variant, args.continuity, queue))
            proc.start()
            out = _collect(proc, queue, args.timeout * 4)  # ours, its read-back and Poisson
            for method in ("ours", "poisson"):
                print(_row(name, variant, method, out[method]), flush=True)
            results.append({"case": name, "variant": variant, **out})
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
