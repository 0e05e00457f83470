"""A segment left in two parts by a cut is cut into its parts (issue 10: automatic layouts of
a torus scan and of OCCT's shape.stl were refused with "segment N falls apart into 2
separate pieces" from inside the split step), and polygons of many corners split fast."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pde2cad.errors import InputError
from pde2cad.layout.adjacency import build_layout, separate_pieces
from pde2cad.layout.split import best_split


def _sheet(n: int, seed: int) -> np.ndarray:
    """``n`` random points on the unit square (a plane), wavy in z."""
    xy = np.random.default_rng(seed).random((n, 2))
    return np.column_stack([xy, 0.05 * np.sin(3 * xy[:, 0])])


def test_a_segment_in_two_parts_gets_a_label_per_part() -> None:
    pts = _sheet(20000, 0)
    x = pts[:, 0]
    lab = np.where(x < 0.3, 0, np.where(x < 0.4, 1, 0)).astype(np.int64)  # 0 on both sides of 1
    with pytest.raises(InputError, match="falls apart"):
        build_layout(pts, lab, check=False)
    out, pieces = separate_pieces(pts, lab, first_new=10)
    assert pieces == {0: [0, 10]}
    # the larger part (x > 0.4, 60 % of the points) keeps the label, the other is new
    assert np.all(out[x > 0.4] == 0) and np.all(out[x < 0.3] == 10) and np.all(out[lab == 1] == 1)
    build_layout(pts, out, check=False)  # no longer falls apart


def test_a_crumb_too_small_for_a_segment_joins_its_neighbour() -> None:
    """A part with over COMPONENT_SHARE (1 %) of its segment's points but under the 50 a
    segment needs takes its neighbour's label."""
    pts = _sheet(20000, 1)
    x, y = pts[:, 0], pts[:, 1]
    lab = (x > 0.1).astype(np.int64)
    crumb = (x > 0.8) & (x < 0.845) & (y > 0.5) & (y < 0.545)  # ~40 points inside label 1
    assert 0.01 * ((lab == 0).sum() + crumb.sum()) <= crumb.sum() < 50
    lab[crumb] = 0
    out, pieces = separate_pieces(pts, lab, first_new=5)
    assert pieces == {}
    assert np.all(out[crumb] == 1) and np.all(out[~crumb] == lab[~crumb])


def test_nothing_apart_returns_the_labels_unchanged() -> None:
    pts = _sheet(5000, 2)
    lab = (pts[:, 0] > 0.5).astype(np.int64)
    out, pieces = separate_pieces(pts, lab, first_new=2)
    assert pieces == {} and out is lab or np.array_equal(out, lab)


@pytest.mark.parametrize("n", [16, 24, 30])
def test_many_corners_split_into_quads_and_triangles_fast(n: int) -> None:
    """A regular n-gon (a crease-bounded CAD face with many corners): every corner in some
    piece, pieces of 3 or 4 corners, in about a second (the exhaustive chord search took
    0.8 s at 16 corners and grows 1.7x per corner)."""
    a = 2 * np.pi * np.arange(n) / n
    p = np.column_stack([np.cos(a), np.sin(a)])
    d = {}
    for i in range(n):
        for j in range(n):
            if i != j:
                v = p[j] - p[i]
                d[(i, j)] = v / np.linalg.norm(v)
    t0 = time.perf_counter()
    pieces = best_split(d, n)
    assert time.perf_counter() - t0 < 5.0
    assert all(len(q) in (3, 4) for q in pieces)
    assert set().union(*map(set, pieces)) == set(range(n))
    # a triangulated/quadrangulated n-gon: pieces' corner counts add up to n + 2 (pieces - 1)
    assert sum(len(q) for q in pieces) == n + 2 * (len(pieces) - 1)


def test_a_piece_too_small_joins_the_piece_next_to_it() -> None:
    """A split (or a sector cut) that leaves a sliver under the 50 points a segment needs
    gives the sliver to the piece of its nearest point instead of refusing the layout."""
    from pde2cad.layout.split import _absorb_small

    pts = _sheet(4000, 3)
    x = pts[:, 0]
    which = np.where(x < 0.5, 0, np.where(x < 0.505, 1, 2)).astype(np.int64)  # piece 1: ~20 points
    assert 0 < (which == 1).sum() < 50
    out = _absorb_small(pts, which, 50)
    assert sorted(np.unique(out).tolist()) == [0, 1]  # renumbered 0 .. Q-1
    assert np.all(out[x < 0.49] == out[x < 0.49][0]) and np.all(out[x > 0.51] == out[x > 0.51][0])
    assert out[x < 0.49][0] != out[x > 0.51][0]
    assert np.array_equal(_absorb_small(pts, np.zeros(4000, np.int64), 50), np.zeros(4000))
    assert _absorb_small(pts[:30], which[:30], 50).max() == 0  # every piece small: one piece


def test_pieces_facing_each_other_across_a_gap_share_no_border() -> None:
    """Two random sheets ending edge to edge, one 0.6 neighbour radii above the other (the
    teapot's lid wall and its rim's lip on a 0.2 %-noise cloud, 0.1 apart at radius
    0.053): points of both lie within a radius of each other and each surface ends there,
    as at a crease, but even the closest pair stays a gap apart. They share no border and
    each keeps its own 4 corners. Without the gap, flat or folded up by 90 degrees (a
    crease), the same sheets share one."""
    rng = np.random.default_rng(3)
    n = 20_000
    low = np.column_stack([rng.uniform(-1.0, 0.0, n), rng.uniform(0.0, 1.0, n), np.zeros(n)])
    s = rng.uniform(0.0, 1.0, n)
    high = np.column_stack([s, rng.uniform(0.0, 1.0, n), np.zeros(n)])
    labels = np.repeat([0, 1], n)
    radius = build_layout(np.vstack([low, high + [0.0, 0.0, 5.0]]), labels).radius
    step = high + [0.0, 0.0, 0.6 * radius]
    assert cKDTree(low).query(step)[0].min() < radius
    apart = build_layout(np.vstack([low, step]), labels)
    assert (0, 1) not in apart.adjacency
    assert all(len(ids) == 4 for ids in apart.segment_corners.values())
    up = np.column_stack([np.zeros(n), high[:, 1], s])
    for other in (high, up):
        assert (0, 1) in build_layout(np.vstack([low, other]), labels).adjacency
