"""Segments that are no 3- or 4-sided region are split into 3/4-sided patches.

Own re-segmentations of analytic surfaces (:mod:`pde2cad.samples`), reconstructed with C1
and read back from STEP: valid, closed where closed, seams without gaps or kinks, and close
to the true surface."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad import samples
from pde2cad.layout.split import best_split

pytest.importorskip("OCP")

from pde2cad.occ import measure, read_step  # noqa: E402
from pde2cad.reconstruct import Reconstruction, reconstruct  # noqa: E402


def _true_error(rec: Reconstruction, cloud: samples.LabelledCloud) -> float:
    """Mean distance of a 41 x 41 grid on every face to the true surface, over the diagonal."""
    g = np.linspace(0.0, 1.0, 41)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    q = np.vstack([s.evaluate(u, v) for s in rec.surfaces.values()])
    return float(cloud.distance(q).mean() / cloud.diagonal)


def _check(
    rec: Reconstruction, cloud: samples.LabelledCloud, tmp_path: Path, max_angle: float
) -> dict:  # type: ignore[type-arg]
    m = measure(read_step(rec.write_step(tmp_path / "split.step")))
    assert m["valid"] and m["closed"] == cloud.closed
    assert m["max_gap"] <= 1e-7 * cloud.diagonal
    assert m["max_angle_deg"] <= max_angle
    assert _true_error(rec, cloud) <= 1e-4
    assert all(len(ids) in (3, 4) for ids in rec.network.loops.values())
    return m


def _tube_angle(points: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.arctan2(points[:, 1], points[:, 0]) % (2 * np.pi)


def test_best_split_cuts_a_2x1_hexagon_into_its_squares() -> None:
    """Corners of a 2 x 1 rectangle with the middle of both long sides as corners (T-nodes):
    the chord between the T-nodes gives two squares."""
    xy = np.array([[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]], dtype=float)
    n = len(xy)
    directions = {(i, j): xy[j] - xy[i] for i in range(n) for j in range(n) if i != j}
    assert sorted(map(sorted, best_split(directions, n))) == [[0, 1, 4, 5], [1, 2, 3, 4]]


def test_best_split_pentagon_cuts_from_the_t_node() -> None:
    """A unit square with a T-node in its bottom side: a triangle and a quad whose chord
    starts at the T-node (a chord elsewhere would leave the T-node a 180-degree corner)."""
    xy = np.array([[0, 0], [0.5, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    directions = {(i, j): xy[j] - xy[i] for i in range(5) for j in range(5) if i != j}
    pieces = best_split(directions, 5)
    assert sorted(len(p) for p in pieces) == [3, 4]
    chord = set(pieces[0]) & set(pieces[1])
    assert 1 in chord


def test_torus_two_patches_merged(tmp_path: Path) -> None:
    """Two neighbouring torus patches as one segment: 6 corners (two of them T-nodes of the
    neighbours' corners); cut back into two quads along the chord between the T-nodes."""
    cloud = samples.torus(20000)
    lab = cloud.labels.copy()
    lab[lab == 1] = 0
    rec = reconstruct(cloud.points, lab, continuity="c1")
    assert rec.splits.pieces == {0: [0, 16]} and rec.splits.corners == {0: 6}
    assert rec.c0_fallback == []
    m = _check(rec, cloud, tmp_path, 1.0)
    assert m["n_faces"] == 16 and m["shared_edges"] == 32 and m["free_edges"] == 0


def test_torus_one_patch_split_in_two(tmp_path: Path) -> None:
    """One torus patch cut in two across the tube: its two neighbours around the tube get a
    T-node each (5 corners); each is cut straight across its strip, which puts a T-node on
    both sides of the opposite patch (6 corners), cut between them: the cut closes around
    the tube and every corner joins four patches (exact C1)."""
    cloud = samples.torus(20000)
    lab = cloud.labels.copy()
    lab[(lab == 0) & (_tube_angle(cloud.points) < np.pi / 4)] = 99
    rec = reconstruct(cloud.points, lab, continuity="c1")
    assert sorted(rec.splits.pieces) == [1, 2, 3]
    assert all(len(p) == 2 for p in rec.splits.pieces.values())
    assert rec.splits.corners == {1: 5, 2: 6, 3: 5}
    assert all(rec.network.regular.values()) and rec.c0_fallback == []
    m = _check(rec, cloud, tmp_path, 1.0)
    assert m["n_faces"] == 20 and m["free_edges"] == 0
