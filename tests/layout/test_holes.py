"""Segments with several holes (3 or more boundary loops) cut into quads round the holes.

A gently curved 4 x 2 sheet, z = 0.15 x^2, sampled at random with holes of different sizes
cut out, given as ONE label; reconstructed with C1 and read back from STEP."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pde2cad.layout.holes import spread

pytest.importorskip("OCP")

from pde2cad.occ import measure, read_step  # noqa: E402
from pde2cad.reconstruct import reconstruct  # noqa: E402

Holes = tuple[tuple[float, float, float], ...]
#: Two holes of radius 0.4 and 0.3; three in a row of radius 0.3, 0.35 and 0.25.
LAYOUTS: dict[str, Holes] = {
    "two": ((-0.9, 0.0, 0.4), (0.9, 0.1, 0.3)),
    "three": ((-1.3, 0.0, 0.3), (0.0, 0.2, 0.35), (1.3, -0.1, 0.25)),
}


def _sheet(holes: Holes, n: int = 20000, seed: int = 0) -> NDArray[np.float64]:
    """``n`` random points of z = 0.15 x^2 over [-2, 2] x [-1, 1] outside the ``holes``
    (centre x, centre y, radius)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([-2.0, -1.0], [2.0, 1.0], size=(2 * n, 2))
    keep = np.ones(len(xy), dtype=bool)
    for cx, cy, r in holes:
        keep &= np.hypot(xy[:, 0] - cx, xy[:, 1] - cy) > r
    xy = xy[keep][:n]
    return np.column_stack([xy, 0.15 * xy[:, 0] ** 2])


def test_spread_moves_close_angles_apart_and_keeps_far_ones() -> None:
    a = np.array([-2.0, 0.0, 0.1, 2.0])
    out = spread(a, 0.5)
    gaps = np.diff(np.append(out, out[0] + 2 * np.pi))
    assert gaps.min() >= 0.5 - 1e-6
    assert abs(out[0] - a[0]) < 1e-9 and abs(out[3] - a[3]) < 1e-9
    assert np.allclose(out[1:3].mean(), 0.05)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_sheet_with_holes_as_one_label_reconstructs(name: str, tmp_path: Path) -> None:
    """Every piece 4-sided (measured: 22 quads with two holes, 30 with three), valid, open
    along the rim and the holes only, no gap (2.2e-13 D); the issue's distances (measured:
    in -> faces mean 4.3e-5 D, none beyond 1 % D, faces -> in p95 4.3e-3 D) and smooth
    seams (0.79 and 0.46 deg); 6-8 s CPU each."""
    pts = _sheet(LAYOUTS[name])
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    rec = reconstruct(pts, np.zeros(len(pts), dtype=np.int64), continuity="c1")
    assert rec.splits.loops == {0: len(LAYOUTS[name]) + 1}
    assert all(len(ids) == 4 for ids in rec.network.loops.values())
    m = measure(read_step(rec.write_step(tmp_path / "holes.step")))
    assert m["valid"] and not m["closed"] and m["nonmanifold_edges"] == 0
    assert m["max_gap"] <= 1e-7 * diagonal
    assert m["max_angle_deg"] <= 1.0
    dist = np.concatenate([np.linalg.norm(p.evaluate(p.params[:, 0], p.params[:, 1]) - p.points, axis=1)
                           for p in rec.patches.values()])
    assert dist.mean() <= 2e-3 * diagonal and np.mean(dist > 0.01 * diagonal) < 0.01
    g = np.linspace(0.0, 1.0, 30)
    uu, vv = (a.ravel() for a in np.meshgrid(g, g))
    faces = np.concatenate([p.evaluate(uu, vv) for p in rec.patches.values()])
    # No face over a hole: face samples lie near the input (95 % within 5e-3 D).
    assert np.percentile(cKDTree(pts).query(faces)[0], 95) <= 5e-3 * diagonal
