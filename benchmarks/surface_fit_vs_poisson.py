"""One Chapter 5 patch as a user fits it, against open3d normals + Poisson, in the same run.

Usage (from a plain checkout, with the project's venv python)::

    python benchmarks/surface_fit_vs_poisson.py                  # 1e6 points, 3 repeats
    python benchmarks/surface_fit_vs_poisson.py --shape cap --repeat 5
    python benchmarks/surface_fit_vs_poisson.py --quick          # 1e5 points, 1 repeat
    python benchmarks/surface_fit_vs_poisson.py --json out.json --depth 9

The cloud is unordered (shuffled), uniformly random over a sheet whose true surface is known:

* ``flag``: ``z = 0.1 x sin(3x + 2y)`` over [0, 1] x [0, 0.75] (the tests' flag);
* ``cap``: a sphere cap ``z = sqrt(4 - x^2 - y^2)`` over [-1, 1]^2;
* ``noisy``: the flag with Gaussian noise of 1e-3 on every coordinate;
* ``nonuniform``: ``z = 0.15 sin(4x) cos(3y)`` with x = u^2 (density 10x higher at x = 0.01
  than at x = 1).

Each repeat times, back to back on the same cloud:

* ours: ``fit_patch(points, m=10, n=10)``, exactly as a user calls it: boundary extraction
  (alpha shape, corners, rim estimate, side fits), parameterization and the sine
  deformation (Eq. 5.17);
* open3d: ``estimate_normals`` (hybrid radius 6 spacings, 30 neighbours), orientation along
  +z (the sheets are height fields) and ``create_from_point_cloud_poisson(depth)``.

The ratio is taken per repeat (neighbours on a shared machine slow both alike within one
repeat) and summarized by its median; the load average is printed with it. Both results are
then compared with the TRUE surface on a 401 x 401 grid: distance from each true point to
our patch (closest point by projection) and to the Poisson mesh trimmed to the data
(vertices below the 2 % density quantile and outside the points' box removed). The peak is
the largest memory numpy held during one ``fit_patch`` (tracemalloc), besides the cloud.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import pde2cad  # noqa: F401
except ImportError:  # plain checkout without an installed package
    sys.path.insert(0, str(ROOT / "src"))

from pde2cad.surfaces.patch import Patch, fit_patch  # noqa: E402
from pde2cad.surfaces.projection import project_points  # noqa: E402
from pde2cad.surfaces.region import extract_boundary  # noqa: E402

TERMS = 10
Sheet = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _flag(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    x, y = u, 0.75 * v
    return np.stack([x, y, 0.1 * x * np.sin(3 * x + 2 * y)], axis=-1)


def _cap(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    x, y = 2 * u - 1, 2 * v - 1
    return np.stack([x, y, np.sqrt(4 - x * x - y * y)], axis=-1)


def _wave(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack([u, v, 0.15 * np.sin(4 * u) * np.cos(3 * v)], axis=-1)


#: name -> (true surface over [0, 1]^2, map of the uniform samples, noise, area)
SHAPES: dict[str, tuple[Sheet, Callable[[np.ndarray], np.ndarray], float, float]] = {
    "flag": (_flag, lambda u: u, 0.0, 0.75),
    "cap": (_cap, lambda u: u, 0.0, 4.0),
    "noisy": (_flag, lambda u: u, 1e-3, 0.75),
    "nonuniform": (_wave, lambda u: u * u, 0.0, 1.0),
}


def make_cloud(shape: str, count: int, seed: int = 0) -> np.ndarray:
    """Shuffled samples of the sheet (count, 3)."""
    sheet, warp, noise, _ = SHAPES[shape]
    rng = np.random.default_rng(seed)
    uv = rng.random((2, count))
    points = sheet(warp(uv[0]), uv[1])
    if noise:
        points = points + noise * rng.standard_normal(points.shape)
    return points[rng.permutation(count)]


def truth_grid(shape: str, count: int = 401) -> np.ndarray:
    """Dense samples of the true surface, (count^2, 3)."""
    g = np.linspace(0.0, 1.0, count)
    u, v = np.meshgrid(g, g, indexing="ij")
    return SHAPES[shape][0](u.ravel(), v.ravel())


def timed(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """Result, wall seconds and CPU seconds (all threads) of one call."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def ours(points: np.ndarray, rims: bool = True) -> Patch:
    return fit_patch(points, m=TERMS, n=TERMS, rims=rims)


def poisson(points: np.ndarray, shape: str, depth: int) -> Any:
    """open3d normals + Poisson, timed as one: what a user needs before meshing."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    spacing = np.sqrt(SHAPES[shape][3] / len(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=6 * spacing, max_nn=30))
    pcd.orient_normals_to_align_with_direction(np.array([0.0, 0.0, 1.0]))
    return o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)


def patch_truth(patch: Patch, truth: np.ndarray) -> dict[str, float]:
    _, dist, _ = project_points(patch, truth)
    return {"mean": float(dist.mean()), "max": float(dist.max())}


def poisson_truth(result: Any, points: np.ndarray, truth: np.ndarray) -> dict[str, Any]:
    import open3d as o3d

    mesh, density = result
    density = np.asarray(density)
    mesh.remove_vertices_by_mask(density < np.quantile(density, 0.02))
    mesh = mesh.crop(o3d.geometry.AxisAlignedBoundingBox(points.min(axis=0), points.max(axis=0)))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    dist = scene.compute_distance(o3d.core.Tensor(truth.astype(np.float32))).numpy()
    return {
        "mean": float(dist.mean()),
        "max": float(dist.max()),
        "vertices": len(mesh.vertices),
    }


def traced_peak(fn: Callable[[], Any]) -> float:
    """Largest memory (bytes) numpy and Python allocated during ``fn``, beyond the start."""
    tracemalloc.start()
    try:
        fn()
        return float(tracemalloc.get_traced_memory()[1])
    finally:
        tracemalloc.stop()


def run(shape: str, count: int, repeat: int, depth: int, rims: bool = True) -> dict[str, Any]:
    points = make_cloud(shape, count)
    rows = []
    patch = mesh = None
    for _ in range(repeat):
        load = os.getloadavg()[0]
        patch, t_ours, c_ours = timed(lambda: ours(points, rims))
        mesh, t_o3d, c_o3d = timed(lambda: poisson(points, shape, depth))
        rows.append(
            {"load": load, "ours_s": t_ours, "ours_cpu": c_ours, "open3d_s": t_o3d,
             "open3d_cpu": c_o3d, "ratio": t_o3d / t_ours}
        )
    _, t_bnd, c_bnd = timed(lambda: extract_boundary(points, rims=rims))
    truth = truth_grid(shape)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    assert patch is not None
    return {
        "shape": shape,
        "points": count,
        "depth": depth,
        "repeats": rows,
        "median_ratio": float(np.median([r["ratio"] for r in rows])),
        "boundary_s": t_bnd,
        "boundary_cpu": c_bnd,
        "rims": rims,
        "peak_bytes": traced_peak(lambda: ours(points, rims)),
        "diagonal": diagonal,
        "ours_truth": patch_truth(patch, truth),
        "ours_variables": patch.n_variables,
        "open3d_truth": poisson_truth(mesh, points, truth),
    }


def report(res: dict[str, Any]) -> None:
    print(
        f"\n{res['shape']}, {res['points']:,d} unordered points: fit_patch(M = N = {TERMS}, "
        f"rims={res['rims']}, boundary extraction included) vs open3d normals + Poisson depth "
        f"{res['depth']} ({os.cpu_count()} cores; wall s / CPU s)"
    )
    print(f"{'repeat':>6} {'load':>5} {'ours':>13} {'open3d':>15} {'ratio':>7}")
    for k, r in enumerate(res["repeats"]):
        print(
            f"{k:>6} {r['load']:>5.1f} {r['ours_s']:>6.2f}/{r['ours_cpu']:<6.2f}"
            f"{r['open3d_s']:>7.2f}/{r['open3d_cpu']:<7.2f} {r['ratio']:>7.1f}"
        )
    print(f"median ratio (open3d / ours): {res['median_ratio']:.1f}x")
    print(
        f"boundary extraction alone: {res['boundary_s']:.2f} s wall / {res['boundary_cpu']:.2f} "
        f"s CPU; fit_patch peak numpy memory {res['peak_bytes'] / 2**20:.0f} MiB "
        f"(the cloud itself: {res['points'] * 24 / 2**20:.0f} MiB)"
    )
    d = res["diagonal"]
    o, p = res["ours_truth"], res["open3d_truth"]
    print("distance from the true surface (401 x 401 grid), in units of the diagonal:")
    print(f"  ours:   mean {o['mean'] / d:.2e}  max {o['max'] / d:.2e}  "
          f"({res['ours_variables']:,d} variables)")
    print(f"  open3d: mean {p['mean'] / d:.2e}  max {p['max'] / d:.2e}  "
          f"({3 * p['vertices']:,d} variables)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", choices=sorted(SHAPES), default="flag")
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3, help="back-to-back timings")
    parser.add_argument("--depth", type=int, default=9, help="Poisson octree depth (default 9)")
    parser.add_argument("--quick", action="store_true", help="1e5 points, 1 repeat")
    parser.add_argument("--json", type=Path, help="write all numbers here")
    parser.add_argument("--loop-sides", action="store_true",
                        help="fit_patch(rims=False): sides on the boundary loop, no rim estimate")
    args = parser.parse_args(argv)
    count, repeat = (100_000, 1) if args.quick else (args.points, args.repeat)
    res = run(args.shape, count, repeat, args.depth, rims=not args.loop_sides)
    report(res)
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
