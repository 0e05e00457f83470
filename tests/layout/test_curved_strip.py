"""A curved strip whose sides carry many neighbours' corners is cut into few, whole pieces
(issue 10: a fillet strip of OCCT's shape.stl with 16 corners was cut into 46 cells, whose
crumbs pinched or left a piece with a lost side).

Own synthetic shape: a 270-degree C-shaped band on the paraboloid z = 0.15 r^2, three
rings of segments; the middle ring is one segment, the inner ring is cut at 3 angles and the
outer one at 4, two of them 0.015 rad from an inner cut (strip cuts from both would leave a
slab two point spacings wide)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pde2cad import samples
from pde2cad.layout import split

pytest.importorskip("OCP")

from pde2cad.occ import measure, read_step  # noqa: E402
from pde2cad.reconstruct import reconstruct  # noqa: E402

INNER_CUTS = [0.9, 2.6, 3.9]
OUTER_CUTS = [0.915, 1.75, 2.615, 3.3]


def _band(n_points: int = 30000, seed: int = 0) -> samples.LabelledCloud:
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.uniform(1.0, 1.5**2, n_points))
    t = rng.uniform(0.0, 1.5 * np.pi, n_points)
    pts = np.column_stack([r * np.cos(t), r * np.sin(t), 0.15 * r**2])
    lab = np.zeros(n_points, dtype=np.int64)
    inner, outer = r < 1.1, r > 1.3
    lab[inner] = 1 + np.searchsorted(INNER_CUTS, t[inner])
    lab[outer] = 10 + np.searchsorted(OUTER_CUTS, t[outer])

    def distance(q: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.asarray(q, float)
        rr = np.hypot(q[:, 0], q[:, 1])
        return np.abs(q[:, 2] - 0.15 * rr**2) / np.sqrt(1 + (0.3 * rr) ** 2)

    return samples.LabelledCloud("band", pts, lab, distance, False)


def test_curved_strip_with_many_corners(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The middle ring (11 corners: 4 ends, 7 neighbours' corners) becomes at most 5 pieces
    of at least MIN_PIECE_POINTS each (a 11-gon needs 4 quads), every patch 3/4-sided, and the
    layout reconstructs with C1: no gaps, smooth seams, close to the paraboloid."""
    cloud = _band()
    real = split._split_one
    pieces: list[int] = []

    def counted(points: NDArray[np.float64], *args: object) -> NDArray[np.int64]:
        out = real(points, *args)  # type: ignore[arg-type]
        pieces.extend(np.bincount(out).tolist())
        return out

    monkeypatch.setattr(split, "_split_one", counted)
    rec = reconstruct(cloud.points, cloud.labels, continuity="c1")
    assert min(pieces) >= split.MIN_PIECE_POINTS
    assert rec.splits.corners[0] == 11 and 4 <= len(rec.splits.pieces[0]) <= 5
    assert all(len(ids) in (3, 4) for ids in rec.network.loops.values())
    m = measure(read_step(rec.write_step(tmp_path / "band.step")))
    assert m["valid"] and m["max_gap"] <= 1e-7 * cloud.diagonal and m["max_angle_deg"] <= 1.0
    g = np.linspace(0.0, 1.0, 41)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    q = np.vstack([s.evaluate(u, v) for s in rec.surfaces.values()])
    assert float(cloud.distance(q).mean() / cloud.diagonal) <= 1e-4


def test_a_slab_between_near_cuts_is_a_crumb() -> None:
    """Cells of a 2 x 1 sheet (spacing ~0.01): a 0.02-wide slab holds well over
    MIN_PIECE_POINTS points but is narrower than the corner reach, so it is a crumb; halves
    are not."""
    xy = np.random.default_rng(0).random((20000, 2)) * [2.0, 1.0]
    pts = np.column_stack([xy, np.zeros(len(xy))])
    s = np.linspace(0.0, 1.0, 200, endpoint=False)
    loop = np.vstack([np.column_stack([2 * s, 0 * s]), np.column_stack([2 + 0 * s, s]),
                      np.column_stack([2 - 2 * s, 1 + 0 * s]), np.column_stack([0 * s, 1 - s])])
    loop = np.column_stack([loop, np.zeros(len(loop))])
    reach = 0.08
    halves = (xy[:, 0] > 1.0).astype(np.int64)
    slab = halves + ((xy[:, 0] > 1.0) & (xy[:, 0] < 1.02))
    assert not split._has_crumbs(pts, loop, halves, reach)
    assert (slab == 2).sum() > 3 * split.MIN_PIECE_POINTS
    assert split._has_crumbs(pts, loop, slab, reach)
