"""Known corners (an automatic layout's coarse vertices) and the labels that go with them."""

from __future__ import annotations

import numpy as np
import pytest

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import build_layout
from pde2cad.layout.auto import (
    clean_labels,
    claim_sides,
    crease_regions,
    known_corners,
    label_points,
    point_normals,
    region_borders,
    surface_faces,
)
from pde2cad.layout.known import KnownCorners, with_known_corners

# A 2 x 2 grid of unit squares on z = 0: corners (i, j) -> 3 i + j.
GRID_V = np.array([[i, j, 0.0] for i in range(3) for j in range(3)])
GRID_F = [(0, 3, 4, 1), (1, 4, 5, 2), (3, 6, 7, 4), (4, 7, 8, 5)]
CUBE_V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
CUBE_Q = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]


def _grid_cloud(n: int = 20000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    xy = np.random.default_rng(seed).random((n, 2)) * 2.0
    pts = np.column_stack([xy, 0.05 * np.sin(xy[:, 0]) * np.cos(xy[:, 1])])
    lab = (xy[:, 0] >= 1).astype(np.int64) * 2 + (xy[:, 1] >= 1)
    return pts, lab


def test_known_corners_replace_the_inferred_ones() -> None:
    """Each square gets its 4 grid vertices, snapped onto the cloud near the truth; diagonal squares (which touch at the centre only) share no border."""
    pts, lab = _grid_cloud()
    layout = build_layout(pts, lab, check=False)
    from scipy.spatial import cKDTree

    known = KnownCorners(GRID_V, {f: GRID_F[f] for f in range(4)}, np.array(
        [True, True, True, True, False, True, True, True, True]))
    out = with_known_corners(layout, known, pts, lab, cKDTree(pts))
    assert len(out.corners) == 9
    assert all(len(c) == 4 for c in out.segment_corners.values())
    truth = np.column_stack([GRID_V[:, :2], 0.05 * np.sin(GRID_V[:, 0]) * np.cos(GRID_V[:, 1])])
    off = np.linalg.norm(out.corners - truth, axis=1) / layout.spacing
    # Junctions of 2-4 squares on their junction; the square's outer corners on its
    # nearest point (a quarter disc around it: a few spacings; the edges refine them).
    assert off[[1, 3, 4, 5, 7]].max() < 3.0 and off.max() < 8.0
    assert set(out.borders) == {(0, 1), (0, 2), (1, 3), (2, 3)}
    assert out.open_corners is not None and out.open_corners.sum() == 8


def test_a_segment_without_3_or_4_known_corners_is_named() -> None:
    pts, lab = _grid_cloud(4000)
    layout = build_layout(pts, lab, check=False)
    from scipy.spatial import cKDTree

    known = KnownCorners(GRID_V, {0: GRID_F[0], 1: GRID_F[1], 2: GRID_F[2], 3: (4, 7)})
    with pytest.raises(InputError, match="segment 3 has 2 known corners"):
        with_known_corners(layout, known, pts, lab, cKDTree(pts))


def test_surface_faces_lie_on_the_sphere_where_the_cube_faces_cut_chords() -> None:
    """The cube's faces projected to the unit sphere: a face centre lies 0.42 inside the
    sphere, the laid-on grid within 1 % of it; every triangle belongs to its face."""
    pts = np.random.default_rng(1).normal(size=(30000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    cube = CUBE_V / np.sqrt(3.0)
    grid, tris, owner = surface_faces(pts, cube, CUBE_Q, point_normals(pts), cells=6)
    assert np.abs(np.linalg.norm(grid, axis=1) - 1.0).max() < 0.01
    assert len(tris) == 6 * 72 and np.array_equal(np.bincount(owner), np.full(6, 72))
    # Labels through the grid match the cube-map faces (the dominant axis of each point).
    labels = owner[label_points(pts, grid, tris)]
    axis = np.argmax(np.abs(pts), axis=1) * 2 + (pts[np.arange(len(pts)),
                                                    np.argmax(np.abs(pts), axis=1)] > 0)
    pairs = np.unique(np.column_stack([labels, axis]), axis=0, return_counts=True)[1]
    assert np.sort(pairs)[-6:].sum() >= 0.99 * len(pts)


def test_claim_sides_gives_an_edge_strip_back_to_its_two_faces() -> None:
    """A third label cut across the middle of the edge between squares 0 and 2 (x = 1,
    0 <= y <= 1) leaves them without a common border; the strip goes back to them, split by
    the side of the edge each point lies on."""
    pts, lab = _grid_cloud()
    intruder = (np.abs(pts[:, 0] - 1) < 0.1) & (np.abs(pts[:, 1] - 0.5) < 0.2)
    bad = np.where(intruder, 1, lab)
    fixed = claim_sides(pts, bad, GRID_V, GRID_F, point_normals(pts))
    assert np.array_equal(fixed[intruder], np.where(pts[intruder, 0] < 1, 0, 2))
    assert np.array_equal(fixed[~intruder], lab[~intruder])


def test_known_corners_need_labels_and_faces_one_to_one() -> None:
    pts, lab = _grid_cloud(4000)
    known = known_corners(lab, clean_labels(pts, lab), GRID_V, GRID_F)
    assert known is not None and known.segments[3] == GRID_F[3]
    assert known.on_open.sum() == 8 and not known.on_open[4]
    merged = np.where(lab == 3, 2, lab)  # faces 2 and 3 one label: no one-to-one map
    assert known_corners(lab, clean_labels(pts, merged), GRID_V, GRID_F) is None


def test_crease_specks_smaller_than_min_area_are_no_regions() -> None:
    """A subdivided box with one vertex of a face pushed out: the bump's triangles bend by
    more than 30 deg, a speck region; with min_area it joins its face, the box keeps 6."""
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box((1.0, 2.0, 3.0)).subdivide().subdivide()
    v, f = np.array(box.vertices), np.asarray(box.faces)
    top = np.flatnonzero((np.abs(v[:, 2] - 1.5) < 1e-9) & (np.abs(v[:, :2]).max(axis=1) < 0.3))
    v[top[0], 2] += 0.4
    assert crease_regions(v, f, 30.0).max() + 1 > 6
    region = crease_regions(v, f, 30.0, min_area=0.5)
    assert region.max() + 1 == 6
    assert region_borders(f, region) == region_borders(np.asarray(box.faces),
                                                       crease_regions(np.asarray(box.vertices),
                                                                      f, 30.0))
