"""Benchmark one Chapter 5 patch against Poisson surface reconstruction (open3d).

Usage (from a plain checkout, with the project's venv python)::

    python benchmarks/surface_fit_vs_poisson.py            # 1e5, 3e5, 1e6 points
    python benchmarks/surface_fit_vs_poisson.py --quick    # 1e5 points only
    python benchmarks/surface_fit_vs_poisson.py --json out.json --depth 9

The cloud is the "flag" of the tests: ``z = 0.1 x sin(3x + 2y)`` over [0, 1] x [0, 0.75],
uniformly random (unstructured) points. For each size, in a fresh process (so the peak memory
``ru_maxrss`` is that size's own):

* boundary extraction with the four true corners (timed apart: it is not the fit);
* ``fit_patch(points, m=10, n=10, boundary=...)``: parameterization (closest points on the
  bilinear Coons patch) + the sine deformation (Eq. 5.17); the projection is also timed on
  its own (the same call), the rest of ``fit_patch`` being residuals and least squares;
* ``patch.errors`` (Eq. 5.22 plus a re-projection for the orthogonal errors), timed apart.

Then, on the largest cloud, open3d's normal estimation + Poisson reconstruction (depth 8 and
``--depth``), trimmed to the data (vertices below the 2 % density quantile and outside the
points' bounding box removed, the usual clean-up of an open surface). Both results are
compared on a dense grid of the TRUE surface: distance from each true point to the Poisson mesh
(``RaycastingScene.compute_distance``) and to our patch (closest point by projection).
"Variables" counts the stored scalars: 3 per mesh vertex for Poisson; sides, amplitudes and
(for C1) ribbons for the patch (``Patch.n_variables``).

Times are wall-clock seconds (best of ``--repeat``) with the CPU seconds of the process
beside them: on a shared machine the wall time also measures the neighbours.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import resource
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import pde2cad  # noqa: F401
except ImportError:  # plain checkout without an installed package
    sys.path.insert(0, str(ROOT / "src"))

from pde2cad.surfaces.coons import BilinearCoons  # noqa: E402
from pde2cad.surfaces.patch import Patch, fit_patch  # noqa: E402
from pde2cad.surfaces.projection import project_points  # noqa: E402
from pde2cad.surfaces.region import extract_boundary  # noqa: E402

TERMS = 10
#: A second, finer patch for the comparison with Poisson (largest cloud only).
FINE_TERMS = 15


def flag(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The test flag (Fig. 5.9 stand-in), unit-sized: (..., 3)."""
    x, y = u, 0.75 * v
    return np.stack([x, y, 0.1 * x * np.sin(3 * x + 2 * y)], axis=-1)


def cloud(count: int, seed: int = 0) -> np.ndarray:
    uv = np.random.default_rng(seed).random((2, count))
    return flag(uv[0], uv[1])


def truth_grid(count: int = 401) -> np.ndarray:
    """Dense samples of the true surface, (count^2, 3)."""
    g = np.linspace(0.0, 1.0, count)
    u, v = np.meshgrid(g, g, indexing="ij")
    return flag(u.ravel(), v.ravel())


CORNERS = flag(np.array([0.0, 1.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0, 1.0]))


def timed(fn: Any, repeat: int = 1) -> tuple[Any, float, float]:
    """Result, best wall time and the CPU time of that run."""
    best, cpu, out = np.inf, np.nan, None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = time.perf_counter() - w0
        if wall < best:
            best, cpu = wall, time.process_time() - c0
    return out, best, cpu


def run_ours(count: int, repeat: int, with_truth: bool) -> dict[str, Any]:
    """One size, in its own process (see main)."""
    points = cloud(count)
    region, t_boundary, c_boundary = timed(lambda: extract_boundary(points, corners=CORNERS))
    # fit_patch's first and biggest step, on its own.
    base = BilinearCoons.from_loop(*region.sides)
    _, t_proj, c_proj = timed(lambda: project_points(base, points), repeat)
    patch, t_fit, c_fit = timed(
        lambda: fit_patch(points, m=TERMS, n=TERMS, boundary=region), repeat
    )
    errors, t_err, c_err = timed(lambda: patch.errors)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2  # kB -> GB
    out: dict[str, Any] = {
        "points": count,
        "boundary_s": t_boundary,
        "boundary_cpu": c_boundary,
        "projection_s": t_proj,
        "projection_cpu": c_proj,
        "least_squares_s": t_fit - t_proj,
        "least_squares_cpu": c_fit - c_proj,
        "fit_s": t_fit,
        "fit_cpu": c_fit,
        "errors_s": t_err,
        "errors_cpu": c_err,
        "peak_gb": peak,
        "variables": patch.n_variables,
        "errors": errors,
        "side_errors": region.side_errors.tolist(),
    }
    if with_truth:
        out["truth"] = truth_distance_patch(patch)
        fine, t_fine, c_fine = timed(
            lambda: fit_patch(points, m=FINE_TERMS, n=FINE_TERMS, boundary=region)
        )
        out["fine"] = {
            "fit_s": t_fine,
            "fit_cpu": c_fine,
            "variables": fine.n_variables,
            "truth": truth_distance_patch(fine),
        }
    return out


def truth_distance_patch(patch: Patch) -> dict[str, float]:
    """Distance from the dense true surface to the patch (closest points by projection)."""
    _, dist, _ = project_points(patch, truth_grid())
    return {"mean": float(dist.mean()), "max": float(dist.max())}


def run_poisson(points: np.ndarray, depth: int) -> dict[str, Any]:
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    spacing = np.sqrt(0.75 / len(points))  # mean point spacing on the flag's area

    def normals() -> None:
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=6 * spacing, max_nn=30))
        # The flag is a height field: orient every normal upwards.
        pcd.orient_normals_to_align_with_direction(np.array([0.0, 0.0, 1.0]))

    _, t_normals, c_normals = timed(normals)

    def poisson() -> Any:
        return o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)

    (mesh, density), t_poisson, c_poisson = timed(poisson)
    raw_vertices = len(mesh.vertices)
    density = np.asarray(density)
    mesh.remove_vertices_by_mask(density < np.quantile(density, 0.02))
    box = o3d.geometry.AxisAlignedBoundingBox(points.min(axis=0), points.max(axis=0))
    mesh = mesh.crop(box)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    query = o3d.core.Tensor(truth_grid().astype(np.float32))
    dist = scene.compute_distance(query).numpy().astype(float)
    return {
        "depth": depth,
        "normals_s": t_normals,
        "normals_cpu": c_normals,
        "poisson_s": t_poisson,
        "poisson_cpu": c_poisson,
        "vertices_raw": raw_vertices,
        "vertices": len(mesh.vertices),
        "triangles": len(mesh.triangles),
        "variables": 3 * len(mesh.vertices),
        "truth": {"mean": float(dist.mean()), "max": float(dist.max())},
    }


def _child(count: int, repeat: int, with_truth: bool, queue: Any) -> None:
    try:
        queue.put(run_ours(count, repeat, with_truth))
    except BaseException as exc:  # report, do not hang the parent
        queue.put({"points": count, "failed": f"{type(exc).__name__}: {exc}"})


def in_fresh_process(count: int, repeat: int, with_truth: bool) -> dict[str, Any]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(count, repeat, with_truth, queue))
    proc.start()
    result = queue.get()
    proc.join()
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="1e5 points only, Poisson depth 8")
    parser.add_argument("--depth", type=int, default=9, help="deepest Poisson octree (default 9)")
    parser.add_argument("--repeat", type=int, default=1, help="runs per timing, best kept")
    parser.add_argument("--json", type=Path, help="write all numbers here")
    args = parser.parse_args(argv)
    sizes = [100_000] if args.quick else [100_000, 300_000, 1_000_000]
    depths = [8] if args.quick else sorted({8, args.depth})

    ours = []
    for count in sizes:
        res = in_fresh_process(count, args.repeat, with_truth=count == sizes[-1])
        if "failed" in res:
            print(f"{count:>9,d} points: FAILED {res['failed']}")
            return 1
        ours.append(res)
    print(f"\nOne patch, M = N = {TERMS}, flag cloud (wall s / CPU s; {mp.cpu_count()} cores)")
    print(
        f"{'points':>9} {'boundary':>13} {'projection':>13} {'rest':>13} "
        f"{'fit_patch':>13} {'us/point':>8} {'errors':>13} {'peak GB':>7} "
        f"{'mean err':>9} {'max err':>9} {'mean orth':>9}"
    )
    for r in ours:
        e = r["errors"]
        print(
            f"{r['points']:>9,d} {r['boundary_s']:>6.2f}/{r['boundary_cpu']:<6.2f}"
            f"{r['projection_s']:>7.2f}/{r['projection_cpu']:<6.2f}"
            f"{r['least_squares_s']:>7.2f}/{r['least_squares_cpu']:<6.2f}"
            f"{r['fit_s']:>7.2f}/{r['fit_cpu']:<6.2f}"
            f"{1e6 * r['fit_s'] / r['points']:>8.2f} "
            f"{r['errors_s']:>6.2f}/{r['errors_cpu']:<6.2f}"
            f"{r['peak_gb']:>7.2f} {e['mean']:>9.2e} {e['max']:>9.2e} "
            f"{e['mean_orthogonal']:>9.2e}"
        )
    if len(ours) > 1:
        slope = np.polyfit(
            np.log([r["points"] for r in ours]), np.log([r["fit_s"] for r in ours]), 1
        )[0]
        print(f"fit_patch time ~ N^{slope:.2f} (1 = linear)")

    big = ours[-1]
    points = cloud(big["points"])
    poisson = [run_poisson(points, d) for d in depths]
    print(f"\nAgainst Poisson on {big['points']:,d} points (distance from the true surface)")
    print(
        f"{'method':<22} {'time s':>8} {'CPU s':>8} {'variables':>10} {'mean dist':>10} "
        f"{'max dist':>10} {'time x':>7} {'vars x':>8} {'mean x':>8}"
    )
    t_ours = big["fit_s"]
    print(
        f"{'patch M=N=10 (ours)':<22} {t_ours:>8.2f} {big['fit_cpu']:>8.2f} "
        f"{big['variables']:>10,d} {big['truth']['mean']:>10.2e} {big['truth']['max']:>10.2e} "
        f"{1:>7.2f} {1:>8.1f} {1:>8.2f}"
    )
    fine = big["fine"]
    print(
        f"{f'patch M=N={FINE_TERMS} (ours)':<22} {fine['fit_s']:>8.2f} {fine['fit_cpu']:>8.2f} "
        f"{fine['variables']:>10,d} {fine['truth']['mean']:>10.2e} "
        f"{fine['truth']['max']:>10.2e} {fine['fit_s'] / t_ours:>7.2f} "
        f"{fine['variables'] / big['variables']:>8.1f} "
        f"{fine['truth']['mean'] / big['truth']['mean']:>8.2f}"
    )
    for p in poisson:
        t = p["normals_s"] + p["poisson_s"]
        c = p["normals_cpu"] + p["poisson_cpu"]
        print(
            f"{'Poisson depth ' + str(p['depth']):<22} {t:>8.2f} {c:>8.2f} {p['variables']:>10,d} "
            f"{p['truth']['mean']:>10.2e} {p['truth']['max']:>10.2e} {t / t_ours:>7.2f} "
            f"{p['variables'] / big['variables']:>8.1f} "
            f"{p['truth']['mean'] / big['truth']['mean']:>8.2f}"
        )
    print(f"(x columns: ratio to the M=N={TERMS} patch; boundary extraction not in our times)")
    if args.json:
        args.json.write_text(json.dumps({"ours": ours, "poisson": poisson}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
